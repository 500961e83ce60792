//! The generated pid-notch and H∞ controllers on target (issue 14): the bundled example's
//! pipeline with `[control] method = "pid-notch"` and `"hinf"` (reduced to `hinf_order = 4`),
//! `ferrosid codegen`'s Rust module flashed into the `ctl` image of `tests/qemu`
//! (`ferrosid_firmware::control::PidNotchLaw` / `StateSpaceLaw` built from the generated
//! consts), run under QEMU (`-icount shift=0`) in closed loop with the example axis (the
//! identified model G0, the header's A, B, C in f32) for the pipeline's saturated reference
//! step (5 rad/s against ±0.3 N·m).
//!
//! Checks: the target's trajectory matches the host's own prediction — the `step` the
//! pipeline's control stage computed in f64 for its receipts (`synth::sim::
//! saturated_step_general` with the same law: the PID's conditional integration then the
//! notches; the state-space controller with its back-calculation gain) — within the stated
//! tolerance on every sample; the command never leaves the rails; the step is really
//! saturated (so the anti-windup is exercised); and the per-step instruction count (SysTick
//! under `-icount`) with the image's size (llvm-size) and stack high water.
//!
//! Needs qemu-system-arm, llvm-size and the thumbv7em-none-eabihf target (scripts/setup.sh).
use std::path::{Path, PathBuf};

use ferrosid::pipeline::{run_pipeline, LoadedConfig, PipelineRun};
use ferrosid_tests::{
    build_model_image, decode_defmt, image_size, log_field, repo_root, run_qemu, RunOptions,
};

/// Tolerance of the target trajectory against the host's f64 prediction, as a fraction of the
/// step height (y) and of the actuator limit (u): f32 coefficients and arithmetic (relative
/// errors ~1e-7) through the closed loop. Measured: at most 2.6e-6 of r and 4.6e-6 of the limit
/// (pid-notch and hinf, r = 5 and 15); a clamp or the conditional integration switching one
/// sample apart would show as a jump above this.
const TOL_Y: f64 = 1e-4;
const TOL_U: f64 = 1e-4;

fn example_path() -> PathBuf {
    repo_root().join("examples").join("pipeline.toml")
}

/// The example pipeline without the gap, compensation and physical stages, with `extra`
/// added to `[control]`.
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

/// What one run of the image gave.
struct TargetRun {
    trace: Vec<(f64, f64)>,
    head: String,
    icount: String,
    stack: String,
}

fn run_target(elf: &Path, r: f64, samples: usize, law: &str) -> TargetRun {
    let q = run_qemu(
        elf,
        &RunOptions {
            args: vec![format!("r={r}"), format!("samples={samples}")],
            icount: true,
            timeout: std::time::Duration::from_secs(600),
        },
    )
    .unwrap();
    let lines = decode_defmt(elf, &q.stdout).unwrap();
    let text = |p: &str| {
        lines
            .iter()
            .find(|l| l.text.starts_with(p))
            .unwrap_or_else(|| panic!("no {p} line: {:?} {}", q.exit_code, q.stderr))
            .text
            .clone()
    };
    let head = text("CTL ");
    let rails = text("RAILS ");
    assert_eq!(q.exit_code, 0, "image verdict: {head} {rails}");
    assert!(head.contains(&format!("law={law}")), "{head}");
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
    assert_eq!(trace.len(), samples);
    TargetRun {
        trace,
        head,
        icount: text("ICOUNT "),
        stack: text("STACK "),
    }
}

/// Compares a target run with the host's step `host` (y and applied u per sample); returns
/// (max |Δy|, max |Δu|, target samples at the rail).
fn compare(
    name: &str,
    t: &TargetRun,
    host: &ferrosid::robust::step::StepResponse,
    r: f64,
    lim: f64,
) -> (f64, f64, usize) {
    let (mut ey, mut eu, mut at_rail) = (0.0f64, 0.0f64, 0usize);
    for (i, &(y, u)) in t.trace.iter().enumerate() {
        assert!(
            u.abs() <= lim * (1.0 + 1e-7),
            "sample {i}: u = {u} beyond ±{lim}"
        );
        if u.abs() >= lim * (1.0 - 1e-6) {
            at_rail += 1;
        }
        ey = ey.max((y - host.y[i]).abs());
        eu = eu.max((u - host.u[i]).abs());
    }
    eprintln!(
        "{name}, r = {r}: {}; target vs host max |Δy| {ey:.3e} ({:.3e} of r), max |Δu| \
         {eu:.3e} ({:.3e} of the limit); samples at the rail target {at_rail} host {}; \
         overshoot host {:.2} %; y(end) target {:.4} host {:.4}; {}; {}",
        t.head,
        ey / r.abs(),
        eu / lim,
        host.samples_at_rail,
        host.overshoot_pct,
        t.trace.last().unwrap().0,
        host.y.last().unwrap(),
        t.icount,
        t.stack
    );
    assert!(
        ey <= TOL_Y * r.abs(),
        "{name}, r = {r}: y differs from the host by {ey}"
    );
    assert!(
        eu <= TOL_U * lim,
        "{name}, r = {r}: u differs from the host by {eu}"
    );
    let (mean, max) = (log_field(&t.icount, "mean"), log_field(&t.icount, "max"));
    assert!(mean > 0.0 && max >= mean, "{}", t.icount);
    (ey, eu, at_rail)
}

fn check(name: &str, extra: &str, law: &str) {
    let run = run(extra);
    let c = run.control.as_ref().expect("control block");
    assert_eq!(c.status, "designed", "{:?}", c.error);
    let host = c.step.clone().expect("the host's saturated step");
    let k = &run.config.control;
    let (r, lim) = (k.reference_amplitude, k.actuator_limit);
    let input = ferrosid::ops::codegen::codegen_input(
        run.codegen_parts().unwrap(),
        &ferrosid::ops::codegen::CodegenOptions {
            prefix: "axis1".into(),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(
        input.model.matrices.d.iter().flatten().all(|&d| d == 0.0),
        "the image's plant has no feedthrough"
    );
    let sk = input.state_controller.as_ref().expect("state controller");
    match law {
        "kn" => assert!(sk.pid_notch.is_some(), "pid-notch block"),
        _ => assert!(
            sk.saturation
                .as_ref()
                .is_some_and(|s| s.l.iter().any(|&v| v != 0.0)),
            "back-calculation gain"
        ),
    }
    let files = ferrosid_codegen::generate(&input).unwrap();
    // One cargo target directory for both images (the module differs; build.rs reruns on it).
    let target = repo_root().join("target").join("qemu-ctl");
    let dir = target.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    let module = dir.join(&files.rs_file_name);
    if std::fs::read_to_string(&module).ok().as_deref() != Some(files.rust_module.as_str()) {
        std::fs::write(&module, &files.rust_module).unwrap();
    }
    let elf = build_model_image("ctl", "FERROSID_CTL_MODEL", &module, &target);
    let size = image_size(&elf).unwrap();
    eprintln!(
        "{name}: flash {} B, static RAM {} B (text {}, data {}, bss {})",
        size.flash(),
        size.ram(),
        size.text,
        size.data,
        size.bss
    );
    // 1. The pipeline's own step (its receipts' prediction), at the design amplitude.
    let samples = host.y.len().min(20_000);
    let t = run_target(&elf, r, samples, law);
    compare(name, &t, &host, r, lim);
    // 2. A step three times as high, deep into saturation (the anti-windup acts), against the
    // host's f64 simulation of the same law (`synth::sim::saturated_step_general`).
    let r3 = 3.0 * r;
    let model = run.model();
    let host_law = ferrosid::pipeline::control_stage::chosen_law(c, model.ts)
        .unwrap()
        .expect("the chosen law");
    let spec = ferrosid::robust::step::StepSpec {
        amplitude: r3,
        actuator_limit: lim,
        duration_s: (samples as f64 + 0.5) * model.ts,
        anti_windup: k.anti_windup,
        settle_band: 0.02,
    };
    let host3 = ferrosid::synth::sim::saturated_step_general(model, host_law, &spec).unwrap();
    assert_eq!(host3.y.len(), samples);
    let t3 = run_target(&elf, r3, samples, law);
    let (_, _, at_rail) = compare(name, &t3, &host3, r3, lim);
    assert!(
        host3.samples_at_rail > 10 && at_rail > 10,
        "the {r3} step must saturate (anti-windup exercised): target {at_rail}, host {}",
        host3.samples_at_rail
    );
}
#[test]
fn pid_notch_on_target_matches_the_host_step() {
    check("pid-notch", "method = \"pid-notch\"", "kn");
}

#[test]
fn hinf_reduced_on_target_matches_the_host_step() {
    check("hinf", "method = \"hinf\"\nhinf_order = 4", "ss");
}
