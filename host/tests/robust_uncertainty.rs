//! Multiplicative uncertainty envelope and W_m(s) fit against known perturbed plants.
use ferrosid::robust::norms::logspace;
use ferrosid::robust::uncertainty::{
    fit_uncertainty_weight, fit_uncertainty_weights, multiplicative_envelope, UncertaintyWeight,
    WeightFitOptions,
};
use num_complex::Complex64;
use std::f64::consts::PI;

use crate::test_models::{horner, hurwitz, weight_order};

fn j() -> Complex64 {
    Complex64::new(0.0, 1.0)
}

/// |num/den|(j2πf) at every frequency of `f` (Hz).
fn magnitude(num: &[f64], den: &[f64], f: &[f64]) -> Vec<f64> {
    f.iter()
        .map(|&f| {
            let s = j() * 2.0 * PI * f;
            (horner(num, s) / horner(den, s)).norm()
        })
        .collect()
}

fn check_weight(w: &UncertaintyWeight, f: &[f64], l: &[f64]) {
    assert_eq!(w.num.len(), w.order + 1);
    assert_eq!(w.den.len(), w.order + 1);
    assert!(hurwitz(&w.num), "zeros not in LHP: {:?}", w.num);
    assert!(hurwitz(&w.den), "poles not in LHP: {:?}", w.den);
    assert!(w.constraint_holds);
    let mut worst = 0.0f64;
    for (&fi, &li) in f.iter().zip(l) {
        let s = j() * 2.0 * PI * fi;
        let mag = (horner(&w.num, s) / horner(&w.den, s)).norm();
        assert!(
            mag >= li * (1.0 - 1e-12),
            "|W| = {mag} < l = {li} at {fi} Hz"
        );
        worst = worst.max(mag / li.max(w.min_level));
    }
    assert!((worst - w.worst_overbound_ratio).abs() <= 1e-9 * worst);
}

#[test]
fn envelope_of_scaled_plants_is_the_largest_relative_error() {
    let f = logspace(0.1, 100.0, 50);
    let g0: Vec<Complex64> = f
        .iter()
        .map(|&f| 1.0 / (j() * 2.0 * PI * f + 1.0))
        .collect();
    let eps = [
        Complex64::new(0.1, 0.0),
        Complex64::new(0.0, -0.25),
        Complex64::new(-0.05, 0.05),
    ];
    let fam: Vec<Vec<Complex64>> = eps
        .iter()
        .map(|e| g0.iter().map(|g| g * (1.0 + e)).collect())
        .collect();
    let l = multiplicative_envelope(&g0, &fam).unwrap();
    for v in l {
        assert!((v - 0.25).abs() < 1e-12, "{v}");
    }
}

#[test]
fn envelope_of_weighted_perturbations_equals_the_weight() {
    // G_k = G0 (1 + δ_k W(jω)), |δ_k| = 1: the envelope is |W(jω)| exactly.
    let wnum = [0.5, 0.2];
    let wden = [0.01, 1.0];
    let f = logspace(0.01, 1000.0, 80);
    let g0: Vec<Complex64> = f
        .iter()
        .map(|&f| {
            let s = j() * 2.0 * PI * f;
            3.0 / (s * s + 0.4 * s + 4.0)
        })
        .collect();
    let fam: Vec<Vec<Complex64>> = [0.0, 1.0, 2.5, 4.0]
        .iter()
        .map(|&ph: &f64| {
            let d = Complex64::from_polar(1.0, ph);
            f.iter()
                .zip(&g0)
                .map(|(&f, g)| {
                    let s = j() * 2.0 * PI * f;
                    g * (1.0 + d * horner(&wnum, s) / horner(&wden, s))
                })
                .collect()
        })
        .collect();
    let l = multiplicative_envelope(&g0, &fam).unwrap();
    for (&fi, &li) in f.iter().zip(&l) {
        let s = j() * 2.0 * PI * fi;
        let w = (horner(&wnum, s) / horner(&wden, s)).norm();
        assert!((li - w).abs() <= 1e-12 * w.max(1.0), "{li} vs {w}");
    }
}

#[test]
fn first_order_envelope_is_recovered_by_a_first_order_weight() {
    // l(ω) = |(s/2 + 0.1)/(s/200 + 1)|: 10 % at low frequency rising to 100 at high frequency.
    let (num, den) = ([0.5, 0.1], [0.005, 1.0]);
    let f = logspace(0.01, 1000.0, 120);
    let l = magnitude(&num, &den, &f);
    let w = fit_uncertainty_weight(&f, &l, &weight_order(1)).unwrap();
    check_weight(&w, &f, &l);
    assert!(w.worst_overbound_ratio < 1.01, "{w:?}");
    // Recovered zero and pole (0.2 and 200 rad/s) within 2 %.
    assert!((w.zeros[0][0] + 0.2).abs() < 0.004, "{:?}", w.zeros);
    assert!((w.poles[0][0] + 200.0).abs() < 4.0, "{:?}", w.poles);
}

#[test]
fn resonant_envelope_needs_order_two() {
    // l(ω) = |0.1 (s² + 2·0.7·30 s + 900)/(s² + 2·0.15·60 s + 3600)|·...: a bump near 60 rad/s.
    let (num, den) = (
        [0.8, 2.0 * 0.7 * 30.0 * 0.8, 900.0 * 0.8],
        [1.0, 2.0 * 0.15 * 60.0, 3600.0],
    );
    let f = logspace(0.1, 100.0, 150);
    let l = magnitude(&num, &den, &f);
    let fits = fit_uncertainty_weights(&f, &l, &weight_order(3)).unwrap();
    assert_eq!(fits.len(), 3);
    for w in &fits {
        check_weight(w, &f, &l);
    }
    let (w1, w2, w3) = (&fits[0], &fits[1], &fits[2]);
    assert!(
        w1.worst_overbound_ratio > 1.5,
        "order 1 should be loose: {}",
        w1.worst_overbound_ratio
    );
    assert!(
        w2.worst_overbound_ratio < 1.05,
        "order 2 should be tight: {}",
        w2.worst_overbound_ratio
    );
    assert!(w2.mean_overbound_db < 0.5 * w1.mean_overbound_db);
    assert!(w3.mean_overbound_db <= w2.mean_overbound_db + 1e-9);
}

#[test]
fn delay_family_overbound_and_order_monotonicity() {
    // Unmodelled delays τ ∈ {0.2, 0.5, 1, 2} ms around G0 = 100/(s + 100): the classic
    // multiplicative envelope |e^{−jωτ} − 1| that rises as ωτ and saturates at 2.
    let f = logspace(1.0, 2000.0, 200);
    let g0: Vec<Complex64> = f
        .iter()
        .map(|&f| 100.0 / (j() * 2.0 * PI * f + 100.0))
        .collect();
    let fam: Vec<Vec<Complex64>> = [0.2e-3, 0.5e-3, 1e-3, 2e-3]
        .iter()
        .map(|&tau| {
            f.iter()
                .zip(&g0)
                .map(|(&f, g)| g * Complex64::from_polar(1.0, -2.0 * PI * f * tau))
                .collect()
        })
        .collect();
    let l = multiplicative_envelope(&g0, &fam).unwrap();
    let fits = fit_uncertainty_weights(&f, &l, &weight_order(2)).unwrap();
    for w in &fits {
        check_weight(w, &f, &l);
    }
    assert!(
        fits[1].mean_overbound_db < fits[0].mean_overbound_db - 0.1,
        "{} vs {}",
        fits[1].mean_overbound_db,
        fits[0].mean_overbound_db
    );
    // The weight's low-frequency slope follows ωτ_max (within the overbound).
    let w1 = &fits[0];
    assert!(w1.magnitude_hz(1.0) >= 2.0 * PI * 1.0 * 2e-3 * 0.999);
}

#[test]
fn weight_state_space_matches_polynomials() {
    let f = logspace(0.1, 10.0, 20);
    let l: Vec<f64> = f.iter().map(|f| 0.1 + 0.05 * f).collect();
    let w = fit_uncertainty_weight(&f, &l, &weight_order(1)).unwrap();
    let ss = w.to_state_space().unwrap();
    for &fi in &f {
        let a = ss.freq_response_siso(fi).unwrap();
        let b = w.freq_response_hz(fi);
        assert!((a - b).norm() <= 1e-10 * b.norm());
    }
    // Serialises for receipts.json.
    let js = serde_json::to_string(&w).unwrap();
    assert!(js.contains("\"worst_overbound_ratio\""));
}

#[test]
fn bad_inputs_are_clear_errors() {
    let f = [1.0, 2.0, 3.0];
    let l = [0.1, 0.2, 0.3];
    let o = WeightFitOptions::default();
    let msg = |r: Result<UncertaintyWeight, ferrosid::Error>| r.unwrap_err().to_string();
    assert!(msg(fit_uncertainty_weight(&f, &l[..2], &o)).contains("3 frequencies but 2"));
    assert!(msg(fit_uncertainty_weight(&[1.0, 1.0, 3.0], &l, &o)).contains("increase strictly"));
    assert!(msg(fit_uncertainty_weight(&[1.0, -2.0, 3.0], &l, &o)).contains("bin 1"));
    assert!(msg(fit_uncertainty_weight(&f, &[0.1, f64::NAN, 0.3], &o)).contains("envelope bin 1"));
    assert!(msg(fit_uncertainty_weight(
        &f,
        &l,
        &WeightFitOptions { order: 4, ..o }
    ))
    .contains("order 4"));
    assert!(msg(fit_uncertainty_weight(
        &f,
        &l,
        &WeightFitOptions { order: 0, ..o }
    ))
    .contains("order 0"));
    assert!(msg(fit_uncertainty_weight(&f[..2], &l[..2], &o)).contains("at least 3"));
    let g0 = [Complex64::new(1.0, 0.0), Complex64::new(0.0, 0.0)];
    let fam = vec![vec![Complex64::new(1.0, 0.0); 2]];
    assert!(multiplicative_envelope(&g0, &fam)
        .unwrap_err()
        .to_string()
        .contains("zero at bin 1"));
    let fam3 = vec![vec![Complex64::new(1.0, 0.0); 3]];
    assert!(
        multiplicative_envelope(&[Complex64::new(1.0, 0.0); 2], &fam3)
            .unwrap_err()
            .to_string()
            .contains("member 0 has 3 bins")
    );
    let empty: Vec<Vec<Complex64>> = vec![];
    assert!(multiplicative_envelope(&[Complex64::new(1.0, 0.0)], &empty).is_err());
}
