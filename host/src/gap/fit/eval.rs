//! Training data, fitted candidates, and the evaluation of a model with its poles and effects
//! fixed (residues, feedthrough and offset by variable projection).
use super::model::{sensor_transform, AugmentedModel, VelocitySource};
use super::FRICTION_SUBSTEPS;
use crate::error::Result;
use crate::gap::drift::scored_sse;
use crate::gap::effect::Effect;
use crate::gap::friction_port::fit_linear_params_body;
use crate::gap::modal::{FitSet, ModalModel};
use crate::gap::place::{Place, PlacedEffect};

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

impl Fitted {
    /// `model` scored by its free run on `td` as it stands (nothing re-fitted); `None` when the
    /// cost is not finite.
    pub fn free_run(td: &TrainData, model: AugmentedModel) -> Option<Fitted> {
        let train_cost = model.cost(&td.base, &td.u);
        train_cost
            .is_finite()
            .then_some(Fitted { model, train_cost })
    }
}

/// Re-fits the linear part's residues (poles fixed) for `effect` and returns the model and its
/// training cost.
pub(super) fn eval_fixed_poles(
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
        return crate::gap::structure::eval_two_mass(td, model);
    }
    let effects = model.effects();
    let clip = effects.iter().find_map(|p| match (p.place, p.effect) {
        (Place::Sensor, Effect::Saturation { limit }) => Some(limit),
        _ => None,
    });
    let only_drive = effects
        .iter()
        .all(|p| p.place == Place::Drive || p.effect.kind().is_state_clamp());
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
    let cost = if let Some((law, b)) = body {
        let mut wd = Vec::with_capacity(td.u.len());
        let mut f = Vec::with_capacity(td.u.len());
        for u in &td.u {
            let d = model.drive_input(u).ok()?;
            f.push(model.friction_loop_body(&d, law, m, b)?.1);
            wd.push(d);
        }
        fit_linear_params_body(&mut model.linear, &td.base, &wd, &f, b, mask.as_deref())?;
        f64::NAN
    } else {
        let mut w = Vec::with_capacity(td.u.len());
        for u in &td.u {
            let wd = model.drive_input(u).ok()?;
            w.push(match model.motor_friction() {
                Some(law) => model.friction_loop_m(&wd, law, m).1,
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
            Some(law) if m != FRICTION_SUBSTEPS => {
                let wd = model.drive_input(u).ok()?;
                let mut yh = model.friction_loop_m(&wd, law, m).0;
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
pub(super) fn eval_added(
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

pub(super) fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n)
        .map(|i| (a + (b - a) * i as f64 / (n - 1).max(1) as f64).exp())
        .collect()
}

/// Keeps `cand` in `best` when it has the lower training cost.
pub(crate) fn keep_best(best: &mut Option<Fitted>, cand: Option<Fitted>) {
    if let Some(c) = cand {
        if best.as_ref().is_none_or(|b| c.train_cost < b.train_cost) {
            *best = Some(c);
        }
    }
}
