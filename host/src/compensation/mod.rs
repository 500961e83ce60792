//! Compensation of a diagnosed nonlinearity: its design from the gap diagnosis ([`design`]),
//! the control law that applies it in f64 ([`ControlStep`], the same law the firmware runs in
//! f32). The residual nonlinearity the compensated loop still sees is
//! [`crate::limit_cycle::Residual`] (a describing-function concept, so it lives there).
//!
//! The compensation itself is [`ferrosid_codegen::Compensation`] (plain data shared with the
//! generated headers): friction feedforward (Coulomb + viscous with a smoothing band around
//! zero velocity), dead-zone inverse, backlash inverse (only at the drive) and back-calculation
//! anti-windup for saturation; all magnitudes in the plant's input units.
pub mod design;
pub mod law;

pub use design::{design, design_from, parse_verdict, verdict_effects, DesignOptions};
pub use law::ControlStep;
