//! Augmented models (linear part + one effect) and the fits that estimate them.
//!
//! Every candidate is fitted the same way on the training logs, minimising the free-run
//! simulation cost Σ NRMSE² (see [`crate::gap::modal`]):
//! 1. **Parameter search with the linear poles fixed.** The effect parameters are searched on a
//!    logarithmic grid spanning the data's scale (input RMS, output lattice, sample time), the
//!    best grid point is refined by golden-section search (1 parameter) or Nelder–Mead (2);
//!    every evaluation re-fits the residues, feedthrough and offset of the linear part by
//!    variable projection (an exact least-squares step for the input-side effects; one
//!    simulate-then-refit fixed-point step for friction, whose force depends on the model).
//! 2. **Alternating refinement.** The signal entering the linear part (through the effect, or
//!    u minus the simulated friction force) is frozen, the poles are re-fitted by output-error
//!    Levenberg–Marquardt on it, and the effect parameters are searched again locally;
//!    two rounds, keeping a round only if it lowers the cost.
//!
//! Friction acts against the velocity of the driven mass, which a black-box model does not
//! expose: the fit tries both the model output (velocity-output plants) and its backward
//! difference divided by `ts` (position-output plants) and keeps the better
//! ([`VelocitySource`]). Quantization is estimated from the lattice of the measured outputs.
use super::effect::{
    deadzone, delay_signal, quantize, resonance_filter, saturation, Effect, EffectKind, Play,
    StickSlip,
};
use super::modal::{FitSet, ModalModel};
use super::optim::{golden_section, nelder_mead};
use crate::error::Result;

/// Which signal of the linear model stands for the velocity that friction opposes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VelocitySource {
    /// The model output itself (velocity-output plants).
    Output,
    /// The backward difference of the model output over `ts` (position-output plants).
    OutputRate,
}

impl VelocitySource {
    /// Report name (`output`, `output_rate`).
    pub fn name(self) -> &'static str {
        match self {
            VelocitySource::Output => "output",
            VelocitySource::OutputRate => "output_rate",
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

    /// Closed loop of the linear part with stick-slip friction at its input.
    fn friction_loop(&self, u: &[f64], level: f64, breakaway: f64) -> (Vec<f64>, Vec<f64>) {
        let lin = &self.linear;
        let ts = lin.ts;
        let mut fr = StickSlip::new(level, breakaway);
        let cb = lin.cb();
        let g = match self.velocity {
            VelocitySource::Output => cb,
            VelocitySource::OutputRate => cb / ts,
        };
        let mut x = lin.zero_state();
        let mut y = Vec::with_capacity(u.len());
        let mut w = Vec::with_capacity(u.len());
        for &uk in u {
            let yo = lin.state_output(&x);
            let next = lin.free_next_output(&x);
            let v_free = match self.velocity {
                VelocitySource::Output => next,
                VelocitySource::OutputRate => (next - yo) / ts,
            };
            let f = fr.force(v_free + g * uk, g);
            let wk = uk - f;
            y.push(yo + lin.d * wk + lin.offset);
            w.push(wk);
            lin.step(&mut x, wk);
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
    let mut model = AugmentedModel {
        linear: lin.clone(),
        effect: Some(effect),
        velocity,
    };
    match effect {
        Effect::Quantization { .. } => {}
        Effect::CoulombFriction { .. } | Effect::Stiction { .. } => {
            let mut w = Vec::with_capacity(td.u.len());
            for u in &td.u {
                w.push(model.simulate_with_input(u).ok()?.1);
            }
            model.linear.fit_linear_params(&td.base.with_input(w))?;
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

/// 1-parameter search: grid, then golden section in log space between the best point's
/// neighbours.
fn search_1d(
    grid: &[f64],
    golden_iters: usize,
    mut make: impl FnMut(f64) -> Option<Fitted>,
) -> Option<Fitted> {
    let mut best: Option<Fitted> = None;
    let mut best_i = 0;
    for (i, &p) in grid.iter().enumerate() {
        let c = make(p);
        if let Some(c) = c {
            if best.as_ref().is_none_or(|b| c.train_cost < b.train_cost) {
                best = Some(c);
                best_i = i;
            }
        }
    }
    best.as_ref()?;
    let lo = grid[best_i.saturating_sub(1)];
    let hi = grid[(best_i + 1).min(grid.len() - 1)];
    if hi > lo && golden_iters > 0 {
        let mut local: Option<Fitted> = None;
        golden_section(
            |lp| {
                let c = make(lp.exp());
                let v = c.as_ref().map_or(f64::INFINITY, |c| c.train_cost);
                keep_best(&mut local, c);
                v
            },
            lo.ln(),
            hi.ln(),
            golden_iters,
        );
        keep_best(&mut best, local);
    }
    best
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

/// Fits one candidate effect to the training data starting from the linear re-fit `lin`.
/// `coulomb` is the fitted Coulomb candidate (used to start the stiction search).
pub fn fit_candidate(
    kind: EffectKind,
    td: &TrainData,
    lin: &ModalModel,
    coulomb: Option<&Fitted>,
) -> Option<Fitted> {
    let fitted = initial_search(kind, td, lin, coulomb)?;
    Some(polish(td, fitted))
}

fn initial_search(
    kind: EffectKind,
    td: &TrainData,
    lin: &ModalModel,
    coulomb: Option<&Fitted>,
) -> Option<Fitted> {
    let s = td.u_rms.max(1e-300);
    let ts = td.ts;
    let out = VelocitySource::Output;
    match kind {
        EffectKind::CoulombFriction => {
            let grid = log_grid(0.01 * s, 1.5 * s, 16);
            // Choose the velocity proxy on the grid, then refine with it.
            let mut best: Option<(Fitted, VelocitySource)> = None;
            for vel in [VelocitySource::Output, VelocitySource::OutputRate] {
                if let Some(f) = search_1d(&grid, 0, |p| {
                    eval_fixed_poles(td, lin, Effect::CoulombFriction { level: p }, vel)
                }) {
                    if best
                        .as_ref()
                        .is_none_or(|(b, _)| f.train_cost < b.train_cost)
                    {
                        best = Some((f, vel));
                    }
                }
            }
            let (_, vel) = best?;
            search_1d(&grid, 14, |p| {
                eval_fixed_poles(td, lin, Effect::CoulombFriction { level: p }, vel)
            })
        }
        EffectKind::Stiction => {
            let (lvl0, vel, lin0) = match coulomb {
                Some(c) => match c.model.effect {
                    Some(Effect::CoulombFriction { level }) => {
                        (level, c.model.velocity, c.model.linear.clone())
                    }
                    _ => (0.3 * s, out, lin.clone()),
                },
                None => (0.3 * s, out, lin.clone()),
            };
            let make = |lvl: f64, ratio: f64| {
                eval_fixed_poles(
                    td,
                    &lin0,
                    Effect::Stiction {
                        level: lvl,
                        breakaway: lvl * ratio,
                    },
                    vel,
                )
            };
            let mut best: Option<Fitted> = None;
            let mut start = (lvl0, 1.5);
            for &lf in &[0.4, 0.6, 0.8, 1.0] {
                for &ratio in &[1.25, 1.6, 2.0, 2.6, 3.4] {
                    let c = make(lvl0 * lf, ratio);
                    let better = c
                        .as_ref()
                        .is_some_and(|c| best.as_ref().is_none_or(|b| c.train_cost < b.train_cost));
                    if better {
                        start = (lvl0 * lf, ratio);
                        best = c;
                    }
                }
            }
            let mut local: Option<Fitted> = None;
            nelder_mead(
                |p| {
                    let c = make(p[0].exp(), 1.0 + p[1].exp());
                    let v = c.as_ref().map_or(f64::INFINITY, |c| c.train_cost);
                    keep_best(&mut local, c);
                    v
                },
                &[start.0.ln(), (start.1 - 1.0).ln()],
                &[0.2, 0.3],
                40,
                1e-10,
            );
            keep_best(&mut best, local);
            best
        }
        EffectKind::Backlash => search_1d(&log_grid(0.01 * s, 2.0 * s, 16), 14, |p| {
            eval_fixed_poles(td, lin, Effect::Backlash { gap: p }, out)
        }),
        EffectKind::Deadzone => search_1d(&log_grid(0.01 * s, 2.0 * s, 16), 14, |p| {
            eval_fixed_poles(td, lin, Effect::Deadzone { width: p }, out)
        }),
        EffectKind::Saturation => {
            let hi = td.u_peak.max(0.25 * s);
            search_1d(&log_grid(0.2 * s, hi, 16), 14, |p| {
                eval_fixed_poles(td, lin, Effect::Saturation { limit: p }, out)
            })
        }
        EffectKind::TimeDelay => {
            // Linear grid in half samples, then golden section between neighbours.
            let grid: Vec<f64> = (0..=(2.0 * MAX_DELAY_SAMPLES) as usize)
                .map(|i| 0.5 * i as f64 * ts)
                .collect();
            let make = |p: f64| eval_fixed_poles(td, lin, Effect::TimeDelay { seconds: p }, out);
            let mut best: Option<Fitted> = None;
            let mut bi = 0;
            for (i, &p) in grid.iter().enumerate() {
                let c = make(p);
                if c.as_ref()
                    .is_some_and(|c| best.as_ref().is_none_or(|b| c.train_cost < b.train_cost))
                {
                    best = c;
                    bi = i;
                }
            }
            let lo = grid[bi.saturating_sub(1)];
            let hi = grid[(bi + 1).min(grid.len() - 1)];
            let mut local: Option<Fitted> = None;
            golden_section(
                |p| {
                    let c = make(p);
                    let v = c.as_ref().map_or(f64::INFINITY, |c| c.train_cost);
                    keep_best(&mut local, c);
                    v
                },
                lo,
                hi,
                14,
            );
            keep_best(&mut best, local);
            best
        }
        EffectKind::Resonance => {
            let (flo, fhi) = resonance_range_hz(ts);
            let make = |f: f64, z: f64| {
                if !(flo..=fhi).contains(&f) || !(0.0..=MAX_RESONANCE_DAMPING).contains(&z) {
                    return None;
                }
                eval_fixed_poles(
                    td,
                    lin,
                    Effect::Resonance {
                        freq_hz: f,
                        damping: z,
                    },
                    out,
                )
            };
            let mut best: Option<Fitted> = None;
            let mut start = (flo, 0.05);
            for &f in &log_grid(flo, fhi, 28) {
                for &z in &[0.02, 0.05, 0.12, 0.3] {
                    let c = make(f, z);
                    if c.as_ref()
                        .is_some_and(|c| best.as_ref().is_none_or(|b| c.train_cost < b.train_cost))
                    {
                        best = c;
                        start = (f, z);
                    }
                }
            }
            let mut local: Option<Fitted> = None;
            nelder_mead(
                |p| {
                    let c = make(p[0].exp(), p[1].exp());
                    let v = c.as_ref().map_or(f64::INFINITY, |c| c.train_cost);
                    keep_best(&mut local, c);
                    v
                },
                &[start.0.ln(), start.1.ln()],
                &[0.08, 0.4],
                50,
                1e-12,
            );
            keep_best(&mut best, local);
            best
        }
        EffectKind::Quantization => {
            let step = lattice_step(&td.base.y)?;
            eval_fixed_poles(td, lin, Effect::Quantization { step }, out)
        }
    }
}

/// Local re-search of the effect parameters around `f` with the linear part of `f`.
fn local_search(td: &TrainData, f: &Fitted) -> Option<Fitted> {
    let lin = &f.model.linear;
    let vel = f.model.velocity;
    let e = f.model.effect?;
    let one = |build: &dyn Fn(f64) -> Effect, p0: f64| -> Option<Fitted> {
        let mut best: Option<Fitted> = None;
        golden_section(
            |lp| {
                let c = eval_fixed_poles(td, lin, build(lp.exp()), vel);
                let v = c.as_ref().map_or(f64::INFINITY, |c| c.train_cost);
                keep_best(&mut best, c);
                v
            },
            p0.ln() - 0.2,
            p0.ln() + 0.2,
            12,
        );
        best
    };
    match e {
        Effect::CoulombFriction { level } => one(&|p| Effect::CoulombFriction { level: p }, level),
        Effect::Backlash { gap } => one(&|p| Effect::Backlash { gap: p }, gap),
        Effect::Deadzone { width } => one(&|p| Effect::Deadzone { width: p }, width),
        Effect::Saturation { limit } => one(&|p| Effect::Saturation { limit: p }, limit),
        Effect::TimeDelay { seconds } => {
            let mut best: Option<Fitted> = None;
            golden_section(
                |p| {
                    let c = eval_fixed_poles(
                        td,
                        lin,
                        Effect::TimeDelay {
                            seconds: p.max(0.0),
                        },
                        vel,
                    );
                    let v = c.as_ref().map_or(f64::INFINITY, |c| c.train_cost);
                    keep_best(&mut best, c);
                    v
                },
                seconds - 0.75 * td.ts,
                seconds + 0.75 * td.ts,
                12,
            );
            best
        }
        Effect::Stiction { level, breakaway } => {
            let mut best: Option<Fitted> = None;
            nelder_mead(
                |p| {
                    let l = p[0].exp();
                    let c = eval_fixed_poles(
                        td,
                        lin,
                        Effect::Stiction {
                            level: l,
                            breakaway: l * (1.0 + p[1].exp()),
                        },
                        vel,
                    );
                    let v = c.as_ref().map_or(f64::INFINITY, |c| c.train_cost);
                    keep_best(&mut best, c);
                    v
                },
                &[level.ln(), (breakaway / level - 1.0).max(1e-3).ln()],
                &[0.1, 0.2],
                30,
                1e-12,
            );
            best
        }
        Effect::Resonance { freq_hz, damping } => {
            let mut best: Option<Fitted> = None;
            nelder_mead(
                |p| {
                    let (f, z) = (p[0].exp(), p[1].exp());
                    if z > MAX_RESONANCE_DAMPING {
                        return f64::INFINITY;
                    }
                    let c = eval_fixed_poles(
                        td,
                        lin,
                        Effect::Resonance {
                            freq_hz: f,
                            damping: z,
                        },
                        vel,
                    );
                    let v = c.as_ref().map_or(f64::INFINITY, |c| c.train_cost);
                    keep_best(&mut best, c);
                    v
                },
                &[freq_hz.ln(), damping.ln()],
                &[0.03, 0.2],
                30,
                1e-12,
            );
            best
        }
        Effect::Quantization { .. } => None,
    }
}

/// Alternating refinement (module docs, step 2).
fn polish(td: &TrainData, mut f: Fitted) -> Fitted {
    for _ in 0..2 {
        // Freeze the signal entering the linear part, re-fit the poles on it.
        let mut w = Vec::with_capacity(td.u.len());
        for u in &td.u {
            match f.model.simulate_with_input(u) {
                Ok((_, wl)) => w.push(wl),
                Err(_) => return f,
            }
        }
        let mut lin = f.model.linear.clone();
        if lin.fit_output_error(&td.base.with_input(w), 15).is_none() {
            return f;
        }
        let Some(e) = f.model.effect else { return f };
        let Some(mut cand) = eval_fixed_poles(td, &lin, e, f.model.velocity) else {
            return f;
        };
        if let Some(l) = local_search(td, &cand) {
            if l.train_cost < cand.train_cost {
                cand = l;
            }
        }
        if cand.train_cost < f.train_cost * (1.0 - 1e-6) {
            f = cand;
        } else {
            break;
        }
    }
    f
}
