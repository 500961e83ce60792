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
use super::diagnose::{nested_likelihood_ratio, NESTED_LR_THRESHOLD};
use super::effect::{Effect, EffectKind};
use super::fit::{
    fit_placed, joint_fit, AugmentedModel, FitHints, Fitted, TrainData, VelocitySource,
    JOINT_MAX_ITER,
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
    if range.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
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
    if s0.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
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
    /// Breakaway estimate: the 90th percentile over dwells of the largest |input| held without
    /// moving (at rest the drive balances the friction), input units.
    pub breakaway: f64,
    /// Median |input| at the first sample after a dwell (an upper bound of the breakaway,
    /// inflated by the acceleration that follows), input units.
    pub exit_median: f64,
    /// Median over dwells of the largest |input| held without moving, input units.
    pub hold_max: f64,
    /// Velocity band counted as zero, in velocity units (output units, or output units per
    /// second for a position output).
    pub band: f64,
    /// Which signal stood for the velocity.
    pub velocity: VelocitySource,
}

/// Shortest run at zero velocity that counts as a dwell, samples.
pub const MIN_DWELL_SAMPLES: usize = 8;

/// Fewest dwells for [`dwell_evidence`] to report any.
pub const MIN_DWELLS: usize = 5;

/// Finds dwells in the training logs: runs of at least [`MIN_DWELL_SAMPLES`] samples where the
/// velocity (the output, or its first difference over `ts` for a position output) stays within
/// a band of zero (four times its noise level, estimated from sample-to-sample differences near
/// zero; at least 1e-3 and at most 5 % of its RMS) while the median |input| over the run is at
/// least 5 % of the input RMS. The breakaway estimate is the 90th percentile over dwells of the
/// largest |input| held at rest (the last two samples of each dwell left out). `None` with fewer than [`MIN_DWELLS`] dwells or under 1 % of the
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
    if rms.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
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
            holds.push(
                ul[s..k.saturating_sub(2).max(s + 1)]
                    .iter()
                    .fold(0.0f64, |a, x| a.max(x.abs())),
            );
        }
    }
    let share = in_dwell as f64 / scored.max(1) as f64;
    if dwells < MIN_DWELLS || share < 0.01 {
        return None;
    }
    let quantile = |mut x: Vec<f64>, q: f64| {
        x.sort_by(f64::total_cmp);
        x[((x.len() - 1) as f64 * q).round() as usize]
    };
    Some(DwellEvidence {
        dwells,
        dwell_share: share,
        breakaway: quantile(holds.clone(), 0.9),
        exit_median: quantile(exits, 0.5),
        hold_max: quantile(holds, 0.5),
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
    /// The measured training outputs as logged, before any averaging (the lattice of a
    /// quantizing sensor is only in the raw values: averaging over periods fills it in).
    /// Empty: the outputs of the training data.
    pub raw_outputs: Vec<Vec<f64>>,
    /// Validation NRMSE a perfect model would still leave (the noise floor), when known: no
    /// pair is tried once the selected single is within [`PAIR_FLOOR_FACTOR`] of it.
    pub noise_floor: Option<f64>,
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
    let lattice = if opts.raw_outputs.is_empty() {
        lattice_evidence(&td.base.y)
    } else {
        lattice_evidence(&opts.raw_outputs)
    };
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
        let fc = fit_placed(*c, td, &use_bases, hint, sim_poles, &hints);
        if std::env::var_os("GAP_PROFILE").is_some() {
            eprintln!("profile: {c} {:.3} s (cpu)", profile_seconds() - t0);
        }
        match fc {
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
            &hints,
        ) {
            singles.push(score(f, val_u, val_y, warmup, gap_linear));
            singles.sort_by(|a, b| a.gap.total_cmp(&b.gap));
        }
    }
    // Nested: stiction vs Coulomb friction at the same place.
    resolve_nested(
        &mut singles,
        td,
        dwell.as_ref(),
        opts.nested_margin,
        &mut notes,
    );
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
    let try_pairs = selected_models.first().is_some_and(|f| {
        f.improvement < PAIR_WORTH_TRYING
            && opts.noise_floor.is_none_or(|fl| {
                f.gap.partial_cmp(&(PAIR_FLOOR_FACTOR * fl)) != Some(std::cmp::Ordering::Less)
                    && f.gap != PAIR_FLOOR_FACTOR * fl
            })
    });
    if !try_pairs && !selected_models.is_empty() {
        notes.push(format!(
            "no pair tried: the best single closes more than {:.0} % of the linear gap or \
             is within {PAIR_FLOOR_FACTOR}x the noise floor",
            100.0 * PAIR_WORTH_TRYING
        ));
    }
    if let Some(first) = selected_models.first().cloned().filter(|_| try_pairs) {
        let k1 = kind_of(&first);
        let partners: Vec<Candidate> = singles
            .iter()
            .skip(1)
            .filter(|s| s.improvement >= 0.5 * opts.margin)
            .filter_map(|s| {
                s.effects
                    .first()
                    .map(|p| Candidate::new(p.effect.kind(), p.place))
            })
            .filter(|c| {
                Some(c.kind) != k1 && !(c.kind.is_friction() && k1.is_some_and(|k| k.is_friction()))
            })
            .filter(|c| c.kind != EffectKind::Quantization && c.kind != EffectKind::Stiction)
            .take(opts.pair_partners)
            .collect();
        let mut partners = partners;
        if dwell.is_some()
            && !k1.is_some_and(|k| k.is_friction())
            && !partners.iter().any(|c| c.kind.is_friction())
        {
            // Dwells at zero velocity: friction is a partner whatever its single score.
            partners.push(Candidate::new(EffectKind::CoulombFriction, Place::Motor));
        }
        // Polish the single first, so a pair is credited only with what its second effect
        // adds (not with further iterations on the first).
        let first = match joint_fit(
            td,
            &Fitted {
                model: first.model.clone(),
                train_cost: first.train_cost,
            },
            JOINT_MAX_ITER,
        ) {
            Some(j) if j.train_cost < first.train_cost => {
                let s = score(j, val_u, val_y, warmup, gap_linear);
                if s.gap <= first.gap {
                    selected_models[0] = s.clone();
                    s
                } else {
                    first
                }
            }
            _ => first,
        };
        let base = first.model.clone();
        for c in partners {
            if c.place.needs_two_mass()
                && base.two_mass.is_none()
                && base.motor_friction().is_some()
            {
                continue;
            }
            let t0 = profile_seconds();
            let fc = fit_placed(c, td, std::slice::from_ref(&base), None, sim_poles, &hints);
            if std::env::var_os("GAP_PROFILE").is_some() {
                eprintln!("profile: pair + {c} {:.3} s (cpu)", profile_seconds() - t0);
            }
            if let Some(f) = fc {
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

/// Orders stiction against Coulomb friction at the place of the better-ranked one (nested:
/// stiction with breakaway = level is Coulomb friction). Stiction ranks first when its
/// validation NRMSE is within the nested margin of Coulomb's and either dwell evidence shows a
/// held input at least 1.2 times its sliding level with a fitted breakaway at least 1.3 times
/// that level, or the training likelihood ratio over Coulomb friction exceeds
/// [`NESTED_LR_THRESHOLD`] (see [`nested_likelihood_ratio`]); or, without either, when it
/// lowers the validation NRMSE by the nested margin.
fn resolve_nested(
    singles: &mut [Scored],
    td: &TrainData,
    dwell: Option<&DwellEvidence>,
    nested_margin: f64,
    notes: &mut Vec<String>,
) {
    let first_friction = singles
        .iter()
        .find_map(|x| x.effects.first().filter(|p| p.effect.kind().is_friction()))
        .map(|p| p.place);
    let Some(place) = first_friction else { return };
    let pos = |k: EffectKind, s: &[Scored]| {
        s.iter().position(|x| {
            x.effects
                .first()
                .is_some_and(|p| p.effect.kind() == k && p.place == place)
        })
    };
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
    let lr = nested_likelihood_ratio(
        &singles[ic].model,
        &singles[is].model,
        &td.u,
        &td.base.y,
        td.base.warmup,
    )
    .unwrap_or(0.0);
    let dwell_says = dwell.is_some_and(|d| d.breakaway >= 1.2 * ratio.1) && ratio.0 >= 1.3;
    let evidence = dwell_says || (lr > NESTED_LR_THRESHOLD && ratio.0 >= 1.3);
    let stiction_wins =
        (evidence && gs <= gc * (1.0 + nested_margin)) || gs < gc * (1.0 - nested_margin);
    notes.push(format!(
        "stiction vs coulomb_friction at {place}: validation NRMSE {gs:.4} vs {gc:.4}, fitted \
         breakaway ratio {:.2}, training likelihood ratio {lr:.1}, dwell breakaway {}",
        ratio.0,
        dwell.map_or("none".to_string(), |d| format!(
            "{:.4} ({} dwells)",
            d.breakaway, d.dwells
        ))
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
            let l = lattice_evidence(std::slice::from_ref(&y)).expect("lattice");
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

/// End-to-end checks of the selection on simulated axes (same-law simulator
/// [`crate::gap::plant`], with the drivetrain play integrated by a different scheme).
#[cfg(test)]
mod cases {
    use super::*;
    use crate::gap::benchmark::{filtered_noise, multisine};
    use crate::gap::effect::{quantize, saturation};
    use crate::gap::modal::FitSet;
    use crate::gap::plant::{simulate, Plant, SimSettings};
    use crate::gap::rng::Rng;
    use crate::lti::StateSpace;

    pub(super) const TS: f64 = 1e-3;

    pub(super) struct Case {
        pub td: TrainData,
        pub starts: Vec<ModalModel>,
        pub poles: Vec<Complex64>,
        pub structure: Option<TwoMassStructure>,
        pub vu: Vec<f64>,
        pub vy: Vec<f64>,
        pub warmup: usize,
    }

    /// Logs of `truth` (input → measured output) with the nominal `plant` perturbed by ±15 %:
    /// filtered noise at RMS `a` and 3`a` for training, a multisine at 2`a` for validation.
    pub(super) fn make_case(
        plant: Plant,
        a: f64,
        f_c: f64,
        n: usize,
        seed: u64,
        truth: &dyn Fn(&[f64], u64) -> Vec<f64>,
    ) -> Case {
        let mut rng = Rng::new(seed);
        let nominal: StateSpace = plant
            .perturbed(0.15, &mut rng)
            .physical()
            .unwrap()
            .sys
            .c2d_zoh(TS)
            .unwrap();
        let u_lo = filtered_noise(n, TS, f_c, a, &mut rng);
        let u_hi = filtered_noise(n, TS, f_c, 3.0 * a, &mut rng);
        let vu = multisine(n, TS, 0.2, f_c, 2.0 * a, &mut rng);
        let y_lo = truth(&u_lo, 1);
        let y_hi = truth(&u_hi, 2);
        let vy = truth(&vu, 3);
        let poles = nominal.poles().unwrap();
        let slowest = poles
            .iter()
            .map(|p| p.norm())
            .filter(|&r| r < 1.0 - 1e-9)
            .fold(0.0f64, f64::max);
        let tau = if slowest > 0.0 {
            -1.0 / slowest.ln()
        } else {
            0.0
        };
        let warmup = ((5.0 * tau).ceil() as usize).min(n / 10).max(
            if poles.iter().any(|p| (p - 1.0).norm() < 1e-9) {
                n / 10
            } else {
                0
            },
        );
        let td = TrainData::new(
            TS,
            vec![u_lo.clone(), u_hi.clone()],
            vec![y_lo, y_hi],
            warmup,
        )
        .unwrap();
        let mut lin = ModalModel::from_poles(TS, &poles, false).unwrap();
        lin.fit_output_error(&td.base, 60).unwrap();
        let mut nom = ModalModel::from_poles(TS, &poles, false).unwrap();
        let y_sim: Vec<Vec<f64>> =
            td.u.iter()
                .map(|u| nominal.simulate_siso(u, None).unwrap())
                .collect();
        nom.fit_linear_params(&FitSet::new(td.u.clone(), y_sim, warmup).unwrap())
            .unwrap();
        nom.offset = lin.offset;
        Case {
            structure: TwoMassStructure::detect(&nominal),
            td,
            starts: vec![lin, nom],
            poles,
            vu,
            vy,
            warmup,
        }
    }

    pub(super) fn settings(noise_std: f64, seed: u64) -> SimSettings {
        SimSettings {
            ts: TS,
            substeps: 8,
            noise_std,
            seed,
        }
    }

    /// Output RMS of `plant` for filtered noise at RMS `a` (noise scale of the cases).
    pub(super) fn y_rms(plant: &Plant, a: f64, f_c: f64) -> f64 {
        let mut rng = Rng::new(99);
        let u = filtered_noise(8192, TS, f_c, a, &mut rng);
        let y = simulate(plant, None, &u, &settings(0.0, 0)).unwrap();
        (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt()
    }

    pub(super) fn run(c: &Case) -> Selection {
        select_effects(
            &c.td,
            &c.starts,
            &c.poles,
            c.structure.as_ref(),
            &c.vu,
            &c.vy,
            c.warmup,
            &SelectOptions::default(),
        )
        .unwrap()
    }

    pub(super) fn describe(s: &Selection) -> String {
        let sel: Vec<String> = s
            .selected
            .iter()
            .map(|e| {
                format!(
                    "{}@{} share {:.2} gap {:.4}",
                    e.effect, e.place, e.share, e.gap_after
                )
            })
            .collect();
        let singles: Vec<String> = s
            .singles
            .iter()
            .take(if std::env::var_os("GAP_ALL").is_some() {
                99
            } else {
                4
            })
            .map(|x| {
                format!(
                    "{} {:.4}",
                    x.effects.first().map_or("-".into(), |p| p.to_string()),
                    x.gap
                )
            })
            .collect();
        format!(
            "gap_linear {:.4}; selected [{}]; top singles [{}]; notes {:?}",
            s.gap_linear,
            sel.join("; "),
            singles.join("; "),
            s.notes
        )
    }

    /// CPU seconds of this thread (user + system), from /proc; 0 where unavailable.
    pub(super) fn cpu_seconds() -> f64 {
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

    // The checked cases, shared by the checks below and the study (`n` samples per log).

    /// Integrating axis with Coulomb friction 1.0 (seed 21).
    pub(super) fn axis_friction_case(n: usize) -> Case {
        let ax = Plant::axis();
        let ns = 0.01 * y_rms(&ax, 2.0, 20.0);
        let e = Effect::CoulombFriction { level: 1.0 };
        make_case(ax, 2.0, 20.0, n, 21, &|u, k| {
            simulate(&ax, Some(&e), u, &settings(ns, k)).unwrap()
        })
    }

    /// Quantization after noise at 5 % of the RMS, flexure position in metres (tiny scale);
    /// returns the case and the true step.
    pub(super) fn small_quantization_case(n: usize) -> (Case, f64) {
        let fx = Plant::flexure();
        let rms = y_rms(&fx, 1.0, 60.0) * 1e-6;
        let step = 0.05 * rms;
        let c = make_case(fx, 1.0, 60.0, n, 22, &|u, k| {
            simulate(&fx, None, u, &settings(0.01 * rms * 1e6, k))
                .unwrap()
                .into_iter()
                .map(|v| quantize(v * 1e-6, step))
                .collect()
        });
        (c, step)
    }

    /// DC motor with a sensor clipping at 60 % of a probe run's peak; returns the case and
    /// the clip level.
    pub(super) fn sensor_clip_case(n: usize) -> (Case, f64) {
        let dc = Plant::dc_motor();
        let mut rng = Rng::new(5);
        let probe = filtered_noise(n, TS, 100.0, 3.0, &mut rng);
        let pk = simulate(&dc, None, &probe, &settings(0.0, 0))
            .unwrap()
            .iter()
            .fold(0.0f64, |a, v| a.max(v.abs()));
        let lim = 0.6 * pk;
        let ns = 0.01 * y_rms(&dc, 1.0, 100.0);
        let c = make_case(dc, 1.0, 100.0, n, 23, &|u, k| {
            simulate(&dc, None, u, &settings(ns, k))
                .unwrap()
                .into_iter()
                .map(|v| saturation(v, lim))
                .collect()
        });
        (c, lim)
    }

    /// Lightly damped mode at 160 Hz (ζ = 0.02) in series, DC motor excited to 200 Hz.
    pub(super) fn resonance_160_case(n: usize) -> Case {
        let dc = Plant::dc_motor();
        let e = Effect::Resonance {
            freq_hz: 160.0,
            damping: 0.02,
        };
        let ns = 0.01 * y_rms(&dc, 1.0, 200.0);
        make_case(dc, 1.0, 200.0, n, 24, &|u, k| {
            simulate(&dc, Some(&e), u, &settings(ns, k)).unwrap()
        })
    }

    /// Pair: input saturation at 1.5 and Coulomb friction 0.3, DC motor.
    pub(super) fn saturation_friction_case(n: usize) -> Case {
        let dc = Plant::dc_motor();
        let e = Effect::CoulombFriction { level: 0.3 };
        let ns = 0.01 * y_rms(&dc, 1.0, 100.0);
        make_case(dc, 1.0, 100.0, n, 25, &|u, k| {
            let us: Vec<f64> = u.iter().map(|&v| saturation(v, 1.5)).collect();
            simulate(&dc, Some(&e), &us, &settings(ns, k)).unwrap()
        })
    }

    /// Karnopp stiction 0.2 / breakaway 0.4 on the DC motor.
    pub(super) fn stiction_case(n: usize) -> Case {
        let dc = Plant::dc_motor();
        let ns = 0.01 * y_rms(&dc, 1.0, 100.0);
        let e = Effect::Stiction {
            level: 0.2,
            breakaway: 0.4,
        };
        make_case(dc, 1.0, 100.0, n, 26, &|u, k| {
            simulate(&dc, Some(&e), u, &settings(ns, k)).unwrap()
        })
    }

    fn more_cases() {
        let n = 16384;
        let show = |name: &str, c: &Case| {
            let t0 = cpu_seconds();
            let s = run(c);
            eprintln!("{name} ({:.2} s): {}", cpu_seconds() - t0, describe(&s));
        };
        show("axis coulomb 1.0", &axis_friction_case(n));
        let (c, step) = small_quantization_case(n);
        eprintln!("(true step {step:.3e})");
        show("flexure quantization 5 %", &c);
        let (c, lim) = sensor_clip_case(n);
        eprintln!("(true clip {lim:.4})");
        show("dc sensor clip", &c);
        show("dc resonance 160 Hz", &resonance_160_case(n));
        show(
            "dc saturation 1.5 + coulomb 0.3",
            &saturation_friction_case(n),
        );
        show("dc stiction 0.2/0.4", &stiction_case(n));
    }

    /// Study (not a check): prints the selection on a range of cases.
    #[test]
    #[ignore]
    fn study() {
        use crate::gap::effect::Effect;
        use crate::gap::plant::simulate_drivetrain_backlash;
        let n = 16384;
        let tm = Plant::two_mass();
        let crate::gap::plant::Plant::TwoMass(tmp) = tm else {
            unreachable!()
        };
        let ns = 0.01 * y_rms(&tm, 0.05, 120.0);
        for gap in [0.003, 0.008] {
            let c = make_case(tm, 0.05, 120.0, n, 11, &|u, k| {
                simulate_drivetrain_backlash(&tmp, gap, u, &settings(ns, k)).unwrap()
            });
            eprintln!(
                "structure {:?}",
                c.structure.as_ref().map(|s| s.mapping_nrmse)
            );
            let t0 = cpu_seconds();
            let s = run(&c);
            eprintln!(
                "drivetrain backlash {gap} rad ({:.2} s): {}",
                cpu_seconds() - t0,
                describe(&s)
            );
        }
        if std::env::var_os("GAP_ONLY_DT").is_some() {
            return;
        }
        if std::env::var_os("GAP_MORE").is_some() {
            more_cases();
            return;
        }
        for (name, e) in [
            (
                "stiction 1.8x",
                Effect::Stiction {
                    level: 0.01,
                    breakaway: 0.018,
                },
            ),
            ("coulomb", Effect::CoulombFriction { level: 0.015 }),
        ] {
            let c = make_case(tm, 0.05, 120.0, n, 12, &|u, k| {
                simulate(&tm, Some(&e), u, &settings(ns, k)).unwrap()
            });
            let t0 = cpu_seconds();
            let s = run(&c);
            eprintln!("{name} ({:.2} s): {}", cpu_seconds() - t0, describe(&s));
        }
    }
}

/// Checks of the selection on simulated axes, one per failure shape of issue 9.
#[cfg(test)]
mod checks {
    use super::cases::{
        make_case, resonance_160_case, run, saturation_friction_case, sensor_clip_case, settings,
        small_quantization_case, stiction_case, y_rms, Case,
    };
    use super::*;
    use crate::gap::plant::{simulate, simulate_drivetrain_backlash, Plant};

    const N: usize = 16384;

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    fn only(s: &Selection) -> (Effect, Place) {
        assert_eq!(s.selected.len(), 1, "{:?}", s.selected);
        (s.selected[0].effect, s.selected[0].place)
    }

    /// Backlash in the shaft of a two-mass axis (integrated by a different scheme than the
    /// candidate): the structure is found in the nominal and the verdict is backlash in the
    /// drivetrain with the play within 10 %.
    #[test]
    fn drivetrain_backlash_is_found_in_the_two_mass_structure() {
        let tm = Plant::two_mass();
        let Plant::TwoMass(p) = tm else {
            unreachable!()
        };
        let ns = 0.01 * y_rms(&tm, 0.05, 120.0);
        let c = make_case(tm, 0.05, 120.0, N, 11, &|u, k| {
            simulate_drivetrain_backlash(&p, 0.003, u, &settings(ns, k)).unwrap()
        });
        assert!(c.structure.is_some());
        let s = run(&c);
        let (e, place) = only(&s);
        assert_eq!(place, Place::Drivetrain);
        let Effect::Backlash { gap } = e else {
            panic!("{e}")
        };
        assert!(rel(gap, 0.003) < 0.1, "gap {gap}");
        assert!(s.selected[0].gap_after < 0.3 * s.gap_linear);
    }

    /// Quantization after noise at 5 % of the output RMS on a position output in metres
    /// (steps of about 4e-5): decided by the lattice although it cannot pass the 10 % margin.
    #[test]
    fn quantization_is_decided_by_the_lattice_at_small_scale() {
        let (c, step) = small_quantization_case(N);
        let s = run(&c);
        let (e, place) = only(&s);
        assert_eq!(place, Place::Sensor);
        let Effect::Quantization { step: got } = e else {
            panic!("{e}")
        };
        assert!(rel(got, step) < 1e-3, "{got} vs {step}");
        assert!(s.lattice.is_some());
    }

    /// Karnopp stiction, breakaway 2× the Coulomb level, on the DC motor: stiction with both
    /// levels within 10 %.
    #[test]
    fn stiction_with_a_stick_band_is_told_from_coulomb_friction() {
        let s = run(&stiction_case(N));
        let (e, place) = only(&s);
        assert_eq!(place, Place::Motor);
        let Effect::Stiction { level, breakaway } = e else {
            panic!("{e}")
        };
        assert!(rel(level, 0.2) < 0.1 && rel(breakaway, 0.4) < 0.1, "{e}");
        assert!(s.dwell.is_some());
    }

    /// A lightly damped mode at 160 Hz in series with the input: found at its frequency.
    #[test]
    fn lightly_damped_mode_above_130_hz_is_found() {
        let s = run(&resonance_160_case(N));
        let (e, _) = only(&s);
        let Effect::Resonance { freq_hz, damping } = e else {
            panic!("{e}")
        };
        assert!(
            rel(freq_hz, 160.0) < 0.01 && rel(damping, 0.02) < 0.15,
            "{e}"
        );
    }

    /// A sensor that clips: saturation at the sensor with the clip level.
    #[test]
    fn sensor_clipping_is_saturation_at_the_sensor() {
        let (c, lim) = sensor_clip_case(N);
        let s = run(&c);
        let (e, place) = only(&s);
        assert_eq!(place, Place::Sensor);
        let Effect::Saturation { limit } = e else {
            panic!("{e}")
        };
        assert!(rel(limit, lim) < 0.01, "{limit} vs {lim}");
    }

    /// Input saturation and Coulomb friction together: both selected, with shares summing
    /// to 1.
    #[test]
    fn saturation_and_friction_are_selected_as_a_pair() {
        let s = run(&saturation_friction_case(N));
        let kinds: Vec<(EffectKind, Place)> = s
            .selected
            .iter()
            .map(|x| (x.effect.kind(), x.place))
            .collect();
        assert!(
            kinds.contains(&(EffectKind::Saturation, Place::Drive)),
            "{kinds:?}"
        );
        assert!(
            kinds
                .iter()
                .any(|(k, p)| k.is_friction() && *p == Place::Motor),
            "{kinds:?}"
        );
        let total: f64 = s.selected.iter().map(|x| x.share).sum();
        assert!((total - 1.0).abs() < 1e-12);
        assert!(s.selected.iter().all(|x| x.share > 0.0));
    }

    fn axis_case(seed: u64, u_scale: f64, y_scale: f64) -> Case {
        let ax = Plant::axis();
        let ns = 0.01 * y_rms(&ax, 2.0, 20.0);
        let e = Effect::CoulombFriction { level: 1.0 };
        make_case(ax, 2.0, 20.0, N, seed, &|u, k| {
            let ui: Vec<f64> = u.iter().map(|v| v / u_scale).collect();
            simulate(&ax, Some(&e), &ui, &settings(ns, k))
                .unwrap()
                .into_iter()
                .map(|v| v * y_scale)
                .collect()
        })
    }

    /// Integrating plant (position output, pole at z = 1): friction acts on the derivative of
    /// the position and is fitted within 2 %.
    #[test]
    fn friction_on_an_integrating_axis() {
        let c = axis_case(21, 1.0, 1.0);
        assert!(c.starts[0].real.contains(&1.0));
        let s = run(&c);
        let (e, place) = only(&s);
        assert_eq!(place, Place::Motor);
        let level = match e {
            Effect::CoulombFriction { level } => level,
            Effect::Stiction { level, .. } => level,
            _ => panic!("{e}"),
        };
        assert!(rel(level, 1.0) < 0.02, "{e}");
        assert_eq!(s.model.velocity, VelocitySource::OutputDerivative);
    }

    /// No candidate ends worse on the training logs than the linear part it extends.
    #[test]
    fn candidates_never_score_worse_than_the_linear_model() {
        let c = axis_case(21, 1.0, 1.0);
        let s = run(&c);
        let lin = AugmentedModel::linear(c.starts[0].clone()).cost(&c.td.base, &c.td.u);
        for x in &s.singles {
            assert!(
                x.train_cost <= lin * (1.0 + 1e-9),
                "{:?}: {} > {lin}",
                x.effects,
                x.train_cost
            );
        }
    }
}

/// Invariance and conditioning of the fits (issue 9: results moved with the input units and
/// with 3e-9 relative differences between file formats).
#[cfg(test)]
mod conditioning {
    use super::cases::{make_case, run, settings, y_rms, Case};
    use super::*;
    use crate::gap::plant::{simulate, Plant};
    use crate::gap::rng::Rng;

    fn axis_case() -> Case {
        let ax = Plant::axis();
        let ns = 0.01 * y_rms(&ax, 2.0, 20.0);
        let e = Effect::CoulombFriction { level: 1.0 };
        make_case(ax, 2.0, 20.0, 16384, 31, &|u, k| {
            simulate(&ax, Some(&e), u, &settings(ns, k)).unwrap()
        })
    }

    /// The same case with every input sample mapped by `fu` and every output sample by `fy`
    /// (the linear starts scaled to match: residues and feedthrough by the output/input
    /// ratio `gain`, the offset by `fy`).
    fn mapped(c: &Case, fu: &dyn Fn(f64) -> f64, fy: &dyn Fn(f64) -> f64, gain: f64) -> Case {
        let u: Vec<Vec<f64>> =
            c.td.u
                .iter()
                .map(|l| l.iter().map(|&v| fu(v)).collect())
                .collect();
        let y: Vec<Vec<f64>> =
            c.td.base
                .y
                .iter()
                .map(|l| l.iter().map(|&v| fy(v)).collect())
                .collect();
        let starts = c
            .starts
            .iter()
            .map(|s| {
                let mut s = s.clone();
                s.residues.iter_mut().for_each(|r| *r *= gain);
                s.d *= gain;
                s.offset = fy(s.offset);
                s
            })
            .collect();
        Case {
            td: TrainData::new(c.td.ts, u, y, c.td.base.warmup).unwrap(),
            starts,
            poles: c.poles.clone(),
            structure: c.structure.clone(),
            vu: c.vu.iter().map(|&v| fu(v)).collect(),
            vy: c.vy.iter().map(|&v| fy(v)).collect(),
            warmup: c.warmup,
        }
    }

    fn params(s: &Selection) -> Vec<(String, f64)> {
        s.selected
            .iter()
            .flat_map(|x| {
                x.effect
                    .params()
                    .into_iter()
                    .map(move |(n, v)| (format!("{}.{n}", x.effect.kind()), v))
            })
            .collect()
    }

    /// Rescaling the input (V → N, ×7.3) and the output (mm → m, ×1e-3) maps the fitted
    /// friction level by the input factor and changes nothing else (1e-6 relative).
    #[test]
    fn friction_fit_is_invariant_to_input_and_output_units() {
        let c = axis_case();
        let a = run(&c);
        let (ku, ky) = (7.3, 1e-3);
        let b = run(&mapped(&c, &|v| v * ku, &|v| v * ky, ky / ku));
        let (pa, pb) = (params(&a), params(&b));
        assert_eq!(pa.len(), pb.len(), "{pa:?} vs {pb:?}");
        assert!(!pa.is_empty());
        for ((n, va), (_, vb)) in pa.iter().zip(&pb) {
            let want = va * ku; // friction levels are in input units
            assert!(
                (vb - want).abs() <= 1e-6 * want.abs(),
                "{n}: {vb} vs {want}"
            );
        }
        assert!((a.selected[0].gap_after - b.selected[0].gap_after).abs() < 1e-6);
    }

    /// Perturbing every sample by 1e-9 relative (a 9-digit CSV against a .mat file) moves
    /// every fitted parameter by at most 1e-6 relative.
    #[test]
    fn fits_are_well_conditioned() {
        let c = axis_case();
        let a = run(&c);
        let mut rng = Rng::new(77);
        let jitter: Vec<f64> = (0..4 * 16384)
            .map(|_| 1e-9 * (2.0 * rng.uniform() - 1.0))
            .collect();
        let k = std::cell::Cell::new(0usize);
        let bump = |v: f64| {
            let i = k.get();
            k.set(i + 1);
            v * (1.0 + jitter[i % jitter.len()])
        };
        let b = run(&mapped(&c, &bump, &bump, 1.0));
        let (pa, pb) = (params(&a), params(&b));
        assert_eq!(pa.len(), pb.len(), "{pa:?} vs {pb:?}");
        for ((n, va), (_, vb)) in pa.iter().zip(&pb) {
            assert!((vb - va).abs() <= 1e-6 * va.abs(), "{n}: {vb} vs {va}");
        }
    }
}
