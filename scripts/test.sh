#!/usr/bin/env bash
# THE test command of ferrosid: every test, host and firmware (QEMU), in one run.
#   1. scripts/setup.sh installs what is missing (Cortex-M4F target, qemu-system-arm, llvm-size);
#   2. cargo test --workspace runs all host tests and the QEMU tests of tests/ (which build the
#      firmware images in target/qemu and run them on qemu-system-arm -machine mps2-an386).
# Exits non-zero if setup fails or any test fails (or none ran). Arguments, if any, replace
# `--workspace` in the cargo test command line (e.g. scripts/test.sh -p ferrosid-tests).
set -uo pipefail
cd "$(dirname "$0")/.."

./scripts/setup.sh || { echo "test.sh: setup failed (see above); no test was run." >&2; exit 1; }

log=$(mktemp "${TMPDIR:-/tmp}/ferrosid-test.XXXXXX")
trap 'rm -f "$log"' EXIT

start=$(date +%s)
# Arguments replace the package selection, e.g. `scripts/test.sh -p ferrosid-tests`;
# without arguments every workspace crate is tested.
if [ $# -eq 0 ]; then set -- --workspace; fi
cargo test --no-fail-fast "$@" 2>&1 </dev/null | tee "$log"
status=${PIPESTATUS[0]}
secs=$(( $(date +%s) - start ))

# Sum cargo's per-binary "test result:" lines.
read -r passed failed ignored < <(awk '
    /^test result:/ {
        for (i = 1; i <= NF; i++) {
            if ($(i+1) ~ /^passed/)  p += $i
            if ($(i+1) ~ /^failed/)  f += $i
            if ($(i+1) ~ /^ignored/) g += $i
        }
    }
    END { printf "%d %d %d\n", p, f, g }' "$log")

echo
echo "================ ferrosid test summary ================"
grep -E '^test .* \.\.\. FAILED$' "$log" | sed -e 's/^test /  FAILED: /' -e 's/ \.\.\. FAILED$//' || true
grep -E '^error(\[E[0-9]+\])?:' "$log" | sort -u | head -n 20 | sed 's/^/  /' || true
echo "cargo test $*: exit status $status after ${secs} s"
echo "summary: $passed passed, $failed failed, $ignored skipped"
if [ "$status" -ne 0 ]; then
    echo "RESULT: FAIL"
    exit "$status"
fi
if [ "$passed" -eq 0 ]; then
    echo "RESULT: FAIL (no test ran)"
    exit 1
fi
echo "RESULT: PASS"
