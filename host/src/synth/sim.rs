//! Saturated closed-loop step of a discrete SISO plant with a general discrete controller (the
//! counterpart of [`crate::robust::step::saturated_step`], which runs the PID law).
//!
//! Per sample k: `y[k] = C x[k] + D u[k]; e[k] = r − y[k]; v[k] = law(e[k]);
//! u[k] = clamp(v[k], ±limit); x[k+1] = A x[k] + B u[k]`. The laws ([`DiscreteLaw`]):
//! - a state-space controller `v = C_k ξ + D_k e, ξ⁺ = A_k ξ + B_k e`, optionally with the
//!   observer form of back-calculation anti-windup ([`SsFilter::with_anti_windup`]):
//!   `u = clamp(v, ±limit), ξ⁺ = A_k ξ + B_k e + L (u − v)` (the f32 twin is
//!   `ferrosid_firmware::control::StateSpaceLaw`; L from [`anti_windup_gain`]);
//! - a PID (with its conditional-integration anti-windup, [`DiscretePid::update_detailed`])
//!   followed by a state-space filter (the notches): `v = N(PID(e))`, the PID's anti-windup
//!   acting on its own output.
//!
//! With a plant feedthrough D ≠ 0 the loop is algebraic; e[k] is then solved from
//! e = r − C x − D·u(e) by bisection (monotone for a well-posed loop), as in the PID simulation.
//! Units: time in seconds, amplitude in plant output units, limit in plant input units.
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::robust::pid::{DiscretePid, DiscretePidState};
use crate::robust::step::{
    loop_error_by_bisection, step_samples, summarise, StepResponse, StepSpec,
};
use faer::Mat;

/// A discrete SISO state-space filter with its state, in flat row-major storage.
#[derive(Debug, Clone)]
pub struct SsFilter {
    n: usize,
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
    d: f64,
    x: Vec<f64>,
    /// Back-calculation gain L (None: no anti-windup).
    aw: Option<Vec<f64>>,
}

impl SsFilter {
    /// The filter of a discrete SISO model, state zero.
    pub fn new(sys: &StateSpace) -> Result<Self> {
        sys.validate()?;
        if !sys.is_siso() || !sys.is_discrete() {
            return Err(Error::InvalidArgument(
                "saturated step: the controller must be a discrete SISO model".into(),
            ));
        }
        let n = sys.n_states();
        Ok(Self {
            n,
            a: (0..n * n).map(|k| sys.a[(k / n, k % n)]).collect(),
            b: (0..n).map(|i| sys.b[(i, 0)]).collect(),
            c: (0..n).map(|j| sys.c[(0, j)]).collect(),
            d: sys.d[(0, 0)],
            x: vec![0.0; n],
            aw: None,
        })
    }

    /// The same filter with the observer-form back-calculation gain `l` (one entry per state,
    /// finite): at a rail the state update gets `+ L (u − v)` (module docs).
    pub fn with_anti_windup(mut self, l: &[f64]) -> Result<Self> {
        if l.len() != self.n || l.iter().any(|v| !v.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "anti-windup gain: need {} finite entries, got {:?}",
                self.n, l
            )));
        }
        self.aw = Some(l.to_vec());
        Ok(self)
    }

    /// The back-calculation gain, if any.
    pub fn anti_windup(&self) -> Option<&[f64]> {
        self.aw.as_deref()
    }

    /// Output v for input `e`, applied input u = clamp(v, ±limit); the state advances with the
    /// back-calculation term L (u − v) when the filter has a gain (else as [`Self::step`]).
    /// Returns v.
    pub fn step_saturated(&mut self, e: f64, limit: f64) -> f64 {
        let Some(l) = self.aw.clone() else {
            return self.step(e);
        };
        let v = self.output(e);
        let corr = v.clamp(-limit, limit) - v;
        let mut next = vec![0.0; self.n];
        for (i, nx) in next.iter_mut().enumerate() {
            *nx = self.b[i] * e
                + l[i] * corr
                + (0..self.n)
                    .map(|j| self.a[i * self.n + j] * self.x[j])
                    .sum::<f64>();
        }
        self.x = next;
        v
    }

    /// Output for input `e` at the current state (state unchanged).
    pub fn output(&self, e: f64) -> f64 {
        self.c.iter().zip(&self.x).map(|(c, x)| c * x).sum::<f64>() + self.d * e
    }

    /// Output for input `e`, then the state advances.
    pub fn step(&mut self, e: f64) -> f64 {
        let y = self.output(e);
        let mut next = vec![0.0; self.n];
        for (i, v) in next.iter_mut().enumerate() {
            *v = self.b[i] * e
                + (0..self.n)
                    .map(|j| self.a[i * self.n + j] * self.x[j])
                    .sum::<f64>();
        }
        self.x = next;
        y
    }
}

/// A controller law for [`saturated_step_general`].
#[derive(Debug, Clone)]
pub enum DiscreteLaw {
    /// A state-space controller (anti-windup when the filter has a gain).
    StateSpace(SsFilter),
    /// A PID with anti-windup, then a filter (e.g. the notches).
    PidThenFilter {
        /// The PID law.
        pid: DiscretePid,
        /// Its state.
        state: DiscretePidState,
        /// The filter after it.
        filter: SsFilter,
        /// Conditional-integration anti-windup on the PID output.
        anti_windup: bool,
    },
}

impl DiscreteLaw {
    /// Sample time of the law, s (None for the state-space law, which carries none).
    fn pid_ts(&self) -> Option<f64> {
        match self {
            Self::StateSpace(_) => None,
            Self::PidThenFilter { pid, .. } => Some(pid.ts),
        }
    }

    /// Demand v for error `e` against the rails ±`limit` (the caller applies clamp(v)); the
    /// state advances, with the law's anti-windup.
    pub fn step(&mut self, e: f64, limit: f64) -> f64 {
        match self {
            Self::StateSpace(f) => f.step_saturated(e, limit),
            Self::PidThenFilter {
                pid,
                state,
                filter,
                anti_windup,
            } => {
                let (_, v) = pid.update_detailed(state, e, Some(limit), *anti_windup);
                filter.step(v)
            }
        }
    }
}

/// Back-calculation gain of a discrete SISO controller (A, B, C, D) for the observer form
/// `ξ⁺ = A ξ + B e + L (u − v)`: the steady-state Kalman gain of (A, C) with unit state and
/// measurement weights, `L = A X Cᵀ (1 + C X Cᵀ)⁻¹` with X the stabilising solution of the dual
/// DARE (A − L C is then stable, so the state stays bounded while the input sits on a rail;
/// the controller should be balanced so the unit weights are meaningful). Errors: a
/// continuous or MIMO controller, or a DARE that cannot be solved reliably (its own error).
pub fn anti_windup_gain(k: &StateSpace) -> Result<Vec<f64>> {
    k.validate()?;
    if !k.is_discrete() || !k.is_siso() {
        return Err(Error::InvalidArgument(
            "anti-windup gain: the controller must be a discrete SISO model".into(),
        ));
    }
    let n = k.n_states();
    let at = k.a.transpose().to_owned();
    let ct = k.c.transpose().to_owned();
    let q = Mat::<f64>::identity(n, n);
    let r = Mat::<f64>::identity(1, 1);
    let x = super::riccati::dare(at.as_ref(), ct.as_ref(), q.as_ref(), r.as_ref())?.x;
    let xc = &x * &ct;
    let s = 1.0 + (&k.c * &xc)[(0, 0)];
    let l = &k.a * &xc;
    let out: Vec<f64> = (0..n).map(|i| l[(i, 0)] / s).collect();
    if out.iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical(
            "anti-windup gain: not finite (controller too ill-conditioned)".into(),
        ));
    }
    Ok(out)
}

/// Simulates the saturated step of the discrete SISO `plant` under `law` (module docs).
/// Errors: a continuous or MIMO plant, mismatched sample times, an invalid spec, an ill-posed
/// algebraic loop, or a diverging response (unstable loop).
pub fn saturated_step_general(
    plant: &StateSpace,
    mut law: DiscreteLaw,
    spec: &StepSpec,
) -> Result<StepResponse> {
    plant.validate()?;
    if !plant.is_discrete() || !plant.is_siso() {
        return Err(Error::InvalidArgument(
            "saturated step: the plant must be a discrete SISO model".into(),
        ));
    }
    if let Some(t) = law.pid_ts() {
        if (t - plant.ts).abs() > 1e-12 * plant.ts {
            return Err(Error::InvalidArgument(format!(
                "saturated step: plant ts = {} s but controller ts = {t} s",
                plant.ts
            )));
        }
    }
    let (r, lim) = (spec.amplitude, spec.actuator_limit);
    if !(r.is_finite() && r != 0.0 && lim.is_finite() && lim > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "saturated step: amplitude {r} must be finite and non-zero, limit {lim} finite and > 0"
        )));
    }
    let n_samples = step_samples(spec, plant.ts)?;
    let mut g = SsFilter::new(plant)?;
    let mut out = Trace::default();
    for k in 0..n_samples {
        let cx = g.output(0.0);
        let e = if g.d == 0.0 {
            r - cx
        } else {
            solve_algebraic_loop(&law, r, cx, g.d, lim, k)?
        };
        let v = law.step(e, lim);
        let u = v.clamp(-lim, lim);
        let y = cx + g.d * u;
        if !(y.is_finite() && v.is_finite()) {
            return Err(Error::Numerical(format!(
                "saturated step: the response diverged at t = {} s (unstable loop)",
                k as f64 * plant.ts
            )));
        }
        g.step(u);
        out.push(k as f64 * plant.ts, y, u, v, lim);
    }
    Ok(out.summarise(plant.ts, r, lim, spec.settle_band))
}

/// e with e = r − cx − d·clamp(law(e)), by bisection on a copy of the law.
fn solve_algebraic_loop(
    law: &DiscreteLaw,
    r: f64,
    cx: f64,
    d: f64,
    lim: f64,
    k: usize,
) -> Result<f64> {
    let phi = |e: f64| -> f64 {
        let mut l2 = law.clone();
        e - (r - cx - d * l2.step(e, lim).clamp(-lim, lim))
    };
    loop_error_by_bisection(phi, r - cx, d, lim, k)
}

#[derive(Default)]
struct Trace {
    t: Vec<f64>,
    y: Vec<f64>,
    u: Vec<f64>,
    v: Vec<f64>,
    at_rail: usize,
    peak_ratio: f64,
}

impl Trace {
    fn push(&mut self, t: f64, y: f64, u: f64, v: f64, lim: f64) {
        if v.abs() >= lim {
            self.at_rail += 1;
        }
        self.peak_ratio = self.peak_ratio.max(v.abs() / lim);
        self.t.push(t);
        self.y.push(y);
        self.u.push(u);
        self.v.push(v);
    }

    /// The summary numbers, defined and computed as for [`crate::robust::step::StepResponse`].
    fn summarise(self, ts: f64, r: f64, lim: f64, band_rel: f64) -> StepResponse {
        let mut out = StepResponse {
            ts,
            amplitude: r,
            actuator_limit: lim,
            hits_rail: false,
            samples_at_rail: self.at_rail,
            peak_demand_ratio: self.peak_ratio,
            overshoot_pct: 0.0,
            settling_time_s: None,
            rise_time_s: None,
            final_error: 0.0,
            t: self.t,
            y: self.y,
            u: self.u,
            u_demand: self.v,
        };
        summarise(&mut out, band_rel);
        out
    }
}
