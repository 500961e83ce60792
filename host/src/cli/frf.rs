//! `ferrosid frf`: empirical frequency response (Welch H1 or period-synchronous averaging) with
//! magnitude-squared coherence and coherence gating, from one or more logs.
//!
//! * Welch (default): the segments of all logs are pooled into one estimate per
//!   (input, output) pair; the logs must share the sample rate and channel layout.
//! * `--period P`: period-synchronous averaging at the excited lines, one estimate per log and
//!   pair (the noise variance of H comes from the spread over periods).
//!
//! Default segment length (`--nperseg auto`): the largest power of two not above 1/4 of the
//! shortest log, capped at 4096 and at least 8 samples, so that at least 7 half-overlapped
//! segments are averaged.
//!
//! Exit status: 0 when at least one bin of every estimate passes the coherence gate, 1 when an
//! estimate has no bin above the gate (nothing usable for fitting or validation).
use super::output::{self, fixed, Align, Table};
use super::ExitCode;
use crate::data::Log;
use crate::error::{Error, Result};
use crate::io::{read_log, require_len, LogSpec};
use crate::spectral::{
    Detrend, Etfe, ExcludedBand, PeriodicAveraging, PeriodicFrf, Welch, Window,
    DEFAULT_COHERENCE_THRESHOLD, MAX_NPERSEG, MIN_NPERSEG,
};
use clap::ValueEnum;
use num_complex::Complex64;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;

/// Which signals to read from each log (shared by `frf` and `identify`).
#[derive(Debug, Clone, clap::Args)]
pub struct LogArgs {
    /// Input channel: CSV column, .mat variable, or 1-based column number of a headerless text
    /// log. Repeat for several inputs. Default: `u` (CSV), column 1 (text); required for .mat.
    #[arg(long = "input", short = 'u', value_name = "NAME")]
    pub inputs: Vec<String>,
    /// Output channel (same conventions as --input). Default: `y` (CSV), column 2 (text).
    #[arg(long = "output", short = 'y', value_name = "NAME")]
    pub outputs: Vec<String>,
    /// Time column/variable. Default: `t` when a CSV header has it; none for .mat and text.
    #[arg(long, value_name = "NAME")]
    pub time: Option<String>,
    /// Seconds per unit of the time column (e.g. 1e-6 for microseconds). Default 1.
    #[arg(long, value_name = "S")]
    pub time_scale: Option<f64>,
    /// Sample rate in Hz: required without a time column, checked against it otherwise.
    #[arg(long, value_name = "HZ")]
    pub fs: Option<f64>,
    /// .mat only: scalar variable holding the sample rate in Hz (default: `fs` if present).
    #[arg(long, value_name = "NAME")]
    pub fs_var: Option<String>,
    /// Largest accepted relative jitter of the time column's sample intervals.
    #[arg(long, value_name = "REL", default_value_t = crate::io::DEFAULT_TIME_JITTER_REL)]
    pub time_jitter: f64,
}

impl LogArgs {
    /// The reader specification these flags describe.
    pub fn spec(&self) -> LogSpec {
        let mut spec = LogSpec {
            inputs: self.inputs.clone(),
            outputs: self.outputs.clone(),
            time: self.time.clone(),
            time_scale: self.time_scale,
            fs: self.fs,
            fs_var: self.fs_var.clone(),
            ..LogSpec::default()
        };
        spec.checks.time_jitter_rel = self.time_jitter;
        spec
    }

    /// Reads every log in `paths` (in order), printing each log's warnings on stderr.
    pub fn read_all(&self, paths: &[PathBuf]) -> Result<Vec<Log>> {
        let spec = self.spec();
        let pb = output::progress(paths.len() as u64, "reading logs");
        let mut logs = Vec::with_capacity(paths.len());
        for p in paths {
            let log = read_log(p, &spec)?;
            for w in &log.warnings {
                output::warn(&format!("{}: {w}", p.display()));
            }
            logs.push(log);
            pb.inc(1);
        }
        pb.finish_and_clear();
        Ok(logs)
    }
}

/// Data window of each Welch segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WindowArg {
    /// Periodic Hann.
    Hann,
    /// Periodic Hamming.
    Hamming,
    /// Periodic Blackman.
    Blackman,
    /// Rectangular (scipy `boxcar`).
    Boxcar,
}

impl WindowArg {
    fn window(self) -> Window {
        match self {
            WindowArg::Hann => Window::Hann,
            WindowArg::Hamming => Window::Hamming,
            WindowArg::Blackman => Window::Blackman,
            WindowArg::Boxcar => Window::Rectangular,
        }
    }
}

/// Per-segment detrending before windowing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DetrendArg {
    /// Subtract the segment mean.
    Constant,
    /// Subtract the least-squares line.
    Linear,
    /// No detrending.
    None,
}

impl DetrendArg {
    fn detrend(self) -> Detrend {
        match self {
            DetrendArg::Constant => Detrend::Constant,
            DetrendArg::Linear => Detrend::Linear,
            DetrendArg::None => Detrend::None,
        }
    }
}

/// Settings of the frequency-response estimate (shared by `frf` and `identify`'s validation).
#[derive(Debug, Clone, clap::Args)]
pub struct EtfeArgs {
    /// Welch segment length in samples (frequency resolution fs/N Hz), or `auto`: the largest
    /// power of two <= 1/4 of the shortest log, within 8..=4096.
    #[arg(long, value_name = "N|auto", default_value = "auto")]
    pub nperseg: String,
    /// Overlap of consecutive Welch segments in samples. Default: nperseg/2.
    #[arg(long, value_name = "N")]
    pub overlap: Option<usize>,
    /// Welch data window.
    #[arg(long, value_enum, default_value_t = WindowArg::Hann)]
    pub window: WindowArg,
    /// Welch per-segment detrending.
    #[arg(long, value_enum, default_value_t = DetrendArg::Constant)]
    pub detrend: DetrendArg,
    /// Excitation period in samples: use period-synchronous averaging instead of Welch.
    #[arg(long, value_name = "P")]
    pub period: Option<usize>,
    /// With --period: leading periods to discard as transient.
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub skip_periods: usize,
    /// Coherence gate: bins with coherence below this are marked and not used.
    #[arg(long, value_name = "C", default_value_t = DEFAULT_COHERENCE_THRESHOLD)]
    pub gate: f64,
}

impl EtfeArgs {
    /// Checks option values that clap cannot.
    pub fn validate(&self) -> Result<()> {
        if !(self.gate.is_finite() && (0.0..=1.0).contains(&self.gate)) {
            return Err(Error::InvalidArgument(format!(
                "--gate must be a coherence in [0, 1], got {}",
                self.gate
            )));
        }
        self.nperseg_fixed()?;
        if let Some(p) = self.period {
            if !(2..=MAX_NPERSEG).contains(&p) {
                return Err(Error::InvalidArgument(format!(
                    "--period must be in 2..={MAX_NPERSEG} samples, got {p}"
                )));
            }
        }
        Ok(())
    }

    fn nperseg_fixed(&self) -> Result<Option<usize>> {
        if self.nperseg.eq_ignore_ascii_case("auto") {
            return Ok(None);
        }
        let n: usize = self.nperseg.trim().parse().map_err(|_| {
            Error::InvalidArgument(format!(
                "--nperseg must be a number of samples or `auto`, got `{}`",
                self.nperseg
            ))
        })?;
        if !(MIN_NPERSEG..=MAX_NPERSEG).contains(&n) {
            return Err(Error::InvalidArgument(format!(
                "--nperseg must be in {MIN_NPERSEG}..={MAX_NPERSEG} samples, got {n}"
            )));
        }
        Ok(Some(n))
    }

    /// The Welch settings for logs whose shortest has `min_len` samples.
    pub fn welch(&self, min_len: usize) -> Result<Welch> {
        let nperseg = match self.nperseg_fixed()? {
            Some(n) => n,
            None => auto_nperseg(min_len),
        };
        Ok(Welch {
            nperseg,
            noverlap: self.overlap,
            window: self.window.window(),
            detrend: self.detrend.detrend(),
        })
    }

    /// The period-synchronous settings, if `--period` was given.
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

/// Arguments of `ferrosid frf`.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "\
Examples:
  ferrosid frf examples/data/two_mass_high.csv
  ferrosid frf examples/data/two_mass_low.csv examples/data/two_mass_high.csv --nperseg 512 --json
  ferrosid frf examples/data/two_mass_validate.csv --period 1000 --skip-periods 1
  ferrosid frf robot_arm.dat --fs 1 --input 1 --output 2 --window boxcar
  ferrosid frf MultisineTypeA.mat --input iq_refx --output omega_max --period 2500

Several logs are pooled into one Welch estimate (same sample rate and channels); with --period
each log gets its own period-synchronous estimate. Every (input, output) pair is estimated.

Columns: frequency in Hz, |H| in dB (output units per input unit), phase in degrees wrapped to
(-180, 180], magnitude-squared coherence, and `low` where the bin fails the gate (coherence
below --gate, or no input power at that bin).

Exit codes: 0 success, 1 an estimate has no bin above the coherence gate, 2 usage error,
3 input data error (file and line named), 4 numerical failure.")]
pub struct Args {
    /// Log files (.csv, .mat, .dat/.txt).
    #[arg(required = true, value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// Channel selection.
    #[command(flatten)]
    pub select: LogArgs,
    /// Estimator settings.
    #[command(flatten)]
    pub etfe: EtfeArgs,
    /// Print machine-readable JSON instead of the table.
    #[arg(long)]
    pub json: bool,
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
        window: WindowArg,
        /// Detrending.
        detrend: DetrendArg,
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

/// Computes the report of `ferrosid frf` for already-read logs.
pub fn estimate(logs: &[Log], etfe: &EtfeArgs) -> Result<FrfReport> {
    etfe.validate()?;
    check_compatible(logs)?;
    let first = &logs[0];
    let (m, p) = (first.inputs.len(), first.outputs.len());
    let mut estimates = Vec::new();
    let method;
    if let Some(per) = etfe.periodic() {
        method = MethodSummary::Periodic {
            period: per.period,
            skip_periods: per.skip_periods,
        };
        let pb = output::progress((logs.len() * m * p) as u64, "period-synchronous FRF");
        for log in logs {
            for j in 0..m {
                for i in 0..p {
                    let r = per.frf_log(log, j, i)?;
                    estimates.push(FrfEstimate::from_periodic(
                        &r,
                        &log.inputs[j].name,
                        &log.outputs[i].name,
                        log.path.display().to_string(),
                        etfe.gate,
                    ));
                    pb.inc(1);
                }
            }
        }
        pb.finish_and_clear();
    } else {
        let min_len = logs.iter().map(Log::len).min().unwrap_or(0);
        let welch = etfe.welch(min_len)?;
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
            window: etfe.window,
            detrend: etfe.detrend,
            resolution_hz: first.fs() / welch.nperseg as f64,
        };
        let names: Vec<String> = logs.iter().map(|l| l.path.display().to_string()).collect();
        let pb = output::progress((logs.len() * m * p) as u64, "Welch spectra");
        for j in 0..m {
            for i in 0..p {
                let mut acc = welch.accumulator(first.fs())?;
                for log in logs {
                    acc.add(&log.inputs[j].data, &log.outputs[i].data)?;
                    pb.inc(1);
                }
                let e = acc.finish()?;
                estimates.push(FrfEstimate::from_welch(
                    &e,
                    &first.inputs[j].name,
                    &first.outputs[i].name,
                    names.clone(),
                    etfe.gate,
                ));
            }
        }
        pb.finish_and_clear();
    }
    Ok(FrfReport {
        command: "frf",
        logs: logs.iter().map(LogSummary::of).collect(),
        method,
        gate: etfe.gate,
        estimates,
        normalisation: NORMALISATION_NOTE,
    })
}

/// Human-readable rendering of a report.
pub fn render_text(r: &FrfReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "ferrosid frf");
    for l in &r.logs {
        let _ = writeln!(
            s,
            "log {}: {} samples at {} Hz, inputs [{}], outputs [{}]",
            l.path,
            l.samples,
            output::general(l.fs_hz, 3),
            l.inputs.join(", "),
            l.outputs.join(", ")
        );
        for w in &l.warnings {
            let _ = writeln!(s, "  warning: {w}");
        }
    }
    match &r.method {
        MethodSummary::Welch {
            nperseg,
            noverlap,
            window,
            detrend,
            resolution_hz,
        } => {
            let _ = writeln!(
                s,
                "method: Welch H1, nperseg {nperseg} ({} Hz bins), overlap {noverlap}, {} window, \
                 {} detrend",
                output::general(*resolution_hz, 4),
                enum_name(window),
                enum_name(detrend)
            );
        }
        MethodSummary::Periodic {
            period,
            skip_periods,
        } => {
            let _ = writeln!(
                s,
                "method: period-synchronous averaging, period {period} samples, {skip_periods} \
                 leading period(s) skipped"
            );
        }
    }
    let _ = writeln!(s, "coherence gate: >= {}", r.gate);
    let _ = writeln!(s, "{}", r.normalisation);
    for e in &r.estimates {
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "{} -> {} ({} averages{})",
            e.input,
            e.output,
            e.n_averages,
            if e.logs.len() == 1 {
                format!(", {}", e.logs[0])
            } else {
                format!(", {} logs pooled", e.logs.len())
            }
        );
        let periodic = e.std_h.is_some();
        let mut cols = vec![
            ("freq_Hz", Align::Right),
            ("|H|_dB", Align::Right),
            ("phase_deg", Align::Right),
            ("coherence", Align::Right),
        ];
        if periodic {
            cols.push(("std_H_dB", Align::Right));
        }
        cols.push(("gate", Align::Left));
        let mut t = Table::new(&cols);
        for k in 0..e.freq_hz.len() {
            let mut row = vec![
                fixed(e.freq_hz[k], 3),
                fixed(e.mag_db[k], 2),
                fixed(e.phase_deg[k], 1),
                fixed(e.coherence[k], 4),
            ];
            if let Some(sd) = &e.std_h {
                // Relative standard deviation in dB of |H|: 20 log10(1 + std/|H|).
                let a = (e.re[k] * e.re[k] + e.im[k] * e.im[k]).sqrt();
                row.push(fixed(20.0 * (1.0 + sd[k] / a).log10(), 3));
            }
            row.push(if e.gated[k] { "" } else { "low" }.into());
            t.row(row);
        }
        s.push_str(&t.render(2));
        let _ = writeln!(
            s,
            "{} of {} bins pass the coherence gate",
            e.n_gated(),
            e.freq_hz.len()
        );
        for n in &e.notes {
            let _ = writeln!(s, "note: {n}");
        }
        if !e.excluded_bands.is_empty() {
            let bands: Vec<String> = e
                .excluded_bands
                .iter()
                .map(|b| {
                    format!(
                        "{}-{} Hz (min {})",
                        fixed(b.f_lo_hz, 3),
                        fixed(b.f_hi_hz, 3),
                        fixed(b.min_coherence, 3)
                    )
                })
                .collect();
            let _ = writeln!(s, "below the gate: {}", bands.join(", "));
        }
    }
    s
}

fn enum_name<T: Serialize>(v: &T) -> String {
    serde_json::to_value(v)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default()
}

/// Runs `ferrosid frf`.
pub fn run(args: &Args) -> Result<ExitCode> {
    args.etfe.validate()?;
    let logs = args.select.read_all(&args.logs)?;
    let report = estimate(&logs, &args.etfe)?;
    if args.json {
        output::emit(&output::json_string(&report)?)?;
    } else {
        output::emit(&render_text(&report))?;
    }
    if report.estimates.iter().any(|e| e.n_gated() == 0) {
        output::warn("an estimate has no bin with coherence above the gate");
        return Ok(ExitCode::CheckFailed);
    }
    Ok(ExitCode::Ok)
}
