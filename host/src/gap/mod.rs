//! Sim-to-real gap diagnosis: where a nominal model and the measured plant disagree, which
//! unmodelled effect explains it, and how far the gap shrinks once the effect is added.
//!
//! Entry point: [`diagnose`] (command line: `ferrosid gap`, [`crate::cli::gap`]).
pub mod align;
pub mod diagnose;
pub mod drift;
pub mod effect;
pub mod evidence;
pub mod figures;
pub mod fit;
pub mod friction_port;
pub mod linear;
pub mod locate;
pub mod logs;
pub mod modal;
pub mod noise;
pub mod outliers;
pub use crate::optim;
pub mod place;
pub mod reading;
pub mod report;
pub mod select;
pub mod simfile;
#[cfg(test)]
pub mod simulator;
pub mod state_limit;
pub mod structure;
pub mod verdict;

pub use diagnose::{diagnose, Diagnosis, GapOptions};
pub use effect::{Effect, EffectKind};
pub use reading::diagnose_at_operating_point;
pub use report::GapReport;
