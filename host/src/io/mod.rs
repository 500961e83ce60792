//! Log ingestion: CSV with a header ([`csv`]), MATLAB v5 `.mat` ([`mat`]) and headerless
//! whitespace-separated text such as the DaISy `.dat` sets ([`text`]).
//!
//! Every reader returns a [`Log`] that satisfies the invariants documented on that type (equal
//! channel lengths, finite samples, `ts > 0`) or an [`Error`] naming the file and the line
//! (text formats) or variable (`.mat`) at fault. The checks shared by all formats are collected
//! in [`Checks`]:
//!
//! * **Time axis.** A time column/variable must be strictly increasing (else: error naming the
//!   first offending line) and uniform: every interval `dt_k` must satisfy
//!   `|dt_k - ts| <= time_jitter_rel * ts + 64 * eps * max(|t_k|, |t_k+1|)` where
//!   `ts = (t_last - t_first) / (n - 1)`; the default `time_jitter_rel` is `1e-6`. Time columns
//!   printed with few digits (e.g. `%.6f` at 3 kHz) fail this on purpose: pass the sample rate
//!   explicitly instead, or raise the tolerance knowingly.
//! * **Length.** At least [`Checks::min_samples`] samples (default 2). Analyses that need more
//!   call [`require_len`].
//! * **Excitation.** An input channel whose samples are all identical is an error (no
//!   excitation, nothing can be identified).
//! * **Clipping** (warning only, pushed to [`Log::warnings`]): an output channel has a run of at
//!   least [`Checks::clip_run`] (default 4) consecutive samples exactly equal to its maximum or
//!   to its minimum. Quantised but unclipped sensors rarely sit on their extreme value for
//!   several samples in a row; saturated ones do. A constant output is also a warning.
//!
//! Several logs per run: call [`read_log`] once per file.
use std::path::Path;

use crate::data::{Channel, Log};
use crate::error::{Error, Result};

pub mod csv;
pub mod mat;
pub mod text;

pub use self::csv::{read_csv, CsvOptions};
pub use self::mat::{read_mat, MatFile, MatOptions};
pub use self::text::{read_columns, TextOptions};

/// Default relative tolerance on the sample-interval jitter of a time column.
pub const DEFAULT_TIME_JITTER_REL: f64 = 1e-6;
/// Default run length (samples) of identical extreme output values flagged as clipping.
pub const DEFAULT_CLIP_RUN: usize = 4;

/// Plausibility checks applied by every reader (see the module documentation for the rules).
#[derive(Debug, Clone, PartialEq)]
pub struct Checks {
    /// Largest accepted relative deviation of one sample interval from the mean interval
    /// (dimensionless, default [`DEFAULT_TIME_JITTER_REL`] = 1e-6). Also the tolerance used when
    /// both a time column and an explicit sample rate are given and must agree.
    pub time_jitter_rel: f64,
    /// Minimum number of consecutive samples exactly at an output's maximum or minimum that
    /// raises a clipping warning (default [`DEFAULT_CLIP_RUN`] = 4; must be >= 2).
    pub clip_run: usize,
    /// Fewest samples a log may have (default 2, must be >= 1).
    pub min_samples: usize,
}

impl Default for Checks {
    fn default() -> Self {
        Self {
            time_jitter_rel: DEFAULT_TIME_JITTER_REL,
            clip_run: DEFAULT_CLIP_RUN,
            min_samples: 2,
        }
    }
}

impl Checks {
    fn validate(&self) -> Result<()> {
        if !(self.time_jitter_rel.is_finite() && self.time_jitter_rel >= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "time jitter tolerance must be finite and >= 0, got {}",
                self.time_jitter_rel
            )));
        }
        if self.clip_run < 2 {
            return Err(Error::InvalidArgument(format!(
                "clip run length must be >= 2 samples, got {}",
                self.clip_run
            )));
        }
        if self.min_samples < 1 {
            return Err(Error::InvalidArgument(
                "minimum number of samples must be >= 1".into(),
            ));
        }
        Ok(())
    }
}

/// Format-independent description of which signals to read, for [`read_log`].
///
/// Names mean column headers (CSV), variable names (`.mat`) or 1-based column numbers written as
/// text such as `"1"` (headerless text). Empty `inputs`/`outputs` select the format's default:
/// CSV `u` / `y`; text columns 1 / 2; `.mat` has no default (an error asks for names).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LogSpec {
    /// Input channel names (u).
    pub inputs: Vec<String>,
    /// Output channel names (y).
    pub outputs: Vec<String>,
    /// Time column/variable. `None`: CSV uses `t` when the header has it; `.mat` and text use
    /// none.
    pub time: Option<String>,
    /// Seconds per unit of the time column/variable (`None` = 1.0, i.e. seconds; the motor-bench
    /// `time` variable counts microseconds: 1e-6).
    pub time_scale: Option<f64>,
    /// Sample rate in Hz. Required when there is no time column; when both are present they
    /// must agree within [`Checks::time_jitter_rel`].
    pub fs: Option<f64>,
    /// `.mat` only: scalar variable holding the sample rate in Hz (`None`: use `fs` if the file
    /// has such a scalar and neither `fs` nor a time variable was given).
    pub fs_var: Option<String>,
    /// Plausibility checks.
    pub checks: Checks,
}

/// Reads one log, choosing the reader from the file extension (case-insensitive): `.csv` →
/// [`read_csv`], `.mat` → [`read_mat`], `.dat` / `.txt` → [`read_columns`].
pub fn read_log(path: &Path, spec: &LogSpec) -> Result<Log> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "csv" => {
            let mut o = CsvOptions {
                time: spec.time.clone(),
                time_scale: spec.time_scale.unwrap_or(1.0),
                fs: spec.fs,
                checks: spec.checks.clone(),
                ..CsvOptions::default()
            };
            if !spec.inputs.is_empty() {
                o.inputs = spec.inputs.clone();
            }
            if !spec.outputs.is_empty() {
                o.outputs = spec.outputs.clone();
            }
            read_csv(path, &o)
        }
        "mat" => read_mat(
            path,
            &MatOptions {
                inputs: spec.inputs.clone(),
                outputs: spec.outputs.clone(),
                time: spec.time.clone(),
                time_scale: spec.time_scale.unwrap_or(1.0),
                fs: spec.fs,
                fs_var: spec.fs_var.clone(),
                checks: spec.checks.clone(),
            },
        ),
        "dat" | "txt" => {
            if spec.time.is_some() {
                return Err(Error::InvalidArgument(format!(
                    "{}: headerless text logs have no named time column; give the sample rate",
                    path.display()
                )));
            }
            let cols = |names: &[String], default: usize| -> Result<Vec<usize>> {
                if names.is_empty() {
                    return Ok(vec![default]);
                }
                names
                    .iter()
                    .map(|n| {
                        n.trim().parse::<usize>().map_err(|_| {
                            Error::InvalidArgument(format!(
                                "{}: text logs select columns by 1-based number, got `{n}`",
                                path.display()
                            ))
                        })
                    })
                    .collect()
            };
            read_columns(
                path,
                &TextOptions {
                    input_cols: cols(&spec.inputs, 1)?,
                    output_cols: cols(&spec.outputs, 2)?,
                    fs: spec.fs,
                    checks: spec.checks.clone(),
                },
            )
        }
        _ => Err(Error::InvalidArgument(format!(
            "{}: unknown log format `.{ext}`; expected .csv, .mat, .dat or .txt",
            path.display()
        ))),
    }
}

/// Checks that `log` holds at least `needed` samples for `analysis` (e.g. "Welch with
/// nperseg = 1024"); the error names the file, the analysis and both counts.
pub fn require_len(log: &Log, needed: usize, analysis: &str) -> Result<()> {
    if log.len() < needed {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!(
                "too few samples for {analysis}: need at least {needed}, the log has {}",
                log.len()
            ),
        });
    }
    Ok(())
}

/// Where a sample-time decision came from, used by the readers.
pub(crate) enum TimeSource<'a> {
    /// Time stamps in seconds, with a description of where each sample came from for errors
    /// (`loc(k)` names sample k, e.g. "line 12" or "sample 12").
    Stamps {
        t: &'a [f64],
        fs: Option<f64>,
        what: &'a str,
    },
    /// Explicit sample rate only.
    Rate(f64),
}

/// Validates an explicit sample rate.
pub(crate) fn check_fs(fs: f64) -> Result<()> {
    if !(fs.is_finite() && fs > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "sample rate must be finite and > 0 Hz, got {fs}"
        )));
    }
    Ok(())
}

/// Derives the sample time (s) from time stamps or a rate, checking monotonicity and uniformity.
/// `loc(k)` turns a 0-based sample index into the caller's error location; errors are made by
/// `err(k, msg)`.
pub(crate) fn sample_time(
    src: TimeSource<'_>,
    checks: &Checks,
    err: &dyn Fn(usize, String) -> Error,
    whole: &dyn Fn(String) -> Error,
) -> Result<f64> {
    match src {
        TimeSource::Rate(fs) => {
            check_fs(fs)?;
            Ok(1.0 / fs)
        }
        TimeSource::Stamps { t, fs, what } => {
            let n = t.len();
            if n < 2 {
                return match fs {
                    Some(fs) => {
                        check_fs(fs)?;
                        Ok(1.0 / fs)
                    }
                    None => Err(whole(format!(
                        "a single sample in {what} does not define a sample time; give fs"
                    ))),
                };
            }
            for k in 0..n - 1 {
                if t[k + 1] <= t[k] {
                    return Err(err(
                        k + 1,
                        format!(
                            "{what} is not strictly increasing: {} follows {}",
                            t[k + 1],
                            t[k]
                        ),
                    ));
                }
            }
            let ts = (t[n - 1] - t[0]) / (n - 1) as f64;
            if !(ts.is_finite() && ts > 0.0) {
                return Err(whole(format!(
                    "{what} gives an unusable sample time {ts} s"
                )));
            }
            for k in 0..n - 1 {
                let dt = t[k + 1] - t[k];
                let tol = checks.time_jitter_rel * ts
                    + 64.0 * f64::EPSILON * t[k].abs().max(t[k + 1].abs());
                if (dt - ts).abs() > tol {
                    return Err(err(
                        k + 1,
                        format!(
                            "non-uniform sampling in {what}: interval {dt:e} s, mean interval \
                             {ts:e} s (relative deviation {:.3e} exceeds the tolerance {:e}); \
                             if the time stamps are rounded, give the sample rate instead",
                            (dt - ts).abs() / ts,
                            checks.time_jitter_rel
                        ),
                    ));
                }
            }
            if let Some(fs) = fs {
                check_fs(fs)?;
                let rel = (ts * fs - 1.0).abs();
                if rel > checks.time_jitter_rel.max(1e-12) {
                    return Err(whole(format!(
                        "{what} implies fs = {} Hz but fs = {fs} Hz was given",
                        1.0 / ts
                    )));
                }
            }
            Ok(ts)
        }
    }
}

/// Final checks shared by all readers: length, excitation, clipping warnings. Builds the [`Log`].
pub(crate) fn finish_log(
    path: &Path,
    ts: f64,
    inputs: Vec<Channel>,
    outputs: Vec<Channel>,
    checks: &Checks,
) -> Result<Log> {
    let data_err = |msg: String| Error::Data {
        file: path.to_path_buf(),
        msg,
    };
    if inputs.is_empty() || outputs.is_empty() {
        return Err(data_err(
            "a log needs at least one input and one output channel".into(),
        ));
    }
    let n = inputs[0].data.len();
    for c in inputs.iter().chain(outputs.iter()) {
        if c.data.len() != n {
            return Err(data_err(format!(
                "channel `{}` has {} samples but `{}` has {n}",
                c.name,
                c.data.len(),
                inputs[0].name
            )));
        }
    }
    if n == 0 {
        return Err(data_err("no samples".into()));
    }
    if n < checks.min_samples {
        return Err(data_err(format!(
            "too few samples: {n}, at least {} required",
            checks.min_samples
        )));
    }
    let mut warnings = Vec::new();
    for c in &inputs {
        if is_constant(&c.data) && n > 1 {
            return Err(data_err(format!(
                "input `{}` is constant ({}) over all {n} samples: no excitation, nothing to \
                 identify",
                c.name, c.data[0]
            )));
        }
    }
    for c in &outputs {
        if n > 1 && is_constant(&c.data) {
            warnings.push(format!(
                "output `{}` is constant ({}) over all {n} samples: sensor disconnected?",
                c.name, c.data[0]
            ));
        } else if let Some(w) = clip_warning(&c.name, &c.data, checks.clip_run) {
            warnings.push(w);
        }
    }
    Ok(Log {
        path: path.to_path_buf(),
        ts,
        inputs,
        outputs,
        warnings,
    })
}

fn is_constant(x: &[f64]) -> bool {
    x.iter().all(|&v| v == x[0])
}

/// Clipping rule (see module docs): runs of >= `min_run` samples exactly at the max or the min.
pub(crate) fn clip_warning(name: &str, x: &[f64], min_run: usize) -> Option<String> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in x {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    let mut parts = Vec::new();
    for (label, ext) in [("maximum", hi), ("minimum", lo)] {
        let (mut runs, mut samples, mut longest, mut cur) = (0usize, 0usize, 0usize, 0usize);
        let mut close = |cur: usize| {
            if cur >= min_run {
                runs += 1;
                samples += cur;
                longest = longest.max(cur);
            }
        };
        for &v in x {
            if v == ext {
                cur += 1;
            } else {
                close(cur);
                cur = 0;
            }
        }
        close(cur);
        if runs > 0 {
            parts.push(format!(
                "{samples} samples in {runs} run(s) of >= {min_run} (longest {longest}) sit at \
                 the {label} {ext}"
            ));
        }
    }
    if parts.is_empty() {
        None
    } else {
        Some(format!(
            "output `{name}` looks clipped/saturated: {}",
            parts.join("; ")
        ))
    }
}
