#!/usr/bin/env bash
# The layers include only downwards (docs/ARCHITECTURE.md): every `#include "DIR/..."` of a file
# in a layer must name a layer it may use. Checks the tree at ROOT (the repository), then checks
# itself: a copy of core/ with an include of daemon/ must be refused.
#   tests/layering_check.sh ROOT
set -uo pipefail
ROOT=${1:?usage: layering_check.sh ROOT}
# layer: the layers its files may include ("turncal" is the generated version and model list).
# daemon/ is in rooms, each a layer of its own (daemon/CMakeLists.txt); an include of the daemon
# names its room ("daemon/station/station.h" is daemon/station). A file belongs to the most
# specific layer whose folder holds it (daemon/turncald_main.cc to daemon).
BELOW_DAEMON="core drivers protocol report turncal"
declare -A ALLOWED=(
  [core]="core turncal"
  [drivers]="core drivers turncal"
  [protocol]="core drivers protocol turncal"
  [report]="core drivers protocol report turncal"
  [sim]="core drivers protocol sim turncal"
  [daemon/state]="$BELOW_DAEMON daemon/state"
  [daemon/station]="$BELOW_DAEMON daemon/state daemon/station"
  [daemon/device]="$BELOW_DAEMON daemon/device"
  [daemon/device_write]="$BELOW_DAEMON daemon/state daemon/station daemon/device daemon/device_write"
  [daemon/registry]="$BELOW_DAEMON daemon/state daemon/registry"
  [daemon/service]="$BELOW_DAEMON daemon/state daemon/station daemon/device daemon/device_write
                    daemon/registry daemon/service"
  [daemon]="$BELOW_DAEMON daemon/state daemon/station daemon/device daemon/device_write
            daemon/registry daemon/service"
  [montecarlo]="core drivers protocol report sim daemon/state daemon/station daemon/device
                daemon/device_write daemon/registry daemon/service montecarlo turncal"
  [tools]="core drivers protocol report sim daemon/state daemon/station daemon/device
           daemon/device_write daemon/registry daemon/service montecarlo tools turncal"
)
# The layer a file belongs to: the longest layer folder that holds it.
owner() {
  local rel=${2#"$1"/} best="" layer
  for layer in "${!ALLOWED[@]}"; do
    if [[ "$rel" == "$layer"/* && ${#layer} -gt ${#best} ]]; then best=$layer; fi
  done
  echo "$best"
}
check() {
  local root=$1 bad=0 layer file target allowed
  for layer in "${!ALLOWED[@]}"; do
    [ -d "$root/$layer" ] || continue
    while IFS=: read -r file target; do
      [[ "$(owner "$root" "$file")" == "$layer" ]] || continue
      allowed=$(echo ${ALLOWED[$layer]})  # one line, single spaces
      if [[ " $allowed " != *" $target "* ]]; then
        echo "layering: ${file#"$root"/} includes $target/, above or beside $layer/" >&2
        bad=$((bad + 1))
      fi
    done < <(grep -rHoE '^#include "[a-z_]+/([a-z_]+/)?' "$root/$layer" --include='*.h' \
               --include='*.cc' |
             sed -E 's/:#include "(daemon\/[a-z_]+)\/$/:\1/; s/:#include "([a-z_]+)\/([a-z_]+\/)?$/:\1/')
  done
  return $((bad > 0))
}
failures=0
if check "$ROOT"; then echo "layering: every include runs downwards"; else failures=1; fi
# The check must be able to fail: an include from core/ into daemon/ is refused.
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
mkdir -p "$scratch/core"
printf '#include "daemon/station/station.h"\n' > "$scratch/core/upward.h"
if check "$scratch" 2> /dev/null; then
  echo "layering: the check passed an include from core/ into daemon/" >&2
  failures=1
fi
echo "layering: $failures failure(s)"
exit "$failures"
