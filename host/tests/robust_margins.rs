//! Classical margins, closed-loop transfers and Tustin discretisation against closed forms.
use ferrosid::lti::{StateSpace, TransferFunction};
use ferrosid::robust::discretize::tustin;
use ferrosid::robust::loops::{margins, FeedbackLoop};
use ferrosid::robust::norms::hinf_norm;
use num_complex::Complex64;
use std::f64::consts::PI;

fn tf(num: &[f64], den: &[f64], ts: f64) -> TransferFunction {
    TransferFunction::new(num.to_vec(), den.to_vec(), ts).unwrap()
}
fn ss(num: &[f64], den: &[f64], ts: f64) -> StateSpace {
    tf(num, den, ts).to_state_space().unwrap()
}

#[test]
fn type_one_second_order_loop() {
    // L = K/(s(s+1)): no phase crossover (GM = ∞); ω_gc² = (√(1+4K²) − 1)/2,
    // PM = 90° − atan(ω_gc), DM = PM/ω_gc.
    for k in [0.5, 1.0, 10.0] {
        let m = margins(&ss(&[k], &[1.0, 1.0, 0.0], 0.0), None).unwrap();
        let wgc = (((1.0f64 + 4.0 * k * k).sqrt() - 1.0) / 2.0).sqrt();
        let pm = 90.0 - wgc.atan().to_degrees();
        assert!(m.gain_margin.is_infinite(), "{m:?}");
        assert!(m.phase_crossover_hz.is_none());
        assert!((m.phase_margin_deg - pm).abs() < 1e-8, "{m:?} vs {pm}");
        assert!((m.gain_crossover_hz.unwrap() * 2.0 * PI - wgc).abs() < 1e-9 * wgc);
        assert!((m.delay_margin_s - pm.to_radians() / wgc).abs() < 1e-8);
        assert_eq!(m.gain_crossovers_hz.len(), 1);
    }
}

#[test]
fn third_order_loops_gain_margin() {
    // K/(s(s+1)(s+2)): phase crossover at √2 rad/s, GM = 6/K.
    let m = margins(&ss(&[2.0], &[1.0, 3.0, 2.0, 0.0], 0.0), None).unwrap();
    assert!((m.gain_margin - 3.0).abs() < 1e-9, "{m:?}");
    assert!((m.gain_margin_db - 20.0 * 3f64.log10()).abs() < 1e-8);
    assert!((m.phase_crossover_hz.unwrap() * 2.0 * PI - 2f64.sqrt()).abs() < 1e-9);
    // K/(s+1)³: phase crossover at √3 rad/s, GM = 8/K.
    let m = margins(&ss(&[4.0], &[1.0, 3.0, 3.0, 1.0], 0.0), None).unwrap();
    assert!((m.gain_margin - 2.0).abs() < 1e-9, "{m:?}");
    assert!((m.phase_crossover_hz.unwrap() * 2.0 * PI - 3f64.sqrt()).abs() < 1e-9);
    // Unstable closed loop (K = 10 > 8): gain margin below one.
    let m = margins(&ss(&[10.0], &[1.0, 3.0, 3.0, 1.0], 0.0), None).unwrap();
    assert!((m.gain_margin - 0.8).abs() < 1e-9);
    assert!(m.phase_margin_deg < 0.0);
}

#[test]
fn phase_lead_crossover_of_a_stable_loop_has_a_positive_margin() {
    // L(s) = 2s/(s + 1): |L| = 1 at ω = 1/√3 where ∠L = 90° − 30° = +60°; the closed loop
    // (s + 1)/(3s + 1) is stable. A phase lead of 120° reaches −1 first (PM = 120°, not
    // 180° + 60° wrapped to −120°); a delay must add 240° of lag: τ = (4π/3)/ω.
    let m = margins(&ss(&[2.0, 0.0], &[1.0, 1.0], 0.0), None).unwrap();
    let w = 1.0 / 3f64.sqrt();
    assert!((m.phase_margin_deg - 120.0).abs() < 1e-7, "{m:?}");
    assert!((m.gain_crossover_hz.unwrap() * 2.0 * PI - w).abs() < 1e-9);
    assert!(
        (m.delay_margin_s - (4.0 * PI / 3.0) / w).abs() < 1e-7,
        "{m:?}"
    );
}

#[test]
fn discrete_integrator_margins() {
    // L(z) = K·ts/(z − 1): phase crossover at Nyquist with GM = 2/(K ts);
    // gain crossover θ = 2 asin(K ts/2), PM = 90° − θ/2.
    let ts = 1e-3;
    let k = 300.0;
    let m = margins(&ss(&[k * ts], &[1.0, -1.0], ts), None).unwrap();
    assert!((m.gain_margin - 2.0 / (k * ts)).abs() < 1e-9, "{m:?}");
    assert!((m.phase_crossover_hz.unwrap() - 0.5 / ts).abs() < 1e-6);
    let theta = 2.0 * (k * ts / 2.0).asin();
    assert!(
        (m.phase_margin_deg - (90.0 - theta.to_degrees() / 2.0)).abs() < 1e-7,
        "{m:?}"
    );
    assert!((m.gain_crossover_hz.unwrap() - theta / ts / (2.0 * PI)).abs() < 1e-7);
}

#[test]
fn closed_loop_transfers_of_a_standard_second_order_loop() {
    // L = ωn²/(s(s + 2ζωn)) gives T = ωn²/(s² + 2ζωn s + ωn²): M_t = 1/(2ζ√(1−ζ²)).
    let (wn, zeta) = (20.0, 0.3);
    let l = ss(&[wn * wn], &[1.0, 2.0 * zeta * wn, 0.0], 0.0);
    let k = StateSpace::identity(1, 0.0).unwrap();
    let lp = FeedbackLoop::new(&l, &k).unwrap();
    assert!(lp.is_stable().unwrap());
    let mt = hinf_norm(&lp.t).unwrap();
    let exact = 1.0 / (2.0 * zeta * (1.0f64 - zeta * zeta).sqrt());
    assert!((mt.gamma - exact).abs() < 1e-7 * exact, "{mt:?}");
    // M_s against an independent golden-section maximisation of the closed form
    // |S|² = ω²(ω² + a²)/((ωn² − ω²)² + a²ω²), a = 2ζωn.
    let a = 2.0 * zeta * wn;
    let s2 = |w: f64| w * w * (w * w + a * a) / ((wn * wn - w * w).powi(2) + a * a * w * w);
    let (mut lo, mut hi) = (1.0, 200.0);
    for _ in 0..200 {
        let m1 = lo + (hi - lo) / 3.0;
        let m2 = hi - (hi - lo) / 3.0;
        if s2(m1) < s2(m2) {
            lo = m1
        } else {
            hi = m2
        }
    }
    let ms_exact = s2(0.5 * (lo + hi)).sqrt();
    let ms = hinf_norm(&lp.s).unwrap();
    assert!(
        (ms.gamma - ms_exact).abs() < 1e-7 * ms_exact,
        "{ms:?} vs {ms_exact}"
    );
    // KS = K S = S here; GS = L S.
    for w in [0.5, 7.0, 40.0] {
        let s = Complex64::new(0.0, w);
        let lv = wn * wn / (s * (s + a));
        let sv = 1.0 / (1.0 + lv);
        assert!((lp.s.freq_response(w).unwrap()[(0, 0)] - sv).norm() < 1e-12);
        assert!((lp.t.freq_response(w).unwrap()[(0, 0)] - lv * sv).norm() < 1e-12);
        assert!((lp.ks.freq_response(w).unwrap()[(0, 0)] - sv).norm() < 1e-12);
        assert!((lp.gs.freq_response(w).unwrap()[(0, 0)] - lv * sv).norm() < 1e-12);
    }
}

#[test]
fn unstable_closed_loop_detected() {
    let l = ss(&[10.0], &[1.0, 3.0, 3.0, 1.0], 0.0);
    let lp = FeedbackLoop::new(&l, &StateSpace::identity(1, 0.0).unwrap()).unwrap();
    assert!(!lp.is_stable().unwrap());
    assert!(lp.stability_abscissa().unwrap() > 0.0);
    assert!(hinf_norm(&lp.s).is_err());
}

#[test]
fn tustin_closed_forms() {
    // 1/s with plain Tustin: (ts/2)(z + 1)/(z − 1).
    let ts = 0.01;
    let d = tustin(&tf(&[1.0], &[1.0, 0.0], 0.0), ts, None).unwrap();
    assert_eq!(d.den.len(), 2);
    assert!((d.num[0] - ts / 2.0).abs() < 1e-15 && (d.num[1] - ts / 2.0).abs() < 1e-15);
    assert!((d.den[1] + 1.0).abs() < 1e-15);
    // Prewarped first-order low-pass: exact at the prewarp frequency and at DC.
    let c = tf(&[50.0], &[1.0, 50.0], 0.0);
    let wp = 2.0 * PI * 30.0;
    let d = tustin(&c, ts, Some(wp)).unwrap();
    let dz = d.freq_response(wp).unwrap();
    let cs = c.freq_response(wp).unwrap();
    assert!((dz - cs).norm() < 1e-12, "{dz} vs {cs}");
    assert!((d.dc_gain().unwrap() - 1.0).abs() < 1e-12);
    // Frequency warping law: G_d(e^{jωts}) = G_c(j c tan(ω ts/2)).
    let cc = wp / (wp * ts / 2.0).tan();
    for w in [3.0, 100.0, 250.0] {
        let a = d.freq_response(w).unwrap();
        let b = c.freq_response(cc * (w * ts / 2.0).tan()).unwrap();
        assert!((a - b).norm() < 1e-12);
    }
    assert!(tustin(&c, ts, Some(PI / ts)).is_err());
    assert!(tustin(&tf(&[1.0, 0.0, 0.0], &[1.0, 1.0], 0.0), ts, None).is_err());
}

#[test]
fn mismatched_sample_times_are_refused() {
    let g = ss(&[1.0], &[1.0, 1.0], 0.01);
    let k = ss(&[1.0], &[1.0, 1.0], 0.02);
    assert!(FeedbackLoop::new(&g, &k)
        .unwrap_err()
        .to_string()
        .contains("sample times"));
}
