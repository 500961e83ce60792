//! Several `[control]` methods in one run (issue 14): `methods = ["pid", "pid-notch", "hinf",
//! "mpc"]`, each designed on the same G0 and W_m, and the comparison the report shows.
//!
//! How `method` and `methods` combine ([`resolve_methods`]):
//! * `method = "x"` alone: one method, as before (`methods` is absent from the settings echo).
//! * `methods = [a, b, ...]` alone: `a` is the *primary* method; `method` is set to it, so the
//!   run's `receipts.json`, report sections and codegen are exactly those of a run with
//!   `method = "a"`.
//! * both: `method` must equal the first entry of `methods` (else an error naming its line).
//! * an empty list, a repeated method (`loopshape` and `pid-notch` are the same) or an unknown
//!   name is an error naming the line.
//!
//! [`run_methods`] runs the control stage for the primary method into the run's receipts
//! (unchanged), then for every other method on a copy of the receipts as they were before the
//! stage (the PID's), with the configuration's `method` set to that method. Each method's
//! result is a [`MethodRun`]: the top-level receipts a single-method run of it would have, its
//! `control` block and crossover. `ferrosid run` writes each non-primary one as
//! `receipts.<method>.json` ([`method_view`], [`method_receipts_file`]); the report's
//! comparison table and `receipts.json`'s `comparison` array are its [`ComparisonRow`]s.
use super::config::{LoadedConfig, PipelineConfig};
use super::control_stage::{run_control_stage, ControlMethod, ControlOutcome, ControlStageInputs};
use super::PipelineRun;
use crate::error::Result;
use crate::robust::receipts::{ReceiptKind, Receipts};
use serde::Serialize;

/// The methods of a configuration, primary first: `methods` when written, else `[method]`.
pub fn methods_of(c: &PipelineConfig) -> Vec<ControlMethod> {
    c.control
        .methods
        .clone()
        .unwrap_or_else(|| vec![c.control.method])
}

/// Sets `control.method` to the first entry of `control.methods` (when written): the primary
/// method every single-method code path reads.
pub fn apply_primary(c: &mut PipelineConfig) {
    if let Some(first) = c.control.methods.as_ref().and_then(|m| m.first()) {
        c.control.method = *first;
    }
}

/// Checks `control.methods` against `control.method` (module docs) and applies the primary.
pub(super) fn resolve_methods(cfg: &mut LoadedConfig) -> Result<()> {
    let Some(list) = cfg.config.control.methods.clone() else {
        return Ok(());
    };
    if list.is_empty() {
        return Err(cfg.key_error(
            "control.methods",
            "must name at least one method (\"pid\", \"pid-notch\", \"hinf\", \"mpc\")",
        ));
    }
    for (i, m) in list.iter().enumerate() {
        if list[..i].contains(m) {
            return Err(cfg.key_error(
                "control.methods",
                format!(
                    "\"{}\" is listed twice (\"pid-notch\" is \"loopshape\")",
                    m.name()
                ),
            ));
        }
    }
    let written = cfg.keys_written_in("control").any(|k| k == "method");
    if written && cfg.config.control.method != list[0] {
        return Err(cfg.key_error(
            "control.method",
            format!(
                "\"{}\" differs from the first entry of control.methods (\"{}\"), the primary \
                 method; write one of the two keys, or put the primary method first",
                cfg.config.control.method.name(),
                list[0].name()
            ),
        ));
    }
    apply_primary(&mut cfg.config);
    Ok(())
}

/// One method's result in a run with several methods.
#[derive(Debug, Clone)]
pub struct MethodRun {
    /// The method.
    pub method: ControlMethod,
    /// The top-level receipts a run with `method` alone has.
    pub receipts: Receipts,
    /// The crossover those receipts refer to, Hz.
    pub crossover_hz: f64,
    /// Its control block (None for `pid`).
    pub control: Option<ControlOutcome>,
}

/// Runs the control stage for every method (module docs). `receipts` and `fc` become the
/// primary method's, as with one method. Returns the primary's outcome and, with two or more
/// methods, every method's [`MethodRun`] (primary first; empty with one method).
pub(super) fn run_methods(
    c: &PipelineConfig,
    inp: ControlStageInputs<'_>,
    receipts: &mut Receipts,
    fc: &mut f64,
    progress: &dyn Fn(&str),
) -> Result<(Option<ControlOutcome>, Vec<MethodRun>)> {
    let methods = methods_of(c);
    let before = (receipts.clone(), *fc);
    let primary = run_control_stage(c, inp, receipts)?.map(|(o, f)| {
        *fc = f;
        o
    });
    if methods.len() < 2 {
        return Ok((primary, Vec::new()));
    }
    let mut runs = vec![MethodRun {
        method: methods[0],
        receipts: receipts.clone(),
        crossover_hz: *fc,
        control: primary.clone(),
    }];
    for &m in &methods[1..] {
        progress(&format!("control ({})", m.name()));
        let mut cm = c.clone();
        cm.control.method = m;
        cm.control.methods = None;
        let mut rs = before.0.clone();
        let (control, f) = match run_control_stage(&cm, inp, &mut rs)? {
            Some((o, f)) => (Some(o), f),
            None => (None, before.1),
        };
        runs.push(MethodRun {
            method: m,
            receipts: rs,
            crossover_hz: f,
            control,
        });
    }
    Ok((primary, runs))
}

/// The file a method's receipts go to: `receipts.json` for the primary, else
/// `receipts.<method>.json` (`<method>` as [`ControlMethod::name`]: `pid`, `loopshape`, `hinf`,
/// `mpc`).
pub fn method_receipts_file(method: ControlMethod, primary: bool) -> String {
    if primary {
        "receipts.json".into()
    } else {
        format!("receipts.{}.json", method.name())
    }
}

/// Every `receipts.<method>.json` a run may write (for the output directory's ownership check).
pub const METHOD_RECEIPT_FILES: [&str; 4] = [
    "receipts.pid.json",
    "receipts.loopshape.json",
    "receipts.hinf.json",
    "receipts.mpc.json",
];

/// The run as a single-method run of `m` would record it: its receipts, crossover and control
/// block, and the settings with `method = m` and no `methods` (so `receipts.<method>.json` reads
/// like that run's `receipts.json`, and `ferrosid codegen --control` takes it).
pub fn method_view(run: &PipelineRun, m: &MethodRun) -> PipelineRun {
    let mut v = run.clone();
    v.config.control.method = m.method;
    v.config.control.methods = None;
    v.receipts = m.receipts.clone();
    v.receipts_crossover_hz = m.crossover_hz;
    v.control = m.control.clone();
    v.comparison = Vec::new();
    v
}

/// Instructions per control step measured on the target (Cortex-M4F under
/// `qemu-system-arm -icount shift=0`) for a controller structure.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TargetCost {
    /// Mean instructions per step.
    pub mean: f64,
    /// Largest (None when only the mean was measured).
    pub max: Option<f64>,
    /// Which test measured it (docs/controllers.md).
    pub source: &'static str,
}

/// The structures whose step was measured on the target, and the figures (docs/controllers.md; the cost
/// depends on the structure — sections, order, horizon, iterations — not on the coefficients).
fn measured_cost(structure: &Structure) -> Option<TargetCost> {
    let t = |mean, max, source| Some(TargetCost { mean, max, source });
    match *structure {
        Structure::Pid { rolloff: true } => t(
            50.0,
            None,
            "e2e_closedloop, PID with roll-off, mean of 65,536 steps",
        ),
        Structure::PidNotch { notches: 1 } => t(
            71.0,
            Some(80.0),
            "e2e_controllers, PID + roll-off + 1 notch",
        ),
        Structure::StateSpace { order: 4 } => {
            t(92.0, Some(120.0), "e2e_controllers, state space of order 4")
        }
        Structure::Mpc {
            horizon: 10,
            iterations: 60,
        } => t(
            34_660.0,
            Some(34_680.0),
            "e2e_mpc, N = 10, 60 ADMM iterations",
        ),
        Structure::Mpc {
            horizon: 20,
            iterations: 60,
        } => t(
            108_197.0,
            Some(108_199.0),
            "e2e_mpc, N = 20, 60 ADMM iterations",
        ),
        _ => None,
    }
}

/// The controller's structure (what sets its cost on the target).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Structure {
    /// PID (with or without the second-order roll-off).
    Pid {
        /// Roll-off present.
        rolloff: bool,
    },
    /// PID + roll-off + notch biquads.
    PidNotch {
        /// Number of notches.
        notches: usize,
    },
    /// A state-space controller (H∞).
    StateSpace {
        /// States.
        order: usize,
    },
    /// The condensed MPC.
    Mpc {
        /// Horizon N.
        horizon: usize,
        /// ADMM iterations per step.
        iterations: usize,
    },
}

/// One row of the comparison table (report, `receipts.json` `comparison`). Every number is the
/// value of that method's receipt of the same name (null when it has none: a failed design,
/// or a receipt that does not apply to the method).
#[derive(Debug, Clone, Serialize)]
pub struct ComparisonRow {
    /// The method ([`ControlMethod::name`]).
    pub method: ControlMethod,
    /// The file its receipts are in.
    pub receipts_file: String,
    /// `designed` or `failed` (for `pid`: whether the PID was tuned).
    pub status: &'static str,
    /// `controller_design`: the PID's design crossover, the lowest gain crossover of the
    /// loop-shaped and H∞ loops, the −3 dB bandwidth of the MPC's unconstrained closed loop, Hz.
    pub crossover_hz: Option<f64>,
    /// What `crossover_hz` is.
    pub crossover_kind: &'static str,
    /// `sensitivity_peak` M_s.
    pub sensitivity_peak: Option<f64>,
    /// `robust_stability` ‖W_m T‖∞.
    pub wm_t_peak: Option<f64>,
    /// `peak_control_effort` ‖KS‖∞·reference amplitude, input units.
    pub peak_control_effort: Option<f64>,
    /// The actuator limit it is held to, input units.
    pub actuator_limit: f64,
    /// `step_overshoot`, %.
    pub step_overshoot_pct: Option<f64>,
    /// `step_settling_time`, s.
    pub step_settling_s: Option<f64>,
    /// The diagnosed effect the step receipts simulate in the loop (`mpc` with
    /// `control.step_effect.simulated`: `effect at place`); None: the step is on G0 alone, as
    /// the other methods' (`control.linear_step_receipts` then has the MPC's G0 step).
    pub step_effect: Option<String>,
    /// The controller's structure (None without a controller).
    pub structure: Option<Structure>,
    /// States of the controller that runs (None: no controller, or not an LTI controller).
    pub controller_order: Option<usize>,
    /// Instructions per step measured on the target for this structure (None: not measured).
    pub target_cost: Option<TargetCost>,
    /// Receipts in that method's list.
    pub receipts: usize,
    /// The failing ones, by name.
    pub failed: Vec<String>,
    /// Every receipt holds.
    pub all_pass: bool,
}

/// The comparison rows of a run with several methods (empty with one).
pub fn comparison_rows(run: &PipelineRun) -> Vec<ComparisonRow> {
    run.comparison
        .iter()
        .enumerate()
        .map(|(i, m)| row(run, m, i == 0))
        .collect()
}

fn row(run: &PipelineRun, m: &MethodRun, primary: bool) -> ComparisonRow {
    let value = |k: ReceiptKind| m.receipts.of_kind(k).map(|r| r.value);
    let k = &run.config.control;
    let (status, structure, order) = match &m.control {
        None => {
            let pid = run.tuned();
            (
                if pid.is_some() { "designed" } else { "failed" },
                pid.map(|t| Structure::Pid {
                    rolloff: t.pid.rolloff.is_some(),
                }),
                pid.and_then(|t| t.discrete.as_ref())
                    .map(|d| d.den.len().saturating_sub(1)),
            )
        }
        Some(c) => {
            let structure = match (&c.design, &c.controller_ss) {
                (Some(super::control_stage::DesignSummary::Loopshape { notches, .. }), Some(_)) => {
                    Some(Structure::PidNotch {
                        notches: notches.len(),
                    })
                }
                (Some(super::control_stage::DesignSummary::Hinf { .. }), Some(ss)) => {
                    Some(Structure::StateSpace {
                        order: ss.n_states(),
                    })
                }
                (Some(super::control_stage::DesignSummary::Mpc { spec, .. }), _) => {
                    Some(Structure::Mpc {
                        horizon: spec.horizon,
                        iterations: spec.iterations,
                    })
                }
                _ => None,
            };
            (
                c.status,
                structure,
                c.controller_ss.as_ref().map(|s| s.n_states()),
            )
        }
    };
    let failed: Vec<String> = m.receipts.failed().map(|r| r.name.clone()).collect();
    ComparisonRow {
        method: m.method,
        receipts_file: method_receipts_file(m.method, primary),
        status,
        crossover_hz: value(ReceiptKind::ControllerDesign).filter(|v| v.is_finite()),
        crossover_kind: match m.method {
            ControlMethod::Pid => "design crossover",
            ControlMethod::Mpc => "−3 dB bandwidth of the unconstrained closed loop",
            _ => "lowest gain crossover",
        },
        sensitivity_peak: value(ReceiptKind::SensitivityPeak),
        wm_t_peak: value(ReceiptKind::RobustStability),
        peak_control_effort: value(ReceiptKind::PeakControlEffort),
        actuator_limit: k.actuator_limit,
        step_overshoot_pct: value(ReceiptKind::StepOvershoot),
        step_settling_s: value(ReceiptKind::StepSettlingTime),
        step_effect: m
            .control
            .as_ref()
            .and_then(|c| c.step_effect.as_ref())
            .filter(|e| e.simulated)
            .map(|e| {
                format!(
                    "{} at {}",
                    e.effect.as_deref().unwrap_or("effect"),
                    e.place.as_deref().unwrap_or("?")
                )
            }),
        target_cost: structure.as_ref().and_then(measured_cost),
        structure,
        controller_order: order,
        receipts: m.receipts.receipts.len(),
        all_pass: failed.is_empty(),
        failed,
    }
}

/// `(file name, JSON)` of every non-primary method's `receipts.<method>.json` (empty with one
/// method): the [`method_view`]'s [`super::ReceiptsDocument`].
pub fn method_documents(run: &PipelineRun) -> Result<Vec<(String, String)>> {
    run.comparison
        .iter()
        .skip(1)
        .map(|m| {
            let doc = super::ReceiptsDocument::from_run(&method_view(run, m));
            Ok((method_receipts_file(m.method, false), doc.to_json()?))
        })
        .collect()
}
