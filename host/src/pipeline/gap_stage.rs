//! The gap-diagnosis stage of the pipeline: when the data say the identified model G0 does not
//! tell the whole story, the run diagnoses it as a nominal sim ([`crate::gap::diagnose`]) and
//! the report shows where G0 and the plant disagree, which unmodelled effect explains it (or
//! that none of the vocabulary does: `unexplained`, with the evidence) and how far the gap
//! shrinks.
//!
//! **When.** `[gap] run = "auto"` (default) diagnoses when a flag is up: the dual-amplitude
//! audit says *not linear*, or the receipt `audit_gain_shift`, `audit_phase_shift`,
//! `audit_coherence`, `etfe_phase_agreement` or `cross_validation_fit` fails. `"always"`
//! diagnoses every run, `"never"` none. The stage needs a `[validation]` log (the diagnosis ranks
//! on fresh data) and a SISO log; otherwise it is skipped with the reason.
//!
//! **Data.** G0 (discrete, at the preprocessed logs' sample time) is the sim; every `[[runs]]`
//! log trains, the `[validation]` log validates — the logs *as read*, brought to G0's operating
//! point (`u − u0`, `y − y0`, the estimation run's means) and rate by
//! [`crate::operating_point::logs_at_model_point`], exactly as `ferrosid gap` treats the
//! `model.json` the run writes. (Not each log's own mean: an offset removed per log would move
//! a friction or dead-zone effect away from where the plant has it.) When G0 has an operating
//! point with offsets, the logs as read (only decimated, G0 applied about zero) are diagnosed
//! too and the reading with the smaller validated gap is reported
//! ([`crate::gap::diagnose_at_operating_point`]: friction and dead zones act at zero *absolute*
//! speed and command). A failing diagnosis does not fail the
//! run: its error is reported in place of the result (the stage is evidence, not a receipt).
use serde::{Deserialize, Serialize};

use super::LogData;
use crate::data::Log;
use crate::gap::{diagnose_at_operating_point, GapOptions, GapReport};
use crate::lti::StateSpace;
use crate::operating_point::OperatingPoint;
use crate::robust::receipts::{Receipt, ReceiptKind};

/// When the pipeline runs the gap diagnosis (`[gap] run`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GapRun {
    /// When the audit or a model receipt flags (see the module docs).
    #[default]
    Auto,
    /// On every run.
    Always,
    /// Never.
    Never,
}

/// The receipts whose failure triggers the diagnosis under [`GapRun::Auto`].
pub const TRIGGER_RECEIPTS: [ReceiptKind; 5] = [
    ReceiptKind::AuditGainShift,
    ReceiptKind::AuditPhaseShift,
    ReceiptKind::AuditCoherence,
    ReceiptKind::EtfePhaseAgreement,
    ReceiptKind::CrossValidationFit,
];

/// What the stage did.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum GapStage {
    /// Not run: why (no flag under `auto`, `never`, no validation log, not SISO).
    Skipped {
        /// The reason, in words.
        reason: String,
    },
    /// Ran and produced a report.
    Diagnosed {
        /// The flags that triggered it (`always` when configured so).
        triggered_by: Vec<String>,
        /// The diagnosis (schema in `docs/gap.md`).
        report: Box<GapReport>,
    },
    /// Triggered but the diagnosis failed (its error).
    Failed {
        /// The flags that triggered it.
        triggered_by: Vec<String>,
        /// The error message.
        error: String,
    },
}

impl GapStage {
    /// The report, when the diagnosis ran.
    pub fn report(&self) -> Option<&GapReport> {
        match self {
            GapStage::Diagnosed { report, .. } => Some(report),
            _ => None,
        }
    }
}

/// The flags that trigger the diagnosis: a *not linear* audit and the failing
/// [`TRIGGER_RECEIPTS`], by name.
pub fn triggers(audit_not_linear: bool, receipts: &[Receipt]) -> Vec<String> {
    let mut t = Vec::new();
    if audit_not_linear {
        t.push("nonlinearity_audit".to_string());
    }
    for r in receipts {
        if !r.pass && r.kind().is_some_and(|k| TRIGGER_RECEIPTS.contains(&k)) {
            t.push(r.name.clone());
        }
    }
    t
}

/// Runs the stage: decides from `mode` and `flags` (see [`triggers`]) whether to diagnose G0
/// (`model`, discrete, identified at operating point `op`) against the raw logs of the `runs`
/// (training) and `validation`; `progress` hears "gap diagnosis" when it runs.
pub fn run_gap_stage(
    mode: GapRun,
    flags: Vec<String>,
    model: &StateSpace,
    op: Option<&OperatingPoint>,
    runs: &[LogData],
    validation: Option<&LogData>,
    progress: &dyn Fn(&str),
) -> GapStage {
    let triggered_by = match mode {
        GapRun::Never => {
            return GapStage::Skipped {
                reason: "[gap] run = \"never\"".into(),
            }
        }
        GapRun::Always => vec!["always".to_string()],
        GapRun::Auto if flags.is_empty() => {
            return GapStage::Skipped {
                reason: "no flag: the audit found the plant linear enough and every model \
                         receipt passed ([gap] run = \"always\" diagnoses anyway)"
                    .into(),
            }
        }
        GapRun::Auto => flags,
    };
    let Some(val) = validation else {
        return GapStage::Skipped {
            reason: "no [validation] log: the diagnosis ranks candidate effects on fresh data"
                .into(),
        };
    };
    if !model.is_siso() {
        return GapStage::Skipped {
            reason: "the gap diagnosis is SISO; this model has several channels".into(),
        };
    }
    progress("gap diagnosis");
    let logs: Vec<Log> = runs.iter().map(|r| r.raw.clone()).collect();
    match diagnose_at_operating_point(model, op, None, &logs, &val.raw, &GapOptions::default()) {
        Ok(d) => GapStage::Diagnosed {
            triggered_by,
            report: Box::new(d.report),
        },
        Err(e) => GapStage::Failed {
            triggered_by,
            error: e.to_string(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robust::receipts::Comparison;

    fn receipt(kind: ReceiptKind, pass: bool) -> Receipt {
        Receipt {
            name: kind.name().to_string(),
            description: String::new(),
            value: 0.0,
            value_text: String::new(),
            limit: 0.0,
            unit: "1".into(),
            comparison: Comparison::AtMost,
            pass,
            detail: String::new(),
        }
    }

    #[test]
    fn only_model_flags_trigger() {
        let rs = [
            receipt(ReceiptKind::GainMargin, false),
            receipt(ReceiptKind::AuditPhaseShift, false),
            receipt(ReceiptKind::CrossValidationFit, true),
        ];
        assert_eq!(triggers(false, &rs), vec!["audit_phase_shift".to_string()]);
        assert_eq!(
            triggers(true, &rs[..1]),
            vec!["nonlinearity_audit".to_string()]
        );
        assert!(triggers(false, &rs[..1]).is_empty());
    }

    #[test]
    fn skipped_without_flag_or_validation() {
        let m = |v: f64| faer::Mat::from_fn(1, 1, |_, _| v);
        let g = StateSpace::new(m(0.5), m(1.0), m(1.0), m(0.0), 1e-3).unwrap();
        let s = run_gap_stage(GapRun::Auto, vec![], &g, None, &[], None, &|_| {});
        assert!(matches!(s, GapStage::Skipped { ref reason } if reason.contains("no flag")));
        let s = run_gap_stage(GapRun::Always, vec![], &g, None, &[], None, &|_| {});
        assert!(matches!(s, GapStage::Skipped { ref reason } if reason.contains("validation")));
        let s = run_gap_stage(
            GapRun::Never,
            vec!["x".into()],
            &g,
            None,
            &[],
            None,
            &|_| {},
        );
        assert!(matches!(s, GapStage::Skipped { ref reason } if reason.contains("never")));
    }
}
