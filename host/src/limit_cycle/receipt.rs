//! The `limit_cycle` receipt: describing-function prediction and nonlinear simulation of the
//! tuned loop with one diagnosed nonlinearity, with or without its compensation.
//!
//! [`analyse`] runs both: [`predict`](super::predict()) (for a compensated loop on the residual
//! nonlinearity, [`crate::limit_cycle::Residual`]) and [`simulate`](super::simulate()) from a
//! start-up kick, then [`detect`](super::detect()) on the nonlinearity's input. [`receipt`]
//! turns the result into a [`Receipt`] of kind [`ReceiptKind::LimitCycle`]:
//!
//! | value | unit | pass when |
//! |---|---|---|
//! | stable cycles predicted + cycles found in simulation, larger than the tolerance | 1 | = 0 (<= 0) |
//!
//! A cycle counts when its amplitude at the plant output exceeds `amplitude_tol` (output units;
//! default 0, every cycle counts — a pipeline sets it to what the sensor cannot resolve, e.g.
//! its noise): predicted cycles by their output amplitude
//! ([`PredictedLimitCycle::output_amplitude`]), a simulated one by the half peak-to-peak of
//! the output over the tail. Unstable predicted cycles (they separate decaying from growing
//! oscillations and are not observed as such) are listed in the detail but not counted; a
//! simulation that diverges counts as a cycle. The detail records every predicted and the
//! simulated frequency (Hz) and amplitude (at the nonlinearity's input and at the output).
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::describing::DescribingFunction;
use super::detect::{detect, DetectOptions, SimulatedLimitCycle};
use super::lure::{LureLoop, Nonlinearity, Site};
use super::predict::{predict_with, PredictOptions, PredictedLimitCycle};
use super::simulate::{simulate, SimSpec};
use crate::error::{Error, Result};
use crate::limit_cycle::Residual;
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
    /// Largest acceptable oscillation amplitude at the plant output, output units (>= 0,
    /// default 0: every cycle counts).
    pub amplitude_tol: f64,
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
            amplitude_tol: 0.0,
        }
    }
}

/// Prediction and simulation of one nonlinearity in the loop.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LimitCycleAnalysis {
    /// The nonlinearity analysed.
    pub nonlinearity: Nonlinearity,
    /// Whether a compensation was active.
    pub compensated: bool,
    /// Every describing-function solution, by frequency.
    pub predicted: Vec<PredictedLimitCycle>,
    /// The oscillation found in the simulation's tail at the nonlinearity's input, if any.
    pub simulated: Option<SimulatedLimitCycle>,
    /// The oscillation found in the simulation's tail at the plant output, if any.
    pub simulated_output: Option<SimulatedLimitCycle>,
    /// Half the peak-to-peak of the plant output over the simulation's tail, output units.
    pub output_tail_half_ptp: f64,
    /// The tolerance applied, output units.
    pub amplitude_tol: f64,
    /// Set when the simulation diverged (the message).
    pub diverged: Option<String>,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Start-up kick used, input units.
    pub kick: f64,
    /// The plant output over the last [`TRACE_SAMPLES`] samples of the simulation (output
    /// units, one per controller sample; empty when it diverged), for the report's figure.
    #[serde(skip)]
    pub output_trace: Vec<f64>,
}

/// Samples of the simulated output kept in [`LimitCycleAnalysis::output_trace`].
pub const TRACE_SAMPLES: usize = 2000;

impl LimitCycleAnalysis {
    /// Predicted cycles that count: stable, with an output amplitude above the tolerance.
    pub fn counted_predicted(&self) -> impl Iterator<Item = &PredictedLimitCycle> {
        let tol = self.amplitude_tol;
        self.predicted
            .iter()
            .filter(move |p| p.stable && !(p.output_amplitude <= tol))
    }

    /// Whether the simulation counts as a cycle: it diverged, or an oscillation was detected
    /// and the output's half peak-to-peak over the tail exceeds the tolerance.
    pub fn simulated_counts(&self) -> bool {
        self.diverged.is_some()
            || ((self.simulated.is_some() || self.simulated_output.is_some())
                && !(self.output_tail_half_ptp <= self.amplitude_tol))
    }

    /// Cycles counted by the receipt.
    pub fn count(&self) -> usize {
        self.counted_predicted().count() + usize::from(self.simulated_counts())
    }

    /// True when neither the prediction nor the simulation finds a cycle that counts.
    pub fn passes(&self) -> bool {
        self.count() == 0
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
    if !(opts.amplitude_tol.is_finite() && opts.amplitude_tol >= 0.0) {
        return Err(Error::InvalidArgument(format!(
            "limit-cycle analysis: amplitude_tol = {} must be finite and >= 0",
            opts.amplitude_tol
        )));
    }
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
    let mut output_trace = Vec::new();
    let (simulated, simulated_output, output_tail_half_ptp, diverged) =
        match simulate(lp, nl, comp, &spec) {
            Ok(run) => {
                let nt =
                    ((run.y.len() as f64) * opts.detect.tail_fraction.clamp(0.05, 1.0)) as usize;
                let tail = &run.y[run.y.len() - nt.min(run.y.len())..];
                let (lo, hi) = tail
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
                output_trace = run.y[run.y.len().saturating_sub(TRACE_SAMPLES)..].to_vec();
                (
                    detect(&run.nl_input, ts, &opts.detect),
                    detect(&run.y, ts, &opts.detect),
                    if tail.is_empty() {
                        0.0
                    } else {
                        0.5 * (hi - lo)
                    },
                    None,
                )
            }
            Err(Error::Numerical(m)) => (None, None, f64::INFINITY, Some(m)),
            Err(e) => return Err(e),
        };
    Ok(LimitCycleAnalysis {
        nonlinearity: *nl,
        compensated: comp.is_some_and(|c| c.enabled),
        predicted,
        simulated,
        simulated_output,
        output_tail_half_ptp,
        amplitude_tol: opts.amplitude_tol,
        diverged,
        duration_s,
        kick,
        output_trace,
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
            "describing function: {} cycle at {} Hz, amplitude {} ({unit}), {} at the output{}",
            if p.stable {
                "stable"
            } else {
                "unstable (not counted)"
            },
            sig(p.freq_hz),
            sig(p.amplitude),
            sig(p.output_amplitude),
            if p.refined { "" } else { ", grid estimate" }
        ));
    }
    match (
        a.simulated.as_ref().or(a.simulated_output.as_ref()),
        &a.diverged,
    ) {
        (_, Some(m)) => parts.push(format!("simulation diverged: {m}")),
        (Some(s), None) => parts.push(format!(
            "simulation: cycle at {} Hz, amplitude {} ({}, first harmonic; half peak-to-peak \
             {}), output half peak-to-peak {}",
            sig(s.freq_hz),
            sig(s.amplitude),
            if a.simulated.is_some() {
                unit
            } else {
                "output units"
            },
            sig(s.half_peak_to_peak),
            sig(a.output_tail_half_ptp)
        )),
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
    if a.amplitude_tol > 0.0 {
        parts.push(format!(
            "cycles with an output amplitude <= {} not counted",
            sig(a.amplitude_tol)
        ));
    }
    let count = a.count();
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
