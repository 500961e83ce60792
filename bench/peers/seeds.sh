#!/usr/bin/env bash
# Multi-realisation accuracy study of issue 3: ferrosid N4SID vs SLICOT n4sid (Octave) on
# N_SEEDS independent logs of the reference plant (bench/peers/plant.py; seed k = 1..N_SEEDS draws
# the input and the output noise), FRF errors as in compare.py, paired statistics per metric.
# One noise realisation (results.md) cannot tell a 0.1 % difference from chance; this can.
#
# Usage: bench/peers/seeds.sh [N_SEEDS]      (default 10, at least 2)
#
# The reference log of results.md is run too and shown beside the seeds (not in the statistics).
# Writes bench/peers/seeds.md and prints it. Work files (logs, JSON) go to bench/peers/work/seeds/
# (ignored by git); logs are generated once per seed and reused. Timing is not measured (one run
# per tool and seed). SIPPY is not run (11 s per log). Needs octave + octave-control and python3
# with scipy: run bench/peers/run.sh once to install them.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
work="$here/work/seeds"
nseeds="${1:-10}"
case "$nseeds" in
  '' | *[!0-9]*) echo "error: N_SEEDS must be a positive integer, got '$nseeds'" >&2; exit 2 ;;
esac
if [ "$nseeds" -lt 2 ]; then
  echo "error: N_SEEDS must be at least 2 for paired statistics, got $nseeds" >&2
  exit 2
fi
mkdir -p "$work"
PY="${PYTHON:-python3}"

say() { printf '== %s\n' "$*" >&2; }

if ! octave --no-gui --quiet --no-window-system --eval "pkg load control" >/dev/null 2>&1; then
  echo "error: octave with the control package is not available; run bench/peers/run.sh first" \
       "(it installs octave and octave-control with apt-get)" >&2
  exit 1
fi
if ! "$PY" -c "import scipy" >/dev/null 2>&1; then
  echo "error: $PY cannot import scipy; run bench/peers/run.sh first (pip install scipy)" >&2
  exit 1
fi

say "building ferrosid (release)"
(cd "$root" && cargo build --release -q -p ferrosid --example peer_bench)
bench="${CARGO_TARGET_DIR:-$root/target}/release/examples/peer_bench"

for k in $(seq 1 "$nseeds"); do
  log="$work/plant3_seed$k.csv"
  if [ ! -s "$log" ]; then
    (cd "$here" && "$PY" gen_data.py "$log.tmp" "$k") && mv "$log.tmp" "$log"
  fi
  say "seed $k: ferrosid"
  "$bench" "$log" "$work/ferrosid_seed$k.json" 1
done

# The reference log of results.md (default seed), reported beside the seeds, not in the statistics.
ref="$work/plant3_ref.csv"
if [ ! -s "$ref" ]; then
  (cd "$here" && "$PY" gen_data.py "$ref.tmp") && mv "$ref.tmp" "$ref"
fi
say "reference log: ferrosid"
"$bench" "$ref" "$work/ferrosid_ref.json" 1

say "SLICOT (one Octave process for all logs)"
(cd "$here" && octave --no-gui --quiet --no-window-system --eval \
   "for k = 1:$nseeds, octave_n4sid(sprintf('%s/plant3_seed%d.csv', '$work', k), sprintf('%s/octave_seed%d.json', '$work', k), 1); end; octave_n4sid('$ref', '$work/octave_ref.json', 1);")

say "statistics"
(cd "$here" && "$PY" seeds.py "$work" "$nseeds" "$here/seeds.md")
