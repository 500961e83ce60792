//! Physical plant models and the effect simulator behind the labelled gap benchmark and the
//! bundled example data.
//!
//! Three continuous-time plants, each driven by a force-like input acting on the mass whose
//! motion is measured (collocated), which is where friction acts:
//!
//! * [`TwoMass`] — two-mass actuator: motor inertia `jm` driven by torque u (N·m), coupled to a
//!   load inertia `jl` through a shaft of stiffness `k` (N·m/rad) and damping `c` (N·m·s/rad),
//!   viscous friction `bm`, `bl` (N·m·s/rad) on each side; output the motor speed (rad/s).
//!   States (θm − θl, ωm, ωl).
//! * [`Axis`] — positioning axis: mass `m` (kg) with viscous friction `b` (N·s/m), driven by
//!   force u (N); output the position in millimetres (an integrating plant, pole at s = 0).
//!   States (x in m, v in m/s).
//! * [`Flexure`] — flexure-guided stage: mass `m` (kg) on a flexure of stiffness `k` (N/m) with
//!   damping `c` (N·s/m), driven by force u (N); output the stage position in micrometres.
//!   States (x in m, v in m/s).
//! * [`DcMotor`] — voltage-driven DC motor: armature resistance `r` (Ω) and inductance `l` (H),
//!   torque constant `kt` (N·m/A) and back-EMF constant `ke` (V·s/rad), rotor inertia `j`
//!   (kg·m²) and viscous friction `b` (N·m·s/rad); input the armature voltage (V), output the
//!   speed (rad/s). States (i, ω). Friction torque acts on the rotor, one integrator behind the
//!   input; its label in input units is torque·r/kt (the voltage that balances it at rest).
//!
//! [`simulate`] integrates a plant with one [`Effect`] placed as documented in
//! `ferrosid::gap::effect`: the linear dynamics exactly (ZOH at `substeps` sub-steps per sample,
//! input held over each sample as a DAC would), friction by the [`StickSlip`] law on the
//! physical velocity state at every sub-step, a delay on the held input with sub-step
//! resolution, a resonance as two extra states in series with the input, and measurement noise
//! (white, Gaussian) added before the sensor's quantizer. This is deliberately a finer and
//! differently structured integration than the sample-rate models the diagnosis fits.
use super::rng::Rng;
use faer::Mat;
use ferrosid::error::{Error, Result};
use ferrosid::gap::effect::{
    deadzone, quantize, resonance_mode, saturation, Effect, Play, RateLimiter, StickSlip,
};
use ferrosid::lti::{StateSpace, StateSpaceData};

/// Two-mass actuator parameters (SI units, see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoMass {
    /// Motor inertia, kg·m².
    pub jm: f64,
    /// Load inertia, kg·m².
    pub jl: f64,
    /// Shaft stiffness, N·m/rad.
    pub k: f64,
    /// Shaft damping, N·m·s/rad.
    pub c: f64,
    /// Motor viscous friction, N·m·s/rad.
    pub bm: f64,
    /// Load viscous friction, N·m·s/rad.
    pub bl: f64,
}

/// Flexure stage parameters (SI units; output in µm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flexure {
    /// Moving mass, kg.
    pub m: f64,
    /// Flexure stiffness, N/m.
    pub k: f64,
    /// Damping, N·s/m.
    pub c: f64,
}

/// DC motor parameters (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DcMotor {
    /// Armature resistance, Ω.
    pub r: f64,
    /// Armature inductance, H.
    pub l: f64,
    /// Torque constant, N·m/A.
    pub kt: f64,
    /// Back-EMF constant, V·s/rad.
    pub ke: f64,
    /// Rotor inertia, kg·m².
    pub j: f64,
    /// Viscous friction, N·m·s/rad.
    pub b: f64,
}

/// Positioning axis parameters (SI units; output in mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// Moving mass, kg.
    pub m: f64,
    /// Viscous friction, N·s/m.
    pub b: f64,
}

/// One of the benchmark plants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Plant {
    /// Positioning axis, force in, position (mm) out: an integrating plant.
    Axis(Axis),
    /// Two-mass actuator, torque in, motor speed out.
    TwoMass(TwoMass),
    /// Flexure stage, force in, position (µm) out.
    Flexure(Flexure),
    /// DC motor, voltage in, speed out.
    DcMotor(DcMotor),
}

/// Continuous-time physical model of a plant, the pieces [`simulate`] needs.
#[derive(Debug, Clone)]
pub struct Physical {
    /// Linear model u → y (continuous time).
    pub sys: StateSpace,
    /// Column through which a friction force on the driven mass enters ẋ (physical force units).
    pub b_force: Vec<f64>,
    /// Index of the driven mass's velocity in the state.
    pub velocity_state: usize,
    /// Physical friction force per input unit (1 for force/torque inputs, kt/r for the motor).
    pub force_per_input: f64,
}

impl Plant {
    /// The default two-mass actuator: 50 Hz resonance, 25 Hz anti-resonance, 5 % shaft damping.
    pub fn two_mass() -> Self {
        Plant::TwoMass(TwoMass {
            jm: 2e-4,
            jl: 6e-4,
            k: 15.0,
            c: 4.7e-3,
            bm: 2e-3,
            bl: 3e-3,
        })
    }
    /// The default positioning axis: 2 kg, mechanical time constant 0.2 s.
    pub fn axis() -> Self {
        Plant::Axis(Axis { m: 2.0, b: 10.0 })
    }
    /// The default flexure stage: 10 Hz, about 5 % damping.
    pub fn flexure() -> Self {
        Plant::Flexure(Flexure {
            m: 0.5,
            k: 2000.0,
            c: 3.0,
        })
    }
    /// The default DC motor: mechanical pole near 2 Hz, electrical near 160 Hz.
    pub fn dc_motor() -> Self {
        Plant::DcMotor(DcMotor {
            r: 2.0,
            l: 2e-3,
            kt: 0.05,
            ke: 0.05,
            j: 1e-4,
            b: 1e-4,
        })
    }

    /// Short name (`two_mass`, `flexure`, `dc_motor`).
    pub fn name(&self) -> &'static str {
        match self {
            Plant::Axis(_) => "axis",
            Plant::TwoMass(_) => "two_mass",
            Plant::Flexure(_) => "flexure",
            Plant::DcMotor(_) => "dc_motor",
        }
    }

    /// A copy with every physical parameter multiplied by (1 + δ), δ uniform in
    /// [−rel, rel] drawn from `rng`: the "nominal simulation" a team would have written down.
    pub fn perturbed(&self, rel: f64, rng: &mut Rng) -> Self {
        let mut f = || 1.0 + rel * (2.0 * rng.uniform() - 1.0);
        match *self {
            Plant::Axis(p) => Plant::Axis(Axis {
                m: p.m * f(),
                b: p.b * f(),
            }),
            Plant::TwoMass(p) => Plant::TwoMass(TwoMass {
                jm: p.jm * f(),
                jl: p.jl * f(),
                k: p.k * f(),
                c: p.c * f(),
                bm: p.bm * f(),
                bl: p.bl * f(),
            }),
            Plant::Flexure(p) => Plant::Flexure(Flexure {
                m: p.m * f(),
                k: p.k * f(),
                c: p.c * f(),
            }),
            Plant::DcMotor(p) => Plant::DcMotor(DcMotor {
                r: p.r * f(),
                l: p.l * f(),
                kt: p.kt * f(),
                ke: p.ke * f(),
                j: p.j * f(),
                b: p.b * f(),
            }),
        }
    }

    /// The continuous physical model. Errors only for non-physical parameters (non-finite or
    /// non-positive masses, inductance, ...).
    pub fn physical(&self) -> Result<Physical> {
        let check = |vals: &[(&str, f64)]| -> Result<()> {
            for &(n, v) in vals {
                if !(v.is_finite() && v > 0.0) {
                    return Err(Error::InvalidArgument(format!(
                        "{}: parameter {n} = {v} must be finite and > 0",
                        self.name()
                    )));
                }
            }
            Ok(())
        };
        let m = |r: usize, c: usize, v: &[f64]| Mat::from_fn(r, c, |i, j| v[i * c + j]);
        match *self {
            Plant::Axis(p) => {
                check(&[("m", p.m), ("b", p.b)])?;
                let a = m(2, 2, &[0.0, 1.0, 0.0, -p.b / p.m]);
                let b = m(2, 1, &[0.0, 1.0 / p.m]);
                let c = m(1, 2, &[1e3, 0.0]);
                Ok(Physical {
                    sys: StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0)?,
                    b_force: vec![0.0, 1.0 / p.m],
                    velocity_state: 1,
                    force_per_input: 1.0,
                })
            }
            Plant::TwoMass(p) => {
                check(&[("jm", p.jm), ("jl", p.jl), ("k", p.k)])?;
                let a = m(
                    3,
                    3,
                    &[
                        0.0,
                        1.0,
                        -1.0,
                        -p.k / p.jm,
                        -(p.c + p.bm) / p.jm,
                        p.c / p.jm,
                        p.k / p.jl,
                        p.c / p.jl,
                        -(p.c + p.bl) / p.jl,
                    ],
                );
                let b = m(3, 1, &[0.0, 1.0 / p.jm, 0.0]);
                let c = m(1, 3, &[0.0, 1.0, 0.0]);
                Ok(Physical {
                    sys: StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0)?,
                    b_force: vec![0.0, 1.0 / p.jm, 0.0],
                    velocity_state: 1,
                    force_per_input: 1.0,
                })
            }
            Plant::Flexure(p) => {
                check(&[("m", p.m), ("k", p.k), ("c", p.c)])?;
                let a = m(2, 2, &[0.0, 1.0, -p.k / p.m, -p.c / p.m]);
                let b = m(2, 1, &[0.0, 1.0 / p.m]);
                let c = m(1, 2, &[1e6, 0.0]);
                Ok(Physical {
                    sys: StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0)?,
                    b_force: vec![0.0, 1.0 / p.m],
                    velocity_state: 1,
                    force_per_input: 1.0,
                })
            }
            Plant::DcMotor(p) => {
                check(&[
                    ("r", p.r),
                    ("l", p.l),
                    ("kt", p.kt),
                    ("ke", p.ke),
                    ("j", p.j),
                ])?;
                let a = m(2, 2, &[-p.r / p.l, -p.ke / p.l, p.kt / p.j, -p.b / p.j]);
                let b = m(2, 1, &[1.0 / p.l, 0.0]);
                let c = m(1, 2, &[0.0, 1.0]);
                Ok(Physical {
                    sys: StateSpace::new(a, b, c, Mat::zeros(1, 1), 0.0)?,
                    b_force: vec![0.0, 1.0 / p.j],
                    velocity_state: 1,
                    force_per_input: p.kt / p.r,
                })
            }
        }
    }

    /// The plant's linear model as the `--sim` JSON of `ferrosid gap` (continuous, `ts` 0).
    pub fn sim_json(&self) -> Result<String> {
        let data = StateSpaceData::from(&self.physical()?.sys);
        serde_json::to_string_pretty(&data)
            .map_err(|e| Error::Numerical(format!("serialising the sim model: {e}")))
    }
}

/// Simulation settings for [`simulate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimSettings {
    /// Sample time of the log, s.
    pub ts: f64,
    /// Integration sub-steps per sample (>= 1; default 8).
    pub substeps: usize,
    /// Standard deviation of the white measurement noise added to y (output units).
    pub noise_std: f64,
    /// Seed of the noise.
    pub seed: u64,
}

/// Simulates `plant` with an optional `effect` for the held input sequence `u` (one value per
/// sample, input units), returning the measured output (one per sample, taken at the start of
/// each sample period, before that sample's input acts). The plant starts at rest.
pub fn simulate(
    plant: &Plant,
    effect: Option<&Effect>,
    u: &[f64],
    s: &SimSettings,
) -> Result<Vec<f64>> {
    if !(s.ts.is_finite() && s.ts > 0.0) || s.substeps == 0 {
        return Err(Error::InvalidArgument(format!(
            "plant simulation needs ts > 0 and substeps >= 1 (got {} s, {})",
            s.ts, s.substeps
        )));
    }
    if let Some(e) = effect {
        e.validate()?;
        if let Effect::StateLimit { .. } = e {
            return Err(Error::InvalidArgument(
                "plant simulation: state_limit is not simulated by the benchmark plants".into(),
            ));
        }
    }
    let phys = plant.physical()?;
    let n0 = phys.sys.n_states();
    // Append the series resonance (states after the plant's) when asked.
    let (a_c, b_u, b_f, c_row) = match effect {
        Some(Effect::Resonance { freq_hz, damping }) => {
            let r = resonance_mode(*freq_hz, *damping)?;
            let n = n0 + 2;
            let a = Mat::from_fn(n, n, |i, j| match (i < n0, j < n0) {
                (true, true) => phys.sys.a[(i, j)],
                (true, false) => phys.sys.b[(i, 0)] * r.c[(0, j - n0)],
                (false, false) => r.a[(i - n0, j - n0)],
                (false, true) => 0.0,
            });
            let bu: Vec<f64> = (0..n)
                .map(|i| if i < n0 { 0.0 } else { r.b[(i - n0, 0)] })
                .collect();
            let mut bf = phys.b_force.clone();
            bf.extend([0.0, 0.0]);
            let c: Vec<f64> = (0..n)
                .map(|j| if j < n0 { phys.sys.c[(0, j)] } else { 0.0 })
                .collect();
            (a, bu, bf, c)
        }
        _ => (
            phys.sys.a.clone(),
            (0..n0).map(|i| phys.sys.b[(i, 0)]).collect(),
            phys.b_force.clone(),
            (0..n0).map(|j| phys.sys.c[(0, j)]).collect(),
        ),
    };
    let n = a_c.nrows();
    let h = s.ts / s.substeps as f64;
    // Two inputs: u (held) and −friction force.
    let sys2 = StateSpace::new(
        a_c,
        Mat::from_fn(n, 2, |i, j| if j == 0 { b_u[i] } else { -b_f[i] }),
        Mat::from_fn(1, n, |_, j| c_row[j]),
        Mat::zeros(1, 2),
        0.0,
    )?
    .c2d_zoh(h)?;
    let ad: Vec<f64> = (0..n * n).map(|k| sys2.a[(k / n, k % n)]).collect();
    let bu: Vec<f64> = (0..n).map(|i| sys2.b[(i, 0)]).collect();
    let bf: Vec<f64> = (0..n).map(|i| sys2.b[(i, 1)]).collect();
    let vi = phys.velocity_state;
    // Friction on the driven mass, in physical force units.
    let mut friction =
        match effect {
            Some(Effect::CoulombFriction { level }) => {
                let f = level * phys.force_per_input;
                Some(StickSlip::new(f, f))
            }
            Some(Effect::Stiction {
                stribeck_velocity, ..
            }) if *stribeck_velocity > 0.0 => return Err(Error::InvalidArgument(
                "the same-law plant simulator has no Stribeck curve (stribeck_velocity must be 0)"
                    .into(),
            )),
            Some(Effect::Stiction {
                level, breakaway, ..
            }) => Some(StickSlip::new(
                level * phys.force_per_input,
                breakaway * phys.force_per_input,
            )),
            _ => None,
        };
    // Command-path nonlinearity at the sample rate (digital command, then DAC hold).
    let mut play = match effect {
        Some(Effect::Backlash { gap }) => Some(Play::new(*gap)),
        _ => None,
    };
    let mut rate = match effect {
        Some(Effect::SlewRate { rate }) => Some(RateLimiter::new(rate * s.ts)),
        _ => None,
    };
    let cmd: Vec<f64> = u
        .iter()
        .map(|&uk| match effect {
            Some(Effect::SlewRate { .. }) => rate.as_mut().map_or(uk, |r| r.apply(uk)),
            Some(Effect::Deadzone { width }) => deadzone(uk, *width),
            Some(Effect::Saturation { limit }) => saturation(uk, *limit),
            Some(Effect::Backlash { .. }) => play.as_mut().map_or(uk, |p| p.apply(uk)),
            _ => uk,
        })
        .collect();
    let delay_sub = match effect {
        Some(Effect::TimeDelay { seconds }) => (seconds / h).round() as usize,
        _ => 0,
    };
    let q_step = match effect {
        Some(Effect::Quantization { step }) => Some(*step),
        _ => None,
    };
    let g = bf[vi]; // change of velocity per unit friction force over one sub-step (negative sign
                    // already in the column): v_end = v_trial + g·F with g < 0.
    let mut rng = Rng::new(s.seed);
    let mut x = vec![0.0; n];
    let mut xn = vec![0.0; n];
    let mut y = Vec::with_capacity(u.len());
    for k in 0..u.len() {
        let mut yk: f64 = c_row.iter().zip(&x).map(|(c, x)| c * x).sum();
        if s.noise_std > 0.0 {
            yk += s.noise_std * rng.normal();
        }
        if let Some(q) = q_step {
            yk = quantize(yk, q);
        }
        y.push(yk);
        for j in 0..s.substeps {
            let idx = (k * s.substeps + j) as isize - delay_sub as isize;
            let uin = if idx < 0 {
                0.0
            } else {
                cmd[idx as usize / s.substeps]
            };
            for i in 0..n {
                let row = &ad[i * n..(i + 1) * n];
                xn[i] = row.iter().zip(&x).map(|(a, b)| a * b).sum::<f64>() + bu[i] * uin;
            }
            if let Some(fr) = friction.as_mut() {
                let f = fr.force(xn[vi], -g);
                for i in 0..n {
                    xn[i] += bf[i] * f;
                }
            }
            std::mem::swap(&mut x, &mut xn);
        }
    }
    if y.iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical(
            "plant simulation produced a non-finite output".into(),
        ));
    }
    Ok(y)
}

/// Simulates the two-mass actuator `p` with backlash of total play `gap` (rad) in the shaft:
/// the shaft transmits k·dz(θ, gap) + c·θ' while engaged (|θ| >= gap/2) and nothing inside
/// the play (θ = θ_m − θ_l). Integration: the two inertias exactly (ZOH of the uncoupled
/// masses with their viscous friction) with the shaft torque by Heun's rule (predictor–
/// corrector) at `substeps` sub-steps per sample — a different scheme from the diagnosis's
/// piecewise-linear two-mass model. Output the motor speed with white noise of `noise_std`,
/// as [`simulate`].
pub fn simulate_drivetrain_backlash(
    p: &TwoMass,
    gap: f64,
    u: &[f64],
    s: &SimSettings,
) -> Result<Vec<f64>> {
    if !(s.ts.is_finite() && s.ts > 0.0)
        || s.substeps == 0
        || gap
            .partial_cmp(&0.0)
            .is_none_or(|o| o == std::cmp::Ordering::Less)
    {
        return Err(Error::InvalidArgument(format!(
            "drivetrain backlash simulation needs ts > 0, substeps >= 1 and gap >= 0 (got {} s, \
             {}, {gap})",
            s.ts, s.substeps
        )));
    }
    let h = s.ts / s.substeps as f64;
    // Uncoupled inertia J with viscous b: ω' = (τ − bω)/J, exact for a held τ.
    let step = |w: f64, tau: f64, j: f64, b: f64| -> (f64, f64) {
        // Returns (ω_end, ∫ω dt over the sub-step).
        let a = b / j;
        let e = (-a * h).exp();
        let w_inf = tau / b;
        let w_end = w_inf + (w - w_inf) * e;
        let integral = w_inf * h + (w - w_inf) * (1.0 - e) / a;
        (w_end, integral)
    };
    let half = 0.5 * gap;
    let shaft = |th: f64, dth: f64| -> f64 {
        if th > half {
            p.k * (th - half) + p.c * dth
        } else if th < -half {
            p.k * (th + half) + p.c * dth
        } else {
            0.0
        }
    };
    let mut rng = Rng::new(s.seed);
    let (mut th, mut wm, mut wl) = (0.0f64, 0.0f64, 0.0f64);
    let mut y = Vec::with_capacity(u.len());
    for &uk in u {
        let mut yk = wm;
        if s.noise_std > 0.0 {
            yk += s.noise_std * rng.normal();
        }
        y.push(yk);
        for _ in 0..s.substeps {
            let t0 = shaft(th, wm - wl);
            let (wm1, im1) = step(wm, uk - t0, p.jm, p.bm);
            let (wl1, il1) = step(wl, t0, p.jl, p.bl);
            let th1 = th + im1 - il1;
            let t1 = shaft(th1, wm1 - wl1);
            let tau = 0.5 * (t0 + t1);
            let (wm2, im2) = step(wm, uk - tau, p.jm, p.bm);
            let (wl2, il2) = step(wl, tau, p.jl, p.bl);
            th += im2 - il2;
            wm = wm2;
            wl = wl2;
        }
    }
    if y.iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical(
            "drivetrain backlash simulation produced a non-finite output".into(),
        ));
    }
    Ok(y)
}
