//! ferrosid firmware core: excitation generators and a streaming Welch estimator with online
//! magnitude-squared coherence, written for a Cortex-M4F (`thumbv7em-none-eabihf`).
//!
//! * `no_std`, no allocator, all sizes are const generics, memory is fixed at compile time.
//! * f32 arithmetic throughout (the M4F has a single-precision FPU).
//! * No panic is reachable from any input: invalid configurations are rejected by constructors
//!   returning `Result`, and non-finite samples are counted and quarantined, never propagated.
//! * Hardware-free: everything here builds and is tested on the host with `cargo test`.
//!
//! Modules: [`excitation`] (PRBS, chirp, multisine), [`welch`] (streaming cross/auto spectra,
//! H1, coherence, [`CoherenceGate`]), [`window`] (flash window tables), [`trig`] (const and fast
//! sine), [`fft`] (microfft dispatch), [`rng`] (seeded SplitMix64), [`Error`].
#![cfg_attr(not(test), no_std)]

mod error;
pub mod excitation;
pub mod fft;
mod gate;
pub mod rng;
pub mod trig;
pub mod welch;
pub mod window;

pub use error::Error;
pub use excitation::Excitation;
pub use gate::{CoherenceGate, MAX_GATE_BINS};
pub use welch::{Welch, WelchConfig};
pub use window::Window;
