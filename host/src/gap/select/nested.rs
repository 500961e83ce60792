//! Stiction against Coulomb friction at one place (nested models: stiction with breakaway =
//! level is Coulomb friction), decided on the dwell evidence, the training likelihood ratio
//! and the validation NRMSE.
use super::{dwell_evidence, score, DwellEvidence, PairContext, Scored};
use crate::gap::diagnose::{nested_likelihood_ratio, NESTED_LR_THRESHOLD};
use crate::gap::effect::{Effect, EffectKind};
use crate::gap::fit::{
    eval_model, fit_placed, refined, AugmentedModel, Fitted, TrainData, FRICTION_SUBSTEPS,
    JOINT_MAX_ITER,
};
use crate::gap::place::{Candidate, Place, PlacedEffect};

/// Smallest fitted breakaway/level ratio that counts as a stick band: below it stiction is
/// Coulomb friction with a breakaway the data barely move (a fit's wobble around the nested
/// model), and Coulomb friction, the simpler model, ranks first whatever the validation NRMSE.
pub const MIN_STICK_BAND: f64 = 1.3;

/// Dwell evidence counts only when the fitted breakaway reaches this share of the dwells'
/// breakaway estimate (see [`resolve_nested`]).
pub const DWELL_CONSISTENCY: f64 = 0.5;

/// With a decisive training likelihood ratio (above [`NESTED_LR_THRESHOLD`]), stiction ranks
/// first unless its validation NRMSE is worse than Coulomb friction's by more than this
/// (relative): a law with a stick band and a sliding curve the vocabulary lacks (Stribeck,
/// LuGre) extrapolates a little worse either way, and the training evidence is the sharper test.
pub const EVIDENCE_TOLERANCE: f64 = 0.10;

/// Within this factor of the noise floor the validation NRMSE cannot separate stiction from
/// Coulomb friction (see [`resolve_nested`]).
pub const NESTED_FLOOR_FACTOR: f64 = 2.0;

/// Orders stiction against Coulomb friction at the place of the better-ranked one (nested:
/// models that differ only in that effect — singles, or pairs with the same other effect —
/// stiction with breakaway = level is Coulomb friction). Stiction ranks first when its
/// validation NRMSE is within the nested margin of Coulomb's and dwell evidence shows a held
/// input at least 1.2 times its sliding level that the fit reproduces ([`DWELL_CONSISTENCY`]),
/// or within [`EVIDENCE_TOLERANCE`] of it when the training likelihood ratio over Coulomb
/// friction exceeds [`NESTED_LR_THRESHOLD`] (see [`nested_likelihood_ratio`]); or,
/// without either, when it lowers the validation NRMSE by the nested margin. Always only with a
/// fitted breakaway at least [`MIN_STICK_BAND`] times the level. With that evidence, a stiction model whose
/// validation NRMSE is within [`NESTED_FLOOR_FACTOR`] of the noise floor (`noise_floor`, when
/// known) also ranks first: there the validation log cannot separate the two (what is left is
/// noise), and the training evidence decides — provided the training likelihood ratio is
/// positive (a stiction fit that ends no better than Coulomb friction on the training logs is
/// evidence against its stick band).
pub(super) fn resolve_nested(
    singles: &mut [Scored],
    td: &TrainData,
    dwell: Option<&DwellEvidence>,
    nested_margin: f64,
    noise_floor: Option<f64>,
    notes: &mut Vec<String>,
) {
    let first_friction = singles
        .iter()
        .find_map(|x| x.effects.iter().find(|p| p.effect.kind().is_friction()))
        .map(|p| p.place);
    let Some(place) = first_friction else { return };
    let pos = |k: EffectKind, s: &[Scored]| {
        s.iter().position(|x| {
            x.effects
                .iter()
                .any(|p| p.effect.kind() == k && p.place == place)
        })
    };
    let (Some(is), Some(ic)) = (
        pos(EffectKind::Stiction, singles),
        pos(EffectKind::CoulombFriction, singles),
    ) else {
        return;
    };
    let (gs, gc) = (singles[is].gap, singles[ic].gap);
    let stiction = singles[is]
        .effects
        .iter()
        .find(|p| p.effect.kind() == EffectKind::Stiction && p.place == place)
        .map(|p| p.effect);
    let ratio = match stiction {
        Some(Effect::Stiction {
            level, breakaway, ..
        }) => (breakaway / level, level),
        _ => (1.0, f64::NAN),
    };
    let lr = nested_likelihood_ratio(
        &singles[ic].model,
        &singles[is].model,
        &td.u,
        &td.base.y,
        td.base.warmup,
        td.base.drift_window,
    )
    .unwrap_or(0.0);
    let band = ratio.0 >= MIN_STICK_BAND;
    // Dwells count when the fitted model reproduces their breakaway (within a factor
    // 1/DWELL_CONSISTENCY): held inputs far above what any fit holds are fast input content
    // the body filters out, not a stick band.
    let dwell_says = dwell.is_some_and(|d| {
        d.breakaway >= 1.2 * ratio.1 && ratio.0 * ratio.1 >= DWELL_CONSISTENCY * d.breakaway
    }) && band;
    let decisive = lr > NESTED_LR_THRESHOLD && band;
    let evidence = dwell_says || decisive;
    // At the floor the training evidence decides, so it must not speak against stiction: a
    // stiction fit no better on the training logs than Coulomb friction (ratio clamped at 0)
    // does not take the floor's tie.
    let at_floor =
        lr > 0.0 && noise_floor.is_some_and(|fl| fl > 0.0 && gs <= NESTED_FLOOR_FACTOR * fl);
    let tolerance = if decisive {
        EVIDENCE_TOLERANCE
    } else {
        nested_margin
    };
    let stiction_wins = band
        && ((evidence && (gs <= gc * (1.0 + tolerance) || at_floor))
            || gs < gc * (1.0 - nested_margin));
    notes.push(format!(
        "stiction vs coulomb_friction at {place}: validation NRMSE {gs:.4} vs {gc:.4}, fitted \
         breakaway ratio {:.2}, training likelihood ratio {lr:.1}, dwell breakaway {}{}",
        ratio.0,
        dwell.map_or("none".to_string(), |d| format!(
            "{:.4} ({} dwells)",
            d.breakaway, d.dwells
        )),
        if at_floor {
            ", stiction within the nested floor factor of the noise floor"
        } else {
            ""
        }
    ));
    if stiction_wins != (is < ic) {
        singles.swap(is, ic);
    }
}

/// A selected pair with friction at the motor against its nested variant, the other effect
/// kept: Coulomb friction against its stiction variant (fitted from it, the breakaway scanned),
/// stiction against its Coulomb variant (the stiction replaced by Coulomb friction at its level,
/// refined jointly). Decided by [`resolve_nested`], with the dwell evidence read on the pair's
/// drive output when it has a drive-side effect (what the friction feels: a play in front of
/// it holds the input a half gap away from the force that breaks the body loose). Returns the
/// better-ranked of the two.
pub(super) fn pair_nested_variant(
    pair: Scored,
    ctx: &PairContext,
    base: &AugmentedModel,
    dwell: Option<&DwellEvidence>,
    notes: &mut Vec<String>,
) -> Scored {
    let td = ctx.td;
    let Some(fp) = pair
        .effects
        .iter()
        .find(|p| p.place == Place::Motor && p.effect.kind().is_friction())
        .copied()
    else {
        return pair;
    };
    let variant = match fp.effect {
        Effect::CoulombFriction { .. } => {
            let c = Fitted {
                model: pair.model.clone(),
                train_cost: pair.train_cost,
            };
            fit_placed(
                Candidate::new(EffectKind::Stiction, Place::Motor),
                td,
                std::slice::from_ref(base),
                Some(&c),
                ctx.sim_poles,
                ctx.hints,
            )
        }
        Effect::Stiction { level, .. } => coulomb_variant(td, &pair, fp, level),
        _ => None,
    };
    let Some(v) = variant.map(|f| score(f, ctx.val, ctx.gap_linear)) else {
        return pair;
    };
    let other = match fp.effect.kind() {
        EffectKind::Stiction => EffectKind::CoulombFriction,
        _ => EffectKind::Stiction,
    };
    if !v.effects.iter().any(|p| p.effect.kind() == other) {
        return pair;
    }
    let drive_dwell = if pair.effects.iter().any(|p| p.place == Place::Drive) {
        let w: Option<Vec<Vec<f64>>> =
            td.u.iter()
                .map(|u| pair.model.drive_input(u).ok())
                .collect();
        w.and_then(|w| dwell_evidence(&w, &td.base.y, td.ts, ctx.velocity, td.base.warmup))
    } else {
        dwell.cloned()
    };
    let mut two = vec![pair, v];
    two.sort_by(|a, b| a.gap.total_cmp(&b.gap));
    resolve_nested(
        &mut two,
        td,
        drive_dwell.as_ref(),
        ctx.opts.nested_margin,
        ctx.opts.noise_floor,
        notes,
    );
    two.swap_remove(0)
}

/// `pair` with its stiction `fp` replaced by Coulomb friction at `level`, residues re-fitted,
/// then refined jointly (kept when that lowers the training cost).
fn coulomb_variant(td: &TrainData, pair: &Scored, fp: PlacedEffect, level: f64) -> Option<Fitted> {
    let list: Vec<PlacedEffect> = pair
        .model
        .effects_in_selection_order()
        .into_iter()
        .map(|p| {
            if p == fp {
                PlacedEffect {
                    effect: Effect::CoulombFriction { level },
                    place: p.place,
                }
            } else {
                p
            }
        })
        .collect();
    let mut m = pair.model.clone();
    m.set_effects_in_selection_order(&list);
    let f = eval_model(td, m, FRICTION_SUBSTEPS)?;
    Some(refined(td, f, JOINT_MAX_ITER))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::fit::{AugmentedModel, VelocitySource};
    use crate::gap::modal::ModalModel;
    use crate::gap::place::{Place, PlacedEffect};
    use crate::gap::simulator::benchmark::filtered_noise;
    use crate::gap::simulator::rng::Rng;
    use num_complex::Complex64;

    fn scored(model: AugmentedModel, gap: f64) -> Scored {
        Scored {
            effects: model.effects_in_selection_order(),
            model,
            train_cost: 0.0,
            gap,
            improvement: 0.5,
        }
    }

    /// A first-order velocity axis (pole 0.99) with stiction (level 0.2, breakaway 0.4) at its
    /// input, and the same linear part with Coulomb friction at 0.2: the training likelihood
    /// ratio is decisive; validation NRMSEs 0.0062 (stiction) vs 0.0059 (Coulomb), 5 % apart.
    fn nested_pair() -> (Vec<Scored>, TrainData) {
        let mut lin = ModalModel::from_poles(1e-3, &[Complex64::new(0.99, 0.0)], false).unwrap();
        lin.residues = vec![0.01];
        let with = |e: Effect| {
            let mut m = AugmentedModel::linear(lin.clone()).with_added(PlacedEffect {
                effect: e,
                place: Place::Motor,
            });
            m.velocity = VelocitySource::Output;
            m
        };
        let stiction = with(Effect::Stiction {
            level: 0.2,
            breakaway: 0.4,
            stribeck_velocity: 0.0,
        });
        let coulomb = with(Effect::CoulombFriction { level: 0.2 });
        let mut rng = Rng::new(5);
        let u: Vec<Vec<f64>> = (0..2)
            .map(|k| filtered_noise(4000, 1e-3, 20.0, 0.5 * (1 + 2 * k) as f64, &mut rng))
            .collect();
        let y: Vec<Vec<f64>> = u
            .iter()
            .map(|ul| {
                let y = stiction.simulate(ul).unwrap();
                let s = 1e-3 * (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
                y.iter().map(|v| v + s * rng.normal()).collect()
            })
            .collect();
        let td = TrainData::new(1e-3, u, y, 100).unwrap();
        (vec![scored(coulomb, 0.0059), scored(stiction, 0.0062)], td)
    }

    fn first_is_stiction(s: &[Scored]) -> bool {
        s[0].effects[0].effect.kind() == EffectKind::Stiction
    }

    /// With decisive training evidence, stiction 5 % behind Coulomb friction on validation ranks
    /// first (within the evidence tolerance, and within twice the noise floor); 12 % behind it
    /// ranks first only within twice the noise floor, and stays behind without a floor or well
    /// above it.
    #[test]
    fn nested_tie_at_the_noise_floor_goes_to_the_training_evidence() {
        let (singles, td) = nested_pair();
        let mut notes = Vec::new();
        let mut s = singles.clone();
        resolve_nested(&mut s, &td, None, 0.03, Some(0.0043), &mut notes);
        assert!(first_is_stiction(&s), "{notes:?}");
        assert!(notes[0].contains("noise floor"), "{notes:?}");
        let mut s = singles.clone();
        resolve_nested(&mut s, &td, None, 0.03, None, &mut notes);
        assert!(first_is_stiction(&s), "{notes:?}");
        // 12 % behind: beyond the evidence tolerance.
        let mut behind = singles;
        behind[1].gap = 0.0066;
        let mut s = behind.clone();
        resolve_nested(&mut s, &td, None, 0.03, Some(0.0043), &mut notes);
        assert!(first_is_stiction(&s), "{notes:?}");
        let mut s = behind.clone();
        resolve_nested(&mut s, &td, None, 0.03, None, &mut notes);
        assert!(!first_is_stiction(&s), "{notes:?}");
        let mut s = behind;
        resolve_nested(&mut s, &td, None, 0.03, Some(0.001), &mut notes);
        assert!(!first_is_stiction(&s), "{notes:?}");
    }

    /// Dwell evidence at the noise floor does not hand the tie to stiction when the training
    /// logs speak against it: on data made by Coulomb friction the stiction model (breakaway
    /// 2× level) fits the training logs worse (likelihood ratio clamped at 0) and stays behind,
    /// while the same dwell evidence with decisive training evidence (the logs made by
    /// stiction) puts it first.
    #[test]
    fn floor_tie_needs_training_evidence_for_stiction() {
        let (singles, td) = nested_pair();
        let coulomb_y: Vec<Vec<f64>> =
            td.u.iter()
                .map(|u| singles[0].model.simulate(u).unwrap())
                .collect();
        let td_c = TrainData::new(1e-3, td.u.clone(), coulomb_y, 100).unwrap();
        let dwell = DwellEvidence {
            dwells: 20,
            dwell_share: 0.1,
            breakaway: 0.4,
            exit_median: 0.45,
            hold_max: 0.35,
            band: 1e-3,
            velocity: crate::gap::fit::VelocitySource::Output,
        };
        // Stiction 25 % behind on validation, both within twice the floor.
        let mut behind = singles;
        behind[1].gap = 0.0074;
        let mut notes = Vec::new();
        let mut s = behind.clone();
        resolve_nested(&mut s, &td_c, Some(&dwell), 0.03, Some(0.0043), &mut notes);
        assert!(!first_is_stiction(&s), "{notes:?}");
        assert!(notes[0].contains("likelihood ratio 0.0"), "{notes:?}");
        let mut s = behind;
        resolve_nested(&mut s, &td, Some(&dwell), 0.03, Some(0.0043), &mut notes);
        assert!(first_is_stiction(&s), "{notes:?}");
    }

    /// A fitted breakaway below [`MIN_STICK_BAND`] times the level is Coulomb friction, even 5 %
    /// ahead on validation.
    #[test]
    fn stiction_without_a_stick_band_is_coulomb_friction() {
        let (mut singles, td) = nested_pair();
        let mut m = singles[1].model.clone();
        m.effect = Some(Effect::Stiction {
            level: 0.2,
            breakaway: 0.22,
            stribeck_velocity: 0.0,
        });
        singles[1] = scored(m, 0.0056);
        singles.swap(0, 1);
        let mut notes = Vec::new();
        resolve_nested(&mut singles, &td, None, 0.03, None, &mut notes);
        assert!(!first_is_stiction(&singles), "{notes:?}");
    }
}
