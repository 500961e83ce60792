//! `run_pipeline`: [`ferrosid::pipeline::run_pipeline`] on a PIPELINE.toml — the function
//! `ferrosid run` calls — kept as a [`PipelineRun`] object whose methods give the CLI's
//! outputs: `receipts.json` (`ferrosid run --json`), `model.json`, the self-contained HTML
//! report with its inline SVG figures, the output directory, and the firmware header.
use crate::{json_text, run_released, to_py_err};
use ferrosid::pipeline::{LoadedConfig, ReceiptsDocument};
use pyo3::prelude::*;
use std::path::PathBuf;

/// A finished pipeline run (immutable).
#[pyclass(module = "ferrosid._native", frozen)]
pub struct PipelineRun {
    run: ferrosid::pipeline::PipelineRun,
    config_dir: PathBuf,
    output_dir: Option<PathBuf>,
}

#[pymethods]
impl PipelineRun {
    /// `receipts.json`: what `ferrosid run --json` prints.
    fn receipts_json(&self, py: Python<'_>) -> PyResult<String> {
        run_released(py, || ReceiptsDocument::from_run(&self.run).to_json())
    }

    /// `model.json`: G0 with its operating point.
    fn model_json(&self, py: Python<'_>) -> PyResult<String> {
        run_released(py, || json_text(&self.run.model_file()))
    }

    /// The plain-text receipts table `ferrosid run` prints.
    fn summary_text(&self) -> String {
        ReceiptsDocument::from_run(&self.run).summary_text()
    }

    /// `report.html`: the self-contained report with inline SVG figures.
    fn report_html(&self, py: Python<'_>) -> PyResult<String> {
        run_released(py, || {
            let figs = ferrosid::report::figures(&self.run)?;
            ferrosid::report::render_html(&self.run, &figs)
        })
    }

    /// The report's figures as (name, caption, SVG document).
    fn figures(&self, py: Python<'_>) -> PyResult<Vec<(String, String, String)>> {
        run_released(py, || {
            Ok(ferrosid::report::figures(&self.run)?
                .into_iter()
                .map(|f| (f.name.to_string(), f.caption, f.svg))
                .collect())
        })
    }

    /// Writes the run's output directory as `ferrosid run --out DIR` does (receipts.json,
    /// model.json, pid.json, wm.json, report.html, figures/); `None`: the pipeline file's
    /// `output_dir`, else `out`. Returns the directory.
    #[pyo3(signature = (out=None))]
    fn write_outputs(&self, py: Python<'_>, out: Option<PathBuf>) -> PyResult<PathBuf> {
        let dir = out
            .or_else(|| self.output_dir.as_ref().map(|o| self.config_dir.join(o)))
            .unwrap_or_else(|| PathBuf::from("out"));
        run_released(py, || {
            let mut d = ferrosid::output::prepare_output_dir(&dir)?;
            ferrosid::output::write_outputs_to(&self.run, &mut d)?;
            Ok(dir.clone())
        })
    }

    /// The firmware header and Rust module of the run (model with its operating point, the
    /// tuned PID, W_m and the receipts): (C header, Rust module).
    #[pyo3(signature = (prefix="ferrosid"))]
    fn codegen(&self, py: Python<'_>, prefix: &str) -> PyResult<(String, String)> {
        run_released(py, || {
            let parts = self.run.codegen_parts()?;
            let opts = ferrosid::ops::codegen::CodegenOptions {
                prefix: prefix.into(),
                ..Default::default()
            };
            let input = ferrosid::ops::codegen::codegen_input(parts, &opts)?;
            let g = ferrosid_codegen::generate(&input)
                .map_err(|e| ferrosid::Error::InvalidArgument(format!("code generation: {e}")))?;
            Ok((g.c_header, g.rust_module))
        })
    }

    /// True when every receipt passed.
    #[getter]
    fn all_pass(&self) -> bool {
        self.run.receipts.all_pass
    }
}

/// Runs the pipeline of `path` (a PIPELINE.toml; log paths relative to it) — `ferrosid run`
/// without writing files.
#[pyfunction]
pub fn run_pipeline(py: Python<'_>, path: PathBuf) -> PyResult<PipelineRun> {
    let cfg = LoadedConfig::load(&path).map_err(|e| to_py_err(py, &e))?;
    let output_dir = cfg.config.output_dir.clone();
    let config_dir = cfg.base_dir.clone();
    let run = run_released(py, || ferrosid::pipeline::run_pipeline(&cfg, &|_| {}))?;
    Ok(PipelineRun {
        run,
        config_dir,
        output_dir,
    })
}
