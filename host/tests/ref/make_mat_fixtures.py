#!/usr/bin/env python3
"""Writes the small MATLAB v5 fixtures read by host/tests/io_mat.rs.

Generated with scipy 1.17.1 / numpy 2.4.6 (scipy.io.savemat, format='5'). Run from the repository
root:  python3 host/tests/ref/make_mat_fixtures.py

The signals are closed-form so the Rust test recomputes them independently:
  k = 0..99, u[k] = sin(0.1 k) + 0.5 cos(0.37 k), y[k] = round(1000 sin(0.05 k)) (stored int16),
  t[k] = 0.001 k (seconds), ys[k] = float32(0.25 k - 3).
Also: fs = uint16 1000 (scalar), y_short (99 samples), y_nan (NaN at 1-based sample 18),
u_const (all 2.5), mat2 (3x4 double), t_back (time going backwards at 1-based sample 51),
z (complex), name (char), st (struct), ce (cell).
"""
import numpy as np
import scipy.io

k = np.arange(100)
u = np.sin(0.1 * k) + 0.5 * np.cos(0.37 * k)
y = np.round(1000 * np.sin(0.05 * k)).astype(np.int16)
t = 0.001 * k
ys = (0.25 * k - 3).astype(np.float32)
y_nan = u.copy()
y_nan[17] = np.nan
t_back = t.copy()
t_back[50] = t_back[48]
variables = {
    "u": u.reshape(-1, 1),
    "y": y.reshape(-1, 1),
    "ys": ys.reshape(1, -1),
    "t": t.reshape(-1, 1),
    "fs": np.uint16(1000),
    "y_short": u[:99].reshape(-1, 1),
    "y_nan": y_nan.reshape(-1, 1),
    "u_const": np.full((100, 1), 2.5),
    "mat2": np.arange(12.0).reshape(3, 4),
    "t_back": t_back.reshape(-1, 1),
    "z": (u + 1j * u).reshape(-1, 1),
    "name": "motor bench",
    "st": {"a": 1.0, "b": "x"},
    "ce": np.array([[1.0, "two"]], dtype=object),
}
for compress, fname in [(True, "io_small_v5_compressed.mat"), (False, "io_small_v5_plain.mat")]:
    scipy.io.savemat(
        "host/tests/fixtures/" + fname, variables, format="5", do_compression=compress
    )
print("ok")
