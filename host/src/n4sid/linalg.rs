//! Dense helpers of the subspace steps: inner product, thin SVD, pivoted least squares.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use crate::error::{Error, Result};
use faer::linalg::solvers::SolveLstsq;
use faer::{Mat, MatRef};

/// 8-lane dot product (vectorisable without reassociation by the compiler).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut s = (acc[0] + acc[4]) + (acc[1] + acc[5]) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

pub(super) struct Svd {
    pub(super) u: Mat<f64>,
    pub(super) s: Vec<f64>,
    pub(super) v: Mat<f64>,
}

pub(super) fn thin_svd(m: MatRef<'_, f64>, what: &str) -> Result<Svd> {
    let svd = m
        .thin_svd()
        .map_err(|e| Error::Numerical(format!("SVD of {what} did not converge: {e:?}")))?;
    let s: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    Ok(Svd {
        u: svd.U().to_owned(),
        s,
        v: svd.V().to_owned(),
    })
}

/// Least squares min ‖A x − B‖ by column-pivoted QR; errors when A is rank deficient to
/// working precision.
pub(super) fn lstsq(a: MatRef<'_, f64>, b: MatRef<'_, f64>, what: &str) -> Result<Mat<f64>> {
    let qr = a.col_piv_qr();
    let r = qr.R();
    let d = a.ncols().min(a.nrows());
    if d == 0 {
        return Ok(Mat::zeros(a.ncols(), b.ncols()));
    }
    let r0 = r[(0, 0)].abs();
    let rmin = (0..d)
        .map(|i| r[(i, i)].abs())
        .fold(f64::INFINITY, f64::min);
    if !(rmin > 1e-13 * r0) || a.nrows() < a.ncols() {
        return Err(Error::Numerical(format!(
            "{what}: regressors are rank deficient (pivot ratio {:.1e})",
            rmin / r0
        )));
    }
    let x = qr.solve_lstsq(b);
    for j in 0..x.ncols() {
        for i in 0..x.nrows() {
            if !x[(i, j)].is_finite() {
                return Err(Error::Numerical(format!("{what}: solution not finite")));
            }
        }
    }
    Ok(x)
}
