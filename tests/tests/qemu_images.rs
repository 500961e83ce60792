//! The other firmware images of `tests/qemu` under QEMU: the instruction-count bench and the
//! size probe. Speed figures are not asserted against bars here (benchmarks are not tests; see
//! scripts/bench-firmware.sh); these tests check that the images work and that the
//! measurement machinery measures what it claims. One exception is a bound, not a speed: the
//! largest number of instructions of any single `Welch::push` (the real-time guarantee). Under
//! `-icount` instruction counts are deterministic, so that is a count assertion.
//!
//! Needs qemu-system-arm, llvm-objdump, llvm-symbolizer and the thumbv7em-none-eabihf target: when they are
//! missing these tests FAIL with a message telling to run scripts/setup.sh.

use std::sync::OnceLock;
use std::time::Duration;

use ferrosid_tests::{
    build_images, build_run_decode, documented_figures, panic_sites, repo_root, LogLine, PanicSite,
    RunOptions, PERFORMANCE_DOC,
};

fn run(bin: &str, opts: &RunOptions) -> (i32, Vec<LogLine>, String) {
    match build_run_decode(bin, opts) {
        Ok((run, lines)) => {
            for l in &lines {
                println!("{bin}: {l}");
            }
            (run.exit_code, lines, run.stderr)
        }
        Err(e) => panic!("QEMU harness: {e}"),
    }
}

/// Value of the line `BENCH <name> <value> <unit>`.
fn bench_value(lines: &[LogLine], name: &str) -> Option<f64> {
    lines.iter().find_map(|l| {
        let mut it = l.text.split_whitespace();
        (it.next() == Some("BENCH") && it.next() == Some(name))
            .then(|| it.next().and_then(|v| v.parse().ok()))
            .flatten()
    })
}

/// The bench image run once under `-icount shift=0` (exit code, decoded lines, stderr), shared
/// by the tests that read its figures.
fn bench_run() -> &'static (i32, Vec<LogLine>, String) {
    static RUN: OnceLock<(i32, Vec<LogLine>, String)> = OnceLock::new();
    RUN.get_or_init(|| {
        let opts = RunOptions {
            icount: true,
            timeout: Duration::from_secs(300),
            ..RunOptions::default()
        };
        run("bench", &opts)
    })
}

/// Bound on the instructions of any single `Welch::push` (issue 16: an estimator running in a
/// 10 kHz control ISR on an 80 MHz Cortex-M4F must cost a bounded, small part of a period).
const MAX_PUSH_INSTRUCTIONS: f64 = 5_000.0;

/// Every push measured alone over 64 Ki samples (127 segment ends at N = 1024): none exceeds
/// [`MAX_PUSH_INSTRUCTIONS`], for N = 256 and N = 1024 (Hann, 50 % overlap) and for N = 1024
/// with a rectangular window and no overlap. The spreading is real: one segment's work done at
/// once (`flush`) costs more than ten times that bound, and the figures are exact to one SysTick
/// tick (40 instructions).
#[test]
fn welch_push_has_a_bounded_instruction_count() {
    let (code, lines, stderr) = bench_run();
    assert_eq!(*code, 0, "bench exit code (stderr: {stderr})");
    for name in [
        "welch_push_max_n256",
        "welch_push_max_n1024",
        "welch_push_max_rect_hop1024_n1024",
    ] {
        let v = bench_value(lines, name).unwrap_or_else(|| panic!("no BENCH {name} line"));
        assert!(
            v > 0.0 && v <= MAX_PUSH_INSTRUCTIONS,
            "{name} = {v} instructions, bound {MAX_PUSH_INSTRUCTIONS}"
        );
    }
    let work = bench_value(lines, "welch_segment_work_n1024").expect("segment work line");
    assert!(
        work > 10.0 * MAX_PUSH_INSTRUCTIONS,
        "one segment's work is {work} instructions: too small for the bound to mean anything"
    );
    // The mean per push includes the spread work: it lies between the work per hop and the max.
    let mean = bench_value(lines, "welch_push_n1024").expect("mean line");
    let max = bench_value(lines, "welch_push_max_n1024").expect("max line");
    assert!(
        work / 512.0 < mean && mean < max,
        "mean {mean}, work/hop {}, max {max}",
        work / 512.0
    );
}

/// Under `-icount shift=0` QEMU advances its virtual clock 1 ns per instruction and the
/// mps2-an386 SysTick runs at 25 MHz: 40 instructions per tick, which the image measures on a
/// loop of known length (to within the +-1 tick quantisation of the measurement). The bench's figures must be present, finite and positive.
#[test]
fn bench_counts_instructions_under_icount() {
    let (code, lines, stderr) = bench_run();
    let (code, lines) = (*code, lines.as_slice());
    assert_eq!(code, 0, "bench exit code (stderr: {stderr})");
    // Each measured interval is quantised to whole ticks: +-1 tick in 100 000.
    let ipt = bench_value(lines, "calibration_instr_per_tick").expect("calibration line");
    assert!(
        (ipt - 40.0).abs() < 40.0 * 1e-4,
        "instructions per SysTick tick under -icount shift=0: {ipt}, expected 40"
    );
    for name in [
        "welch_push_n256",
        "welch_push_n1024",
        "welch_push_max_n256",
        "welch_push_max_n1024",
        "welch_segment_push_n1024",
        "welch_segment_work_n1024",
        "prbs15_hold1",
        "chirp_linear",
        "chirp_log",
        "multisine1024_play",
        "control_pid",
        "control_pid_friction_ff",
        "control_pid_dead_zone_inverse",
        "control_pid_backlash_inverse",
        "control_pid_anti_windup",
        "control_pid_all_compensation",
    ] {
        let v = bench_value(lines, name).unwrap_or_else(|| panic!("no BENCH {name} line"));
        assert!(v.is_finite() && v > 0.0, "{name} = {v}");
    }
    // Each compensation part adds work to the PID step, and all together cost the most.
    let pid = bench_value(lines, "control_pid").unwrap_or(0.0);
    for name in [
        "control_pid_friction_ff",
        "control_pid_dead_zone_inverse",
        "control_pid_backlash_inverse",
        "control_pid_anti_windup",
    ] {
        let v = bench_value(lines, name).unwrap_or(0.0);
        let all = bench_value(lines, "control_pid_all_compensation").unwrap_or(0.0);
        assert!(
            pid < v && v < all,
            "{name} = {v}, PID alone {pid}, all {all}"
        );
    }
    // Welch<1024>, 64 Ki samples, hop 512: (65536 - 1024)/512 + 1 = 127 segments end; the
    // last one ends with the last push and is still in work (its work follows the next pushes).
    assert_eq!(bench_value(lines, "welch_n1024_averages"), Some(126.0));
}

/// Every bench figure written in docs/firmware-performance.md is what the bench measures now,
/// within the noise stated beside it (instruction counts under `-icount` are deterministic: the
/// noise is the resolution, one SysTick tick or the printed decimal). The sizes in the document
/// are checked by `scripts/bench-firmware.sh` (they need the size-probe image's llvm-size).
#[test]
fn bench_figures_match_the_performance_document() {
    let (code, lines, stderr) = bench_run();
    assert_eq!(*code, 0, "bench exit code (stderr: {stderr})");
    let path = repo_root().join(PERFORMANCE_DOC);
    let doc = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let figures = documented_figures(&doc);
    assert!(
        figures.iter().any(|f| f.name == "welch_push_n1024"),
        "{PERFORMANCE_DOC} documents no welch_push_n1024"
    );
    let mut stale = Vec::new();
    for f in figures.iter().filter(|f| !f.name.starts_with("sizeprobe_")) {
        match bench_value(lines, &f.name) {
            Some(v) if (v - f.value).abs() <= f.noise => {}
            v => stale.push(format!(
                "{}: documented {} ± {}, measured {v:?}",
                f.name, f.value, f.noise
            )),
        }
    }
    assert!(
        stale.is_empty(),
        "{PERFORMANCE_DOC} is stale (regenerate with scripts/bench-firmware.sh):\n{}",
        stale.join("\n")
    );
}

/// Without `-icount` the SysTick follows wall-clock time, so the bench must refuse to report
/// (exit 1) rather than print meaningless counts.
#[test]
fn bench_refuses_without_icount() {
    let (code, lines, _) = run("bench", &RunOptions::default());
    assert_eq!(code, 1, "bench without -icount must fail");
    assert!(lines.iter().any(|l| l.text.contains("-icount")));
    assert!(bench_value(&lines, "welch_push_n1024").is_none());
}

/// The size probe runs: its estimate passes its own sanity check (exit 0) and it reports its
/// painted stack high-water mark (somewhere between one frame and the 32 KiB painted).
#[test]
fn sizeprobe_runs_and_reports_its_stack() {
    let (code, lines, stderr) = run("sizeprobe", &RunOptions::default());
    assert_eq!(code, 0, "sizeprobe exit code (stderr: {stderr})");
    let stack: u64 = lines
        .iter()
        .find_map(|l| l.text.strip_prefix("STACK "))
        .and_then(|t| t.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("STACK line");
    assert!(
        (64..32 * 1024).contains(&stack),
        "stack high-water {stack} B"
    );
}

/// Source directory of the firmware crate as recorded in the images' debug information.
const FIRMWARE_SRC: &str = "/firmware/src/";

/// Panic call sites of image `bin` (see [`panic_sites`]).
fn sites_of(bin: &str) -> Vec<PanicSite> {
    let elf = match build_images(&[bin]) {
        Ok(mut v) => v.remove(0),
        Err(e) => panic!("QEMU harness: {e}"),
    };
    let sites = panic_sites(&elf).unwrap_or_else(|e| panic!("panic-path scan: {e}"));
    println!("{bin}: {} branches to panic entry points", sites.len());
    sites
}

/// Panic call sites whose inlined source frames include firmware code.
fn firmware_sites(sites: &[PanicSite]) -> String {
    sites
        .iter()
        .filter(|s| s.has_frame_in(FIRMWARE_SRC))
        .map(|s| format!("{s}\n"))
        .collect()
}

/// "No panic reachable from any input": the `nopanic` image calls the firmware's public API
/// with opaque (`black_box`) inputs, so every run-time check the firmware would need is compiled
/// in; no branch to a panic entry point may come from firmware code (frames attributed by the
/// debug information, inlining included). The image must also run to completion.
#[test]
fn firmware_api_has_no_panic_path() {
    let offending = firmware_sites(&sites_of("nopanic"));
    assert!(
        offending.is_empty(),
        "panic paths in ferrosid-firmware:\n{offending}"
    );
    let (code, _, stderr) = run("nopanic", &RunOptions::default());
    assert_eq!(code, 0, "nopanic exit code (stderr: {stderr})");
}

/// Same for the size-probe image (Welch<1024>, PRBS, gate, H1 as a product would link them).
#[test]
fn sizeprobe_has_no_firmware_panic_path() {
    let offending = firmware_sites(&sites_of("sizeprobe"));
    assert!(
        offending.is_empty(),
        "panic paths in ferrosid-firmware:\n{offending}"
    );
}

/// The scan finds a real panic path: the self-test's deliberate `panic!` (for `--panic`),
/// attributed to selftest.rs. Shows that the two tests above can fail.
#[test]
fn panic_path_scan_finds_the_selftest_panic() {
    let sites = sites_of("selftest");
    assert!(
        sites
            .iter()
            .any(|s| s.has_frame_in("tests/qemu/src/bin/selftest.rs")),
        "scan missed the deliberate panic; sites:\n{}",
        sites.iter().map(|s| format!("{s}\n")).collect::<String>()
    );
}
