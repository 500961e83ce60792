#!/usr/bin/env bash
# Builds the Python package (python/, PyO3 + maturin, abi3) into a virtual environment under
# target/ and runs its tests (pytest: python/tests), idempotently. Called by scripts/test.sh.
#
#   1. target/python-venv: created with `python3 -m venv` if missing (Python >= 3.11);
#   2. maturin, numpy, pytest, dask[distributed] (pandas when available) from PyPI with pip,
#      only when one is missing (no network otherwise);
#   3. the wheel: `maturin build --profile dev` of python/ (a workspace of its own, see
#      python/Cargo.toml) into the shared target/, so after the first build only what changed
#      is compiled — then `pip install` of that wheel into the venv (replacing the previous
#      one; nothing is written into the source tree);
#   4. pytest python/tests (the tests that compare with the CLI use target/debug/ferrosid).
#
# Usage: scripts/python-setup.sh [--no-test] [PYTEST ARGS...]
# Environment: PYTHON (interpreter for the venv, default python3).
# Exit status: 0 when everything installed and every test passed; 1 otherwise, with what to do.
set -euo pipefail
cd "$(dirname "$0")/.."

say() { printf 'python-setup: %s\n' "$*"; }
fail() { printf 'python-setup: ERROR: %s\n' "$*" >&2; exit 1; }

run_tests=1
if [ "${1:-}" = "--no-test" ]; then run_tests=0; shift; fi

PY=${PYTHON:-python3}
VENV=target/python-venv
command -v "$PY" >/dev/null 2>&1 || fail "$PY not found: install Python >= 3.11 (with pip and venv) or set PYTHON."
"$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' \
    || fail "$("$PY" --version 2>&1) is too old: the package needs Python >= 3.11 (set PYTHON)."

if [ ! -x "$VENV/bin/python" ]; then
    say "creating the virtual environment $VENV"
    "$PY" -m venv "$VENV" \
        || fail "'$PY -m venv $VENV' failed (its error is above): if the venv module is missing, install it (Debian: apt-get install python3-venv)."
fi
VPY="$VENV/bin/python"

# Install what is missing, nothing else (a warm machine touches no network).
missing=()
"$VPY" -c 'import maturin' >/dev/null 2>&1 || missing+=("maturin>=1.7,<2")
"$VPY" -c 'import numpy' >/dev/null 2>&1 || missing+=("numpy>=1.24")
"$VPY" -c 'import pytest' >/dev/null 2>&1 || missing+=("pytest")
"$VPY" -c 'import dask.distributed' >/dev/null 2>&1 || missing+=("dask[distributed]")
if [ ${#missing[@]} -gt 0 ]; then
    say "installing from PyPI: ${missing[*]}"
    "$VPY" -m pip install --quiet --disable-pip-version-check "${missing[@]}" \
        || fail "pip could not install ${missing[*]} (no network, or PyPI unreachable?). Install them into $VENV by hand: $VPY -m pip install ${missing[*]}"
fi
# pandas is optional (the pandas tests skip without it); try once, never fail on it.
if ! "$VPY" -c 'import pandas' >/dev/null 2>&1; then
    "$VPY" -m pip install --quiet --disable-pip-version-check pandas >/dev/null 2>&1 \
        || say "pandas not installed (optional; its tests will be skipped)"
fi

say "building the extension (maturin, dev profile, shared target/)"
export CARGO_TARGET_DIR="$PWD/target"
rm -rf target/python-wheels
"$VENV/bin/maturin" build --quiet --profile dev --compatibility linux \
        --manifest-path python/Cargo.toml --interpreter "$VPY" --out target/python-wheels \
    || fail "maturin build failed (see the compiler output above)."
wheel=$(ls target/python-wheels/ferrosid-*.whl 2>/dev/null | head -n 1)
[ -n "$wheel" ] || fail "maturin produced no wheel in target/python-wheels."
"$VPY" -m pip install --quiet --disable-pip-version-check --no-deps --force-reinstall "$wheel" \
    || fail "pip could not install $wheel."
"$VPY" -c 'import ferrosid; print("python-setup: ferrosid", ferrosid.__version__, "from", ferrosid.__file__)' \
    || fail "the installed package does not import."

if [ "$run_tests" -eq 1 ]; then
    # The comparisons with the command line need the CLI of the same tree.
    cargo build --quiet -p ferrosid --bin ferrosid || fail "cargo build of the ferrosid CLI failed."
    export FERROSID_CLI="$PWD/target/debug/ferrosid"
    say "pytest python/tests"
    # From the repository root: python/ferrosid (sources without the compiled module) must
    # not shadow the installed package; no .pytest_cache in the tree.
    "$VPY" -m pytest -q -ra -p no:cacheprovider python/tests "$@" || fail "Python tests failed (see above)."
fi
