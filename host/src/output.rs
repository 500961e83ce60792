//! A finished run's output directory: `receipts.json`, `model.json`, `pid.json`, `wm.json`,
//! `report.html` and `figures/*.svg`, written atomically through
//! [`crate::io::file_safety::OutputDir`].
//!
//! This sits above [`crate::report`] in the layer table (`host/tests/layers.rs`): the pipeline
//! computes a [`PipelineRun`], the report renders it, and this module writes both renderings
//! and the JSON documents to disk. The same logs and settings give byte-identical files.
use crate::error::Result;
use crate::io::file_safety::OutputDir;
use crate::pipeline::{json_pretty, PipelineRun, ReceiptsDocument};
use std::path::{Path, PathBuf};

/// Files written by [`write_outputs`], relative to the output directory.
pub const OUTPUT_FILES: [&str; 6] = [
    "receipts.json",
    "compensation.json",
    "model.json",
    "pid.json",
    "wm.json",
    "report.html",
];

/// Every path (relative to the output directory) that [`write_outputs`] may write or remove:
/// [`OUTPUT_FILES`] and `figures/<name>.svg` for each of [`crate::report::FIGURE_NAMES`].
pub fn output_paths() -> Vec<PathBuf> {
    OUTPUT_FILES
        .iter()
        .chain(&crate::pipeline::control_methods::METHOD_RECEIPT_FILES)
        .map(PathBuf::from)
        .chain(
            crate::report::FIGURE_NAMES
                .iter()
                .map(|n| Path::new("figures").join(format!("{n}.svg"))),
        )
        .collect()
}

/// Takes `dir` for writing before any computation (see [`crate::io::file_safety`]): creates
/// it, takes its lock, and checks that none of [`output_paths`] exists there unless ferrosid
/// wrote it.
///
/// # Errors
/// [`Error::Io`] naming the directory, the lock holder or the file that would be replaced.
pub fn prepare_output_dir(dir: &Path) -> Result<OutputDir> {
    let out = OutputDir::acquire(dir)?;
    let paths = output_paths();
    out.check_replaceable(paths.iter().map(PathBuf::as_path))?;
    Ok(out)
}

/// Writes `receipts.json`, `model.json` (`{"a","b","c","d","ts"}`, the discrete G0 for
/// `ferrosid gap --sim` and `ferrosid codegen --model`), `pid.json` (the tuning result, for
/// `codegen --pid`; absent without a controller), `wm.json` (the fitted weight, for
/// `codegen --wm`; absent without one), `report.html` and `figures/*.svg` into `dir` (created
/// if missing), through [`prepare_output_dir`] and [`write_outputs_to`]. Returns the paths
/// written.
pub fn write_outputs(run: &PipelineRun, dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = prepare_output_dir(dir)?;
    write_outputs_to(run, &mut out)
}

/// Writes the outputs of `run` into a held output directory. Everything is rendered in
/// memory first, then written as one step ([`OutputDir::write_all`]): a full disk or a crash
/// while rendering leaves the previous run's files as they were. Every file is listed in the
/// directory's manifest with its digest; `pid.json`/`wm.json` and figures that this run does
/// not produce are removed only when an earlier ferrosid run wrote them and they are unchanged
/// (the manifest says so), so the directory describes this run and no user file is ever
/// deleted.
pub fn write_outputs_to(run: &PipelineRun, out: &mut OutputDir) -> Result<Vec<PathBuf>> {
    let mut files: Vec<(PathBuf, String)> = Vec::new();
    let mut stale: Vec<PathBuf> = Vec::new();
    let mut put = |rel: &str, text: Option<String>| match text {
        Some(t) => files.push((PathBuf::from(rel), t)),
        None => stale.push(PathBuf::from(rel)),
    };
    let doc = ReceiptsDocument::from_run(run);
    put("receipts.json", Some(doc.to_json()?));
    // `[control] methods`: the other methods' receipts, each as its own run would write it.
    let per_method = crate::pipeline::control_methods::method_documents(run)?;
    for name in crate::pipeline::control_methods::METHOD_RECEIPT_FILES {
        let json = per_method
            .iter()
            .find(|(f, _)| f == name)
            .map(|(_, j)| j.clone());
        put(name, json);
    }
    put("model.json", Some(json_pretty(&run.model_file())?));
    put("pid.json", run.tuned().map(json_pretty).transpose()?);
    put("wm.json", run.weight().map(json_pretty).transpose()?);
    put(
        "compensation.json",
        run.compensation
            .decision()
            .map(|d| json_pretty(&d.file()))
            .transpose()?,
    );
    let figures = crate::report::figures(run)?;
    for name in crate::report::FIGURE_NAMES {
        let rel = format!("figures/{name}.svg");
        put(
            &rel,
            figures
                .iter()
                .find(|f| f.name == name)
                .map(|f| f.svg.clone()),
        );
    }
    // Figures beyond the fixed names (none today) are written too.
    for f in figures
        .iter()
        .filter(|f| !crate::report::FIGURE_NAMES.contains(&f.name))
    {
        put(&format!("figures/{}.svg", f.name), Some(f.svg.clone()));
    }
    put(
        "report.html",
        Some(crate::report::render_html(run, &figures)?),
    );
    out.write_all(&files, &stale)
}
