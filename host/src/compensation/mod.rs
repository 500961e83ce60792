//! Compensation of a diagnosed nonlinearity: its design from the gap diagnosis ([`design`]),
//! the control law that applies it in f64 ([`ControlStep`], the same law the firmware runs in
//! f32), and the residual nonlinearity the loop still sees ([`residual::Residual`], for the
//! limit-cycle prediction of the compensated loop).
//!
//! The compensation itself is [`ferrosid_codegen::Compensation`] (plain data shared with the
//! generated headers): friction feedforward (Coulomb + viscous with a smoothing band around
//! zero velocity), dead-zone inverse, backlash inverse (only at the drive) and back-calculation
//! anti-windup for saturation; all magnitudes in the plant's input units.
pub mod design;
pub mod law;
pub mod residual;

pub use design::{design, design_from, parse_verdict, verdict_effects, DesignOptions};
pub use law::ControlStep;
pub use residual::Residual;
