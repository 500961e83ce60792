//! `frf` and `identify`: logs from numpy arrays ([`ferrosid::ops::arrays::log_from_arrays`],
//! the file readers' checks), then [`ferrosid::ops::frf::estimate`] and
//! [`ferrosid::ops::identify::identify`] — the functions `ferrosid frf` and `ferrosid
//! identify` call — and their reports as the CLI's `--json` text.
use crate::{json_text, run_released, UsageError};
use ferrosid::n4sid::options::{N4sidOptions, OrderSelection, Weighting};
use ferrosid::ops::frf::FrfOptions;
use ferrosid::ops::identify::IdentifyOptions;
use ferrosid::ops::NoProgress;
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::collections::BTreeMap;

/// One log as the Python package passes it: (source name, sample time in seconds, inputs,
/// outputs), each channel (name, 1-D float64 array).
pub(crate) type LogArg<'py> = (
    String,
    f64,
    Vec<(String, PyReadonlyArray1<'py, f64>)>,
    Vec<(String, PyReadonlyArray1<'py, f64>)>,
);

/// The samples of the channels, copied out of numpy (contiguous or not).
fn copy_channels(ch: &[(String, PyReadonlyArray1<'_, f64>)]) -> Vec<(String, Vec<f64>)> {
    ch.iter()
        .map(|(n, a)| (n.clone(), a.as_array().iter().copied().collect()))
        .collect()
}

/// Copies every log's samples (with the GIL held), to be checked and used without it.
pub(crate) struct OwnedLog {
    source: String,
    ts_s: f64,
    inputs: Vec<(String, Vec<f64>)>,
    outputs: Vec<(String, Vec<f64>)>,
}

impl OwnedLog {
    pub(crate) fn of(l: &LogArg<'_>) -> Self {
        OwnedLog {
            source: l.0.clone(),
            ts_s: l.1,
            inputs: copy_channels(&l.2),
            outputs: copy_channels(&l.3),
        }
    }

    pub(crate) fn into_log(self) -> ferrosid::Result<ferrosid::data::Log> {
        ferrosid::ops::arrays::log_from_arrays(&self.source, self.ts_s, self.inputs, self.outputs)
    }
}

/// Options given as a dict (keyword arguments of the Python function), read into a library
/// options type with unknown keys refused.
pub(crate) fn options<T: serde::de::DeserializeOwned>(
    py: Python<'_>,
    what: &str,
    opts: Option<&Bound<'_, PyDict>>,
) -> PyResult<T> {
    let empty = PyDict::new(py);
    let d = opts.unwrap_or(&empty);
    pythonize::depythonize::<T>(d.as_any()).map_err(|e| UsageError::new_err(format!("{what}: {e}")))
}

/// Empirical frequency response (Welch H1 or period-synchronous) of `logs`: the JSON of
/// `ferrosid frf --json`. `options`: the fields of `FrfOptions` (nperseg, overlap, window,
/// detrend, period, skip_periods, gate).
#[pyfunction]
#[pyo3(signature = (logs, options=None))]
pub fn frf(
    py: Python<'_>,
    logs: Vec<LogArg<'_>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<String> {
    let opts: FrfOptions = self::options(py, "frf options", options)?;
    let owned: Vec<OwnedLog> = logs.iter().map(OwnedLog::of).collect();
    run_released(py, move || {
        let logs = owned
            .into_iter()
            .map(OwnedLog::into_log)
            .collect::<ferrosid::Result<Vec<_>>>()?;
        let report = ferrosid::ops::frf::estimate(&logs, &opts, &NoProgress)?;
        json_text(&report)
    })
}

fn parse_enum<T: serde::de::DeserializeOwned>(what: &str, v: &str) -> PyResult<T> {
    serde_json::from_value(serde_json::Value::String(v.into()))
        .map_err(|_| UsageError::new_err(format!("{what} {v:?} is not one of the accepted values")))
}

/// N4SID identification with order selection and validation: the JSON of `ferrosid identify
/// --json`. The keyword arguments are the CLI's flags with the same defaults.
#[pyfunction]
#[pyo3(signature = (logs, validate=None, *, order=None, order_range=None, block_rows=20,
    no_d=false, d_auto=false, stable_margin=None, weighting="moesp", remove="mean",
    decimate=None, crossover_hz=None, phase_tol=None, max_lag=25, etfe=None, structure=None,
    known=None))]
#[allow(clippy::too_many_arguments)]
pub fn identify(
    py: Python<'_>,
    logs: Vec<LogArg<'_>>,
    validate: Option<LogArg<'_>>,
    order: Option<usize>,
    order_range: Option<(usize, usize)>,
    block_rows: usize,
    no_d: bool,
    d_auto: bool,
    stable_margin: Option<f64>,
    weighting: &str,
    remove: &str,
    decimate: Option<usize>,
    crossover_hz: Option<f64>,
    phase_tol: Option<f64>,
    max_lag: usize,
    etfe: Option<&Bound<'_, PyDict>>,
    structure: Option<String>,
    known: Option<BTreeMap<String, f64>>,
) -> PyResult<String> {
    let order = match (order, order_range) {
        (Some(0), _) => return Err(UsageError::new_err("--order must be >= 1")),
        (Some(n), _) => OrderSelection::Fixed(n),
        (None, Some((min, max))) => OrderSelection::Range { min, max },
        (None, None) => OrderSelection::Auto,
    };
    let weighting = match weighting {
        "moesp" => Weighting::Moesp,
        "cva" => Weighting::Cva,
        w => {
            return Err(UsageError::new_err(format!(
                "weighting {w:?}: expected \"moesp\" or \"cva\""
            )))
        }
    };
    let physical = match &structure {
        None => None,
        Some(name) => {
            let s =
                ferrosid::greybox::Structure::parse(name).map_err(|e| crate::to_py_err(py, &e))?;
            let mut g = ferrosid::greybox::GreyBoxOptions::new(s);
            for (k, v) in known.iter().flatten() {
                g = g.with_known(k, *v);
            }
            Some(g)
        }
    };
    let opts = IdentifyOptions {
        n4sid: N4sidOptions {
            block_rows,
            order,
            weighting,
            estimate_d: !no_d,
            d_significance: d_auto.then_some(2.0),
            stability_margin: stable_margin,
            ..N4sidOptions::default()
        },
        remove: parse_enum("remove", remove)?,
        decimate,
        crossover_hz,
        phase_tol_deg: phase_tol.unwrap_or(IdentifyOptions::default().phase_tol_deg),
        max_lag,
        etfe: self::options(py, "etfe options", etfe)?,
        closed_loop: None,
        physical,
    };
    let owned: Vec<OwnedLog> = logs.iter().map(OwnedLog::of).collect();
    let vowned = validate.as_ref().map(OwnedLog::of);
    run_released(py, move || {
        let logs = owned
            .into_iter()
            .map(OwnedLog::into_log)
            .collect::<ferrosid::Result<Vec<_>>>()?;
        let vlog = vowned.map(OwnedLog::into_log).transpose()?;
        let report = ferrosid::ops::identify::identify(&logs, vlog.as_ref(), &opts, &NoProgress)?;
        json_text(&report)
    })
}

/// A log read from a file with the command line's readers and checks (CSV, `.mat`, text):
/// (sample time in seconds, inputs, outputs, reader warnings), each channel (name, samples).
/// The arguments are the CLI's `--input`, `--output`, `--fs`, `--time`, `--time-scale`.
#[pyfunction]
#[pyo3(signature = (path, inputs, outputs, fs=None, time=None, time_scale=None))]
#[allow(clippy::type_complexity)]
pub fn read_log<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    inputs: Vec<String>,
    outputs: Vec<String>,
    fs: Option<f64>,
    time: Option<String>,
    time_scale: Option<f64>,
) -> PyResult<(
    f64,
    Vec<(String, Bound<'py, PyArray1<f64>>)>,
    Vec<(String, Bound<'py, PyArray1<f64>>)>,
    Vec<String>,
)> {
    let spec = ferrosid::io::LogSpec {
        inputs,
        outputs,
        time,
        time_scale,
        fs,
        ..Default::default()
    };
    let log = run_released(py, || ferrosid::io::read_log(&path, &spec))?;
    let arrays = |ch: Vec<ferrosid::data::Channel>| {
        ch.into_iter()
            .map(|c| (c.name, PyArray1::from_vec(py, c.data)))
            .collect::<Vec<_>>()
    };
    Ok((
        log.ts,
        arrays(log.inputs),
        arrays(log.outputs),
        log.warnings,
    ))
}
