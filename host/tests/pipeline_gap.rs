//! The pipeline's gap-diagnosis stage on the bundled example (examples/pipeline.toml): skipped
//! when nothing flags, run when a model receipt fails, and its verdict and gap figures agree
//! with `ferrosid gap` run by hand on the files the pipeline wrote (a second path: the model
//! file round trip, the CLI's own log reading and operating point, the same logs).
use ferrosid::output::write_outputs;
use ferrosid::pipeline::gap_stage::GapStage;
use ferrosid::pipeline::{run_pipeline, LoadedConfig};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "ferrosid-pipeline-gap-{name}-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// The bundled pipeline with its `[audit] max_gain_shift_db` replaced by `audit_extra` and
/// `[gap] run = gap_run` added.
fn config(audit_extra: &str, gap_run: &str) -> LoadedConfig {
    let path = examples().join("pipeline.toml");
    let text = std::fs::read_to_string(&path).expect("examples/pipeline.toml");
    assert!(
        text.contains("max_gain_shift_db = 3.0\n"),
        "example pipeline changed"
    );
    let text = text.replace("max_gain_shift_db = 3.0\n", "");
    // The example asks for the diagnosis always; this test sets `[gap] run` itself.
    let text = text.replace("[gap]\nrun = \"always\"\n", "");
    let text = text.replace("[audit]\n", &format!("[audit]\n{audit_extra}"));
    let text = format!("{text}\n[gap]\nrun = \"{gap_run}\"\n");
    LoadedConfig::from_text(&path, &text).expect("config")
}

#[test]
fn skipped_when_nothing_flags_and_never_means_never() {
    let run = run_pipeline(&config("max_gain_shift_db = 3.0\n", "auto"), &|_| {}).expect("run");
    assert!(
        run.receipts.all_pass,
        "the bundled example passes every receipt"
    );
    match &run.gap {
        GapStage::Skipped { reason } => assert!(reason.contains("no flag"), "{reason}"),
        other => panic!("expected skipped, got {other:?}"),
    }
    // A failing audit receipt under `never`: still skipped.
    let run = run_pipeline(&config("max_gain_shift_db = 1.0\n", "never"), &|_| {}).expect("run");
    assert!(!run.receipts.all_pass);
    assert!(matches!(run.gap, GapStage::Skipped { ref reason } if reason.contains("never")));
}

#[test]
fn a_failing_audit_receipt_triggers_the_diagnosis_and_it_matches_the_cli() {
    // The example's gain shift between amplitudes is 2.3 dB: a 1 dB limit fails the receipt.
    let run = run_pipeline(&config("max_gain_shift_db = 1.0\n", "auto"), &|_| {}).expect("run");
    let (triggered_by, report) = match &run.gap {
        GapStage::Diagnosed {
            triggered_by,
            report,
        } => (triggered_by, report),
        other => panic!("expected a diagnosis, got {other:?}"),
    };
    assert!(
        triggered_by.iter().any(|t| t == "audit_gain_shift"),
        "{triggered_by:?}"
    );
    assert!(report.gap_linear <= report.gap_before + 1e-12);
    assert!(report.gap_after.is_finite() && report.noise_floor.nrmse.is_finite());

    // receipts.json and report.html carry it.
    let out = scratch("flagged");
    write_outputs(&run, &out).expect("write");
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("receipts.json")).unwrap()).unwrap();
    let g = &doc["gap_diagnosis"];
    assert_eq!(g["status"], "diagnosed", "{g}");
    assert_eq!(g["report"]["verdict"], report.verdict.as_str());
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<section id=\"gap\">"), "no gap section");
    assert!(
        html.contains(&format!("Verdict: {}", report.verdict)),
        "verdict not shown"
    );

    // Second path: `ferrosid gap` on the model file the run wrote and the raw logs.
    let data = examples().join("data");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_ferrosid"))
        .arg("gap")
        .arg("--sim")
        .arg(out.join("model.json"))
        .arg("--real")
        .arg(data.join("two_mass_low.csv"))
        .arg("--real")
        .arg(data.join("two_mass_high.csv"))
        .arg("--validate")
        .arg(data.join("two_mass_validate.csv"))
        .arg("--json")
        .output()
        .expect("ferrosid gap");
    assert_eq!(
        st.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let cli: Value = serde_json::from_slice(&st.stdout).expect("gap --json");
    assert_eq!(cli["verdict"], report.verdict.as_str(), "verdicts differ");
    // Same operating point, same logs: the figures agree up to the model file's round trip
    // (shortest round-trip floats: bit for bit in practice; 1e-6 relative allowed).
    for (key, ours) in [
        ("gap_before", report.gap_before),
        ("gap_linear", report.gap_linear),
    ] {
        let theirs = cli[key].as_f64().expect(key);
        assert!(
            (theirs - ours).abs() <= 1e-6 * ours.max(1e-3),
            "{key}: pipeline {ours}, cli {theirs}"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}
