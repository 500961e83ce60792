//! Robust control with receipts: the numerical core that turns an identified plant into a
//! controller an engineer can trust, and the evidence (receipts) that it can be trusted.
//!
//! - [`norms`]: H∞ norm by Hamiltonian bisection (continuous and discrete), with its peak
//!   frequency.
pub mod audit;
pub mod discretize;
pub mod loops;
pub mod norms;
pub mod pid;
pub mod receipts;
pub mod step;
pub mod uncertainty;
