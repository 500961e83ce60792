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

/// Uniform noise in [-0.5, 0.5) from a 64-bit LCG (Knuth's MMIX constants): a fixed test
/// signal for the gap unit tests, independent of [`rng::Rng`].
pub fn lcg_noise(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        })
        .collect()
}
