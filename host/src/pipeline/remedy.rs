//! What `ferrosid run` does after the gap diagnosis ([`super::gap_stage`]): the compensation
//! stage ([`super::compensation_stage`]) on the tuned loop, and the seed flowchart's choice
//! carried out.
//!
//! * `compensate` — the designed compensation goes into the generated code
//!   ([`super::PipelineRun::codegen_parts`], `compensation.json`); the receipts are re-checked
//!   with the compensated plant: the `limit_cycle` receipts *with* the compensation replace
//!   those without it (the loop receipts of G0 stand: the compensation removes the effect G0
//!   does not model, so G0 is the compensated plant's linear model).
//! * `widen_wm` — the measured envelope l_m is raised to at least the diagnosed gap
//!   (`gap_linear`, the validation NRMSE that no linear model explains) at every bin, W_m is
//!   re-fitted, the PID re-tuned (lower bandwidth) and every loop receipt and `limit_cycle`
//!   receipt recomputed for the re-tuned loop; the run's controller, weight and curves become
//!   the re-tuned ones.
//! * `keep` — the `limit_cycle` receipts without compensation join the receipts.
//!
//! `receipts_before` are the loop receipts of the first design plus its `limit_cycle`
//! receipts without compensation; `receipts_after` the receipts of the design the choice
//! leads to (equal to `before` for `keep`). The run's receipt list is `receipts_after` plus the
//! model receipts. The sensor noise σ that sets the default smoothing band and the cycle
//! tolerance is the diagnosis' noise floor (NRMSE) times the RMS of the preprocessed
//! validation output.
use super::compensation_stage::{
    run_compensation_stage, Choice, CompensationStage, CompensationStageOptions,
};
use super::config::LoadedConfig;
use super::gap_stage::GapStage;
use super::{rms, stages, EnvelopeData, LogData};
use crate::compensation::DesignOptions;
use crate::error::Result;
use crate::limit_cycle::AnalysisOptions;
use crate::lti::StateSpace;
use crate::robust::pid::TunedPid;
use crate::robust::receipts::{LoopCurves, Receipt, ReceiptKind, Receipts, ReceiptsReport};
use crate::robust::uncertainty::UncertaintyWeight;
use serde::Serialize;
use std::f64::consts::PI;

/// The remedy stage's record in `receipts.json` (`compensation`).
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum CompensationOutcome {
    /// Not run: why (no diagnosis, no controller, ...).
    Skipped {
        /// The reason, in words.
        reason: String,
    },
    /// The stage failed (its error); the run's receipts are those of the first design.
    Failed {
        /// The error message.
        error: String,
    },
    /// The stage ran and its choice was carried out.
    Decided(Box<Decision>),
}

impl CompensationOutcome {
    /// The decision, when the stage ran.
    pub fn decision(&self) -> Option<&Decision> {
        match self {
            Self::Decided(d) => Some(d),
            _ => None,
        }
    }
}

/// The stage's result and what the choice changed.
#[derive(Debug, Clone, Serialize)]
pub struct Decision {
    /// `compensate`, `widen_wm` or `keep`.
    pub choice: Choice,
    /// Why, in words.
    pub reason: String,
    /// Sensor noise σ estimated from the diagnosis, output units (null when unavailable).
    pub sensor_noise: f64,
    /// Smoothing band of the friction feedforward used, velocity units.
    pub velocity_resolution: f64,
    /// Cycle tolerance of the `limit_cycle` receipts, output units.
    pub amplitude_tol: f64,
    /// The stage: compensation, per-effect analyses without/with it, effects not analysed.
    pub stage: CompensationStage,
    /// Receipts of the first design (loop receipts + `limit_cycle` without compensation).
    pub receipts_before: Vec<Receipt>,
    /// Receipts of the design the choice leads to.
    pub receipts_after: Vec<Receipt>,
    /// The widened weight and re-tuned controller (`widen_wm` only).
    pub retuned: Option<Retuned>,
}

impl Decision {
    /// The compensation for the generated code (`compensate` only).
    pub fn compensation(&self) -> Option<&ferrosid_codegen::Compensation> {
        (self.choice == Choice::Compensate && self.stage.compensation.enabled)
            .then_some(&self.stage.compensation)
    }
}

impl Decision {
    /// `compensation.json` ([`crate::ops::codegen::CompensationFile`]): the choice, the reason
    /// and the block, enabled only for `compensate`.
    pub fn file(&self) -> crate::ops::codegen::CompensationFile {
        let mut compensation = self.stage.compensation.clone();
        compensation.enabled = self.compensation().is_some();
        crate::ops::codegen::CompensationFile {
            kind: crate::ops::codegen::COMPENSATION_FILE_KIND.into(),
            choice: match self.choice {
                Choice::Compensate => "compensate",
                Choice::WidenWm => "widen_wm",
                Choice::Keep => "keep",
            }
            .into(),
            reason: self.reason.clone(),
            compensation,
        }
    }
}

/// The `widen_wm` branch's new design.
#[derive(Debug, Clone, Serialize)]
pub struct Retuned {
    /// Floor of the widened envelope l_m (dimensionless).
    pub envelope_floor: f64,
    /// Crossover of the first design, Hz.
    pub crossover_before_hz: f64,
    /// Crossover of the re-tuned design, Hz (null when re-tuning failed).
    pub crossover_after_hz: Option<f64>,
    /// Why re-tuning failed, when it did.
    pub tuning_error: Option<String>,
    /// The widened weight.
    pub weight: UncertaintyWeight,
    /// The widened envelope.
    #[serde(skip)]
    pub envelope: EnvelopeData,
    /// The re-tuned controller.
    #[serde(skip)]
    pub tuned: Option<TunedPid>,
    /// Its loop report and curves.
    #[serde(skip)]
    pub loop_report: Option<(ReceiptsReport, LoopCurves)>,
}

/// What the remedy needs from the run so far.
pub(super) struct RemedyInputs<'a> {
    pub cfg: &'a LoadedConfig,
    pub gap: &'a GapStage,
    pub model: &'a StateSpace,
    pub tuned: Option<&'a TunedPid>,
    pub envelope: Option<&'a EnvelopeData>,
    pub validation: Option<&'a LogData>,
    pub loop_inputs: stages::LoopStageInputs<'a>,
}

/// Is `r` a receipt of the design (recomputed when the controller changes), not of the audit?
fn is_loop_receipt(r: &Receipt) -> bool {
    !matches!(
        r.kind(),
        Some(
            ReceiptKind::NonlinearityAudit
                | ReceiptKind::AuditGainShift
                | ReceiptKind::AuditPhaseShift
                | ReceiptKind::AuditCoherence
        )
    )
}

/// The design receipts of a list (every receipt but the audit's).
fn design_receipts(rs: &[Receipt]) -> Vec<Receipt> {
    rs.iter().filter(|r| is_loop_receipt(r)).cloned().collect()
}

/// Runs the stage and carries out its choice; `receipts` (the first design's) become the
/// final list (module docs). A failing stage is reported, not an error.
pub(super) fn remedy(
    inp: RemedyInputs<'_>,
    receipts: &mut Receipts,
    progress: &dyn Fn(&str),
) -> Result<CompensationOutcome> {
    let Some(report) = inp.gap.report() else {
        return Ok(CompensationOutcome::Skipped {
            reason: "no gap diagnosis (see gap_diagnosis)".into(),
        });
    };
    let Some(pid) = inp.tuned.and_then(|t| t.discrete.as_ref()) else {
        return Ok(CompensationOutcome::Skipped {
            reason: "no discrete controller to analyse (tuning failed)".into(),
        });
    };
    progress("compensation");
    let k = &inp.cfg.config.compensation;
    let y_rms = inp.validation.map_or(f64::NAN, |v| rms(v.log.y()));
    let sensor_noise = report.noise_floor.nrmse * y_rms;
    let noise = if sensor_noise.is_finite() && sensor_noise > 0.0 {
        sensor_noise
    } else {
        0.01 * y_rms
    };
    let fc = inp.loop_inputs.fc;
    let velocity_resolution = k.velocity_resolution.unwrap_or(noise);
    let amplitude_tol = k.amplitude_tol.unwrap_or(3.0 * noise);
    let opts = CompensationStageOptions {
        design: DesignOptions {
            inverse_smoothing_rel: k.inverse_smoothing_rel,
            ..DesignOptions::new(
                &format!(
                    "ferrosid run {}",
                    inp.cfg
                        .path
                        .file_name()
                        .map_or(String::new(), |n| n.to_string_lossy().into_owned())
                ),
                velocity_resolution,
                k.tracking_time_s.unwrap_or(1.0 / (2.0 * PI * fc)),
            )
        },
        analysis: AnalysisOptions {
            amplitude_tol,
            duration_s: k.simulate_s,
            ..AnalysisOptions::default()
        },
        allow_compensation: k.enabled,
    };
    let stage = match run_compensation_stage(report, inp.model, pid, &opts) {
        Ok(s) => s,
        Err(e) => {
            return Ok(CompensationOutcome::Failed {
                error: e.to_string(),
            })
        }
    };
    let mut before = design_receipts(&receipts.receipts);
    before.extend(stage.receipts_before());
    let mut retuned = None;
    let after = match stage.choice {
        Choice::Keep => before.clone(),
        Choice::Compensate => {
            let mut a: Vec<Receipt> = before
                .iter()
                .filter(|r| r.kind() != Some(ReceiptKind::LimitCycle))
                .cloned()
                .collect();
            a.extend(stage.receipts_after());
            a
        }
        Choice::WidenWm => {
            let (r, rec) = widen_and_retune(&inp, report.gap_linear, &opts, progress)?;
            retuned = r;
            rec
        }
    };
    // The final list: the non-loop receipts in their place, then the chosen design's.
    let mut fin = Receipts::default();
    for r in receipts.receipts.iter().filter(|r| !is_loop_receipt(r)) {
        fin.push(r.clone());
    }
    for r in &after {
        fin.push(r.clone());
    }
    *receipts = fin;
    Ok(CompensationOutcome::Decided(Box::new(Decision {
        choice: stage.choice,
        reason: stage.reason.clone(),
        sensor_noise,
        velocity_resolution,
        amplitude_tol,
        stage,
        receipts_before: before,
        receipts_after: after,
        retuned,
    })))
}

/// The `widen_wm` branch: widened envelope, re-fitted W_m, re-tuned PID, its loop and
/// `limit_cycle` receipts. Returns the new design (None when no envelope exists) and its
/// receipts.
fn widen_and_retune(
    inp: &RemedyInputs<'_>,
    gap_linear: f64,
    opts: &CompensationStageOptions,
    progress: &dyn Fn(&str),
) -> Result<(Option<Retuned>, Vec<Receipt>)> {
    let c = &inp.cfg.config;
    let Some(env) = inp.envelope else {
        return Ok((None, Vec::new()));
    };
    progress("re-tuning with a wider W_m");
    let floor = if gap_linear.is_finite() {
        gap_linear
    } else {
        0.0
    };
    let mut wide = env.clone();
    for l in &mut wide.level {
        *l = l.max(floor);
    }
    let weight = stages::fit_weight(inp.cfg, &wide)?;
    let tuning = stages::tune(c, inp.model, Some(&weight))?;
    let mut rs = Receipts::default();
    rs.push(stages::controller_design_receipt(
        c,
        tuning.as_ref().map_err(|e| e.0.as_str()),
    ));
    let (tuned, tuning_error) = match tuning {
        Ok(t) => (Some(t), None),
        Err(e) => (None, Some(e.0)),
    };
    let fc = tuned
        .as_ref()
        .map_or(c.control.crossover_hz, |t| t.design.crossover_hz);
    let li = &inp.loop_inputs;
    let (rep, curves) = stages::loop_receipts(
        c,
        stages::LoopStageInputs {
            model: inp.model,
            tuned: tuned.as_ref(),
            weight: Some(&weight),
            nominal: li.nominal,
            fs: li.fs,
            fc,
            limits: stages::receipt_limits(c, fc),
            cross_validation: li.cross_validation.clone(),
        },
        &mut rs,
    )?;
    let mut after = design_receipts(&rs.receipts);
    if let (Some(pid), Some(report)) = (
        tuned.as_ref().and_then(|t| t.discrete.as_ref()),
        inp.gap.report(),
    ) {
        let no_comp = CompensationStageOptions {
            allow_compensation: false,
            ..opts.clone()
        };
        let st = run_compensation_stage(report, inp.model, pid, &no_comp)?;
        after.extend(st.receipts_before());
    }
    Ok((
        Some(Retuned {
            envelope_floor: floor,
            crossover_before_hz: li.fc,
            crossover_after_hz: tuned.as_ref().map(|t| t.design.crossover_hz),
            tuning_error,
            weight,
            envelope: wide,
            loop_report: rep.zip(curves),
            tuned,
        }),
        after,
    ))
}

/// The lines `ferrosid run` prints about the diagnosis and the compensation stage.
pub fn summary_lines(run: &super::PipelineRun) -> String {
    let mut s = String::new();
    match &run.gap {
        GapStage::Skipped { reason } => {
            s.push_str(&format!("  gap diagnosis: skipped ({reason})\n"))
        }
        GapStage::Failed { error, .. } => {
            s.push_str(&format!("  gap diagnosis: failed ({error})\n"))
        }
        GapStage::Diagnosed {
            triggered_by,
            report,
        } => s.push_str(&format!(
            "  gap diagnosis (triggered by {}): verdict {}; validation NRMSE G0 {}, linear \
             re-fit {}, with the verdict {}\n",
            triggered_by.join(", "),
            report.verdict,
            super::fmt_num(report.gap_before),
            super::fmt_num(report.gap_linear),
            super::fmt_num(report.gap_after)
        )),
    }
    match &run.compensation {
        CompensationOutcome::Skipped { reason } => {
            s.push_str(&format!("  compensation: skipped ({reason})\n"))
        }
        CompensationOutcome::Failed { error } => {
            s.push_str(&format!("  compensation: failed ({error})\n"))
        }
        CompensationOutcome::Decided(d) => {
            let choice = match d.choice {
                Choice::Compensate => "compensate",
                Choice::WidenWm => "widen_wm",
                Choice::Keep => "keep",
            };
            s.push_str(&format!("  compensation: {choice} — {}\n", d.reason));
            for e in &d.stage.effects {
                let show = |r: &Receipt| {
                    format!("{} ({})", if r.pass { "pass" } else { "FAIL" }, r.detail)
                };
                s.push_str(&format!(
                    "    limit_cycle with {}: before {}\n",
                    e.label,
                    show(&e.receipt_before)
                ));
                if let Some(r) = &e.receipt_after {
                    s.push_str(&format!("      after {}\n", show(r)));
                }
            }
            if let Some(r) = &d.retuned {
                s.push_str(&format!(
                    "    W_m widened to an envelope floor of {}: crossover {} Hz -> {} Hz\n",
                    super::fmt_num(r.envelope_floor),
                    super::fmt_num(r.crossover_before_hz),
                    r.crossover_after_hz.map_or("none".into(), super::fmt_num)
                ));
            }
            let fails = |rs: &[Receipt]| rs.iter().filter(|r| !r.pass).count();
            s.push_str(&format!(
                "    receipts before: {} of {} pass; after: {} of {} pass\n",
                d.receipts_before.len() - fails(&d.receipts_before),
                d.receipts_before.len(),
                d.receipts_after.len() - fails(&d.receipts_after),
                d.receipts_after.len()
            ));
        }
    }
    s
}
