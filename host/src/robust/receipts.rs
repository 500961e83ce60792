//! Receipts: every claim about a tuned loop as a number with its limit and a pass/fail, each
//! computed independently of the tuner (norms by Hamiltonian bisection, margins by bracketed
//! root finding, the step by simulation of the firmware control law).
//!
//! The receipts of [`compute_receipts`], by `name`:
//!
//! | name | value | unit | pass when |
//! |---|---|---|---|
//! | `closed_loop_stable` | max Re(pole) (continuous) or max \|pole\| (discrete) | rad/s or 1 | < 0 resp. < 1 |
//! | `gain_margin` | smallest \|GM\| over phase crossovers | dB | >= limit |
//! | `phase_margin` | smallest PM over gain crossovers | deg | >= limit |
//! | `sensitivity_peak` | M_s = ‖S‖∞ | 1 | <= limit |
//! | `complementary_sensitivity_peak` | M_t = ‖T‖∞ | 1 | <= limit |
//! | `robust_stability` | ‖W_m T‖∞ | 1 | < 1 |
//! | `disturbance_rejection_bandwidth` | first f where \|S\| rises through −3 dB | Hz | >= limit |
//! | `peak_control_effort` | ‖KS‖∞ · reference amplitude | actuator units | <= actuator limit |
//! | `step_actuator_demand` | max \|u demand\| / actuator limit | 1 | <= 1 (rail not hit) |
//! | `step_overshoot` | overshoot of the saturated step | % | <= limit |
//! | `step_settling_time` | 2 % settling time of the saturated step | s | <= limit |
//! | `etfe_phase_agreement` | max \|∠G0 − ∠ETFE\| over gated bins <= 2 f_c | deg | <= limit |
//! | `cross_validation_fit` | fit on fresh data (from validation) | % | >= limit |
//!
//! `peak_control_effort` definition: KS maps a reference (or measurement noise) sinusoid to the
//! actuator command, so ‖KS‖∞ times the largest reference amplitude is the largest steady-state
//! command amplitude a sinusoidal reference of that amplitude can demand at the worst
//! frequency. It is compared with the actuator limit (e.g. the current limit in A).
//!
//! JSON: values that are infinite (e.g. no phase crossover → infinite gain margin) serialise as
//! `null`; `value_text` always carries a readable rendering ("inf dB").
use super::loops::{analysis_grid, bisect_root, margins, FeedbackLoop, Margins};
use super::norms::{hinf_norm, HinfNorm};
use super::pid::{implemented_loop, weight_in_domain, DiscretePid, Pid};
use super::step::{saturated_step, StepResponse, StepSpec};
use super::uncertainty::UncertaintyWeight;
use crate::error::{Error, Result};
use crate::lti::{FreqEvaluator, StateSpace};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// How a receipt's value is compared with its limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Comparison {
    /// pass iff value <= limit
    AtMost,
    /// pass iff value >= limit
    AtLeast,
    /// pass iff value < limit
    LessThan,
    /// pass iff value > limit
    GreaterThan,
}

impl Comparison {
    /// The operator as text ("<=", ">=", "<", ">").
    pub fn symbol(self) -> &'static str {
        match self {
            Comparison::AtMost => "<=",
            Comparison::AtLeast => ">=",
            Comparison::LessThan => "<",
            Comparison::GreaterThan => ">",
        }
    }
    /// Evaluates the comparison; NaN never passes.
    pub fn holds(self, value: f64, limit: f64) -> bool {
        match self {
            Comparison::AtMost => value <= limit,
            Comparison::AtLeast => value >= limit,
            Comparison::LessThan => value < limit,
            Comparison::GreaterThan => value > limit,
        }
    }
}

/// The kind of a receipt: the one list of receipt identifiers. [`Receipt::name`] carries
/// [`ReceiptKind::name`] (the stable snake_case identifier in JSON, reports and headers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReceiptKind {
    /// `closed_loop_stable`: closed-loop stability (pole abscissa or modulus).
    ClosedLoopStable,
    /// `gain_margin`: gain margin.
    GainMargin,
    /// `phase_margin`: phase margin.
    PhaseMargin,
    /// `sensitivity_peak`: M_s = ‖S‖∞.
    SensitivityPeak,
    /// `complementary_sensitivity_peak`: M_t = ‖T‖∞.
    ComplementarySensitivityPeak,
    /// `robust_stability`: ‖W_m T‖∞ < 1.
    RobustStability,
    /// `disturbance_rejection_bandwidth`: first frequency where |S| rises through −3 dB.
    DisturbanceRejectionBandwidth,
    /// `peak_control_effort`: ‖KS‖∞ times the reference amplitude.
    PeakControlEffort,
    /// `step_actuator_demand`: saturated step: demand over the actuator rail.
    StepActuatorDemand,
    /// `step_overshoot`: saturated step overshoot.
    StepOvershoot,
    /// `step_settling_time`: saturated step 2 % settling time.
    StepSettlingTime,
    /// `etfe_phase_agreement`: largest phase error of G0 against the gated ETFE.
    EtfePhaseAgreement,
    /// `cross_validation_fit`: model fit on fresh (validation) data.
    CrossValidationFit,
    /// `controller_design`: achieved design crossover of the robust PID.
    ControllerDesign,
    /// `nonlinearity_audit`: dual-amplitude audit not possible (fewer than two runs).
    NonlinearityAudit,
    /// `audit_gain_shift`: largest gain shift between excitation amplitudes.
    AuditGainShift,
    /// `audit_phase_shift`: largest phase shift between excitation amplitudes.
    AuditPhaseShift,
    /// `audit_coherence`: lowest coherence of any run near crossover.
    AuditCoherence,
    /// `limit_cycle`: self-sustained oscillations with a diagnosed nonlinearity, predicted by
    /// describing function and found by simulation ([`crate::limit_cycle::receipt`]).
    LimitCycle,
}

impl ReceiptKind {
    /// Every kind, loop receipts first (the order of the module table), then the pipeline's
    /// model receipts.
    pub const ALL: [ReceiptKind; 19] = [
        ReceiptKind::ClosedLoopStable,
        ReceiptKind::GainMargin,
        ReceiptKind::PhaseMargin,
        ReceiptKind::SensitivityPeak,
        ReceiptKind::ComplementarySensitivityPeak,
        ReceiptKind::RobustStability,
        ReceiptKind::DisturbanceRejectionBandwidth,
        ReceiptKind::PeakControlEffort,
        ReceiptKind::StepActuatorDemand,
        ReceiptKind::StepOvershoot,
        ReceiptKind::StepSettlingTime,
        ReceiptKind::EtfePhaseAgreement,
        ReceiptKind::CrossValidationFit,
        ReceiptKind::ControllerDesign,
        ReceiptKind::NonlinearityAudit,
        ReceiptKind::AuditGainShift,
        ReceiptKind::AuditPhaseShift,
        ReceiptKind::AuditCoherence,
        ReceiptKind::LimitCycle,
    ];

    /// The stable identifier (snake_case).
    pub const fn name(self) -> &'static str {
        match self {
            ReceiptKind::ClosedLoopStable => "closed_loop_stable",
            ReceiptKind::GainMargin => "gain_margin",
            ReceiptKind::PhaseMargin => "phase_margin",
            ReceiptKind::SensitivityPeak => "sensitivity_peak",
            ReceiptKind::ComplementarySensitivityPeak => "complementary_sensitivity_peak",
            ReceiptKind::RobustStability => "robust_stability",
            ReceiptKind::DisturbanceRejectionBandwidth => "disturbance_rejection_bandwidth",
            ReceiptKind::PeakControlEffort => "peak_control_effort",
            ReceiptKind::StepActuatorDemand => "step_actuator_demand",
            ReceiptKind::StepOvershoot => "step_overshoot",
            ReceiptKind::StepSettlingTime => "step_settling_time",
            ReceiptKind::EtfePhaseAgreement => "etfe_phase_agreement",
            ReceiptKind::CrossValidationFit => "cross_validation_fit",
            ReceiptKind::ControllerDesign => "controller_design",
            ReceiptKind::NonlinearityAudit => "nonlinearity_audit",
            ReceiptKind::AuditGainShift => "audit_gain_shift",
            ReceiptKind::AuditPhaseShift => "audit_phase_shift",
            ReceiptKind::AuditCoherence => "audit_coherence",
            ReceiptKind::LimitCycle => "limit_cycle",
        }
    }

    /// The kind whose [`Self::name`] is `name`, if any.
    pub fn from_name(name: &str) -> Option<ReceiptKind> {
        ReceiptKind::ALL.into_iter().find(|k| k.name() == name)
    }
}

impl std::fmt::Display for ReceiptKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One verified claim: `value` compared with `limit` by `comparison`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Receipt {
    /// Stable identifier (snake_case, see the module table): [`ReceiptKind::name`] of
    /// [`Self::kind`]. Kept as text so receipts files of other versions still load.
    pub name: String,
    /// What is measured, in words.
    pub description: String,
    /// Measured value (JSON `null` when infinite or undefined; see `value_text`).
    pub value: f64,
    /// Readable value with unit ("8.3 dB", "inf dB").
    pub value_text: String,
    /// Limit the value is held to.
    pub limit: f64,
    /// Unit of `value` and `limit` ("dB", "deg", "Hz", "s", "%", "1", or the actuator unit).
    pub unit: String,
    /// The comparison applied.
    pub comparison: Comparison,
    /// Whether the receipt passes.
    pub pass: bool,
    /// How it was computed and where (frequency of a peak, grid cross-check, ...).
    pub detail: String,
}

impl Receipt {
    /// The kind of this receipt (`None` for a name this version does not know, e.g. from a
    /// newer receipts file).
    pub fn kind(&self) -> Option<ReceiptKind> {
        ReceiptKind::from_name(&self.name)
    }

    /// Builds a receipt of kind `kind` and evaluates `pass`.
    pub fn new(
        kind: ReceiptKind,
        description: &str,
        value: f64,
        comparison: Comparison,
        limit: f64,
        unit: &str,
        detail: String,
    ) -> Self {
        let value_text = if value.is_finite() {
            format!("{} {unit}", fmt_sig(value))
        } else if value.is_nan() {
            format!("undefined {unit}")
        } else if value > 0.0 {
            format!("inf {unit}")
        } else {
            format!("-inf {unit}")
        };
        Self {
            name: kind.name().into(),
            description: description.into(),
            value,
            value_text,
            limit,
            unit: unit.into(),
            comparison,
            pass: comparison.holds(value, limit),
            detail,
        }
    }
}

fn fmt_sig(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v.abs() >= 1e5 || v.abs() < 1e-3 {
        format!("{v:.4e}")
    } else {
        format!("{v:.4}")
    }
}

/// A set of receipts with its overall verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Receipts {
    /// Schema identifier of this structure.
    pub schema: String,
    /// True when every receipt passes.
    pub all_pass: bool,
    /// The receipts, in the order of the module table (absent inputs skip theirs).
    pub receipts: Vec<Receipt>,
}

impl Default for Receipts {
    fn default() -> Self {
        Self {
            schema: "ferrosid.receipts/1".into(),
            all_pass: true,
            receipts: Vec::new(),
        }
    }
}

impl Receipts {
    /// Appends a receipt and updates `all_pass`.
    pub fn push(&mut self, r: Receipt) {
        self.all_pass &= r.pass;
        self.receipts.push(r);
    }
    /// The receipt named `name`, if present (prefer [`Self::of_kind`]).
    pub fn get(&self, name: &str) -> Option<&Receipt> {
        self.receipts.iter().find(|r| r.name == name)
    }
    /// The receipt of kind `kind`, if present.
    pub fn of_kind(&self, kind: ReceiptKind) -> Option<&Receipt> {
        self.get(kind.name())
    }
    /// The failing receipts.
    pub fn failed(&self) -> impl Iterator<Item = &Receipt> {
        self.receipts.iter().filter(|r| !r.pass)
    }
}

/// Limits the receipts are held to.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ReceiptLimits {
    /// Minimum gain margin, dB (default 6).
    pub gain_margin_db_min: f64,
    /// Minimum phase margin, degrees (default 30).
    pub phase_margin_deg_min: f64,
    /// Maximum M_s (default 1.6).
    pub ms_max: f64,
    /// Maximum M_t (default 1.5).
    pub mt_max: f64,
    /// Minimum disturbance-rejection bandwidth, Hz (default 0.25 × crossover).
    pub disturbance_bandwidth_hz_min: f64,
    /// Maximum saturated-step overshoot, % (default 25).
    pub overshoot_pct_max: f64,
    /// Maximum saturated-step 2 % settling time, s (default 20 / crossover).
    pub settling_time_s_max: f64,
    /// Maximum |phase error| between G0 and the ETFE, degrees (default 5).
    pub etfe_phase_error_deg_max: f64,
    /// ETFE phase agreement checked up to this multiple of the crossover (default 2).
    pub etfe_max_freq_factor: f64,
}

impl ReceiptLimits {
    /// The defaults listed on each field, for a loop crossing over at `crossover_hz`.
    pub fn for_crossover(crossover_hz: f64) -> Self {
        Self {
            gain_margin_db_min: 6.0,
            phase_margin_deg_min: 30.0,
            ms_max: 1.6,
            mt_max: 1.5,
            disturbance_bandwidth_hz_min: 0.25 * crossover_hz,
            overshoot_pct_max: 25.0,
            settling_time_s_max: 20.0 / crossover_hz,
            etfe_phase_error_deg_max: 5.0,
            etfe_max_freq_factor: 2.0,
        }
    }
}

/// A measured frequency response to compare the model's phase with.
#[derive(Debug, Clone, Copy)]
pub struct EtfeView<'a> {
    /// Bin frequencies, Hz.
    pub freq_hz: &'a [f64],
    /// Measured response at each bin.
    pub h: &'a [Complex64],
    /// Coherence gate: true for bins to use (None: all bins).
    pub gate: Option<&'a [bool]>,
}

impl<'a> EtfeView<'a> {
    /// A view of a Welch H1 estimate with an optional coherence gate (e.g. `etfe.gate(0.8)`).
    pub fn from_etfe(etfe: &'a crate::spectral::Etfe, gate: Option<&'a [bool]>) -> Self {
        Self {
            freq_hz: &etfe.freq_hz,
            h: &etfe.h,
            gate,
        }
    }
}

/// A cross-validation result handed over from validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CrossValidation {
    /// Fit on fresh data, percent (100 = perfect, NRMSE-based as defined by validation).
    pub fit_percent: f64,
    /// Required minimum, percent.
    pub limit_percent: f64,
    /// Which data set / definition.
    pub detail: String,
}

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

/// Phase agreement of G0 with the ETFE over a slice of frequency.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseSlice {
    /// Slice start, Hz.
    pub f_lo_hz: f64,
    /// Slice end, Hz.
    pub f_hi_hz: f64,
    /// Gated bins in the slice.
    pub bins: usize,
    /// Largest |phase error| in the slice, degrees (0 without bins).
    pub max_abs_error_deg: f64,
}

/// Phase agreement of the model with the ETFE at gated bins below `f_max_hz`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseAgreement {
    /// Upper frequency checked, Hz.
    pub f_max_hz: f64,
    /// Gated bins used.
    pub bins_used: usize,
    /// Largest |∠G0 − ∠ETFE| (wrapped to (−180°, 180°]), degrees.
    pub max_abs_error_deg: f64,
    /// Where it occurs, Hz.
    pub at_hz: f64,
    /// Octave slices ending at `f_max_hz`, lowest first.
    pub slices: Vec<PhaseSlice>,
    /// (f_hz, signed error deg) for every bin used.
    pub per_bin: Vec<(f64, f64)>,
}

/// Phase of the model `plant` against a measured response at gated bins with f <= `f_max_hz`,
/// sliced into octaves. Errors: mismatched lengths or a model evaluation failure.
pub fn phase_agreement(
    plant: &StateSpace,
    etfe: &EtfeView<'_>,
    f_max_hz: f64,
) -> Result<PhaseAgreement> {
    let n = etfe.freq_hz.len();
    if etfe.h.len() != n || etfe.gate.is_some_and(|g| g.len() != n) {
        return Err(Error::InvalidArgument(format!(
            "ETFE: {} frequencies, {} responses, {} gate flags (must agree)",
            n,
            etfe.h.len(),
            etfe.gate.map_or(n, |g| g.len())
        )));
    }
    let ev = FreqEvaluator::new(plant);
    let mut per_bin = Vec::new();
    for i in 0..n {
        let f = etfe.freq_hz[i];
        if !(f > 0.0 && f <= f_max_hz && etfe.gate.is_none_or(|g| g[i])) {
            continue;
        }
        let h = etfe.h[i];
        if !(h.re.is_finite() && h.im.is_finite()) || h.norm() == 0.0 {
            continue;
        }
        let g = ev.at_rad_s(2.0 * PI * f)?[(0, 0)];
        per_bin.push((f, (g / h).arg().to_degrees()));
    }
    let (mut worst, mut at) = (0.0f64, f64::NAN);
    for &(f, e) in &per_bin {
        if e.abs() > worst || at.is_nan() {
            worst = worst.max(e.abs());
            at = f;
        }
    }
    let mut slices = Vec::new();
    if let Some(f_lo) = per_bin.first().map(|p| p.0) {
        let mut hi = f_max_hz;
        loop {
            let lo = hi / 2.0;
            let in_slice: Vec<f64> = per_bin
                .iter()
                .filter(|(f, _)| *f > lo && *f <= hi)
                .map(|p| p.1.abs())
                .collect();
            slices.push(PhaseSlice {
                f_lo_hz: lo,
                f_hi_hz: hi,
                bins: in_slice.len(),
                max_abs_error_deg: in_slice.iter().copied().fold(0.0, f64::max),
            });
            if lo <= f_lo {
                break;
            }
            hi = lo;
        }
        slices.reverse();
    }
    Ok(PhaseAgreement {
        f_max_hz,
        bins_used: per_bin.len(),
        max_abs_error_deg: worst,
        at_hz: at,
        slices,
        per_bin,
    })
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
fn push_margin_receipts(rs: &mut Receipts, m: Option<&Margins>, lim: &ReceiptLimits) {
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
fn push_norm_receipts(
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
            let grid = super::norms::logspace(wc * 1e-4, top, 20_000);
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
fn push_step_receipts(
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
            rs.push(Receipt::new(
                ReceiptKind::StepOvershoot,
                "overshoot of the saturated closed-loop step",
                s.overshoot_pct,
                Comparison::AtMost,
                lim.overshoot_pct_max,
                "%",
                format!("rise time 10–90 %: {:?} s", s.rise_time_s),
            ));
            rs.push(Receipt::new(
                ReceiptKind::StepSettlingTime,
                "2 % settling time of the saturated closed-loop step",
                s.settling_time_s.unwrap_or(f64::INFINITY),
                Comparison::AtMost,
                lim.settling_time_s_max,
                "s",
                format!(
                    "simulated {} s; final error {}",
                    fmt_sig(s.t.last().copied().unwrap_or(0.0)),
                    fmt_sig(s.final_error)
                ),
            ));
        }
        Err(e) => {
            for (n, d, l, u) in [
                (
                    ReceiptKind::StepActuatorDemand,
                    "saturated step: demand / rail",
                    1.0,
                    "1",
                ),
                (
                    ReceiptKind::StepOvershoot,
                    "saturated step overshoot",
                    lim.overshoot_pct_max,
                    "%",
                ),
                (
                    ReceiptKind::StepSettlingTime,
                    "saturated step settling time",
                    lim.settling_time_s_max,
                    "s",
                ),
            ] {
                rs.push(Receipt::new(
                    n,
                    d,
                    f64::INFINITY,
                    Comparison::AtMost,
                    l,
                    u,
                    format!("simulation failed: {e}"),
                ));
            }
        }
    }
}

/// The ETFE phase-agreement receipt of the plant model against the measured ETFE.
fn push_etfe_receipt(
    rs: &mut Receipts,
    plant: &StateSpace,
    e: &EtfeView<'_>,
    lim: &ReceiptLimits,
    fc: f64,
) -> Result<PhaseAgreement> {
    let p = phase_agreement(plant, e, lim.etfe_max_freq_factor * fc)?;
    rs.push(etfe_phase_receipt(
        &p,
        lim.etfe_phase_error_deg_max,
        if p.bins_used == 0 {
            format!("no gated ETFE bin below {} Hz", fmt_sig(p.f_max_hz))
        } else {
            format!(
                "{} gated bins up to {} Hz; worst at {} Hz; octave slices: {}",
                p.bins_used,
                fmt_sig(p.f_max_hz),
                fmt_sig(p.at_hz),
                p.slices
                    .iter()
                    .map(|s| format!(
                        "{}–{} Hz: {} deg ({} bins)",
                        fmt_sig(s.f_lo_hz),
                        fmt_sig(s.f_hi_hz),
                        fmt_sig(s.max_abs_error_deg),
                        s.bins
                    ))
                    .collect::<Vec<_>>()
                    .join("; ")
            )
        },
    ));
    Ok(p)
}

/// The `cross_validation_fit` receipt of a fit on fresh data.
pub fn cross_validation_receipt(cv: &CrossValidation) -> Receipt {
    Receipt::new(
        ReceiptKind::CrossValidationFit,
        CROSS_VALIDATION_DESCRIPTION,
        cv.fit_percent,
        Comparison::AtLeast,
        cv.limit_percent,
        "%",
        cv.detail.clone(),
    )
}

/// The failing `cross_validation_fit` receipt when no validation log was given
/// (`limit_percent`: the fit the model would have had to reach, %).
pub fn missing_cross_validation_receipt(limit_percent: f64) -> Receipt {
    Receipt::new(
        ReceiptKind::CrossValidationFit,
        CROSS_VALIDATION_DESCRIPTION,
        f64::NAN,
        Comparison::AtLeast,
        limit_percent,
        "%",
        "no `[validation]` log given: the model was not checked on fresh data".into(),
    )
}

const CROSS_VALIDATION_DESCRIPTION: &str = "model fit on fresh (validation) data";

/// The `etfe_phase_agreement` receipt of a phase comparison (undefined, hence failing, when no
/// gated bin was compared); `limit_deg` the largest accepted |phase error|, degrees.
pub fn etfe_phase_receipt(p: &PhaseAgreement, limit_deg: f64, detail: String) -> Receipt {
    Receipt::new(
        ReceiptKind::EtfePhaseAgreement,
        "largest |phase(G0) − phase(ETFE)| at coherence-gated bins up to the stated multiple \
         of crossover",
        if p.bins_used == 0 {
            f64::NAN
        } else {
            p.max_abs_error_deg
        },
        Comparison::AtMost,
        limit_deg,
        "deg",
        detail,
    )
}

/// Magnitudes of the loop transfers on a frequency list, for plots (|S|, |T|, |KS|, 1/|W_m|).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoopCurves {
    /// Frequencies, Hz.
    pub freq_hz: Vec<f64>,
    /// |L|.
    pub l_mag: Vec<f64>,
    /// ∠L, degrees (wrapped).
    pub l_phase_deg: Vec<f64>,
    /// |S|.
    pub s_mag: Vec<f64>,
    /// |T|.
    pub t_mag: Vec<f64>,
    /// |KS|.
    pub ks_mag: Vec<f64>,
    /// 1/|W_m(j2πf)| (continuous weight), when a weight is given.
    pub inv_wm_mag: Option<Vec<f64>>,
}

/// Evaluates [`LoopCurves`] at `freq_hz` (Hz, below Nyquist for discrete loops).
pub fn loop_curves(
    lp: &FeedbackLoop,
    weight: Option<&UncertaintyWeight>,
    freq_hz: &[f64],
) -> Result<LoopCurves> {
    let (el, es, et, ek) = (
        FreqEvaluator::new(&lp.l),
        FreqEvaluator::new(&lp.s),
        FreqEvaluator::new(&lp.t),
        FreqEvaluator::new(&lp.ks),
    );
    let mut c = LoopCurves {
        freq_hz: freq_hz.to_vec(),
        l_mag: Vec::new(),
        l_phase_deg: Vec::new(),
        s_mag: Vec::new(),
        t_mag: Vec::new(),
        ks_mag: Vec::new(),
        inv_wm_mag: weight.map(|_| Vec::new()),
    };
    for &f in freq_hz {
        let w = 2.0 * PI * f;
        let l = el.at_rad_s(w)?[(0, 0)];
        c.l_mag.push(l.norm());
        c.l_phase_deg.push(l.arg().to_degrees());
        c.s_mag.push(es.at_rad_s(w)?[(0, 0)].norm());
        c.t_mag.push(et.at_rad_s(w)?[(0, 0)].norm());
        c.ks_mag.push(ek.at_rad_s(w)?[(0, 0)].norm());
        if let (Some(v), Some(wm)) = (c.inv_wm_mag.as_mut(), weight) {
            v.push(1.0 / wm.freq_response(w).norm());
        }
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn receipt_kinds_have_one_name_each_matching_serde() {
        let mut names: Vec<&str> = ReceiptKind::ALL.iter().map(|k| k.name()).collect();
        for k in ReceiptKind::ALL {
            assert_eq!(ReceiptKind::from_name(k.name()), Some(k));
            let json = serde_json::to_string(&k).unwrap();
            assert_eq!(json, format!("\"{}\"", k.name()));
        }
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), ReceiptKind::ALL.len());
        assert_eq!(ReceiptKind::from_name("no_such_receipt"), None);
    }

    #[test]
    fn receipts_are_found_by_kind_and_keep_the_name_as_text() {
        let mut rs = Receipts::default();
        let cv = CrossValidation {
            fit_percent: 91.0,
            limit_percent: 80.0,
            detail: String::new(),
        };
        rs.push(cross_validation_receipt(&cv));
        rs.push(missing_cross_validation_receipt(80.0));
        let r = rs.of_kind(ReceiptKind::CrossValidationFit).unwrap();
        assert_eq!(r.name, "cross_validation_fit");
        assert_eq!(r.kind(), Some(ReceiptKind::CrossValidationFit));
        assert!(r.pass);
        // The receipt without validation data is undefined, hence failing.
        assert!(!rs.all_pass);
        assert!(rs.of_kind(ReceiptKind::GainMargin).is_none());
    }
}
