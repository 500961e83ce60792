//! Limit cycles of tuned loops with diagnosed nonlinearities: describing-function prediction
//! against the simulated nonlinear loop, and the compensation that removes them.
//!
//! Loops (controller sample time 1 ms):
//! * **friction loop** — a speed plant with a second-order actuator lag,
//!   G(s) = 200·ω_a²/((0.2 s + 1)(s² + 1.4 ω_a s + ω_a²)), ω_a = 2π·40 rad/s (rad/s per N·m),
//!   PI tuned by `tune_pid` for 5 Hz crossover; Coulomb friction 0.008 N·m on the output
//!   speed. The actuator lag takes G/(1 + CG) through −180° near 40 Hz: a friction chatter.
//! * **dead-zone loop** — the positioning axis of `ferrosid_sim::plant` (2 kg, 10 N·s/m, mm out),
//!   a PID with strong integral action (kp 0.5, ki 10, kd 0.05, τ_f 2 ms): the loop gain
//!   passes −180° below crossover with |L| > 1 (conditionally stable), so a 0.5 N dead zone
//!   oscillates.
//! * **backlash loop** — the two-mass actuator of the bundled example, PI with roll-off tuned
//!   for 8 Hz (the pipeline's settings), backlash of 0.02 N·m in the drive.
//!
//! Tolerances: the describing function is a first-harmonic approximation; on these loops it
//! agrees with the simulation within 25 % in frequency and 20 % in amplitude (measured:
//! friction 40.1 vs 39.9 Hz, 0.0312 vs 0.0316 rad/s; dead zone 1.95 vs 1.88 Hz, 0.747 vs
//! 0.654 N; backlash 1.80 vs 1.47 Hz, 0.0123 vs 0.0110 N·m).
mod limit_cycle_support;
use ferrosid::compensation::{design_from, DesignOptions};
use ferrosid::gap::effect::Effect;
use ferrosid::gap::fit::VelocitySource;
use ferrosid::gap::place::{Place, PlacedEffect};
use ferrosid::limit_cycle::*;
use ferrosid::lti::{poly_mul, TransferFunction};
use ferrosid::robust::pid::Pid;
use ferrosid::robust::receipts::ReceiptKind;
use ferrosid_sim::plant::Plant;
use limit_cycle_support::{speed_plant_with_actuator_lag, tuned, unity_p, verdict};
use std::f64::consts::PI;

fn friction_loop() -> LureLoop {
    let g = speed_plant_with_actuator_lag();
    LureLoop::new(&g, &tuned(&g, 5.0, None), VelocitySource::Output).unwrap()
}

fn dead_zone_loop() -> LureLoop {
    let ax = Plant::axis().physical().unwrap().sys;
    let pid = Pid {
        kp: 0.5,
        ki: 10.0,
        kd: 0.05,
        tau_f: 0.002,
        rolloff: None,
    }
    .discretize(1e-3, None)
    .unwrap();
    LureLoop::new(&ax, &pid, VelocitySource::OutputDerivative).unwrap()
}

/// The bundled example's two-mass actuator with the pipeline's PI + roll-off for 8 Hz.
fn two_mass_loop() -> LureLoop {
    let p = Plant::two_mass().physical().unwrap().sys;
    LureLoop::new(
        &p,
        &tuned(&p, 8.0, Some((4.0, 0.7))),
        VelocitySource::Output,
    )
    .unwrap()
}

/// `effect` at `place` as a nonlinearity of the loop.
fn placed(effect: Effect, place: Place) -> Nonlinearity {
    Nonlinearity::from_placed(&PlacedEffect { effect, place }).unwrap()
}

/// The one stable predicted cycle of `a`, after checking that the simulation shows `what`
/// and agrees with it within `f_tol` in frequency and `a_tol` in amplitude.
fn stable_cycle_agrees(
    a: &LimitCycleAnalysis,
    what: &str,
    f_tol: f64,
    a_tol: f64,
) -> PredictedLimitCycle {
    let p = one_stable(a);
    let s = a
        .simulated
        .as_ref()
        .unwrap_or_else(|| panic!("simulation shows {what}"));
    agree(&p, s, f_tol, a_tol);
    p
}

fn one_stable(a: &LimitCycleAnalysis) -> PredictedLimitCycle {
    let s: Vec<_> = a.predicted.iter().filter(|p| p.stable).copied().collect();
    assert_eq!(s.len(), 1, "{:?}", a.predicted);
    s[0]
}

fn agree(p: &PredictedLimitCycle, s: &SimulatedLimitCycle, f_tol: f64, a_tol: f64) {
    assert!(
        (p.freq_hz / s.freq_hz - 1.0).abs() < f_tol,
        "frequency: predicted {} Hz, simulated {} Hz",
        p.freq_hz,
        s.freq_hz
    );
    assert!(
        (p.amplitude / s.amplitude - 1.0).abs() < a_tol,
        "amplitude: predicted {}, simulated {}",
        p.amplitude,
        s.amplitude
    );
}

#[test]
fn friction_cycle_is_predicted_simulated_and_compensated() {
    let lp = friction_loop();
    let nl = placed(Effect::CoulombFriction { level: 0.008 }, Place::Motor);
    // Acceptance: oscillations under half the speed sensor's noise (0.01 rad/s) do not count.
    let opts = AnalysisOptions {
        amplitude_tol: 0.005,
        ..AnalysisOptions::default()
    };
    let before = analyse(&lp, &nl, None, &opts).unwrap();
    let p = stable_cycle_agrees(&before, "the friction cycle", 0.05, 0.1);
    assert!(p.freq_hz > 30.0 && p.freq_hz < 50.0, "{p:?}");
    let r = receipt(&before, "coulomb_friction at motor");
    assert_eq!(r.kind(), Some(ReceiptKind::LimitCycle));
    assert!(!r.pass && r.value == 2.0, "{r:?}");
    assert!(r.detail.contains("Hz"), "{}", r.detail);

    // Compensation designed from the diagnosis, feedforward band 1e-4 rad/s.
    let comp = design_from(
        "coulomb_friction",
        &[verdict("coulomb_friction", "motor", &[("level", 0.008)])],
        0.2,
        0.05,
        &DesignOptions::new("test", 1e-4, 0.05),
    )
    .unwrap();
    assert!(comp.enabled && comp.friction_feedforward.is_some());
    let after = analyse(&lp, &nl, Some(&comp), &opts).unwrap();
    assert!(after.compensated);
    let r = receipt(&after, "coulomb_friction at motor");
    assert!(r.pass, "{}", r.detail);
    // What remains is at least 8x smaller than the cycle it replaces.
    assert!(after.output_tail_half_ptp < before.output_tail_half_ptp / 8.0);
    for p in &after.predicted {
        assert!(p.output_amplitude < 0.005, "{p:?}");
    }
}

#[test]
fn dead_zone_cycle_is_predicted_simulated_and_compensated() {
    let lp = dead_zone_loop();
    let nl = placed(Effect::Deadzone { width: 0.5 }, Place::Drive);
    // Acceptance: 10 µm (0.01 mm) of position.
    let opts = AnalysisOptions {
        amplitude_tol: 0.01,
        ..AnalysisOptions::default()
    };
    let before = analyse(&lp, &nl, None, &opts).unwrap();
    stable_cycle_agrees(&before, "the dead-zone cycle", 0.1, 0.2);
    assert!(!receipt(&before, "deadzone at drive").pass);

    let comp = design_from(
        "deadzone",
        &[verdict("deadzone", "drive", &[("width", 0.5)])],
        0.3,
        0.05,
        &DesignOptions::new("test", 1e-3, 0.05),
    )
    .unwrap();
    assert!(comp.dead_zone_inverse.is_some());
    let after = analyse(&lp, &nl, Some(&comp), &opts).unwrap();
    assert!(receipt(&after, "deadzone at drive").pass, "{:?}", after);
    assert!(after.output_tail_half_ptp < before.output_tail_half_ptp / 100.0);
}

#[test]
fn backlash_cycle_in_the_bundled_example_loop() {
    let lp = two_mass_loop();
    let nl = placed(Effect::Backlash { gap: 0.02 }, Place::Drive);
    let a = analyse(&lp, &nl, None, &AnalysisOptions::default()).unwrap();
    let p = stable_cycle_agrees(&a, "the backlash cycle", 0.25, 0.2);
    // The describing function of the play has a phase lag: the solution is off the real axis.
    assert!(p.df_value.1 < 0.0 && p.refined);
}

#[test]
fn bundled_example_loop_has_no_friction_cycle() {
    // The collocated two-mass speed loop keeps G/(1 + CG) within ±180°: no crossing, and the
    // simulation from a kick of 4 × the friction level settles.
    let lp = two_mass_loop();
    let nl = placed(Effect::CoulombFriction { level: 0.008 }, Place::Motor);
    let a = analyse(&lp, &nl, None, &AnalysisOptions::default()).unwrap();
    assert!(a.predicted.is_empty(), "{:?}", a.predicted);
    assert!(a.simulated.is_none());
    assert!(receipt(&a, "coulomb_friction at motor").pass);
}

/// Relay and a type-1 third-order plant, sampled fast (0.1 ms): the classical textbook case.
/// L(s) = K/(s(s+1)(s+2)) crosses the negative real axis at ω = √2 rad/s where L = −K/6, so
/// with a relay of level M the describing function predicts A = 4M·K/(6π), stable.
#[test]
fn relay_with_third_order_plant_matches_the_closed_form() {
    let k = 6.0;
    let g = TransferFunction::new(vec![k], poly_mul(&[1.0, 0.0], &[1.0, 3.0, 2.0]), 0.0)
        .unwrap()
        .to_state_space()
        .unwrap();
    // Unity feedback through a P controller of gain 1.
    let pid = unity_p(1e-4);
    let lp = LureLoop::new(&g, &pid, VelocitySource::Output).unwrap();
    // An ideal relay on the command.
    let nl = Nonlinearity {
        df: DescribingFunction::Relay { level: 1.0 },
        site: Site::Drive,
    };
    let pr = predict(&lp, &nl, &PredictOptions::default()).unwrap();
    assert_eq!(pr.len(), 1, "{pr:?}");
    let w = 2.0f64.sqrt();
    // Sampling at 0.1 ms shifts the crossing by about ωT/2 of phase: 1e-3 relative.
    assert!(
        (pr[0].freq_hz * 2.0 * PI / w - 1.0).abs() < 2e-3,
        "{:?}",
        pr[0]
    );
    let a = 4.0 * k / (6.0 * PI);
    assert!((pr[0].amplitude / a - 1.0).abs() < 2e-3, "{:?}", pr[0]);
    assert!(pr[0].stable && pr[0].refined);
    // The simulation agrees within 5 % (the relay output is a square wave: its harmonics
    // pass the plant attenuated by 1/27 and less).
    let run = simulate(&lp, &nl, None, &SimSpec::new(60.0, 1.0)).unwrap();
    let s = detect(&run.nl_input, run.ts, &DetectOptions::default()).unwrap();
    agree(&pr[0], &s, 0.05, 0.05);
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let lp = friction_loop();
    let nan = PlacedEffect {
        effect: Effect::CoulombFriction { level: f64::NAN },
        place: Place::Motor,
    };
    let e = Nonlinearity::from_placed(&nan).unwrap_err().to_string();
    assert!(e.contains("level") && e.contains("not finite"), "{e}");
    let e = Nonlinearity::from_placed(&PlacedEffect {
        effect: Effect::TimeDelay { seconds: 0.001 },
        place: Place::Drive,
    })
    .unwrap_err()
    .to_string();
    assert!(e.contains("linear"), "{e}");
    let e = Nonlinearity::from_placed(&PlacedEffect {
        effect: Effect::Backlash { gap: 0.01 },
        place: Place::Drivetrain,
    })
    .unwrap_err()
    .to_string();
    assert!(e.contains("two-mass"), "{e}");
    let bad = Nonlinearity {
        df: DescribingFunction::DeadZone {
            width: f64::INFINITY,
        },
        site: Site::Drive,
    };
    assert!(predict(&lp, &bad, &PredictOptions::default()).is_err());
    assert!(simulate(&lp, &bad, None, &SimSpec::new(1.0, 0.1)).is_err());
    let ok = Nonlinearity {
        df: DescribingFunction::DeadZone { width: 0.1 },
        site: Site::Drive,
    };
    let e = simulate(&lp, &ok, None, &SimSpec::new(f64::NAN, 0.1))
        .unwrap_err()
        .to_string();
    assert!(e.contains("duration"), "{e}");
    let e = predict(
        &lp,
        &ok,
        &PredictOptions {
            n_freq: 2,
            ..PredictOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("n_freq"), "{e}");
    let opts = AnalysisOptions {
        amplitude_tol: -1.0,
        ..AnalysisOptions::default()
    };
    assert!(analyse(&lp, &ok, None, &opts).is_err());
    // A plant whose sample time differs from the controller's.
    let gd = lp.plant.clone();
    let mut pid = lp.controller.clone();
    pid.ts = 2e-3;
    let e = LureLoop::new(&gd, &pid, VelocitySource::Output)
        .unwrap_err()
        .to_string();
    assert!(e.contains("sample time"), "{e}");
    pid.ts = 1e-3;
    pid.kp = f64::NAN;
    assert!(LureLoop::new(&gd, &pid, VelocitySource::Output).is_err());
}
