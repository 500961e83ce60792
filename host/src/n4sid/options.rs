//! Options of an N4SID identification: horizon, order choice, weighting, factorization, and
//! which parts of the model are estimated.
use serde::Serialize;

/// How the weighted projection is formed before the SVD (see the module docs). Also the
/// `--weighting` value of `ferrosid identify` (feature `cli`: `moesp`, `cva`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Weighting {
    /// PO-MOESP: SVD of L₃₂ (W₁ = I, W₂ = Π⊥_{U_f}). Default.
    Moesp,
    /// Canonical variate analysis: W₁ = (Y_f Π⊥_{U_f} Y_fᵀ)^(−½), W₂ = Π⊥_{U_f}.
    Cva,
}

/// How the LQ factor of the block Hankel matrix is obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Factorization {
    /// Cholesky of the correlation matrix (fast), Householder QR if that fails. Default.
    Auto,
    /// Householder QR of the J × 2i(m+p) data matrix (slower, never squares the conditioning).
    Qr,
}

/// Model order: fixed, or selected automatically within a range (rule in the module docs:
/// the largest singular-value gap among the orders supported by Bauer's SVC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum OrderSelection {
    /// Automatic over 1..=min((i−1)·p, 20).
    Auto,
    /// Automatic within `min..=max` (both >= 1, max <= (i−1)·p).
    Range {
        /// Smallest order considered.
        min: usize,
        /// Largest order considered.
        max: usize,
    },
    /// Exactly this order (1..=(i−1)·p).
    Fixed(usize),
}

/// Largest accepted number of block rows i. The data matrix has 2·i·(m+p) rows and its
/// correlation matrix (2·i·(m+p))² entries: i = 1000 with one input and one output is already a
/// 4000 × 4000 matrix (128 MB), beyond anything a plant model of order ≤ (i−1)·p needs.
pub const MAX_BLOCK_ROWS: usize = 1000;

/// Options of [`n4sid`]. `Default` gives i = 20, automatic order, MOESP weighting, D and x0
/// estimated, no stability enforcement, Kalman gain estimated.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct N4sidOptions {
    /// Number of block rows i (past and future horizon), in 2..=[`MAX_BLOCK_ROWS`].
    pub block_rows: usize,
    /// Order choice.
    pub order: OrderSelection,
    /// Weighting of the projection before the SVD.
    pub weighting: Weighting,
    /// LQ factor computation.
    pub factorization: Factorization,
    /// Estimate the feedthrough D (false: D = 0).
    pub estimate_d: bool,
    /// With `estimate_d`, a significance test on the estimate: `Some(k)` fixes D = 0 (and re-fits
    /// B and x0) when every entry of D lies within k standard errors of zero. The standard errors
    /// come from the output-error least squares, σ²·diag((ΦᵀΦ)⁻¹) with σ² the pooled residual
    /// variance (exact for white output noise on a SISO log). A strictly proper plant sampled
    /// with a zero-order hold has D = 0; an insignificant D estimate only adds noise where the
    /// plant's gain is small. `None` (default): D is kept as estimated.
    pub d_significance: Option<f64>,
    /// Estimate the initial state x0 together with B and D (false: x0 = 0).
    pub estimate_x0: bool,
    /// If set, enforce every discrete pole to satisfy |z| <= 1 − margin (0 < margin < 1).
    pub stability_margin: Option<f64>,
    /// Estimate the steady-state Kalman gain (innovation form) for one-step prediction.
    pub estimate_kalman_gain: bool,
}

impl Default for N4sidOptions {
    fn default() -> Self {
        Self {
            block_rows: 20,
            order: OrderSelection::Auto,
            weighting: Weighting::Moesp,
            factorization: Factorization::Auto,
            estimate_d: true,
            d_significance: None,
            estimate_x0: true,
            stability_margin: None,
            estimate_kalman_gain: true,
        }
    }
}
