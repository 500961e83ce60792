//! Stiction against Coulomb friction at one place (nested models: stiction with breakaway =
//! level is Coulomb friction), decided on the dwell evidence, the training likelihood ratio
//! and the validation NRMSE.
use super::{DwellEvidence, Scored};
use crate::gap::diagnose::{nested_likelihood_ratio, NESTED_LR_THRESHOLD};
use crate::gap::effect::{Effect, EffectKind};
use crate::gap::fit::TrainData;

/// Orders stiction against Coulomb friction at the place of the better-ranked one (nested:
/// stiction with breakaway = level is Coulomb friction). Stiction ranks first when its
/// validation NRMSE is within the nested margin of Coulomb's and either dwell evidence shows a
/// held input at least 1.2 times its sliding level with a fitted breakaway at least 1.3 times
/// that level, or the training likelihood ratio over Coulomb friction exceeds
/// [`NESTED_LR_THRESHOLD`] (see [`nested_likelihood_ratio`]); or, without either, when it
/// lowers the validation NRMSE by the nested margin.
pub(super) fn resolve_nested(
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
