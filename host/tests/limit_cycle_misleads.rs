//! The describing function is not to be trusted without the simulation: stiction in a
//! position loop with integral action hunts (stick, integrator winds up to the breakaway
//! level, slip, overshoot, stick again), a cycle the describing function cannot see — for a
//! sinusoidal velocity the Karnopp law only slides, so its describing function is the Coulomb
//! relay at the sliding level, and −1/N never meets the linear part of this loop.
//!
//! Loop: the positioning axis of `gap::plant` (2 kg, 10 N·s/m, output mm), PID kp 0.3 N/mm,
//! ki 5 N/(mm·s), kd 0.03 N·s/mm, τ_f 2 ms, 1 ms sample time; stiction sliding 0.5 N,
//! breakaway 1.0 N. Measured: hunting at 1.15 Hz, velocity first harmonic 10.9 mm/s.
use ferrosid::gap::effect::Effect;
use ferrosid::gap::fit::VelocitySource;
use ferrosid::gap::place::{Place, PlacedEffect};
use ferrosid::gap::plant::Plant;
use ferrosid::limit_cycle::*;
use ferrosid::robust::pid::Pid;

#[test]
fn stiction_hunting_is_missed_by_the_describing_function_and_found_by_simulation() {
    let ax = Plant::axis().physical().unwrap().sys;
    let pid = Pid {
        kp: 0.3,
        ki: 5.0,
        kd: 0.03,
        tau_f: 0.002,
        rolloff: None,
    }
    .discretize(1e-3, None)
    .unwrap();
    let lp = LureLoop::new(&ax, &pid, VelocitySource::OutputDerivative).unwrap();
    let stiction = Nonlinearity::from_placed(&PlacedEffect {
        effect: Effect::Stiction {
            level: 0.5,
            breakaway: 1.0,
        },
        place: Place::Motor,
    })
    .unwrap();
    // The describing function sees only the sliding level.
    assert_eq!(stiction.df.eval(0.3), DescribingFunction::Relay { level: 0.5 }.eval(0.3));
    let a = analyse(&lp, &stiction, None, &AnalysisOptions::default()).unwrap();
    assert!(a.predicted.is_empty(), "{:?}", a.predicted);
    let s = a.simulated.expect("the simulation finds the hunting cycle");
    assert!(s.freq_hz > 0.5 && s.freq_hz < 3.0, "{s:?}");
    assert!(s.amplitude > 1.0, "{s:?}");
    // So the receipt fails on the simulation alone.
    let r = receipt(&a, "stiction at motor");
    assert!(!r.pass && r.value == 1.0, "{}", r.detail);
    assert!(r.detail.contains("no intersection"), "{}", r.detail);
}
