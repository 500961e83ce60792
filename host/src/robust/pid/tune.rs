//! Robust tuning of [`super::Pid`] for a target crossover (the method is in the module
//! documentation of [`super`]).
use super::{DiscretePid, Pid, Rolloff};
use crate::error::{Error, Result};
use crate::lti::{FreqEvaluator, StateSpace};
use crate::robust::discretize::tustin_state_space;
use crate::robust::loops::{analysis_grid, FeedbackLoop};
use crate::robust::norms::{self, balance, hinf_norm, sigma_max};
use crate::robust::uncertainty::UncertaintyWeight;
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

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
    let scales = norms::logspace(spec.max_crossover_scale, spec.min_crossover_scale, n_scales);
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
