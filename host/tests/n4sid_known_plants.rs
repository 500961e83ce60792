//! N4SID on simulated known plants: the identified order and frequency response are compared
//! with the true plant (closed-form or exactly discretised), with stated tolerances.
mod n4sid_support;

use faer::Mat;
use ferrosid::lti::StateSpace;
use ferrosid::n4sid::{
    estimate_x0, n4sid_slices, Factorization, N4sidOptions, OrderSelection, Weighting,
};
use n4sid_support::*;

const TS: f64 = 1e-3;

/// (u, y) of the reference third-order plant, random binary input, white output noise with
/// standard deviation `noise` × std(y).
fn reference_data(n: usize, noise: f64, seed: u64) -> (Vec<f64>, Vec<f64>, StateSpace) {
    let plant = third_order_plant(TS);
    let mut rng = Rng::new(seed);
    let u = rng.binary(n);
    let y0 = plant.simulate_siso(&u, None).unwrap();
    let sd = std_dev(&y0);
    let y = y0.iter().map(|v| v + noise * sd * rng.normal()).collect();
    (u, y, plant)
}

#[test]
fn noise_free_third_order_is_recovered_exactly() {
    let (u, y, plant) = reference_data(3000, 0.0, 1);
    let r = n4sid_slices(TS, &[&u], &[&y], &N4sidOptions::default()).unwrap();
    assert_eq!(r.order, 3, "{}", r.order_reason);
    assert!(r.order_reason.contains("gap"), "{}", r.order_reason);
    let f = logspace(0.1, 490.0, 300);
    let err = max_rel_error(&r.model, &plant, &f);
    assert!(err < 1e-8, "max relative FRF error {err:.3e}");
    // The discrete model is the ZOH of the continuous plant: its d2c recovers the closed form.
    let cont = r.model.d2c_zoh().unwrap();
    for &fk in &[0.5, 10.0, 39.0, 40.0, 41.0, 200.0] {
        let g = cont.freq_response_siso(fk).unwrap();
        let exact = third_order_plant_response(fk);
        assert!((g - exact).norm() <= 1e-7 * exact.norm(), "f={fk}");
    }
}

#[test]
fn third_order_with_output_noise_picks_order_three_and_matches_the_plant() {
    // 5 % output noise (26 dB SNR), 20,000 samples.
    let (u, y, plant) = reference_data(20_000, 0.05, 2);
    let r = n4sid_slices(TS, &[&u], &[&y], &N4sidOptions::default()).unwrap();
    assert_eq!(r.order, 3, "{}", r.order_reason);
    // Within the band where the plant has gain (|G| > 0.03, up to 70 Hz): 2 %.
    let f = logspace(0.5, 70.0, 200);
    let err = max_rel_error(&r.model, &plant, &f);
    assert!(err < 0.02, "max relative FRF error {err:.3e}");
    // Resonance: continuous poles −ζωn ± jωd within 0.05 Hz and damping within 10 %.
    let cont = r.model.d2c_zoh().unwrap();
    let p = cont.poles().unwrap();
    let res = p.iter().find(|s| s.im > 0.0).expect("a complex pole pair");
    let wn = res.norm();
    let zeta = -res.re / wn;
    assert!(
        (wn / (2.0 * std::f64::consts::PI) - 40.0).abs() < 0.05,
        "fn = {}",
        wn / (2.0 * std::f64::consts::PI)
    );
    assert!((zeta - 0.02).abs() < 0.002, "ζ = {zeta}");
}

#[test]
fn cva_weighting_agrees_with_moesp() {
    let (u, y, plant) = reference_data(20_000, 0.05, 3);
    let opts = N4sidOptions {
        weighting: Weighting::Cva,
        ..Default::default()
    };
    let r = n4sid_slices(TS, &[&u], &[&y], &opts).unwrap();
    assert_eq!(r.order, 3, "{}", r.order_reason);
    assert!(r.singular_values.iter().all(|&s| (0.0..=1.0).contains(&s)));
    let f = logspace(0.5, 70.0, 200);
    let err = max_rel_error(&r.model, &plant, &f);
    assert!(err < 0.02, "max relative FRF error {err:.3e}");
}

#[test]
fn cholesky_and_qr_paths_give_the_same_model() {
    // The Hankel-correlation Cholesky path must equal the Householder QR of the data matrix.
    let (u, y, _) = reference_data(8_000, 0.1, 4);
    let fast = n4sid_slices(TS, &[&u], &[&y], &N4sidOptions::default()).unwrap();
    let qr = n4sid_slices(
        TS,
        &[&u],
        &[&y],
        &N4sidOptions {
            factorization: Factorization::Qr,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(fast.factorization_used, "cholesky");
    assert_eq!(qr.factorization_used, "qr");
    assert_eq!(fast.order, qr.order);
    for (a, b) in fast.singular_values.iter().zip(&qr.singular_values) {
        assert!(
            (a - b).abs() <= 1e-9 * fast.singular_values[0],
            "{a} vs {b}"
        );
    }
    let f = logspace(0.5, 400.0, 100);
    assert!(max_rel_error(&fast.model, &qr.model, &f) < 1e-7);
}

/// A 2x2, 4-state discrete system with two modes and cross-coupling.
fn mimo_plant() -> StateSpace {
    let a = mat(&[
        &[1.6, -0.8, 0.0, 0.0],
        &[1.0, 0.0, 0.0, 0.0],
        &[0.0, 0.0, 0.5, 0.2],
        &[0.0, 0.0, -0.2, 0.5],
    ]);
    let b = mat(&[&[1.0, 0.0], &[0.0, 0.0], &[0.3, 1.0], &[0.0, 0.5]]);
    let c = mat(&[&[0.2, 0.1, 1.0, 0.0], &[0.0, 0.3, 0.2, 1.0]]);
    let d = mat(&[&[0.1, 0.0], &[0.0, 0.0]]);
    StateSpace::new(a, b, c, d, 0.01).unwrap()
}

fn mimo_data(n: usize, noise: f64, seed: u64) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let plant = mimo_plant();
    let mut rng = Rng::new(seed);
    let u = vec![rng.binary(n), rng.binary(n)];
    let y0 = plant.simulate(&u, None).unwrap();
    let y = y0
        .iter()
        .map(|ch| {
            let sd = std_dev(ch);
            ch.iter().map(|v| v + noise * sd * rng.normal()).collect()
        })
        .collect();
    (u, y)
}

#[test]
fn mimo_two_by_two_known_system() {
    let plant = mimo_plant();
    let f = logspace(0.05, 49.0, 100);
    // Noise-free: exact.
    let (u, y) = mimo_data(4000, 0.0, 5);
    let ur: Vec<&[f64]> = u.iter().map(|c| c.as_slice()).collect();
    let yr: Vec<&[f64]> = y.iter().map(|c| c.as_slice()).collect();
    let r = n4sid_slices(0.01, &ur, &yr, &N4sidOptions::default()).unwrap();
    assert_eq!(r.order, 4, "{}", r.order_reason);
    assert_eq!((r.model.n_outputs(), r.model.n_inputs()), (2, 2));
    let err = max_rel_error(&r.model, &plant, &f);
    assert!(err < 1e-7, "noise-free MIMO FRF error {err:.3e}");
    // 5 % noise on each output: order 4 and every channel within 5 % in band.
    let (u, y) = mimo_data(20_000, 0.05, 6);
    let ur: Vec<&[f64]> = u.iter().map(|c| c.as_slice()).collect();
    let yr: Vec<&[f64]> = y.iter().map(|c| c.as_slice()).collect();
    let r = n4sid_slices(0.01, &ur, &yr, &N4sidOptions::default()).unwrap();
    assert_eq!(r.order, 4, "{}", r.order_reason);
    // Channel (1,0) passes through a zero-ish region; compare absolute error against the
    // largest gain of each channel instead of pointwise relative error.
    let gh = r.model.freq_responses_hz(&f).unwrap();
    let g = plant.freq_responses_hz(&f).unwrap();
    for i in 0..2 {
        for j in 0..2 {
            let peak = g.iter().map(|m| m[(i, j)].norm()).fold(0.0, f64::max);
            let worst = gh
                .iter()
                .zip(&g)
                .map(|(a, b)| (a[(i, j)] - b[(i, j)]).norm())
                .fold(0.0, f64::max);
            assert!(
                worst < 0.05 * peak,
                "channel ({i},{j}): {worst:.3e} vs peak {peak:.3e}"
            );
        }
    }
}

#[test]
fn badly_scaled_data_identify_as_well_as_normalised_data() {
    // 1e-6 s sample time, inputs of 1e3 amplitude, outputs of order 1e-4.
    let (u, y, _) = reference_data(20_000, 0.05, 7);
    let us: Vec<f64> = u.iter().map(|v| v * 1e3).collect();
    let ys: Vec<f64> = y.iter().map(|v| v * 1e-4).collect();
    let r1 = n4sid_slices(TS, &[&u], &[&y], &N4sidOptions::default()).unwrap();
    let r2 = n4sid_slices(1e-6, &[&us], &[&ys], &N4sidOptions::default()).unwrap();
    assert_eq!(r2.order, 3, "{}", r2.order_reason);
    assert_eq!(r2.model.ts, 1e-6);
    // Same model up to the gain 1e-7, compared at the same normalised frequencies.
    let f1 = logspace(0.5, 400.0, 100);
    let f2: Vec<f64> = f1.iter().map(|f| f * TS / 1e-6).collect();
    let g1 = r1.model.freq_responses_siso_hz(&f1).unwrap();
    let g2 = r2.model.freq_responses_siso_hz(&f2).unwrap();
    for (a, b) in g1.iter().zip(&g2) {
        let rel = (a * 1e-7 - b).norm() / (a.norm() * 1e-7);
        assert!(rel < 1e-8, "scaled fit differs by {rel:.3e}");
    }
    // And against the true plant (scaled): the in-band accuracy of the normal case.
    let plant = third_order_plant(TS);
    let g = plant
        .freq_responses_siso_hz(&logspace(0.5, 70.0, 50))
        .unwrap();
    let gb = r2
        .model
        .freq_responses_siso_hz(
            &logspace(0.5, 70.0, 50)
                .iter()
                .map(|f| f * TS / 1e-6)
                .collect::<Vec<_>>(),
        )
        .unwrap();
    for (a, b) in g.iter().zip(&gb) {
        assert!((a * 1e-7 - b).norm() < 0.02 * a.norm() * 1e-7);
    }
}

#[test]
fn feedthrough_is_estimated_or_fixed_to_zero() {
    // Biproper plant: 0.5 + 0.2/(z − 0.8).
    let plant = StateSpace::new(
        mat(&[&[0.8]]),
        mat(&[&[1.0]]),
        mat(&[&[0.2]]),
        mat(&[&[0.5]]),
        0.1,
    )
    .unwrap();
    let mut rng = Rng::new(8);
    let u = rng.binary(2000);
    let y = plant.simulate_siso(&u, None).unwrap();
    let r = n4sid_slices(
        0.1,
        &[&u],
        &[&y],
        &N4sidOptions {
            order: OrderSelection::Fixed(1),
            ..Default::default()
        },
    )
    .unwrap();
    assert!((r.model.d[(0, 0)] - 0.5).abs() < 1e-9);
    assert!((r.model.a[(0, 0)] - 0.8).abs() < 1e-9);
    let r0 = n4sid_slices(
        0.1,
        &[&u],
        &[&y],
        &N4sidOptions {
            order: OrderSelection::Fixed(1),
            estimate_d: false,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(r0.model.d[(0, 0)], 0.0);
}

#[test]
fn order_range_override_is_respected() {
    let (u, y, _) = reference_data(5000, 0.05, 9);
    let r = n4sid_slices(
        TS,
        &[&u],
        &[&y],
        &N4sidOptions {
            order: OrderSelection::Range { min: 4, max: 6 },
            ..Default::default()
        },
    )
    .unwrap();
    assert!((4..=6).contains(&r.order), "{}", r.order_reason);
    assert!(r.order_reason.contains("4..="), "{}", r.order_reason);
}

#[test]
fn initial_state_is_estimated() {
    let plant = third_order_plant(TS);
    let mut rng = Rng::new(10);
    let u = rng.binary(2000);
    let x0 = [0.3, -1.2, 2.0];
    let y = plant.simulate_siso(&u, Some(&x0)).unwrap();
    let est = estimate_x0(&plant, &[&u], &[&y]).unwrap();
    for (a, b) in est.iter().zip(&x0) {
        assert!((a - b).abs() < 1e-8, "{est:?}");
    }
    // Identification with a non-zero initial state still recovers the plant exactly, and its
    // x0 reproduces the data.
    let r = n4sid_slices(TS, &[&u], &[&y], &N4sidOptions::default()).unwrap();
    assert_eq!(r.order, 3);
    let ysim = r.model.simulate_siso(&u, Some(&r.x0)).unwrap();
    let worst = y
        .iter()
        .zip(&ysim)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-8 * std_dev(&y), "max sim error {worst:.3e}");
}

/// Unstable discrete plant: pole at z = 1.01 plus a stable mode.
fn unstable_plant() -> StateSpace {
    StateSpace::new(
        mat(&[&[1.01, 0.0], &[0.0, 0.6]]),
        mat(&[&[1.0], &[1.0]]),
        mat(&[&[1.0, 1.0]]),
        mat(&[&[0.0]]),
        0.01,
    )
    .unwrap()
}

#[test]
fn unstable_plant_is_reported_and_stability_can_be_enforced() {
    let plant = unstable_plant();
    let mut rng = Rng::new(11);
    let u = rng.binary(400);
    let y0 = plant.simulate_siso(&u, None).unwrap();
    let y: Vec<f64> = y0.iter().map(|v| v + 1e-4 * rng.normal()).collect();
    let fixed2 = N4sidOptions {
        block_rows: 10,
        order: OrderSelection::Fixed(2),
        ..Default::default()
    };
    let r = n4sid_slices(0.01, &[&u], &[&y], &fixed2).unwrap();
    let p = r.model.poles().unwrap();
    assert!(
        (p[0].re - 1.01).abs() < 1e-3 && p[0].im.abs() < 1e-9,
        "{p:?}"
    );
    assert!(!r.stability_enforced);
    assert!(
        r.warnings.iter().any(|w| w.contains("unstable")),
        "{:?}",
        r.warnings
    );
    // Enforced with a 0.02 margin: every pole within |z| <= 0.98, the change reported.
    let r = n4sid_slices(
        0.01,
        &[&u],
        &[&y],
        &N4sidOptions {
            stability_margin: Some(0.02),
            ..fixed2
        },
    )
    .unwrap();
    assert!(r.stability_enforced);
    let p = r.model.poles().unwrap();
    assert!(p.iter().all(|z| z.norm() <= 0.98 + 1e-9), "{p:?}");
    // The stable pole is kept.
    assert!(p.iter().any(|z| (z.re - 0.6).abs() < 1e-3), "{p:?}");
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("stability enforced") && w.contains("moved")),
        "{:?}",
        r.warnings
    );
    assert!(r.model.is_stable(0.02 - 1e-9).unwrap());
}

#[test]
fn stable_fit_is_left_alone_by_enforcement() {
    let (u, y, plant) = reference_data(5000, 0.0, 12);
    let r = n4sid_slices(
        TS,
        &[&u],
        &[&y],
        &N4sidOptions {
            stability_margin: Some(0.001),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(!r.stability_enforced);
    assert!(max_rel_error(&r.model, &plant, &logspace(0.5, 400.0, 50)) < 1e-8);
}

#[test]
fn order_beyond_the_numerical_rank_is_flagged() {
    let (u, y, _) = reference_data(3000, 0.0, 13);
    let r = n4sid_slices(
        TS,
        &[&u],
        &[&y],
        &N4sidOptions {
            order: OrderSelection::Fixed(6),
            ..Default::default()
        },
    );
    match r {
        Ok(r) => assert!(
            r.warnings
                .iter()
                .any(|w| w.contains("numerical rank") || w.contains("ill-conditioned")),
            "{:?}",
            r.warnings
        ),
        Err(e) => assert!(e.to_string().contains("ill-conditioned"), "{e}"),
    }
}

#[test]
fn summary_serialises() {
    let (u, y, _) = reference_data(3000, 0.02, 14);
    let r = n4sid_slices(TS, &[&u], &[&y], &N4sidOptions::default()).unwrap();
    let json = serde_json::to_string(&r.summary()).unwrap();
    assert!(json.contains("\"order\":3"));
    assert!(json.contains("singular_values"));
    let _ = Mat::<f64>::zeros(1, 1);
}

/// Relative frequency-response error |G_id − G|/|G| at `f_hz`.
fn rel_err_at(model: &StateSpace, plant: &StateSpace, f_hz: f64) -> f64 {
    let g = plant.freq_response_siso(f_hz).unwrap();
    (model.freq_response_siso(f_hz).unwrap() - g).norm() / g.norm()
}

#[test]
fn insignificant_feedthrough_is_dropped_and_the_test_is_calibrated() {
    // The reference plant is strictly proper (ZOH-sampled): its true D is 0, so the estimated
    // D is pure noise and |D|/SE is approximately standard normal when the standard error is
    // right. Over 40 noise realisations, the share within k SE must match P(|N(0,1)| <= k):
    // 68.3 % for k = 1 (expected 27.3 of 40, binomial sd 2.9: accept 20..=34) and 95.4 % for
    // k = 2 (expected 38.2: accept >= 34). A standard error off by 2x either way fails the
    // k = 1 band (it would give 38 % or 95 %).
    let opts = |k: f64| N4sidOptions {
        order: OrderSelection::Fixed(3),
        d_significance: Some(k),
        estimate_kalman_gain: false,
        ..Default::default()
    };
    let (mut within1, mut within2) = (0, 0);
    let (mut err_auto, mut err_est) = (0.0, 0.0);
    for seed in 0..40u64 {
        let (u, y, plant) = reference_data(4000, 0.1, 1000 + seed);
        let r1 = n4sid_slices(TS, &[&u], &[&y], &opts(1.0)).unwrap();
        let r2 = n4sid_slices(TS, &[&u], &[&y], &opts(2.0)).unwrap();
        for r in [&r1, &r2] {
            if r.d_fixed_by_test {
                assert_eq!(r.model.d[(0, 0)], 0.0);
                assert!(
                    r.warnings
                        .iter()
                        .any(|w| w.contains("feedthrough D fixed to zero")),
                    "{:?}",
                    r.warnings
                );
            } else {
                assert_ne!(r.model.d[(0, 0)], 0.0);
            }
        }
        within1 += r1.d_fixed_by_test as usize;
        within2 += r2.d_fixed_by_test as usize;
        // Near Nyquist the plant is ~70 dB down and a noisy D dominates the relative error.
        let est = n4sid_slices(
            TS,
            &[&u],
            &[&y],
            &N4sidOptions {
                order: OrderSelection::Fixed(3),
                estimate_kalman_gain: false,
                ..Default::default()
            },
        )
        .unwrap();
        assert!(!est.d_fixed_by_test);
        err_auto += rel_err_at(&r2.model, &plant, 450.0);
        err_est += rel_err_at(&est.model, &plant, 450.0);
    }
    println!(
        "within 1 SE: {within1}/40, within 2 SE: {within2}/40; mean rel. error at 450 Hz: \
         auto {:.3e}, estimated {:.3e}",
        err_auto / 40.0,
        err_est / 40.0
    );
    assert!((20..=34).contains(&within1), "within 1 SE: {within1}/40");
    assert!(within2 >= 34, "within 2 SE: {within2}/40");
    assert!(
        err_auto < 0.5 * err_est,
        "mean rel. error at 450 Hz: auto {} vs estimated {}",
        err_auto / 40.0,
        err_est / 40.0
    );
}

#[test]
fn significant_feedthrough_is_kept() {
    // Biproper plant 0.5 + 0.2/(z − 0.8) with 5 % output noise: |D|/SE is in the hundreds.
    let plant = StateSpace::new(
        mat(&[&[0.8]]),
        mat(&[&[1.0]]),
        mat(&[&[0.2]]),
        mat(&[&[0.5]]),
        0.1,
    )
    .unwrap();
    let mut rng = Rng::new(21);
    let u = rng.binary(2000);
    let y0 = plant.simulate_siso(&u, None).unwrap();
    let sd = std_dev(&y0);
    let y: Vec<f64> = y0.iter().map(|v| v + 0.05 * sd * rng.normal()).collect();
    let r = n4sid_slices(
        0.1,
        &[&u],
        &[&y],
        &N4sidOptions {
            order: OrderSelection::Fixed(1),
            d_significance: Some(2.0),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(!r.d_fixed_by_test);
    assert!(
        (r.model.d[(0, 0)] - 0.5).abs() < 0.01,
        "D = {}",
        r.model.d[(0, 0)]
    );
}
