//! Shared by the spectral integration tests: a seeded Gaussian generator and an independent
//! direct-form IIR filter with its frequency response (scipy's `lfilter`/`freqz` conventions).
#![allow(dead_code)]
use std::f64::consts::PI;

use num_complex::Complex64;

/// SplitMix64 + Box–Muller: a small seeded Gaussian generator (no external RNG crate needed).
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in (0, 1).
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    /// Standard normal (one Box–Muller draw per call).
    pub fn gauss(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * PI * b).cos()
    }
    pub fn gauss_vec(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.gauss()).collect()
    }
}

/// y = B(q⁻¹)/A(q⁻¹) u from rest, direct form (scipy.signal.lfilter).
pub fn lfilter(b: &[f64], a: &[f64], u: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; u.len()];
    for n in 0..u.len() {
        let mut acc = 0.0;
        for (i, &bi) in b.iter().enumerate() {
            if n >= i {
                acc += bi * u[n - i];
            }
        }
        for (i, &ai) in a.iter().enumerate().skip(1) {
            if n >= i {
                acc -= ai * y[n - i];
            }
        }
        y[n] = acc / a[0];
    }
    y
}

/// H(e^{jw}) = B(e^{-jw}) / A(e^{-jw}), w in rad/sample.
pub fn freqz(b: &[f64], a: &[f64], w: f64) -> Complex64 {
    let z1 = Complex64::from_polar(1.0, -w);
    let poly = |c: &[f64]| {
        c.iter()
            .rev()
            .fold(Complex64::new(0.0, 0.0), |acc, &ci| acc * z1 + ci)
    };
    poly(b) / poly(a)
}
