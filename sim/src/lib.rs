//! Development-only simulators for ferrosid: NOT part of the `ferrosid` library.
//!
//! * [`plant`] — the same-law plant simulator (four physical plants, one effect each, the
//!   effect laws of `ferrosid::gap::effect` integrated at sub-steps);
//! * [`benchmark`] — the same-law gap benchmark: setups, labelled cases, log generation,
//!   scoring and the markdown summary, plus the excitation signals ([`benchmark::filtered_noise`],
//!   [`benchmark::multisine`]);
//! * [`rng`] — the seeded SplitMix64 / Box–Muller generator behind every generated log.
//!
//! Used by ferrosid's integration tests, benches and examples (a dev-dependency), by the
//! example-data generators in `sim/examples/` and by `ferrosid-gapsim` (its first family).
//! The library's own unit tests compile these same three files into their test build
//! (`host/src/gap/simulator.rs`, `#[cfg(test)]`): a dev crate that depends on `ferrosid` would
//! hand them a second copy of the library with different types. So the files name the library
//! as `ferrosid::` (the library's test build has `extern crate self as ferrosid`) and each other
//! as `super::`.
pub mod benchmark;
pub mod plant;
pub mod rng;
