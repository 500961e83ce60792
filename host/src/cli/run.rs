//! `ferrosid run PIPELINE.toml`: re-executes the whole chain from raw logs to receipts
//! (ingest → preprocess → ETFE + coherence → N4SID → validation → audit → W_m → robust PID →
//! receipts; see [`crate::pipeline`]) and writes into the output directory:
//!
//! * `receipts.json` — every receipt with value, limit and pass/fail, plus the evidence and the
//!   provenance (schema `ferrosid.pipeline.receipts/1`, docs/receipts-schema.md);
//! * `model.json` — the identified discrete model `{"a","b","c","d","ts"}` (for
//!   `ferrosid gap --sim` and `ferrosid codegen --model`);
//! * `pid.json`, `wm.json` — the tuned controller and the uncertainty weight (for
//!   `ferrosid codegen --pid/--wm`), when they exist;
//! * `report.html` — the self-contained report; `figures/*.svg` — its figures.
//!
//! Output directory: `--out DIR`, else `output_dir` of the pipeline file (relative to that
//! file), else `out` in the current directory. It is checked before anything is computed: it is
//! created if missing, locked (`.ferrosid.lock`) against a concurrent run, and ferrosid only
//! replaces or removes files it wrote there itself (listed in `.ferrosid-manifest`); see
//! [`crate::io::file_safety`]. The same logs and settings give byte-identical
//! files.
//!
//! Exit status: 0 when every receipt passes, 1 when any receipt fails (the files are written
//! either way), 3 for unusable data or a bad pipeline file (named with file, line and key),
//! 4 when identification fails numerically.
use super::output::emit as print;
use super::ExitCode;
use crate::error::Result;
use crate::output::{prepare_output_dir, write_outputs_to};
use crate::pipeline::{run_pipeline, LoadedConfig, ReceiptsDocument};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;

/// Flags of `ferrosid run`.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Examples:\n  ferrosid run examples/pipeline.toml\n  \
    ferrosid run examples/pipeline.toml --out build/axis1 --json > receipts.json\n\n\
    Exit status: 0 all receipts pass, 1 a receipt fails, 3 data or pipeline-file error, \
    4 numerical failure.")]
pub struct Args {
    /// The pipeline file (TOML; schema in docs/pipeline-schema.md).
    #[arg(value_name = "PIPELINE.toml")]
    pub pipeline: PathBuf,
    /// Output directory (default: `output_dir` from the pipeline file, else ./out).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print receipts.json on stdout instead of the summary table.
    #[arg(long)]
    pub json: bool,
}

fn spinner() -> ProgressBar {
    let pb = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template("{spinner} pipeline: {msg} {elapsed}") {
        pb.set_style(style);
    }
    if !pb.is_hidden() {
        pb.enable_steady_tick(std::time::Duration::from_millis(100));
    }
    pb
}

/// Runs `ferrosid run`.
pub fn run(args: &Args) -> Result<ExitCode> {
    // Regular file, size cap, UTF-8 (a UTF-16 file is named as such) before the TOML parser.
    crate::io::input::read_text(&args.pipeline)?;
    let cfg = LoadedConfig::load(&args.pipeline)?;
    let out_dir = match (&args.out, &cfg.config.output_dir) {
        (Some(o), _) => o.clone(),
        (None, Some(o)) => cfg.resolve(o),
        (None, None) => PathBuf::from("out"),
    };
    // File safety before any computation: the directory is writable, locked against a
    // concurrent run, and holds no file of ours' names that ferrosid did not write.
    let mut out = prepare_output_dir(&out_dir)?;
    if out_dir
        .join(crate::io::file_safety::INCOMPLETE_FILE)
        .exists()
    {
        super::output::warn(&format!(
            "{}: an earlier run was killed while it replaced its files (it holds {}); this run \
             replaces them all",
            out_dir.display(),
            crate::io::file_safety::INCOMPLETE_FILE
        ));
    }
    let pb = spinner();
    let result = run_pipeline(&cfg, &|stage| pb.set_message(stage.to_string()));
    pb.finish_and_clear();
    let run = result?;
    let written = write_outputs_to(&run, &mut out)?;
    drop(out);
    let doc = ReceiptsDocument::from_run(&run);
    if args.json {
        print(&doc.to_json()?)?;
    } else {
        let mut s = String::new();
        s.push_str(&format!("{}\n", run.title));
        s.push_str(&format!(
            "  model: order {} at {} Hz from `{}`; {}\n",
            run.ident.order,
            crate::pipeline::fmt_num(1.0 / run.model().ts),
            run.nominal_run().name,
            match run.tuned() {
                Some(t) => format!(
                    "PID crossover {} Hz (target {} Hz)",
                    crate::pipeline::fmt_num(t.design.crossover_hz),
                    crate::pipeline::fmt_num(t.target_crossover_hz)
                ),
                None => "no controller (tuning infeasible)".into(),
            }
        ));
        s.push_str(&crate::pipeline::remedy::summary_lines(&run));
        s.push_str(&run.physical.summary_line());
        s.push('\n');
        s.push_str(&doc.summary_text());
        s.push('\n');
        if doc.all_pass {
            s.push_str(&format!("PASS: all {} receipts hold\n", doc.receipts.len()));
        } else {
            let failed: Vec<&str> = run.receipts.failed().map(|r| r.name.as_str()).collect();
            s.push_str(&format!(
                "FAIL: {} of {} receipts fail ({})\n",
                doc.failed,
                doc.receipts.len(),
                failed.join(", ")
            ));
        }
        s.push_str(&format!(
            "wrote {} files to {} (report: {})\n",
            written.len(),
            out_dir.display(),
            out_dir.join("report.html").display()
        ));
        print(&s)?;
    }
    Ok(if doc.all_pass {
        ExitCode::Ok
    } else {
        ExitCode::CheckFailed
    })
}
