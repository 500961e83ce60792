//! Compensation design from gap verdicts: which part each diagnosed effect gets, disabled for
//! `none`/`unexplained`, and clear errors for bad diagnoses and options.
mod limit_cycle_support;
use ferrosid::compensation::{design_from, parse_verdict, ControlStep, DesignOptions};
use ferrosid::gap::report::VerdictEffect;
use ferrosid::robust::pid::Pid;
use limit_cycle_support::verdict as ve;

fn opts() -> DesignOptions {
    DesignOptions::new("ferrosid gap on a.csv,b.csv", 0.01, 0.05)
}

#[test]
fn each_effect_gets_its_part() {
    let c = design_from(
        "stiction+deadzone",
        &[
            ve("stiction", "motor", &[("level", 0.02), ("breakaway", 0.05)]),
            ve("deadzone", "drive", &[("width", 0.4)]),
        ],
        0.3,
        0.04,
        &opts(),
    )
    .unwrap();
    assert!(c.enabled);
    let ff = c.friction_feedforward.unwrap();
    // The feedforward cancels the sliding level (the breakaway is not a steady force).
    assert_eq!(
        (ff.coulomb, ff.viscous, ff.smoothing_velocity),
        (0.02, 0.0, 0.01)
    );
    let dz = c.dead_zone_inverse.unwrap();
    assert_eq!(dz.width, 0.4);
    assert!((dz.smoothing - 0.004).abs() < 1e-15);
    assert_eq!(c.provenance.effect, "stiction+deadzone");
    // One place per effect, in the order of `effect`.
    assert_eq!(c.provenance.place, "motor+drive");
    assert_eq!(c.provenance.nrmse_before, Some(0.3));
    assert_eq!(c.provenance.nrmse_after, Some(0.04));
    assert_eq!(c.provenance.source, "ferrosid gap on a.csv,b.csv");

    let c = design_from(
        "saturation",
        &[ve("saturation", "drive", &[("limit", 0.25)])],
        0.3,
        0.04,
        &opts(),
    )
    .unwrap();
    let aw = c.anti_windup.unwrap();
    assert_eq!(
        (aw.u_min, aw.u_max, aw.tracking_time_s),
        (-0.25, 0.25, 0.05)
    );

    let c = design_from(
        "backlash",
        &[ve("backlash", "drive", &[("gap", 0.1)])],
        0.3,
        0.04,
        &opts(),
    )
    .unwrap();
    assert_eq!(c.backlash_inverse.unwrap().gap, 0.1);
}

#[test]
fn no_compensation_where_the_place_does_not_allow_it_or_the_verdict_is_none() {
    // Backlash in the drivetrain cannot be undone from the command; quantization is a sensor
    // effect: the result is a disabled block.
    for (v, e) in [
        ("backlash", ve("backlash", "drivetrain", &[("gap", 0.1)])),
        (
            "quantization",
            ve("quantization", "sensor", &[("step", 0.01)]),
        ),
    ] {
        let c = design_from(v, &[e], 0.3, 0.04, &opts()).unwrap();
        assert!(!c.enabled && c.backlash_inverse.is_none(), "{c:?}");
    }
    for v in ["none", "unexplained"] {
        let c = design_from(v, &[], 0.3, f64::NAN, &opts()).unwrap();
        assert!(!c.enabled);
        assert_eq!(c.provenance.verdict, v);
        assert_eq!(c.provenance.effect, "");
        assert_eq!(c.provenance.nrmse_after, None);
        // The control law with a disabled block is the plain PID.
        let pid = Pid {
            kp: 2.0,
            ki: 0.0,
            kd: 0.0,
            tau_f: 0.0,
            rolloff: None,
        }
        .discretize(1e-3, None)
        .unwrap();
        let mut step = ControlStep::new(&pid, Some(&c)).unwrap();
        assert!(!step.compensated());
        assert_eq!(step.step(1.0, 0.25), 1.5);
    }
}

#[test]
fn bad_diagnoses_and_options_are_clear_errors() {
    let err = |v: &str, e: &[VerdictEffect], o: &DesignOptions| {
        design_from(v, e, 0.3, 0.1, o).unwrap_err().to_string()
    };
    let e = err("", &[], &opts());
    assert!(e.contains("verdict is empty"), "{e}");
    let e = err("coulomb_friction", &[], &opts());
    assert!(e.contains("verdict_effects is empty"), "{e}");
    let e = err(
        "coulomb_friction",
        &[ve("coulomb_friction", "motor", &[("level", f64::NAN)])],
        &opts(),
    );
    assert!(
        e.contains("coulomb_friction") && e.contains("level") && e.contains("not finite"),
        "{e}"
    );
    let e = err(
        "coulomb_friction",
        &[ve("coulomb_friction", "motor", &[("lvl", 0.1)])],
        &opts(),
    );
    assert!(e.contains("parameter level is missing"), "{e}");
    let e = err(
        "deadzone",
        &[ve("deadzone", "drive", &[("width", -1.0)])],
        &opts(),
    );
    assert!(e.contains("width must be > 0"), "{e}");
    let e = err("magic", &[ve("magic", "drive", &[])], &opts());
    assert!(e.contains("unknown effect"), "{e}");
    let e = err(
        "deadzone",
        &[ve("deadzone", "elsewhere", &[("width", 0.1)])],
        &opts(),
    );
    assert!(e.contains("unknown place"), "{e}");
    let mut o = opts();
    o.velocity_resolution = f64::INFINITY;
    let e = err("none", &[], &o);
    assert!(e.contains("velocity_resolution"), "{e}");
    let mut o = opts();
    o.inverse_smoothing_rel = 0.0;
    assert!(err("none", &[], &o).contains("inverse_smoothing_rel"));
    let mut o = opts();
    o.tracking_time_s = -1.0;
    assert!(err("none", &[], &o).contains("tracking_time_s"));
    // A parsed verdict keeps the order and places.
    let p = parse_verdict(
        "deadzone+coulomb_friction",
        &[
            ve("deadzone", "drive", &[("width", 0.1)]),
            ve("coulomb_friction", "motor", &[("level", 0.01)]),
        ],
    )
    .unwrap();
    assert_eq!(p.len(), 2);
    assert_eq!(p[1].place.name(), "motor");
}
