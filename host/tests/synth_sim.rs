//! The general saturated-step simulation against the PID one (a second implementation):
//! identical with a PID law and a unit filter, and equal in the linear range with the PID's
//! transfer function run as a state-space law.
use ferrosid::lti::{StateSpace, TransferFunction};
use ferrosid::robust::pid::Pid;
use ferrosid::robust::step::{saturated_step, StepSpec};
use ferrosid::synth::sim::{saturated_step_general, DiscreteLaw, SsFilter};

fn plant(d: f64) -> StateSpace {
    // 100/((s/(2π·1.5) + 1)(s/(2π·40) + 1)) + d, ZOH at 1 kHz.
    let (a, b) = (
        2.0 * std::f64::consts::PI * 1.5,
        2.0 * std::f64::consts::PI * 40.0,
    );
    let num = if d == 0.0 {
        vec![100.0 * a * b]
    } else {
        vec![d, d * (a + b), d * a * b + 100.0 * a * b]
    };
    TransferFunction::new(num, vec![1.0, a + b, a * b], 0.0)
        .unwrap()
        .to_state_space()
        .unwrap()
        .c2d_zoh(1e-3)
        .unwrap()
}

fn pid() -> Pid {
    Pid {
        kp: 0.05,
        ki: 0.8,
        kd: 2e-4,
        tau_f: 2e-3,
        rolloff: None,
    }
}

#[test]
fn pid_law_with_unit_filter_matches_the_pid_simulation_exactly() {
    for d in [0.0, 0.5] {
        let g = plant(d);
        let dp = pid().discretize(1e-3, Some(8.0)).unwrap();
        for anti_windup in [true, false] {
            let spec = StepSpec {
                amplitude: 5.0,
                actuator_limit: 0.1, // saturates: the anti-windup path is exercised
                duration_s: 2.0,
                anti_windup,
                settle_band: 0.02,
            };
            let a = saturated_step(&g, &dp, &spec).unwrap();
            let law = DiscreteLaw::PidThenFilter {
                pid: dp.clone(),
                state: Default::default(),
                filter: SsFilter::new(&StateSpace::identity(1, 1e-3).unwrap()).unwrap(),
                anti_windup,
            };
            let b = saturated_step_general(&g, law, &spec).unwrap();
            assert!(a.samples_at_rail > 10, "the rail is hit");
            for k in 0..a.y.len() {
                assert!(
                    (a.y[k] - b.y[k]).abs() <= 1e-9 * (1.0 + a.y[k].abs()),
                    "y[{k}]"
                );
                assert!((a.u[k] - b.u[k]).abs() <= 1e-9, "u[{k}]");
            }
            assert_eq!(a.samples_at_rail, b.samples_at_rail);
            assert!((a.overshoot_pct - b.overshoot_pct).abs() < 1e-6);
            assert_eq!(a.settling_time_s, b.settling_time_s);
        }
    }
}

#[test]
fn state_space_law_equals_the_pid_in_the_linear_range() {
    let g = plant(0.0);
    let dp = pid().discretize(1e-3, Some(8.0)).unwrap();
    let spec = StepSpec {
        amplitude: 1.0,
        actuator_limit: 1e6,
        duration_s: 1.0,
        anti_windup: false,
        settle_band: 0.02,
    };
    let a = saturated_step(&g, &dp, &spec).unwrap();
    let law = DiscreteLaw::StateSpace(SsFilter::new(&dp.to_state_space().unwrap()).unwrap());
    let b = saturated_step_general(&g, law, &spec).unwrap();
    let peak = a.y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for k in 0..a.y.len() {
        assert!(
            (a.y[k] - b.y[k]).abs() <= 1e-8 * peak,
            "y[{k}] {} vs {}",
            a.y[k],
            b.y[k]
        );
    }
    assert!(!b.hits_rail);
    // Bad input: a continuous controller, a zero amplitude.
    let cont = pid().to_state_space().unwrap();
    assert!(SsFilter::new(&cont)
        .unwrap_err()
        .to_string()
        .contains("discrete"));
    let mut bad = spec;
    bad.amplitude = 0.0;
    let law = DiscreteLaw::StateSpace(SsFilter::new(&dp.to_state_space().unwrap()).unwrap());
    let e = saturated_step_general(&g, law, &bad)
        .unwrap_err()
        .to_string();
    assert!(e.contains("amplitude"), "{e}");
}
