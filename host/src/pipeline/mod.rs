//! The whole chain from raw logs to receipts, driven by a `PIPELINE.toml` ([`config`]):
//!
//! ingest → preprocess → Welch ETFE + coherence → N4SID → validation → nonlinearity audit →
//! uncertainty weight W_m → robust PID tuning → receipts.
//!
//! [`run_pipeline`] computes everything into a [`PipelineRun`] (pure: no files written, no
//! clock read); [`document::ReceiptsDocument`] is its `receipts.json` (schema in
//! `docs/receipts-schema.md`); the layers above render it: [`crate::report`] (HTML report and
//! SVG figures) and [`crate::output`] (`receipts.json`, `model.json`, `pid.json`, `wm.json`,
//! `report.html` and `figures/*.svg` in an output directory). The same logs and settings give
//! byte-identical files (no time stamps, no hash-ordered maps, shortest round-trip floats).
//!
//! Which data feed which stage:
//! * every `[[runs]]` log and the `[validation]` log get the same preprocessing and the same
//!   Welch settings (so their ETFEs share one frequency grid);
//! * the nominal model G0 is N4SID on the estimation run (`[identification].run`, default the
//!   largest-amplitude run);
//! * the audit overlays the ETFEs of all runs (needs two or more);
//! * the multiplicative envelope l_m compares the ETFEs of the `[uncertainty].family` logs
//!   (default: all runs and the validation log) with G0 at the bins where every member passes
//!   the coherence gate; above the highest such bin the data say nothing, and l_m is set to
//!   `beyond_band_level` (default 1, i.e. 100 %) up to 100 × Nyquist, and for the decade below
//!   the lowest such bin it is held at the lowest measured octave's largest value;
//! * the cross-validation fit is the free-run simulation fit of G0 on the validation log, with
//!   the initial state estimated; the residual correlation tests use the Kalman predictor.
//!
//! Units: frequencies in Hz, time in seconds, signals in the log's units
//! (`[signals].input_unit`, `output_unit`).
pub mod arrays;
pub mod compensation_stage;
pub mod config;
pub mod control_cycles;
pub mod control_methods;
pub mod control_mpc;
pub mod control_stage;
pub mod document;
pub mod gap_stage;
pub mod physical_stage;
pub mod remedy;
mod stages;

use crate::data::Log;
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::n4sid::N4sidResult;
use crate::ops::codegen::{receipt_line, weight_coefficients, CodegenParts, ControllerSource};
use crate::preprocess::Preprocessing;
use crate::robust::audit::NonlinearityAudit;
use crate::robust::pid::TunedPid;
use crate::robust::receipts::{
    missing_cross_validation_receipt, LoopCurves, Receipts, ReceiptsReport,
};
use crate::robust::uncertainty::UncertaintyWeight;
use crate::spectral::Etfe;
use crate::validate::{ResidualTest, SimulationFit};
use serde::Serialize;
use sha2::{Digest, Sha256};
use std::f64::consts::PI;
use std::path::Path;

pub use config::{LoadedConfig, PipelineConfig};
pub use document::ReceiptsDocument;

/// Largest residual-correlation lag tested on the validation log (samples).
pub const RESIDUAL_MAX_LAG: usize = 25;

/// One input file with its content hash, as recorded in the provenance.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InputFile {
    /// `pipeline`, `run` or `validation`.
    pub role: String,
    /// Run name (`validation` for the validation log, the TOML file name for the pipeline).
    pub name: String,
    /// Path as written in the pipeline file (forward slashes), or the pipeline file's name.
    pub path: String,
    /// SHA-256 of the file's bytes, lower-case hex.
    pub sha256: String,
    /// File size in bytes.
    pub bytes: u64,
    /// Samples read (0 for the pipeline file).
    pub samples: usize,
    /// Sample rate as read, Hz (0 for the pipeline file).
    pub fs_hz: f64,
    /// Reader warnings (e.g. suspected clipping).
    pub warnings: Vec<String>,
}

/// One log after preprocessing, with its ETFE.
#[derive(Debug, Clone)]
pub struct LogData {
    /// Run name, or `validation`.
    pub name: String,
    /// Excitation amplitude used by the audit (configured, or the input RMS after
    /// preprocessing), input units.
    pub amplitude: f64,
    /// True when `amplitude` is the measured input RMS rather than a configured value.
    pub amplitude_is_rms: bool,
    /// The preprocessed log.
    pub log: Log,
    /// The log as read, before preprocessing (the gap stage compares G0 with it through the
    /// operating point, as `ferrosid gap` does with a model file).
    pub raw: Log,
    /// What preprocessing did.
    pub preprocessing: Preprocessing,
    /// Welch H1 estimate with coherence.
    pub etfe: Etfe,
}

impl LogData {
    /// The operating point of a model identified on this run alone (the means its
    /// preprocessing removed; [`crate::operating_point`]); `None` when it cannot be formed.
    pub fn operating_point(&self) -> Option<crate::operating_point::OperatingPoint> {
        crate::operating_point::operating_point_of(
            std::slice::from_ref(&self.preprocessing),
            self.log.inputs.len(),
            self.log.outputs.len(),
        )
        .ok()
    }
}

/// A continuous-time mode of the identified model, from a discrete pole z via s = ln(z)/ts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct Mode {
    /// Natural frequency |s|/(2π), Hz.
    pub natural_hz: f64,
    /// Damping ratio −Re(s)/|s| (1 for a real pole; negative for an unstable mode).
    pub damping: f64,
    /// True for a complex pair (reported once, Im s > 0).
    pub oscillatory: bool,
    /// The discrete pole z as [re, im].
    pub z: [f64; 2],
}

/// The envelope the weight was fitted to.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnvelopeData {
    /// Frequencies, Hz: the assumed decade below the measured band, the measured bins, then
    /// the unmeasured bins above (up to 100 × Nyquist).
    pub freq_hz: Vec<f64>,
    /// l_m at each bin (dimensionless).
    pub level: Vec<f64>,
    /// The first `below` entries are the assumed decade below the measured band.
    pub below: usize,
    /// The next `measured` entries are measured bins; the rest are `beyond_band_level`.
    pub measured: usize,
    /// Family members (log names).
    pub family: Vec<String>,
    /// Highest measured bin, Hz.
    pub f_top_hz: f64,
}

impl EnvelopeData {
    /// Index range of the measured bins in `freq_hz`/`level`.
    pub fn measured_range(&self) -> std::ops::Range<usize> {
        self.below..self.below + self.measured
    }
    /// (f, l_m) of the measured bins.
    pub fn measured_points(&self) -> Vec<(f64, f64)> {
        self.measured_range()
            .map(|i| (self.freq_hz[i], self.level[i]))
            .collect()
    }
    /// (f, level) of the assumed points below and above the measured band.
    pub fn assumed_points(&self) -> Vec<(f64, f64)> {
        let r = self.measured_range();
        (0..self.freq_hz.len())
            .filter(|i| !r.contains(i))
            .map(|i| (self.freq_hz[i], self.level[i]))
            .collect()
    }
    /// Number of assumed points above the measured band.
    pub fn beyond(&self) -> usize {
        self.freq_hz.len() - self.below - self.measured
    }
}

/// The uncertainty stage's result: the envelope and the weight W_m fitted to it.
#[derive(Debug, Clone, PartialEq)]
pub struct WeightFit {
    /// The envelope the weight was fitted to.
    pub envelope: EnvelopeData,
    /// The fitted multiplicative uncertainty weight.
    pub weight: UncertaintyWeight,
}

/// Why the uncertainty stage has no weight (a finding: robust stability is then not checked).
#[derive(Debug, Clone, PartialEq)]
pub enum NoWeight {
    /// Fewer than three bins pass the coherence gate for every family member.
    TooFewBins {
        /// Bins that pass for every member.
        bins: usize,
        /// The family (log names).
        family: Vec<String>,
        /// The coherence gate.
        gate: f64,
    },
}

impl std::fmt::Display for NoWeight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NoWeight::TooFewBins { bins, family, gate } => write!(
                f,
                "only {bins} bins where every family member ({}) passes the coherence gate \
                 {gate}: no uncertainty weight; robust stability is not checked",
                family.join(", ")
            ),
        }
    }
}

/// Why the PID tuner produced no controller (a finding the `controller_design` receipt
/// reports, not an error of the run): the tuner's message.
#[derive(Debug, Clone, PartialEq)]
pub struct TuningFailed(pub String);

impl std::fmt::Display for TuningFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// Everything the pipeline computed, for the receipts document and the report.
#[derive(Debug, Clone)]
pub struct PipelineRun {
    /// Report title.
    pub title: String,
    /// The configuration with all defaults filled in.
    pub config: PipelineConfig,
    /// The pipeline file's own provenance entry.
    pub pipeline_file: InputFile,
    /// Provenance of every log, in the order runs…, validation.
    pub inputs: Vec<InputFile>,
    /// The runs, in file order.
    pub runs: Vec<LogData>,
    /// The validation log, if any.
    pub validation: Option<LogData>,
    /// Index into `runs` of the estimation run.
    pub nominal: usize,
    /// N4SID result on the estimation run.
    pub ident: N4sidResult,
    /// Modes of the identified model, increasing natural frequency.
    pub modes: Vec<Mode>,
    /// Static gain of G0 (output units per input unit); infinite with a pole at z = 1.
    pub dc_gain: f64,
    /// Free-run fit on the validation log.
    pub validation_fit: Option<SimulationFit>,
    /// Residual correlation tests on the validation log.
    pub residuals: Option<ResidualTest>,
    /// Nonlinearity audit (None with fewer than two runs).
    pub audit: Option<NonlinearityAudit>,
    /// The uncertainty stage: the envelope and the weight fitted to it, or why there is none.
    pub uncertainty: std::result::Result<WeightFit, NoWeight>,
    /// The tuning stage: the tuned PID, or why no controller meets the limits.
    pub tuning: std::result::Result<TunedPid, TuningFailed>,
    /// Everything computed for the loop receipts (None without a controller).
    pub loop_report: Option<ReceiptsReport>,
    /// |S|, |T|, |KS|, 1/|W_m| of the implemented loop on a log grid (None without a
    /// controller).
    pub curves: Option<LoopCurves>,
    /// Crossover the receipts refer to, Hz (the achieved design crossover, or the target
    /// without a controller).
    pub receipts_crossover_hz: f64,
    /// All receipts and the verdict.
    pub receipts: Receipts,
    /// The gap diagnosis of G0 ([`gap_stage`]): run when the audit or a model receipt flags.
    pub gap: gap_stage::GapStage,
    /// The compensation stage after the diagnosis and its choice ([`remedy`]).
    pub compensation: remedy::CompensationOutcome,
    /// Physical parameters of the `[physical]` structure ([`physical_stage`]).
    pub physical: physical_stage::PhysicalOutcome,
    /// The `[control] method` stage ([`control_stage`]; None for `pid`).
    pub control: Option<control_stage::ControlOutcome>,
    /// With `[control] methods` of two or more: every method's result, primary first
    /// ([`control_methods`]); empty otherwise.
    pub comparison: Vec<control_methods::MethodRun>,
}

impl PipelineRun {
    /// The fitted W_m, if any.
    pub fn weight(&self) -> Option<&UncertaintyWeight> {
        self.uncertainty.as_ref().ok().map(|u| &u.weight)
    }
    /// The envelope W_m was fitted to, if any.
    pub fn envelope(&self) -> Option<&EnvelopeData> {
        self.uncertainty.as_ref().ok().map(|u| &u.envelope)
    }
    /// The tuned PID, if any.
    pub fn tuned(&self) -> Option<&TunedPid> {
        self.tuning.as_ref().ok()
    }

    /// The model file content (`model.json`): G0 with the operating point and preprocessing
    /// of the estimation run ([`crate::operating_point`]).
    pub fn model_file(&self) -> crate::lti::StateSpaceData {
        let mut d = crate::lti::StateSpaceData::from(self.model());
        d.operating_point = self.nominal_run().operating_point();
        d
    }

    /// The parts of a firmware header from this run, without the disk (the input of
    /// [`crate::ops::codegen::codegen_input`]): G0 with the operating point of the estimation
    /// run, the tuned controller, the fitted W_m, every receipt and the digests of the pipeline
    /// file and the logs. The same parts `ferrosid codegen` reads from `model.json`,
    /// `pid.json`, `wm.json` and `receipts.json`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the run has no uncertainty weight (the power-up check
    /// needs one; the error says why it is missing).
    pub fn codegen_parts(&self) -> Result<CodegenParts> {
        let weight = match &self.uncertainty {
            Ok(u) => &u.weight,
            Err(why) => {
                return Err(Error::InvalidArgument(format!(
                    "the run has no uncertainty weight for the power-up check: {why}"
                )))
            }
        };
        let model_file = self.model_file();
        let sources = std::iter::once(&self.pipeline_file)
            .chain(&self.inputs)
            .map(|f| ferrosid_codegen::SourceDigest {
                label: format!("{}: {}", f.role, f.path),
                sha256: f.sha256.clone(),
            })
            .collect();
        Ok(CodegenParts {
            compensation: self.compensation_block().cloned(),
            model: self.model().clone(),
            model_origin: Path::new(&self.pipeline_file.path).to_path_buf(),
            operating_point: model_file.operating_point,
            controller: self.tuned().map(|t| ControllerSource::Tuned {
                pid: t.pid,
                discrete: t.discrete.clone(),
                crossover_hz: Some(t.design.crossover_hz),
                prewarp_hz: None,
            }),
            weight: weight_coefficients(weight),
            receipts: self.receipts.receipts.iter().map(receipt_line).collect(),
            sources,
            state_controller: self.control.as_ref().and_then(control_stage::codegen_block),
        })
    }

    /// The compensation for the generated code, when the run chose `compensate`.
    pub fn compensation_block(&self) -> Option<&ferrosid_codegen::Compensation> {
        self.compensation.decision().and_then(|d| d.compensation())
    }

    /// The estimation run.
    pub fn nominal_run(&self) -> &LogData {
        &self.runs[self.nominal]
    }
    /// A log by name (a run or `validation`).
    pub fn log_named(&self, name: &str) -> Option<&LogData> {
        self.runs
            .iter()
            .chain(self.validation.iter())
            .find(|l| l.name == name)
    }
    /// The identified discrete model G0.
    pub fn model(&self) -> &StateSpace {
        &self.ident.model
    }
}

/// SHA-256 of `bytes` as lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    let d = Sha256::digest(bytes);
    let mut s = String::with_capacity(64);
    for b in d.iter() {
        s.push_str(&format!("{b:02x}"));
    }
    s
}

fn display_path(p: &Path) -> String {
    p.to_string_lossy().replace('\\', "/")
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

/// Modes of a discrete model: each real pole once, each complex pair once (Im z > 0), sorted
/// by natural frequency. Poles at z <= 0 on the real axis have no continuous equivalent and
/// are skipped (listed in the model's poles).
pub fn modes_of(model: &StateSpace) -> Result<Vec<Mode>> {
    let ts = model.ts;
    let mut out = Vec::new();
    for z in model.poles()? {
        if z.im < 0.0 || (z.im == 0.0 && z.re <= 0.0) {
            continue;
        }
        let s = if ts > 0.0 { z.ln() / ts } else { z };
        let wn = s.norm();
        if !(wn.is_finite() && wn > 0.0) {
            continue;
        }
        out.push(Mode {
            natural_hz: wn / (2.0 * PI),
            damping: -s.re / wn,
            oscillatory: z.im > 0.0,
            z: [z.re, z.im],
        });
    }
    out.sort_by(|a, b| a.natural_hz.total_cmp(&b.natural_hz));
    Ok(out)
}

fn dc_gain_of(model: &StateSpace) -> f64 {
    match model.dc_gain() {
        Ok(g) => g[(0, 0)],
        Err(_) => f64::INFINITY,
    }
}

/// Runs the whole chain on a loaded configuration, one [`stages`] function per stage.
/// `progress` is called with the name of each stage as it starts (for progress displays).
/// Errors: data errors (unreadable or invalid logs, mismatched sample rates; [`Error::Io`],
/// [`Error::Parse`], [`Error::Data`], naming the file), configuration errors naming the
/// pipeline file and key, and numerical failures of identification ([`Error::Numerical`]). A
/// controller that cannot be tuned, an audit that finds nonlinearity or a failing limit is
/// *not* an error: it is a failing receipt.
pub fn run_pipeline(cfg: &LoadedConfig, progress: &dyn Fn(&str)) -> Result<PipelineRun> {
    let c = &cfg.config;
    let names = cfg.run_names();
    progress("ingest");
    let ingested = stages::ingest_all(cfg, &names)?;
    let (runs, validation, inputs) = stages::prepare_logs(cfg, ingested, progress)?;
    let fs = runs[0].log.fs();
    let fc_target = c.control.crossover_hz;
    stages::check_crossover(cfg, fs)?;

    progress("n4sid");
    let nominal = stages::nominal_index(cfg, &names, &runs);
    let ident = stages::identify_nominal(cfg, &runs[nominal])?;
    progress("physical");
    let physical = physical_stage::PhysicalOutcome::of(c.physical.as_ref(), &runs, nominal);
    let model = ident.model.clone();
    let modes = modes_of(&model)?;
    let dc_gain = dc_gain_of(&model);

    progress("validation");
    let (validation_fit, residuals) = stages::validate_nominal(&ident, validation.as_ref())?;

    let mut receipts = Receipts::default();
    progress("audit");
    let audit = stages::audit_runs(cfg, &runs, fc_target)?;
    stages::push_audit_receipts(&mut receipts, audit.as_ref(), &c.audit, fc_target);

    progress("uncertainty");
    let uncertainty = stages::uncertainty(cfg, &model, &runs, validation.as_ref())?;
    let weight = uncertainty.as_ref().ok().map(|u| &u.weight);

    progress("tuning");
    let tuning = stages::tune(c, &model, weight)?;
    receipts.push(stages::controller_design_receipt(
        c,
        tuning.as_ref().map_err(|e| e.0.as_str()),
    ));
    let tuned = tuning.as_ref().ok();

    progress("receipts");
    let fc = tuned.map_or(fc_target, |t| t.design.crossover_hz);
    let cv_min = c
        .receipts
        .cross_validation_fit_min
        .unwrap_or(config::DEFAULT_CV_FIT_MIN);
    let cross_validation =
        stages::cross_validation_of(validation_fit.as_ref(), validation.as_ref(), cv_min);
    let has_cross_validation = cross_validation.is_some();
    let loop_inputs = stages::LoopStageInputs {
        model: &model,
        tuned,
        weight,
        nominal: &runs[nominal],
        fs,
        fc,
        limits: stages::receipt_limits(c, fc),
        cross_validation,
    };
    let (mut loop_report, mut curves) =
        stages::loop_receipts(c, loop_inputs.clone(), &mut receipts)?;
    if !has_cross_validation {
        receipts.push(missing_cross_validation_receipt(cv_min));
    }
    let flags = gap_stage::triggers(
        audit
            .as_ref()
            .is_some_and(|a| a.verdict == crate::robust::audit::Verdict::NotLinear),
        &receipts.receipts,
    );
    let gap = gap_stage::run_gap_stage(
        c.gap.run,
        flags,
        &model,
        runs[nominal].operating_point().as_ref(),
        &runs,
        validation.as_ref(),
        progress,
    );
    let compensation = remedy::remedy(
        remedy::RemedyInputs {
            cfg,
            gap: &gap,
            model: &model,
            tuned,
            envelope: uncertainty.as_ref().ok().map(|u| &u.envelope),
            validation: validation.as_ref(),
            loop_inputs,
        },
        &mut receipts,
        progress,
    )?;
    // `widen_wm`: the re-tuned design replaces the first one downstream.
    let (mut tuning, mut uncertainty, mut fc) = (tuning, uncertainty, fc);
    if let Some(r) = compensation.decision().and_then(|d| d.retuned.as_ref()) {
        if let (Some(t), Some((rep, cur))) = (&r.tuned, &r.loop_report) {
            fc = t.design.crossover_hz;
            tuning = Ok(t.clone());
            uncertainty = Ok(WeightFit {
                envelope: r.envelope.clone(),
                weight: r.weight.clone(),
            });
            (loop_report, curves) = (Some(rep.clone()), Some(cur.clone()));
        }
    }
    progress("control");
    let (control, comparison) = control_methods::run_methods(
        c,
        control_stage::ControlStageInputs {
            model: &model,
            weight: uncertainty.as_ref().ok().map(|u| &u.weight),
            baseline: tuning.as_ref().ok(),
            fs,
            f_first_bin: runs[nominal].etfe.freq_hz.get(1).copied(),
            gap: gap.report(),
            remedy: compensation.decision(),
        },
        &mut receipts,
        &mut fc,
        progress,
    )?;
    progress("done");
    Ok(PipelineRun {
        title: stages::title(cfg),
        config: c.clone(),
        pipeline_file: stages::pipeline_file_entry(cfg),
        inputs,
        runs,
        validation,
        nominal,
        ident,
        modes,
        dc_gain,
        validation_fit,
        residuals,
        audit,
        uncertainty,
        tuning,
        loop_report,
        curves,
        receipts_crossover_hz: fc,
        receipts,
        gap,
        compensation,
        physical,
        control,
        comparison,
    })
}

/// `n` log-spaced frequencies from `lo` to `hi` (inclusive), Hz.
pub fn log_grid(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (a, b) = (lo.ln(), hi.ln());
    (0..n)
        .map(|i| (a + (b - a) * i as f64 / (n.max(2) - 1) as f64).exp())
        .collect()
}

/// Compact number formatting for receipt details (4 significant digits).
pub fn fmt_num(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v == 0.0 {
        "0".into()
    } else if v.abs() >= 1e5 || v.abs() < 1e-3 {
        format!("{v:.3e}")
    } else {
        let digits = (3 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.digits$}")
    }
}

/// Pretty JSON with a trailing newline (non-finite floats become `null`).
pub fn json_pretty<T: Serialize>(v: &T) -> Result<String> {
    let mut s = serde_json::to_string_pretty(v)
        .map_err(|e| Error::Numerical(format!("serialising JSON: {e}")))?;
    s.push('\n');
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_weight_reads_as_the_note_receipts_json_carried() {
        let w = NoWeight::TooFewBins {
            bins: 2,
            family: vec!["low".into(), "validation".into()],
            gate: 0.85,
        };
        assert_eq!(
            w.to_string(),
            "only 2 bins where every family member (low, validation) passes the coherence gate \
             0.85: no uncertainty weight; robust stability is not checked"
        );
        assert_eq!(TuningFailed("no PID".into()).to_string(), "no PID");
    }
}
