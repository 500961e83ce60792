//! The design card's crates on the target (issue 16): the `cratecmp` image
//! (`tests/qemu/src/bin/cratecmp.rs`) measures nalgebra, micromath and heapless against what
//! they replace, under `qemu-system-arm -icount shift=0`, and this test prints its figures (the
//! README's table "Design-card crates on the target") and checks the claims the firmware's
//! choices rest on. Instruction counts under `-icount` are deterministic, so the two count
//! comparisons below are count assertions, not timings.
//!
//! Run: `cargo test -p ferrosid-tests --test design_card_crates -- --nocapture`.
//! Needs qemu-system-arm, llvm-nm and the thumbv7em-none-eabihf target (scripts/setup.sh).

use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use ferrosid_tests::{build_run_decode, image_path, LogLine, RunOptions};

/// The image run once under `-icount shift=0`: exit code and decoded lines.
fn cmp_run() -> &'static (i32, Vec<LogLine>) {
    static RUN: OnceLock<(i32, Vec<LogLine>)> = OnceLock::new();
    RUN.get_or_init(|| {
        let opts = RunOptions {
            icount: true,
            timeout: Duration::from_secs(300),
            ..RunOptions::default()
        };
        match build_run_decode("cratecmp", &opts) {
            Ok((run, lines)) => {
                for l in &lines {
                    println!("cratecmp: {l}");
                }
                assert_eq!(run.exit_code, 0, "cratecmp exit code ({})", run.stderr);
                (run.exit_code, lines)
            }
            Err(e) => panic!("QEMU harness: {e}"),
        }
    })
}

/// `(instructions per call, max error)` of the line `CMP job=<job> variant=<variant> ...`.
fn figure(job: &str, variant: &str) -> (f64, f64) {
    let (_, lines) = cmp_run();
    let field = |t: &str, k: &str| -> Option<f64> {
        t.split_whitespace()
            .find_map(|w| w.strip_prefix(k).and_then(|r| r.strip_prefix('=')))
            .and_then(|v| v.parse().ok())
    };
    lines
        .iter()
        .find(|l| {
            l.text.starts_with("CMP ")
                && l.text.contains(&format!(" job={job} "))
                && l.text.contains(&format!(" variant={variant} "))
        })
        .and_then(|l| Some((field(&l.text, "instr")?, field(&l.text, "err")?)))
        .unwrap_or_else(|| panic!("no CMP line for {job}/{variant}"))
}

const MODELS: [(&str, usize); 3] = [
    ("model_axis2", 2),
    ("model_twomass4", 4),
    ("model_threemass6", 6),
];

/// Model evaluation at the 16 check bins, nalgebra (the firmware's `model_response`) against
/// the hand-written elimination it replaced: both within tolerance of numpy's complex128
/// response (1e-4 relative for the 2- and 4-state models; 5e-3 for the 6-state one, whose
/// lightly damped non-collocated realisation loses about three digits of f32 anywhere), and
/// nalgebra with fewer instructions at 2 and 4 states.
#[test]
fn model_evaluation_nalgebra_against_hand_written() {
    println!("| model | states | instr/eval hand | instr/eval nalgebra | max rel. error hand | nalgebra |");
    for (job, ns) in MODELS {
        let (ih, eh) = figure(job, "hand");
        let (inal, en) = figure(job, "nalgebra");
        println!("| {job} | {ns} | {ih:.0} | {inal:.0} | {eh:.2e} | {en:.2e} |");
        let tol = if ns <= 4 { 1e-4 } else { 5e-3 };
        assert!(
            eh < tol && en < tol,
            "{job}: errors {eh:e} / {en:e}, tolerance {tol:e}"
        );
        assert!(ih > 0.0 && inal > 0.0, "{job}: counts {ih} / {inal}");
        if ns <= 4 {
            assert!(inal < ih, "{job}: nalgebra {inal} instr, hand-written {ih}");
        }
    }
}

/// The unit-circle point of a check bin: the firmware's table path is as accurate as the f64
/// series it replaced (G0's error the same within a factor 2) and costs about 1 % of it;
/// micromath's sin/cos (2e-3 rad) would make G0 wrong by more than 1 % — rejected.
#[test]
fn unit_circle_table_against_series_and_micromath() {
    let (it, et) = figure("unit_circle", "table");
    let (is, es) = figure("unit_circle", "f64series");
    let (im, em) = figure("unit_circle", "micromath");
    let (il, el) = figure("unit_circle", "libm");
    println!(
        "z = e^(j2πk/N): table {it:.0} instr {et:.1e}; f64 series {is:.0} {es:.1e}; \
         micromath {im:.0} {em:.1e}; libm {il:.0} {el:.1e}"
    );
    assert!(et < 2.5e-7 && es < 1e-7, "table {et:e}, series {es:e}");
    assert!(it < is / 10.0, "table {it} instr, series {is}");
    assert!(em > 1e-4, "micromath's z error {em:e}");
    for (job, _) in MODELS {
        let (_, gt) = figure(job, "z_table");
        let (_, gs) = figure(job, "z_f64series");
        let (_, gm) = figure(job, "z_micromath");
        println!(
            "{job}: G0 error with z from table {gt:.2e}, f64 series {gs:.2e}, micromath {gm:.2e}"
        );
        assert!(gt <= 2.0 * gs + 1e-7, "{job}: table {gt:e}, series {gs:e}");
        assert!(gm > 1e-2, "{job}: micromath {gm:e}");
    }
}

/// micromath's scalar functions against libm and the firmware's table sine: printed, and the
/// accuracy facts the firmware's choices rest on (sqrt 5 % off, sin 1e-3 off).
#[test]
fn micromath_scalar_functions() {
    for (job, kind) in [
        ("sqrt", "rel"),
        ("exp", "rel"),
        ("atan2", "abs"),
        ("sin_phase", "abs"),
    ] {
        let other = if job == "sin_phase" { "table" } else { "libm" };
        let (io, eo) = figure(job, other);
        let (im, em) = figure(job, "micromath");
        println!("{job}: {other} {io:.1} instr, {kind} error {eo:.1e}; micromath {im:.1} instr, {em:.1e}");
        assert!(eo < 1e-6, "{job}/{other} error {eo:e}");
        assert!(em > 100.0 * eo, "{job}: micromath {em:e} against {eo:e}");
    }
    assert!(figure("sqrt", "micromath").1 > 0.01);
}

/// The failing-frequency list: heapless::Vec gives the same list as the array and count.
#[test]
fn failed_list_heapless_equals_array() {
    let (ia, _) = figure("failed_list", "array");
    let (ih, same) = figure("failed_list", "heapless");
    println!("failed_hz list of 16 results: array {ia:.0} instr, heapless::Vec {ih:.0}");
    assert_eq!(same, 0.0, "the two lists differ");
}

/// Code size of the model evaluation per state count: the sizes of the out-of-line
/// `eval_hand` (hand-written elimination inlined) and of the firmware's `model_response`
/// monomorphisations (nalgebra inlined) plus their `eval_nalgebra` call wrappers, from
/// `llvm-nm --print-size`. Printed for README; each set has three symbols growing with N.
#[test]
fn model_evaluation_code_size() {
    cmp_run();
    let elf = image_path("cratecmp");
    let out = Command::new("llvm-nm")
        .args(["--print-size", "-C"])
        .arg(&elf)
        .output()
        .expect("llvm-nm (scripts/setup.sh installs it)");
    assert!(out.status.success(), "llvm-nm failed");
    let text = String::from_utf8_lossy(&out.stdout);
    let sizes = |pat: &str| -> Vec<u64> {
        let mut v: Vec<u64> = text
            .lines()
            .filter(|l| l.contains(pat))
            .filter_map(|l| u64::from_str_radix(l.split_whitespace().nth(1)?, 16).ok())
            .collect();
        v.sort_unstable();
        v
    };
    let hand = sizes("cratecmp::eval_hand::");
    let na = sizes("ferrosid_firmware::check::model::model_response::");
    let wrap = sizes("cratecmp::eval_nalgebra::");
    assert_eq!(
        (hand.len(), na.len(), wrap.len()),
        (3, 3, 3),
        "symbols: {hand:?} {na:?} {wrap:?}"
    );
    for (i, (_, ns)) in MODELS.iter().enumerate() {
        println!(
            "model evaluation code, {ns} states: hand-written {} B, nalgebra {} B",
            hand[i],
            na[i] + wrap[i]
        );
    }
}
