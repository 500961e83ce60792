#!/usr/bin/env bash
# THE test command of ferrosid: every test, host and firmware (QEMU), in one run.
#   1. scripts/setup.sh installs what is missing (Cortex-M4F target, qemu-system-arm, llvm-size);
#   2. cargo test --workspace runs all host tests and the QEMU tests of tests/ (which build the
#      firmware images in target/qemu and run them on qemu-system-arm -machine mps2-an386);
#   3. scripts/python-setup.sh builds the Python package (python/) into target/python-venv
#      (installing maturin, numpy, pytest, dask from PyPI when missing) and runs pytest.
# Exits non-zero if setup fails or any test fails (or none ran). Arguments, if any, replace
# `--workspace` in the cargo test command line (e.g. scripts/test.sh -p ferrosid-tests) and
# skip step 3 unless FERROSID_PYTHON=1; FERROSID_PYTHON=0 skips it always.
set -uo pipefail
cd "$(dirname "$0")/.."

./scripts/setup.sh || { echo "test.sh: setup failed (see above); no test was run." >&2; exit 1; }

# No incremental cache: a fresh clone gains nothing from it and it took 1.3 GB of target/.
export CARGO_INCREMENTAL=${CARGO_INCREMENTAL:-0}

log=$(mktemp "${TMPDIR:-/tmp}/ferrosid-test.XXXXXX")
trap 'rm -f "$log"' EXIT

start=$(date +%s)
# Arguments replace the package selection, e.g. `scripts/test.sh -p ferrosid-tests`;
# without arguments every workspace crate is tested.
python=${FERROSID_PYTHON:-}
if [ $# -eq 0 ]; then set -- --workspace; python=${python:-1}; fi
cargo test --no-fail-fast "$@" 2>&1 </dev/null | tee "$log"
status=${PIPESTATUS[0]}
secs=$(( $(date +%s) - start ))

# The Python package: built on the same target/ (reusing the library just compiled), pytest.
py_status=0
py_line="python: skipped (FERROSID_PYTHON=1 to run with arguments)"
if [ "${python:-0}" = 1 ]; then
    py_start=$(date +%s)
    ./scripts/python-setup.sh 2>&1 </dev/null | tee -a "$log"
    py_status=${PIPESTATUS[0]}
    py_result=$(grep -E '^(=+ )?[0-9]+ (passed|failed|error).* in [0-9.]+s' "$log" | tail -n 1 | tr -d '=')
    py_line="python: exit status $py_status after $(( $(date +%s) - py_start )) s: ${py_result:-no pytest summary (setup failed?)}"
fi

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
echo "$py_line"
if [ "$status" -ne 0 ]; then
    echo "RESULT: FAIL"
    exit "$status"
fi
if [ "$py_status" -ne 0 ]; then
    echo "RESULT: FAIL (Python package)"
    exit "$py_status"
fi
if [ "$passed" -eq 0 ]; then
    echo "RESULT: FAIL (no test ran)"
    exit 1
fi
echo "RESULT: PASS"
