//! Receipts against closed-form loops, and end to end on a tuned sampled loop.
use ferrosid::lti::{StateSpace, TransferFunction};
use ferrosid::robust::pid::{tune_pid, Pid, PidTuningSpec};
use ferrosid::robust::receipts::{
    compute_receipts, Comparison, CrossValidation, EtfeView, Receipt, ReceiptInputs, ReceiptLimits,
};
use ferrosid::robust::uncertainty::{fit_uncertainty_weight, WeightFitOptions};
use num_complex::Complex64;
use std::f64::consts::PI;

use crate::test_models::p_only;

fn ss(num: &[f64], den: &[f64]) -> StateSpace {
    TransferFunction::new(num.to_vec(), den.to_vec(), 0.0)
        .unwrap()
        .to_state_space()
        .unwrap()
}

fn inputs<'a>(plant: &'a StateSpace, pid: &'a Pid, fc: f64) -> ReceiptInputs<'a> {
    ReceiptInputs {
        plant,
        pid,
        controller_ts: None,
        crossover_hz: fc,
        weight: None,
        actuator_limit: 100.0,
        actuator_unit: "A",
        reference_amplitude: 1.0,
        etfe: None,
        cross_validation: None,
        limits: ReceiptLimits::for_crossover(fc),
        anti_windup: true,
    }
}

fn get<'a>(r: &'a ferrosid::robust::receipts::Receipts, name: &str) -> &'a Receipt {
    r.get(name)
        .unwrap_or_else(|| panic!("receipt {name} missing"))
}

#[test]
fn proportional_control_of_type_one_plant_closed_forms() {
    // L = K/(s(s + 1)), K = 4: GM = ∞, PM = 90° − atan(ω_gc), T standard second order with
    // ωn = 2, ζ = 1/4: M_t = 1/(2ζ√(1−ζ²)); |S| = −3 dB at ω² = (−(1+2K) + √((1+2K)² + 4K²))/2;
    // ‖KS‖∞ = K·M_s.
    let k = 4.0;
    let plant = ss(&[1.0], &[1.0, 1.0, 0.0]);
    let pid = p_only(k);
    let wgc = (((1.0f64 + 4.0 * k * k).sqrt() - 1.0) / 2.0).sqrt();
    let fc = wgc / (2.0 * PI);
    let rep = compute_receipts(&inputs(&plant, &pid, fc)).unwrap();
    let r = &rep.receipts;
    assert!(get(r, "closed_loop_stable").pass);
    let gm = get(r, "gain_margin");
    assert!(gm.value.is_infinite() && gm.pass && gm.value_text.starts_with("inf"));
    let pm = get(r, "phase_margin");
    assert!(
        (pm.value - (90.0 - wgc.atan().to_degrees())).abs() < 1e-8,
        "{pm:?}"
    );
    let zeta: f64 = 0.25;
    let mt = get(r, "complementary_sensitivity_peak");
    assert!(
        (mt.value - 1.0 / (2.0 * zeta * (1.0 - zeta * zeta).sqrt())).abs() < 1e-7,
        "{mt:?}"
    );
    assert!(
        !mt.pass && !r.all_pass,
        "M_t = 2.07 must fail the 1.5 limit"
    );
    let w3 = ((-(1.0 + 2.0 * k) + ((1.0 + 2.0 * k).powi(2) + 4.0 * k * k).sqrt()) / 2.0).sqrt();
    let bw = get(r, "disturbance_rejection_bandwidth");
    assert!(
        (bw.value - w3 / (2.0 * PI)).abs() < 1e-9,
        "{bw:?} vs {}",
        w3 / (2.0 * PI)
    );
    let ms = get(r, "sensitivity_peak").value;
    let ks = get(r, "peak_control_effort");
    assert!((ks.value - k * ms).abs() < 1e-7 * k * ms, "{ks:?}");
    assert_eq!(ks.unit, "A");
    assert!(r.get("robust_stability").is_none() && r.get("etfe_phase_agreement").is_none());
}

#[test]
fn weight_etfe_and_cross_validation_receipts() {
    // Plant 10/(s + 10) with PI; ETFE = plant with a 1 ms delay: phase error 360·f·τ degrees,
    // largest at the highest gated bin below 2 f_c.
    let plant = ss(&[10.0], &[1.0, 10.0]);
    let pid = Pid {
        kp: 1.0,
        ki: 20.0,
        kd: 0.0,
        tau_f: 0.0,
        rolloff: None,
    };
    let fc = 3.0;
    let tau = 1e-3;
    let f: Vec<f64> = (1..=100).map(|k| 0.25 * k as f64).collect();
    let h: Vec<Complex64> = f
        .iter()
        .map(|&f| {
            let s = Complex64::new(0.0, 2.0 * PI * f);
            10.0 / (s + 10.0) * (-s * tau).exp()
        })
        .collect();
    // Gate out 5.75 Hz and everything above 5.5 Hz stays outside 2 f_c = 6 Hz anyway.
    let gate: Vec<bool> = f.iter().map(|&f| f != 5.75 && f != 6.0).collect();
    // A constant weight 0.3: ‖W T‖∞ = 0.3·M_t.
    let fw: Vec<f64> = (1..=20).map(|k| k as f64).collect();
    let wm = fit_uncertainty_weight(
        &fw,
        &[0.3; 20],
        &WeightFitOptions {
            order: 1,
            ..Default::default()
        },
    )
    .unwrap();
    let mut inp = inputs(&plant, &pid, fc);
    inp.weight = Some(&wm);
    inp.etfe = Some(EtfeView {
        freq_hz: &f,
        h: &h,
        gate: Some(&gate),
    });
    inp.cross_validation = Some(CrossValidation {
        fit_percent: 87.5,
        limit_percent: 90.0,
        detail: "run 3".into(),
    });
    let rep = compute_receipts(&inp).unwrap();
    let r = &rep.receipts;
    let pa = get(r, "etfe_phase_agreement");
    assert!((pa.value - 360.0 * 5.5 * tau).abs() < 1e-9, "{pa:?}");
    assert!(pa.pass);
    let p = rep.phase_agreement.as_ref().unwrap();
    assert_eq!(p.bins_used, 22);
    assert!(p
        .slices
        .iter()
        .all(|s| s.max_abs_error_deg <= 360.0 * s.f_hi_hz * tau + 1e-9));
    let mt = get(r, "complementary_sensitivity_peak").value;
    let rs = get(r, "robust_stability");
    let wlev = wm.magnitude_hz(1.0);
    assert!(
        (wlev - 0.3).abs() < 1e-6,
        "constant weight fitted as {wlev}"
    );
    assert!(
        (rs.value - wlev * mt).abs() < 1e-6,
        "{rs:?} vs {}",
        wlev * mt
    );
    assert_eq!(rs.comparison, Comparison::LessThan);
    let cv = get(r, "cross_validation_fit");
    assert!(!cv.pass && cv.value == 87.5 && cv.limit == 90.0);
    assert!(!r.all_pass);
    assert_eq!(
        r.failed().count(),
        r.receipts.iter().filter(|x| !x.pass).count()
    );
}

#[test]
fn saturated_step_rail_obviously_hit_and_obviously_not() {
    let plant = ss(&[1.0], &[1.0, 1.0, 0.0]);
    let pid = p_only(0.5); // slow, well damped: u(0+) = 0.5 per unit step
    let fc = 0.07;
    let mut inp = inputs(&plant, &pid, fc);
    inp.actuator_limit = 10.0; // 20× headroom
    let rep = compute_receipts(&inp).unwrap();
    let r = get(&rep.receipts, "step_actuator_demand");
    assert!(r.pass && (r.value - 0.05).abs() < 1e-9, "{r:?}");
    let s = rep.step.as_ref().unwrap();
    assert!(!s.hits_rail);
    inp.actuator_limit = 0.05; // 10× too small
    let rep = compute_receipts(&inp).unwrap();
    let r = get(&rep.receipts, "step_actuator_demand");
    assert!(!r.pass && (r.value - 10.0).abs() < 1e-9, "{r:?}");
    assert!(rep.step.as_ref().unwrap().u.iter().all(|u| u.abs() <= 0.05));
    assert!(!rep.receipts.all_pass);
}

#[test]
fn unstable_loop_fails_without_erroring() {
    // K/(s+1)³ with K = 10 > 8 is unstable in closed loop.
    let plant = ss(&[1.0], &[1.0, 3.0, 3.0, 1.0]);
    let pid = p_only(10.0);
    let rep = compute_receipts(&inputs(&plant, &pid, 0.3)).unwrap();
    let r = &rep.receipts;
    assert!(!get(r, "closed_loop_stable").pass);
    assert!(get(r, "sensitivity_peak").value.is_infinite());
    assert!(!r.all_pass);
    let js = serde_json::to_value(r).unwrap();
    assert_eq!(js["schema"], "ferrosid.receipts/1");
    let ms = js["receipts"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["name"] == "sensitivity_peak")
        .unwrap();
    assert!(ms["value"].is_null() && ms["pass"] == false);
}

#[test]
fn tuned_sampled_dc_motor_passes_its_receipts() {
    let (j, b, ts) = (0.01, 0.1, 5e-4);
    let plant = ss(&[1.0], &[j, b, 0.0]);
    let mut spec = PidTuningSpec::new(40.0);
    spec.controller_ts = Some(ts);
    spec.rolloff_ratio = Some((8.0, 0.7));
    let t = tune_pid(&plant, &spec).unwrap();
    let fc = t.design.crossover_hz;
    let mut inp = inputs(&plant, &t.pid, fc);
    inp.controller_ts = Some(ts);
    inp.limits.mt_max = 1.6;
    inp.limits.overshoot_pct_max = 40.0;
    inp.limits.settling_time_s_max = 60.0 / fc;
    inp.actuator_limit = 1e3;
    inp.reference_amplitude = 0.01;
    let rep = compute_receipts(&inp).unwrap();
    for r in &rep.receipts.receipts {
        println!(
            "{:32} {:>16} {} {:<10} {}",
            r.name,
            r.value_text,
            r.comparison.symbol(),
            r.limit,
            if r.pass { "PASS" } else { "FAIL" }
        );
    }
    assert!((get(&rep.receipts, "sensitivity_peak").value - t.ms).abs() < 1e-6 * t.ms);
    assert!(
        rep.receipts.all_pass,
        "{:?}",
        rep.receipts.failed().collect::<Vec<_>>()
    );
    let d = rep.discrete_controller.as_ref().unwrap();
    assert_eq!(d, t.discrete.as_ref().unwrap());
    let js = serde_json::to_string(&rep).unwrap();
    assert!(js.contains("\"step_settling_time\""));
}

#[test]
fn bad_inputs_are_clear_errors() {
    let plant = ss(&[1.0], &[1.0, 1.0, 0.0]);
    let pid = p_only(1.0);
    let mut inp = inputs(&plant, &pid, 0.1);
    inp.actuator_limit = 0.0;
    assert!(compute_receipts(&inp).is_err_and(|e| e.to_string().contains("actuator limit")));
    let mut inp = inputs(&plant, &pid, f64::NAN);
    inp.limits = ReceiptLimits::for_crossover(1.0);
    assert!(compute_receipts(&inp).is_err_and(|e| e.to_string().contains("crossover")));
    let mut inp = inputs(&plant, &pid, 0.1);
    inp.reference_amplitude = -1.0;
    assert!(compute_receipts(&inp).is_err_and(|e| e.to_string().contains("reference amplitude")));
    let f = [1.0, 2.0];
    let h = [Complex64::new(1.0, 0.0)];
    let mut inp = inputs(&plant, &pid, 0.1);
    inp.etfe = Some(EtfeView {
        freq_hz: &f,
        h: &h,
        gate: None,
    });
    assert!(compute_receipts(&inp).is_err_and(|e| e.to_string().contains("must agree")));
}
