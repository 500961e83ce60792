#!/usr/bin/env bash
# Whole-process `ferrosid identify` against SLICOT's n4sid core, alternated in one session
# (issue 16, item 3). On a shared machine the load changes from minute to minute, so each
# round times every ferrosid binary given and then SLICOT, back to back, and the ratio is
# taken within a round.
#
# Usage: bench/peers/alternate.sh ROUNDS REPEATS FERROSID_BINARY [FERROSID_BINARY ...]
#
# Needs the peer log (bench/peers/work/plant3_100k.csv, made by run.sh or gen_data.py) and
# Octave with the control package (run.sh installs both). Per round and binary it prints the
# best wall and CPU time of REPEATS runs of `identify LOG --input u --output y --json`
# (process_time.py), SLICOT's best of REPEATS n4sid calls (octave_n4sid.m), the ratio
# ferrosid wall / SLICOT, and the 1-minute load average.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
work="$here/work"
log="$work/plant3_100k.csv"
rounds="${1:?rounds}"
repeats="${2:?repeats}"
shift 2
[ "$#" -ge 1 ] || { echo "usage: alternate.sh ROUNDS REPEATS FERROSID_BINARY..." >&2; exit 2; }
[ -s "$log" ] || { echo "error: $log missing (run bench/peers/gen_data.py $log)" >&2; exit 1; }
PY="${PYTHON:-python3}"
for r in $(seq 1 "$rounds"); do
  declare -A wall=()
  for bin in "$@"; do
    "$PY" "$here/process_time.py" "$bin" "$log" "$work/alt_process.json" "$repeats" 2>/dev/null
    read -r w c l < <("$PY" -c 'import json,sys; d=json.load(open(sys.argv[1]));
print(d["identify_process_best_seconds"], d["identify_process_cpu_best_seconds"], d["load_average_1min"])' \
      "$work/alt_process.json")
    wall[$bin]=$w
    printf 'round %d  %-40s wall %7.1f ms  CPU %7.1f ms  load %.2f\n' "$r" "$bin" \
      "$(echo "$w * 1000" | bc -l)" "$(echo "$c * 1000" | bc -l)" "$l"
  done
  (cd "$here" && octave --no-gui --quiet --no-window-system \
     --eval "octave_n4sid('$log', '$work/alt_octave.json', $repeats)" 2>/dev/null)
  s=$("$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]))["seconds"])' "$work/alt_octave.json")
  printf 'round %d  %-40s n4sid core %7.1f ms  load %.2f\n' "$r" "SLICOT (Octave)" \
    "$(echo "$s * 1000" | bc -l)" "$(cut -d' ' -f1 /proc/loadavg)"
  for bin in "$@"; do
    printf 'round %d  %-40s ratio to SLICOT %.2f\n' "$r" "$bin" "$(echo "${wall[$bin]} / $s" | bc -l)"
  done
  unset wall
done
