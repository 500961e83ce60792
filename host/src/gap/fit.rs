//! Augmented models (linear part + one effect) and the fits that estimate them.
//!
//! Every candidate is fitted the same way on the training logs, minimising the free-run
//! simulation cost Σ NRMSE² (see [`crate::gap::modal`]):
//! 1. **Grid with the poles fixed.** The effect parameters are searched on a grid spanning the
//!    data's scales (input RMS and peak, sample time, resonance band), on the first
//!    [`COARSE_SAMPLES`] scored samples of each training log, starting from each linear part
//!    offered (the linear re-fit and the nominal sim); every point re-fits the residues,
//!    feedthrough and offset by variable projection (exact least squares for the input-side
//!    effects; one simulate-then-refit step for friction, whose force depends on the model).
//! 2. **Joint refinement.** From the best grid point, Levenberg–Marquardt on all the data over
//!    the poles and the effect parameters together ([`joint_fit`]).
//!
//! Friction acts against the velocity of the driven mass, which a black-box model does not
//! expose: the fit tries both the model output (velocity-output plants) and its time
//! derivative (position-output plants) and keeps the better ([`VelocitySource`]); with the
//! output as the velocity, the friction force enters either at the input or at the slowest real
//! mode only (the driven body behind faster drive dynamics, e.g. a motor's electrical lag:
//! [`FrictionPort`]). Quantization is estimated from the lattice of the measured outputs.
use super::drift::{detrended, scored_sse};
use super::effect::{
    deadzone, delay_signal, quantize, resonance_filter, saturation, Effect, EffectKind, Play,
    RateLimiter, StickSlip, NULL_RESONANCE_CYCLES_PER_SAMPLE,
};
use super::friction_port::fit_linear_params_body;
pub use super::friction_port::{slowest_mode, FrictionPort};
use super::modal::{FitSet, ModalModel};
use super::optim::levenberg_marquardt_steps;
use super::place::{default_place, Candidate, Place, PlacedEffect};
use super::select::lattice_evidence;
use super::state_limit::{limited_mode, state_clamp};
use super::structure::TwoMassModel;
use crate::error::{Error, Result};
use num_complex::Complex64;

/// Sub-steps per sample of the friction loop (friction switches within a sample period).
pub const FRICTION_SUBSTEPS: usize = 4;

/// Which signal of the linear model stands for the velocity that friction opposes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VelocitySource {
    /// The model output itself, output offset included (velocity-output plants).
    Output,
    /// The time derivative of the model output (position-output plants), from the
    /// continuous-time equivalent of the linear part: v = C·(A_c·x + B_c·w). (A model with a
    /// real pole <= 0 has no such equivalent; it falls back to the backward difference of
    /// the output over `ts`.)
    OutputDerivative,
}

impl VelocitySource {
    /// Report name (`output`, `output_derivative`).
    pub fn name(self) -> &'static str {
        match self {
            VelocitySource::Output => "output",
            VelocitySource::OutputDerivative => "output_derivative",
        }
    }
}

/// A linear part with one or more effects.
///
/// The first effect is `effect` at `place` (kept as its own field: most models carry one);
/// further effects of a selected combination are in `extra`. [`Self::effects`] lists them all in
/// signal order: drive → plant (motor / drivetrain / load / state) → sensor. When an effect sits
/// inside a two-mass structure (drivetrain backlash, load friction) the plant is `two_mass`
/// (physical coordinates, [`crate::gap::structure`]) instead of `linear`.
#[derive(Debug, Clone)]
pub struct AugmentedModel {
    /// Linear part (discrete, modal form).
    pub linear: ModalModel,
    /// The (first) effect, if any.
    pub effect: Option<Effect>,
    /// Where `effect` acts.
    pub place: Place,
    /// Further effects, each with its place (pairs).
    pub extra: Vec<PlacedEffect>,
    /// Velocity proxy used by friction effects on the modal linear part.
    pub velocity: VelocitySource,
    /// Where friction on the modal linear part enters it (with [`VelocitySource::Output`]).
    pub friction_port: FrictionPort,
    /// Physical two-mass plant used instead of `linear` when an effect acts inside it.
    pub two_mass: Option<TwoMassModel>,
}

/// The input of the linear part for an input-side effect, `None` for the others.
pub fn input_transform(effect: &Effect, u: &[f64], ts: f64) -> Result<Option<Vec<f64>>> {
    Ok(match *effect {
        Effect::Deadzone { width } => Some(u.iter().map(|&v| deadzone(v, width)).collect()),
        Effect::Saturation { limit } => Some(u.iter().map(|&v| saturation(v, limit)).collect()),
        Effect::Backlash { gap } => {
            let mut p = Play::new(gap);
            Some(u.iter().map(|&v| p.apply(v)).collect())
        }
        Effect::TimeDelay { seconds } => Some(delay_signal(u, seconds / ts)),
        Effect::Resonance { freq_hz, damping } => Some(resonance_filter(u, ts, freq_hz, damping)?),
        Effect::SlewRate { rate } => {
            let mut r = RateLimiter::new(rate * ts);
            Some(u.iter().map(|&v| r.apply(v)).collect())
        }
        _ => None,
    })
}

/// Applies a sensor-side effect to a simulated output in place (no-op for other effects).
pub fn sensor_transform(effect: &Effect, y: &mut [f64]) {
    match *effect {
        Effect::Quantization { step } => y.iter_mut().for_each(|v| *v = quantize(*v, step)),
        Effect::Saturation { limit } => y.iter_mut().for_each(|v| *v = saturation(*v, limit)),
        _ => {}
    }
}

/// Whether a placed effect is friction acting on the modal linear part's input.
fn is_motor_friction(pe: &PlacedEffect) -> bool {
    pe.place == Place::Motor
        && matches!(
            pe.effect,
            Effect::CoulombFriction { .. } | Effect::Stiction { .. }
        )
}

/// (level, breakaway) of a friction effect.
pub fn friction_levels(e: &Effect) -> Option<(f64, f64)> {
    match *e {
        Effect::CoulombFriction { level } => Some((level, level)),
        Effect::Stiction { level, breakaway } => Some((level, breakaway)),
        _ => None,
    }
}

impl AugmentedModel {
    /// The linear model alone.
    pub fn linear(linear: ModalModel) -> Self {
        Self {
            linear,
            effect: None,
            place: Place::Drive,
            extra: Vec::new(),
            velocity: VelocitySource::Output,
            friction_port: FrictionPort::Input,
            two_mass: None,
        }
    }

    /// Report name of the friction's velocity proxy: [`VelocitySource::name`], or
    /// `output_slowest_mode` when friction acts on the slowest mode ([`FrictionPort`]).
    pub fn velocity_label(&self) -> &'static str {
        match self.body_mode() {
            Some(_) => "output_slowest_mode",
            None => self.velocity.name(),
        }
    }

    /// Index of the body mode friction acts on ([`FrictionPort::SlowestMode`]), when the port is
    /// set and the linear part admits it.
    pub fn body_mode(&self) -> Option<usize> {
        if self.friction_port != FrictionPort::SlowestMode
            || self.velocity != VelocitySource::Output
        {
            return None;
        }
        slowest_mode(&self.linear)
    }

    /// Every effect with its place, in signal order (drive, plant, sensor; selection order
    /// within a stage).
    pub fn effects(&self) -> Vec<PlacedEffect> {
        let mut v: Vec<PlacedEffect> = self
            .effect
            .map(|effect| PlacedEffect {
                effect,
                place: self.place,
            })
            .into_iter()
            .chain(self.extra.iter().copied())
            .collect();
        v.sort_by_key(|p| p.place.order());
        v
    }

    /// Every effect in the order they were added (first `effect`, then `extra`).
    pub fn effects_in_selection_order(&self) -> Vec<PlacedEffect> {
        self.effect
            .map(|effect| PlacedEffect {
                effect,
                place: self.place,
            })
            .into_iter()
            .chain(self.extra.iter().copied())
            .collect()
    }

    /// Replaces the effects (same count and order as [`Self::effects_in_selection_order`]).
    pub fn set_effects_in_selection_order(&mut self, list: &[PlacedEffect]) {
        let mut it = list.iter();
        if self.effect.is_some() {
            if let Some(p) = it.next() {
                self.effect = Some(p.effect);
                self.place = p.place;
            }
        }
        self.extra = it.copied().collect();
    }

    /// A copy with `pe` added (as the first effect when there is none).
    pub fn with_added(&self, pe: PlacedEffect) -> Self {
        let mut m = self.clone();
        if m.effect.is_none() {
            m.effect = Some(pe.effect);
            m.place = pe.place;
        } else {
            m.extra.push(pe);
        }
        m
    }

    /// Free-run output for input `u` from rest.
    pub fn simulate(&self, u: &[f64]) -> Result<Vec<f64>> {
        Ok(self.simulate_with_input(u)?.0)
    }

    /// The input after every drive-side effect and a state limit ([`state_clamp`] on the
    /// mode of [`limited_mode`]).
    pub fn drive_input(&self, u: &[f64]) -> Result<Vec<f64>> {
        let mut w = u.to_vec();
        for pe in self.effects() {
            if pe.place == Place::Drive {
                if let Some(t) = input_transform(&pe.effect, &w, self.linear.ts)? {
                    w = t;
                }
            }
        }
        for pe in self.effects() {
            if let Effect::StateLimit { limit } = pe.effect {
                if self.two_mass.is_some() {
                    return Err(Error::InvalidArgument(format!(
                        "{}: a state limit is not realised on a two-mass plant",
                        pe.effect
                    )));
                }
                // Without a limitable mode (e.g. a stand-in pole next to the integrator) the
                // level holds the drive itself (p = 0: an input saturation).
                let p = limited_mode(&self.linear).map_or(0.0, |b| self.linear.real[b]);
                w = state_clamp(&w, p, limit);
            }
        }
        Ok(w)
    }

    /// Motor friction (level, breakaway) acting on the modal linear part, if any.
    pub fn motor_friction(&self) -> Option<(f64, f64)> {
        self.effects()
            .iter()
            .find(|p| is_motor_friction(p))
            .and_then(|p| friction_levels(&p.effect))
    }

    /// Free-run output and the signal that entered the linear part.
    pub fn simulate_with_input(&self, u: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let effects = self.effects();
        let w = self.drive_input(u)?;
        let (mut y, w) = if let Some(tm) = &self.two_mass {
            (tm.simulate(&w, &effects)?, w)
        } else if let Some((level, breakaway)) = self.motor_friction() {
            self.friction_loop(&w, level, breakaway)
        } else {
            (self.linear.simulate(&w), w)
        };
        for pe in &effects {
            if pe.place == Place::Sensor {
                sensor_transform(&pe.effect, &mut y);
            }
        }
        Ok((y, w))
    }
    /// Closed loop of the linear part with stick-slip friction at its input, integrated in
    /// [`FRICTION_SUBSTEPS`] sub-steps per sample (see [`Self::friction_loop_m`]).
    fn friction_loop(&self, u: &[f64], level: f64, breakaway: f64) -> (Vec<f64>, Vec<f64>) {
        self.friction_loop_m(u, level, breakaway, FRICTION_SUBSTEPS)
    }

    /// Closed loop of the linear part with stick-slip friction at its input, in `m` sub-steps
    /// per sample (one when the model has a real pole <= 0, which has no real sub-step).
    /// Returns the output and the per-sample mean of the input that entered the linear part.
    pub fn friction_loop_m(
        &self,
        u: &[f64],
        level: f64,
        breakaway: f64,
        m: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        if let Some(b) = self.body_mode() {
            if let Some((y, f)) = self.friction_loop_body(u, level, breakaway, m, b) {
                // The linear part's input is u; the force acts behind it (see
                // FrictionPort::SlowestMode), so `w` here is u − f only as a summary.
                let w = u.iter().zip(&f).map(|(a, b)| a - b).collect();
                return (y, w);
            }
        }
        let lin = &self.linear;
        let (sub, m) = match lin.substepper(m.max(1)) {
            Some(s) => (s, m.max(1)),
            None => return self.friction_loop_sample_rate(u, level, breakaway),
        };
        let mut fr = StickSlip::new(level, breakaway);
        let cb = sub.cb();
        let rate = self.velocity == VelocitySource::OutputDerivative;
        let g = if rate { sub.rate_gain() } else { cb };
        let mut x = lin.zero_state();
        let mut y = Vec::with_capacity(u.len());
        let mut w = Vec::with_capacity(u.len());
        // State part of the output, carried from sub-step to sub-step: C·x' = C·A_h·x + cb·w.
        let mut yo = 0.0;
        for &uk in u {
            let y0 = yo;
            let mut wsum = 0.0;
            let mut w_first = uk;
            for j in 0..m {
                let next = sub.free_next_output(&x);
                // The velocity is the modelled output itself, offset included: an offset that
                // only shifted the friction's velocity would let a fit bias the mass into
                // never crossing zero speed (friction reduced to a constant force).
                let v_free = if rate {
                    sub.free_next_rate(&x)
                } else {
                    next + lin.offset
                };
                let f = fr.force(v_free + g * uk, g);
                let wj = uk - f;
                if j == 0 {
                    w_first = wj;
                }
                wsum += wj;
                sub.step(&mut x, wj);
                yo = next + cb * wj;
            }
            y.push(y0 + lin.d * w_first + lin.offset);
            w.push(wsum / m as f64);
        }
        (y, w)
    }

    /// Sample-rate version of [`Self::friction_loop_m`] for models without a sub-step.
    fn friction_loop_sample_rate(
        &self,
        u: &[f64],
        level: f64,
        breakaway: f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let lin = &self.linear;
        let ts = lin.ts;
        let mut fr = StickSlip::new(level, breakaway);
        let cb = lin.cb();
        let g = match self.velocity {
            VelocitySource::Output => cb,
            VelocitySource::OutputDerivative => cb / ts,
        };
        let st = lin.stepper();
        let mut x = lin.zero_state();
        let mut y = Vec::with_capacity(u.len());
        let mut w = Vec::with_capacity(u.len());
        for &uk in u {
            let yo = lin.state_output(&x);
            let next = st.free_next_output(&x);
            let v_free = match self.velocity {
                VelocitySource::Output => next + lin.offset,
                VelocitySource::OutputDerivative => (next - yo) / ts,
            };
            let f = fr.force(v_free + g * uk, g);
            let wk = uk - f;
            y.push(yo + lin.d * wk + lin.offset);
            w.push(wk);
            st.step(&mut x, wk);
        }
        (y, w)
    }

    /// Σ NRMSE² on the training set (free run).
    pub fn cost(&self, set: &FitSet, u: &[Vec<f64>]) -> f64 {
        let mut c = 0.0;
        for ((ul, y), &wt) in u.iter().zip(&set.y).zip(&set.weight) {
            let Ok(yh) = self.simulate(ul) else {
                return f64::INFINITY;
            };
            c += wt * scored_sse(y, &yh, set.warmup, set.drift_window);
        }
        if c.is_finite() {
            c
        } else {
            f64::INFINITY
        }
    }
}

/// Training data shared by all candidate fits.
#[derive(Debug, Clone)]
pub struct TrainData {
    /// Sample time, s.
    pub ts: f64,
    /// Training inputs.
    pub u: Vec<Vec<f64>>,
    /// The fit set with w = u.
    pub base: FitSet,
    /// Largest per-log input RMS (input units): the scale of level-type parameter grids.
    pub u_rms: f64,
    /// Largest |u| over the training logs.
    pub u_peak: f64,
}

impl TrainData {
    /// Bundles the training logs (inputs `u`, outputs `y`) with a warm-up in samples.
    pub fn new(ts: f64, u: Vec<Vec<f64>>, y: Vec<Vec<f64>>, warmup: usize) -> Result<Self> {
        let base = FitSet::new(u.clone(), y, warmup)?;
        let u_rms = u
            .iter()
            .map(|v| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt())
            .fold(0.0, f64::max);
        let u_peak = u
            .iter()
            .flat_map(|v| v.iter())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        Ok(Self {
            ts,
            u,
            base,
            u_rms,
            u_peak,
        })
    }
}

impl TrainData {
    /// Largest per-log standard deviation of the measured output (output units).
    pub fn y_std(&self) -> f64 {
        self.base
            .y
            .iter()
            .map(|y| {
                let m = y.iter().sum::<f64>() / y.len() as f64;
                (y.iter().map(|v| (v - m).powi(2)).sum::<f64>() / y.len() as f64).sqrt()
            })
            .fold(0.0f64, f64::max)
            .max(1e-300)
    }

    /// A copy keeping the warm-up and at most `scored` further samples of each log.
    pub fn coarse(&self, scored: usize) -> TrainData {
        let keep = self.base.warmup + scored;
        if self.u.iter().all(|u| u.len() <= keep) {
            return self.clone();
        }
        let cut = |v: &Vec<Vec<f64>>| -> Vec<Vec<f64>> {
            v.iter().map(|x| x[..x.len().min(keep)].to_vec()).collect()
        };
        let u = cut(&self.u);
        let y = cut(&self.base.y);
        match TrainData::new(self.ts, u, y, self.base.warmup) {
            Ok(mut t) => {
                t.base.drift_window = self.base.drift_window;
                t
            }
            Err(_) => self.clone(),
        }
    }
}

/// A fitted candidate.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The model.
    pub model: AugmentedModel,
    /// Its training cost Σ NRMSE².
    pub train_cost: f64,
}

/// Re-fits the linear part's residues (poles fixed) for `effect` and returns the model and its
/// training cost.
fn eval_fixed_poles(
    td: &TrainData,
    lin: &ModalModel,
    effect: Effect,
    velocity: VelocitySource,
) -> Option<Fitted> {
    let mut m = AugmentedModel::linear(lin.clone()).with_added(PlacedEffect::at_default(effect));
    m.velocity = velocity;
    eval_model(td, m, FRICTION_SUBSTEPS)
}

/// Fraction of a sensor limit beyond which measured samples are left out of the linear
/// least-squares step (they carry the clip, not the linear part).
const CLIP_MASK_FRACTION: f64 = 0.98;

/// With the poles and every effect of `model` fixed, re-fits residues, feedthrough and offset
/// (variable projection: exact least squares when the linear part's input does not depend on
/// them; one simulate-then-refit step for motor friction, whose force depends on the model;
/// samples at a sensor clip left out) and returns the model with its training cost. Models on a
/// two-mass plant are only evaluated (their parameters are physical, see
/// [`crate::gap::structure`]). `m`: friction sub-steps.
pub fn eval_model(td: &TrainData, mut model: AugmentedModel, m: usize) -> Option<Fitted> {
    if model.two_mass.is_some() {
        return super::structure::eval_two_mass(td, model);
    }
    let effects = model.effects();
    let clip = effects.iter().find_map(|p| match (p.place, p.effect) {
        (Place::Sensor, Effect::Saturation { limit }) => Some(limit),
        _ => None,
    });
    let only_drive = effects
        .iter()
        .all(|p| p.place == Place::Drive || p.effect.kind() == EffectKind::StateLimit);
    let mask: Option<Vec<Vec<bool>>> = clip.map(|limit| {
        td.base
            .y
            .iter()
            .map(|y| {
                y.iter()
                    .map(|v| v.abs() < CLIP_MASK_FRACTION * limit)
                    .collect()
            })
            .collect()
    });
    let body = model
        .motor_friction()
        .and_then(|lb| Some((lb, model.body_mode()?)));
    let cost = if let Some(((level, breakaway), b)) = body {
        let mut wd = Vec::with_capacity(td.u.len());
        let mut f = Vec::with_capacity(td.u.len());
        for u in &td.u {
            let d = model.drive_input(u).ok()?;
            f.push(model.friction_loop_body(&d, level, breakaway, m, b)?.1);
            wd.push(d);
        }
        fit_linear_params_body(&mut model.linear, &td.base, &wd, &f, b, mask.as_deref())?;
        f64::NAN
    } else {
        let mut w = Vec::with_capacity(td.u.len());
        for u in &td.u {
            let wd = model.drive_input(u).ok()?;
            w.push(match model.motor_friction() {
                Some((level, breakaway)) => model.friction_loop_m(&wd, level, breakaway, m).1,
                None => wd,
            });
        }
        model
            .linear
            .fit_linear_params_with_input(&td.base, &w, mask.as_deref())?
    };
    if only_drive {
        return cost.is_finite().then_some(Fitted {
            model,
            train_cost: cost,
        });
    }
    let mut c = 0.0;
    for ((u, y), &wt) in td.u.iter().zip(&td.base.y).zip(&td.base.weight) {
        let yh = match model.motor_friction() {
            Some((level, breakaway)) if m != FRICTION_SUBSTEPS => {
                let wd = model.drive_input(u).ok()?;
                let mut yh = model.friction_loop_m(&wd, level, breakaway, m).0;
                for p in &effects {
                    if p.place == Place::Sensor {
                        sensor_transform(&p.effect, &mut yh);
                    }
                }
                yh
            }
            _ => model.simulate(u).ok()?,
        };
        c += wt * scored_sse(y, &yh, td.base.warmup, td.base.drift_window);
    }
    c.is_finite().then_some(Fitted {
        model,
        train_cost: c,
    })
}

/// [`eval_model`] of `base` with `effect` added at `place` and the given velocity proxy.
fn eval_added(
    td: &TrainData,
    base: &AugmentedModel,
    effect: Effect,
    place: Place,
    velocity: VelocitySource,
    m: usize,
) -> Option<Fitted> {
    let mut model = base.with_added(PlacedEffect { effect, place });
    model.velocity = velocity;
    eval_model(td, model, m)
}

fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n)
        .map(|i| (a + (b - a) * i as f64 / (n - 1).max(1) as f64).exp())
        .collect()
}

fn keep_best(best: &mut Option<Fitted>, cand: Option<Fitted>) {
    if let Some(c) = cand {
        if best.as_ref().is_none_or(|b| c.train_cost < b.train_cost) {
            *best = Some(c);
        }
    }
}

/// Lower and upper ends of the search range of resonance frequencies, Hz.
pub fn resonance_range_hz(ts: f64) -> (f64, f64) {
    let fs = 1.0 / ts;
    (fs / 1000.0, 0.45 * fs)
}

/// Largest damping ratio a fitted `resonance` may have (a better-damped mode is not a
/// resonance and would mimic a delay or a lag).
pub const MAX_RESONANCE_DAMPING: f64 = 0.3;

/// Smallest damping ratio a fitted `resonance` may have: lighter damping than this is below
/// what any log of practical length resolves (its half-power bandwidth 2ζf would be finer than
/// the frequency resolution of 10^4 periods of the mode), and an optimiser left free drifts to
/// absurd values (1e-107 was once reported).
pub const MIN_RESONANCE_DAMPING: f64 = 1e-4;

/// Longest delay searched, in samples.
pub const MAX_DELAY_SAMPLES: f64 = 32.0;

/// The output quantization step read off the lattice of measured values (see
/// [`crate::gap::select::lattice_evidence`]), `None` when the outputs do not sit on a lattice.
pub fn lattice_step(y: &[Vec<f64>]) -> Option<f64> {
    lattice_evidence(y).map(|l| l.step)
}

/// Samples per training log (after the warm-up) used by the coarse grid stage.
pub const COARSE_SAMPLES: usize = 4096;

/// Iteration cap of the joint Levenberg–Marquardt refinement.
pub const JOINT_MAX_ITER: usize = 12;

/// Iteration cap of the coarse screening refinements (they only rank the starts).
pub const SCREEN_MAX_ITER: usize = 6;

/// Hints that seed or bound a candidate fit (evidence read off the data before fitting).
#[derive(Debug, Clone, Copy, Default)]
pub struct FitHints {
    /// Quantization step from the lattice of the measured outputs.
    pub lattice_step: Option<f64>,
    /// Breakaway level (input units) from dwells at zero velocity.
    pub breakaway: Option<f64>,
}

/// Fits one candidate effect (at its default place) to the training data. `starts` are linear
/// parts to start from (the linear re-fit and the nominal sim in modal form); `coulomb` is the
/// fitted Coulomb candidate (the stiction fit starts from it). See [`fit_placed`].
pub fn fit_candidate(
    kind: EffectKind,
    td: &TrainData,
    starts: &[ModalModel],
    coulomb: Option<&Fitted>,
    sim_poles: &[Complex64],
) -> Option<Fitted> {
    let bases: Vec<AugmentedModel> = starts
        .iter()
        .map(|l| AugmentedModel::linear(l.clone()))
        .collect();
    let hints = FitHints {
        lattice_step: lattice_step(&td.base.y),
        breakaway: None,
    };
    fit_placed(
        Candidate::new(kind, default_place(kind)),
        td,
        &bases,
        coulomb,
        sim_poles,
        &hints,
    )
}

/// Fits `cand` on top of each model in `bases` (linear parts for single effects; the selected
/// model for a second effect) and keeps the best.
///
/// Stage 1 searches the new effect's parameters on a grid over a coarse copy of the training
/// data (the first [`COARSE_SAMPLES`] scored samples of each log) from every base, with the
/// poles and the base's effects fixed; the [`GRID_STARTS`] best grid points of distinct
/// parameter values are screened by a joint refinement on the coarse data (the fixed-pole cost
/// misleads when the base's poles are off); stage 2 refines the winner jointly by
/// Levenberg–Marquardt on all the data ([`joint_fit`]). Stiction starts from the Coulomb fit
/// (`coulomb`, or fitted here) with the breakaway ratio scanned (and seeded by
/// `hints.breakaway`); quantization takes its step from `hints.lattice_step`.
///
/// A candidate never ends worse on the training data than the first base it extends: if the
/// fit does not beat it, the base is returned with the effect at its null parameter (a
/// negligible gap, width, level or delay; a limit far beyond the data), which reproduces the
/// base.
pub fn fit_placed(
    cand: Candidate,
    td: &TrainData,
    bases: &[AugmentedModel],
    coulomb: Option<&Fitted>,
    sim_poles: &[Complex64],
    hints: &FitHints,
) -> Option<Fitted> {
    let kind = cand.kind;
    let base0 = bases.first()?;
    let start = match kind {
        EffectKind::Stiction => {
            let own;
            let c = match coulomb {
                Some(c) => c,
                None => {
                    own = fit_placed(
                        Candidate::new(EffectKind::CoulombFriction, cand.place),
                        td,
                        bases,
                        None,
                        sim_poles,
                        hints,
                    )?;
                    &own
                }
            };
            stiction_start(td, c, hints.breakaway)?
        }
        EffectKind::Quantization => {
            let step = hints.lattice_step?;
            return eval_added(
                td,
                base0,
                Effect::Quantization { step },
                cand.place,
                base0.velocity,
                FRICTION_SUBSTEPS,
            );
        }
        EffectKind::Backlash if cand.place == Place::Drivetrain => {
            let f = super::structure::fit_drivetrain_backlash(
                td,
                bases,
                COARSE_SAMPLES,
                JOINT_MAX_ITER,
            )?;
            return Some(null_guard(td, cand, base0, f));
        }
        _ => {
            let coarse = td.coarse(COARSE_SAMPLES);
            let mut grid: Vec<Fitted> = Vec::new();
            for b in bases {
                grid.extend(initial_search(cand, &coarse, b));
            }
            grid.sort_by(|a, b| a.train_cost.total_cmp(&b.train_cost));
            let key = |f: &Fitted| {
                f.model
                    .effects_in_selection_order()
                    .last()
                    .map_or(f64::NAN, |e| effect_to_coords(&e.effect, td.ts)[0])
            };
            let min_sep = if kind == EffectKind::TimeDelay {
                DISTINCT_DELAY_SAMPLES
            } else {
                DISTINCT_LN
            };
            let mut picked: Vec<Fitted> = Vec::new();
            // Friction on the slowest mode is a basin of its own kind, not of its level: its
            // best grid point is screened too.
            let slowest = grid.iter().find(|g| g.model.body_mode().is_some()).cloned();
            for g in grid {
                if picked.len() >= grid_starts(cand) {
                    break;
                }
                let k = key(&g);
                if picked.iter().all(|p| (key(p) - k).abs() > min_sep) {
                    picked.push(g);
                }
            }
            if let Some(g) = slowest {
                if picked.iter().all(|p| p.model.body_mode().is_none()) {
                    picked.push(g);
                }
            }
            let mut best: Option<Fitted> = None;
            for p in picked {
                let refined = match joint_fit(&coarse, &p, SCREEN_MAX_ITER) {
                    Some(j) if j.train_cost < p.train_cost => j,
                    _ => p,
                };
                keep_best(&mut best, Some(refined));
            }
            eval_model(td, best?.model, FRICTION_SUBSTEPS)?
        }
    };
    let iters = match (cand.place, kind) {
        (Place::Load, _) => JOINT_MAX_ITER / 2,
        // Smooth in its parameters: converges in a few more steps.
        (_, EffectKind::Resonance) => 2 * JOINT_MAX_ITER,
        _ => JOINT_MAX_ITER,
    };
    let fitted = match joint_fit(td, &start, iters) {
        Some(j) if j.train_cost < start.train_cost => j,
        _ => start,
    };
    let fitted = if kind == EffectKind::Resonance && base0.effect.is_none() {
        relabel_resonance(td, fitted, sim_poles)
    } else if kind == EffectKind::StateLimit {
        // Scored by its free run (the guard below compares like with like).
        let train_cost = fitted.model.cost(&td.base, &td.u);
        Fitted {
            model: fitted.model,
            train_cost,
        }
    } else {
        fitted
    };
    Some(null_guard(td, cand, base0, fitted))
}

/// The effect of `kind` at its null parameter: a model with it reproduces the model without it
/// (to 1e-12 of the data's scales; a resonance far above the sample rate, see
/// [`NULL_RESONANCE_CYCLES_PER_SAMPLE`]). `None` never, kept for kinds without a null.
pub fn null_effect(kind: EffectKind, place: Place, td: &TrainData) -> Option<Effect> {
    let s = td.u_rms.max(1e-300);
    let y_peak = td
        .base
        .y
        .iter()
        .flat_map(|y| y.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(1e-300);
    let tiny = 1e-12 * s;
    Some(match kind {
        EffectKind::CoulombFriction => Effect::CoulombFriction { level: tiny },
        EffectKind::Stiction => Effect::Stiction {
            level: tiny,
            breakaway: tiny,
        },
        EffectKind::Backlash => Effect::Backlash { gap: tiny },
        EffectKind::Deadzone => Effect::Deadzone { width: tiny },
        EffectKind::Saturation if place == Place::Sensor => Effect::Saturation {
            limit: 1e12 * y_peak,
        },
        EffectKind::Saturation => Effect::Saturation {
            limit: 1e12 * td.u_peak.max(s),
        },
        EffectKind::TimeDelay => Effect::TimeDelay { seconds: 0.0 },
        EffectKind::SlewRate => Effect::SlewRate {
            rate: 1e12 * td.u_peak.max(s) / td.ts,
        },
        EffectKind::Quantization => Effect::Quantization {
            step: 1e-12 * y_peak,
        },
        EffectKind::StateLimit => Effect::StateLimit {
            limit: 1e12 * td.u_peak.max(s),
        },
        EffectKind::Resonance => Effect::Resonance {
            freq_hz: NULL_RESONANCE_CYCLES_PER_SAMPLE / td.ts,
            damping: MAX_RESONANCE_DAMPING,
        },
    })
}

/// Keeps `fitted` if it is at least as good as `base` on the training data, else returns
/// `base` with the candidate's effect at its null parameter (see [`fit_placed`]).
fn null_guard(td: &TrainData, cand: Candidate, base: &AugmentedModel, fitted: Fitted) -> Fitted {
    let base_cost = base.cost(&td.base, &td.u);
    if fitted.train_cost.partial_cmp(&base_cost) != Some(std::cmp::Ordering::Greater) {
        return fitted;
    }
    let Some(e) = null_effect(cand.kind, cand.place, td) else {
        return fitted;
    };
    let mut model = base.with_added(PlacedEffect {
        effect: e,
        place: cand.place,
    });
    if cand.kind.is_friction() {
        model.velocity = fitted.model.velocity;
        model.friction_port = fitted.model.friction_port;
    }
    let train_cost = model.cost(&td.base, &td.u);
    if train_cost <= fitted.train_cost {
        Fitted { model, train_cost }
    } else {
        fitted
    }
}

/// Largest relative training-cost increase at which a relabelled resonance model counts as
/// fitting the data equally well (see [`relabel_resonance`]).
pub const RELABEL_COST_TOL: f64 = 0.10;

/// Continuous-equivalent (rad/s) of the discrete pole r·e^{jφ} at sample time `ts`.
fn pair_to_s(r: f64, phi: f64, ts: f64) -> Complex64 {
    Complex64::new(r.ln(), phi) / ts
}

/// Natural frequency (Hz) and damping ratio of a continuous pole.
fn freq_damping(s: Complex64) -> (f64, f64) {
    let wn = s.norm();
    (
        wn / (2.0 * std::f64::consts::PI),
        if wn > 0.0 { -s.re / wn } else { 1.0 },
    )
}

/// Σ over the linear part's poles of the relative distance |s − s_sim|/|s_sim| to the nearest
/// pole of the nominal sim (continuous equivalents).
fn distance_to_sim(lin: &ModalModel, sim_s: &[Complex64]) -> f64 {
    lin.poles()
        .iter()
        .map(|&z| {
            let s = z.ln() / lin.ts;
            sim_s
                .iter()
                .map(|&q| (s - q).norm() / q.norm().max(1e-300))
                .fold(f64::INFINITY, f64::min)
        })
        .sum()
}

/// An added mode in series and a mode of the linear part can swap roles with the same
/// input-output behaviour (the residues absorb the difference), so the data alone cannot say
/// which mode is the unmodelled one. Among the labellings that fit the training data within
/// [`RELABEL_COST_TOL`] of the fitted one, this keeps the one whose linear part is closest to
/// the nominal sim's poles (`sim_poles`, discrete at the logs' sample time): the added mode is
/// the one the sim does not have.
fn relabel_resonance(td: &TrainData, fitted: Fitted, sim_poles: &[Complex64]) -> Fitted {
    let Some(Effect::Resonance { freq_hz, damping }) = fitted.model.effect else {
        return fitted;
    };
    let sim_s: Vec<Complex64> = sim_poles
        .iter()
        .filter(|z| z.norm() > 0.0)
        .map(|&z| z.ln() / td.ts)
        .collect();
    if sim_s.is_empty() {
        return fitted;
    }
    let lin = &fitted.model.linear;
    let (flo, fhi) = resonance_range_hz(td.ts);
    let w = 2.0 * std::f64::consts::PI * freq_hz;
    let s_eff = Complex64::new(-damping * w, w * (1.0 - damping * damping).max(0.0).sqrt());
    let z_eff = (s_eff * td.ts).exp();
    let mut best_d = distance_to_sim(lin, &sim_s);
    let mut best = fitted.clone();
    for (i, &(r, phi)) in lin.pairs.iter().enumerate() {
        let (f, z) = freq_damping(pair_to_s(r, phi, td.ts));
        if !(flo..=fhi).contains(&f)
            || !(MIN_RESONANCE_DAMPING..=MAX_RESONANCE_DAMPING).contains(&z)
        {
            continue;
        }
        let mut swapped = lin.clone();
        swapped.pairs[i] = (z_eff.norm(), z_eff.im.atan2(z_eff.re));
        let effect = Effect::Resonance {
            freq_hz: f,
            damping: z,
        };
        let Some(start) = eval_fixed_poles(td, &swapped, effect, VelocitySource::Output) else {
            continue;
        };
        let cand = match joint_fit(td, &start, JOINT_MAX_ITER) {
            Some(j) if j.train_cost < start.train_cost => j,
            _ => start,
        };
        if cand.train_cost > fitted.train_cost * (1.0 + RELABEL_COST_TOL) {
            continue;
        }
        let d = distance_to_sim(&cand.model.linear, &sim_s);
        if d < best_d {
            best_d = d;
            best = cand;
        }
    }
    best
}

/// Grid points screened by a coarse joint refinement in [`fit_placed`] (the best of
/// distinct parameter values).
pub const GRID_STARTS: usize = 3;

/// Screened grid points for a candidate: [`GRID_STARTS`]; two for motor friction, one for
/// friction on the load (a two-mass fit in physical coordinates, the costliest).
fn grid_starts(cand: Candidate) -> usize {
    match (cand.place, cand.kind) {
        (Place::Load, _) => 1,
        // The friction loop is the costliest simulation: two screened starts.
        (_, EffectKind::CoulombFriction) => 2,
        _ => GRID_STARTS,
    }
}

/// Grid points whose first parameter (level, gap, width, limit, frequency) differs by less than
/// this in ln (a factor 1.5) count as the same start.
const DISTINCT_LN: f64 = 0.405;

/// Delays closer than this (samples) count as the same start.
const DISTINCT_DELAY_SAMPLES: f64 = 1.0;

/// The stiction start: the fitted Coulomb model with the breakaway ratio giving the lowest
/// training cost among 1.1 … 3.4 (and the ratio `breakaway`/level from dwell evidence, when
/// given).
fn stiction_start(td: &TrainData, c: &Fitted, breakaway: Option<f64>) -> Option<Fitted> {
    let list = c.model.effects_in_selection_order();
    let idx = list
        .iter()
        .rposition(|p| p.effect.kind() == EffectKind::CoulombFriction)?;
    let Effect::CoulombFriction { level } = list[idx].effect else {
        return None;
    };
    let mut ratios = vec![1.1, 1.3, 1.6, 2.0, 2.6, 3.4];
    if let Some(b) = breakaway {
        if b > level && b < 5.0 * level {
            ratios.push(b / level);
        }
    }
    let mut best: Option<Fitted> = None;
    for ratio in ratios {
        let mut m = c.model.clone();
        let mut l = list.clone();
        l[idx].effect = Effect::Stiction {
            level,
            breakaway: level * ratio,
        };
        m.set_effects_in_selection_order(&l);
        let cost = m.cost(&td.base, &td.u);
        keep_best(
            &mut best,
            cost.is_finite().then_some(Fitted {
                model: m,
                train_cost: cost,
            }),
        );
    }
    best
}

/// Unconstrained coordinates of an effect's parameters and back (see [`joint_fit`]).
fn effect_to_coords(e: &Effect, ts: f64) -> Vec<f64> {
    match *e {
        Effect::CoulombFriction { level } => vec![level.ln()],
        Effect::Stiction { level, breakaway } => {
            vec![level.ln(), (breakaway / level - 1.0).max(1e-4).ln()]
        }
        Effect::Backlash { gap } => vec![gap.ln()],
        Effect::Deadzone { width } => vec![width.ln()],
        Effect::Saturation { limit } => vec![limit.ln()],
        Effect::TimeDelay { seconds } => vec![seconds / ts],
        Effect::Resonance { freq_hz, damping } => vec![freq_hz.ln(), damping.ln()],
        Effect::Quantization { step } => vec![step.ln()],
        Effect::SlewRate { rate } => vec![rate.ln()],
        Effect::StateLimit { limit } => vec![limit.ln()],
    }
}

fn effect_from_coords(kind: EffectKind, c: &[f64], ts: f64) -> Option<Effect> {
    let e = match kind {
        EffectKind::CoulombFriction => Effect::CoulombFriction { level: c[0].exp() },
        EffectKind::Stiction => Effect::Stiction {
            level: c[0].exp(),
            breakaway: c[0].exp() * (1.0 + c[1].exp()),
        },
        EffectKind::Backlash => Effect::Backlash { gap: c[0].exp() },
        EffectKind::Deadzone => Effect::Deadzone { width: c[0].exp() },
        EffectKind::Saturation => Effect::Saturation { limit: c[0].exp() },
        EffectKind::TimeDelay => {
            if c[0] < 0.0 || c[0] > MAX_DELAY_SAMPLES {
                return None;
            }
            Effect::TimeDelay { seconds: c[0] * ts }
        }
        EffectKind::Resonance => {
            let (f, z) = (c[0].exp(), c[1].exp());
            let (flo, fhi) = resonance_range_hz(ts);
            if !(flo..=fhi).contains(&f)
                || !(MIN_RESONANCE_DAMPING..=MAX_RESONANCE_DAMPING).contains(&z)
            {
                return None;
            }
            Effect::Resonance {
                freq_hz: f,
                damping: z,
            }
        }
        EffectKind::Quantization => Effect::Quantization { step: c[0].exp() },
        EffectKind::SlewRate => Effect::SlewRate { rate: c[0].exp() },
        EffectKind::StateLimit => Effect::StateLimit { limit: c[0].exp() },
    };
    e.validate().ok().map(|_| e)
}

/// Forward-difference step for an effect coordinate: 1e-3 (log units, or samples for the
/// delay) — these costs are only piecewise smooth in the parameter — and 1e-5 for the smooth
/// resonance coordinates.
fn effect_coord_step(kind: EffectKind) -> f64 {
    match kind {
        EffectKind::Resonance => 1e-5,
        _ => 1e-3,
    }
}

/// Whether the LM refinement moves this effect's parameters (the quantization step is read
/// off the data's lattice and stays fixed).
fn is_free(kind: EffectKind) -> bool {
    kind != EffectKind::Quantization
}

/// Stage 2 of [`fit_placed`]: Levenberg–Marquardt on the simulated error over all parameters
/// at once, from `start`. When the linear part's input does not depend on the model (effects
/// in the drive, quantization at the sensor), the coordinates are the pole parameters and the
/// effect parameters, with residues, feedthrough and offset eliminated by variable projection
/// (exact for these structures). Otherwise (motor friction, whose force depends on the model
/// output; a sensor clip) residues, feedthrough and offset are coordinates too. Models on a
/// two-mass plant are refined in physical coordinates by [`crate::gap::structure`].
/// (Alternating between the linear part and the effect stalls: a linear part fitted to a
/// wrongly distorted input is self-consistent.)
pub fn joint_fit(td: &TrainData, start: &Fitted, max_iter: usize) -> Option<Fitted> {
    let m0 = &start.model;
    if m0.two_mass.is_some() {
        return super::structure::joint_fit_two_mass(td, start, max_iter);
    }
    let list0 = m0.effects_in_selection_order();
    if list0.is_empty() || !list0.iter().any(|p| is_free(p.effect.kind())) {
        return None;
    }
    let lin0 = &m0.linear;
    let n = lin0.n_states();
    let ts = td.ts;
    let projectable = list0.iter().all(|p| {
        p.place == Place::Drive
            || (p.place == Place::Sensor && p.effect.kind() == EffectKind::Quantization)
            || p.effect.kind() == EffectKind::StateLimit
    });
    let mut theta0 = lin0.pole_params();
    let mut steps: Vec<f64> = theta0.iter().map(|t| 1e-6 * t.abs().max(1.0)).collect();
    let mut spans: Vec<(usize, usize)> = Vec::new();
    for p in &list0 {
        let k = p.effect.kind();
        if is_free(k) {
            let c = effect_to_coords(&p.effect, ts);
            spans.push((theta0.len(), c.len()));
            steps.extend(std::iter::repeat_n(effect_coord_step(k), c.len()));
            theta0.extend(c);
        } else {
            spans.push((theta0.len(), 0));
        }
    }
    let n_eff_end = theta0.len();
    // Linear coordinates (when not projectable), scaled to O(1).
    let cmax = lin0
        .residues
        .iter()
        .fold(0.0f64, |a, b| a.max(b.abs()))
        .max(1e-300);
    let cscale: Vec<f64> = lin0
        .residues
        .iter()
        .map(|c| c.abs().max(1e-3 * cmax))
        .collect();
    let ystd = td.y_std();
    let dscale = lin0.d.abs().max(1e-3 * ystd / td.u_rms.max(1e-300));
    let use_d = lin0.use_d;
    if !projectable {
        let extra = n + usize::from(use_d) + 1;
        theta0.extend(std::iter::repeat_n(0.0, extra));
        steps.extend(std::iter::repeat_n(1e-6, extra));
    }
    let build = |th: &[f64]| -> Option<AugmentedModel> {
        let mut lin = lin0.clone();
        lin.set_pole_params(&th[..n]);
        let mut list = list0.clone();
        for (p, &(at, len)) in list.iter_mut().zip(&spans) {
            if len > 0 {
                p.effect = effect_from_coords(p.effect.kind(), &th[at..at + len], ts)?;
            }
        }
        if !projectable {
            let mut k = n_eff_end;
            for i in 0..n {
                lin.residues[i] = lin0.residues[i] + cscale[i] * th[k + i];
            }
            k += n;
            if use_d {
                lin.d = lin0.d + dscale * th[k];
                k += 1;
            }
            lin.offset = lin0.offset + ystd * th[k];
        }
        let mut m = m0.clone();
        m.linear = lin;
        m.set_effects_in_selection_order(&list);
        Some(m)
    };
    let scored: usize = td
        .base
        .y
        .iter()
        .map(|y| y.len().saturating_sub(td.base.warmup))
        .sum();
    let residuals = |th: &[f64]| -> Option<Vec<f64>> {
        let mut model = build(th)?;
        if projectable {
            let mut w = Vec::with_capacity(td.u.len());
            for u in &td.u {
                w.push(model.drive_input(u).ok()?);
            }
            model
                .linear
                .fit_linear_params_with_input(&td.base, &w, None)?;
        }
        let mut r = Vec::with_capacity(scored);
        for ((u, y), &wt) in td.u.iter().zip(&td.base.y).zip(&td.base.weight) {
            let yh = model.simulate(u).ok()?;
            let sw = wt.sqrt();
            let e = y.iter().zip(&yh).skip(td.base.warmup).map(|(a, b)| a - b);
            match td.base.drift_window {
                Some(w) => r.extend(detrended(&e.collect::<Vec<_>>(), w).iter().map(|v| sw * v)),
                None => r.extend(e.map(|v| sw * v)),
            }
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    };
    let (theta, _) = levenberg_marquardt_steps(residuals, &theta0, &steps, max_iter, 1e-6);
    let mut model = build(&theta)?;
    if projectable {
        let mut w = Vec::with_capacity(td.u.len());
        for u in &td.u {
            w.push(model.drive_input(u).ok()?);
        }
        model
            .linear
            .fit_linear_params_with_input(&td.base, &w, None)?;
    }
    let train_cost = model.cost(&td.base, &td.u);
    train_cost
        .is_finite()
        .then_some(Fitted { model, train_cost })
}

/// Resonance frequencies (Hz) to search: a log grid over [`resonance_range_hz`] at about 12 %
/// spacing plus a 2.5 % grid around the strongest peaks of the base model's residual spectrum
/// (a lightly damped mode is only found near its frequency).
fn resonance_grid_hz(td: &TrainData, base: &AugmentedModel) -> Vec<f64> {
    let (flo, fhi) = resonance_range_hz(td.ts);
    let n = ((fhi / flo).ln() / 0.12).ceil() as usize + 1;
    let mut f = log_grid(flo, fhi, n);
    for peak in residual_peaks_hz(td, base, 3) {
        for i in -4i32..=4 {
            let v = peak * (0.025 * i as f64).exp();
            if (flo..=fhi).contains(&v) {
                f.push(v);
            }
        }
    }
    f.sort_by(f64::total_cmp);
    f
}

/// The `k` frequencies (Hz) where the residual of `base` on the training logs has the largest
/// power relative to the output's, from a DFT at 4 % log spacing over the resonance range.
fn residual_peaks_hz(td: &TrainData, base: &AugmentedModel, k: usize) -> Vec<f64> {
    let (flo, fhi) = resonance_range_hz(td.ts);
    let n = ((fhi / flo).ln() / 0.04).ceil() as usize + 1;
    let freqs = log_grid(flo.max(2.0 / (td.ts * COARSE_SAMPLES as f64)), fhi, n);
    let mut score = vec![0.0; freqs.len()];
    for (u, y) in td.u.iter().zip(&td.base.y) {
        let Ok(yh) = base.simulate(u) else {
            return Vec::new();
        };
        let w0 = td.base.warmup;
        let r: Vec<f64> = y.iter().zip(&yh).skip(w0).map(|(a, b)| a - b).collect();
        let yy: Vec<f64> = y[w0..].to_vec();
        let hann = hann_window(r.len());
        for (i, &f) in freqs.iter().enumerate() {
            let pr = dft_power(&r, &hann, f * td.ts);
            let py = dft_power(&yy, &hann, f * td.ts);
            if py > 0.0 {
                score[i] += pr / py;
            }
        }
    }
    let mut idx: Vec<usize> = (0..freqs.len()).collect();
    idx.sort_by(|&a, &b| score[b].total_cmp(&score[a]));
    let mut out: Vec<f64> = Vec::new();
    for i in idx {
        if out.len() >= k {
            break;
        }
        if out.iter().all(|&o| (freqs[i] / o).ln().abs() > 0.1) {
            out.push(freqs[i]);
        }
    }
    out
}

/// The Hann window of [`dft_power`] for a signal of `n` samples: its value at every
/// `(n / 8192).max(1)`-th sample (the samples the DFT uses).
fn hann_window(n: usize) -> Vec<f64> {
    let step = (n / 8192).max(1);
    (0..n / step)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * (i * step) as f64 / n as f64).cos())
        .collect()
}

/// |Σ x_t e^{−j2πνt}|² with a Hann window over a band of ±2 % of ν (cycles per sample),
/// averaged over 5 frequencies so a line between grid points is not missed. `hann`: the
/// window from [`hann_window`] for `x.len()` samples.
fn dft_power(x: &[f64], hann: &[f64], nu: f64) -> f64 {
    let n = x.len();
    if n < 2 {
        return 0.0;
    }
    let step = (n / 8192).max(1);
    let mut acc = 0.0;
    for j in -2i32..=2 {
        let f = nu * (1.0 + 0.01 * j as f64);
        let (mut re, mut im) = (0.0, 0.0);
        let w = 2.0 * std::f64::consts::PI * f;
        let (s, c) = w.sin_cos();
        let (mut cr, mut ci) = (1.0f64, 0.0f64);
        // Every `step`-th sample enters the sum; the rotation advances at every sample.
        for (chunk, &hw) in x[..step * (n / step)].chunks_exact(step).zip(hann) {
            let v = chunk[0];
            re += hw * v * cr;
            im -= hw * v * ci;
            for _ in 0..step {
                let nr = cr * c - ci * s;
                ci = cr * s + ci * c;
                cr = nr;
            }
        }
        acc += re * re + im * im;
    }
    acc
}

/// Stage 1 of [`fit_placed`]: every point of the grid of the candidate's parameters added to
/// `base` with its poles and effects fixed (the residues re-fitted at every point), on the
/// (coarse) data `td`.
fn initial_search(cand: Candidate, td: &TrainData, base: &AugmentedModel) -> Vec<Fitted> {
    if cand.place.needs_two_mass() || base.two_mass.is_some() {
        return super::structure::initial_search_two_mass(cand, td, base);
    }
    let s = td.u_rms.max(1e-300);
    let ts = td.ts;
    let out = base.velocity;
    let m = FRICTION_SUBSTEPS;
    let place = cand.place;
    let on_grid = |grid: &[f64], make: &dyn Fn(f64) -> Effect| -> Vec<Fitted> {
        grid.iter()
            .filter_map(|&p| eval_added(td, base, make(p), place, out, m))
            .collect()
    };
    match cand.kind {
        EffectKind::CoulombFriction => {
            // Sample-rate friction (only the basin matters here). The velocity follows from
            // the structure: the derivative of the output when the linear part integrates
            // (position output); otherwise both proxies are tried.
            let grid = log_grid(0.01 * s, 1.5 * s, 12);
            let mut all = Vec::new();
            let sources: &[(VelocitySource, FrictionPort)] = if base.linear.real.contains(&1.0) {
                &[(VelocitySource::OutputDerivative, FrictionPort::Input)]
            } else if place == Place::Motor && slowest_mode(&base.linear).is_some() {
                &[
                    (VelocitySource::Output, FrictionPort::Input),
                    (VelocitySource::OutputDerivative, FrictionPort::Input),
                    (VelocitySource::Output, FrictionPort::SlowestMode),
                ]
            } else {
                &[
                    (VelocitySource::Output, FrictionPort::Input),
                    (VelocitySource::OutputDerivative, FrictionPort::Input),
                ]
            };
            for &(vel, port) in sources {
                all.extend(grid.iter().filter_map(|&p| {
                    let mut b = base.clone();
                    b.friction_port = port;
                    eval_added(td, &b, Effect::CoulombFriction { level: p }, place, vel, 1)
                }));
            }
            all
        }
        EffectKind::Backlash => on_grid(&log_grid(0.01 * s, 2.0 * s, 16), &|p| Effect::Backlash {
            gap: p,
        }),
        EffectKind::Deadzone => on_grid(&log_grid(0.01 * s, 2.0 * s, 16), &|p| Effect::Deadzone {
            width: p,
        }),
        EffectKind::Saturation if place == Place::Sensor => {
            let y_peak = td
                .base
                .y
                .iter()
                .flat_map(|y| y.iter())
                .fold(0.0f64, |a, v| a.max(v.abs()));
            on_grid(&log_grid(0.6 * y_peak, 1.02 * y_peak, 12), &|p| {
                Effect::Saturation { limit: p }
            })
        }
        EffectKind::Saturation => {
            let hi = td.u_peak.max(0.25 * s);
            on_grid(&log_grid(0.2 * s, hi, 16), &|p| Effect::Saturation {
                limit: p,
            })
        }
        EffectKind::TimeDelay => {
            let grid: Vec<f64> = (0..=(2.0 * MAX_DELAY_SAMPLES) as usize)
                .map(|i| 0.5 * i as f64 * ts)
                .collect();
            on_grid(&grid, &|p| Effect::TimeDelay { seconds: p })
        }
        EffectKind::SlewRate => {
            let dmax =
                td.u.iter()
                    .flat_map(|u| u.windows(2).map(|w| (w[1] - w[0]).abs()))
                    .fold(0.0f64, f64::max);
            if dmax <= 0.0 {
                return Vec::new();
            }
            on_grid(&log_grid(0.03 * dmax / ts, dmax / ts, 12), &|p| {
                Effect::SlewRate { rate: p }
            })
        }
        EffectKind::Resonance => {
            let mut all = Vec::new();
            for f in resonance_grid_hz(td, base) {
                for &z in &[0.02, 0.1] {
                    all.extend(eval_added(
                        td,
                        base,
                        Effect::Resonance {
                            freq_hz: f,
                            damping: z,
                        },
                        place,
                        out,
                        m,
                    ));
                }
            }
            all
        }
        EffectKind::StateLimit => {
            // The grid spans the levels the limited mode's state reaches on the training
            // inputs (in input units: state·(1 − p)), from a tenth of its RMS to its peak: a
            // slow mode low-passes the input, so its level can sit far below the input's.
            let Some(b) = limited_mode(&base.linear) else {
                return Vec::new();
            };
            let p = base.linear.real[b];
            let (mut sum2, mut count, mut peak) = (0.0, 0usize, 0.0f64);
            for u in &td.u {
                let Ok(w) = base.drive_input(u) else {
                    return Vec::new();
                };
                let mut x = 0.0;
                for wk in w {
                    x = p * x + wk;
                    let v = x * (1.0 - p);
                    sum2 += v * v;
                    count += 1;
                    peak = peak.max(v.abs());
                }
            }
            let rms = (sum2 / count.max(1) as f64).sqrt();
            if !(rms > 0.0 && peak.is_finite()) {
                return Vec::new();
            }
            on_grid(&log_grid(0.1 * rms, peak, 16), &|p| Effect::StateLimit {
                limit: p,
            })
        }
        EffectKind::Stiction | EffectKind::Quantization => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::benchmark::filtered_noise;
    use crate::gap::plant::{simulate, Plant, SimSettings};
    use crate::gap::rng::Rng;

    /// The exact ZOH model of a plant's linear part as a modal model with fitted residues.
    fn exact_modal(plant: &Plant, ts: f64, u: &[f64], y_lin: &[f64]) -> ModalModel {
        let d = plant.physical().unwrap().sys.c2d_zoh(ts).unwrap();
        let mut m = ModalModel::from_poles(ts, &d.poles().unwrap(), false).unwrap();
        let set = FitSet::new(vec![u.to_vec()], vec![y_lin.to_vec()], 0).unwrap();
        let c = m.fit_linear_params(&set).unwrap();
        assert!(c < 1e-12, "exact modal fit cost {c}");
        m
    }

    fn check_friction(
        plant: Plant,
        amp: f64,
        level: f64,
        breakaway: f64,
        vel: VelocitySource,
    ) -> f64 {
        check_friction_at(plant, amp, level, breakaway, vel, FrictionPort::Input)
    }

    fn check_friction_at(
        plant: Plant,
        amp: f64,
        level: f64,
        breakaway: f64,
        vel: VelocitySource,
        port: FrictionPort,
    ) -> f64 {
        let ts = 1e-3;
        let mut rng = Rng::new(5);
        let u = filtered_noise(8000, ts, 100.0, amp, &mut rng);
        let s = SimSettings {
            ts,
            substeps: 8,
            noise_std: 0.0,
            seed: 0,
        };
        let y_lin = simulate(&plant, None, &u, &s).unwrap();
        let effect = Effect::Stiction { level, breakaway };
        let y_true = simulate(&plant, Some(&effect), &u, &s).unwrap();
        let mut m = AugmentedModel::linear(exact_modal(&plant, ts, &u, &y_lin))
            .with_added(PlacedEffect::at_default(effect));
        m.velocity = vel;
        m.friction_port = port;
        let y = m.simulate(&u).unwrap();
        let s1 = SimSettings { substeps: 1, ..s };
        let y_true1 = simulate(&plant, Some(&effect), &u, &s1).unwrap();
        eprintln!(
            "truth(1) vs model {:.4}, truth(8) vs truth(1) {:.4}",
            crate::gap::modal::nrmse(&y_true1, &y, 0),
            crate::gap::modal::nrmse(&y_true, &y_true1, 0)
        );
        crate::gap::modal::nrmse(&y_true, &y, 0)
    }

    #[test]
    fn sample_rate_friction_matches_substepped_plant() {
        let e = check_friction(
            Plant::two_mass(),
            0.05,
            0.015,
            0.015,
            VelocitySource::Output,
        );
        let e2 = check_friction(Plant::two_mass(), 0.05, 0.015, 0.03, VelocitySource::Output);
        let e3 = check_friction(
            Plant::flexure(),
            1.0,
            0.3,
            0.3,
            VelocitySource::OutputDerivative,
        );
        let e4 = check_friction(Plant::dc_motor(), 1.0, 0.3, 0.3, VelocitySource::Output);
        eprintln!("two_mass coulomb {e:.4} stiction {e2:.4} flexure {e3:.4} dc {e4:.4}");
        assert!(e < 0.05 && e2 < 0.05);
    }

    /// The voltage-driven DC motor (friction torque on the rotor, behind the armature's
    /// electrical lag): friction on the slowest mode reproduces the substepped plant's stick-slip
    /// (breakaway twice the sliding level), friction at the voltage input does not (holding the
    /// rotor there would take a voltage that stops the current within a sub-step).
    #[test]
    fn slowest_mode_friction_matches_a_motor_behind_its_electrical_lag() {
        let body = check_friction_at(
            Plant::dc_motor(),
            1.0,
            0.3,
            0.6,
            VelocitySource::Output,
            FrictionPort::SlowestMode,
        );
        let input = check_friction_at(
            Plant::dc_motor(),
            1.0,
            0.3,
            0.6,
            VelocitySource::Output,
            FrictionPort::Input,
        );
        eprintln!("dc motor stiction: slowest mode {body:.4}, input {input:.4}");
        assert!(body < 0.03, "slowest-mode friction error {body}");
        assert!(body < 0.5 * input, "slowest mode {body} vs input {input}");
    }

    /// The slowest-mode port's variable projection recovers the residues of a model it
    /// generated (friction forces held fixed): the regressors are exact.
    #[test]
    fn slowest_mode_projection_recovers_its_own_residues() {
        let ts = 1e-3;
        let mut lin = ModalModel::from_poles(
            ts,
            &[
                num_complex::Complex64::new(0.3, 0.0),
                num_complex::Complex64::new(0.99, 0.0),
            ],
            false,
        )
        .unwrap();
        lin.residues = vec![-2.0, 0.5];
        lin.offset = 0.1;
        let mut m = AugmentedModel::linear(lin.clone()).with_added(PlacedEffect::at_default(
            Effect::CoulombFriction { level: 0.2 },
        ));
        m.friction_port = FrictionPort::SlowestMode;
        let b = m.body_mode().expect("eligible");
        assert_eq!(b, 1);
        let mut rng = Rng::new(3);
        let u = filtered_noise(4000, ts, 50.0, 1.0, &mut rng);
        let (y, f) = m.friction_loop_body(&u, 0.2, 0.2, 1, b).unwrap();
        let set = FitSet::new(vec![u.clone()], vec![y], 10).unwrap();
        let mut fitted = lin.clone();
        fitted.residues = vec![0.0, 0.0];
        fitted.offset = 0.0;
        fit_linear_params_body(&mut fitted, &set, &[u], &[f], b, None).unwrap();
        for (a, e) in fitted.residues.iter().zip(&lin.residues) {
            assert!((a - e).abs() < 1e-8 * e.abs(), "{:?}", fitted.residues);
        }
        assert!((fitted.offset - 0.1).abs() < 1e-9);
    }
}
