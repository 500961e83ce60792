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
use super::frf::{EtfeArgs, LogArgs};
use super::output::{self, fixed, general, Align, Table, TerminalProgress};
use super::ExitCode;
use crate::closed_loop::ClosedLoopMethod;
use crate::data::Log;
use crate::error::{Error, Result};
use crate::greybox::{GreyBoxFit, GreyBoxOptions, ParameterStatus, Structure};
use crate::io::file_safety::{check_output_file, refuse_input_overwrite, write_atomic, Own};

/// Top-level keys every `--params-out` file ferrosid writes has (a grey-box fit).
const PARAMS_KEYS: &[&str] = &["structure", "parameters", "confidence", "interval_method"];
use crate::n4sid::{N4sidOptions, OrderSelection, Weighting};
use crate::ops::identify::ClosedLoopSettings;
pub use crate::ops::identify::{
    identify as identify_with, Continuous, IdentifyOptions, IdentifyReport, PairComparison, Root,
    Validation, NORMALISATION_NOTE,
};
use crate::preprocess::Removal;
use crate::validate::PHASE_BOUND_DEG;
use std::fmt::Write as _;
use std::path::PathBuf;

/// The `--weighting` values (the library's [`crate::n4sid::Weighting`]).
pub use crate::n4sid::Weighting as WeightingArg;
/// The `--remove` values (the library's [`crate::preprocess::Removal`]).
pub use crate::preprocess::Removal as DetrendMode;

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
  ferrosid identify loop.csv --reference r --order 2      (closed loop: u, y and the reference r)
  ferrosid identify MultisineTypeA.mat --input iq_refx --output omega_max --decimate 4 \\
      --order 4 --structure two-mass-lag --known Kt=1 --params-out params.json

Several estimation logs are preprocessed separately and concatenated. The validation log gets the
same preprocessing; its ETFE uses the --nperseg/--window/--period/--gate settings (as `frf`).
The model file (--out) holds {\"a\",\"b\",\"c\",\"d\",\"ts\"} (matrix rows, ts in seconds) and the
operating point (the means removed: the model maps y - y0 = G (u - u0)); it is accepted by
`ferrosid gap --sim` and `ferrosid codegen --model`. --out may not name an input log.

Without --reference, a feedback test warns when the input depends on past output noise (the log
was recorded in closed loop: direct N4SID is then biased; give the reference with --reference).
--structure fits a physical model (grey box) and prints its parameters with 95 % intervals; a
parameter the signals cannot separate must be given with --known NAME=VALUE (SI units).

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
    #[arg(long, value_enum, default_value_t = Weighting::Moesp)]
    pub weighting: Weighting,
    /// Offset removal before identification.
    #[arg(long = "remove", value_enum, default_value_t = Removal::Mean)]
    pub remove: Removal,
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
    /// Replace an existing --out/--params-out file even when ferrosid did not write it.
    #[arg(long)]
    pub force: bool,
    /// Closed-loop log: the reference channel (same conventions as --input; one per input).
    /// Selects an unbiased closed-loop method (--closed-loop-method) instead of direct N4SID.
    #[arg(long, value_name = "NAME")]
    pub reference: Vec<String>,
    /// Closed-loop method (with --reference): two-stage (plant order) or joint-input-output
    /// (closed-loop order; unstable plants; needs a controller with direct feedthrough).
    #[arg(long, value_enum, default_value_t = ClosedLoopMethod::TwoStage, requires = "reference")]
    pub closed_loop_method: ClosedLoopMethod,
    /// Order of the two-stage method's stage-1 model reference -> input (default: automatic).
    #[arg(long, value_name = "N", requires = "reference")]
    pub stage1_order: Option<usize>,
    /// Physical structure to fit (grey box): stage, stage-velocity, dc-motor, two-mass,
    /// two-mass-position, two-mass-lag. Prints the physical parameters with units, 95 % intervals and status.
    #[arg(long, value_name = "NAME")]
    pub structure: Option<String>,
    /// A parameter of --structure known from elsewhere, held fixed (SI units), e.g. Kt=0.12.
    /// Repeat for several. Required where one input/output pair cannot separate parameters.
    #[arg(long, value_name = "NAME=VALUE", requires = "structure")]
    pub known: Vec<String>,
    /// Write the physical parameters (--structure) to this JSON file.
    #[arg(long, value_name = "FILE", requires = "structure")]
    pub params_out: Option<PathBuf>,
}

/// `--known NAME=VALUE` → (name, value).
pub(crate) fn parse_known(s: &str) -> Result<(String, f64)> {
    let bad = || {
        Error::InvalidArgument(format!(
            "--known must look like NAME=VALUE (e.g. Kt=0.12), got `{}`",
            crate::error::excerpt(s)
        ))
    };
    let (name, value) = s.split_once('=').ok_or_else(bad)?;
    let value: f64 = value.trim().parse().map_err(|_| bad())?;
    Ok((name.trim().to_string(), value))
}

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
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `--order 0` or a malformed `--order-range`.
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
        Ok(N4sidOptions {
            block_rows: self.block_rows,
            order,
            weighting: self.weighting,
            estimate_d: !self.no_d,
            d_significance: self.d_auto.then_some(2.0),
            stability_margin: self.stable_margin,
            ..N4sidOptions::default()
        })
    }

    /// The library options these flags describe, checked.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the flag that is out of range.
    pub fn options(&self) -> Result<IdentifyOptions> {
        let opts = IdentifyOptions {
            n4sid: self.n4sid_options()?,
            remove: self.remove,
            decimate: self.decimate,
            crossover_hz: self.crossover_hz,
            phase_tol_deg: self.phase_tol,
            max_lag: self.max_lag,
            etfe: self.etfe.options()?,
            closed_loop: if self.reference.is_empty() {
                None
            } else {
                if self.stage1_order == Some(0) {
                    return Err(Error::InvalidArgument("--stage1-order must be >= 1".into()));
                }
                Some(ClosedLoopSettings {
                    method: self.closed_loop_method,
                    reference: self.reference.clone(),
                    stage1_order: self.stage1_order,
                })
            },
            physical: match &self.structure {
                None => None,
                Some(name) => {
                    let mut g = GreyBoxOptions::new(Structure::parse(name)?);
                    for k in &self.known {
                        let (n, v) = parse_known(k)?;
                        g = g.with_known(&n, v);
                    }
                    Some(g)
                }
            },
        };
        opts.validate()?;
        Ok(opts)
    }
}

/// Identifies and validates a model from already-read logs with these flags
/// ([`crate::ops::identify::identify`], progress on stderr; no printing, no file writing).
pub fn identify(logs: &[Log], vlog: Option<&Log>, args: &Args) -> Result<IdentifyReport> {
    let mut report = identify_with(logs, vlog, &args.options()?, &TerminalProgress::default())?;
    report.model_file = args.out.as_ref().map(|p| p.display().to_string());
    Ok(report)
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
    text_header(&mut s, r);
    text_order(&mut s, r);
    text_poles(&mut s, r);
    text_validation(&mut s, r);
    text_footer(&mut s, r);
    s
}

/// Title, logs, preprocessing and the identification settings.
fn text_header(s: &mut String, r: &IdentifyReport) {
    let _ = writeln!(s, "ferrosid identify");
    for l in &r.logs {
        let _ = writeln!(s, "{}", super::output::log_line(l));
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
            Some(m) => format!(", stability margin {}", super::num(m)),
            None => String::new(),
        }
    );
}

/// Closed-loop method, singular values and the order choice.
fn text_order(s: &mut String, r: &IdentifyReport) {
    if let Some(cl) = &r.closed_loop {
        let _ = writeln!(
            s,
            "closed-loop method: {} (closed-loop model order {}; the reference explains {} of \
             the input energy)",
            cl.description,
            cl.closed_loop_order,
            cl.input_explained
                .iter()
                .map(|e| format!("{} %", fixed(100.0 * e, 1)))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
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
}

/// Discrete poles and the continuous equivalent.
fn text_poles(s: &mut String, r: &IdentifyReport) {
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
}

/// Validation: fit, operating point, ETFE phase agreement, residual tests.
fn text_validation(s: &mut String, r: &IdentifyReport) {
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
    let _ = writeln!(
        s,
        "  ETFE: {}, coherence gate >= {}",
        v.etfe,
        super::num(v.gate)
    );
    for p in &v.phase {
        let c = &p.comparison;
        let _ = writeln!(
            s,
            "  {} -> {}: {} gated bins up to {} Hz compared ({} below the gate), max |phase \
             error| {} deg, max |magnitude error| {} dB{}",
            p.input,
            p.output,
            c.bins.len(),
            output::general(c.f_max_hz, 3),
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
}

/// Feedback test, physical parameters, warnings, operating point, output file.
fn text_footer(s: &mut String, r: &IdentifyReport) {
    if let Some(f) = &r.feedback {
        for (o, st) in f.outputs.iter().enumerate() {
            let _ = writeln!(
                s,
                "  feedback test (output {o}, innovations vs future inputs at lags 1..{}): \
                 N*R^2 = {} vs chi^2({}) threshold {} at {} %: {}",
                f.max_lag,
                fixed(st.statistic, 1),
                st.dof,
                fixed(st.threshold, 1),
                100.0 * f.significance,
                if st.detected {
                    "FEEDBACK DETECTED (see warnings)"
                } else {
                    "no feedback detected"
                }
            );
        }
    }
    if let Some(g) = &r.physical {
        s.push_str(&render_physical(g));
    }
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
}

/// The physical parameters of a grey-box fit as a table with units, intervals and status.
pub fn render_physical(g: &GreyBoxFit) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\nphysical parameters ({}; {} % intervals; fit NRMSE {} vs black box {}; {} \
         iterations{}):",
        g.structure.name(),
        (100.0 * g.confidence * 1e6).round() / 1e6,
        fixed(g.nrmse, 4),
        fixed(g.black_box_nrmse, 4),
        g.iterations,
        if g.converged { "" } else { ", NOT converged" }
    );
    let mut t = Table::new(&[
        ("name", Align::Left),
        ("value", Align::Right),
        ("interval", Align::Right),
        ("unit", Align::Left),
        ("status", Align::Left),
        ("meaning", Align::Left),
    ]);
    for p in &g.parameters {
        t.row(vec![
            p.name.clone(),
            general(p.value, 5),
            p.interval.map_or("-".into(), |[lo, hi]| {
                format!("[{}, {}]", general(lo, 4), general(hi, 4))
            }),
            p.unit.clone(),
            match p.status {
                ParameterStatus::Estimated => "estimated",
                ParameterStatus::Known => "known",
                ParameterStatus::Undetermined => "undetermined (value means nothing)",
            }
            .into(),
            p.description.clone(),
        ]);
    }
    s.push_str(&t.render(2));
    let _ = writeln!(s, "  intervals: {}", g.interval_method);
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
    args.options()?;
    let inputs: Vec<&std::path::Path> = args
        .logs
        .iter()
        .chain(&args.validate)
        .map(PathBuf::as_path)
        .collect();
    for (flag, out, own) in [
        ("--out", &args.out, Own::Content(super::own_model_file)),
        ("--params-out", &args.params_out, Own::JsonKeys(PARAMS_KEYS)),
    ] {
        if let Some(out) = out {
            refuse_input_overwrite(out, flag, &inputs)?;
            check_output_file(out, flag, own, args.force)?;
        }
    }
    let mut select = args.select.clone();
    if !args.reference.is_empty() {
        // The reference channels are read as extra inputs and split off again by the library.
        if select.inputs.is_empty() {
            select.inputs.push("u".into());
        }
        select.inputs.extend(args.reference.iter().cloned());
    }
    let logs = select.read_all(&args.logs)?;
    let vlog = match &args.validate {
        Some(p) => select.read_all(std::slice::from_ref(p))?.pop(),
        None => None,
    };
    let report = identify(&logs, vlog.as_ref(), args)?;
    if let Some(path) = &args.out {
        write_atomic(path, output::json_string(&report.n4sid.model)?.as_bytes())?;
    }
    if let (Some(path), Some(g)) = (&args.params_out, &report.physical) {
        write_atomic(path, output::json_string(g)?.as_bytes())?;
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
