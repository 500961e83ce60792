//! `[control] methods = [...]`: several controller methods in one run on the bundled two-mass
//! example, each method's receipts equal to its own single-method run's, the comparison rows
//! equal to those receipts, and the `method`/`methods` keys refusing bad input with file, line
//! and key.
use crate::bundled_example::{example_text, load, run};
use ferrosid::pipeline::control_methods::{comparison_rows, method_documents, ComparisonRow};
use ferrosid::pipeline::control_stage::{codegen_block, ControlMethod};
use ferrosid::pipeline::{run_pipeline, PipelineRun, ReceiptsDocument};
use ferrosid::robust::receipts::ReceiptKind;
use serde_json::Value;
use std::path::Path;

fn doc(run: &PipelineRun) -> Value {
    serde_json::from_str(&ReceiptsDocument::from_run(run).to_json().unwrap()).unwrap()
}

fn value_of(run: &PipelineRun, k: ReceiptKind) -> Option<f64> {
    run.receipts.of_kind(k).map(|r| r.value)
}

/// A row against the single-method run's receipts: the same numbers.
fn check_row(row: &ComparisonRow, single: &PipelineRun) {
    let m = row.method.name();
    let same = |what: &str, a: Option<f64>, k: ReceiptKind| {
        let b = value_of(single, k).filter(|v| what != "crossover" || v.is_finite());
        assert_eq!(a, b, "{m}: {what} of the table vs the single-method run");
    };
    same("crossover", row.crossover_hz, ReceiptKind::ControllerDesign);
    same("M_s", row.sensitivity_peak, ReceiptKind::SensitivityPeak);
    same("W_m T", row.wm_t_peak, ReceiptKind::RobustStability);
    same(
        "effort",
        row.peak_control_effort,
        ReceiptKind::PeakControlEffort,
    );
    same(
        "overshoot",
        row.step_overshoot_pct,
        ReceiptKind::StepOvershoot,
    );
    same(
        "settling",
        row.step_settling_s,
        ReceiptKind::StepSettlingTime,
    );
    assert_eq!(row.all_pass, single.receipts.all_pass, "{m}: all pass");
    assert_eq!(row.receipts, single.receipts.receipts.len(), "{m}");
    assert_eq!(
        row.controller_order,
        single
            .control
            .as_ref()
            .and_then(|c| c.controller_ss.as_ref())
            .map(|k| k.n_states())
            .or_else(|| {
                (row.method == ControlMethod::Pid).then(|| {
                    let d = single.tuned().unwrap().discrete.as_ref().unwrap();
                    d.den.len() - 1
                })
            }),
        "{m}: order"
    );
}

#[test]
fn several_methods_give_each_single_runs_receipts_and_a_comparison_table() {
    let multi = run("methods = [\"pid\", \"pid-notch\", \"hinf\", \"mpc\"]\n");
    let singles: Vec<(ControlMethod, PipelineRun)> = [
        ("pid", ControlMethod::Pid),
        ("pid-notch", ControlMethod::Loopshape),
        ("hinf", ControlMethod::Hinf),
        ("mpc", ControlMethod::Mpc),
    ]
    .into_iter()
    .map(|(name, m)| (m, run(&format!("method = \"{name}\"\n"))))
    .collect();

    // The primary (pid) is the run's own result, as a single pid run has it.
    let (d_multi, d_pid) = (doc(&multi), doc(&singles[0].1));
    assert_eq!(multi.config.control.method, ControlMethod::Pid);
    assert_eq!(d_multi["receipts"], d_pid["receipts"]);
    assert_eq!(d_multi["crossover_hz"], d_pid["crossover_hz"]);
    assert!(d_multi.get("control").is_none());
    assert!(
        d_pid.get("comparison").is_none(),
        "no comparison with one method"
    );

    // Every other method's file: its single run's receipts, control block and crossover.
    let files = method_documents(&multi).unwrap();
    assert_eq!(
        files.iter().map(|(f, _)| f.as_str()).collect::<Vec<_>>(),
        [
            "receipts.loopshape.json",
            "receipts.hinf.json",
            "receipts.mpc.json"
        ]
    );
    for ((file, json), (m, single)) in files.iter().zip(&singles[1..]) {
        let d: Value = serde_json::from_str(json).unwrap();
        let s = doc(single);
        for key in ["receipts", "control", "crossover_hz", "verdict"] {
            assert_eq!(d[key], s[key], "{file}: {key}");
        }
        assert_eq!(d["provenance"]["settings"]["control"]["method"], m.name());
        assert!(d["provenance"]["settings"]["control"]
            .get("methods")
            .is_none());
        assert!(d.get("comparison").is_none());
        // The codegen block of the file's run is the single run's.
        let view_block = multi
            .comparison
            .iter()
            .find(|r| r.method == *m)
            .and_then(|r| r.control.as_ref())
            .and_then(codegen_block);
        let single_block = single.control.as_ref().and_then(codegen_block);
        assert_eq!(view_block, single_block, "{file}: codegen block");
    }

    // The table: one row per method, primary first, each number the single run's receipt.
    let rows = comparison_rows(&multi);
    assert_eq!(rows.len(), 4);
    assert_eq!(rows[0].receipts_file, "receipts.json");
    for (row, (m, single)) in rows.iter().zip(&singles) {
        assert_eq!(row.method, *m);
        check_row(row, single);
        eprintln!(
            "{:>9}: crossover {:?} Hz, M_s {:?}, W_m T {:?}, effort {:?}/{}, overshoot {:?} %, \
             settling {:?} s, order {:?}, target {:?}, {} receipts, failed {:?}",
            m.name(),
            row.crossover_hz,
            row.sensitivity_peak,
            row.wm_t_peak,
            row.peak_control_effort,
            row.actuator_limit,
            row.step_overshoot_pct,
            row.step_settling_s,
            row.controller_order,
            row.target_cost.map(|c| c.mean),
            row.receipts,
            row.failed
        );
    }
    // README: pid-notch and hinf reach a higher crossover than the PID on this example.
    let fc = |i: usize| rows[i].crossover_hz.unwrap();
    assert!(
        fc(1) > fc(0) && fc(2) > fc(0),
        "{} {} {}",
        fc(0),
        fc(1),
        fc(2)
    );
    // The MPC has no LTI loop: no M_s, ‖W_m T‖∞ or ‖KS‖∞, but its step.
    assert!(rows[3].sensitivity_peak.is_none() && rows[3].wm_t_peak.is_none());
    assert!(rows[3].peak_control_effort.is_none() && rows[3].step_overshoot_pct.is_some());

    // receipts.json carries the rows; the report renders them.
    let comp = d_multi["comparison"].as_array().unwrap();
    assert_eq!(comp.len(), 4);
    assert_eq!(comp[2]["method"], "hinf");
    assert_eq!(comp[2]["receipts_file"], "receipts.hinf.json");
    let html = ferrosid::report::render_html(&multi, &[]).unwrap();
    let table = &html[html.find("id=\"control-comparison\"").unwrap()..];
    for row in &rows {
        assert!(table.contains(&ferrosid::pipeline::fmt_num(row.crossover_hz.unwrap())));
    }
    assert!(!ferrosid::report::render_html(&singles[2].1, &[])
        .unwrap()
        .contains("control-comparison"));
    files_generate_each_methods_controller(&multi, &singles);
}

/// `ferrosid codegen --control` arguments for the files of `dir`.
fn codegen_args(dir: &Path, control: &Path) -> ferrosid::cli::codegen::Args {
    use clap::Parser;
    let p = |f: &str| dir.join(f).into_os_string();
    let cli = ferrosid::cli::Cli::try_parse_from([
        "ferrosid".into(),
        "codegen".into(),
        "--model".into(),
        p("model.json"),
        "--wm".into(),
        p("wm.json"),
        "--control".into(),
        control.as_os_str().to_owned(),
        "--out-dir".into(),
        p("gen"),
    ])
    .unwrap();
    let ferrosid::cli::Command::Codegen(a) = cli.command else {
        panic!("codegen arguments")
    };
    a
}

/// The output directory of the multi-method run: every `receipts.<method>.json` gives, through
/// `ferrosid codegen --control`, the controller block of that method's own run; a later
/// single-method run into the same directory removes them.
fn files_generate_each_methods_controller(
    multi: &PipelineRun,
    singles: &[(ControlMethod, PipelineRun)],
) {
    let dir = std::env::temp_dir().join(format!("ferrosid-methods-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    ferrosid::output::write_outputs(multi, &dir).unwrap();
    for (m, single) in &singles[1..] {
        let file = dir.join(format!("receipts.{}.json", m.name()));
        let input = ferrosid::cli::codegen::build_input(&codegen_args(&dir, &file)).unwrap();
        let own = single.codegen_parts().unwrap().state_controller.unwrap();
        let read = input.state_controller.expect("block from the file");
        // Everything but the note (which names the file it was read from).
        let m = m.name();
        assert_eq!(read.method, own.method, "{m}");
        assert_eq!(read.matrices, own.matrices, "{m}: matrices");
        assert_eq!(
            read.saturation, own.saturation,
            "{m}: rails / anti-windup gain"
        );
        assert_eq!(read.pid_notch, own.pid_notch, "{m}: PID + notch block");
        assert_eq!(read.mpc, own.mpc, "{m}: MPC data");
    }
    // The primary (pid) file has no controller block.
    let input =
        ferrosid::cli::codegen::build_input(&codegen_args(&dir, &dir.join("receipts.json")))
            .unwrap();
    assert!(input.state_controller.is_none());
    ferrosid::output::write_outputs(&singles[0].1, &dir).unwrap();
    for m in ["loopshape", "hinf", "mpc"] {
        assert!(
            !dir.join(format!("receipts.{m}.json")).exists(),
            "{m} stale file removed"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_non_pid_primary_keeps_its_single_run_receipts() {
    // `methods` alone: the first entry is the primary; `method` may repeat it.
    let a = load("methods = [\"hinf\", \"pid\"]\n").unwrap();
    let b = load("method = \"hinf\"\nmethods = [\"hinf\", \"pid\"]\n").unwrap();
    assert_eq!(a.config.control.method, ControlMethod::Hinf);
    assert_eq!(a.config, b.config);
    let multi = run_pipeline(&a, &|_| {}).unwrap();
    let single = run("method = \"hinf\"\n");
    let (dm, ds) = (doc(&multi), doc(&single));
    for key in ["receipts", "control", "crossover_hz"] {
        assert_eq!(dm[key], ds[key], "{key}");
    }
    // The pid file is the PID's receipts (the ones hinf replaced).
    let files = method_documents(&multi).unwrap();
    assert_eq!(files.len(), 1);
    let pid: Value = serde_json::from_str(&files[0].1).unwrap();
    assert_eq!(pid["receipts"], doc(&run(""))["receipts"]);
    assert!(pid.get("control").is_none());
}

#[test]
fn method_keys_name_file_line_and_key() {
    let err = |extra: &str| load(extra).unwrap_err().to_string();
    let line_of = |extra: &str, key: &str| {
        example_text(extra)
            .lines()
            .position(|l| l.starts_with(key))
            .unwrap()
            + 1
    };
    let e = err("methods = [\"pid\", \"lqr\"]\n");
    let l = line_of("methods = [\"pid\", \"lqr\"]\n", "methods");
    assert!(
        e.contains(&format!("pipeline.toml:{l}:")) && e.contains("control.methods"),
        "{e}"
    );
    assert!(e.contains("lqr"), "{e}");
    let extra = "method = \"mpc\"\nmethods = [\"pid\", \"mpc\"]\n";
    let e = err(extra);
    assert!(
        e.contains(&format!("pipeline.toml:{}:", line_of(extra, "method =")))
            && e.contains("control.method`")
            && e.contains("first entry"),
        "{e}"
    );
    let extra = "methods = [\"pid\", \"loopshape\", \"pid-notch\"]\n";
    let e = err(extra);
    assert!(
        e.contains(&format!("pipeline.toml:{}:", line_of(extra, "methods"))) && e.contains("twice"),
        "{e}"
    );
    let e = err("methods = []\n");
    assert!(
        e.contains("control.methods") && e.contains("at least one"),
        "{e}"
    );
    // A method's own key needs its method in the list.
    let extra = "methods = [\"pid\", \"mpc\"]\nhinf_order = 4\n";
    let e = err(extra);
    assert!(
        e.contains(&format!("pipeline.toml:{}:", line_of(extra, "hinf_order")))
            && e.contains("does not list"),
        "{e}"
    );
    assert!(load("methods = [\"pid\", \"hinf\"]\nhinf_order = 4\n").is_ok());
    let e = err("methods = [\"pid\", \"mpc\"]\nmpc_rate_limit = 1.0\n");
    assert!(e.contains("control.mpc_rate_limit"), "{e}");
}
