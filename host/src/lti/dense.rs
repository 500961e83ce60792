//! Dense-matrix helpers shared by the LTI modules: finite-entry and sample-time checks, block
//! stacking, the induced 1-norm, a guarded square solve, and eigenvalues.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use crate::error::{Error, Result};
use faer::linalg::solvers::Solve;
use faer::{Mat, MatRef};
use num_complex::Complex64;

/// Refuses a matrix with a non-finite entry, naming it `name[i,j]`.
pub(crate) fn check_finite(name: &str, m: MatRef<'_, f64>) -> Result<()> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            let v = m[(i, j)];
            if !v.is_finite() {
                return Err(Error::InvalidArgument(format!(
                    "{name}[{i},{j}] = {v} is not finite"
                )));
            }
        }
    }
    Ok(())
}

/// Refuses a sample time that is not finite or negative (seconds; 0 = continuous).
pub(crate) fn check_ts(ts: f64) -> Result<()> {
    if !ts.is_finite() || ts < 0.0 {
        return Err(Error::InvalidArgument(format!(
            "sample time ts = {ts} s must be finite and >= 0 (0 = continuous time)"
        )));
    }
    Ok(())
}

/// True when two sample times (s) are equal up to a relative 1e-12.
pub(crate) fn same_ts(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

/// Induced 1-norm (largest column sum of absolute values).
pub(crate) fn norm1(m: MatRef<'_, f64>) -> f64 {
    let mut best = 0.0f64;
    for j in 0..m.ncols() {
        let s: f64 = (0..m.nrows()).map(|i| m[(i, j)].abs()).sum();
        best = best.max(s);
    }
    best
}

/// The block matrix [[a11, a12], [a21, a22]].
pub(crate) fn block2x2(
    a11: MatRef<'_, f64>,
    a12: MatRef<'_, f64>,
    a21: MatRef<'_, f64>,
    a22: MatRef<'_, f64>,
) -> Mat<f64> {
    let (r1, c1) = (a11.nrows(), a11.ncols());
    let (r2, c2) = (a22.nrows(), a22.ncols());
    Mat::from_fn(r1 + r2, c1 + c2, |i, j| match (i < r1, j < c1) {
        (true, true) => a11[(i, j)],
        (true, false) => a12[(i, j - c1)],
        (false, true) => a21[(i - r1, j)],
        (false, false) => a22[(i - r1, j - c1)],
    })
}

/// Stacks `top` above `bottom`.
pub(crate) fn vstack(top: MatRef<'_, f64>, bottom: MatRef<'_, f64>) -> Mat<f64> {
    let r1 = top.nrows();
    let cols = top.ncols().max(bottom.ncols());
    Mat::from_fn(r1 + bottom.nrows(), cols, |i, j| {
        if i < r1 {
            top[(i, j)]
        } else {
            bottom[(i - r1, j)]
        }
    })
}

/// Puts `left` beside `right`.
pub(crate) fn hstack(left: MatRef<'_, f64>, right: MatRef<'_, f64>) -> Mat<f64> {
    let c1 = left.ncols();
    let rows = left.nrows().max(right.nrows());
    Mat::from_fn(rows, c1 + right.ncols(), |i, j| {
        if j < c1 {
            left[(i, j)]
        } else {
            right[(i, j - c1)]
        }
    })
}

/// Solves `a · x = rhs` for square `a` by LU with partial pivoting, refusing singular or
/// non-finite results.
pub(crate) fn solve_square(
    a: MatRef<'_, f64>,
    rhs: MatRef<'_, f64>,
    what: &str,
) -> Result<Mat<f64>> {
    let n = a.nrows();
    if n == 0 {
        return Ok(Mat::zeros(0, rhs.ncols()));
    }
    let lu = a.partial_piv_lu();
    let u = lu.U();
    let scale = norm1(a).max(f64::MIN_POSITIVE);
    let min_piv = (0..n)
        .map(|i| u[(i, i)].abs())
        .fold(f64::INFINITY, f64::min);
    if !(min_piv > (n as f64) * f64::EPSILON * scale) {
        return Err(Error::Numerical(format!(
            "{what}: matrix is singular to working precision (smallest LU pivot {min_piv:.3e}, \
             norm {scale:.3e})"
        )));
    }
    let x = lu.solve(rhs);
    check_finite(what, x.as_ref()).map_err(|_| {
        Error::Numerical(format!(
            "{what}: solution is not finite (matrix nearly singular)"
        ))
    })?;
    Ok(x)
}

/// Eigenvalues of a real square matrix (any order; empty for 0×0).
pub fn eigenvalues(a: MatRef<'_, f64>) -> Result<Vec<Complex64>> {
    if a.nrows() != a.ncols() {
        return Err(Error::InvalidArgument(format!(
            "eigenvalues of a non-square {}x{} matrix",
            a.nrows(),
            a.ncols()
        )));
    }
    if a.nrows() == 0 {
        return Ok(Vec::new());
    }
    check_finite("matrix", a)?;
    a.eigenvalues()
        .map_err(|e| Error::Numerical(format!("eigenvalue iteration did not converge: {e:?}")))
}
