//! H∞ norms by Hamiltonian bisection against closed forms and an independent dense grid.
use faer::Mat;
use ferrosid::lti::StateSpace;
use ferrosid::robust::norms::{hinf_norm, logspace, peak_gain_on_grid};
use ferrosid_sim::rng::Rng;
use std::f64::consts::PI;

use crate::test_models::ss;

/// The certified bound γ is at least the grid peak `gp` (up to `above` relative rounding) and
/// at most a relative `below` above it (the grid's resolution).
fn assert_brackets(gamma: f64, gp: f64, above: f64, below: f64, label: &str) {
    assert!(
        gp <= gamma * (1.0 + above),
        "{label}: grid {gp} above certified bound {gamma}"
    );
    assert!(
        gamma <= gp * (1.0 + below),
        "{label}: bound {gamma} vs grid {gp}"
    );
}

#[test]
fn first_order_lowpass_peak_is_dc_gain() {
    // K/(s + a): sup |G| = K/a at ω = 0.
    for (k, a) in [(3.0, 2.0), (0.5, 100.0), (1e3, 1e-2)] {
        let r = hinf_norm(&ss(&[k], &[1.0, a], 0.0)).unwrap();
        assert!((r.gamma - k / a).abs() <= 1e-8 * k / a, "{r:?}");
        assert!(r.gamma_lower <= r.gamma);
        assert_eq!(r.peak_w_rad_s, 0.0);
    }
}

#[test]
fn second_order_resonance_closed_form() {
    // ωn²/(s² + 2ζωn s + ωn²), ζ < 1/√2: peak 1/(2ζ√(1−ζ²)) at ωn√(1−2ζ²).
    for (wn, zeta) in [
        (1.0, 0.05),
        (2.0 * PI * 50.0, 0.2),
        (10.0, 0.5),
        (3.0, 0.01),
    ] {
        let r = hinf_norm(&ss(&[wn * wn], &[1.0, 2.0 * zeta * wn, wn * wn], 0.0)).unwrap();
        let peak = 1.0 / (2.0 * zeta * (1.0f64 - zeta * zeta).sqrt());
        let wpk = wn * (1.0f64 - 2.0 * zeta * zeta).sqrt();
        assert!(
            (r.gamma - peak).abs() <= 1e-8 * peak,
            "ζ={zeta}: {r:?} vs {peak}"
        );
        assert!(
            (r.peak_w_rad_s - wpk).abs() <= 1e-4 * wpk,
            "ζ={zeta}: {r:?} vs {wpk}"
        );
        assert!((r.peak_f_hz - wpk / (2.0 * PI)).abs() <= 1e-4 * wpk);
    }
}

#[test]
fn well_damped_second_order_peak_at_dc() {
    // ζ = 0.9 > 1/√2: no resonance, peak = 1 at ω = 0.
    let r = hinf_norm(&ss(&[4.0], &[1.0, 3.6, 4.0], 0.0)).unwrap();
    assert!((r.gamma - 1.0).abs() <= 1e-8, "{r:?}");
    assert!(r.peak_w_rad_s < 1e-3);
}

#[test]
fn biproper_highpass_supremum_at_infinity() {
    // 2s/(s + 1): sup = 2 = |D|, approached as ω → ∞.
    let r = hinf_norm(&ss(&[2.0, 0.0], &[1.0, 1.0], 0.0)).unwrap();
    assert!((r.gamma - 2.0).abs() <= 1e-8, "{r:?}");
    assert!(r.peak_w_rad_s.is_infinite());
}

#[test]
fn lead_with_feedthrough_closed_form() {
    // (s + 1)/(0.1 s + 1) has |G| increasing from 1 to 10: sup = 10 at ∞; and the inverse
    // (0.1 s + 1)/(s + 1) peaks at DC with 1.
    let r = hinf_norm(&ss(&[1.0, 1.0], &[0.1, 1.0], 0.0)).unwrap();
    assert!((r.gamma - 10.0).abs() <= 1e-7, "{r:?}");
    let r = hinf_norm(&ss(&[0.1, 1.0], &[1.0, 1.0], 0.0)).unwrap();
    assert!((r.gamma - 1.0).abs() <= 1e-8, "{r:?}");
}

#[test]
fn discrete_first_order_closed_forms() {
    // b/(z − a): |G(e^{jθ})| = b/|e^{jθ} − a|, max b/(1 − |a|) at θ = 0 (a > 0) or θ = π (a < 0).
    let ts = 1e-3;
    let r = hinf_norm(&ss(&[0.2], &[1.0, -0.8], ts)).unwrap();
    assert!((r.gamma - 1.0).abs() <= 1e-8, "{r:?}");
    assert!(r.peak_w_rad_s.abs() < 1e-6);
    let r = hinf_norm(&ss(&[0.2], &[1.0, 0.8], ts)).unwrap();
    assert!((r.gamma - 1.0).abs() <= 1e-8, "{r:?}");
    assert!((r.peak_w_rad_s - PI / ts).abs() <= 1e-6 * PI / ts, "{r:?}");
}

#[test]
fn discrete_resonance_matches_zoh_of_continuous_and_dense_grid() {
    // A lightly damped mode discretised with ZOH: compare the Hamiltonian norm with a dense
    // grid over the unit circle refined by golden section (independent code path).
    let wn = 2.0 * PI * 40.0;
    let zeta = 0.03;
    let g = ss(&[wn * wn], &[1.0, 2.0 * zeta * wn, wn * wn], 0.0)
        .c2d_zoh(1e-3)
        .unwrap();
    let r = hinf_norm(&g).unwrap();
    let grid: Vec<f64> = (0..=200_000)
        .map(|k| PI / 1e-3 * k as f64 / 200_000.0)
        .collect();
    let (gp, gw) = peak_gain_on_grid(&g, &grid).unwrap();
    assert_brackets(r.gamma, gp, 1e-12, 1e-5, "ZOH resonance");
    assert!(
        (r.peak_w_rad_s - gw).abs() <= 2e-3 * gw,
        "{} vs {gw}",
        r.peak_w_rad_s
    );
    // Close to the continuous peak (ZOH distorts a 40 Hz mode at 1 kHz only slightly).
    let cont = 1.0 / (2.0 * zeta * (1.0f64 - zeta * zeta).sqrt());
    assert!((r.gamma / cont - 1.0).abs() < 0.05, "{} vs {cont}", r.gamma);
}

/// Uniform in [−1, 1) from the workspace's seeded generator.
fn symmetric(rng: &mut Rng) -> f64 {
    2.0 * rng.uniform() - 1.0
}

#[test]
fn random_stable_mimo_models_agree_with_dense_grid() {
    let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
    for (n, m, p) in [(3, 1, 1), (5, 2, 3), (7, 3, 2), (4, 2, 2)] {
        // Block-diagonal modes (real poles and damped pairs) mixed by random B, C, D.
        let mut a = Mat::<f64>::zeros(n, n);
        let mut i = 0;
        while i < n {
            if i + 1 < n && symmetric(&mut rng) > -0.3 {
                let wn = 10f64.powf(symmetric(&mut rng) * 1.5);
                let zeta = 0.05 + 0.4 * (symmetric(&mut rng) + 1.0) / 2.0;
                let (re, im) = (-zeta * wn, wn * (1.0 - zeta * zeta).sqrt());
                a[(i, i)] = re;
                a[(i + 1, i + 1)] = re;
                a[(i, i + 1)] = im;
                a[(i + 1, i)] = -im;
                i += 2;
            } else {
                a[(i, i)] = -10f64.powf(symmetric(&mut rng) * 1.5);
                i += 1;
            }
        }
        let b = Mat::from_fn(n, m, |_, _| symmetric(&mut rng));
        let c = Mat::from_fn(p, n, |_, _| symmetric(&mut rng));
        let d = Mat::from_fn(p, m, |_, _| 0.3 * symmetric(&mut rng));
        let sys = StateSpace::new(a, b, c, d, 0.0).unwrap();
        let r = hinf_norm(&sys).unwrap();
        let grid = logspace(1e-4, 1e4, 40_001);
        let (gp, _) = peak_gain_on_grid(&sys, &grid).unwrap();
        assert_brackets(r.gamma, gp, 1e-10, 2e-3, &format!("n={n}"));
        assert!(r.gamma <= r.gamma_lower * (1.0 + 3e-9));
    }
}

#[test]
fn unstable_and_marginal_models_are_refused() {
    let e = hinf_norm(&ss(&[1.0], &[1.0, -1.0], 0.0)).unwrap_err();
    assert!(e.to_string().contains("not stable"), "{e}");
    let e = hinf_norm(&ss(&[1.0], &[1.0, 0.0], 0.0)).unwrap_err(); // integrator
    assert!(e.to_string().contains("not stable"), "{e}");
    let e = hinf_norm(&ss(&[1.0], &[1.0, -1.0], 0.01)).unwrap_err(); // z = 1
    assert!(e.to_string().contains("not stable"), "{e}");
}

#[test]
fn static_gain_norm_is_largest_singular_value() {
    // [[3, 0], [4, 0]] has σ̄ = 5.
    let d = Mat::from_fn(2, 2, |i, j| [[3.0, 0.0], [4.0, 0.0]][i][j]);
    let r = hinf_norm(&StateSpace::gain(d, 0.0).unwrap()).unwrap();
    assert!((r.gamma - 5.0).abs() < 1e-12);
}

#[test]
fn badly_scaled_high_frequency_resonances() {
    // Fourth-order companion form with two kHz modes: coefficients span ~15 decades.
    let (w1, z1, w2, z2) = (2.0 * PI * 800.0, 0.02, 2.0 * PI * 5000.0, 0.01);
    let d1 = [1.0, 2.0 * z1 * w1, w1 * w1];
    let d2 = [1.0, 2.0 * z2 * w2, w2 * w2];
    let den = ferrosid::lti::poly_mul(&d1, &d2);
    let sys = ss(&[w1 * w1 * w2 * w2], &den, 0.0);
    let r = hinf_norm(&sys).unwrap();
    let grid = logspace(2.0 * PI * 10.0, 2.0 * PI * 1e5, 400_001);
    let (gp, gw) = peak_gain_on_grid(&sys, &grid).unwrap();
    assert_brackets(r.gamma, gp, 1e-10, 1e-4, "two resonances");
    assert!((r.peak_w_rad_s / gw - 1.0).abs() < 1e-3);
}
