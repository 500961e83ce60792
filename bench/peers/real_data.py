"""Independent reference for the real-data tests (host/tests/cli_real_data.rs): identifies the
DaISy robot arm and CD-player arm and the motor bench with SLICOT's n4sid (GNU Octave control
package) and SIPPY's N4SID, and writes their validation fits and the motor bench's resonance /
anti-resonance to bench/peers/real_data_results.json (committed with this script).

Usage (from the repository root, with ../shared/data present):
    python3 bench/peers/real_data.py [OUT.json]

Protocol, identical for every tool (and for ferrosid in the tests):
* every data segment has its own channel means removed before use;
* the same fixed model order and i = 20 block rows (SLICOT 's' = 20, SIPPY SS_f = 20), D estimated;
* fit per output = 100 (1 - ||y - y_sim|| / ||y - mean(y)||) of the free-run simulation on the
  validation segment, from the initial state that minimises ||y - y_sim|| (linear least squares,
  computed here with numpy: y_sim = O x0 + y_zero_state);
* cases:
  - robot_arm.dat (1024 x [u y], ts = 1): order 4; "in-sample" (identify and validate on all
    samples) and "split" (identify on samples 0..700, validate on 700..1024);
  - CD_player_arm.dat (2048 x [u1 u2 y1 y2], ts = 1): order 8; in-sample and split 0..1400 /
    1400..2048;
  - motor bench: identify on MultisineTypeA.mat, validate on MultisineTypeB.mat, input iq_refx,
    output omega_max, fs = 2500 Hz; order 4.
* motor bench resonance / anti-resonance: the lightly damped (|zeta| < 0.1) pole and zero pairs
  of each model, as natural frequencies |ln z| / (2 pi ts) in Hz.
"""
import json
import os
import subprocess
import sys
import tempfile
import warnings

import numpy as np
import scipy.io as sio
import scipy.signal as sig

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
DATA = os.path.abspath(os.path.join(ROOT, "..", "shared", "data"))
BLOCK_ROWS = 20


def demean(x):
    return x - x.mean(axis=0, keepdims=True)


def simulate(a, b, c, d, u, x0):
    n = a.shape[0]
    x = np.array(x0, dtype=float).reshape(n)
    y = np.empty((u.shape[0], c.shape[0]))
    for k in range(u.shape[0]):
        y[k] = c @ x + d @ u[k]
        x = a @ x + b @ u[k]
    return y


def fit_percent(model, u, y):
    """Free-run fit per output with the least-squares initial state."""
    a, b, c, d = model
    n = a.shape[0]
    y0 = simulate(a, b, c, d, u, np.zeros(n))
    # Columns of O: response to unit initial states, zero input.
    cols = []
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1.0
        cols.append(simulate(a, b * 0, c, d * 0, u * 0, e).reshape(-1, order="F"))
    obs = np.column_stack(cols)
    x0, *_ = np.linalg.lstsq(obs, (y - y0).reshape(-1, order="F"), rcond=None)
    ys = simulate(a, b, c, d, u, x0)
    fits = []
    for i in range(y.shape[1]):
        e = np.linalg.norm(y[:, i] - ys[:, i]) / np.linalg.norm(y[:, i] - y[:, i].mean())
        fits.append(100.0 * (1.0 - e))
    return fits


def sippy_model(u, y, order, ts):
    from sippy_unipi import system_identification

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = system_identification(
            y.T, u.T, "N4SID", SS_fixed_order=order, SS_f=BLOCK_ROWS, SS_D_required=True, tsample=ts
        )
    return tuple(np.atleast_2d(np.asarray(x, dtype=float)) for x in (m.A, m.B, m.C, m.D))


def slicot_model(u, y, order, ts):
    with tempfile.TemporaryDirectory() as tmp:
        np.savetxt(os.path.join(tmp, "u.txt"), u)
        np.savetxt(os.path.join(tmp, "y.txt"), y)
        script = (
            "pkg load control; u = load('{t}/u.txt'); y = load('{t}/y.txt'); "
            "sys = n4sid(iddata(y, u, {ts}), {n}, 's', {i}); [a, b, c, d] = ssdata(sys); "
            "save('-ascii', '-double', '{t}/a.txt', 'a'); save('-ascii', '-double', '{t}/b.txt', 'b'); "
            "save('-ascii', '-double', '{t}/c.txt', 'c'); save('-ascii', '-double', '{t}/d.txt', 'd');"
        ).format(t=tmp, ts=repr(ts), n=order, i=BLOCK_ROWS)
        subprocess.run(
            ["octave", "--no-gui", "--quiet", "--no-window-system", "--eval", script],
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        n, m, p = order, u.shape[1], y.shape[1]
        a = np.loadtxt(os.path.join(tmp, "a.txt")).reshape(n, n)
        b = np.loadtxt(os.path.join(tmp, "b.txt")).reshape(n, m)
        c = np.loadtxt(os.path.join(tmp, "c.txt")).reshape(p, n)
        d = np.loadtxt(os.path.join(tmp, "d.txt")).reshape(p, m)
    return a, b, c, d


def light_pairs(roots, ts):
    """Natural frequencies (Hz) and damping of the lightly damped (|zeta| < 0.1) complex pairs
    (im > 0)."""
    out = []
    for z in roots:
        if z.imag <= 0:
            continue
        s = np.log(z) / ts
        w = abs(s)
        zeta = -s.real / w
        if abs(zeta) < 0.1:
            out.append({"freq_hz": float(w / (2 * np.pi)), "damping": float(zeta)})
    return sorted(out, key=lambda r: r["freq_hz"])


def resonances(model, ts):
    a, b, c, d = model
    poles = np.linalg.eigvals(a)
    num, _ = sig.ss2tf(a, b, c, d)
    zeros = np.roots(num[0])
    return {"poles": light_pairs(poles, ts), "zeros": light_pairs(zeros, ts)}


def daisy(name, n_in, order, split):
    raw = np.loadtxt(os.path.join(DATA, "daisy", name))
    cases = {}
    for label, est, val in [
        ("in_sample", slice(None), slice(None)),
        ("split", slice(0, split), slice(split, None)),
    ]:
        ue, ye = demean(raw[est, :n_in]), demean(raw[est, n_in:])
        uv, yv = demean(raw[val, :n_in]), demean(raw[val, n_in:])
        res = {}
        for tool, fn in [("slicot", slicot_model), ("sippy", sippy_model)]:
            m = fn(ue, ye, order, 1.0)
            res[tool] = {"fit_percent": fit_percent(m, uv, yv)}
        cases[label] = res
    return {"order": order, "split_at": split, "cases": cases}


def motor():
    def load(f):
        d = sio.loadmat(
            os.path.join(DATA, "motor-bench", f), variable_names=["iq_refx", "omega_max", "fs"]
        )
        fs = float(np.asarray(d["fs"]).ravel()[0])
        u = demean(np.asarray(d["iq_refx"], dtype=float).reshape(-1, 1))
        y = demean(np.asarray(d["omega_max"], dtype=float).reshape(-1, 1))
        return u, y, 1.0 / fs

    ue, ye, ts = load("MultisineTypeA.mat")
    uv, yv, _ = load("MultisineTypeB.mat")
    res = {}
    for tool, fn in [("slicot", slicot_model), ("sippy", sippy_model)]:
        m = fn(ue, ye, 4, ts)
        res[tool] = {"fit_percent": fit_percent(m, uv, yv), **resonances(m, ts)}
    return {"order": 4, "ts": ts, "cases": {"A_to_B": res}}


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "real_data_results.json")
    if not os.path.isdir(DATA):
        sys.exit("error: %s not found" % DATA)
    import scipy
    import sippy_unipi  # noqa: F401 (version below)
    from importlib.metadata import version

    ver = subprocess.run(
        ["octave", "--no-gui", "--quiet", "--no-window-system", "--eval",
         "pkg load control; v = pkg('list', 'control'); printf('%s %s', version(), v{1}.version)"],
        check=True, capture_output=True, text=True,
    ).stdout.split()
    results = {
        "generated_by": "bench/peers/real_data.py",
        "tools": {
            "slicot": "SLICOT IB01AD/IB01BD via GNU Octave %s control %s" % (ver[0], ver[1]),
            "sippy": "SIPPY (sippy_unipi) %s, N4SID" % version("sippy_unipi"),
            "scipy": scipy.__version__,
            "numpy": np.__version__,
        },
        "block_rows": BLOCK_ROWS,
        "robot_arm": daisy("robot_arm.dat", 1, 4, 700),
        "cd_player_arm": daisy("CD_player_arm.dat", 2, 8, 1400),
        "motor_bench": motor(),
    }
    with open(out, "w") as fh:
        json.dump(results, fh, indent=1, sort_keys=True)
        fh.write("\n")
    print(json.dumps(results, indent=1, sort_keys=True))


if __name__ == "__main__":
    main()
