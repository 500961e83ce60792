#!/usr/bin/env bash
# Runs every cargo-fuzz target in fuzz/ for SECONDS each (default 60), at the lowest CPU
# priority, seeded from the corpus kept in the repository (fuzz/corpus/<target>/: the bad
# inputs of issue 10 and a few good ones). New inputs go to fuzz/work/ (not committed).
#
#   ./scripts/fuzz.sh [SECONDS] [TARGET...]
#
# Installs cargo-fuzz when missing (idempotent). Only the stable toolchain is needed:
# RUSTC_BOOTSTRAP=1 lets stable rustc accept the sanitizer-coverage flags cargo-fuzz passes.
# A target that finds a crash, a leak or a hang (> 10 s per input) stops with the reproducer
# in fuzz/artifacts/<target>/; the script then exits 1 after running the remaining targets.
set -euo pipefail
cd "$(dirname "$0")/.."
secs="${1:-60}"
shift || true
if ! command -v cargo-fuzz >/dev/null 2>&1; then
    echo "fuzz.sh: installing cargo-fuzz"
    cargo install cargo-fuzz --locked
fi
export RUSTC_BOOTSTRAP=1
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets < <(cd fuzz && cargo fuzz list)
fi
failed=()
for t in "${targets[@]}"; do
    mkdir -p "fuzz/corpus/$t" "fuzz/work/$t"
    echo "fuzz.sh: $t for ${secs}s"
    if ! nice -n 19 cargo fuzz run "$t" "fuzz/work/$t" "fuzz/corpus/$t" -- \
        -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
        -print_final_stats=1 2>&1 | tail -n 25; then
        failed+=("$t")
    fi
done
if [ ${#failed[@]} -gt 0 ]; then
    echo "fuzz.sh: FAILED: ${failed[*]} (reproducers in fuzz/artifacts/)"
    exit 1
fi
echo "fuzz.sh: all ${#targets[@]} targets ran ${secs}s without a crash, leak or hang"
