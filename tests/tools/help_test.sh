#!/usr/bin/env bash
# Every `turncal` subcommand's --help is a manual page: DESCRIPTION, EXAMPLES, EXIT STATUS and
# SEE ALSO after the options (tools/help_text.cc); `turncald --help` likewise. Each example's
# command must be a subcommand that exists.
# Usage: help_test.sh TURNCAL TURNCALD
set -uo pipefail
turncal=$1
turncald=$2
failures=0
commands=$("$turncal" --help | awk '/^Subcommands:/{on=1; next} on && /^  [a-z]/{print $1}')
[[ -n $commands ]] || { echo "FAIL: no subcommands in turncal --help"; exit 1; }
n=0
for c in $commands; do
  n=$((n + 1))
  text=$("$turncal" "$c" --help 2>&1)
  for section in DESCRIPTION EXAMPLES "EXIT STATUS" "SEE ALSO"; do
    if ! grep -q "^$section\$" <<< "$text"; then
      echo "FAIL: turncal $c --help has no $section"
      failures=$((failures + 1))
    fi
  done
  # Every example names an existing subcommand (the first word after "turncal").
  while read -r used; do
    [[ -z $used ]] && continue
    grep -qx "$used" <<< "$commands" || {
      echo "FAIL: turncal $c --help: example uses unknown command '$used'"
      failures=$((failures + 1))
    }
  done < <(grep '^  \$ turncal ' <<< "$text" | awk '{print $3}')
done
text=$("$turncald" --help 2>&1)
for section in DESCRIPTION EXAMPLES "EXIT STATUS" "SEE ALSO"; do
  grep -q "^$section\$" <<< "$text" || { echo "FAIL: turncald --help has no $section"; failures=$((failures + 1)); }
done
echo "help pages: $n turncal commands and turncald checked, $failures failures"
[[ $failures == 0 ]]
