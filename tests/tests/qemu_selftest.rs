//! The on-target self-test image (`tests/qemu/src/bin/selftest.rs`) built for
//! thumbv7em-none-eabihf and run on `qemu-system-arm -machine mps2-an386 -cpu cortex-m4`.
//!
//! The image checks the firmware's generators and Welch estimator against references computed
//! independently on the target (direct f64 DFT, analytic responses of simulated plants, PRBS
//! period and balance, ...) and exits through semihosting with 0 when every check passed, 1 when
//! one failed and 101 on a panic. These tests check that exit code and that every expected check
//! reported PASS in the decoded defmt log; the other tests show that the harness can fail.
//!
//! Needs qemu-system-arm and the thumbv7em-none-eabihf target: when they are missing these tests
//! FAIL with a message telling to run scripts/setup.sh.

use ferrosid_tests::{build_run_decode, LogLine, QemuRun, RunOptions};

/// Every check the self-test must report, in the order it runs them.
const EXPECTED_CHECKS: &[&str] = &[
    "fpu_enabled",
    "prbs_period_and_balance",
    "prbs_flat_spectrum",
    "prbs_rejects_bad_config",
    "chirp_linear_law",
    "chirp_log_law",
    "multisine_schroeder_spectrum",
    "multisine_crest_beats_schroeder",
    "welch_matches_direct_dft",
    "welch_h1_first_order_lag",
    "welch_h1_resonant_mode",
    "welch_h1_periodic_exact",
    "coherence_statistics",
    "coherence_gate",
    "nonfinite_quarantine",
    "welch_bad_input",
];

/// The check whose reference `--inject-failure` corrupts.
const INJECTED_CHECK: &str = "welch_h1_periodic_exact";

/// Builds and runs the self-test with `args`, panicking with the harness error if that fails.
fn run_selftest(args: &[&str]) -> (QemuRun, Vec<LogLine>) {
    let opts = RunOptions {
        args: args.iter().map(|s| s.to_string()).collect(),
        ..RunOptions::default()
    };
    match build_run_decode("selftest", &opts) {
        Ok(r) => r,
        Err(e) => panic!("QEMU harness: {e}"),
    }
}

fn dump(run: &QemuRun, lines: &[LogLine]) {
    for l in lines {
        println!("target: {l}");
    }
    if !run.stderr.is_empty() {
        println!("target stderr: {}", run.stderr);
    }
    println!("exit code {}", run.exit_code);
}

/// Verdict (`PASS`/`FAIL`) of check `name`, i.e. of the line `CHECK <name> <verdict> ...`.
fn verdict<'a>(lines: &'a [LogLine], name: &str) -> Option<&'a str> {
    lines.iter().find_map(|l| {
        let mut it = l.text.split_whitespace();
        (it.next() == Some("CHECK") && it.next() == Some(name))
            .then(|| it.next())
            .flatten()
    })
}

#[test]
fn selftest_passes_on_cortex_m4f() {
    let (run, lines) = run_selftest(&[]);
    dump(&run, &lines);
    let missing: Vec<&&str> = EXPECTED_CHECKS
        .iter()
        .filter(|c| verdict(&lines, c) != Some("PASS"))
        .collect();
    assert!(
        missing.is_empty(),
        "checks missing or not PASS: {missing:?}"
    );
    let reported = lines
        .iter()
        .filter(|l| l.text.starts_with("CHECK "))
        .count();
    assert_eq!(
        reported,
        EXPECTED_CHECKS.len(),
        "the image reported checks this test does not know about; add them to EXPECTED_CHECKS"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.text == format!("SELFTEST PASS {0}/{0}", EXPECTED_CHECKS.len())),
        "no final SELFTEST PASS line"
    );
    assert_eq!(run.exit_code, 0, "self-test image exit code");
}

#[test]
fn injected_wrong_reference_makes_the_selftest_fail() {
    let (run, lines) = run_selftest(&["--inject-failure"]);
    dump(&run, &lines);
    assert_eq!(run.exit_code, 1, "a failed check must give exit code 1");
    let failed: Vec<&str> = EXPECTED_CHECKS
        .iter()
        .copied()
        .filter(|c| verdict(&lines, c) == Some("FAIL"))
        .collect();
    assert_eq!(failed, [INJECTED_CHECK], "exactly the injected check fails");
    assert!(lines.iter().any(|l| l.text.starts_with("SELFTEST FAIL 1/")));
}

#[test]
fn panic_on_target_exits_nonzero_and_keeps_the_log_decodable() {
    let (run, lines) = run_selftest(&["--panic"]);
    dump(&run, &lines);
    assert_eq!(run.exit_code, 101, "panic exit code");
    assert!(
        run.stderr.contains("panicked at"),
        "panic location on semihosting stderr"
    );
    assert!(!lines.iter().any(|l| l.text.starts_with("SELFTEST PASS")));
}
