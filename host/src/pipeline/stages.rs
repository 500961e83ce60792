//! The stages of [`super::run_pipeline`], one function each, in the order they run:
//! ingest → preprocess + ETFE → N4SID → validation → audit → uncertainty weight → tuning →
//! receipts (the gap diagnosis is [`super::gap_stage`]). Every stage returns a `Result` for
//! errors (unreadable data, bad configuration, numerical failure); a finding that is not an
//! error (no weight can be formed, no controller meets the limits) is returned as a value
//! that becomes a note or a failing receipt.
use super::config::{self, LoadedConfig, PipelineConfig};
use super::RESIDUAL_MAX_LAG;
use super::{
    display_path, fmt_num, log_grid, rms, sha256_hex, EnvelopeData, InputFile, LogData, NoWeight,
    TuningFailed, WeightFit,
};
use crate::data::Log;
use crate::error::{Error, Result};
use crate::io::{read_log, LogSpec};
use crate::lti::StateSpace;
use crate::n4sid::{n4sid, N4sidOptions, N4sidResult, OrderSelection};
use crate::preprocess::{preprocess, Step};
use crate::robust::audit::{audit_nonlinearity, AuditOptions, FrfRun, NonlinearityAudit};
use crate::robust::pid::{implemented_loop, tune_pid, Pid, TunedPid};
use crate::robust::receipts::{
    compute_receipts, cross_validation_receipt, etfe_phase_receipt, loop_curves, phase_agreement,
    Comparison, CrossValidation, EtfeView, LoopCurves, Receipt, ReceiptInputs, ReceiptKind,
    ReceiptLimits, Receipts, ReceiptsReport,
};
use crate::robust::uncertainty::{
    fit_uncertainty_weight, multiplicative_envelope, UncertaintyWeight, WeightFitOptions,
};
use crate::spectral::Welch;
use crate::validate::{
    residual_test, simulation_fit_log, InitialState, ResidualTest, SimulationFit,
};
use num_complex::Complex64;
use std::f64::consts::PI;

/// Reads one log of the pipeline and records its provenance.
fn ingest(
    cfg: &LoadedConfig,
    key: &str,
    role: &str,
    name: &str,
    entry: &config::LogEntry,
) -> Result<(Log, InputFile)> {
    let s = &cfg.config.signals;
    let path = cfg.resolve(&entry.file);
    let bytes = crate::io::input::read_bytes(&path, crate::io::input::MAX_LOG_BYTES)?;
    let spec = LogSpec {
        inputs: vec![entry.input.clone().unwrap_or_else(|| s.input.clone())],
        outputs: vec![entry.output.clone().unwrap_or_else(|| s.output.clone())],
        time: entry.time.clone().or_else(|| s.time.clone()),
        time_scale: s.time_scale,
        fs: entry.fs.or(s.fs),
        ..LogSpec::default()
    };
    let mut spec = spec;
    if let Some(j) = s.time_jitter {
        spec.checks.time_jitter_rel = j;
    }
    let log = read_log(&path, &spec).map_err(|e| match e {
        Error::InvalidArgument(m) => cfg.key_error(&format!("{key}.file"), m),
        other => other,
    })?;
    let file = InputFile {
        role: role.into(),
        name: name.into(),
        path: display_path(&entry.file),
        sha256: sha256_hex(&bytes),
        bytes: bytes.len() as u64,
        samples: log.len(),
        fs_hz: log.fs(),
        warnings: log.warnings.clone(),
    };
    Ok((log, file))
}

/// The pipeline file's own provenance entry.
pub(super) fn pipeline_file_entry(cfg: &LoadedConfig) -> InputFile {
    let file_name = cfg
        .path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    InputFile {
        role: "pipeline".into(),
        name: file_name.clone(),
        path: file_name,
        sha256: sha256_hex(cfg.text.as_bytes()),
        bytes: cfg.text.len() as u64,
        samples: 0,
        fs_hz: 0.0,
        warnings: Vec::new(),
    }
}

/// The report title: `name`, or the pipeline file's stem.
pub(super) fn title(cfg: &LoadedConfig) -> String {
    cfg.config.name.clone().unwrap_or_else(|| {
        cfg.path
            .file_stem()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "pipeline".into())
    })
}

/// A log as read, with its run name and configured amplitude.
pub(super) struct RawLog {
    name: String,
    amplitude: Option<f64>,
    log: Log,
}

/// The logs as read, and the provenance of each (runs…, validation).
pub(super) struct Ingested {
    runs: Vec<RawLog>,
    validation: Option<RawLog>,
    inputs: Vec<InputFile>,
}

/// Reads every `[[runs]]` log and the `[validation]` log and checks that they share one
/// sample rate.
pub(super) fn ingest_all(cfg: &LoadedConfig, names: &[String]) -> Result<Ingested> {
    let c = &cfg.config;
    let mut runs = Vec::new();
    let mut inputs = Vec::new();
    for (i, entry) in c.runs.iter().enumerate() {
        let (log, file) = ingest(cfg, &format!("runs[{i}]"), "run", &names[i], entry)?;
        runs.push(RawLog {
            name: names[i].clone(),
            amplitude: entry.amplitude,
            log,
        });
        inputs.push(file);
    }
    let validation = match &c.validation {
        Some(v) => {
            let name = v.name.clone().unwrap_or_else(|| "validation".into());
            let (log, file) = ingest(cfg, "validation", "validation", &name, v)?;
            inputs.push(file);
            Some(RawLog {
                name,
                amplitude: v.amplitude,
                log,
            })
        }
        None => None,
    };
    let ts0 = runs[0].log.ts;
    for r in runs.iter().chain(validation.iter()) {
        let log = &r.log;
        if (log.ts - ts0).abs() > 1e-9 * ts0 {
            return Err(Error::Data {
                file: log.path.clone(),
                msg: format!(
                    "sample rate {} Hz differs from {} Hz of `{}`: every log of a pipeline \
                     must share one sample rate (one ETFE grid, one model)",
                    log.fs(),
                    1.0 / ts0,
                    runs[0].log.path.display()
                ),
            });
        }
    }
    Ok(Ingested {
        runs,
        validation,
        inputs,
    })
}

/// One log of a pipeline run: `raw` preprocessed with `steps`, its ETFE with `welch`, and the
/// audit's excitation amplitude (`amplitude` when configured, else the input RMS after
/// preprocessing).
pub(super) fn prepare_log(
    name: String,
    amplitude: Option<f64>,
    raw: Log,
    steps: &[Step],
    welch: &Welch,
) -> Result<LogData> {
    let (log, preprocessing) = preprocess(&raw, steps)?;
    let etfe = welch.etfe_log(&log, 0, 0)?;
    let (amplitude, amplitude_is_rms) = match amplitude {
        Some(a) => (a, false),
        None => (rms(log.u()), true),
    };
    Ok(LogData {
        name,
        amplitude,
        amplitude_is_rms,
        log,
        raw,
        preprocessing,
        etfe,
    })
}

/// Preprocesses every log identically and estimates its ETFE on the common Welch grid.
/// Returns the runs, the validation log and the provenance entries.
pub(super) fn prepare_logs(
    cfg: &LoadedConfig,
    ingested: Ingested,
    progress: &dyn Fn(&str),
) -> Result<(Vec<LogData>, Option<LogData>, Vec<InputFile>)> {
    let c = &cfg.config;
    progress("preprocess");
    let steps = c.preprocess.steps();
    let welch = c.etfe.welch();
    let prep = |r: RawLog, written: String| -> Result<LogData> {
        let mut d = prepare_log(r.name, r.amplitude, r.log, &steps, &welch)?;
        // Record the path as written in the pipeline file, not as resolved from the current
        // directory, so receipts.json does not depend on where `ferrosid run` was started.
        d.preprocessing.source = written;
        Ok(d)
    };
    progress("etfe");
    let Ingested {
        runs: raw_runs,
        validation: raw_val,
        inputs,
    } = ingested;
    let mut runs = Vec::new();
    for (i, r) in raw_runs.into_iter().enumerate() {
        runs.push(prep(r, inputs[i].path.clone())?);
    }
    let validation = match raw_val {
        Some(r) => {
            let written = inputs.last().map(|f| f.path.clone()).unwrap_or_default();
            Some(prep(r, written)?)
        }
        None => None,
    };
    Ok((runs, validation, inputs))
}

/// Refuses a target crossover at or above the data's Nyquist frequency (`fs` Hz).
pub(super) fn check_crossover(cfg: &LoadedConfig, fs: f64) -> Result<()> {
    let fc_target = cfg.config.control.crossover_hz;
    if fc_target >= 0.5 * fs {
        return Err(cfg.key_error(
            "control.crossover_hz",
            format!(
                "{fc_target} Hz is at or above the Nyquist frequency {} Hz of the data",
                0.5 * fs
            ),
        ));
    }
    Ok(())
}

/// Index of the estimation run: `[identification].run`, else the largest amplitude.
pub(super) fn nominal_index(cfg: &LoadedConfig, names: &[String], runs: &[LogData]) -> usize {
    match &cfg.config.identification.run {
        Some(r) => names.iter().position(|n| n == r).unwrap_or(0),
        None => {
            let mut best = 0;
            for (i, r) in runs.iter().enumerate() {
                if r.amplitude > runs[best].amplitude {
                    best = i;
                }
            }
            best
        }
    }
}

/// The N4SID options of `[identification]`.
pub(super) fn n4sid_options(id: &config::Identification) -> N4sidOptions {
    let order = match (id.order, id.order_min, id.order_max) {
        (Some(n), _, _) => OrderSelection::Fixed(n),
        (None, None, None) => OrderSelection::Auto,
        (None, lo, hi) => OrderSelection::Range {
            min: lo.unwrap_or(1),
            max: hi.unwrap_or(((id.block_rows - 1).min(20)).max(lo.unwrap_or(1))),
        },
    };
    N4sidOptions {
        block_rows: id.block_rows,
        order,
        estimate_d: id.estimate_d,
        stability_margin: id.stability_margin,
        ..N4sidOptions::default()
    }
}

/// N4SID on the estimation run; option errors name `[identification]`.
pub(super) fn identify_nominal(cfg: &LoadedConfig, run: &LogData) -> Result<N4sidResult> {
    n4sid(&run.log, &n4sid_options(&cfg.config.identification)).map_err(|e| match e {
        Error::InvalidArgument(m) => cfg.key_error("identification", m),
        other => other,
    })
}

/// Free-run fit and residual tests of G0 on the validation log (both `None` without one; the
/// residual tests `None` when they cannot be computed).
pub(super) fn validate_nominal(
    ident: &N4sidResult,
    validation: Option<&LogData>,
) -> Result<(Option<SimulationFit>, Option<ResidualTest>)> {
    let model = &ident.model;
    Ok(match validation {
        Some(v) => {
            let fit = simulation_fit_log(model, &v.log, InitialState::Estimate)?;
            let lag = RESIDUAL_MAX_LAG.min(v.log.len() / 4).max(1);
            let res = residual_test(
                model,
                ident.kalman_gain.as_ref().map(|k| k.as_ref()),
                &[v.log.u()],
                &[v.log.y()],
                lag,
            )
            .ok();
            (Some(fit), res)
        }
        None => (None, None),
    })
}

/// The dual-amplitude nonlinearity audit of the runs' ETFEs (`None` with fewer than two runs).
pub(super) fn audit_runs(
    cfg: &LoadedConfig,
    runs: &[LogData],
    fc_target: f64,
) -> Result<Option<NonlinearityAudit>> {
    if runs.len() < 2 {
        return Ok(None);
    }
    let a = &cfg.config.audit;
    let frf: Vec<FrfRun> = runs
        .iter()
        .map(|r| FrfRun {
            label: r.name.clone(),
            amplitude: r.amplitude,
            freq_hz: r.etfe.freq_hz.clone(),
            h: r.etfe.h.clone(),
            coherence: r.etfe.coherence.clone(),
        })
        .collect();
    let opts = AuditOptions {
        crossover_hz: fc_target,
        band_factor: a.band_factor,
        max_gain_shift_db: a.max_gain_shift_db,
        max_phase_shift_deg: a.max_phase_shift_deg,
        min_coherence: a.min_coherence,
        coherence_band_factor: a.coherence_band_factor,
    };
    audit_nonlinearity(&frf, &opts)
        .map(Some)
        .map_err(|e| match e {
            Error::InvalidArgument(m) => cfg.key_error("audit", m),
            other => other,
        })
}

/// Robust PID tuning of G0 against `[control]`: `Ok(Err(why))` when no controller meets the
/// limits (a finding, reported by the `controller_design` receipt), `Err` for other errors.
pub(super) fn tune(
    c: &PipelineConfig,
    model: &StateSpace,
    weight: Option<&UncertaintyWeight>,
) -> Result<std::result::Result<TunedPid, TuningFailed>> {
    let spec = super::control_stage::pid_spec(c, weight);
    match tune_pid(model, &spec) {
        Ok(t) => Ok(Ok(t)),
        Err(Error::InvalidArgument(m)) | Err(Error::Numerical(m)) => Ok(Err(TuningFailed(m))),
        Err(e) => Err(e),
    }
}

/// The `controller_design` receipt: the achieved crossover against the smallest accepted one.
pub(super) fn controller_design_receipt(
    c: &PipelineConfig,
    tuning: std::result::Result<&TunedPid, &str>,
) -> Receipt {
    let k = &c.control;
    let fc_target = k.crossover_hz;
    let min_fc = k.min_crossover_scale * fc_target;
    Receipt::new(
        ReceiptKind::ControllerDesign,
        "achieved design crossover of the robust PID (highest crossover meeting M_s, ‖W_m T‖∞ \
         < 1 and the actuator limit)",
        tuning.map_or(f64::NAN, |t| t.design.crossover_hz),
        Comparison::AtLeast,
        min_fc,
        "Hz",
        match tuning {
            Ok(t) => format!(
                "target {} Hz; phase-margin target {:.1} deg, integral ratio {:.3}, lead ratio \
                 {:.3}; {} candidates evaluated",
                fmt_num(fc_target),
                t.design.phase_margin_target_deg,
                t.design.integral_ratio,
                t.design.lead_ratio,
                t.candidates_evaluated
            ),
            Err(e) => e.to_string(),
        },
    )
}

/// Receipt limits at crossover `fc` Hz with the `[receipts]` and `[control]` overrides.
pub(super) fn receipt_limits(c: &PipelineConfig, fc: f64) -> ReceiptLimits {
    let r = &c.receipts;
    let mut limits = ReceiptLimits::for_crossover(fc);
    limits.ms_max = c.control.ms_max;
    let set = |slot: &mut f64, v: Option<f64>| {
        if let Some(v) = v {
            *slot = v;
        }
    };
    set(&mut limits.gain_margin_db_min, r.gain_margin_db_min);
    set(&mut limits.phase_margin_deg_min, r.phase_margin_deg_min);
    set(&mut limits.mt_max, r.mt_max);
    set(
        &mut limits.disturbance_bandwidth_hz_min,
        r.disturbance_bandwidth_hz_min,
    );
    set(&mut limits.overshoot_pct_max, r.overshoot_pct_max);
    set(&mut limits.settling_time_s_max, r.settling_time_s_max);
    set(
        &mut limits.etfe_phase_error_deg_max,
        r.etfe_phase_error_deg_max,
    );
    set(&mut limits.etfe_max_freq_factor, r.etfe_max_freq_factor);
    limits
}

/// The cross-validation evidence of the validation fit (`None` without a validation log).
pub(super) fn cross_validation_of(
    fit: Option<&SimulationFit>,
    validation: Option<&LogData>,
    limit_percent: f64,
) -> Option<CrossValidation> {
    fit.map(|f| CrossValidation {
        fit_percent: f.fit_percent[0],
        limit_percent,
        detail: format!(
            "free-run simulation of G0 on `{}` ({} samples), initial state estimated; NRMSE {}",
            validation.map_or("", |v| v.name.as_str()),
            validation.map_or(0, |v| v.log.len()),
            fmt_num(f.nrmse[0])
        ),
    })
}

/// What the loop receipts stage needs besides the configuration.
#[derive(Clone)]
pub(super) struct LoopStageInputs<'a> {
    /// G0.
    pub model: &'a StateSpace,
    /// The tuned controller, if any.
    pub tuned: Option<&'a TunedPid>,
    /// The fitted weight, if any.
    pub weight: Option<&'a UncertaintyWeight>,
    /// The estimation run (its ETFE is the phase reference).
    pub nominal: &'a LogData,
    /// Sample rate of the logs, Hz.
    pub fs: f64,
    /// Crossover the receipts refer to, Hz.
    pub fc: f64,
    /// Limits of the receipts.
    pub limits: ReceiptLimits,
    /// Cross-validation evidence, if any.
    pub cross_validation: Option<CrossValidation>,
}

/// The receipts' inputs for the loop of `model` and `pid` with the `[control]` settings
/// (no ETFE, no cross-validation: the model receipts are the caller's).
pub(super) fn receipt_inputs<'a>(
    c: &'a PipelineConfig,
    model: &'a StateSpace,
    pid: &'a Pid,
    fc: f64,
    weight: Option<&'a UncertaintyWeight>,
    limits: ReceiptLimits,
) -> ReceiptInputs<'a> {
    let k = &c.control;
    ReceiptInputs {
        plant: model,
        pid,
        controller_ts: None,
        crossover_hz: fc,
        weight,
        actuator_limit: k.actuator_limit,
        actuator_unit: &c.signals.input_unit,
        reference_amplitude: k.reference_amplitude,
        etfe: None,
        cross_validation: None,
        limits,
        anti_windup: k.anti_windup,
    }
}

/// The frequency grid of the loop curves, Hz: 600 log-spaced points from below the
/// crossover and the lowest ETFE bin (`f_first_bin`) to just under Nyquist.
pub(super) fn curves_grid(fc: f64, fs: f64, f_first_bin: Option<f64>) -> Vec<f64> {
    let f_lo = (fc / 50.0).min(0.5 * f_first_bin.unwrap_or(fc));
    log_grid(f_lo, 0.5 * fs * 0.999, 600)
}

/// The loop receipts of the tuned controller and the loop curves for the report; without a
/// controller only the model receipts (ETFE phase, cross-validation) are issued.
pub(super) fn loop_receipts(
    c: &PipelineConfig,
    inp: LoopStageInputs<'_>,
    receipts: &mut Receipts,
) -> Result<(Option<ReceiptsReport>, Option<LoopCurves>)> {
    let nom = &inp.nominal.etfe;
    let gate = nom.gate(c.etfe.coherence_gate);
    let view = EtfeView {
        freq_hz: &nom.freq_hz,
        h: &nom.h,
        gate: Some(&gate),
    };
    let fc = inp.fc;
    let Some(t) = inp.tuned else {
        // Without a controller the loop receipts cannot be issued (they are absent and the
        // failing `controller_design` receipt says why); the model receipts still are.
        let p = phase_agreement(inp.model, &view, inp.limits.etfe_max_freq_factor * fc)?;
        receipts.push(etfe_phase_receipt(
            &p,
            inp.limits.etfe_phase_error_deg_max,
            format!(
                "{} gated bins up to {} Hz (target crossover; no controller)",
                p.bins_used,
                fmt_num(p.f_max_hz)
            ),
        ));
        if let Some(cv) = &inp.cross_validation {
            receipts.push(cross_validation_receipt(cv));
        }
        return Ok((None, None));
    };
    let rep = compute_receipts(&ReceiptInputs {
        etfe: Some(view),
        cross_validation: inp.cross_validation.clone(),
        ..receipt_inputs(c, inp.model, &t.pid, fc, inp.weight, inp.limits)
    })?;
    for rc in &rep.receipts.receipts {
        receipts.push(rc.clone());
    }
    let (lp, _) = implemented_loop(inp.model, &t.pid, None, Some(fc))?;
    let grid = curves_grid(fc, inp.fs, nom.freq_hz.get(1).copied());
    let curves = loop_curves(&lp, inp.weight, &grid)?;
    Ok((Some(rep), Some(curves)))
}

/// The audit's receipts (gain shift, phase shift, coherence near crossover), or one failing
/// receipt saying the audit did not run (fewer than two runs).
pub(super) fn push_audit_receipts(
    rs: &mut Receipts,
    audit: Option<&NonlinearityAudit>,
    a: &config::AuditSettings,
    fc: f64,
) {
    let Some(au) = audit else {
        rs.push(Receipt::new(
            ReceiptKind::NonlinearityAudit,
            "dual-amplitude nonlinearity audit near crossover",
            f64::NAN,
            Comparison::AtLeast,
            2.0,
            "runs",
            "fewer than two `[[runs]]` at different amplitudes: linearity near crossover was \
             not checked"
                .into(),
        ));
        return;
    };
    let g = &au.worst_gain_shift_db;
    rs.push(Receipt::new(
        ReceiptKind::AuditGainShift,
        "largest gain shift between excitation amplitudes within the audit band",
        g.value.abs(),
        Comparison::AtMost,
        a.max_gain_shift_db,
        "dB",
        format!(
            "{} between `{}` and `{}` at {} Hz; band {}–{} Hz ({} bins); {} flagged band(s)",
            fmt_num(g.value),
            g.run_a,
            g.run_b,
            fmt_num(g.f_hz),
            fmt_num(au.band_hz.0),
            fmt_num(au.band_hz.1),
            au.bins_examined,
            au.shift_bands.len()
        ),
    ));
    let p = &au.worst_phase_shift_deg;
    rs.push(Receipt::new(
        ReceiptKind::AuditPhaseShift,
        "largest phase shift between excitation amplitudes within the audit band",
        p.value.abs(),
        Comparison::AtMost,
        a.max_phase_shift_deg,
        "deg",
        format!(
            "{} deg between `{}` and `{}` at {} Hz",
            fmt_num(p.value),
            p.run_a,
            p.run_b,
            fmt_num(p.f_hz)
        ),
    ));
    let (lo, hi) = (fc / a.coherence_band_factor, fc * a.coherence_band_factor);
    let mut worst = (f64::INFINITY, f64::NAN);
    for b in au.bins.iter().filter(|b| b.f_hz >= lo && b.f_hz <= hi) {
        if b.min_coherence < worst.0 {
            worst = (b.min_coherence, b.f_hz);
        }
    }
    rs.push(Receipt::new(
        ReceiptKind::AuditCoherence,
        "lowest coherence of any run near crossover",
        if worst.0.is_finite() {
            worst.0
        } else {
            f64::NAN
        },
        Comparison::AtLeast,
        a.min_coherence,
        "1",
        if worst.0.is_finite() {
            format!(
                "at {} Hz, window {}–{} Hz; {} coherence drop(s)",
                fmt_num(worst.1),
                fmt_num(lo),
                fmt_num(hi),
                au.coherence_drops.len()
            )
        } else {
            format!(
                "no bin in the coherence window {}–{} Hz",
                fmt_num(lo),
                fmt_num(hi)
            )
        },
    ));
}

/// The multiplicative envelope of the `[uncertainty].family` around G0 and the weight fitted
/// to it (see the module docs of [`super`]); `Ok(Err(NoWeight::TooFewBins))` when fewer than
/// three bins pass the gate for every family member.
pub(super) fn uncertainty(
    cfg: &LoadedConfig,
    model: &StateSpace,
    runs: &[LogData],
    validation: Option<&LogData>,
) -> Result<std::result::Result<WeightFit, NoWeight>> {
    let u = &cfg.config.uncertainty;
    let gate = cfg.config.etfe.coherence_gate;
    let family: Vec<&LogData> = match &u.family {
        Some(names) => names
            .iter()
            .filter_map(|n| {
                if n == "validation" {
                    validation
                } else {
                    runs.iter().find(|l| &l.name == n)
                }
            })
            .collect(),
        None => runs.iter().chain(validation).collect(),
    };
    let grid = &runs[0].etfe.freq_hz;
    let nyq = 0.5 * runs[0].log.fs();
    let ok: Vec<bool> = (0..grid.len())
        .map(|i| {
            grid[i] > 0.0 && grid[i] < nyq && family.iter().all(|m| m.etfe.coherence[i] >= gate)
        })
        .collect();
    let idx: Vec<usize> = (0..grid.len()).filter(|&i| ok[i]).collect();
    if idx.len() < 3 {
        return Ok(Err(NoWeight::TooFewBins {
            bins: idx.len(),
            family: family.iter().map(|m| m.name.clone()).collect(),
            gate,
        }));
    }
    let f: Vec<f64> = idx.iter().map(|&i| grid[i]).collect();
    let ev = model.freq_evaluator();
    let mut g0 = Vec::with_capacity(f.len());
    for &fi in &f {
        g0.push(ev.at_rad_s(2.0 * PI * fi)?[(0, 0)]);
    }
    let fam: Vec<Vec<Complex64>> = family
        .iter()
        .map(|m| idx.iter().map(|&i| m.etfe.h[i]).collect())
        .collect();
    let measured_level = multiplicative_envelope(&g0, &fam)?;
    let measured = f.len();
    let f_first = f[0];
    let f_top = f[measured - 1];
    // Below the measured band: one decade at a stated level (default: hold the largest l_m of
    // the lowest measured octave), so the weight is not an unconstrained extrapolation there.
    let below = u.below_band_level.unwrap_or_else(|| {
        f.iter()
            .zip(&measured_level)
            .filter(|(fi, _)| **fi <= 2.0 * f_first)
            .map(|(_, l)| *l)
            .fold(0.0, f64::max)
    });
    let mut freq = Vec::new();
    let mut level = Vec::new();
    for fi in log_grid(f_first / 10.0, f_first, 9).into_iter().take(8) {
        freq.push(fi);
        level.push(below);
    }
    let below_bins = freq.len();
    freq.extend_from_slice(&f);
    level.extend_from_slice(&measured_level);
    // Above the measured band: the unmeasured bins up to Nyquist and two decades beyond (a
    // sampled loop sees the continuous weight up to s = ∞ through the Tustin map).
    if u.beyond_band_level > 0.0 {
        for &fi in grid.iter().filter(|&&fi| fi > f_top && fi < nyq) {
            freq.push(fi);
            level.push(u.beyond_band_level);
        }
        for fi in log_grid(nyq, 100.0 * nyq, 13) {
            freq.push(fi);
            level.push(u.beyond_band_level);
        }
    }
    let env = EnvelopeData {
        freq_hz: freq,
        level,
        below: below_bins,
        measured,
        family: family.iter().map(|m| m.name.clone()).collect(),
        f_top_hz: f_top,
    };
    let weight = fit_weight(cfg, &env)?;
    Ok(Ok(WeightFit {
        envelope: env,
        weight,
    }))
}

/// W_m fitted to an envelope with the `[uncertainty]` order and floor.
pub(super) fn fit_weight(cfg: &LoadedConfig, env: &EnvelopeData) -> Result<UncertaintyWeight> {
    let u = &cfg.config.uncertainty;
    fit_uncertainty_weight(
        &env.freq_hz,
        &env.level,
        &WeightFitOptions {
            order: u.order,
            min_level: u.min_level,
            ..WeightFitOptions::default()
        },
    )
}
