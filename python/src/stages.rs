//! `audit`, `fit_wm`, `tune_pid` and `gap` on logs in memory: the pipeline's stage functions
//! through [`ferrosid::pipeline::arrays`] (the same calls `ferrosid run` makes, with the
//! settings of a pipeline file's sections given as dicts), and the gap diagnosis with the
//! options of `ferrosid gap` ([`ferrosid::cli::gap::Args::options`]). Each returns the
//! section of `receipts.json` the pipeline writes for the stage, as JSON text.
use crate::ops::{options, LogArg, OwnedLog};
use crate::{json_text, run_released, UsageError};
use ferrosid::pipeline::arrays::{self, RunLog, StageSettings};
use ferrosid::pipeline::config::Control;
use ferrosid::robust::uncertainty::UncertaintyWeight;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// One run as the Python package passes it: (run name, amplitude or None, log).
pub(crate) type RunArg<'py> = (String, Option<f64>, LogArg<'py>);

/// The runs and the validation log copied out of numpy (with the GIL), to be checked and
/// prepared without it.
struct OwnedRuns {
    runs: Vec<(String, Option<f64>, OwnedLog)>,
    validation: Option<OwnedLog>,
}

impl OwnedRuns {
    fn of(runs: &[RunArg<'_>], validation: Option<&LogArg<'_>>) -> Self {
        OwnedRuns {
            runs: runs
                .iter()
                .map(|(n, a, l)| (n.clone(), *a, OwnedLog::of(l)))
                .collect(),
            validation: validation.map(OwnedLog::of),
        }
    }

    fn prepare(
        self,
        what: &str,
        settings: &StageSettings,
    ) -> ferrosid::Result<arrays::PreparedLogs> {
        let runs = self
            .runs
            .into_iter()
            .map(|(name, amplitude, l)| {
                Ok(RunLog {
                    name,
                    amplitude,
                    log: l.into_log()?,
                })
            })
            .collect::<ferrosid::Result<Vec<_>>>()?;
        let validation = self.validation.map(OwnedLog::into_log).transpose()?;
        arrays::prepare(what, settings, runs, validation)
    }
}

fn model_of(
    text: &str,
) -> ferrosid::Result<(
    ferrosid::lti::StateSpace,
    Option<ferrosid::data::OperatingPoint>,
)> {
    arrays::model_from_json(text, "model")
}

/// The dual-amplitude nonlinearity audit (the pipeline's audit stage): (the `audit` section of
/// `receipts.json`, the audit's receipts), as JSON text. `settings`: the pipeline file's
/// sections (`preprocess`, `etfe`, `audit`).
#[pyfunction]
#[pyo3(signature = (runs, crossover_hz, settings=None))]
pub fn audit(
    py: Python<'_>,
    runs: Vec<RunArg<'_>>,
    crossover_hz: f64,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<(String, String)> {
    let settings: StageSettings = options(py, "audit settings", settings)?;
    let owned = OwnedRuns::of(&runs, None);
    run_released(py, move || {
        let p = owned.prepare("audit()", &settings)?;
        let (summary, receipts) = arrays::audit(&p, crossover_hz)?;
        Ok((json_text(&summary)?, json_text(&receipts)?))
    })
}

/// The multiplicative uncertainty weight W_m around the model (JSON of a model file) of the
/// runs and the validation log (the pipeline's uncertainty stage): (the `uncertainty_weight`
/// section of `receipts.json`, the weight itself), as JSON text.
#[pyfunction]
#[pyo3(signature = (model, runs, validation=None, settings=None))]
pub fn fit_wm(
    py: Python<'_>,
    model: &str,
    runs: Vec<RunArg<'_>>,
    validation: Option<LogArg<'_>>,
    settings: Option<&Bound<'_, PyDict>>,
) -> PyResult<(String, String)> {
    let settings: StageSettings = options(py, "fit_wm settings", settings)?;
    let owned = OwnedRuns::of(&runs, validation.as_ref());
    let model = model.to_string();
    run_released(py, move || {
        let (sys, _) = model_of(&model)?;
        let p = owned.prepare("fit_wm()", &settings)?;
        let (summary, weight) = arrays::fit_weight(&p, &sys)?;
        Ok((json_text(&summary)?, json_text(&weight)?))
    })
}

/// The robust PID of the model (JSON of a model file) against the `[control]` requirements
/// (`control`: a dict of that section's keys) and the weight (JSON of the weight `fit_wm`
/// returns; none: robust stability is not constrained): the `controller` section of
/// `receipts.json` as JSON text.
#[pyfunction]
#[pyo3(signature = (model, control, weight=None))]
pub fn tune_pid(
    py: Python<'_>,
    model: &str,
    control: &Bound<'_, PyDict>,
    weight: Option<&str>,
) -> PyResult<String> {
    let control: Control = options(py, "tune_pid requirements", Some(control))?;
    let weight: Option<UncertaintyWeight> = weight
        .map(serde_json::from_str)
        .transpose()
        .map_err(|e| UsageError::new_err(format!("tune_pid: the weight is not a W_m: {e}")))?;
    let model = model.to_string();
    run_released(py, move || {
        let (sys, _) = model_of(&model)?;
        json_text(&arrays::tune(
            "tune_pid()",
            &sys,
            weight.as_ref(),
            &control,
        )?)
    })
}

/// The sim-to-real gap diagnosis of the model (JSON of a model file, with its operating
/// point) on the training logs and the validation log as read, with the options of `ferrosid
/// gap` (`--margin`, `--threshold`, `--gate`, `--warmup`, `--nperseg`, `--effects`): the
/// report of `ferrosid gap --json` as JSON text.
#[pyfunction]
#[pyo3(signature = (model, train, validate, *, margin=None, threshold=0.2, gate=None,
    warmup=None, nperseg=None, effects=Vec::new()))]
#[allow(clippy::too_many_arguments)]
pub fn gap(
    py: Python<'_>,
    model: &str,
    train: Vec<LogArg<'_>>,
    validate: LogArg<'_>,
    margin: Option<f64>,
    threshold: f64,
    gate: Option<f64>,
    warmup: Option<usize>,
    nperseg: Option<usize>,
    effects: Vec<String>,
) -> PyResult<String> {
    // The command line's argument struct: its defaults and its checks of the options.
    let args = ferrosid::cli::gap::Args {
        sim: "model".into(),
        real: Vec::new(),
        validate: "validation".into(),
        select: ferrosid::cli::frf::LogArgs {
            inputs: Vec::new(),
            outputs: Vec::new(),
            time: None,
            time_scale: None,
            fs: None,
            fs_var: None,
            time_jitter: ferrosid::io::DEFAULT_TIME_JITTER_REL,
        },
        json: true,
        figures: None,
        margin: margin.unwrap_or(ferrosid::gap::diagnose::DEFAULT_MARGIN),
        threshold,
        gate: gate.unwrap_or(ferrosid::spectral::DEFAULT_COHERENCE_THRESHOLD),
        warmup,
        nperseg,
        effects,
        expect: None,
        decimate: None,
        force: false,
    };
    let opts = args.options().map_err(|e| crate::to_py_err(py, &e))?;
    let train: Vec<OwnedLog> = train.iter().map(OwnedLog::of).collect();
    let validate = OwnedLog::of(&validate);
    let model = model.to_string();
    run_released(py, move || {
        let (sys, op) = model_of(&model)?;
        let train = train
            .into_iter()
            .map(OwnedLog::into_log)
            .collect::<ferrosid::Result<Vec<_>>>()?;
        let validate = validate.into_log()?;
        let report = arrays::gap("gap()", &sys, op.as_ref(), &train, &validate, &opts)?;
        json_text(&report)
    })
}
