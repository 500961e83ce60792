//! Shared test helpers: seeded noise, discrete plants, and an independent f64 implementation of
//! scipy.signal.csd / welch / coherence (rustfft, not microfft), written from scipy's documented
//! conventions: periodic Hann from `get_window('hann', N)`, `detrend='constant'` per segment,
//! `scaling='density'` = 1/(fs Σw²), one-sided doubling except DC and Nyquist, `Pxy = conj(X)·Y`,
//! mean over segments starting at 0, hop, 2·hop, … while a full segment fits.
#![allow(dead_code)]

use ferrosid_firmware::rng::SplitMix64;
use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

/// Seeded Gaussian noise from the firmware's SplitMix64 (`ferrosid_firmware::rng`, the
/// workspace's one generator). Not `ferrosid_sim::rng::Rng`: that dev crate depends on the host
/// library, which these no_std-crate tests do not build.
pub struct Noise(SplitMix64);

impl Noise {
    pub fn new(seed: u64) -> Self {
        Self(SplitMix64::new(seed))
    }
    /// Standard normal (Box–Muller, one draw per call).
    pub fn gauss(&mut self) -> f64 {
        let a = 1.0 - self.0.next_f64(); // (0, 1]
        let b = self.0.next_f64();
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }
    pub fn gauss_vec(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.gauss()).collect()
    }
}

/// Direct-form IIR `y[n] = Σ b[i] x[n-i] - Σ_{i>=1} a[i] y[n-i]` (a[0] = 1), zero initial state.
pub fn lfilter(b: &[f64], a: &[f64], x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for n in 0..x.len() {
        let mut acc = 0.0;
        for (i, &bi) in b.iter().enumerate() {
            if n >= i {
                acc += bi * x[n - i];
            }
        }
        for (i, &ai) in a.iter().enumerate().skip(1) {
            if n >= i {
                acc -= ai * y[n - i];
            }
        }
        y[n] = acc;
    }
    y
}

/// Frequency response `B(z)/A(z)` at `z = e^{jω}`, ω in rad/sample.
pub fn freqz(b: &[f64], a: &[f64], w: f64) -> Complex64 {
    let ev = |c: &[f64]| {
        c.iter()
            .enumerate()
            .map(|(i, &ci)| Complex64::from_polar(ci, -w * i as f64))
            .sum::<Complex64>()
    };
    ev(b) / ev(a)
}

/// Round a f64 signal to f32 (what the firmware sees) and back, so that the reference
/// works on exactly the same numbers.
pub fn to_f32(x: &[f64]) -> Vec<f32> {
    x.iter().map(|&v| v as f32).collect()
}
pub fn widen(x: &[f32]) -> Vec<f64> {
    x.iter().map(|&v| v as f64).collect()
}

pub struct RefSpectra {
    pub suu: Vec<f64>,
    pub syy: Vec<f64>,
    pub suy: Vec<Complex64>,
    pub segments: usize,
}

impl RefSpectra {
    pub fn coherence(&self, k: usize) -> f64 {
        self.suy[k].norm_sqr() / (self.suu[k] * self.syy[k])
    }
    pub fn h1(&self, k: usize) -> Complex64 {
        self.suy[k] / self.suu[k]
    }
}

/// scipy-convention Welch cross/auto spectra in f64. `skip(start)` excludes segments.
#[allow(clippy::too_many_arguments)]
pub fn ref_csd(
    u: &[f64],
    y: &[f64],
    n: usize,
    overlap: usize,
    hann: bool,
    detrend: bool,
    fs: f64,
    skip: impl Fn(usize) -> bool,
) -> RefSpectra {
    let w: Vec<f64> = (0..n)
        .map(|i| {
            if hann {
                0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos()
            } else {
                1.0
            }
        })
        .collect();
    let s2: f64 = w.iter().map(|v| v * v).sum();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
    let hop = n - overlap;
    let nb = n / 2 + 1;
    let (mut suu, mut syy) = (vec![0.0; nb], vec![0.0; nb]);
    let mut suy = vec![Complex64::new(0.0, 0.0); nb];
    let mut segments = 0;
    let mut start = 0;
    while start + n <= u.len() {
        if !skip(start) {
            let seg = |x: &[f64]| {
                let s = &x[start..start + n];
                let m = if detrend {
                    s.iter().sum::<f64>() / n as f64
                } else {
                    0.0
                };
                let mut b: Vec<Complex64> = s
                    .iter()
                    .zip(&w)
                    .map(|(&v, &wi)| Complex64::new((v - m) * wi, 0.0))
                    .collect();
                fft.process(&mut b);
                b
            };
            let (uf, yf) = (seg(u), seg(y));
            for k in 0..nb {
                suu[k] += uf[k].norm_sqr();
                syy[k] += yf[k].norm_sqr();
                suy[k] += uf[k].conj() * yf[k];
            }
            segments += 1;
        }
        start += hop;
    }
    for k in 0..nb {
        let c = if k == 0 || k == n / 2 { 1.0 } else { 2.0 } / (fs * s2 * segments as f64);
        suu[k] *= c;
        syy[k] *= c;
        suy[k] *= c;
    }
    RefSpectra {
        suu,
        syy,
        suy,
        segments,
    }
}
