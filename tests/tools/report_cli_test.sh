#!/usr/bin/env bash
# `turncal report --state-dir DIR -o FILE [--device D]` without a daemon: a state directory made
# by `turncald --replay CAPTURE --once --state-dir DIR` on a `turncal sim` capture gives one
# report with every plot; a second device gives one file per device (name before the
# extension); --device picks one; calibrations without their pose records take them from the
# journal; no calibrations, an unknown device and malformed JSON are refused with exit code 2
# and a message. Usage: report_cli_test.sh TURNCAL TURNCALD
set -uo pipefail
turncal=$1
turncald=$2
# shellcheck source=shell_test_lib.sh
. "$(dirname "$0")/shell_test_lib.sh"
# expect_refusal WORDS COMMAND...: exit code 2 and WORDS in the message.
expect_refusal() {
  local words=$1
  shift
  "$@" > "$dir/out.txt" 2> "$dir/err.txt"
  local rc=$?
  [[ $rc == 2 ]] || fail "$* exited $rc, not 2"
  grep -q -- "$words" "$dir/err.txt" || fail "$*: no '$words' in: $(cat "$dir/err.txt")"
}

"$turncal" sim --protocol xbus --seed 3 -o "$dir/s.tcap" > /dev/null 2>&1 || fail "turncal sim"
"$turncald" --replay "$dir/s.tcap" --once --state-dir "$dir/state" 2> "$dir/turncald.log" ||
  fail "turncald --replay --once --state-dir"
ls "$dir/state/calibrations"

# One device: FILE itself, its path printed first.
"$turncal" report --state-dir "$dir/state" -o "$dir/r.html" > "$dir/written.txt" || fail "report"
cat "$dir/written.txt"
[[ $(cut -f1 "$dir/written.txt") == "$dir/r.html" ]] || fail "the path printed is not r.html"
plots=$(grep -o '<svg class="plot" id="[a-z0-9-]*"' "$dir/r.html" | wc -l)
[[ $plots == 6 ]] || fail "$plots plots, not 6 (3 per model)"
grep -qi '<script' "$dir/r.html" && fail "a script in the report"

# The unit's drift (issue 39 item 3): `turncal registry drift --json`'s rows as a file; each
# model's section ends with its table; a file that is not that is refused.
cat > "$dir/drift.json" << 'EOF'
[{"model": "accel13", "parameter": "Sx", "calibrations": 5, "first": "2026-01-01",
  "last": "2026-09-01", "repeatability": {"value": 2e-5, "ci95": [1e-5, 6e-5]},
  "trend": {"per_month": 5e-6, "sigma_per_month": 1e-6, "resolved": true}, "tolerance": 1e-4,
  "recalibrate": {"date": "2027-03-01", "sigma_days": 30, "not_before": "2027-01-15"}}]
EOF
"$turncal" report --state-dir "$dir/state" -o "$dir/d.html" --drift "$dir/drift.json" > /dev/null ||
  fail "report --drift"
grep -q 'id="drift-accel13-Sx"' "$dir/d.html" || fail "report --drift: no drift row for Sx"
grep -q '2027-03-01 &#177; 30 d' "$dir/d.html" || fail "report --drift: no recalibration date"
echo '{"not": "drift"}' > "$dir/notdrift.json"
expect_refusal "is not .turncal registry drift SERIAL --json. output" \
  "$turncal" report --state-dir "$dir/state" -o "$dir/x.html" --drift "$dir/notdrift.json"

# Two devices: one file each; --device picks one; an unknown device is refused.
for f in "$dir"/state/calibrations/imu.*.json; do
  sed 's/"device": "imu"/"device": "imu2"/' "$f" > "${f/\/imu./\/imu2.}"
done
"$turncal" report --state-dir "$dir/state" -o "$dir/two.html" --json > "$dir/two.jsonl" ||
  fail "report of two devices"
cat "$dir/two.jsonl"
[[ -s $dir/two.imu.html && -s $dir/two.imu2.html && ! -e $dir/two.html ]] ||
  fail "two devices: not two.imu.html and two.imu2.html"
"$turncal" report --state-dir "$dir/state" -o "$dir/one.html" --device imu2 > /dev/null ||
  fail "--device imu2"
[[ -s $dir/one.html ]] || fail "--device imu2 wrote no one.html"
expect_refusal "no calibration of device 'nope'.*devices there: imu, imu2" \
  "$turncal" report --state-dir "$dir/state" -o "$dir/x.html" --device nope

# Calibrations without their records (written before they carried them): from the journal.
if command -v python3 > /dev/null; then
  python3 - "$dir/state/calibrations/imu.accel13.json" << 'EOF'
import json, sys
c = json.load(open(sys.argv[1]))
del c["provenance"]["records"]
json.dump(c, open(sys.argv[1], "w"), indent=2)
EOF
  "$turncal" report --state-dir "$dir/state" -o "$dir/j.html" --device imu 2> "$dir/j.err" \
    > /dev/null || fail "report from the journal"
  grep -q "pose records taken from the journal" "$dir/j.err" || fail "journal not used"
  grep -q 'class="missing"' "$dir/j.html" && fail "journal records not used in j.html"
fi

# Refusals.
expect_refusal "no calibrations found" "$turncal" report --state-dir "$dir/none" -o "$dir/x.html"
mkdir -p "$dir/empty/calibrations"
expect_refusal "no calibrations found" "$turncal" report --state-dir "$dir/empty" -o "$dir/x.html"
mkdir -p "$dir/bad/calibrations"
printf '{"device": "imu", "model": "accel13", "params": {' > "$dir/bad/calibrations/imu.accel13.json"
expect_refusal "is not valid JSON" "$turncal" report --state-dir "$dir/bad" -o "$dir/x.html"
printf '{"device": "imu", "model": "accel13"}' > "$dir/bad/calibrations/imu.accel13.json"
expect_refusal "'params' is missing" "$turncal" report --state-dir "$dir/bad" -o "$dir/x.html"
# A number out of range, a document filed under another device's name: refused, not a crash.
printf '{"device": "imu", "model": "accel13", "chi2": 1e400}' > "$dir/bad/calibrations/imu.accel13.json"
expect_refusal "is not valid JSON" "$turncal" report --state-dir "$dir/bad" -o "$dir/x.html"
sed 's/"device": "imu"/"device": "other"/' "$dir/state/calibrations/imu.mag13.json" \
  > "$dir/bad/calibrations/imu.accel13.json"
expect_refusal "names device 'other', but its file name says 'imu'" \
  "$turncal" report --state-dir "$dir/bad" -o "$dir/x.html"
# A journal line whose device is not a string, and provenance poses that are not objects, when the
# calibration has no records: the journal is not used; no crash (exit 0 or a refusal).
if command -v python3 > /dev/null; then
  mkdir -p "$dir/odd/calibrations"
  printf '{"device":5,"record":{}}\n' > "$dir/odd/journal.jsonl"
  python3 - "$dir/state/calibrations/imu.mag13.json" "$dir/odd/calibrations/imu.mag13.json" << 'EOF'
import json, sys
c = json.load(open(sys.argv[1]))
del c["provenance"]["records"]
c["provenance"]["poses"] = [1] + c["provenance"]["poses"][1:]
json.dump(c, open(sys.argv[2], "w"), indent=2)
EOF
  "$turncal" report --state-dir "$dir/odd" -o "$dir/odd.html" > /dev/null 2> "$dir/odd.err"
  rc=$?
  [[ $rc == 0 || $rc == 2 ]] || fail "odd journal and poses: exit $rc (a crash?): $(cat "$dir/odd.err")"
fi
expect_refusal "cannot connect\|No such file\|connect" \
  "$turncal" report --socket "$dir/no.sock" -o "$dir/x.html"
# Without -o, --state-dir or --device: the old text report from the daemon.
expect_refusal "turncal report" "$turncal" report --socket "$dir/no.sock"

echo "report cli: $failures failure(s)"
[[ $failures == 0 ]]
