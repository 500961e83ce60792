//! The W_m uncertainty-weight fit on the README's case: the envelope of ±5 % and ±10 % shifts of
//! a 60 Hz two-mass resonance on 300 log-spaced bins (1–400 Hz), order 3 (and order 2, the
//! pipeline's default), by the rational interior-point fit and by the reference Nelder–Mead fit.
//! Run: `cargo bench -p ferrosid --bench wm_fit`.
use criterion::{criterion_group, criterion_main, Criterion};
use ferrosid::lti::{poly_mul, TransferFunction};
use ferrosid::robust::norms::logspace;
use ferrosid::robust::uncertainty::{
    fit_uncertainty_weight, multiplicative_envelope, WeightFitMethod, WeightFitOptions,
};
use num_complex::Complex64;
use std::f64::consts::PI;

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

fn bench(c: &mut Criterion) {
    let wr0 = 2.0 * PI * 60.0;
    let f = logspace(1.0, 400.0, 300);
    let g0 = two_mass_response(wr0, &f);
    let fam: Vec<Vec<Complex64>> = [0.9, 0.95, 1.05, 1.1]
        .iter()
        .map(|&r| two_mass_response(wr0 * r, &f))
        .collect();
    let l = multiplicative_envelope(&g0, &fam).expect("envelope");
    let opts = |order, method| WeightFitOptions {
        order,
        method,
        ..WeightFitOptions::default()
    };
    for (name, method) in [
        ("rational", WeightFitMethod::Rational),
        ("nelder_mead", WeightFitMethod::NelderMead),
    ] {
        let w = fit_uncertainty_weight(&f, &l, &opts(3, method)).expect("weight");
        println!(
            "{name}: order 3 mean overbound {:.4} dB, worst ratio {:.3}",
            w.mean_overbound_db, w.worst_overbound_ratio
        );
    }
    let mut g = c.benchmark_group("wm_fit");
    g.sample_size(10);
    g.bench_function("rational_order3_300_bins", |b| {
        b.iter(|| fit_uncertainty_weight(&f, &l, &opts(3, WeightFitMethod::Rational)))
    });
    g.bench_function("rational_order2_300_bins", |b| {
        b.iter(|| fit_uncertainty_weight(&f, &l, &opts(2, WeightFitMethod::Rational)))
    });
    g.bench_function("nelder_mead_order3_300_bins", |b| {
        b.iter(|| fit_uncertainty_weight(&f, &l, &opts(3, WeightFitMethod::NelderMead)))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
