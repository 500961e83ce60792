//! The compensated control law is implemented twice on purpose (issue 12): in f32 `no_std` in
//! the firmware (`ferrosid_firmware::control`) and in f64 on the host
//! (`ferrosid::compensation::ControlStep`, used by the limit-cycle simulation). This test runs
//! both on the same reference/measurement sequences, step by step, for the PID alone and with
//! each compensation part, and bounds the difference.
//!
//! Tolerance: |u_f32 − u_f64| <= 1e-5 · (1 + slope) · max|u| at every step, where slope is the
//! steepest ramp of the active parts (1 + width/(2·smoothing) for the dead-zone inverse,
//! (gap/2)/smoothing for the backlash inverse, coulomb/smoothing_velocity per velocity unit
//! for the feedforward): the f32 coefficients and arithmetic carry relative errors ~1e-7 that
//! the trapezoidal integrator accumulates over the 6000 steps (bounded by the loop-free
//! sequence: no feedback amplifies them here) and that a ramp multiplies by its slope.
//! Saturation switching and the play operator are piecewise linear and continuous, so they do
//! not turn small differences into large ones.
use ferrosid::compensation::ControlStep;
use ferrosid::robust::pid::{DiscretePid, Pid, Rolloff};
use ferrosid_codegen as cg;
use ferrosid_firmware::control as fw;

const TS: f64 = 1e-3;
const STEPS: usize = 6000;

fn pid() -> DiscretePid {
    Pid {
        kp: 0.9,
        ki: 30.0,
        kd: 0.004,
        tau_f: 5e-4,
        rolloff: Some(Rolloff {
            corner_hz: 150.0,
            zeta: 0.7,
        }),
    }
    .discretize(TS, Some(20.0))
    .unwrap()
}

fn fw_pid(p: &DiscretePid) -> fw::PidConfig {
    fw::PidConfig {
        kp: p.kp as f32,
        ki_d: p.ki_d as f32,
        a_d: p.a_d as f32,
        b_d: p.b_d as f32,
        rolloff: p.rolloff.map(|r| fw::Biquad {
            b: r.b.map(|v| v as f32),
            a: r.a.map(|v| v as f32),
        }),
    }
}

/// The firmware's configuration from the codegen block, as the generated module carries it
/// (alpha and ts/T_t computed in f64, then rounded).
fn fw_comp(c: &cg::Compensation) -> fw::CompensationConfig {
    fw::CompensationConfig {
        friction_feedforward: c.friction_feedforward.map(|f| fw::FrictionFeedforward {
            coulomb: f.coulomb as f32,
            viscous: f.viscous as f32,
            smoothing_velocity: f.smoothing_velocity as f32,
            velocity: match f.velocity {
                cg::VelocitySource::Output => fw::VelocitySource::Output,
                cg::VelocitySource::Reference => fw::VelocitySource::Reference,
                cg::VelocitySource::OutputDifference { filter_hz } => {
                    fw::VelocitySource::OutputDifference {
                        alpha: (1.0 - (-2.0 * std::f64::consts::PI * filter_hz * TS).exp()) as f32,
                    }
                }
            },
            lag_aware: f.lag_aware.map(|l| {
                let delay = match f.velocity {
                    cg::VelocitySource::OutputDifference { filter_hz } => {
                        let a = 1.0 - (-2.0 * std::f64::consts::PI * filter_hz * TS).exp();
                        TS / 2.0 + TS * (1.0 - a) / a
                    }
                    _ => 0.0,
                };
                fw::LagAware {
                    pole: (-TS / l.lag_s).exp() as f32,
                    prediction_s: (l.horizon_s + delay) as f32,
                    stick_band: l.stick_band as f32,
                }
            }),
        }),
        dead_zone_inverse: c.dead_zone_inverse.map(|d| fw::DeadZoneInverse {
            width: d.width as f32,
            smoothing: d.smoothing as f32,
        }),
        backlash_inverse: c.backlash_inverse.map(|b| fw::BacklashInverse {
            gap: b.gap as f32,
            smoothing: b.smoothing as f32,
        }),
        anti_windup: c.anti_windup.map(|a| fw::AntiWindup {
            u_min: a.u_min as f32,
            u_max: a.u_max as f32,
            gain: (TS / a.tracking_time_s) as f32,
        }),
    }
}

fn all_parts() -> cg::Compensation {
    cg::Compensation {
        enabled: true,
        provenance: cg::CompensationProvenance {
            effect: "deadzone".into(),
            place: "drive".into(),
            verdict: "explained".into(),
            source: "test".into(),
            nrmse_before: None,
            nrmse_after: None,
        },
        friction_feedforward: Some(cg::FrictionFeedforward {
            coulomb: 0.1,
            viscous: 0.02,
            smoothing_velocity: 0.5,
            velocity: cg::VelocitySource::OutputDifference { filter_hz: 60.0 },
            lag_aware: None,
        }),
        dead_zone_inverse: Some(cg::DeadZoneInverse {
            width: 0.2,
            smoothing: 0.02,
        }),
        backlash_inverse: Some(cg::BacklashInverse {
            gap: 0.06,
            smoothing: 0.01,
        }),
        anti_windup: Some(cg::AntiWindup {
            u_min: -0.6,
            u_max: 0.7,
            tracking_time_s: 0.02,
        }),
    }
}

/// Reference: a square wave with steps; measurement: a lagged, rippled copy (so the command
/// crosses zero, reverses, and saturates).
fn signals(k: usize) -> (f64, f64) {
    let t = k as f64 * TS;
    let r = if (k / 1500).is_multiple_of(2) {
        0.3
    } else {
        -0.25
    };
    let y = 0.2 * (2.0 * std::f64::consts::PI * 1.3 * t).sin()
        + 0.03 * (2.0 * std::f64::consts::PI * 17.0 * t).sin()
        + if k > 3000 { 0.1 } else { 0.0 };
    (r, y)
}

/// Runs both laws; returns (worst difference, peak |u|).
fn compare(comp: Option<&cg::Compensation>) -> (f64, f64) {
    let p = pid();
    let mut host = ControlStep::new(&p, comp).unwrap();
    let law = fw::ControlLaw::new(&fw::ControlConfig {
        ts_s: TS as f32,
        pid: fw_pid(&p),
        compensation: comp.map(fw_comp),
    })
    .unwrap();
    let mut st = fw::ControlState::new();
    let (mut worst, mut peak) = (0.0f64, 0.0f64);
    for k in 0..STEPS {
        let (r, y) = signals(k);
        let u64_ = host.step(r, y);
        let u32_ = law.step(&mut st, r as f32, y as f32);
        assert!(!u32_.held);
        worst = worst.max((u64_ - f64::from(u32_.u)).abs());
        peak = peak.max(u64_.abs());
    }
    (worst, peak)
}

fn only(f: impl Fn(&mut cg::Compensation)) -> cg::Compensation {
    let mut c = cg::Compensation {
        friction_feedforward: None,
        dead_zone_inverse: None,
        backlash_inverse: None,
        anti_windup: None,
        ..all_parts()
    };
    f(&mut c);
    c
}

#[test]
fn firmware_f32_law_follows_the_host_f64_law_step_by_step() {
    let full = all_parts();
    let cases: Vec<(&str, Option<cg::Compensation>, f64)> = vec![
        ("PID with roll-off", None, 1.0),
        (
            "friction feedforward",
            Some(only(|c| c.friction_feedforward = full.friction_feedforward)),
            // coulomb/smoothing_velocity = 0.2 per velocity unit; velocities here ~2 units/s
            // from the difference of y: 1 + 0.2·... bounded by the coulomb ramp slope times the
            // velocity error, itself f32 rounding of y differences / ts (~1e-4 units/s).
            1.0,
        ),
        (
            "lag-aware friction feedforward",
            Some(only(|c| {
                let mut ff = full.friction_feedforward.unwrap();
                ff.lag_aware = Some(cg::LagAwareFriction {
                    lag_s: 3e-3,
                    horizon_s: 1e-3,
                    stick_band: 0.05,
                });
                c.friction_feedforward = Some(ff);
            })),
            // The deadbeat inverse multiplies f's steps by 1 + p/(1 − p) = 3.5 (p = e^{−1/3});
            // the stuck branch's ramp has slope coulomb/stick_band = 2 per input unit of the
            // lagged command, the predicted velocity carries (horizon + delay)/ts ≈ 3 times the
            // rounding of a difference of w.
            3.5 * (1.0 + 2.0) * 3.0,
        ),
        (
            "dead-zone inverse",
            Some(only(|c| c.dead_zone_inverse = full.dead_zone_inverse)),
            1.0 + 0.1 / 0.02,
        ),
        (
            "backlash inverse",
            Some(only(|c| c.backlash_inverse = full.backlash_inverse)),
            0.03 / 0.01,
        ),
        (
            "anti-windup",
            Some(only(|c| c.anti_windup = full.anti_windup)),
            1.0,
        ),
        (
            "all parts",
            Some(full.clone()),
            (1.0 + 0.1 / 0.02) * (1.0 + 0.03 / 0.01),
        ),
    ];
    for (name, comp, slope) in cases {
        let (worst, peak) = compare(comp.as_ref());
        let bound = 1e-5 * (1.0 + slope) * peak;
        println!(
            "{name}: worst |u_f32 - u_f64| = {worst:.3e} (peak |u| {peak:.3}, bound {bound:.3e})"
        );
        assert!(peak > 0.1, "{name}: the sequence must drive the law");
        assert!(worst <= bound, "{name}: {worst:e} > {bound:e}");
    }
    // The comparison can fail: a law differing in one coefficient by 1 % is caught.
    let mut off = all_parts();
    if let Some(dz) = off.dead_zone_inverse.as_mut() {
        dz.width *= 1.01;
    }
    let p = pid();
    let mut host = ControlStep::new(&p, Some(&all_parts())).unwrap();
    let law = fw::ControlLaw::new(&fw::ControlConfig {
        ts_s: TS as f32,
        pid: fw_pid(&p),
        compensation: Some(fw_comp(&off)),
    })
    .unwrap();
    let mut st = fw::ControlState::new();
    let worst = (0..STEPS)
        .map(|k| {
            let (r, y) = signals(k);
            (host.step(r, y) - f64::from(law.step(&mut st, r as f32, y as f32).u)).abs()
        })
        .fold(0.0f64, f64::max);
    assert!(
        worst > 1e-3,
        "a 1 % width change went unnoticed ({worst:e})"
    );
}
