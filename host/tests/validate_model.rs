//! Validation metrics against closed forms: NRMSE/fit of known signals, phase/magnitude errors
//! of a known offset against the ETFE slices, residual correlation tests that must pass for
//! the true model and fail for a wrong one.
mod n4sid_support;

use ferrosid::lti::StateSpace;
use ferrosid::validate::{
    compare_with_etfe, residual_test, simulation_fit, InitialState, ResidualKind, PHASE_BOUND_DEG,
};
use ferrosid::Error;
use n4sid_support::*;
use num_complex::Complex64;

#[test]
fn fit_of_a_half_gain_model_is_fifty_percent() {
    // y = u with zero-mean u; the model y = 0.5u leaves ‖0.5u‖ = 0.5‖u − ū‖: fit 50 %.
    let u: Vec<f64> = (0..1000)
        .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
        .collect();
    let half = StateSpace::gain(mat(&[&[0.5]]), 1.0).unwrap();
    let fit = simulation_fit(&half, &[&u], &[&u], InitialState::Zero).unwrap();
    assert!((fit.nrmse[0] - 0.5).abs() < 1e-14);
    assert!((fit.fit_percent[0] - 50.0).abs() < 1e-12);
}

#[test]
fn true_model_fits_perfectly_with_estimated_initial_state() {
    let plant = third_order_plant(1e-3);
    let mut rng = Rng::new(1);
    let u = rng.binary(3000);
    let y = plant.simulate_siso(&u, Some(&[1.0, -0.5, 0.25])).unwrap();
    let fit = simulation_fit(&plant, &[&u], &[&y], InitialState::Estimate).unwrap();
    assert!(fit.nrmse[0] < 1e-9, "{}", fit.nrmse[0]);
    let zero = simulation_fit(&plant, &[&u], &[&y], InitialState::Zero).unwrap();
    assert!(zero.fit_percent[0] < fit.fit_percent[0]);
    // With noise: identical to the independent formula in the support module.
    let yn: Vec<f64> = y.iter().map(|v| v + 0.1 * rng.normal()).collect();
    let fit = simulation_fit(
        &plant,
        &[&u],
        &[&yn],
        InitialState::Given(vec![1.0, -0.5, 0.25]),
    )
    .unwrap();
    let ysim = plant.simulate_siso(&u, Some(&[1.0, -0.5, 0.25])).unwrap();
    assert!((fit.fit_percent[0] - fit_percent(&yn, &ysim)).abs() < 1e-10);
}

#[test]
fn simulation_fit_bad_inputs() {
    let plant = third_order_plant(1e-3);
    let u = vec![1.0; 100];
    let y = vec![2.0; 100];
    let r = simulation_fit(&plant, &[&u], &[&y], InitialState::Zero);
    assert!(
        matches!(r, Err(Error::Data { .. })),
        "constant output: {r:?}"
    );
    let r = simulation_fit(&plant, &[&u, &u], &[&y], InitialState::Zero);
    assert!(r.unwrap_err().to_string().contains("2 input"));
    let r = simulation_fit(&plant, &[&u], &[&y[..50]], InitialState::Zero);
    assert!(r.unwrap_err().to_string().contains("mismatched lengths"));
    let cont = third_order_plant_tf().to_state_space().unwrap();
    assert!(simulation_fit(&cont, &[&u], &[&y], InitialState::Zero).is_err());
    let r = simulation_fit(&plant, &[&u], &[&y], InitialState::Given(vec![0.0]));
    assert!(r.is_err(), "wrong x0 length");
}

/// ETFE slices from the true discrete plant times a known complex factor.
fn etfe_with_offset(plant: &StateSpace, f: &[f64], factor: Complex64) -> Vec<Complex64> {
    plant
        .freq_responses_siso_hz(f)
        .unwrap()
        .iter()
        .map(|g| g * factor)
        .collect()
}

#[test]
fn etfe_phase_and_magnitude_errors_of_a_known_offset() {
    let plant = third_order_plant(1e-3);
    let f: Vec<f64> = (0..=100).map(|k| k as f64 * 2.0).collect(); // 0..200 Hz
    let offset_deg: f64 = 3.0;
    let factor = Complex64::from_polar(1.1, offset_deg.to_radians());
    let h = etfe_with_offset(&plant, &f, factor);
    let mut gate = vec![true; f.len()];
    gate[10] = false; // 20 Hz
    gate[20] = false; // 40 Hz
    let cmp = compare_with_etfe(&plant, 0, 0, &f, &h, &gate, 30.0, PHASE_BOUND_DEG).unwrap();
    // Bins in (0, 60] Hz: 2, 4, ..., 60 = 30 bins, two gated out.
    assert_eq!(cmp.bins.len(), 28);
    assert_eq!(cmp.gated_out, 2);
    assert_eq!(cmp.f_max_hz, 60.0);
    for b in &cmp.bins {
        assert!((b.phase_err_deg + offset_deg).abs() < 1e-9, "{b:?}");
        assert!((b.mag_err_db + 20.0 * 1.1f64.log10()).abs() < 1e-9);
    }
    assert!(cmp.within_bound);
    assert!((cmp.max_abs_phase_err_deg - 3.0).abs() < 1e-9);
    // 7° offset violates the ±5° checklist bound.
    let h7 = etfe_with_offset(&plant, &f, Complex64::from_polar(1.0, 7f64.to_radians()));
    let cmp = compare_with_etfe(&plant, 0, 0, &f, &h7, &gate, 30.0, PHASE_BOUND_DEG).unwrap();
    assert!(!cmp.within_bound);
    // Wrapping: an offset of 181° is reported as +179° (error = −181° wrapped).
    let hw = etfe_with_offset(&plant, &f, Complex64::from_polar(1.0, 181f64.to_radians()));
    let cmp = compare_with_etfe(&plant, 0, 0, &f, &hw, &gate, 30.0, PHASE_BOUND_DEG).unwrap();
    for b in &cmp.bins {
        assert!(
            (b.phase_err_deg - 179.0).abs() < 1e-9,
            "{}",
            b.phase_err_deg
        );
        assert!(b.phase_err_deg > -180.0 && b.phase_err_deg <= 180.0);
    }
}

#[test]
fn etfe_comparison_bad_inputs() {
    let plant = third_order_plant(1e-3);
    let f = vec![1.0, 2.0, 3.0];
    let h = etfe_with_offset(&plant, &f, Complex64::new(1.0, 0.0));
    let all = vec![true; 3];
    assert!(compare_with_etfe(&plant, 0, 0, &f, &h[..2], &all, 10.0, 5.0).is_err());
    assert!(compare_with_etfe(&plant, 0, 0, &f, &h, &all, 0.0, 5.0).is_err());
    assert!(compare_with_etfe(&plant, 1, 0, &f, &h, &all, 10.0, 5.0).is_err());
    let none = vec![false; 3];
    let e = compare_with_etfe(&plant, 0, 0, &f, &h, &none, 10.0, 5.0).unwrap_err();
    assert!(e.to_string().contains("no coherence-gated"), "{e}");
    let mut hn = h.clone();
    hn[1] = Complex64::new(f64::NAN, 0.0);
    assert!(compare_with_etfe(&plant, 0, 0, &f, &hn, &all, 10.0, 5.0).is_err());
}

#[test]
fn residual_tests_pass_for_the_true_model_and_fail_for_a_wrong_one() {
    let plant = third_order_plant(1e-3);
    let mut rng = Rng::new(3);
    let n = 20_000;
    let u = rng.binary(n);
    let y0 = plant.simulate_siso(&u, None).unwrap();
    let y: Vec<f64> = y0.iter().map(|v| v + 0.05 * rng.normal()).collect();
    let t = residual_test(&plant, None, &[&u], &[&y], 25).unwrap();
    assert_eq!(t.kind, ResidualKind::OutputError);
    assert!((t.bound - 2.58 / (n as f64).sqrt()).abs() < 1e-15);
    assert_eq!(t.autocorr[0].len(), 25);
    assert_eq!(t.crosscorr[0][0].len(), 26);
    assert!(t.whiteness_ok && t.independence_ok, "{t:?}");
    // A model with 20 % too little gain leaves input-correlated residuals.
    let mut wrong = plant.clone();
    for i in 0..wrong.c.ncols() {
        wrong.c[(0, i)] *= 0.8;
    }
    let t = residual_test(&wrong, None, &[&u], &[&y], 25).unwrap();
    assert!(!t.independence_ok, "frac {}", t.frac_cross_outside);
    assert!(residual_test(&plant, None, &[&u], &[&y], 0).is_err());
}

#[test]
fn one_step_predictor_residual_is_white_for_the_innovation_model() {
    // Coloured noise: y = G u + H e with H = 1 + C(zI − A)⁻¹K. The output error is coloured
    // (whiteness fails) while the Kalman predictor residual is e itself (white).
    let a = mat(&[&[0.95]]);
    let model = StateSpace::new(
        a.clone(),
        mat(&[&[1.0]]),
        mat(&[&[1.0]]),
        mat(&[&[0.0]]),
        1.0,
    )
    .unwrap();
    let k = mat(&[&[0.7]]);
    let mut rng = Rng::new(4);
    let n = 20_000;
    let u = rng.binary(n);
    let e = rng.noise(n, 0.5);
    let mut x = 0.0;
    let mut y = vec![0.0; n];
    for t in 0..n {
        y[t] = x + e[t];
        x = 0.95 * x + u[t] + 0.7 * e[t];
    }
    let oe = residual_test(&model, None, &[&u], &[&y], 20).unwrap();
    assert!(!oe.whiteness_ok, "OE residual should be coloured");
    let pe = residual_test(&model, Some(k.as_ref()), &[&u], &[&y], 20).unwrap();
    assert_eq!(pe.kind, ResidualKind::OneStepPrediction);
    assert!(pe.whiteness_ok && pe.independence_ok, "{pe:?}");
}
