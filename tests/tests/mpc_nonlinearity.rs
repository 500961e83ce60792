//! The MPC's host closed-loop simulation with a diagnosed nonlinearity between the MPC and the
//! plant (issue 14: "closed-loop simulation with saturation and the diagnosed nonlinearity"):
//! `ferrosid::synth::mpc::MpcDesign::closed_loop_step_with`. Each effect is checked against an
//! independent per-sample evaluation of its law on the recorded command, and the loop's
//! consequences against closed-form expectations (first-order plant with DC gain 1, an MPC
//! without integral action).
use ferrosid::gap::effect::Effect;
use ferrosid::lti::{StateSpace, TransferFunction};
use ferrosid::synth::mpc::{MpcDesign, MpcSpec};

const TS: f64 = 1e-3;
const R: f64 = 0.2;
const SAMPLES: usize = 1500;

/// G(z) = 0.05/(z − 0.95): DC gain 1, time constant ≈ 19.5 ms.
fn plant() -> StateSpace {
    TransferFunction::new(vec![0.05], vec![1.0, -0.95], TS)
        .unwrap()
        .to_state_space()
        .unwrap()
}

fn design(p: &StateSpace) -> MpcDesign {
    MpcDesign::new(
        p,
        MpcSpec {
            horizon: 10,
            q: 1.0,
            r_rate: 0.01,
            u_min: -0.3,
            u_max: 0.3,
            du_max: 0.05,
            rho: 1.0,
            iterations: 60,
        },
    )
    .unwrap()
}

#[test]
fn plant_input_drives_the_plant_and_without_an_effect_it_is_the_command() {
    let p = plant();
    let d = design(&p);
    let b = d.closed_loop_step_with(&p, None, R, SAMPLES, 0.02).unwrap();
    assert_eq!(b.plant_input, b.step.u);
    // With a dead zone, the recorded output is the plant's response to the recorded plant
    // input (re-simulated here from the transfer function y[k+1] = 0.95 y[k] + 0.05 w[k]).
    let z = d
        .closed_loop_step_with(&p, Some(&Effect::Deadzone { width: 0.1 }), R, SAMPLES, 0.02)
        .unwrap();
    let mut y = 0.0;
    for k in 0..SAMPLES {
        assert!(
            (z.step.y[k] - y).abs() <= 1e-12,
            "sample {k}: {} vs {y}",
            z.step.y[k]
        );
        y = 0.95 * y + 0.05 * z.plant_input[k];
    }
}

#[test]
fn each_effect_acts_on_the_plant_input_by_its_own_law() {
    let p = plant();
    let d = design(&p);
    let plain = d.closed_loop_step(&p, R, SAMPLES, 0.02).unwrap();
    // Saturation below the MPC's box (above the steady input r/G(1) = 0.2): the plant never
    // sees more than 0.22, the command does (the MPC does not know the effect), and the
    // response is slower.
    let s = d
        .closed_loop_step_with(
            &p,
            Some(&Effect::Saturation { limit: 0.22 }),
            R,
            SAMPLES,
            0.02,
        )
        .unwrap();
    for (w, u) in s.plant_input.iter().zip(&s.step.u) {
        assert_eq!(*w, u.clamp(-0.22, 0.22));
        assert!(u.abs() <= 0.3 * (1.0 + 1e-12));
    }
    assert!(s.step.u.iter().any(|u| u.abs() > 0.22));
    let t90 = |y: &[f64]| y.iter().position(|v| *v >= 0.9 * R).unwrap();
    assert!(t90(&s.step.y) > t90(&plain.step.y));
    // Dead zone of full width 0.1: w = sign(u)·max(|u| − 0.05, 0); with no integral action the
    // output settles at the DC gain times the last plant input (G(1) = 1), below r.
    let z = d
        .closed_loop_step_with(&p, Some(&Effect::Deadzone { width: 0.1 }), R, SAMPLES, 0.02)
        .unwrap();
    for (w, u) in z.plant_input.iter().zip(&z.step.u) {
        assert!((w - u.signum() * (u.abs() - 0.05).max(0.0)).abs() <= 1e-15);
    }
    let (y_end, w_end) = (*z.step.y.last().unwrap(), *z.plant_input.last().unwrap());
    assert!((y_end - w_end).abs() <= 1e-6, "{y_end} vs G(1)·w = {w_end}");
    assert!(y_end < R - 1e-3, "offset without integral action: {y_end}");
    // Time delay of 3 samples: w[k] = u[k − 3].
    let t = d
        .closed_loop_step_with(
            &p,
            Some(&Effect::TimeDelay { seconds: 3.0 * TS }),
            R,
            SAMPLES,
            0.02,
        )
        .unwrap();
    for k in 0..SAMPLES {
        let want = if k >= 3 { t.step.u[k - 3] } else { 0.0 };
        assert_eq!(t.plant_input[k], want);
    }
    // Coulomb friction 0.02 against the output's sign: at rest after the step, w = u − 0.02,
    // and the output settles below the reference by the friction's share.
    let f = d
        .closed_loop_step_with(
            &p,
            Some(&Effect::CoulombFriction { level: 0.02 }),
            R,
            SAMPLES,
            0.02,
        )
        .unwrap();
    let (y, u, w) = (
        *f.step.y.last().unwrap(),
        *f.step.u.last().unwrap(),
        *f.plant_input.last().unwrap(),
    );
    assert!((w - (u - 0.02)).abs() <= 1e-12, "{w} vs {u} − 0.02");
    assert!(
        (y - w).abs() <= 1e-6 && y < *plain.step.y.last().unwrap() - 1e-3,
        "{y}"
    );
    // Rails and rate limit of the command hold under every effect.
    for run in [&s, &z, &t, &f] {
        let mut prev = 0.0;
        for u in &run.step.u {
            assert!(u.abs() <= 0.3 * (1.0 + 1e-12) && (u - prev).abs() <= 0.05 * (1.0 + 1e-9));
            prev = *u;
        }
    }
}

#[test]
fn effects_that_need_the_subsampled_plant_are_refused() {
    let p = plant();
    let d = design(&p);
    let e = d
        .closed_loop_step_with(
            &p,
            Some(&Effect::Stiction {
                level: 0.01,
                breakaway: 0.02,
                stribeck_velocity: 0.0,
            }),
            R,
            SAMPLES,
            0.02,
        )
        .unwrap_err();
    assert!(e.to_string().contains("stiction"), "{e}");
}
