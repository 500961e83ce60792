//! PID + notch against plain PID on the bundled two-mass model, same constraints.
use ferrosid::robust::loops::{margins, FeedbackLoop};
use ferrosid::robust::norms::hinf_norm;
use ferrosid::robust::pid::{tune_pid, PidTuningSpec};
use ferrosid::synth::loopshape::{place_notches, tune_pid_notch, Notch};

use crate::test_models::two_mass;

/// The `[control]` section of examples/pipeline.toml: 8 Hz target, roll-off at 4× crossover
/// (ζ 0.7), M_s ≤ 1.6, actuator 0.3 N·m for a 5 rad/s step (‖KS‖∞ ≤ 0.06).
fn spec() -> PidTuningSpec {
    let mut s = PidTuningSpec::new(8.0);
    s.ms_max = 1.6;
    s.rolloff_ratio = Some((4.0, 0.7));
    s.ks_max = Some(0.3 / 5.0);
    s
}

#[test]
fn notch_sits_on_the_resonance_and_attenuates_only_around_it() {
    let g = two_mass();
    let n = place_notches(&g, 8.0, 0.3, None).unwrap();
    assert_eq!(n.len(), 1, "{n:?}");
    let pole = g.poles().unwrap().into_iter().find(|p| p.im > 0.0).unwrap();
    assert!((n[0].centre_hz - pole.norm() / (2.0 * std::f64::consts::PI)).abs() < 1e-9);
    let tf = n[0].transfer_function().unwrap();
    let at = |f: f64| tf.freq_response_hz(f).unwrap().norm();
    assert!((20.0 * at(n[0].centre_hz).log10() - n[0].depth_db()).abs() < 1e-9);
    assert!(at(1.0) > 0.99 && at(1000.0) > 0.99);
    for f in [1.0, 10.0, 30.0, 50.0, 100.0, 300.0] {
        assert!(at(f) <= 1.0 + 1e-12);
    }
    let bad = Notch {
        centre_hz: 50.0,
        zeta_num: 0.5,
        zeta_den: 0.3,
    };
    assert!(bad.transfer_function().is_err());
}

#[test]
fn pid_notch_reaches_a_higher_crossover_than_pid_with_every_constraint() {
    let g = two_mass();
    let s = spec();
    let plain = tune_pid(&g, &s).unwrap();
    let shaped = tune_pid_notch(&g, &s, 0.3).unwrap();
    // Independent re-verification of the plain PID on its loop.
    let k = plain.pid.to_state_space().unwrap();
    let lp = FeedbackLoop::new(&g, &k).unwrap();
    let mp = margins(&lp.l, None).unwrap();
    let fc_plain = mp.gain_crossover_hz.unwrap();
    let fc_notch = shaped.margins.gain_crossover_hz.unwrap();
    eprintln!(
        "plain PID: crossover {fc_plain:.3} Hz, PM {:.1}°, GM {:.1} dB, M_s {:.3}, ‖KS‖∞ {:.4}",
        mp.phase_margin_deg,
        mp.gain_margin_db,
        hinf_norm(&lp.s).unwrap().gamma,
        hinf_norm(&lp.ks).unwrap().gamma
    );
    eprintln!(
        "PID+notch: crossover {fc_notch:.3} Hz (all {:?}), PM {:.1}°, GM {:.1} dB, M_s {:.3}, \
         ‖KS‖∞ {:.4}, notches {:?}",
        shaped.margins.gain_crossovers_hz,
        shaped.margins.phase_margin_deg,
        shaped.margins.gain_margin_db,
        shaped.ms,
        shaped.ks,
        shaped.notches
    );
    assert!(shaped.ms <= 1.6 * (1.0 + 1e-6));
    assert!(shaped.ks <= 0.06 * (1.0 + 1e-6));
    assert!(shaped.margins.phase_margin_deg >= 30.0);
    assert!(shaped.margins.gain_margin_db >= 6.0);
    assert!(fc_notch > fc_plain, "{fc_notch} vs {fc_plain}");
}

#[test]
fn sampled_spec_on_a_continuous_plant_is_refused() {
    let mut s = spec();
    s.controller_ts = Some(1e-3);
    let e = tune_pid_notch(&two_mass(), &s, 0.3).unwrap_err();
    assert!(e.to_string().contains("discrete plant"), "{e}");
}

/// The bundled example end to end: the pipeline's identified model (order 3 at 1 kHz) and
/// fitted W_m, its plain PID, and PID + notch under the same `[control]` limits, with the
/// receipts of [`compute_receipts`] on the shaped loop.
#[test]
fn bundled_example_pid_notch_gains_crossover_with_every_receipt() {
    use ferrosid::pipeline::{run_pipeline, LoadedConfig};
    use ferrosid::robust::receipts::{compute_receipts, ReceiptInputs, ReceiptLimits};
    let toml = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/pipeline.toml");
    if !toml.exists() {
        eprintln!("skipped: {} not found", toml.display());
        return;
    }
    let cfg = LoadedConfig::load(&toml).unwrap();
    let run = run_pipeline(&cfg, &|_| {}).unwrap();
    let k = &run.config.control;
    let plain = run.tuned().expect("the pipeline tunes a PID");
    let mut s = PidTuningSpec::new(k.crossover_hz);
    s.ms_max = k.ms_max;
    s.weight = run.weight().cloned();
    s.ks_max = k
        .limit_control_effort
        .then(|| k.actuator_limit / k.reference_amplitude);
    s.rolloff_ratio = k.rolloff_ratio.map(|r| (r, k.rolloff_zeta));
    s.integral = k.integral;
    s.derivative = k.derivative;
    s.min_crossover_scale = k.min_crossover_scale;
    let d = tune_pid_notch(run.model(), &s, 0.3).unwrap();
    let rep = compute_receipts(&ReceiptInputs {
        plant: &d.shaped_plant,
        pid: &d.pid.pid,
        controller_ts: None,
        crossover_hz: d.pid.design.crossover_hz,
        weight: run.weight(),
        actuator_limit: k.actuator_limit,
        actuator_unit: "N·m",
        reference_amplitude: k.reference_amplitude,
        etfe: None,
        cross_validation: None,
        limits: {
            // As the pipeline sets them (examples/pipeline.toml overrides none of these).
            let mut l = ReceiptLimits::for_crossover(d.pid.design.crossover_hz);
            l.ms_max = k.ms_max;
            l
        },
        anti_windup: k.anti_windup,
    })
    .unwrap();
    eprintln!(
        "bundled example: plain PID {:.3} Hz, PID+notch {:.3} Hz (margins {:?} Hz), notches \
         {:?}, M_s {:.3}, ‖W_m T‖∞ {:?}, ‖KS‖∞ {:.4}",
        plain.design.crossover_hz,
        d.pid.design.crossover_hz,
        d.margins.gain_crossovers_hz,
        d.notches,
        d.ms,
        d.wm_t,
        d.ks
    );
    for r in &rep.receipts.receipts {
        eprintln!(
            "  {} {} (limit {}) {}",
            r.name, r.value_text, r.limit, r.pass
        );
    }
    let failed: Vec<_> = rep.receipts.failed().map(|r| r.name.clone()).collect();
    assert!(failed.is_empty(), "failed receipts: {failed:?}");
    assert!(d.pid.design.crossover_hz > plain.design.crossover_hz * 1.05);
}
