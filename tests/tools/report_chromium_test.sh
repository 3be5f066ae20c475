#!/usr/bin/env bash
# The HTML calibration report in a real browser: `turncal sim` -> `turncald --replay --once
# --state-dir` -> `turncal report --state-dir -o`, then headless Chromium loads the file (no
# network, no script): every plot is in its DOM, and a screenshot is a non-empty PNG.
# Exit 77 (ctest: skipped) when chromium is not installed. Usage:
#   report_chromium_test.sh TURNCAL TURNCALD [KEEP_DIR]   (KEEP_DIR keeps report.html, report.png)
set -uo pipefail
turncal=$1
turncald=$2
keep=${3:-}
chromium=$(command -v chromium || command -v chromium-browser || true)
if [[ -z $chromium ]]; then
  echo "SKIP: chromium is not installed (apt-get install chromium)"
  exit 77
fi
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
die() {
  echo "FAIL: $*"
  exit 1
}
# Chromium's profile and crash files stay in the temporary folder.
browser() {
  timeout 120 "$chromium" --headless=new --no-sandbox --disable-gpu --disable-dev-shm-usage \
    --no-first-run --user-data-dir="$dir/profile" "$@" 2>> "$dir/chromium.log"
}

"$turncal" sim --protocol mip --seed 4 -o "$dir/s.tcap" > /dev/null 2>&1 || die "turncal sim"
"$turncald" --replay "$dir/s.tcap" --once --state-dir "$dir/state" 2> "$dir/turncald.log" ||
  die "turncald --replay --once --state-dir"
"$turncal" report --state-dir "$dir/state" -o "$dir/report.html" > "$dir/written.txt" ||
  die "turncal report"
report=$(head -n 1 "$dir/written.txt" | cut -f1)
[[ -s $report ]] || die "no report written"
ids=$(grep -o '<svg class="plot" id="[a-z0-9-]*"' "$report" | sed 's/.*id="//; s/"$//')
[[ -n $ids ]] || die "no plot in the report"

browser --dump-dom "file://$report" > "$dir/dom.html" || die "chromium --dump-dom: $(tail -n 5 "$dir/chromium.log")"
plots=0
for id in $ids; do
  grep -q "<svg[^>]*id=\"$id\"" "$dir/dom.html" || die "plot $id is not in the DOM"
  plots=$((plots + 1))
done
grep -q '<title id="residuals-accel13-title">' "$dir/dom.html" || die "a plot lost its <title>"

browser --window-size=1000,6000 --screenshot="$dir/report.png" "file://$report" > /dev/null ||
  die "chromium --screenshot: $(tail -n 5 "$dir/chromium.log")"
[[ -s $dir/report.png ]] || die "the screenshot is empty"
[[ $(head -c 4 "$dir/report.png" | tail -c 3) == PNG ]] || die "the screenshot is not a PNG"
png_bytes=$(stat -c %s "$dir/report.png")
if [[ -n $keep ]]; then
  mkdir -p "$keep" && cp "$report" "$dir/report.png" "$keep/"
fi
echo "report chromium: $plots plots in the DOM, $(stat -c %s "$report") byte report, $png_bytes byte screenshot"
