//! `ferrosid codegen`: C header and `no_std` Rust module of an identified model, its PID gains,
//! its uncertainty weight W_m and the power-up self-identification settings (crate
//! `ferrosid-codegen`, askama templates).
//!
//! Inputs (JSON files written by other `ferrosid` commands, read leniently):
//! * `--model`: `{"ts", "a", "b", "c", "d"}` (row-major; what `ferrosid identify` writes; an
//!   object with that under `"model"` also works). A continuous model (`ts = 0`) is discretised
//!   (ZOH) at `--ts`; a discrete one must already be at the control rate, and its inverse ZOH is
//!   documented as the continuous model when it exists.
//! * `--pid`: a tuning result (`{"pid", "discrete", "design", ...}`, the `pid.json` of `ferrosid
//!   run`; its discrete controller is used), a discrete PID (`ts, kp, ki_d, a_d, b_d, num,
//!   den[, rolloff]`) or a continuous one (`kp, ki, kd, tau_f[, rolloff]`, Tustin-discretised at
//!   the model rate, prewarped at `--prewarp-hz`). The file is deserialised as each of the three
//!   types in that order; the first that fits is used (their required fields exclude each
//!   other), and the error lists why each one did not fit.
//! * `--wm`: `{"num", "den"}` (a fitted `UncertaintyWeight`), or `--wm-level L` for a flat
//!   relative tolerance W_m = L.
//! * `--receipts`: `receipts.json` (`{"receipts": [...]}`, also nested one level deeper).
//! * `--compensation`: `compensation.json` as `ferrosid run` writes it
//!   ([`crate::ops::codegen::CompensationFile`], `"kind": "ferrosid.compensation/1"`): the
//!   compensation block goes into the header and module (applied only when the run chose
//!   `compensate`; otherwise it is written disabled).
//! * `--control`: the `receipts.json` of a `ferrosid run` with `[control] method = "pid-notch"`,
//!   `"hinf"` or `"mpc"`, read typed (its `control` block and `provenance.settings`): the
//!   chosen controller goes into the header and module as `ferrosid run` would generate it —
//!   the state-space block with its rails and back-calculation gain (`hinf`), plus the PID +
//!   notch biquads (`pid-notch`), or the MPC's QP data (`mpc`, re-designed from `--model` and
//!   the run's settings, and checked against the run's recorded unconstrained law, so a
//!   different model is refused). `--model` must be the run's model (same sample time).
//! * `--source FILE` (repeatable): logs and settings files whose SHA-256 goes into the
//!   provenance; the model/PID/W_m/receipts files are always included.
//!
//! Output: `<out-dir>/<prefix>.h` and `<out-dir>/<prefix>.rs` (prefix sanitised), written only
//! when their content changes (so firmware builds that include them stay cached). The same
//! inputs always give byte-identical files.
//!
//! Templates: `--templates DIR` renders `DIR/model.h` and/or `DIR/model.rs` instead of the
//! built-in ones (run-time engine, same context; see the `ferrosid_codegen` crate docs);
//! `--write-templates DIR` writes the built-in templates there as a starting point and exits.
//!
//! Examples:
//! ```text
//! ferrosid codegen --model model.json --pid tuned.json --wm wm.json --receipts receipts.json \
//!     --source logs/unit_a.csv --prefix axis1 --out-dir firmware/generated
//! ferrosid codegen --model model.json --wm-level 0.2 --check-hz 5,10,20,40 --prefix axis1 --out-dir gen
//! ```
use super::ExitCode;
use crate::error::{Error, Result};
use crate::io::file_safety::{refuse_input_overwrite, write_atomic};
use crate::lti::{StateSpace, StateSpaceData};
pub use crate::ops::codegen::default_check_hz;
use crate::ops::codegen::{
    codegen_input, sig4, CodegenOptions, CodegenParts, CompensationFile, ControllerSource,
    COMPENSATION_FILE_KIND,
};
use crate::robust::pid::{DiscretePid, Pid};
use ferrosid_codegen as cg;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Flags of `ferrosid codegen`.
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_help = "Examples:\n  ferrosid codegen --model model.json --pid tuned.json --wm wm.json \
    --receipts receipts.json --source logs/unit_a.csv --prefix axis1 --out-dir gen\n  \
    ferrosid codegen --model model.json --wm-level 0.2 --check-hz 5,10,20,40 --prefix axis1 --out-dir gen\n  \
    ferrosid codegen --write-templates my_templates\n\n\
    Exit codes: 0 files written, 2 usage error, 3 unreadable or malformed input file (named), \
    4 the model cannot be discretised or checked."
)]
pub struct Args {
    /// Model JSON ({"ts","a","b","c","d"}, row-major; ts = 0 for continuous).
    #[arg(long, value_name = "FILE", required_unless_present = "write_templates")]
    pub model: Option<PathBuf>,
    /// Control sample time in s, to discretise a continuous model (ZOH).
    #[arg(long, value_name = "S")]
    pub ts: Option<f64>,
    /// PID JSON: continuous (kp, ki, kd, tau_f), discrete (ki_d, a_d, b_d) or a tuning result.
    #[arg(long, value_name = "FILE")]
    pub pid: Option<PathBuf>,
    /// Tustin prewarp frequency (Hz) for a continuous PID (default: plain Tustin).
    #[arg(long, value_name = "HZ")]
    pub prewarp_hz: Option<f64>,
    /// Uncertainty weight JSON ({"num","den"}, continuous, s in rad/s).
    #[arg(long, value_name = "FILE", conflicts_with = "wm_level")]
    pub wm: Option<PathBuf>,
    /// Flat relative tolerance instead of a fitted W_m (e.g. 0.2 = 20 %).
    #[arg(long, value_name = "L")]
    pub wm_level: Option<f64>,
    /// Receipts JSON for the provenance summary.
    #[arg(long, value_name = "FILE")]
    pub receipts: Option<PathBuf>,
    /// Compensation JSON (`compensation.json` of `ferrosid run`).
    #[arg(long, value_name = "FILE")]
    pub compensation: Option<PathBuf>,
    /// `receipts.json` of a `ferrosid run` whose `[control] method` chose pid-notch, hinf or
    /// mpc: that controller is generated too.
    #[arg(long, value_name = "FILE")]
    pub control: Option<PathBuf>,
    /// Source file (log, settings) whose SHA-256 goes into the provenance. Repeatable.
    #[arg(long = "source", value_name = "FILE")]
    pub sources: Vec<PathBuf>,
    /// Identifier prefix (sanitised to a C identifier, e.g. `axis-1` -> `AXIS_1`).
    #[arg(long, value_name = "NAME", default_value = "ferrosid")]
    pub prefix: String,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", required_unless_present = "write_templates")]
    pub out_dir: Option<PathBuf>,
    /// Directory with user templates model.h / model.rs (others fall back to the built-ins).
    #[arg(long, value_name = "DIR")]
    pub templates: Option<PathBuf>,
    /// Write the built-in templates to DIR (a starting point for --templates) and exit.
    /// An existing template that differs from the built-in one (an edited copy) is not
    /// replaced unless --force is given.
    #[arg(long, value_name = "DIR")]
    pub write_templates: Option<PathBuf>,
    /// With --write-templates: replace edited templates too.
    #[arg(long, requires = "write_templates")]
    pub force: bool,
    /// Check frequencies in Hz, comma separated (snapped to Welch bins). Default: 8
    /// log-spaced frequencies from 2 bins to the highest excited frequency.
    #[arg(long, value_name = "HZ,...", value_delimiter = ',')]
    pub check_hz: Vec<f64>,
    /// Welch segment length N of the power-up self-identification (power of two, 64..=4096).
    #[arg(long, value_name = "N", default_value_t = 512)]
    pub welch_n: usize,
    /// Periods averaged on target.
    #[arg(long, value_name = "K", default_value_t = 4)]
    pub averages: u32,
    /// Periods discarded before averaging (transient).
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub settle_periods: u32,
    /// Coherence gate of the on-target check.
    #[arg(long, value_name = "C", default_value_t = 0.9)]
    pub gate: f64,
    /// RMS of the power-up multisine, in plant input units.
    #[arg(long, value_name = "U", default_value_t = 1.0)]
    pub excitation_rms: f64,
    /// Highest excited frequency, Hz (default fs/4).
    #[arg(long, value_name = "HZ")]
    pub excitation_max_hz: Option<f64>,
    /// Fewest check frequencies that must pass the coherence gate (default: half, rounded up).
    #[arg(long, value_name = "K")]
    pub min_checked: Option<usize>,
    /// Print a JSON summary on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

fn read_text(path: &Path) -> Result<String> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        file: path.to_path_buf(),
        source,
    })?;
    // Malformed JSON is a parse error with its line, whatever the expected type.
    serde_json::from_str::<serde::de::IgnoredAny>(&text).map_err(|e| Error::Parse {
        file: path.to_path_buf(),
        line: e.line(),
        msg: format!("not valid JSON: {e}"),
    })?;
    Ok(text)
}

fn read_json(path: &Path) -> Result<Value> {
    let text = read_text(path)?;
    serde_json::from_str(&text).map_err(|e| Error::Parse {
        file: path.to_path_buf(),
        line: e.line(),
        msg: format!("not valid JSON: {e}"),
    })
}

fn data_err(path: &Path, msg: impl Into<String>) -> Error {
    Error::Data {
        file: path.to_path_buf(),
        msg: msg.into(),
    }
}

/// Reads a model file: a `StateSpaceData` at the top level or under `"model"`.
pub fn read_model(path: &Path) -> Result<StateSpace> {
    read_model_file(path).map(|(s, _)| s)
}

/// [`read_model`] with the operating point the file records (None for files without one).
/// The file is a [`StateSpaceData`], or an object with one under `"model"`.
pub fn read_model_file(path: &Path) -> Result<(StateSpace, Option<crate::data::OperatingPoint>)> {
    #[derive(serde::Deserialize)]
    struct Wrapped {
        model: StateSpaceData,
    }
    let text = read_text(path)?;
    let data = match serde_json::from_str::<StateSpaceData>(&text) {
        Ok(d) => d,
        Err(bare) => match serde_json::from_str::<Wrapped>(&text) {
            Ok(w) => w.model,
            Err(wrapped) => {
                return Err(data_err(
                    path,
                    format!(
                        "no model: expected an object with \"ts\", \"a\", \"b\", \"c\", \"d\" \
                         ({bare}) or one under \"model\" ({wrapped})"
                    ),
                ))
            }
        },
    };
    let sys = StateSpace::try_from(&data).map_err(|e| data_err(path, e.to_string()))?;
    Ok((sys, data.operating_point))
}

/// Reads a PID file (module docs: a tuning result, a discrete or a continuous PID, tried as
/// typed formats in that order) as the controller the header is generated for (a continuous
/// one prewarped at `prewarp_hz`).
pub fn read_pid(path: &Path, prewarp_hz: Option<f64>) -> Result<ControllerSource> {
    #[derive(serde::Deserialize)]
    struct Design {
        crossover_hz: Option<f64>,
    }
    #[derive(serde::Deserialize)]
    struct TuningFile {
        pid: Pid,
        discrete: Option<DiscretePid>,
        design: Option<Design>,
    }
    let text = read_text(path)?;
    let tuned = match serde_json::from_str::<TuningFile>(&text) {
        Ok(t) => {
            return Ok(ControllerSource::Tuned {
                pid: t.pid,
                discrete: t.discrete,
                crossover_hz: t.design.and_then(|d| d.crossover_hz),
                prewarp_hz,
            })
        }
        Err(e) => e,
    };
    let discrete = match serde_json::from_str::<DiscretePid>(&text) {
        Ok(d) => return Ok(ControllerSource::Discrete(d)),
        Err(e) => e,
    };
    let continuous = match serde_json::from_str::<Pid>(&text) {
        Ok(pid) => return Ok(ControllerSource::Continuous { pid, prewarp_hz }),
        Err(e) => e,
    };
    Err(data_err(
        path,
        format!(
            "not a PID: as a tuning result ({{\"pid\", \"discrete\", \"design\"}}): {tuned}; as a \
             discrete PID: {discrete}; as a continuous PID: {continuous}"
        ),
    ))
}

/// Reads `compensation.json` ([`CompensationFile`], kind `ferrosid.compensation/1`) and checks
/// it; errors name the file (and the line for malformed JSON).
pub fn read_compensation(path: &Path) -> Result<cg::Compensation> {
    let text = read_text(path)?;
    let f: CompensationFile = serde_json::from_str(&text).map_err(|e| Error::Parse {
        file: path.to_path_buf(),
        line: e.line(),
        msg: format!("not a compensation file ({COMPENSATION_FILE_KIND}): {e}"),
    })?;
    f.validate().map_err(|e| data_err(path, e.to_string()))?;
    Ok(f.compensation)
}

/// The parts of a pipeline run's `receipts.json` that carry its chosen controller (typed; other
/// keys are ignored).
#[derive(serde::Deserialize)]
struct RunRecord {
    provenance: RunProvenance,
    #[serde(default)]
    control: Option<ControlRecord>,
}

#[derive(serde::Deserialize)]
struct RunProvenance {
    settings: crate::pipeline::PipelineConfig,
}

#[derive(serde::Deserialize)]
struct ControlRecord {
    method: crate::pipeline::control_stage::ControlMethod,
    status: String,
    #[serde(default)]
    error: Option<String>,
    #[serde(default)]
    controller: Option<StateSpaceData>,
    #[serde(default)]
    design: Option<DesignRecord>,
}

/// The `design` object of the record: the fields codegen needs per `kind` (`loopshape`:
/// pid, design, notches, anti_windup; `hinf`: anti_windup_gain; `mpc`: model_states,
/// unconstrained_kx). A plain struct, not an internally tagged enum: serde buffers a tagged
/// enum's content, and with serde_json's arbitrary-precision numbers a buffered float no
/// longer reads as an f64.
#[derive(serde::Deserialize)]
struct DesignRecord {
    kind: String,
    #[serde(default)]
    pid: Option<Pid>,
    #[serde(default)]
    design: Option<crate::robust::pid::PidDesignPoint>,
    #[serde(default)]
    notches: Option<Vec<crate::synth::loopshape::Notch>>,
    #[serde(default)]
    anti_windup: Option<bool>,
    #[serde(default)]
    anti_windup_gain: Option<Vec<f64>>,
    #[serde(default)]
    model_states: Option<usize>,
    #[serde(default)]
    unconstrained_kx: Option<Vec<f64>>,
}

/// Reads the chosen controller of a pipeline run from its `receipts.json` (module docs) for
/// the discrete model `model` the header is generated for. Ok(None) for method `pid` (give
/// its PID with `--pid`). Errors name the file: not a run's receipts, a failed design, a
/// sample time or model that differs from `model`.
pub fn read_control(path: &Path, model: &StateSpace) -> Result<Option<cg::StateController>> {
    use crate::pipeline::control_stage::{pid_notch_block, saturation_block, ControlMethod};
    let text = read_text(path)?;
    let rec: RunRecord = serde_json::from_str(&text).map_err(|e| Error::Parse {
        file: path.to_path_buf(),
        line: e.line(),
        msg: format!("not the receipts.json of a `ferrosid run`: {e}"),
    })?;
    let settings = rec.provenance.settings;
    let Some(c) = rec.control else {
        return match settings.control.method {
            ControlMethod::Pid => Ok(None),
            m => Err(data_err(
                path,
                format!("method {} but no \"control\" block", m.name()),
            )),
        };
    };
    if c.status != "designed" {
        return Err(data_err(
            path,
            format!(
                "the {} design of this run failed: {}",
                c.method.name(),
                c.error.as_deref().unwrap_or("no reason given")
            ),
        ));
    }
    if !model.is_discrete() {
        return Err(data_err(path, "the model must be discrete (give --ts)"));
    }
    let ts = model.ts;
    let limit = settings.control.actuator_limit;
    let err = |e: Error| data_err(path, e.to_string());
    let controller = |what: &str| -> Result<StateSpace> {
        let data = c
            .controller
            .as_ref()
            .ok_or_else(|| data_err(path, format!("the {what} record has no \"controller\"")))?;
        let k = StateSpace::try_from(data).map_err(|e| data_err(path, e.to_string()))?;
        if !((k.ts - ts).abs() <= 1e-12 * ts) {
            return Err(data_err(
                path,
                format!(
                    "the controller's ts = {} s differs from the model's {ts} s",
                    k.ts
                ),
            ));
        }
        Ok(k)
    };
    let block = |k: &StateSpace| cg::StateController {
        method: c.method.name().to_string(),
        ts_s: k.ts,
        matrices: crate::ops::codegen::matrices(k),
        note: format!(
            "{} controller of order {} from {}; receipts as in that file",
            c.method.name(),
            k.n_states(),
            path.display()
        ),
        mpc: None,
        saturation: None,
        pid_notch: None,
    };
    let missing = |what: &str| {
        data_err(
            path,
            format!(
                "the {} record's \"design\" has no \"{what}\"",
                c.method.name()
            ),
        )
    };
    let d = match (&c.method, c.design) {
        (ControlMethod::Pid, _) => return Ok(None),
        (m, Some(d)) if d.kind == kind_of(*m) => d,
        (m, d) => {
            return Err(data_err(
                path,
                format!(
                    "the {} record has no matching \"design\" block (kind {:?})",
                    m.name(),
                    d.map(|d| d.kind)
                ),
            ))
        }
    };
    match c.method {
        ControlMethod::Loopshape => {
            let k = controller("pid-notch")?;
            let pid = d.pid.ok_or_else(|| missing("pid"))?;
            let design = d.design.ok_or_else(|| missing("design"))?;
            let notches = d.notches.ok_or_else(|| missing("notches"))?;
            let aw = d.anti_windup.unwrap_or(settings.control.anti_windup);
            let kn =
                pid_notch_block(&pid, design.crossover_hz, &notches, ts, limit, aw).map_err(err)?;
            Ok(Some(cg::StateController {
                pid_notch: kn,
                ..block(&k)
            }))
        }
        ControlMethod::Hinf => {
            let k = controller("hinf")?;
            // A record written before the gain was recorded: the same deterministic design.
            let gain = match (d.anti_windup_gain, settings.control.anti_windup) {
                (Some(g), _) => Some(g),
                (None, true) => Some(crate::synth::sim::anti_windup_gain(&k).map_err(err)?),
                (None, false) => None,
            };
            Ok(Some(cg::StateController {
                saturation: Some(saturation_block(gain.as_deref(), k.n_states(), limit)),
                ..block(&k)
            }))
        }
        ControlMethod::Mpc => mpc_controller(path, model, &settings, &d).map(Some),
        ControlMethod::Pid => Ok(None),
    }
}

/// The MPC block of a run's `control` record, re-designed on `model` with the run's settings
/// and checked against the run's recorded unconstrained law (another model: an error naming
/// both laws).
fn mpc_controller(
    path: &Path,
    model: &StateSpace,
    settings: &crate::pipeline::PipelineConfig,
    d: &DesignRecord,
) -> Result<cg::StateController> {
    let err = |e: Error| data_err(path, e.to_string());
    let missing = |what: &str| {
        data_err(
            path,
            format!("the mpc record's \"design\" has no \"{what}\""),
        )
    };
    let model_states = d.model_states.ok_or_else(|| missing("model_states"))?;
    let unconstrained_kx = d
        .unconstrained_kx
        .as_deref()
        .ok_or_else(|| missing("unconstrained_kx"))?;
    let spec = crate::pipeline::control_mpc::mpc_spec(settings);
    let design = crate::synth::mpc::MpcDesign::new(model, spec).map_err(err)?;
    let kx = design.unconstrained_law().map_err(err)?.kx;
    let scale = unconstrained_kx
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(1e-300);
    let same = model.n_states() == model_states
        && kx.len() == unconstrained_kx.len()
        && kx
            .iter()
            .zip(unconstrained_kx)
            .all(|(a, b)| (a - b).abs() <= 1e-9 * scale);
    if !same {
        return Err(data_err(
            path,
            format!(
                "the run's MPC was designed on another model: its unconstrained law \
                 k_x = {unconstrained_kx:?} ({model_states} states), the MPC re-designed \
                 on --model gives {kx:?} ({} states)",
                model.n_states()
            ),
        ));
    }
    Ok(crate::pipeline::control_mpc::mpc_state_controller(
        &design, model,
    ))
}

/// The `kind` of a method's design summary.
fn kind_of(m: crate::pipeline::control_stage::ControlMethod) -> &'static str {
    use crate::pipeline::control_stage::ControlMethod;
    match m {
        ControlMethod::Pid => "pid",
        ControlMethod::Loopshape => "loopshape",
        ControlMethod::Hinf => "hinf",
        ControlMethod::Mpc => "mpc",
    }
}

/// Reads W_m coefficients (`num`, `den`) from a JSON file.
pub fn read_weight(path: &Path) -> Result<cg::WeightCoefficients> {
    let v = read_json(path)?;
    let coeffs = |k: &str| -> Result<Vec<f64>> {
        let arr = v
            .get(k)
            .and_then(Value::as_array)
            .ok_or_else(|| data_err(path, format!("missing array \"{k}\"")))?;
        arr.iter()
            .enumerate()
            .map(|(i, x)| {
                x.as_f64()
                    .ok_or_else(|| data_err(path, format!("\"{k}\"[{i}] is not a number")))
            })
            .collect()
    };
    let order = v.get("order").and_then(Value::as_u64);
    let ratio = v.get("worst_overbound_ratio").and_then(Value::as_f64);
    let mut note = String::from("fitted multiplicative uncertainty weight");
    if let Some(o) = order {
        note.push_str(&format!(", order {o}"));
    }
    if let Some(r) = ratio {
        note.push_str(&format!(", worst overbound ratio {r:.3}"));
    }
    Ok(cg::WeightCoefficients {
        num: coeffs("num")?,
        den: coeffs("den")?,
        note,
    })
}

/// Reads a receipts summary from `receipts.json` (the `ferrosid.receipts/1` list, top level or
/// nested one level deeper).
pub fn read_receipts(path: &Path) -> Result<Vec<cg::ReceiptLine>> {
    let v = read_json(path)?;
    let list = v
        .get("receipts")
        .and_then(|r| {
            r.as_array()
                .or_else(|| r.get("receipts").and_then(Value::as_array))
        })
        .ok_or_else(|| data_err(path, "no \"receipts\" array"))?;
    let mut out = Vec::with_capacity(list.len());
    for (i, r) in list.iter().enumerate() {
        let s = |k: &str| r.get(k).and_then(Value::as_str).map(str::to_string);
        let name = s("name").ok_or_else(|| data_err(path, format!("receipt {i}: no \"name\"")))?;
        let pass = r
            .get("pass")
            .and_then(Value::as_bool)
            .ok_or_else(|| data_err(path, format!("receipt {i} ({name}): no boolean \"pass\"")))?;
        let value = s("value_text")
            .or_else(|| r.get("value").map(|v| v.to_string()))
            .unwrap_or_else(|| "?".into());
        let op = match s("comparison").as_deref() {
            Some("at_most") => "<=",
            Some("at_least") => ">=",
            Some("less_than") => "<",
            Some("greater_than") => ">",
            _ => "vs",
        };
        let limit = match r.get("limit") {
            Some(Value::Number(n)) => n.as_f64().map(sig4).unwrap_or_else(|| n.to_string()),
            Some(v) => v.to_string(),
            None => String::new(),
        };
        let unit = s("unit").unwrap_or_default();
        out.push(cg::ReceiptLine {
            name,
            value,
            condition: format!("{op} {limit} {unit}").trim().to_string(),
            pass,
        });
    }
    Ok(out)
}

/// SHA-256 of a file's bytes with its label.
pub fn digest_file(path: &Path, role: &str) -> Result<cg::SourceDigest> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io {
        file: path.to_path_buf(),
        source,
    })?;
    Ok(cg::SourceDigest {
        label: format!("{role}: {}", path.display()),
        sha256: cg::sha256_hex(&bytes),
    })
}

/// Builds the generator input from the parsed flags (everything but writing files): reads
/// the parts from the files and hands them to [`crate::ops::codegen::codegen_input`].
pub fn build_input(args: &Args) -> Result<cg::CodegenInput> {
    let model_path = args
        .model
        .as_deref()
        .ok_or_else(|| Error::InvalidArgument("--model is required".into()))?;
    let (model, operating_point) = read_model_file(model_path)?;
    let mut sources = vec![digest_file(model_path, "model")?];
    let controller = match &args.pid {
        Some(p) => {
            sources.push(digest_file(p, "pid")?);
            Some(read_pid(p, args.prewarp_hz)?)
        }
        None => None,
    };
    let weight =
        match (&args.wm, args.wm_level) {
            (Some(p), _) => {
                sources.push(digest_file(p, "wm")?);
                read_weight(p)?
            }
            (None, Some(l)) => {
                if !(l.is_finite() && l > 0.0) {
                    return Err(Error::InvalidArgument(format!(
                        "--wm-level must be finite and > 0, got {l}"
                    )));
                }
                cg::WeightCoefficients {
                    num: vec![l],
                    den: vec![1.0],
                    note: format!("flat relative tolerance {l} (--wm-level)"),
                }
            }
            (None, None) => return Err(Error::InvalidArgument(
                "the power-up check needs an uncertainty weight: give --wm FILE or --wm-level L"
                    .into(),
            )),
        };
    let receipts = match &args.receipts {
        Some(p) => {
            sources.push(digest_file(p, "receipts")?);
            read_receipts(p)?
        }
        None => Vec::new(),
    };
    let compensation = match &args.compensation {
        Some(p) => {
            sources.push(digest_file(p, "compensation")?);
            Some(read_compensation(p)?)
        }
        None => None,
    };
    let state_controller = match &args.control {
        Some(p) => {
            sources.push(digest_file(p, "control")?);
            let ts_model = match args.ts {
                Some(t) if !model.is_discrete() => model
                    .c2d_zoh(t)
                    .map_err(|e| data_err(model_path, e.to_string()))?,
                _ => model.clone(),
            };
            read_control(p, &ts_model)?
        }
        None => None,
    };
    for s in &args.sources {
        sources.push(digest_file(s, "source")?);
    }
    let parts = CodegenParts {
        compensation,
        model,
        model_origin: model_path.to_path_buf(),
        operating_point,
        controller,
        weight,
        receipts,
        sources,
        state_controller,
    };
    codegen_input(parts, &args.options())
}

impl Args {
    /// The prefix and self-identification settings of the flags.
    pub fn options(&self) -> CodegenOptions {
        CodegenOptions {
            prefix: self.prefix.clone(),
            ts: self.ts,
            check_hz: self.check_hz.clone(),
            welch_n: self.welch_n,
            averages: self.averages,
            settle_periods: self.settle_periods,
            gate: self.gate,
            excitation_rms: self.excitation_rms,
            excitation_max_hz: self.excitation_max_hz,
            min_checked: self.min_checked,
        }
    }
}

/// The files a codegen input came from, so that errors in their contents name them.
#[derive(Debug, Clone, Default)]
pub struct InputFiles {
    /// `--model` file.
    pub model: Option<PathBuf>,
    /// `--pid` file.
    pub pid: Option<PathBuf>,
    /// `--wm` file.
    pub wm: Option<PathBuf>,
    /// `--compensation` file.
    pub compensation: Option<PathBuf>,
    /// The sample time came from `--ts` (a continuous model discretised), not from the file.
    pub ts_flag: bool,
}

impl InputFiles {
    /// The files named by the flags.
    pub fn of(args: &Args) -> Self {
        Self {
            model: args.model.clone(),
            pid: args.pid.clone(),
            wm: args.wm.clone(),
            compensation: args.compensation.clone(),
            ts_flag: args.ts.is_some(),
        }
    }
}

/// Maps a generator error to the crate error: a bad field of the model, PID or W_m is an input
/// data error naming that file (exit 3); a bad self-identification setting or prefix is a usage
/// error (exit 2); a user template that cannot be read or rendered is a data error naming it.
pub fn codegen_error(e: cg::Error, files: &InputFiles) -> Error {
    match e {
        cg::Error::TemplateIo { file, source } => Error::Io { file, source },
        cg::Error::Render { template, msg } => Error::Data {
            file: PathBuf::from(&template),
            msg: format!("template: {msg}"),
        },
        cg::Error::Input { field, msg } if field == "model.ts_s" && files.ts_flag => {
            Error::InvalidArgument(format!("--ts: {msg}"))
        }
        cg::Error::Input { field, msg } => {
            let head = field.split(['.', '[']).next().unwrap_or("");
            let file = match head {
                "model" | "continuous" => files.model.as_ref(),
                "pid" => files.pid.as_ref(),
                "weight" => files.wm.as_ref(),
                "compensation" => files.compensation.as_ref(),
                _ => None,
            };
            match file {
                Some(f) => Error::Data {
                    file: f.clone(),
                    msg: format!("`{field}`: {msg}"),
                },
                None => Error::InvalidArgument(format!("codegen input `{field}`: {msg}")),
            }
        }
    }
}

/// Generates the files for `input` (with `templates` when given) and writes them into
/// `out_dir`, each only when its content changed. Returns the generated set and the paths.
pub fn generate_to_dir(
    input: &cg::CodegenInput,
    templates: Option<&Path>,
    out_dir: &Path,
    files: &InputFiles,
) -> Result<(cg::Generated, PathBuf, PathBuf)> {
    let g = match templates {
        Some(dir) => cg::generate_with_templates(input, dir),
        None => cg::generate(input),
    }
    .map_err(|e| codegen_error(e, files))?;
    std::fs::create_dir_all(out_dir).map_err(|source| Error::Io {
        file: out_dir.to_path_buf(),
        source,
    })?;
    let h = out_dir.join(&g.c_file_name);
    let r = out_dir.join(&g.rs_file_name);
    for path in [&h, &r] {
        let inputs: Vec<&Path> = [&files.model, &files.pid, &files.wm, &files.compensation]
            .into_iter()
            .flatten()
            .map(PathBuf::as_path)
            .collect();
        refuse_input_overwrite(path, "--out-dir", &inputs)?;
    }
    for (path, text) in [(&h, &g.c_header), (&r, &g.rust_module)] {
        write_if_changed(path, text)?;
    }
    Ok((g, h, r))
}

/// Writes `text` to `path` unless the file already holds exactly that.
pub fn write_if_changed(path: &Path, text: &str) -> Result<()> {
    if std::fs::read(path).ok().as_deref() == Some(text.as_bytes()) {
        return Ok(());
    }
    write_atomic(path, text.as_bytes())
}

#[derive(serde::Serialize)]
struct Summary<'a> {
    c_header: &'a Path,
    rust_module: &'a Path,
    prefix: &'a str,
    inputs_sha256: &'a str,
    checks: &'a [cg::CheckPoint],
    self_id_samples: u64,
}

/// Runs `ferrosid codegen`.
pub fn run(args: &Args) -> Result<ExitCode> {
    if let Some(dir) = &args.write_templates {
        std::fs::create_dir_all(dir).map_err(|source| Error::Io {
            file: dir.clone(),
            source,
        })?;
        let names = [cg::C_TEMPLATE, cg::RUST_TEMPLATE];
        if !args.force {
            for name in names {
                let p = dir.join(name);
                let text = cg::builtin_template(name).unwrap_or_default();
                if p.exists() && std::fs::read(&p).ok().as_deref() != Some(text.as_bytes()) {
                    return Err(Error::Io {
                        file: p,
                        source: std::io::Error::new(
                            std::io::ErrorKind::AlreadyExists,
                            "exists and differs from the built-in template (edited?): not \
                             replaced; pass --force to overwrite it",
                        ),
                    });
                }
            }
        }
        for name in names {
            let text = cg::builtin_template(name).unwrap_or_default();
            write_if_changed(&dir.join(name), text)?;
        }
        println!(
            "wrote {} and {} to {}; edit them and pass --templates {}",
            cg::C_TEMPLATE,
            cg::RUST_TEMPLATE,
            dir.display(),
            dir.display()
        );
        println!("template variables (all under `c`):");
        for (name, what) in cg::context_variables() {
            println!("  {name}: {what}");
        }
        return Ok(ExitCode::Ok);
    }
    let out_dir = args
        .out_dir
        .as_deref()
        .ok_or_else(|| Error::InvalidArgument("--out-dir is required".into()))?;
    crate::io::file_safety::check_dir_writable(out_dir)?;
    let input = build_input(args)?;
    let (g, h, r) = generate_to_dir(
        &input,
        args.templates.as_deref(),
        out_dir,
        &InputFiles::of(args),
    )?;
    let samples = u64::from(input.self_id.settle_periods + input.self_id.averages)
        * input.self_id.welch_n as u64;
    if args.json {
        let s = Summary {
            c_header: &h,
            rust_module: &r,
            prefix: &g.prefix,
            inputs_sha256: &g.inputs_sha256,
            checks: &g.checks,
            self_id_samples: samples,
        };
        let text = serde_json::to_string_pretty(&s)
            .map_err(|e| Error::InvalidArgument(format!("JSON summary: {e}")))?;
        println!("{text}");
    } else {
        println!("C header:    {}", h.display());
        println!("Rust module: {}", r.display());
        println!("prefix {}, inputs sha256 {}", g.prefix, g.inputs_sha256);
        println!(
            "power-up self-identification: {} samples ({} s at {} Hz)",
            samples,
            samples as f64 * input.model.ts_s,
            1.0 / input.model.ts_s
        );
        println!("check frequencies (requested -> bin -> Hz):");
        for c in &g.checks {
            println!("  {:>10.4} -> {:>4} -> {:.4}", c.requested_hz, c.bin, c.hz);
        }
    }
    Ok(ExitCode::Ok)
}
