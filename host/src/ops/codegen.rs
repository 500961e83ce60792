//! `codegen` as a library call: the generator input ([`ferrosid_codegen::CodegenInput`]) from
//! typed parts in memory — a model with its operating point, a controller, an uncertainty
//! weight, receipts and source digests — plus the power-up self-identification settings.
//! `ferrosid codegen` reads the parts from JSON files;
//! [`crate::pipeline::PipelineRun::codegen_parts`] takes them from a run, without the disk.
use crate::data::OperatingPoint;
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use crate::robust::pid::{DiscretePid, Pid};
use crate::robust::receipts::{Comparison, Receipt};
use crate::robust::uncertainty::UncertaintyWeight;
use ferrosid_codegen as cg;
use std::path::{Path, PathBuf};

/// A controller to generate gains for.
#[derive(Debug, Clone, PartialEq)]
pub enum ControllerSource {
    /// A continuous PID, Tustin-discretised at the model rate, prewarped at `prewarp_hz`
    /// (plain Tustin without it).
    Continuous {
        /// The controller.
        pid: Pid,
        /// Tustin prewarp frequency, Hz.
        prewarp_hz: Option<f64>,
    },
    /// A discrete PID, used as is.
    Discrete(DiscretePid),
    /// A tuning result: its discrete controller when it has one, else the continuous one
    /// discretised at the model rate, prewarped at the design crossover (or `prewarp_hz`).
    Tuned {
        /// The continuous controller.
        pid: Pid,
        /// The discrete controller of the tuning, if any.
        discrete: Option<DiscretePid>,
        /// Design crossover, Hz.
        crossover_hz: Option<f64>,
        /// Prewarp frequency when the design gives none, Hz.
        prewarp_hz: Option<f64>,
    },
}

/// What a header is generated from, already in memory.
#[derive(Debug, Clone)]
pub struct CodegenParts {
    /// The plant model (discrete at the control rate, or continuous).
    pub model: StateSpace,
    /// Where the model came from (a file or a pipeline), named in data errors.
    pub model_origin: PathBuf,
    /// The operating point the model was identified at (None: raw signals).
    pub operating_point: Option<OperatingPoint>,
    /// The controller, if any.
    pub controller: Option<ControllerSource>,
    /// The uncertainty weight W_m of the power-up check.
    pub weight: cg::WeightCoefficients,
    /// Receipt summary lines for the provenance block.
    pub receipts: Vec<cg::ReceiptLine>,
    /// Content hashes of every source.
    pub sources: Vec<cg::SourceDigest>,
    /// The compensation block (from `compensation::design`), if any.
    pub compensation: Option<cg::Compensation>,
    /// A state-space controller chosen instead of the PID (`[control] method`), if any.
    pub state_controller: Option<cg::StateController>,
}

/// `kind` of a [`CompensationFile`].
pub const COMPENSATION_FILE_KIND: &str = "ferrosid.compensation/1";

/// `compensation.json`, written by `ferrosid run` after the compensation stage and read by
/// `ferrosid codegen --compensation`: the stage's choice, its reason and the compensation block,
/// enabled only when the choice was `compensate`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompensationFile {
    /// Always [`COMPENSATION_FILE_KIND`].
    pub kind: String,
    /// `compensate`, `widen_wm` or `keep`.
    pub choice: String,
    /// Why, in words.
    pub reason: String,
    /// The block for the generated code.
    pub compensation: cg::Compensation,
}

impl CompensationFile {
    /// Checks the kind, the choice, the block's fields and that the block is enabled only for
    /// `compensate`; the message names the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::InvalidArgument(m));
        if self.kind != COMPENSATION_FILE_KIND {
            return bad(format!(
                "`kind` is {:?}, expected {COMPENSATION_FILE_KIND:?}",
                self.kind
            ));
        }
        if !["compensate", "widen_wm", "keep"].contains(&self.choice.as_str()) {
            return bad(format!(
                "`choice` is {:?}, expected compensate, widen_wm or keep",
                self.choice
            ));
        }
        if self.compensation.enabled && self.choice != "compensate" {
            return bad(format!(
                "`compensation.enabled` is true but the choice was {:?}",
                self.choice
            ));
        }
        self.compensation
            .validate()
            .map_err(|e| Error::InvalidArgument(format!("`compensation`: {e}")))
    }
}

/// Identifier prefix and power-up self-identification settings (see `ferrosid codegen
/// --help` for each).
#[derive(Debug, Clone, PartialEq)]
pub struct CodegenOptions {
    /// Identifier prefix (sanitised by the generator).
    pub prefix: String,
    /// Control sample time in s, to discretise a continuous model (ZOH).
    pub ts: Option<f64>,
    /// Check frequencies in Hz; empty: [`default_check_hz`].
    pub check_hz: Vec<f64>,
    /// Welch segment length N on target.
    pub welch_n: usize,
    /// Periods averaged on target.
    pub averages: u32,
    /// Periods discarded before averaging.
    pub settle_periods: u32,
    /// Coherence gate of the on-target check.
    pub gate: f64,
    /// RMS of the power-up multisine, plant input units.
    pub excitation_rms: f64,
    /// Highest excited frequency, Hz (default fs/4).
    pub excitation_max_hz: Option<f64>,
    /// Fewest check frequencies that must pass the gate (default: half, rounded up).
    pub min_checked: Option<usize>,
}

impl Default for CodegenOptions {
    fn default() -> Self {
        Self {
            prefix: "ferrosid".into(),
            ts: None,
            check_hz: Vec::new(),
            welch_n: 512,
            averages: 4,
            settle_periods: 1,
            gate: 0.9,
            excitation_rms: 1.0,
            excitation_max_hz: None,
            min_checked: None,
        }
    }
}

fn data_err(path: &Path, msg: impl Into<String>) -> Error {
    Error::Data {
        file: path.to_path_buf(),
        msg: msg.into(),
    }
}

fn rows(m: &faer::Mat<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

/// The generator's matrices of a state-space model (rows).
pub fn matrices(s: &StateSpace) -> cg::Matrices {
    cg::Matrices {
        a: rows(&s.a),
        b: rows(&s.b),
        c: rows(&s.c),
        d: rows(&s.d),
    }
}

/// The discrete model at the control rate and the continuous model for documentation.
fn models(
    path: &Path,
    sys: &StateSpace,
    ts: Option<f64>,
) -> Result<(StateSpace, Option<cg::ContinuousModel>)> {
    if sys.is_discrete() {
        if let Some(t) = ts {
            if (t - sys.ts).abs() > 1e-9 * sys.ts {
                return Err(data_err(
                    path,
                    format!(
                        "the model is discrete at ts = {} s but --ts {t} s was given; identify \
                         at the control rate",
                        sys.ts
                    ),
                ));
            }
        }
        let cont = sys.d2c_zoh().ok().map(|c| cg::ContinuousModel {
            matrices: matrices(&c),
            note: "inverse ZOH (matrix logarithm) of the discrete model".into(),
        });
        Ok((sys.clone(), cont))
    } else {
        let t = ts.ok_or_else(|| {
            data_err(
                path,
                "the model is continuous (ts = 0): give the control sample time with --ts",
            )
        })?;
        let d = sys.c2d_zoh(t)?;
        Ok((
            d,
            Some(cg::ContinuousModel {
                matrices: matrices(sys),
                note: format!("the model as given; discretised by ZOH at ts = {t} s"),
            }),
        ))
    }
}

/// The generator's gains of a discrete PID (and its continuous origin, documented).
pub fn pid_gains(dp: &DiscretePid, cont: Option<&Pid>) -> cg::PidGains {
    cg::PidGains {
        ts_s: dp.ts,
        kp: dp.kp,
        ki_d: dp.ki_d,
        a_d: dp.a_d,
        b_d: dp.b_d,
        rolloff: dp.rolloff.map(|bq| cg::Biquad { b: bq.b, a: bq.a }),
        prewarp_hz: dp.prewarp_hz,
        continuous: cont.map(|p| cg::ContinuousPid {
            kp: p.kp,
            ki: p.ki,
            kd: p.kd,
            tau_f: p.tau_f,
        }),
    }
}

/// `v` with 4 decimals, or 4 significant digits in exponent form for very large or small
/// magnitudes (the receipts' own rendering of values).
pub fn sig4(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        format!("{v}")
    } else if v.abs() >= 1e5 || v.abs() < 1e-3 {
        format!("{v:.4e}")
    } else {
        format!("{v:.4}")
    }
}

/// Default check frequencies: 8 log-spaced from 2 bins to `f_max`.
pub fn default_check_hz(fs: f64, n: usize, f_max: f64) -> Vec<f64> {
    let df = fs / n as f64;
    let lo = 2.0 * df;
    let hi = f_max.max(lo);
    let k = 8usize;
    let mut bins: Vec<usize> = (0..k)
        .map(|i| {
            let f = lo * (hi / lo).powf(i as f64 / (k - 1) as f64);
            ((f / df).round() as usize).max(1)
        })
        .collect();
    bins.dedup();
    bins.into_iter().map(|b| b as f64 * df).collect()
}

impl ControllerSource {
    /// The discrete gains at sample time `ts` s.
    ///
    /// # Errors
    /// From the Tustin discretisation of a continuous controller.
    pub fn gains(&self, ts: f64) -> Result<cg::PidGains> {
        Ok(match self {
            Self::Discrete(dp) => pid_gains(dp, None),
            Self::Continuous { pid, prewarp_hz } => {
                pid_gains(&pid.discretize(ts, *prewarp_hz)?, Some(pid))
            }
            Self::Tuned {
                pid,
                discrete: Some(dp),
                ..
            } => pid_gains(dp, Some(pid)),
            Self::Tuned {
                pid,
                discrete: None,
                crossover_hz,
                prewarp_hz,
            } => pid_gains(
                &pid.discretize(ts, crossover_hz.or(*prewarp_hz))?,
                Some(pid),
            ),
        })
    }
}

/// The generator's weight of a fitted W_m, with its order and worst overbound ratio noted.
pub fn weight_coefficients(w: &UncertaintyWeight) -> cg::WeightCoefficients {
    cg::WeightCoefficients {
        num: w.num.clone(),
        den: w.den.clone(),
        note: format!(
            "fitted multiplicative uncertainty weight, order {}, worst overbound ratio {:.3}",
            w.order, w.worst_overbound_ratio
        ),
    }
}

/// The provenance summary line of a receipt: its value, the condition it is held to
/// (`<= 1.4 1`) and whether it passed. A non-finite limit reads `null`, as in receipts.json.
pub fn receipt_line(r: &Receipt) -> cg::ReceiptLine {
    let op = match r.comparison {
        Comparison::AtMost => "<=",
        Comparison::AtLeast => ">=",
        Comparison::LessThan => "<",
        Comparison::GreaterThan => ">",
    };
    let limit = if r.limit.is_finite() {
        sig4(r.limit)
    } else {
        "null".to_string()
    };
    cg::ReceiptLine {
        name: r.name.clone(),
        value: r.value_text.clone(),
        condition: format!("{op} {limit} {}", r.unit).trim().to_string(),
        pass: r.pass,
    }
}

/// The generator input of `parts` with the settings `opts`.
///
/// # Errors
/// [`Error::Data`] naming [`CodegenParts::model_origin`] when a discrete model is not at
/// `opts.ts` or a continuous one has no `opts.ts`; errors of the controller's discretisation.
pub fn codegen_input(parts: CodegenParts, opts: &CodegenOptions) -> Result<cg::CodegenInput> {
    let (disc, cont) = models(&parts.model_origin, &parts.model, opts.ts)?;
    let operating_point = parts.operating_point.map(|o| cg::OperatingPointValues {
        note: format!(
            "Identified after {} removal{} from logs at {} Hz.",
            o.detrend,
            if o.decimation > 1 {
                format!(" and decimation by {}", o.decimation)
            } else {
                String::new()
            },
            o.fs_raw_hz
        ),
        u0: o.u0,
        y0: o.y0,
    });
    let ts = disc.ts;
    let fs = 1.0 / ts;
    let pid = match &parts.controller {
        Some(c) => Some(c.gains(ts)?),
        None => None,
    };
    let f_max = opts.excitation_max_hz.unwrap_or(fs / 4.0);
    let check_hz = if opts.check_hz.is_empty() {
        default_check_hz(fs, opts.welch_n, f_max)
    } else {
        opts.check_hz.clone()
    };
    let min_checked = opts.min_checked.unwrap_or(check_hz.len().div_ceil(2));
    Ok(cg::CodegenInput {
        compensation: parts.compensation,
        state_controller: parts.state_controller,
        prefix: opts.prefix.clone(),
        model: cg::DiscreteModel {
            ts_s: ts,
            matrices: matrices(&disc),
        },
        continuous: cont,
        pid,
        weight: parts.weight,
        self_id: cg::SelfIdSettings {
            welch_n: opts.welch_n,
            check_hz,
            coherence_gate: opts.gate,
            averages: opts.averages,
            settle_periods: opts.settle_periods,
            excitation_rms: opts.excitation_rms,
            excitation_max_hz: f_max,
            min_checked,
            closed_loop: None,
        },
        provenance: cg::Provenance {
            tool: format!("ferrosid {}", env!("CARGO_PKG_VERSION")),
            sources: parts.sources,
            receipts: parts.receipts,
            notes: Vec::new(),
        },
        operating_point,
    })
}
