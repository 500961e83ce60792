//! ferrosid: system identification with receipts.
//!
//! From raw input/output logs to a verified model and the evidence of where it holds:
//! ingestion ([`io`]), preprocessing ([`preprocess`]), Welch H1 frequency response with
//! coherence gating ([`spectral`]), LTI models and their algebra ([`lti`]), N4SID subspace
//! identification ([`n4sid`]) and validation ([`validate`]).
//!
//! Units: time in seconds, frequency in Hz unless a name says `_rad_s`. All numerics are f64.
#![forbid(unsafe_code)]

// The unit tests compile the dev crate ferrosid-sim's simulator files into this crate
// (`gap::simulator`); those files name the library `ferrosid::`, as they do in their own crate.
#[cfg(test)]
extern crate self as ferrosid;

#[cfg(feature = "cli")]
pub mod cli;
pub mod closed_loop;
pub mod compensation;
pub mod data;
pub mod error;
pub mod fleet;
pub mod gap;
pub mod greybox;
pub mod io;
pub mod limit_cycle;
pub mod lti;
pub mod n4sid;
pub mod operating_point;
pub mod ops;
pub mod optim;
pub mod output;
pub mod pipeline;
pub mod plot;
pub mod preprocess;
pub mod rational_fit;
pub mod report;
pub mod robust;
pub mod spectral;
pub mod synth;
pub mod target_frame;
pub mod validate;

pub use data::{Channel, Log};
pub use error::{Error, Result};
