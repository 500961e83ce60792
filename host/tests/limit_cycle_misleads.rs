//! The describing function is not to be trusted without the simulation: stiction in a
//! position loop with integral action hunts (stick, integrator winds up to the breakaway
//! level, slip, overshoot, stick again), a cycle the describing function cannot see — for a
//! sinusoidal velocity the Karnopp law only slides, so its describing function is the Coulomb
//! relay at the sliding level, and −1/N never meets the linear part of this loop.
//!
//! Loop: the positioning axis of `ferrosid_sim::plant` (2 kg, 10 N·s/m, output mm), PID kp
//! 0.3 N/mm, ki 5 N/(mm·s), kd 0.03 N·s/mm, τ_f 2 ms, 1 ms sample time; stiction sliding 0.5 N,
//! breakaway 1.0 N. Measured: hunting at 1.15 Hz, velocity first harmonic 10.9 mm/s.
mod limit_cycle_support;
use ferrosid::gap::effect::Effect;
use ferrosid::gap::fit::VelocitySource;
use ferrosid::gap::place::{Place, PlacedEffect};
use ferrosid::limit_cycle::*;
use ferrosid::robust::pid::Pid;
use ferrosid_sim::plant::Plant;
use limit_cycle_support::unity_p;

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
            stribeck_velocity: 0.0,
        },
        place: Place::Motor,
    })
    .unwrap();
    // The describing function sees only the sliding level.
    assert_eq!(
        stiction.df.eval(0.3),
        DescribingFunction::Relay { level: 0.5 }.eval(0.3)
    );
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

/// Sampling alone makes a relay loop oscillate: a first-order plant K/(τs + 1) never reaches
/// −180° in continuous time, but its ZOH equivalent is real and negative at the Nyquist
/// frequency, L(−1) = −K(1 − a)/(1 + a) with a = e^{−T/τ}. Evaluated at z = e^{jωT} the
/// describing function finds that period-2 cycle; its amplitude 4M|L(−1)|/π is 4/π too large,
/// because at the Nyquist frequency the relay's sampled output ±M *is* its fundamental (the
/// sinusoidal-input describing function assumes a continuous sinusoid). The simulation gives
/// the exact Y = M|L(−1)|.
#[test]
fn sampling_makes_a_nyquist_cycle_whose_amplitude_the_describing_function_overstates() {
    use ferrosid::lti::TransferFunction;
    let (k, tau, ts, m) = (2.0, 0.01, 1e-3, 0.5);
    let g = TransferFunction::new(vec![k], vec![tau, 1.0], 0.0)
        .unwrap()
        .to_state_space()
        .unwrap();
    let pid = unity_p(ts);
    let lp = LureLoop::new(&g, &pid, VelocitySource::Output).unwrap();
    let nl = Nonlinearity {
        df: DescribingFunction::Relay { level: m },
        site: Site::Drive,
    };
    let a = (-ts / tau).exp();
    let l_nyq = k * (1.0 - a) / (1.0 + a);
    let pr = predict(&lp, &nl, &PredictOptions::default()).unwrap();
    assert_eq!(pr.len(), 1, "{pr:?}");
    assert!((pr[0].freq_hz - 0.5 / ts).abs() < 1e-6 / ts, "{:?}", pr[0]);
    let df_amp = 4.0 * m * l_nyq / std::f64::consts::PI;
    assert!(
        (pr[0].amplitude / df_amp - 1.0).abs() < 1e-6,
        "{:?} vs {df_amp}",
        pr[0]
    );
    let run = simulate(&lp, &nl, None, &SimSpec::new(2.0, 0.1)).unwrap();
    let s = detect(&run.nl_input, run.ts, &DetectOptions::default()).unwrap();
    assert!((s.freq_hz - 0.5 / ts).abs() < 1e-3 / ts, "{s:?}");
    // The command u = −y alternates ±M·|L(−1)|.
    assert!(
        (s.amplitude / (m * l_nyq) - 1.0).abs() < 1e-6,
        "{s:?} vs {}",
        m * l_nyq
    );
}
