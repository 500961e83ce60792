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
