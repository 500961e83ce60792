//! H∞ mixed sensitivity against an interpolation bound, with the closed-loop norm checked
//! independently, and balanced truncation against its error bound.
use ferrosid::lti::{StateSpace, StateSpaceData, TransferFunction};
use ferrosid::robust::loops::margins;
use ferrosid::robust::norms::hinf_norm;
use ferrosid::synth::balred::{balanced_truncation, balanced_truncation_to_bound};
use ferrosid::synth::hinf::{
    hinf_mixed_sensitivity, performance_weight, weighted_closed_loop_norm, HinfOptions,
    MixedSensitivityWeights,
};

fn tf(num: &[f64], den: &[f64]) -> StateSpace {
    TransferFunction::new(num.to_vec(), den.to_vec(), 0.0)
        .unwrap()
        .to_state_space()
        .unwrap()
}

/// |W(s)| at a real point s.
fn mag_at(w: &StateSpace, s: f64) -> f64 {
    w.evaluate(num_complex::Complex64::new(s, 0.0)).unwrap()[(0, 0)].norm()
}

#[test]
fn rhp_zero_interpolation_bound_is_approached() {
    // G = (1 − s)/(s + 1)²: a right-half-plane zero at z = 1 rad/s forces S(1) = 1 for every
    // stabilising K, so ‖W_S S‖∞ ≥ |W_S(1)| (maximum modulus) and γ_opt ≥ |W_S(1)|. As the
    // actuator weight ρ → 0 the S/KS optimum tends to that bound (the one-block
    // Nevanlinna–Pick value).
    let g = tf(&[-1.0, 1.0], &[1.0, 2.0, 1.0]);
    let ws = performance_weight(0.3 / (2.0 * std::f64::consts::PI), 2.0, 1e-3, 1e3).unwrap();
    let bound = mag_at(&ws, 1.0);
    let mut prev = f64::INFINITY;
    for rho in [1e-1, 1e-2, 1e-3] {
        let w = MixedSensitivityWeights {
            ws: ws.clone(),
            wks: rho,
            wt: None,
        };
        let d = hinf_mixed_sensitivity(&g, &w, HinfOptions::default()).unwrap();
        eprintln!(
            "rho {rho:e}: gamma in [{:.6}, {:.6}], built at {:.6}, closed loop {:.6}, bound \
             {bound:.6}, residuals {:.2e} {:.2e}",
            d.gamma_lower,
            d.gamma_upper,
            d.gamma,
            d.closed_loop.gamma,
            d.riccati_residuals.0,
            d.riccati_residuals.1
        );
        // Necessary: nothing beats the interpolation bound.
        assert!(d.closed_loop.gamma >= bound * (1.0 - 1e-9));
        assert!(d.gamma_upper >= bound * (1.0 - 1e-3));
        // Independent closed loop within the design level.
        assert!(d.closed_loop.gamma <= d.gamma * (1.0 + 1e-6));
        // The level declared not achievable is not beaten by the controller found.
        assert!(d.closed_loop.gamma >= d.gamma_lower);
        assert!(
            d.gamma_upper <= prev * (1.0 + 1e-3),
            "γ must not grow as ρ shrinks"
        );
        prev = d.gamma_upper;
        if rho == 1e-1 && d.controller.is_stable(0.0).unwrap() {
            let n = d.controller.n_states();
            let r = balanced_truncation(&d.controller, n - 1).unwrap();
            let err = hinf_norm(&d.controller.parallel(&r.reduced.clone_negated()).unwrap())
                .unwrap()
                .gamma;
            eprintln!(
                "controller {n} → {} states: ‖K − K_r‖∞ = {err:.4e}, σ_n = {:.4e}, bound {:.4e}",
                n - 1,
                r.hankel_singular_values[n - 1],
                r.error_bound
            );
            assert!(err <= r.error_bound * (1.0 + 1e-6));
            assert!(err >= r.hankel_singular_values[n - 1] * (1.0 - 1e-6));
        }
    }
    assert!(
        prev <= bound * 1.05,
        "γ {prev} vs interpolation bound {bound}"
    );
}

#[test]
fn two_mass_design_with_uncertainty_weight_meets_its_level() {
    // The bundled two-mass model (examples/data/two_mass_sim.json: motor speed from torque) with
    // a W_m rising through 1 near 60 Hz; bandwidth 8 Hz, M_s 1.6, actuator 0.3 N·m for 5 rad/s.
    let g = two_mass();
    let w0 = 2.0 * std::f64::consts::PI * 60.0;
    let wm = tf(&[1.0 / w0, 0.1], &[1.0 / (4.0 * w0), 1.0]);
    let w = MixedSensitivityWeights {
        ws: performance_weight(8.0, 1.6, 1e-3, 1e3).unwrap(),
        wks: 5.0 / 0.3,
        wt: Some(wm),
    };
    let d = hinf_mixed_sensitivity(&g, &w, HinfOptions::default()).unwrap();
    let (norm, lp) = weighted_closed_loop_norm(&g, &d.controller, &w).unwrap();
    eprintln!(
        "two-mass: gamma [{:.5}, {:.5}] at {:.5}; closed loop {:.5}; M_s {:.4}; residuals {:.2e} {:.2e}",
        d.gamma_lower,
        d.gamma_upper,
        d.gamma,
        norm.gamma,
        hinf_norm(&lp.s).unwrap().gamma,
        d.riccati_residuals.0,
        d.riccati_residuals.1
    );
    assert!(norm.gamma <= d.gamma * (1.0 + 1e-6));
    assert!(d.riccati_residuals.0 < 1e-9 && d.riccati_residuals.1 < 1e-9);
    // γ < 1: every weighted requirement holds. Read them back from the loop independently.
    assert!(d.gamma < 1.0, "γ = {}", d.gamma);
    let ms = hinf_norm(&lp.s).unwrap().gamma;
    let ks = hinf_norm(&lp.ks).unwrap().gamma;
    let m = margins(&lp.l, None).unwrap();
    eprintln!(
        "two-mass H∞: order {}, crossover {:?} Hz, PM {:.1}°, GM {:.1} dB, M_s {ms:.4}, ‖KS‖∞ {ks:.4e}",
        d.controller.n_states(),
        m.gain_crossover_hz,
        m.phase_margin_deg,
        m.gain_margin_db
    );
    assert!(ms <= 1.6 && ks <= 0.3 / 5.0);
    eprintln!(
        "two-mass H∞: all gain crossovers {:?} Hz; controller poles {:?}",
        m.gain_crossovers_hz,
        d.controller.poles().unwrap()
    );
    // Balanced truncation to a firmware order where the controller allows it (stable K);
    // an unstable central controller is refused with a clear error instead.
    if d.controller.is_stable(0.0).unwrap() {
        let r = balanced_truncation(&d.controller, 4).unwrap();
        let err = hinf_norm(&d.controller.parallel(&r.reduced.clone_negated()).unwrap())
            .unwrap()
            .gamma;
        eprintln!(
            "controller → 4 states: ‖K − K_r‖∞ = {err:.4e} (bound {:.4e})",
            r.error_bound
        );
        assert!(err <= r.error_bound * (1.0 + 1e-6));
    } else {
        let e = balanced_truncation(&d.controller, 4).unwrap_err();
        assert!(e.to_string().contains("stable"), "{e}");
    }
}

#[test]
fn strictly_proper_ws_and_positive_wks_are_required() {
    let g = tf(&[1.0], &[1.0, 1.0]);
    let w = MixedSensitivityWeights {
        ws: tf(&[1.0, 1.0], &[1.0, 0.01]),
        wks: 1.0,
        wt: None,
    };
    let e = hinf_mixed_sensitivity(&g, &w, HinfOptions::default()).unwrap_err();
    assert!(e.to_string().contains("strictly proper"), "{e}");
    let w = MixedSensitivityWeights {
        ws: tf(&[1.0], &[1.0, 0.01]),
        wks: 0.0,
        wt: None,
    };
    let e = hinf_mixed_sensitivity(&g, &w, HinfOptions::default()).unwrap_err();
    assert!(e.to_string().contains("W_KS"), "{e}");
}

/// examples/data/two_mass_sim.json: motor speed (rad/s) from torque (N·m).
fn two_mass() -> StateSpace {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/two_mass_sim.json");
    let data: StateSpaceData =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    StateSpace::try_from(&data).unwrap()
}

fn chain(n_modes: usize) -> StateSpace {
    // Sum of lightly damped modes with decaying residues: many small Hankel values.
    let mut sys: Option<StateSpace> = None;
    for k in 0..n_modes {
        let wn = 2.0 * (k as f64 + 1.0).powf(1.5);
        let part = tf(
            &[wn / (k as f64 + 1.0).powi(2)],
            &[1.0, 2.0 * 0.05 * wn, wn * wn],
        );
        sys = Some(match sys {
            None => part,
            Some(s) => s.parallel(&part).unwrap(),
        });
    }
    sys.unwrap()
}

#[test]
fn balanced_truncation_error_lies_between_the_hankel_bounds() {
    let g = chain(5);
    for order in [2, 4, 6, 8] {
        let r = balanced_truncation(&g, order).unwrap();
        let err = hinf_norm(&g.parallel(&r.reduced.clone_negated()).unwrap())
            .unwrap()
            .gamma;
        let lower = r.hankel_singular_values[order];
        eprintln!(
            "order {order}: ‖G − G_r‖∞ = {err:.4e}, σ_(r+1) = {lower:.4e}, bound {:.4e}",
            r.error_bound
        );
        assert!(r.reduced.is_stable(0.0).unwrap());
        assert!(err <= r.error_bound * (1.0 + 1e-6), "error above 2Σσ");
        assert!(err >= lower * (1.0 - 1e-6), "error below σ_(r+1)");
    }
}

#[test]
fn discrete_truncation_and_order_from_bound() {
    let g = chain(4).c2d_zoh(0.01).unwrap();
    let r = balanced_truncation_to_bound(&g, 0.1).unwrap();
    let err = hinf_norm(&g.parallel(&r.reduced.clone_negated()).unwrap())
        .unwrap()
        .gamma;
    eprintln!(
        "discrete: order {} of {}, err {err:.4e}, bound {:.4e}, hsv {:?}",
        r.reduced.n_states(),
        g.n_states(),
        r.error_bound,
        r.hankel_singular_values
    );
    assert!(r.error_bound <= 0.1);
    assert!(err <= r.error_bound * (1.0 + 1e-6));
    assert!(r.reduced.n_states() < g.n_states());
    let e = balanced_truncation(&tf(&[1.0], &[1.0, -1.0]), 1).unwrap_err();
    assert!(e.to_string().contains("stable"), "{e}");
}

trait Negate {
    fn clone_negated(&self) -> StateSpace;
}
impl Negate for StateSpace {
    fn clone_negated(&self) -> StateSpace {
        let mut s = self.clone();
        s.c = &s.c * faer::Scale(-1.0);
        s.d = &s.d * faer::Scale(-1.0);
        s
    }
}
