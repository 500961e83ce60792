"""README "Python": the quick start runs as written (in a scratch directory that sees the
repository's examples/), and what its comments claim holds."""
import os
import re

import ferrosid
from conftest import ROOT


def quick_start() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("\n## Python\n"):]
    section = section[: section.index("\n## ", 1)]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert blocks, "README's Python section has no python block"
    return blocks[0]


def test_quick_start_runs_as_written(tmp_path, monkeypatch):
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(quick_start(), "README.md (Python quick start)", "exec"), ns)
    run, a, wm, pid, g = (ns[k] for k in ("run", "a", "wm", "pid", "g"))
    d = run.to_dict()
    # The comments' claims: the array-level stages equal the pipeline's sections.
    assert a.verdict == "linear_enough" and a.to_dict() == d["audit"]
    assert g.verdict == "coulomb_friction" == d["gap_diagnosis"]["report"]["verdict"]
    assert wm.to_dict()["num"] == d["uncertainty_weight"]["num"]
    assert pid.crossover_hz == d["controller"]["design"]["crossover_hz"]
    assert "operating_point" in ns["model"].data
    assert (tmp_path / "out" / "receipts.json").is_file()
    assert "AXIS1" in ns["header"]
    assert isinstance(ns["r"], ferrosid.FrfResult) and os.getcwd() == str(tmp_path)
