//! The `limit_cycle` receipt: describing-function prediction and nonlinear simulation of the
//! tuned loop with one diagnosed nonlinearity, with or without its compensation.
//!
//! [`analyse`] runs both: [`predict`](super::predict()) (for a compensated loop on the residual
//! nonlinearity, [`crate::compensation::Residual`]) and [`simulate`](super::simulate()) from a
//! start-up kick, then [`detect`](super::detect()) on the nonlinearity's input. [`receipt`]
//! turns the result into a [`Receipt`] of kind [`ReceiptKind::LimitCycle`]:
//!
//! | value | unit | pass when |
//! |---|---|---|
//! | stable cycles predicted + cycles found in simulation | 1 | = 0 (<= 0) |
//!
//! Unstable predicted cycles (they separate decaying from growing oscillations and are not
//! observed as such) are listed in the detail but not counted; a simulation that diverges
//! counts as a cycle (the loop does not settle). The detail records every predicted and the
//! simulated frequency (Hz) and amplitude (at the nonlinearity's input).
use super::describing::DescribingFunction;
use super::detect::{detect, DetectOptions, SimulatedLimitCycle};
use super::lure::{LureLoop, Nonlinearity, Site};
use super::predict::{predict_with, PredictOptions, PredictedLimitCycle};
use super::simulate::{simulate, SimSpec};
use crate::compensation::Residual;
use crate::error::{Error, Result};
use crate::robust::receipts::{Comparison, Receipt, ReceiptKind};
use ferrosid_codegen::Compensation;
use serde::{Deserialize, Serialize};

/// Settings of [`analyse`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AnalysisOptions {
    /// Describing-function scan.
    pub predict: PredictOptions,
    /// Oscillation detector.
    pub detect: DetectOptions,
    /// Simulated time, s (`None`: at least 20,000 samples and 60 periods of the slowest
    /// predicted cycle, at most 400,000 samples).
    pub duration_s: Option<f64>,
    /// Start-up kick at the plant input, input units (`None`: 4 × the nonlinearity's scale for
    /// drive and velocity sites, 10 quantization steps (or limits) over |G| at a tenth of the
    /// Nyquist frequency for the sensor site).
    pub kick: Option<f64>,
    /// Friction sub-steps per sample (default 16).
    pub substeps: usize,
    /// Constant reference, output units (default 0).
    pub reference: f64,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        Self {
            predict: PredictOptions::default(),
            detect: DetectOptions::default(),
            duration_s: None,
            kick: None,
            substeps: 16,
            reference: 0.0,
        }
    }
}

/// Prediction and simulation of one nonlinearity in the loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LimitCycleAnalysis {
    /// The nonlinearity analysed.
    pub nonlinearity: Nonlinearity,
    /// Whether a compensation was active.
    pub compensated: bool,
    /// Every describing-function solution, by frequency.
    pub predicted: Vec<PredictedLimitCycle>,
    /// The oscillation found in the simulation's tail, if any.
    pub simulated: Option<SimulatedLimitCycle>,
    /// Set when the simulation diverged (the message).
    pub diverged: Option<String>,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Start-up kick used, input units.
    pub kick: f64,
}

impl LimitCycleAnalysis {
    /// Predicted cycles that are stable.
    pub fn stable_predicted(&self) -> impl Iterator<Item = &PredictedLimitCycle> {
        self.predicted.iter().filter(|p| p.stable)
    }

    /// True when neither the prediction (stable cycles) nor the simulation finds a cycle.
    pub fn passes(&self) -> bool {
        self.stable_predicted().next().is_none()
            && self.simulated.is_none()
            && self.diverged.is_none()
    }
}

/// Predicts and simulates `nl` in `lp`, with `comp` when given and enabled (module docs).
/// Errors for invalid parameters, options or compensation (the crate's error enum).
pub fn analyse(
    lp: &LureLoop,
    nl: &Nonlinearity,
    comp: Option<&Compensation>,
    opts: &AnalysisOptions,
) -> Result<LimitCycleAnalysis> {
    nl.df.validate()?;
    let residual = Residual::new(nl, comp);
    let (h_a, tol) = if residual.is_numeric() {
        (1e-3, 1e-6)
    } else {
        (1e-6, 1e-11)
    };
    let predicted = predict_with(lp, nl, &|a| residual.eval(a), h_a, tol, &opts.predict)?;
    let ts = lp.ts;
    let duration_s = match opts.duration_s {
        Some(d) => d,
        None => {
            let slowest = predicted
                .iter()
                .map(|p| p.freq_hz)
                .fold(f64::INFINITY, f64::min);
            let periods = if slowest.is_finite() && slowest > 0.0 {
                60.0 / (slowest * ts)
            } else {
                0.0
            };
            periods.clamp(20_000.0, 400_000.0).round() * ts
        }
    };
    let kick = match opts.kick {
        Some(k) => k,
        None => match nl.site {
            Site::Drive | Site::Velocity => 4.0 * nl.df.scale(),
            Site::Sensor => {
                let g = lp
                    .plant_response(0.1 * lp.nyquist_rad_s())
                    .map(|g| g.norm())
                    .unwrap_or(1.0);
                let step = match nl.df {
                    DescribingFunction::Quantization { step } => step,
                    _ => nl.df.scale(),
                };
                10.0 * step / g.max(1e-300)
            }
        },
    };
    if !kick.is_finite() {
        return Err(Error::InvalidArgument(format!(
            "limit-cycle analysis: start-up kick {kick} is not finite"
        )));
    }
    let spec = SimSpec {
        duration_s,
        reference: opts.reference,
        kick,
        kick_samples: 5,
        substeps: opts.substeps,
    };
    let (simulated, diverged) = match simulate(lp, nl, comp, &spec) {
        Ok(run) => (detect(&run.nl_input, ts, &opts.detect), None),
        Err(Error::Numerical(m)) => (None, Some(m)),
        Err(e) => return Err(e),
    };
    Ok(LimitCycleAnalysis {
        nonlinearity: *nl,
        compensated: comp.is_some_and(|c| c.enabled),
        predicted,
        simulated,
        diverged,
        duration_s,
        kick,
    })
}

fn sig(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e4 || v.abs() < 1e-3) {
        format!("{v:.3e}")
    } else {
        format!("{v:.4}")
    }
}

/// The `limit_cycle` receipt of an analysis (module table); `label` names the effect and place
/// in the description (e.g. "coulomb_friction at motor").
pub fn receipt(analysis: &LimitCycleAnalysis, label: &str) -> Receipt {
    let a = analysis;
    let unit = match a.nonlinearity.site {
        Site::Drive => "command (input units)",
        Site::Velocity => "velocity",
        Site::Sensor => "output units",
    };
    let mut parts = Vec::new();
    if a.predicted.is_empty() {
        parts.push("describing function: no intersection of -1/N(A) with L".to_string());
    }
    for p in &a.predicted {
        parts.push(format!(
            "describing function: {} cycle at {} Hz, amplitude {} ({unit}){}",
            if p.stable { "stable" } else { "unstable (not counted)" },
            sig(p.freq_hz),
            sig(p.amplitude),
            if p.refined { "" } else { ", grid estimate" }
        ));
    }
    match (&a.simulated, &a.diverged) {
        (Some(s), _) => parts.push(format!(
            "simulation: cycle at {} Hz, amplitude {} (first harmonic; half peak-to-peak {}) \
             ({unit})",
            sig(s.freq_hz),
            sig(s.amplitude),
            sig(s.half_peak_to_peak)
        )),
        (None, Some(m)) => parts.push(format!("simulation diverged: {m}")),
        (None, None) => parts.push(format!(
            "simulation: no sustained oscillation in the steady-state tail of {} s after a kick \
             of {} input units",
            sig(a.duration_s),
            sig(a.kick)
        )),
    }
    parts.push(if a.compensated {
        "with compensation".into()
    } else {
        "without compensation".into()
    });
    let count = a.stable_predicted().count()
        + usize::from(a.simulated.is_some() || a.diverged.is_some());
    Receipt::new(
        ReceiptKind::LimitCycle,
        &format!(
            "self-sustained oscillation with {label} ({}): describing function and simulation",
            a.nonlinearity.df.name()
        ),
        count as f64,
        Comparison::AtMost,
        0.0,
        "1",
        parts.join("; "),
    )
}
