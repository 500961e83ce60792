//! The rational (interior-point) W_m fit against the reference Nelder–Mead fit on the same
//! envelopes: the README's benchmark case (±10 % resonance shifts, 300 bins, orders 1–3), the
//! bundled example's envelope (`examples/pipeline.toml`) and the motor-bench envelope
//! (`../shared/data/motor-bench`, skipped with a notice when absent).
//!
//! Each case checks, independently of the library: |W_m(jω_i)| >= l_m(ω_i) at every bin
//! (Horner evaluation written here), numerator and denominator Hurwitz (Routh), the mean
//! log-overbound J recomputed here no larger than the reference fit's, and bitwise-identical
//! results on a second run (determinism).
use ferrosid::io::{read_log, LogSpec};
use ferrosid::lti::{poly_mul, TransferFunction};
use ferrosid::pipeline::{run_pipeline, LoadedConfig};
use ferrosid::robust::norms::logspace;
use ferrosid::robust::uncertainty::{
    fit_uncertainty_weights, multiplicative_envelope, UncertaintyWeight, WeightFitMethod,
    WeightFitOptions,
};
use ferrosid::spectral::PeriodicAveraging;
use num_complex::Complex64;
use std::f64::consts::PI;

use crate::test_models::{horner, hurwitz};
use std::path::{Path, PathBuf};

/// J in dB recomputed here: 20·log10 of the trapezoidal-in-ln ω weighted geometric mean of
/// |W_m|/l_m, after checking the overbound at every bin.
fn checked_mean_overbound_db(w: &UncertaintyWeight, f: &[f64], l: &[f64]) -> f64 {
    assert!(hurwitz(&w.num), "zeros not in the LHP: {:?}", w.num);
    assert!(hurwitz(&w.den), "poles not in the LHP: {:?}", w.den);
    let floor = w.min_level;
    let m = f.len();
    let ln_w: Vec<f64> = f.iter().map(|f| (2.0 * PI * f).ln()).collect();
    let (mut acc, mut wsum) = (0.0, 0.0);
    for i in 0..m {
        let s = Complex64::new(0.0, 2.0 * PI * f[i]);
        let mag = (horner(&w.num, s) / horner(&w.den, s)).norm();
        let li = l[i].max(floor);
        assert!(mag >= li, "|W| = {mag:e} < l = {li:e} at {} Hz", f[i]);
        let lo = ln_w[i.saturating_sub(1)];
        let hi = ln_w[(i + 1).min(m - 1)];
        let wi = 0.5 * (hi - lo);
        acc += wi * (mag / li).ln();
        wsum += wi;
    }
    20.0 * acc / wsum / std::f64::consts::LN_10
}

/// Fits orders 1..=`order` with both methods and checks the rational fit against the
/// reference at every order. Returns (rational J, reference J) per order in dB.
fn compare(name: &str, f: &[f64], l: &[f64], order: usize, min_level: f64) -> Vec<(f64, f64)> {
    let opts = |method| WeightFitOptions {
        order,
        min_level,
        method,
        ..WeightFitOptions::default()
    };
    let new = fit_uncertainty_weights(f, l, &opts(WeightFitMethod::Rational)).expect("rational");
    let again = fit_uncertainty_weights(f, l, &opts(WeightFitMethod::Rational)).expect("rerun");
    assert_eq!(new, again, "{name}: the rational fit is not deterministic");
    let old = fit_uncertainty_weights(f, l, &opts(WeightFitMethod::NelderMead)).expect("reference");
    let mut out = Vec::new();
    for (wn, wo) in new.iter().zip(&old) {
        let jn = checked_mean_overbound_db(wn, f, l);
        let jo = checked_mean_overbound_db(wo, f, l);
        assert!(
            (jn - wn.mean_overbound_db).abs() < 1e-9,
            "{name}: reported J differs"
        );
        eprintln!(
            "{name} order {}: J rational {jn:.6} dB (worst ratio {:.4}), Nelder–Mead {jo:.6} dB \
             (worst ratio {:.4})",
            wn.order, wn.worst_overbound_ratio, wo.worst_overbound_ratio
        );
        // At least as tight: no larger mean log-overbound (1e-6 dB covers rounding only).
        assert!(
            jn <= jo + 1e-6,
            "{name} order {}: rational J {jn} dB > reference {jo} dB",
            wn.order
        );
        out.push((jn, jo));
    }
    for pair in new.windows(2) {
        assert!(pair[1].mean_overbound_db <= pair[0].mean_overbound_db + 1e-9);
    }
    out
}

/// Two-mass plant 1/(J s²) · ωr²/(s² + 2ζωr s + ωr²) at `f` (Hz).
fn two_mass_response(wr: f64, f: &[f64]) -> Vec<Complex64> {
    TransferFunction::new(
        vec![wr * wr],
        poly_mul(&[2e-3, 0.0, 0.0], &[1.0, 2.0 * 0.05 * wr, wr * wr]),
        0.0,
    )
    .and_then(|t| t.to_state_space())
    .and_then(|g| g.freq_responses_siso_hz(f))
    .expect("two-mass response")
}

#[test]
fn readme_case_resonance_shift_300_bins() {
    // The README / benches/wm_fit.rs case: ±5 %, ±10 % shifts of a 60 Hz resonance.
    let wr0 = 2.0 * PI * 60.0;
    let f = logspace(1.0, 400.0, 300);
    let g0 = two_mass_response(wr0, &f);
    let fam: Vec<Vec<Complex64>> = [0.9, 0.95, 1.05, 1.1]
        .iter()
        .map(|&r| two_mass_response(wr0 * r, &f))
        .collect();
    let l = multiplicative_envelope(&g0, &fam).expect("envelope");
    compare("README case", &f, &l, 3, 1e-3);
}

#[test]
fn bundled_example_envelope() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cfg = LoadedConfig::load(&root.join("examples/pipeline.toml")).expect("config");
    let run = run_pipeline(&cfg, &|_| {}).expect("pipeline");
    let env = run.envelope().expect("the example forms an envelope");
    let min_level = cfg.config.uncertainty.min_level;
    compare("bundled example", &env.freq_hz, &env.level, 3, min_level);
}

/// `../shared/data/motor-bench` relative to the project root (the main checkout, or a worktree
/// one level further down).
fn motor_bench_dir() -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let tried = [
        root.join("../shared/data/motor-bench"),
        root.join("../../shared/data/motor-bench"),
    ];
    let found = tried.iter().find(|d| d.exists()).cloned();
    if found.is_none() {
        eprintln!("skipping: {} not present", tried[0].display());
    }
    found
}

#[test]
fn motor_bench_envelope() {
    let Some(dir) = motor_bench_dir() else {
        return;
    };
    // Period-synchronous FRFs of the two multisine logs (motor speed / current reference).
    let frf = |file: &str| {
        let log = read_log(
            &dir.join(file),
            &LogSpec {
                inputs: vec!["iq_refx".into()],
                outputs: vec!["omega_max".into()],
                ..LogSpec::default()
            },
        )
        .expect("motor-bench log");
        PeriodicAveraging::new(2500)
            .frf_log(&log, 0, 0)
            .expect("periodic FRF")
    };
    let (a, b) = (frf("MultisineTypeA.mat"), frf("MultisineTypeB.mat"));
    // Lines excited in both logs; nominal = their mean, family = both logs.
    let mut f = Vec::new();
    let (mut g0, mut ga, mut gb) = (Vec::new(), Vec::new(), Vec::new());
    for (i, &fa) in a.freq_hz.iter().enumerate() {
        if let Some(j) = b.freq_hz.iter().position(|&fb| (fb - fa).abs() < 1e-9) {
            f.push(fa);
            g0.push(0.5 * (a.h[i] + b.h[j]));
            ga.push(a.h[i]);
            gb.push(b.h[j]);
        }
    }
    eprintln!("motor bench: {} common lines", f.len());
    assert!(f.len() >= 20, "only {} common lines", f.len());
    let l = multiplicative_envelope(&g0, &[ga, gb]).expect("envelope");
    compare("motor bench", &f, &l, 3, 1e-3);
}
