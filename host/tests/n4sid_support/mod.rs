//! Shared helpers of the n4sid_*/validate_* tests: a seeded RNG, excitation, known plants,
//! and a small whitespace-separated text reader for the DaISy files (the official readers
//! live in `ferrosid::io`; this one is kept independent on purpose).
#![allow(dead_code)]
use faer::Mat;
use ferrosid::lti::{poly_mul, StateSpace, TransferFunction};
use num_complex::Complex64;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

#[allow(unused_imports)] // not every test that declares this module draws noise
pub use ferrosid_sim::rng::Rng;

pub fn std_dev(x: &[f64]) -> f64 {
    let m = x.iter().sum::<f64>() / x.len() as f64;
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / x.len() as f64).sqrt()
}

/// The reference plant: G(s) = a/(s+a) · ωn²/(s² + 2ζωn s + ωn²) with a = 2π·5 rad/s,
/// ωn = 2π·40 rad/s, ζ = 0.02 (unit DC gain), continuous.
pub fn third_order_plant_tf() -> TransferFunction {
    let a = 2.0 * PI * 5.0;
    let wn = 2.0 * PI * 40.0;
    let zeta = 0.02;
    TransferFunction::new(
        vec![a * wn * wn],
        poly_mul(&[1.0, a], &[1.0, 2.0 * zeta * wn, wn * wn]),
        0.0,
    )
    .unwrap()
}

/// The reference plant discretised (ZOH) at `ts` seconds.
pub fn third_order_plant(ts: f64) -> StateSpace {
    third_order_plant_tf()
        .to_state_space()
        .unwrap()
        .c2d_zoh(ts)
        .unwrap()
}

/// Closed-form continuous frequency response of the reference plant at f Hz.
pub fn third_order_plant_response(f_hz: f64) -> Complex64 {
    let s = Complex64::new(0.0, 2.0 * PI * f_hz);
    let a = 2.0 * PI * 5.0;
    let wn = 2.0 * PI * 40.0;
    let zeta = 0.02;
    a * wn * wn / ((s + a) * (s * s + 2.0 * zeta * wn * s + wn * wn))
}

/// Max over `f_hz` of |G1 − G2| / |G2|, G2 the reference.
pub fn max_rel_error(g: &StateSpace, reference: &StateSpace, f_hz: &[f64]) -> f64 {
    let a = g.freq_responses_hz(f_hz).unwrap();
    let b = reference.freq_responses_hz(f_hz).unwrap();
    let mut worst = 0.0f64;
    for (x, y) in a.iter().zip(&b) {
        for i in 0..x.nrows() {
            for j in 0..x.ncols() {
                let e = (x[(i, j)] - y[(i, j)]).norm() / y[(i, j)].norm();
                worst = worst.max(e);
            }
        }
    }
    worst
}

/// Log-spaced frequencies.
pub fn logspace(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / (n - 1) as f64))
        .collect()
}

pub fn mat(rows: &[&[f64]]) -> Mat<f64> {
    Mat::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
}

/// `../shared/data/<rel>` relative to the repository root, if present.
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("..")
        .join("shared")
        .join("data")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("NOTICE: {} absent, test skipped", p.display());
        None
    }
}

/// Reads a whitespace-separated numeric table (DaISy .dat) into columns.
pub fn read_columns(path: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    for line in text.lines() {
        let vals: Vec<f64> = line
            .split_whitespace()
            .map(|t| t.parse::<f64>().unwrap())
            .collect();
        if vals.is_empty() {
            continue;
        }
        if cols.is_empty() {
            cols = vec![Vec::new(); vals.len()];
        }
        assert_eq!(vals.len(), cols.len(), "ragged row in {}", path.display());
        for (c, v) in cols.iter_mut().zip(vals) {
            c.push(v);
        }
    }
    cols
}

pub fn demean(x: &[f64]) -> Vec<f64> {
    let m = x.iter().sum::<f64>() / x.len() as f64;
    x.iter().map(|v| v - m).collect()
}

/// Free-run fit % = 100(1 − ‖y − ŷ‖/‖y − ȳ‖), computed here independently of `validate`.
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> f64 {
    let m = y.iter().sum::<f64>() / y.len() as f64;
    let num: f64 = y.iter().zip(yhat).map(|(a, b)| (a - b).powi(2)).sum();
    let den: f64 = y.iter().map(|a| (a - m).powi(2)).sum();
    100.0 * (1.0 - (num / den).sqrt())
}
