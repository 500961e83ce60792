//! Grey-box identification: physical parameters (masses, inertias, stiffness, damping, motor
//! constants) with confidence intervals, from one input/output log.
//!
//! Path: (1) a black-box N4SID model of the structure's order; (2) start values mapped in
//! closed form from its poles and zeros ([`start`]); (3) an output-error fit of the physical
//! structure in log-parameters with the initial state projected out ([`output_error`]);
//! (4) intervals from the covariance of that fit (see [`output_error`]), in log space (so they are
//! asymmetric and never cross zero): value·exp(±z·σ_log), z the normal quantile of the
//! confidence level.
//!
//! Identifiability is a rule, not a hope: [`Structure::check_known`] states what one
//! input/output pair of each structure determines and refuses to fit without the parameters
//! that fix the rest (`--known NAME=VALUE`); after the fit, a condition number of J'J above
//! [`MAX_CONDITION`] is an error naming the combination the data does not determine — unless
//! that combination is one parameter alone, which is then reported
//! [`ParameterStatus::Undetermined`] (never with a number presented as an estimate).
//!
//! Assumptions (stated in every report): the structure is right (check the fit's NRMSE and the
//! residual test of `validate`), the input is known exactly (measurement noise on the output
//! only); constant input and output offsets are estimated with the initial state.
//! Intervals cover the truth at their stated rate under those assumptions (Monte-Carlo test in
//! `host/tests/greybox_coverage.rs`).
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
pub mod output_error;
pub mod start;
pub mod structure;

pub use structure::{Measured, ParameterSpec, Structure};

use crate::error::{Error, Result};
use crate::n4sid::{self, ChannelSet, N4sidOptions, OrderSelection};
use serde::Serialize;

/// Largest accepted condition number of J'J (free log-parameters): beyond it the data
/// determine a combination of parameters, not each parameter.
pub const MAX_CONDITION: f64 = 1e12;

/// What to fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GreyBoxOptions {
    /// The physical structure.
    pub structure: Structure,
    /// Parameters known from elsewhere (name, SI value), held fixed.
    pub known: Vec<(String, f64)>,
    /// Confidence level of the intervals, in (0, 1) (default 0.95).
    pub confidence: f64,
    /// Largest number of Levenberg–Marquardt iterations (1..=1000, default 200).
    pub max_iterations: usize,
}

impl GreyBoxOptions {
    /// Options for `structure` with nothing known, 95 % intervals, 200 iterations.
    pub fn new(structure: Structure) -> Self {
        GreyBoxOptions {
            structure,
            known: Vec::new(),
            confidence: 0.95,
            max_iterations: 200,
        }
    }

    /// Adds a known parameter.
    pub fn with_known(mut self, name: &str, value: f64) -> Self {
        self.known.push((name.to_string(), value));
        self
    }

    /// Checks the known parameters' names and values, the identifiability rule, the confidence
    /// level and the iteration limit, before any data are read.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] saying what is wrong (an unknown name lists the structure's
    /// parameters; a non-identifiable request names the parameters to give with `--known`).
    pub fn check(&self) -> Result<()> {
        self.known_vector().map(|_| ())
    }

    /// Known values per parameter of the structure, after checking names, values and the
    /// identifiability rule.
    fn known_vector(&self) -> Result<Vec<Option<f64>>> {
        let specs = self.structure.parameters();
        let mut known = vec![None; specs.len()];
        for (name, value) in &self.known {
            let i = self.structure.index_of(name).ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "--known {}: structure {} has no parameter of that name (it has {})",
                    crate::error::excerpt(name),
                    self.structure.name(),
                    specs.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
                ))
            })?;
            if !(value.is_finite() && *value > 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "--known {name}={value}: must be finite and > 0 {}",
                    specs[i].unit
                )));
            }
            if known[i].is_some() {
                return Err(Error::InvalidArgument(format!(
                    "--known {name} given twice"
                )));
            }
            known[i] = Some(*value);
        }
        let flags: Vec<bool> = known.iter().map(Option::is_some).collect();
        if flags.iter().all(|&k| k) {
            return Err(Error::InvalidArgument(format!(
                "structure {}: every parameter is known; nothing to estimate",
                self.structure.name()
            )));
        }
        self.structure.check_known(&flags)?;
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "confidence must be in (0, 1), got {}",
                self.confidence
            )));
        }
        if !(1..=1000).contains(&self.max_iterations) {
            return Err(Error::InvalidArgument(format!(
                "max_iterations must be in 1..=1000, got {}",
                self.max_iterations
            )));
        }
        Ok(known)
    }
}

/// One physical parameter of a fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PhysicalParameter {
    /// Name (`Jm`, `Kt`, ...).
    pub name: String,
    /// SI unit.
    pub unit: String,
    /// Meaning.
    pub description: String,
    /// Estimate; the given value when known; where the fit left it when undetermined.
    pub value: f64,
    /// Standard deviation (delta method: value·σ_log); `None` unless estimated.
    pub std_dev: Option<f64>,
    /// Confidence interval [low, high]; `None` unless estimated.
    pub interval: Option<[f64; 2]>,
    /// Estimated, known (given), or undetermined by the data.
    pub status: ParameterStatus,
}

/// How a [`PhysicalParameter`]'s value came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParameterStatus {
    /// Estimated from the data, with an interval.
    Estimated,
    /// Given (`--known`), held fixed.
    Known,
    /// The data do not determine it: alone it spans the weakest direction of J'J (its effect
    /// is below the noise in the excited band). Held where the fit left it; its value means
    /// nothing, the other parameters' intervals are conditional on it.
    Undetermined,
}

/// Result of [`fit`].
#[derive(Debug, Clone, Serialize)]
pub struct GreyBoxFit {
    /// The structure fitted.
    pub structure: Structure,
    /// Parameters in the structure's order.
    pub parameters: Vec<PhysicalParameter>,
    /// Confidence level of the intervals.
    pub confidence: f64,
    /// Start values mapped from the black-box model (SI, structure order).
    pub start: Vec<f64>,
    /// Simulation NRMSE of the fitted structure on the log (‖y − ŷ‖/‖y − ȳ‖).
    pub nrmse: f64,
    /// Simulation NRMSE of the black-box model of the same order (for comparison).
    pub black_box_nrmse: f64,
    /// Levenberg–Marquardt iterations.
    pub iterations: usize,
    /// Whether the fit converged (log-step < 1e-9, cost stalled, or no descent left).
    pub converged: bool,
    /// Condition number of J'J in log-parameters.
    pub condition: f64,
    /// How the intervals were computed, in words.
    pub interval_method: String,
}

impl GreyBoxFit {
    /// The parameter called `name`.
    pub fn parameter(&self, name: &str) -> Option<&PhysicalParameter> {
        self.parameters.iter().find(|p| p.name == name)
    }
}

/// Standard normal quantile for a two-sided interval of level `confidence` (Acklam's rational
/// approximation, relative error < 1.2e-9 — far below what a confidence level needs).
#[allow(clippy::excessive_precision)]
pub fn normal_quantile_two_sided(confidence: f64) -> f64 {
    let p = 0.5 + confidence / 2.0;
    // Acklam (2003), coefficients as published.
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383577518672690e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let plow = 0.02425;
    if p > 1.0 - plow {
        let q = (-2.0 * (1.0 - p).ln()).sqrt();
        -(((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Fits `opts.structure` to the SISO log `data` (input = the drive's command, output = the
/// sensor; see [`structure`] for units). The black-box start uses mean-removed data; the
/// output-error fit uses the log as recorded, with offsets estimated.
///
/// Errors: a multi-channel log, fewer than 20·(order + 1) samples, a known-parameter set that
/// breaks the identifiability rule, a black-box model whose poles/zeros do not fit the
/// structure (the message says which), a fit that does not determine every free parameter
/// (condition number above [`MAX_CONDITION`], naming the weakest combination).
pub fn fit(data: &ChannelSet<'_>, opts: &GreyBoxOptions) -> Result<GreyBoxFit> {
    let known = opts.known_vector()?;
    let structure = opts.structure;
    let n = check_siso(data, structure)?;
    let u = crate::validate::demeaned(data.u[0]);
    let y = crate::validate::demeaned(data.y[0]);
    let (ur, yr) = ([u.as_slice()], [y.as_slice()]);
    let centred = ChannelSet {
        u: &ur,
        y: &yr,
        ..*data
    };
    let bb = black_box_start(&centred, structure)?;
    let ts = data.ts;
    let f_lo = (5.0 / (n as f64 * ts)).min(0.01 / ts);
    let f_hi = 0.4 / ts;
    let grid: Vec<f64> = (0..200)
        .map(|k| f_lo * (f_hi / f_lo).powf(k as f64 / 199.0))
        .collect();
    let start = start::start_values(structure, &bb.model, &known, &grid)?;
    let (sol, undetermined) = fit_determined(data, opts, &known, &start)?;
    let parameters = parameter_table(structure, &sol, &known, &undetermined, opts.confidence);
    let energy: f64 = y.iter().map(|v| v * v).sum::<f64>().max(f64::MIN_POSITIVE);
    let bb_sim = bb.model.simulate_siso(&u, Some(&bb.x0))?;
    let bb_rss: f64 = bb_sim.iter().zip(&y).map(|(a, b)| (a - b) * (a - b)).sum();
    Ok(GreyBoxFit {
        structure,
        parameters,
        confidence: opts.confidence,
        start,
        nrmse: (sol.rss / energy).sqrt(),
        black_box_nrmse: (bb_rss / energy).sqrt(),
        iterations: sol.iterations,
        converged: sol.converged,
        condition: sol.condition,
        interval_method: format!(
            "output-error covariance in log-parameters ({}); assumes the structure is right and \
             the input noise-free",
            if sol.white_residual {
                "residual white (Ljung-Box, 1 %): classical sigma^2 (J'J)^-1"
            } else {
                "residual coloured (Ljung-Box, 1 %): Newey-West sandwich"
            }
        ),
    })
}

/// The log's length after checking it is SISO, of equal-length channels and long enough for
/// `structure`.
fn check_siso(data: &ChannelSet<'_>, structure: Structure) -> Result<usize> {
    if data.u.len() != 1 || data.y.len() != 1 {
        return Err(Error::InvalidArgument(format!(
            "{}: grey-box fit needs one input and one output, got {} and {}",
            data.source.display(),
            data.u.len(),
            data.y.len()
        )));
    }
    let n = data.y[0].len();
    let min_len = 20 * (structure.order() + 1);
    if n < min_len || data.u[0].len() != n {
        return Err(Error::Data {
            file: data.source.to_path_buf(),
            msg: format!(
                "grey-box fit needs >= {min_len} samples of equal-length u and y, got {n}"
            ),
        });
    }
    Ok(n)
}

/// The black-box N4SID model of the structure's order on the mean-removed log: where the
/// start values come from.
fn black_box_start(centred: &ChannelSet<'_>, structure: Structure) -> Result<n4sid::N4sidResult> {
    n4sid::identify(
        centred,
        &N4sidOptions {
            order: OrderSelection::Fixed(structure.order()),
            estimate_d: false,
            // Rigid-body axes put a pole at (or, from noise, just outside) z = 1; the start
            // needs the poles' places, not an exact integrator.
            stability_margin: Some(1e-6),
            ..N4sidOptions::default()
        },
    )
    .map_err(|e| Error::Numerical(format!("grey-box start: black-box N4SID failed: {e}")))
}

/// The output-error fit from `start`. A parameter the data leave undetermined on its own (it
/// alone spans the weakest direction of J'J, e.g. a viscous friction whose pole lies below the
/// excited band) is held where the fit left it and marked in the returned flags, and the rest
/// is re-fitted; an error names the weakest combination when no single parameter is to blame.
fn fit_determined(
    data: &ChannelSet<'_>,
    opts: &GreyBoxOptions,
    known: &[Option<f64>],
    start: &[f64],
) -> Result<(output_error::Solution, Vec<bool>)> {
    let structure = opts.structure;
    let ts = data.ts;
    let specs = structure.parameters();
    let mut fixed = known.to_vec();
    let mut undetermined = vec![false; specs.len()];
    let mut current = start.to_vec();
    loop {
        let problem = output_error::Problem {
            structure,
            u: data.u[0],
            y: data.y[0],
            ts,
            fixed: fixed.clone(),
        };
        let sol = problem.solve(&current, opts.max_iterations)?;
        let free: Vec<usize> = (0..fixed.len()).filter(|&i| fixed[i].is_none()).collect();
        let cov_defined = (0..free.len()).all(|i| sol.cov_log[(i, i)].is_finite());
        if sol.condition <= MAX_CONDITION && cov_defined {
            return Ok((sol, undetermined));
        }
        let dominant = sol
            .weakest
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .filter(|(_, w)| w.abs() > 0.95 && free.len() > 1);
        if let Some((k, _)) = dominant {
            let i = free[k];
            undetermined[i] = true;
            fixed[i] = Some(sol.params[i]);
            current = sol.params.clone();
            continue;
        }
        let combo: Vec<String> = free
            .iter()
            .zip(&sol.weakest)
            .filter(|(_, w)| w.abs() > 0.3)
            .map(|(&i, w)| format!("{}{}", if *w < 0.0 { "-" } else { "+" }, specs[i].name))
            .collect();
        return Err(Error::Numerical(format!(
            "{}: the data do not determine every parameter of {} (condition {:.1e} > {:.0e}); \
             the least determined combination of log-parameters is {}: give one of them with \
             --known or excite the band where they act",
            data.source.display(),
            structure.name(),
            sol.condition,
            MAX_CONDITION,
            combo.join(" ")
        )));
    }
}

/// Each parameter with its status and, when estimated, its standard deviation and interval at
/// `confidence` (log-normal: the covariance is in log-parameters).
fn parameter_table(
    structure: Structure,
    sol: &output_error::Solution,
    known: &[Option<f64>],
    undetermined: &[bool],
    confidence: f64,
) -> Vec<PhysicalParameter> {
    let specs = structure.parameters();
    let z = normal_quantile_two_sided(confidence);
    let mut parameters = Vec::with_capacity(specs.len());
    let mut fi = 0;
    for (i, s) in specs.iter().enumerate() {
        let value = sol.params[i];
        let status = if known[i].is_some() {
            ParameterStatus::Known
        } else if undetermined[i] {
            ParameterStatus::Undetermined
        } else {
            ParameterStatus::Estimated
        };
        let (std_dev, interval) = if status != ParameterStatus::Estimated {
            (None, None)
        } else {
            let sd = sol.cov_log[(fi, fi)].max(0.0).sqrt();
            fi += 1;
            (
                Some(value * sd),
                Some([value * (-z * sd).exp(), value * (z * sd).exp()]),
            )
        };
        parameters.push(PhysicalParameter {
            name: s.name.into(),
            unit: s.unit.into(),
            description: s.description.into(),
            value,
            std_dev,
            interval,
            status,
        });
    }
    parameters
}

/// [`fit`] on a SISO [`crate::data::Log`] (the pipeline's physical stage, the fleet, `identify
/// --structure`).
///
/// # Errors
/// As [`fit`]; [`Error::Data`] for a log that is not SISO.
pub fn fit_log(log: &crate::data::Log, opts: &GreyBoxOptions) -> Result<GreyBoxFit> {
    if log.inputs.len() != 1 || log.outputs.len() != 1 {
        return Err(Error::Data {
            file: log.path.clone(),
            msg: format!(
                "physical structure {} needs one input and one output, the log has {} and {}",
                opts.structure.name(),
                log.inputs.len(),
                log.outputs.len()
            ),
        });
    }
    let u = [log.inputs[0].data.as_slice()];
    let y = [log.outputs[0].data.as_slice()];
    let un = [log.inputs[0].name.clone()];
    let yn = [log.outputs[0].name.clone()];
    fit(
        &ChannelSet {
            source: &log.path,
            ts: log.ts,
            u: &u,
            y: &y,
            u_names: &un,
            y_names: &yn,
        },
        opts,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantiles() {
        for (c, z) in [
            (0.95, 1.959963984540054),
            (0.99, 2.5758293035489),
            (0.682689492, 1.0),
        ] {
            assert!((normal_quantile_two_sided(c) - z).abs() < 1e-5, "{c}");
        }
    }
}
