//! `identify` as a library call: from logs to a validated discrete state-space model.
//!
//! Steps (every one is recorded in the [`IdentifyReport`]):
//! 1. preprocess each log the same way ([`crate::preprocess`]: mean or trend removal, optional
//!    anti-aliased decimation);
//! 2. several estimation logs are concatenated after preprocessing (same sample rate and
//!    channels required); each junction disturbs the `block_rows` Hankel columns that span it,
//!    which the report states;
//! 3. N4SID ([`crate::n4sid`]) with automatic order selection or a fixed order / order range;
//! 4. continuous-time equivalent by the inverse ZOH ([`crate::lti::StateSpace::d2c_zoh`]), or a
//!    warning when the discrete poles do not allow one (e.g. poles on the negative real axis);
//! 5. validation ([`crate::validate`]) on a validation log (or, without it, on the estimation
//!    data, labelled as such): free-run simulation fit (NRMSE, fit %), model versus ETFE at
//!    every coherence-gated bin up to twice the crossover with the phase checklist, residual
//!    auto/cross-correlation tests at 99 % confidence, and the fit through the model's
//!    operating point on the raw validation log ([`crate::operating_point`]);
//! 6. the feedback test ([`crate::closed_loop::feedback_test`]) on the estimation data: a
//!    warning when the input depends on past output noise (closed-loop data, where direct
//!    N4SID is biased). With [`IdentifyOptions::closed_loop`] the reference channels are split
//!    off the logs and the plant is identified by an unbiased closed-loop method
//!    ([`crate::closed_loop`]) instead.
use super::frf::{check_compatible, FrfReport, LogSummary, MethodSummary};
use super::{NoProgress, Progress};
use crate::closed_loop::{
    feedback_test, identify_closed_loop, ClosedLoopMethod, ClosedLoopOptions, ClosedLoopSummary,
    FeedbackTest,
};
use crate::data::{Channel, Log, OperatingPoint};
use crate::error::{Error, Result};
use crate::greybox::{GreyBoxFit, GreyBoxOptions};
use crate::lti::{StateSpace, StateSpaceData};
use crate::n4sid::{n4sid, ChannelSet, N4sidOptions, N4sidResult, N4sidSummary, MAX_BLOCK_ROWS};
use crate::operating_point::operating_point_of;
use crate::preprocess::{preprocess, Preprocessing, Removal, Step, StepRecord, MAX_DECIMATION};
use crate::validate::{
    compare_with_etfe, residual_test, simulation_fit_log, simulation_fit_operating_point,
    EtfeComparison, InitialState, ResidualTest, SimulationFit, PHASE_BOUND_DEG,
};
use num_complex::Complex64;
use serde::Serialize;

/// Settings of an identification. Error messages name the options as the command line
/// spells them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IdentifyOptions {
    /// N4SID options (horizon, order choice, weighting, feedthrough, stability margin).
    pub n4sid: N4sidOptions,
    /// Offset removal applied to every log.
    pub remove: Removal,
    /// Anti-aliased decimation factor (2..=[`MAX_DECIMATION`]), after offset removal.
    pub decimate: Option<usize>,
    /// Crossover frequency in Hz: enables the phase checklist up to twice this frequency.
    pub crossover_hz: Option<f64>,
    /// Phase bound of the checklist, degrees.
    pub phase_tol_deg: f64,
    /// Largest lag of the residual correlation tests, samples.
    pub max_lag: usize,
    /// Validation ETFE settings.
    pub etfe: super::frf::FrfOptions,
    /// Closed-loop identification: `None` identifies u → y directly.
    pub closed_loop: Option<ClosedLoopSettings>,
    /// Physical parameters: a grey-box fit of this structure ([`crate::greybox`]) on the
    /// (single, SISO) estimation log after preprocessing.
    pub physical: Option<GreyBoxOptions>,
}

/// How to identify from a closed-loop log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClosedLoopSettings {
    /// The method.
    pub method: ClosedLoopMethod,
    /// Names of the reference channels: input channels of every log (estimation and
    /// validation) that are split off and used as the reference, one per remaining input.
    pub reference: Vec<String>,
    /// Stage-1 (reference → input) order of the two-stage method; `None`: automatic.
    pub stage1_order: Option<usize>,
}

impl Default for IdentifyOptions {
    fn default() -> Self {
        Self {
            n4sid: N4sidOptions::default(),
            remove: Removal::Mean,
            decimate: None,
            crossover_hz: None,
            phase_tol_deg: PHASE_BOUND_DEG,
            max_lag: 25,
            etfe: super::frf::FrfOptions::default(),
            closed_loop: None,
            physical: None,
        }
    }
}

impl IdentifyOptions {
    /// Checks the values the N4SID call itself does not.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the option.
    pub fn validate(&self) -> Result<()> {
        self.etfe.validate()?;
        if let Some(f) = self.crossover_hz {
            super::check_flag(
                "--crossover-hz",
                f,
                0.0,
                true,
                crate::io::MAX_FS_HZ / 2.0,
                " Hz",
            )?;
        }
        if !(self.phase_tol_deg.is_finite() && self.phase_tol_deg > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "--phase-tol must be > 0 degrees, got {}",
                self.phase_tol_deg
            )));
        }
        if let Some(g) = &self.physical {
            g.check()?;
            if self.closed_loop.is_some() {
                return Err(Error::InvalidArgument(
                    "--structure with --reference: the grey-box output-error fit is biased under \
                     feedback like direct N4SID; fit the physical structure on an open-loop log"
                        .into(),
                ));
            }
        }
        if self.max_lag == 0 {
            return Err(Error::InvalidArgument("--max-lag must be >= 1".into()));
        }
        if !(2..=MAX_BLOCK_ROWS).contains(&self.n4sid.block_rows) {
            return Err(Error::InvalidArgument(format!(
                "--block-rows must be in 2..={MAX_BLOCK_ROWS}, got {}",
                self.n4sid.block_rows
            )));
        }
        if let Some(q) = self.decimate {
            if !(2..=MAX_DECIMATION).contains(&q) {
                return Err(Error::InvalidArgument(format!(
                    "--decimate must be in 2..={MAX_DECIMATION}, got {q}"
                )));
            }
        }
        if let Some(m) = self.n4sid.stability_margin {
            if !(m.is_finite() && m > 0.0 && m < 1.0) {
                return Err(Error::InvalidArgument(format!(
                    "--stable-margin must be in (0, 1), got {m}"
                )));
            }
        }
        Ok(())
    }

    /// The preprocessing steps applied to every log.
    pub fn steps(&self) -> Vec<Step> {
        crate::preprocess::steps(self.remove, self.decimate.unwrap_or(1))
    }
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
    /// Feedback test on the estimation data (direct identification only; `None` with a
    /// closed-loop method, which handles feedback, or when the log is too short).
    pub feedback: Option<FeedbackTest>,
    /// The closed-loop method used, if any.
    pub closed_loop: Option<ClosedLoopSummary>,
    /// Physical parameters with intervals (with [`IdentifyOptions::physical`]).
    pub physical: Option<GreyBoxFit>,
}

/// What `identify` says about signal scale (also in its JSON report).
pub const NORMALISATION_NOTE: &str = "signals are normalised internally (N4SID: per-channel RMS; \
    spectra, fits and correlations: exact powers of two), so results do not depend on the \
    signals' units; every number is reported in the log's units";

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
    report: &FrfReport,
    opts: &IdentifyOptions,
) -> Result<(String, Vec<PairComparison>)> {
    let label = match &report.method {
        MethodSummary::Welch {
            nperseg, noverlap, ..
        } => format!("Welch H1, nperseg {nperseg}, overlap {noverlap}"),
        MethodSummary::Periodic {
            period,
            skip_periods,
        } => format!("period-synchronous, period {period}, {skip_periods} skipped"),
    };
    let (crossover, checklist) = match opts.crossover_hz {
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
        let comparison = compare_with_etfe(model, i, j, &f, &h, &g, crossover, opts.phase_tol_deg)
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

/// Identifies a model from already-read estimation logs and validates it on `vlog` (or on the
/// estimation data without one). No printing, no files; the report's `model_file` is left
/// `None` for the caller that writes one.
///
/// # Errors
/// [`Error::InvalidArgument`] for options out of range; [`Error::Data`] naming the log whose
/// channels or sample rate do not match; [`Error::Numerical`] when N4SID cannot be trusted.
pub fn identify(
    logs: &[Log],
    vlog: Option<&Log>,
    opts: &IdentifyOptions,
    progress: &dyn Progress,
) -> Result<IdentifyReport> {
    opts.validate()?;
    check_compatible(logs)?;
    let steps = opts.steps();
    let mut warnings = Vec::new();
    for l in logs.iter().chain(vlog) {
        for w in &l.warnings {
            warnings.push(format!("{}: {w}", l.path.display()));
        }
    }
    let reference = opts.closed_loop.as_ref().map(|c| c.reference.as_slice());
    let mut pre_logs = Vec::with_capacity(logs.len());
    let mut records = Vec::with_capacity(logs.len());
    let mut refs: Vec<Vec<Vec<f64>>> = Vec::new();
    for l in logs {
        let (mut p, mut r) = preprocess(l, &steps)?;
        if let Some(names) = reference {
            refs.push(split_reference(&mut p, Some(&mut r), names)?);
        }
        pre_logs.push(p);
        records.push(r);
    }
    let stripped_vlog = match (vlog, reference) {
        (Some(v), Some(names)) => {
            let mut v = v.clone();
            split_reference(&mut v, None, names)?;
            Some(v)
        }
        _ => None,
    };
    let vlog = stripped_vlog.as_ref().or(vlog);
    let est = if pre_logs.len() == 1 {
        pre_logs.swap_remove(0)
    } else {
        warnings.push(format!(
            "{} estimation logs concatenated: each of the {} junctions disturbs the {} Hankel \
             columns that span it",
            logs.len(),
            logs.len() - 1,
            2 * opts.n4sid.block_rows - 1
        ));
        concatenate(&pre_logs)
    };
    let operating_point = operating_point_of(&records, est.inputs.len(), est.outputs.len())?;
    progress.begin("N4SID", None);
    // The work that needs the data only (the feedback test, the validation data and its ETFE)
    // runs on a second thread beside N4SID; its results are used in the order a serial run
    // would use them, so the report is the same.
    let (res, data_only) = std::thread::scope(|scope| {
        let data_only = scope.spawn(|| data_only_work(&est, vlog, opts));
        let res = estimate(&est, &refs, opts, &mut warnings);
        (res, join(data_only))
    });
    progress.end();
    let (res, closed_loop) = res?;
    let DataOnly {
        feedback: (feedback, feedback_warnings),
        validation_data,
    } = data_only;
    warnings.extend(feedback_warnings);
    warnings.extend(res.warnings.iter().map(|w| format!("n4sid: {w}")));
    let model = &res.model;
    let mut poles: Vec<Root> = model
        .poles()?
        .into_iter()
        .map(|z| Root::discrete(z, model.ts))
        .collect();
    sort_roots(&mut poles);
    let continuous = continuous_equivalent(model, &mut warnings)?;
    progress.begin("validating", None);
    let validation = validate_model(&res, vlog, validation_data, &operating_point, opts);
    progress.end();
    let validation = validation?;
    let physical = match &opts.physical {
        Some(g) => {
            progress.begin("grey-box fit", None);
            let fit = physical_fit(&est, g, logs.len(), &mut warnings);
            progress.end();
            Some(fit?)
        }
        None => None,
    };
    let phase_checklist_passed = opts
        .crossover_hz
        .map(|_| validation.phase.iter().all(|p| p.comparison.within_bound));
    Ok(IdentifyReport {
        command: "identify",
        logs: logs.iter().map(LogSummary::of).collect(),
        preprocessing: records,
        estimation_samples: est.len(),
        ts: model.ts,
        options: opts.n4sid.clone(),
        poles,
        continuous,
        validation,
        warnings,
        phase_checklist_passed,
        model_file: None,
        normalisation: NORMALISATION_NOTE,
        n4sid: {
            let mut s = res.summary();
            s.model.operating_point = Some(operating_point.clone());
            s
        },
        operating_point,
        feedback,
        closed_loop,
        physical,
    })
}

/// The grey-box fit on the preprocessed estimation data `est` (SISO; with several logs
/// concatenated, the junctions are transients the output-error fit does not model: warned).
fn physical_fit(
    est: &Log,
    g: &GreyBoxOptions,
    n_logs: usize,
    warnings: &mut Vec<String>,
) -> Result<GreyBoxFit> {
    if n_logs > 1 {
        warnings.push(format!(
            "grey-box fit on {n_logs} concatenated logs: each junction is a jump the \
             output-error fit treats as data (fit one log for clean intervals)"
        ));
    }
    let fit = crate::greybox::fit_log(est, g)?;
    if !fit.converged {
        warnings.push(format!(
            "grey-box fit of {} did not converge in {} iterations: the parameters and \
             intervals are where it stopped",
            g.structure.name(),
            fit.iterations
        ));
    }
    Ok(fit)
}

/// Splits the reference channels `names` (input channels) off `log` and, when given, their
/// entries off the preprocessing `record`; returns them in the order of `names`.
fn split_reference(
    log: &mut Log,
    record: Option<&mut Preprocessing>,
    names: &[String],
) -> Result<Vec<Vec<f64>>> {
    let mut idx = Vec::with_capacity(names.len());
    for name in names {
        let j = log
            .inputs
            .iter()
            .position(|c| &c.name == name)
            .ok_or_else(|| Error::Data {
                file: log.path.clone(),
                msg: format!(
                    "--reference {}: no input channel of that name (inputs: {})",
                    crate::error::excerpt(name),
                    log.inputs
                        .iter()
                        .map(|c| c.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })?;
        if idx.contains(&j) {
            return Err(Error::InvalidArgument(format!(
                "--reference {name} given twice"
            )));
        }
        idx.push(j);
    }
    if idx.len() >= log.inputs.len() {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: "every input channel is a reference: the plant input (--input) is missing".into(),
        });
    }
    let out = idx.iter().map(|&j| log.inputs[j].data.clone()).collect();
    let mut desc = idx.clone();
    desc.sort_unstable_by(|a, b| b.cmp(a));
    for &j in &desc {
        log.inputs.remove(j);
    }
    if let Some(rec) = record {
        for step in &mut rec.steps {
            match step {
                StepRecord::RemoveMean { channels } => desc.iter().for_each(|&j| {
                    channels.remove(j);
                }),
                StepRecord::RemoveTrend { channels } => desc.iter().for_each(|&j| {
                    channels.remove(j);
                }),
                StepRecord::Decimate { .. } => {}
            }
        }
    }
    Ok(out)
}

/// The model: direct N4SID, or the closed-loop method with the reference channels `refs` (one
/// entry per estimation log, concatenated here).
fn estimate(
    est: &Log,
    refs: &[Vec<Vec<f64>>],
    opts: &IdentifyOptions,
    warnings: &mut Vec<String>,
) -> Result<(N4sidResult, Option<ClosedLoopSummary>)> {
    let Some(cl) = &opts.closed_loop else {
        return Ok((n4sid(est, &opts.n4sid)?, None));
    };
    let r: Vec<Vec<f64>> = (0..cl.reference.len())
        .map(|j| refs.iter().flat_map(|l| l[j].iter().copied()).collect())
        .collect();
    let rs: Vec<&[f64]> = r.iter().map(Vec::as_slice).collect();
    let u: Vec<&[f64]> = est.inputs.iter().map(|c| c.data.as_slice()).collect();
    let y: Vec<&[f64]> = est.outputs.iter().map(|c| c.data.as_slice()).collect();
    let un: Vec<String> = est.inputs.iter().map(|c| c.name.clone()).collect();
    let yn: Vec<String> = est.outputs.iter().map(|c| c.name.clone()).collect();
    let data = ChannelSet {
        source: &est.path,
        ts: est.ts,
        u: &u,
        y: &y,
        u_names: &un,
        y_names: &yn,
    };
    let out = identify_closed_loop(
        &data,
        &rs,
        &ClosedLoopOptions {
            method: cl.method,
            n4sid: opts.n4sid.clone(),
            stage1_order: cl.stage1_order,
        },
    )?;
    warnings.extend(out.warnings.iter().map(|w| format!("closed loop: {w}")));
    let summary = out.summary();
    Ok((out.plant, Some(summary)))
}

/// The result of a scoped thread, its panic passed on.
fn join<T>(h: std::thread::ScopedJoinHandle<'_, T>) -> T {
    h.join()
        .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
}

/// The work on the data alone: the feedback test (direct identification only) with its
/// warnings, and the validation data with its ETFE.
struct DataOnly<'a> {
    feedback: (Option<FeedbackTest>, Vec<String>),
    validation_data: Result<ValidationData<'a>>,
}

/// [`DataOnly`] for the preprocessed estimation data `est` and the validation log `vlog`.
fn data_only_work<'a>(est: &'a Log, vlog: Option<&Log>, opts: &IdentifyOptions) -> DataOnly<'a> {
    let mut warnings = Vec::new();
    let feedback = match opts.closed_loop {
        Some(_) => None,
        None => run_feedback_test(est, opts.max_lag, &mut warnings),
    };
    DataOnly {
        feedback: (feedback, warnings),
        validation_data: validation_data(est, vlog, opts),
    }
}

/// The feedback test of the direct model on the estimation data, with a warning when it
/// detects feedback; `None` (and a warning saying why) when it cannot run.
fn run_feedback_test(
    est: &Log,
    max_lag: usize,
    warnings: &mut Vec<String>,
) -> Option<FeedbackTest> {
    let u: Vec<&[f64]> = est.inputs.iter().map(|c| c.data.as_slice()).collect();
    let y: Vec<&[f64]> = est.outputs.iter().map(|c| c.data.as_slice()).collect();
    let lag = max_lag.min(est.len() / 10).max(1);
    match feedback_test(&u, &y, lag) {
        Ok(t) => {
            if t.detected {
                let worst = t.outputs.iter().max_by(|a, b| {
                    (a.statistic / a.threshold).total_cmp(&(b.statistic / b.threshold))
                });
                if let Some(w) = worst {
                    warnings.push(format!(
                        "feedback detected: the innovations (ARX predictor residual) are \
                         correlated with future inputs (N*R^2 = {:.1} > {:.1}, the chi^2({}) quantile at {} % \
                         significance): the log looks closed-loop, and direct N4SID is biased \
                         under feedback; log the reference and identify with --reference COL",
                        w.statistic,
                        w.threshold,
                        w.dof,
                        100.0 * t.significance
                    ));
                }
            }
            Some(t)
        }
        Err(e) => {
            warnings.push(format!("feedback test not run: {e}"));
            None
        }
    }
}

/// Sorts roots by natural frequency, then imaginary part.
fn sort_roots(r: &mut [Root]) {
    r.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz).then(a.im.total_cmp(&b.im)));
}

/// The continuous-time equivalent of `model` (inverse ZOH) with its poles and, for a SISO
/// model, its zeros below Nyquist; `None` with a warning when the inverse ZOH fails.
fn continuous_equivalent(
    model: &StateSpace,
    warnings: &mut Vec<String>,
) -> Result<Option<Continuous>> {
    let ct = match model.d2c_zoh() {
        Ok(ct) => ct,
        Err(e) => {
            warnings.push(format!(
                "no continuous-time equivalent (inverse ZOH failed: {e}); the discrete model \
                 is still valid at ts = {} s",
                model.ts
            ));
            return Ok(None);
        }
    };
    let mut cp: Vec<Root> = ct.poles()?.into_iter().map(Root::continuous).collect();
    sort_roots(&mut cp);
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
                sort_roots(&mut zeros);
            }
            Err(e) => warnings.push(format!("zeros of the continuous model: {e}")),
        }
    }
    Ok(Some(Continuous {
        model: StateSpaceData::from(&ct),
        poles: cp,
        zeros,
    }))
}

/// The data a model is validated on, prepared before the model exists.
struct ValidationData<'a> {
    /// What the data are ("estimation data" or the validation log's path).
    label: String,
    /// The validation log's preprocessing (`None` on the estimation data).
    record: Option<Preprocessing>,
    /// The preprocessed data.
    log: std::borrow::Cow<'a, Log>,
    /// Their ETFE.
    etfe: Result<FrfReport>,
}

/// The validation log `vlog` preprocessed like the estimation logs or, without one, the
/// preprocessed estimation data `est`, with the ETFE of either.
fn validation_data<'a>(
    est: &'a Log,
    vlog: Option<&Log>,
    opts: &IdentifyOptions,
) -> Result<ValidationData<'a>> {
    let (label, record, log) = match vlog {
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
            let (p, r) = preprocess(v, &opts.steps())?;
            (
                v.path.display().to_string(),
                Some(r),
                std::borrow::Cow::Owned(p),
            )
        }
        None => (
            "estimation data".to_string(),
            None,
            std::borrow::Cow::Borrowed(est),
        ),
    };
    let etfe = super::frf::estimate(std::slice::from_ref(&*log), &opts.etfe, &NoProgress);
    Ok(ValidationData {
        label,
        record,
        log,
        etfe,
    })
}

/// Validation of the identified model on the prepared data `data` (the preprocessed `vlog`,
/// or the estimation data without one). The residual tests run on a second thread beside the
/// simulation fit and the ETFE comparison.
fn validate_model(
    res: &N4sidResult,
    vlog: Option<&Log>,
    data: Result<ValidationData<'_>>,
    operating_point: &OperatingPoint,
    opts: &IdentifyOptions,
) -> Result<Validation> {
    let model = &res.model;
    let ValidationData {
        label: vdata,
        record: vpre,
        log: vlog_pre,
        etfe,
    } = data?;
    if let Some(v) = vlog {
        if ((vlog_pre.ts - model.ts) / model.ts).abs() > 1e-9 {
            return Err(Error::Data {
                file: v.path.clone(),
                msg: format!(
                    "validation sample time {} s (after preprocessing) differs from the \
                     model's {} s",
                    vlog_pre.ts, model.ts
                ),
            });
        }
    }
    let u: Vec<&[f64]> = vlog_pre.inputs.iter().map(|c| c.data.as_slice()).collect();
    let y: Vec<&[f64]> = vlog_pre.outputs.iter().map(|c| c.data.as_slice()).collect();
    let max_lag = opts.max_lag.min(vlog_pre.len() / 4).max(1);
    let (fit, pairs, residuals) = std::thread::scope(|scope| {
        let residuals = scope.spawn(|| {
            residual_test(
                model,
                res.kalman_gain.as_ref().map(|k| k.as_ref()),
                &u,
                &y,
                max_lag,
            )
        });
        let fit = simulation_fit_log(model, &vlog_pre, InitialState::Estimate);
        let pairs = match (&fit, etfe) {
            (Ok(_), Ok(report)) => compare_pairs(model, &vlog_pre, &report, opts),
            (_, Err(e)) => Err(e),
            (Err(_), Ok(_)) => Ok((String::new(), Vec::new())), // not used: `fit` fails first
        };
        (fit, pairs, join(residuals))
    });
    let fit = fit?;
    let (etfe_label, phase) = pairs?;
    let residuals = residuals?;
    let (operating_point_fit, operating_point_fit_note) = match vlog {
        None => (None, Some("no --validate log".to_string())),
        Some(_) if operating_point.decimation > 1 => (
            None,
            Some(format!(
                "the model is decimated by {}: the raw validation log is not at its rate",
                operating_point.decimation
            )),
        ),
        Some(v) => match simulation_fit_operating_point(model, operating_point, v) {
            Ok(f) => (Some(f), None),
            Err(e) => (None, Some(e.to_string())),
        },
    };
    Ok(Validation {
        data: vdata,
        preprocessing: vpre,
        fit,
        etfe: etfe_label,
        gate: opts.etfe.gate,
        phase,
        residuals,
        operating_point_fit,
        operating_point_fit_note,
    })
}
