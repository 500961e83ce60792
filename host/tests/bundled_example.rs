//! The bundled two-mass example (`examples/pipeline.toml`) as the pipeline tests load it:
//! without the `[physical]` stage (slow in debug, and not what they test), usually without the
//! gap stage, with extra lines appended to `[control]`. Shared by `pipeline_control`,
//! `pipeline_methods`, `pipeline_control_cycles` and `synth_mpc`.
#![allow(dead_code)]
use ferrosid::pipeline::{run_pipeline, LoadedConfig, PipelineRun};
use std::path::{Path, PathBuf};

/// The `[control]` line after which [`with_control`] appends its lines.
pub const CONTROL_ANCHOR: &str = "reference_amplitude = 5.0   # rad/s speed step\n";

/// Path of the example pipeline file.
pub fn example_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/pipeline.toml")
}

/// The example's text up to its `[physical]` section (its gap and compensation stages kept).
pub fn without_physical() -> String {
    let t = std::fs::read_to_string(example_path()).unwrap();
    match t.find("[physical]") {
        Some(i) => t[..i].to_string(),
        None => t,
    }
}

/// `text` with the lines `extra` appended to `[control]` (after [`CONTROL_ANCHOR`]).
pub fn with_control(text: &str, extra: &str) -> String {
    text.replace(CONTROL_ANCHOR, &format!("{CONTROL_ANCHOR}{extra}"))
}

/// The example without the gap, compensation and physical stages, with `extra` lines appended
/// to `[control]`.
pub fn example_text(extra: &str) -> String {
    let t = without_physical().replace("[gap]\nrun = \"always\"", "[gap]\nrun = \"never\"");
    with_control(&t, extra)
}

/// [`example_text`] loaded.
pub fn load(extra: &str) -> ferrosid::error::Result<LoadedConfig> {
    LoadedConfig::from_text(&example_path(), &example_text(extra))
}

/// [`example_text`] run through the pipeline.
pub fn run(extra: &str) -> PipelineRun {
    run_pipeline(&load(extra).unwrap(), &|_| {}).unwrap()
}

/// The run's HTML report.
pub fn report_html(run: &PipelineRun) -> String {
    let figs = ferrosid::report::figures(run).unwrap();
    ferrosid::report::render_html(run, &figs).unwrap()
}

/// The run's code-generation input with the prefix `axis1`.
pub fn codegen_axis1(run: &PipelineRun) -> ferrosid_codegen::CodegenInput {
    ferrosid::ops::codegen::codegen_input(
        run.codegen_parts().unwrap(),
        &ferrosid::ops::codegen::CodegenOptions {
            prefix: "axis1".into(),
            ..Default::default()
        },
    )
    .unwrap()
}

/// Each `(extra, key, what)`: [`example_text`] with the lines `extra` (one or more) fails to
/// load with an error naming `pipeline.toml`, the line of the last extra line, `key` and
/// `what`.
pub fn assert_bad_control_keys(cases: &[(&str, &str, &str)]) {
    // The `reference_amplitude` line is where the extra lines start.
    let line = example_text("")
        .lines()
        .position(|l| l.starts_with("reference_amplitude"))
        .unwrap()
        + 2;
    for &(extra, key, what) in cases {
        let e = load(&format!("{extra}\n")).unwrap_err().to_string();
        let at = line + extra.matches('\n').count();
        assert!(e.contains(&format!("pipeline.toml:{at}")), "{extra}: {e}");
        assert!(e.contains(key) && e.contains(what), "{extra}: {e}");
    }
}
