"""The reference case of the peer benchmark (issue 3) and helpers shared by the scripts.

Plant: third-order, lightly damped,

    G(s) = a * wn^2 / ((s + a) (s^2 + 2 zeta wn s + wn^2)),
    a = 2 pi 5 rad/s (real pole at 5 Hz), wn = 2 pi 40 rad/s (resonance at 40 Hz), zeta = 0.02,

unit DC gain, discretised by zero-order hold at fs = 1 kHz (the same plant as
host/benches/n4sid.rs). Log: 100,000 samples of a random binary +-1 input (white, seeded) and the
noise-free response plus white Gaussian output noise of 10 % of its standard deviation.

Everything here uses numpy/scipy only, so the data and the "true" frequency response are
independent of ferrosid.
"""
import numpy as np
import scipy.signal as sig

FS = 1000.0
TS = 1.0 / FS
N = 100_000
SEED = 20240611
A = 2 * np.pi * 5.0
WN = 2 * np.pi * 40.0
ZETA = 0.02
NOISE_REL = 0.10


def true_discrete():
    """(A, B, C, D) of the ZOH-discretised plant (scipy.signal.cont2discrete)."""
    num = [A * WN**2]
    den = np.polymul([1.0, A], [1.0, 2 * ZETA * WN, WN**2])
    ss = sig.tf2ss(num, den)
    ad, bd, cd, dd, _ = sig.cont2discrete(ss, TS, method="zoh")
    return ad, bd, cd, dd


def make_log(seed=SEED):
    """(u, y) of the benchmark log. `seed` seeds numpy's default_rng for both the input and the
    output noise; the default SEED is the reference log of results.md (bench/peers/seeds.sh draws
    other realisations of the same plant and noise level with seeds 1, 2, ...)."""
    rng = np.random.default_rng(seed)
    u = np.where(rng.random(N) < 0.5, -1.0, 1.0)
    ad, bd, cd, dd = true_discrete()
    _, y0, _ = sig.dlsim((ad, bd, cd, dd, TS), u)
    y0 = y0[:, 0]
    y = y0 + NOISE_REL * np.std(y0) * rng.standard_normal(N)
    return u, y


def freq_response(a, b, c, d, f_hz, ts=TS):
    """SISO discrete response C (zI - A)^-1 B + D at z = exp(j 2 pi f ts)."""
    a = np.atleast_2d(np.asarray(a, dtype=float))
    b = np.atleast_2d(np.asarray(b, dtype=float))
    c = np.atleast_2d(np.asarray(c, dtype=float))
    d = np.atleast_2d(np.asarray(d, dtype=float))
    n = a.shape[0]
    out = np.empty(len(f_hz), dtype=complex)
    for k, f in enumerate(f_hz):
        z = np.exp(2j * np.pi * f * ts)
        x = np.linalg.solve(z * np.eye(n) - a, b[:, :1])
        out[k] = (c[:1, :] @ x)[0, 0] + d[0, 0]
    return out


def frf_errors(model, f_hz=None):
    """Errors of a model's response against the true plant on a log grid of 400 points from
    0.1 Hz to 0.9 * Nyquist (450 Hz):
    (RMS relative, max relative, RMS relative up to 100 Hz, max |G_id - G| / max |G|).
    Relative error is |G_id - G| / |G| at each frequency; near 0.9 Nyquist the plant is ~80 dB
    below its DC gain, so there the relative error measures the noise in the estimated D."""
    if f_hz is None:
        f_hz = np.logspace(np.log10(0.1), np.log10(0.45 * FS), 400)
    g = freq_response(*true_discrete(), f_hz)
    h = freq_response(model["a"], model["b"], model["c"], model["d"], f_hz)
    rel = np.abs(h - g) / np.abs(g)
    low = f_hz <= 100.0
    return (
        float(np.sqrt(np.mean(rel**2))),
        float(np.max(rel)),
        float(np.sqrt(np.mean(rel[low] ** 2))),
        float(np.max(np.abs(h - g)) / np.max(np.abs(g))),
    )
