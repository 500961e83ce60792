//! Each command's whole job as a library call: typed options in, a serde-serialisable typed
//! report out, no printing and no files. The front ends (`cli`, a future Python package) map
//! their arguments to these options and render the reports; [`crate::pipeline`] composes the
//! same building blocks into one run.
//!
//! * [`arrays`] — logs from arrays in memory, checked like files (the Python package);
//! * [`codegen`] — the firmware-header generator input from a model, controller, weight and
//!   receipts in memory (`ferrosid codegen`, and a pipeline run without the disk);
//! * [`frf`] — empirical frequency response (Welch H1 or period-synchronous) with coherence
//!   gating, from one or more logs (`ferrosid frf`);
//! * [`identify`] — N4SID with order selection, continuous-time equivalent and validation
//!   against a log (`ferrosid identify`).
//!
//! Long steps report through a [`Progress`] the caller supplies ([`NoProgress`] ignores it),
//! so the library never draws on a terminal itself.
pub mod arrays;
pub mod codegen;
pub mod frf;
pub mod identify;

/// Receives the progress of long steps (the CLI draws it as a bar or a spinner on stderr).
pub trait Progress {
    /// A step named `what` starts; `total` units of work when known (a bar), else a spinner.
    fn begin(&self, what: &str, total: Option<u64>);
    /// `n` more units of the current step are done.
    fn advance(&self, n: u64);
    /// The current step is finished.
    fn end(&self);
}

/// A [`Progress`] that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn begin(&self, _what: &str, _total: Option<u64>) {}
    fn advance(&self, _n: u64) {}
    fn end(&self) {}
}

/// `v` for a message: plain for ordinary magnitudes, scientific otherwise (never 300 digits).
pub fn num(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-4..1e9).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Checks a numeric flag at the command-line boundary: `v` finite and within `lo..=hi`
/// (`lo` excluded when `open_lo`). The error names the flag, the range, its unit and the value.
///
/// # Errors
/// [`crate::error::Error::InvalidArgument`] (exit 2).
pub fn check_flag(
    flag: &str,
    v: f64,
    lo: f64,
    open_lo: bool,
    hi: f64,
    unit: &str,
) -> crate::error::Result<()> {
    let above_lo = if open_lo { v > lo } else { v >= lo };
    if v.is_finite() && above_lo && v <= hi {
        return Ok(());
    }
    let range = if open_lo && lo == 0.0 {
        format!("> 0 and <= {}", num(hi))
    } else {
        format!("in [{}, {}]", num(lo), num(hi))
    };
    Err(crate::error::Error::InvalidArgument(format!(
        "{flag} must be a finite number {range}{unit}, got {}",
        num(v)
    )))
}
