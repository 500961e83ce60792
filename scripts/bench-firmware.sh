#!/usr/bin/env bash
# Firmware figures for README.md: instruction counts of the streaming Welch estimator and the
# excitation generators on the emulated Cortex-M4F (qemu-system-arm -icount shift=0: SysTick
# deltas are deterministic instruction counts), and the static RAM / flash of the `sizeprobe`
# image (PRBS + Welch<1024> + coherence) from llvm-size, checked against the issue's bars.
#
# Bars (issue 33): Welch<1024> push <= 120 instructions per sample (mean) and <= 5,000 for the
# largest single push; RAM <= 24 N + 2 KiB, flash <= 32 KiB.
#
# Prints a markdown table on stdout (also saved to target/firmware-bench.md); progress and the
# raw image logs go to stderr. Exit status non-zero if an image fails, a figure is missing, or a
# figure written in docs/firmware-performance.md differs from the measured one by more than the
# noise stated beside it (the document is then stale: regenerate it from this table). A bar that
# is not met is reported in the table ("NOT met"), not as a failure.
set -euo pipefail
cd "$(dirname "$0")/.."

./scripts/setup.sh >&2
mkdir -p target
cargo run -q -p ferrosid-tests --bin ferrosid-qemu -- report </dev/null | tee target/firmware-bench.md
