//! The receipt's log lines, shared by the `powerup` and `closedloop` images (`#[path]` module:
//! one definition of the `RECEIPT` and `VERDICT` formats the host parses, see
//! `ferrosid_frame::RECEIPT_FIELDS`).
use ferrosid_powerup::{failed_hz, CheckResult, Overall};

/// One `RECEIPT` line per check frequency.
pub fn rows(results: &[CheckResult]) {
    for r in results {
        defmt::println!(
            "RECEIPT {=u16} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=str}",
            r.bin,
            r.hz,
            r.coherence,
            r.g0.re,
            r.g0.im,
            r.g_meas.re,
            r.g_meas.im,
            r.rel_error,
            r.wm,
            r.sigma,
            r.verdict.as_str()
        );
    }
}

/// The `VERDICT` line over `C` results (`min_checked` counted frequencies needed); returns the
/// verdict for the exit status.
pub fn verdict<const C: usize>(results: &[CheckResult; C], min_checked: usize) -> Overall {
    let overall = Overall::from_checks(results, min_checked);
    let failed = failed_hz(results);
    let checked = results.iter().filter(|r| r.verdict.counts()).count();
    defmt::println!(
        "VERDICT {=str} checked={=usize}/{=usize} failed_hz={=[?]}",
        overall.as_str(),
        checked,
        C,
        failed.as_slice()
    );
    overall
}
