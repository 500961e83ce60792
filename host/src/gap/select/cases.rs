//! End-to-end checks of the selection on simulated axes (same-law simulator
//! [`crate::gap::simulator::plant`], with the drivetrain play integrated by a different scheme):
//! the case builders shared by the checks and the study.
use super::*;
use crate::gap::effect::{quantize, saturation};
use crate::gap::modal::FitSet;
use crate::gap::simulator::benchmark::{filtered_noise, multisine};
use crate::gap::simulator::plant::{simulate, Plant, SimSettings};
use crate::gap::simulator::rng::Rng;
use crate::lti::StateSpace;

pub(super) const TS: f64 = 1e-3;

pub(super) struct Case {
    pub td: TrainData,
    pub starts: Vec<ModalModel>,
    pub poles: Vec<Complex64>,
    pub structure: Option<TwoMassStructure>,
    pub vu: Vec<f64>,
    pub vy: Vec<f64>,
    pub warmup: usize,
}

/// Logs of `truth` (input → measured output) with the nominal `plant` perturbed by ±15 %:
/// filtered noise at RMS `a` and 3`a` for training, a multisine at 2`a` for validation.
pub(super) fn make_case(
    plant: Plant,
    a: f64,
    f_c: f64,
    n: usize,
    seed: u64,
    truth: &dyn Fn(&[f64], u64) -> Vec<f64>,
) -> Case {
    let mut rng = Rng::new(seed);
    let nominal: StateSpace = plant
        .perturbed(0.15, &mut rng)
        .physical()
        .unwrap()
        .sys
        .c2d_zoh(TS)
        .unwrap();
    let u_lo = filtered_noise(n, TS, f_c, a, &mut rng);
    let u_hi = filtered_noise(n, TS, f_c, 3.0 * a, &mut rng);
    let vu = multisine(n, TS, 0.2, f_c, 2.0 * a, &mut rng);
    let y_lo = truth(&u_lo, 1);
    let y_hi = truth(&u_hi, 2);
    let vy = truth(&vu, 3);
    let poles = nominal.poles().unwrap();
    let slowest = poles
        .iter()
        .map(|p| p.norm())
        .filter(|&r| r < 1.0 - 1e-9)
        .fold(0.0f64, f64::max);
    let tau = if slowest > 0.0 {
        -1.0 / slowest.ln()
    } else {
        0.0
    };
    let warmup = ((5.0 * tau).ceil() as usize).min(n / 10).max(
        if poles.iter().any(|p| (p - 1.0).norm() < 1e-9) {
            n / 10
        } else {
            0
        },
    );
    let td = TrainData::new(
        TS,
        vec![u_lo.clone(), u_hi.clone()],
        vec![y_lo, y_hi],
        warmup,
    )
    .unwrap();
    let mut lin = ModalModel::from_poles(TS, &poles, false).unwrap();
    lin.fit_output_error(&td.base, 60).unwrap();
    let mut nom = ModalModel::from_poles(TS, &poles, false).unwrap();
    let y_sim: Vec<Vec<f64>> =
        td.u.iter()
            .map(|u| nominal.simulate_siso(u, None).unwrap())
            .collect();
    nom.fit_linear_params(&FitSet::new(td.u.clone(), y_sim, warmup).unwrap())
        .unwrap();
    nom.offset = lin.offset;
    Case {
        structure: TwoMassStructure::detect(&nominal),
        td,
        starts: vec![lin, nom],
        poles,
        vu,
        vy,
        warmup,
    }
}

pub(super) fn settings(noise_std: f64, seed: u64) -> SimSettings {
    SimSettings {
        ts: TS,
        substeps: 8,
        noise_std,
        seed,
    }
}

/// Output RMS of `plant` for filtered noise at RMS `a` (noise scale of the cases).
pub(super) fn y_rms(plant: &Plant, a: f64, f_c: f64) -> f64 {
    let mut rng = Rng::new(99);
    let u = filtered_noise(8192, TS, f_c, a, &mut rng);
    let y = simulate(plant, None, &u, &settings(0.0, 0)).unwrap();
    (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt()
}

pub(super) fn run(c: &Case) -> Selection {
    select_effects(
        &c.td,
        &c.starts,
        &c.poles,
        c.structure.as_ref(),
        &c.vu,
        &c.vy,
        c.warmup,
        &SelectOptions::default(),
    )
    .unwrap()
}

pub(super) fn describe(s: &Selection) -> String {
    let sel: Vec<String> = s
        .selected
        .iter()
        .map(|e| {
            format!(
                "{}@{} share {:.2} gap {:.4}",
                e.effect, e.place, e.share, e.gap_after
            )
        })
        .collect();
    let singles: Vec<String> = s
        .singles
        .iter()
        .take(if std::env::var_os("GAP_ALL").is_some() {
            99
        } else {
            4
        })
        .map(|x| {
            format!(
                "{} {:.4}",
                x.effects.first().map_or("-".into(), |p| p.to_string()),
                x.gap
            )
        })
        .collect();
    format!(
        "gap_linear {:.4}; selected [{}]; top singles [{}]; notes {:?}",
        s.gap_linear,
        sel.join("; "),
        singles.join("; "),
        s.notes
    )
}

/// CPU seconds of this thread (see [`super::thread_cpu_seconds`]).
fn cpu_seconds() -> f64 {
    super::thread_cpu_seconds()
}

// The checked cases, shared by the checks below and the study (`n` samples per log).

/// Integrating axis with Coulomb friction 1.0 (seed 21).
pub(super) fn axis_friction_case(n: usize) -> Case {
    let ax = Plant::axis();
    let ns = 0.01 * y_rms(&ax, 2.0, 20.0);
    let e = Effect::CoulombFriction { level: 1.0 };
    make_case(ax, 2.0, 20.0, n, 21, &|u, k| {
        simulate(&ax, Some(&e), u, &settings(ns, k)).unwrap()
    })
}

/// Quantization after noise at 5 % of the RMS, flexure position in metres (tiny scale);
/// returns the case and the true step.
pub(super) fn small_quantization_case(n: usize) -> (Case, f64) {
    let fx = Plant::flexure();
    let rms = y_rms(&fx, 1.0, 60.0) * 1e-6;
    let step = 0.05 * rms;
    let c = make_case(fx, 1.0, 60.0, n, 22, &|u, k| {
        simulate(&fx, None, u, &settings(0.01 * rms * 1e6, k))
            .unwrap()
            .into_iter()
            .map(|v| quantize(v * 1e-6, step))
            .collect()
    });
    (c, step)
}

/// DC motor with a sensor clipping at 60 % of a probe run's peak; returns the case and
/// the clip level.
pub(super) fn sensor_clip_case(n: usize) -> (Case, f64) {
    let dc = Plant::dc_motor();
    let mut rng = Rng::new(5);
    let probe = filtered_noise(n, TS, 100.0, 3.0, &mut rng);
    let pk = simulate(&dc, None, &probe, &settings(0.0, 0))
        .unwrap()
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    let lim = 0.6 * pk;
    let ns = 0.01 * y_rms(&dc, 1.0, 100.0);
    let c = make_case(dc, 1.0, 100.0, n, 23, &|u, k| {
        simulate(&dc, None, u, &settings(ns, k))
            .unwrap()
            .into_iter()
            .map(|v| saturation(v, lim))
            .collect()
    });
    (c, lim)
}

/// Lightly damped mode at 160 Hz (ζ = 0.02) in series, DC motor excited to 200 Hz.
pub(super) fn resonance_160_case(n: usize) -> Case {
    let dc = Plant::dc_motor();
    let e = Effect::Resonance {
        freq_hz: 160.0,
        damping: 0.02,
    };
    let ns = 0.01 * y_rms(&dc, 1.0, 200.0);
    make_case(dc, 1.0, 200.0, n, 24, &|u, k| {
        simulate(&dc, Some(&e), u, &settings(ns, k)).unwrap()
    })
}

/// Pair: input saturation at 1.5 and Coulomb friction 0.3, DC motor.
pub(super) fn saturation_friction_case(n: usize) -> Case {
    let dc = Plant::dc_motor();
    let e = Effect::CoulombFriction { level: 0.3 };
    let ns = 0.01 * y_rms(&dc, 1.0, 100.0);
    make_case(dc, 1.0, 100.0, n, 25, &|u, k| {
        let us: Vec<f64> = u.iter().map(|&v| saturation(v, 1.5)).collect();
        simulate(&dc, Some(&e), &us, &settings(ns, k)).unwrap()
    })
}

/// Karnopp stiction 0.2 / breakaway 0.4 on the DC motor.
pub(super) fn stiction_case(n: usize) -> Case {
    let dc = Plant::dc_motor();
    let ns = 0.01 * y_rms(&dc, 1.0, 100.0);
    let e = Effect::Stiction {
        level: 0.2,
        breakaway: 0.4,
        stribeck_velocity: 0.0,
    };
    make_case(dc, 1.0, 100.0, n, 26, &|u, k| {
        simulate(&dc, Some(&e), u, &settings(ns, k)).unwrap()
    })
}

fn more_cases() {
    let n = 16384;
    let show = |name: &str, c: &Case| {
        let t0 = cpu_seconds();
        let s = run(c);
        eprintln!("{name} ({:.2} s): {}", cpu_seconds() - t0, describe(&s));
    };
    show("axis coulomb 1.0", &axis_friction_case(n));
    let (c, step) = small_quantization_case(n);
    eprintln!("(true step {step:.3e})");
    show("flexure quantization 5 %", &c);
    let (c, lim) = sensor_clip_case(n);
    eprintln!("(true clip {lim:.4})");
    show("dc sensor clip", &c);
    show("dc resonance 160 Hz", &resonance_160_case(n));
    show(
        "dc saturation 1.5 + coulomb 0.3",
        &saturation_friction_case(n),
    );
    show("dc stiction 0.2/0.4", &stiction_case(n));
}

/// Study (not a check): prints the selection on a range of cases.
#[test]
#[ignore]
fn study() {
    use crate::gap::effect::Effect;
    use crate::gap::simulator::plant::simulate_drivetrain_backlash;
    let n = 16384;
    let tm = Plant::two_mass();
    let crate::gap::simulator::plant::Plant::TwoMass(tmp) = tm else {
        unreachable!()
    };
    let ns = 0.01 * y_rms(&tm, 0.05, 120.0);
    for gap in [0.003, 0.008] {
        let c = make_case(tm, 0.05, 120.0, n, 11, &|u, k| {
            simulate_drivetrain_backlash(&tmp, gap, u, &settings(ns, k)).unwrap()
        });
        eprintln!(
            "structure {:?}",
            c.structure.as_ref().map(|s| s.mapping_nrmse)
        );
        let t0 = cpu_seconds();
        let s = run(&c);
        eprintln!(
            "drivetrain backlash {gap} rad ({:.2} s): {}",
            cpu_seconds() - t0,
            describe(&s)
        );
    }
    if std::env::var_os("GAP_ONLY_DT").is_some() {
        return;
    }
    if std::env::var_os("GAP_MORE").is_some() {
        more_cases();
        return;
    }
    for (name, e) in [
        (
            "stiction 1.8x",
            Effect::Stiction {
                level: 0.01,
                breakaway: 0.018,
                stribeck_velocity: 0.0,
            },
        ),
        ("coulomb", Effect::CoulombFriction { level: 0.015 }),
    ] {
        let c = make_case(tm, 0.05, 120.0, n, 12, &|u, k| {
            simulate(&tm, Some(&e), u, &settings(ns, k)).unwrap()
        });
        let t0 = cpu_seconds();
        let s = run(&c);
        eprintln!("{name} ({:.2} s): {}", cpu_seconds() - t0, describe(&s));
    }
}
