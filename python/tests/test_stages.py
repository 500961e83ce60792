"""The pipeline's stages on numpy arrays — audit, fit_wm, tune_pid, gap — equal the sections
`ferrosid run` writes for the same logs and settings (the bundled example,
examples/pipeline.toml), and `ferrosid gap --json`; bad inputs raise clear exceptions.

Two ways in: the logs read with the command line's reader (`Log.read`: the same samples and
sample time as the pipeline, so the sections must be equal exactly) and plain numpy arrays
from `np.loadtxt` at fs = 1000 Hz with the model from `ferrosid.identify` (the chain a
notebook user writes; equal to a stated relative tolerance, since the sample time comes from
`fs` rather than the file's time column)."""
import json
import os
import threading
import time

import numpy as np
import pytest

import ferrosid
from conftest import ROOT

LOW = "examples/data/two_mass_low.csv"
HIGH = "examples/data/two_mass_high.csv"
VAL = "examples/data/two_mass_validate.csv"
# The bundled pipeline's settings (examples/pipeline.toml).
ETFE = dict(nperseg=500, coherence_gate=0.85)
CONTROL = dict(crossover_hz=8.0, rolloff_ratio=4.0, ms_max=1.6, actuator_limit=0.3,
               reference_amplitude=5.0)


@pytest.fixture(scope="module")
def bundled():
    """(pipeline result, its receipts document, the three logs as the pipeline reads them)."""
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        run = ferrosid.run_pipeline("examples/pipeline.toml")
        logs = {k: ferrosid.Log.read(p) for k, p in (("low", LOW), ("high", HIGH), ("val", VAL))}
    finally:
        os.chdir(cwd)
    return run, run.to_dict(), logs


def arrays(path):
    t, u, y = np.loadtxt(ROOT / path, delimiter=",", skiprows=1, unpack=True)
    return u, y


def close(a, b, rel):
    """Recursive comparison of two JSON values: equal keys, strings and booleans, numbers to
    `rel` relative (absolute 1e-12 near zero)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), (a.keys(), getattr(b, "keys", None))
        for k in a:
            close(a[k], b[k], rel)
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), (a, b)
        for x, y in zip(a, b):
            close(x, y, rel)
    elif isinstance(a, float) and not isinstance(b, bool):
        assert b == pytest.approx(a, rel=rel, abs=1e-12), (a, b)
    else:
        assert a == b


def first_weight(d):
    """The weight the tuning stage used first: the pipeline replaces its `uncertainty_weight`
    by a widened one only when the compensation stage chose `widen_wm`."""
    comp = d["compensation"]
    if comp.get("status") == "decided" and comp.get("choice") == "widen_wm":
        pytest.skip("the bundled run widened W_m; its section is the re-tuned weight")
    return d["uncertainty_weight"], d["controller"]


def test_audit_equals_pipeline(bundled):
    run, d, logs = bundled
    a = ferrosid.audit(low=(logs["low"], 0.05), high=(logs["high"], 0.15),
                       crossover_hz=8.0, max_gain_shift_db=3.0, max_phase_shift_deg=15.0,
                       **ETFE)
    assert isinstance(a, ferrosid.AuditResult)
    assert a.to_dict() == d["audit"]
    assert a.verdict == d["audit"]["verdict"]
    names = {r["name"] for r in a.receipts}
    assert names == {"audit_gain_shift", "audit_phase_shift", "audit_coherence"}
    assert a.receipts == [r for r in d["receipts"] if r["name"] in names]
    # The section is what the pipeline path returns too.
    assert ferrosid.audit(run) == d["audit"]


def test_audit_thresholds_change_the_verdict(bundled):
    """The thresholds reach the library: the bundled runs' phase shift (about 13.6 deg) fails a
    10 deg limit."""
    _, d, logs = bundled
    shift = abs(d["audit"]["worst_phase_shift_deg"]["value"])
    a = ferrosid.audit(low=(logs["low"], 0.05), high=(logs["high"], 0.15), crossover_hz=8.0,
                       max_phase_shift_deg=0.5 * shift, **ETFE)
    assert a.verdict == "not_linear" and not a.linear_enough
    assert any(r["name"] == "audit_phase_shift" and not r["pass"] for r in a.receipts)


def test_fit_wm_and_tune_pid_equal_pipeline(bundled):
    run, d, logs = bundled
    want_wm, want_pid = first_weight(d)
    wm = ferrosid.fit_wm(run.model, low=(logs["low"], 0.05), high=(logs["high"], 0.15),
                         validation=logs["val"], order=2, **ETFE)
    assert isinstance(wm, ferrosid.WeightResult)
    assert wm.to_dict() == want_wm
    # |W_m| overbounds the envelope it was fitted to.
    w = wm.weight
    assert np.all(wm.magnitude(w["freq_hz"]) >= 0.999 * np.asarray(w["envelope"]))
    pid = ferrosid.tune_pid(run.model, wm, **CONTROL)
    assert isinstance(pid, ferrosid.ControllerResult)
    assert pid.to_dict() == want_pid
    assert pid.crossover_hz == want_pid["design"]["crossover_hz"]
    # Without W_m the robust-stability constraint is gone: a crossover at least as high.
    free = ferrosid.tune_pid(run.model, **CONTROL)
    assert free.crossover_hz >= pid.crossover_hz * (1 - 1e-9)


def test_gap_equals_pipeline_and_cli(bundled, cli, tmp_path):
    run, d, logs = bundled
    assert d["gap_diagnosis"]["status"] == "diagnosed"
    g = ferrosid.gap(run.model, low=logs["low"], high=logs["high"], validation=logs["val"])
    assert isinstance(g, ferrosid.GapResult)
    assert g.to_dict() == d["gap_diagnosis"]["report"]
    assert g.verdict == d["gap_diagnosis"]["report"]["verdict"]
    # `ferrosid gap` on the model.json the run writes: the same report, byte for byte.
    model = tmp_path / "model.json"
    model.write_text(run.model_json())
    code, out, err = cli("gap", "--sim", model, "--real", LOW, "--real", HIGH,
                         "--validate", VAL, "--json")
    assert code == 0, err
    assert g.to_json() == out


def test_chain_from_numpy_arrays(bundled):
    """A notebook's chain: np.loadtxt arrays at fs = 1000 Hz, the model from identify(), then
    every stage; equal to the pipeline's sections to 1e-6 relative (the pipeline takes its
    sample time from the time column, 1 ms up to the decimal text's rounding)."""
    run, d, _ = bundled
    (u1, y1), (u2, y2), (u3, y3) = arrays(LOW), arrays(HIGH), arrays(VAL)
    fs = 1000.0
    m = ferrosid.identify(u2, y2, fs=fs, no_d=True, validate=(u3, y3)).model
    assert m.A.shape == run.model.A.shape
    got_poles = np.sort_complex(np.linalg.eigvals(m.A))
    want_poles = np.sort_complex(np.linalg.eigvals(run.model.A))
    assert np.allclose(got_poles, want_poles, rtol=1e-9, atol=1e-12)
    assert m.data["operating_point"]["y0"] == pytest.approx(
        json.loads(run.model_json())["operating_point"]["y0"], rel=1e-12)

    a = ferrosid.audit(low=(u1, y1, 0.05), high=(u2, y2, 0.15), fs=fs, crossover_hz=8.0, **ETFE)
    close(d["audit"], a.to_dict(), 1e-6)

    want_wm, want_pid = first_weight(d)
    wm = ferrosid.fit_wm(m, low=(u1, y1, 0.05), high=(u2, y2, 0.15), validation=(u3, y3),
                         fs=fs, **ETFE)
    close(want_wm, wm.to_dict(), 1e-6)
    pid = ferrosid.tune_pid(m, wm, **CONTROL)
    close(want_pid, pid.to_dict(), 1e-6)


def test_gap_from_numpy_arrays(bundled):
    run, d, _ = bundled
    (u1, y1), (u2, y2), (u3, y3) = arrays(LOW), arrays(HIGH), arrays(VAL)
    m = ferrosid.identify(u2, y2, fs=1000.0, no_d=True).model
    g = ferrosid.gap(m, low=(u1, y1), high=(u2, y2), validation=(u3, y3), fs=1000.0)
    want = d["gap_diagnosis"]["report"]
    assert g.verdict == want["verdict"]
    assert g["gap_after"] == pytest.approx(want["gap_after"], rel=1e-6)


# --- bad inputs ----------------------------------------------------------------------------

U, Y = arrays(HIGH)


def test_audit_bad_inputs(bundled):
    _, _, logs = bundled
    with pytest.raises(TypeError, match="takes no model"):
        ferrosid.audit(ferrosid.Model({"a": [[0.5]], "b": [[1]], "c": [[1]], "d": [[0]],
                                       "ts": 1e-3}), low=(U, Y), high=(U, Y), fs=1e3,
                       crossover_hz=8.0)
    with pytest.raises(TypeError, match="crossover_hz"):
        ferrosid.audit(low=(U, Y), high=(U, Y), fs=1e3)
    with pytest.raises(ferrosid.UsageError, match="two or more runs") as e:
        ferrosid.audit(low=(U, Y), fs=1e3, crossover_hz=8.0)
    assert e.value.exit_code == 2
    with pytest.raises(ferrosid.UsageError, match=r"control.crossover_hz.*Nyquist"):
        ferrosid.audit(low=(U, Y), high=(U, Y), fs=1e3, crossover_hz=600.0)
    with pytest.raises(ferrosid.UsageError, match="crossover_hz"):
        ferrosid.audit(low=(U, Y), high=(U, Y), fs=1e3, crossover_hz=-1.0)
    with pytest.raises(ferrosid.UsageError, match="audit.max_gain_shift_db"):
        ferrosid.audit(low=(U, Y), high=(U, Y), fs=1e3, crossover_hz=8.0, max_gain_shift_db=0)
    with pytest.raises(ferrosid.UsageError, match="unknown variant `triangle`"):
        ferrosid.audit(low=(U, Y), high=(U, Y), fs=1e3, crossover_hz=8.0, window="triangle")
    # A misspelt option is not a run.
    with pytest.raises(TypeError, match="nperseq: expected a ferrosid.Log"):
        ferrosid.audit(low=(U, Y), high=(U, Y), fs=1e3, crossover_hz=8.0, nperseq=500)
    with pytest.raises(TypeError, match="fs"):
        ferrosid.audit(low=(U, Y), high=(U, Y), crossover_hz=8.0)
    y = Y.copy()
    y[5] = np.nan
    with pytest.raises(ferrosid.DataError, match=r"high.*`y` sample 5 .*NaN") as e:
        ferrosid.audit(low=(U, Y), high=(U, y), fs=1e3, crossover_hz=8.0)
    assert e.value.exit_code == 3
    with pytest.raises(ferrosid.DataError, match="has 9 samples"):
        ferrosid.audit(low=(U, Y), high=(U[:10], Y[:9]), fs=1e3, crossover_hz=8.0)
    with pytest.raises(ferrosid.DataError, match="sample rate"):
        ferrosid.audit(low=logs["low"], high=ferrosid.Log(U, Y, 2000.0), crossover_hz=8.0)
    with pytest.raises(ValueError, match="1-D"):
        ferrosid.audit(low=(np.stack([U, U], 1), Y), high=(U, Y), fs=1e3, crossover_hz=8.0)
    with pytest.raises(TypeError, match="dtype"):
        ferrosid.audit(low=(U.astype(str), Y), high=(U, Y), fs=1e3, crossover_hz=8.0)
    with pytest.raises(ferrosid.FerrosidError):
        ferrosid.audit(low=(U[:50], Y[:50]), high=(U[:50], Y[:50]), fs=1e3, crossover_hz=8.0,
                       nperseg=500)


def test_fit_wm_tune_pid_gap_bad_inputs(bundled):
    run, _, logs = bundled
    with pytest.raises(TypeError, match="model is required"):
        ferrosid.fit_wm(low=(U, Y), fs=1e3)
    with pytest.raises(TypeError, match="model: expected"):
        ferrosid.fit_wm(42, low=(U, Y), fs=1e3)
    with pytest.raises(ferrosid.UsageError, match=r"ts = 0.001 s but the logs .* 0.0005"):
        ferrosid.fit_wm(run.model, low=(U, Y), fs=2000.0)
    with pytest.raises(ferrosid.UsageError, match="uncertainty.order"):
        ferrosid.fit_wm(run.model, low=(U, Y), fs=1e3, order=7)
    with pytest.raises(ferrosid.UsageError, match="uncertainty.family.*`nope`"):
        ferrosid.fit_wm(run.model, low=(U, Y), fs=1e3, family=["nope"])
    with pytest.raises(ferrosid.FerrosidError, match="model"):
        ferrosid.fit_wm({"a": [[0.5, 1]], "b": [[1]], "c": [[1]], "d": [[0]], "ts": 1e-3},
                        low=(U, Y), fs=1e3)
    # Noise has no coherent bin: no weight can be formed (the pipeline's note, as an error).
    rng = np.random.default_rng(3)
    with pytest.raises(ferrosid.DataError, match="coherence gate"):
        ferrosid.fit_wm(run.model, low=(rng.standard_normal(4000), rng.standard_normal(4000)),
                        fs=1e3, nperseg=500)

    with pytest.raises(TypeError, match="actuator_limit is required"):
        ferrosid.tune_pid(run.model, crossover_hz=8.0)
    with pytest.raises(TypeError, match="WeightResult"):
        ferrosid.tune_pid(run.model, {"num": [1]}, **CONTROL)
    with pytest.raises(ferrosid.UsageError, match="control.ms_max"):
        ferrosid.tune_pid(run.model, **{**CONTROL, "ms_max": 0.9})
    with pytest.raises(ferrosid.UsageError, match=r"control.crossover_hz.*Nyquist"):
        ferrosid.tune_pid(run.model, **{**CONTROL, "crossover_hz": 900.0})
    with pytest.raises(ferrosid.UsageError, match="continuous"):
        ferrosid.tune_pid({"a": [[-1.0]], "b": [[1]], "c": [[1]], "d": [[0]], "ts": 0.0},
                          **CONTROL)
    with pytest.raises(ferrosid.NumericalError, match="no controller meets") as e:
        ferrosid.tune_pid(run.model, **{**CONTROL, "actuator_limit": 1e-9})
    assert e.value.exit_code == 4

    with pytest.raises(TypeError, match="validation"):
        ferrosid.gap(run.model, low=logs["low"])
    with pytest.raises(ferrosid.UsageError, match="unknown effect `friction`"):
        ferrosid.gap(run.model, low=logs["low"], validation=logs["val"], effects=["friction"])
    with pytest.raises(ferrosid.UsageError, match="--margin"):
        ferrosid.gap(run.model, low=logs["low"], validation=logs["val"], margin=2.0)
    with pytest.raises(ferrosid.DataError, match="not asymptotically stable"):
        ferrosid.gap({"a": [[1.5]], "b": [[1]], "c": [[1]], "d": [[0]], "ts": 1e-3},
                     low=logs["low"], validation=logs["val"])


def test_gil_is_released_during_the_stages(bundled):
    """A Python thread keeps ticking while fit_wm and tune_pid work (no timing assertion when
    the calls are too quick to tell)."""
    run, _, logs = bundled
    ticks = []
    done = threading.Event()

    def ticker():
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=ticker)
    t.start()
    t0 = time.perf_counter()
    wm = ferrosid.fit_wm(run.model, low=logs["low"], high=logs["high"],
                         validation=logs["val"], **ETFE)
    ferrosid.tune_pid(run.model, wm, **CONTROL)
    t1 = time.perf_counter()
    done.set()
    t.join()
    if t1 - t0 < 0.05:
        pytest.skip("the stages finished too quickly to observe the GIL")
    inside = [x for x in ticks if t0 < x < t1]
    assert len(inside) >= 3, (len(inside), t1 - t0)
