//! Linear time-invariant models: state space and transfer functions, their frequency
//! responses, simulation, discretisation (ZOH) and its inverse.
//!
//! Conventions: `ts == 0.0` means continuous time (x' = Ax + Bu), `ts > 0` discrete time with
//! sample time `ts` seconds (x[k+1] = Ax[k] + Bu[k]). Shapes: A n×n, B n×m, C p×n, D p×m.
use faer::Mat;

/// A state-space model (A, B, C, D) with its sample time.
#[derive(Debug, Clone)]
pub struct StateSpace {
    /// State matrix, n×n.
    pub a: Mat<f64>,
    /// Input matrix, n×m.
    pub b: Mat<f64>,
    /// Output matrix, p×n.
    pub c: Mat<f64>,
    /// Feedthrough matrix, p×m.
    pub d: Mat<f64>,
    /// Sample time in seconds; 0 for continuous time.
    pub ts: f64,
}
