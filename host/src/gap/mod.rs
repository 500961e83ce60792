//! Sim-to-real gap diagnosis (placeholder docs, replaced below).
pub mod effect;
pub mod fit;
pub mod modal;
pub mod optim;
pub mod plant;
pub mod rng;
pub mod simfile;
