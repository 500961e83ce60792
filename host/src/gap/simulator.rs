//! Test-only (`#[cfg(test)]`): the simulator of the dev crate `ferrosid-sim` (`sim/src/`),
//! compiled into the library's unit tests, and the fixed noise signal of the modal and drift
//! tests. The library build does not contain any of it.
//!
//! Why the files are included rather than the crate used: `ferrosid-sim` depends on
//! `ferrosid`, so as a dev-dependency of the unit tests it would bring a second copy of the
//! library whose `Effect`, `StateSpace`, ... are other types than the ones under test. The
//! same three files are compiled here against this crate (`extern crate self as ferrosid` in
//! `lib.rs`), so the unit tests and the integration tests use one simulator and one RNG.
#[path = "../../../sim/src/benchmark.rs"]
pub mod benchmark;
#[path = "../../../sim/src/plant.rs"]
pub mod plant;
#[path = "../../../sim/src/rng.rs"]
pub mod rng;

/// Uniform noise in [-0.5, 0.5) from the workspace's generator ([`rng::Rng`]): the fixed test
/// signal of the modal and drift tests.
pub fn uniform_noise(n: usize, seed: u64) -> Vec<f64> {
    let mut r = rng::Rng::new(seed);
    (0..n).map(|_| r.uniform() - 0.5).collect()
}
