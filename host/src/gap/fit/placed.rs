//! One candidate effect at its place, fitted end to end ([`fit_placed`]): grid, screening,
//! joint refinement, and the null guard that keeps a candidate from ending worse than its base.
use super::eval::{eval_added, eval_model, keep_best, Fitted, TrainData};
use super::joint::{effect_to_coords, refined};
use super::model::AugmentedModel;
use super::resonance::relabel_resonance;
use super::search::initial_search;
use super::{
    lattice_step, COARSE_SAMPLES, FRICTION_SUBSTEPS, JOINT_MAX_ITER, MAX_RESONANCE_DAMPING,
    SCREEN_MAX_ITER,
};
use crate::gap::effect::{Effect, EffectKind, NULL_RESONANCE_CYCLES_PER_SAMPLE};
use crate::gap::modal::ModalModel;
use crate::gap::place::{default_place, Candidate, Place, PlacedEffect};
use num_complex::Complex64;

/// Hints that seed or bound a candidate fit (evidence read off the data before fitting).
#[derive(Debug, Clone, Copy, Default)]
pub struct FitHints {
    /// Quantization step from the lattice of the measured outputs.
    pub lattice_step: Option<f64>,
    /// Breakaway level (input units) from dwells at zero velocity.
    pub breakaway: Option<f64>,
    /// Training cost (all the data) of the model the candidate must improve on: the linear
    /// re-fit for a single, the first effect's model for a pair. A drivetrain fit that does not
    /// lower it by [`SCREEN_MIN_GAIN`] after its coarse search is not refined.
    pub to_beat: Option<f64>,
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
        to_beat: None,
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
/// Levenberg–Marquardt on all the data ([`super::joint_fit`]) when the screen lowered the
/// base's coarse cost by [`SCREEN_MIN_GAIN`] (else the screened fit is kept, evaluated on all
/// the data; drivetrain backlash is screened against `hints.to_beat`). Stiction starts from the Coulomb fit
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
    // Whether the start earns the joint refinement on all the data (see [`promising`]).
    let mut refine = true;
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
            let f = crate::gap::structure::fit_drivetrain_backlash(
                td,
                bases,
                COARSE_SAMPLES,
                JOINT_MAX_ITER,
                hints.to_beat,
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
                keep_best(&mut best, Some(refined(&coarse, p, SCREEN_MAX_ITER)));
            }
            let best = best?;
            refine = promising(&coarse, base0, best.train_cost);
            eval_model(td, best.model, FRICTION_SUBSTEPS)?
        }
    };
    let iters = match (cand.place, kind) {
        (Place::Load, _) => JOINT_MAX_ITER / 2,
        // Smooth in its parameters: converges in a few more steps.
        (_, EffectKind::Resonance) => 2 * JOINT_MAX_ITER,
        _ => JOINT_MAX_ITER,
    };
    let fitted = if refine {
        refined(td, start, iters)
    } else {
        start
    };
    let fitted = if kind == EffectKind::Resonance && base0.effect.is_none() && refine {
        relabel_resonance(td, fitted, sim_poles)
    } else if kind.is_state_clamp() {
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
            stribeck_velocity: 0.0,
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
        EffectKind::CurrentLimit => Effect::CurrentLimit {
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
pub(super) fn null_guard(
    td: &TrainData,
    cand: Candidate,
    base: &AugmentedModel,
    fitted: Fitted,
) -> Fitted {
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

/// Smallest relative drop of the coarse training cost below the base's for a candidate to earn
/// its joint refinement on all the data. A candidate is worth selecting only when it lowers the
/// validation NRMSE by half the selection margin (5 %, a cost drop near 10 %); one that does not
/// lower the cost of the coarse data (the first [`COARSE_SAMPLES`] scored samples of every log)
/// by a tenth of that after its screening refinement is kept as screened, evaluated on all the
/// data (and null-guarded like any other fit).
pub const SCREEN_MIN_GAIN: f64 = 0.01;

/// Whether `cost` lies below `reference` by more than [`SCREEN_MIN_GAIN`] (relative): the one
/// test every refinement screen applies.
pub fn beats_by_screen_gain(cost: f64, reference: f64) -> bool {
    cost < (1.0 - SCREEN_MIN_GAIN) * reference
}

/// Whether a candidate whose screened fit costs `screened` on `coarse` lowers the cost of
/// `base` (its residues, feedthrough and offset re-fitted on the same data) by at least
/// [`SCREEN_MIN_GAIN`]; `true` when the base cannot be evaluated.
pub(super) fn promising(coarse: &TrainData, base: &AugmentedModel, screened: f64) -> bool {
    eval_model(coarse, base.clone(), FRICTION_SUBSTEPS)
        .is_none_or(|b| beats_by_screen_gain(screened, b.train_cost))
}

/// Grid points screened by a coarse joint refinement in [`fit_placed`] (the best of
/// distinct parameter values).
pub const GRID_STARTS: usize = 3;

/// Screened grid points for a candidate: [`GRID_STARTS`]; two for motor friction, one for
/// friction on the load (a two-mass fit in physical coordinates, the costliest).
pub(super) fn grid_starts(cand: Candidate) -> usize {
    match (cand.place, cand.kind) {
        (Place::Load, _) => 1,
        // The friction loop is the costliest simulation: two screened starts.
        (_, EffectKind::CoulombFriction) => 2,
        _ => GRID_STARTS,
    }
}

/// Grid points whose first parameter (level, gap, width, limit, frequency) differs by less than
/// this in ln (a factor 1.5) count as the same start.
pub(super) const DISTINCT_LN: f64 = 0.405;

/// Delays closer than this (samples) count as the same start.
pub(super) const DISTINCT_DELAY_SAMPLES: f64 = 1.0;

/// The stiction start: the fitted Coulomb model with the breakaway ratio giving the lowest
/// training cost among 1.1 … 3.4 (and the ratio `breakaway`/level from dwell evidence, when
/// given).
pub(super) fn stiction_start(td: &TrainData, c: &Fitted, breakaway: Option<f64>) -> Option<Fitted> {
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
            stribeck_velocity: 0.0,
        };
        m.set_effects_in_selection_order(&l);
        keep_best(&mut best, Fitted::free_run(td, m));
    }
    best
}
