//! `receipts.json`: the machine-readable record of a pipeline run (schema
//! `ferrosid.pipeline.receipts/1`, documented field by field in `docs/receipts-schema.md`).
//!
//! Keys appear in the order of the struct fields below (serde serialises structs in
//! declaration order), numbers use serde_json's shortest round-trip form, non-finite numbers
//! are `null`, and nothing depends on the clock or on hash ordering: the same inputs give a
//! byte-identical file. The top-level `receipts` array has the same element shape as
//! [`crate::robust::receipts::Receipt`], so `ferrosid codegen --receipts` reads it directly.
use super::{fmt_num, EnvelopeData, InputFile, Mode, PipelineConfig, PipelineRun};
use crate::error::Result;
use crate::preprocess::Preprocessing;
use crate::robust::audit::{CoherenceDrop, NonlinearityAudit, ShiftBand, Verdict, WorstShift};
use crate::robust::pid::{DiscretePid, Pid, PidDesignPoint};
use crate::robust::receipts::Receipt;
use crate::robust::uncertainty::UncertaintyWeight;
use crate::validate::ResidualKind;
use serde::Serialize;

/// Schema identifier written in `receipts.json`.
pub const SCHEMA: &str = "ferrosid.pipeline.receipts/1";

/// The tool that wrote the file.
#[derive(Debug, Clone, Serialize)]
pub struct Tool {
    /// Always `ferrosid`.
    pub name: &'static str,
    /// Crate version.
    pub version: &'static str,
}

/// The identified model in brief.
#[derive(Debug, Clone, Serialize)]
pub struct ModelSummary {
    /// Estimation run name.
    pub estimation_run: String,
    /// Model order n.
    pub order: usize,
    /// Why this order.
    pub order_reason: String,
    /// Sample time, s (the model is discrete).
    pub ts: f64,
    /// Weighted singular values used for the order choice.
    pub singular_values: Vec<f64>,
    /// Discrete poles [re, im].
    pub poles_z: Vec<[f64; 2]>,
    /// Modes (natural frequency Hz, damping) from s = ln(z)/ts.
    pub modes: Vec<Mode>,
    /// Static gain (output units per input unit; null when infinite).
    pub dc_gain: f64,
    /// True when every pole has |z| < 1.
    pub stable: bool,
    /// True when stability was enforced.
    pub stability_enforced: bool,
    /// Identification warnings.
    pub warnings: Vec<String>,
}

/// Residual correlation tests in brief.
#[derive(Debug, Clone, Serialize)]
pub struct ResidualSummary {
    /// Which residual (one-step prediction or output error).
    pub kind: ResidualKind,
    /// Largest lag tested.
    pub max_lag: usize,
    /// 99 % bound ±2.58/√N.
    pub bound: f64,
    /// Fraction of autocorrelation lags outside the bound.
    pub frac_auto_outside: f64,
    /// Fraction of cross-correlation lags outside the bound.
    pub frac_cross_outside: f64,
    /// Whiteness test verdict.
    pub whiteness_ok: bool,
    /// Independence-from-input verdict.
    pub independence_ok: bool,
}

/// Validation on fresh data.
#[derive(Debug, Clone, Serialize)]
pub struct ValidationSummary {
    /// Validation log name.
    pub log: String,
    /// Fit percent (100·(1 − NRMSE)).
    pub fit_percent: f64,
    /// NRMSE.
    pub nrmse: f64,
    /// Residual tests (null when they could not run).
    pub residuals: Option<ResidualSummary>,
}

/// Nonlinearity audit evidence (per-bin data are in the report).
#[derive(Debug, Clone, Serialize)]
pub struct AuditSummary {
    /// `linear_enough` or `not_linear`.
    pub verdict: Verdict,
    /// Reasons for the verdict.
    pub reasons: Vec<String>,
    /// Audit band examined, Hz.
    pub band_hz: (f64, f64),
    /// Runs (label, amplitude).
    pub runs: Vec<(String, f64)>,
    /// Bins examined.
    pub bins_examined: usize,
    /// Worst gain shift.
    pub worst_gain_shift_db: WorstShift,
    /// Worst phase shift.
    pub worst_phase_shift_deg: WorstShift,
    /// Flagged bands.
    pub shift_bands: Vec<ShiftBand>,
    /// Coherence drops near crossover.
    pub coherence_drops: Vec<CoherenceDrop>,
}

impl From<&NonlinearityAudit> for AuditSummary {
    /// The audit's verdict and evidence without the per-bin data.
    fn from(a: &NonlinearityAudit) -> Self {
        AuditSummary {
            verdict: a.verdict,
            reasons: a.reasons.clone(),
            band_hz: a.band_hz,
            runs: a.runs.clone(),
            bins_examined: a.bins_examined,
            worst_gain_shift_db: a.worst_gain_shift_db.clone(),
            worst_phase_shift_deg: a.worst_phase_shift_deg.clone(),
            shift_bands: a.shift_bands.clone(),
            coherence_drops: a.coherence_drops.clone(),
        }
    }
}

/// The uncertainty weight in brief.
#[derive(Debug, Clone, Serialize)]
pub struct WeightSummary {
    /// Order.
    pub order: usize,
    /// Numerator, descending powers of s (rad/s).
    pub num: Vec<f64>,
    /// Denominator, descending powers of s, monic.
    pub den: Vec<f64>,
    /// Zeros [re, im], rad/s.
    pub zeros: Vec<[f64; 2]>,
    /// Poles [re, im], rad/s.
    pub poles: Vec<[f64; 2]>,
    /// |W_m(0)|: low-frequency relative uncertainty.
    pub low_frequency_gain: f64,
    /// |W_m(∞)|: high-frequency relative uncertainty.
    pub high_frequency_gain: f64,
    /// Largest |W_m|/l_m (looseness).
    pub worst_overbound_ratio: f64,
    /// Smallest |W_m|/l_m (>= 1 when the overbound holds).
    pub min_overbound_ratio: f64,
    /// Log-frequency mean overbound, dB (the minimised objective).
    pub mean_overbound_db: f64,
    /// Family members.
    pub family: Vec<String>,
    /// Assumed points in the decade below the measured band.
    pub below_band_points: usize,
    /// Level assumed there.
    pub below_band_level: f64,
    /// Measured bins in the envelope.
    pub measured_bins: usize,
    /// Lowest measured bin, Hz.
    pub measured_band_bottom_hz: f64,
    /// Assumed points above the measured band (to 100 × Nyquist) at `beyond_band_level`.
    pub beyond_band_points: usize,
    /// Highest measured bin, Hz.
    pub measured_band_top_hz: f64,
    /// The optimisation problem solved.
    pub objective: String,
}

/// The tuned controller.
#[derive(Debug, Clone, Serialize)]
pub struct ControllerSummary {
    /// Continuous PID (gains map error in output units to input units).
    pub pid: Pid,
    /// The discrete firmware law (Tustin, prewarped at the crossover).
    pub discrete: Option<DiscretePid>,
    /// Winning design point.
    pub design: PidDesignPoint,
    /// Requested crossover, Hz.
    pub target_crossover_hz: f64,
    /// Tuning method.
    pub method: String,
}

/// Welch grid shared by every log.
#[derive(Debug, Clone, Serialize)]
pub struct EtfeSummary {
    /// Sample rate after preprocessing, Hz.
    pub fs_hz: f64,
    /// Segment length.
    pub nperseg: usize,
    /// Overlap.
    pub noverlap: usize,
    /// Resolution fs/nperseg, Hz.
    pub resolution_hz: f64,
    /// Coherence gate.
    pub coherence_gate: f64,
    /// Per log: (name, averages, bins passing the gate).
    pub logs: Vec<(String, usize, usize)>,
}

/// Where everything came from.
#[derive(Debug, Clone, Serialize)]
pub struct Provenance {
    /// The pipeline file.
    pub pipeline: InputFile,
    /// Every log read.
    pub inputs: Vec<InputFile>,
    /// Preprocessing record per log.
    pub preprocessing: Vec<Preprocessing>,
    /// Welch settings and gating per log.
    pub etfe: EtfeSummary,
    /// The configuration with all defaults filled in.
    pub settings: PipelineConfig,
}

/// The whole `receipts.json`.
#[derive(Debug, Clone, Serialize)]
pub struct ReceiptsDocument {
    /// [`SCHEMA`].
    pub schema: &'static str,
    /// Writer.
    pub tool: Tool,
    /// Report title.
    pub name: String,
    /// `pass` when every receipt passes, else `fail`.
    pub verdict: &'static str,
    /// Same as `verdict == "pass"`.
    pub all_pass: bool,
    /// Number of passing receipts.
    pub passed: usize,
    /// Number of failing receipts.
    pub failed: usize,
    /// Crossover the loop receipts refer to, Hz.
    pub crossover_hz: f64,
    /// The receipts, in pipeline order.
    pub receipts: Vec<Receipt>,
    /// The identified model.
    pub model: ModelSummary,
    /// Validation on fresh data (null without a validation log).
    pub validation: Option<ValidationSummary>,
    /// Audit evidence (null with fewer than two runs).
    pub audit: Option<AuditSummary>,
    /// Uncertainty weight (null when none could be fitted).
    pub uncertainty_weight: Option<WeightSummary>,
    /// Why there is no weight.
    pub uncertainty_weight_note: Option<String>,
    /// The controller (null when tuning was infeasible).
    pub controller: Option<ControllerSummary>,
    /// Why tuning failed.
    pub controller_error: Option<String>,
    /// Inputs and settings.
    pub provenance: Provenance,
    /// The gap diagnosis stage: `{"status": "skipped", "reason"}`, `{"status": "diagnosed",
    /// "triggered_by", "report"}` (the `ferrosid gap --json` report) or `{"status": "failed",
    /// "triggered_by", "error"}`.
    pub gap_diagnosis: super::gap_stage::GapStage,
    /// The compensation stage and its choice: `{"status": "skipped", "reason"}`,
    /// `{"status": "failed", "error"}` or `{"status": "decided", "choice", "reason", ...,
    /// "receipts_before", "receipts_after"}` (docs/receipts-schema.md).
    pub compensation: super::remedy::CompensationOutcome,
    /// Physical parameters: `{"status": "skipped"}`, `{"status": "fitted", "run", "fit"}`
    /// (parameters with unit, value, interval and status) or `{"status": "failed", "error"}`.
    pub physical: super::physical_stage::PhysicalOutcome,
    /// The `[control] method` stage (absent for `pid`; docs/receipts-schema.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub control: Option<super::control_stage::ControlOutcome>,
    /// `[control] methods` with two or more: one row per method, primary first, and the file
    /// its receipts are in (absent otherwise; docs/receipts-schema.md).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub comparison: Vec<super::control_methods::ComparisonRow>,
}

impl WeightSummary {
    /// The summary of the fitted weight `w` over its envelope `e` (what receipts.json and the
    /// Python `fit_wm` report).
    pub fn new(w: &UncertaintyWeight, e: &EnvelopeData) -> Self {
        Self {
            order: w.order,
            num: w.num.clone(),
            den: w.den.clone(),
            zeros: w.zeros.clone(),
            poles: w.poles.clone(),
            low_frequency_gain: weight_low_gain(&w.num, &w.den),
            high_frequency_gain: weight_high_gain(&w.num, &w.den),
            worst_overbound_ratio: w.worst_overbound_ratio,
            min_overbound_ratio: w.min_overbound_ratio,
            mean_overbound_db: w.mean_overbound_db,
            family: e.family.clone(),
            below_band_points: e.below,
            below_band_level: e.level.first().copied().unwrap_or(f64::NAN),
            measured_bins: e.measured,
            measured_band_bottom_hz: e.freq_hz.get(e.below).copied().unwrap_or(f64::NAN),
            beyond_band_points: e.beyond(),
            measured_band_top_hz: e.f_top_hz,
            objective: w.objective.clone(),
        }
    }
}

impl ReceiptsDocument {
    /// Builds the document of a run.
    pub fn from_run(run: &PipelineRun) -> Self {
        let rs = &run.receipts;
        let passed = rs.receipts.iter().filter(|r| r.pass).count();
        let id = &run.ident;
        let poles = run.model().poles().unwrap_or_default();
        let model = ModelSummary {
            estimation_run: run.nominal_run().name.clone(),
            order: id.order,
            order_reason: id.order_reason.clone(),
            ts: run.model().ts,
            singular_values: id.singular_values.clone(),
            poles_z: poles.iter().map(|z| [z.re, z.im]).collect(),
            modes: run.modes.clone(),
            dc_gain: run.dc_gain,
            stable: poles.iter().all(|z| z.norm() < 1.0),
            stability_enforced: id.stability_enforced,
            warnings: id.warnings.clone(),
        };
        let validation = match (&run.validation, &run.validation_fit) {
            (Some(v), Some(f)) => Some(ValidationSummary {
                log: v.name.clone(),
                fit_percent: f.fit_percent[0],
                nrmse: f.nrmse[0],
                residuals: run.residuals.as_ref().map(|r| ResidualSummary {
                    kind: r.kind,
                    max_lag: r.max_lag,
                    bound: r.bound,
                    frac_auto_outside: r.frac_auto_outside,
                    frac_cross_outside: r.frac_cross_outside,
                    whiteness_ok: r.whiteness_ok,
                    independence_ok: r.independence_ok,
                }),
            }),
            _ => None,
        };
        let audit = run.audit.as_ref().map(AuditSummary::from);
        let uncertainty_weight = run
            .uncertainty
            .as_ref()
            .ok()
            .map(|u| WeightSummary::new(&u.weight, &u.envelope));
        let controller = run.tuned().map(|t| ControllerSummary {
            pid: t.pid,
            discrete: t.discrete.clone(),
            design: t.design,
            target_crossover_hz: t.target_crossover_hz,
            method: t.method.clone(),
        });
        let gate = run.config.etfe.coherence_gate;
        let nom = &run.nominal_run().etfe;
        let etfe = EtfeSummary {
            fs_hz: nom.fs,
            nperseg: nom.nperseg,
            noverlap: nom.noverlap,
            resolution_hz: nom.fs / nom.nperseg as f64,
            coherence_gate: gate,
            logs: run
                .runs
                .iter()
                .chain(run.validation.iter())
                .map(|l| {
                    (
                        l.name.clone(),
                        l.etfe.n_averages,
                        l.etfe.gate(gate).iter().filter(|&&g| g).count(),
                    )
                })
                .collect(),
        };
        Self {
            schema: SCHEMA,
            tool: Tool {
                name: "ferrosid",
                version: env!("CARGO_PKG_VERSION"),
            },
            name: run.title.clone(),
            verdict: if rs.all_pass { "pass" } else { "fail" },
            all_pass: rs.all_pass,
            passed,
            failed: rs.receipts.len() - passed,
            crossover_hz: run.receipts_crossover_hz,
            receipts: rs.receipts.clone(),
            model,
            validation,
            audit,
            uncertainty_weight,
            uncertainty_weight_note: run.uncertainty.as_ref().err().map(ToString::to_string),
            controller,
            controller_error: run.tuning.as_ref().err().map(ToString::to_string),
            provenance: Provenance {
                pipeline: run.pipeline_file.clone(),
                inputs: run.inputs.clone(),
                preprocessing: run
                    .runs
                    .iter()
                    .chain(run.validation.iter())
                    .map(|l| l.preprocessing.clone())
                    .collect(),
                etfe,
                settings: run.config.clone(),
            },
            gap_diagnosis: run.gap.clone(),
            compensation: run.compensation.clone(),
            physical: run.physical.clone(),
            control: run.control.clone(),
            comparison: super::control_methods::comparison_rows(run),
        }
    }

    /// Pretty JSON with a trailing newline.
    pub fn to_json(&self) -> Result<String> {
        super::json_pretty(self)
    }

    /// Plain-text summary table of the receipts (what `ferrosid run` prints).
    pub fn summary_text(&self) -> String {
        let mut rows: Vec<[String; 5]> = vec![[
            "receipt".into(),
            "value".into(),
            "limit".into(),
            "".into(),
            "result".into(),
        ]];
        for r in &self.receipts {
            rows.push([
                r.name.clone(),
                r.value_text.clone(),
                format!("{} {} {}", r.comparison.symbol(), fmt_num(r.limit), r.unit),
                String::new(),
                if r.pass { "pass".into() } else { "FAIL".into() },
            ]);
        }
        let w: Vec<usize> = (0..5)
            .map(|j| rows.iter().map(|r| r[j].chars().count()).max().unwrap_or(0))
            .collect();
        let mut s = String::new();
        for r in &rows {
            let line = format!(
                "  {:<w0$}  {:>w1$}  {:<w2$}  {}",
                r[0],
                r[1],
                r[2],
                r[4],
                w0 = w[0],
                w1 = w[1],
                w2 = w[2]
            );
            s.push_str(line.trim_end());
            s.push('\n');
        }
        s
    }
}

/// |W(0)| = |num(0)/den(0)| for descending-power coefficients.
pub fn weight_low_gain(num: &[f64], den: &[f64]) -> f64 {
    match (num.last(), den.last()) {
        (Some(n), Some(d)) if *d != 0.0 => (n / d).abs(),
        _ => f64::NAN,
    }
}

/// |W(∞)| = |num[0]/den[0]| for a biproper weight (equal degrees).
pub fn weight_high_gain(num: &[f64], den: &[f64]) -> f64 {
    if num.len() == den.len() && !den.is_empty() && den[0] != 0.0 {
        (num[0] / den[0]).abs()
    } else {
        0.0
    }
}
