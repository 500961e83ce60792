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
//!    the dwell evidence and the nested margin. A best single that reaches half the margin is a
//!    tentative forward step: kept only when a pair on top of it reaches the margin (two
//!    effects that each explain a part of the gap, e.g. friction behind a saturated drive);
//! 3. each of the next best singles is fitted again on top of the selected one (a model with
//!    two effects, in place order), and Coulomb friction at the motor always (its single fit is
//!    masked by a stronger first effect), and play in the drive when the first is friction
//!    (likewise masked); the best pair is kept if it improves the validation
//!    NRMSE of the single by `pair_margin` (relative) and removes `min_excess_closed` of the
//!    single's excess over the noise floor (the verdict rule's test, step by step), a pair with Coulomb friction at the motor
//!    weighed against its stiction variant as the singles are; no pair is sought once the
//!    single is within [`PAIR_FLOOR_FACTOR`] of the noise floor. A backward step then drops
//!    each effect of that pair in turn: when the pair does not beat a reduced model by the
//!    same rule, the dropped effect was a passenger (a Coulomb level 1/140 of its single fit's
//!    "closing" a gap that the partner's longer fit closed) and the reduced model is the
//!    single;
//! 4. a lattice in the measured outputs ([`lattice_evidence`]) decides quantization by itself:
//!    a sensor whose readings sit on a lattice quantizes, whatever the margin says.
//!
//! Each selected effect reports its own share of the shrink (gap_linear − gap_after): the
//! forward-selection deltas, clipped at zero and normalised to sum to 1.
use super::drift::validation_nrmse;
use super::effect::{Effect, EffectKind};
use super::fit::{
    beats_by_screen_gain, eval_model, fit_placed, joint_fit, refined, AugmentedModel, FitHints,
    Fitted, TrainData, VelocitySource, FRICTION_SUBSTEPS, JOINT_MAX_ITER,
};
use super::modal::ModalModel;
use super::place::{Candidate, Place, PlacedEffect};
use super::structure::TwoMassStructure;
use crate::error::{Error, Result};
use num_complex::Complex64;

mod contradiction;
mod dwell;
mod lattice;
mod nested;
mod stribeck;

#[cfg(test)]
mod cases;
#[cfg(test)]
mod checks;
#[cfg(test)]
mod conditioning;

use contradiction::DataFacts;
pub use contradiction::{CLIP_TOL, MAX_SHARE_BEYOND_CLIP, MIN_REVERSALS, REVERSAL_BAND};
pub use dwell::{dwell_evidence, DwellEvidence, MIN_DWELLS, MIN_DWELL_SAMPLES};
pub use lattice::{lattice_evidence, LatticeEvidence, LATTICE_TOL_STEPS, MIN_LATTICE_SHARE};
pub use nested::NESTED_FLOOR_FACTOR;
use nested::{pair_nested_variant, resolve_nested};

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
    /// The measured training outputs as logged, before any averaging (the lattice of a
    /// quantizing sensor is only in the raw values: averaging over periods fills it in).
    /// Empty: the outputs of the training data.
    pub raw_outputs: Vec<Vec<f64>>,
    /// Validation NRMSE a perfect model would still leave (the noise floor), when known: no
    /// pair is tried once the selected single is within [`PAIR_FLOOR_FACTOR`] of it.
    pub noise_floor: Option<f64>,
    /// Share of the selected single's excess over the noise floor (its validation NRMSE minus
    /// `noise_floor`, the floor taken as 0 when unknown) a second effect must remove: the
    /// verdict rule's test for the first effect, applied to the second (a second effect that
    /// trims a little off a gap far above the floor stands in for something else, e.g. linear
    /// dynamics the nominal lacks).
    pub min_excess_closed: f64,
    /// Drift window of the validation NRMSE ([`crate::gap::modal::validation_nrmse`]), for a
    /// linear part with an integrator; `None`: the plain NRMSE.
    pub drift_window: Option<usize>,
    /// Sample alignment already applied to the logs ([`crate::gap::align`]), samples: a time
    /// delay that keeps the total lag within the alignment range is the alignment's.
    pub alignment_samples: f64,
}

/// A second effect is not sought once the best single's validation NRMSE is within this
/// factor of the noise floor.
pub const PAIR_FLOOR_FACTOR: f64 = 2.0;

impl Default for SelectOptions {
    fn default() -> Self {
        Self {
            margin: 0.10,
            pair_margin: 0.10,
            nested_margin: 0.03,
            pair_partners: 2,
            candidates: Vec::new(),
            raw_outputs: Vec::new(),
            noise_floor: None,
            min_excess_closed: crate::gap::diagnose::DEFAULT_MIN_EXCESS_CLOSED,
            drift_window: None,
            alignment_samples: 0.0,
        }
    }
}

/// Pairs are tried only when the best single leaves more than this share of the linear
/// re-fit's validation NRMSE unexplained: improvement (gap_linear − gap)/gap_linear below it.
pub const PAIR_WORTH_TRYING: f64 = 0.9;

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
        Candidate::new(K::StateLimit, Place::State),
        Candidate::new(K::CurrentLimit, Place::State),
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

/// CPU seconds of the calling thread (from /proc, Linux) when `GAP_PROFILE` is set, else 0:
/// per-candidate timing that a loaded machine does not inflate.
fn profile_seconds() -> f64 {
    if std::env::var_os("GAP_PROFILE").is_none() {
        return 0.0;
    }
    thread_cpu_seconds()
}

/// Prints `what` with the CPU seconds since `t0` (a [`profile_seconds`] reading) when
/// `GAP_PROFILE` is set.
fn profile_since(what: &str, t0: f64) {
    if std::env::var_os("GAP_PROFILE").is_some() {
        eprintln!("profile: {what} {:.3} s (cpu)", profile_seconds() - t0);
    }
}

/// CPU seconds of this thread (user + system), from /proc; 0 where unavailable.
fn thread_cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/thread-self/stat")
        .ok()
        .and_then(|s| {
            let rest = s.rsplit(')').next()?.to_string();
            let f: Vec<&str> = rest.split_whitespace().collect();
            let ut: f64 = f.get(11)?.parse().ok()?;
            let st: f64 = f.get(12)?.parse().ok()?;
            Some((ut + st) / 100.0)
        })
        .unwrap_or(0.0)
}

/// Validation data of the selection: input, output, warm-up, drift window.
pub(super) type Val<'a> = (&'a [f64], &'a [f64], usize, Option<usize>);

fn score(f: Fitted, val: Val, gap_linear: f64) -> Scored {
    let (val_u, val_y, warmup, drift) = val;
    let gap = match f.model.simulate(val_u) {
        Ok(yh) => {
            let g = validation_nrmse(val_y, &yh, warmup, drift);
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

pub(super) fn kind_of(s: &Scored) -> Option<EffectKind> {
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
    let val: Val = (val_u, val_y, warmup, opts.drift_window);
    let gap_linear = validation_nrmse(val_y, &linear.simulate(val_u)?, warmup, opts.drift_window);
    let raw = if opts.raw_outputs.is_empty() {
        &td.base.y
    } else {
        &opts.raw_outputs
    };
    let lattice = lattice_evidence(raw);
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
        to_beat: Some(linear.cost(&td.base, &td.u)),
    };
    let bases = bases_of(starts, structure);
    let cands = if opts.candidates.is_empty() {
        default_candidates(structure.is_some())
    } else {
        opts.candidates.clone()
    };
    // 1. Singles.
    let facts = DataFacts::of(
        raw,
        &td.u,
        td.ts,
        vel,
        td.base.warmup,
        opts.alignment_samples,
    );
    let mut singles = fit_singles(
        td,
        &bases,
        &cands,
        (sim_poles, &hints),
        (val, gap_linear),
        &facts,
        &mut notes,
    );
    // Nested: stiction vs Coulomb friction at the same place.
    let t0 = profile_seconds();
    resolve_nested(
        &mut singles,
        td,
        dwell.as_ref(),
        opts.nested_margin,
        opts.noise_floor,
        &mut notes,
    );
    profile_since("nested singles", t0);
    // 2. Best single (a forward step below the margin when it reaches half of it: kept only
    // if a pair on top of it reaches the margin, see below).
    let (mut selected_models, tentative) = first_step(&singles, opts, &mut notes);
    // 3. Pairs on top of the selected single.
    let mut pairs: Vec<Scored> = Vec::new();
    let try_pairs = selected_models
        .first()
        .is_some_and(|f| pairs_worth_trying(f, opts));
    if !try_pairs && !selected_models.is_empty() {
        notes.push(format!(
            "no pair tried: the best single closes more than {:.0} % of the linear gap or \
             is within {PAIR_FLOOR_FACTOR}x the noise floor",
            100.0 * PAIR_WORTH_TRYING
        ));
    }
    if let Some(first) = selected_models.first().cloned().filter(|_| try_pairs) {
        let ctx = PairContext {
            td,
            singles: &singles,
            sim_poles,
            hints: &hints,
            val,
            gap_linear,
            opts,
            velocity: vel,
            structure_base: bases.iter().find(|b| b.two_mass.is_some()),
        };
        let (first, tried, chosen) = ctx.select(first, tentative, dwell.as_ref(), &mut notes);
        selected_models[0] = first;
        pairs = tried;
        selected_models.extend(chosen);
    }
    if tentative
        && selected_models.len() < 2
        && selected_models
            .first()
            .is_some_and(|s| s.improvement < opts.margin)
    {
        // The forward step below the margin found no pair that reaches it: nothing selected.
        selected_models.clear();
    }
    // The selected friction on a Stribeck curve when the training logs ask for one.
    if let Some(last) = selected_models.last_mut() {
        let t0 = profile_seconds();
        stribeck::refine_stribeck(last, td, val, gap_linear, &mut notes);
        profile_since("stribeck", t0);
    }
    // 4. Lattice evidence decides quantization; the effects selected besides it must pass
    // the verdict rule on their own.
    let model = lattice_decides(
        &mut selected_models,
        &linear,
        lattice,
        td,
        (val, gap_linear),
        opts,
        &mut notes,
    );
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

/// Step 2 of [`select_effects`]: the best single when it improves on the linear re-fit by the
/// margin; when it reaches only half of it, a tentative forward step (the flag), which a pair
/// has to carry over the margin. Notes a best single below the margin.
fn first_step(
    singles: &[Scored],
    opts: &SelectOptions,
    notes: &mut Vec<String>,
) -> (Vec<Scored>, bool) {
    let Some(best) = singles.first() else {
        return (Vec::new(), false);
    };
    if best.improvement >= opts.margin {
        return (vec![best.clone()], false);
    }
    notes.push(format!(
        "best single {} improves the validation NRMSE by {:.3} < margin {}",
        best.effects
            .first()
            .map_or("?".to_string(), |p| p.to_string()),
        best.improvement,
        opts.margin
    ));
    if best.improvement >= 0.5 * opts.margin {
        (vec![best.clone()], true)
    } else {
        (Vec::new(), false)
    }
}

/// Whether pairs are grown on `first`: it leaves more than [`PAIR_WORTH_TRYING`] of the linear
/// gap open and (with a noise floor) stays at or above [`PAIR_FLOOR_FACTOR`] times the floor.
fn pairs_worth_trying(first: &Scored, opts: &SelectOptions) -> bool {
    first.improvement < PAIR_WORTH_TRYING
        && opts.noise_floor.is_none_or(|fl| {
            first.gap.partial_cmp(&(PAIR_FLOOR_FACTOR * fl)) != Some(std::cmp::Ordering::Less)
                && first.gap != PAIR_FLOOR_FACTOR * fl
        })
}

/// The linear parts every single extends: each start, and with a two-mass structure the
/// nominal's two-mass plant (for the structure's places), offset from the first start.
fn bases_of(starts: &[ModalModel], structure: Option<&TwoMassStructure>) -> Vec<AugmentedModel> {
    let mut bases: Vec<AugmentedModel> = starts
        .iter()
        .map(|l| AugmentedModel::linear(l.clone()))
        .collect();
    if let (Some(s), Some(lin)) = (structure, starts.first()) {
        let mut b = AugmentedModel::linear(lin.clone());
        let mut tm = s.model.clone();
        tm.offset = lin.offset;
        b.two_mass = Some(tm);
        bases.push(b);
    }
    bases
}

/// Step 1 of [`select_effects`]: every candidate fitted alone from the `bases` it may extend
/// (the two-mass places from the structure's bases too) and scored on validation, best first;
/// stiction at the motor starts from the Coulomb fit, and friction on the load that ranks first
/// gets its stiction variant.
fn fit_singles(
    td: &TrainData,
    bases: &[AugmentedModel],
    cands: &[Candidate],
    (sim_poles, hints): (&[Complex64], &FitHints),
    (val, gap_linear): (Val, f64),
    facts: &DataFacts,
    notes: &mut Vec<String>,
) -> Vec<Scored> {
    let mut singles: Vec<Scored> = Vec::new();
    let mut coulomb: Option<Fitted> = None;
    let mut order = cands.to_vec();
    order.sort();
    for c in &order {
        // Inside a two-mass structure: the re-fit mapped to physical coordinates and the
        // nominal's structure (the nominal in modal form maps to the same plant).
        let use_bases: Vec<AugmentedModel> = if c.place.needs_two_mass() {
            bases
                .iter()
                .enumerate()
                .filter(|(i, b)| *i == 0 || b.two_mass.is_some())
                .map(|(_, b)| b.clone())
                .collect()
        } else {
            bases
                .iter()
                .filter(|b| b.two_mass.is_none())
                .cloned()
                .collect()
        };
        let hint = if c.kind == EffectKind::Stiction && c.place == Place::Motor {
            coulomb.as_ref()
        } else {
            None
        };
        let t0 = profile_seconds();
        let fc = fit_placed(*c, td, &use_bases, hint, sim_poles, hints);
        profile_since(&c.to_string(), t0);
        let why_not = fc.as_ref().and_then(|f| {
            f.model
                .effects()
                .iter()
                .find_map(|pe| facts.contradiction(pe))
        });
        match (fc, why_not) {
            (Some(_), Some(why)) => notes.push(why),
            (Some(f), None) => {
                if c.kind == EffectKind::CoulombFriction && c.place == Place::Motor {
                    coulomb = Some(f.clone());
                }
                singles.push(score(f, val, gap_linear));
            }
            (None, _) => notes.push(format!("{c}: no fit")),
        }
    }
    singles.sort_by(|a, b| a.gap.total_cmp(&b.gap));
    // Friction on the load wins: its stiction variant, started from it.
    if singles
        .first()
        .and_then(|s| s.effects.first())
        .is_some_and(|p| p.place == Place::Load && p.effect.kind() == EffectKind::CoulombFriction)
    {
        let c = Fitted {
            model: singles[0].model.clone(),
            train_cost: singles[0].train_cost,
        };
        let cand = Candidate::new(EffectKind::Stiction, Place::Load);
        if let Some(f) = fit_placed(
            cand,
            td,
            std::slice::from_ref(&c.model),
            Some(&c),
            sim_poles,
            hints,
        ) {
            singles.push(score(f, val, gap_linear));
            singles.sort_by(|a, b| a.gap.total_cmp(&b.gap));
        }
    }
    singles
}

/// Share of the excess gap_linear − floor (floor 0 when unknown) that a validation NRMSE of
/// `gap` removes.
fn excess_closed(gap: f64, gap_linear: f64, floor: Option<f64>) -> f64 {
    let f = floor.unwrap_or(0.0).clamp(0.0, gap_linear);
    (gap_linear - gap) / (gap_linear - f).max(1e-300)
}

/// The verdict rule ([`crate::gap::verdict::VerdictRule`]) on a scored selection step alone:
/// the margin over the linear re-fit and the share of the excess over the floor.
fn passes_rule_alone(s: &Scored, gap_linear: f64, opts: &SelectOptions) -> bool {
    s.gap.is_finite()
        && s.improvement >= opts.margin
        && excess_closed(s.gap, gap_linear, opts.noise_floor) >= opts.min_excess_closed
}

/// Step 4 of [`select_effects`]: a lattice in the measured outputs decides quantization by
/// itself (added at the sensor to the selected model when it lacks it). Returns the final
/// model (the last selected step, or `linear`).
fn lattice_decides(
    selected_models: &mut Vec<Scored>,
    linear: &AugmentedModel,
    lattice: Option<LatticeEvidence>,
    td: &TrainData,
    (val, gap_linear): (Val, f64),
    opts: &SelectOptions,
    notes: &mut Vec<String>,
) -> AugmentedModel {
    let Some(l) = lattice else {
        return selected_models
            .last()
            .map_or(linear.clone(), |s| s.model.clone());
    };
    // The lattice names quantization by itself; nothing else rides in on it: the effects
    // selected besides a lattice-added quantization pass the verdict rule without it or go.
    let has_q = |m: &AugmentedModel| {
        m.effects()
            .iter()
            .any(|p| p.effect.kind() == EffectKind::Quantization)
    };
    if let Some(last) = selected_models.last() {
        if !has_q(&last.model) && !passes_rule_alone(last, gap_linear, opts) {
            notes.push(format!(
                "{} closes {:.0} % of the linear re-fit's excess over the noise floor (the \
                 verdict rule asks {:.0} %): not named beside the lattice's quantization",
                last.effects
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(" + "),
                100.0 * excess_closed(last.gap, gap_linear, opts.noise_floor),
                100.0 * opts.min_excess_closed
            ));
            selected_models.clear();
        }
    }
    let mut model = selected_models
        .last()
        .map_or(linear.clone(), |s| s.model.clone());
    if !has_q(&model) {
        let m = model.with_added(PlacedEffect {
            effect: Effect::Quantization { step: l.step },
            place: Place::Sensor,
        });
        let f = Fitted {
            train_cost: m.cost(&td.base, &td.u),
            model: m,
        };
        let s = score(f, val, gap_linear);
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
    model
}

/// What the pair stage of [`select_effects`] shares between the singles it grows pairs from.
struct PairContext<'a> {
    td: &'a TrainData,
    singles: &'a [Scored],
    sim_poles: &'a [Complex64],
    hints: &'a FitHints,
    val: Val<'a>,
    gap_linear: f64,
    opts: &'a SelectOptions,
    /// The velocity the dwell evidence reads (output or its derivative).
    velocity: VelocitySource,
    /// The nominal's two-mass plant (offset from the linear re-fit), when it has one.
    structure_base: Option<&'a AugmentedModel>,
}

impl PairContext<'_> {
    /// `single` refined jointly before pairs grow from it, so a pair is credited only with
    /// what its second effect adds (not with further iterations on the first); kept only when
    /// it does not score worse on validation.
    fn polish(&self, single: Scored) -> Scored {
        let f = Fitted {
            model: single.model.clone(),
            train_cost: single.train_cost,
        };
        match joint_fit(self.td, &f, JOINT_MAX_ITER) {
            Some(j) if j.train_cost < single.train_cost => {
                let s = score(j, self.val, self.gap_linear);
                if s.gap <= single.gap {
                    s
                } else {
                    single
                }
            }
            _ => single,
        }
    }

    /// The second effects tried on top of `first`: the next best singles of other kinds (at
    /// most `pair_partners`, each reaching half the margin alone), Coulomb friction at the motor whatever its
    /// single score (alone it is fitted against the gap of the stronger effect too, a
    /// saturated drive, a delay, which can pull its level to zero), play in the drive
    /// behind friction (both act at velocity reversals, and alone the play is fitted against
    /// the friction's gap), and with a two-mass structure backlash in the drivetrain (alone it
    /// is fitted against a saturated drive's gap too: 4 % on a shaft whose play the pair
    /// closes).
    fn partners(&self, first: &Scored) -> Vec<Candidate> {
        let k1 = kind_of(first);
        let friction1 = k1.is_some_and(|k| k.is_friction());
        let mut partners: Vec<Candidate> = self
            .singles
            .iter()
            .filter(|s| s.improvement >= 0.5 * self.opts.margin)
            .filter_map(|s| {
                s.effects
                    .first()
                    .map(|p| Candidate::new(p.effect.kind(), p.place))
            })
            .filter(|c| {
                Some(c.kind) != k1
                    && !(c.kind.is_friction() && friction1)
                    && c.kind != EffectKind::Quantization
                    && c.kind != EffectKind::Stiction
            })
            .take(self.opts.pair_partners)
            .collect();
        if !friction1 && !partners.iter().any(|c| c.kind.is_friction()) {
            partners.push(Candidate::new(EffectKind::CoulombFriction, Place::Motor));
        }
        if friction1 && !partners.iter().any(|c| c.kind == EffectKind::Backlash) {
            partners.push(Candidate::new(EffectKind::Backlash, Place::Drive));
        }
        let drivetrain = Candidate::new(EffectKind::Backlash, Place::Drivetrain);
        let structure = self
            .singles
            .iter()
            .any(|s| s.effects.iter().any(|p| p.place == Place::Drivetrain));
        let first_in_drivetrain = first.effects.iter().any(|p| p.place == Place::Drivetrain);
        if structure && !first_in_drivetrain && !partners.contains(&drivetrain) {
            partners.push(drivetrain);
        }
        partners
    }

    /// Step 3 of [`select_effects`]: `first` polished, the pairs grown on it (best first), and
    /// the best pair when it improves on `first` by `pair_margin`, removes `min_excess_closed`
    /// of its excess over the noise floor and, after a `tentative` first step, reaches the
    /// margin over the linear model itself (weighed against its stiction variant).
    fn select(
        &self,
        first: Scored,
        tentative: bool,
        dwell: Option<&DwellEvidence>,
        notes: &mut Vec<String>,
    ) -> (Scored, Vec<Scored>, Option<Scored>) {
        let opts = self.opts;
        let t0 = profile_seconds();
        let first = self.polish(first);
        profile_since("polish", t0);
        let mut pairs = self.pairs_on(&first);
        pairs.sort_by(|a, b| a.gap.total_cmp(&b.gap));
        let Some(p) = pairs.first().cloned() else {
            return (first, pairs, None);
        };
        let rel = (first.gap - p.gap) / first.gap;
        let floor = opts.noise_floor.unwrap_or(0.0).clamp(0.0, first.gap);
        let closed = (first.gap - p.gap) / (first.gap - floor).max(1e-300);
        if rel >= opts.pair_margin
            && closed >= opts.min_excess_closed
            && (!tentative || p.improvement >= opts.margin)
        {
            let t0 = profile_seconds();
            let passenger = self.passenger_free(&p);
            profile_since("passenger check", t0);
            if let Some(r) = passenger {
                notes.push(format!(
                    "pair {} ({:.4}) without its {} scores {:.4}: the pair adds no effect, \
                     kept as the single {}",
                    p.effects
                        .iter()
                        .map(|e| e.to_string())
                        .collect::<Vec<_>>()
                        .join(" + "),
                    p.gap,
                    p.effects
                        .iter()
                        .find(|e| !r.effects.contains(e))
                        .map_or("?".to_string(), |e| e.effect.kind().to_string()),
                    r.gap,
                    r.effects.first().map_or("?".to_string(), |e| e.to_string()),
                ));
                let first = if r.gap < first.gap { r } else { first };
                return (first, pairs, None);
            }
            let t0 = profile_seconds();
            let p = pair_nested_variant(p, self, &first.model, dwell, notes);
            profile_since("pair nested variant", t0);
            return (first, pairs, Some(p));
        }
        notes.push(format!(
            "best pair improves on the single by {rel:.3} (pair margin {}) and removes \
             {:.0} % of its excess over the noise floor (needs {:.0} %): not selected",
            opts.pair_margin,
            100.0 * closed,
            100.0 * opts.min_excess_closed
        ));
        (first, pairs, None)
    }

    /// Backward step on a pair about to be selected: each of its effects removed (the other's
    /// parameters and the linear part's poles as the pair fitted them, residues re-fitted) and
    /// the reduced model scored. When the pair does not beat the best reduced model by the pair
    /// rule (`pair_margin` and `min_excess_closed` of the reduced model's excess over the
    /// floor), the removed effect is a passenger — the pair's gain came from its partner's
    /// longer fit — and the reduced model is returned.
    fn passenger_free(&self, pair: &Scored) -> Option<Scored> {
        let n = pair.model.effects_in_selection_order().len();
        if n < 2 {
            return None;
        }
        let r = (0..n)
            .filter_map(|i| eval_model(self.td, pair.model.without(i), FRICTION_SUBSTEPS))
            .map(|f| score(f, self.val, self.gap_linear))
            .min_by(|a, b| a.gap.total_cmp(&b.gap))?;
        let floor = self.opts.noise_floor.unwrap_or(0.0).clamp(0.0, r.gap);
        let rel = (r.gap - pair.gap) / r.gap;
        let closed = (r.gap - pair.gap) / (r.gap - floor).max(1e-300);
        (!(rel >= self.opts.pair_margin && closed >= self.opts.min_excess_closed)).then_some(r)
    }

    /// The model partner `c` is fitted on: `first`'s; for a partner inside the two-mass
    /// structure (drivetrain, load) on a `first` fitted on the modal linear part, the
    /// structure's two-mass plant (as the best single inside it fitted it, else the nominal's)
    /// carrying `first`'s effects — a modal linear part refined around a drive effect need not
    /// convert back to a two-mass plant, and the pair must be one model.
    fn base_for(&self, first: &Scored, c: Candidate) -> Option<AugmentedModel> {
        let base = &first.model;
        if !c.place.needs_two_mass() || base.two_mass.is_some() {
            return Some(base.clone());
        }
        let mut m = match self.singles.iter().find(|s| s.model.two_mass.is_some()) {
            Some(s) => s.model.clone(),
            None => self.structure_base?.clone(),
        };
        m.effect = None;
        m.place = Place::Drive;
        m.extra.clear();
        for pe in base.effects_in_selection_order() {
            m = m.with_added(pe);
        }
        Some(m)
    }

    /// Every partner of `first` ([`Self::partners`]) fitted on top of it and scored.
    fn pairs_on(&self, first: &Scored) -> Vec<Scored> {
        let mut pairs = Vec::new();
        for c in self.partners(first) {
            let Some(base) = self.base_for(first, c) else {
                continue;
            };
            let t0 = profile_seconds();
            let hints = FitHints {
                to_beat: Some(first.train_cost),
                ..*self.hints
            };
            let fc = fit_placed(
                c,
                self.td,
                std::slice::from_ref(&base),
                None,
                self.sim_poles,
                &hints,
            );
            profile_since(&format!("pair + {c}"), t0);
            // A pair inside the two-mass structure: a second joint refinement (its cost is
            // narrow in the gap and the first stops short when the drive effect moves too),
            // when the first brought it a gain on `first` worth refining (see
            // [`crate::gap::fit::SCREEN_MIN_GAIN`]).
            let t0 = profile_seconds();
            let fc = match fc {
                Some(f)
                    if c.place.needs_two_mass()
                        && beats_by_screen_gain(f.train_cost, first.train_cost) =>
                {
                    Some(refined(self.td, f, JOINT_MAX_ITER))
                }
                other => other,
            };
            if c.place.needs_two_mass() {
                profile_since(&format!("pair + {c} second refinement"), t0);
            }
            if let Some(f) = fc {
                pairs.push(score(f, self.val, self.gap_linear));
            }
        }
        pairs
    }
}

/// The selected effects with their forward-selection shares: each step's model adds one effect
/// to the previous one; its share is its drop of the validation NRMSE, clipped at zero,
/// normalised to sum to 1 — and 0 for every effect when nothing dropped (a lattice can name
/// quantization on a gap that does not shrink: its share of no shrink is none).
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
    // Effects of the final model carry the refined parameters, and the kind the pair stage's
    // nested decision gave the friction at a place (stiction or Coulomb friction).
    if let Some(last) = steps.last() {
        for o in out.iter_mut() {
            let (k, place) = (o.effect.kind(), o.place);
            if let Some(p) = last.effects.iter().find(|p| {
                p.place == place
                    && (p.effect.kind() == k || (p.effect.kind().is_friction() && k.is_friction()))
            }) {
                o.effect = p.effect;
            }
        }
    }
    let total: f64 = deltas.iter().sum();
    for (o, d) in out.iter_mut().zip(&deltas) {
        o.share = if total > 0.0 { d / total } else { 0.0 };
    }
    out
}
