//! Checks of the selection on simulated axes, one per failure shape of issue 9.
use super::cases::{
    make_case, resonance_160_case, run, saturation_friction_case, sensor_clip_case, settings,
    small_quantization_case, stiction_case, y_rms, Case,
};
use super::*;
use crate::gap::simulator::plant::{simulate, simulate_drivetrain_backlash, Plant};

const N: usize = 16384;

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

fn only(s: &Selection) -> (Effect, Place) {
    assert_eq!(s.selected.len(), 1, "{:?}", s.selected);
    (s.selected[0].effect, s.selected[0].place)
}

/// Backlash in the shaft of a two-mass axis (integrated by a different scheme than the
/// candidate): the structure is found in the nominal and the verdict is backlash in the
/// drivetrain with the play within 10 %.
#[test]
fn drivetrain_backlash_is_found_in_the_two_mass_structure() {
    let tm = Plant::two_mass();
    let Plant::TwoMass(p) = tm else {
        unreachable!()
    };
    let ns = 0.01 * y_rms(&tm, 0.05, 120.0);
    let c = make_case(tm, 0.05, 120.0, N, 11, &|u, k| {
        simulate_drivetrain_backlash(&p, 0.003, u, &settings(ns, k)).unwrap()
    });
    assert!(c.structure.is_some());
    let s = run(&c);
    let (e, place) = only(&s);
    assert_eq!(place, Place::Drivetrain);
    let Effect::Backlash { gap } = e else {
        panic!("{e}")
    };
    assert!(rel(gap, 0.003) < 0.1, "gap {gap}");
    assert!(s.selected[0].gap_after < 0.3 * s.gap_linear);
}

/// Quantization after noise at 5 % of the output RMS on a position output in metres
/// (steps of about 4e-5): decided by the lattice although it cannot pass the 10 % margin.
#[test]
fn quantization_is_decided_by_the_lattice_at_small_scale() {
    let (c, step) = small_quantization_case(N);
    let s = run(&c);
    let (e, place) = only(&s);
    assert_eq!(place, Place::Sensor);
    let Effect::Quantization { step: got } = e else {
        panic!("{e}")
    };
    assert!(rel(got, step) < 1e-3, "{got} vs {step}");
    assert!(s.lattice.is_some());
}

/// Karnopp stiction, breakaway 2× the Coulomb level, on the DC motor: stiction with the level
/// within 10 % and the breakaway within the 25 % (friction on the rotor's slowest mode
/// fits it at 0.32: the mode ignores the back-EMF coupling of the rotor to the current).
#[test]
fn stiction_with_a_stick_band_is_told_from_coulomb_friction() {
    let s = run(&stiction_case(N));
    let (e, place) = only(&s);
    assert_eq!(place, Place::Motor);
    let Effect::Stiction {
        level, breakaway, ..
    } = e
    else {
        panic!("{e}")
    };
    assert!(rel(level, 0.2) < 0.1 && rel(breakaway, 0.4) < 0.25, "{e}");
    assert!(s.dwell.is_some());
}

/// A lightly damped mode at 160 Hz in series with the input: found at its frequency.
#[test]
fn lightly_damped_mode_above_130_hz_is_found() {
    let s = run(&resonance_160_case(N));
    let (e, _) = only(&s);
    let Effect::Resonance { freq_hz, damping } = e else {
        panic!("{e}")
    };
    assert!(
        rel(freq_hz, 160.0) < 0.01 && rel(damping, 0.02) < 0.15,
        "{e}"
    );
}

/// A sensor that clips: saturation at the sensor with the clip level.
#[test]
fn sensor_clipping_is_saturation_at_the_sensor() {
    let (c, lim) = sensor_clip_case(N);
    let s = run(&c);
    let (e, place) = only(&s);
    assert_eq!(place, Place::Sensor);
    let Effect::Saturation { limit } = e else {
        panic!("{e}")
    };
    assert!(rel(limit, lim) < 0.01, "{limit} vs {lim}");
}

/// Input saturation and Coulomb friction together: both selected, with shares summing
/// to 1.
#[test]
fn saturation_and_friction_are_selected_as_a_pair() {
    let s = run(&saturation_friction_case(N));
    let kinds: Vec<(EffectKind, Place)> = s
        .selected
        .iter()
        .map(|x| (x.effect.kind(), x.place))
        .collect();
    assert!(
        kinds.contains(&(EffectKind::Saturation, Place::Drive)),
        "{kinds:?}"
    );
    assert!(
        kinds
            .iter()
            .any(|(k, p)| k.is_friction() && *p == Place::Motor),
        "{kinds:?}"
    );
    let total: f64 = s.selected.iter().map(|x| x.share).sum();
    assert!((total - 1.0).abs() < 1e-12);
    assert!(s.selected.iter().all(|x| x.share > 0.0));
}

fn axis_case(seed: u64, u_scale: f64, y_scale: f64) -> Case {
    let ax = Plant::axis();
    let ns = 0.01 * y_rms(&ax, 2.0, 20.0);
    let e = Effect::CoulombFriction { level: 1.0 };
    make_case(ax, 2.0, 20.0, N, seed, &|u, k| {
        let ui: Vec<f64> = u.iter().map(|v| v / u_scale).collect();
        simulate(&ax, Some(&e), &ui, &settings(ns, k))
            .unwrap()
            .into_iter()
            .map(|v| v * y_scale)
            .collect()
    })
}

/// Integrating plant (position output, pole at z = 1): friction acts on the derivative of
/// the position and is fitted within 2 %.
#[test]
fn friction_on_an_integrating_axis() {
    let c = axis_case(21, 1.0, 1.0);
    assert!(c.starts[0].real.contains(&1.0));
    let s = run(&c);
    let (e, place) = only(&s);
    assert_eq!(place, Place::Motor);
    let level = match e {
        Effect::CoulombFriction { level } => level,
        Effect::Stiction { level, .. } => level,
        _ => panic!("{e}"),
    };
    assert!(rel(level, 1.0) < 0.02, "{e}");
    assert_eq!(s.model.velocity, VelocitySource::OutputDerivative);
}

/// No candidate ends worse on the training logs than the linear part it extends.
#[test]
fn candidates_never_score_worse_than_the_linear_model() {
    let c = axis_case(21, 1.0, 1.0);
    let s = run(&c);
    let lin = AugmentedModel::linear(c.starts[0].clone()).cost(&c.td.base, &c.td.u);
    for x in &s.singles {
        assert!(
            x.train_cost <= lin * (1.0 + 1e-9),
            "{:?}: {} > {lin}",
            x.effects,
            x.train_cost
        );
    }
}
