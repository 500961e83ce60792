//! ferrosid firmware core: excitation generators and a streaming Welch estimator with online
//! magnitude-squared coherence, written for a Cortex-M4F (`thumbv7em-none-eabihf`).
//!
//! * `no_std`, no allocator, all sizes are const generics, memory is fixed at compile time.
//! * f32 arithmetic throughout (the M4F has a single-precision FPU).
//! * No panic is reachable from any input: invalid configurations are rejected by constructors
//!   returning `Result`, and non-finite samples are counted and quarantined, never propagated.
//! * Hardware-free: everything here builds and is tested on the host with `cargo test`.
//!
//! Modules: [`check`] (the power-up check: flashed model vs measured response within |W_m|,
//! open-loop H1 and closed-loop indirect estimate),
//! [`control`] (discrete PID with roll-off, friction feedforward, dead-zone and
//! backlash inverses, back-calculation anti-windup; limit-cycle detector), [`excitation`] (PRBS, chirp, multisine), [`welch`] (streaming cross/auto spectra,
//! H1, coherence, [`CoherenceGate`]), [`window`] (flash window tables), [`trig`] (const and fast
//! sine), [`fft`] (microfft dispatch), [`rng`] (seeded SplitMix64), [`decimal`] (small decimal
//! parser for settings), [`Error`].
//!
//! ```
//! use ferrosid_firmware::excitation::Prbs;
//! use ferrosid_firmware::{Excitation, Welch, WelchConfig};
//!
//! // 10-bit MLS, ±1, one chip per sample, into a first-order lag y[n] = 0.9 y[n-1] + 0.1 u[n-1].
//! let mut prbs = Prbs::new(10, 1, 1.0, 1)?;
//! let mut w = Welch::<256>::new(WelchConfig::scipy_default(1000.0, 256))?;
//! let (mut u_prev, mut y) = (0.0f32, 0.0f32);
//! for _ in 0..20_000 {
//!     y = 0.9 * y + 0.1 * u_prev;
//!     u_prev = prbs.next_sample();
//!     w.push(u_prev, y);
//! }
//! // Bin 8 (31.25 Hz): compare with H(e^{jω}) = 0.1 e^{-jω} / (1 - 0.9 e^{-jω}).
//! let om = 2.0 * core::f32::consts::PI * 8.0 / 256.0;
//! let (c, s) = (om.cos(), om.sin());
//! let (den_re, den_im) = (1.0 - 0.9 * c, 0.9 * s);
//! let d2 = den_re * den_re + den_im * den_im;
//! let (h_re, h_im) = (0.1 * (c * den_re - s * den_im) / d2, 0.1 * (-s * den_re - c * den_im) / d2);
//! let (re, im) = w.h1(8).unwrap();
//! assert!(((re - h_re).powi(2) + (im - h_im).powi(2)).sqrt() < 0.03 * (h_re.hypot(h_im)));
//! assert!(w.coherence(8) > 0.95 && w.gate(0.9).count() > 100);
//! # Ok::<(), ferrosid_firmware::Error>(())
//! ```
//!
//! Segment lengths are checked at compile time:
//! ```compile_fail
//! # use ferrosid_firmware::{Welch, WelchConfig};
//! let w = Welch::<100>::new(WelchConfig::scipy_default(1000.0, 100)); // not a power of two
//! ```
#![cfg_attr(not(test), no_std)]

pub mod check;
pub mod control;
pub mod decimal;
mod error;
pub mod excitation;
pub mod fft;
mod gate;
pub mod mpc;
pub mod rng;
pub mod trig;
pub mod welch;
pub mod window;

pub use error::Error;
pub use excitation::Excitation;
pub use gate::{CoherenceGate, MAX_GATE_BINS};
pub use welch::{Welch, WelchConfig};
pub use window::Window;
