//! `ferrosid codegen --control receipts.json` (issue 14): the controller a pipeline run chose
//! (pid-notch, hinf, mpc) is generated from the run's files exactly as the run generates it
//! itself. For each method the bundled example's pipeline runs in process, writes its outputs
//! (`ferrosid::output::write_outputs`), and the command line (through the real parser)
//! `codegen --model model.json --wm wm.json --control receipts.json` builds a generator input
//! whose state-controller block equals the one of the run's own `codegen_parts` — the same
//! matrices, rails, back-calculation gain, PID + notch biquads or MPC QP data (the MPC is
//! re-designed from the model file and must reproduce the run's). Mismatches are refused:
//! the MPC record against another model, a record of a failed design, a file that is not a
//! run's receipts.
use std::path::{Path, PathBuf};

use clap::Parser as _;
use ferrosid::pipeline::{run_pipeline, LoadedConfig, PipelineRun};
use ferrosid_tests::repo_root;

fn example_path() -> PathBuf {
    repo_root().join("examples").join("pipeline.toml")
}

fn run(extra: &str) -> PipelineRun {
    let t = std::fs::read_to_string(example_path()).unwrap();
    let t = t.replace("[gap]\nrun = \"always\"", "[gap]\nrun = \"never\"");
    let t = match t.find("[physical]") {
        Some(i) => t[..i].to_string(),
        None => t,
    };
    let anchor = "reference_amplitude = 5.0   # rad/s speed step\n";
    assert!(t.contains(anchor), "the example's [control] changed");
    let t = t.replace(anchor, &format!("{anchor}{extra}\n"));
    let cfg = LoadedConfig::from_text(&example_path(), &t).unwrap();
    run_pipeline(&cfg, &|_| {}).unwrap()
}

fn args(dir: &Path, control: &Path) -> ferrosid::cli::codegen::Args {
    let cli = ferrosid::cli::Cli::try_parse_from([
        "ferrosid".as_ref(),
        "codegen".as_ref(),
        "--model".as_ref(),
        dir.join("model.json").as_os_str(),
        "--wm".as_ref(),
        dir.join("wm.json").as_os_str(),
        "--control".as_ref(),
        control.as_os_str(),
        "--out-dir".as_ref(),
        dir.join("gen").as_os_str(),
        "--prefix".as_ref(),
        "axis1".as_ref(),
    ])
    .unwrap();
    let ferrosid::cli::Command::Codegen(a) = cli.command else {
        panic!("codegen arguments")
    };
    a
}

/// Runs `method`, writes its outputs into a fresh directory and compares the block read back
/// from the files with the run's own. Returns the directory.
fn check(name: &str, extra: &str) -> PathBuf {
    let run = run(extra);
    let own = run
        .codegen_parts()
        .unwrap()
        .state_controller
        .expect("the run's own block");
    let dir = std::env::temp_dir().join(format!("ferrosid-cgctl-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    ferrosid::output::write_outputs(&run, &dir).unwrap();
    let receipts = dir.join("receipts.json");
    let input = ferrosid::cli::codegen::build_input(&args(&dir, &receipts)).unwrap();
    let read = input.state_controller.clone().expect("block from the files");
    assert_eq!(read.method, own.method);
    assert_eq!(read.matrices, own.matrices, "{name}: matrices");
    assert_eq!(read.saturation, own.saturation, "{name}: rails / anti-windup gain");
    assert_eq!(read.pid_notch, own.pid_notch, "{name}: PID + notch block");
    assert_eq!(read.mpc, own.mpc, "{name}: MPC data");
    match name {
        "pid-notch" => assert!(read.pid_notch.is_some()),
        "hinf" => assert!(read.saturation.is_some()),
        _ => assert!(read.mpc.is_some()),
    }
    // The files generate (and the C header holds the block).
    let files = ferrosid_codegen::generate(&input).unwrap();
    assert!(files.c_header.contains("AXIS1_HAS_STATE_CONTROLLER") || read.mpc.is_some());
    dir
}

#[test]
fn pid_notch_from_files_equals_the_runs_block() {
    let dir = check("pid-notch", "method = \"pid-notch\"");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn hinf_from_files_equals_the_runs_block() {
    let dir = check("hinf", "method = \"hinf\"\nhinf_order = 4");
    // A record of a failed design is refused, naming the file.
    let receipts = dir.join("receipts.json");
    let text = std::fs::read_to_string(&receipts).unwrap();
    let failed = text.replacen("\"status\": \"designed\"", "\"status\": \"failed\"", 1);
    assert_ne!(failed, text);
    let bad = dir.join("failed.json");
    std::fs::write(&bad, failed).unwrap();
    let e = ferrosid::cli::codegen::build_input(&args(&dir, &bad)).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("failed.json") && msg.contains("failed"), "{msg}");
    // Not a run's receipts (the W_m file): a parse error naming the file.
    let e = ferrosid::cli::codegen::build_input(&args(&dir, &dir.join("wm.json"))).unwrap_err();
    assert!(e.to_string().contains("wm.json"), "{e}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn mpc_from_files_equals_the_runs_block_and_refuses_another_model() {
    let dir = check("mpc", "method = \"mpc\"\nmpc_horizon = 10");
    // Another model (the plant's B scaled): the re-designed law differs, refused.
    let model = dir.join("model.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    let b = v.get_mut("b").expect("model.json has b");
    for row in b.as_array_mut().unwrap() {
        for x in row.as_array_mut().unwrap() {
            *x = serde_json::json!(x.as_f64().unwrap() * 1.5);
        }
    }
    std::fs::write(&model, serde_json::to_string(&v).unwrap()).unwrap();
    let e = ferrosid::cli::codegen::build_input(&args(&dir, &dir.join("receipts.json")))
        .unwrap_err();
    assert!(
        e.to_string().contains("another model") && e.to_string().contains("receipts.json"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(dir);
}
