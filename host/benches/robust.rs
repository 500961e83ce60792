//! Robust-control core: H∞ norm by Hamiltonian bisection, W_m(s) fit, PID tuning and the full
//! receipts of a tuned loop.
//! Run: `cargo bench -p ferrosid --bench robust`.
use criterion::{criterion_group, criterion_main, Criterion};
use ferrosid::lti::{poly_mul, StateSpace, TransferFunction};
use ferrosid::robust::norms::{hinf_norm, logspace};
use ferrosid::robust::pid::{implemented_loop, tune_pid, PidTuningSpec};
use ferrosid::robust::receipts::{compute_receipts, ReceiptInputs, ReceiptLimits};
use ferrosid::robust::uncertainty::{
    fit_uncertainty_weight, multiplicative_envelope, WeightFitOptions,
};
use num_complex::Complex64;
use std::f64::consts::PI;

/// Two-mass plant 1/(J s²) · ωr²/(s² + 2ζωr s + ωr²).
fn two_mass(wr: f64) -> StateSpace {
    TransferFunction::new(
        vec![wr * wr],
        poly_mul(&[2e-3, 0.0, 0.0], &[1.0, 2.0 * 0.05 * wr, wr * wr]),
        0.0,
    )
    .and_then(|t| t.to_state_space())
    .expect("plant")
}

fn bench(c: &mut Criterion) {
    let wr0 = 2.0 * PI * 60.0;
    let plant = two_mass(wr0);
    let ts = 1e-4;
    // Envelope of ±10 % resonance shifts on 300 bins and its order-3 weight.
    let f = logspace(1.0, 400.0, 300);
    let resp = |wr: f64| -> Vec<Complex64> {
        let g = two_mass(wr);
        g.freq_responses_siso_hz(&f).expect("response")
    };
    let g0 = resp(wr0);
    let fam: Vec<Vec<Complex64>> = [0.9, 0.95, 1.05, 1.1]
        .iter()
        .map(|&r| resp(wr0 * r))
        .collect();
    let l = multiplicative_envelope(&g0, &fam).expect("envelope");
    let opts = WeightFitOptions {
        order: 3,
        ..Default::default()
    };
    let wm = fit_uncertainty_weight(&f, &l, &opts).expect("weight");
    let mut spec = PidTuningSpec::new(25.0);
    spec.weight = Some(wm.clone());
    spec.rolloff_ratio = Some((8.0, 0.7));
    spec.min_crossover_scale = 0.05;
    spec.controller_ts = Some(ts);
    let tuned = tune_pid(&plant, &spec).expect("tuning");
    let (lp, _) = implemented_loop(
        &plant,
        &tuned.pid,
        Some(ts),
        Some(tuned.design.crossover_hz),
    )
    .expect("loop");
    println!(
        "closed loop: {} states; tuned crossover {:.3} Hz, {} candidates",
        lp.t.n_states(),
        tuned.design.crossover_hz,
        tuned.candidates_evaluated
    );
    let mut g = c.benchmark_group("robust");
    g.sample_size(10);
    g.bench_function("hinf_norm_T_sampled_two_mass", |b| {
        b.iter(|| hinf_norm(&lp.t).expect("norm"))
    });
    g.bench_function("fit_weight_order3_300_bins", |b| {
        b.iter(|| fit_uncertainty_weight(&f, &l, &opts).expect("weight"))
    });
    g.bench_function("tune_pid_sampled_two_mass_with_weight", |b| {
        b.iter(|| tune_pid(&plant, &spec).expect("tuning"))
    });
    g.bench_function("receipts_sampled_two_mass", |b| {
        b.iter(|| {
            let fc = tuned.design.crossover_hz;
            let inp = ReceiptInputs {
                plant: &plant,
                pid: &tuned.pid,
                controller_ts: Some(ts),
                crossover_hz: fc,
                weight: Some(&wm),
                actuator_limit: 10.0,
                actuator_unit: "A",
                reference_amplitude: 0.01,
                etfe: None,
                cross_validation: None,
                limits: ReceiptLimits::for_crossover(fc),
                anti_windup: true,
            };
            compute_receipts(&inp).expect("receipts")
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
