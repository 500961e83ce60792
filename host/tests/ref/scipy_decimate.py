#!/usr/bin/env python3
"""Reference data for host/tests/preprocess_scipy.rs.

Generated with scipy 1.17.1 and numpy 2.4.6. Run from the repository root:
    python3 host/tests/ref/scipy_decimate.py
Writes host/tests/fixtures/preprocess_scipy_decimate.json with the test signal x, and for
q in (2, 3, 5, 10): scipy.signal.cheby1(8, 0.05, 0.8/q, output='sos') and
scipy.signal.decimate(x, q) (defaults: ftype='iir', zero_phase=True, i.e. sosfiltfilt), plus
scipy.signal.detrend(x, type='linear') and the fitted line's offset/slope (numpy.polyfit).
"""
import json

import numpy as np
import scipy
import scipy.signal as sig

rng = np.random.default_rng(7)
n = 2003
k = np.arange(n)
x = (rng.standard_normal(n) + 3.0 + 1e-3 * k + 2.0 * np.sin(2 * np.pi * 0.01 * k)
     + 0.5 * np.sin(2 * np.pi * 0.37 * k))
cases = []
for q in (2, 3, 5, 10):
    sos = sig.cheby1(8, 0.05, 0.8 / q, output="sos")
    y = sig.decimate(x, q)
    cases.append({"q": q, "sos": sos.tolist(), "y": y.tolist()})
slope, offset = np.polyfit(k, x, 1)
out = {
    "generator": "host/tests/ref/scipy_decimate.py",
    "scipy_version": scipy.__version__,
    "x": x.tolist(),
    "cases": cases,
    "detrend_linear": sig.detrend(x, type="linear").tolist(),
    "line_offset": offset,
    "line_slope_per_sample": slope,
}
with open("host/tests/fixtures/preprocess_scipy_decimate.json", "w") as fh:
    json.dump(out, fh)
print("ok")
