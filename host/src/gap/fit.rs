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
//! derivative (position-output plants) and keeps the better ([`VelocitySource`]). Quantization is estimated from the lattice of the measured outputs.
use super::effect::{
    deadzone, delay_signal, quantize, resonance_filter, saturation, Effect, EffectKind, Play,
    StickSlip,
};
use super::modal::{FitSet, ModalModel};
use super::optim::levenberg_marquardt_steps;
use crate::error::Result;
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

/// A linear part with at most one effect.
#[derive(Debug, Clone)]
pub struct AugmentedModel {
    /// Linear part (discrete, modal form).
    pub linear: ModalModel,
    /// The effect, if any.
    pub effect: Option<Effect>,
    /// Velocity proxy used by friction effects.
    pub velocity: VelocitySource,
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
        _ => None,
    })
}

impl AugmentedModel {
    /// The linear model alone.
    pub fn linear(linear: ModalModel) -> Self {
        Self {
            linear,
            effect: None,
            velocity: VelocitySource::Output,
        }
    }

    /// Free-run output for input `u` from rest.
    pub fn simulate(&self, u: &[f64]) -> Result<Vec<f64>> {
        Ok(self.simulate_with_input(u)?.0)
    }

    /// Free-run output and the signal that entered the linear part.
    pub fn simulate_with_input(&self, u: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let lin = &self.linear;
        match self.effect {
            None => Ok((lin.simulate(u), u.to_vec())),
            Some(Effect::Quantization { step }) => Ok((
                lin.simulate(u)
                    .into_iter()
                    .map(|v| quantize(v, step))
                    .collect(),
                u.to_vec(),
            )),
            Some(Effect::CoulombFriction { level }) => Ok(self.friction_loop(u, level, level)),
            Some(Effect::Stiction { level, breakaway }) => {
                Ok(self.friction_loop(u, level, breakaway))
            }
            Some(ref e) => {
                let w = input_transform(e, u, lin.ts)?.unwrap_or_else(|| u.to_vec());
                Ok((lin.simulate(&w), w))
            }
        }
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
            c += wt
                * y.iter()
                    .zip(&yh)
                    .skip(set.warmup)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>();
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
            Ok(t) => t,
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
    eval_fixed_poles_m(td, lin, effect, velocity, FRICTION_SUBSTEPS)
}

/// [`eval_fixed_poles`] with `m` friction sub-steps (1 in the coarse grid, where only the
/// basin matters).
fn eval_fixed_poles_m(
    td: &TrainData,
    lin: &ModalModel,
    effect: Effect,
    velocity: VelocitySource,
    m: usize,
) -> Option<Fitted> {
    let mut model = AugmentedModel {
        linear: lin.clone(),
        effect: Some(effect),
        velocity,
    };
    match effect {
        Effect::Quantization { .. } => {}
        Effect::CoulombFriction { level } | Effect::Stiction { level, .. } => {
            let breakaway = match effect {
                Effect::Stiction { breakaway, .. } => breakaway,
                _ => level,
            };
            let mut w = Vec::with_capacity(td.u.len());
            for u in &td.u {
                w.push(model.friction_loop_m(u, level, breakaway, m).1);
            }
            model.linear.fit_linear_params(&td.base.with_input(w))?;
            let mut c = 0.0;
            for ((u, y), &wt) in td.u.iter().zip(&td.base.y).zip(&td.base.weight) {
                let yh = model.friction_loop_m(u, level, breakaway, m).0;
                c += wt
                    * y.iter()
                        .zip(&yh)
                        .skip(td.base.warmup)
                        .map(|(a, b)| (a - b).powi(2))
                        .sum::<f64>();
            }
            return c.is_finite().then_some(Fitted {
                model,
                train_cost: c,
            });
        }
        ref e => {
            let mut w = Vec::with_capacity(td.u.len());
            for u in &td.u {
                w.push(input_transform(e, u, td.ts).ok()??);
            }
            let cost = model.linear.fit_linear_params(&td.base.with_input(w))?;
            return Some(Fitted {
                model,
                train_cost: cost,
            });
        }
    }
    let train_cost = model.cost(&td.base, &td.u);
    train_cost
        .is_finite()
        .then_some(Fitted { model, train_cost })
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

/// Longest delay searched, in samples.
pub const MAX_DELAY_SAMPLES: f64 = 32.0;

/// Estimates the output quantization step from the lattice of measured values: the smallest
/// gap between distinct values, refined over the full range, accepted only if at least 99 % of
/// the distinct values lie within 1e-6 steps of that lattice and there are at most half as many
/// distinct values as samples. `None` when the outputs do not sit on a lattice.
pub fn lattice_step(y: &[Vec<f64>]) -> Option<f64> {
    let mut v: Vec<f64> = y.iter().flat_map(|l| l.iter().copied()).collect();
    let total = v.len();
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() < 3 || v.len() * 2 > total {
        return None;
    }
    let range = v[v.len() - 1] - v[0];
    let dmin = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|&d| d > 1e-12 * range)
        .fold(f64::INFINITY, f64::min);
    if !dmin.is_finite() {
        return None;
    }
    let levels = (range / dmin).round();
    let step = range / levels;
    let on = v
        .iter()
        .filter(|&&x| {
            let q = (x - v[0]) / step;
            (q - q.round()).abs() <= 1e-6 * (1.0 + q.abs() * 1e-3)
        })
        .count();
    (on as f64 >= 0.99 * v.len() as f64).then_some(step)
}

/// Samples per training log (after the warm-up) used by the coarse grid stage.
pub const COARSE_SAMPLES: usize = 4096;

/// Iteration cap of the joint Levenberg–Marquardt refinement.
pub const JOINT_MAX_ITER: usize = 12;

/// Fits one candidate effect to the training data. `starts` are linear parts to start from
/// (the linear re-fit and the nominal sim in modal form); `coulomb` is the fitted Coulomb
/// candidate (the stiction fit starts from it).
///
/// Stage 1 searches the effect parameters on a grid over a coarse copy of the training data
/// (the first [`COARSE_SAMPLES`] scored samples of each log) from every start, with the poles
/// fixed; stage 2 refines the best point jointly by Levenberg–Marquardt on all the data (see
/// [`joint_fit`]). Between the two, the [`GRID_STARTS`] best grid points of distinct parameter
/// values are screened by a joint refinement on the coarse data, because the fixed-pole cost
/// misleads when the linear start's poles are off.
pub fn fit_candidate(
    kind: EffectKind,
    td: &TrainData,
    starts: &[ModalModel],
    coulomb: Option<&Fitted>,
    sim_poles: &[Complex64],
) -> Option<Fitted> {
    let start = match kind {
        EffectKind::Stiction => stiction_start(td, coulomb?)?,
        EffectKind::Quantization => {
            let step = lattice_step(&td.base.y)?;
            let lin = starts.first()?;
            return eval_fixed_poles(
                td,
                lin,
                Effect::Quantization { step },
                VelocitySource::Output,
            );
        }
        _ => {
            // The cost with the poles fixed is a poor guide when the linear start's poles are
            // off (a stuck mass or an added mode shifts the re-fit's resonance; the re-fit may
            // even take over the added mode): screen the best grid points of GRID_STARTS
            // distinct parameter values by a joint refinement on the coarse data, then refine
            // the winner on all the data.
            let coarse = td.coarse(COARSE_SAMPLES);
            let mut grid: Vec<Fitted> = Vec::new();
            for lin in starts {
                grid.extend(initial_search(kind, &coarse, lin));
            }
            grid.sort_by(|a, b| a.train_cost.total_cmp(&b.train_cost));
            let key = |f: &Fitted| {
                f.model
                    .effect
                    .map_or(f64::NAN, |e| effect_to_coords(&e, td.ts)[0])
            };
            let min_sep = if kind == EffectKind::TimeDelay {
                DISTINCT_DELAY_SAMPLES
            } else {
                DISTINCT_LN
            };
            let mut picked: Vec<Fitted> = Vec::new();
            for g in grid {
                if picked.len() >= GRID_STARTS {
                    break;
                }
                let k = key(&g);
                if picked.iter().all(|p| (key(p) - k).abs() > min_sep) {
                    picked.push(g);
                }
            }
            let mut best: Option<Fitted> = None;
            for p in picked {
                let refined = match joint_fit(&coarse, &p, JOINT_MAX_ITER) {
                    Some(j) if j.train_cost < p.train_cost => j,
                    _ => p,
                };
                keep_best(&mut best, Some(refined));
            }
            let b = best?;
            eval_fixed_poles(td, &b.model.linear, b.model.effect?, b.model.velocity)?
        }
    };
    let fitted = match joint_fit(td, &start, JOINT_MAX_ITER) {
        Some(j) if j.train_cost < start.train_cost => j,
        _ => start,
    };
    Some(if kind == EffectKind::Resonance {
        relabel_resonance(td, fitted, sim_poles)
    } else {
        fitted
    })
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
        if !(flo..=fhi).contains(&f) || z <= 0.0 || z > MAX_RESONANCE_DAMPING || z.is_nan() {
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

/// Grid points screened by a coarse joint refinement in [`fit_candidate`] (the best of
/// distinct parameter values).
pub const GRID_STARTS: usize = 3;

/// Grid points whose first parameter (level, gap, width, limit, frequency) differs by less than
/// this in ln (a factor 1.5) count as the same start.
const DISTINCT_LN: f64 = 0.405;

/// Delays closer than this (samples) count as the same start.
const DISTINCT_DELAY_SAMPLES: f64 = 1.0;

/// The stiction start: the fitted Coulomb model with the breakaway ratio giving the lowest
/// training cost among 1.1 … 3.4.
fn stiction_start(td: &TrainData, c: &Fitted) -> Option<Fitted> {
    let Some(Effect::CoulombFriction { level }) = c.model.effect else {
        return None;
    };
    let mut best: Option<Fitted> = None;
    for &ratio in &[1.1, 1.3, 1.6, 2.0, 2.6, 3.4] {
        let mut m = c.model.clone();
        m.effect = Some(Effect::Stiction {
            level,
            breakaway: level * ratio,
        });
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
            if !(flo..=fhi).contains(&f) || z > MAX_RESONANCE_DAMPING {
                return None;
            }
            Effect::Resonance {
                freq_hz: f,
                damping: z,
            }
        }
        EffectKind::Quantization => Effect::Quantization { step: c[0].exp() },
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

/// Stage 2 of [`fit_candidate`]: Levenberg–Marquardt on the simulated error over all
/// parameters at once, from `start`. For the input-side effects the coordinates are the pole
/// parameters and the effect parameters, with residues, feedthrough and offset eliminated by
/// variable projection (exact for these structures). For friction, whose force depends on the
/// model output, residues, feedthrough and offset are coordinates too. (Alternating between
/// the linear part and the effect stalls: a linear part fitted to a wrongly distorted input is
/// self-consistent.)
pub fn joint_fit(td: &TrainData, start: &Fitted, max_iter: usize) -> Option<Fitted> {
    let m0 = &start.model;
    let e0 = m0.effect?;
    let kind = e0.kind();
    if kind == EffectKind::Quantization {
        return None;
    }
    let lin0 = &m0.linear;
    let n = lin0.n_states();
    let ts = td.ts;
    let eff0 = effect_to_coords(&e0, ts);
    let ne = eff0.len();
    let friction = matches!(kind, EffectKind::CoulombFriction | EffectKind::Stiction);
    let mut theta0 = lin0.pole_params();
    let mut steps: Vec<f64> = theta0.iter().map(|t| 1e-6 * t.abs().max(1.0)).collect();
    theta0.extend(&eff0);
    steps.extend(std::iter::repeat_n(effect_coord_step(kind), ne));
    // Friction: linear coordinates, scaled to O(1).
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
    let ystd = td
        .base
        .y
        .iter()
        .map(|y| {
            let m = y.iter().sum::<f64>() / y.len() as f64;
            (y.iter().map(|v| (v - m).powi(2)).sum::<f64>() / y.len() as f64).sqrt()
        })
        .fold(0.0f64, f64::max)
        .max(1e-300);
    let dscale = lin0.d.abs().max(1e-3 * ystd / td.u_rms.max(1e-300));
    let use_d = lin0.use_d;
    if friction {
        let extra = n + usize::from(use_d) + 1;
        theta0.extend(std::iter::repeat_n(0.0, extra));
        steps.extend(std::iter::repeat_n(1e-6, extra));
    }
    let build = |th: &[f64]| -> Option<AugmentedModel> {
        let mut lin = lin0.clone();
        lin.set_pole_params(&th[..n]);
        let effect = effect_from_coords(kind, &th[n..n + ne], ts)?;
        if friction {
            let mut k = n + ne;
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
        Some(AugmentedModel {
            linear: lin,
            effect: Some(effect),
            velocity: m0.velocity,
        })
    };
    let residuals = |th: &[f64]| -> Option<Vec<f64>> {
        let mut model = build(th)?;
        if friction {
            let mut r = Vec::new();
            for ((u, y), &wt) in td.u.iter().zip(&td.base.y).zip(&td.base.weight) {
                let yh = model.simulate(u).ok()?;
                let sw = wt.sqrt();
                r.extend(
                    y.iter()
                        .zip(&yh)
                        .skip(td.base.warmup)
                        .map(|(a, b)| sw * (a - b)),
                );
            }
            r.iter().all(|v| v.is_finite()).then_some(r)
        } else {
            let e = model.effect?;
            let mut w = Vec::with_capacity(td.u.len());
            for u in &td.u {
                w.push(input_transform(&e, u, ts).ok()??);
            }
            model.linear.projected_residuals(&td.base.with_input(w))
        }
    };
    let (theta, _) = levenberg_marquardt_steps(residuals, &theta0, &steps, max_iter, 1e-6);
    let mut model = build(&theta)?;
    if !friction {
        let e = model.effect?;
        let mut w = Vec::with_capacity(td.u.len());
        for u in &td.u {
            w.push(input_transform(&e, u, ts).ok()??);
        }
        model.linear.fit_linear_params(&td.base.with_input(w))?;
    }
    let train_cost = model.cost(&td.base, &td.u);
    train_cost
        .is_finite()
        .then_some(Fitted { model, train_cost })
}

/// Stage 1 of [`fit_candidate`]: every point of the grid of effect parameters with the poles
/// of `lin` fixed (the residues re-fitted at every point), on the (coarse) data `td`.
fn initial_search(kind: EffectKind, td: &TrainData, lin: &ModalModel) -> Vec<Fitted> {
    let s = td.u_rms.max(1e-300);
    let ts = td.ts;
    let out = VelocitySource::Output;
    let on_grid = |grid: &[f64], make: &dyn Fn(f64) -> Option<Fitted>| -> Vec<Fitted> {
        grid.iter().filter_map(|&p| make(p)).collect()
    };
    match kind {
        EffectKind::CoulombFriction => {
            // Both velocity proxies, sample-rate friction (only the basin matters here).
            let grid = log_grid(0.01 * s, 1.5 * s, 12);
            let mut all = Vec::new();
            for vel in [VelocitySource::Output, VelocitySource::OutputDerivative] {
                all.extend(on_grid(&grid, &|p| {
                    eval_fixed_poles_m(td, lin, Effect::CoulombFriction { level: p }, vel, 1)
                }));
            }
            all
        }
        EffectKind::Backlash => on_grid(&log_grid(0.01 * s, 2.0 * s, 16), &|p| {
            eval_fixed_poles(td, lin, Effect::Backlash { gap: p }, out)
        }),
        EffectKind::Deadzone => on_grid(&log_grid(0.01 * s, 2.0 * s, 16), &|p| {
            eval_fixed_poles(td, lin, Effect::Deadzone { width: p }, out)
        }),
        EffectKind::Saturation => {
            let hi = td.u_peak.max(0.25 * s);
            on_grid(&log_grid(0.2 * s, hi, 16), &|p| {
                eval_fixed_poles(td, lin, Effect::Saturation { limit: p }, out)
            })
        }
        EffectKind::TimeDelay => {
            let grid: Vec<f64> = (0..=(2.0 * MAX_DELAY_SAMPLES) as usize)
                .map(|i| 0.5 * i as f64 * ts)
                .collect();
            on_grid(&grid, &|p| {
                eval_fixed_poles(td, lin, Effect::TimeDelay { seconds: p }, out)
            })
        }
        EffectKind::Resonance => {
            let (flo, fhi) = resonance_range_hz(ts);
            let mut all = Vec::new();
            for &f in &log_grid(flo, fhi, 40) {
                for &z in &[0.02, 0.05, 0.12, 0.3] {
                    all.extend(eval_fixed_poles(
                        td,
                        lin,
                        Effect::Resonance {
                            freq_hz: f,
                            damping: z,
                        },
                        out,
                    ));
                }
            }
            all
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
        let m = AugmentedModel {
            linear: exact_modal(&plant, ts, &u, &y_lin),
            effect: Some(effect),
            velocity: vel,
        };
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
}
