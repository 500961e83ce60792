#!/usr/bin/env bash
# Peer benchmark of issue 3, side by side in one run:
#   ferrosid N4SID (i = 20)  vs  SLICOT n4sid via GNU Octave's control package  vs  SIPPY N4SID,
#   ferrosid Welch + coherence  vs  scipy.signal welch/csd (and a one-pass numpy version),
# on the 100,000-sample third-order lightly damped log of bench/peers/plant.py. Writes the markdown
# table to bench/peers/results.md and prints it.
#
# Usage: bench/peers/run.sh [REPEATS]      (default 5; Welch timings use 4x as many)
#
# Installs what is missing, idempotently: octave + octave-control (apt-get), scipy + sippy-unipi
# (pip; the module is `sippy_unipi`). Needs network access to Debian apt and PyPI only for what is
# not installed yet. Work files go to bench/peers/work/ (ignored by git).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
work="$here/work"
repeats="${1:-5}"
mkdir -p "$work"

say() { printf '== %s\n' "$*" >&2; }

# --- peers ---------------------------------------------------------------------------------------
have_octave_control() {
  command -v octave >/dev/null 2>&1 &&
    octave --no-gui --quiet --no-window-system --eval "pkg load control" >/dev/null 2>&1
}
if ! have_octave_control; then
  say "installing octave and octave-control (apt-get)"
  sudo_cmd=""
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then sudo_cmd="sudo"; else
      echo "error: octave-control is missing and neither root nor sudo is available;" \
           "install it with: apt-get install octave octave-control" >&2
      exit 1
    fi
  fi
  if ! { $sudo_cmd apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
         $sudo_cmd apt-get install -y -qq octave octave-control >/dev/null; }; then
    echo "error: apt-get could not install octave octave-control" >&2
    exit 1
  fi
  have_octave_control || { echo "error: octave control package still not loadable" >&2; exit 1; }
fi

PY="${PYTHON:-python3}"
if ! "$PY" -c "import scipy, sippy_unipi" >/dev/null 2>&1; then
  say "installing scipy and sippy-unipi (pip)"
  if ! "$PY" -m pip install --quiet scipy sippy-unipi; then
    echo "error: pip could not install scipy sippy-unipi" >&2
    exit 1
  fi
fi

# --- data and ferrosid ---------------------------------------------------------------------------
log="$work/plant3_100k.csv"
if [ ! -s "$log" ]; then
  say "generating the 100,000-sample log"
  (cd "$here" && "$PY" gen_data.py "$log")
fi

say "building ferrosid (release)"
(cd "$root" && cargo build --release -q -p ferrosid --example peer_bench)
target_dir="${CARGO_TARGET_DIR:-$root/target}"

# --- runs ----------------------------------------------------------------------------------------
say "ferrosid"
"$target_dir/release/examples/peer_bench" "$log" "$work/ferrosid.json" "$repeats"
say "ferrosid identify, whole process"
(cd "$root" && cargo build --release -q -p ferrosid)
"$PY" "$here/process_time.py" "$target_dir/release/ferrosid" "$log" "$work/process.json" "$repeats"
say "python (scipy, SIPPY)"
(cd "$here" && "$PY" python_peers.py "$log" "$work/python.json" "$repeats")
say "octave (SLICOT)"
(cd "$here" && octave --no-gui --quiet --no-window-system \
   --eval "octave_n4sid('$log', '$work/octave.json', $repeats)")

say "table"
(cd "$here" && "$PY" compare.py "$work" "$here/results.md")
