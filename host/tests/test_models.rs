//! Models and closed forms shared by the LTI, robust and synthesis tests: the bundled two-mass
//! model, a transfer function as state space, a P-only PID, and Horner evaluation and the
//! Routh–Hurwitz test written here, independent of the library's polynomial code.
#![allow(dead_code)]
use ferrosid::lti::{StateSpace, StateSpaceData, TransferFunction};
use ferrosid::robust::pid::Pid;
use ferrosid::robust::uncertainty::WeightFitOptions;
use num_complex::Complex64;

/// num(s)/den(s) (descending powers; `ts` > 0: of z) as a state-space model.
pub fn ss(num: &[f64], den: &[f64], ts: f64) -> StateSpace {
    TransferFunction::new(num.to_vec(), den.to_vec(), ts)
        .unwrap()
        .to_state_space()
        .unwrap()
}

/// examples/data/two_mass_sim.json: motor speed (rad/s) from torque (N·m), continuous.
pub fn two_mass() -> StateSpace {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/two_mass_sim.json");
    let data: StateSpaceData =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    StateSpace::try_from(&data).unwrap()
}

/// A proportional-only controller.
pub fn p_only(kp: f64) -> Pid {
    Pid {
        kp,
        ki: 0.0,
        kd: 0.0,
        tau_f: 0.0,
        rolloff: None,
    }
}

/// p(s) by Horner's rule (descending powers).
pub fn horner(p: &[f64], s: Complex64) -> Complex64 {
    p.iter()
        .fold(Complex64::new(0.0, 0.0), |acc, &c| acc * s + c)
}

/// Routh–Hurwitz for degree <= 3: all roots of `p` (descending powers) in the open left half
/// plane.
pub fn hurwitz(p: &[f64]) -> bool {
    let a: Vec<f64> = p.iter().map(|c| c / p[0]).collect();
    match a.len() {
        2 => a[1] > 0.0,
        3 => a[1] > 0.0 && a[2] > 0.0,
        4 => a[1] > 0.0 && a[2] > 0.0 && a[3] > 0.0 && a[1] * a[2] > a[3],
        _ => panic!("degree {}", a.len() - 1),
    }
}

/// The default W_m fit options with `order`.
pub fn weight_order(order: usize) -> WeightFitOptions {
    WeightFitOptions {
        order,
        ..Default::default()
    }
}
