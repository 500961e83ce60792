//! H∞ mixed sensitivity on the bundled two-mass model: controller poles and the closed-loop
//! norm against the design level as the backoff from γ_opt and the weights change (issue 14).
//!
//!   cargo run --release -p ferrosid --example hinf_study
use ferrosid::lti::{StateSpace, StateSpaceData, TransferFunction};
use ferrosid::synth::hinf::{
    hinf_mixed_sensitivity, performance_weight, HinfOptions, MixedSensitivityWeights,
};
use std::f64::consts::PI;

fn main() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data/two_mass_sim.json");
    let data: StateSpaceData =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let g = StateSpace::try_from(&data).unwrap();
    println!("plant poles (Hz, ζ):");
    for p in g.poles().unwrap() {
        println!(
            "  {:.3} Hz ζ {:.4}",
            p.norm() / (2.0 * PI),
            -p.re / p.norm()
        );
    }
    let w0 = 2.0 * PI * 60.0;
    let wm = TransferFunction::new(vec![1.0 / w0, 0.1], vec![1.0 / (4.0 * w0), 1.0], 0.0)
        .unwrap()
        .to_state_space()
        .unwrap();
    for (label, wt) in [("W_T = W_m", Some(wm.clone())), ("no W_T", None)] {
        for backoff in [0.0, 0.01, 0.05, 0.2, 1.0] {
            let w = MixedSensitivityWeights {
                ws: performance_weight(8.0, 1.6, 1e-3, 1e3).unwrap(),
                wks: 5.0 / 0.3,
                wt: wt.clone(),
            };
            let opt = HinfOptions {
                backoff,
                stable_controller: false,
                ..Default::default()
            };
            match hinf_mixed_sensitivity(&g, &w, opt) {
                Ok(d) => {
                    let unstable: Vec<String> = d
                        .controller
                        .poles()
                        .unwrap()
                        .iter()
                        .filter(|p| p.re > 0.0 && p.im >= 0.0)
                        .map(|p| format!("{:.2} Hz (Re {:.3e})", p.norm() / (2.0 * PI), p.re))
                        .collect();
                    println!(
                        "{label}, backoff {backoff}: γ [{:.5}, {:.5}] at {:.5}, closed loop {:.5}; \
                         unstable K poles {:?}",
                        d.gamma_lower, d.gamma_upper, d.gamma, d.closed_loop.gamma, unstable
                    );
                }
                Err(e) => println!("{label}, backoff {backoff}: {e}"),
            }
        }
    }
}
