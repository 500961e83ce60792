//! Welch spectra, cross-spectra and coherence against scipy.signal (welch, csd, coherence).
//! Reference: tests/fixtures/spectral_scipy_welch.json, written by tests/ref/scipy_welch.py
//! (scipy 1.17.1). Tolerance: 1e-9 relative at every bin whose reference magnitude is above
//! 1e-7 of the largest (bins at the round-off floor, e.g. DC after detrending, are skipped).
#![allow(clippy::needless_range_loop)]
use ferrosid::spectral::{Detrend, Welch, Window};
use num_complex::Complex64;
use serde::Deserialize;

use crate::scipy_spectra::WithSpectra;

#[derive(Deserialize)]
struct Case {
    nperseg: usize,
    noverlap: Option<usize>,
    window: String,
    detrend: String,
}

#[derive(Deserialize)]
struct Fixture {
    scipy_version: String,
    fs: f64,
    u: Vec<f64>,
    y: Vec<f64>,
    cases: Vec<WithSpectra<Case>>,
}

fn load() -> Fixture {
    let p = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/spectral_scipy_welch.json"
    );
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn settings(c: &Case) -> Welch {
    Welch {
        nperseg: c.nperseg,
        noverlap: c.noverlap,
        window: match c.window.as_str() {
            "hann" => Window::Hann,
            "hamming" => Window::Hamming,
            "blackman" => Window::Blackman,
            "boxcar" => Window::Rectangular,
            w => panic!("unknown window {w}"),
        },
        detrend: match c.detrend.as_str() {
            "constant" => Detrend::Constant,
            "linear" => Detrend::Linear,
            "none" => Detrend::None,
            d => panic!("unknown detrend {d}"),
        },
    }
}

/// Largest relative error over bins whose reference magnitude exceeds `floor` × the largest.
fn max_rel(ours: &[Complex64], reference: &[Complex64], floor: f64) -> (f64, usize) {
    assert_eq!(ours.len(), reference.len());
    let top = reference.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let mut worst = (0.0, 0);
    for (k, (a, b)) in ours.iter().zip(reference).enumerate() {
        if b.norm() > floor * top {
            let e = (a - b).norm() / b.norm();
            if e > worst.0 {
                worst = (e, k);
            }
        }
    }
    worst
}

fn real(v: &[f64]) -> Vec<Complex64> {
    v.iter().map(|&x| Complex64::new(x, 0.0)).collect()
}

const TOL: f64 = 1e-9;
const FLOOR: f64 = 1e-7;

#[test]
fn welch_csd_coherence_match_scipy() {
    let fx = load();
    eprintln!("reference: scipy {}", fx.scipy_version);
    for c in &fx.cases {
        let w = settings(c);
        let e = w.etfe(&fx.u, &fx.y, fx.fs).unwrap();
        let label = format!(
            "nperseg {} noverlap {:?} {} {}",
            c.nperseg, c.noverlap, c.window, c.detrend
        );
        assert_eq!(e.freq_hz.len(), c.scipy.f.len(), "{label}");
        let (ef, _) = max_rel(&real(&e.freq_hz), &real(&c.scipy.f), 0.0);
        assert!(ef < 1e-14, "{label}: frequencies {ef}");
        let (eu, ku) = max_rel(&real(&e.suu), &real(&c.scipy.pxx), FLOOR);
        let (ey, ky) = max_rel(&real(&e.syy), &real(&c.scipy.pyy), FLOOR);
        let pxy = c.scipy.pxy();
        let (ec, kc) = max_rel(&e.suy, &pxy, FLOOR);
        // Coherence: relative error where the cross-spectrum itself is above the floor.
        let top = pxy.iter().map(|z| z.norm()).fold(0.0, f64::max);
        let mut eh = 0.0f64;
        for k in 0..c.scipy.cxy.len() {
            if pxy[k].norm() > FLOOR * top && c.scipy.cxy[k] > 0.0 {
                eh = eh.max((e.coherence[k] - c.scipy.cxy[k]).abs() / c.scipy.cxy[k]);
            }
        }
        eprintln!(
            "{label}: segments {} | rel err Pxx {eu:.1e} (bin {ku}) Pyy {ey:.1e} (bin {ky}) \
             Pxy {ec:.1e} (bin {kc}) Cxy {eh:.1e}",
            e.n_averages
        );
        for (name, err) in [("Pxx", eu), ("Pyy", ey), ("Pxy", ec), ("Cxy", eh)] {
            assert!(
                err < TOL,
                "{label}: {name} relative error {err:e} > {TOL:e}"
            );
        }
        // H1 = Pxy / Pxx, as defined.
        for k in 0..e.h.len() {
            if c.scipy.pxx[k] > FLOOR * c.scipy.pxx.iter().cloned().fold(0.0, f64::max) {
                let h_ref = pxy[k] / c.scipy.pxx[k];
                assert!(
                    (e.h[k] - h_ref).norm() <= TOL * h_ref.norm().max(1e-300),
                    "{label}: H1 bin {k}"
                );
            }
        }
        // Stand-alone PSD equals the auto-spectrum of the ETFE path.
        let p = w.psd(&fx.u, fx.fs).unwrap();
        let (ep, _) = max_rel(&real(&p.density), &real(&c.scipy.pxx), FLOOR);
        assert!(ep < TOL, "{label}: psd {ep:e}");
    }
}

#[test]
fn pooled_accumulator_equals_concatenated_segments() {
    // Pooling two records = mean over all their segments. With noverlap 0 and record lengths that
    // are multiples of nperseg, that equals one record made of both.
    let fx = load();
    let w = Welch {
        noverlap: Some(0),
        ..Welch::new(200)
    };
    let (a, b) = (3000, 6000);
    let whole = w.etfe(&fx.u[..b], &fx.y[..b], fx.fs).unwrap();
    let mut acc = w.accumulator(fx.fs).unwrap();
    acc.add(&fx.u[..a], &fx.y[..a]).unwrap();
    acc.add(&fx.u[a..b], &fx.y[a..b]).unwrap();
    let pooled = acc.finish().unwrap();
    assert_eq!(pooled.n_averages, whole.n_averages);
    for k in 0..whole.h.len() {
        assert!((pooled.suy[k] - whole.suy[k]).norm() <= 1e-12 * whole.suy[k].norm().max(1e-12));
        assert!((pooled.coherence[k] - whole.coherence[k]).abs() < 1e-12);
    }
}
