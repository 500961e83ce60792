//! The pipeline's stages on logs in memory, one call each, for front ends that hold their logs
//! as arrays (the Python package): the nonlinearity audit, the uncertainty weight W_m, the
//! robust PID and the gap diagnosis — without a `PIPELINE.toml` and without files.
//!
//! Each operation calls the *same stage function* [`super::run_pipeline`] calls (the private
//! `stages` module: `audit_runs`, `uncertainty`, `tune`; [`super::gap_stage`]'s
//! [`crate::gap::diagnose_at_operating_point`]) with a configuration built in memory from
//! [`StageSettings`] — the `[preprocess]`, `[etfe]`, `[audit]`, `[uncertainty]` and `[control]`
//! sections of a pipeline file, with the same defaults and the same validation
//! ([`LoadedConfig::from_text`]) — and returns the section of `receipts.json` the pipeline
//! writes for that stage ([`AuditSummary`], [`WeightSummary`], [`ControllerSummary`],
//! [`GapReport`]). So the same logs and settings give the same numbers as `ferrosid run`, bit
//! for bit (the Python tests compare them on the bundled example).
//!
//! The logs go through [`prepare`] first: every log (runs and validation) is preprocessed
//! with `[preprocess]` and gets its Welch ETFE with `[etfe]`, as the pipeline's ingest stage
//! does after reading the files; a log's `path` stands for its file name in messages.
//!
//! Errors: a setting out of range is [`Error::InvalidArgument`] naming the operation and the
//! key (`control.crossover_hz`, ...) as a pipeline file's error names it; bad samples are
//! [`Error::Data`] naming the log (from [`crate::ops::arrays::log_from_arrays`] and the
//! stages).
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::config::{
    AuditSettings, Control, EtfeSettings, LoadedConfig, LogEntry, PipelineConfig, Preprocess,
    UncertaintySettings,
};
use super::document::{AuditSummary, ControllerSummary, WeightSummary};
use super::{stages, LogData};
use crate::data::{Log, OperatingPoint};
use crate::error::{Error, Result};
use crate::gap::{diagnose_at_operating_point, GapOptions, GapReport};
use crate::lti::{StateSpace, StateSpaceData};
use crate::robust::receipts::{Receipt, Receipts};
use crate::robust::uncertainty::UncertaintyWeight;

/// The sections of a `PIPELINE.toml` the stage operations read, each with the file's defaults
/// when absent (keys and ranges in docs/pipeline-schema.md). `control` is required by
/// [`tune`] only.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageSettings {
    /// `[preprocess]`: offset removal and decimation of every log.
    #[serde(default)]
    pub preprocess: Preprocess,
    /// `[etfe]`: Welch settings and coherence gate, the same for every log.
    #[serde(default)]
    pub etfe: EtfeSettings,
    /// `[audit]`: the audit's thresholds.
    #[serde(default)]
    pub audit: AuditSettings,
    /// `[uncertainty]`: the weight's order, floor, family and assumed levels.
    #[serde(default)]
    pub uncertainty: UncertaintySettings,
    /// `[control]`: the robust PID's requirements.
    #[serde(default)]
    pub control: Option<Control>,
}

/// One log in memory: its run name, the excitation amplitude (input units; `None`: the input
/// RMS after preprocessing, as a `[[runs]]` entry without `amplitude`) and the log as read.
#[derive(Debug, Clone)]
pub struct RunLog {
    /// Run name (unique; not `validation`).
    pub name: String,
    /// Excitation amplitude, input units.
    pub amplitude: Option<f64>,
    /// The log as read (its `path` names it in messages).
    pub log: Log,
}

/// Logs prepared as the pipeline prepares its runs, with the configuration the stages read.
#[derive(Debug, Clone)]
pub struct PreparedLogs {
    /// The configuration (in memory; its `path` is the operation's name).
    pub config: LoadedConfig,
    /// The runs, in the order given.
    pub runs: Vec<LogData>,
    /// The validation log, if any.
    pub validation: Option<LogData>,
}

/// A `[control]` section with only the crossover set, for the stages that do not read the
/// controller's requirements (the configuration's required keys must hold a valid value).
fn neutral_control(crossover_hz: f64) -> Result<Control> {
    Control::deserialize(serde_json::json!({
        "crossover_hz": crossover_hz,
        "actuator_limit": 1.0,
    }))
    .map_err(|e| Error::InvalidArgument(format!("control: {e}")))
}

/// The configuration of `settings` and these logs, validated as a pipeline file is: a setting
/// out of range is [`Error::InvalidArgument`] `"{what}: key `section.key`: ..."`.
fn configure(
    what: &str,
    settings: &StageSettings,
    control: Control,
    runs: &[(String, Option<f64>, PathBuf)],
    validation: Option<&Path>,
) -> Result<LoadedConfig> {
    let entry = |name: Option<String>, amplitude: Option<f64>, file: &Path| LogEntry {
        name,
        file: file.to_path_buf(),
        amplitude,
        input: None,
        output: None,
        time: None,
        fs: None,
    };
    let config = PipelineConfig {
        name: None,
        output_dir: None,
        signals: Default::default(),
        runs: runs
            .iter()
            .map(|(n, a, f)| entry(Some(n.clone()), *a, f))
            .collect(),
        validation: validation.map(|f| entry(Some("validation".into()), None, f)),
        preprocess: settings.preprocess.clone(),
        etfe: settings.etfe.clone(),
        identification: Default::default(),
        audit: settings.audit.clone(),
        uncertainty: settings.uncertainty.clone(),
        control,
        receipts: Default::default(),
        gap: Default::default(),
        compensation: Default::default(),
        physical: None,
    };
    // Validated by the pipeline file's own checks: through its TOML text (no line numbers
    // are reported: the text is not the user's).
    let text = toml::to_string(&config)
        .map_err(|e| Error::InvalidArgument(format!("{what}: settings: {e}")))?;
    let loaded = LoadedConfig::from_text(Path::new(what), &text).map_err(|e| match e {
        Error::Parse { msg, .. } | Error::Data { msg, .. } => {
            Error::InvalidArgument(format!("{what}: {msg}"))
        }
        other => other,
    })?;
    let mut loaded = loaded.without_text();
    loaded.config = config;
    super::control_methods::apply_primary(&mut loaded.config);
    Ok(loaded)
}

/// Preprocesses `runs` and `validation` with `settings.preprocess` and estimates their Welch
/// ETFEs with `settings.etfe`, as the pipeline does after reading its files; `what` names the
/// operation in errors.
///
/// # Errors
/// [`Error::InvalidArgument`] for no run, a reserved or duplicate run name or a setting out of
/// range; [`Error::Data`] naming the log for logs at different sample rates, a log too short
/// for the Welch segment, or one that preprocessing rejects.
pub fn prepare(
    what: &str,
    settings: &StageSettings,
    runs: Vec<RunLog>,
    validation: Option<Log>,
) -> Result<PreparedLogs> {
    if runs.is_empty() {
        return Err(Error::InvalidArgument(format!(
            "{what}: no run: give at least one log"
        )));
    }
    let entries: Vec<(String, Option<f64>, PathBuf)> = runs
        .iter()
        .map(|r| (r.name.clone(), r.amplitude, r.log.path.clone()))
        .collect();
    let control = match &settings.control {
        Some(c) => c.clone(),
        None => neutral_control(1.0)?,
    };
    let cfg = configure(
        what,
        settings,
        control,
        &entries,
        validation.as_ref().map(|v| v.path.as_path()),
    )?;
    let ts0 = runs[0].log.ts;
    for log in runs.iter().map(|r| &r.log).chain(validation.iter()) {
        if (log.ts - ts0).abs() > 1e-9 * ts0 {
            return Err(Error::Data {
                file: log.path.clone(),
                msg: format!(
                    "sample rate {} Hz differs from {} Hz of `{}`: every log must share one \
                     sample rate (one ETFE grid, one model)",
                    log.fs(),
                    1.0 / ts0,
                    runs[0].log.path.display()
                ),
            });
        }
    }
    let c = &cfg.config;
    let steps = c.preprocess.steps();
    let welch = c.etfe.welch();
    // As the pipeline's `prepare_logs`: preprocessing, the ETFE on the common grid, the
    // amplitude (configured, else the input RMS after preprocessing).
    let prep = |name: String, amplitude: Option<f64>, raw: Log| -> Result<LogData> {
        stages::prepare_log(name, amplitude, raw, &steps, &welch)
    };
    let runs = runs
        .into_iter()
        .map(|r| prep(r.name, r.amplitude, r.log))
        .collect::<Result<Vec<_>>>()?;
    let validation = validation
        .map(|v| prep("validation".into(), None, v))
        .transpose()?;
    Ok(PreparedLogs {
        config: cfg,
        runs,
        validation,
    })
}

/// The dual-amplitude nonlinearity audit of the runs' ETFEs around `crossover_hz`, with the
/// `[audit]` thresholds (the pipeline's audit stage): the `audit` section of `receipts.json`
/// and the audit's three receipts.
///
/// # Errors
/// [`Error::InvalidArgument`] with fewer than two runs, or a crossover that is not below the
/// logs' Nyquist frequency or not finite and positive.
pub fn audit(p: &PreparedLogs, crossover_hz: f64) -> Result<(AuditSummary, Vec<Receipt>)> {
    let what = p.config.path.display().to_string();
    if p.runs.len() < 2 {
        return Err(Error::InvalidArgument(format!(
            "{what}: the audit overlays two or more runs at different amplitudes; got {}",
            p.runs.len()
        )));
    }
    if !(crossover_hz.is_finite() && crossover_hz > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "{what}: key `control.crossover_hz`: must be finite and > 0, got {crossover_hz}"
        )));
    }
    let mut cfg = p.config.clone();
    cfg.config.control = neutral_control(crossover_hz)?;
    stages::check_crossover(&cfg, p.runs[0].log.fs()).map_err(as_argument(&what))?;
    let a = stages::audit_runs(&cfg, &p.runs, crossover_hz)?
        .ok_or_else(|| Error::InvalidArgument(format!("{what}: the audit did not run")))?;
    let mut receipts = Receipts::default();
    stages::push_audit_receipts(&mut receipts, Some(&a), &cfg.config.audit, crossover_hz);
    let summary = AuditSummary::from(&a);
    Ok((summary, receipts.receipts))
}

/// The multiplicative uncertainty weight W_m of the `[uncertainty]` family (default: every run
/// and the validation log) around `model` (discrete, at the logs' sample time; the pipeline's
/// uncertainty stage): the `uncertainty_weight` section of `receipts.json` and the weight
/// itself (for [`tune`]).
///
/// # Errors
/// [`Error::InvalidArgument`] for a model that is not discrete at the logs' sample time or not
/// SISO; [`Error::Data`] when fewer than three bins pass the coherence gate for every family
/// member (the pipeline's "no uncertainty weight" note); fitting errors.
pub fn fit_weight(
    p: &PreparedLogs,
    model: &StateSpace,
) -> Result<(WeightSummary, UncertaintyWeight)> {
    let what = p.config.path.display().to_string();
    check_model(&what, model, Some(p.runs[0].log.ts))?;
    let fit = stages::uncertainty(&p.config, model, &p.runs, p.validation.as_ref())?;
    let (e, w) = match fit {
        Ok(u) => (u.envelope, u.weight),
        Err(why) => {
            return Err(Error::Data {
                file: PathBuf::from(&what),
                msg: why.to_string(),
            })
        }
    };
    let summary = WeightSummary::new(&w, &e);
    Ok((summary, w))
}

/// The robust PID of `model` (discrete) against `control` (the `[control]` section) and the
/// weight `weight` (‖W_m T‖∞ < 1 when given; the pipeline's tuning stage): the `controller`
/// section of `receipts.json`. `what` names the operation in errors.
///
/// # Errors
/// [`Error::InvalidArgument`] for a setting out of range, a crossover at or above the model's
/// Nyquist frequency or a model that is not discrete and SISO; [`Error::Numerical`] when no
/// controller meets the requirements (the pipeline's failing `controller_design` receipt,
/// with its reason).
pub fn tune(
    what: &str,
    model: &StateSpace,
    weight: Option<&UncertaintyWeight>,
    control: &Control,
) -> Result<ControllerSummary> {
    check_model(what, model, None)?;
    let cfg = configure(
        what,
        &StageSettings::default(),
        control.clone(),
        &[("model".into(), None, "model".into())],
        None,
    )?;
    stages::check_crossover(&cfg, 1.0 / model.ts).map_err(as_argument(what))?;
    match stages::tune(&cfg.config, model, weight)? {
        Ok(t) => Ok(ControllerSummary {
            pid: t.pid,
            discrete: t.discrete.clone(),
            design: t.design,
            target_crossover_hz: t.target_crossover_hz,
            method: t.method.clone(),
        }),
        Err(why) => Err(Error::Numerical(format!(
            "{what}: no controller meets the requirements: {why}"
        ))),
    }
}

/// The sim-to-real gap diagnosis of `model` (with its operating point `op`, as `model.json`
/// carries it) against the training logs `train` and the validation log `validate`, as read:
/// what the pipeline's gap stage and `ferrosid gap` do ([`diagnose_at_operating_point`]; a
/// continuous model is discretised by zero-order hold at the logs' rate, a discrete one must
/// be at it). Returns the report (`ferrosid gap --json`; the pipeline's
/// `gap_diagnosis.report`).
///
/// # Errors
/// As `ferrosid gap`: [`Error::Data`] for a model that is not SISO, not at the logs' rate or
/// not stable; the diagnosis's errors.
pub fn gap(
    what: &str,
    model: &StateSpace,
    op: Option<&OperatingPoint>,
    train: &[Log],
    validate: &Log,
    opts: &GapOptions,
) -> Result<GapReport> {
    if train.is_empty() {
        return Err(Error::InvalidArgument(format!(
            "{what}: no training log: give at least one"
        )));
    }
    let factor = op.map_or(1, |o| o.decimation).max(1);
    let sim = crate::gap::simfile::discretise_for_logs(
        model,
        validate.ts * factor as f64,
        Path::new(what),
    )?;
    Ok(diagnose_at_operating_point(&sim, op, None, train, validate, opts)?.report)
}

/// A model from JSON text as `ferrosid gap` and `ferrosid codegen` read a model file
/// (`{"a", "b", "c", "d", "ts"}` with an optional `operating_point`, or `{"num", "den",
/// "ts"}`), with its operating point; `name` names it in errors.
///
/// # Errors
/// [`Error::Parse`] / [`Error::Data`] naming `name` for invalid JSON or matrices.
pub fn model_from_json(text: &str, name: &str) -> Result<(StateSpace, Option<OperatingPoint>)> {
    let sys = crate::gap::simfile::parse_sim(text, Path::new(name))?;
    let op = serde_json::from_str::<serde_json::Value>(text)
        .ok()
        .filter(|v| v.get("a").is_some())
        .and_then(|v| serde_json::from_value::<StateSpaceData>(v).ok())
        .and_then(|ss| ss.operating_point);
    Ok((sys, op))
}

/// A SISO discrete model (at sample time `ts` when given).
fn check_model(what: &str, model: &StateSpace, ts: Option<f64>) -> Result<()> {
    if !model.is_siso() {
        return Err(Error::InvalidArgument(format!(
            "{what}: the model has {} input(s) and {} output(s); the stage is SISO",
            model.n_inputs(),
            model.n_outputs()
        )));
    }
    if !model.is_discrete() {
        return Err(Error::InvalidArgument(format!(
            "{what}: the model is continuous (ts = 0); give the discrete model identified from \
             the logs"
        )));
    }
    if let Some(ts) = ts {
        if (model.ts - ts).abs() > 1e-9 * ts {
            return Err(Error::InvalidArgument(format!(
                "{what}: the model is discrete with ts = {} s but the logs are sampled at ts = \
                 {ts} s",
                model.ts
            )));
        }
    }
    Ok(())
}

/// A configuration error of an in-memory configuration as a plain argument error.
fn as_argument(what: &str) -> impl Fn(Error) -> Error + '_ {
    move |e| match e {
        Error::Parse { msg, .. } | Error::Data { msg, .. } => {
            Error::InvalidArgument(format!("{what}: {msg}"))
        }
        other => other,
    }
}
