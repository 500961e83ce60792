//! Saturated closed-loop step against closed-form discrete responses.
use ferrosid::lti::{StateSpace, TransferFunction};
use ferrosid::robust::pid::Pid;
use ferrosid::robust::step::{saturated_step, StepSpec};

use crate::test_models::p_only;

fn integrator(ts: f64) -> StateSpace {
    // y[k+1] = y[k] + ts·u[k]: G(z) = ts/(z − 1).
    TransferFunction::new(vec![ts], vec![1.0, -1.0], ts)
        .unwrap()
        .to_state_space()
        .unwrap()
}

#[test]
fn unsaturated_proportional_loop_matches_geometric_closed_form() {
    let (ts, kp, r) = (1e-3, 50.0, 2.0);
    let ctrl = p_only(kp).discretize(ts, None).unwrap();
    let spec = StepSpec {
        amplitude: r,
        actuator_limit: 1e3,
        duration_s: 0.2,
        anti_windup: true,
        settle_band: 0.02,
    };
    let s = saturated_step(&integrator(ts), &ctrl, &spec).unwrap();
    let q = 1.0 - kp * ts;
    for (k, &y) in s.y.iter().enumerate() {
        let exact = r * (1.0 - q.powi(k as i32));
        assert!((y - exact).abs() < 1e-12, "k={k}: {y} vs {exact}");
    }
    assert!(!s.hits_rail);
    assert!((s.peak_demand_ratio - kp * r / 1e3).abs() < 1e-12);
    assert_eq!(s.overshoot_pct, 0.0);
    // Settling: y[k] within 2 % once q^k <= 0.02.
    let k_settle = (0.02f64.ln() / q.ln()).ceil() as usize;
    assert!(
        (s.settling_time_s.unwrap() - k_settle as f64 * ts).abs() < 1e-12,
        "{:?}",
        s.settling_time_s
    );
    assert!(s.final_error.abs() < 1e-3);
}

#[test]
fn saturated_proportional_loop_ramps_at_the_rail() {
    // With u clamped at L the integrator ramps y[k] = k·ts·L while kp(r − y) >= L.
    let (ts, kp, r, lim) = (1e-3, 50.0, 2.005, 10.0);
    let ctrl = p_only(kp).discretize(ts, None).unwrap();
    let spec = StepSpec {
        amplitude: r,
        actuator_limit: lim,
        duration_s: 0.5,
        anti_windup: true,
        settle_band: 0.02,
    };
    let s = saturated_step(&integrator(ts), &ctrl, &spec).unwrap();
    assert!(s.hits_rail);
    assert!((s.peak_demand_ratio - kp * r / lim).abs() < 1e-12);
    let k_rail = ((r - lim / kp) / (ts * lim)).floor() as usize; // last k with demand >= L
    assert_eq!(s.samples_at_rail, k_rail + 1);
    for k in 0..=k_rail {
        assert!((s.y[k] - k as f64 * ts * lim).abs() < 1e-12);
        assert_eq!(s.u[k], lim);
    }
    assert!(s.u.iter().all(|u| u.abs() <= lim));
    assert_eq!(s.overshoot_pct, 0.0);
}

#[test]
fn feedthrough_plant_solves_the_algebraic_loop() {
    // y = D·u (no states) with u = kp(r − y): u = kp r/(1 + kp D); saturated: y = D·L.
    let ts = 1e-3;
    let (d, kp, r) = (0.5, 4.0, 1.0);
    let g = StateSpace::gain(faer::Mat::from_fn(1, 1, |_, _| d), ts).unwrap();
    let ctrl = p_only(kp).discretize(ts, None).unwrap();
    let spec = StepSpec {
        amplitude: r,
        actuator_limit: 100.0,
        duration_s: 0.01,
        anti_windup: true,
        settle_band: 0.02,
    };
    let s = saturated_step(&g, &ctrl, &spec).unwrap();
    let u = kp * r / (1.0 + kp * d);
    assert!((s.u[0] - u).abs() < 1e-9 && (s.y[0] - d * u).abs() < 1e-9);
    let spec = StepSpec {
        actuator_limit: 1.0,
        ..spec
    };
    let s = saturated_step(&g, &ctrl, &spec).unwrap();
    assert!((s.y[0] - d * 1.0).abs() < 1e-9 && s.hits_rail);
}

#[test]
fn anti_windup_reduces_overshoot_of_a_saturated_pi_loop() {
    let ts = 1e-3;
    let pi = Pid {
        kp: 20.0,
        ki: 200.0,
        kd: 0.0,
        tau_f: 0.0,
        rolloff: None,
    };
    let ctrl = pi.discretize(ts, None).unwrap();
    let spec = StepSpec {
        amplitude: 1.0,
        actuator_limit: 2.0,
        duration_s: 3.0,
        anti_windup: false,
        settle_band: 0.02,
    };
    let wound = saturated_step(&integrator(ts), &ctrl, &spec).unwrap();
    let aw = saturated_step(
        &integrator(ts),
        &ctrl,
        &StepSpec {
            anti_windup: true,
            ..spec
        },
    )
    .unwrap();
    assert!(wound.hits_rail && aw.hits_rail);
    assert!(
        wound.overshoot_pct > aw.overshoot_pct + 5.0,
        "{} vs {}",
        wound.overshoot_pct,
        aw.overshoot_pct
    );
}

#[test]
fn bad_inputs_are_clear_errors() {
    let ts = 1e-3;
    let ctrl = p_only(1.0).discretize(ts, None).unwrap();
    let spec = StepSpec {
        amplitude: 1.0,
        actuator_limit: 1.0,
        duration_s: 0.1,
        anti_windup: true,
        settle_band: 0.02,
    };
    let cont = TransferFunction::new(vec![1.0], vec![1.0, 0.0], 0.0)
        .unwrap()
        .to_state_space()
        .unwrap();
    assert!(saturated_step(&cont, &ctrl, &spec).is_err_and(|e| e.to_string().contains("discrete")));
    assert!(saturated_step(&integrator(2e-3), &ctrl, &spec)
        .is_err_and(|e| e.to_string().contains("controller ts")));
    let e = |s: StepSpec| match saturated_step(&integrator(ts), &ctrl, &s) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("accepted {s:?}"),
    };
    assert!(e(StepSpec {
        amplitude: 0.0,
        ..spec
    })
    .contains("amplitude"));
    assert!(e(StepSpec {
        actuator_limit: -1.0,
        ..spec
    })
    .contains("actuator limit"));
    assert!(e(StepSpec {
        duration_s: 1e-4,
        ..spec
    })
    .contains("samples"));
    assert!(e(StepSpec {
        settle_band: 0.0,
        ..spec
    })
    .contains("settling band"));
    // An unstable open-loop plant (pole at z = 2) with a bounded command diverges.
    let unstable = TransferFunction::new(vec![1.0], vec![1.0, -2.0], ts)
        .unwrap()
        .to_state_space()
        .unwrap();
    let s = StepSpec {
        duration_s: 10.0,
        ..spec
    };
    match saturated_step(&unstable, &ctrl, &s) {
        Err(e) => assert!(e.to_string().contains("diverged"), "{e}"),
        Ok(r) => panic!("no divergence detected, final y = {}", r.y.last().unwrap()),
    }
}
