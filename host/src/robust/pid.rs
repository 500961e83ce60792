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
use super::discretize::{tustin, tustin_constant, tustin_state_space};
use super::loops::{analysis_grid, FeedbackLoop};
use super::norms::{balance, hinf_norm, sigma_max};
use super::uncertainty::UncertaintyWeight;
use crate::error::{Error, Result};
use crate::lti::{poly_mul, FreqEvaluator, StateSpace, TransferFunction};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

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

/// What [`tune_pid`] must achieve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PidTuningSpec {
    /// Target (and by default maximum) gain crossover frequency, Hz.
    pub target_crossover_hz: f64,
    /// Largest admissible sensitivity peak M_s = ‖S‖∞ (default 1.6).
    pub ms_max: f64,
    /// Multiplicative uncertainty weight: require ‖W_m T‖∞ < 1 (robust stability).
    pub weight: Option<UncertaintyWeight>,
    /// Largest admissible ‖KS‖∞ (actuator units per output unit), e.g. the actuator limit
    /// divided by the largest reference amplitude.
    pub ks_max: Option<f64>,
    /// Controller sample time, s. Required to be `None` or equal to the plant's `ts` for a
    /// discrete plant (then the plant's `ts` is used); for a continuous plant `Some(ts)` tunes
    /// the sampled loop (ZOH plant, Tustin controller) and `None` a continuous controller.
    pub controller_ts: Option<f64>,
    /// Roll-off corner as a multiple of the crossover (e.g. 8) and its damping; `None` for
    /// no roll-off.
    pub rolloff_ratio: Option<(f64, f64)>,
    /// Use integral action (default true).
    pub integral: bool,
    /// Use derivative (lead) action (default true).
    pub derivative: bool,
    /// Crossover search range as fractions of the target (default 0.1 ..= 1.0).
    pub min_crossover_scale: f64,
    /// Upper end of the crossover search range (default 1.0: the target is the ceiling).
    pub max_crossover_scale: f64,
    /// Largest phase lead the derivative filter may supply, degrees (default 65).
    pub max_phase_lead_deg: f64,
}

impl PidTuningSpec {
    /// Defaults around a target crossover in Hz: M_s <= 1.6, PID without roll-off, search
    /// 0.1…1 × target.
    pub fn new(target_crossover_hz: f64) -> Self {
        Self {
            target_crossover_hz,
            ms_max: 1.6,
            weight: None,
            ks_max: None,
            controller_ts: None,
            rolloff_ratio: None,
            integral: true,
            derivative: true,
            min_crossover_scale: 0.1,
            max_crossover_scale: 1.0,
            max_phase_lead_deg: 65.0,
        }
    }
}

/// Shape parameters of the series-form design at one crossover.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PidDesignPoint {
    /// Design crossover, Hz (|L| = 1 there by construction).
    pub crossover_hz: f64,
    /// Phase-margin target used for the lead, degrees.
    pub phase_margin_target_deg: f64,
    /// α_i = ω_c/ω_i (∞ without integral action).
    pub integral_ratio: f64,
    /// β = ω_p/ω_z (1 without lead).
    pub lead_ratio: f64,
}

/// Result of [`tune_pid`]: the controller, its discrete form and the design evidence. The
/// receipts ([`super::receipts`]) re-verify everything independently.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TunedPid {
    /// Continuous controller.
    pub pid: Pid,
    /// Firmware controller (Tustin, prewarped at the crossover) when a sample time applies.
    pub discrete: Option<DiscretePid>,
    /// The winning design point.
    pub design: PidDesignPoint,
    /// Requested target crossover, Hz.
    pub target_crossover_hz: f64,
    /// ‖S‖∞ of the implemented loop (Hamiltonian).
    pub ms: f64,
    /// ‖T‖∞ of the implemented loop.
    pub mt: f64,
    /// ‖W_m T‖∞ (None without a weight).
    pub wm_t: Option<f64>,
    /// ‖KS‖∞ of the implemented loop.
    pub ks: f64,
    /// Candidates evaluated during the search.
    pub candidates_evaluated: usize,
    /// One-paragraph statement of the method.
    pub method: String,
}

/// The loop that will actually run: the plant and the controller in the same domain.
/// Returns (plant in loop domain, controller state space, discrete controller if any).
pub fn implemented_loop(
    plant: &StateSpace,
    pid: &Pid,
    controller_ts: Option<f64>,
    prewarp_hz: Option<f64>,
) -> Result<(FeedbackLoop, Option<DiscretePid>)> {
    let ts = resolve_ts(plant, controller_ts)?;
    match ts {
        None => {
            let k = pid.to_state_space()?;
            Ok((FeedbackLoop::new(plant, &k)?, None))
        }
        Some(ts) => {
            let g = if plant.is_discrete() {
                plant.clone()
            } else {
                plant.c2d_zoh(ts)?
            };
            let dp = pid.discretize(ts, prewarp_hz)?;
            // Same transfer function as `dp`, realised by a state-space Tustin map of the
            // balanced continuous controller (better conditioned than the z-polynomials).
            let k = tustin_state_space(
                &balance(&pid.to_state_space()?)?,
                ts,
                prewarp_hz.map(|f| 2.0 * PI * f),
            )?;
            Ok((FeedbackLoop::new(&g, &k)?, Some(dp)))
        }
    }
}

fn resolve_ts(plant: &StateSpace, controller_ts: Option<f64>) -> Result<Option<f64>> {
    if plant.is_discrete() {
        match controller_ts {
            Some(t) if (t - plant.ts).abs() > 1e-12 * plant.ts => {
                Err(Error::InvalidArgument(format!(
                    "controller sample time {t} s differs from the discrete plant's {} s; \
                     identify or resample the plant at the controller rate",
                    plant.ts
                )))
            }
            _ => Ok(Some(plant.ts)),
        }
    } else {
        match controller_ts {
            Some(t) if !(t.is_finite() && t > 0.0) => Err(Error::InvalidArgument(format!(
                "controller sample time {t} s must be finite and > 0"
            ))),
            other => Ok(other),
        }
    }
}

/// The weight W_m in the loop's domain: itself for continuous loops, Tustin prewarped at
/// `prewarp_hz` for discrete ones.
pub fn weight_in_domain(
    w: &UncertaintyWeight,
    ts: Option<f64>,
    prewarp_hz: Option<f64>,
) -> Result<StateSpace> {
    match ts {
        None => w.to_state_space(),
        Some(ts) => tustin_state_space(
            &balance(&w.to_state_space()?)?,
            ts,
            prewarp_hz.map(|f| 2.0 * PI * f),
        ),
    }
}

struct Eval {
    pid: Pid,
    point: PidDesignPoint,
    ms: f64,
    mt: f64,
    wm_t: Option<f64>,
    ks: f64,
}

struct Tuner<'a> {
    spec: &'a PidTuningSpec,
    ts: Option<f64>,
    loop_plant: StateSpace,
    ev: FreqEvaluator,
    evaluated: usize,
}

impl Tuner<'_> {
    /// Series-form design at crossover `w` (rad/s); None when the lead needed is too large.
    fn design(&self, w: f64, pm_deg: f64, alpha: f64) -> Result<Option<(Pid, PidDesignPoint)>> {
        let spec = self.spec;
        let g = self.ev.at_rad_s(w)?[(0, 0)];
        let rolloff = spec.rolloff_ratio.map(|(ratio, zeta)| Rolloff {
            corner_hz: ratio * w / (2.0 * PI),
            zeta,
        });
        let r = match rolloff {
            Some(ro) => {
                let wr = 2.0 * PI * ro.corner_hz;
                let s = Complex64::new(0.0, w);
                wr * wr / (s * s + 2.0 * ro.zeta * wr * s + wr * wr)
            }
            None => Complex64::new(1.0, 0.0),
        };
        let gr = g * r;
        if gr.norm().partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Ok(None);
        }
        let wi = if spec.integral { w / alpha } else { 0.0 };
        let lag = (wi / w).atan().to_degrees();
        let mut lead = pm_deg - 180.0 - gr.arg().to_degrees() + lag;
        while lead > 180.0 {
            lead -= 360.0;
        }
        while lead <= -180.0 {
            lead += 360.0;
        }
        if lead > spec.max_phase_lead_deg || (lead > 0.0 && !spec.derivative) {
            return Ok(None);
        }
        let beta = if lead > 0.0 {
            let s = lead.to_radians().sin();
            (1.0 + s) / (1.0 - s)
        } else {
            1.0
        };
        let (wz, wp) = (w / beta.sqrt(), w * beta.sqrt());
        let s = Complex64::new(0.0, w);
        let shape = (s + wi) / s * (1.0 + s / wz) / (1.0 + s / wp);
        let k = 1.0 / (gr.norm() * shape.norm());
        let pid = if beta > 1.0 {
            Pid {
                kp: k * (1.0 + wi / wz - wi / wp),
                ki: k * wi,
                kd: k * (1.0 / wz - 1.0 / wp) * (1.0 - wi / wp),
                tau_f: 1.0 / wp,
                rolloff,
            }
        } else {
            Pid {
                kp: k,
                ki: k * wi,
                kd: 0.0,
                tau_f: 0.0,
                rolloff,
            }
        };
        Ok(Some((
            pid,
            PidDesignPoint {
                crossover_hz: w / (2.0 * PI),
                phase_margin_target_deg: pm_deg,
                integral_ratio: if spec.integral { alpha } else { f64::INFINITY },
                lead_ratio: beta,
            },
        )))
    }

    /// Evaluates a design on the implemented loop; None when infeasible.
    fn check(&mut self, pid: Pid, point: PidDesignPoint) -> Result<Option<Eval>> {
        self.evaluated += 1;
        let spec = self.spec;
        let (lp, _) = match implemented_loop(
            &self.loop_plant,
            &pid,
            self.ts,
            self.ts.map(|_| point.crossover_hz),
        ) {
            Ok(v) => v,
            Err(_) => return Ok(None),
        };
        if !lp.is_stable()? {
            return Ok(None);
        }
        let wm = match &spec.weight {
            Some(w) => Some(weight_in_domain(w, self.ts, Some(point.crossover_hz))?),
            None => None,
        };
        let wmt_sys = match &wm {
            Some(w) => Some(lp.t.series(w)?),
            None => None,
        };
        // Cheap screen: grid values are lower bounds of the H∞ norms.
        let wc = 2.0 * PI * point.crossover_hz;
        let grid = analysis_grid(&lp.l, Some((wc / 100.0, wc * 100.0)), 30)?;
        let ev_s = FreqEvaluator::new(&lp.s);
        let ev_ks = FreqEvaluator::new(&lp.ks);
        let ev_wt = wmt_sys.as_ref().map(FreqEvaluator::new);
        // A point where an evaluation fails (numerically at a pole) is simply not screened.
        let peak = |ev: &FreqEvaluator, w: f64| -> f64 {
            ev.at_rad_s(w)
                .ok()
                .and_then(|g| sigma_max(&g).ok())
                .unwrap_or(0.0)
        };
        for &w in &grid {
            if peak(&ev_s, w) > spec.ms_max {
                return Ok(None);
            }
            if let Some(e) = &ev_wt {
                if peak(e, w) >= 1.0 {
                    return Ok(None);
                }
            }
            if let Some(kmax) = spec.ks_max {
                if peak(&ev_ks, w) > kmax {
                    return Ok(None);
                }
            }
        }
        // A norm that cannot be evaluated (e.g. an ill-conditioned candidate) makes the
        // candidate infeasible rather than aborting the search.
        let Ok(ms) = hinf_norm(&lp.s).map(|h| h.gamma) else {
            return Ok(None);
        };
        if ms > spec.ms_max {
            return Ok(None);
        }
        let wm_t = match &wmt_sys {
            Some(sys) => {
                let Ok(v) = hinf_norm(sys).map(|h| h.gamma) else {
                    return Ok(None);
                };
                if v >= 1.0 {
                    return Ok(None);
                }
                Some(v)
            }
            None => None,
        };
        let Ok(ks) = hinf_norm(&lp.ks).map(|h| h.gamma) else {
            return Ok(None);
        };
        if let Some(kmax) = spec.ks_max {
            if ks > kmax {
                return Ok(None);
            }
        }
        let Ok(mt) = hinf_norm(&lp.t).map(|h| h.gamma) else {
            return Ok(None);
        };
        Ok(Some(Eval {
            pid,
            point,
            ms,
            mt,
            wm_t,
            ks,
        }))
    }

    /// Best feasible candidate at crossover `w`, if any: the largest integral gain Ki (as in
    /// MIGO, Åström & Hägglund), or the smallest M_s without integral action.
    fn best_at(&mut self, w: f64) -> Result<Option<Eval>> {
        let mut best: Option<Eval> = None;
        let alphas: &[f64] = if self.spec.integral {
            &[2.0, 3.0, 5.0, 8.0, 15.0, 30.0]
        } else {
            &[f64::INFINITY]
        };
        for pm in [30.0, 35.0, 40.0, 45.0, 50.0, 55.0, 60.0, 65.0, 70.0] {
            for &alpha in alphas {
                if let Some((pid, point)) = self.design(w, pm, alpha)? {
                    if let Some(e) = self.check(pid, point)? {
                        let better = |b: &Eval| {
                            if self.spec.integral {
                                e.pid.ki > b.pid.ki
                            } else {
                                e.ms < b.ms
                            }
                        };
                        if best.as_ref().is_none_or(better) {
                            best = Some(e);
                        }
                    }
                }
            }
        }
        Ok(best)
    }
}

/// Tunes a PID for the SISO `plant` (continuous or discrete) following `spec`; see the module
/// docs for the method. Errors: invalid spec or plant, a target at or above the Nyquist
/// frequency, or no feasible design anywhere in the crossover range
/// ([`Error::InvalidArgument`] starting "PID tuning infeasible:", naming the constraints).
pub fn tune_pid(plant: &StateSpace, spec: &PidTuningSpec) -> Result<TunedPid> {
    plant.validate()?;
    if !plant.is_siso() {
        return Err(Error::InvalidArgument(format!(
            "PID tuning needs a SISO plant, got {}x{}",
            plant.n_outputs(),
            plant.n_inputs()
        )));
    }
    let fc = spec.target_crossover_hz;
    if !(fc.is_finite() && fc > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "target crossover {fc} Hz must be finite and > 0"
        )));
    }
    if !(spec.ms_max.is_finite() && spec.ms_max > 1.0) {
        return Err(Error::InvalidArgument(format!(
            "ms_max = {} must be finite and > 1",
            spec.ms_max
        )));
    }
    if let Some(k) = spec.ks_max {
        if !(k.is_finite() && k > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "ks_max = {k} must be finite and > 0"
            )));
        }
    }
    if !(spec.min_crossover_scale > 0.0
        && spec.max_crossover_scale >= spec.min_crossover_scale
        && spec.max_crossover_scale.is_finite())
    {
        return Err(Error::InvalidArgument(format!(
            "crossover scale range {}..{} must satisfy 0 < min <= max < ∞",
            spec.min_crossover_scale, spec.max_crossover_scale
        )));
    }
    if !(spec.max_phase_lead_deg > 0.0 && spec.max_phase_lead_deg < 90.0) {
        return Err(Error::InvalidArgument(format!(
            "max_phase_lead_deg = {} must lie in (0, 90)",
            spec.max_phase_lead_deg
        )));
    }
    if let Some((ratio, zeta)) = spec.rolloff_ratio {
        if !(ratio.is_finite() && ratio > 1.0 && zeta.is_finite() && zeta > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "roll-off ratio {ratio} must be > 1 and damping {zeta} > 0"
            )));
        }
    }
    let ts = resolve_ts(plant, spec.controller_ts)?;
    if let Some(t) = ts {
        let nyq = 0.5 / t;
        if fc * spec.max_crossover_scale >= nyq {
            return Err(Error::InvalidArgument(format!(
                "target crossover {} Hz is at or above the Nyquist frequency {nyq} Hz of the \
                 controller sample time {t} s",
                fc * spec.max_crossover_scale
            )));
        }
    }
    let loop_plant = match (ts, plant.is_discrete()) {
        (Some(t), false) => plant.c2d_zoh(t)?,
        _ => plant.clone(),
    };
    let mut tuner = Tuner {
        spec,
        ts,
        ev: FreqEvaluator::new(&loop_plant),
        loop_plant: loop_plant.clone(),
        evaluated: 0,
    };
    let wt = 2.0 * PI * fc;
    let n_scales = 25;
    let scales =
        super::norms::logspace(spec.max_crossover_scale, spec.min_crossover_scale, n_scales);
    let mut found: Option<(f64, Eval)> = None;
    let mut above: Option<f64> = None;
    for &sc in &scales {
        if let Some(e) = tuner.best_at(wt * sc)? {
            found = Some((sc, e));
            break;
        }
        above = Some(sc);
    }
    let (mut sc_ok, mut best) = found.ok_or_else(|| {
        Error::InvalidArgument(format!(
            "PID tuning infeasible: no PID with crossover in {:.4}..{:.4} Hz meets M_s <= {}{}{} with a stable loop \
             (phase lead capped at {}°); lower the target, relax the limits or add roll-off",
            fc * spec.min_crossover_scale,
            fc * spec.max_crossover_scale,
            spec.ms_max,
            if spec.weight.is_some() { ", ‖W_m T‖∞ < 1" } else { "" },
            spec.ks_max
                .map(|k| format!(", ‖KS‖∞ <= {k}"))
                .unwrap_or_default(),
            spec.max_phase_lead_deg
        ))
    })?;
    if let Some(mut sc_bad) = above {
        for _ in 0..8 {
            let mid = (sc_ok * sc_bad).sqrt();
            match tuner.best_at(wt * mid)? {
                Some(e) => {
                    sc_ok = mid;
                    best = e;
                }
                None => sc_bad = mid,
            }
        }
    }
    let discrete = match ts {
        Some(t) => Some(best.pid.discretize(t, Some(best.point.crossover_hz))?),
        None => None,
    };
    Ok(TunedPid {
        pid: best.pid,
        discrete,
        design: best.point,
        target_crossover_hz: fc,
        ms: best.ms,
        mt: best.mt,
        wm_t: best.wm_t,
        ks: best.ks,
        candidates_evaluated: tuner.evaluated,
        method: "series-form PID loop-shaped at a trial crossover (lead from a phase-margin \
                 target, integral corner at crossover/α_i, gain for |L| = 1), searched over \
                 crossover (max first, then bisection), phase-margin target and α_i; feasibility \
                 on the implemented loop: closed-loop stability, M_s, ‖W_m T‖∞ < 1, ‖KS‖∞ by \
                 Hamiltonian H∞ norms; Tustin discretisation prewarped at the crossover"
            .into(),
    })
}
