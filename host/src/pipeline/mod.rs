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
pub mod config;
pub mod document;
pub mod gap_stage;

use crate::data::Log;
use crate::error::{Error, Result};
use crate::io::{read_log, LogSpec};
use crate::lti::StateSpace;
use crate::n4sid::{n4sid, N4sidOptions, N4sidResult, OrderSelection};
use crate::preprocess::{preprocess, Preprocessing};
use crate::robust::audit::{audit_nonlinearity, AuditOptions, FrfRun, NonlinearityAudit};
use crate::robust::pid::{implemented_loop, tune_pid, PidTuningSpec, TunedPid};
use crate::robust::receipts::{
    compute_receipts, cross_validation_receipt, etfe_phase_receipt, loop_curves,
    missing_cross_validation_receipt, phase_agreement, Comparison, CrossValidation, EtfeView,
    LoopCurves, Receipt, ReceiptInputs, ReceiptKind, ReceiptLimits, Receipts, ReceiptsReport,
};
use crate::robust::uncertainty::{
    fit_uncertainty_weight, multiplicative_envelope, UncertaintyWeight, WeightFitOptions,
};
use crate::spectral::Etfe;
use crate::validate::{
    residual_test, simulation_fit_log, InitialState, ResidualTest, SimulationFit,
};
use num_complex::Complex64;
use serde::Serialize;
use sha2::{Digest, Sha256};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

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
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
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
    /// The envelope and the weight (None when it could not be formed; see `weight_note`).
    pub envelope: Option<EnvelopeData>,
    /// Fitted multiplicative uncertainty weight.
    pub weight: Option<UncertaintyWeight>,
    /// Why there is no weight, when there is none.
    pub weight_note: Option<String>,
    /// The tuned controller.
    pub tuned: Option<TunedPid>,
    /// Why tuning failed, when it did.
    pub tuning_error: Option<String>,
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
}

impl PipelineRun {
    /// The model file content (`model.json`): G0 with the operating point and preprocessing
    /// of the estimation run ([`crate::operating_point`]).
    pub fn model_file(&self) -> crate::lti::StateSpaceData {
        let mut d = crate::lti::StateSpaceData::from(self.model());
        d.operating_point = self.nominal_run().operating_point();
        d
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

/// Reads one log of the pipeline and records its provenance.
fn ingest(
    cfg: &LoadedConfig,
    key: &str,
    role: &str,
    name: &str,
    entry: &config::LogEntry,
) -> Result<(Log, InputFile)> {
    let s = &cfg.config.signals;
    let path = cfg.resolve(&entry.file);
    let bytes = std::fs::read(&path).map_err(|source| Error::Io {
        file: path.clone(),
        source,
    })?;
    let spec = LogSpec {
        inputs: vec![entry.input.clone().unwrap_or_else(|| s.input.clone())],
        outputs: vec![entry.output.clone().unwrap_or_else(|| s.output.clone())],
        time: entry.time.clone().or_else(|| s.time.clone()),
        time_scale: s.time_scale,
        fs: entry.fs.or(s.fs),
        ..LogSpec::default()
    };
    let mut spec = spec;
    if let Some(j) = s.time_jitter {
        spec.checks.time_jitter_rel = j;
    }
    let log = read_log(&path, &spec).map_err(|e| match e {
        Error::InvalidArgument(m) => cfg.key_error(&format!("{key}.file"), m),
        other => other,
    })?;
    let file = InputFile {
        role: role.into(),
        name: name.into(),
        path: display_path(&entry.file),
        sha256: sha256_hex(&bytes),
        bytes: bytes.len() as u64,
        samples: log.len(),
        fs_hz: log.fs(),
        warnings: log.warnings.clone(),
    };
    Ok((log, file))
}

/// Runs the whole chain on a loaded configuration. `progress` is called with the name of each
/// stage as it starts (for progress displays). Errors: data errors (unreadable or invalid
/// logs, mismatched sample rates; [`Error::Io`], [`Error::Parse`], [`Error::Data`], naming the
/// file), configuration errors naming the pipeline file and key, and numerical failures of
/// identification ([`Error::Numerical`]). A controller that cannot be tuned, an audit that
/// finds nonlinearity or a failing limit is *not* an error: it is a failing receipt.
pub fn run_pipeline(cfg: &LoadedConfig, progress: &dyn Fn(&str)) -> Result<PipelineRun> {
    let c = &cfg.config;
    let names = cfg.run_names();
    let pipeline_file = InputFile {
        role: "pipeline".into(),
        name: cfg
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        path: cfg
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        sha256: sha256_hex(cfg.text.as_bytes()),
        bytes: cfg.text.len() as u64,
        samples: 0,
        fs_hz: 0.0,
        warnings: Vec::new(),
    };
    let title = c.name.clone().unwrap_or_else(|| {
        cfg.path
            .file_stem()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "pipeline".into())
    });

    // 1. Ingest.
    progress("ingest");
    let mut raw = Vec::new();
    let mut inputs = Vec::new();
    for (i, entry) in c.runs.iter().enumerate() {
        let (log, file) = ingest(cfg, &format!("runs[{i}]"), "run", &names[i], entry)?;
        raw.push((names[i].clone(), entry.amplitude, log));
        inputs.push(file);
    }
    let raw_val = match &c.validation {
        Some(v) => {
            let name = v.name.clone().unwrap_or_else(|| "validation".into());
            let (log, file) = ingest(cfg, "validation", "validation", &name, v)?;
            inputs.push(file);
            Some((name, v.amplitude, log))
        }
        None => None,
    };
    let ts0 = raw[0].2.ts;
    for (_, _, log) in raw.iter().chain(raw_val.iter()) {
        if (log.ts - ts0).abs() > 1e-9 * ts0 {
            return Err(Error::Data {
                file: log.path.clone(),
                msg: format!(
                    "sample rate {} Hz differs from {} Hz of `{}`: every log of a pipeline \
                     must share one sample rate (one ETFE grid, one model)",
                    log.fs(),
                    1.0 / ts0,
                    raw[0].2.path.display()
                ),
            });
        }
    }

    // 2. Preprocess, 3. ETFE + coherence.
    progress("preprocess");
    let steps = c.preprocess.steps();
    let welch = c.etfe.welch();
    let prep = |name: String, amp: Option<f64>, log: Log, written: String| -> Result<LogData> {
        let raw = log;
        let (log, mut record) = preprocess(&raw, &steps)?;
        // Record the path as written in the pipeline file, not as resolved from the current
        // directory, so receipts.json does not depend on where `ferrosid run` was started.
        record.source = written;
        let etfe = welch.etfe_log(&log, 0, 0)?;
        let (amplitude, is_rms) = match amp {
            Some(a) => (a, false),
            None => (rms(log.u()), true),
        };
        Ok(LogData {
            name,
            amplitude,
            amplitude_is_rms: is_rms,
            log,
            raw,
            preprocessing: record,
            etfe,
        })
    };
    progress("etfe");
    let mut runs = Vec::new();
    for (i, (name, amp, log)) in raw.into_iter().enumerate() {
        runs.push(prep(name, amp, log, inputs[i].path.clone())?);
    }
    let validation = match raw_val {
        Some((name, amp, log)) => {
            let written = inputs.last().map(|f| f.path.clone()).unwrap_or_default();
            Some(prep(name, amp, log, written)?)
        }
        None => None,
    };
    let fs = runs[0].log.fs();
    let fc_target = c.control.crossover_hz;
    if fc_target >= 0.5 * fs {
        return Err(cfg.key_error(
            "control.crossover_hz",
            format!(
                "{fc_target} Hz is at or above the Nyquist frequency {} Hz of the data",
                0.5 * fs
            ),
        ));
    }

    // 4. N4SID on the estimation run.
    progress("n4sid");
    let nominal = match &c.identification.run {
        Some(r) => names.iter().position(|n| n == r).unwrap_or(0),
        None => {
            let mut best = 0;
            for (i, r) in runs.iter().enumerate() {
                if r.amplitude > runs[best].amplitude {
                    best = i;
                }
            }
            best
        }
    };
    let id = &c.identification;
    let order = match (id.order, id.order_min, id.order_max) {
        (Some(n), _, _) => OrderSelection::Fixed(n),
        (None, None, None) => OrderSelection::Auto,
        (None, lo, hi) => OrderSelection::Range {
            min: lo.unwrap_or(1),
            max: hi.unwrap_or(((id.block_rows - 1).min(20)).max(lo.unwrap_or(1))),
        },
    };
    let opts = N4sidOptions {
        block_rows: id.block_rows,
        order,
        estimate_d: id.estimate_d,
        stability_margin: id.stability_margin,
        ..N4sidOptions::default()
    };
    let ident = n4sid(&runs[nominal].log, &opts).map_err(|e| match e {
        Error::InvalidArgument(m) => cfg.key_error("identification", m),
        other => other,
    })?;
    let model = ident.model.clone();
    let modes = modes_of(&model)?;
    let dc_gain = dc_gain_of(&model);

    // 5. Validation.
    progress("validation");
    let (validation_fit, residuals) = match &validation {
        Some(v) => {
            let fit = simulation_fit_log(&model, &v.log, InitialState::Estimate)?;
            let lag = RESIDUAL_MAX_LAG.min(v.log.len() / 4).max(1);
            let res = residual_test(
                &model,
                ident.kalman_gain.as_ref().map(|k| k.as_ref()),
                &[v.log.u()],
                &[v.log.y()],
                lag,
            )
            .ok();
            (Some(fit), res)
        }
        None => (None, None),
    };

    let mut receipts = Receipts::default();

    // 6. Nonlinearity audit.
    progress("audit");
    let a = &c.audit;
    let audit = if runs.len() >= 2 {
        let frf: Vec<FrfRun> = runs
            .iter()
            .map(|r| FrfRun {
                label: r.name.clone(),
                amplitude: r.amplitude,
                freq_hz: r.etfe.freq_hz.clone(),
                h: r.etfe.h.clone(),
                coherence: r.etfe.coherence.clone(),
            })
            .collect();
        let opts = AuditOptions {
            crossover_hz: fc_target,
            band_factor: a.band_factor,
            max_gain_shift_db: a.max_gain_shift_db,
            max_phase_shift_deg: a.max_phase_shift_deg,
            min_coherence: a.min_coherence,
            coherence_band_factor: a.coherence_band_factor,
        };
        Some(audit_nonlinearity(&frf, &opts).map_err(|e| match e {
            Error::InvalidArgument(m) => cfg.key_error("audit", m),
            other => other,
        })?)
    } else {
        None
    };
    push_audit_receipts(&mut receipts, audit.as_ref(), a, fc_target);

    // 7. Uncertainty weight.
    progress("uncertainty");
    let (envelope, weight, weight_note) = uncertainty(cfg, &model, &runs, validation.as_ref())?;

    // 8. Robust PID tuning.
    progress("tuning");
    let k = &c.control;
    let mut spec = PidTuningSpec::new(fc_target);
    spec.ms_max = k.ms_max;
    spec.weight = weight.clone();
    spec.ks_max = k
        .limit_control_effort
        .then(|| k.actuator_limit / k.reference_amplitude);
    spec.rolloff_ratio = k.rolloff_ratio.map(|r| (r, k.rolloff_zeta));
    spec.integral = k.integral;
    spec.derivative = k.derivative;
    spec.min_crossover_scale = k.min_crossover_scale;
    let (tuned, tuning_error) = match tune_pid(&model, &spec) {
        Ok(t) => (Some(t), None),
        Err(Error::InvalidArgument(m)) | Err(Error::Numerical(m)) => (None, Some(m)),
        Err(e) => return Err(e),
    };
    let min_fc = k.min_crossover_scale * fc_target;
    receipts.push(Receipt::new(
        ReceiptKind::ControllerDesign,
        "achieved design crossover of the robust PID (highest crossover meeting M_s, ‖W_m T‖∞ \
         < 1 and the actuator limit)",
        tuned.as_ref().map_or(f64::NAN, |t| t.design.crossover_hz),
        Comparison::AtLeast,
        min_fc,
        "Hz",
        match (&tuned, &tuning_error) {
            (Some(t), _) => format!(
                "target {} Hz; phase-margin target {:.1} deg, integral ratio {:.3}, lead ratio \
                 {:.3}; {} candidates evaluated",
                fmt_num(fc_target),
                t.design.phase_margin_target_deg,
                t.design.integral_ratio,
                t.design.lead_ratio,
                t.candidates_evaluated
            ),
            (None, Some(e)) => e.clone(),
            (None, None) => String::new(),
        },
    ));

    // 9. Receipts.
    progress("receipts");
    let r = &c.receipts;
    let fc = tuned.as_ref().map_or(fc_target, |t| t.design.crossover_hz);
    let mut limits = ReceiptLimits::for_crossover(fc);
    limits.ms_max = k.ms_max;
    if let Some(v) = r.gain_margin_db_min {
        limits.gain_margin_db_min = v;
    }
    if let Some(v) = r.phase_margin_deg_min {
        limits.phase_margin_deg_min = v;
    }
    if let Some(v) = r.mt_max {
        limits.mt_max = v;
    }
    if let Some(v) = r.disturbance_bandwidth_hz_min {
        limits.disturbance_bandwidth_hz_min = v;
    }
    if let Some(v) = r.overshoot_pct_max {
        limits.overshoot_pct_max = v;
    }
    if let Some(v) = r.settling_time_s_max {
        limits.settling_time_s_max = v;
    }
    if let Some(v) = r.etfe_phase_error_deg_max {
        limits.etfe_phase_error_deg_max = v;
    }
    if let Some(v) = r.etfe_max_freq_factor {
        limits.etfe_max_freq_factor = v;
    }
    let cv_min = r
        .cross_validation_fit_min
        .unwrap_or(config::DEFAULT_CV_FIT_MIN);
    let cross_validation = validation_fit.as_ref().map(|f| CrossValidation {
        fit_percent: f.fit_percent[0],
        limit_percent: cv_min,
        detail: format!(
            "free-run simulation of G0 on `{}` ({} samples), initial state estimated; NRMSE {}",
            validation.as_ref().map_or("", |v| v.name.as_str()),
            validation.as_ref().map_or(0, |v| v.log.len()),
            fmt_num(f.nrmse[0])
        ),
    });
    let nom = &runs[nominal].etfe;
    let gate = nom.gate(c.etfe.coherence_gate);
    let view = EtfeView {
        freq_hz: &nom.freq_hz,
        h: &nom.h,
        gate: Some(&gate),
    };
    let (loop_report, curves) = match &tuned {
        Some(t) => {
            let inp = ReceiptInputs {
                plant: &model,
                pid: &t.pid,
                controller_ts: None,
                crossover_hz: fc,
                weight: weight.as_ref(),
                actuator_limit: k.actuator_limit,
                actuator_unit: &c.signals.input_unit,
                reference_amplitude: k.reference_amplitude,
                etfe: Some(view),
                cross_validation: cross_validation.clone(),
                limits,
                anti_windup: k.anti_windup,
            };
            let rep = compute_receipts(&inp)?;
            for rc in &rep.receipts.receipts {
                receipts.push(rc.clone());
            }
            let (lp, _) = implemented_loop(&model, &t.pid, None, Some(fc))?;
            let nyq = 0.5 * fs;
            let f_lo = (fc / 50.0).min(0.5 * nom.freq_hz.get(1).copied().unwrap_or(fc));
            let grid = log_grid(f_lo, nyq * 0.999, 600);
            let curves = loop_curves(&lp, weight.as_ref(), &grid)?;
            (Some(rep), Some(curves))
        }
        None => {
            // Without a controller the loop receipts cannot be issued (they are absent and the
            // failing `controller_design` receipt says why); the model receipts still are.
            let p = phase_agreement(&model, &view, limits.etfe_max_freq_factor * fc)?;
            receipts.push(etfe_phase_receipt(
                &p,
                limits.etfe_phase_error_deg_max,
                format!(
                    "{} gated bins up to {} Hz (target crossover; no controller)",
                    p.bins_used,
                    fmt_num(p.f_max_hz)
                ),
            ));
            if let Some(cv) = &cross_validation {
                receipts.push(cross_validation_receipt(cv));
            }
            (None, None)
        }
    };
    if cross_validation.is_none() {
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
    progress("done");
    Ok(PipelineRun {
        title,
        config: c.clone(),
        pipeline_file,
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
        envelope,
        weight,
        weight_note,
        tuned,
        tuning_error,
        loop_report,
        curves,
        receipts_crossover_hz: fc,
        receipts,
        gap,
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

fn push_audit_receipts(
    rs: &mut Receipts,
    audit: Option<&NonlinearityAudit>,
    a: &config::AuditSettings,
    fc: f64,
) {
    let Some(au) = audit else {
        rs.push(Receipt::new(
            ReceiptKind::NonlinearityAudit,
            "dual-amplitude nonlinearity audit near crossover",
            f64::NAN,
            Comparison::AtLeast,
            2.0,
            "runs",
            "fewer than two `[[runs]]` at different amplitudes: linearity near crossover was \
             not checked"
                .into(),
        ));
        return;
    };
    let g = &au.worst_gain_shift_db;
    rs.push(Receipt::new(
        ReceiptKind::AuditGainShift,
        "largest gain shift between excitation amplitudes within the audit band",
        g.value.abs(),
        Comparison::AtMost,
        a.max_gain_shift_db,
        "dB",
        format!(
            "{} between `{}` and `{}` at {} Hz; band {}–{} Hz ({} bins); {} flagged band(s)",
            fmt_num(g.value),
            g.run_a,
            g.run_b,
            fmt_num(g.f_hz),
            fmt_num(au.band_hz.0),
            fmt_num(au.band_hz.1),
            au.bins_examined,
            au.shift_bands.len()
        ),
    ));
    let p = &au.worst_phase_shift_deg;
    rs.push(Receipt::new(
        ReceiptKind::AuditPhaseShift,
        "largest phase shift between excitation amplitudes within the audit band",
        p.value.abs(),
        Comparison::AtMost,
        a.max_phase_shift_deg,
        "deg",
        format!(
            "{} deg between `{}` and `{}` at {} Hz",
            fmt_num(p.value),
            p.run_a,
            p.run_b,
            fmt_num(p.f_hz)
        ),
    ));
    let (lo, hi) = (fc / a.coherence_band_factor, fc * a.coherence_band_factor);
    let mut worst = (f64::INFINITY, f64::NAN);
    for b in au.bins.iter().filter(|b| b.f_hz >= lo && b.f_hz <= hi) {
        if b.min_coherence < worst.0 {
            worst = (b.min_coherence, b.f_hz);
        }
    }
    rs.push(Receipt::new(
        ReceiptKind::AuditCoherence,
        "lowest coherence of any run near crossover",
        if worst.0.is_finite() {
            worst.0
        } else {
            f64::NAN
        },
        Comparison::AtLeast,
        a.min_coherence,
        "1",
        if worst.0.is_finite() {
            format!(
                "at {} Hz, window {}–{} Hz; {} coherence drop(s)",
                fmt_num(worst.1),
                fmt_num(lo),
                fmt_num(hi),
                au.coherence_drops.len()
            )
        } else {
            format!(
                "no bin in the coherence window {}–{} Hz",
                fmt_num(lo),
                fmt_num(hi)
            )
        },
    ));
}

type UncertaintyOut = (
    Option<EnvelopeData>,
    Option<UncertaintyWeight>,
    Option<String>,
);

fn uncertainty(
    cfg: &LoadedConfig,
    model: &StateSpace,
    runs: &[LogData],
    validation: Option<&LogData>,
) -> Result<UncertaintyOut> {
    let u = &cfg.config.uncertainty;
    let gate = cfg.config.etfe.coherence_gate;
    let family: Vec<&LogData> = match &u.family {
        Some(names) => names
            .iter()
            .filter_map(|n| {
                if n == "validation" {
                    validation
                } else {
                    runs.iter().find(|l| &l.name == n)
                }
            })
            .collect(),
        None => runs.iter().chain(validation).collect(),
    };
    let grid = &runs[0].etfe.freq_hz;
    let nyq = 0.5 * runs[0].log.fs();
    let ok: Vec<bool> = (0..grid.len())
        .map(|i| {
            grid[i] > 0.0 && grid[i] < nyq && family.iter().all(|m| m.etfe.coherence[i] >= gate)
        })
        .collect();
    let idx: Vec<usize> = (0..grid.len()).filter(|&i| ok[i]).collect();
    if idx.len() < 3 {
        return Ok((
            None,
            None,
            Some(format!(
                "only {} bins where every family member ({}) passes the coherence gate {}: no \
                 uncertainty weight; robust stability is not checked",
                idx.len(),
                family
                    .iter()
                    .map(|m| m.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                gate
            )),
        ));
    }
    let f: Vec<f64> = idx.iter().map(|&i| grid[i]).collect();
    let ev = model.freq_evaluator();
    let mut g0 = Vec::with_capacity(f.len());
    for &fi in &f {
        g0.push(ev.at_rad_s(2.0 * PI * fi)?[(0, 0)]);
    }
    let fam: Vec<Vec<Complex64>> = family
        .iter()
        .map(|m| idx.iter().map(|&i| m.etfe.h[i]).collect())
        .collect();
    let measured_level = multiplicative_envelope(&g0, &fam)?;
    let measured = f.len();
    let f_first = f[0];
    let f_top = f[measured - 1];
    // Below the measured band: one decade at a stated level (default: hold the largest l_m of
    // the lowest measured octave), so the weight is not an unconstrained extrapolation there.
    let below = u.below_band_level.unwrap_or_else(|| {
        f.iter()
            .zip(&measured_level)
            .filter(|(fi, _)| **fi <= 2.0 * f_first)
            .map(|(_, l)| *l)
            .fold(0.0, f64::max)
    });
    let mut freq = Vec::new();
    let mut level = Vec::new();
    for fi in log_grid(f_first / 10.0, f_first, 9).into_iter().take(8) {
        freq.push(fi);
        level.push(below);
    }
    let below_bins = freq.len();
    freq.extend_from_slice(&f);
    level.extend_from_slice(&measured_level);
    // Above the measured band: the unmeasured bins up to Nyquist and two decades beyond (a
    // sampled loop sees the continuous weight up to s = ∞ through the Tustin map).
    if u.beyond_band_level > 0.0 {
        for &fi in grid.iter().filter(|&&fi| fi > f_top && fi < nyq) {
            freq.push(fi);
            level.push(u.beyond_band_level);
        }
        for fi in log_grid(nyq, 100.0 * nyq, 13) {
            freq.push(fi);
            level.push(u.beyond_band_level);
        }
    }
    let w = fit_uncertainty_weight(
        &freq,
        &level,
        &WeightFitOptions {
            order: u.order,
            min_level: u.min_level,
            ..WeightFitOptions::default()
        },
    )?;
    Ok((
        Some(EnvelopeData {
            freq_hz: freq,
            level,
            below: below_bins,
            measured,
            family: family.iter().map(|m| m.name.clone()).collect(),
            f_top_hz: f_top,
        }),
        Some(w),
        None,
    ))
}

/// Pretty JSON with a trailing newline (non-finite floats become `null`).
pub fn json_pretty<T: Serialize>(v: &T) -> Result<String> {
    let mut s = serde_json::to_string_pretty(v)
        .map_err(|e| Error::Numerical(format!("serialising JSON: {e}")))?;
    s.push('\n');
    Ok(s)
}
