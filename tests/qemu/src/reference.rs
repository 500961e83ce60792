//! Independent references for the on-target self-test, computed in `f64` on the Cortex-M4F
//! (software double precision: slow, but a different arithmetic and a different algorithm from
//! the firmware's `f32` FFT path).
//!
//! * [`Dft`]: direct O(N²) discrete Fourier transform with a `libm` twiddle table.
//! * [`welch_reference`]: Welch auto/cross spectra with scipy's conventions (periodic Hann from
//!   `libm::cos`, constant detrend, density scaling, one-sided doubling), built on [`Dft`].
//! * [`UniformNoise`]: uniform white test signals from the firmware's SplitMix64 (the
//!   workspace's one generator; the signals are inputs, not the code under test).
//! * [`FirstOrderLag`], [`SecondOrderMode`]: discrete plants simulated in `f64`, with their
//!   analytic frequency responses.

use core::f64::consts::PI;

use ferrosid_firmware::rng::SplitMix64;

/// Complex number `(re, im)`.
pub type C64 = (f64, f64);

/// `a·b`.
pub fn cmul(a: C64, b: C64) -> C64 {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

/// `a/b` (`b ≠ 0`).
pub fn cdiv(a: C64, b: C64) -> C64 {
    let d = b.0 * b.0 + b.1 * b.1;
    ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
}

/// `|a|`.
pub fn cabs(a: C64) -> f64 {
    libm::sqrt(a.0 * a.0 + a.1 * a.1)
}

/// `e^{-jω}`.
pub fn e_minus_j(omega: f64) -> C64 {
    (libm::cos(omega), -libm::sin(omega))
}

/// Wraps an angle (rad) into `(-π, π]`.
pub fn wrap_pi(mut a: f64) -> f64 {
    while a > PI {
        a -= 2.0 * PI;
    }
    while a <= -PI {
        a += 2.0 * PI;
    }
    a
}

/// Uniform white test signals in `[-1, 1)` (variance 1/3) from the firmware's SplitMix64.
pub struct UniformNoise(SplitMix64);

impl UniformNoise {
    /// Seeded generator (any seed).
    pub fn new(seed: u32) -> Self {
        UniformNoise(SplitMix64::new(u64::from(seed)))
    }

    /// Uniform in `[-1, 1)`.
    pub fn uniform(&mut self) -> f64 {
        2.0 * self.0.next_f64() - 1.0
    }
}

/// Direct DFT of length `n <= MAX` with a twiddle table `e^{j2πm/n}` from `libm`.
pub struct Dft<const MAX: usize> {
    n: usize,
    cos: [f64; MAX],
    sin: [f64; MAX],
}

impl<const MAX: usize> Dft<MAX> {
    /// Twiddles for length `n` (clamped to `1..=MAX`).
    pub fn new(n: usize) -> Self {
        let n = n.clamp(1, MAX);
        let mut d = Dft {
            n,
            cos: [0.0; MAX],
            sin: [0.0; MAX],
        };
        for m in 0..n {
            let a = 2.0 * PI * m as f64 / n as f64;
            d.cos[m] = libm::cos(a);
            d.sin[m] = libm::sin(a);
        }
        d
    }

    /// Transform length.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True for a zero-length transform.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// `X[k] = Σ_n x[n]·e^{-j2πkn/N}` over the first `N` entries of `x` (`N = len()`).
    pub fn bin(&self, x: &[f64], k: usize) -> C64 {
        let n = self.n;
        let k = k % n;
        let (mut re, mut im) = (0.0, 0.0);
        let mut idx = 0usize;
        for &v in x.iter().take(n) {
            re += v * self.cos[idx];
            im -= v * self.sin[idx];
            idx += k;
            if idx >= n {
                idx -= n;
            }
        }
        (re, im)
    }
}

/// Window of the reference Welch estimate.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum RefWindow {
    /// Periodic Hann `0.5 - 0.5 cos(2πn/N)` (scipy `get_window('hann', N)`).
    Hann,
    /// All ones.
    Rectangular,
}

/// Welch spectra of the reference, bins `0..=N/2` (`B = N/2 + 1` entries used).
pub struct RefSpectra<const B: usize> {
    /// One-sided `S_uu` (signal²/Hz).
    pub uu: [f64; B],
    /// One-sided `S_yy` (signal²/Hz).
    pub yy: [f64; B],
    /// One-sided `S_uy = c·mean conj(U)·Y` (re, im).
    pub uy: [C64; B],
    /// Segments averaged.
    pub segments: u32,
    /// Segments skipped because they contain a NaN, ±inf or `|x| > 1e12`.
    pub skipped: u32,
}

impl<const B: usize> RefSpectra<B> {
    /// Magnitude-squared coherence at bin `k`.
    pub fn coherence(&self, k: usize) -> f64 {
        let (re, im) = self.uy[k];
        (re * re + im * im) / (self.uu[k] * self.yy[k])
    }
}

/// Welch estimate of `u`, `y` with segment length `N` (`B = N/2 + 1`, `N <= MAX`), hop `hop`,
/// segments starting at `0, hop, 2·hop, …` that fit in the record, scipy's conventions.
pub fn welch_reference<const MAX: usize, const B: usize>(
    dft: &Dft<MAX>,
    u: &[f32],
    y: &[f32],
    hop: usize,
    window: RefWindow,
    detrend_mean: bool,
    fs_hz: f64,
) -> RefSpectra<B> {
    let n = dft.len();
    let mut out = RefSpectra {
        uu: [0.0; B],
        yy: [0.0; B],
        uy: [(0.0, 0.0); B],
        segments: 0,
        skipped: 0,
    };
    let mut w = [0.0f64; MAX];
    let mut s2 = 0.0;
    for (i, wi) in w.iter_mut().enumerate().take(n) {
        *wi = match window {
            RefWindow::Hann => 0.5 - 0.5 * libm::cos(2.0 * PI * i as f64 / n as f64),
            RefWindow::Rectangular => 1.0,
        };
        s2 += *wi * *wi;
    }
    let mut su = [0.0f64; MAX];
    let mut sy = [0.0f64; MAX];
    let len = u.len().min(y.len());
    let mut start = 0;
    while start + n <= len {
        let seg_u = &u[start..start + n];
        let seg_y = &y[start..start + n];
        start += hop;
        // Negated on purpose: NaN compares false, so it counts as bad.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let bad = |x: &f32| !(x.abs() <= 1.0e12);
        if seg_u.iter().any(bad) || seg_y.iter().any(bad) {
            out.skipped += 1;
            continue;
        }
        let (mut mu, mut my) = (0.0, 0.0);
        if detrend_mean {
            mu = seg_u.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
            my = seg_y.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
        }
        for i in 0..n {
            su[i] = (seg_u[i] as f64 - mu) * w[i];
            sy[i] = (seg_y[i] as f64 - my) * w[i];
        }
        for k in 0..=n / 2 {
            let uk = dft.bin(&su[..n], k);
            let yk = dft.bin(&sy[..n], k);
            out.uu[k] += uk.0 * uk.0 + uk.1 * uk.1;
            out.yy[k] += yk.0 * yk.0 + yk.1 * yk.1;
            // conj(U)·Y
            out.uy[k].0 += uk.0 * yk.0 + uk.1 * yk.1;
            out.uy[k].1 += uk.0 * yk.1 - uk.1 * yk.0;
        }
        out.segments += 1;
    }
    if out.segments > 0 {
        for k in 0..=n / 2 {
            let one_sided = if k == 0 || k == n / 2 { 1.0 } else { 2.0 };
            let c = one_sided / (fs_hz * s2 * out.segments as f64);
            out.uu[k] *= c;
            out.yy[k] *= c;
            out.uy[k].0 *= c;
            out.uy[k].1 *= c;
        }
    }
    out
}

/// First-order lag `y[n] = a·y[n-1] + (1 - a)·u[n]` (unit DC gain), simulated in `f64`.
pub struct FirstOrderLag {
    /// Pole `a` (`|a| < 1`).
    pub a: f64,
    y: f64,
}

impl FirstOrderLag {
    /// Plant at rest with pole `a`.
    pub fn new(a: f64) -> Self {
        FirstOrderLag { a, y: 0.0 }
    }
    /// One step.
    pub fn step(&mut self, u: f64) -> f64 {
        self.y = self.a * self.y + (1.0 - self.a) * u;
        self.y
    }
    /// `H(e^{jω}) = (1 - a) / (1 - a·e^{-jω})`, `ω = 2πf/fs` (rad/sample).
    pub fn response(&self, omega: f64) -> C64 {
        let z1 = e_minus_j(omega);
        cdiv((1.0 - self.a, 0.0), (1.0 - self.a * z1.0, -self.a * z1.1))
    }
}

/// Lightly damped second-order mode: poles `r·e^{±jθ}`,
/// `y[n] = 2r cosθ·y[n-1] - r²·y[n-2] + b0·u[n]` with `b0 = 1 - 2r cosθ + r²` (unit DC gain),
/// simulated in `f64`.
pub struct SecondOrderMode {
    a1: f64,
    a2: f64,
    b0: f64,
    y1: f64,
    y2: f64,
}

impl SecondOrderMode {
    /// Mode at rest with pole radius `r` and pole angle `theta` (rad/sample).
    pub fn new(r: f64, theta: f64) -> Self {
        let a1 = 2.0 * r * libm::cos(theta);
        let a2 = -r * r;
        SecondOrderMode {
            a1,
            a2,
            b0: 1.0 - a1 - a2,
            y1: 0.0,
            y2: 0.0,
        }
    }
    /// One step.
    pub fn step(&mut self, u: f64) -> f64 {
        let y = self.a1 * self.y1 + self.a2 * self.y2 + self.b0 * u;
        self.y2 = self.y1;
        self.y1 = y;
        y
    }
    /// `H(e^{jω}) = b0 / (1 - a1·e^{-jω} - a2·e^{-2jω})`, `ω` in rad/sample.
    pub fn response(&self, omega: f64) -> C64 {
        let z1 = e_minus_j(omega);
        let z2 = e_minus_j(2.0 * omega);
        let den = (
            1.0 - self.a1 * z1.0 - self.a2 * z2.0,
            -self.a1 * z1.1 - self.a2 * z2.1,
        );
        cdiv((self.b0, 0.0), den)
    }
}
