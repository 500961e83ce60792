//! The receipt set of a tuned loop: [`compute_receipts`] and its per-family steps.

use crate::error::{Error, Result};
use crate::lti::{FreqEvaluator, StateSpace};
use crate::robust::loops::{analysis_grid, bisect_root, margins, FeedbackLoop, Margins};
use crate::robust::norms::{hinf_norm, HinfNorm};
use crate::robust::pid::{implemented_loop, weight_in_domain, DiscretePid, Pid};
use crate::robust::step::{saturated_step, StepResponse, StepSpec};
use crate::robust::uncertainty::UncertaintyWeight;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use super::phase::push_etfe_receipt;
use super::*;

/// Everything [`compute_receipts`] needs.
#[derive(Debug, Clone)]
pub struct ReceiptInputs<'a> {
    /// Nominal plant G0 (SISO, continuous or discrete).
    pub plant: &'a StateSpace,
    /// The controller (continuous parameters).
    pub pid: &'a Pid,
    /// Controller sample time, s (None for a continuous loop; forced to the plant's `ts` for a
    /// discrete plant).
    pub controller_ts: Option<f64>,
    /// Crossover the design aimed at, Hz: Tustin prewarp, W_m discretisation, ETFE band and
    /// step duration refer to it.
    pub crossover_hz: f64,
    /// Multiplicative uncertainty weight (skip `robust_stability` when None).
    pub weight: Option<&'a UncertaintyWeight>,
    /// Symmetric actuator limit, plant input units (e.g. A).
    pub actuator_limit: f64,
    /// Unit of the actuator command, for the receipts ("A").
    pub actuator_unit: &'a str,
    /// Reference step height and worst-case reference amplitude, plant output units.
    pub reference_amplitude: f64,
    /// Measured ETFE to check G0's phase against (skip when None).
    pub etfe: Option<EtfeView<'a>>,
    /// Cross-validation fit from validation (skip when None).
    pub cross_validation: Option<CrossValidation>,
    /// Limits.
    pub limits: ReceiptLimits,
    /// Conditional-integration anti-windup in the simulated controller.
    pub anti_windup: bool,
}

/// First frequency (Hz) where |S| rises through 1/√2 (−3 dB) from below, searched on the
/// analysis grid of the loop and refined by bisection. 0 when |S| is already >= −3 dB at the
/// lowest grid frequency; the top of the grid (Nyquist for discrete loops) when it never
/// crosses.
pub fn disturbance_rejection_bandwidth_hz(lp: &FeedbackLoop, crossover_hz: f64) -> Result<f64> {
    let wc = 2.0 * PI * crossover_hz;
    let grid = analysis_grid(&lp.l, Some((wc / 1e3, wc * 1e3)), 200)?;
    let ev = FreqEvaluator::new(&lp.s);
    let f = |w: f64| -> Result<f64> {
        Ok(ev.at_rad_s(w)?[(0, 0)].norm() - std::f64::consts::FRAC_1_SQRT_2)
    };
    let mut prev: Option<(f64, f64)> = None;
    for &w in &grid {
        let Ok(v) = f(w) else { continue };
        match prev {
            None if v >= 0.0 => return Ok(0.0),
            Some((wp, vp)) if vp < 0.0 && v >= 0.0 => {
                return Ok(bisect_root(f, wp, w)? / (2.0 * PI));
            }
            _ => {}
        }
        prev = Some((w, v));
    }
    Ok(grid.last().copied().unwrap_or(0.0) / (2.0 * PI))
}

/// Peak gains of the closed loop used by the receipts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClosedLoopNorms {
    /// ‖S‖∞ (None when the closed loop is unstable).
    pub ms: Option<HinfNorm>,
    /// ‖T‖∞.
    pub mt: Option<HinfNorm>,
    /// ‖KS‖∞ (actuator units per output unit).
    pub ks: Option<HinfNorm>,
    /// ‖W_m T‖∞ from the Hamiltonian (W_m Tustin-prewarped at the crossover for discrete loops).
    pub wm_t: Option<HinfNorm>,
    /// max over a dense grid of |W_m(jω)|·|T| with the exact continuous W_m (discrete loops
    /// evaluate T on the unit circle): an independent cross-check.
    pub wm_t_grid: Option<f64>,
}

/// Everything computed for the receipts, for the report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReceiptsReport {
    /// The receipts and the overall verdict.
    pub receipts: Receipts,
    /// Classical margins of the implemented loop.
    pub margins: Option<Margins>,
    /// Closed-loop peak gains.
    pub norms: ClosedLoopNorms,
    /// Closed-loop poles as [re, im] (s-plane rad/s or z-plane).
    pub closed_loop_poles: Vec<[f64; 2]>,
    /// The discrete controller that was simulated (the firmware law).
    pub discrete_controller: Option<DiscretePid>,
    /// Saturated step response (None if the simulation could not run; see its receipt).
    pub step: Option<StepResponse>,
    /// Phase agreement with the ETFE.
    pub phase_agreement: Option<PhaseAgreement>,
}

/// Computes all receipts for the loop `inp.plant` + `inp.pid` (see the module docs). Failing
/// loops produce failing receipts, not errors; errors are reserved for invalid inputs.
pub fn compute_receipts(inp: &ReceiptInputs<'_>) -> Result<ReceiptsReport> {
    check_inputs(inp)?;
    let fc = inp.crossover_hz;
    let lim = &inp.limits;
    let (lp, dpid) = implemented_loop(inp.plant, inp.pid, inp.controller_ts, Some(fc))?;
    let domain = if lp.is_discrete() {
        format!(
            "sampled loop, ts = {} s (ZOH plant, Tustin controller prewarped at {fc} Hz)",
            lp.plant.ts
        )
    } else {
        "continuous loop".to_string()
    };
    let mut rs = Receipts::default();
    let poles = lp.closed_loop_poles()?;
    let abscissa = lp.stability_abscissa()?;
    let stable = lp.is_stable()?;
    rs.push(Receipt::new(
        ReceiptKind::ClosedLoopStable,
        if lp.is_discrete() {
            "largest closed-loop pole modulus (stable when < 1)"
        } else {
            "largest closed-loop pole real part (stable when < 0)"
        },
        abscissa,
        Comparison::LessThan,
        if lp.is_discrete() { 1.0 } else { 0.0 },
        if lp.is_discrete() { "1" } else { "rad/s" },
        format!("{} closed-loop poles, {domain}", poles.len()),
    ));
    let wc = 2.0 * PI * fc;
    let m = margins(&lp.l, Some((wc / 100.0, wc * 100.0))).ok();
    push_margin_receipts(&mut rs, m.as_ref(), lim);
    let norms = push_norm_receipts(&mut rs, inp, &lp, stable)?;
    let (kd, simulated) = saturated_step_of(inp, &lp, dpid, &domain)?;
    push_step_receipts(&mut rs, inp, &simulated);
    let pa = match &inp.etfe {
        Some(e) => Some(push_etfe_receipt(&mut rs, inp.plant, e, lim, fc)?),
        None => None,
    };
    if let Some(cv) = &inp.cross_validation {
        rs.push(cross_validation_receipt(cv));
    }
    Ok(ReceiptsReport {
        receipts: rs,
        margins: m,
        norms,
        closed_loop_poles: poles.iter().map(|p| [p.re, p.im]).collect(),
        discrete_controller: Some(kd),
        step: simulated.0.ok(),
        phase_agreement: pa,
    })
}

/// Refuses a crossover, actuator limit or reference amplitude that is not finite and > 0.
fn check_inputs(inp: &ReceiptInputs<'_>) -> Result<()> {
    let fc = inp.crossover_hz;
    if !(fc.is_finite() && fc > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "receipts: crossover {fc} Hz must be finite and > 0"
        )));
    }
    if !(inp.actuator_limit.is_finite() && inp.actuator_limit > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "receipts: actuator limit {} must be finite and > 0",
            inp.actuator_limit
        )));
    }
    if !(inp.reference_amplitude.is_finite() && inp.reference_amplitude > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "receipts: reference amplitude {} must be finite and > 0",
            inp.reference_amplitude
        )));
    }
    Ok(())
}

/// The gain- and phase-margin receipts (failing, with the reason, when the margins could not
/// be computed).
pub(crate) fn push_margin_receipts(rs: &mut Receipts, m: Option<&Margins>, lim: &ReceiptLimits) {
    match m {
        Some(m) => {
            rs.push(Receipt::new(
                ReceiptKind::GainMargin,
                "gain margin (smallest |GM| over phase crossovers)",
                if m.gain_margin.is_finite() {
                    m.gain_margin_db.abs()
                } else {
                    f64::INFINITY
                },
                Comparison::AtLeast,
                lim.gain_margin_db_min,
                "dB",
                match m.phase_crossover_hz {
                    Some(f) => format!(
                        "phase crossover at {} Hz (GM factor {}); all phase crossovers {:?} Hz",
                        fmt_sig(f),
                        fmt_sig(m.gain_margin),
                        m.phase_crossovers_hz
                    ),
                    None => "no phase crossover: infinite gain margin".into(),
                },
            ));
            rs.push(Receipt::new(
                ReceiptKind::PhaseMargin,
                "phase margin (smallest over gain crossovers)",
                m.phase_margin_deg,
                Comparison::AtLeast,
                lim.phase_margin_deg_min,
                "deg",
                match m.gain_crossover_hz {
                    Some(f) => format!(
                        "gain crossover at {} Hz; delay margin {} s; all gain crossovers {:?} Hz",
                        fmt_sig(f),
                        fmt_sig(m.delay_margin_s),
                        m.gain_crossovers_hz
                    ),
                    None => "no gain crossover".into(),
                },
            ));
        }
        None => {
            for (n, d, l, u) in [
                (
                    ReceiptKind::GainMargin,
                    "gain margin",
                    lim.gain_margin_db_min,
                    "dB",
                ),
                (
                    ReceiptKind::PhaseMargin,
                    "phase margin",
                    lim.phase_margin_deg_min,
                    "deg",
                ),
            ] {
                rs.push(Receipt::new(
                    n,
                    d,
                    f64::NAN,
                    Comparison::AtLeast,
                    l,
                    u,
                    "margins could not be computed (L evaluated at a pole?)".into(),
                ));
            }
        }
    }
}

/// The peak receipts (M_s, M_t, ‖W_m T‖∞ with a weight, disturbance-rejection bandwidth,
/// control effort); norms are infinite for an unstable loop.
pub(crate) fn push_norm_receipts(
    rs: &mut Receipts,
    inp: &ReceiptInputs<'_>,
    lp: &FeedbackLoop,
    stable: bool,
) -> Result<ClosedLoopNorms> {
    let lim = &inp.limits;
    let fc = inp.crossover_hz;
    let wc = 2.0 * PI * fc;
    let norm = |sys: &StateSpace| -> Option<HinfNorm> {
        if stable {
            hinf_norm(sys).ok()
        } else {
            None
        }
    };
    let ms = norm(&lp.s);
    let mt = norm(&lp.t);
    let ks = norm(&lp.ks);
    let val = |h: &Option<HinfNorm>| h.map_or(f64::INFINITY, |h| h.gamma);
    rs.push(Receipt::new(
        ReceiptKind::SensitivityPeak,
        "M_s = ‖S‖∞, S = 1/(1 + GK)",
        val(&ms),
        Comparison::AtMost,
        lim.ms_max,
        "1",
        peak_detail(&ms),
    ));
    rs.push(Receipt::new(
        ReceiptKind::ComplementarySensitivityPeak,
        "M_t = ‖T‖∞, T = GK/(1 + GK)",
        val(&mt),
        Comparison::AtMost,
        lim.mt_max,
        "1",
        peak_detail(&mt),
    ));
    let mut wm_t = None;
    let mut wm_t_grid = None;
    if let Some(w) = inp.weight {
        let ts = lp.is_discrete().then_some(lp.plant.ts);
        let wsys = weight_in_domain(w, ts, Some(fc))?;
        let wt = lp.t.series(&wsys)?;
        wm_t = norm(&wt);
        if stable {
            // Independent grid with the exact continuous weight.
            let top = if lp.is_discrete() {
                PI / lp.plant.ts * (1.0 - 1e-9)
            } else {
                wc * 1e4
            };
            let grid = crate::robust::norms::logspace(wc * 1e-4, top, 20_000);
            let ev = FreqEvaluator::new(&lp.t);
            let mut mx = 0.0f64;
            for &om in &grid {
                if let Ok(t) = ev.at_rad_s(om) {
                    mx = mx.max(t[(0, 0)].norm() * w.freq_response(om).norm());
                }
            }
            wm_t_grid = Some(mx);
        }
        let value = match (wm_t, wm_t_grid) {
            (Some(h), Some(g)) => h.gamma.max(g),
            _ => f64::INFINITY,
        };
        rs.push(Receipt::new(
            ReceiptKind::RobustStability,
            "‖W_m T‖∞ (robust stability against the measured multiplicative uncertainty)",
            value,
            Comparison::LessThan,
            1.0,
            "1",
            match (wm_t, wm_t_grid) {
                (Some(h), Some(g)) => format!(
                    "max of Hamiltonian value {} (peak {} Hz{}) and dense-grid value {} with \
                     the exact continuous W_m (order {})",
                    fmt_sig(h.gamma),
                    fmt_sig(h.peak_f_hz),
                    if lp.is_discrete() {
                        ", W_m Tustin-prewarped at crossover"
                    } else {
                        ""
                    },
                    fmt_sig(g),
                    w.order
                ),
                _ => UNSTABLE_NOTE.into(),
            },
        ));
    }
    let dbw = if stable {
        disturbance_rejection_bandwidth_hz(lp, fc).ok()
    } else {
        None
    };
    rs.push(Receipt::new(
        ReceiptKind::DisturbanceRejectionBandwidth,
        "first frequency where |S| rises through −3 dB",
        dbw.unwrap_or(0.0),
        Comparison::AtLeast,
        lim.disturbance_bandwidth_hz_min,
        "Hz",
        match dbw {
            Some(_) => "grid bracketing + bisection on |S(jω)| = 1/√2".into(),
            None => UNSTABLE_NOTE.into(),
        },
    ));
    rs.push(Receipt::new(
        ReceiptKind::PeakControlEffort,
        "‖KS‖∞ × reference amplitude: largest actuator command amplitude for a sinusoidal \
         reference (or noise) of that amplitude",
        val(&ks) * inp.reference_amplitude,
        Comparison::AtMost,
        inp.actuator_limit,
        inp.actuator_unit,
        match &ks {
            Some(h) => format!(
                "‖KS‖∞ = {} {}/output unit at {} Hz, reference amplitude {}",
                fmt_sig(h.gamma),
                inp.actuator_unit,
                fmt_sig(h.peak_f_hz),
                fmt_sig(inp.reference_amplitude)
            ),
            None => UNSTABLE_NOTE.into(),
        },
    ));
    Ok(ClosedLoopNorms {
        ms,
        mt,
        ks,
        wm_t,
        wm_t_grid,
    })
}

/// Detail of a peak receipt: the H∞ computation, or why there is no finite value.
const UNSTABLE_NOTE: &str = "closed loop unstable: norm infinite";

fn peak_detail(h: &Option<HinfNorm>) -> String {
    match h {
        Some(h) => format!(
            "Hamiltonian bisection (rel. tol {:e}), peak at {} Hz",
            h.rel_tol,
            fmt_sig(h.peak_f_hz)
        ),
        None => UNSTABLE_NOTE.into(),
    }
}

/// The saturated step on the sampled loop (a continuous design is sampled at 1/(200 f_c)):
/// the discrete controller simulated and the response (or why the simulation failed).
fn saturated_step_of(
    inp: &ReceiptInputs<'_>,
    lp: &FeedbackLoop,
    dpid: Option<DiscretePid>,
    domain: &str,
) -> Result<(DiscretePid, (Result<StepResponse>, String))> {
    let fc = inp.crossover_hz;
    let (gd, kd, sim_note) = match dpid {
        Some(d) => (lp.plant.clone(), d, domain.to_string()),
        None => {
            let ts = 1.0 / (200.0 * fc);
            // A discrete plant always yields a discrete controller above, so the plant here is
            // continuous.
            let gd = inp.plant.c2d_zoh(ts)?;
            let kd = inp.pid.discretize(ts, Some(fc))?;
            let note = format!(
                "continuous design simulated at ts = {ts} s (ZOH plant, Tustin controller)"
            );
            (gd, kd, note)
        }
    };
    let spec = StepSpec {
        amplitude: inp.reference_amplitude,
        actuator_limit: inp.actuator_limit,
        duration_s: (inp.limits.settling_time_s_max * 2.0).max(50.0 / fc),
        anti_windup: inp.anti_windup,
        settle_band: 0.02,
    };
    let step = saturated_step(&gd, &kd, &spec);
    Ok((kd, (step, sim_note)))
}

/// The step receipts (actuator demand, overshoot, settling time), failing when the
/// simulation failed.
pub(crate) fn push_step_receipts(
    rs: &mut Receipts,
    inp: &ReceiptInputs<'_>,
    (step, sim_note): &(Result<StepResponse>, String),
) {
    let lim = &inp.limits;
    let aw = if inp.anti_windup { "with" } else { "without" };
    match step {
        Ok(s) => {
            rs.push(Receipt::new(
                ReceiptKind::StepActuatorDemand,
                "largest controller demand / actuator limit during the saturated step (> 1: \
                 the command hits the rail)",
                s.peak_demand_ratio,
                Comparison::AtMost,
                1.0,
                "1",
                format!(
                    "step of {} to rail ±{} {}; {} samples at the rail; {aw} anti-windup; {sim_note}",
                    fmt_sig(s.amplitude),
                    fmt_sig(s.actuator_limit),
                    inp.actuator_unit,
                    s.samples_at_rail
                ),
            ));
            push_step_shape_receipts(
                rs,
                lim,
                s,
                [
                    "overshoot of the saturated closed-loop step",
                    "2 % settling time of the saturated closed-loop step",
                ],
                "",
                format!(
                    "simulated {} s; final error {}",
                    fmt_sig(s.t.last().copied().unwrap_or(0.0)),
                    fmt_sig(s.final_error)
                ),
            );
        }
        Err(e) => push_failed_step_receipts(
            rs,
            lim,
            [
                "saturated step: demand / rail",
                "saturated step overshoot",
                "saturated step settling time",
            ],
            e,
        ),
    }
}

/// The overshoot and settling-time receipts of a simulated step `s` (descriptions `what`):
/// the overshoot's note is `prefix` and the 10–90 % rise time, the settling time's
/// `settling_note`; a step that never settles reads as an infinite settling time.
pub(crate) fn push_step_shape_receipts(
    rs: &mut Receipts,
    lim: &ReceiptLimits,
    s: &StepResponse,
    what: [&str; 2],
    prefix: &str,
    settling_note: String,
) {
    rs.push(Receipt::new(
        ReceiptKind::StepOvershoot,
        what[0],
        s.overshoot_pct,
        Comparison::AtMost,
        lim.overshoot_pct_max,
        "%",
        format!("{prefix}rise time 10–90 %: {:?} s", s.rise_time_s),
    ));
    rs.push(Receipt::new(
        ReceiptKind::StepSettlingTime,
        what[1],
        s.settling_time_s.unwrap_or(f64::INFINITY),
        Comparison::AtMost,
        lim.settling_time_s_max,
        "s",
        settling_note,
    ));
}

/// The three step receipts (actuator demand, overshoot, settling time; descriptions `what`)
/// failing with the reason the simulation gave.
pub(crate) fn push_failed_step_receipts(
    rs: &mut Receipts,
    lim: &ReceiptLimits,
    what: [&str; 3],
    reason: &dyn std::fmt::Display,
) {
    let kinds = [
        (ReceiptKind::StepActuatorDemand, 1.0, "1"),
        (ReceiptKind::StepOvershoot, lim.overshoot_pct_max, "%"),
        (ReceiptKind::StepSettlingTime, lim.settling_time_s_max, "s"),
    ];
    for ((kind, limit, unit), what) in kinds.into_iter().zip(what) {
        rs.push(Receipt::new(
            kind,
            what,
            f64::INFINITY,
            Comparison::AtMost,
            limit,
            unit,
            format!("simulation failed: {reason}"),
        ));
    }
}
