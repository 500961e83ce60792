//! Limit cycles of the tuned loop with a diagnosed nonlinearity: describing-function
//! prediction, confirmation by simulating the nonlinear closed loop, and the `limit_cycle`
//! receipt.
//!
//! The failure this guards against: a loop tuned on a linear model that breaks into a
//! self-sustained oscillation on hardware because friction, a dead zone or backlash adds phase
//! lag at low amplitude. For the loop ([`LureLoop`]: identified plant + discretised PID with
//! roll-off) and one nonlinearity at its site ([`Nonlinearity::from_placed`] maps a gap
//! diagnosis effect — drive, friction on the velocity, sensor):
//!
//! 1. [`DescribingFunction`] — N(A) of relay/Coulomb friction, relay with hysteresis,
//!    saturation, dead zone, backlash, quantization and stiction ([`describing`]).
//! 2. [`predict`] — intersections of −1/N(A) with the linear part L(e^{jωT}) seen from the
//!    nonlinearity ([`lure`]), each a [`PredictedLimitCycle`] with frequency (Hz), amplitude (at
//!    the nonlinearity's input) and stability (Loeb criterion).
//! 3. [`simulate`] — the nonlinear closed loop with the gap's effect laws (stick-slip friction
//!    resolved at sub-steps, play, dead zone, saturation, quantizer), optionally with the
//!    compensation of [`crate::compensation`] in the control law; [`detect`] reads the
//!    steady-state tail and returns the oscillation's frequency and amplitude, or `None`.
//! 4. [`analyse`] + [`receipt`] — both together and the receipt `limit_cycle`, which passes
//!    when neither the describing function nor the simulation finds a cycle.
//!
//! The describing function is an approximation (it assumes the loop filters out the
//! harmonics and sees only zero-mean sinusoids); its verdict is never used without the
//! simulation. host/tests/limit_cycle_misleads.rs shows a case (stiction at low speed) where it
//! misses a cycle the simulation finds.
pub mod describing;
pub mod detect;
pub mod lure;
pub mod predict;
pub mod receipt;
pub mod residual;
pub mod simulate;

pub use describing::DescribingFunction;
pub use detect::{detect, DetectOptions, SimulatedLimitCycle};
pub use lure::{Body, LureLoop, Nonlinearity, Site};
pub use predict::{predict, predict_with, PredictOptions, PredictedLimitCycle};
pub use receipt::{analyse, receipt, AnalysisOptions, LimitCycleAnalysis};
pub use residual::Residual;
pub use simulate::{simulate, SimSpec, SimulatedRun};
