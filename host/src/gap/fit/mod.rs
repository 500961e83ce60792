//! Augmented models (linear part + one effect) and the fits that estimate them.
//!
//! Every candidate is fitted the same way on the training logs, minimising the free-run
//! simulation cost Σ NRMSE² (see [`crate::gap::modal`]):
//! 1. **Grid with the poles fixed.** The effect parameters are searched on a grid spanning the
//!    data's scales (input RMS and peak, sample time, resonance band), on the first
//!    [`COARSE_SAMPLES`] scored samples of each training log, starting from each linear part
//!    offered (the linear re-fit and the nominal sim); every point re-fits the residues,
//!    feedthrough and offset by variable projection (exact least squares for the input-side
//!    effects; one simulate-then-refit step for friction, whose force depends on the model).
//! 2. **Joint refinement.** From the best grid point, Levenberg–Marquardt on all the data over
//!    the poles and the effect parameters together ([`joint_fit`]), for a candidate whose
//!    screened fit lowered the coarse cost by at least [`SCREEN_MIN_GAIN`] (one that does not
//!    could not reach the selection margin; it keeps its screened fit).
//!
//! Friction acts against the velocity of the driven mass, which a black-box model does not
//! expose: the fit tries both the model output (velocity-output plants) and its time
//! derivative (position-output plants) and keeps the better ([`VelocitySource`]); with the
//! output as the velocity, the friction force enters either at the input or at the slowest real
//! mode only (the driven body behind faster drive dynamics, e.g. a motor's electrical lag:
//! [`FrictionPort`]). Quantization is estimated from the lattice of the measured outputs.
//!
//! Files: `model.rs` (the augmented model and its simulation), `eval.rs` (training data and the
//! fixed-pole evaluation), `search.rs` (stage 1 grids), `joint.rs` (stage 2 refinement),
//! `placed.rs` (one candidate at a place, end to end), `resonance.rs` (the added mode's grid and
//! labelling).
pub use crate::gap::friction_port::{slowest_mode, FrictionPort};

mod eval;
mod joint;
mod model;
mod placed;
mod resonance;
mod search;
#[cfg(test)]
mod tests;

pub(crate) use eval::keep_best;
pub use eval::{eval_model, Fitted, TrainData};
pub use joint::{joint_fit, refined};
pub(crate) use joint::{stiction_coords, stiction_from_coords};
pub use model::{input_transform, sensor_transform, AugmentedModel, VelocitySource};
pub use placed::{
    beats_by_screen_gain, fit_candidate, fit_placed, null_effect, FitHints, GRID_STARTS,
    SCREEN_MIN_GAIN,
};
pub use resonance::RELABEL_COST_TOL;

use crate::gap::select::lattice_evidence;

/// Sub-steps per sample of the friction loop (friction switches within a sample period).
pub const FRICTION_SUBSTEPS: usize = 4;

/// Lower and upper ends of the search range of resonance frequencies, Hz.
pub fn resonance_range_hz(ts: f64) -> (f64, f64) {
    let fs = 1.0 / ts;
    (fs / 1000.0, 0.45 * fs)
}

/// Largest damping ratio a fitted `resonance` may have (a better-damped mode is not a
/// resonance and would mimic a delay or a lag).
pub const MAX_RESONANCE_DAMPING: f64 = 0.3;

/// Smallest damping ratio a fitted `resonance` may have: lighter damping than this is below
/// what any log of practical length resolves (its half-power bandwidth 2ζf would be finer than
/// the frequency resolution of 10^4 periods of the mode), and an optimiser left free drifts to
/// absurd values (1e-107 was once reported).
pub const MIN_RESONANCE_DAMPING: f64 = 1e-4;

/// Longest delay searched, in samples.
pub const MAX_DELAY_SAMPLES: f64 = 32.0;

/// The output quantization step read off the lattice of measured values (see
/// [`crate::gap::select::lattice_evidence`]), `None` when the outputs do not sit on a lattice.
pub fn lattice_step(y: &[Vec<f64>]) -> Option<f64> {
    lattice_evidence(y).map(|l| l.step)
}

/// Samples per training log (after the warm-up) used by the coarse grid stage.
pub const COARSE_SAMPLES: usize = 4096;

/// Iteration cap of the joint Levenberg–Marquardt refinement.
pub const JOINT_MAX_ITER: usize = 12;

/// Relative cost decrease below which a joint refinement stops: a further step would move the
/// likelihood ratio of a log of 10^4 samples by less than 0.1.
pub const JOINT_RTOL: f64 = 1e-5;

/// Iteration cap of the coarse screening refinements (they rank the starts and decide whether
/// the best earns the full refinement, see [`SCREEN_MIN_GAIN`]).
pub const SCREEN_MAX_ITER: usize = 4;
