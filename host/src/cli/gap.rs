//! `ferrosid gap`: sim-to-real gap diagnosis — where the nominal model and the measured plant
//! disagree, which unmodelled effect explains it, and how far the gap shrinks once the effect is
//! added (see [`crate::gap`]).
//!
//! Exit status: 0 when the diagnosis ran (whatever the verdict), 1 when `--expect` names a
//! verdict and the diagnosis differs, 2 usage error, 3 input data error (a sim whose response
//! is identically zero, a constant log, ...), 4 numerical failure.
use super::frf::LogArgs;
use super::output;
use super::ExitCode;
use crate::error::{Error, Result};
use crate::gap::simfile::{discretise_for_logs, load_sim_with_operating_point};
use crate::gap::{diagnose_at_operating_point, EffectKind, GapOptions};
use crate::io::file_safety::{check_output_file, mark_svg, write_atomic, Own, SVG_MARKER};
use std::path::PathBuf;

/// Arguments of `ferrosid gap`.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "\
Examples:
  ferrosid gap --sim examples/data/two_mass_sim.json \\
      --real examples/data/two_mass_low.csv --real examples/data/two_mass_high.csv \\
      --validate examples/data/two_mass_validate.csv
  ferrosid gap --sim sim.json --real low.csv --real high.csv --validate val.csv --json
  ferrosid gap --sim sim.json --real low.csv --real high.csv --validate val.csv \\
      --figures report/ --expect coulomb_friction

The sim model (JSON): {\"ts\": 0.0, \"a\": [[..]], \"b\": [[..]], \"c\": [[..]], \"d\": [[..]]} (ts = 0:
continuous, discretised by zero-order hold at the logs' sample time; ts > 0: discrete at that
sample time) or {\"ts\": .., \"num\": [..], \"den\": [..]}. Same units as the logs. The model
`ferrosid identify --out` writes is accepted.

--real logs (typically a low- and a high-amplitude run) are used for fitting; --validate (a
different excitation) only for ranking. Every effect is fitted as an augmentation of the linear
re-fit: coulomb_friction {level}, stiction {level, breakaway}, backlash {gap}, deadzone {width},
saturation {limit} (input units), time_delay {seconds}, resonance {freq_hz, damping},
quantization {step} (output units). The verdict is the effect with the lowest validation NRMSE
if it improves on the linear re-fit by at least --margin (relative) and removes at least half
of the re-fit's excess over the noise floor; else `none` when the linear re-fit is within twice
the noise floor (estimated from the data: period-to-period scatter of a repeating excitation,
else the residual spectrum where the input has no power), else `unexplained`, with the
evidence of a nonlinearity (amplitude dependence and mode shifts, distortion on non-excited
multisine lines, residual concentration) in the report.

A sim with integrators (poles at z = 1 / s = 0, e.g. a position output) is accepted; other
poles on or outside the unit circle are refused.

--figures DIR writes gap_frequency.svg (multiplicative error of the sim vs frequency, residual
spectra of the nominal sim, the linear re-fit and the verdict model on the validation log) and
gap_overlay.svg (validation output with the three simulations, and their residuals).

Exit codes: 0 success, 1 the verdict differs from --expect, 2 usage error, 3 input data error
(file and line named), 4 numerical failure.")]
pub struct Args {
    /// Nominal (simulation) model, JSON (state space or transfer function; see below).
    #[arg(long, value_name = "SIM.json")]
    pub sim: PathBuf,
    /// Training log (repeat: typically low and high excitation amplitude).
    #[arg(long = "real", value_name = "LOG", required = true)]
    pub real: Vec<PathBuf>,
    /// Validation log with a different excitation (never used for fitting).
    #[arg(long, value_name = "LOG")]
    pub validate: PathBuf,
    /// Channel selection (one input and one output).
    #[command(flatten)]
    pub select: LogArgs,
    /// Print machine-readable JSON instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Write SVG figures into this directory (created if missing).
    #[arg(long, value_name = "DIR")]
    pub figures: Option<PathBuf>,
    /// Replace existing figure files in --figures DIR even when ferrosid did not write them.
    #[arg(long)]
    pub force: bool,
    /// Relative validation-NRMSE improvement over the linear re-fit an effect needs to be the
    /// verdict.
    #[arg(long, value_name = "REL", default_value_t = crate::gap::diagnose::DEFAULT_MARGIN)]
    pub margin: f64,
    /// Multiplicative-error threshold of the reported frequency bands (ratio; 0.2 = 20 %).
    #[arg(long, value_name = "REL", default_value_t = 0.2)]
    pub threshold: f64,
    /// Coherence below which frequency bins are not used and are reported as drops.
    #[arg(long, value_name = "C", default_value_t = crate::spectral::DEFAULT_COHERENCE_THRESHOLD)]
    pub gate: f64,
    /// Samples left out at the start of every log (default: five time constants of the slowest
    /// sim pole, at most a tenth of the shortest log).
    #[arg(long, value_name = "N")]
    pub warmup: Option<usize>,
    /// Welch segment length of the frequency analysis (default: largest power of two <= N/8,
    /// within 64..4096).
    #[arg(long, value_name = "N")]
    pub nperseg: Option<usize>,
    /// Candidate effects to fit, comma separated (default: all).
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub effects: Vec<String>,
    /// Expected verdict (an effect name, `a+b` for a pair, `none` or `unexplained`): exit 1 if
    /// the diagnosis disagrees.
    #[arg(long, value_name = "EFFECT")]
    pub expect: Option<String>,
    /// Anti-aliased decimation of every log by this integer factor before the diagnosis (as
    /// `identify --decimate`; the sim must then be continuous or discrete at the decimated
    /// sample time).
    #[arg(long, value_name = "Q")]
    pub decimate: Option<usize>,
}

fn parse_kind(s: &str) -> Result<EffectKind> {
    EffectKind::from_name(s.trim()).ok_or_else(|| {
        let names: Vec<&str> = EffectKind::ALL.iter().map(|k| k.name()).collect();
        Error::InvalidArgument(format!(
            "unknown effect `{s}`; expected one of {}",
            names.join(", ")
        ))
    })
}

impl Args {
    /// The diagnosis options these flags describe (checked).
    pub fn options(&self) -> Result<GapOptions> {
        if !(self.margin.is_finite() && (0.0..1.0).contains(&self.margin)) {
            return Err(Error::InvalidArgument(format!(
                "--margin must be in [0, 1), got {}",
                self.margin
            )));
        }
        if !(self.threshold.is_finite() && self.threshold > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "--threshold must be > 0, got {}",
                self.threshold
            )));
        }
        if !(self.gate.is_finite() && (0.0..=1.0).contains(&self.gate)) {
            return Err(Error::InvalidArgument(format!(
                "--gate must be a coherence in [0, 1], got {}",
                self.gate
            )));
        }
        let candidates = if self.effects.is_empty() {
            EffectKind::ALL.to_vec()
        } else {
            self.effects
                .iter()
                .map(|s| parse_kind(s))
                .collect::<Result<Vec<_>>>()?
        };
        if let Some(e) = &self.expect {
            if e != "none" && e != "unexplained" {
                for part in e.split('+') {
                    parse_kind(part)?;
                }
            }
        }
        if let Some(q) = self.decimate {
            if q < 2 {
                return Err(Error::InvalidArgument(format!(
                    "--decimate must be an integer >= 2, got {q}"
                )));
            }
        }
        Ok(GapOptions {
            margin: self.margin,
            threshold: self.threshold,
            coherence_min: self.gate,
            warmup: self.warmup,
            nperseg: self.nperseg,
            candidates,
            ..GapOptions::default()
        })
    }
}

/// Sample-time range of the logs `gap` diagnoses, s (1 ns to 1 s): the sim is discretised and
/// every effect is simulated at the logs' sample time; below this range the fits' scalings
/// leave the floating-point range (`--time-scale=1e-308` panicked), above it the two-mass
/// example ran for minutes (10 s per sample: over 60 s without an answer; 1 s: 0.5 s).
pub const GAP_SAMPLE_TIME_RANGE_S: (f64, f64) = (1e-9, 1.0);

fn check_gap_sample_time(ts: f64, path: &std::path::Path) -> Result<()> {
    let (lo, hi) = GAP_SAMPLE_TIME_RANGE_S;
    if ts.is_finite() && (lo..=hi).contains(&ts) {
        return Ok(());
    }
    Err(Error::InvalidArgument(format!(
        "{}: sample time {} s is outside gap's range [{}, {}] s; check --time-scale (seconds \
         per unit of the time column) or --fs",
        path.display(),
        super::num(ts),
        super::num(lo),
        super::num(hi)
    )))
}

/// Largest sim order (states) `gap` diagnoses: 20 (about 9 s on the two-mass logs in the test
/// build, 30 states 21 s; a 60-state sim took 213 s).
pub const MAX_SIM_ORDER: usize = 20;

/// The files `--figures DIR` receives.
pub const FIGURE_FILES: [&str; 2] = ["gap_frequency.svg", "gap_overlay.svg"];

/// Before any work: `dir` is a directory (or can be created) and none of [`FIGURE_FILES`] in it
/// is a file ferrosid did not write (unless `force`).
fn check_figures_dir(dir: &std::path::Path, force: bool) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        return Err(Error::Io {
            file: dir.to_path_buf(),
            source: std::io::Error::other("--figures names a file, expected a directory"),
        });
    }
    crate::io::file_safety::check_dir_writable(dir)?;
    for name in FIGURE_FILES {
        check_output_file(&dir.join(name), "--figures", Own::Marker(SVG_MARKER), force)?;
    }
    Ok(())
}

/// Runs `ferrosid gap`.
pub fn run(args: &Args) -> Result<ExitCode> {
    let opts = args.options()?;
    // The sim file by the rule of every JSON reader (regular file, size cap, UTF-8, no
    // repeated key) before the gap module parses it.
    crate::io::input::read_json_text(&args.sim)?;
    if let Some(dir) = &args.figures {
        check_figures_dir(dir, args.force)?;
    }
    let (sim, op) = load_sim_with_operating_point(&args.sim)?;
    if sim.n_states() > MAX_SIM_ORDER {
        return Err(Error::Data {
            file: args.sim.clone(),
            msg: format!(
                "the sim has {} states; gap diagnoses sims of at most {MAX_SIM_ORDER} states (its \
                 cost grows steeply with the order: 20 states take about 9 s, 60 took minutes); \
                 reduce the model (e.g. balanced truncation) first",
                sim.n_states()
            ),
        });
    }
    let train = args.select.read_all(&args.real)?;
    let validate = args
        .select
        .read_all(std::slice::from_ref(&args.validate))?
        .remove(0);
    for (log, path) in train
        .iter()
        .zip(&args.real)
        .chain([(&validate, &args.validate)])
    {
        check_gap_sample_time(log.ts, path)?;
    }
    // A model written by `identify`/`run` maps deviations from the operating point it was
    // identified at: the logs are compared as deviations from it (u − u0, y − y0) and as read,
    // at the model's rate, and the reading with the smaller validated gap is reported
    // (`gap::reading`).
    if let Some(op) = &op {
        output::note(&format!(
            "{} carries an operating point (u0 = {:?}, y0 = {:?}, {}); the logs are compared \
             as deviations from it and, unless its offsets are negligible, as read, and the \
             reading that explains more is reported",
            args.sim.display(),
            op.u0,
            op.y0,
            op.detrend
        ));
    }
    let factor = args
        .decimate
        .or_else(|| op.as_ref().map(|o| o.decimation))
        .unwrap_or(1)
        .max(1);
    if args.decimate.is_none() && factor > 1 {
        output::note(&format!(
            "decimating the logs by {factor} as the model file's preprocessing records"
        ));
    }
    let sim_d = discretise_for_logs(&sim, validate.ts * factor as f64, &args.sim)?;
    let spinner = output::spinner("diagnosing the sim-to-real gap");
    let d =
        diagnose_at_operating_point(&sim_d, op.as_ref(), args.decimate, &train, &validate, &opts);
    spinner.finish_and_clear();
    let d = d?;
    if let Some(dir) = &args.figures {
        std::fs::create_dir_all(dir).map_err(|source| Error::Io {
            file: dir.clone(),
            source,
        })?;
        let figures = crate::gap::figures::figures(&d)?;
        for (name, _) in &figures {
            check_output_file(
                &dir.join(name),
                "--figures",
                Own::Marker(SVG_MARKER),
                args.force,
            )?;
        }
        for (name, svg) in figures {
            write_atomic(&dir.join(name), mark_svg(&svg).as_bytes())?;
        }
    }
    if args.json {
        output::emit(&output::json_string(&d.report)?)?;
    } else {
        output::emit(&d.report.to_text())?;
    }
    Ok(match &args.expect {
        Some(e) if *e != d.report.verdict => {
            output::warn(&format!(
                "verdict `{}` differs from the expected `{e}`",
                d.report.verdict
            ));
            ExitCode::CheckFailed
        }
        _ => ExitCode::Ok,
    })
}
