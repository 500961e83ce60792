//! Linear time-invariant models: state space and transfer functions, their frequency
//! responses, simulation, discretisation (ZOH) and its inverse, and the interconnections
//! (series, parallel, negative feedback) that loop-shaping code builds on.
//!
//! Conventions: `ts == 0.0` means continuous time (x' = Ax + Bu), `ts > 0` discrete time with
//! sample time `ts` seconds (x[k+1] = Ax[k] + Bu[k]). Shapes: A n×n, B n×m, C p×n, D p×m, with
//! n >= 0 states, m >= 1 inputs and p >= 1 outputs. Angular frequencies are in rad/s
//! (`w_rad_s`), ordinary frequencies in Hz (`f_hz`). A discrete model is evaluated on the unit
//! circle, z = exp(j·ω·ts).
//!
//! Numerical contracts:
//! - Frequency responses solve (sI − A)X = B after an orthogonal Hessenberg reduction of A
//!   (done once per evaluator), with a pivoted O(n²) elimination per frequency; never an
//!   explicit inverse. Evaluating at a pole is an [`Error::Numerical`].
//! - [`expm`] is scaling and squaring with Padé approximants of degree 3..13 (Higham 2005,
//!   "The scaling and squaring method for the matrix exponential revisited").
//! - [`logm`] is inverse scaling and squaring: product-form Denman–Beavers square roots with
//!   determinant scaling until ‖X − I‖₁ ≤ 1/4, then a 10-point Gauss–Legendre quadrature of
//!   log(I+Y) = ∫₀¹ Y(I+tY)⁻¹dt (the [10/10] Padé approximant; Higham, "Functions of Matrices",
//!   ch. 11).
//!
//! Module layout (one concept each; everything is re-exported here, so `crate::lti::X` paths
//! stay valid):
//! - [`state_space`]: the [`StateSpace`] model, its invariants, poles, DC gain, and the serde
//!   form [`StateSpaceData`];
//! - [`freq_response`]: frequency evaluation through a once-reduced Hessenberg form
//!   ([`FreqEvaluator`]);
//! - [`simulate`]: time-domain simulation of discrete models;
//! - [`discretize`]: ZOH discretisation and its inverse;
//! - [`interconnect`]: series, parallel and feedback connections;
//! - [`transfer_function`]: SISO transfer functions and the conversions to and from state space;
//! - [`polynomial`]: polynomial algebra and roots (descending powers);
//! - [`matrix_function`]: matrix exponential and logarithm;
//! - [`dense`]: dense-matrix helpers shared by the modules above (finite checks, stacking,
//!   guarded square solve, eigenvalues).
//!
//! Dependency direction inside `lti`: `dense` ← `polynomial`, `matrix_function` ←
//! `state_space` ← the other modules; nothing here imports from outside `crate::error`,
//! `crate::data` (operating point carried by [`StateSpaceData`]) and faer/num-complex/serde.

pub mod dense;
pub mod discretize;
pub mod freq_response;
pub mod interconnect;
pub mod matrix_function;
pub mod polynomial;
pub mod simulate;
pub mod state_space;
pub mod transfer_function;

pub use dense::eigenvalues;
pub(crate) use dense::{norm1, solve_square};
pub use freq_response::FreqEvaluator;
pub use matrix_function::{expm, logm};
pub use polynomial::{poly_add, poly_eval, poly_from_roots, poly_mul, poly_roots};
pub use state_space::{StateSpace, StateSpaceData};
pub use transfer_function::TransferFunction;
