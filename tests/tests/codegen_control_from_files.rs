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
    let read = input
        .state_controller
        .clone()
        .expect("block from the files");
    assert_eq!(read.method, own.method);
    assert_eq!(read.matrices, own.matrices, "{name}: matrices");
    assert_eq!(
        read.saturation, own.saturation,
        "{name}: rails / anti-windup gain"
    );
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
    if read.mpc.is_none() {
        c_step_matches_the_firmware(&dir, &files, &read);
    }
    dir
}

/// An error sequence that drives the controller onto both rails.
fn error_at(k: usize) -> f32 {
    let sq = if (k / 300) % 2 == 0 { 8.0 } else { -6.0 };
    sq + 0.5 * ((k as f32) * 0.3).sin()
}

/// The generated C step (`axis1_k_step` with its rails and back-calculation, or
/// `axis1_kn_step`), compiled with gcc -Werror, against the firmware's f32 law built from the
/// same block, 2000 steps from rest with e = r − y (y = 0).
fn c_step_matches_the_firmware(
    dir: &Path,
    files: &ferrosid_codegen::Generated,
    sk: &ferrosid_codegen::StateController,
) {
    use ferrosid_firmware::control as fw;
    const STEPS: usize = 2000;
    std::fs::write(dir.join(&files.c_file_name), &files.c_header).unwrap();
    let (decl, call) = if sk.pid_notch.is_some() {
        (
            "AXIS1_kn_state s; memset(&s, 0, sizeof s);",
            "AXIS1_kn_step(&s, e)",
        )
    } else {
        ("float xi[AXIS1_K_N_STATES] = {0};", "AXIS1_k_step(xi, e)")
    };
    let main = format!(
        "#include <stdio.h>\n#include <string.h>\n#include <math.h>\n#include \"{}\"\n\
         int main(void) {{\n    int k;\n    {decl}\n    for (k = 0; k < {STEPS}; ++k) {{\n        \
         float e = (((k / 300) % 2) == 0 ? 8.0f : -6.0f) + 0.5f * sinf((float)k * 0.3f);\n        \
         printf(\"%.9g\\n\", (double){call});\n    }}\n    return 0;\n}}\n",
        files.c_file_name
    );
    std::fs::write(dir.join("main.c"), main).unwrap();
    let exe = dir.join("step");
    let out = std::process::Command::new("gcc")
        .args([
            "-std=c99",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            "-O0",
            "-ffp-contract=off",
            "-o",
        ])
        .arg(&exe)
        .arg(dir.join("main.c"))
        .arg("-lm")
        .output()
        .expect("gcc");
    assert!(
        out.status.success(),
        "gcc: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = std::process::Command::new(&exe).output().unwrap();
    let c_out: Vec<f64> = String::from_utf8(run.stdout)
        .unwrap()
        .lines()
        .map(|l| l.parse().unwrap())
        .collect();
    assert_eq!(c_out.len(), STEPS);
    let f = |v: f64| v as f32;
    let mut fw_out = Vec::new();
    let lim;
    if let Some(kn) = &sk.pid_notch {
        lim = kn.u_max;
        let bq = |b: &ferrosid_codegen::Biquad| fw::Biquad {
            b: b.b.map(f),
            a: b.a.map(f),
        };
        let mut sections = [fw::Biquad {
            b: [1.0, 0.0, 0.0],
            a: [1.0, 0.0, 0.0],
        }; 1];
        assert_eq!(kn.sections.len(), 1, "the example has one notch");
        sections[0] = bq(&kn.sections[0]);
        let law = fw::PidNotchLaw::new(&fw::PidNotchConfig {
            pid: fw::PidConfig {
                kp: f(kn.pid.kp),
                ki_d: f(kn.pid.ki_d),
                a_d: f(kn.pid.a_d),
                b_d: f(kn.pid.b_d),
                rolloff: kn.pid.rolloff.as_ref().map(bq),
            },
            cascade: fw::BiquadCascade { sections },
            u_min: f(kn.u_min),
            u_max: f(kn.u_max),
            anti_windup: kn.anti_windup,
        })
        .unwrap();
        let mut st = fw::PidNotchState::new();
        for k in 0..STEPS {
            fw_out.push(f64::from(law.step(&mut st, error_at(k), 0.0).u));
        }
    } else {
        let s = sk.saturation.as_ref().unwrap();
        lim = s.u_max;
        let m = &sk.matrices;
        assert_eq!(m.a.len(), 4, "hinf_order = 4");
        let law = fw::StateSpaceLaw::<4>::new(&fw::StateSpaceConfig {
            a: std::array::from_fn(|i| std::array::from_fn(|j| f(m.a[i][j]))),
            b: std::array::from_fn(|i| f(m.b[i][0])),
            c: std::array::from_fn(|j| f(m.c[0][j])),
            d: f(m.d[0][0]),
            l: std::array::from_fn(|i| f(s.l[i])),
            u_min: f(s.u_min),
            u_max: f(s.u_max),
        })
        .unwrap();
        let mut st = fw::StateSpaceState::new();
        for k in 0..STEPS {
            fw_out.push(f64::from(law.step(&mut st, error_at(k), 0.0).u));
        }
    }
    let at_rail = c_out
        .iter()
        .filter(|u| u.abs() >= lim * (1.0 - 1e-6))
        .count();
    assert!(at_rail > 100, "the sequence must saturate ({at_rail})");
    // Same f32 operations in the same order (gcc without contraction, the Rust without FMA on
    // x86-64): agreement to a few ulps of the rail.
    let worst = c_out
        .iter()
        .zip(&fw_out)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f64, f64::max);
    eprintln!(
        "C step vs firmware law: max |Δu| {worst:.3e} (rail {lim}), {at_rail} samples at the rail"
    );
    assert!(worst <= 1e-5 * lim, "C vs firmware: {worst}");
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
    assert!(
        msg.contains("failed.json") && msg.contains("failed"),
        "{msg}"
    );
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
    let e =
        ferrosid::cli::codegen::build_input(&args(&dir, &dir.join("receipts.json"))).unwrap_err();
    assert!(
        e.to_string().contains("another model") && e.to_string().contains("receipts.json"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(dir);
}
