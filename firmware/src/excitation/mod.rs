//! Excitation generators: deterministic, seeded, sample by sample.
//!
//! * [`Prbs`]: maximum-length binary sequence (MLS) from a Galois LFSR, register length 5..=31.
//! * [`Chirp`]: linear or logarithmic swept sine with raised-cosine fades.
//! * [`Multisine`]: one period of `N` samples built from chosen FFT lines, with Schroeder,
//!   random or optimised phases; the odd random-phase design of Pintelon & Schoukens via
//!   [`odd_random_phase_lines`].
//!
//! All generators implement [`Excitation`]; none allocates or panics.

mod chirp;
mod multisine;
mod prbs;

pub use chirp::{Chirp, ChirpConfig, ChirpLaw};
pub use multisine::{
    odd_random_phase_lines, Line, Multisine, MultisineScratch, MultisineSpec, OddLineCounts, Phases,
};
pub use prbs::{taps as prbs_taps, Prbs, MAX_BITS as PRBS_MAX_BITS, MIN_BITS as PRBS_MIN_BITS};

/// A source of excitation samples: one call per sample period `1/fs`.
pub trait Excitation {
    /// The next sample (in the generator's amplitude units). Never panics, always finite.
    fn next_sample(&mut self) -> f32;
}
