//! The labelled cases of the independent family and their generation.
//!
//! Every case: a plant ([`Setup`]), one or two effects ([`Spec`], parameters relative to the
//! plant's scales, resolved in [`generate`]), an excitation kind and a seed. From the seed: the
//! nominal model (every physical parameter off by up to ±[`NOMINAL_MISMATCH`], uniform), the
//! three input signals and the measurement noise.
//!
//! Excitation (input RMS A of the plant's setup, band [f_lo, f_hi]):
//! * noise cases: training `low` and `high` are band-limited Gaussian noise (4th-order
//!   Butterworth) at RMS A and 3·A, validation a log-spaced random-phase multisine (300 lines)
//!   at RMS 2·A;
//! * periodic cases: all three logs are odd random-phase multisines with detection lines (one
//!   odd line in four left out) of period [`PERIOD`] samples, repeated to fill the log, RMS A,
//!   3·A, 2·A, each log its own phase realisation.
//!
//! The integrating axis has f_lo = 2 Hz (no DC or very-low-frequency content, so the position
//! stays bounded). Each log has `n` samples at [`TS`]; white Gaussian measurement noise of
//! [`NOISE_REL`] times the low run's noise-free output standard deviation is added (standard
//! deviation rather than RMS: the integrating axis's position settles at an offset from its
//! start) before the sensor's range
//! and resolution.
//!
//! # Ground truth (per CONTRACT-gap.md)
//! Effect names and places: Karnopp/Stribeck/LuGre friction with breakaway ≥ 1.3× Coulomb →
//! `stiction {level, breakaway}`, with no static peak (Karnopp with breakaway = Coulomb, LuGre
//! with stat = Coulomb, Dahl) → `coulomb_friction {level}`, at `motor` or `load`; levels in input
//! units (force F at rest ↦ F/force_per_input, e.g. torque·R/Kt for the voltage-driven motor).
//! Drive play → `backlash {gap}` (input units) at `drive`; shaft backlash → `backlash {gap}` at
//! `drivetrain` (gap in rad of shaft twist); dead band, saturation → `deadzone {width}`,
//! `saturation {limit}` at `drive` (input units); slew-rate limit → `slew_rate {rate}` at `drive`
//! (input units/s); velocity limit of the axis → `state_limit {limit}` at `state`, the limit
//! expressed as the constant input that holds the limited state at its limit in steady state
//! (c·v_max newtons); current limit of the motor → `current_limit {limit}` at `state`, R·I_max
//! volts (a clamp of the armature current state, with its inductance, in continuous time: a
//! law no candidate shares); sensor clip →
//! `saturation {limit}` at `sensor` (output units); quantization → `quantization {step}` at
//! `sensor` (output units); delays → `time_delay {seconds}` at `drive` (input) or `sensor`
//! (output); modes → `resonance {freq_hz, damping}` at `drive` (actuator) or `sensor`.
//!
//! # Cross-family rule
//! An effect is *same-family* when one of the diagnosis's candidates has the same law at the same
//! place: Karnopp friction (including Coulomb) on the driven body — the candidate `stiction` is
//! a Karnopp law too, so Karnopp with a stick band counts as same-family although it is
//! integrated here in continuous time with exact stick events —, Stribeck friction on the
//! driven body (the candidate `stiction` carries the same stick band and Stribeck curve
//! coulomb + (stat − coulomb)·exp(−(|v|/v_s)²) since it gained the Stribeck velocity; the law's
//! small viscous term is linear),
//! drive play, dead band and saturation on the held command, an actuator mode of the
//! candidate's form, quantization. Every other effect is *cross-family*: LuGre and Dahl
//! friction, load-side friction,
//! shaft backlash, slew-rate limit, state limit, sensor clipping, fractional (non-integer-sample)
//! delays at either end, sensor-side modes. A pair is cross-family when either effect is.
use crate::excite::{band_noise, log_multisine, odd_multisine, std_dev};
use crate::laws::{Body, Effects, FrictionLaw, Mode};
use crate::plants::Plant;
use crate::rng::Xoshiro;
use crate::simulate::{measure, simulate, RunStats};
use ferrosid::data::Log;
use ferrosid::lti::StateSpace;
use std::f64::consts::PI;

/// Sample time, s.
pub const TS: f64 = 1e-3;
/// Relative parameter mismatch of the nominal model (uniform ±).
pub const NOMINAL_MISMATCH: f64 = 0.15;
/// Measurement noise standard deviation relative to the low run's noise-free output standard
/// deviation.
pub const NOISE_REL: f64 = 0.01;
/// Period of the periodic excitation, samples (f0 = 0.488 Hz at 1 kHz).
pub const PERIOD: usize = 2048;
/// Lines per group of odd lines of which one is a detection line.
pub const DETECTION_GROUP: usize = 4;

/// A plant with its excitation scales.
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    /// The true plant.
    pub plant: Plant,
    /// Input RMS of the low run (input units).
    pub a: f64,
    /// Lower band edge of the excitation, Hz (0: none).
    pub f_lo: f64,
    /// Upper band edge of the excitation, Hz.
    pub f_hi: f64,
    /// RMS of the driven body's velocity in the low run (body units; sets Stribeck velocities).
    pub v_ref: f64,
    /// Approximate output RMS of the low run (output units; integrator tolerances only).
    pub y_ref: f64,
}

/// The four plant setups.
pub fn setups() -> [Setup; 4] {
    [
        Setup {
            plant: Plant::two_mass(),
            a: 0.04,
            f_lo: 0.0,
            f_hi: 150.0,
            v_ref: 2.0,
            y_ref: 2.0,
        },
        Setup {
            plant: Plant::flexure(),
            a: 2.0,
            f_lo: 0.0,
            f_hi: 80.0,
            v_ref: 0.02,
            y_ref: 200.0,
        },
        Setup {
            plant: Plant::dc_motor(),
            a: 1.0,
            f_lo: 0.0,
            f_hi: 180.0,
            v_ref: 10.0,
            y_ref: 10.0,
        },
        Setup {
            plant: Plant::integrating_axis(),
            a: 0.25,
            f_lo: 2.0,
            f_hi: 60.0,
            v_ref: 2e-3,
            y_ref: 1.5e-4,
        },
    ]
}

/// The family of a friction law (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrictionKind {
    /// Switch model with stick band (Coulomb when ratio = 1).
    Karnopp,
    /// Stick band + Stribeck curve + viscous.
    Stribeck,
    /// LuGre bristles.
    LuGre,
    /// Dahl.
    Dahl,
}

/// One effect of a case, with parameters relative to the setup's scales.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Spec {
    /// Friction: Coulomb level `level`·A in input units, breakaway `ratio`·level, on `body`.
    Friction {
        /// Law.
        kind: FrictionKind,
        /// Coulomb level / A.
        level: f64,
        /// Breakaway / Coulomb.
        ratio: f64,
        /// Body.
        body: Body,
    },
    /// Drive play of total `gap`·A.
    Play(f64),
    /// Drive dead band of total width `width`·A.
    Deadzone(f64),
    /// Drive saturation at `limit`·A.
    Saturation(f64),
    /// Slew-rate limit `r`·2π·f_hi·A per second.
    SlewRate(f64),
    /// Shaft backlash of total `g`·A/k rad (two-mass only).
    ShaftBacklash(f64),
    /// Current limit (motor) / velocity limit (axis) at `r` times the low run's scale of it.
    StateLimit(f64),
    /// Input delay, s.
    InputDelay(f64),
    /// Output delay, s.
    OutputDelay(f64),
    /// Actuator mode (Hz, damping ratio).
    ActuatorMode(f64, f64),
    /// Sensor mode (Hz, damping ratio).
    SensorMode(f64, f64),
    /// Sensor range ±`r` times the low run's noise-free output standard deviation.
    SensorClip(f64),
    /// Quantization step `r` times the low run's noise-free output standard deviation.
    Quantization(f64),
    /// Quantization step in absolute output units.
    QuantizationAbs(f64),
}

/// One labelled effect of the ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthEffect {
    /// Effect name of the diagnosis's vocabulary.
    pub name: &'static str,
    /// Place.
    pub place: &'static str,
    /// Parameters in the diagnosis's units.
    pub params: Vec<(&'static str, f64)>,
    /// Whether no candidate shares the generating law (module docs).
    pub cross_family: bool,
    /// The generating law, for the reports.
    pub law: String,
}

/// A case of the independent family.
#[derive(Debug, Clone)]
pub struct Case {
    /// Identifier, e.g. `indep/dc_motor/stribeck/1`.
    pub id: String,
    /// Plant and scales.
    pub setup: Setup,
    /// The effects (empty: only the linear mismatch).
    pub specs: Vec<Spec>,
    /// Periodic (odd multisine) excitation.
    pub periodic: bool,
    /// Seed of nominal mismatch, excitation and noise.
    pub seed: u64,
}

fn fk(kind: FrictionKind, level: f64, ratio: f64) -> Spec {
    Spec::Friction {
        kind,
        level,
        ratio,
        body: Body::Motor,
    }
}

fn load(kind: FrictionKind, level: f64, ratio: f64) -> Spec {
    Spec::Friction {
        kind,
        level,
        ratio,
        body: Body::Load,
    }
}

/// Short label of a spec for case ids.
pub fn spec_label(s: &Spec) -> String {
    match s {
        Spec::Friction {
            kind, ratio, body, ..
        } => {
            let k = match kind {
                FrictionKind::Karnopp if *ratio <= 1.0 => "coulomb",
                FrictionKind::Karnopp => "karnopp",
                FrictionKind::Stribeck => "stribeck",
                FrictionKind::LuGre => "lugre",
                FrictionKind::Dahl => "dahl",
            };
            match body {
                Body::Motor => k.to_string(),
                Body::Load => format!("load_{k}"),
            }
        }
        Spec::Play(_) => "play".into(),
        Spec::Deadzone(_) => "deadzone".into(),
        Spec::Saturation(_) => "saturation".into(),
        Spec::SlewRate(_) => "slew".into(),
        Spec::ShaftBacklash(_) => "shaft_backlash".into(),
        Spec::StateLimit(_) => "state_limit".into(),
        Spec::InputDelay(_) => "in_delay".into(),
        Spec::OutputDelay(_) => "out_delay".into(),
        Spec::ActuatorMode(..) => "act_mode".into(),
        Spec::SensorMode(..) => "sens_mode".into(),
        Spec::SensorClip(_) => "sensor_clip".into(),
        Spec::Quantization(_) => "quant".into(),
        Spec::QuantizationAbs(_) => "quant_abs".into(),
    }
}

/// All cases of the independent family (see the module docs; ≥ 130 over four plants).
///
/// Excitation rule: single effects in variant 1 and every third pair use the periodic
/// excitation, and one effect-free case per plant; everything else band-limited noise.
pub fn cases() -> Vec<Case> {
    use FrictionKind::*;
    let mut out = Vec::new();
    for (pi, setup) in setups().into_iter().enumerate() {
        let plant = setup.plant;
        let is = |n: &str| plant.name() == n;
        // (specs per variant 0 and 1)
        let mut singles: Vec<[Option<Spec>; 2]> = vec![
            [Some(fk(Karnopp, 0.3, 1.0)), Some(fk(Karnopp, 0.5, 1.0))],
            [Some(fk(Karnopp, 0.25, 1.6)), Some(fk(Karnopp, 0.2, 2.2))],
            [Some(fk(Stribeck, 0.25, 1.7)), Some(fk(Stribeck, 0.2, 2.0))],
            [Some(fk(LuGre, 0.25, 1.8)), Some(fk(LuGre, 0.35, 1.0))],
            [Some(fk(Dahl, 0.35, 1.0)), None],
            [Some(Spec::Play(0.6)), Some(Spec::Play(1.2))],
            [Some(Spec::Deadzone(0.6)), Some(Spec::Deadzone(1.2))],
            [Some(Spec::Saturation(1.5)), Some(Spec::Saturation(2.5))],
            [Some(Spec::SlewRate(0.4)), None],
            [
                Some(Spec::InputDelay(2.4e-3)),
                Some(Spec::InputDelay(5.7e-3)),
            ],
            [Some(Spec::OutputDelay(3.3e-3)), None],
            [Some(Spec::SensorClip(2.0)), None],
            [
                Some(Spec::Quantization(0.03)),
                Some(Spec::Quantization(0.08)),
            ],
        ];
        let (f_act, f_sens) = match plant {
            Plant::TwoMass(_) => ([110.0, 140.0], 160.0),
            Plant::Flexure(_) => ([45.0, 70.0], 60.0),
            Plant::DcMotor(_) => ([60.0, 150.0], 135.0),
            Plant::IntegratingAxis(_) => ([25.0, 45.0], 35.0),
        };
        singles.push([
            Some(Spec::ActuatorMode(f_act[0], 0.04)),
            Some(Spec::ActuatorMode(f_act[1], 0.02)),
        ]);
        singles.push([Some(Spec::SensorMode(f_sens, 0.03)), None]);
        if is("two_mass") {
            singles.push([
                Some(load(Karnopp, 0.3, 1.0)),
                Some(load(Karnopp, 0.25, 1.8)),
            ]);
            singles.push([Some(load(Stribeck, 0.25, 1.8)), None]);
            singles.push([
                Some(Spec::ShaftBacklash(0.5)),
                Some(Spec::ShaftBacklash(1.2)),
            ]);
            singles.push([Some(Spec::ShaftBacklash(2.5)), None]);
        }
        if is("dc_motor") || is("int_axis") {
            singles.push([Some(Spec::StateLimit(1.6)), Some(Spec::StateLimit(1.2))]);
        }
        if is("int_axis") {
            singles.push([Some(Spec::QuantizationAbs(6e-6)), None]);
        }
        let mut pairs: Vec<[Spec; 2]> = vec![
            [fk(Karnopp, 0.3, 1.0), Spec::Saturation(2.0)],
            [fk(Karnopp, 0.2, 1.8), Spec::Saturation(2.0)],
            [Spec::Play(0.8), fk(Karnopp, 0.3, 1.0)],
            [Spec::Deadzone(0.8), Spec::Quantization(0.05)],
            [fk(Stribeck, 0.2, 1.8), Spec::Quantization(0.05)],
            [fk(LuGre, 0.3, 1.0), Spec::InputDelay(3.6e-3)],
        ];
        if is("two_mass") {
            pairs.push([Spec::ShaftBacklash(1.0), fk(Karnopp, 0.3, 1.0)]);
            pairs.push([Spec::ShaftBacklash(1.0), Spec::Saturation(2.0)]);
        }
        let base = 100_000 + 1000 * pi as u64;
        let mut idx = 0u64;
        let mut push = |specs: Vec<Spec>, v: usize, periodic: bool, out: &mut Vec<Case>| {
            let label = if specs.is_empty() {
                "none".to_string()
            } else {
                specs.iter().map(spec_label).collect::<Vec<_>>().join("+")
            };
            idx += 1;
            out.push(Case {
                id: format!("indep/{}/{}/{}", plant.name(), label, v),
                setup,
                specs,
                periodic,
                seed: base + idx,
            });
        };
        push(vec![], 0, false, &mut out);
        push(vec![], 1, false, &mut out);
        push(vec![], 2, true, &mut out);
        for pair in &singles {
            for (v, s) in pair.iter().enumerate() {
                if let Some(s) = s {
                    push(vec![*s], v, v == 1, &mut out);
                }
            }
        }
        for (i, p) in pairs.iter().enumerate() {
            push(p.to_vec(), 0, i % 3 == 2, &mut out);
        }
    }
    out
}

/// The generated data of one case.
#[derive(Debug, Clone)]
pub struct CaseData {
    /// Nominal (mismatched) continuous-time linear model.
    pub sim: StateSpace,
    /// Training logs: low, high amplitude.
    pub train: Vec<Log>,
    /// Validation log.
    pub validate: Log,
    /// Ground truth (empty: effect-free).
    pub truth: Vec<TruthEffect>,
    /// NRMSE the measurement noise alone leaves on the validation log (the true noise floor).
    pub noise_floor: f64,
    /// Integration counters of the three runs.
    pub stats: [RunStats; 3],
}

fn log_of(name: String, u: Vec<f64>, y: Vec<f64>) -> Log {
    Log::siso(name, TS, u, y)
}

/// Bristle stiffness giving a presliding natural frequency of `f_hz` on a body of inverse mass
/// `inv_mass`.
fn bristle_stiffness(f_hz: f64, inv_mass: f64) -> f64 {
    (2.0 * PI * f_hz).powi(2) / inv_mass
}

/// The effects (physical units) and the truth of `specs` on `setup`; output-relative parameters
/// use `y_sd` (noise-free output standard deviation of the low run).
pub fn resolve(setup: &Setup, specs: &[Spec], y_sd: f64) -> (Effects, Vec<TruthEffect>) {
    let plant = setup.plant;
    let a = setup.a;
    let mut fx = Effects::default();
    let mut truth = Vec::new();
    let mut te = |name, place, params: Vec<(&'static str, f64)>, cross, law: String| {
        truth.push(TruthEffect {
            name,
            place,
            params,
            cross_family: cross,
            law,
        })
    };
    for s in specs {
        match *s {
            Spec::Friction {
                kind,
                level,
                ratio,
                body,
            } => {
                let fpi = plant.force_per_input();
                let (fc, fs) = (level * a * fpi, level * ratio * a * fpi);
                let iv = match body {
                    Body::Motor => plant.motor_velocity(),
                    Body::Load => plant.load_velocity().unwrap_or(1),
                };
                let im = plant.inv_mass(iv);
                let v_s = 0.1 * setup.v_ref;
                let law = match kind {
                    FrictionKind::Karnopp => FrictionLaw::Karnopp {
                        coulomb: fc,
                        breakaway: fs,
                    },
                    FrictionKind::Stribeck => FrictionLaw::Stribeck {
                        coulomb: fc,
                        stat: fs,
                        v_s,
                        viscous: 0.05 * fc / setup.v_ref,
                    },
                    FrictionKind::LuGre => {
                        let sigma0 = bristle_stiffness(250.0, im);
                        FrictionLaw::LuGre {
                            coulomb: fc,
                            stat: fs,
                            v_s,
                            sigma0,
                            sigma1: 2.0 * 0.7 * (sigma0 / im).sqrt(),
                            sigma2: 0.05 * fc / setup.v_ref,
                        }
                    }
                    FrictionKind::Dahl => FrictionLaw::Dahl {
                        coulomb: fc,
                        sigma0: bristle_stiffness(150.0, im),
                    },
                };
                fx.friction = Some((law, body));
                let place = if body == Body::Motor { "motor" } else { "load" };
                // Karnopp and Stribeck laws on the driven body are the stiction candidate's (a stick band
                // and, since the candidate gained the Stribeck velocity, the same Stribeck curve);
                // LuGre, Dahl and load-side friction are not.
                let cross = !matches!(kind, FrictionKind::Karnopp | FrictionKind::Stribeck)
                    || body == Body::Load;
                let law_s = format!("{kind:?}");
                if ratio >= 1.3 {
                    te(
                        "stiction",
                        place,
                        vec![("level", level * a), ("breakaway", level * ratio * a)],
                        cross,
                        law_s,
                    );
                } else {
                    te(
                        "coulomb_friction",
                        place,
                        vec![("level", level * a)],
                        cross,
                        law_s,
                    );
                }
            }
            Spec::Play(g) => {
                fx.drive_play = Some(g * a);
                te(
                    "backlash",
                    "drive",
                    vec![("gap", g * a)],
                    false,
                    "play".into(),
                );
            }
            Spec::Deadzone(w) => {
                fx.drive_deadzone = Some(w * a);
                te(
                    "deadzone",
                    "drive",
                    vec![("width", w * a)],
                    false,
                    "dead band".into(),
                );
            }
            Spec::Saturation(l) => {
                fx.drive_saturation = Some(l * a);
                te(
                    "saturation",
                    "drive",
                    vec![("limit", l * a)],
                    false,
                    "clamp".into(),
                );
            }
            Spec::SlewRate(r) => {
                let rate = r * 2.0 * PI * setup.f_hi * a;
                fx.slew_rate = Some(rate);
                te(
                    "slew_rate",
                    "drive",
                    vec![("rate", rate)],
                    true,
                    "slew limit".into(),
                );
            }
            Spec::ShaftBacklash(g) => {
                let k = plant.shaft().map_or(1.0, |(k, _)| k);
                let gap = g * a / k;
                fx.shaft_backlash = Some(gap);
                te(
                    "backlash",
                    "drivetrain",
                    vec![("gap", gap)],
                    true,
                    "shaft dead zone".into(),
                );
            }
            Spec::StateLimit(r) => match plant {
                Plant::DcMotor(p) => {
                    let imax = r * a / p.r;
                    fx.state_limit = Some((0, imax));
                    te(
                        "current_limit",
                        "state",
                        vec![("limit", imax * p.r)],
                        true,
                        "current limit".into(),
                    );
                }
                Plant::IntegratingAxis(p) => {
                    let vmax = r * setup.v_ref;
                    fx.state_limit = Some((1, vmax));
                    te(
                        "state_limit",
                        "state",
                        vec![("limit", vmax * p.c)],
                        true,
                        "velocity limit".into(),
                    );
                }
                _ => {}
            },
            Spec::InputDelay(d) => {
                fx.input_delay = d;
                te(
                    "time_delay",
                    "drive",
                    vec![("seconds", d)],
                    true,
                    "fractional input delay".into(),
                );
            }
            Spec::OutputDelay(d) => {
                fx.output_delay = d;
                te(
                    "time_delay",
                    "sensor",
                    vec![("seconds", d)],
                    true,
                    "fractional output delay".into(),
                );
            }
            Spec::ActuatorMode(f, z) => {
                fx.actuator_mode = Some(Mode {
                    freq_hz: f,
                    damping: z,
                });
                te(
                    "resonance",
                    "drive",
                    vec![("freq_hz", f), ("damping", z)],
                    false,
                    "actuator mode".into(),
                );
            }
            Spec::SensorMode(f, z) => {
                fx.sensor_mode = Some(Mode {
                    freq_hz: f,
                    damping: z,
                });
                te(
                    "resonance",
                    "sensor",
                    vec![("freq_hz", f), ("damping", z)],
                    true,
                    "sensor mode".into(),
                );
            }
            Spec::SensorClip(r) => {
                fx.sensor_clip = Some(r * y_sd);
                te(
                    "saturation",
                    "sensor",
                    vec![("limit", r * y_sd)],
                    true,
                    "sensor clip".into(),
                );
            }
            Spec::Quantization(r) => {
                fx.quant_step = Some(r * y_sd);
                te(
                    "quantization",
                    "sensor",
                    vec![("step", r * y_sd)],
                    false,
                    "quantizer after noise".into(),
                );
            }
            Spec::QuantizationAbs(q) => {
                fx.quant_step = Some(q);
                te(
                    "quantization",
                    "sensor",
                    vec![("step", q)],
                    false,
                    "quantizer after noise".into(),
                );
            }
        }
    }
    (fx, truth)
}

/// Converts an integration failure into the crate's error.
fn sim_err(id: &str, e: crate::ode::OdeError) -> ferrosid::error::Error {
    ferrosid::error::Error::Numerical(format!("{id}: simulation failed: {e}"))
}

/// The three inputs of a case (module docs): low, high and validation, `n` samples each, drawn
/// from `rng` in that order.
pub fn excitations(
    s: &Setup,
    periodic: bool,
    n: usize,
    rng: &mut Xoshiro,
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    if periodic {
        let periods = n.div_ceil(PERIOD);
        let f_lo = s.f_lo.max(0.4);
        let mut mk = |r: f64| {
            let mut v =
                odd_multisine(PERIOD, periods, TS, f_lo, s.f_hi, DETECTION_GROUP, r, rng).signal;
            v.truncate(n);
            v
        };
        (mk(s.a), mk(3.0 * s.a), mk(2.0 * s.a))
    } else {
        (
            band_noise(n, TS, s.f_lo, s.f_hi, s.a, rng),
            band_noise(n, TS, s.f_lo, s.f_hi, 3.0 * s.a, rng),
            log_multisine(n, TS, s.f_lo.max(0.2), s.f_hi, 300, 2.0 * s.a, rng),
        )
    }
}

/// Generates the logs of `case` with `n` samples each (see the module docs).
pub fn generate(case: &Case, n: usize) -> ferrosid::error::Result<CaseData> {
    let s = case.setup;
    let mut rng = Xoshiro::new(case.seed);
    let nominal = s.plant.perturbed(NOMINAL_MISMATCH, &mut rng).linear()?;
    let (u_low, u_high, u_val) = excitations(&s, case.periodic, n, &mut rng);
    // Output scale from the low run: the output-relative parameters (sensor range and
    // resolution) act in `measure`, not in the simulation, so this run is already the real one.
    let (fx0, _) = resolve(&s, &case.specs, 1.0);
    let (clean_low, st_low) =
        simulate(s.plant, &fx0, &u_low, TS, s.a, s.y_ref).map_err(|e| sim_err(&case.id, e))?;
    let y_sd = std_dev(&clean_low);
    let (fx, truth) = resolve(&s, &case.specs, y_sd);
    let noise_std = NOISE_REL * y_sd;
    let run = |u: &[f64], amp: f64| simulate(s.plant, &fx, u, TS, amp, s.y_ref * amp / s.a);
    let (clean_high, st_high) = run(&u_high, 3.0 * s.a).map_err(|e| sim_err(&case.id, e))?;
    let (clean_val, st_val) = run(&u_val, 2.0 * s.a).map_err(|e| sim_err(&case.id, e))?;
    let mut nrng = Xoshiro::new(case.seed ^ 0x5DEE_CE66_D1CE_4E5B);
    let y_low = measure(&clean_low, &fx, noise_std, &mut nrng);
    let y_high = measure(&clean_high, &fx, noise_std, &mut nrng);
    let y_val = measure(&clean_val, &fx, noise_std, &mut nrng);
    let mean = y_val.iter().sum::<f64>() / n as f64;
    let sd = (y_val.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    let noise_floor = if sd > 0.0 { noise_std / sd } else { f64::NAN };
    Ok(CaseData {
        sim: nominal,
        train: vec![
            log_of(format!("{}/low", case.id), u_low, y_low),
            log_of(format!("{}/high", case.id), u_high, y_high),
        ],
        validate: log_of(format!("{}/validate", case.id), u_val, y_val),
        truth,
        noise_floor,
        stats: [st_low, st_high, st_val],
    })
}
