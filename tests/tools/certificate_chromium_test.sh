#!/usr/bin/env bash
# The calibration certificate end to end (docs/CERTIFICATES.md): `turncal sim` -> `turncald
# --replay --once --state-dir` -> `turncal certificate -o --pdf`. Headless Chromium prints it to
# a PDF of one or two pages and takes a screenshot that is not blank (dark text on white, counted
# pixel by pixel); `--verify` passes on the file, on every model's file and on a history
# version's, the hash can be recomputed with sed and sha256sum as the docs say, and a copy edited
# with sed fails with exit 1. Exit 77 (ctest: skipped) when chromium is not installed. Usage:
#   certificate_chromium_test.sh TURNCAL TURNCALD [KEEP_DIR]   (KEEP_DIR keeps cert.html, .pdf, .png)
set -uo pipefail
turncal=$1
turncald=$2
keep=${3:-}
# shellcheck source=shell_test_lib.sh
. "$(dirname "$0")/shell_test_lib.sh"
die() {
  echo "FAIL: $*"
  echo "certificate chromium: $((failures + 1)) failures"
  exit 1
}

"$turncal" sim --protocol mip --seed 4 -o "$dir/s.tcap" > /dev/null 2>&1 || die "turncal sim"
"$turncald" --replay "$dir/s.tcap" --once --state-dir "$dir/state" 2> "$dir/turncald.log" ||
  die "turncald --replay --once --state-dir"

# Without Chromium --pdf says so (exit 2) and the HTML is still written.
env -u TURNCAL_CHROMIUM PATH=/nonexistent "$turncal" certificate --state-dir "$dir/state" \
  --device imu --model accel13 -o "$dir/nochromium.html" --pdf "$dir/nochromium.pdf" \
  > /dev/null 2> "$dir/nochromium.err"
rc=$?
[[ $rc == 2 ]] || fail "--pdf without Chromium exited $rc, not 2"
grep -q "needs Chromium" "$dir/nochromium.err" || fail "--pdf without Chromium: $(cat "$dir/nochromium.err")"
[[ -s $dir/nochromium.html ]] || fail "--pdf without Chromium wrote no HTML"

chromium=$(command -v chromium || command -v chromium-browser || true)
if [[ -z $chromium ]]; then
  echo "SKIP: chromium is not installed (apt-get install chromium)"
  exit 77
fi
browser() {
  timeout 120 "$chromium" --headless --no-sandbox --disable-gpu --disable-dev-shm-usage \
    --disable-quic --no-first-run --disable-background-networking --disable-component-update \
    --disable-sync --user-data-dir="$dir/profile" "$@" 2>> "$dir/chromium.log"
}

cert=$dir/cert.html
"$turncal" certificate --state-dir "$dir/state" --device imu --model accel13 --station lab-2 \
  -o "$cert" --pdf "$dir/cert.pdf" > "$dir/written.txt" 2> "$dir/certificate.err" ||
  die "turncal certificate --pdf: $(cat "$dir/certificate.err")"
grep -q "lab-2-imu-accel13-v[0-9]*	sha256 [0-9a-f]\{64\}" "$dir/written.txt" ||
  fail "no certificate number and hash printed: $(cat "$dir/written.txt")"

# The PDF: a PDF, one or two A4 pages.
[[ $(head -c 5 "$dir/cert.pdf") == %PDF- ]] || die "cert.pdf is not a PDF"
pages=$(python3 -c '
import re, sys
data = open(sys.argv[1], "rb").read()
print(len(re.findall(rb"/Type\s*/Page(?![a-zA-Z])", data)))' "$dir/cert.pdf")
[[ $pages -ge 1 && $pages -le 2 ]] || fail "the PDF has $pages pages, not 1 or 2"

# The screenshot: a PNG, and not blank -- between 1 % and 25 % of its pixels dark (text, rules).
browser --window-size=900,1400 --hide-scrollbars --screenshot="$dir/cert.png" "file://$cert" \
  > /dev/null || die "chromium --screenshot: $(tail -n 5 "$dir/chromium.log")"
[[ $(head -c 4 "$dir/cert.png" | tail -c 3) == PNG ]] || die "the screenshot is not a PNG"
dark=$(python3 - "$dir/cert.png" << 'EOF'
import struct, sys, zlib
data = open(sys.argv[1], "rb").read()
pos, idat = 8, b""
while pos < len(data):
    length, kind = struct.unpack(">I4s", data[pos:pos + 8])
    body = data[pos + 8:pos + 8 + length]
    if kind == b"IHDR":
        width, height, depth, color = struct.unpack(">IIBB", body[:10])
    elif kind == b"IDAT":
        idat += body
    pos += 12 + length
assert depth == 8 and color in (2, 6), (depth, color)
bpp = 3 if color == 2 else 4
raw, stride, prev, dark = zlib.decompress(idat), width * bpp, bytearray(width * bpp), 0
for y in range(height):
    f, row = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
    for i in range(stride):
        a = row[i - bpp] if i >= bpp else 0
        b, c = prev[i], prev[i - bpp] if i >= bpp else 0
        if f == 1: row[i] = (row[i] + a) & 255
        elif f == 2: row[i] = (row[i] + b) & 255
        elif f == 3: row[i] = (row[i] + (a + b) // 2) & 255
        elif f == 4:
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            row[i] = (row[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
    dark += sum(1 for x in range(0, stride, bpp) if row[x] + row[x + 1] + row[x + 2] < 384)
    prev = row
print(f"{100.0 * dark / (width * height):.2f}")
EOF
)
python3 -c "import sys; sys.exit(0 if 1 <= float('$dark') <= 25 else 1)" ||
  fail "the screenshot is blank or black: $dark % dark pixels"

# --verify: the file as written, then the recipe of docs/CERTIFICATES.md without turncal.
"$turncal" certificate --verify "$cert" > "$dir/verify.txt" || fail "--verify: $(cat "$dir/verify.txt")"
grep -q "^verified: " "$dir/verify.txt" || fail "--verify printed: $(cat "$dir/verify.txt")"
h=$(grep -o 'turncal-certificate-sha256" content="[0-9a-f]*' "$cert" | cut -d'"' -f3)
again=$(sed "s/$h/$(printf '0%.0s' $(seq 64))/g" "$cert" | sha256sum | cut -d' ' -f1)
[[ $again == "$h" ]] || fail "sed + sha256sum gives $again, the certificate claims $h"

# An edited copy fails with exit 1: the verdict, then one digit of a parameter's value.
sed 's/>PASS</>FAIL</' "$cert" > "$dir/edited.html"
cmp -s "$cert" "$dir/edited.html" && fail "sed changed nothing"
"$turncal" certificate --verify "$dir/edited.html" > "$dir/edited.txt"
rc=$?
[[ $rc == 1 ]] || fail "--verify of an edited copy exited $rc, not 1"
grep -q "^FAILED: " "$dir/edited.txt" || fail "--verify of an edited copy printed: $(cat "$dir/edited.txt")"
# (bx's value: its first digit written twice, 38.2 -> 338.2)
sed -E 's/(<tr id="param-bx"[^>]*><td class="name">bx<\/td><td class="kind">[a-z]*<\/td><td>-?)([0-9])/\1\2\2/' \
  "$cert" > "$dir/digit.html"
cmp -s "$cert" "$dir/digit.html" && fail "the digit edit changed nothing"
"$turncal" certificate --verify "$dir/digit.html" > /dev/null
rc=$?
[[ $rc == 1 ]] || fail "--verify of a copy with one digit changed exited $rc, not 1"
# Not a certificate, or no file: exit 2.
"$turncal" certificate --verify "$dir/state/reports/imu.html" > /dev/null 2>&1
rc=$?
[[ $rc == 2 ]] || fail "--verify of a report exited $rc, not 2"
"$turncal" certificate --verify "$dir/none.html" > /dev/null 2>&1
rc=$?
[[ $rc == 2 ]] || fail "--verify of a missing file exited $rc, not 2"

# Every model: one file each, OUT.MODEL.html; and an earlier version from history/.
"$turncal" certificate --state-dir "$dir/state" --device imu -o "$dir/all.html" > /dev/null ||
  fail "certificate of every model"
for m in accel13 mag13; do
  "$turncal" certificate --verify "$dir/all.$m.html" > /dev/null || fail "all.$m.html does not verify"
done
"$turncal" certificate --state-dir "$dir/state" --device imu --model mag13 --version 1 \
  -o "$dir/v1.html" > /dev/null || fail "certificate of history version 1"
grep -q 'unknown-imu-mag13-v1' "$dir/v1.html" || fail "v1.html is not version 1's"
"$turncal" certificate --verify "$dir/v1.html" > /dev/null || fail "v1.html does not verify"
"$turncal" certificate --state-dir "$dir/state" --device imu --model mag13 --version 999 \
  -o "$dir/v999.html" > /dev/null 2>&1
rc=$?
[[ $rc == 2 ]] || fail "a version that does not exist exited $rc, not 2"

if [[ -n $keep ]]; then
  mkdir -p "$keep" && cp "$cert" "$dir/cert.pdf" "$dir/cert.png" "$keep/"
fi
echo "certificate chromium: $pages page PDF, $dark % dark pixels, $(stat -c %s "$cert") byte certificate, $failures failures"
[[ $failures == 0 ]]
