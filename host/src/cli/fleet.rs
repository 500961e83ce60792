//! `ferrosid fleet DIR`: the pipeline on every unit (serial number) of a fleet directory, in
//! parallel, with a summary of the parameter distributions across units (see
//! [`crate::fleet`] for the directory layouts and the statistics).
//!
//! Each unit's outputs (receipts, model, report) go to `<out>/<serial>/`, the summary to
//! `<out>/fleet.json` (default `<out>` = `out/fleet` in the current directory).
//!
//! `--shard K/N` runs the K-th of N disjoint shards of the units (default output
//! `out/fleet-shard-K-of-N`), and `ferrosid fleet merge SHARD...` combines the shards'
//! `fleet.json` files into the whole fleet's summary (see [`crate::fleet::shard`]).
//!
//! Exit status: 0 when every unit passes every receipt, 1 when a unit fails a receipt or its
//! pipeline could not run (the table says which), 3 when the fleet directory, the template or
//! a shard summary is unusable.
use super::output::emit as print;
use super::ExitCode;
use crate::error::{Error, Result};
use crate::fleet::{run_fleet, FleetOptions, FleetSummary, Shard, OUTLIER_Z};
use crate::pipeline::physical_stage::PhysicalConfig;
use crate::pipeline::{fmt_num, LoadedConfig};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;

/// Flags of `ferrosid fleet`.
#[derive(Debug, Clone, clap::Args)]
#[command(
    after_help = "Examples:\n  ferrosid fleet examples/fleet\n  \
    ferrosid fleet logs/line3 --pipeline axis.toml --jobs 4 --json > fleet.json\n  \
    ferrosid fleet logs/line3 --shard 2/4 --out out/shard2   # one array job of four\n  \
    ferrosid fleet merge out/shard1 out/shard2 out/shard3 out/shard4 --out out/fleet\n\n\
    Layouts: DIR/<serial>/<file> (one subdirectory per unit) or DIR/<serial>_<file>.\n\
    Exit status: 0 all units pass, 1 a unit fails or errors, 3 unusable directory, template \
    or shard summary.",
    args_conflicts_with_subcommands = true
)]
pub struct Args {
    /// `merge`: combine shard summaries instead of running a fleet.
    #[command(subcommand)]
    pub command: Option<FleetCommand>,
    /// Fleet directory (a directory named `merge` must be given as `./merge`).
    #[arg(value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Run only the K-th of N shards of the units (1 <= K <= N; units dealt round-robin in
    /// serial-number order), e.g. one array job of a batch scheduler; combine with `fleet merge`.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// Pipeline template (default: DIR/pipeline.toml); its log paths are per unit.
    #[arg(long, value_name = "TEMPLATE.toml")]
    pub pipeline: Option<PathBuf>,
    /// Worker threads, 1..=256 (default: one per CPU; never more than the CPUs or the units).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Output directory for per-unit results and fleet.json (default: out/fleet).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print the summary as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Fit this physical structure (grey box: stage, stage-velocity, dc-motor, two-mass,
    /// two-mass-position, two-mass-lag) on each unit's identification run and report the parameters'
    /// distributions in physical units, flagging units outside the fleet's spread.
    #[arg(long, value_name = "NAME")]
    pub structure: Option<String>,
    /// A parameter of --structure known from elsewhere, held fixed (SI units), e.g. Kt=1.
    #[arg(long, value_name = "NAME=VALUE", requires = "structure")]
    pub known: Vec<String>,
}

/// Subcommands of `ferrosid fleet`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum FleetCommand {
    /// Combine the fleet.json of every shard (`fleet --shard K/N`) into the fleet's summary.
    Merge(MergeArgs),
}

/// Flags of `ferrosid fleet merge`.
#[derive(Debug, Clone, clap::Args)]
pub struct MergeArgs {
    /// Shard summaries: fleet.json files, or the shards' output directories holding one.
    #[arg(value_name = "SHARD", required = true)]
    pub shards: Vec<PathBuf>,
    /// Write the merged summary to DIR/fleet.json as well.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print the summary as JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

fn opt(v: Option<f64>) -> String {
    v.map_or("-".into(), fmt_num)
}

fn table(rows: &[Vec<String>], right: &[bool]) -> String {
    let ncol = rows.iter().map(|r| r.len()).max().unwrap_or(0);
    let w: Vec<usize> = (0..ncol)
        .map(|j| {
            rows.iter()
                .map(|r| r.get(j).map_or(0, |c| c.chars().count()))
                .max()
                .unwrap_or(0)
        })
        .collect();
    let mut s = String::new();
    for r in rows {
        let mut line = String::from(" ");
        for (j, wj) in w.iter().enumerate() {
            let c = r.get(j).map_or("", |c| c.as_str());
            let pad = " ".repeat(wj - c.chars().count());
            line.push(' ');
            if right.get(j).copied().unwrap_or(false) {
                line.push_str(&pad);
                line.push_str(c);
            } else {
                line.push_str(c);
                line.push_str(&pad);
            }
            line.push(' ');
        }
        s.push_str(line.trim_end());
        s.push('\n');
    }
    s
}

/// The human-readable summary.
pub fn summary_text(dir: &str, s: &FleetSummary) -> String {
    let mut out = format!(
        "fleet {dir}: {} units ({:?} layout): {} pass, {} fail, {} error\n\n",
        s.units.len(),
        s.layout,
        s.units_pass,
        s.units_fail,
        s.units_error
    )
    .replace("Subdirectories", "subdirectory")
    .replace("Prefix", "file-prefix");
    if let Some(sh) = &s.shard {
        out.insert_str(
            out.len() - 1,
            &format!(
                "shard {}/{} of a fleet of {} units\n",
                sh.index, sh.count, sh.units_total
            ),
        );
    }
    let nmodes = s
        .units
        .iter()
        .map(|u| u.oscillatory().len())
        .max()
        .unwrap_or(0)
        .min(3);
    let mut head = vec![
        "serial".to_string(),
        "status".into(),
        "receipts".into(),
        "order".into(),
        "dc gain".into(),
    ];
    for k in 1..=nmodes {
        head.push(format!("f{k} (Hz)"));
        head.push(format!("ζ{k}"));
    }
    head.extend(["|W_m(0)|", "|W_m(∞)|", "fc (Hz)", "M_s", "fit %"].map(String::from));
    let mut rows = vec![head];
    for u in &s.units {
        let mut r = vec![
            u.serial.clone(),
            u.status.to_string(),
            format!("{}/{}", u.passed, u.receipts),
            u.order.map_or("-".into(), |o| o.to_string()),
            opt(u.dc_gain),
        ];
        let osc = u.oscillatory();
        for k in 0..nmodes {
            r.push(opt(osc.get(k).map(|m| m.natural_hz)));
            r.push(opt(osc.get(k).map(|m| m.damping)));
        }
        r.extend([
            opt(u.wm_low_gain),
            opt(u.wm_high_gain),
            opt(u.crossover_hz),
            opt(u.ms),
            opt(u.validation_fit_percent),
        ]);
        rows.push(r);
    }
    let mut right = vec![false, false, true, true, true];
    right.extend(std::iter::repeat_n(true, 2 * nmodes + 5));
    out.push_str(&table(&rows, &right));
    out.push('\n');
    out.push_str(&distribution_table(&s.parameters));
    out.push_str(&physical_text(s));
    let errs: Vec<String> = s
        .units
        .iter()
        .filter_map(|u| {
            if let Some(e) = &u.error {
                Some(format!("  {}: error: {e}", u.serial))
            } else if !u.failed.is_empty() {
                Some(format!(
                    "  {}: failing receipts: {}",
                    u.serial,
                    u.failed.join(", ")
                ))
            } else {
                None
            }
        })
        .collect();
    if !errs.is_empty() {
        out.push('\n');
        out.push_str(&errs.join("\n"));
        out.push('\n');
    }
    out
}

/// One row per distribution: parameter, unit, n, min, median, max, mean, std.
fn distribution_table(dists: &[crate::fleet::Distribution]) -> String {
    let mut rows = vec![[
        "parameter",
        "unit",
        "n",
        "min",
        "median",
        "max",
        "mean",
        "std",
    ]
    .map(String::from)
    .to_vec()];
    for d in dists {
        rows.push(vec![
            d.parameter.clone(),
            d.unit.clone(),
            d.count.to_string(),
            fmt_num(d.min),
            fmt_num(d.median),
            fmt_num(d.max),
            fmt_num(d.mean),
            fmt_num(d.std),
        ]);
    }
    table(&rows, &[false, false, true, true, true, true, true, true])
}

/// The physical parameters per unit, their distributions and the units outside the spread.
fn physical_text(s: &FleetSummary) -> String {
    if s.physical.is_empty() && s.units.iter().all(|u| u.physical_error.is_none()) {
        return String::new();
    }
    let mut out = String::from(
        "\nphysical parameters per unit (95 % intervals; * = outside the fleet's spread):\n",
    );
    let mut rows = vec![vec![
        "serial".to_string(),
        "parameter".into(),
        "value".into(),
        "interval".into(),
        "unit".into(),
        "status".into(),
    ]];
    for u in &s.units {
        for p in &u.physical {
            let flagged = s
                .outliers
                .iter()
                .any(|o| o.serial == u.serial && o.parameter == p.name);
            rows.push(vec![
                u.serial.clone(),
                p.name.clone(),
                format!("{}{}", fmt_num(p.value), if flagged { " *" } else { "" }),
                p.interval.map_or("-".into(), |[lo, hi]| {
                    format!("[{}, {}]", fmt_num(lo), fmt_num(hi))
                }),
                p.unit.clone(),
                format!("{:?}", p.status).to_lowercase(),
            ]);
        }
        if let Some(e) = &u.physical_error {
            rows.push(vec![
                u.serial.clone(),
                "-".into(),
                "-".into(),
                "-".into(),
                "-".into(),
                format!("fit: {e}"),
            ]);
        }
    }
    out.push_str(&table(&rows, &[false, false, true, true, false, false]));
    out.push_str("\nphysical parameter distributions (estimated values):\n");
    out.push_str(&distribution_table(&s.physical));
    if s.outliers.is_empty() {
        out.push_str(&format!(
            "no unit outside the fleet's spread (modified z-score on log values > {OUTLIER_Z})\n"
        ));
    }
    for o in &s.outliers {
        out.push_str(&format!(
            "  {}: {} = {} outside the fleet's spread (median {}, modified z-score {:.1} > {OUTLIER_Z})\n",
            o.serial,
            o.parameter,
            fmt_num(o.value),
            fmt_num(o.median),
            o.robust_z
        ));
    }
    out
}

/// Runs `ferrosid fleet` (or `ferrosid fleet merge`).
pub fn run(args: &Args) -> Result<ExitCode> {
    if let Some(FleetCommand::Merge(m)) = &args.command {
        return merge(m);
    }
    let Some(dir) = &args.dir else {
        return Err(Error::InvalidArgument(
            "give the fleet directory (ferrosid fleet DIR), or `ferrosid fleet merge SHARD...`"
                .into(),
        ));
    };
    let shard = args.shard.as_deref().map(Shard::parse).transpose()?;
    if !dir.is_dir() {
        return Err(Error::Io {
            file: dir.clone(),
            source: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                if dir.exists() {
                    "not a directory: give the fleet directory holding one log set per unit"
                } else {
                    "fleet directory not found"
                },
            ),
        });
    }
    crate::fleet::worker_threads(args.jobs, 1)?;
    let template_path = args
        .pipeline
        .clone()
        .unwrap_or_else(|| dir.join("pipeline.toml"));
    if template_path.exists() {
        crate::io::input::read_text(&template_path)?;
    }
    if !template_path.is_file() {
        return Err(Error::Data {
            file: template_path,
            msg: "no pipeline template: give --pipeline TEMPLATE.toml or put pipeline.toml in \
                  the fleet directory"
                .into(),
        });
    }
    let template = LoadedConfig::load(&template_path)?;
    let (_, all) = crate::fleet::discover_units(dir)?;
    let n_units = shard.map_or(all.len(), |s| s.select(&all).len());
    let pb = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(n_units as u64), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) =
        ProgressStyle::with_template("fleet [{bar:30}] {pos}/{len} units {msg} {elapsed}")
    {
        pb.set_style(style.progress_chars("=> "));
    }
    let physical = match &args.structure {
        None => None,
        Some(name) => {
            let mut known = std::collections::BTreeMap::new();
            for k in &args.known {
                let (n, v) = super::identify::parse_known(k)?;
                known.insert(n, v);
            }
            let p = PhysicalConfig {
                structure: name.clone(),
                known,
                confidence: None,
                run: None,
            };
            p.options()?;
            Some(p)
        }
    };
    let default_out = match shard {
        Some(s) => format!("out/fleet-shard-{}-of-{}", s.index, s.count),
        None => "out/fleet".into(),
    };
    let opts = FleetOptions {
        physical,
        shard,
        jobs: args.jobs,
        out_dir: Some(
            args.out
                .clone()
                .unwrap_or_else(|| PathBuf::from(default_out)),
        ),
    };
    let summary = run_fleet(dir, &template, &opts, &|serial| {
        pb.set_message(serial.to_string());
        pb.inc(1);
    });
    pb.finish_and_clear();
    report(&dir.display().to_string(), &summary?, args.json)
}

/// Prints a summary (JSON or tables) and maps it to the exit status.
fn report(what: &str, summary: &FleetSummary, json: bool) -> Result<ExitCode> {
    if json {
        print(&crate::pipeline::json_pretty(summary)?)?;
    } else {
        print(&summary_text(what, summary))?;
    }
    Ok(if summary.all_pass() {
        ExitCode::Ok
    } else {
        ExitCode::CheckFailed
    })
}

/// `ferrosid fleet merge`.
fn merge(m: &MergeArgs) -> Result<ExitCode> {
    if let Some(o) = &m.out {
        // The merged summary must not replace one of the shard summaries it is merged from.
        let target = o.join(crate::fleet::FLEET_SUMMARY_FILE);
        let inputs: Vec<PathBuf> = m
            .shards
            .iter()
            .map(|p| {
                if p.is_dir() {
                    p.join(crate::fleet::FLEET_SUMMARY_FILE)
                } else {
                    p.clone()
                }
            })
            .collect();
        let refs: Vec<&std::path::Path> = inputs.iter().map(PathBuf::as_path).collect();
        crate::io::file_safety::refuse_input_overwrite(&target, "--out", &refs)?;
    }
    let shards = m
        .shards
        .iter()
        .map(|p| crate::fleet::shard::read_summary(p))
        .collect::<Result<Vec<_>>>()?;
    let summary = crate::fleet::merge_summaries(&m.shards, shards)?;
    if let Some(o) = &m.out {
        let mut top = crate::io::file_safety::OutputDir::acquire(o)?;
        let name = std::path::Path::new(crate::fleet::FLEET_SUMMARY_FILE);
        top.check_replaceable([name])?;
        top.write(name, &crate::pipeline::json_pretty(&summary)?)?;
    }
    let what = format!("merge of {} shards", m.shards.len());
    report(&what, &summary, m.json)
}
