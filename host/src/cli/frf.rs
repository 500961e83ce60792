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
use super::output::{self, fixed, Align, Table, TerminalProgress};
use super::ExitCode;
use crate::data::Log;
use crate::error::{Error, Result};
use crate::io::{read_log, LogSpec};
pub use crate::ops::frf::{
    auto_nperseg, check_compatible, mag_db, phase_deg, FrfEstimate, FrfOptions, FrfReport,
    LogSummary, MethodSummary, NORMALISATION_NOTE,
};
/// The `--detrend` values (the library's [`crate::spectral::Detrend`]).
pub use crate::spectral::Detrend as DetrendArg;
/// The `--window` values (the library's [`crate::spectral::WindowName`]).
pub use crate::spectral::WindowName as WindowArg;
use crate::spectral::DEFAULT_COHERENCE_THRESHOLD;
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
    /// Largest accepted deviation of each sample interval of the time column from the median
    /// interval, relative to the median (intervals alternating 1.000/1.002 ms deviate by 0.2 %
    /// from their median of 1.000 ms; stamps within their printed rounding of a uniform grid
    /// are accepted whatever this is). The sample time is then the mean interval.
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

    /// Checks the numeric flags ([`crate::io::MIN_TIME_SCALE`]..., docs/safety.md).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the flag.
    pub fn check(&self) -> Result<()> {
        use crate::io::{MAX_FS_HZ, MAX_TIME_SCALE, MIN_FS_HZ, MIN_TIME_SCALE};
        if let Some(v) = self.time_scale {
            super::check_flag(
                "--time-scale",
                v,
                MIN_TIME_SCALE,
                false,
                MAX_TIME_SCALE,
                " seconds per unit of the time column",
            )?;
        }
        if let Some(v) = self.fs {
            super::check_flag("--fs", v, MIN_FS_HZ, false, MAX_FS_HZ, " Hz")?;
        }
        if !(0.0..=crate::io::MAX_TIME_JITTER_REL).contains(&self.time_jitter) {
            return Err(Error::InvalidArgument(format!(
                "--time-jitter must be a relative tolerance in [0, {}], got {}",
                crate::io::MAX_TIME_JITTER_REL,
                super::num(self.time_jitter)
            )));
        }
        Ok(())
    }

    /// Reads every log in `paths` (in order), printing each log's warnings on stderr.
    pub fn read_all(&self, paths: &[PathBuf]) -> Result<Vec<Log>> {
        self.check()?;
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
    /// The library options these flags describe.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `--nperseg` is neither a number nor `auto`.
    pub fn options(&self) -> Result<FrfOptions> {
        let nperseg = if self.nperseg.eq_ignore_ascii_case("auto") {
            None
        } else {
            Some(self.nperseg.trim().parse().map_err(|_| {
                Error::InvalidArgument(format!(
                    "--nperseg must be a number of samples or `auto`, got `{}`",
                    self.nperseg
                ))
            })?)
        };
        Ok(FrfOptions {
            nperseg,
            overlap: self.overlap,
            window: self.window,
            detrend: self.detrend,
            period: self.period,
            skip_periods: self.skip_periods,
            gate: self.gate,
        })
    }

    /// Checks option values that clap cannot (see [`FrfOptions::validate`]).
    pub fn validate(&self) -> Result<()> {
        self.options()?.validate()
    }
}

/// Computes the report of `ferrosid frf` for already-read logs ([`crate::ops::frf::estimate`]
/// with these flags, progress on stderr).
pub fn estimate(logs: &[Log], etfe: &EtfeArgs) -> Result<FrfReport> {
    crate::ops::frf::estimate(logs, &etfe.options()?, &TerminalProgress::default())
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

/// Human-readable rendering of a report.
pub fn render_text(r: &FrfReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "ferrosid frf");
    for l in &r.logs {
        let _ = writeln!(s, "{}", output::log_line(l));
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
    let _ = writeln!(s, "coherence gate: >= {}", super::num(r.gate));
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
