//! PID controllers with a filtered derivative and an optional second-order roll-off, their
//! Tustin discretisation for the firmware, and robust tuning for a target crossover.
//!
//! # Controller
//! K(s) = (Kp + Ki/s + Kd·s/(τ_f·s + 1)) · R(s), with the optional roll-off
//! R(s) = ω_r² / (s² + 2ζ_r·ω_r·s + ω_r²). Units: the gains map the control error (plant
//! output units) to the actuator command (plant input units); Ki in 1/s, Kd in s, τ_f in s,
//! ω_r in rad/s.
//!
//! # Tuning method ([`tune_pid`])
//! Loop shaping at a trial crossover ω (rad/s) with the series form
//! K(s) = k · (s + ω_i)/s · (1 + s/ω_z)/(1 + s/ω_p) · R(s), ω_i = ω/α_i, ω_z = ω/√β,
//! ω_p = ω·√β, whose lead (1 + s/ω_z)/(1 + s/ω_p) gives its maximum phase
//! φ_lead = asin((β − 1)/(β + 1)) exactly at ω. For a phase-margin target φ_m the lead must
//! supply φ_lead = φ_m − 180° − ∠(G·R)(jω) + atan(1/α_i) (wrapped to (−180°, 180°], so no phase
//! unwrapping is needed); β = 1 (a PI) when that is <= 0, infeasible when it exceeds
//! [`PidTuningSpec::max_phase_lead_deg`]. The gain k makes |L(jω)| = 1, so ω is a gain crossover
//! by construction. The series form maps to the parallel gains exactly:
//! Ki = k·ω_i, Kp = k·(1 + ω_i/ω_z − ω_i/ω_p), Kd = k·(1/ω_z − 1/ω_p)·(1 − ω_i/ω_p),
//! τ_f = 1/ω_p.
//!
//! Search: for crossover scales from `max_crossover_scale` down to `min_crossover_scale` of the
//! target (log grid, then bisection between the best feasible and the next infeasible scale),
//! every (φ_m, α_i) on a grid is evaluated on the loop that will actually run (discrete
//! controller on the ZOH plant when a sample time is given). A candidate is feasible when the
//! closed loop is stable, M_s = ‖S‖∞ <= `ms_max`, ‖W_m·T‖∞ < 1 (when a weight is given) and
//! ‖KS‖∞ <= `ks_max` (when given). Infeasibility is screened cheaply on a frequency grid (a
//! grid value is a lower bound of the norm, so a grid violation is certain) and confirmed with
//! the Hamiltonian H∞ norms of [`super::norms`]. The highest feasible crossover wins; among
//! the feasible candidates at that crossover the one with the largest integral gain Ki (best
//! low-frequency load-disturbance rejection, the criterion of MIGO, Åström & Hägglund), or the
//! smallest M_s for a controller without integral action.
//!
//! # Discretisation
//! Tustin prewarped at the design crossover ([`super::discretize`]), so the discrete
//! controller's response at ω_c equals the continuous one exactly. [`DiscretePid`] exposes the
//! parallel-form difference equations (what the firmware runs):
//!
//! ```text
//! p[k] = Kp·e[k]
//! i[k] = i[k−1] + k_i·(e[k] + e[k−1])
//! d[k] = a_d·d[k−1] + b_d·(e[k] − e[k−1])
//! v[k] = p[k] + i[k] + d[k];   u[k] = roll-off biquad of v (or v)
//! ```
use super::discretize::{tustin, tustin_constant};
use crate::error::{Error, Result};
use crate::lti::{poly_mul, StateSpace, TransferFunction};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

mod tune;
pub use tune::{
    implemented_loop, tune_pid, weight_in_domain, PidDesignPoint, PidTuningSpec, TunedPid,
};

/// Second-order low-pass roll-off R(s) = ω_r²/(s² + 2ζ_r ω_r s + ω_r²).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Rolloff {
    /// Corner frequency ω_r / 2π, Hz (> 0).
    pub corner_hz: f64,
    /// Damping ratio ζ_r (> 0; 0.707 for a Butterworth corner).
    pub zeta: f64,
}

/// A continuous PID with filtered derivative and optional roll-off (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pid {
    /// Proportional gain Kp (actuator units per output unit).
    pub kp: f64,
    /// Integral gain Ki (per second).
    pub ki: f64,
    /// Derivative gain Kd (seconds).
    pub kd: f64,
    /// Derivative filter time constant τ_f, s (> 0 whenever kd != 0).
    pub tau_f: f64,
    /// Optional second-order roll-off.
    pub rolloff: Option<Rolloff>,
}

impl Pid {
    /// Checks finiteness, τ_f > 0 when Kd != 0, τ_f >= 0, and a valid roll-off.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("kp", self.kp),
            ("ki", self.ki),
            ("kd", self.kd),
            ("tau_f", self.tau_f),
        ] {
            if !v.is_finite() {
                return Err(Error::InvalidArgument(format!(
                    "PID {name} = {v} is not finite"
                )));
            }
        }
        if self.tau_f < 0.0 {
            return Err(Error::InvalidArgument(format!(
                "PID derivative filter time constant tau_f = {} s must be >= 0",
                self.tau_f
            )));
        }
        if self.kd != 0.0 && self.tau_f == 0.0 {
            return Err(Error::InvalidArgument(
                "PID with kd != 0 needs a derivative filter tau_f > 0 (a pure derivative is \
                 improper)"
                    .into(),
            ));
        }
        if let Some(r) = self.rolloff {
            if !(r.corner_hz.is_finite() && r.corner_hz > 0.0 && r.zeta.is_finite() && r.zeta > 0.0)
            {
                return Err(Error::InvalidArgument(format!(
                    "PID roll-off corner {} Hz and damping {} must be finite and > 0",
                    r.corner_hz, r.zeta
                )));
            }
        }
        Ok(())
    }

    /// PID part (without roll-off) as num/den in descending powers of s.
    fn pid_polys(&self) -> (Vec<f64>, Vec<f64>) {
        let (kp, ki, kd, tau) = (self.kp, self.ki, self.kd, self.tau_f);
        match (ki != 0.0, tau > 0.0) {
            // (Kp τ + Kd) s² + (Kp + Ki τ) s + Ki over τ s² + s.
            (true, true) => (vec![kp * tau + kd, kp + ki * tau, ki], vec![tau, 1.0, 0.0]),
            (true, false) => (vec![kp, ki], vec![1.0, 0.0]),
            // (Kp τ + Kd) s + Kp over τ s + 1.
            (false, true) => (vec![kp * tau + kd, kp], vec![tau, 1.0]),
            (false, false) => (vec![kp], vec![1.0]),
        }
    }

    /// The roll-off as num/den, or 1/1.
    fn rolloff_polys(&self) -> (Vec<f64>, Vec<f64>) {
        match self.rolloff {
            Some(r) => {
                let w = 2.0 * PI * r.corner_hz;
                (vec![w * w], vec![1.0, 2.0 * r.zeta * w, w * w])
            }
            None => (vec![1.0], vec![1.0]),
        }
    }

    /// The whole controller as a continuous transfer function.
    pub fn transfer_function(&self) -> Result<TransferFunction> {
        self.validate()?;
        let (pn, pd) = self.pid_polys();
        let (rn, rd) = self.rolloff_polys();
        TransferFunction::new(poly_mul(&pn, &rn), poly_mul(&pd, &rd), 0.0)
    }

    /// The whole controller as a continuous state-space model.
    pub fn to_state_space(&self) -> Result<StateSpace> {
        self.transfer_function()?.to_state_space()
    }

    /// K(jω) at `w_rad_s` (rad/s).
    pub fn freq_response(&self, w_rad_s: f64) -> Result<Complex64> {
        self.transfer_function()?.freq_response(w_rad_s)
    }

    /// Tustin discretisation with sample time `ts` (s), prewarped at `prewarp_hz` (Hz, below
    /// Nyquist) or plain Tustin when `None`.
    pub fn discretize(&self, ts: f64, prewarp_hz: Option<f64>) -> Result<DiscretePid> {
        self.validate()?;
        let wp = prewarp_hz.map(|f| 2.0 * PI * f);
        let c = tustin_constant(ts, wp)?;
        let ki_d = self.ki / c;
        let (a_d, b_d) = if self.tau_f > 0.0 {
            let tc = self.tau_f * c;
            ((tc - 1.0) / (tc + 1.0), self.kd * c / (tc + 1.0))
        } else {
            (0.0, 0.0)
        };
        let rolloff = match self.rolloff {
            Some(_) => {
                let (rn, rd) = self.rolloff_polys();
                let d = tustin(&TransferFunction::new(rn, rd, 0.0)?, ts, wp)?;
                let pad = |v: &[f64]| -> [f64; 3] {
                    let mut o = [0.0; 3];
                    let off = 3 - v.len();
                    o[off..].copy_from_slice(v);
                    o
                };
                Some(Biquad {
                    b: pad(&d.num),
                    a: pad(&d.den),
                })
            }
            None => None,
        };
        let whole = tustin(&self.transfer_function()?, ts, wp)?;
        Ok(DiscretePid {
            ts,
            prewarp_hz,
            kp: self.kp,
            ki_d,
            a_d,
            b_d,
            rolloff,
            num: whole.num,
            den: whole.den,
        })
    }
}

/// A second-order section `y[k] = b0 x[k] + b1 x[k−1] + b2 x[k−2] − a1 y[k−1] − a2 y[k−2]`
/// (a0 = 1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Biquad {
    /// Numerator [b0, b1, b2] (coefficients of z⁻⁰, z⁻¹, z⁻²).
    pub b: [f64; 3],
    /// Denominator [1, a1, a2].
    pub a: [f64; 3],
}

/// The firmware form of a Tustin-discretised [`Pid`] (see the module docs for the difference
/// equations). All coefficients are dimensionless per sample except as noted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiscretePid {
    /// Sample time, s.
    pub ts: f64,
    /// Prewarp frequency, Hz (None: plain Tustin).
    pub prewarp_hz: Option<f64>,
    /// Proportional gain Kp.
    pub kp: f64,
    /// Integrator coefficient k_i = Ki/c (trapezoidal): `i[k] = i[k−1] + k_i (e[k] + e[k−1])`.
    pub ki_d: f64,
    /// Derivative filter pole a_d = (τ_f c − 1)/(τ_f c + 1): `d[k] = a_d d[k−1] + b_d Δe[k]`.
    pub a_d: f64,
    /// Derivative gain b_d = Kd c/(τ_f c + 1).
    pub b_d: f64,
    /// Roll-off section applied to v = p + i + d (None: u = v).
    pub rolloff: Option<Biquad>,
    /// The whole controller as one transfer function in z, descending powers (= ascending
    /// powers of z⁻¹), `den[0] = 1`.
    pub num: Vec<f64>,
    /// Denominator matching `num`.
    pub den: Vec<f64>,
}

/// Internal state of [`DiscretePid::update`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DiscretePidState {
    e1: f64,
    i: f64,
    d: f64,
    v1: f64,
    v2: f64,
    u1: f64,
    u2: f64,
}

impl DiscretePidState {
    /// Adds `delta` to the integrator state i (the back-calculation anti-windup of a law that
    /// wraps the controller: the compensated control step).
    pub(crate) fn add_to_integrator(&mut self, delta: f64) {
        self.i += delta;
    }
}

impl DiscretePid {
    /// The whole controller as a discrete transfer function.
    pub fn transfer_function(&self) -> Result<TransferFunction> {
        TransferFunction::new(self.num.clone(), self.den.clone(), self.ts)
    }
    /// The whole controller as a discrete state-space model.
    pub fn to_state_space(&self) -> Result<StateSpace> {
        self.transfer_function()?.to_state_space()
    }
    /// One controller step for error sample `e`; returns the command. With `limit = Some(l)`
    /// (l > 0) the command is clamped to [−l, l] and the integrator is held (conditional
    /// integration anti-windup) whenever integrating would push a saturated command further
    /// into saturation; with `None` the law is linear and equals [`Self::transfer_function`].
    pub fn update(&self, st: &mut DiscretePidState, e: f64, limit: Option<f64>) -> f64 {
        self.update_detailed(st, e, limit, true).0
    }

    /// [`Self::update`] returning (applied command, demanded command before the clamp);
    /// `anti_windup = false` keeps integrating through saturation (plain hard saturation).
    pub fn update_detailed(
        &self,
        st: &mut DiscretePidState,
        e: f64,
        limit: Option<f64>,
        anti_windup: bool,
    ) -> (f64, f64) {
        let i_new = st.i + self.ki_d * (e + st.e1);
        let d_new = self.a_d * st.d + self.b_d * (e - st.e1);
        let p = self.kp * e;
        let out = |i: f64, st: &DiscretePidState| -> (f64, f64) {
            let v = p + i + d_new;
            let u = match self.rolloff {
                Some(bq) => {
                    bq.b[0] * v + bq.b[1] * st.v1 + bq.b[2] * st.v2
                        - bq.a[1] * st.u1
                        - bq.a[2] * st.u2
                }
                None => v,
            };
            (v, u)
        };
        let (mut v, mut u) = out(i_new, st);
        let mut i_keep = i_new;
        if let (Some(l), true) = (limit, anti_windup) {
            if u.abs() > l && (i_new - st.i) * u > 0.0 {
                i_keep = st.i;
                let r = out(i_keep, st);
                v = r.0;
                u = r.1;
            }
        }
        st.e1 = e;
        st.i = i_keep;
        st.d = d_new;
        st.v2 = st.v1;
        st.v1 = v;
        st.u2 = st.u1;
        // The roll-off filter state holds the unclamped output so the filter stays linear.
        st.u1 = u;
        match limit {
            Some(l) => (u.clamp(-l, l), u),
            None => (u, u),
        }
    }
}
