//! Log ingestion: CSV with a header ([`csv`]), MATLAB v5 `.mat` ([`mat`]) and headerless
//! whitespace-separated text such as the DaISy `.dat` sets ([`text`]).
//!
//! Every reader returns a [`Log`] that satisfies the invariants documented on that type (equal
//! channel lengths, finite samples, `ts > 0`) or an [`Error`] naming the file and the line
//! (text formats) or variable (`.mat`) at fault. The checks shared by all formats are collected
//! in [`Checks`]:
//!
//! * **Time axis.** A time column/variable must be strictly increasing (else: error naming the
//!   first offending line) and uniform: with `m` the median interval, every interval `dt_k`
//!   must satisfy `|dt_k - m| <= time_jitter_rel * m + 64 * eps * max(|t_k|, |t_k+1|)`; the
//!   default `time_jitter_rel` is `1e-3` ([`DEFAULT_TIME_JITTER_REL`]), which accepts the
//!   rounding of time vectors printed to 6–9 digits. **Printed rounding** (CSV): stamps that
//!   fail the interval rule are still accepted when some uniform grid `a + k T` passes within
//!   `r_k + time_jitter_rel * T` of every stamp `t_k`, where `r_k` is the stamp's rounding as
//!   printed (half a unit in the last digit of its column's format, capped at
//!   [`MAX_PRINTED_ROUNDING_REL`]` * T`; rules in `printed.rs`) — so a long log whose stamps
//!   were written with 9 significant digits at t = 1000 s is read, while a dropped, doubled or
//!   shifted sample is still refused. The sample time is then the mean interval
//!   `(t_last - t_first) / (n - 1)` (rounding averages out). A log that fails names the line
//!   and the two options that fix it: a larger tolerance, or an explicit sample rate.
//! * **Explicit sample rate with a time column.** The rate takes precedence: the log uses
//!   `1/fs`, with a warning when the time column is irregular. The column's mean interval must
//!   still agree with `1/fs` within `max(time_jitter_rel, FS_AGREEMENT_REL)`, else the log is
//!   refused (one of the two is wrong).
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
pub mod file_safety;
pub mod input;
pub mod mat;
mod printed;
pub mod text;

pub use self::csv::{read_csv, CsvOptions};
pub use self::mat::{read_mat, MatFile, MatOptions};
pub use self::text::{read_columns, TextOptions};

/// Default relative tolerance on the sample-interval jitter of a time column (1e-3 of the
/// interval: time vectors printed with 9 significant digits, or accumulated in single
/// precision, carry rounding of 1e-6..2.4e-4 of the interval and must not be refused).
pub const DEFAULT_TIME_JITTER_REL: f64 = 1e-3;
/// Largest relative disagreement between an explicit sample rate and the mean interval of a
/// time column that is accepted (the explicit rate is then used); beyond it one of the two is
/// wrong and the reader refuses the log.
pub const FS_AGREEMENT_REL: f64 = 1e-3;
/// Largest accepted jitter tolerance: beyond half an interval a time column does not describe
/// a uniform sampling at all.
pub const MAX_TIME_JITTER_REL: f64 = 0.5;
/// Largest share of the sample interval that the printed rounding of the time stamps may add
/// to the grid tolerance (see the module documentation): stamps printed more coarsely cannot
/// tell a uniform grid from a dropped sample.
pub const MAX_PRINTED_ROUNDING_REL: f64 = 0.25;
/// Default run length (samples) of identical extreme output values flagged as clipping.
pub const DEFAULT_CLIP_RUN: usize = 4;
/// Smallest `--time-scale` (seconds per unit of a time column) accepted: 1e-300. Below it the
/// stamps' products leave the normal floating-point range (1e-308 made `gap` panic).
pub const MIN_TIME_SCALE: f64 = 1e-300;
/// Largest `--time-scale` accepted: 1e300.
pub const MAX_TIME_SCALE: f64 = 1e300;
/// Smallest sample rate (`--fs`, `fs` of a pipeline or a .mat file) accepted, Hz.
pub const MIN_FS_HZ: f64 = 1e-300;
/// Largest sample rate accepted, Hz.
pub const MAX_FS_HZ: f64 = 1e300;
/// Range of the sample time a log may end up with (from its time column or its rate), s:
/// normal floating-point numbers whose inverse is one too (round 1 made every analysis
/// scale-invariant over it: a log at 1e-300 s per sample identifies like one at 1 ms).
pub const SAMPLE_TIME_RANGE_S: (f64, f64) = (1e-300, 1e300);

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
        if !(0.0..=MAX_TIME_JITTER_REL).contains(&self.time_jitter_rel) {
            return Err(Error::InvalidArgument(format!(
                "time jitter tolerance (--time-jitter) must lie in [0, {MAX_TIME_JITTER_REL}], \
                 got {}",
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
        /// Rounding of each stamp as printed, s (half a unit in its last printed digit);
        /// empty when the stamps are exact binary numbers. Called only when the stamps fail
        /// the interval rule.
        rounding: &'a dyn Fn() -> Vec<f64>,
        fs: Option<f64>,
        what: &'a str,
    },
    /// Explicit sample rate only.
    Rate(f64),
}

/// Validates an explicit sample rate.
pub(crate) fn check_fs(fs: f64) -> Result<()> {
    if !(fs.is_finite() && (MIN_FS_HZ..=MAX_FS_HZ).contains(&fs)) {
        return Err(Error::InvalidArgument(format!(
            "sample rate (--fs) must be a finite number in [{MIN_FS_HZ:e}, {MAX_FS_HZ:e}] Hz, \
             got {}",
            if fs.is_finite() && fs != 0.0 {
                format!("{fs:e}")
            } else {
                format!("{fs}")
            }
        )));
    }
    Ok(())
}

/// Derives the sample time (s) from time stamps or a rate, checking monotonicity and uniformity
/// (rules in the module documentation). `err(k, msg)` makes the error for 0-based sample `k`,
/// `whole(msg)` one about the whole time axis. Returns the sample time and, when an explicit
/// sample rate overrides an irregular time column, a warning saying so.
pub(crate) fn sample_time(
    src: TimeSource<'_>,
    checks: &Checks,
    err: &dyn Fn(usize, String) -> Error,
    whole: &dyn Fn(String) -> Error,
) -> Result<(f64, Option<String>)> {
    let stamped = matches!(src, TimeSource::Stamps { .. });
    let (ts, warning) = sample_time_unchecked(src, checks, err, whole)?;
    let (lo, hi) = SAMPLE_TIME_RANGE_S;
    if !(ts.is_finite() && (lo..=hi).contains(&ts)) {
        return Err(whole(format!(
            "the sample time is {ts:e} s, outside [{lo:e}, {hi:e}] s (sample rate {:e} Hz); {}",
            1.0 / ts,
            if stamped {
                "check the time column's unit and --time-scale (seconds per unit)"
            } else {
                "check --fs"
            }
        )));
    }
    Ok((ts, warning))
}

fn sample_time_unchecked(
    src: TimeSource<'_>,
    checks: &Checks,
    err: &dyn Fn(usize, String) -> Error,
    whole: &dyn Fn(String) -> Error,
) -> Result<(f64, Option<String>)> {
    match src {
        TimeSource::Rate(fs) => {
            check_fs(fs)?;
            Ok((1.0 / fs, None))
        }
        TimeSource::Stamps {
            t,
            rounding,
            fs,
            what,
        } => {
            let n = t.len();
            if n < 2 {
                return match fs {
                    Some(fs) => {
                        check_fs(fs)?;
                        Ok((1.0 / fs, None))
                    }
                    None => Err(whole(format!(
                        "a single sample in {what} does not define a sample time; give fs"
                    ))),
                };
            }
            let mut repeated = 0usize;
            for k in 0..n - 1 {
                // Repeated stamps (rounding at a rate above the printed resolution) are read
                // when a sample rate is given, which then takes precedence (checked below).
                if t[k + 1] == t[k] && fs.is_some() {
                    repeated += 1;
                    continue;
                }
                if t[k + 1] <= t[k] {
                    return Err(err(
                        k + 1,
                        format!(
                            "{what} is not strictly increasing: {} follows {}{}",
                            t[k + 1],
                            t[k],
                            if t[k + 1] == t[k] {
                                " (stamps rounded to fewer digits than the rate needs? give \
                                 the sample rate with --fs, pipeline `fs`, which then takes \
                                 precedence over the time column)"
                            } else {
                                ""
                            }
                        ),
                    ));
                }
            }
            if let (Some(fs), true) = (fs, repeated > 0) {
                check_fs(fs)?;
                let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
                let rel = (mean * fs - 1.0).abs();
                let tol = checks.time_jitter_rel.max(FS_AGREEMENT_REL);
                if rel.is_nan() || rel > tol {
                    return Err(whole(format!(
                        "{what} implies fs = {} Hz but fs = {fs} Hz was given (they differ by \
                         {rel:.2e} relative, more than {tol:e}); drop one of the two",
                        1.0 / mean
                    )));
                }
                return Ok((
                    1.0 / fs,
                    Some(format!(
                        "{what} repeats {repeated} time stamps (rounded to fewer digits than \
                         the rate needs); using the given fs = {fs} Hz instead of the time stamps"
                    )),
                ));
            }
            // Robust interval: the median (a dropped sample or a glitch does not move it).
            // The element at n/2 in total order, as a sort would put it (selection, O(n)).
            let mut dts: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
            let mid = dts.len() / 2;
            let median = *dts.select_nth_unstable_by(mid, f64::total_cmp).1;
            let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
            if !(median.is_finite() && median > 0.0 && mean.is_finite() && mean > 0.0) {
                return Err(whole(format!(
                    "{what} gives an unusable sample time {median} s"
                )));
            }
            let tol_rel = checks.time_jitter_rel;
            let worst = (0..n - 1)
                .map(|k| {
                    let dt = t[k + 1] - t[k];
                    let tol =
                        tol_rel * median + 64.0 * f64::EPSILON * t[k].abs().max(t[k + 1].abs());
                    (k, dt, (dt - median).abs() / tol.max(f64::MIN_POSITIVE))
                })
                .max_by(|a, b| a.2.total_cmp(&b.2));
            let irregular = worst
                .filter(|w| w.2 > 1.0)
                .filter(|_| !printed::on_uniform_grid(t, &rounding(), mean, tol_rel));
            if let Some(fs) = fs {
                check_fs(fs)?;
                // An explicit rate takes precedence over the time column; the column must
                // still describe roughly the same rate (else one of the two is wrong).
                let rel = (mean * fs - 1.0).abs();
                if rel > tol_rel.max(FS_AGREEMENT_REL) {
                    return Err(whole(format!(
                        "{what} implies fs = {} Hz but fs = {fs} Hz was given (they differ by \
                         {:.2e} relative, more than {:e}); drop one of the two",
                        1.0 / mean,
                        rel,
                        tol_rel.max(FS_AGREEMENT_REL)
                    )));
                }
                let warning = irregular.map(|(k, dt, _)| {
                    format!(
                        "{what} is not uniform (interval {dt:e} s after sample {}, median \
                         {median:e} s); using the given fs = {fs} Hz instead of the time stamps",
                        k + 1
                    )
                });
                return Ok((1.0 / fs, warning));
            }
            if let Some((k, dt, _)) = irregular {
                return Err(err(
                    k + 1,
                    format!(
                        "non-uniform sampling in {what}: interval {dt:e} s, median interval \
                         {median:e} s (relative deviation {:.3e} exceeds the tolerance {:e}, \
                         and the stamps are off a uniform grid by more than their printed \
                         rounding); \
                         if the time stamps are rounded or jittered, raise the tolerance \
                         (--time-jitter REL, pipeline `[signals] time_jitter`) or give the sample \
                         rate (--fs HZ, pipeline `fs`), which then takes precedence over the \
                         time column",
                        (dt - median).abs() / median,
                        tol_rel
                    ),
                ));
            }
            // Every interval is within the tolerance of the median: the mean over the whole
            // log is the more precise estimate (rounding errors of the stamps average out).
            Ok((mean, None))
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
