//! The fleet summary: per-unit results ([`UnitResult`]), their distributions across units
//! ([`Distribution`]) and the units outside the spread of a physical parameter ([`Outlier`]).
//! Everything here is serialisable both ways, so shard summaries can be read back and merged
//! ([`super::shard`]) and a distributed engine can ship unit results between processes.
use super::{Layout, FLEET_SCHEMA};
use crate::greybox::ParameterStatus;
use crate::pipeline::document::{weight_high_gain, weight_low_gain};
use crate::pipeline::physical_stage::PhysicalOutcome;
use crate::pipeline::{Mode, PipelineRun};
use crate::robust::receipts::ReceiptKind;
use serde::{Deserialize, Serialize};

/// One unit's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnitResult {
    /// Serial number.
    pub serial: String,
    /// `pass`, `fail` (a receipt failed) or `error` (the pipeline could not run).
    pub status: String,
    /// The error, for `error`.
    pub error: Option<String>,
    /// Receipts passed.
    pub passed: usize,
    /// Receipts issued.
    pub receipts: usize,
    /// Names of failing receipts.
    pub failed: Vec<String>,
    /// Model order.
    pub order: Option<usize>,
    /// Static gain (output/input units).
    pub dc_gain: Option<f64>,
    /// Modes of the identified model.
    pub modes: Vec<Mode>,
    /// |W_m(0)|.
    pub wm_low_gain: Option<f64>,
    /// |W_m(∞)|.
    pub wm_high_gain: Option<f64>,
    /// Achieved design crossover, Hz.
    pub crossover_hz: Option<f64>,
    /// M_s of the implemented loop.
    pub ms: Option<f64>,
    /// Validation fit, %.
    pub validation_fit_percent: Option<f64>,
    /// Output directory of the unit (when outputs were written).
    pub out_dir: Option<String>,
    /// Physical parameters (with [`FleetOptions::physical`]).
    pub physical: Vec<UnitParameter>,
    /// Why the physical fit failed, when it did (the unit's pipeline result stands).
    pub physical_error: Option<String>,
}

/// One physical parameter of one unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnitParameter {
    /// Name (`Jm`, `k`, ...).
    pub name: String,
    /// SI unit.
    pub unit: String,
    /// Value.
    pub value: f64,
    /// 95 % interval (estimated parameters only).
    pub interval: Option<[f64; 2]>,
    /// Estimated, known or undetermined.
    pub status: ParameterStatus,
}

/// A unit outside the fleet's spread of one physical parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outlier {
    /// Serial number.
    pub serial: String,
    /// Parameter name.
    pub parameter: String,
    /// The unit's value.
    pub value: f64,
    /// Fleet median.
    pub median: f64,
    /// Modified z-score on log values.
    pub robust_z: f64,
}

/// Modified z-score beyond which a unit is outside the fleet's spread (Iglewicz & Hoaglin).
pub const OUTLIER_Z: f64 = 3.5;
/// Fewest units with an estimate of a parameter for its spread to be judged.
pub const MIN_UNITS_FOR_SPREAD: usize = 4;

/// The parameters of a pipeline's physical stage and why they are missing or doubtful (a
/// failed fit, or one that did not converge: its values are where it stopped).
fn physical_of(outcome: &PhysicalOutcome) -> (Vec<UnitParameter>, Option<String>) {
    match outcome {
        PhysicalOutcome::Skipped => (Vec::new(), None),
        PhysicalOutcome::Failed { error } => (Vec::new(), Some(error.clone())),
        PhysicalOutcome::Fitted(stage) => {
            let fit = &stage.fit;
            let params = fit
                .parameters
                .iter()
                .map(|p| UnitParameter {
                    name: p.name.clone(),
                    unit: p.unit.clone(),
                    value: p.value,
                    interval: p.interval,
                    status: p.status,
                })
                .collect();
            let note = (!fit.converged).then(|| {
                format!(
                    "grey-box fit did not converge in {} iterations (values where it stopped)",
                    fit.iterations
                )
            });
            (params, note)
        }
    }
}

impl UnitResult {
    /// The outcome of one unit's pipeline run: receipts, model, weight, controller and the
    /// run's `[physical]` outcome ([`PipelineRun::physical`]; nothing when it was skipped).
    pub fn from_run(serial: &str, run: &PipelineRun, out_dir: Option<String>) -> Self {
        let rs = &run.receipts;
        let passed = rs.receipts.iter().filter(|r| r.pass).count();
        let (physical, physical_error) = physical_of(&run.physical);
        Self {
            serial: serial.into(),
            status: if rs.all_pass { "pass" } else { "fail" }.into(),
            error: None,
            passed,
            receipts: rs.receipts.len(),
            failed: rs.failed().map(|r| r.name.clone()).collect(),
            order: Some(run.ident.order),
            dc_gain: Some(run.dc_gain),
            modes: run.modes.clone(),
            wm_low_gain: run.weight().map(|w| weight_low_gain(&w.num, &w.den)),
            wm_high_gain: run.weight().map(|w| weight_high_gain(&w.num, &w.den)),
            crossover_hz: run.tuned().map(|t| t.design.crossover_hz),
            ms: rs.of_kind(ReceiptKind::SensitivityPeak).map(|r| r.value),
            validation_fit_percent: run.validation_fit.as_ref().map(|f| f.fit_percent[0]),
            out_dir,
            physical,
            physical_error,
        }
    }

    /// A unit whose pipeline could not run, with the error's message.
    pub fn error(serial: &str, message: String) -> Self {
        Self {
            serial: serial.into(),
            status: "error".into(),
            error: Some(message),
            passed: 0,
            receipts: 0,
            failed: Vec::new(),
            order: None,
            dc_gain: None,
            modes: Vec::new(),
            wm_low_gain: None,
            wm_high_gain: None,
            crossover_hz: None,
            ms: None,
            validation_fit_percent: None,
            out_dir: None,
            physical: Vec::new(),
            physical_error: None,
        }
    }

    /// Oscillatory modes (complex pairs), increasing frequency.
    pub fn oscillatory(&self) -> Vec<Mode> {
        self.modes
            .iter()
            .filter(|m| m.oscillatory)
            .copied()
            .collect()
    }
}

/// Distribution of one parameter across units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Distribution {
    /// Parameter name.
    pub parameter: String,
    /// Unit of the parameter.
    pub unit: String,
    /// Units contributing.
    pub count: usize,
    /// Smallest value.
    pub min: f64,
    /// Median.
    pub median: f64,
    /// Largest value.
    pub max: f64,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (0 for one unit).
    pub std: f64,
}

impl Distribution {
    /// Statistics of `values` (non-finite values are ignored); None when none is finite.
    pub fn of(parameter: &str, unit: &str, values: &[f64]) -> Option<Self> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(|a, b| a.total_cmp(b));
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let var = if n > 1 {
            v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64
        } else {
            0.0
        };
        let median = if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        };
        Some(Self {
            parameter: parameter.into(),
            unit: unit.into(),
            count: n,
            min: v[0],
            median,
            max: v[n - 1],
            mean,
            std: var.sqrt(),
        })
    }
}

/// The fleet summary (`--json` output and `fleet.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FleetSummary {
    /// [`FLEET_SCHEMA`].
    pub schema: String,
    /// Directory layout found.
    pub layout: Layout,
    /// Units passing every receipt.
    pub units_pass: usize,
    /// Units with a failing receipt.
    pub units_fail: usize,
    /// Units whose pipeline could not run.
    pub units_error: usize,
    /// Per unit, in serial-number order.
    pub units: Vec<UnitResult>,
    /// Distributions across units.
    pub parameters: Vec<Distribution>,
    /// Distributions of the estimated physical parameters across units (SI units).
    pub physical: Vec<Distribution>,
    /// Units outside the fleet's spread, per physical parameter.
    pub outliers: Vec<Outlier>,
    /// Output signal unit (`[signals].output_unit` of the template).
    pub output_unit: String,
    /// Input signal unit (`[signals].input_unit` of the template).
    pub input_unit: String,
    /// Which part of the fleet this summary covers, when it is one shard of it
    /// (`ferrosid fleet --shard K/N`); absent for a whole fleet.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<super::shard::ShardInfo>,
}

/// Distributions of the physical parameters (estimated values only) and the units outside
/// each one's spread.
fn physical_spread(units: &[UnitResult]) -> (Vec<Distribution>, Vec<Outlier>) {
    let mut names: Vec<(String, String)> = Vec::new();
    for u in units {
        for p in &u.physical {
            if !names.iter().any(|(n, _)| n == &p.name) {
                names.push((p.name.clone(), p.unit.clone()));
            }
        }
    }
    let mut dists = Vec::new();
    let mut outliers = Vec::new();
    for (name, unit) in names {
        let vals: Vec<(&str, f64)> = units
            .iter()
            .filter_map(|u| {
                u.physical
                    .iter()
                    .find(|p| p.name == name && p.status == ParameterStatus::Estimated)
                    .filter(|p| p.value > 0.0 && p.value.is_finite())
                    .map(|p| (u.serial.as_str(), p.value))
            })
            .collect();
        let v: Vec<f64> = vals.iter().map(|x| x.1).collect();
        dists.extend(Distribution::of(&name, &unit, &v));
        if vals.len() < MIN_UNITS_FOR_SPREAD {
            continue;
        }
        let logs: Vec<f64> = v.iter().map(|x| x.ln()).collect();
        let med = median(&logs);
        let mad = median(&logs.iter().map(|x| (x - med).abs()).collect::<Vec<_>>());
        if mad.is_nan() || mad <= 0.0 {
            continue;
        }
        for ((serial, value), l) in vals.iter().zip(&logs) {
            let z = 0.6745 * (l - med) / mad;
            if z.abs() > OUTLIER_Z {
                outliers.push(Outlier {
                    serial: serial.to_string(),
                    parameter: name.clone(),
                    value: *value,
                    median: med.exp(),
                    robust_z: z,
                });
            }
        }
    }
    (dists, outliers)
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

impl FleetSummary {
    /// Summarises unit results.
    pub fn new(
        layout: Layout,
        units: Vec<UnitResult>,
        output_unit: &str,
        input_unit: &str,
    ) -> Self {
        let mut parameters = Vec::new();
        let ok: Vec<&UnitResult> = units.iter().filter(|u| u.status != "error").collect();
        let col = |f: &dyn Fn(&UnitResult) -> Option<f64>| -> Vec<f64> {
            ok.iter().filter_map(|u| f(u)).collect()
        };
        let gain_unit = format!("{output_unit}/{input_unit}");
        parameters.extend(Distribution::of(
            "dc_gain",
            &gain_unit,
            &col(&|u| u.dc_gain),
        ));
        let max_modes = ok.iter().map(|u| u.oscillatory().len()).max().unwrap_or(0);
        for k in 0..max_modes {
            let f = col(&|u| u.oscillatory().get(k).map(|m| m.natural_hz));
            let z = col(&|u| u.oscillatory().get(k).map(|m| m.damping));
            parameters.extend(Distribution::of(
                &format!("mode{}_natural_frequency", k + 1),
                "Hz",
                &f,
            ));
            parameters.extend(Distribution::of(&format!("mode{}_damping", k + 1), "1", &z));
        }
        parameters.extend(Distribution::of(
            "wm_low_frequency_gain",
            "1",
            &col(&|u| u.wm_low_gain),
        ));
        parameters.extend(Distribution::of(
            "wm_high_frequency_gain",
            "1",
            &col(&|u| u.wm_high_gain),
        ));
        parameters.extend(Distribution::of(
            "crossover",
            "Hz",
            &col(&|u| u.crossover_hz),
        ));
        parameters.extend(Distribution::of("sensitivity_peak", "1", &col(&|u| u.ms)));
        parameters.extend(Distribution::of(
            "validation_fit",
            "%",
            &col(&|u| u.validation_fit_percent),
        ));
        parameters.extend(Distribution::of(
            "receipts_passed",
            "count",
            &col(&|u| Some(u.passed as f64)),
        ));
        let (physical, outliers) = physical_spread(&units);
        Self {
            schema: FLEET_SCHEMA.into(),
            layout,
            output_unit: output_unit.into(),
            input_unit: input_unit.into(),
            shard: None,
            physical,
            outliers,
            units_pass: units.iter().filter(|u| u.status == "pass").count(),
            units_fail: units.iter().filter(|u| u.status == "fail").count(),
            units_error: units.iter().filter(|u| u.status == "error").count(),
            units,
            parameters,
        }
    }

    /// True when every unit passed every receipt.
    pub fn all_pass(&self) -> bool {
        self.units_fail == 0 && self.units_error == 0
    }
}
