//! Hardware/QEMU glue of the power-up and closed-loop images, free of hardware.
//!
//! The check itself (model response, |W_m|, per-frequency verdicts, the open-loop and
//! closed-loop estimates) lives in the firmware crate, [`ferrosid_firmware::check`], and is
//! re-exported here for the images; [`plant`] holds the discrete plant simulations that stand
//! in for hardware under QEMU.
#![no_std]
#![forbid(unsafe_code)]

pub use ferrosid_firmware::check::*;

pub mod plant;
