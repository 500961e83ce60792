//! Closed-loop step response with a hard actuator saturation: the discrete plant (ZOH) driven
//! by the firmware controller ([`DiscretePid::update_detailed`]) through a clamp at
//! ±`actuator_limit`.
//!
//! Per sample k: `y[k] = C x[k] + D u[k]; e[k] = r − y[k]; u[k] = clamp(PID(e[k]));
//! x[k+1] = A x[k] + B u[k]`. With a plant feedthrough D ≠ 0 the loop is algebraic; `e[k]` is then solved
//! from e = r − C x − D·u(e) by bisection (the map is monotone when the loop is well posed,
//! 1 + D·g > 0 with g the controller's instantaneous gain).
//!
//! Units: time in seconds, `amplitude` in plant output units, `actuator_limit` in plant input
//! units (e.g. A of motor current).
use super::pid::{DiscretePid, DiscretePidState};
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use serde::{Deserialize, Serialize};

/// What to simulate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepSpec {
    /// Reference step height, plant output units (non-zero).
    pub amplitude: f64,
    /// Symmetric actuator limit (> 0), plant input units: u ∈ [−limit, limit].
    pub actuator_limit: f64,
    /// Simulated duration, s (at least 2 samples).
    pub duration_s: f64,
    /// Conditional-integration anti-windup in the controller (false: plain hard saturation
    /// with the integrator winding up).
    pub anti_windup: bool,
    /// Settling band as a fraction of |amplitude| (e.g. 0.02).
    pub settle_band: f64,
}

impl StepSpec {
    /// A step of `amplitude` against `actuator_limit`, lasting 50 periods of the crossover
    /// frequency `crossover_hz`, 2 % settling band, anti-windup on.
    pub fn for_crossover(amplitude: f64, actuator_limit: f64, crossover_hz: f64) -> Self {
        Self {
            amplitude,
            actuator_limit,
            duration_s: 50.0 / crossover_hz,
            anti_windup: true,
            settle_band: 0.02,
        }
    }
}

/// The simulated response and its summary numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepResponse {
    /// Sample time, s.
    pub ts: f64,
    /// Reference step height.
    pub amplitude: f64,
    /// Actuator limit used.
    pub actuator_limit: f64,
    /// Sample times `t[k] = k·ts`, s.
    pub t: Vec<f64>,
    /// Plant output `y[k]`.
    pub y: Vec<f64>,
    /// Applied (clamped) actuator command `u[k]`.
    pub u: Vec<f64>,
    /// Controller demand before the clamp.
    pub u_demand: Vec<f64>,
    /// True when the demand reached or exceeded the rail at any sample.
    pub hits_rail: bool,
    /// Number of samples at the rail.
    pub samples_at_rail: usize,
    /// `max_k |u_demand[k]| / actuator_limit` (> 1 means the rail clipped the command).
    pub peak_demand_ratio: f64,
    /// Overshoot beyond the reference in percent of |amplitude| (>= 0).
    pub overshoot_pct: f64,
    /// Time after which y stays within the settling band, s (None: not settled by the end).
    pub settling_time_s: Option<f64>,
    /// 10 %–90 % rise time, s (None: 90 % never reached).
    pub rise_time_s: Option<f64>,
    /// Final tracking error r − y at the last sample.
    pub final_error: f64,
}

/// Simulates the saturated closed-loop step of the discrete SISO `plant` with controller
/// `ctrl` (same sample time). Errors: continuous or MIMO plant, mismatched sample times,
/// invalid spec, an ill-posed algebraic loop, or a response that leaves the finite range
/// (an unstable loop).
pub fn saturated_step(
    plant: &StateSpace,
    ctrl: &DiscretePid,
    spec: &StepSpec,
) -> Result<StepResponse> {
    let n_samples = check_step(plant, ctrl, spec)?;
    let n = plant.n_states();
    let a: Vec<f64> = (0..n * n).map(|k| plant.a[(k / n, k % n)]).collect();
    let b: Vec<f64> = (0..n).map(|i| plant.b[(i, 0)]).collect();
    let c: Vec<f64> = (0..n).map(|j| plant.c[(0, j)]).collect();
    let d = plant.d[(0, 0)];
    let (r, lim) = (spec.amplitude, spec.actuator_limit);
    let mut x = vec![0.0; n];
    let mut xn = vec![0.0; n];
    let mut st = DiscretePidState::default();
    let mut out = StepResponse {
        ts: plant.ts,
        amplitude: r,
        actuator_limit: lim,
        t: Vec::with_capacity(n_samples),
        y: Vec::with_capacity(n_samples),
        u: Vec::with_capacity(n_samples),
        u_demand: Vec::with_capacity(n_samples),
        hits_rail: false,
        samples_at_rail: 0,
        peak_demand_ratio: 0.0,
        overshoot_pct: 0.0,
        settling_time_s: None,
        rise_time_s: None,
        final_error: 0.0,
    };
    for k in 0..n_samples {
        let cx: f64 = c.iter().zip(&x).map(|(ci, xi)| ci * xi).sum();
        let (y, u, v) = if d == 0.0 {
            let e = r - cx;
            let mut s2 = st;
            let (u, v) = ctrl.update_detailed(&mut s2, e, Some(lim), spec.anti_windup);
            st = s2;
            (cx, u, v)
        } else {
            let e = algebraic_loop_error(ctrl, &st, spec, cx, d, k)?;
            let (u, v) = ctrl.update_detailed(&mut st, e, Some(lim), spec.anti_windup);
            (cx + d * u, u, v)
        };
        if !(y.is_finite() && v.is_finite()) {
            return Err(Error::Numerical(format!(
                "saturated step: the response diverged at t = {} s (unstable loop)",
                k as f64 * plant.ts
            )));
        }
        for i in 0..n {
            let mut acc = b[i] * u;
            for j in 0..n {
                acc += a[i * n + j] * x[j];
            }
            xn[i] = acc;
        }
        std::mem::swap(&mut x, &mut xn);
        if v.abs() >= lim {
            out.samples_at_rail += 1;
        }
        out.peak_demand_ratio = out.peak_demand_ratio.max(v.abs() / lim);
        out.t.push(k as f64 * plant.ts);
        out.y.push(y);
        out.u.push(u);
        out.u_demand.push(v);
    }
    summarise(&mut out, spec.settle_band);
    Ok(out)
}

/// The number of samples to simulate, after checking the plant, the controller's sample time
/// and the spec.
fn check_step(plant: &StateSpace, ctrl: &DiscretePid, spec: &StepSpec) -> Result<usize> {
    plant.validate()?;
    if !plant.is_discrete() || !plant.is_siso() {
        return Err(Error::InvalidArgument(
            "saturated step: the plant must be a discrete SISO model (discretise with c2d_zoh)"
                .into(),
        ));
    }
    if (plant.ts - ctrl.ts).abs() > 1e-12 * plant.ts {
        return Err(Error::InvalidArgument(format!(
            "saturated step: plant ts = {} s but controller ts = {} s",
            plant.ts, ctrl.ts
        )));
    }
    if !(spec.amplitude.is_finite() && spec.amplitude != 0.0) {
        return Err(Error::InvalidArgument(format!(
            "saturated step: amplitude {} must be finite and non-zero",
            spec.amplitude
        )));
    }
    if !(spec.actuator_limit.is_finite() && spec.actuator_limit > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "saturated step: actuator limit {} must be finite and > 0",
            spec.actuator_limit
        )));
    }
    step_samples(spec, plant.ts)
}

/// The number of samples of a step of `spec` at sample time `ts`, after checking the settling
/// band and the duration (the last checks of [`saturated_step`] and of the general
/// controller's step, `synth::sim::saturated_step_general`).
pub(crate) fn step_samples(spec: &StepSpec, ts: f64) -> Result<usize> {
    if !(spec.settle_band.is_finite() && spec.settle_band > 0.0 && spec.settle_band < 1.0) {
        return Err(Error::InvalidArgument(format!(
            "saturated step: settling band {} must lie in (0, 1)",
            spec.settle_band
        )));
    }
    let n_samples = (spec.duration_s / ts).floor();
    if !(n_samples.is_finite() && (2.0..=5e7).contains(&n_samples)) {
        return Err(Error::InvalidArgument(format!(
            "saturated step: duration {} s at ts = {ts} s gives {n_samples} samples (need 2..5e7)",
            spec.duration_s
        )));
    }
    Ok(n_samples as usize)
}

/// The tracking error e of sample `k` when the plant feedthrough `d` ≠ 0 closes an algebraic
/// loop: the root of φ(e) = e − (r − cx − d·u(e)) by bisection (`cx` = C·x, `st` the
/// controller state before the sample, left unchanged).
fn algebraic_loop_error(
    ctrl: &DiscretePid,
    st: &DiscretePidState,
    spec: &StepSpec,
    cx: f64,
    d: f64,
    k: usize,
) -> Result<f64> {
    let (r, lim) = (spec.amplitude, spec.actuator_limit);
    let st = *st;
    let phi = |e: f64| -> f64 {
        let mut s2 = st;
        let (u, _) = ctrl.update_detailed(&mut s2, e, Some(lim), spec.anti_windup);
        e - (r - cx - d * u)
    };
    loop_error_by_bisection(phi, r - cx, d, lim, k)
}

/// The root of `phi` (φ(e) = e − (r − cx − d·u(e)), increasing when the loop is well posed)
/// by 200 bisection steps on r − cx ± (|r − cx| + |d|·lim + 1), `r_cx` = r − cx; an error
/// when φ does not change sign there (sample `k`). Shared with the general controller's step.
pub(crate) fn loop_error_by_bisection(
    phi: impl Fn(f64) -> f64,
    r_cx: f64,
    d: f64,
    lim: f64,
    k: usize,
) -> Result<f64> {
    let span = r_cx.abs() + d.abs() * lim + 1.0;
    let (mut lo, mut hi) = (r_cx - span, r_cx + span);
    if phi(lo) > 0.0 || phi(hi) < 0.0 {
        return Err(Error::Numerical(format!(
            "saturated step: algebraic loop through plant feedthrough D = {d} is ill \
             posed at sample {k}"
        )));
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if phi(mid) > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Ok(0.5 * (lo + hi))
}

/// The summary numbers of a simulated response (`out.t`, `y`, `samples_at_rail` filled in):
/// rail hits, overshoot, settling time within `settle_band`·|r|, rise time, final error.
pub(crate) fn summarise(out: &mut StepResponse, settle_band: f64) {
    let r = out.amplitude;
    out.hits_rail = out.samples_at_rail > 0;
    let sgn = r.signum();
    let ar = r.abs();
    let peak = out
        .y
        .iter()
        .map(|y| y * sgn)
        .fold(f64::NEG_INFINITY, f64::max);
    out.overshoot_pct = ((peak - ar) / ar * 100.0).max(0.0);
    let band = settle_band * ar;
    let last_out = out.y.iter().rposition(|y| (y - r).abs() > band);
    out.settling_time_s = match last_out {
        None => Some(0.0),
        Some(k) if k + 1 < out.y.len() => Some(out.t[k + 1]),
        Some(_) => None,
    };
    let t10 = out.y.iter().position(|y| y * sgn >= 0.1 * ar);
    let t90 = out.y.iter().position(|y| y * sgn >= 0.9 * ar);
    out.rise_time_s = match (t10, t90) {
        (Some(a), Some(b)) => Some(out.t[b] - out.t[a]),
        _ => None,
    };
    out.final_error = r - out.y.last().copied().unwrap_or(0.0);
}
