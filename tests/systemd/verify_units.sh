#!/usr/bin/env bash
# Checks the systemd files of systemd/ without a running systemd (systemd/README.md):
# - `systemd-analyze verify` on turncald.service and turncald.socket, alone and with the
#   tcp-serial.conf drop-in: any warning or error naming our units fails the test;
# - `systemd-sysusers --dry-run` on turncal.sysusers, into an empty root;
# - `systemd-analyze security --offline=true`: prints the exposure of turncald.service, with and
#   without the drop-in, and fails when either is above the level measured when the unit was
#   written plus 0.5 (a unit change that loosens the sandbox has to move these numbers on purpose).
# verify checks that ExecStart= is executable, and /usr/sbin/turncald is not installed here, so the
# copies under test run /bin/true instead (same line numbers, so messages point at the sources);
# nothing else is changed, and nothing needs a build.
# Usage: verify_units.sh [SOURCE_DIR]
set -euo pipefail
command -v systemd-analyze > /dev/null || { echo "SKIP: systemd-analyze is not installed"; exit 0; }
source_dir=${1:-$(cd "$(dirname "$0")/../.." && pwd)}
units=$source_dir/systemd

# Exposure measured with systemd 252 (systemd/README.md, table); the test allows 0.5 more.
measured=0.7
measured_tcp=1.5

dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
failed=0

# Copies of the units in DIR, ExecStart= pointing at /bin/true; with "tcp", the drop-in too.
stage() {
  mkdir -p "$1"
  sed 's#^ExecStart=/usr/sbin/turncald #ExecStart=/bin/true #' "$units/turncald.service" \
    > "$1/turncald.service"
  grep -q '^ExecStart=/bin/true ' "$1/turncald.service" \
    || { echo "FAIL: no ExecStart=/usr/sbin/turncald line to rewrite"; exit 1; }
  cp "$units/turncald.socket" "$1/"
  if [[ ${2:-} == tcp ]]; then
    mkdir -p "$1/turncald.service.d"
    cp "$units/tcp-serial.conf" "$1/turncald.service.d/"
  fi
  if [[ ${2:-} == registry ]]; then
    mkdir -p "$1/turncald.service.d"
    cp "$units/registry.conf" "$1/turncald.service.d/"
  fi
}

verify() {  # DIR LABEL
  local out rc=0
  out=$(cd "$1" && systemd-analyze verify --man=no ./turncald.socket ./turncald.service 2>&1) \
    || rc=$?
  # Lines about other units (the system's own) are not ours to fix.
  out=$(grep -E "turncald|turncal\.|tcp-serial|registry\.conf|$1" <<< "$out" || true)
  if [[ $rc != 0 || -n $out ]]; then
    echo "FAIL: systemd-analyze verify ($2), exit $rc:"
    echo "$out"
    failed=1
  else
    echo "verify ($2): no warnings"
  fi
}

exposure() {  # DIR LABEL LIMIT
  local out level
  out=$(cd "$1" && systemd-analyze security --offline=true ./turncald.service 2>&1) || true
  level=$(sed -n 's/^→ Overall exposure level for turncald.service: \([0-9.]*\) .*/\1/p' <<< "$out")
  if [[ -z $level ]]; then
    echo "FAIL: no exposure level in systemd-analyze security ($2):"
    echo "$out"
    failed=1
    return
  fi
  echo "exposure ($2): $level (limit $3); not set:"
  grep '^✗' <<< "$out" | sed 's/  */ /g; s/^/  /'
  if awk -v l="$level" -v m="$3" 'BEGIN { exit !(l > m) }'; then
    echo "FAIL: exposure $level is above $3"
    failed=1
  fi
}

stage "$dir/plain"
stage "$dir/tcp" tcp
verify "$dir/plain" "units"
verify "$dir/tcp" "units + tcp-serial.conf"
stage "$dir/registry" registry
verify "$dir/registry" "units + registry.conf"

if command -v systemd-sysusers > /dev/null; then
  mkdir -p "$dir/root/etc"
  if out=$(systemd-sysusers --dry-run --root="$dir/root" "$units/turncal.sysusers" 2>&1) \
     && grep -q "Creating user 'turncal'" <<< "$out"; then
    echo "sysusers: creates user and group turncal"
  else
    echo "FAIL: systemd-sysusers --dry-run turncal.sysusers:"
    echo "$out"
    failed=1
  fi
fi

limit=$(awk -v m="$measured" 'BEGIN { print m + 0.5 }')
limit_tcp=$(awk -v m="$measured_tcp" 'BEGIN { print m + 0.5 }')
exposure "$dir/plain" "turncald.service" "$limit"
exposure "$dir/tcp" "turncald.service + tcp-serial.conf" "$limit_tcp"
exposure "$dir/registry" "turncald.service + registry.conf" "$limit_tcp"

[[ $failed == 0 ]] && echo "systemd units: verified"
exit $failed
