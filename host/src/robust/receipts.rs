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

mod compute;
mod curves;
mod phase;

pub use compute::{
    compute_receipts, disturbance_rejection_bandwidth_hz, ClosedLoopNorms, ReceiptInputs,
    ReceiptsReport,
};
pub(crate) use compute::{
    push_failed_step_receipts, push_margin_receipts, push_norm_receipts, push_step_receipts,
    push_step_shape_receipts,
};
pub use curves::{loop_curves, LoopCurves};
pub use phase::{etfe_phase_receipt, phase_agreement, EtfeView, PhaseAgreement, PhaseSlice};

use serde::{Deserialize, Serialize};

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
