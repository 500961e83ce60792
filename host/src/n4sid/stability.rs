//! Step 6: stability enforcement of the identified A (reflection and radial pull of poles).
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use crate::error::{Error, Result};
use crate::lti::eigenvalues;
use faer::linalg::solvers::Solve;
use faer::Mat;
use num_complex::Complex64;

pub(super) fn fmt_pole(z: Complex64) -> String {
    format!(
        "{:.6}{:+.6}j (|z| = {:.6}, angle {:.2}°)",
        z.re,
        z.im,
        z.norm(),
        z.arg().to_degrees()
    )
}

/// Moves poles inside |z| <= 1 − margin: reflection 1/z̄ for |z| >= 1, then radial pull to the
/// margin circle. Returns the new A (same state basis) and the change descriptions.
pub(super) fn enforce_stability(a: &Mat<f64>, margin: f64) -> Result<(Mat<f64>, Vec<String>)> {
    let n = a.nrows();
    let rmax = 1.0 - margin;
    let target = |z: Complex64| -> Complex64 {
        let mut t = z;
        if t.norm() >= 1.0 {
            t = Complex64::new(1.0, 0.0) / t.conj();
        }
        if t.norm() > rmax {
            t *= rmax / t.norm();
        }
        t
    };
    let poles = eigenvalues(a.as_ref())?;
    if poles.iter().all(|z| z.norm() <= rmax) {
        return Ok((a.clone(), Vec::new()));
    }
    let mut changes = Vec::new();
    let eig = a
        .eigen()
        .map_err(|e| Error::Numerical(format!("eigendecomposition of A failed: {e:?}")))?;
    let v = eig.U().to_owned();
    let lam: Vec<Complex64> = eig.S().column_vector().iter().copied().collect();
    let sv = v
        .singular_values()
        .map_err(|e| Error::Numerical(format!("SVD of eigenvectors failed: {e:?}")))?;
    let cond = sv[0] / sv[sv.len() - 1];
    if cond.is_finite() && cond < 1e8 {
        let new_lam: Vec<Complex64> = lam.iter().map(|&z| target(z)).collect();
        for (&z, &t) in lam.iter().zip(&new_lam) {
            if (z - t).norm() > 0.0 && z.im >= 0.0 {
                changes.push(format!("pole {} moved to {}", fmt_pole(z), fmt_pole(t)));
            }
        }
        // A' = V Λ' V⁻¹  ⇔  Vᵀ A'ᵀ = (V Λ')ᵀ.
        let vl = Mat::from_fn(n, n, |i, j| v[(i, j)] * new_lam[j]);
        let vt = v.transpose().to_owned();
        let rhs = vl.transpose().to_owned();
        let at = vt.partial_piv_lu().solve(&rhs);
        let scale = crate::lti::norm1(a.as_ref()).max(1.0);
        let mut a_new = Mat::<f64>::zeros(n, n);
        for i in 0..n {
            for j in 0..n {
                let z = at[(j, i)];
                if !(z.im.abs() <= 1e-8 * scale) || !z.re.is_finite() {
                    return Err(Error::Numerical(
                        "stability enforcement produced a complex A (unpaired poles)".into(),
                    ));
                }
                a_new[(i, j)] = z.re;
            }
        }
        Ok((a_new, changes))
    } else {
        // Nearly defective A: scale the whole matrix so that its spectral radius is rmax.
        let rho = poles.iter().map(|z| z.norm()).fold(0.0, f64::max);
        let f = rmax / rho;
        changes.push(format!(
            "A is nearly defective (eigenvector condition {cond:.1e}); all poles scaled by \
             {f:.6} so that the spectral radius {rho:.6} becomes {rmax:.6}"
        ));
        Ok((a * faer::Scale(f), changes))
    }
}
