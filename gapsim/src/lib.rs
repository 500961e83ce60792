//! An independent second simulator for the ferrosid gap benchmark, and the two-family benchmark
//! harness.
//!
//! The first family (`ferrosid_sim::benchmark`) generates every effect with the same equations
//! and in the same place as the candidate models the diagnosis fits. This crate generates logs
//! from separately written physics: its own adaptive Dormand–Prince 5(4) integrator with event
//! location ([`ode`]), its own effect laws (Karnopp, Stribeck, LuGre and Dahl friction on the
//! motor or the load side, backlash in the drive or in a two-mass shaft, dead band, saturation,
//! slew-rate limit, state limit, sensor clipping, quantization after noise, fractional delays,
//! modes at the actuator or the sensor; [`laws`], [`hybrid`]), its own plants ([`plants`]) and
//! its own random numbers ([`rng`]). Nothing here uses `ferrosid::gap` except to run the
//! diagnosis under test and the first family in [`bench`].
pub mod bench;
pub mod cases;
pub mod excite;
pub mod hybrid;
pub mod laws;
pub mod null;
pub mod ode;
pub mod plants;
pub mod rng;
pub mod score;
pub mod simulate;
