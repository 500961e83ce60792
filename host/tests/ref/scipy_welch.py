#!/usr/bin/env python3
"""Reference spectra for host/tests/spectral_scipy.rs.

Generated with scipy 1.17.1 and numpy 2.4.6 (Python 3.11). Run from the repository root:
    python3 host/tests/ref/scipy_welch.py
It writes host/tests/fixtures/spectral_scipy_welch.json holding the signals themselves (so the
Rust test does not depend on numpy's RNG) and, for several settings, scipy.signal's
welch(u), welch(y), csd(u, y) and coherence(u, y): f, Pxx, Pyy, Pxy (re/im), Cxy.

Signal: u = seeded Gaussian noise (numpy default_rng(20240611)) plus an offset and a slow ramp
(so the detrend options matter); y = lfilter(b, a, u) with a lightly damped second-order plant
plus 5 % white output noise. fs = 2500 Hz, 6000 samples.
"""
import json

import numpy as np
import scipy
import scipy.signal as sig

rng = np.random.default_rng(20240611)
n = 6000
fs = 2500.0
u = rng.standard_normal(n) + 0.7 + 2e-4 * np.arange(n)
# Poles at radius 0.97, angle 0.3 rad (about 119 Hz); a zero at z = -0.5.
r, th = 0.97, 0.3
a = [1.0, -2 * r * np.cos(th), r * r]
b = [0.05, 0.025]
y = sig.lfilter(b, a, u) + 0.05 * rng.standard_normal(n)

settings = [
    dict(nperseg=256, noverlap=None, window="hann", detrend="constant"),
    dict(nperseg=1000, noverlap=None, window="hann", detrend="constant"),
    dict(nperseg=1000, noverlap=250, window="boxcar", detrend=False),
    dict(nperseg=256, noverlap=0, window="hann", detrend=False),
    dict(nperseg=333, noverlap=100, window="hamming", detrend="linear"),
    dict(nperseg=257, noverlap=200, window="blackman", detrend="constant"),
    dict(nperseg=8, noverlap=None, window="boxcar", detrend="constant"),
]
cases = []
for s in settings:
    kw = dict(fs=fs, nperseg=s["nperseg"], noverlap=s["noverlap"], window=s["window"],
              detrend=s["detrend"])
    f, pxx = sig.welch(u, **kw)
    _, pyy = sig.welch(y, **kw)
    _, pxy = sig.csd(u, y, **kw)
    _, cxy = sig.coherence(u, y, **kw)
    cases.append({
        "nperseg": s["nperseg"],
        "noverlap": s["noverlap"],
        "window": s["window"],
        "detrend": s["detrend"] if s["detrend"] else "none",
        "f": f.tolist(),
        "pxx": pxx.tolist(),
        "pyy": pyy.tolist(),
        "pxy_re": pxy.real.tolist(),
        "pxy_im": pxy.imag.tolist(),
        "cxy": cxy.tolist(),
    })

out = {
    "generator": "host/tests/ref/scipy_welch.py",
    "scipy_version": scipy.__version__,
    "numpy_version": np.__version__,
    "fs": fs,
    "u": u.tolist(),
    "y": y.tolist(),
    "cases": cases,
}
with open("host/tests/fixtures/spectral_scipy_welch.json", "w") as fh:
    json.dump(out, fh)
print("wrote", len(cases), "cases")
