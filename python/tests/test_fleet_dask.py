"""The Dask fleet example (python/examples/dask_fleet.py) on a LocalCluster of two worker
processes: its summary equals `ferrosid fleet --json` on the same units (the example fleet,
with the physical two-mass fit, so distributions and outlier flags are compared too)."""
import json
import pathlib
import sys

import pytest

import ferrosid

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "examples"))
import dask_fleet  # noqa: E402


def without_out_dir(d):
    for u in d["units"]:
        u.pop("out_dir", None)
    return d


def test_dask_fleet_equals_cli(cli, in_root, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    code, out, err = cli("fleet", "examples/fleet", "--structure", "two-mass", "--known",
                         "Kt=1", "--out", tmp_path / "fleet", "--json")
    assert code == 1, err  # SN0004 (dragging bearing) fails a receipt
    want = json.loads(out)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            s = dask_fleet.run_fleet_on_dask(
                "examples/fleet", client,
                physical={"structure": "two-mass", "known": {"Kt": 1.0}},
            )
    assert isinstance(s, ferrosid.FleetSummary)
    got = s.to_dict()
    # The CLI wrote each unit's outputs (out_dir); the Dask run wrote none: compare the rest.
    assert all(u["out_dir"] is None for u in got["units"])
    assert without_out_dir(got) == without_out_dir(want)
    assert [o["serial"] for o in got["outliers"]] == ["SN0004"] * len(got["outliers"])
    assert got["outliers"], "the faulty unit is flagged"


def test_unit_errors_are_results_not_exceptions(tmp_path):
    (tmp_path / "SN1").mkdir()
    (tmp_path / "SN1" / "low.csv").write_text("t,u,y\n0,1,2\n")
    layout, serials = ferrosid.fleet_units(tmp_path)
    assert (layout, serials) == ("subdirectories", ["SN1"])
    tpl = pathlib.Path(__file__).resolve().parents[2] / "examples" / "fleet" / "pipeline.toml"
    u = ferrosid.fleet_unit(tmp_path, tpl, layout, "SN1")
    assert u["status"] == "error" and "low.csv: too few samples" in u["error"]
    s = ferrosid.fleet_summary(tpl, layout, [u])
    assert s["units_error"] == 1
    with pytest.raises(ferrosid.UsageError, match="not a fleet unit result"):
        ferrosid.fleet_summary(tpl, layout, [{"serial": "x"}])
