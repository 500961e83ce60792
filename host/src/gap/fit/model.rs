//! The augmented model: a linear part in modal form with effects at their places, its free run
//! and the friction loop.
use super::FRICTION_SUBSTEPS;
use crate::error::{Error, Result};
use crate::gap::drift::scored_sse;
use crate::gap::effect::{
    deadzone, delay_signal, quantize, resonance_filter, saturation, Effect, Play, RateLimiter,
    StickSlip,
};
use crate::gap::friction_port::{slowest_mode, FrictionPort};
use crate::gap::modal::{FitSet, ModalModel, SubStep};
use crate::gap::place::{Place, PlacedEffect};
use crate::gap::state_limit::{limited_mode, rate_clamp, state_clamp};
use crate::gap::structure::TwoMassModel;

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
            Some(u.iter().map(|&v| r.apply_averaged(v)).collect())
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

    /// A copy without the `i`-th effect of [`Self::effects_in_selection_order`] (the others and
    /// the linear part unchanged).
    pub fn without(&self, i: usize) -> Self {
        let mut m = self.clone();
        m.effect = None;
        m.place = Place::Drive;
        m.extra.clear();
        for (j, pe) in self.effects_in_selection_order().into_iter().enumerate() {
            if j != i {
                m = m.with_added(pe);
            }
        }
        m
    }

    /// Free-run output for input `u` from rest.
    pub fn simulate(&self, u: &[f64]) -> Result<Vec<f64>> {
        Ok(self.simulate_with_input(u)?.0)
    }

    /// The input after every drive-side effect and a state or current limit ([`state_clamp`]
    /// or [`rate_clamp`] on the mode of [`limited_mode`]).
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
            if let Effect::StateLimit { limit } | Effect::CurrentLimit { limit } = pe.effect {
                if self.two_mass.is_some() {
                    return Err(Error::InvalidArgument(format!(
                        "{}: a state limit is not realised on a two-mass plant",
                        pe.effect
                    )));
                }
                // Without a limitable mode (e.g. a stand-in pole next to the integrator) the
                // level holds the drive itself (p = 0: an input saturation).
                let p = limited_mode(&self.linear).map_or(0.0, |b| self.linear.real[b]);
                w = match pe.effect {
                    Effect::CurrentLimit { .. } => rate_clamp(&w, p, limit),
                    _ => state_clamp(&w, p, limit),
                };
            }
        }
        Ok(w)
    }

    /// The law of the motor friction acting on the modal linear part, if any.
    pub fn motor_friction(&self) -> Option<StickSlip> {
        self.effects()
            .iter()
            .find(|p| is_motor_friction(p))
            .and_then(|p| StickSlip::of(&p.effect))
    }

    /// Free-run output and the signal that entered the linear part.
    pub fn simulate_with_input(&self, u: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let effects = self.effects();
        let w = self.drive_input(u)?;
        let (mut y, w) = if let Some(tm) = &self.two_mass {
            (tm.simulate(&w, &effects)?, w)
        } else if let Some(law) = self.motor_friction() {
            self.friction_loop(&w, law)
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
    fn friction_loop(&self, u: &[f64], law: StickSlip) -> (Vec<f64>, Vec<f64>) {
        self.friction_loop_m(u, law, FRICTION_SUBSTEPS)
    }

    /// Closed loop of the linear part with stick-slip friction at its input, in `m` sub-steps
    /// per sample (one when the model has a real pole <= 0, which has no real sub-step).
    /// Returns the output and the per-sample mean of the input that entered the linear part.
    pub fn friction_loop_m(&self, u: &[f64], law: StickSlip, m: usize) -> (Vec<f64>, Vec<f64>) {
        if let Some(b) = self.body_mode() {
            if let Some((y, f)) = self.friction_loop_body(u, law, m, b) {
                // The linear part's input is u; the force acts behind it (see
                // FrictionPort::SlowestMode), so `w` here is u − f only as a summary.
                let w = u.iter().zip(&f).map(|(a, b)| a - b).collect();
                return (y, w);
            }
        }
        let lin = &self.linear;
        let (sub, m) = match lin.substepper(m.max(1)) {
            Some(s) => (s, m.max(1)),
            None => return self.friction_loop_sample_rate(u, law),
        };
        let cb = sub.cb();
        let rate = self.velocity == VelocitySource::OutputDerivative;
        let g = if rate { sub.rate_gain() } else { cb };
        let run = FrictionRun {
            law,
            m,
            rate,
            g,
            cb,
            d: lin.d,
            offset: lin.offset,
        };
        // The usual mode counts with the state on the stack (the same bits as the general
        // stepper, see SubStep).
        macro_rules! fixed {
            ($(($nr:literal, $np:literal))*) => {
                match (lin.real.len(), lin.pairs.len()) {
                    $(($nr, $np) => {
                        if let Some(f) = sub.fixed::<$nr, $np>() {
                            return run.on(&f, u);
                        }
                    })*
                    _ => {}
                }
            };
        }
        fixed!(
            (1, 0)(2, 0)(3, 0)(4, 0)(5, 0)(6, 0)(0, 1)(1, 1)(2, 1)(3, 1)(4, 1)(0, 2)(1, 2)(2, 2)(
                3, 2
            )(4, 2)(0, 3)(1, 3)(2, 3)(0, 4)
        );
        run.on(&sub, u)
    }

    /// Sample-rate version of [`Self::friction_loop_m`] for models without a sub-step.
    fn friction_loop_sample_rate(&self, u: &[f64], law: StickSlip) -> (Vec<f64>, Vec<f64>) {
        let lin = &self.linear;
        let ts = lin.ts;
        let mut fr = law;
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

/// The settings of one friction loop on a sub-stepped linear part (see
/// [`AugmentedModel::friction_loop_m`]).
struct FrictionRun {
    law: StickSlip,
    /// Sub-steps per sample.
    m: usize,
    /// Whether the velocity is the output's derivative (else the output).
    rate: bool,
    /// The velocity's change per unit of held input over one sub-step.
    g: f64,
    /// C·B_h.
    cb: f64,
    d: f64,
    offset: f64,
}

impl FrictionRun {
    /// The loop on `sub`: the output and the per-sample mean of the linear part's input.
    fn on<S: SubStep>(&self, sub: &S, u: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (m, g, cb) = (self.m, self.g, self.cb);
        let mut fr = self.law;
        let mut x = sub.zero_state();
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
                let v_free = if self.rate {
                    sub.free_next_rate(&x)
                } else {
                    next + self.offset
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
            y.push(y0 + self.d * w_first + self.offset);
            w.push(wsum / m as f64);
        }
        (y, w)
    }
}
