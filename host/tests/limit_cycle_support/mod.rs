//! Shared helpers of the limit-cycle and compensation tests: the friction loop's plant, a
//! PID tuned at the 1 ms controller rate, a unity P controller, and a gap verdict effect.
#![allow(dead_code)]
use ferrosid::gap::report::VerdictEffect;
use ferrosid::lti::{poly_mul, StateSpace, TransferFunction};
use ferrosid::robust::pid::{tune_pid, DiscretePid, Pid, PidTuningSpec};
use std::collections::BTreeMap;
use std::f64::consts::PI;

/// Controller sample time of every loop in these tests, s.
pub const TS: f64 = 1e-3;

/// The friction loop's speed plant with a second-order actuator lag (continuous):
/// G(s) = 200·ω_a²/((0.2 s + 1)(s² + 1.4 ω_a s + ω_a²)), ω_a = 2π·40 rad/s (rad/s per N·m).
pub fn speed_plant_with_actuator_lag() -> StateSpace {
    let wa = 2.0 * PI * 40.0;
    TransferFunction::new(
        vec![200.0 * wa * wa],
        poly_mul(&[0.2, 1.0], &[1.0, 1.4 * wa, wa * wa]),
        0.0,
    )
    .unwrap()
    .to_state_space()
    .unwrap()
}

/// PID (with the optional roll-off) tuned by `tune_pid` for crossover `fc` Hz, discretised at
/// [`TS`].
pub fn tuned(plant: &StateSpace, fc: f64, rolloff: Option<(f64, f64)>) -> DiscretePid {
    let mut spec = PidTuningSpec::new(fc);
    spec.controller_ts = Some(TS);
    spec.rolloff_ratio = rolloff;
    tune_pid(plant, &spec).unwrap().discrete.unwrap()
}

/// Unity proportional controller discretised at `ts` s.
pub fn unity_p(ts: f64) -> DiscretePid {
    Pid {
        kp: 1.0,
        ki: 0.0,
        kd: 0.0,
        tau_f: 0.0,
        rolloff: None,
    }
    .discretize(ts, None)
    .unwrap()
}

/// A verdict effect with full share.
pub fn verdict(effect: &str, place: &str, params: &[(&str, f64)]) -> VerdictEffect {
    VerdictEffect {
        effect: effect.into(),
        place: place.into(),
        params: params
            .iter()
            .map(|(k, v)| (k.to_string(), *v))
            .collect::<BTreeMap<_, _>>(),
        share: 1.0,
    }
}
