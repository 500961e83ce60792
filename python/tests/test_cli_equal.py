"""Python results equal the command line's JSON, byte for byte, on the bundled example
(examples/) and on the real motor bench (../shared/data/motor-bench, skipped when absent)."""
import json

import numpy as np
import pytest

import ferrosid
from conftest import shared

HIGH = "examples/data/two_mass_high.csv"
VALIDATE = "examples/data/two_mass_validate.csv"


def csv_log(path, root):
    t, u, y = np.loadtxt(root / path, delimiter=",", skiprows=1, unpack=True)
    return u, y


def test_frf_equals_cli(cli, in_root):
    code, out, err = cli("frf", HIGH, "--fs", "1000", "--input", "u", "--output", "y",
                         "--nperseg", "500", "--json")
    assert code == 0, err
    u, y = csv_log(HIGH, in_root)
    r = ferrosid.frf(u, y, fs=1000.0, name=HIGH, nperseg=500)
    assert isinstance(r, ferrosid.FrfResult)
    assert r.to_json() == out
    assert r.to_dict() == json.loads(out)
    # The typed views agree with the columns.
    e = r.estimates[0]
    assert np.array_equal(r.freq_hz(), np.asarray(e["freq_hz"]))
    assert np.allclose(np.abs(r.h())[1:], 10 ** (np.asarray(e["mag_db"][1:], float) / 20), rtol=1e-12)


def test_frf_accepts_the_file_reader_and_pandas(cli, in_root):
    code, out, _ = cli("frf", HIGH, "--json")
    log = ferrosid.Log.read(HIGH)
    assert ferrosid.frf(log).to_json() == out
    pd = pytest.importorskip("pandas")
    df = pd.read_csv(in_root / HIGH)
    r = ferrosid.frf(ferrosid.Log.from_frame(df, "u", "y", fs=log.fs, name=HIGH))
    a, b = json.loads(r.to_json()), json.loads(out)
    # Same samples (pandas parses the decimal text exactly); only the rate's origin differs.
    assert a["estimates"][0]["re"] == pytest.approx(b["estimates"][0]["re"], rel=1e-9, abs=1e-12)


def test_identify_equals_cli(cli, in_root):
    code, out, err = cli("identify", HIGH, "--fs", "1000", "--validate", VALIDATE, "--json")
    assert code in (0, 1), err
    u, y = csv_log(HIGH, in_root)
    vu, vy = csv_log(VALIDATE, in_root)
    r = ferrosid.identify(
        u, y, fs=1000.0, name=HIGH,
        validate=ferrosid.Log(vu, vy, 1000.0, name=VALIDATE),
    )
    assert r.to_json() == out
    m = r.model
    assert m.A.shape == (len(r["poles"]), len(r["poles"]))
    assert m.ts == 1e-3


def test_model_converts_to_python_control(in_root):
    control = pytest.importorskip("control", reason="python-control not installed (optional)")
    u, y = csv_log(HIGH, in_root)
    m = ferrosid.identify(u, y, fs=1000.0, order=3).model
    sys = m.to_control()
    assert sys.dt == m.ts
    back = ferrosid.Model.from_control(sys)
    assert np.array_equal(back.A, m.A) and np.array_equal(back.D, m.D)


def test_run_pipeline_equals_cli(cli, in_root, tmp_path):
    code, out, err = cli("run", "examples/pipeline.toml", "--out", tmp_path / "out", "--json")
    assert code in (0, 1), err
    run = ferrosid.run_pipeline("examples/pipeline.toml")
    assert run.to_json() == out
    assert run.all_pass == (code == 0)
    assert run.model_json() == (tmp_path / "out" / "model.json").read_text()
    html = run._repr_html_()
    assert "<svg" in html and html == (tmp_path / "out" / "report.html").read_text()
    # The stage views are sections of the same document.
    d = json.loads(out)
    assert ferrosid.receipts(run)["receipts"] == d["receipts"]
    assert ferrosid.audit(run) == d["audit"]
    assert ferrosid.fit_wm(run) == d["uncertainty_weight"]
    assert ferrosid.tune_pid(run) == d["controller"]
    assert ferrosid.gap(run) == d["gap_diagnosis"]
    header, module = run.codegen("axis1")
    assert "AXIS1" in header and "pub" in module


def test_motor_bench_identify_equals_cli(cli):
    a = shared("motor-bench/MultisineTypeA.mat")
    code, out, err = cli("identify", a, "--input", "iq_refx", "--output", "omega_max",
                         "--order", "4", "--json")
    assert code in (0, 1), err
    log = ferrosid.Log.read(a, input="iq_refx", output="omega_max")
    r = ferrosid.identify(log, order=4)
    assert r.to_json() == out
