//! Simulation of the nonlinear closed loop: the tuned loop of [`LureLoop`] with one
//! nonlinearity at its site, the same effect laws the gap diagnosis fits
//! ([`crate::gap::effect`]), and optionally the compensation in the control law
//! ([`crate::compensation::ControlStep`]).
//!
//! Per controller sample k (sample time T):
//! 1. measure y = C·x + D·w₋ (w₋ the plant input of the previous sample); at the `sensor`
//!    site the measurement is N(y) (quantizer or clip);
//! 2. command u = controller(r, y_m) (PID with roll-off, plus the compensation if given);
//! 3. plant input w = N(u) at the `drive` site (dead zone, saturation, or the play operator at
//!    the sample rate, as a digital command before the DAC), plus the start-up kick;
//! 4. the plant over the sample, input held: at the `velocity` site (friction) in `substeps`
//!    exact ZOH sub-steps of the continuous plant, with the Karnopp stick-slip law
//!    ([`StickSlip`]) deciding at every sub-step whether the friction holds the mass at rest or
//!    slides — the same law and velocity proxy as the gap fit (the output, or its time
//!    derivative C(A_c x + B_c w) for a position output); elsewhere one exact discrete step.
//!    With friction on the slowest mode ([`crate::limit_cycle::Body`]) the force acts on a
//!    separate first-order body state instead of the plant input (y = G(u) − B(F)), as in the
//!    gap fit's friction port.
//!
//! The recorded signal `nl_input` is the nonlinearity's input at each sample (u for `drive` —
//! with a compensation, the command u_c before the dead-zone/backlash inverses, the input of
//! the residual nonlinearity [`crate::limit_cycle::Residual`] —
//! y for `sensor`, the velocity for `velocity`): the signal whose amplitude the describing
//! function predicts.
use super::lure::{LureLoop, Nonlinearity, Site};
use crate::compensation::ControlStep;
use crate::error::{Error, Result};
use crate::gap::effect::{deadzone, quantize, saturation, Play, StickSlip};
use crate::gap::fit::VelocitySource;
use crate::limit_cycle::DescribingFunction;
use ferrosid_codegen::Compensation;
use serde::{Deserialize, Serialize};

/// What to simulate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimSpec {
    /// Simulated time, s (> 0; at most 10⁷ samples).
    pub duration_s: f64,
    /// Constant reference, output units.
    pub reference: f64,
    /// Start-up kick: added to the plant input (input units) during the first `kick_samples`
    /// samples, to leave the equilibrium.
    pub kick: f64,
    /// Samples the kick lasts (>= 0).
    pub kick_samples: usize,
    /// Sub-steps per sample for friction (>= 1; default 16).
    pub substeps: usize,
}

impl SimSpec {
    /// `duration_s` with reference 0, the given kick over 5 samples, 16 sub-steps.
    pub fn new(duration_s: f64, kick: f64) -> Self {
        Self {
            duration_s,
            reference: 0.0,
            kick,
            kick_samples: 5,
            substeps: 16,
        }
    }
}

/// A simulated run, one value per controller sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulatedRun {
    /// Sample time, s.
    pub ts: f64,
    /// The nonlinearity's input (module docs).
    pub nl_input: Vec<f64>,
    /// Plant output y, output units.
    pub y: Vec<f64>,
    /// Controller command u, input units.
    pub u: Vec<f64>,
    /// Whether a compensation was active.
    pub compensated: bool,
}

/// A drive or sensor nonlinearity with its memory (the play's position, the hysteretic
/// relay's output), applied once per sample.
struct NlState {
    df: DescribingFunction,
    play: Option<Play>,
    hyst_out: Option<f64>,
}

impl NlState {
    fn new(df: DescribingFunction) -> Self {
        let play = match df {
            DescribingFunction::Backlash { gap } => Some(Play::new(gap)),
            _ => None,
        };
        Self {
            df,
            play,
            hyst_out: None,
        }
    }

    fn apply(&mut self, x: f64) -> f64 {
        match self.df {
            DescribingFunction::Saturation { limit } => saturation(x, limit),
            DescribingFunction::DeadZone { width } => deadzone(x, width),
            DescribingFunction::Quantization { step } => quantize(x, step),
            DescribingFunction::Backlash { .. } => self.play.as_mut().map_or(x, |p| p.apply(x)),
            DescribingFunction::RelayHysteresis { level, half_width } => {
                let o = self
                    .hyst_out
                    .get_or_insert(if x < 0.0 { -level } else { level });
                if x >= half_width {
                    *o = level;
                } else if x <= -half_width {
                    *o = -level;
                }
                *o
            }
            DescribingFunction::Relay { level } | DescribingFunction::Stiction { level, .. } => {
                if x == 0.0 {
                    0.0
                } else {
                    level * x.signum()
                }
            }
        }
    }
}

/// The control law stepped: the PID (with the compensation) or a general controller (its
/// last command kept for `nl_input`).
enum Law {
    Pid(ControlStep),
    General(crate::synth::sim::DiscreteLaw, f64),
}

impl Law {
    /// The loop's law: its general controller when it has one (a compensation is refused
    /// there), else the PID with `comp`.
    fn new(lp: &LureLoop, comp: Option<&Compensation>) -> Result<Self> {
        match &lp.general {
            None => Ok(Law::Pid(ControlStep::new(&lp.controller, comp)?)),
            Some(_) if comp.is_some_and(|c| c.enabled) => Err(Error::InvalidArgument(
                "limit-cycle simulation: a compensation is only simulated with the PID law".into(),
            )),
            Some(g) => Ok(Law::General(g.law.clone(), 0.0)),
        }
    }
    fn step(&mut self, r: f64, y: f64) -> f64 {
        match self {
            Law::Pid(c) => c.step(r, y),
            Law::General(law, u) => {
                *u = law.step(r - y, f64::INFINITY);
                *u
            }
        }
    }
    fn pre_inverse_command(&self) -> f64 {
        match self {
            Law::Pid(c) => c.pre_inverse_command(),
            Law::General(_, u) => *u,
        }
    }
    fn compensated(&self) -> bool {
        matches!(self, Law::Pid(c) if c.compensated())
    }
}

/// Simulates the loop `lp` with `nl` (see the module docs), with `comp` in the control law when
/// given and enabled. Errors for invalid parameters, a compensation that fails validation (its
/// field named), a bad spec, or a diverging simulation (non-finite state).
pub fn simulate(
    lp: &LureLoop,
    nl: &Nonlinearity,
    comp: Option<&Compensation>,
    spec: &SimSpec,
) -> Result<SimulatedRun> {
    nl.df.validate()?;
    let ts = lp.ts;
    let n_samples = sample_count(spec, ts)?;
    let mut ctl = Law::new(lp, comp)?;
    let friction = matches!(nl.site, Site::Velocity);
    let plant = SubstepPlant::new(lp, friction, spec.substeps)?;
    let mut fr = friction_law(friction, nl)?;
    let (n, m, c, d) = (plant.n, plant.m, &plant.c, plant.d);
    let mut xf = 0.0;
    let mut map = NlState::new(nl.df);
    let mut x = vec![0.0; n];
    let mut xn = vec![0.0; n];
    let mut w_prev = 0.0;
    let mut run = SimulatedRun {
        ts,
        nl_input: Vec::with_capacity(n_samples),
        y: Vec::with_capacity(n_samples),
        u: Vec::with_capacity(n_samples),
        compensated: ctl.compensated(),
    };
    let mut out_prev = 0.0;
    for k in 0..n_samples {
        let y = dot(c, &x) + d * w_prev - xf;
        let y_m = if nl.site == Site::Sensor {
            map.apply(y)
        } else {
            y
        };
        let u = ctl.step(spec.reference, y_m);
        let mut w = if nl.site == Site::Drive {
            map.apply(u)
        } else {
            u
        };
        if k < spec.kick_samples {
            w += spec.kick;
        }
        let v_now = if plant.body.is_some() {
            dot(c, &x) - xf
        } else if friction {
            plant.velocity_of(&x, out_prev, w)
        } else {
            0.0
        };
        run.nl_input.push(match nl.site {
            Site::Drive => ctl.pre_inverse_command(),
            Site::Sensor => y,
            Site::Velocity => v_now,
        });
        run.y.push(y);
        run.u.push(u);
        for _ in 0..m {
            let o_before = dot(c, &x);
            plant.substep(&x, w, &mut xn, &mut xf, fr.as_mut(), o_before);
            out_prev = o_before;
            std::mem::swap(&mut x, &mut xn);
        }
        w_prev = w;
        if !x.iter().all(|v| v.is_finite()) || !y.is_finite() {
            return Err(Error::Numerical(format!(
                "limit-cycle simulation diverged (non-finite state) at sample {k} of {n_samples}"
            )));
        }
    }
    Ok(run)
}

/// The number of controller samples of `spec` at sample time `ts`, after checking the spec.
fn sample_count(spec: &SimSpec, ts: f64) -> Result<usize> {
    let n_samples = spec.duration_s / ts;
    let valid = (1.0..=1e7).contains(&n_samples)
        && spec.substeps != 0
        && spec.reference.is_finite()
        && spec.kick.is_finite();
    if !valid {
        return Err(Error::InvalidArgument(format!(
            "limit-cycle simulation: need 0 < duration (at most 1e7 samples), substeps >= 1 and \
             a finite reference and kick (got {spec:?})"
        )));
    }
    Ok(n_samples.round() as usize)
}

/// The Karnopp stick-slip law of a friction nonlinearity at the velocity site (`None`
/// elsewhere); an error for a non-friction law at the velocity site.
fn friction_law(friction: bool, nl: &Nonlinearity) -> Result<Option<StickSlip>> {
    let fr = match (friction, nl.df) {
        (true, DescribingFunction::Relay { level }) => Some(StickSlip::new(level, level)),
        (true, DescribingFunction::Stiction { level, breakaway }) => {
            Some(StickSlip::new(level, breakaway))
        }
        _ => None,
    };
    if friction && fr.is_none() {
        return Err(Error::InvalidArgument(format!(
            "limit-cycle simulation: {} is not a friction law for the velocity site",
            nl.df.name()
        )));
    }
    Ok(fr)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>()
}

/// The plant's linear dynamics over one sub-step (the whole sample without friction), with the
/// column the friction force enters through and the velocity proxy.
struct SubstepPlant {
    /// States.
    n: usize,
    /// Sub-steps per sample.
    m: usize,
    /// Sub-step length, s.
    h: f64,
    /// A of the sub-step, row-major.
    ad: Vec<f64>,
    /// B of the sub-step.
    bd: Vec<f64>,
    /// The column through which the friction force enters over a sub-step: the plant input's,
    /// or, with friction at the body (`LureLoop::friction_input`), the ZOH of that column.
    bfd: Vec<f64>,
    /// C.
    c: Vec<f64>,
    /// D.
    d: f64,
    /// Whether the velocity is the output's derivative.
    rate: bool,
    /// C·A_c and C·B_c of the continuous plant (empty / 0 without one or without `rate`).
    ca: Vec<f64>,
    cb_c: f64,
    /// Friction on the slowest mode: (p_h, K·(1 − p_h)) of the body state per sub-step.
    body: Option<(f64, f64)>,
    /// Change of the velocity at the end of a sub-step per unit friction force.
    g: f64,
}

impl SubstepPlant {
    /// Linear dynamics: sub-stepped continuous plant for friction when available.
    fn new(lp: &LureLoop, friction: bool, substeps: usize) -> Result<Self> {
        let ts = lp.ts;
        let (sys, m) = match (&lp.plant_continuous, friction) {
            (Some(c), true) => (c.c2d_zoh(ts / substeps as f64)?, substeps),
            _ => (lp.plant.clone(), 1),
        };
        let n = sys.n_states();
        let h = ts / m as f64;
        let ad: Vec<f64> = (0..n * n).map(|k| sys.a[(k / n, k % n)]).collect();
        let bd: Vec<f64> = (0..n).map(|i| sys.b[(i, 0)]).collect();
        let bfd: Vec<f64> = match (&lp.friction_input, &lp.plant_continuous, friction) {
            (Some(bf), Some(pc), true) => {
                let fsys = crate::lti::StateSpace::new(
                    pc.a.clone(),
                    faer::Mat::from_fn(n, 1, |i, _| bf[i]),
                    pc.c.clone(),
                    faer::Mat::zeros(1, 1),
                    0.0,
                )?
                .c2d_zoh(h)?;
                (0..n).map(|i| fsys.b[(i, 0)]).collect()
            }
            _ => bd.clone(),
        };
        let c: Vec<f64> = (0..n).map(|j| sys.c[(0, j)]).collect();
        let d = sys.d[(0, 0)];
        // Velocity proxy: v = C·x (output) or v = C·(A_c x + B_c w) (derivative of the output).
        let rate = lp.velocity == VelocitySource::OutputDerivative;
        let (ca, cb_c) = match (&lp.plant_continuous, rate) {
            (Some(pc), true) => (
                (0..n)
                    .map(|j| (0..n).map(|k| pc.c[(0, k)] * pc.a[(k, j)]).sum())
                    .collect::<Vec<f64>>(),
                (0..n).map(|k| pc.c[(0, k)] * pc.b[(k, 0)]).sum::<f64>(),
            ),
            _ => (Vec::new(), 0.0),
        };
        let g = if !rate {
            dot(&c, &bfd)
        } else if !ca.is_empty() {
            dot(&ca, &bfd)
                + if lp.friction_input.is_some() {
                    0.0
                } else {
                    cb_c
                }
        } else {
            dot(&c, &bfd) / h
        };
        // Friction on the slowest mode (lp.body): a separate first-order body state x_f per
        // sub-step h, x_f ← p_h·x_f + K·(1 − p_h)·F, y = C·x + D·w − x_f (the gap fit's
        // friction port); the velocity is the output.
        let body = match lp.body {
            Some(b) if friction => {
                let ph = (b.pole_rad_s * ts / m as f64).exp();
                Some((ph, b.dc_gain * (1.0 - ph)))
            }
            _ => None,
        };
        let g = body.map_or(g, |(_, k)| k);
        Ok(Self {
            n,
            m,
            h,
            ad,
            bd,
            bfd,
            c,
            d,
            rate,
            ca,
            cb_c,
            body,
            g,
        })
    }

    /// The velocity proxy at state `x` (`x_prev_out`: the output a sub-step earlier, for a
    /// finite difference without a continuous plant; `w`: the plant input).
    fn velocity_of(&self, x: &[f64], x_prev_out: f64, w: f64) -> f64 {
        if !self.rate {
            dot(&self.c, x)
        } else if !self.ca.is_empty() {
            dot(&self.ca, x) + self.cb_c * w
        } else {
            (dot(&self.c, x) - x_prev_out) / self.h
        }
    }

    /// One sub-step from `x` with input `w` into `xn`, the friction law `fr` (if any) deciding
    /// the force from the trial velocity; `xf` is the body state; `o_before` the output at `x`.
    fn substep(
        &self,
        x: &[f64],
        w: f64,
        xn: &mut [f64],
        xf: &mut f64,
        fr: Option<&mut StickSlip>,
        o_before: f64,
    ) {
        let n = self.n;
        for (i, xi) in xn.iter_mut().enumerate() {
            *xi = dot(&self.ad[i * n..(i + 1) * n], x) + self.bd[i] * w;
        }
        match (fr, self.body) {
            (Some(f), Some((ph, k))) => {
                let v_trial = dot(&self.c, xn) - ph * *xf;
                let force = f.force(v_trial, self.g);
                *xf = ph * *xf + k * force;
            }
            (Some(f), None) => {
                let v_trial = self.velocity_of(xn, o_before, w);
                let force = f.force(v_trial, self.g);
                for (xi, b) in xn.iter_mut().zip(&self.bfd) {
                    *xi -= b * force;
                }
            }
            (None, _) => {}
        }
    }
}
