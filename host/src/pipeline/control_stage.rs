//! The `[control] method` switch (issue 14): which controller structure the pipeline designs
//! and issues its loop receipts for.
//!
//! - `pid` (default): the robust PID tuner ([`crate::robust::pid::tune_pid`]); this stage does
//!   nothing and every output is what it was before the switch existed.
//! - `loopshape` (alias `pid-notch`): PID + roll-off + notches on the lightly damped modes of
//!   G0 ([`crate::synth::loopshape::tune_pid_notch`]), same constraints as the PID tuner.
//! - `hinf`: H∞ mixed sensitivity ([`crate::synth::hinf`]) on the continuous equivalent of G0
//!   (d2c of the ZOH model) with W_S from the crossover and M_s, W_KS = reference amplitude /
//!   actuator limit and W_T = W_m; the bandwidth of W_S is the target crossover, lowered by
//!   geometric bisection (down to `min_crossover_scale`) until γ ≤ 1. The controller is
//!   discretised by Tustin prewarped at that bandwidth and runs at the model rate.
//! - `mpc`: the condensed MPC of [`crate::synth::mpc`] on G0 (state feedback on the model's
//!   state), box ±actuator_limit, rate limit `mpc_rate_limit` per sample, solved by ADMM with a
//!   fixed budget per sample. Its receipts ([`mpc_receipts`]): `controller_design` (−3 dB
//!   bandwidth of the unconstrained law's closed loop), `closed_loop_stable` (that loop's
//!   poles), and the constrained step from the host simulation of the law as it runs on the
//!   target (`step_actuator_demand`: rails and rate limit respected, `step_overshoot`,
//!   `step_settling_time`). The frequency-domain loop receipts do not apply to a
//!   state-feedback MPC; they are listed with the reason under `control.not_applicable`.
//!
//! For `loopshape` and `hinf` the PID is still tuned (it is the baseline the gained crossover
//! is measured against, and the gap and compensation stages refer to it); then the chosen
//! controller's loop receipts — `controller_design`, `closed_loop_stable`, margins, M_s, M_t,
//! `robust_stability` (‖W_m T‖∞, Hamiltonian and dense grid), disturbance-rejection bandwidth,
//! peak control effort and the saturated step — are computed on the sampled loop of G0 and the
//! chosen controller and replace the PID's in `receipts.json` (the PID's are kept in the
//! `control` block as `replaced_pid_receipts`). The model receipts (ETFE phase,
//! cross-validation, audit) are unchanged. When the compensation stage analysed limit cycles,
//! the `limit_cycle` receipts are the chosen loop's too ([`super::control_cycles`]; for `mpc`
//! not applicable). Several methods in one run: [`super::control_methods`].
use super::config::{LoadedConfig, PipelineConfig};
use super::control_mpc::{mpc_codegen_block, run_mpc, MAX_MPC_HORIZON, MAX_MPC_ITERATIONS};
use super::fmt_num;
use crate::error::{Error, Result};
use crate::lti::{StateSpace, StateSpaceData};
use crate::robust::discretize::tustin_state_space;
use crate::robust::loops::{margins, FeedbackLoop, Margins};
use crate::robust::norms::{balance, hinf_norm};
use crate::robust::pid::{weight_in_domain, Pid, PidDesignPoint, PidTuningSpec, TunedPid};
use crate::robust::receipts::{
    loop_curves, push_margin_receipts, push_norm_receipts, push_step_receipts, Comparison,
    LoopCurves, Receipt, ReceiptInputs, ReceiptKind, ReceiptLimits, Receipts,
};
use crate::robust::step::{StepResponse, StepSpec};
use crate::robust::uncertainty::UncertaintyWeight;
use crate::synth::balred::balanced_truncation;
use crate::synth::hinf::{
    hinf_mixed_sensitivity, performance_weight, HinfDesign, HinfOptions, MixedSensitivityWeights,
};
use crate::synth::loopshape::{tune_pid_notch, Notch};
use crate::synth::mpc::MpcDesign;
use crate::synth::sim::{anti_windup_gain, saturated_step_general, DiscreteLaw, SsFilter};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// `[control] method`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ControlMethod {
    /// Robust PID (default).
    #[default]
    Pid,
    /// PID + roll-off + notches.
    #[serde(alias = "pid-notch")]
    Loopshape,
    /// H∞ mixed sensitivity.
    Hinf,
    /// Condensed MPC (input box and rate limit, ADMM with a fixed budget).
    Mpc,
}

impl ControlMethod {
    /// True for the default `pid` (used to omit the key from the settings echo).
    pub fn is_pid(&self) -> bool {
        *self == Self::Pid
    }
    /// The key's value as written.
    pub fn name(self) -> &'static str {
        match self {
            Self::Pid => "pid",
            Self::Loopshape => "loopshape",
            Self::Hinf => "hinf",
            Self::Mpc => "mpc",
        }
    }
}

/// Default of `control.notch_max_damping`.
pub const DEFAULT_NOTCH_MAX_DAMPING: f64 = 0.3;
/// Default of `control.hinf_ws_floor`.
pub const DEFAULT_HINF_WS_FLOOR: f64 = 1e-3;
/// Default of `control.hinf_backoff`.
pub const DEFAULT_HINF_BACKOFF: f64 = 0.01;
/// Geometric bisection steps of the H∞ bandwidth search.
const HINF_BANDWIDTH_STEPS: usize = 6;
/// The method a `[control]` key belongs to, by its prefix (`notch_`, `hinf_`, `mpc_`); None
/// for a key every method reads.
fn method_of_key(key: &str) -> Option<ControlMethod> {
    [
        ("notch_", ControlMethod::Loopshape),
        ("hinf_", ControlMethod::Hinf),
        ("mpc_", ControlMethod::Mpc),
    ]
    .into_iter()
    .find_map(|(prefix, m)| key.starts_with(prefix).then_some(m))
}

/// Checks the method-specific `[control]` keys: ranges, and no key of another method (it would
/// be silently ignored).
pub(super) fn validate_method_keys(cfg: &LoadedConfig) -> Result<()> {
    let k = &cfg.config.control;
    let methods = super::control_methods::methods_of(&cfg.config);
    for key in cfg.keys_written_in("control") {
        let Some(method) = method_of_key(key) else {
            continue;
        };
        if !methods.contains(&method) {
            let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
            return Err(cfg.key_error(
                &format!("control.{key}"),
                if k.methods.is_some() {
                    format!(
                        "only used with method \"{}\", which control.methods ({}) does not \
                         list",
                        method.name(),
                        names.join(", ")
                    )
                } else {
                    format!(
                        "only used with method = \"{}\" (method is \"{}\")",
                        method.name(),
                        k.method.name()
                    )
                },
            ));
        }
    }
    let range = |key: &str, v: Option<f64>, lo: f64, hi: f64, closed: bool| -> Result<()> {
        match v {
            Some(v) if !(v.is_finite() && v >= lo && v <= hi && (closed || (v > lo && v < hi))) => {
                let (l, r) = if closed { ('[', ']') } else { ('(', ')') };
                Err(cfg.key_error(key, format!("must lie in {l}{lo}, {hi}{r}, got {v}")))
            }
            _ => Ok(()),
        }
    };
    range(
        "control.notch_max_damping",
        k.notch_max_damping,
        0.0,
        1.0,
        false,
    )?;
    range("control.hinf_ws_floor", k.hinf_ws_floor, 0.0, 0.5, false)?;
    range("control.hinf_backoff", k.hinf_backoff, 0.0, 1.0, true)?;
    let positive = |key: &str, v: Option<f64>, zero_ok: bool| -> Result<()> {
        match v {
            Some(v) if !(v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0))) => Err(cfg
                .key_error(
                    key,
                    format!(
                        "must be finite and {}, got {v}",
                        if zero_ok { ">= 0" } else { "> 0" }
                    ),
                )),
            _ => Ok(()),
        }
    };
    positive("control.mpc_output_weight", k.mpc_output_weight, false)?;
    positive("control.mpc_rate_weight", k.mpc_rate_weight, true)?;
    positive("control.mpc_rate_limit", k.mpc_rate_limit, false)?;
    positive("control.mpc_rho", k.mpc_rho, false)?;
    if let Some(n) = k.mpc_horizon {
        if !(1..=MAX_MPC_HORIZON).contains(&n) {
            return Err(cfg.key_error(
                "control.mpc_horizon",
                format!(
                    "must lie in [1, {MAX_MPC_HORIZON}] samples (the firmware stores an N×N \
                     f32 matrix), got {n}"
                ),
            ));
        }
    }
    if let Some(n) = k.mpc_iterations {
        if !(1..=MAX_MPC_ITERATIONS).contains(&n) {
            return Err(cfg.key_error(
                "control.mpc_iterations",
                format!("must lie in [1, {MAX_MPC_ITERATIONS}] per control step, got {n}"),
            ));
        }
    }
    if let (Some(d), true) = (k.mpc_rate_limit, methods.contains(&ControlMethod::Mpc)) {
        if d.is_finite() && d > 2.0 * k.actuator_limit {
            return Err(cfg.key_error(
                "control.mpc_rate_limit",
                format!(
                    "{d} per sample exceeds the full rail-to-rail swing 2·actuator_limit = {} \
                     (the limit would never act)",
                    2.0 * k.actuator_limit
                ),
            ));
        }
    }
    if k.hinf_order == Some(0) {
        return Err(cfg.key_error(
            "control.hinf_order",
            "must be >= 1 (states of the reduced controller)",
        ));
    }
    Ok(())
}

/// What was designed, per method.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DesignSummary {
    /// PID + notches.
    Loopshape {
        /// The PID part (tuned on the notched plant).
        pid: Pid,
        /// Its design point.
        design: PidDesignPoint,
        /// The notches (centre Hz, ζ_n, ζ_d).
        notches: Vec<Notch>,
        /// Modes with damping below this were notched.
        notch_max_damping: f64,
        /// Conditional integration of the PID at the rails (`control.anti_windup`).
        anti_windup: bool,
    },
    /// H∞ mixed sensitivity.
    Hinf {
        /// Bandwidth of W_S the search settled on, Hz.
        bandwidth_hz: f64,
        /// Bandwidths tried, Hz, with the γ reached (null: synthesis failed).
        bandwidths_tried: Vec<(f64, Option<f64>)>,
        /// Low-frequency floor ε of W_S.
        ws_floor: f64,
        /// W_S roll-off corner, Hz.
        ws_rolloff_hz: f64,
        /// W_KS (output units per input unit).
        wks: f64,
        /// Order of W_T = W_m (null without a weight).
        wt_order: Option<usize>,
        /// Bracket of γ_opt.
        gamma_lower: f64,
        /// Smallest γ found achievable.
        gamma_upper: f64,
        /// Level the controller was built at.
        gamma: f64,
        /// ‖[W_S S; W_KS KS; W_T T]‖∞ of the continuous loop, recomputed from G and K.
        closed_loop_gamma: f64,
        /// Relative residuals of the X and Y Riccati equations.
        riccati_residuals: [f64; 2],
        /// Controller order.
        order: usize,
        /// True when the continuous controller itself is stable.
        controller_stable: bool,
        /// The balanced truncation to `hinf_order` (null without reduction).
        reduction: Option<Reduction>,
        /// Back-calculation gain L of the discrete controller that runs (observer form
        /// ξ⁺ = Aξ + Be + L(u − v), `synth::sim::anti_windup_gain`; null with
        /// `control.anti_windup = false`).
        anti_windup_gain: Option<Vec<f64>>,
    },
    /// Condensed MPC.
    Mpc {
        /// The settings (horizon, weights, box, rate limit, ρ, iterations).
        spec: MpcSpecSummary,
        /// ADMM proximal weight σ.
        sigma: f64,
        /// States of the prediction model (G0).
        model_states: usize,
        /// The unconstrained law u₀ = −k_x·x + k_r·r + k_u·u_prev.
        unconstrained_kx: Vec<f64>,
        /// See `unconstrained_kx`.
        unconstrained_kr: f64,
        /// See `unconstrained_kx`.
        unconstrained_ku: f64,
        /// Largest pole modulus of the unconstrained closed loop.
        unconstrained_pole_modulus: f64,
        /// −3 dB bandwidth of the unconstrained closed loop r → y, Hz (null: above Nyquist).
        unconstrained_bandwidth_hz: Option<f64>,
        /// Largest |Δu| applied in the step, input units.
        step_max_abs_du: f64,
        /// Largest distance of the raw ADMM iterate U₀ outside the box in the step (the
        /// clamp of the applied input removes it).
        step_max_raw_excess: f64,
    },
}

/// The MPC settings as used (defaults filled in).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct MpcSpecSummary {
    /// Horizon N, samples.
    pub horizon: usize,
    /// Output weight q.
    pub output_weight: f64,
    /// Input-rate weight ρ_Δ.
    pub rate_weight: f64,
    /// Input box.
    pub u_min: f64,
    /// Input box.
    pub u_max: f64,
    /// Largest |Δu| per sample.
    pub rate_limit: f64,
    /// ADMM penalty ρ.
    pub rho: f64,
    /// ADMM iterations per step.
    pub iterations: usize,
}

/// A loop receipt that does not apply to the chosen method, and why.
#[derive(Debug, Clone, Serialize)]
pub struct NotApplicable {
    /// Receipt name.
    pub name: String,
    /// Why it does not apply.
    pub reason: String,
}

/// A balanced truncation of the continuous H∞ controller (before Tustin).
#[derive(Debug, Clone, Serialize)]
pub struct Reduction {
    /// Order of the full controller.
    pub full_order: usize,
    /// Order kept.
    pub order: usize,
    /// Hankel singular values of the full controller.
    pub hankel_singular_values: Vec<f64>,
    /// A-priori bound 2·Σ(discarded σ) on ‖K − K_r‖∞.
    pub error_bound: f64,
    /// ‖K − K_r‖∞ measured (Hamiltonian bisection).
    pub measured_error: f64,
    /// The loop receipts with the full-order (discretised) controller, for comparison.
    pub receipts_before: Option<Receipts>,
}

/// The stage's result, as written to `receipts.json` (`control`).
#[derive(Debug, Clone, Serialize)]
pub struct ControlOutcome {
    /// The method.
    pub method: ControlMethod,
    /// `designed` or `failed`.
    pub status: &'static str,
    /// Why the design failed.
    pub error: Option<String>,
    /// The design.
    pub design: Option<DesignSummary>,
    /// The controller that runs (discrete, at the model rate; u = K·e).
    pub controller: Option<StateSpaceData>,
    /// Lowest gain crossover of the chosen loop, Hz.
    pub gain_crossover_hz: Option<f64>,
    /// Design crossover of the PID tuned on the same plant, Hz (the baseline).
    pub baseline_pid_crossover_hz: Option<f64>,
    /// The chosen loop's receipts (also merged into the top-level list).
    pub receipts: Receipts,
    /// The PID receipts the chosen ones replaced in the top-level list.
    pub replaced_pid_receipts: Vec<Receipt>,
    /// Loop receipts that do not apply to the method (with the reason); the PID's of the same
    /// name are in `replaced_pid_receipts`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub not_applicable: Vec<NotApplicable>,
    /// `mpc`: the gap verdict's effect and whether the step receipts simulate it in the loop
    /// (absent when the run diagnosed no effect; [`super::control_mpc::StepEffect`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub step_effect: Option<super::control_mpc::StepEffect>,
    /// `mpc` with the effect in the loop: the step receipts on the linear G0 (the plant the
    /// other methods' step receipts use), for comparison; absent otherwise.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub linear_step_receipts: Vec<Receipt>,
    /// Margins of the chosen loop.
    pub margins: Option<Margins>,
    /// Loop curves for the report (not written to JSON).
    #[serde(skip)]
    pub curves: Option<LoopCurves>,
    /// Saturated step for the report (not written to JSON).
    #[serde(skip)]
    pub step: Option<StepResponse>,
    /// The discrete controller (for codegen; not written twice).
    #[serde(skip)]
    pub controller_ss: Option<StateSpace>,
    /// The MPC design and its prediction model (for codegen).
    #[serde(skip)]
    pub mpc: Option<(MpcDesign, StateSpace)>,
}

/// A designed controller: the discrete law that runs and its summary.
struct Designed {
    controller: StateSpace,
    law: DiscreteLaw,
    /// The full-order controller and its law when `controller` is a reduction of it.
    full: Option<(StateSpace, DiscreteLaw)>,
    /// Crossover the receipt limits and the prewarp refer to, Hz.
    design_hz: f64,
    summary: DesignSummary,
}

/// The PID tuner's spec from `[control]` (shared with the `pid` method).
pub(super) fn pid_spec(c: &PipelineConfig, weight: Option<&UncertaintyWeight>) -> PidTuningSpec {
    let k = &c.control;
    let mut spec = PidTuningSpec::new(k.crossover_hz);
    spec.ms_max = k.ms_max;
    spec.weight = weight.cloned();
    spec.ks_max = k
        .limit_control_effort
        .then(|| k.actuator_limit / k.reference_amplitude);
    spec.rolloff_ratio = k.rolloff_ratio.map(|r| (r, k.rolloff_zeta));
    spec.integral = k.integral;
    spec.derivative = k.derivative;
    spec.min_crossover_scale = k.min_crossover_scale;
    spec
}

/// A design failure that is a finding (reported by `controller_design`), not an error.
pub(super) fn finding<T>(r: Result<T>) -> Result<std::result::Result<T, String>> {
    match r {
        Ok(t) => Ok(Ok(t)),
        Err(Error::InvalidArgument(m)) | Err(Error::Numerical(m)) => Ok(Err(m)),
        Err(e) => Err(e),
    }
}

fn design_loopshape(
    c: &PipelineConfig,
    model: &StateSpace,
    weight: Option<&UncertaintyWeight>,
) -> Result<std::result::Result<Designed, String>> {
    let zmax = c
        .control
        .notch_max_damping
        .unwrap_or(DEFAULT_NOTCH_MAX_DAMPING);
    let d = match finding(tune_pid_notch(model, &pid_spec(c, weight), zmax))? {
        Ok(d) => d,
        Err(e) => return Ok(Err(e)),
    };
    let ts = model.ts;
    let fc = d.pid.design.crossover_hz;
    let mut notch = StateSpace::identity(1, ts)?;
    for n in &d.notches {
        notch = n.in_domain(Some(ts))?.series(&notch)?;
    }
    let law = DiscreteLaw::PidThenFilter {
        pid: d.pid.pid.discretize(ts, Some(fc))?,
        state: Default::default(),
        filter: SsFilter::new(&notch)?,
        anti_windup: c.control.anti_windup,
    };
    Ok(Ok(Designed {
        controller: d.controller,
        law,
        full: None,
        design_hz: fc,
        summary: DesignSummary::Loopshape {
            pid: d.pid.pid,
            design: d.pid.design,
            notches: d.notches,
            notch_max_damping: zmax,
            anti_windup: c.control.anti_windup,
        },
    }))
}

fn design_hinf(
    c: &PipelineConfig,
    model: &StateSpace,
    weight: Option<&UncertaintyWeight>,
) -> Result<std::result::Result<Designed, String>> {
    let k = &c.control;
    let gc = model.d2c_zoh()?;
    let wt = weight
        .map(|w| weight_in_domain(w, None, None))
        .transpose()?;
    let floor = k.hinf_ws_floor.unwrap_or(DEFAULT_HINF_WS_FLOOR);
    let opt = HinfOptions {
        backoff: k.hinf_backoff.unwrap_or(DEFAULT_HINF_BACKOFF),
        ..HinfOptions::default()
    };
    // W_S rolls off at half the Nyquist frequency (strictly proper; no controller dynamics
    // beyond what the sampled loop can carry), at least at twice the bandwidth.
    let nyq = 0.5 / model.ts;
    let wks = k.reference_amplitude / k.actuator_limit;
    let attempt = |bw: f64| -> Result<(HinfDesign, f64)> {
        let rolloff = (0.5 * nyq / bw).max(2.0);
        let w = MixedSensitivityWeights {
            ws: performance_weight(bw, k.ms_max, floor, rolloff)?,
            wks,
            wt: wt.clone(),
        };
        Ok((hinf_mixed_sensitivity(&gc, &w, opt)?, rolloff * bw))
    };
    let mut tried = Vec::new();
    let mut best: Option<(f64, HinfDesign, f64)> = None;
    let mut last_err = String::new();
    // Feasible (γ ≤ 1) at bandwidth `bw`? Records every attempt and the best design.
    let mut feasible = |bw: f64| -> Result<bool> {
        match finding(attempt(bw))? {
            Ok((d, roll)) => {
                tried.push((bw, Some(d.gamma)));
                let ok = d.gamma <= 1.0;
                if ok && best.as_ref().map_or(true, |b| bw > b.0) {
                    best = Some((bw, d, roll));
                }
                Ok(ok)
            }
            Err(e) => {
                tried.push((bw, None));
                last_err = e;
                Ok(false)
            }
        }
    };
    let (mut lo, mut hi) = (k.min_crossover_scale * k.crossover_hz, k.crossover_hz);
    if !feasible(hi)? && feasible(lo)? {
        for _ in 0..HINF_BANDWIDTH_STEPS {
            let mid = (lo * hi).sqrt();
            if feasible(mid)? {
                lo = mid;
            } else {
                hi = mid;
            }
        }
    }
    let Some((bw, d, roll)) = best else {
        return Ok(Err(format!(
            "H∞ mixed sensitivity: no bandwidth between {} and {} Hz reaches γ ≤ 1 (tried {}){}",
            fmt_num(k.min_crossover_scale * k.crossover_hz),
            fmt_num(k.crossover_hz),
            tried
                .iter()
                .map(|(b, g)| format!(
                    "{} Hz: γ {}",
                    fmt_num(*b),
                    g.map_or("failed".into(), fmt_num)
                ))
                .collect::<Vec<_>>()
                .join(", "),
            if last_err.is_empty() {
                String::new()
            } else {
                format!("; last error: {last_err}")
            }
        )));
    };
    let wc = 2.0 * PI * bw;
    let kd = tustin_state_space(&balance(&d.controller)?, model.ts, Some(wc))?;
    let (kd, full, reduction) = match k.hinf_order {
        Some(r) if r < d.controller.n_states() => {
            let red = match finding(balanced_truncation(&balance(&d.controller)?, r))? {
                Ok(red) => red,
                Err(e) => return Ok(Err(format!("H∞ controller reduction: {e}"))),
            };
            let mut neg = red.reduced.clone();
            neg.c = &neg.c * faer::Scale(-1.0);
            neg.d = &neg.d * faer::Scale(-1.0);
            let measured = hinf_norm(&d.controller.parallel(&neg)?)?.gamma;
            let kr = tustin_state_space(&balance(&red.reduced)?, model.ts, Some(wc))?;
            let law = DiscreteLaw::StateSpace(hinf_filter(&kd, k.anti_windup)?);
            let info = Reduction {
                full_order: d.controller.n_states(),
                order: r,
                hankel_singular_values: red.hankel_singular_values.clone(),
                error_bound: red.error_bound,
                measured_error: measured,
                receipts_before: None,
            };
            (kr, Some((kd, law)), Some(info))
        }
        _ => (kd, None, None),
    };
    let law = hinf_filter(&kd, k.anti_windup)?;
    let summary = DesignSummary::Hinf {
        bandwidth_hz: bw,
        bandwidths_tried: tried,
        ws_floor: floor,
        ws_rolloff_hz: roll,
        wks,
        wt_order: weight.map(|w| w.order),
        gamma_lower: d.gamma_lower,
        gamma_upper: d.gamma_upper,
        gamma: d.gamma,
        closed_loop_gamma: d.closed_loop.gamma,
        riccati_residuals: [d.riccati_residuals.0, d.riccati_residuals.1],
        order: d.controller.n_states(),
        controller_stable: d.controller.is_stable(0.0)?,
        reduction,
        anti_windup_gain: law.anti_windup().map(<[f64]>::to_vec),
    };
    Ok(Ok(Designed {
        law: DiscreteLaw::StateSpace(law),
        controller: kd,
        full,
        design_hz: bw,
        summary,
    }))
}

/// The discrete H∞ controller's law: with `anti_windup`, the observer-form back-calculation
/// gain of [`anti_windup_gain`] (the same law the firmware's `StateSpaceLaw` runs).
fn hinf_filter(kd: &StateSpace, anti_windup: bool) -> Result<SsFilter> {
    let f = SsFilter::new(kd)?;
    if anti_windup {
        f.with_anti_windup(&anti_windup_gain(kd)?)
    } else {
        Ok(f)
    }
}

/// What the stage needs from the pipeline.
#[derive(Clone, Copy)]
pub(super) struct ControlStageInputs<'a> {
    /// G0 (discrete).
    pub model: &'a StateSpace,
    /// The final W_m, if any.
    pub weight: Option<&'a UncertaintyWeight>,
    /// The PID (baseline), if tuned.
    pub baseline: Option<&'a TunedPid>,
    /// Sample rate of the logs, Hz.
    pub fs: f64,
    /// Lowest ETFE bin above 0, Hz (bottom of the curves' grid).
    pub f_first_bin: Option<f64>,
    /// The run's gap diagnosis, when it ran (the MPC simulates its verdict's effect).
    pub gap: Option<&'a crate::gap::GapReport>,
    /// The compensation stage's decision, when it ran (the chosen loop's `limit_cycle`
    /// receipts analyse its effects, [`super::control_cycles`]).
    pub remedy: Option<&'a super::remedy::Decision>,
}

impl ControlStageInputs<'_> {
    /// Design crossover of the PID baseline, Hz (None when it could not be tuned).
    pub fn baseline_crossover_hz(&self) -> Option<f64> {
        self.baseline.map(|t| t.design.crossover_hz)
    }
}

/// A loop receipt a chosen controller replaces: `controller_design` and the loop receipts,
/// which [`ReceiptKind::ALL`] lists first (up to `step_settling_time`).
fn is_loop_kind(k: ReceiptKind) -> bool {
    let loop_end = ReceiptKind::ALL
        .iter()
        .position(|x| *x == ReceiptKind::StepSettlingTime)
        .map_or(0, |i| i + 1);
    k == ReceiptKind::ControllerDesign || ReceiptKind::ALL[..loop_end].contains(&k)
}

/// Runs the stage for a non-PID method (None for `pid`) and merges its receipts into
/// `receipts` (module docs). Returns the outcome and the crossover the receipts refer to.
pub(super) fn run_control_stage(
    c: &PipelineConfig,
    inp: ControlStageInputs<'_>,
    receipts: &mut Receipts,
) -> Result<Option<(ControlOutcome, f64)>> {
    let method = c.control.method;
    let mut out = ControlOutcome {
        method,
        status: "failed",
        error: None,
        design: None,
        controller: None,
        gain_crossover_hz: None,
        baseline_pid_crossover_hz: inp.baseline_crossover_hz(),
        receipts: Receipts::default(),
        replaced_pid_receipts: Vec::new(),
        not_applicable: Vec::new(),
        step_effect: None,
        linear_step_receipts: Vec::new(),
        margins: None,
        curves: None,
        step: None,
        controller_ss: None,
        mpc: None,
    };
    let owns_cycles = super::control_cycles::analysed(&inp);
    let designed = match method {
        ControlMethod::Pid => return Ok(None),
        ControlMethod::Loopshape => design_loopshape(c, inp.model, inp.weight)?,
        ControlMethod::Hinf => design_hinf(c, inp.model, inp.weight)?,
        ControlMethod::Mpc => {
            let fc = run_mpc(c, &inp, &mut out)?;
            out.not_applicable
                .extend(super::control_cycles::mpc_not_applicable(&inp));
            out.replaced_pid_receipts = merge(receipts, &out.receipts, owns_cycles);
            return Ok(Some((out, fc)));
        }
    };
    let fc = match designed {
        Err(e) => {
            out.receipts.push(design_receipt(
                c,
                method,
                Err(&e),
                out.baseline_pid_crossover_hz,
            ));
            out.error = Some(e);
            c.control.crossover_hz
        }
        Ok(d) => {
            let fc = d.design_hz;
            let limits = super::stages::receipt_limits(c, fc);
            let lr = chosen_loop_receipts(c, &inp, (&d.controller, &d.law, fc), &limits)?;
            let mut d = d;
            if let (
                Some((kf, lawf)),
                DesignSummary::Hinf {
                    reduction: Some(red),
                    ..
                },
            ) = (&d.full, &mut d.summary)
            {
                let before = chosen_loop_receipts(c, &inp, (kf, lawf, fc), &limits)?;
                red.receipts_before = Some(before.receipts);
            }
            // The bandwidth: the lowest gain crossover (a loop that stays near |L| = 1 around a
            // resonance has more; the margins refer to the worst of them).
            let achieved = lr
                .margins
                .as_ref()
                .and_then(|m| m.gain_crossovers_hz.first().copied());
            out.receipts.push(design_receipt(
                c,
                method,
                Ok(achieved.unwrap_or(fc)),
                out.baseline_pid_crossover_hz,
            ));
            for r in lr.receipts.receipts {
                out.receipts.push(r);
            }
            let cycles =
                super::control_cycles::chosen_limit_cycles(c, &inp, method, &d.controller, &d.law)?;
            for r in cycles {
                out.receipts.push(r);
            }
            out.status = "designed";
            out.design = Some(d.summary);
            out.controller = Some(StateSpaceData::from(&d.controller));
            out.controller_ss = Some(d.controller);
            out.gain_crossover_hz = achieved;
            out.margins = lr.margins;
            out.curves = Some(lr.curves);
            out.step = lr.step;
            fc
        }
    };
    out.replaced_pid_receipts = merge(receipts, &out.receipts, owns_cycles);
    Ok(Some((out, fc)))
}

/// Replaces the loop receipts of `main` by those of `chosen` (in place, by name; a chosen
/// receipt without a counterpart is appended; a PID loop receipt without a chosen counterpart
/// is removed) and returns the replaced ones. With `cycles`, the `limit_cycle` receipts (one
/// per analysed effect, all of that name) are the chosen loop's too: the PID's are replaced
/// by all of the chosen ones at the place of the first.
fn merge(main: &mut Receipts, chosen: &Receipts, cycles: bool) -> Vec<Receipt> {
    let mut replaced = Vec::new();
    let mut list = Vec::with_capacity(main.receipts.len());
    let is_cycle = |r: &Receipt| cycles && r.kind() == Some(ReceiptKind::LimitCycle);
    let chosen_cycles: Vec<&Receipt> = chosen.receipts.iter().filter(|r| is_cycle(*r)).collect();
    let mut cycles_placed = false;
    for r in main.receipts.drain(..) {
        if is_cycle(&r) {
            if !cycles_placed {
                list.extend(chosen_cycles.iter().map(|x| (*x).clone()));
                cycles_placed = true;
            }
            replaced.push(r);
            continue;
        }
        let is_loop = r.kind().is_some_and(is_loop_kind);
        match chosen.get(&r.name) {
            Some(new) if is_loop => {
                replaced.push(r);
                list.push(new.clone());
            }
            _ if is_loop => replaced.push(r),
            _ => list.push(r),
        }
    }
    for r in &chosen.receipts {
        if is_cycle(r) {
            if !cycles_placed {
                list.push(r.clone());
            }
        } else if !list.iter().any(|x| x.name == r.name) {
            list.push(r.clone());
        }
    }
    main.all_pass = list.iter().all(|r| r.pass);
    main.receipts = list;
    replaced
}

/// `controller_design` for the chosen method: the achieved gain crossover against the smallest
/// accepted one, with the PID baseline in the detail.
pub(super) fn design_receipt(
    c: &PipelineConfig,
    method: ControlMethod,
    achieved: std::result::Result<f64, &str>,
    baseline: Option<f64>,
) -> Receipt {
    let k = &c.control;
    let base = baseline.map_or("PID baseline: not tunable".to_string(), |b| {
        format!("PID baseline {} Hz", fmt_num(b))
    });
    Receipt::new(
        ReceiptKind::ControllerDesign,
        match method {
            ControlMethod::Loopshape => {
                "lowest gain crossover of the PID + notch loop (highest PID crossover on the notched \
                 plant meeting M_s, ‖W_m T‖∞ < 1 and the actuator limit)"
            }
            ControlMethod::Mpc => {
                "−3 dB bandwidth of the MPC's unconstrained closed loop r → y (the law the \
                 constrained MPC follows away from the limits)"
            }
            _ => {
                "lowest gain crossover of the H∞ mixed-sensitivity loop (highest W_S bandwidth with \
                 γ ≤ 1 on [W_S S; W_KS KS; W_m T])"
            }
        },
        achieved.unwrap_or(f64::NAN),
        Comparison::AtLeast,
        k.min_crossover_scale * k.crossover_hz,
        "Hz",
        match achieved {
            Ok(f) => format!(
                "method {}; target {} Hz; {base}; gained {} Hz",
                method.name(),
                fmt_num(k.crossover_hz),
                baseline.map_or("n/a".into(), |b| fmt_num(f - b))
            ),
            Err(e) => format!("method {}: {e}; {base}", method.name()),
        },
    )
}

struct LoopReceipts {
    receipts: Receipts,
    margins: Option<Margins>,
    curves: LoopCurves,
    step: Option<StepResponse>,
}

/// The PID receipts' loop-independent pushers need a PID in their inputs; they never read it.
const UNUSED_PID: Pid = Pid {
    kp: 0.0,
    ki: 0.0,
    kd: 0.0,
    tau_f: 0.0,
    rolloff: None,
};

/// The loop receipts of G0 with the chosen discrete controller (same definitions as the
/// PID's: [`crate::robust::receipts::compute_receipts`]).
fn chosen_loop_receipts(
    c: &PipelineConfig,
    inp: &ControlStageInputs<'_>,
    (controller, law, fc): (&StateSpace, &DiscreteLaw, f64),
    limits: &ReceiptLimits,
) -> Result<LoopReceipts> {
    let k = &c.control;
    let lp = FeedbackLoop::new(inp.model, controller)?;
    let mut rs = Receipts::default();
    let poles = lp.closed_loop_poles()?;
    let stable = lp.is_stable()?;
    rs.push(Receipt::new(
        ReceiptKind::ClosedLoopStable,
        "largest closed-loop pole modulus (stable when < 1)",
        lp.stability_abscissa()?,
        Comparison::LessThan,
        1.0,
        "1",
        format!(
            "{} closed-loop poles, sampled loop, ts = {} s ({} controller of order {})",
            poles.len(),
            inp.model.ts,
            c.control.method.name(),
            controller.n_states()
        ),
    ));
    let wc = 2.0 * PI * fc;
    let m = margins(&lp.l, Some((wc / 100.0, wc * 100.0))).ok();
    push_margin_receipts(&mut rs, m.as_ref(), limits);
    let ri = ReceiptInputs {
        // Both laws run with anti-windup when asked (the state-space law by observer-form
        // back-calculation).
        anti_windup: k.anti_windup,
        ..super::stages::receipt_inputs(c, inp.model, &UNUSED_PID, fc, inp.weight, *limits)
    };
    push_norm_receipts(&mut rs, &ri, &lp, stable)?;
    let spec = StepSpec {
        amplitude: k.reference_amplitude,
        actuator_limit: k.actuator_limit,
        duration_s: (limits.settling_time_s_max * 2.0).max(50.0 / fc),
        anti_windup: k.anti_windup,
        settle_band: 0.02,
    };
    let note = match law {
        DiscreteLaw::StateSpace(f) => format!(
            "sampled loop, ts = {} s, state-space controller clamped at the rail ({})",
            inp.model.ts,
            if f.anti_windup().is_some() {
                "observer-form back-calculation anti-windup"
            } else {
                "no anti-windup"
            }
        ),
        DiscreteLaw::PidThenFilter { .. } => format!(
            "sampled loop, ts = {} s, Tustin PID (its anti-windup) then the notches",
            inp.model.ts
        ),
    };
    let step = saturated_step_general(inp.model, law.clone(), &spec);
    let kept = step.as_ref().ok().cloned();
    push_step_receipts(&mut rs, &ri, &(step, note));
    let grid = super::stages::curves_grid(fc, inp.fs, inp.f_first_bin);
    let curves = loop_curves(&lp, inp.weight, &grid)?;
    Ok(LoopReceipts {
        receipts: rs,
        margins: m,
        curves,
        step: kept,
    })
}

/// The chosen controller as a codegen block (None for a failed design).
pub fn codegen_block(c: &ControlOutcome) -> Option<ferrosid_codegen::StateController> {
    if c.mpc.is_some() {
        return mpc_codegen_block(c);
    }
    let k = c.controller_ss.as_ref()?;
    Some(ferrosid_codegen::StateController {
        method: c.method.name().to_string(),
        ts_s: k.ts,
        matrices: crate::ops::codegen::matrices(k),
        note: format!(
            "{} controller of order {}, lowest gain crossover {} Hz (PID baseline {} Hz); \
             receipts as in receipts.json",
            c.method.name(),
            k.n_states(),
            c.gain_crossover_hz.map_or("none".into(), fmt_num),
            c.baseline_pid_crossover_hz.map_or("n/a".into(), fmt_num)
        ),
        mpc: None,
        saturation: codegen_saturation(c),
        pid_notch: codegen_pid_notch(c, k.ts),
    })
}

/// The actuator rails of the chosen loop's step (±`control.actuator_limit`).
fn rails(c: &ControlOutcome) -> Option<f64> {
    c.step.as_ref().map(|s| s.actuator_limit)
}

/// Rails and back-calculation gain of an H∞ controller (None for other methods, or without a
/// step to take the rails from).
fn codegen_saturation(c: &ControlOutcome) -> Option<ferrosid_codegen::StateSaturation> {
    let Some(DesignSummary::Hinf {
        anti_windup_gain, ..
    }) = &c.design
    else {
        return None;
    };
    let n = c.controller_ss.as_ref()?.n_states();
    Some(saturation_block(anti_windup_gain.as_deref(), n, rails(c)?))
}

/// The codegen rails ±`limit` with the back-calculation gain `gain` (None: zero, plain
/// clamping) of an `n`-state controller.
pub fn saturation_block(
    gain: Option<&[f64]>,
    n: usize,
    limit: f64,
) -> ferrosid_codegen::StateSaturation {
    ferrosid_codegen::StateSaturation {
        l: gain.map_or_else(|| vec![0.0; n], <[f64]>::to_vec),
        u_min: -limit,
        u_max: limit,
    }
}

/// The PID + notch form of a `loopshape` design at sample time `ts`.
fn codegen_pid_notch(c: &ControlOutcome, ts: f64) -> Option<ferrosid_codegen::PidNotchController> {
    let Some(DesignSummary::Loopshape {
        pid,
        design,
        notches,
        anti_windup,
        ..
    }) = &c.design
    else {
        return None;
    };
    pid_notch_block(
        pid,
        design.crossover_hz,
        notches,
        ts,
        rails(c)?,
        *anti_windup,
    )
    .ok()?
}

/// The PID + notch codegen block of a `loopshape` design: the PID discretised at `ts` as the
/// design simulation does (Tustin prewarped at its crossover), each notch as its biquad
/// ([`Notch::biquad`]), rails ±`limit`. Ok(None) without a notch (the PID block is then the
/// whole controller; a C array cannot be empty).
pub fn pid_notch_block(
    pid: &Pid,
    crossover_hz: f64,
    notches: &[Notch],
    ts: f64,
    limit: f64,
    anti_windup: bool,
) -> Result<Option<ferrosid_codegen::PidNotchController>> {
    if notches.is_empty() {
        return Ok(None);
    }
    let dp = pid.discretize(ts, Some(crossover_hz))?;
    let sections = notches
        .iter()
        .map(|n| n.biquad(ts).map(|(b, a)| ferrosid_codegen::Biquad { b, a }))
        .collect::<Result<Vec<_>>>()?;
    Ok(Some(ferrosid_codegen::PidNotchController {
        pid: crate::ops::codegen::pid_gains(&dp, Some(pid)),
        sections,
        u_min: -limit,
        u_max: limit,
        anti_windup,
    }))
}

/// The discrete law the control stage simulated for its saturated step (`loopshape`: the
/// PID's conditional integration then the notches; `hinf`: the state-space controller with
/// its back-calculation gain), rebuilt from the outcome at sample time `ts`; None for other
/// methods or a failed design. For checks of the same law elsewhere (the target, other steps).
pub fn chosen_law(c: &ControlOutcome, ts: f64) -> Result<Option<DiscreteLaw>> {
    match &c.design {
        Some(DesignSummary::Loopshape {
            pid,
            design,
            notches,
            anti_windup,
            ..
        }) => {
            let mut notch = StateSpace::identity(1, ts)?;
            for n in notches {
                notch = n.in_domain(Some(ts))?.series(&notch)?;
            }
            Ok(Some(DiscreteLaw::PidThenFilter {
                pid: pid.discretize(ts, Some(design.crossover_hz))?,
                state: Default::default(),
                filter: SsFilter::new(&notch)?,
                anti_windup: *anti_windup,
            }))
        }
        Some(DesignSummary::Hinf {
            anti_windup_gain, ..
        }) => {
            let Some(k) = c.controller_ss.as_ref() else {
                return Ok(None);
            };
            let f = SsFilter::new(k)?;
            Ok(Some(DiscreteLaw::StateSpace(match anti_windup_gain {
                Some(l) => f.with_anti_windup(l)?,
                None => f,
            })))
        }
        _ => Ok(None),
    }
}
