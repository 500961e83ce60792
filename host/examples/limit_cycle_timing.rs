//! How long the limit-cycle receipt takes on the bundled example's loop: the two-mass actuator
//! of `examples/` (true plant `ferrosid_sim::plant::Plant::two_mass()`), PI with roll-off tuned
//! like `examples/pipeline.toml` (8 Hz target, roll-off at 4 × crossover, M_s 1.6, 1 ms), with the
//! example's Coulomb friction (0.008 N·m at the motor) and, for comparison, 0.02 N·m of drive
//! backlash; plus the friction loop of host/tests/limit_cycle_loops.rs.
//!
//! `cargo run --release -p ferrosid --example limit_cycle_timing` prints, per case, the
//! median wall time of `predict` (default grids) and of `simulate` (20 s, 20,000 samples) over
//! 7 repetitions, and the prediction/simulation figures.
use ferrosid::gap::effect::Effect;
use ferrosid::gap::fit::VelocitySource;
use ferrosid::gap::place::{Place, PlacedEffect};
use ferrosid::limit_cycle::*;
use ferrosid::lti::{poly_mul, StateSpace, TransferFunction};
use ferrosid::robust::pid::{tune_pid, PidTuningSpec};
use ferrosid_sim::plant::Plant;
use std::time::Instant;

fn median_ms(mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..7)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[3]
}

fn case(name: &str, plant: &StateSpace, fc: f64, rolloff: Option<(f64, f64)>, pe: PlacedEffect) {
    let mut spec = PidTuningSpec::new(fc);
    spec.controller_ts = Some(1e-3);
    spec.rolloff_ratio = rolloff;
    let pid = tune_pid(plant, &spec)
        .expect("tuning")
        .discrete
        .expect("discrete");
    let lp = LureLoop::new(plant, &pid, VelocitySource::Output).expect("loop");
    let nl = Nonlinearity::from_placed(&pe).expect("nonlinearity");
    let opts = PredictOptions::default();
    let spec = SimSpec::new(20.0, 4.0 * nl.df.scale());
    let t_pred = median_ms(|| {
        predict(&lp, &nl, &opts).expect("predict");
    });
    let t_sim = median_ms(|| {
        simulate(&lp, &nl, None, &spec).expect("simulate");
    });
    let run = simulate(&lp, &nl, None, &spec).expect("simulate");
    let t_det = median_ms(|| {
        detect(&run.nl_input, run.ts, &DetectOptions::default());
    });
    let pred = predict(&lp, &nl, &opts).expect("predict");
    let sim = detect(&run.nl_input, run.ts, &DetectOptions::default());
    println!("{name}: {pe}");
    println!(
        "  predict {t_pred:.1} ms ({} x {} grid), simulate {t_sim:.1} ms (20,000 samples x {} \
         sub-steps), detect {t_det:.2} ms",
        opts.n_freq,
        opts.n_amp,
        if nl.site == Site::Velocity {
            spec.substeps
        } else {
            1
        }
    );
    for p in &pred {
        println!(
            "  predicted: {:.3} Hz, amplitude {:.4e}, {}",
            p.freq_hz,
            p.amplitude,
            if p.stable { "stable" } else { "unstable" }
        );
    }
    match sim {
        Some(s) => println!(
            "  simulated: {:.3} Hz, amplitude {:.4e}",
            s.freq_hz, s.amplitude
        ),
        None => println!("  simulated: no sustained oscillation"),
    }
}

fn main() {
    let two_mass = Plant::two_mass().physical().expect("plant").sys;
    case(
        "bundled example loop",
        &two_mass,
        8.0,
        Some((4.0, 0.7)),
        PlacedEffect {
            effect: Effect::CoulombFriction { level: 0.008 },
            place: Place::Motor,
        },
    );
    case(
        "bundled example loop",
        &two_mass,
        8.0,
        Some((4.0, 0.7)),
        PlacedEffect {
            effect: Effect::Backlash { gap: 0.02 },
            place: Place::Drive,
        },
    );
    let wa = 2.0 * std::f64::consts::PI * 40.0;
    let lagged = TransferFunction::new(
        vec![200.0 * wa * wa],
        poly_mul(&[0.2, 1.0], &[1.0, 1.4 * wa, wa * wa]),
        0.0,
    )
    .and_then(|t| t.to_state_space())
    .expect("plant");
    case(
        "friction loop (tests)",
        &lagged,
        5.0,
        None,
        PlacedEffect {
            effect: Effect::CoulombFriction { level: 0.008 },
            place: Place::Motor,
        },
    );
}
