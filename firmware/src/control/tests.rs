//! Host tests of the control step against closed forms and independent f64 references.
use super::*;

fn pid(kp: f32, ki_d: f32, a_d: f32, b_d: f32) -> PidConfig {
    PidConfig {
        kp,
        ki_d,
        a_d,
        b_d,
        rolloff: None,
    }
}

fn law(p: PidConfig, comp: Option<CompensationConfig>) -> ControlLaw {
    ControlLaw::new(&ControlConfig {
        ts_s: 1e-3,
        pid: p,
        compensation: comp,
    })
    .unwrap()
}

/// Constant error e = 1 from rest: u[k] = kp + ki_d (2k + 1) + b_d a_d^k exactly.
#[test]
fn pid_step_matches_the_closed_form() {
    let (kp, ki_d, a_d, b_d) = (0.8f32, 0.002f32, 0.6f32, 3.0f32);
    let l = law(pid(kp, ki_d, a_d, b_d), None);
    let mut st = ControlState::new();
    for k in 0..200 {
        let out = l.step(&mut st, 1.0, 0.0);
        let want = f64::from(kp)
            + f64::from(ki_d) * (2.0 * k as f64 + 1.0)
            + f64::from(b_d) * f64::from(a_d).powi(k);
        assert!(
            (f64::from(out.u) - want).abs() <= 1e-5 * want.abs().max(1.0),
            "k = {k}: {} vs {want}",
            out.u
        );
        assert_eq!(out.u, out.u_pid);
    }
}

/// The roll-off biquad in series: the response to a unit step of v equals an f64 direct-form
/// run of the same section (here with a pure proportional PID, v = kp·e).
#[test]
fn rolloff_matches_an_f64_biquad() {
    let bq = Biquad {
        b: [0.02, 0.04, 0.02],
        a: [1.0, -1.56, 0.64],
    };
    let l = law(
        PidConfig {
            rolloff: Some(bq),
            ..pid(2.0, 0.0, 0.0, 0.0)
        },
        None,
    );
    let mut st = ControlState::new();
    let (mut v1, mut v2, mut u1, mut u2) = (0.0f64, 0.0, 0.0, 0.0);
    for k in 0..300 {
        let out = l.step(&mut st, 1.0, 0.0);
        let v = 2.0;
        let u = 0.02 * v + 0.04 * v1 + 0.02 * v2 + 1.56 * u1 - 0.64 * u2;
        (v2, v1, u2, u1) = (v1, v, u1, u);
        assert!((f64::from(out.u) - u).abs() < 1e-5, "k = {k}");
    }
    // DC gain of the section is 0.08 / 0.08 = 1: the command settles at kp = 2.
    assert!((f64::from(l.step(&mut st, 1.0, 0.0).u) - 2.0).abs() < 1e-4);
}

/// The lag-aware feedforward by hand (velocity output w = y, pole p = 0.5 so the deadbeat
/// lead is p/(1 − p) = 1, prediction 2 ms = 2 samples, band 1, stuck band 0.1, coulomb 0.2,
/// no viscous term): the command equals f + (f − f_prev), f = 0.2·s.
#[test]
fn lag_aware_feedforward_by_hand() {
    let ff = FrictionFeedforward {
        coulomb: 0.2,
        viscous: 0.0,
        smoothing_velocity: 1.0,
        velocity: VelocitySource::Output,
        lag_aware: Some(LagAware {
            pole: 0.5,
            prediction_s: 2e-3,
            stick_band: 0.1,
        }),
    };
    let comp = Some(CompensationConfig {
        friction_feedforward: Some(ff),
        ..CompensationConfig::NONE
    });
    // PID zero: the feedforward alone; T stays 0, so a stuck body gets s = 0.
    let l = law(pid(0.0, 0.0, 0.0, 0.0), comp);
    let mut st = ControlState::new();
    // k0: y = 0.5, first step: no acceleration, w_p = 0.5 (stuck), s = T/0.1 = 0: u = 0.
    assert!(l.step(&mut st, 0.0, 0.5).u.abs() < 1e-7);
    // k1: y = 0.9, dw = 0.4, w_p = 0.9 + 2·0.4 = 1.7 >= 1: s = 1, f = 0.2, u = 0.2 + 0.2 = 0.4.
    assert!((l.step(&mut st, 0.0, 0.9).u - 0.4).abs() < 1e-6);
    // k2: y = 0.3, dw = −0.6, w_p = 0.3 − 1.2 = −0.9: stuck, s = 0: f = 0, u = 0 − 0.2.
    assert!((l.step(&mut st, 0.0, 0.3).u + 0.2).abs() < 1e-6);
    // k3: y = −2: w_p = −2 − 4.6 < −1: f = −0.2, u = −0.2 − 0.2.
    assert!((l.step(&mut st, 0.0, -2.0).u + 0.4).abs() < 1e-6);
    // A proportional PID (kp = 1, e = −y): stuck body, the lagged command picks the side.
    let l = law(pid(1.0, 0.0, 0.0, 0.0), comp);
    let mut st = ControlState::new();
    // y = −0.08: u_pid = 0.08, T = 0.5·0 + 0.5·0.08 = 0.04, s = 0.4, f = 0.08,
    // u = 0.08 + 0.08 + 1·0.08 = 0.24.
    let out = l.step(&mut st, 0.0, -0.08);
    assert!((out.u - 0.24).abs() < 1e-6, "{}", out.u);
    // Same y: T = 0.5·0.04 + 0.04 = 0.06, s = 0.6, f = 0.12, u_ff = 0.12 + 0.04 = 0.16.
    let out = l.step(&mut st, 0.0, -0.08);
    assert!((out.u_ff - 0.16).abs() < 1e-6, "{}", out.u_ff);
    // Out-of-range settings are refused naming the field.
    for (bad, what) in [
        (
            LagAware {
                pole: 1.0,
                prediction_s: 1e-3,
                stick_band: 0.1,
            },
            "friction_feedforward.lag_aware.pole",
        ),
        (
            LagAware {
                pole: 0.5,
                prediction_s: -1e-3,
                stick_band: 0.1,
            },
            "friction_feedforward.lag_aware.prediction_s",
        ),
        (
            LagAware {
                pole: 0.5,
                prediction_s: 1e-3,
                stick_band: 0.0,
            },
            "friction_feedforward.lag_aware.stick_band",
        ),
    ] {
        let e = ControlLaw::new(&ControlConfig {
            ts_s: 1e-3,
            pid: pid(0.0, 0.0, 0.0, 0.0),
            compensation: Some(CompensationConfig {
                friction_feedforward: Some(FrictionFeedforward {
                    lag_aware: Some(bad),
                    ..ff
                }),
                ..CompensationConfig::NONE
            }),
        })
        .unwrap_err();
        assert_eq!(e, crate::Error::InvalidControlParameter { what }, "{what}");
    }
}

#[test]
fn friction_feedforward_ramps_through_zero_velocity() {
    let ff = FrictionFeedforward {
        coulomb: 0.3,
        viscous: 0.01,
        smoothing_velocity: 2.0,
        velocity: VelocitySource::Output,
        lag_aware: None,
    };
    let l = law(
        pid(0.0, 0.0, 0.0, 0.0),
        Some(CompensationConfig {
            friction_feedforward: Some(ff),
            ..CompensationConfig::NONE
        }),
    );
    for (w, want) in [
        (0.0f32, 0.0f32),
        (1.0, 0.15 + 0.01),
        (-1.0, -0.16),
        (2.0, 0.32),
        (10.0, 0.4),
        (-10.0, -0.4),
    ] {
        let mut st = ControlState::new();
        let out = l.step(&mut st, 0.0, w);
        assert!((out.u - want).abs() < 1e-6, "w = {w}: {} vs {want}", out.u);
        assert_eq!(out.u, out.u_ff);
    }
    // Reference source: w = r, independent of y.
    let l = law(
        pid(0.0, 0.0, 0.0, 0.0),
        Some(CompensationConfig {
            friction_feedforward: Some(FrictionFeedforward {
                velocity: VelocitySource::Reference,
                ..ff
            }),
            ..CompensationConfig::NONE
        }),
    );
    let mut st = ControlState::new();
    assert!((l.step(&mut st, 1.0, 123.0).u - 0.16).abs() < 1e-6);
}

/// Position output: the backward difference through the first-order filter converges to the
/// true slope of a ramp (0.5 units/s), and the first step sees no velocity.
#[test]
fn output_difference_estimates_the_velocity_of_a_ramp() {
    let alpha = 1.0 - (-2.0 * core::f64::consts::PI * 50.0 * 1e-3f64).exp();
    let l = law(
        pid(0.0, 0.0, 0.0, 0.0),
        Some(CompensationConfig {
            friction_feedforward: Some(FrictionFeedforward {
                coulomb: 0.0,
                viscous: 1.0,
                smoothing_velocity: 1.0,
                velocity: VelocitySource::OutputDifference {
                    alpha: alpha as f32,
                },
                lag_aware: None,
            }),
            ..CompensationConfig::NONE
        }),
    );
    let mut st = ControlState::new();
    let mut w_ref = 0.0f64;
    for k in 0..200 {
        let y = 3.0 + 0.5e-3 * k as f64;
        let out = l.step(&mut st, 0.0, y as f32);
        let raw = if k == 0 { 0.0 } else { 0.5 };
        w_ref += alpha * (raw - w_ref);
        // f32 difference of positions near 3 (ulp 2.4e-7) over 1 ms: 5e-4 units/s resolution.
        assert!(
            (f64::from(out.u) - w_ref).abs() < 2e-3,
            "k = {k}: {} vs {w_ref}",
            out.u
        );
    }
}

/// The plant's dead zone (gap effect law w = sign(u)·max(|u| − width/2, 0)) after the inverse
/// is the identity outside the smoothing band and continuous inside it.
#[test]
fn dead_zone_inverse_undoes_the_dead_zone() {
    let (width, smoothing) = (0.4f32, 0.01f32);
    let l = law(
        pid(1.0, 0.0, 0.0, 0.0),
        Some(CompensationConfig {
            dead_zone_inverse: Some(DeadZoneInverse { width, smoothing }),
            ..CompensationConfig::NONE
        }),
    );
    let dead_zone = |u: f32| u.signum() * (u.abs() - width / 2.0).max(0.0);
    let mut prev: Option<f32> = None;
    for k in -2000..=2000 {
        let u_c = k as f32 * 5e-4;
        let mut st = ControlState::new();
        let out = l.step(&mut st, u_c, 0.0);
        let w = dead_zone(out.u);
        if u_c.abs() >= smoothing {
            assert!((w - u_c).abs() < 1e-6, "u_c = {u_c}: plant sees {w}");
        } else {
            // Inside the band the composite has a residual dead zone of half-width
            // (width/2)·s/(s + width/2) < s and slope (1 + width/(2s)) beyond it.
            assert!(w.abs() <= smoothing + 1e-6);
        }
        // Continuous: between neighbouring commands (5e-4 apart) the output moves by at most
        // the ramp's slope 1 + width/(2·smoothing) times the step.
        if let Some(p) = prev {
            let bound = (1.0 + width / (2.0 * smoothing)) * 5e-4 * 1.001 + 1e-6;
            assert!((out.u - p).abs() <= bound, "jump at {u_c}");
        }
        prev = Some(out.u);
    }
}

/// The gap's play operator (total play `gap`, output follows once the input is more than
/// gap/2 away) after the backlash inverse follows a triangle command exactly, except during the
/// 2·`smoothing` of travel after each reversal (the offset swings from +gap/2 to −gap/2).
#[test]
fn backlash_inverse_takes_up_the_play() {
    let (gap, smoothing) = (0.2f32, 0.01f32);
    let l = law(
        pid(1.0, 0.0, 0.0, 0.0),
        Some(CompensationConfig {
            backlash_inverse: Some(BacklashInverse { gap, smoothing }),
            ..CompensationConfig::NONE
        }),
    );
    let mut st = ControlState::new();
    let mut play_out = 0.0f64;
    let half = f64::from(gap) / 2.0;
    let mut worst_settled = 0.0f64;
    let mut worst_without = 0.0f64;
    for k in 0..4000 {
        // Triangle between −1 and 1, 1000 samples per leg, steps of 2e-3.
        let ph = k % 2000;
        let v = if ph < 1000 {
            -1.0 + 2e-3 * ph as f64
        } else {
            1.0 - 2e-3 * (ph - 1000) as f64
        };
        let out = l.step(&mut st, v as f32, 0.0);
        let u = f64::from(out.u);
        if u - play_out > half {
            play_out = u - half;
        } else if play_out - u > half {
            play_out = u + half;
        }
        // Samples more than 2·`smoothing` (10 steps) after a reversal, after the first leg.
        let since_reversal = ph % 1000;
        if k >= 1000 && since_reversal > 10 {
            worst_settled = worst_settled.max((play_out - v).abs());
        }
        // Without the inverse the load lags the command by gap/2 on every leg.
        worst_without = worst_without.max(half);
    }
    assert!(
        worst_settled < 1e-5,
        "load misses the command by {worst_settled}"
    );
    assert!(worst_without > 0.09);
}

/// Back-calculation: under a constant error the saturated loop's integrator settles where
/// i = u_max − kp·e − 2·ki_d·e + 2·ki_d·e/gain (the fixed point of i_new = i + 2 ki_d e,
/// i = i_new + gain (u_max − kp e − i_new)),
/// instead of winding up without bound.
#[test]
fn anti_windup_bounds_the_integrator() {
    let (kp, ki_d, gain) = (0.5f32, 0.01f32, 0.05f32);
    let aw = AntiWindup {
        u_min: -1.0,
        u_max: 1.0,
        gain,
    };
    let l = law(
        pid(kp, ki_d, 0.0, 0.0),
        Some(CompensationConfig {
            anti_windup: Some(aw),
            ..CompensationConfig::NONE
        }),
    );
    let mut st = ControlState::new();
    let e = 4.0f32;
    for _ in 0..5000 {
        let out = l.step(&mut st, e, 0.0);
        assert!(out.u <= 1.0 && out.u >= -1.0);
    }
    let fixed = f64::from(1.0 - kp * e) - 2.0 * f64::from(ki_d * e)
        + 2.0 * f64::from(ki_d * e) / f64::from(gain);
    assert!(
        (f64::from(st.integrator()) - fixed).abs() < 1e-4,
        "{} vs {fixed}",
        st.integrator()
    );
    // Without anti-windup the integrator grows by 2·ki_d·e per step.
    let plain = law(pid(kp, ki_d, 0.0, 0.0), None);
    let mut st2 = ControlState::new();
    for _ in 0..5000 {
        plain.step(&mut st2, e, 0.0);
    }
    assert!(st2.integrator() > 300.0);
}

#[test]
fn non_finite_measurements_repeat_the_last_command() {
    let l = law(pid(1.0, 0.01, 0.0, 0.0), None);
    let mut st = ControlState::new();
    let first = l.step(&mut st, 1.0, 0.2);
    let frozen = st;
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let out = l.step(&mut st, 1.0, bad);
        assert!(out.held);
        assert_eq!(out.u, first.u);
        let out = l.step(&mut st, bad, 0.0);
        assert!(out.held && out.u == first.u);
        assert_eq!(st, frozen);
    }
}

#[test]
fn bad_parameters_are_refused_naming_the_field() {
    let base = ControlConfig {
        ts_s: 1e-3,
        pid: pid(1.0, 0.01, 0.5, 0.1),
        compensation: Some(CompensationConfig {
            friction_feedforward: Some(FrictionFeedforward {
                coulomb: 0.1,
                viscous: 0.0,
                smoothing_velocity: 0.1,
                velocity: VelocitySource::OutputDifference { alpha: 0.3 },
                lag_aware: None,
            }),
            dead_zone_inverse: Some(DeadZoneInverse {
                width: 0.1,
                smoothing: 0.01,
            }),
            backlash_inverse: Some(BacklashInverse {
                gap: 0.1,
                smoothing: 0.01,
            }),
            anti_windup: Some(AntiWindup {
                u_min: -1.0,
                u_max: 1.0,
                gain: 0.1,
            }),
        }),
    };
    ControlLaw::new(&base).unwrap();
    type Edit = fn(&mut ControlConfig);
    let cases: [(Edit, &str); 12] = [
        (|c| c.ts_s = 0.0, "ts_s"),
        (|c| c.pid.kp = f32::NAN, "pid.kp"),
        (|c| c.pid.a_d = 1.0, "pid.a_d"),
        (
            |c| {
                c.pid.rolloff = Some(Biquad {
                    b: [1.0; 3],
                    a: [2.0, 0.0, 0.0],
                })
            },
            "pid.rolloff.a",
        ),
        (
            |c| {
                c.compensation
                    .as_mut()
                    .unwrap()
                    .friction_feedforward
                    .as_mut()
                    .unwrap()
                    .coulomb = -1.0
            },
            "friction_feedforward.coulomb",
        ),
        (
            |c| {
                c.compensation
                    .as_mut()
                    .unwrap()
                    .friction_feedforward
                    .as_mut()
                    .unwrap()
                    .smoothing_velocity = 0.0
            },
            "friction_feedforward.smoothing_velocity",
        ),
        (
            |c| {
                c.compensation
                    .as_mut()
                    .unwrap()
                    .friction_feedforward
                    .as_mut()
                    .unwrap()
                    .velocity = VelocitySource::OutputDifference { alpha: 1.5 }
            },
            "friction_feedforward.velocity.alpha",
        ),
        (
            |c| {
                c.compensation
                    .as_mut()
                    .unwrap()
                    .dead_zone_inverse
                    .as_mut()
                    .unwrap()
                    .width = f32::INFINITY
            },
            "dead_zone_inverse.width",
        ),
        (
            |c| {
                c.compensation
                    .as_mut()
                    .unwrap()
                    .backlash_inverse
                    .as_mut()
                    .unwrap()
                    .smoothing = -0.1
            },
            "backlash_inverse.smoothing",
        ),
        (
            |c| {
                c.compensation
                    .as_mut()
                    .unwrap()
                    .anti_windup
                    .as_mut()
                    .unwrap()
                    .u_max = -2.0
            },
            "anti_windup.u_max",
        ),
        (
            |c| {
                c.compensation
                    .as_mut()
                    .unwrap()
                    .anti_windup
                    .as_mut()
                    .unwrap()
                    .gain = 2.0
            },
            "anti_windup.gain",
        ),
        (
            |c| {
                c.compensation
                    .as_mut()
                    .unwrap()
                    .anti_windup
                    .as_mut()
                    .unwrap()
                    .u_min = f32::NAN
            },
            "anti_windup.u_min",
        ),
    ];
    for (edit, want) in cases {
        let mut c = base;
        edit(&mut c);
        assert_eq!(
            ControlLaw::new(&c),
            Err(Error::InvalidControlParameter { what: want }),
            "{want}"
        );
        assert!(ControlLaw::new(&c).unwrap_err().to_string().contains(want));
    }
}

#[test]
fn oscillation_detector_finds_frequency_and_amplitude_and_ignores_noise() {
    let ts = 1e-3f32;
    // A clipped (trapezoidal) 7.3 Hz wave plus bounded noise of 5 % of its amplitude.
    let mut rng = crate::rng::SplitMix64::new(3);
    let x: [f32; 3000] = core::array::from_fn(|k| {
        let s = (2.0 * core::f64::consts::PI * 7.3 * k as f64 * 1e-3).sin();
        let n = (rng.next_u32() as f64 / 4294967296.0 - 0.5) * 0.1;
        (0.2 * (1.5 * s).clamp(-1.0, 1.0) + 0.2 * 0.25 * n) as f32
    });
    let o = analyse_oscillation(&x, ts, 5, 0.02);
    assert!(o.oscillating, "{o:?}");
    assert!((o.freq_hz - 7.3).abs() < 0.05, "{o:?}");
    assert!((o.amplitude - 0.2).abs() < 0.01, "{o:?}");
    // Noise alone (amplitude below the floor): no cycle.
    let quiet: [f32; 3000] = core::array::from_fn(|k| 1e-4 * ((k * 7919 % 13) as f32 - 6.0));
    assert!(!analyse_oscillation(&quiet, ts, 5, 0.02).oscillating);
    // A decaying step response crosses its mean once: no cycle.
    let settle: [f32; 3000] = core::array::from_fn(|k| 1.0 - (-(k as f32) * 0.01).exp());
    assert!(!analyse_oscillation(&settle, ts, 5, 1e-3).oscillating);
    assert_eq!(analyse_oscillation(&[], ts, 5, 0.0), Oscillation::default());
}

/// Open-loop use: the compensation applied to an external command equals the closed-loop step
/// of a zero PID fed the same command as its "PID output" (here via the dead-zone inverse and
/// a feedforward from the output), and leaves the PID state at rest.
#[test]
fn compensate_applies_the_parts_to_an_external_command() {
    let comp = CompensationConfig {
        friction_feedforward: Some(FrictionFeedforward {
            coulomb: 0.2,
            viscous: 0.0,
            smoothing_velocity: 1.0,
            velocity: VelocitySource::Output,
            lag_aware: None,
        }),
        dead_zone_inverse: Some(DeadZoneInverse {
            width: 0.4,
            smoothing: 0.01,
        }),
        ..CompensationConfig::NONE
    };
    let l = law(pid(3.0, 0.1, 0.0, 0.0), Some(comp));
    let mut st = ControlState::new();
    for (u_in, y, want) in [
        (0.5f32, 0.5f32, 0.5 + 0.1 + 0.2),
        // u_c = -0.3 + 0.2 = -0.1, then the inverse adds -width/2.
        (-0.3, 2.0, -0.1 - 0.2),
        (0.0, 0.0, 0.0),
    ] {
        let out = l.compensate(&mut st, 0.0, y, u_in);
        assert!((out.u - want).abs() < 1e-6, "{u_in}, {y}: {}", out.u);
        assert_eq!(st.integrator(), 0.0);
    }
    assert!(l.compensate(&mut st, 0.0, 0.0, f32::NAN).held);
}
