//! The simulator's own checks (moved with it from the library, unchanged): closed-form steady
//! states of the plants, the friction and delay laws as simulated, the drivetrain integration
//! against the exact linear plant, and the SplitMix64 reference values and normal moments.
use ferrosid::gap::effect::Effect;
use ferrosid::gap::modal::nrmse;
use ferrosid_sim::plant::{simulate, simulate_drivetrain_backlash, Plant, SimSettings};
use ferrosid_sim::rng::Rng;

fn settings() -> SimSettings {
    SimSettings {
        ts: 1e-3,
        substeps: 8,
        noise_std: 0.0,
        seed: 1,
    }
}

#[test]
fn dc_motor_step_settles_at_the_closed_form_gain() {
    // ω/V at DC = kt / (r·b + kt·ke).
    let p = Plant::dc_motor();
    let Plant::DcMotor(m) = p else { unreachable!() };
    let y = simulate(&p, None, &vec![1.0; 3000], &settings()).unwrap();
    let gain = m.kt / (m.r * m.b + m.kt * m.ke);
    assert!(
        (y[2999] - gain).abs() < 1e-6 * gain,
        "{} vs {gain}",
        y[2999]
    );
}

#[test]
fn flexure_step_settles_at_compliance() {
    let p = Plant::flexure();
    let Plant::Flexure(f) = p else { unreachable!() };
    let y = simulate(&p, None, &vec![2.0; 20000], &settings()).unwrap();
    let want = 2.0 / f.k * 1e6;
    assert!((y[19999] - want).abs() < 1e-6 * want);
}

#[test]
fn friction_holds_below_breakaway_and_slides_above() {
    let p = Plant::two_mass();
    let fr = Effect::Stiction {
        level: 0.02,
        breakaway: 0.05,
        stribeck_velocity: 0.0,
    };
    // 0.04 < breakaway: never moves.
    let y = simulate(&p, Some(&fr), &vec![0.04; 2000], &settings()).unwrap();
    assert!(y.iter().all(|v| v.abs() < 1e-12));
    // 0.06 > breakaway: slides; steady speed (0.06 − 0.02)/(bm + bl).
    let y = simulate(&p, Some(&fr), &vec![0.06; 8000], &settings()).unwrap();
    let want = 0.04 / (2e-3 + 3e-3);
    assert!(
        (y[7999] - want).abs() < 1e-3 * want,
        "{} vs {want}",
        y[7999]
    );
}

#[test]
fn dc_motor_friction_label_is_in_volts() {
    // Coulomb level 0.3 V: at 0.25 V the motor stays put, at 1 V it turns at
    // (1 − 0.3)·kt/(r·b + kt·ke).
    let p = Plant::dc_motor();
    let Plant::DcMotor(m) = p else { unreachable!() };
    let fr = Effect::CoulombFriction { level: 0.3 };
    let y = simulate(&p, Some(&fr), &vec![0.25; 2000], &settings()).unwrap();
    assert!(y.iter().all(|v| v.abs() < 1e-12));
    let y = simulate(&p, Some(&fr), &vec![1.0; 3000], &settings()).unwrap();
    let want = 0.7 * m.kt / (m.r * m.b + m.kt * m.ke);
    assert!(
        (y[2999] - want).abs() < 1e-4 * want,
        "{} vs {want}",
        y[2999]
    );
}

/// Without play the Heun two-mass integration agrees with the exact linear model.
#[test]
fn drivetrain_simulation_without_play_is_the_linear_plant() {
    let p = Plant::two_mass();
    let Plant::TwoMass(tm) = p else {
        unreachable!()
    };
    let mut rng = Rng::new(4);
    let u: Vec<f64> = (0..4000).map(|_| 0.05 * rng.normal()).collect();
    let y0 = simulate(&p, None, &u, &settings()).unwrap();
    let y1 = simulate_drivetrain_backlash(&tm, 0.0, &u, &settings()).unwrap();
    let e = nrmse(&y0, &y1, 0);
    assert!(e < 2e-3, "nrmse {e}");
    // With play the motor runs free inside it: a different response.
    let y2 = simulate_drivetrain_backlash(&tm, 2e-3, &u, &settings()).unwrap();
    assert!(nrmse(&y0, &y2, 0) > 0.05);
}

#[test]
fn delay_shifts_the_response() {
    let p = Plant::flexure();
    let mut u = vec![0.0; 400];
    u[10] = 1.0;
    let y0 = simulate(&p, None, &u, &settings()).unwrap();
    let y1 = simulate(
        &p,
        Some(&Effect::TimeDelay { seconds: 5e-3 }),
        &u,
        &settings(),
    )
    .unwrap();
    for k in 0..395 {
        assert!((y1[k + 5] - y0[k]).abs() < 1e-9 * (1.0 + y0[k].abs()));
    }
}

#[test]
fn splitmix_reference_values() {
    // First outputs for seed 0 from the reference C implementation (Vigna, splitmix64.c).
    let mut r = Rng::new(0);
    assert_eq!(r.next_u64(), 0xE220_A839_7B1D_CDAF);
    assert_eq!(r.next_u64(), 0x6E78_9E6A_A1B9_65F4);
}

#[test]
fn normal_moments() {
    let mut r = Rng::new(42);
    let n = 200_000;
    let v: Vec<f64> = (0..n).map(|_| r.normal()).collect();
    let m = v.iter().sum::<f64>() / n as f64;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n as f64;
    // Standard errors: 1/√n ≈ 0.0022 for the mean, √(2/n) ≈ 0.0032 for the variance.
    assert!(m.abs() < 0.01 && (var - 1.0).abs() < 0.015, "{m} {var}");
}
