//! Friction on the slowest mode (the gap verdict's `velocity_from = "output_slowest_mode"`):
//! the body is the plant's slowest real pole with the plant's static gain; in the 40 Hz
//! actuator-lag speed loop friction on the body leaves no cycle where friction at the input has
//! one (describing function and simulation agree on both); the place is refused where it does
//! not exist.
mod limit_cycle_support;
use ferrosid::gap::fit::VelocitySource;
use ferrosid::limit_cycle::{
    analyse, AnalysisOptions, DescribingFunction, LureLoop, Nonlinearity, Site,
};
use limit_cycle_support::{speed_plant_with_actuator_lag, tuned, TS};

fn body_loop() -> LureLoop {
    let g = speed_plant_with_actuator_lag();
    let pid = tuned(&g, 5.0, None);
    LureLoop::new(&g.c2d_zoh(TS).unwrap(), &pid, VelocitySource::Output)
        .unwrap()
        .with_friction_on_slowest_mode()
        .unwrap()
}

#[test]
fn the_body_is_the_slow_pole_with_the_static_gain() {
    // G(s) = 200·ω_a²/((0.2 s + 1)(s² + 1.4 ω_a s + ω_a²)): body pole −5 rad/s, G(0) = 200.
    let b = body_loop().body.expect("body");
    assert!((b.pole_rad_s + 5.0).abs() < 1e-6, "{b:?}");
    assert!((b.dc_gain - 200.0).abs() < 1e-6 * 200.0, "{b:?}");
}

#[test]
fn friction_on_the_body_has_no_cycle_where_friction_at_the_input_has_one() {
    let lp = body_loop();
    let nl = Nonlinearity {
        df: DescribingFunction::Relay { level: 0.008 },
        site: Site::Velocity,
    };
    let a = analyse(&lp, &nl, None, &AnalysisOptions::default()).unwrap();
    // On the body, B/(1 + C·G) never reaches the negative real axis: neither the describing
    // function nor the simulation finds a cycle.
    assert!(a.predicted.iter().all(|p| !p.stable), "{:?}", a.predicted);
    assert!(a.simulated.is_none(), "{:?}", a.simulated);
    // The same loop with the friction subtracted at the actuator input has the ~40 Hz cycle
    // the describing function predicts and the simulation confirms (within 15 %).
    let at_input = LureLoop::new(&lp.plant, &lp.controller, VelocitySource::Output).unwrap();
    let b = analyse(&at_input, &nl, None, &AnalysisOptions::default()).unwrap();
    let p = b
        .predicted
        .iter()
        .find(|p| p.stable)
        .expect("cycle at the input");
    let sim = b.simulated.expect("simulated cycle at the input");
    assert!((p.freq_hz - 40.1).abs() < 1.0, "{p:?}");
    assert!(
        (sim.freq_hz - p.freq_hz).abs() < 0.15 * p.freq_hz,
        "{sim:?}"
    );
    // The friction path differs from the input's: B/(1 + CG) against G/(1 + CG).
    let w = 2.0 * std::f64::consts::PI * 40.0;
    let (lb, li) = (
        lp.linear_part(Site::Velocity, w).unwrap(),
        at_input.linear_part(Site::Velocity, w).unwrap(),
    );
    assert!((lb - li).norm() > 0.1 * li.norm(), "{lb} vs {li}");
}

#[test]
fn the_place_is_refused_where_it_does_not_exist() {
    let g = speed_plant_with_actuator_lag();
    let pid = tuned(&g, 5.0, None);
    let gd = g.c2d_zoh(TS).unwrap();
    let e = LureLoop::new(&gd, &pid, VelocitySource::OutputDerivative)
        .unwrap()
        .with_friction_on_slowest_mode()
        .unwrap_err()
        .to_string();
    assert!(e.contains("velocity"), "{e}");
    let m = |v: f64| faer::Mat::from_fn(1, 1, |_, _| v);
    let first = ferrosid::lti::StateSpace::new(m(0.99), m(1.0), m(1.0), m(0.0), TS).unwrap();
    let e = LureLoop::new(&first, &pid, VelocitySource::Output)
        .unwrap()
        .with_friction_on_slowest_mode()
        .unwrap_err()
        .to_string();
    assert!(e.contains("two states"), "{e}");
}
