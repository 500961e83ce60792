//! `ferrosid identify`: from logs to a validated discrete state-space model.
//!
//! Pipeline (every step is recorded in the report):
//! 1. read the logs ([`crate::io::read_log`]) and preprocess each one the same way
//!    ([`crate::preprocess`]: mean or trend removal, optional anti-aliased decimation);
//! 2. several estimation logs are concatenated after preprocessing (same sample rate and
//!    channels required); each junction disturbs the `block_rows` Hankel columns that span it,
//!    which the report states;
//! 3. N4SID ([`crate::n4sid`]) with automatic order selection (singular values and the reason
//!    are printed) or a fixed order / order range;
//! 4. continuous-time equivalent by the inverse ZOH ([`crate::lti::StateSpace::d2c_zoh`]), or a
//!    warning when the discrete poles do not allow one (e.g. poles on the negative real axis);
//! 5. validation ([`crate::validate`]) on `--validate LOG` (or, without it, on the estimation
//!    data, labelled as such): free-run simulation fit (NRMSE, fit %), model versus ETFE at
//!    every coherence-gated bin up to twice `--crossover-hz` with the ±5° phase checklist, and
//!    residual auto/cross-correlation tests at 99 % confidence;
//! 6. the model is written with `--out` as `{"a", "b", "c", "d", "ts", "operating_point"}` JSON
//!    (rows of the matrices, `ts` in seconds, the means removed and the preprocessing; see
//!    [`crate::operating_point`]), the format `ferrosid gap --sim` reads. The output path is
//!    checked before any work: not one of the input logs, writable; the file is replaced
//!    atomically.
//!
//! Exit status: 0 when the model was identified and, if `--crossover-hz` was given, every
//! compared bin is within the phase bound; 1 when that phase checklist fails.
use super::frf::{check_compatible, EtfeArgs, LogArgs, LogSummary};
use super::output::{self, fixed, general, Align, Table};
use super::ExitCode;
use crate::data::OperatingPoint;
use crate::data::{Channel, Log};
use crate::error::{Error, Result};
use crate::io::file_safety::{check_writable, refuse_input_overwrite, write_atomic};
use crate::lti::{StateSpace, StateSpaceData};
use crate::n4sid::{n4sid, N4sidOptions, N4sidSummary, OrderSelection, Weighting, MAX_BLOCK_ROWS};
use crate::operating_point::operating_point_of;
use crate::preprocess::MAX_DECIMATION;
use crate::preprocess::{preprocess, Preprocessing, Step};
use crate::validate::{
    compare_with_etfe, residual_test, simulation_fit_log, simulation_fit_operating_point,
    EtfeComparison, InitialState, ResidualTest, SimulationFit, PHASE_BOUND_DEG,
};
use clap::ValueEnum;
use num_complex::Complex64;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;

/// Offset/trend removal applied to every log before identification.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DetrendMode {
    /// Subtract each channel's mean.
    Mean,
    /// Subtract each channel's least-squares line.
    Trend,
    /// Leave the data as measured.
    None,
}

/// Subspace weighting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WeightingArg {
    /// PO-MOESP (SLICOT IB01AD METH='M').
    Moesp,
    /// Canonical variate analysis.
    Cva,
}

/// Arguments of `ferrosid identify`.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "\
Examples:
  ferrosid identify examples/data/two_mass_high.csv --validate examples/data/two_mass_validate.csv
  ferrosid identify examples/data/two_mass_high.csv --validate examples/data/two_mass_validate.csv \\
      --crossover-hz 20 --out model.json
  ferrosid identify run1.csv run2.csv --order-range 2..8 --no-d --stable-margin 0.001 --json
  ferrosid identify MultisineTypeA.mat --input iq_refx --output omega_max \\
      --validate MultisineTypeB.mat --period 2500 --order 4
  ferrosid identify robot_arm.dat --fs 1 --input 1 --output 2 --order 4

Several estimation logs are preprocessed separately and concatenated. The validation log gets the
same preprocessing; its ETFE uses the --nperseg/--window/--period/--gate settings (as `frf`).
The model file (--out) holds {\"a\",\"b\",\"c\",\"d\",\"ts\"} (matrix rows, ts in seconds) and the
operating point (the means removed: the model maps y - y0 = G (u - u0)); it is accepted by
`ferrosid gap --sim` and `ferrosid codegen --model`. --out may not name an input log.

Exit codes: 0 success, 1 the phase checklist failed (a gated bin up to 2x --crossover-hz is
outside +-phase-tol degrees), 2 usage error, 3 input data error (file and line named),
4 numerical failure (ill-conditioned or untrustworthy fit).")]
pub struct Args {
    /// Estimation log files (.csv, .mat, .dat/.txt).
    #[arg(required = true, value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// Validation log (same channels); without it, validation uses the estimation data.
    #[arg(long, value_name = "LOG")]
    pub validate: Option<PathBuf>,
    /// Channel selection (applies to all logs).
    #[command(flatten)]
    pub select: LogArgs,
    /// Fixed model order.
    #[arg(long, value_name = "N", conflicts_with = "order_range")]
    pub order: Option<usize>,
    /// Range for the automatic order selection, e.g. `2..8` (inclusive).
    #[arg(long, value_name = "LO..HI")]
    pub order_range: Option<String>,
    /// Block rows i of the Hankel matrices (past and future horizon).
    #[arg(long, value_name = "I", default_value_t = 20)]
    pub block_rows: usize,
    /// Fix the feedthrough D to zero instead of estimating it.
    #[arg(long, conflicts_with = "d_auto")]
    pub no_d: bool,
    /// Estimate D, then fix it to zero when every entry lies within 2 standard errors of zero
    /// (the sampled model of a strictly proper plant has D = 0).
    #[arg(long)]
    pub d_auto: bool,
    /// Enforce every discrete pole to |z| <= 1 - X (reported when poles move).
    #[arg(long, value_name = "X")]
    pub stable_margin: Option<f64>,
    /// Subspace weighting.
    #[arg(long, value_enum, default_value_t = WeightingArg::Moesp)]
    pub weighting: WeightingArg,
    /// Offset removal before identification.
    #[arg(long = "remove", value_enum, default_value_t = DetrendMode::Mean)]
    pub remove: DetrendMode,
    /// Anti-aliased decimation by this integer factor (after offset removal).
    #[arg(long, value_name = "Q")]
    pub decimate: Option<usize>,
    /// Crossover frequency in Hz: enables the phase checklist up to twice this frequency.
    #[arg(long, value_name = "HZ")]
    pub crossover_hz: Option<f64>,
    /// Phase bound of the checklist, degrees.
    #[arg(long, value_name = "DEG", default_value_t = PHASE_BOUND_DEG)]
    pub phase_tol: f64,
    /// Largest lag of the residual correlation tests, samples.
    #[arg(long, value_name = "M", default_value_t = 25)]
    pub max_lag: usize,
    /// Validation ETFE settings.
    #[command(flatten)]
    pub etfe: EtfeArgs,
    /// Print machine-readable JSON instead of the text report.
    #[arg(long)]
    pub json: bool,
    /// Write the discrete model to this JSON file.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// A pole or zero with its natural frequency and damping.
#[derive(Debug, Clone, Serialize)]
pub struct Root {
    /// Real part (z-plane for discrete, s-plane in rad/s for continuous roots).
    pub re: f64,
    /// Imaginary part.
    pub im: f64,
    /// Natural frequency |s|/2π in Hz (s = ln(z)/ts for discrete roots).
    pub freq_hz: f64,
    /// Damping ratio −Re(s)/|s| (1 for a real stable root at s = 0 limit).
    pub damping: f64,
}

impl Root {
    fn continuous(s: Complex64) -> Self {
        let w = s.norm();
        Self {
            re: s.re,
            im: s.im,
            freq_hz: w / (2.0 * std::f64::consts::PI),
            damping: if w > 0.0 { -s.re / w } else { 1.0 },
        }
    }

    fn discrete(z: Complex64, ts: f64) -> Self {
        let s = if z.norm() > 0.0 {
            z.ln() / ts
        } else {
            Complex64::new(f64::NEG_INFINITY, 0.0)
        };
        let w = s.norm();
        Self {
            re: z.re,
            im: z.im,
            freq_hz: w / (2.0 * std::f64::consts::PI),
            damping: if w > 0.0 && w.is_finite() {
                -s.re / w
            } else {
                1.0
            },
        }
    }
}

/// The continuous-time equivalent.
#[derive(Debug, Clone, Serialize)]
pub struct Continuous {
    /// The model (ts = 0).
    pub model: StateSpaceData,
    /// Poles, ascending natural frequency (s-plane).
    pub poles: Vec<Root>,
    /// Transmission zeros below the Nyquist frequency (SISO only), ascending frequency.
    pub zeros: Vec<Root>,
}

/// Validation results.
#[derive(Debug, Clone, Serialize)]
pub struct Validation {
    /// Validation log path, or `estimation data`.
    pub data: String,
    /// Preprocessing of the validation log (absent when validating on the estimation data).
    pub preprocessing: Option<Preprocessing>,
    /// Free-run simulation fit.
    pub fit: SimulationFit,
    /// ETFE settings used for the comparison.
    pub etfe: String,
    /// Coherence gate threshold.
    pub gate: f64,
    /// Model vs ETFE per (output, input) pair at the gated bins up to `f_max_hz`.
    pub phase: Vec<PairComparison>,
    /// Residual correlation tests.
    pub residuals: ResidualTest,
    /// Free-run fit on the raw validation log through the model's operating point (the model
    /// sees u − u0, its output is compared with y − y0): how the model file performs on data as
    /// recorded. Absent without `--validate`, or with decimation (the raw log is then not at
    /// the model's rate), with the reason in `operating_point_fit_note`.
    pub operating_point_fit: Option<SimulationFit>,
    /// Why `operating_point_fit` is absent, when it is.
    pub operating_point_fit_note: Option<String>,
}

/// Model-versus-ETFE comparison of one channel pair.
#[derive(Debug, Clone, Serialize)]
pub struct PairComparison {
    /// Input channel name.
    pub input: String,
    /// Output channel name.
    pub output: String,
    /// True when the bound is a checklist verdict (`--crossover-hz` given); false when the
    /// comparison covers all gated bins up to Nyquist for information only.
    pub checklist: bool,
    /// The comparison.
    pub comparison: EtfeComparison,
}

/// The JSON document of `ferrosid identify --json`.
#[derive(Debug, Clone, Serialize)]
pub struct IdentifyReport {
    /// Always "identify".
    pub command: &'static str,
    /// Estimation logs.
    pub logs: Vec<LogSummary>,
    /// Preprocessing record of each estimation log.
    pub preprocessing: Vec<Preprocessing>,
    /// Samples used for estimation (after preprocessing and concatenation).
    pub estimation_samples: usize,
    /// Sample time of the model, s.
    pub ts: f64,
    /// N4SID options used.
    pub options: N4sidOptions,
    /// N4SID result (model, order, singular values, reason, poles, warnings).
    pub n4sid: N4sidSummary,
    /// Discrete poles with natural frequency and damping.
    pub poles: Vec<Root>,
    /// Continuous-time equivalent, if it exists.
    pub continuous: Option<Continuous>,
    /// Validation.
    pub validation: Validation,
    /// Every warning (reader, concatenation, N4SID, continuous-time conversion).
    pub warnings: Vec<String>,
    /// Phase checklist verdict: `None` without `--crossover-hz`.
    pub phase_checklist_passed: Option<bool>,
    /// The model file written, if any.
    pub model_file: Option<String>,
    /// Operating point and preprocessing of the model (also stored in the model file).
    pub operating_point: OperatingPoint,
    /// How the numerics treat signal scale.
    pub normalisation: &'static str,
}

/// What `identify` says about signal scale (also in its JSON report).
pub const NORMALISATION_NOTE: &str = "signals are normalised internally (N4SID: per-channel RMS; \
    spectra, fits and correlations: exact powers of two), so results do not depend on the \
    signals' units; every number is reported in the log's units";

fn parse_range(s: &str) -> Result<(usize, usize)> {
    let bad = || {
        Error::InvalidArgument(format!(
            "--order-range must look like LO..HI (e.g. 2..8), got `{s}`"
        ))
    };
    let (lo, hi) = s.split_once("..").ok_or_else(bad)?;
    let hi = hi.strip_prefix('=').unwrap_or(hi);
    let lo: usize = lo.trim().parse().map_err(|_| bad())?;
    let hi: usize = hi.trim().parse().map_err(|_| bad())?;
    if lo < 1 || hi < lo {
        return Err(Error::InvalidArgument(format!(
            "--order-range needs 1 <= LO <= HI, got {lo}..{hi}"
        )));
    }
    Ok((lo, hi))
}

impl Args {
    /// N4SID options from the flags.
    pub fn n4sid_options(&self) -> Result<N4sidOptions> {
        let order = match (self.order, &self.order_range) {
            (Some(n), _) => {
                if n < 1 {
                    return Err(Error::InvalidArgument("--order must be >= 1".into()));
                }
                OrderSelection::Fixed(n)
            }
            (None, Some(r)) => {
                let (min, max) = parse_range(r)?;
                OrderSelection::Range { min, max }
            }
            (None, None) => OrderSelection::Auto,
        };
        if let Some(m) = self.stable_margin {
            if !(m.is_finite() && m > 0.0 && m < 1.0) {
                return Err(Error::InvalidArgument(format!(
                    "--stable-margin must be in (0, 1), got {m}"
                )));
            }
        }
        Ok(N4sidOptions {
            block_rows: self.block_rows,
            order,
            weighting: match self.weighting {
                WeightingArg::Moesp => Weighting::Moesp,
                WeightingArg::Cva => Weighting::Cva,
            },
            estimate_d: !self.no_d,
            d_significance: self.d_auto.then_some(2.0),
            stability_margin: self.stable_margin,
            ..N4sidOptions::default()
        })
    }

    fn steps(&self) -> Vec<Step> {
        let mut steps = Vec::new();
        match self.remove {
            DetrendMode::Mean => steps.push(Step::RemoveMean),
            DetrendMode::Trend => steps.push(Step::RemoveTrend),
            DetrendMode::None => {}
        }
        if let Some(q) = self.decimate {
            steps.push(Step::Decimate { factor: q });
        }
        steps
    }

    fn check(&self) -> Result<()> {
        self.etfe.validate()?;
        if let Some(f) = self.crossover_hz {
            if !(f.is_finite() && f > 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "--crossover-hz must be > 0, got {f}"
                )));
            }
        }
        if !(self.phase_tol.is_finite() && self.phase_tol > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "--phase-tol must be > 0 degrees, got {}",
                self.phase_tol
            )));
        }
        if self.max_lag == 0 {
            return Err(Error::InvalidArgument("--max-lag must be >= 1".into()));
        }
        if !(2..=MAX_BLOCK_ROWS).contains(&self.block_rows) {
            return Err(Error::InvalidArgument(format!(
                "--block-rows must be in 2..={MAX_BLOCK_ROWS}, got {}",
                self.block_rows
            )));
        }
        if let Some(q) = self.decimate {
            if !(2..=MAX_DECIMATION).contains(&q) {
                return Err(Error::InvalidArgument(format!(
                    "--decimate must be in 2..={MAX_DECIMATION}, got {q}"
                )));
            }
        }
        Ok(())
    }
}

/// Concatenates preprocessed logs (checked compatible) into one log named after the first.
fn concatenate(logs: &[Log]) -> Log {
    let first = &logs[0];
    let join = |pick: &dyn Fn(&Log) -> &Vec<Channel>| -> Vec<Channel> {
        (0..pick(first).len())
            .map(|j| Channel {
                name: pick(first)[j].name.clone(),
                data: logs
                    .iter()
                    .flat_map(|l| pick(l)[j].data.iter().copied())
                    .collect(),
            })
            .collect()
    };
    Log {
        path: first.path.clone(),
        ts: first.ts,
        inputs: join(&|l: &Log| &l.inputs),
        outputs: join(&|l: &Log| &l.outputs),
        warnings: Vec::new(),
    }
}

/// Model versus ETFE for every channel pair of the validation log.
fn compare_pairs(
    model: &StateSpace,
    vlog: &Log,
    args: &Args,
) -> Result<(String, Vec<PairComparison>)> {
    let report = super::frf::estimate(std::slice::from_ref(vlog), &args.etfe)?;
    let label = match &report.method {
        super::frf::MethodSummary::Welch {
            nperseg, noverlap, ..
        } => format!("Welch H1, nperseg {nperseg}, overlap {noverlap}"),
        super::frf::MethodSummary::Periodic {
            period,
            skip_periods,
        } => format!("period-synchronous, period {period}, {skip_periods} skipped"),
    };
    let (crossover, checklist) = match args.crossover_hz {
        Some(f) => (f, true),
        // Information only: every gated bin up to Nyquist.
        None => (vlog.fs() / 4.0, false),
    };
    let m = vlog.inputs.len();
    let mut out = Vec::new();
    for (idx, e) in report.estimates.iter().enumerate() {
        let (j, i) = (idx / vlog.outputs.len(), idx % vlog.outputs.len());
        debug_assert!(j < m);
        // Only finite, positive-frequency bins are handed over.
        let keep: Vec<usize> = (0..e.freq_hz.len())
            .filter(|&k| e.freq_hz[k] > 0.0 && e.re[k].is_finite() && e.im[k].is_finite())
            .collect();
        let f: Vec<f64> = keep.iter().map(|&k| e.freq_hz[k]).collect();
        let h: Vec<Complex64> = keep
            .iter()
            .map(|&k| Complex64::new(e.re[k], e.im[k]))
            .collect();
        let g: Vec<bool> = keep.iter().map(|&k| e.gated[k]).collect();
        let comparison = compare_with_etfe(model, i, j, &f, &h, &g, crossover, args.phase_tol)
            .map_err(|err| match err {
                Error::InvalidArgument(msg) => Error::Data {
                    file: vlog.path.clone(),
                    msg: format!("validation ETFE {} -> {}: {msg}", e.input, e.output),
                },
                other => other,
            })?;
        out.push(PairComparison {
            input: e.input.clone(),
            output: e.output.clone(),
            checklist,
            comparison,
        });
    }
    Ok((label, out))
}

/// Runs the whole pipeline on already-read logs (no printing, no file writing).
pub fn identify(logs: &[Log], vlog: Option<&Log>, args: &Args) -> Result<IdentifyReport> {
    args.check()?;
    let opts = args.n4sid_options()?;
    check_compatible(logs)?;
    let steps = args.steps();
    let mut warnings = Vec::new();
    for l in logs.iter().chain(vlog) {
        for w in &l.warnings {
            warnings.push(format!("{}: {w}", l.path.display()));
        }
    }
    let mut pre_logs = Vec::with_capacity(logs.len());
    let mut records = Vec::with_capacity(logs.len());
    for l in logs {
        let (p, r) = preprocess(l, &steps)?;
        pre_logs.push(p);
        records.push(r);
    }
    let est = if pre_logs.len() == 1 {
        pre_logs.swap_remove(0)
    } else {
        warnings.push(format!(
            "{} estimation logs concatenated: each of the {} junctions disturbs the {} Hankel \
             columns that span it",
            logs.len(),
            logs.len() - 1,
            2 * args.block_rows - 1
        ));
        concatenate(&pre_logs)
    };
    let operating_point = operating_point_of(&records, est.inputs.len(), est.outputs.len())?;
    let pb = output::spinner("N4SID");
    let res = n4sid(&est, &opts);
    pb.finish_and_clear();
    let res = res?;
    warnings.extend(res.warnings.iter().map(|w| format!("n4sid: {w}")));
    let model = &res.model;
    let mut poles: Vec<Root> = model
        .poles()?
        .into_iter()
        .map(|z| Root::discrete(z, model.ts))
        .collect();
    poles.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz).then(a.im.total_cmp(&b.im)));
    let continuous = match model.d2c_zoh() {
        Ok(ct) => {
            let mut cp: Vec<Root> = ct.poles()?.into_iter().map(Root::continuous).collect();
            cp.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz).then(a.im.total_cmp(&b.im)));
            let mut zeros = Vec::new();
            if ct.is_siso() {
                match ct.to_transfer_function().and_then(|tf| tf.zeros()) {
                    Ok(z) => {
                        let nyq = 0.5 / model.ts;
                        zeros = z
                            .into_iter()
                            .map(Root::continuous)
                            .filter(|r| r.freq_hz.is_finite() && r.freq_hz < nyq)
                            .collect();
                        zeros.sort_by(|a, b| {
                            a.freq_hz.total_cmp(&b.freq_hz).then(a.im.total_cmp(&b.im))
                        });
                    }
                    Err(e) => warnings.push(format!("zeros of the continuous model: {e}")),
                }
            }
            Some(Continuous {
                model: StateSpaceData::from(&ct),
                poles: cp,
                zeros,
            })
        }
        Err(e) => {
            warnings.push(format!(
                "no continuous-time equivalent (inverse ZOH failed: {e}); the discrete model \
                 is still valid at ts = {} s",
                model.ts
            ));
            None
        }
    };

    // Validation.
    let pb = output::spinner("validating");
    let (vdata, vpre, vlog_pre) = match vlog {
        Some(v) => {
            if v.inputs.len() != est.inputs.len() || v.outputs.len() != est.outputs.len() {
                return Err(Error::Data {
                    file: v.path.clone(),
                    msg: format!(
                        "validation log has {} inputs and {} outputs, the model {} and {}",
                        v.inputs.len(),
                        v.outputs.len(),
                        est.inputs.len(),
                        est.outputs.len()
                    ),
                });
            }
            let (p, r) = preprocess(v, &steps)?;
            if ((p.ts - model.ts) / model.ts).abs() > 1e-9 {
                return Err(Error::Data {
                    file: v.path.clone(),
                    msg: format!(
                        "validation sample time {} s (after preprocessing) differs from the \
                         model's {} s",
                        p.ts, model.ts
                    ),
                });
            }
            (v.path.display().to_string(), Some(r), p)
        }
        None => ("estimation data".to_string(), None, est.clone()),
    };
    let fit = simulation_fit_log(model, &vlog_pre, InitialState::Estimate)?;
    let (etfe_label, phase) = compare_pairs(model, &vlog_pre, args)?;
    let u: Vec<&[f64]> = vlog_pre.inputs.iter().map(|c| c.data.as_slice()).collect();
    let y: Vec<&[f64]> = vlog_pre.outputs.iter().map(|c| c.data.as_slice()).collect();
    let max_lag = args.max_lag.min(vlog_pre.len() / 4).max(1);
    let residuals = residual_test(
        model,
        res.kalman_gain.as_ref().map(|k| k.as_ref()),
        &u,
        &y,
        max_lag,
    )?;
    pb.finish_and_clear();
    let (operating_point_fit, operating_point_fit_note) = match vlog {
        None => (None, Some("no --validate log".to_string())),
        Some(_) if operating_point.decimation > 1 => (
            None,
            Some(format!(
                "the model is decimated by {}: the raw validation log is not at its rate",
                operating_point.decimation
            )),
        ),
        Some(v) => match simulation_fit_operating_point(model, &operating_point, v) {
            Ok(f) => (Some(f), None),
            Err(e) => (None, Some(e.to_string())),
        },
    };
    let phase_checklist_passed = args
        .crossover_hz
        .map(|_| phase.iter().all(|p| p.comparison.within_bound));
    Ok(IdentifyReport {
        command: "identify",
        logs: logs.iter().map(LogSummary::of).collect(),
        preprocessing: records,
        estimation_samples: est.len(),
        ts: model.ts,
        options: opts,
        poles,
        continuous,
        validation: Validation {
            data: vdata,
            preprocessing: vpre,
            fit,
            etfe: etfe_label,
            gate: args.etfe.gate,
            phase,
            residuals,
            operating_point_fit,
            operating_point_fit_note,
        },
        warnings,
        phase_checklist_passed,
        model_file: args.out.as_ref().map(|p| p.display().to_string()),
        normalisation: NORMALISATION_NOTE,
        n4sid: {
            let mut s = res.summary();
            s.model.operating_point = Some(operating_point.clone());
            s
        },
        operating_point,
    })
}

fn roots_table(roots: &[Root], s_plane: bool) -> String {
    let mut t = Table::new(&[
        (if s_plane { "re [rad/s]" } else { "re" }, Align::Right),
        (if s_plane { "im [rad/s]" } else { "im" }, Align::Right),
        ("freq_Hz", Align::Right),
        ("damping", Align::Right),
    ]);
    for r in roots {
        let d = if s_plane { 3 } else { 6 };
        t.row(vec![
            fixed(r.re, d),
            fixed(r.im, d),
            fixed(r.freq_hz, 3),
            fixed(r.damping, 4),
        ]);
    }
    t.render(4)
}

/// Human-readable report.
pub fn render_text(r: &IdentifyReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "ferrosid identify");
    for l in &r.logs {
        let _ = writeln!(
            s,
            "log {}: {} samples at {} Hz, inputs [{}], outputs [{}]",
            l.path,
            l.samples,
            general(l.fs_hz, 3),
            l.inputs.join(", "),
            l.outputs.join(", ")
        );
    }
    let _ = writeln!(s, "\npreprocessing:");
    for p in r
        .preprocessing
        .iter()
        .chain(r.validation.preprocessing.as_ref())
    {
        let _ = writeln!(s, "  {}:", p.source);
        if p.steps.is_empty() {
            let _ = writeln!(s, "    none");
        }
        for step in &p.steps {
            let _ = writeln!(s, "    {}", describe_step(step));
        }
    }
    let _ = writeln!(
        s,
        "\nN4SID: {} samples, {} block rows, {} weighting, D {}, LQ via {}{}",
        r.estimation_samples,
        r.n4sid.block_rows,
        match r.options.weighting {
            Weighting::Moesp => "MOESP",
            Weighting::Cva => "CVA",
        },
        if r.n4sid.d_fixed_by_test {
            "fixed to 0 (estimate within 2 SE of zero)"
        } else if r.options.estimate_d {
            "estimated"
        } else {
            "fixed to 0"
        },
        r.n4sid.factorization_used,
        match r.options.stability_margin {
            Some(m) => format!(", stability margin {m}"),
            None => String::new(),
        }
    );
    let mut t = Table::new(&[
        ("n", Align::Right),
        ("singular value", Align::Right),
        ("canonical corr.", Align::Right),
        ("", Align::Left),
    ]);
    for (k, sv) in r.n4sid.singular_values.iter().enumerate() {
        t.row(vec![
            (k + 1).to_string(),
            output::sci(*sv, 4),
            r.n4sid
                .canonical_correlations
                .get(k)
                .map_or("-".into(), |c| fixed(*c, 4)),
            if k + 1 == r.n4sid.order {
                "<- chosen order".into()
            } else {
                String::new()
            },
        ]);
    }
    s.push_str(&t.render(2));
    let _ = writeln!(s, "{}", r.n4sid.order_reason);
    if r.n4sid.stability_enforced {
        let _ = writeln!(s, "stability was enforced (see warnings)");
    }
    let _ = writeln!(s, "\ndiscrete poles (ts = {} s):", r.ts);
    s.push_str(&roots_table(&r.poles, false));
    match &r.continuous {
        Some(c) => {
            let _ = writeln!(s, "continuous-time equivalent (inverse ZOH) poles:");
            s.push_str(&roots_table(&c.poles, true));
            if !c.zeros.is_empty() {
                let _ = writeln!(s, "continuous-time zeros below Nyquist:");
                s.push_str(&roots_table(&c.zeros, true));
            }
        }
        None => {
            let _ = writeln!(s, "no continuous-time equivalent (see warnings)");
        }
    }

    let v = &r.validation;
    let _ = writeln!(s, "\nvalidation on {}:", v.data);
    for (i, (nrmse, fit)) in v.fit.nrmse.iter().zip(&v.fit.fit_percent).enumerate() {
        let name = r
            .logs
            .first()
            .and_then(|l| l.outputs.get(i))
            .cloned()
            .unwrap_or_else(|| format!("y{i}"));
        let _ = writeln!(
            s,
            "  simulation fit {name}: {} % (NRMSE {}), initial state estimated",
            fixed(*fit, 2),
            fixed(*nrmse, 4)
        );
    }
    match (&v.operating_point_fit, &v.operating_point_fit_note) {
        (Some(f), _) => {
            for (i, fit) in f.fit_percent.iter().enumerate() {
                let _ = writeln!(
                    s,
                    "  fit on the raw log through the operating point (output {i}): {} %",
                    fixed(*fit, 2)
                );
            }
        }
        (None, Some(why)) if vlog_given(v) => {
            let _ = writeln!(s, "  no fit through the operating point: {why}");
        }
        _ => {}
    }
    let _ = writeln!(s, "  ETFE: {}, coherence gate >= {}", v.etfe, v.gate);
    for p in &v.phase {
        let c = &p.comparison;
        let _ = writeln!(
            s,
            "  {} -> {}: {} gated bins up to {} Hz compared ({} below the gate), max |phase \
             error| {} deg, max |magnitude error| {} dB{}",
            p.input,
            p.output,
            c.bins.len(),
            fixed(c.f_max_hz, 3),
            c.gated_out,
            fixed(c.max_abs_phase_err_deg, 2),
            fixed(c.max_abs_mag_err_db, 2),
            if p.checklist {
                format!(
                    ": phase checklist (+-{} deg) {}",
                    c.phase_bound_deg,
                    if c.within_bound { "PASS" } else { "FAIL" }
                )
            } else {
                " (no --crossover-hz: information only)".into()
            }
        );
        if p.checklist {
            let mut t = Table::new(&[
                ("freq_Hz", Align::Right),
                ("model_dB", Align::Right),
                ("etfe_dB", Align::Right),
                ("phase_err_deg", Align::Right),
                ("", Align::Left),
            ]);
            for b in &c.bins {
                t.row(vec![
                    fixed(b.freq_hz, 3),
                    fixed(20.0 * b.model_mag.log10(), 2),
                    fixed(20.0 * b.etfe_mag.log10(), 2),
                    fixed(b.phase_err_deg, 2),
                    if b.phase_err_deg.abs() <= c.phase_bound_deg {
                        "ok".into()
                    } else {
                        "OUT".into()
                    },
                ]);
            }
            s.push_str(&t.render(4));
        }
    }
    let rt = &v.residuals;
    let _ = writeln!(
        s,
        "  residual tests ({}, lags up to {}, 99 % bound +-{}): whiteness {} ({} % of lags \
         outside), independence from input {} ({} % outside)",
        match rt.kind {
            crate::validate::ResidualKind::OneStepPrediction => "one-step prediction error",
            crate::validate::ResidualKind::OutputError => "output error",
        },
        rt.max_lag,
        fixed(rt.bound, 4),
        if rt.whiteness_ok { "pass" } else { "fail" },
        fixed(100.0 * rt.frac_auto_outside, 1),
        if rt.independence_ok { "pass" } else { "fail" },
        fixed(100.0 * rt.frac_cross_outside, 1)
    );
    if !r.warnings.is_empty() {
        let _ = writeln!(s, "\nwarnings:");
        for w in &r.warnings {
            let _ = writeln!(s, "  {w}");
        }
    }
    let op = &r.operating_point;
    let _ =
        writeln!(
        s,
        "\noperating point (stored in the model file): u0 [{}], y0 [{}], detrend {}, decimation {}",
        op.u0.iter().map(|v| general(*v, 4)).collect::<Vec<_>>().join(", "),
        op.y0.iter().map(|v| general(*v, 4)).collect::<Vec<_>>().join(", "),
        op.detrend,
        op.decimation
    );
    let _ = writeln!(s, "{}", r.normalisation);
    if let Some(f) = &r.model_file {
        let _ = writeln!(s, "\nmodel written to {f}");
    }
    s
}

fn vlog_given(v: &Validation) -> bool {
    v.preprocessing.is_some()
}

fn describe_step(step: &crate::preprocess::StepRecord) -> String {
    use crate::preprocess::StepRecord;
    match step {
        StepRecord::RemoveMean { channels } => format!(
            "removed means: {}",
            channels
                .iter()
                .map(|c| format!("{} {}", c.channel, general(c.mean, 4)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        StepRecord::RemoveTrend { channels } => format!(
            "removed lines: {}",
            channels
                .iter()
                .map(|c| format!(
                    "{} {} + {}/s",
                    c.channel,
                    general(c.offset, 4),
                    general(c.slope_per_s, 4)
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        StepRecord::Decimate {
            factor,
            passband_edge_hz,
            fs_out_hz,
            ..
        } => format!(
            "decimated by {factor} to {} Hz (anti-aliasing passband edge {} Hz)",
            general(*fs_out_hz, 3),
            general(*passband_edge_hz, 3)
        ),
    }
}

/// Runs `ferrosid identify`.
pub fn run(args: &Args) -> Result<ExitCode> {
    args.check()?;
    args.n4sid_options()?;
    if let Some(out) = &args.out {
        let inputs: Vec<&std::path::Path> = args
            .logs
            .iter()
            .chain(&args.validate)
            .map(PathBuf::as_path)
            .collect();
        refuse_input_overwrite(out, "--out", &inputs)?;
        check_writable(out)?;
    }
    let logs = args.select.read_all(&args.logs)?;
    let vlog = match &args.validate {
        Some(p) => args.select.read_all(std::slice::from_ref(p))?.pop(),
        None => None,
    };
    let report = identify(&logs, vlog.as_ref(), args)?;
    if let Some(path) = &args.out {
        write_atomic(path, output::json_string(&report.n4sid.model)?.as_bytes())?;
    }
    if args.json {
        output::emit(&output::json_string(&report)?)?;
    } else {
        output::emit(&render_text(&report))?;
    }
    if report.phase_checklist_passed == Some(false) {
        return Ok(ExitCode::CheckFailed);
    }
    Ok(ExitCode::Ok)
}
