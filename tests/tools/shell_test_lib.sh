# Sourced by the shell tests in tests/tools (report_cli_test.sh, certificate_chromium_test.sh):
# a temporary directory $dir, removed at exit, and `fail MESSAGE`, which prints it and counts it in
# $failures.
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
failures=0
fail() {
  echo "FAIL: $*"
  failures=$((failures + 1))
}
