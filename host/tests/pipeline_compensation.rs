//! The whole chain on the bundled example (examples/pipeline.toml, which asks for the gap
//! diagnosis always): diagnosis → compensation stage → the flowchart's choice carried out, in
//! receipts.json (typed `compensation` object with both receipt sets), the report's
//! "Compensation" section and the printed summary.
use ferrosid::output::write_outputs;
use ferrosid::pipeline::compensation_stage::Choice;
use ferrosid::pipeline::gap_stage::GapStage;
use ferrosid::pipeline::{run_pipeline, LoadedConfig};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/pipeline.toml")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "ferrosid-pipeline-comp-{name}-{}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn the_bundled_example_runs_the_whole_chain() {
    let cfg = LoadedConfig::load(&example()).expect("config");
    let run = run_pipeline(&cfg, &|_| {}).expect("run");
    let report = match &run.gap {
        GapStage::Diagnosed { report, .. } => report,
        other => panic!("the example asks for the diagnosis always, got {other:?}"),
    };
    let d = run.compensation.decision().expect("the stage decided");
    // The choice follows the verdict (compensation_stage's table).
    match report.verdict.as_str() {
        "none" => assert_eq!(d.choice, Choice::Keep),
        "unexplained" => {
            assert_eq!(d.choice, Choice::WidenWm, "{}", d.reason);
            let r = d.retuned.as_ref().expect("re-tuned design");
            assert!((r.envelope_floor - report.gap_linear).abs() < 1e-12);
            // A wider W_m never raises the crossover.
            assert!(r.crossover_after_hz.unwrap_or(0.0) <= r.crossover_before_hz + 1e-9);
        }
        _ => assert!(!d.stage.effects.is_empty() || !d.stage.not_analysed.is_empty()),
    }
    assert!(!d.receipts_before.is_empty() && !d.receipts_after.is_empty());
    // The run's receipts are the audit receipts plus the chosen design's.
    let names: Vec<&str> = run
        .receipts
        .receipts
        .iter()
        .map(|r| r.name.as_str())
        .collect();
    for r in &d.receipts_after {
        assert!(names.contains(&r.name.as_str()), "{} missing", r.name);
    }
    assert!(d.sensor_noise.is_finite() && d.sensor_noise > 0.0);
    assert!((d.amplitude_tol - 3.0 * d.sensor_noise).abs() < 1e-12);

    let out = scratch("example");
    write_outputs(&run, &out).expect("write");
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("receipts.json")).unwrap()).unwrap();
    let c = &doc["compensation"];
    assert_eq!(c["status"], "decided", "{c}");
    assert_eq!(
        c["receipts_before"].as_array().map(Vec::len),
        Some(d.receipts_before.len())
    );
    assert_eq!(
        c["receipts_after"].as_array().map(Vec::len),
        Some(d.receipts_after.len())
    );
    assert!(c["choice"].is_string() && c["reason"].is_string());
    assert!(c["stage"]["compensation"]["enabled"].is_boolean());
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<section id=\"compensation\">"));
    assert!(html.contains("Receipts before") && html.contains("Receipts after the choice"));
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn the_printed_summary_shows_diagnosis_and_choice() {
    let out = scratch("cli");
    let st = Command::new(env!("CARGO_BIN_EXE_ferrosid"))
        .arg("run")
        .arg(example())
        .arg("--out")
        .arg(&out)
        .output()
        .expect("run ferrosid");
    let stdout = String::from_utf8_lossy(&st.stdout);
    assert!(
        stdout.contains("gap diagnosis (triggered by always): verdict"),
        "{stdout}"
    );
    assert!(stdout.contains("  compensation: "), "{stdout}");
    assert!(stdout.contains("receipts before: "), "{stdout}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn switched_off_never_compensates() {
    let path = example();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.contains("[compensation]\nenabled = true"),
        "example changed"
    );
    let text = text.replace(
        "[compensation]\nenabled = true",
        "[compensation]\nenabled = false",
    );
    let cfg = LoadedConfig::from_text(&path, &text).expect("config");
    let run = run_pipeline(&cfg, &|_| {}).expect("run");
    let d = run.compensation.decision().expect("decided");
    assert_ne!(d.choice, Choice::Compensate);
    assert!(run.compensation_block().is_none());
    assert!(d.stage.effects.iter().all(|e| e.after.is_none()));
}
