//! Controller synthesis beyond PID (issue 14): the numerical core.
//!
//! - [`lyapunov`]: continuous Lyapunov (A X + X Aᵀ + Q = 0) and discrete Stein
//!   (A X Aᵀ − X + Q = 0) equations, with residual checks;
//! - [`riccati`]: continuous and discrete algebraic Riccati equations (CARE/DARE) by the matrix
//!   sign function of the (Cayley-transformed) Hamiltonian, Newton refinement, and residual,
//!   symmetry and stabilisation checks;
//! - [`hinf`]: H∞ mixed-sensitivity synthesis (W_S S, W_KS KS, W_T T) by γ-iteration on the two
//!   Riccati equations of Doyle–Glover–Khargonekar–Francis (central controller);
//! - [`balred`]: balanced truncation with the 2·Σ(discarded Hankel singular values) bound.
//!
//! Everything here builds on [`crate::lti`] (models, interconnections) and [`crate::robust`]
//! (H∞ norms, loops, receipts); nothing is duplicated from there. Units: time in seconds,
//! frequencies in rad/s (`_rad_s`) or Hz (`_hz`).
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN, so a NaN residual or
// pivot is refused rather than accepted.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
pub mod balred;
pub mod hinf;
pub mod loopshape;
pub mod lyapunov;
pub mod mpc;
pub mod riccati;
pub mod sim;

use faer::{Mat, MatRef};

/// Frobenius norm.
pub(crate) fn fro(m: MatRef<'_, f64>) -> f64 {
    let mut s = 0.0;
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            s += m[(i, j)] * m[(i, j)];
        }
    }
    s.sqrt()
}

/// (M + Mᵀ)/2.
pub(crate) fn sym(m: MatRef<'_, f64>) -> Mat<f64> {
    Mat::from_fn(m.nrows(), m.ncols(), |i, j| 0.5 * (m[(i, j)] + m[(j, i)]))
}

/// ‖M − Mᵀ‖_F / max(‖M‖_F, tiny): 0 for a symmetric matrix.
pub(crate) fn asymmetry(m: MatRef<'_, f64>) -> f64 {
    let d = Mat::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)] - m[(j, i)]);
    fro(d.as_ref()) / fro(m).max(f64::MIN_POSITIVE)
}

/// Refuses a non-square or non-symmetric (relative asymmetry above 1e-10) matrix `name` of
/// expected size `n`.
pub(crate) fn check_symmetric(name: &str, m: MatRef<'_, f64>, n: usize) -> crate::Result<()> {
    if m.nrows() != n || m.ncols() != n {
        return Err(crate::Error::InvalidArgument(format!(
            "{name} must be {n}x{n}, got {}x{}",
            m.nrows(),
            m.ncols()
        )));
    }
    for j in 0..n {
        for i in 0..n {
            if !m[(i, j)].is_finite() {
                return Err(crate::Error::InvalidArgument(format!(
                    "{name}[{i},{j}] = {} is not finite",
                    m[(i, j)]
                )));
            }
        }
    }
    let a = asymmetry(m);
    if a > 1e-10 {
        return Err(crate::Error::InvalidArgument(format!(
            "{name} must be symmetric (relative asymmetry ‖M − Mᵀ‖_F/‖M‖_F = {a:.3e})"
        )));
    }
    Ok(())
}

/// Inverse of a square matrix with log|det|, by LU with partial pivoting; refuses a matrix
/// whose smallest pivot is below n·ε·‖M‖₁ (singular to working precision).
pub(crate) fn inverse_logdet(m: MatRef<'_, f64>, what: &str) -> crate::Result<(Mat<f64>, f64)> {
    use faer::linalg::solvers::Solve;
    let n = m.nrows();
    let lu = m.partial_piv_lu();
    let u = lu.U();
    let scale = crate::lti::norm1(m).max(f64::MIN_POSITIVE);
    let mut logdet = 0.0;
    for i in 0..n {
        let p = u[(i, i)].abs();
        if !(p > (n as f64) * f64::EPSILON * scale) {
            return Err(crate::Error::Numerical(format!(
                "{what}: matrix is singular to working precision (pivot {p:.3e}, norm \
                 {scale:.3e})"
            )));
        }
        logdet += p.ln();
    }
    let inv = lu.solve(Mat::<f64>::identity(n, n).as_ref());
    if (0..n).any(|j| (0..n).any(|i| !inv[(i, j)].is_finite())) {
        return Err(crate::Error::Numerical(format!(
            "{what}: inverse is not finite (matrix nearly singular)"
        )));
    }
    Ok((inv, logdet))
}
