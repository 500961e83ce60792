//! The generated MPC on target (issue 14): the bundled example's pipeline with
//! `[control] method = "mpc"` (horizons 10 and 20), `ferrosid codegen`'s Rust module flashed
//! into the `mpc` image of `tests/qemu`, run under QEMU (`-icount shift=0`) in closed loop with
//! the example axis (the identified model G0, whose state the MPC feeds back) for a 5 rad/s
//! step against ±0.3 N·m rails and a 0.05 N·m/sample rate limit.
//!
//! Checks: on target the applied input never leaves the rails or the rate limit (checked on
//! every one of the 1500 samples here, and by the image itself); the target's trajectory (f32
//! ADMM with the flashed data, f32 plant) matches the host's prediction (f64
//! `MpcDesign::closed_loop_step` of the same design on G0) within the stated tolerance; and the
//! per-step instruction count (SysTick under `-icount`) with the image's size (llvm-size).
//!
//! Needs qemu-system-arm, llvm-size and the thumbv7em-none-eabihf target (scripts/setup.sh).
use std::path::{Path, PathBuf};

use ferrosid::pipeline::{run_pipeline, LoadedConfig, PipelineRun};
use ferrosid_tests::{
    build_model_image, decode_defmt, image_size, log_field, repo_root, run_qemu, RunOptions,
};

/// Tolerance of the target trajectory against the host's f64 prediction, as a fraction of the
/// step height (y) and of the actuator limit (u): f32 against f64 arithmetic (measured: 1.1e-6
/// of r and 2.9e-6 of the limit at N = 10; the margin covers a clamp switching a sample apart
/// only if it switches back at once).
const TOL_Y: f64 = 1e-4;
const TOL_U: f64 = 1e-4;

fn example_path() -> PathBuf {
    repo_root().join("examples").join("pipeline.toml")
}

/// The example pipeline without the gap, compensation and physical stages, `method = "mpc"`
/// with horizon `n`.
fn mpc_run(n: usize) -> PipelineRun {
    let t = std::fs::read_to_string(example_path()).unwrap();
    let t = t.replace("[gap]\nrun = \"always\"", "[gap]\nrun = \"never\"");
    let t = match t.find("[physical]") {
        Some(i) => t[..i].to_string(),
        None => t,
    };
    let t = t.replace(
        "reference_amplitude = 5.0   # rad/s speed step\n",
        &format!(
            "reference_amplitude = 5.0   # rad/s speed step\nmethod = \"mpc\"\nmpc_horizon = {n}\n"
        ),
    );
    let cfg = LoadedConfig::from_text(&example_path(), &t).unwrap();
    run_pipeline(&cfg, &|_| {}).unwrap()
}

fn check_horizon(n: usize) {
    let run = mpc_run(n);
    let c = run.control.as_ref().expect("control block");
    assert_eq!(c.status, "designed", "{:?}", c.error);
    assert!(c.mpc.is_some(), "MPC design");
    // Generated module -> image.
    let input = ferrosid::ops::codegen::codegen_input(
        run.codegen_parts().unwrap(),
        &ferrosid::ops::codegen::CodegenOptions {
            prefix: "axis1".into(),
            ..Default::default()
        },
    )
    .unwrap();
    let files = ferrosid_codegen::generate(&input).unwrap();
    let dir = repo_root().join("target").join(format!("qemu-mpc-n{n}"));
    std::fs::create_dir_all(&dir).unwrap();
    let module = dir.join(&files.rs_file_name);
    if std::fs::read_to_string(&module).ok().as_deref() != Some(files.rust_module.as_str()) {
        std::fs::write(&module, &files.rust_module).unwrap();
    }
    let elf = build_model_image("mpc", "FERROSID_MPC_MODEL", &module, &dir);
    check_run(&run, &elf, n, false);
    // The same loop with nalgebra's fixed-size matrices (the comparison of the issue).
    check_run(&run, &elf, n, true);
}

fn check_run(run: &PipelineRun, elf: &Path, n: usize, nalgebra: bool) {
    let c = run.control.as_ref().unwrap();
    let (d, model) = c.mpc.as_ref().unwrap();
    let k = &run.config.control;
    let r = k.reference_amplitude;
    let mut args = vec![format!("r={r}")];
    if nalgebra {
        args.push("nalgebra".into());
    }
    let q = run_qemu(
        elf,
        &RunOptions {
            args,
            icount: true,
            timeout: std::time::Duration::from_secs(600),
        },
    )
    .unwrap();
    let solver = if nalgebra { "nalgebra" } else { "loops" };
    let lines = decode_defmt(elf, &q.stdout).unwrap();
    let mut trace = Vec::new();
    for l in &lines {
        if let Some(rest) = l.text.strip_prefix("T ") {
            let v: Vec<f64> = rest
                .split_whitespace()
                .map(|t| t.parse().unwrap())
                .collect();
            trace.push((v[1], v[2]));
        }
    }
    let text = |p: &str| {
        lines
            .iter()
            .find(|l| l.text.starts_with(p))
            .unwrap_or_else(|| panic!("no {p} line: {:?} {}", q.exit_code, q.stderr))
            .text
            .clone()
    };
    let rails = text("RAILS ");
    let icount = text("ICOUNT ");
    let stack = text("STACK ");
    assert_eq!(q.exit_code, 0, "image verdict: {rails}");
    assert_eq!(log_field(&rails, "crossed"), 0.0, "{rails}");
    assert_eq!(trace.len(), 1500);
    // Rails and rate limit, every sample, from the trace (independent of the image's check).
    let (lim, du_max) = (k.actuator_limit, d.spec.du_max);
    let mut u_prev = 0.0;
    for (i, &(_, u)) in trace.iter().enumerate() {
        assert!(
            u.abs() <= lim * (1.0 + 1e-7),
            "sample {i}: u = {u} beyond ±{lim}"
        );
        assert!(
            (u - u_prev).abs() <= du_max * (1.0 + 1e-5),
            "sample {i}: Δu = {} beyond {du_max}",
            u - u_prev
        );
        u_prev = u;
    }
    // The host's prediction of the same loop (f64).
    let host = d.closed_loop_step(model, r, trace.len(), 0.02).unwrap();
    let (mut ey, mut eu) = (0.0f64, 0.0f64);
    for (i, &(y, u)) in trace.iter().enumerate() {
        ey = ey.max((y - host.step.y[i]).abs());
        eu = eu.max((u - host.step.u[i]).abs());
    }
    let at_rail = trace
        .iter()
        .filter(|(_, u)| u.abs() >= lim * (1.0 - 1e-6))
        .count();
    assert_eq!(text("SOLVER "), format!("SOLVER {solver}"));
    let size = image_size(elf).unwrap();
    eprintln!(
        "N = {n} ({solver}): target vs host max |Δy| {ey:.3e} ({:.3e} of r), max |Δu| {eu:.3e}; samples at \
         the rail {at_rail}; y(1.5 s) target {:.4} host {:.4}; peak target {:.4}; {icount}; \
         {stack}; flash {} B, static RAM {} B (text {}, data {}, bss {})",
        ey / r,
        trace.last().unwrap().0,
        host.step.y.last().unwrap(),
        trace.iter().map(|t| t.0).fold(f64::MIN, f64::max),
        size.flash(),
        size.ram(),
        size.text,
        size.data,
        size.bss
    );
    assert!(at_rail > 0, "the step must be constrained (reach the rail)");
    assert!(ey <= TOL_Y * r, "N = {n}: y differs from the host by {ey}");
    assert!(
        eu <= TOL_U * lim,
        "N = {n}: u differs from the host by {eu}"
    );
    let (mean, max) = (log_field(&icount, "mean"), log_field(&icount, "max"));
    assert!(mean > 0.0 && max >= mean, "{icount}");
}

#[test]
fn mpc_n10_on_target_respects_the_rails_and_matches_the_host() {
    check_horizon(10);
}

#[test]
fn mpc_n20_on_target_respects_the_rails_and_matches_the_host() {
    check_horizon(20);
}
