//! Compensation design from a gap diagnosis ([`crate::gap::GapReport`]).
//!
//! | diagnosed effect @ place | compensation part | parameters |
//! |---|---|---|
//! | `coulomb_friction` / `stiction` @ `motor` | friction feedforward | coulomb = fitted (sliding) `level`; viscous = 0 (viscous friction is in the linear model); smoothing_velocity = [`DesignOptions::velocity_resolution`]; velocity = [`DesignOptions::velocity`]; lag-aware form = [`DesignOptions::lag_aware`] |
//! | `deadzone` @ `drive` | dead-zone inverse | width = fitted `width`; smoothing = [`DesignOptions::inverse_smoothing_rel`] × width |
//! | `backlash` @ `drive` | backlash inverse | gap = fitted `gap`; smoothing = `inverse_smoothing_rel` × gap |
//! | `saturation` @ `drive` | anti-windup | u_min, u_max = ∓ fitted `limit`; tracking time = [`DesignOptions::tracking_time_s`] |
//! | anything else (quantization, sensor clipping, drivetrain backlash, load friction, delay, resonance, slew rate) | none: the place does not allow undoing it from the command | — |
//!
//! The smoothing bands trade chatter against residual: a limit cycle that survives the
//! compensation has an amplitude of the order of the band (host/tests/compensation_design.rs),
//! so the velocity band is the velocity the sensor can resolve and the inverse bands a small
//! fraction (default 1 %) of the width or play.
//!
//! The result is disabled (`enabled = false`, no parts) when the verdict is `none` or
//! `unexplained`, or when no diagnosed effect has a compensation. Errors (the crate's error
//! enum, naming what is wrong): an empty verdict, a verdict naming effects without
//! `verdict_effects`, an unknown effect or place name, a missing or non-finite parameter, a
//! parameter out of range, or bad options.
use crate::error::{Error, Result};
use crate::gap::effect::{Effect, EffectKind};
use crate::gap::place::{Place, PlacedEffect};
use crate::gap::report::VerdictEffect;
use crate::gap::GapReport;
use ferrosid_codegen::{
    AntiWindup, BacklashInverse, Compensation, CompensationProvenance, DeadZoneInverse,
    FrictionFeedforward, LagAwareFriction, VelocitySource,
};
use std::collections::BTreeMap;

/// Choices the diagnosis cannot make (units in the field docs).
#[derive(Debug, Clone, PartialEq)]
pub struct DesignOptions {
    /// Provenance text, e.g. `ferrosid gap on a.csv,b.csv`.
    pub source: String,
    /// How the firmware estimates the velocity for the friction feedforward.
    pub velocity: VelocitySource,
    /// Smoothing band of the friction feedforward, velocity units (> 0): the velocity the
    /// sensor resolves (e.g. its noise standard deviation for a velocity output).
    pub velocity_resolution: f64,
    /// Smoothing of the dead-zone and backlash inverses as a fraction of the width or play
    /// (in (0, 1], default 0.01).
    pub inverse_smoothing_rel: f64,
    /// Back-calculation tracking time for saturation, s (> 0).
    pub tracking_time_s: f64,
    /// The friction feedforward's lag-aware form, when the friction sits on a body that the
    /// command reaches through a first-order actuator lag (the lag from the model; see
    /// `ferrosid_codegen::LagAwareFriction`); `None` (default): the plain feedforward.
    pub lag_aware: Option<LagAwareFriction>,
}

impl DesignOptions {
    /// Defaults: velocity from the output, the given velocity resolution, 1 % inverse
    /// smoothing, the given tracking time.
    pub fn new(source: &str, velocity_resolution: f64, tracking_time_s: f64) -> Self {
        Self {
            source: source.into(),
            velocity: VelocitySource::Output,
            velocity_resolution,
            inverse_smoothing_rel: 0.01,
            tracking_time_s,
            lag_aware: None,
        }
    }

    fn validate(&self) -> Result<()> {
        let bad = |what: String| {
            Err(Error::InvalidArgument(format!(
                "compensation design: {what}"
            )))
        };
        if !(self.velocity_resolution.is_finite() && self.velocity_resolution > 0.0) {
            return bad(format!(
                "velocity_resolution = {} must be finite and > 0",
                self.velocity_resolution
            ));
        }
        if !(self.inverse_smoothing_rel.is_finite()
            && self.inverse_smoothing_rel > 0.0
            && self.inverse_smoothing_rel <= 1.0)
        {
            return bad(format!(
                "inverse_smoothing_rel = {} must be in (0, 1]",
                self.inverse_smoothing_rel
            ));
        }
        if !(self.tracking_time_s.is_finite() && self.tracking_time_s > 0.0) {
            return bad(format!(
                "tracking_time_s = {} must be finite and > 0",
                self.tracking_time_s
            ));
        }
        Ok(())
    }
}

fn param(effect: &str, params: &BTreeMap<String, f64>, name: &str) -> Result<f64> {
    match params.get(name) {
        Some(v) if v.is_finite() => Ok(*v),
        Some(v) => Err(Error::InvalidArgument(format!(
            "gap verdict effect {effect}: parameter {name} = {v} is not finite"
        ))),
        None => Err(Error::InvalidArgument(format!(
            "gap verdict effect {effect}: parameter {name} is missing"
        ))),
    }
}

/// The verdict's effects with their places, parsed and validated. Empty for `none` and
/// `unexplained`; errors as in the module docs.
pub fn verdict_effects(report: &GapReport) -> Result<Vec<PlacedEffect>> {
    parse_verdict(&report.verdict, &report.verdict_effects)
}

/// [`verdict_effects`] from the verdict text and its effects (`GapReport::verdict`,
/// `GapReport::verdict_effects`).
pub fn parse_verdict(
    verdict: &str,
    verdict_effects: &[VerdictEffect],
) -> Result<Vec<PlacedEffect>> {
    let verdict = verdict.trim();
    if verdict.is_empty() {
        return Err(Error::InvalidArgument(
            "gap report: the verdict is empty (expected none, unexplained or effect names)".into(),
        ));
    }
    if verdict == "none" || verdict == "unexplained" {
        return Ok(Vec::new());
    }
    if verdict_effects.is_empty() {
        return Err(Error::InvalidArgument(format!(
            "gap report: verdict {verdict:?} names effects but verdict_effects is empty"
        )));
    }
    let mut out = Vec::new();
    for ve in verdict_effects {
        let name = ve.effect.as_str();
        let kind = EffectKind::from_name(name).ok_or_else(|| {
            Error::InvalidArgument(format!("gap verdict effect: unknown effect {name:?}"))
        })?;
        let place = Place::from_name(&ve.place).ok_or_else(|| {
            Error::InvalidArgument(format!(
                "gap verdict effect {name}: unknown place {:?}",
                ve.place
            ))
        })?;
        let p = |n: &str| param(name, &ve.params, n);
        let effect = match kind {
            EffectKind::CoulombFriction => Effect::CoulombFriction { level: p("level")? },
            EffectKind::Stiction => Effect::Stiction {
                level: p("level")?,
                breakaway: p("breakaway")?,
                // Optional: written only for a Stribeck curve (0: a Karnopp switch).
                stribeck_velocity: match ve.params.get("stribeck_velocity") {
                    Some(_) => p("stribeck_velocity")?,
                    None => 0.0,
                },
            },
            EffectKind::Backlash => Effect::Backlash { gap: p("gap")? },
            EffectKind::Deadzone => Effect::Deadzone { width: p("width")? },
            EffectKind::Saturation => Effect::Saturation { limit: p("limit")? },
            EffectKind::TimeDelay => Effect::TimeDelay {
                seconds: p("seconds")?,
            },
            EffectKind::Resonance => Effect::Resonance {
                freq_hz: p("freq_hz")?,
                damping: p("damping")?,
            },
            EffectKind::Quantization => Effect::Quantization { step: p("step")? },
            EffectKind::SlewRate => Effect::SlewRate { rate: p("rate")? },
            EffectKind::StateLimit => Effect::StateLimit { limit: p("limit")? },
            EffectKind::CurrentLimit => Effect::CurrentLimit { limit: p("limit")? },
        };
        effect.validate()?;
        out.push(PlacedEffect { effect, place });
    }
    Ok(out)
}

/// The compensation for the diagnosis `report` (module docs).
pub fn design(report: &GapReport, opts: &DesignOptions) -> Result<Compensation> {
    design_from(
        &report.verdict,
        &report.verdict_effects,
        report.gap_linear,
        report.gap_after,
        opts,
    )
}

/// [`design`] from the parts of a gap report: the verdict, its effects, and the validation
/// NRMSE of the linear model (`gap_linear`) and of the verdict model (`gap_after`), recorded in
/// the provenance when finite.
pub fn design_from(
    verdict: &str,
    verdict_effects: &[VerdictEffect],
    gap_linear: f64,
    gap_after: f64,
    opts: &DesignOptions,
) -> Result<Compensation> {
    opts.validate()?;
    let effects = parse_verdict(verdict, verdict_effects)?;
    let finite = |v: f64| v.is_finite().then_some(v);
    let mut comp = Compensation {
        enabled: false,
        provenance: CompensationProvenance {
            effect: effects
                .iter()
                .map(|e| e.effect.kind().name())
                .collect::<Vec<_>>()
                .join("+"),
            // One place per effect, in the order of `effect` ("motor+drive").
            place: effects
                .iter()
                .map(|e| e.place.name())
                .collect::<Vec<_>>()
                .join("+"),
            verdict: verdict.trim().to_string(),
            source: opts.source.clone(),
            nrmse_before: finite(gap_linear),
            nrmse_after: finite(gap_after),
        },
        friction_feedforward: None,
        dead_zone_inverse: None,
        backlash_inverse: None,
        anti_windup: None,
    };
    for pe in &effects {
        match (pe.effect, pe.place) {
            (Effect::CoulombFriction { level }, Place::Motor)
            | (Effect::Stiction { level, .. }, Place::Motor) => {
                comp.friction_feedforward = Some(FrictionFeedforward {
                    coulomb: level,
                    viscous: 0.0,
                    smoothing_velocity: opts.velocity_resolution,
                    velocity: opts.velocity,
                    lag_aware: opts.lag_aware,
                });
            }
            (Effect::Deadzone { width }, Place::Drive) => {
                comp.dead_zone_inverse = Some(DeadZoneInverse {
                    width,
                    smoothing: opts.inverse_smoothing_rel * width,
                });
            }
            (Effect::Backlash { gap }, Place::Drive) => {
                comp.backlash_inverse = Some(BacklashInverse {
                    gap,
                    smoothing: opts.inverse_smoothing_rel * gap,
                });
            }
            (Effect::Saturation { limit }, Place::Drive) => {
                comp.anti_windup = Some(AntiWindup {
                    u_min: -limit,
                    u_max: limit,
                    tracking_time_s: opts.tracking_time_s,
                });
            }
            _ => {}
        }
    }
    comp.enabled = comp.friction_feedforward.is_some()
        || comp.dead_zone_inverse.is_some()
        || comp.backlash_inverse.is_some()
        || comp.anti_windup.is_some();
    comp.validate()
        .map_err(|e| Error::InvalidArgument(format!("compensation design: {e}")))?;
    Ok(comp)
}
