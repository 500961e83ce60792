"""Python peers of the benchmark: scipy.signal Welch/CSD/coherence and SIPPY's N4SID.

Usage: python3 bench/peers/python_peers.py LOG.csv OUT.json [REPEATS]

Timings are the best of REPEATS wall-clock runs (time.perf_counter) inside this process, so
interpreter start-up and file reading are excluded.

* scipy (standard API): welch(u), welch(y), csd(u, y) with nperseg 1024, Hann, 50 % overlap,
  constant detrend (the defaults), then H1 = Puy / Puu and coherence |Puy|^2 / (Puu Pyy) —
  what scipy.signal.coherence does internally, plus the H1 division.
* numpy (one pass): the same estimate with the segments of u and y framed once (stride tricks),
  detrended, windowed and transformed by one batched rfft each: what an expert would write.
* SIPPY: system_identification(y, u, 'N4SID', SS_fixed_order=3, SS_f=20, SS_D_required=True)
  (the future horizon f plays the role of the i = 20 block rows; D estimated as in ferrosid and
  SLICOT).
"""
import json
import sys
import time
import warnings

import numpy as np
import scipy
import scipy.signal as sig

NPERSEG = 1024


def best_of(repeats, fn):
    best, out = np.inf, None
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def scipy_welch(u, y, fs):
    f, puu = sig.welch(u, fs, nperseg=NPERSEG)
    _, pyy = sig.welch(y, fs, nperseg=NPERSEG)
    _, puy = sig.csd(u, y, fs, nperseg=NPERSEG)
    h = puy / puu
    coh = np.abs(puy) ** 2 / (puu * pyy)
    return f, h, coh


def numpy_welch(u, y, fs):
    step = NPERSEG // 2
    nseg = (len(u) - NPERSEG) // step + 1
    win = sig.get_window("hann", NPERSEG)
    idx = np.arange(NPERSEG)[None, :] + step * np.arange(nseg)[:, None]
    su = u[idx]
    sy = y[idx]
    su = (su - su.mean(axis=1, keepdims=True)) * win
    sy = (sy - sy.mean(axis=1, keepdims=True)) * win
    fu = np.fft.rfft(su, axis=1)
    fy = np.fft.rfft(sy, axis=1)
    puu = np.mean(np.abs(fu) ** 2, axis=0)
    pyy = np.mean(np.abs(fy) ** 2, axis=0)
    puy = np.mean(np.conj(fu) * fy, axis=0)
    h = puy / puu
    coh = np.abs(puy) ** 2 / (puu * pyy)
    return np.fft.rfftfreq(NPERSEG, 1.0 / fs), h, coh


def main():
    log, out = sys.argv[1], sys.argv[2]
    repeats = int(sys.argv[3]) if len(sys.argv) > 3 else 5
    data = np.loadtxt(log, delimiter=",", skiprows=1)
    t, u, y = data[:, 0], data[:, 1], data[:, 2]
    ts = (t[-1] - t[0]) / (len(t) - 1)
    fs = 1.0 / ts

    t_scipy, (f, h, coh) = best_of(4 * repeats, lambda: scipy_welch(u, y, fs))
    t_numpy, (_, h2, coh2) = best_of(4 * repeats, lambda: numpy_welch(u, y, fs))

    from sippy_unipi import system_identification

    def sippy_run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return system_identification(
                y, u, "N4SID", SS_fixed_order=3, SS_f=20, SS_D_required=True, tsample=ts
            )

    t_sippy, m = best_of(repeats, sippy_run)
    try:
        from importlib.metadata import version

        sippy_version = version("sippy_unipi")
    except Exception:  # pragma: no cover - metadata missing
        sippy_version = "unknown"
    res = {
        "repeats": repeats,
        "scipy_version": scipy.__version__,
        "numpy_version": np.__version__,
        "sippy_version": sippy_version,
        "scipy_welch_seconds": t_scipy,
        "numpy_welch_seconds": t_numpy,
        "sippy_n4sid_seconds": t_sippy,
        "welch": {
            "freq_hz": f.tolist(),
            "h_re": h.real.tolist(),
            "h_im": h.imag.tolist(),
            "coherence": coh.tolist(),
        },
        "numpy_welch_max_rel_diff_vs_scipy": float(
            max(np.max(np.abs(h2[1:] - h[1:]) / np.abs(h[1:])), np.max(np.abs(coh2 - coh)))
        ),
        "sippy_model": {
            "a": np.asarray(m.A).tolist(),
            "b": np.asarray(m.B).tolist(),
            "c": np.asarray(m.C).tolist(),
            "d": np.asarray(m.D).tolist(),
            "ts": ts,
        },
    }
    with open(out, "w") as fh:
        json.dump(res, fh)
    print(
        "python: scipy welch %.5f s, numpy welch %.5f s, sippy n4sid %.4f s"
        % (t_scipy, t_numpy, t_sippy),
        file=sys.stderr,
    )


if __name__ == "__main__":
    main()
