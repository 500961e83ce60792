//! A pipeline run to a firmware header without the disk: `PipelineRun::codegen_parts` +
//! `ops::codegen::codegen_input` give the same model, operating point, PID gains, W_m and
//! receipt lines as `ferrosid codegen` reading the run's written files (model.json, pid.json,
//! wm.json, receipts.json); only the provenance digests differ.
mod pipeline_support;

use clap::Parser as _;
use ferrosid::cli::{Cli, Command};
use ferrosid::ops::codegen::{codegen_input, CodegenOptions};
use ferrosid::output::write_outputs;
use ferrosid::pipeline::{run_pipeline, LoadedConfig};
use pipeline_support as sup;
use serde_json::Value;

/// `a` and `b` as JSON trees: same shape and text, numbers within `tol` relative (to the
/// larger magnitude, or 1).
fn same<T: serde::Serialize>(a: &T, b: &T, tol: f64) {
    fn walk(a: &Value, b: &Value, at: &str, tol: f64) {
        match (a, b) {
            (Value::Number(x), Value::Number(y)) => {
                let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                assert!(
                    (x - y).abs() <= tol * (x.abs().max(y.abs()) + 1.0),
                    "{at}: {x} vs {y}"
                );
            }
            (Value::Array(x), Value::Array(y)) => {
                assert_eq!(x.len(), y.len(), "{at}: lengths");
                for (i, (p, q)) in x.iter().zip(y).enumerate() {
                    walk(p, q, &format!("{at}[{i}]"), tol);
                }
            }
            (Value::Object(x), Value::Object(y)) => {
                assert_eq!(x.len(), y.len(), "{at}: keys");
                for (k, p) in x {
                    walk(p, &y[k], &format!("{at}.{k}"), tol);
                }
            }
            _ => assert_eq!(a, b, "{at}"),
        }
    }
    let (a, b) = (
        serde_json::to_value(a).unwrap(),
        serde_json::to_value(b).unwrap(),
    );
    assert!(!a.is_null(), "nothing compared");
    walk(&a, &b, "", tol);
}

#[test]
fn a_run_gives_the_same_codegen_input_as_its_written_files() {
    let toml = sup::setup("pipeline-codegen", "", "");
    let dir = toml.parent().expect("dir").to_path_buf();
    let cfg = LoadedConfig::load(&toml).expect("load");
    let run = run_pipeline(&cfg, &|_| {}).expect("run");
    assert!(
        run.tuned().is_some() && run.weight().is_some(),
        "fixture has a PID and a W_m"
    );
    let out = dir.join("out");
    write_outputs(&run, &out).expect("write");

    let from_run = codegen_input(
        run.codegen_parts().expect("parts"),
        &CodegenOptions {
            prefix: "axis1".into(),
            ..CodegenOptions::default()
        },
    )
    .expect("input from the run");

    let f = |name: &str| out.join(name).display().to_string();
    let argv = [
        "ferrosid",
        "codegen",
        "--model",
        &f("model.json"),
        "--pid",
        &f("pid.json"),
        "--wm",
        &f("wm.json"),
        "--receipts",
        &f("receipts.json"),
        "--prefix",
        "axis1",
        "--out-dir",
        &f("gen"),
    ];
    let cli = Cli::try_parse_from(argv).expect("clap");
    let Command::Codegen(args) = &cli.command else {
        panic!("not codegen")
    };
    let from_files = ferrosid::cli::codegen::build_input(args).expect("input from files");

    // Everything but the source digests agrees: numbers to 1e-14 relative (serde_json's
    // default float parser may land one ulp off when the files are read back), text exactly;
    // the continuous model (inverse ZOH, a matrix logarithm) amplifies that ulp, so 1e-9.
    same(&from_run.model, &from_files.model, 1e-14);
    same(&from_run.continuous, &from_files.continuous, 1e-9);
    same(&from_run.pid, &from_files.pid, 1e-14);
    same(&from_run.weight, &from_files.weight, 1e-14);
    same(
        &from_run.operating_point,
        &from_files.operating_point,
        1e-14,
    );
    assert_eq!(from_run.self_id, from_files.self_id);
    assert!(from_run.operating_point.is_some(), "means were removed");
    assert_eq!(from_run.provenance.receipts, from_files.provenance.receipts);
    assert_eq!(
        from_run.provenance.receipts.len(),
        run.receipts.receipts.len()
    );
    // The run's digests are its inputs (pipeline file and logs), not the written files.
    let labels: Vec<&str> = from_run
        .provenance
        .sources
        .iter()
        .map(|s| s.label.as_str())
        .collect();
    assert!(labels[0].starts_with("pipeline: "), "{labels:?}");
    assert_eq!(labels.len(), 1 + run.inputs.len());
    for (s, i) in from_run.provenance.sources[1..].iter().zip(&run.inputs) {
        assert_eq!(s.sha256, i.sha256);
    }

    let a = ferrosid_codegen::generate(&from_run).expect("generate from run");
    let b = ferrosid_codegen::generate(&from_files).expect("generate from files");
    assert_eq!(format!("{:?}", a.checks), format!("{:?}", b.checks));
    assert!(a.c_header.contains("AXIS1") && b.c_header.contains("AXIS1"));
    // Only the provenance differs, so the content hashes do.
    assert_ne!(a.inputs_sha256, b.inputs_sha256);
}
