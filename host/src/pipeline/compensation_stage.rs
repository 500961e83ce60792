//! The compensation stage: from the gap stage's diagnosis and the tuned loop, the
//! `limit_cycle` receipts without and with the designed compensation, and the choice the
//! seed's flowchart asks for — compensate (an explicit inverse nonlinearity) or widen W_m and
//! accept a lower bandwidth — with its reason.
//!
//! Per verdict effect that has a describing function at its place
//! ([`crate::limit_cycle::Nonlinearity::from_placed`]; others are listed in `not_analysed`
//! with the reason) the stage runs [`crate::limit_cycle::analyse`] on the loop (identified
//! plant G0 + discretised PID) without and with [`crate::compensation::design`]'s result, and
//! makes a [`crate::limit_cycle::receipt`] of each.
//!
//! | diagnosis / outcome | choice | reason |
//! |---|---|---|
//! | `none` | `keep` | nothing to compensate; the loop receipts stand |
//! | `unexplained` | `widen_wm` | no model of the effect to invert: cover the gap with W_m and re-tune |
//! | effects, compensation enabled, every receipt with it passes | `compensate` | |
//! | effects, compensation enabled, a receipt with it fails | `widen_wm` | the compensation does not remove the cycle |
//! | effects, nothing to compensate at their place, a receipt fails | `widen_wm` | |
//! | effects, nothing to compensate, every receipt passes | `keep` | |
//!
//! `run_pipeline` runs it after the gap stage and carries out the choice ([`super::remedy`]).
use crate::compensation::{design_from, parse_verdict, DesignOptions};
use crate::error::{Error, Result};
use crate::gap::fit::VelocitySource;
use crate::gap::report::VerdictEffect;
use crate::gap::GapReport;
use crate::limit_cycle::{
    analyse, receipt, AnalysisOptions, LimitCycleAnalysis, LureLoop, Nonlinearity,
};
use crate::lti::StateSpace;
use crate::robust::pid::DiscretePid;
use crate::robust::receipts::Receipt;
use ferrosid_codegen::Compensation;
use serde::{Deserialize, Serialize};

/// The stage's decision (module table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Choice {
    /// Put the compensation into the generated code.
    Compensate,
    /// Widen the uncertainty weight W_m and re-tune (lower bandwidth).
    WidenWm,
    /// Nothing to do: the receipts stand.
    Keep,
}

/// One analysed effect: its label, the analyses and receipts without and with compensation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EffectCycles {
    /// `effect at place`.
    pub label: String,
    /// Without compensation.
    pub before: LimitCycleAnalysis,
    /// With the compensation (`None` when it is disabled).
    pub after: Option<LimitCycleAnalysis>,
    /// The receipt without compensation.
    pub receipt_before: Receipt,
    /// The receipt with compensation (`None` when it is disabled).
    pub receipt_after: Option<Receipt>,
    /// The loop's linear part and −1/N(A) in the complex plane, for the report's figure.
    #[serde(skip)]
    pub locus: Locus,
}

/// Points of the describing-function picture: L(e^{jωT}) seen from the nonlinearity and the
/// locus −1/N(A) (without compensation).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Locus {
    /// (frequency Hz, Re L, Im L).
    pub linear_part: Vec<(f64, f64, f64)>,
    /// (amplitude, Re −1/N, Im −1/N).
    pub neg_inv_n: Vec<(f64, f64, f64)>,
}

/// [`Locus`] of `nl` in `lp`: L on 400 log-spaced frequencies from 1e-3 × Nyquist to Nyquist,
/// −1/N on 400 log-spaced amplitudes over 1e-2..1e3 × the nonlinearity's scale above its
/// threshold (non-finite points dropped).
pub fn locus(lp: &LureLoop, nl: &Nonlinearity) -> Locus {
    let nyq = lp.nyquist_rad_s();
    let linear_part = crate::pipeline::log_grid(1e-3 * nyq, nyq, 400)
        .into_iter()
        .filter_map(|w| {
            let l = lp.linear_part(nl.site, w).ok()?;
            (l.re.is_finite() && l.im.is_finite()).then_some((
                w / (2.0 * std::f64::consts::PI),
                l.re,
                l.im,
            ))
        })
        .collect();
    let (th, sc) = (nl.df.threshold(), nl.df.scale());
    let neg_inv_n = crate::pipeline::log_grid(1e-2 * sc, 1e3 * sc, 400)
        .into_iter()
        .filter_map(|d| {
            let a = th + d;
            let n = nl.df.eval(a);
            let v = -1.0 / n;
            (n.norm() > 0.0 && v.re.is_finite() && v.im.is_finite()).then_some((a, v.re, v.im))
        })
        .collect();
    Locus {
        linear_part,
        neg_inv_n,
    }
}

/// What the stage found and chose.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CompensationStage {
    /// The designed compensation (disabled for `none`/`unexplained` or nothing to compensate).
    pub compensation: Compensation,
    /// Per analysed effect.
    pub effects: Vec<EffectCycles>,
    /// Effects without a limit-cycle analysis, with the reason.
    pub not_analysed: Vec<String>,
    /// The decision.
    pub choice: Choice,
    /// Why, in words.
    pub reason: String,
}

impl CompensationStage {
    /// The receipts without compensation.
    pub fn receipts_before(&self) -> Vec<Receipt> {
        self.effects
            .iter()
            .map(|e| e.receipt_before.clone())
            .collect()
    }
    /// The receipts with compensation (empty when it is disabled).
    pub fn receipts_after(&self) -> Vec<Receipt> {
        self.effects
            .iter()
            .filter_map(|e| e.receipt_after.clone())
            .collect()
    }
}

/// Settings of the stage.
#[derive(Debug, Clone, PartialEq)]
pub struct CompensationStageOptions {
    /// Compensation design choices.
    pub design: DesignOptions,
    /// Limit-cycle analysis settings (`amplitude_tol`: what the sensor cannot resolve).
    pub analysis: AnalysisOptions,
    /// Whether `compensate` may be chosen (false: the analyses run without compensation only
    /// and the choice is `widen_wm` or `keep`; the designed compensation is still reported).
    pub allow_compensation: bool,
}

/// Runs the stage on a gap report (module docs). `plant` is G0 (discrete at the controller's
/// sample time, or continuous), `pid` the discretised controller.
pub fn run_compensation_stage(
    report: &GapReport,
    plant: &StateSpace,
    pid: &DiscretePid,
    opts: &CompensationStageOptions,
) -> Result<CompensationStage> {
    let velocity = verdict_velocity_from(report);
    compensation_stage_from(
        &report.verdict,
        &report.verdict_effects,
        velocity,
        report.gap_linear,
        report.gap_after,
        plant,
        pid,
        opts,
    )
}

/// The velocity proxy of the verdict's own friction fit (not of another candidate's): the
/// `velocity_from` of [`compensation_stage_from`].
pub fn verdict_velocity_from(report: &GapReport) -> Option<&str> {
    report.verdict_effects.iter().find_map(|v| {
        report
            .effects
            .iter()
            .find(|e| e.effect == v.effect && e.place == v.place)
            .and_then(|e| e.velocity_from.as_deref())
    })
}

/// The analysed loop of `plant` and `pid` with the friction fit's velocity source
/// (`velocity_from` as in [`compensation_stage_from`]), and that source.
pub fn lure_loop(
    plant: &StateSpace,
    pid: &DiscretePid,
    velocity_from: Option<&str>,
) -> Result<(LureLoop, VelocitySource)> {
    let (velocity, on_body) = match velocity_from {
        None | Some("output") => (VelocitySource::Output, false),
        Some("output_derivative") => (VelocitySource::OutputDerivative, false),
        Some("output_slowest_mode") => (VelocitySource::Output, true),
        Some(other) => {
            return Err(Error::InvalidArgument(format!(
                "compensation stage: unknown velocity source {other:?} (output, \
                 output_derivative or output_slowest_mode)"
            )))
        }
    };
    let mut lp = LureLoop::new(plant, pid, velocity)?;
    if on_body {
        lp = lp.with_friction_on_slowest_mode()?;
    }
    Ok((lp, velocity))
}

/// [`run_compensation_stage`] from the parts of a gap report: verdict, its effects, the
/// friction fit's velocity source (`output`, `output_derivative` or `output_slowest_mode` —
/// friction on the slowest real mode, [`crate::limit_cycle::Body`]; `None`: output), and the
/// validation NRMSE of the linear and of the verdict model.
#[allow(clippy::too_many_arguments)]
pub fn compensation_stage_from(
    verdict: &str,
    verdict_effects: &[VerdictEffect],
    velocity_from: Option<&str>,
    gap_linear: f64,
    gap_after: f64,
    plant: &StateSpace,
    pid: &DiscretePid,
    opts: &CompensationStageOptions,
) -> Result<CompensationStage> {
    let (lp, velocity) = lure_loop(plant, pid, velocity_from)?;
    let mut design = opts.design.clone();
    if velocity == VelocitySource::OutputDerivative {
        if let ferrosid_codegen::VelocitySource::Output = design.velocity {
            // A position output: the firmware differentiates it, filtered at a fifth of the
            // Nyquist frequency.
            design.velocity = ferrosid_codegen::VelocitySource::OutputDifference {
                filter_hz: 0.1 / pid.ts,
            };
        }
    }
    let compensation = design_from(verdict, verdict_effects, gap_linear, gap_after, &design)?;
    let placed = parse_verdict(verdict, verdict_effects)?;
    let mut effects = Vec::new();
    let mut not_analysed = Vec::new();
    for pe in &placed {
        let label = format!("{} at {}", pe.effect.kind(), pe.place);
        let nl = match Nonlinearity::from_placed(pe) {
            Ok(nl) => nl,
            Err(e) => {
                not_analysed.push(format!("{label}: {e}"));
                continue;
            }
        };
        let before = analyse(&lp, &nl, None, &opts.analysis)?;
        let after = if compensation.enabled && opts.allow_compensation {
            Some(analyse(&lp, &nl, Some(&compensation), &opts.analysis)?)
        } else {
            None
        };
        effects.push(EffectCycles {
            receipt_before: receipt(&before, &label),
            receipt_after: after.as_ref().map(|a| receipt(a, &label)),
            locus: locus(&lp, &nl),
            label,
            before,
            after,
        });
    }
    let before_ok = effects.iter().all(|e| e.receipt_before.pass);
    let after_ok = effects
        .iter()
        .all(|e| e.receipt_after.as_ref().is_none_or(|r| r.pass));
    let (choice, reason) = match verdict.trim() {
        "none" => (
            Choice::Keep,
            "the diagnosis found no unmodelled effect: nothing to compensate, the loop receipts \
             stand"
                .to_string(),
        ),
        "unexplained" => (
            Choice::WidenWm,
            "the gap is unexplained: there is no model of the effect to invert, so W_m must \
             cover it and the loop be re-tuned (lower bandwidth)"
                .to_string(),
        ),
        v if !opts.allow_compensation && !before_ok => (
            Choice::WidenWm,
            format!(
                "{v}: a limit cycle is predicted or simulated and compensation is switched off \
                 ([compensation] enabled = false); widen W_m and re-tune"
            ),
        ),
        v if !opts.allow_compensation => (
            Choice::Keep,
            format!(
                "{v}: compensation is switched off ([compensation] enabled = false) and no limit \
                 cycle is predicted or simulated; the loop receipts stand"
            ),
        ),
        v if compensation.enabled && after_ok => (
            Choice::Compensate,
            if before_ok {
                format!(
                    "{v}: no limit cycle with or without compensation; the compensation removes \
                     the diagnosed effect from the loop (validation NRMSE {gap_linear:.3} \
                     linear, {gap_after:.3} with the effect modelled)"
                )
            } else {
                format!(
                    "{v}: the limit cycle predicted/simulated without compensation is gone with \
                     it (every limit_cycle receipt passes after)"
                )
            },
        ),
        v if compensation.enabled => (
            Choice::WidenWm,
            format!(
                "{v}: a limit_cycle receipt still fails with the compensation; widen W_m and \
                 re-tune instead"
            ),
        ),
        v if !before_ok => (
            Choice::WidenWm,
            format!(
                "{v}: a limit cycle is predicted or simulated and the effect cannot be \
                 compensated at its place; widen W_m and re-tune"
            ),
        ),
        v => (
            Choice::Keep,
            format!(
                "{v}: the effect cannot be compensated at its place, but no limit cycle is \
                 predicted or simulated; the loop receipts stand"
            ),
        ),
    };
    Ok(CompensationStage {
        compensation,
        effects,
        not_analysed,
        choice,
        reason,
    })
}
