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
//! A unit's physical parameters are its pipeline's physical stage
//! ([`crate::pipeline::PipelineRun::physical`]): the template's `[physical]` section, or the
//! one [`FleetOptions::physical`] gives every unit (`ferrosid fleet --structure two-mass
//! --known Kt=1`), fitted once by the pipeline on the identification run after its
//! preprocessing — parameters in physical units with 95 % intervals. The summary then carries
//! each parameter's distribution across units and flags, per parameter, the units
//! outside the fleet's spread: modified z-score |0.6745·(x − median)/MAD| > [`OUTLIER_Z`]
//! (Iglewicz & Hoaglin 1993; median and MAD resist the outlier they look for, a mean and a
//! standard deviation would be pulled towards it), computed on log values (every physical
//! parameter is positive and spreads multiplicatively). At least [`MIN_UNITS_FOR_SPREAD`] units
//! are needed.
//!
//! # Shards and distributed engines
//! [`FleetOptions::shard`] runs one of N disjoint shards ([`shard`]); [`merge_summaries`]
//! combines the shard summaries. The per-unit function is [`UnitJob::run`]: a distributed
//! engine maps it over the units and gathers the results with [`FleetSummary::new`].
use crate::error::{Error, Result};
use crate::io::file_safety::OutputDir;
use crate::output::prepare_output_dir;
use crate::output::write_outputs_to;
use crate::pipeline::config::LoadedConfig;
use crate::pipeline::json_pretty;
use crate::pipeline::physical_stage::PhysicalConfig;
use crate::pipeline::run_pipeline;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub mod shard;
mod summary;

pub use shard::{merge_summaries, Shard, ShardInfo};
pub use summary::{
    Distribution, FleetSummary, Outlier, UnitParameter, UnitResult, MIN_UNITS_FOR_SPREAD, OUTLIER_Z,
};

/// Schema identifier of the fleet summary.
pub const FLEET_SCHEMA: &str = "ferrosid.fleet/1";

/// How units are laid out in the fleet directory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
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

/// Options of [`run_fleet`].
#[derive(Debug, Clone, Default)]
pub struct FleetOptions {
    /// Worker threads (None: the available parallelism); capped by [`worker_threads`].
    pub jobs: Option<usize>,
    /// Write each unit's outputs to `<out>/<serial>/` and the summary to `<out>/fleet.json`.
    pub out_dir: Option<PathBuf>,
    /// A `[physical]` section given to every unit's pipeline (replacing the template's), so
    /// that the pipeline's physical stage fits this structure (see the module docs).
    pub physical: Option<PhysicalConfig>,
    /// Run only this shard of the units (see [`Shard`]); the summary then covers it alone.
    pub shard: Option<Shard>,
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
    if let Some(p) = &opts.physical {
        p.options()?;
    }
    let (layout, all) = discover_units(dir)?;
    let serials = match opts.shard {
        Some(shard) => shard.select(&all),
        None => all.clone(),
    };
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
    let unit = UnitJob {
        dir,
        template,
        layout,
        physical: opts.physical.as_ref(),
    };
    let units: Vec<UnitResult> = pool.install(|| {
        serials
            .par_iter()
            .zip(unit_dirs.par_iter_mut())
            .map(|(serial, unit_dir)| {
                let u = unit.run(serial, unit_dir.as_mut());
                on_unit_done(serial);
                u
            })
            .collect()
    });
    drop(unit_dirs);
    let s = &template.config.signals;
    let mut summary = FleetSummary::new(layout, units, &s.output_unit, &s.input_unit);
    summary.shard = opts.shard.map(|sh| sh.info(all.len()));
    if let Some(top) = &mut top {
        top.write(Path::new(FLEET_SUMMARY_FILE), &json_pretty(&summary)?)?;
    }
    Ok(summary)
}

/// What every unit of one fleet shares: the pure per-unit function of the fleet. [`run_fleet`]
/// maps it over the units on threads; a distributed engine (the Python package's Dask
/// example) maps it over the units on workers and gathers the results into
/// [`FleetSummary::new`].
#[derive(Debug, Clone, Copy)]
pub struct UnitJob<'a> {
    /// The fleet directory.
    pub dir: &'a Path,
    /// The pipeline template.
    pub template: &'a LoadedConfig,
    /// The layout [`discover_units`] found.
    pub layout: Layout,
    /// `[physical]` given to every unit (see [`FleetOptions::physical`]).
    pub physical: Option<&'a PhysicalConfig>,
}

impl UnitJob<'_> {
    /// The pipeline on unit `serial`, its outputs written to `out` when given. Never fails: a
    /// unit whose pipeline cannot run is a [`UnitResult`] with status `error` and the message.
    pub fn run(&self, serial: &str, out: Option<&mut OutputDir>) -> UnitResult {
        let r = unit_config(self.template, self.dir, self.layout, serial).and_then(|mut cfg| {
            if let Some(p) = self.physical {
                cfg.config.physical = Some(p.clone());
            }
            let run = run_pipeline(&cfg, &|_| {})?;
            let out = match out {
                Some(d) => {
                    write_outputs_to(&run, d)?;
                    Some(d.path().to_string_lossy().replace('\\', "/"))
                }
                None => None,
            };
            Ok(UnitResult::from_run(serial, &run, out))
        });
        r.unwrap_or_else(|e| UnitResult::error(serial, e.to_string()))
    }
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
