//! Loop shaping with notch filters: PID (+ roll-off, + the lead of its filtered derivative)
//! in series with notches placed on the plant's lightly damped modes, tuned under the same
//! constraints as [`crate::robust::pid::tune_pid`] (M_s, ‖W_m T‖∞ < 1, ‖KS‖∞).
//!
//! # Notch placement ([`place_notches`])
//! Every pole pair of the plant with damping ζ_p below `max_mode_damping` and natural
//! frequency ω_p above the target crossover gets
//! N(s) = (s² + 2ζ_n ω_p s + ω_p²)/(s² + 2ζ_d ω_p s + ω_p²): centre ω_p (from the model),
//! depth ζ_n/ζ_d with ζ_n = ζ_p (the zeros cancel the resonance peak), width
//! ζ_d = clamp(0.3 + 0.5·|W_m(jω_p)|, 0.3, 1): the less certain the model is at the mode (W_m
//! from the data), the wider the notch, so a mode that moves within the uncertainty stays
//! inside it. |N(jω)| ≤ 1 at every ω.
//!
//! # Tuning ([`tune_pid_notch`])
//! The PID tuner runs on the shaped plant G·N. S, T and W_m·T of its loop are exactly those of
//! the implemented loop K = PID·N, and its KS = PID·S bounds the real KS = N·PID·S from above
//! (|N| ≤ 1), so every constraint it certifies holds for the implemented controller. The
//! result is re-verified independently on the implemented loop (Hamiltonian H∞ norms of S, T,
//! W_m·T, KS; exact crossover solves of [`crate::robust::loops::margins`]).
//!
//! Sampled loops: for a discrete plant (identified at the controller rate) each notch is
//! discretised by Tustin prewarped at its centre and the PID as in the PID tuner (Tustin
//! prewarped at the crossover); W_m is mapped like the tuner maps it.
use crate::error::{Error, Result};
use crate::lti::{StateSpace, TransferFunction};
use crate::robust::discretize::tustin_state_space;
use crate::robust::loops::{margins, FeedbackLoop, Margins};
use crate::robust::norms::balance;
use crate::robust::norms::hinf_norm;
use crate::robust::pid::{implemented_loop, tune_pid, weight_in_domain, PidTuningSpec, TunedPid};
use crate::robust::uncertainty::UncertaintyWeight;
use std::f64::consts::PI;

/// A second-order notch N(s) = (s² + 2ζ_n ω s + ω²)/(s² + 2ζ_d ω s + ω²), ω = 2π·centre.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Notch {
    /// Centre frequency, Hz.
    pub centre_hz: f64,
    /// Numerator damping ζ_n (depth: |N(jω)| = ζ_n/ζ_d at the centre).
    pub zeta_num: f64,
    /// Denominator damping ζ_d (width).
    pub zeta_den: f64,
}

impl Notch {
    /// The notch as a continuous transfer function.
    pub fn transfer_function(&self) -> Result<TransferFunction> {
        let w = 2.0 * PI * self.centre_hz;
        if !(w.is_finite() && w > 0.0 && self.zeta_num >= 0.0 && self.zeta_den > self.zeta_num) {
            return Err(Error::InvalidArgument(format!(
                "notch at {} Hz needs a centre > 0 and 0 <= ζ_n ({}) < ζ_d ({})",
                self.centre_hz, self.zeta_num, self.zeta_den
            )));
        }
        TransferFunction::new(
            vec![1.0, 2.0 * self.zeta_num * w, w * w],
            vec![1.0, 2.0 * self.zeta_den * w, w * w],
            0.0,
        )
    }

    /// The notch as a state-space model: continuous for `ts = None`, else Tustin prewarped at
    /// the centre (so centre and depth are exact in the sampled loop).
    pub fn in_domain(&self, ts: Option<f64>) -> Result<StateSpace> {
        let c = self.transfer_function()?.to_state_space()?;
        match ts {
            None => Ok(c),
            Some(t) => {
                let wc = 2.0 * PI * self.centre_hz;
                if !(wc * t < PI) {
                    return Err(Error::InvalidArgument(format!(
                        "notch centre {} Hz is at or above the Nyquist frequency {} Hz",
                        self.centre_hz,
                        0.5 / t
                    )));
                }
                tustin_state_space(&balance(&c)?, t, Some(wc))
            }
        }
    }

    /// The sampled notch as one biquad `([b0, b1, b2], [1, a1, a2])` in z⁻¹: the Tustin map
    /// prewarped at the centre, s = c (1 − z⁻¹)/(1 + z⁻¹), c = ω/tan(ωT/2) — the same transfer
    /// function as [`Self::in_domain`]`(Some(ts))`, in the firmware's direct form.
    pub fn biquad(&self, ts: f64) -> Result<([f64; 3], [f64; 3])> {
        self.transfer_function()?;
        let w = 2.0 * PI * self.centre_hz;
        if !(ts > 0.0 && w * ts < PI) {
            return Err(Error::InvalidArgument(format!(
                "notch centre {} Hz is at or above the Nyquist frequency {} Hz",
                self.centre_hz,
                0.5 / ts
            )));
        }
        let c = w / (0.5 * w * ts).tan();
        let quad = |z: f64| {
            [
                c * c + 2.0 * z * w * c + w * w,
                2.0 * (w * w - c * c),
                c * c - 2.0 * z * w * c + w * w,
            ]
        };
        let (n, d) = (quad(self.zeta_num), quad(self.zeta_den));
        Ok((n.map(|v| v / d[0]), [1.0, d[1] / d[0], d[2] / d[0]]))
    }

    /// Depth at the centre, dB (negative).
    pub fn depth_db(&self) -> f64 {
        20.0 * (self.zeta_num / self.zeta_den).log10()
    }
}

/// Notches for the lightly damped modes of `plant` above `above_hz` (see the module docs).
pub fn place_notches(
    plant: &StateSpace,
    above_hz: f64,
    max_mode_damping: f64,
    weight: Option<&UncertaintyWeight>,
) -> Result<Vec<Notch>> {
    let mut out = Vec::new();
    for z in plant.poles()? {
        // Discrete poles map to the s-plane by s = ln(z)/ts.
        let p = if plant.is_discrete() {
            z.ln() / plant.ts
        } else {
            z
        };
        if p.im <= 0.0 {
            continue;
        }
        let wn = p.norm();
        let zeta = -p.re / wn;
        if zeta < max_mode_damping && wn > 2.0 * PI * above_hz {
            let u = weight.map_or(0.0, |w| w.freq_response(wn).norm());
            out.push(Notch {
                centre_hz: wn / (2.0 * PI),
                zeta_num: zeta.max(0.0),
                zeta_den: (0.3 + 0.5 * u).clamp(0.3, 1.0),
            });
        }
    }
    Ok(out)
}

/// A PID + notch design with the independent check on the implemented loop.
#[derive(Debug, Clone)]
pub struct LoopShapedDesign {
    /// The PID part (tuned on G·N).
    pub pid: TunedPid,
    /// The notches in series with it.
    pub notches: Vec<Notch>,
    /// The shaped plant N·G the PID was tuned on (same S, T as the implemented loop).
    pub shaped_plant: StateSpace,
    /// The implemented controller K = PID·N (continuous).
    pub controller: StateSpace,
    /// Margins of L = G·K (exact crossover solves).
    pub margins: Margins,
    /// ‖S‖∞, ‖T‖∞, ‖KS‖∞ of the implemented loop; ‖W_m T‖∞ when a weight is given.
    pub ms: f64,
    /// ‖T‖∞.
    pub mt: f64,
    /// ‖KS‖∞.
    pub ks: f64,
    /// ‖W_m T‖∞.
    pub wm_t: Option<f64>,
}

/// Tunes PID + notches for a continuous SISO `plant` under `spec` (module docs). Modes with
/// damping below `max_mode_damping` above the target crossover are notched. Errors: a sampled
/// spec, an infeasible tuning, or an implemented loop that fails the re-verification.
pub fn tune_pid_notch(
    plant: &StateSpace,
    spec: &PidTuningSpec,
    max_mode_damping: f64,
) -> Result<LoopShapedDesign> {
    if spec.controller_ts.is_some() && !plant.is_discrete() {
        return Err(Error::InvalidArgument(
            "PID + notch tuning: a sampled design needs the plant identified at the controller \
             rate (a discrete plant); a continuous plant is tuned in continuous time"
                .into(),
        ));
    }
    let ts = plant.is_discrete().then_some(plant.ts);
    let notches = place_notches(
        plant,
        spec.target_crossover_hz,
        max_mode_damping,
        spec.weight.as_ref(),
    )?;
    let mut shaped = plant.clone();
    let mut n_total = StateSpace::identity(1, ts.unwrap_or(0.0))?;
    for n in &notches {
        let ns = n.in_domain(ts)?;
        shaped = ns.series(&shaped)?;
        n_total = ns.series(&n_total)?;
    }
    let pid = tune_pid(&shaped, spec)?;
    // The PID as the tuner's implemented loop realises it (Tustin prewarped at the crossover
    // for a sampled loop).
    let (pid_loop, _) =
        implemented_loop(&shaped, &pid.pid, ts, ts.map(|_| pid.design.crossover_hz))?;
    let controller = n_total.series(&pid_loop.controller)?;
    let lp = FeedbackLoop::new(plant, &controller)?;
    if !lp.is_stable()? {
        return Err(Error::Numerical(
            "PID + notch: the implemented loop is unstable".into(),
        ));
    }
    let ms = hinf_norm(&lp.s)?.gamma;
    let mt = hinf_norm(&lp.t)?.gamma;
    let ks = hinf_norm(&lp.ks)?.gamma;
    let wm_t = match &spec.weight {
        Some(w) => {
            let wm = weight_in_domain(w, ts, Some(pid.design.crossover_hz))?;
            Some(hinf_norm(&lp.t.series(&wm)?)?.gamma)
        }
        None => None,
    };
    let violated = ms > spec.ms_max * (1.0 + 1e-6)
        || wm_t.is_some_and(|v| v >= 1.0)
        || spec.ks_max.is_some_and(|k| ks > k * (1.0 + 1e-6));
    if violated {
        return Err(Error::Numerical(format!(
            "PID + notch: the implemented loop fails its constraints on re-verification \
             (M_s {ms:.4}, ‖KS‖∞ {ks:.4e}, ‖W_m T‖∞ {wm_t:?})"
        )));
    }
    let wc = 2.0 * PI * pid.design.crossover_hz;
    let margins = margins(&lp.l, Some((wc / 100.0, wc * 100.0)))?;
    Ok(LoopShapedDesign {
        pid,
        notches,
        shaped_plant: shaped,
        controller,
        margins,
        ms,
        mt,
        ks,
        wm_t,
    })
}
