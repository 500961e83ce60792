//! Many units, one pipeline: run the pipeline on every serial number's logs in parallel and
//! summarise the parameter distributions across the fleet.
//!
//! # Layouts of the fleet directory
//! * **One subdirectory per serial number** (`DIR/SN0001/low.csv`, ...): every subdirectory
//!   that is not hidden and not named `out` is a unit; the template's log paths are resolved
//!   inside it. A unit directory holding its own `pipeline.toml` uses that file instead.
//! * **One file prefix per serial number** (`DIR/SN0001_low.csv`, ...), used when `DIR` has no
//!   unit subdirectories: the serial number is the file name up to the first `_`, and a log
//!   path `low.csv` in the template resolves to `DIR/<serial>_low.csv`.
//!
//! The template is `--pipeline FILE` or `DIR/pipeline.toml`. Units are processed in parallel
//! (rayon, `jobs` threads) and reported in serial-number order, so the summary does not depend
//! on scheduling. A unit whose data are unusable is reported with its error; it does not stop
//! the others.
//!
//! # Summary
//! Per unit: receipts passed/total, DC gain, the modes of the identified model (natural
//! frequency in Hz and damping, from s = ln(z)/ts), the uncertainty weight's low- and
//! high-frequency gains |W_m(0)| and |W_m(∞)|, the achieved crossover, M_s and the validation
//! fit. Across units, for each parameter: count, min, median, max, mean and sample standard
//! deviation. Oscillatory modes are matched across units by rank (1st, 2nd, ... lightly
//! damped pair in increasing frequency).
//!
//! # Physical parameters
//! With [`FleetOptions::physical`] (`ferrosid fleet --structure two-mass --known Kt=1`) each
//! unit also gets a grey-box fit ([`crate::greybox::fit_log`]) on its identification run after
//! the pipeline's preprocessing: parameters in physical units with 95 % intervals. The summary
//! then carries each parameter's distribution across units and flags, per parameter, the units
//! outside the fleet's spread: modified z-score |0.6745·(x − median)/MAD| > [`OUTLIER_Z`]
//! (Iglewicz & Hoaglin 1993; median and MAD resist the outlier they look for, a mean and a
//! standard deviation would be pulled towards it), computed on log values (every physical
//! parameter is positive and spreads multiplicatively). At least [`MIN_UNITS_FOR_SPREAD`] units
//! are needed.
use crate::error::{Error, Result};
use crate::greybox::{GreyBoxOptions, ParameterStatus};
use crate::io::file_safety::OutputDir;
use crate::output::prepare_output_dir;
use crate::output::write_outputs_to;
use crate::pipeline::config::LoadedConfig;
use crate::pipeline::document::{weight_high_gain, weight_low_gain};
use crate::pipeline::{json_pretty, run_pipeline, Mode, PipelineRun};
use crate::robust::receipts::ReceiptKind;
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Schema identifier of the fleet summary.
pub const FLEET_SCHEMA: &str = "ferrosid.fleet/1";

/// How units are laid out in the fleet directory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Layout {
    /// `DIR/<serial>/<file>`.
    Subdirectories,
    /// `DIR/<serial>_<file>`.
    Prefix,
}

/// Finds the units of a fleet directory (see the module docs), sorted by serial number.
pub fn discover_units(dir: &Path) -> Result<(Layout, Vec<String>)> {
    let io = |source| Error::Io {
        file: dir.to_path_buf(),
        source,
    };
    let mut subdirs = Vec::new();
    let mut prefixes = std::collections::BTreeSet::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let entry = entry.map_err(io)?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') {
            continue;
        }
        let ft = entry.file_type().map_err(io)?;
        if ft.is_dir() {
            if name != "out" {
                subdirs.push(name);
            }
        } else if ft.is_file() {
            let ext = Path::new(&name)
                .extension()
                .and_then(|e| e.to_str())
                .map(|e| e.to_ascii_lowercase())
                .unwrap_or_default();
            if matches!(ext.as_str(), "csv" | "mat" | "dat" | "txt") {
                if let Some((serial, _)) = name.split_once('_') {
                    if !serial.is_empty() {
                        prefixes.insert(serial.to_string());
                    }
                }
            }
        }
    }
    subdirs.sort();
    if !subdirs.is_empty() {
        return Ok((Layout::Subdirectories, subdirs));
    }
    if !prefixes.is_empty() {
        return Ok((Layout::Prefix, prefixes.into_iter().collect()));
    }
    Err(Error::Data {
        file: dir.to_path_buf(),
        msg: "no units found: expected one subdirectory per serial number, or log files named \
              <serial>_<name>.csv"
            .into(),
    })
}

/// The configuration of one unit: the unit's own `pipeline.toml` if it has one (subdirectory
/// layout), else the template with its log paths resolved for the unit.
pub fn unit_config(
    template: &LoadedConfig,
    dir: &Path,
    layout: Layout,
    serial: &str,
) -> Result<LoadedConfig> {
    match layout {
        Layout::Subdirectories => {
            let udir = dir.join(serial);
            let own = udir.join("pipeline.toml");
            if own.is_file() {
                return LoadedConfig::load(&own);
            }
            let mut c = template.clone();
            c.base_dir = udir;
            c.config.name = Some(unit_title(template, serial));
            Ok(c)
        }
        Layout::Prefix => {
            let mut c = template.clone();
            c.base_dir = dir.to_path_buf();
            let pre = |p: &PathBuf| -> PathBuf {
                let name = p
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let with = format!("{serial}_{name}");
                match p.parent() {
                    Some(par) if !par.as_os_str().is_empty() => par.join(with),
                    _ => PathBuf::from(with),
                }
            };
            for r in &mut c.config.runs {
                r.file = pre(&r.file);
            }
            if let Some(v) = &mut c.config.validation {
                v.file = pre(&v.file);
            }
            c.config.name = Some(unit_title(template, serial));
            Ok(c)
        }
    }
}

fn unit_title(template: &LoadedConfig, serial: &str) -> String {
    match &template.config.name {
        Some(n) => format!("{n} — {serial}"),
        None => serial.to_string(),
    }
}

/// One unit's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct UnitResult {
    /// Serial number.
    pub serial: String,
    /// `pass`, `fail` (a receipt failed) or `error` (the pipeline could not run).
    pub status: &'static str,
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
#[derive(Debug, Clone, Serialize)]
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
#[derive(Debug, Clone, Serialize)]
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

impl UnitResult {
    fn from_run(serial: &str, run: &PipelineRun, out_dir: Option<String>) -> Self {
        let rs = &run.receipts;
        let passed = rs.receipts.iter().filter(|r| r.pass).count();
        Self {
            serial: serial.into(),
            status: if rs.all_pass { "pass" } else { "fail" },
            error: None,
            passed,
            receipts: rs.receipts.len(),
            failed: rs.failed().map(|r| r.name.clone()).collect(),
            order: Some(run.ident.order),
            dc_gain: Some(run.dc_gain),
            modes: run.modes.clone(),
            wm_low_gain: run.weight.as_ref().map(|w| weight_low_gain(&w.num, &w.den)),
            wm_high_gain: run
                .weight
                .as_ref()
                .map(|w| weight_high_gain(&w.num, &w.den)),
            crossover_hz: run.tuned.as_ref().map(|t| t.design.crossover_hz),
            ms: rs.of_kind(ReceiptKind::SensitivityPeak).map(|r| r.value),
            validation_fit_percent: run.validation_fit.as_ref().map(|f| f.fit_percent[0]),
            out_dir,
            physical: Vec::new(),
            physical_error: None,
        }
    }

    /// Adds the grey-box fit of `opts` on the run's identification log.
    fn add_physical(&mut self, run: &PipelineRun, opts: &GreyBoxOptions) {
        let log = &run.runs[run.nominal].log;
        match crate::greybox::fit_log(log, opts) {
            Ok(fit) => {
                self.physical = fit
                    .parameters
                    .into_iter()
                    .map(|p| UnitParameter {
                        name: p.name,
                        unit: p.unit,
                        value: p.value,
                        interval: p.interval,
                        status: p.status,
                    })
                    .collect();
                if !fit.converged {
                    self.physical_error = Some(format!(
                        "grey-box fit did not converge in {} iterations (values where it \
                         stopped)",
                        fit.iterations
                    ));
                }
            }
            Err(e) => self.physical_error = Some(e.to_string()),
        }
    }

    fn error(serial: &str, e: &Error) -> Self {
        Self {
            serial: serial.into(),
            status: "error",
            error: Some(e.to_string()),
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
#[derive(Debug, Clone, Serialize)]
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
#[derive(Debug, Clone, Serialize)]
pub struct FleetSummary {
    /// [`FLEET_SCHEMA`].
    pub schema: &'static str,
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
            schema: FLEET_SCHEMA,
            layout,
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

/// Options of [`run_fleet`].
#[derive(Debug, Clone, Default)]
pub struct FleetOptions {
    /// Worker threads (None: the available parallelism); capped by [`worker_threads`].
    pub jobs: Option<usize>,
    /// Write each unit's outputs to `<out>/<serial>/` and the summary to `<out>/fleet.json`.
    pub out_dir: Option<PathBuf>,
    /// Fit this physical structure on each unit's identification run (see the module docs).
    pub physical: Option<GreyBoxOptions>,
}

/// The fleet summary written at the top of the output directory.
pub const FLEET_SUMMARY_FILE: &str = "fleet.json";

/// Most worker threads [`run_fleet`] starts, whatever `--jobs` asks for.
pub const MAX_JOBS: usize = 256;

/// Worker threads for `units` units: `jobs` (1..=[`MAX_JOBS`]) or, without it, the available
/// parallelism; never more than the number of units (one thread per unit at most) nor more than
/// the available parallelism (more threads than cores only add contention).
///
/// # Errors
/// [`Error::InvalidArgument`] for `jobs` outside 1..=[`MAX_JOBS`].
pub fn worker_threads(jobs: Option<usize>, units: usize) -> Result<usize> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if let Some(j) = jobs {
        if !(1..=MAX_JOBS).contains(&j) {
            return Err(Error::InvalidArgument(format!(
                "--jobs must be in 1..={MAX_JOBS}, got {j}"
            )));
        }
    }
    Ok(jobs.unwrap_or(cores).min(cores).min(units).max(1))
}

/// Runs the template on every unit of `dir` (see the module docs). `on_unit_done` is called
/// (from worker threads) with each serial number as its pipeline finishes. Errors only for an
/// unreadable fleet directory, a bad template, or an output directory that cannot be taken
/// (unwritable, locked by another run, or holding a file ferrosid did not write where an
/// output goes — checked for every unit before any unit is computed); per-unit
/// failures are in the summary.
pub fn run_fleet(
    dir: &Path,
    template: &LoadedConfig,
    opts: &FleetOptions,
    on_unit_done: &(dyn Fn(&str) + Sync),
) -> Result<FleetSummary> {
    if let Some(g) = &opts.physical {
        g.check()?;
    }
    let (layout, serials) = discover_units(dir)?;
    // Every output directory is taken (locked, and checked for files ferrosid did not write)
    // before any unit is computed: a foreign file in the last unit's directory stops the fleet
    // before the first minute of work, not after it.
    let mut top = match &opts.out_dir {
        Some(o) => {
            let top = OutputDir::acquire(o)?;
            top.check_replaceable([Path::new(FLEET_SUMMARY_FILE)])?;
            Some(top)
        }
        None => None,
    };
    let mut unit_dirs: Vec<Option<OutputDir>> = match &opts.out_dir {
        Some(o) => serials
            .iter()
            .map(|serial| prepare_output_dir(&o.join(serial)).map(Some))
            .collect::<Result<_>>()?,
        None => serials.iter().map(|_| None).collect(),
    };
    let threads = worker_threads(opts.jobs, serials.len())?;
    let builder = rayon::ThreadPoolBuilder::new().num_threads(threads);
    let pool = builder.build().map_err(|e| {
        Error::InvalidArgument(format!("cannot start {:?} worker threads: {e}", opts.jobs))
    })?;
    let units: Vec<UnitResult> = pool.install(|| {
        serials
            .par_iter()
            .zip(unit_dirs.par_iter_mut())
            .map(|(serial, unit_dir)| {
                let r = unit_config(template, dir, layout, serial).and_then(|cfg| {
                    let run = run_pipeline(&cfg, &|_| {})?;
                    let out = match unit_dir {
                        Some(d) => {
                            write_outputs_to(&run, d)?;
                            Some(d.path().to_string_lossy().replace('\\', "/"))
                        }
                        None => None,
                    };
                    let mut u = UnitResult::from_run(serial, &run, out);
                    if let Some(g) = &opts.physical {
                        u.add_physical(&run, g);
                    }
                    Ok(u)
                });
                on_unit_done(serial);
                match r {
                    Ok(u) => u,
                    Err(e) => UnitResult::error(serial, &e),
                }
            })
            .collect()
    });
    drop(unit_dirs);
    let s = &template.config.signals;
    let summary = FleetSummary::new(layout, units, &s.output_unit, &s.input_unit);
    if let Some(top) = &mut top {
        top.write(Path::new(FLEET_SUMMARY_FILE), &json_pretty(&summary)?)?;
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distribution_statistics() {
        let d = Distribution::of("x", "Hz", &[3.0, 1.0, 2.0, f64::NAN, 4.0]).unwrap();
        assert_eq!(
            (d.count, d.min, d.max, d.median, d.mean),
            (4, 1.0, 4.0, 2.5, 2.5)
        );
        assert!((d.std - (5.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert!(Distribution::of("x", "", &[f64::NAN]).is_none());
    }
}
