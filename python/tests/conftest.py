"""Shared fixtures: the repository root (the CLI runs there with the same relative paths the
Python calls use, so file names in the reports agree) and the ferrosid CLI of this tree."""
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"
if not SHARED.is_dir():
    SHARED = pathlib.Path("/work/shared/data")


def cli_path() -> pathlib.Path:
    p = pathlib.Path(os.environ.get("FERROSID_CLI", ROOT / "target" / "debug" / "ferrosid"))
    if not p.is_file():
        pytest.fail(f"the ferrosid CLI is not built at {p}: run `cargo build -p ferrosid` first")
    return p


@pytest.fixture
def cli():
    """Runs the CLI in the repository root; returns (exit code, stdout, stderr)."""

    def run(*args):
        r = subprocess.run(
            [str(cli_path()), *map(str, args)], cwd=ROOT, capture_output=True, text=True
        )
        return r.returncode, r.stdout, r.stderr

    return run


@pytest.fixture
def in_root(monkeypatch):
    monkeypatch.chdir(ROOT)
    return ROOT


def shared(rel: str) -> pathlib.Path:
    p = SHARED / rel
    if not p.is_file():
        pytest.skip(f"notice: {p} not found; skipping the real-data comparison")
    return p
