//! Fitting effects inside a two-mass structure: the offset of a two-mass candidate, its grid
//! start, the drivetrain-backlash fit and the joint Nelder–Mead / Levenberg–Marquardt refinement
//! in physical log coordinates (the model itself is [`super::TwoMassModel`]).
use super::{TwoMassModel, TWO_MASS_COORD_STEP};
use crate::gap::effect::{Effect, EffectKind};
use crate::gap::fit::{
    beats_by_screen_gain, eval_model, AugmentedModel, Fitted, TrainData, JOINT_RTOL,
};
use crate::gap::optim::levenberg_marquardt_steps;
use crate::gap::place::{Candidate, Place, PlacedEffect};
/// Sets the two-mass model's offset to its least-squares value on the training logs and
/// returns the cost Σ NRMSE², or `None` when a simulation fails.
fn fit_offset_cost(td: &TrainData, model: &mut AugmentedModel) -> Option<f64> {
    fit_offset_sims(td, model).map(|(c, _)| c)
}

/// [`fit_offset_cost`] and the simulated outputs of the training logs at offset zero.
fn fit_offset_sims(td: &TrainData, model: &mut AugmentedModel) -> Option<(f64, Vec<Vec<f64>>)> {
    let tm = model.two_mass.as_mut()?;
    tm.offset = 0.0;
    let mut sims = Vec::with_capacity(td.u.len());
    let (mut num, mut den) = (0.0, 0.0);
    for ((u, y), &wt) in td.u.iter().zip(&td.base.y).zip(&td.base.weight) {
        let yh = model.simulate(u).ok()?;
        for (a, b) in y.iter().zip(&yh).skip(td.base.warmup) {
            num += wt * (a - b);
            den += wt;
        }
        sims.push(yh);
    }
    let off = if den > 0.0 { num / den } else { 0.0 };
    if let Some(tm) = model.two_mass.as_mut() {
        tm.offset = off;
    }
    let mut c = 0.0;
    for ((y, yh), &wt) in td.base.y.iter().zip(&sims).zip(&td.base.weight) {
        c += wt
            * y.iter()
                .zip(yh)
                .skip(td.base.warmup)
                .map(|(a, b)| (a - b - off).powi(2))
                .sum::<f64>();
    }
    c.is_finite().then_some((c, sims))
}

/// Evaluates a model on a two-mass plant with its offset re-fitted.
pub fn eval_two_mass(td: &TrainData, mut model: AugmentedModel) -> Option<Fitted> {
    let train_cost = fit_offset_cost(td, &mut model)?;
    Some(Fitted { model, train_cost })
}

/// The two-mass plant a candidate inside the structure starts from: the base's own, else the
/// base's linear part mapped to physical coordinates.
fn two_mass_base(base: &AugmentedModel) -> Option<AugmentedModel> {
    if base.two_mass.is_some() {
        return Some(base.clone());
    }
    let tm = TwoMassModel::from_modal(&base.linear)?;
    let mut m = base.clone();
    m.two_mass = Some(tm);
    Some(m)
}

/// Grid stage for a candidate inside a two-mass structure (drivetrain backlash, load or motor
/// friction) added to `base`: gaps scaled by the twist RMS of the linear two-mass plant,
/// friction levels by the input RMS.
pub fn initial_search_two_mass(
    cand: Candidate,
    td: &TrainData,
    base: &AugmentedModel,
) -> Vec<Fitted> {
    let Some(b) = two_mass_base(base) else {
        return Vec::new();
    };
    let s = td.u_rms.max(1e-300);
    let grid: Vec<Effect> = match cand.kind {
        EffectKind::Backlash => {
            let Some(tm) = &b.two_mass else {
                return Vec::new();
            };
            let Ok(w) = b.drive_input(&td.u[0]) else {
                return Vec::new();
            };
            let Ok((_, tw)) = tm.simulate_states(&w, &[]) else {
                return Vec::new();
            };
            if tw.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                return Vec::new();
            }
            log_grid(0.02 * tw, 4.0 * tw, 14)
                .into_iter()
                .map(|g| Effect::Backlash { gap: g })
                .collect()
        }
        EffectKind::CoulombFriction => log_grid(0.01 * s, 1.5 * s, 12)
            .into_iter()
            .map(|l| Effect::CoulombFriction { level: l })
            .collect(),
        _ => return Vec::new(),
    };
    grid.into_iter()
        .filter_map(|effect| {
            eval_model(
                td,
                b.with_added(PlacedEffect {
                    effect,
                    place: cand.place,
                }),
                1,
            )
        })
        .collect()
}

fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n)
        .map(|i| (a + (b - a) * i as f64 / (n - 1).max(1) as f64).exp())
        .collect()
}

/// Backlash in the drivetrain added to each of `bases`, fitted by alternating searches: the
/// free run of a two-mass axis with play has long memory (the load coasts inside the gap), so
/// its cost is narrow and rough in the gap and a gradient method alone stalls. From each base,
/// on the first `coarse_samples`/2 scored samples of each log: the best gap of a grid (30
/// points over 0.02…4 twist RMS), then two Nelder–Mead searches over the main physical
/// parameters and the gap; the best is refined on all the data by a fine gap scan (±6 %) and
/// a joint Levenberg–Marquardt — only when the screened fit, evaluated on all the data, lowers
/// `to_beat` (the training cost of the model the candidate must improve on) by
/// [`crate::gap::fit::SCREEN_MIN_GAIN`].
pub fn fit_drivetrain_backlash(
    td: &TrainData,
    bases: &[AugmentedModel],
    coarse_samples: usize,
    max_iter: usize,
    to_beat: Option<f64>,
) -> Option<Fitted> {
    let coarse = td.coarse(coarse_samples / 2);
    let with_gap = |m: &AugmentedModel, g: f64| -> AugmentedModel {
        let mut m = m.clone();
        let mut list = m.effects_in_selection_order();
        if let Some(p) = list.iter_mut().find(|p| p.place == Place::Drivetrain) {
            p.effect = Effect::Backlash { gap: g };
        }
        m.set_effects_in_selection_order(&list);
        m
    };
    let gap_of = |m: &AugmentedModel| -> f64 {
        m.effects()
            .iter()
            .find_map(|p| match (p.place, p.effect) {
                (Place::Drivetrain, Effect::Backlash { gap }) => Some(gap),
                _ => None,
            })
            .unwrap_or(f64::NAN)
    };
    let scan =
        |data: &TrainData, m: &AugmentedModel, lo: f64, hi: f64, k: usize| -> Option<Fitted> {
            let g0 = gap_of(m);
            let mut best: Option<Fitted> = None;
            for g in log_grid(g0 * lo, g0 * hi, k) {
                if let Some(f) = eval_two_mass(data, with_gap(m, g)) {
                    if best.as_ref().is_none_or(|b| f.train_cost < b.train_cost) {
                        best = Some(f);
                    }
                }
            }
            best
        };
    let mut best: Option<Fitted> = None;
    for b in bases {
        let Some(b) = two_mass_base(b) else { continue };
        let Some(tm) = b.two_mass.clone() else {
            continue;
        };
        let Ok(w) = b.drive_input(&coarse.u[0]) else {
            continue;
        };
        let Ok((_, tw)) = tm.simulate_states(&w, &[]) else {
            continue;
        };
        if tw.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            continue;
        }
        let base = b.with_added(PlacedEffect {
            effect: Effect::Backlash { gap: tw },
            place: Place::Drivetrain,
        });
        let mut grid: Vec<Fitted> = log_grid(0.02 * tw, 4.0 * tw, 30)
            .into_iter()
            .filter_map(|g| eval_two_mass(&coarse, with_gap(&base, g)))
            .collect();
        grid.sort_by(|a, b| a.train_cost.total_cmp(&b.train_cost));
        let mut picked: Vec<Fitted> = Vec::new();
        for g in grid {
            if !picked.is_empty() {
                break;
            }
            if picked
                .iter()
                .all(|p| (gap_of(&p.model) / gap_of(&g.model)).ln().abs() > 0.4)
            {
                picked.push(g);
            }
        }
        for f in picked {
            // Two Nelder–Mead runs, the second restarted with a fresh simplex.
            let f = nelder_mead_two_mass(&coarse, &f, NM_EVALS).unwrap_or(f);
            let f = nelder_mead_two_mass(&coarse, &f, NM_EVALS).unwrap_or(f);
            if best.as_ref().is_none_or(|b| f.train_cost < b.train_cost) {
                best = Some(f);
            }
        }
    }
    let b = best?;
    let mut f = eval_two_mass(td, b.model)?;
    if to_beat.is_some_and(|c| !beats_by_screen_gain(f.train_cost, c)) {
        // The screened fit does not lower the cost to beat enough to earn the refinement.
        return Some(f);
    }
    if let Some(s) = scan(td, &f.model, 0.94, 1.06, 7) {
        if s.train_cost < f.train_cost {
            f = s;
        }
    }
    if let Some(j) = joint_fit_two_mass(td, &f, max_iter) {
        if j.train_cost < f.train_cost {
            f = j;
        }
    }
    Some(f)
}

/// Objective evaluations of the Nelder–Mead search in [`fit_drivetrain_backlash`].
pub const NM_EVALS: usize = 100;

/// Derivative-free search (Nelder–Mead) over ln J_m, ln J_l, ln k, ln c and the ln of every
/// effect parameter of a model on a two-mass plant (the viscous terms and the offset kept /
/// re-fitted): robust to the rough cost of a free run with play.
fn nelder_mead_two_mass(td: &TrainData, start: &Fitted, max_evals: usize) -> Option<Fitted> {
    let m0 = &start.model;
    let tm0 = m0.two_mass.clone()?;
    let list0 = m0.effects_in_selection_order();
    let base = tm0.to_coords();
    let mut x0: Vec<f64> = base[..4].to_vec();
    let mut step = vec![0.08, 0.08, 0.08, 0.3];
    let mut spans = Vec::new();
    for p in &list0 {
        match coords(&p.effect) {
            Some(c) => {
                spans.push((x0.len(), c.len()));
                step.extend(std::iter::repeat_n(0.15, c.len()));
                x0.extend(c);
            }
            None => spans.push((x0.len(), 0)),
        }
    }
    let build = |x: &[f64]| -> Option<AugmentedModel> {
        let mut m = m0.clone();
        let mut c = base.clone();
        c[..4].copy_from_slice(&x[..4]);
        m.two_mass = Some(tm0.with_coords(&c));
        let mut list = list0.clone();
        for (p, &(at, len)) in list.iter_mut().zip(&spans) {
            if len > 0 {
                p.effect = from_coords(&p.effect, &x[at..at + len]);
                p.effect.validate().ok()?;
            }
        }
        m.set_effects_in_selection_order(&list);
        Some(m)
    };
    let (x, _) = crate::gap::optim::nelder_mead(
        |x| {
            build(x)
                .and_then(|m| eval_two_mass(td, m))
                .map_or(f64::INFINITY, |f| f.train_cost)
        },
        &x0,
        &step,
        max_evals,
        1e-9,
    );
    let f = eval_two_mass(td, build(&x)?)?;
    (f.train_cost <= start.train_cost).then_some(f)
}

/// Unconstrained coordinates of an effect acting in or on a two-mass plant.
fn coords(e: &Effect) -> Option<Vec<f64>> {
    Some(match *e {
        Effect::Backlash { gap } => vec![gap.ln()],
        Effect::CoulombFriction { level } => vec![level.ln()],
        Effect::Stiction { .. } => crate::gap::fit::stiction_coords(e),
        Effect::Deadzone { width } => vec![width.ln()],
        Effect::Saturation { limit } => vec![limit.ln()],
        _ => return None,
    })
}

fn from_coords(e: &Effect, c: &[f64]) -> Effect {
    match *e {
        Effect::Backlash { .. } => Effect::Backlash { gap: c[0].exp() },
        Effect::CoulombFriction { .. } => Effect::CoulombFriction { level: c[0].exp() },
        Effect::Stiction { .. } => crate::gap::fit::stiction_from_coords(c).unwrap_or(*e),
        Effect::Deadzone { .. } => Effect::Deadzone { width: c[0].exp() },
        Effect::Saturation { .. } => Effect::Saturation { limit: c[0].exp() },
        other => other,
    }
}

/// Levenberg–Marquardt over the physical parameters (log coordinates) and the effect
/// parameters together, the output offset eliminated by least squares; from `start` (a model
/// on a two-mass plant). Effects without coordinates here (quantization, delay, resonance) stay
/// fixed.
pub fn joint_fit_two_mass(td: &TrainData, start: &Fitted, max_iter: usize) -> Option<Fitted> {
    joint_fit_two_mass_opt(td, start, max_iter, true)
}

/// [`joint_fit_two_mass`], with the effect parameters fixed unless `free_effects`.
fn joint_fit_two_mass_opt(
    td: &TrainData,
    start: &Fitted,
    max_iter: usize,
    free_effects: bool,
) -> Option<Fitted> {
    let m0 = &start.model;
    let tm0 = m0.two_mass.clone()?;
    let list0 = m0.effects_in_selection_order();
    let mut theta0 = tm0.to_coords();
    let mut steps = vec![TWO_MASS_COORD_STEP; theta0.len()];
    let mut spans = Vec::new();
    for p in &list0 {
        match coords(&p.effect).filter(|_| free_effects) {
            Some(c) => {
                spans.push((theta0.len(), c.len()));
                steps.extend(std::iter::repeat_n(1e-3, c.len()));
                theta0.extend(c);
            }
            None => spans.push((theta0.len(), 0)),
        }
    }
    let build = |th: &[f64]| -> Option<AugmentedModel> {
        let mut m = m0.clone();
        m.two_mass = Some(tm0.with_coords(&th[..6]));
        let mut list = list0.clone();
        for (p, &(at, len)) in list.iter_mut().zip(&spans) {
            if len > 0 {
                p.effect = from_coords(&p.effect, &th[at..at + len]);
                p.effect.validate().ok()?;
            }
        }
        m.set_effects_in_selection_order(&list);
        Some(m)
    };
    let scored = td.base.scored_samples();
    let residuals = |th: &[f64]| -> Option<Vec<f64>> {
        let mut model = build(th)?;
        let (_, sims) = fit_offset_sims(td, &mut model)?;
        let off = model.two_mass.as_ref().map_or(0.0, |tm| tm.offset);
        // Without a sensor effect the output at the fitted offset is the offset-free one
        // shifted (the plant adds the offset last); a sensor effect acts after the offset, so
        // those models are simulated again.
        let resim = model.effects().iter().any(|p| p.place == Place::Sensor);
        let mut r = Vec::with_capacity(scored);
        for (((u, y), &wt), y0) in td.u.iter().zip(&td.base.y).zip(&td.base.weight).zip(sims) {
            let yh = if resim {
                model.simulate(u).ok()?
            } else {
                y0.iter().map(|v| v + off).collect()
            };
            let sw = wt.sqrt();
            r.extend(
                y.iter()
                    .zip(&yh)
                    .skip(td.base.warmup)
                    .map(|(a, b)| sw * (a - b)),
            );
        }
        r.iter().all(|v| v.is_finite()).then_some(r)
    };
    let (theta, _) = levenberg_marquardt_steps(residuals, &theta0, &steps, max_iter, JOINT_RTOL);
    let model = build(&theta)?;
    eval_two_mass(td, model)
}
