//! Shared by the spectral integration tests: a seeded Gaussian generator and an independent
//! direct-form IIR filter with its frequency response (scipy's `lfilter`/`freqz` conventions).
#![allow(dead_code)]

use num_complex::Complex64;

/// The workspace's seeded generator (`ferrosid_sim::rng`: the firmware's SplitMix64, Box–Muller
/// normals).
pub use ferrosid_sim::rng::Rng;

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
