#!/usr/bin/env python3
"""scipy reference spectra of the real DaISy logs, for host/tests/spectral_real_data.rs.

Generated with scipy 1.17.1 and numpy 2.4.6 from ../shared/data/daisy (see its README.md for
provenance; the data themselves are not copied into the repository). Run from the repository
root:  python3 host/tests/ref/scipy_daisy.py
Settings: fs = 1 (normalised), nperseg 256, scipy defaults otherwise (Hann, 50 % overlap,
detrend 'constant'). For each SISO pair: f, welch(u), welch(y), csd(u, y), coherence(u, y).
"""
import json

import numpy as np
import scipy
import scipy.signal as sig

root = "../shared/data/daisy/"
pairs = [("robot_arm.dat", 1, 2)] + [
    ("CD_player_arm.dat", i, o) for i in (1, 2) for o in (3, 4)
]
out = {"generator": "host/tests/ref/scipy_daisy.py", "scipy_version": scipy.__version__,
       "nperseg": 256, "pairs": []}
for fname, ci, co in pairs:
    d = np.loadtxt(root + fname)
    u, y = d[:, ci - 1], d[:, co - 1]
    kw = dict(fs=1.0, nperseg=256)
    f, pxx = sig.welch(u, **kw)
    _, pyy = sig.welch(y, **kw)
    _, pxy = sig.csd(u, y, **kw)
    _, cxy = sig.coherence(u, y, **kw)
    out["pairs"].append({"file": fname, "input_col": ci, "output_col": co, "n": len(u),
                         "f": f.tolist(), "pxx": pxx.tolist(), "pyy": pyy.tolist(),
                         "pxy_re": pxy.real.tolist(), "pxy_im": pxy.imag.tolist(),
                         "cxy": cxy.tolist()})
with open("host/tests/fixtures/spectral_daisy_scipy.json", "w") as fh:
    json.dump(out, fh)
print("ok")
