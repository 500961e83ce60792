//! `frf` as a library call: empirical frequency response (Welch H1 or period-synchronous
//! averaging) with magnitude-squared coherence and coherence gating, from one or more logs.
//!
//! * Welch (default): the segments of all logs are pooled into one estimate per
//!   (input, output) pair; the logs must share the sample rate and channel layout.
//! * [`FrfOptions::period`]: period-synchronous averaging at the excited lines, one estimate
//!   per log and pair (the noise variance of H comes from the spread over periods).
//!
//! Default segment length ([`FrfOptions::nperseg`] `None`): the largest power of two not above
//! 1/4 of the shortest log, capped at 4096 and at least 8 samples, so that at least 7
//! half-overlapped segments are averaged ([`auto_nperseg`]).
use super::Progress;
use crate::data::Log;
use crate::error::{Error, Result};
use crate::io::require_len;
use crate::spectral::{
    Detrend, Etfe, ExcludedBand, PeriodicAveraging, PeriodicFrf, Welch, WindowName,
    DEFAULT_COHERENCE_THRESHOLD, MAX_NPERSEG, MIN_NPERSEG,
};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// Settings of a frequency-response estimate (`ferrosid frf`, and the validation ETFE of
/// `identify`). Error messages name the options as the command line spells them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FrfOptions {
    /// Welch segment length in samples (resolution fs/N Hz); `None`: [`auto_nperseg`] of the
    /// shortest log.
    pub nperseg: Option<usize>,
    /// Overlap of consecutive Welch segments in samples; `None`: nperseg/2.
    pub overlap: Option<usize>,
    /// Welch data window.
    pub window: WindowName,
    /// Welch per-segment detrending.
    pub detrend: Detrend,
    /// Excitation period in samples: period-synchronous averaging instead of Welch.
    pub period: Option<usize>,
    /// With `period`: leading periods discarded as transient.
    pub skip_periods: usize,
    /// Coherence gate: bins with coherence below this are marked and not used.
    pub gate: f64,
}

impl Default for FrfOptions {
    fn default() -> Self {
        Self {
            nperseg: None,
            overlap: None,
            window: WindowName::Hann,
            detrend: Detrend::Constant,
            period: None,
            skip_periods: 0,
            gate: DEFAULT_COHERENCE_THRESHOLD,
        }
    }
}

impl FrfOptions {
    /// Checks the values: gate in [0, 1], nperseg and period within their ranges.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the option.
    pub fn validate(&self) -> Result<()> {
        if !(self.gate.is_finite() && (0.0..=1.0).contains(&self.gate)) {
            return Err(Error::InvalidArgument(format!(
                "--gate must be a coherence in [0, 1], got {}",
                self.gate
            )));
        }
        if let Some(n) = self.nperseg {
            if !(MIN_NPERSEG..=MAX_NPERSEG).contains(&n) {
                return Err(Error::InvalidArgument(format!(
                    "--nperseg must be in {MIN_NPERSEG}..={MAX_NPERSEG} samples, got {n}"
                )));
            }
        }
        if let Some(p) = self.period {
            if !(2..=MAX_NPERSEG).contains(&p) {
                return Err(Error::InvalidArgument(format!(
                    "--period must be in 2..={MAX_NPERSEG} samples, got {p}"
                )));
            }
        }
        Ok(())
    }

    /// The Welch settings for logs whose shortest has `min_len` samples.
    pub fn welch(&self, min_len: usize) -> Welch {
        Welch {
            nperseg: self.nperseg.unwrap_or_else(|| auto_nperseg(min_len)),
            noverlap: self.overlap,
            window: self.window.into(),
            detrend: self.detrend,
        }
    }

    /// The period-synchronous settings, if [`Self::period`] is set.
    pub fn periodic(&self) -> Option<PeriodicAveraging> {
        self.period.map(|p| PeriodicAveraging {
            skip_periods: self.skip_periods,
            ..PeriodicAveraging::new(p)
        })
    }
}

/// Default Welch segment length: the largest power of two <= `len / 4`, within
/// `MIN_NPERSEG..=4096`.
pub fn auto_nperseg(len: usize) -> usize {
    let target = (len / 4).clamp(MIN_NPERSEG, 4096);
    let mut n = MIN_NPERSEG;
    while n * 2 <= target {
        n *= 2;
    }
    n
}

/// One log as described in reports.
#[derive(Debug, Clone, Serialize)]
pub struct LogSummary {
    /// Path as given.
    pub path: String,
    /// Samples.
    pub samples: usize,
    /// Sample rate, Hz.
    pub fs_hz: f64,
    /// Input channel names.
    pub inputs: Vec<String>,
    /// Output channel names.
    pub outputs: Vec<String>,
    /// Reader warnings (clipping, constant output).
    pub warnings: Vec<String>,
}

impl LogSummary {
    /// Summary of a log.
    pub fn of(log: &Log) -> Self {
        Self {
            path: log.path.display().to_string(),
            samples: log.len(),
            fs_hz: log.fs(),
            inputs: log.inputs.iter().map(|c| c.name.clone()).collect(),
            outputs: log.outputs.iter().map(|c| c.name.clone()).collect(),
            warnings: log.warnings.clone(),
        }
    }
}

/// Estimator description in the JSON output.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum MethodSummary {
    /// Welch H1.
    Welch {
        /// Segment length, samples.
        nperseg: usize,
        /// Overlap, samples.
        noverlap: usize,
        /// Window.
        window: WindowName,
        /// Detrending.
        detrend: Detrend,
        /// Bin spacing, Hz.
        resolution_hz: f64,
    },
    /// Period-synchronous averaging.
    Periodic {
        /// Period, samples.
        period: usize,
        /// Skipped leading periods.
        skip_periods: usize,
    },
}

/// One frequency-response estimate (one input/output pair), columnar.
#[derive(Debug, Clone, Serialize)]
pub struct FrfEstimate {
    /// Input channel name.
    pub input: String,
    /// Output channel name.
    pub output: String,
    /// Log(s) it comes from.
    pub logs: Vec<String>,
    /// Averages: Welch segments or periods.
    pub n_averages: usize,
    /// Bin frequencies, Hz.
    pub freq_hz: Vec<f64>,
    /// Real part of H.
    pub re: Vec<f64>,
    /// Imaginary part of H.
    pub im: Vec<f64>,
    /// 20 log10 |H| (null where H is undefined).
    pub mag_db: Vec<f64>,
    /// Phase of H in degrees, wrapped to (-180, 180].
    pub phase_deg: Vec<f64>,
    /// Magnitude-squared coherence.
    pub coherence: Vec<f64>,
    /// Standard deviation of H (period-synchronous averaging only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_h: Option<Vec<f64>>,
    /// True where the bin passes the gate (coherence >= gate and, for Welch, input power
    /// present; see [`crate::spectral::Etfe::gate`]).
    pub gated: Vec<bool>,
    /// Runs of bins rejected by the gate.
    pub excluded_bands: Vec<ExcludedBand>,
    /// Why bins cannot pass the gate beyond coherence (e.g. too few averages), if anything.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// The JSON document of `ferrosid frf --json`.
#[derive(Debug, Clone, Serialize)]
pub struct FrfReport {
    /// Always "frf".
    pub command: &'static str,
    /// Logs read.
    pub logs: Vec<LogSummary>,
    /// Estimator.
    pub method: MethodSummary,
    /// Coherence gate threshold.
    pub gate: f64,
    /// One estimate per pair (Welch) or per log and pair (periodic).
    pub estimates: Vec<FrfEstimate>,
    /// How the numerics treat signal scale.
    pub normalisation: &'static str,
}

/// What `frf` says about signal scale (also in its JSON report).
pub const NORMALISATION_NOTE: &str = "signals are normalised internally by exact powers of two \
    before the FFTs, so H and coherence do not depend on the signals' units (densities are \
    reported in the log's units)";

/// Magnitude in dB (NaN where H is not finite or zero).
pub fn mag_db(h: Complex64) -> f64 {
    let a = h.norm();
    if a.is_finite() && a > 0.0 {
        20.0 * a.log10()
    } else {
        f64::NAN
    }
}

/// Phase in degrees wrapped to (-180, 180] (NaN where H is not finite).
pub fn phase_deg(h: Complex64) -> f64 {
    if !(h.re.is_finite() && h.im.is_finite()) {
        return f64::NAN;
    }
    let d = h.im.atan2(h.re).to_degrees();
    if d <= -180.0 {
        d + 360.0
    } else {
        d
    }
}

impl FrfEstimate {
    #[allow(clippy::too_many_arguments)]
    fn new(
        input: &str,
        output: &str,
        logs: Vec<String>,
        n_averages: usize,
        freq_hz: &[f64],
        h: &[Complex64],
        coherence: &[f64],
        std_h: Option<Vec<f64>>,
        gated: Vec<bool>,
        excluded_bands: Vec<ExcludedBand>,
    ) -> Self {
        Self {
            input: input.into(),
            output: output.into(),
            logs,
            n_averages,
            freq_hz: freq_hz.to_vec(),
            re: h.iter().map(|z| z.re).collect(),
            im: h.iter().map(|z| z.im).collect(),
            mag_db: h.iter().map(|&z| mag_db(z)).collect(),
            phase_deg: h.iter().map(|&z| phase_deg(z)).collect(),
            coherence: coherence.to_vec(),
            std_h,
            gated,
            excluded_bands,
            notes: Vec::new(),
        }
    }

    fn from_welch(e: &Etfe, input: &str, output: &str, logs: Vec<String>, gate: f64) -> Self {
        let mut est = Self::new(
            input,
            output,
            logs,
            e.n_averages,
            &e.freq_hz,
            &e.h,
            &e.coherence,
            None,
            e.gate(gate),
            e.excluded_bands(gate),
        );
        est.notes.extend(e.too_few_averages());
        est
    }

    fn from_periodic(p: &PeriodicFrf, input: &str, output: &str, log: String, gate: f64) -> Self {
        Self::new(
            input,
            output,
            vec![log],
            p.n_periods,
            &p.freq_hz,
            &p.h,
            &p.coherence,
            Some(p.var_h.iter().map(|v| v.sqrt()).collect()),
            p.gate(gate),
            p.excluded_bands(gate),
        )
    }

    /// Number of bins that pass the gate.
    pub fn n_gated(&self) -> usize {
        self.gated.iter().filter(|&&g| g).count()
    }
}

/// Checks that all logs share the first log's sample rate (relative 1e-9) and channel counts,
/// as pooling requires; the error names the offending file.
pub fn check_compatible(logs: &[Log]) -> Result<()> {
    let Some(first) = logs.first() else {
        return Err(Error::InvalidArgument("no log given".into()));
    };
    for l in &logs[1..] {
        if ((l.ts - first.ts) / first.ts).abs() > 1e-9 {
            return Err(Error::Data {
                file: l.path.clone(),
                msg: format!(
                    "sample rate {} Hz differs from {} Hz of {}; logs pooled together must \
                     share the sample rate",
                    l.fs(),
                    first.fs(),
                    first.path.display()
                ),
            });
        }
        if l.inputs.len() != first.inputs.len() || l.outputs.len() != first.outputs.len() {
            return Err(Error::Data {
                file: l.path.clone(),
                msg: format!(
                    "{} inputs and {} outputs, but {} has {} and {}",
                    l.inputs.len(),
                    l.outputs.len(),
                    first.path.display(),
                    first.inputs.len(),
                    first.outputs.len()
                ),
            });
        }
    }
    Ok(())
}

/// Computes the report of `ferrosid frf` for already-read logs: one pooled Welch estimate
/// per (input, output) pair, or with [`FrfOptions::period`] one period-synchronous estimate
/// per log and pair.
///
/// # Errors
/// [`Error::InvalidArgument`] for options out of range or no log; [`Error::Data`] naming the
/// log whose sample rate or channels differ from the first, or that is too short.
pub fn estimate(logs: &[Log], opts: &FrfOptions, progress: &dyn Progress) -> Result<FrfReport> {
    opts.validate()?;
    check_compatible(logs)?;
    let first = &logs[0];
    let (m, p) = (first.inputs.len(), first.outputs.len());
    let mut estimates = Vec::new();
    let method;
    if let Some(per) = opts.periodic() {
        method = MethodSummary::Periodic {
            period: per.period,
            skip_periods: per.skip_periods,
        };
        progress.begin("period-synchronous FRF", Some((logs.len() * m * p) as u64));
        for log in logs {
            for j in 0..m {
                for i in 0..p {
                    let r = per.frf_log(log, j, i)?;
                    estimates.push(FrfEstimate::from_periodic(
                        &r,
                        &log.inputs[j].name,
                        &log.outputs[i].name,
                        log.path.display().to_string(),
                        opts.gate,
                    ));
                    progress.advance(1);
                }
            }
        }
        progress.end();
    } else {
        let min_len = logs.iter().map(Log::len).min().unwrap_or(0);
        let welch = opts.welch(min_len);
        for log in logs {
            require_len(
                log,
                welch.nperseg,
                &format!("Welch with nperseg = {}", welch.nperseg),
            )?;
        }
        method = MethodSummary::Welch {
            nperseg: welch.nperseg,
            noverlap: welch.overlap(),
            window: opts.window,
            detrend: opts.detrend,
            resolution_hz: first.fs() / welch.nperseg as f64,
        };
        let names: Vec<String> = logs.iter().map(|l| l.path.display().to_string()).collect();
        progress.begin("Welch spectra", Some((logs.len() * m * p) as u64));
        for j in 0..m {
            for i in 0..p {
                let mut acc = welch.accumulator(first.fs())?;
                for log in logs {
                    acc.add(&log.inputs[j].data, &log.outputs[i].data)?;
                    progress.advance(1);
                }
                let e = acc.finish()?;
                estimates.push(FrfEstimate::from_welch(
                    &e,
                    &first.inputs[j].name,
                    &first.outputs[i].name,
                    names.clone(),
                    opts.gate,
                ));
            }
        }
        progress.end();
    }
    Ok(FrfReport {
        command: "frf",
        logs: logs.iter().map(LogSummary::of).collect(),
        method,
        gate: opts.gate,
        estimates,
        normalisation: NORMALISATION_NOTE,
    })
}
