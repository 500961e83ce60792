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
//! Library only: the lead wires it into `run_pipeline` (receipts.json, report section).
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
}

/// Runs the stage on a gap report (module docs). `plant` is G0 (discrete at the controller's
/// sample time, or continuous), `pid` the discretised controller.
pub fn run_compensation_stage(
    report: &GapReport,
    plant: &StateSpace,
    pid: &DiscretePid,
    opts: &CompensationStageOptions,
) -> Result<CompensationStage> {
    let velocity = report
        .effects
        .iter()
        .find_map(|e| e.velocity_from.as_deref());
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

/// [`run_compensation_stage`] from the parts of a gap report: verdict, its effects, the
/// friction fit's velocity source (`output` or `output_derivative`, `None`: output), and the
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
    let velocity = match velocity_from {
        None | Some("output") => VelocitySource::Output,
        Some("output_derivative") => VelocitySource::OutputDerivative,
        Some(other) => {
            return Err(Error::InvalidArgument(format!(
                "compensation stage: unknown velocity source {other:?} (output or \
                 output_derivative)"
            )))
        }
    };
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
    let lp = LureLoop::new(plant, pid, velocity)?;
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
        let after = if compensation.enabled {
            Some(analyse(&lp, &nl, Some(&compensation), &opts.analysis)?)
        } else {
            None
        };
        effects.push(EffectCycles {
            receipt_before: receipt(&before, &label),
            receipt_after: after.as_ref().map(|a| receipt(a, &label)),
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
