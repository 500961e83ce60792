//! Which effects explain the gap: evidence read off the data (the output lattice of a
//! quantizing sensor, dwells at zero velocity of a sticking axis), every candidate fitted alone,
//! and forward selection of a second effect on top of the best one, decided on the validation
//! log.
//!
//! Forward selection ([`select_effects`]):
//! 1. every candidate (an effect kind at a place, [`Candidate`]) is fitted alone on the
//!    training logs ([`fit_placed`]) and scored by its free-run NRMSE on the validation log;
//! 2. the best single is selected if it improves on the linear re-fit by `margin`
//!    ((gap_linear − gap)/gap_linear); stiction and Coulomb friction (nested) are told apart by
//!    the dwell evidence and the nested margin;
//! 3. each of the next best singles is fitted again on top of the selected one (a model with
//!    two effects, in place order); the best pair is kept if it improves the validation NRMSE of
//!    the single by `pair_margin` (relative);
//! 4. a lattice in the measured outputs ([`lattice_evidence`]) decides quantization by itself:
//!    a sensor whose readings sit on a lattice quantizes, whatever the margin says.
//!
//! Each selected effect reports its own share of the shrink (gap_linear − gap_after): the
//! forward-selection deltas, clipped at zero and normalised to sum to 1.
use super::effect::{Effect, EffectKind};
use super::fit::{
    fit_placed, AugmentedModel, FitHints, Fitted, TrainData, VelocitySource,
};
use super::modal::{nrmse, ModalModel};
use super::place::{Candidate, Place, PlacedEffect};
use super::structure::TwoMassStructure;
use crate::error::{Error, Result};
use num_complex::Complex64;

/// The lattice of measured output values of a quantizing sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeEvidence {
    /// Lattice step, output units.
    pub step: f64,
    /// Lattice origin (one lattice point), output units.
    pub origin: f64,
    /// Share of all samples within 1 % of a step of a lattice point.
    pub share_on_lattice: f64,
    /// Number of distinct lattice levels occupied.
    pub levels: usize,
    /// Step over the output standard deviation.
    pub step_over_std: f64,
}

/// Share of samples on the lattice for [`lattice_evidence`] to report one.
pub const MIN_LATTICE_SHARE: f64 = 0.95;

/// Relative tolerance (in steps) within which a sample counts as on the lattice.
pub const LATTICE_TOL_STEPS: f64 = 0.01;

/// Reads a quantization lattice off the measured outputs (all logs pooled), scale-free: the
/// step is the median gap between neighbouring distinct values (values closer than 1e-9 of the
/// range merged), refined by least squares of the values on their level indices; the evidence
/// holds when at least [`MIN_LATTICE_SHARE`] of the samples lie within
/// [`LATTICE_TOL_STEPS`] of a lattice point, at least 3 levels are occupied, and there are at
/// most half as many distinct values as samples. A few off-lattice values (glitches, a
/// differently rounded file) do not break it. `None` for continuous-valued outputs.
pub fn lattice_evidence(y: &[Vec<f64>]) -> Option<LatticeEvidence> {
    let all: Vec<f64> = y
        .iter()
        .flat_map(|l| l.iter().copied())
        .filter(|v| v.is_finite())
        .collect();
    let total = all.len();
    if total < 16 {
        return None;
    }
    let mut v = all.clone();
    v.sort_by(f64::total_cmp);
    let range = v[total - 1] - v[0];
    if !(range > 0.0) {
        return None;
    }
    let merge = 1e-9 * range;
    let mut distinct: Vec<f64> = Vec::new();
    for &x in &v {
        if distinct.last().is_none_or(|&d| x - d > merge) {
            distinct.push(x);
        }
    }
    if distinct.len() < 3 || distinct.len() * 2 > total {
        return None;
    }
    let mut gaps: Vec<f64> = distinct.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_by(f64::total_cmp);
    let s0 = gaps[gaps.len() / 2];
    if !(s0 > 0.0) {
        return None;
    }
    // Refine: least squares of the distinct values on their level indices (near-lattice ones).
    let o0 = distinct[distinct.len() / 2];
    let (mut sq, mut sv, mut sqq, mut sqv, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &d in &distinct {
        let q = (d - o0) / s0;
        if (q - q.round()).abs() <= 0.1 {
            let qi = q.round();
            sq += qi;
            sv += d;
            sqq += qi * qi;
            sqv += qi * d;
            n += 1.0;
        }
    }
    let det = n * sqq - sq * sq;
    let (step, origin) = if n >= 3.0 && det > 0.0 {
        let st = (n * sqv - sq * sv) / det;
        (st, (sv - st * sq) / n)
    } else {
        (s0, o0)
    };
    if !(step > 0.0 && step.is_finite()) {
        return None;
    }
    let on = all
        .iter()
        .filter(|&&x| {
            let q = (x - origin) / step;
            (q - q.round()).abs() <= LATTICE_TOL_STEPS
        })
        .count();
    let share = on as f64 / total as f64;
    let mut lv: Vec<i64> = distinct
        .iter()
        .map(|&d| ((d - origin) / step).round() as i64)
        .collect();
    lv.dedup();
    let mean = all.iter().sum::<f64>() / total as f64;
    let std = (all.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / total as f64).sqrt();
    (share >= MIN_LATTICE_SHARE && lv.len() >= 3).then_some(LatticeEvidence {
        step,
        origin,
        share_on_lattice: share,
        levels: lv.len(),
        step_over_std: step / std.max(1e-300),
    })
}

/// Dwells at zero velocity while the input pushes: the mark of static friction.
#[derive(Debug, Clone, PartialEq)]
pub struct DwellEvidence {
    /// Number of dwells found (runs of at least [`MIN_DWELL_SAMPLES`]).
    pub dwells: usize,
    /// Share of the scored samples spent in dwells.
    pub dwell_share: f64,
    /// Median |input| at the end of a dwell (the breakaway), input units.
    pub breakaway: f64,
    /// Median over dwells of the largest |input| held without moving, input units.
    pub hold_max: f64,
    /// Velocity band counted as zero, in velocity units (output units, or output units per
    /// second for a position output).
    pub band: f64,
    /// Which signal stood for the velocity.
    pub velocity: VelocitySource,
}

/// Shortest run at zero velocity that counts as a dwell, samples.
pub const MIN_DWELL_SAMPLES: usize = 5;

/// Fewest dwells for [`dwell_evidence`] to report any.
pub const MIN_DWELLS: usize = 5;

/// Finds dwells in the training logs: runs of at least [`MIN_DWELL_SAMPLES`] samples where the
/// velocity (the output, or its first difference over `ts` for a position output) stays within
/// a band of zero (four times its noise level, estimated from sample-to-sample differences near
/// zero; at least 1e-3 and at most 5 % of its RMS) while the median |input| over the run is at
/// least 5 % of the input RMS. The breakaway estimate is the median |input| at the first
/// sample after each dwell. `None` with fewer than [`MIN_DWELLS`] dwells or under 1 % of the
/// samples in dwells.
pub fn dwell_evidence(
    u: &[Vec<f64>],
    y: &[Vec<f64>],
    ts: f64,
    velocity: VelocitySource,
    warmup: usize,
) -> Option<DwellEvidence> {
    let mut vel: Vec<Vec<f64>> = Vec::new();
    for yl in y {
        vel.push(match velocity {
            VelocitySource::Output => yl.clone(),
            VelocitySource::OutputDerivative => {
                let mut v = vec![0.0; yl.len()];
                for k in 1..yl.len() {
                    v[k] = (yl[k] - yl[k - 1]) / ts;
                }
                v
            }
        });
    }
    let all: Vec<f64> = vel
        .iter()
        .flat_map(|v| v.iter().skip(warmup.max(1)).copied())
        .collect();
    if all.len() < 64 {
        return None;
    }
    let rms = (all.iter().map(|x| x * x).sum::<f64>() / all.len() as f64).sqrt();
    if !(rms > 0.0) {
        return None;
    }
    let mut near: Vec<f64> = Vec::new();
    for v in &vel {
        for k in warmup.max(1)..v.len() {
            if v[k].abs() < 0.1 * rms && v[k - 1].abs() < 0.1 * rms {
                near.push((v[k] - v[k - 1]).abs());
            }
        }
    }
    let sigma = if near.len() >= 16 {
        near.sort_by(f64::total_cmp);
        1.4826 * near[near.len() / 2] / std::f64::consts::SQRT_2
    } else {
        0.0
    };
    let band = (4.0 * sigma).clamp(1e-3 * rms, 0.05 * rms);
    let u_rms = (u
        .iter()
        .flat_map(|l| l.iter().skip(warmup))
        .map(|x| x * x)
        .sum::<f64>()
        / all.len() as f64)
        .sqrt();
    let (mut dwells, mut in_dwell, mut scored) = (0usize, 0usize, 0usize);
    let mut exits: Vec<f64> = Vec::new();
    let mut holds: Vec<f64> = Vec::new();
    for (ul, v) in u.iter().zip(&vel) {
        let start = warmup.max(1);
        scored += v.len().saturating_sub(start);
        let mut k = start;
        while k < v.len() {
            if v[k].abs() > band {
                k += 1;
                continue;
            }
            let s = k;
            while k < v.len() && v[k].abs() <= band {
                k += 1;
            }
            let len = k - s;
            if len < MIN_DWELL_SAMPLES || k >= v.len() {
                continue;
            }
            let mut mags: Vec<f64> = ul[s..k].iter().map(|x| x.abs()).collect();
            mags.sort_by(f64::total_cmp);
            if mags[mags.len() / 2] < 0.05 * u_rms {
                continue;
            }
            dwells += 1;
            in_dwell += len;
            exits.push(ul[k].abs().max(ul[k - 1].abs()));
            holds.push(ul[s..k.saturating_sub(2).max(s + 1)].iter().fold(0.0f64, |a, x| a.max(x.abs())));
        }
    }
    let share = in_dwell as f64 / scored.max(1) as f64;
    if dwells < MIN_DWELLS || share < 0.01 {
        return None;
    }
    let median = |mut x: Vec<f64>| {
        x.sort_by(f64::total_cmp);
        x[x.len() / 2]
    };
    Some(DwellEvidence {
        dwells,
        dwell_share: share,
        breakaway: median(exits),
        hold_max: median(holds),
        band,
        velocity,
    })
}

/// Settings of [`select_effects`].
#[derive(Debug, Clone, PartialEq)]
pub struct SelectOptions {
    /// Relative validation improvement over the linear re-fit for the first effect.
    pub margin: f64,
    /// Relative validation improvement over the selected single for a second effect.
    pub pair_margin: f64,
    /// Relative validation improvement stiction needs over Coulomb friction without dwell
    /// evidence.
    pub nested_margin: f64,
    /// How many of the next best singles are tried on top of the best one.
    pub pair_partners: usize,
    /// Candidates (an empty list means [`default_candidates`]).
    pub candidates: Vec<Candidate>,
}

impl Default for SelectOptions {
    fn default() -> Self {
        Self {
            margin: 0.10,
            pair_margin: 0.10,
            nested_margin: 0.03,
            pair_partners: 3,
            candidates: Vec::new(),
        }
    }
}

/// The candidates tried by default: every kind at each place it may act, the two-mass places
/// only when a structure is known.
pub fn default_candidates(two_mass: bool) -> Vec<Candidate> {
    use EffectKind as K;
    let mut v = vec![
        Candidate::new(K::CoulombFriction, Place::Motor),
        Candidate::new(K::Stiction, Place::Motor),
        Candidate::new(K::Backlash, Place::Drive),
        Candidate::new(K::Deadzone, Place::Drive),
        Candidate::new(K::Saturation, Place::Drive),
        Candidate::new(K::Saturation, Place::Sensor),
        Candidate::new(K::TimeDelay, Place::Drive),
        Candidate::new(K::Resonance, Place::Drive),
        Candidate::new(K::Quantization, Place::Sensor),
        Candidate::new(K::SlewRate, Place::Drive),
    ];
    if two_mass {
        v.push(Candidate::new(K::Backlash, Place::Drivetrain));
        v.push(Candidate::new(K::CoulombFriction, Place::Load));
    }
    v
}

/// A fitted and scored model (one or more effects).
#[derive(Debug, Clone)]
pub struct Scored {
    /// The model.
    pub model: AugmentedModel,
    /// Its effects in selection order.
    pub effects: Vec<PlacedEffect>,
    /// Training cost Σ NRMSE².
    pub train_cost: f64,
    /// Free-run NRMSE on the validation log.
    pub gap: f64,
    /// (gap_linear − gap)/gap_linear.
    pub improvement: f64,
}

/// One selected effect.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectedEffect {
    /// The effect and its parameters.
    pub effect: Effect,
    /// Where it acts.
    pub place: Place,
    /// Its own share of the shrink (sums to 1 over the selected effects).
    pub share: f64,
    /// Validation NRMSE once this effect (and the ones selected before it) is added.
    pub gap_after: f64,
}

/// Result of [`select_effects`].
#[derive(Debug, Clone)]
pub struct Selection {
    /// Validation NRMSE of the linear part (the first start).
    pub gap_linear: f64,
    /// Every single candidate, best validation NRMSE first.
    pub singles: Vec<Scored>,
    /// Every pair tried, best first.
    pub pairs: Vec<Scored>,
    /// The selected effects in selection order (empty: none).
    pub selected: Vec<SelectedEffect>,
    /// The model of the selection (the linear part when nothing is selected).
    pub model: AugmentedModel,
    /// Lattice evidence of the measured outputs.
    pub lattice: Option<LatticeEvidence>,
    /// Dwell evidence of the training logs.
    pub dwell: Option<DwellEvidence>,
    /// What was decided and why.
    pub notes: Vec<String>,
}

fn score(f: Fitted, val_u: &[f64], val_y: &[f64], warmup: usize, gap_linear: f64) -> Scored {
    let gap = match f.model.simulate(val_u) {
        Ok(yh) => {
            let g = nrmse(val_y, &yh, warmup);
            if g.is_finite() {
                g
            } else {
                f64::INFINITY
            }
        }
        Err(_) => f64::INFINITY,
    };
    Scored {
        effects: f.model.effects_in_selection_order(),
        model: f.model,
        train_cost: f.train_cost,
        gap,
        improvement: (gap_linear - gap) / gap_linear,
    }
}

fn kind_of(s: &Scored) -> Option<EffectKind> {
    s.effects.first().map(|p| p.effect.kind())
}

/// Forward selection of at most two effects (module docs). `starts`: linear parts to start from
/// (first the linear re-fit, whose validation NRMSE is `gap_linear`; then e.g. the nominal sim
/// in modal form); `sim_poles`: the nominal's discrete poles (labels an added mode);
/// `structure`: a two-mass structure of the nominal, enabling the drivetrain and load places.
///
/// Errors: [`Error::InvalidArgument`] for no start or a validation log not longer than the
/// warm-up.
#[allow(clippy::too_many_arguments)]
pub fn select_effects(
    td: &TrainData,
    starts: &[ModalModel],
    sim_poles: &[Complex64],
    structure: Option<&TwoMassStructure>,
    val_u: &[f64],
    val_y: &[f64],
    warmup: usize,
    opts: &SelectOptions,
) -> Result<Selection> {
    let lin = starts.first().ok_or_else(|| {
        Error::InvalidArgument("select_effects needs at least one linear start".into())
    })?;
    if val_u.len() != val_y.len() || val_y.len() <= warmup + 1 {
        return Err(Error::InvalidArgument(format!(
            "validation log of {} samples (input {}) is not longer than the warm-up of {warmup}",
            val_y.len(),
            val_u.len()
        )));
    }
    let mut notes = Vec::new();
    let linear = AugmentedModel::linear(lin.clone());
    let gap_linear = nrmse(val_y, &linear.simulate(val_u)?, warmup);
    let lattice = lattice_evidence(&td.base.y);
    let position_output = lin.real.iter().any(|&p| p >= 1.0 - 1e-9);
    let vel = if position_output {
        VelocitySource::OutputDerivative
    } else {
        VelocitySource::Output
    };
    let dwell = dwell_evidence(&td.u, &td.base.y, td.ts, vel, td.base.warmup);
    let hints = FitHints {
        lattice_step: lattice.map(|l| l.step),
        breakaway: dwell.as_ref().map(|d| d.breakaway),
    };
    let mut bases: Vec<AugmentedModel> = starts
        .iter()
        .map(|l| AugmentedModel::linear(l.clone()))
        .collect();
    if let Some(s) = structure {
        // The nominal's two-mass plant as a further start for the structure's places.
        let mut b = AugmentedModel::linear(lin.clone());
        let mut tm = s.model.clone();
        tm.offset = lin.offset;
        b.two_mass = Some(tm);
        bases.push(b);
    }
    let cands = if opts.candidates.is_empty() {
        default_candidates(structure.is_some())
    } else {
        opts.candidates.clone()
    };
    // 1. Singles.
    let mut singles: Vec<Scored> = Vec::new();
    let mut coulomb: Option<Fitted> = None;
    let mut order = cands.clone();
    order.sort();
    for c in &order {
        let use_bases: Vec<AugmentedModel> = bases
            .iter()
            .filter(|b| b.two_mass.is_none() || c.place.needs_two_mass())
            .cloned()
            .collect();
        let hint = if c.kind == EffectKind::Stiction && c.place == Place::Motor {
            coulomb.as_ref()
        } else {
            None
        };
        match fit_placed(*c, td, &use_bases, hint, sim_poles, &hints) {
            Some(f) => {
                if c.kind == EffectKind::CoulombFriction && c.place == Place::Motor {
                    coulomb = Some(f.clone());
                }
                singles.push(score(f, val_u, val_y, warmup, gap_linear));
            }
            None => notes.push(format!("{c}: no fit")),
        }
    }
    singles.sort_by(|a, b| a.gap.total_cmp(&b.gap));
    // Nested: stiction vs Coulomb friction at the same place.
    resolve_nested(&mut singles, dwell.as_ref(), opts.nested_margin, &mut notes);
    // 2. Best single.
    let mut selected_models: Vec<Scored> = Vec::new();
    if let Some(best) = singles.first() {
        if best.improvement >= opts.margin {
            selected_models.push(best.clone());
        } else {
            notes.push(format!(
                "best single {} improves the validation NRMSE by {:.3} < margin {}",
                best.effects
                    .first()
                    .map_or("?".to_string(), |p| p.to_string()),
                best.improvement,
                opts.margin
            ));
        }
    }
    // 3. Pairs on top of the selected single.
    let mut pairs: Vec<Scored> = Vec::new();
    if let Some(first) = selected_models.first().cloned() {
        let k1 = kind_of(&first);
        let partners: Vec<Candidate> = singles
            .iter()
            .skip(1)
            .filter(|s| s.improvement > 0.0)
            .filter_map(|s| s.effects.first().map(|p| Candidate::new(p.effect.kind(), p.place)))
            .filter(|c| Some(c.kind) != k1 && !(c.kind.is_friction() && k1.is_some_and(|k| k.is_friction())))
            .filter(|c| c.kind != EffectKind::Quantization)
            .take(opts.pair_partners)
            .collect();
        let base = first.model.clone();
        for c in partners {
            if c.place.needs_two_mass() && base.two_mass.is_none() && base.motor_friction().is_some() {
                continue;
            }
            if let Some(f) = fit_placed(c, td, std::slice::from_ref(&base), None, sim_poles, &hints) {
                pairs.push(score(f, val_u, val_y, warmup, gap_linear));
            }
        }
        pairs.sort_by(|a, b| a.gap.total_cmp(&b.gap));
        if let Some(p) = pairs.first() {
            let rel = (first.gap - p.gap) / first.gap;
            if rel >= opts.pair_margin {
                selected_models.push(p.clone());
            } else {
                notes.push(format!(
                    "best pair improves on the single by {rel:.3} < pair margin {}",
                    opts.pair_margin
                ));
            }
        }
    }
    // 4. Lattice evidence decides quantization.
    let mut model = selected_models
        .last()
        .map_or(linear.clone(), |s| s.model.clone());
    if let Some(l) = lattice {
        let has_q = model
            .effects()
            .iter()
            .any(|p| p.effect.kind() == EffectKind::Quantization);
        if !has_q {
            let m = model.with_added(PlacedEffect {
                effect: Effect::Quantization { step: l.step },
                place: Place::Sensor,
            });
            let f = Fitted {
                train_cost: m.cost(&td.base, &td.u),
                model: m,
            };
            let s = score(f, val_u, val_y, warmup, gap_linear);
            model = s.model.clone();
            selected_models.push(s);
        }
        notes.push(format!(
            "outputs sit on a lattice: step {:.6e} ({:.1} % of the output std), {:.1} % of the \
             samples on it, {} levels",
            l.step,
            100.0 * l.step_over_std,
            100.0 * l.share_on_lattice,
            l.levels
        ));
    }
    let selected = shares(&selected_models, gap_linear);
    Ok(Selection {
        gap_linear,
        singles,
        pairs,
        selected,
        model,
        lattice,
        dwell,
        notes,
    })
}

/// The selected effects with their forward-selection shares: each step's model adds one effect
/// to the previous one; its share is its drop of the validation NRMSE, clipped at zero,
/// normalised to sum to 1 (equal shares when nothing dropped).
fn shares(steps: &[Scored], gap_linear: f64) -> Vec<SelectedEffect> {
    let mut prev = gap_linear;
    let mut deltas = Vec::new();
    let mut out = Vec::new();
    for s in steps {
        let Some(pe) = s.effects.last() else { continue };
        // The effect this step added: the last in selection order whose kind/place is new.
        deltas.push((prev - s.gap).max(0.0));
        prev = s.gap;
        out.push(SelectedEffect {
            effect: pe.effect,
            place: pe.place,
            share: 0.0,
            gap_after: s.gap,
        });
    }
    // Effects of the final model carry the refined parameters.
    if let Some(last) = steps.last() {
        for o in out.iter_mut() {
            if let Some(p) = last
                .effects
                .iter()
                .find(|p| p.effect.kind() == o.effect.kind() && p.place == o.place)
            {
                o.effect = p.effect;
            }
        }
    }
    let total: f64 = deltas.iter().sum();
    let n = out.len().max(1) as f64;
    for (o, d) in out.iter_mut().zip(&deltas) {
        o.share = if total > 0.0 { d / total } else { 1.0 / n };
    }
    out
}

/// Orders stiction against Coulomb friction (nested: stiction with breakaway = level is
/// Coulomb friction). Stiction ranks first when dwell evidence shows a breakaway at least 1.2
/// times its sliding level and its fitted breakaway is at least 1.3 times that level, while
/// its validation NRMSE is within the nested margin of Coulomb's; or without such evidence
/// when it lowers the validation NRMSE by the nested margin. Otherwise Coulomb ranks first.
fn resolve_nested(
    singles: &mut [Scored],
    dwell: Option<&DwellEvidence>,
    nested_margin: f64,
    notes: &mut Vec<String>,
) {
    let pos = |k: EffectKind, s: &[Scored]| s.iter().position(|x| kind_of(x) == Some(k));
    let (Some(is), Some(ic)) = (
        pos(EffectKind::Stiction, singles),
        pos(EffectKind::CoulombFriction, singles),
    ) else {
        return;
    };
    let (gs, gc) = (singles[is].gap, singles[ic].gap);
    let ratio = match singles[is].effects.first().map(|p| p.effect) {
        Some(Effect::Stiction { level, breakaway }) => (breakaway / level, level),
        _ => (1.0, f64::NAN),
    };
    let dwell_says = dwell.is_some_and(|d| d.breakaway >= 1.2 * ratio.1) && ratio.0 >= 1.3;
    let stiction_wins = (dwell_says && gs <= gc * (1.0 + nested_margin))
        || gs < gc * (1.0 - nested_margin);
    notes.push(format!(
        "stiction vs coulomb_friction: validation NRMSE {gs:.4} vs {gc:.4}, fitted breakaway \
         ratio {:.2}, dwell breakaway {}",
        ratio.0,
        dwell.map_or("none".to_string(), |d| format!("{:.4} ({} dwells)", d.breakaway, d.dwells))
    ));
    if stiction_wins != (is < ic) {
        singles.swap(is, ic);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = crate::gap::rng::Rng::new(seed);
        (0..n).map(|_| rng.normal()).collect()
    }

    /// Quantization after noise, steps 3–8 % of the output RMS, at unit and at 6e-6 scale,
    /// written with 9 significant digits: the lattice is found and the step recovered.
    #[test]
    fn lattice_is_found_scale_free_after_noise() {
        for &(scale, rel) in &[(1.0, 0.03), (1.0, 0.08), (2e-4, 0.03), (2e-4, 0.05)] {
            let x = noise(20000, 3);
            // Smooth signal: running mean, then noise before the quantizer.
            let mut s = 0.0;
            let sig: Vec<f64> = x
                .iter()
                .map(|v| {
                    s = 0.95 * s + 0.05 * v;
                    s
                })
                .collect();
            let rms = (sig.iter().map(|v| v * v).sum::<f64>() / sig.len() as f64).sqrt();
            let step = rel * rms * scale;
            let nz = noise(20000, 9);
            let y: Vec<f64> = sig
                .iter()
                .zip(&nz)
                .map(|(a, e)| {
                    let v = (a * scale + 0.01 * rms * scale * e) / step;
                    let q = v.round() * step;
                    format!("{q:.8e}").parse::<f64>().unwrap()
                })
                .collect();
            let l = lattice_evidence(&[y.clone()]).expect("lattice");
            assert!(
                (l.step - step).abs() < 1e-6 * step,
                "scale {scale} rel {rel}: step {} vs {step}",
                l.step
            );
            assert!(l.share_on_lattice > 0.999);
            // A few off-lattice glitches do not break it.
            let mut g = y.clone();
            for k in (0..g.len()).step_by(997) {
                g[k] += 0.37 * step;
            }
            let l = lattice_evidence(&[g]).expect("lattice with glitches");
            assert!((l.step - step).abs() < 1e-6 * step);
        }
        // A continuous signal has none.
        assert!(lattice_evidence(&[noise(5000, 4)]).is_none());
    }
}
