//! The compensation stage: limit-cycle receipts before/after and the choice (compensate,
//! widen W_m, keep) for the friction loop of limit_cycle_loops.rs and for verdicts without
//! anything to compensate.
mod limit_cycle_support;
use ferrosid::compensation::DesignOptions;
use ferrosid::gap::report::VerdictEffect;
use ferrosid::limit_cycle::AnalysisOptions;
use ferrosid::lti::StateSpace;
use ferrosid::pipeline::compensation_stage::{
    compensation_stage_from, Choice, CompensationStageOptions,
};
use ferrosid::robust::pid::DiscretePid;
use limit_cycle_support::{speed_plant_with_actuator_lag, tuned, verdict as ve, TS};

fn friction_loop() -> (StateSpace, DiscretePid) {
    let g = speed_plant_with_actuator_lag();
    let pid = tuned(&g, 5.0, None);
    // The loop as the pipeline has it: G0 discrete at the controller rate.
    (g.c2d_zoh(TS).unwrap(), pid)
}

fn opts() -> CompensationStageOptions {
    CompensationStageOptions {
        design: DesignOptions::new("test", 1e-4, 0.05),
        analysis: AnalysisOptions {
            amplitude_tol: 0.005,
            ..AnalysisOptions::default()
        },
        allow_compensation: true,
    }
}

#[test]
fn friction_is_compensated_and_the_receipts_show_it() {
    let (g, pid) = friction_loop();
    let st = compensation_stage_from(
        "coulomb_friction",
        &[ve("coulomb_friction", "motor", &[("level", 0.008)])],
        Some("output"),
        0.2,
        0.05,
        &g,
        &pid,
        &opts(),
    )
    .unwrap();
    assert_eq!(st.choice, Choice::Compensate, "{}", st.reason);
    assert!(st.compensation.enabled);
    let before = st.receipts_before();
    let after = st.receipts_after();
    assert_eq!((before.len(), after.len()), (1, 1));
    assert!(!before[0].pass && after[0].pass, "{before:?} {after:?}");
    assert!(st.reason.contains("gone"), "{}", st.reason);
    // Discrete G0 (d2c for the friction sub-steps) gives the same cycle as the continuous
    // plant in limit_cycle_loops.rs: about 40 Hz.
    let p = st.effects[0]
        .before
        .predicted
        .iter()
        .find(|p| p.stable)
        .unwrap();
    assert!((p.freq_hz - 40.1).abs() < 1.0, "{p:?}");
}

#[test]
fn none_unexplained_and_uncompensable_verdicts() {
    let (g, pid) = friction_loop();
    let run = |v: &str, e: &[VerdictEffect]| {
        compensation_stage_from(v, e, None, 0.2, 0.1, &g, &pid, &opts()).unwrap()
    };
    let st = run("none", &[]);
    assert_eq!(st.choice, Choice::Keep);
    assert!(!st.compensation.enabled && st.effects.is_empty());
    let st = run("unexplained", &[]);
    assert_eq!(st.choice, Choice::WidenWm);
    // Backlash in the drivetrain: neither analysed nor compensated, nothing fails: keep.
    let st = run(
        "backlash",
        &[ve("backlash", "drivetrain", &[("gap", 0.01)])],
    );
    assert_eq!(st.choice, Choice::Keep, "{}", st.reason);
    assert_eq!(st.not_analysed.len(), 1);
    assert!(
        st.not_analysed[0].contains("two-mass"),
        "{:?}",
        st.not_analysed
    );
    // Bad inputs are errors.
    let e = compensation_stage_from("none", &[], Some("speed"), 0.2, 0.1, &g, &pid, &opts())
        .unwrap_err()
        .to_string();
    assert!(e.contains("velocity source"), "{e}");
    assert!(compensation_stage_from(
        "coulomb_friction",
        &[ve("coulomb_friction", "motor", &[("level", f64::NAN)])],
        None,
        0.2,
        0.1,
        &g,
        &pid,
        &opts()
    )
    .is_err());
}
