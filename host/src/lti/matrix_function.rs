//! Matrix exponential and principal logarithm of real square matrices.
//!
//! - [`expm`] is scaling and squaring with Padé approximants of degree 3..13 (Higham 2005,
//!   "The scaling and squaring method for the matrix exponential revisited").
//! - [`logm`] is inverse scaling and squaring: product-form Denman–Beavers square roots with
//!   determinant scaling until ‖X − I‖₁ ≤ 1/4, then a 10-point Gauss–Legendre quadrature of
//!   log(I+Y) = ∫₀¹ Y(I+tY)⁻¹dt (the [10/10] Padé approximant; Higham, "Functions of Matrices",
//!   ch. 11).
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::dense::{check_finite, eigenvalues, norm1, solve_square};
use crate::error::{Error, Result};
use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, MatRef};

/// Padé coefficients c_k (k = 0..=m) of the [m/m] approximant of exp(x):
/// c_k = (2m−k)!·m! / ((2m)!·k!·(m−k)!).
fn pade_coefficients(m: usize) -> Vec<f64> {
    let mut c = vec![1.0; m + 1];
    for k in 0..m {
        c[k + 1] = c[k] * (m - k) as f64 / (((2 * m - k) * (k + 1)) as f64);
    }
    c
}

fn pade_expm(a: MatRef<'_, f64>, deg: usize) -> Result<Mat<f64>> {
    let n = a.nrows();
    let c = pade_coefficients(deg);
    let a2 = a * a;
    // Even powers I, A², A⁴, ...
    let mut even = vec![Mat::<f64>::identity(n, n)];
    while even.len() <= deg / 2 {
        let next = &even[even.len() - 1] * &a2;
        even.push(next);
    }
    let mut u_inner = Mat::<f64>::zeros(n, n);
    let mut v = Mat::<f64>::zeros(n, n);
    for (j, pw) in even.iter().enumerate() {
        let k_even = 2 * j;
        let k_odd = 2 * j + 1;
        if k_even <= deg {
            v += pw * faer::Scale(c[k_even]);
        }
        if k_odd <= deg {
            u_inner += pw * faer::Scale(c[k_odd]);
        }
    }
    let u = a * &u_inner;
    let num = &v + &u;
    let den = &v - &u;
    solve_square(den.as_ref(), num.as_ref(), "expm: Padé denominator")
}

/// Matrix exponential of a real square matrix by scaling and squaring with Padé approximants
/// (Higham 2005): degree 3, 5, 7, 9 or 13 chosen from ‖A‖₁, scaling by 2⁻ˢ so that
/// ‖A/2ˢ‖₁ ≤ θ₁₃ = 5.37, then s squarings. Accurate to about unit roundoff times the
/// condition number of exp at A.
pub fn expm(a: MatRef<'_, f64>) -> Result<Mat<f64>> {
    let n = a.nrows();
    if a.ncols() != n {
        return Err(Error::InvalidArgument(format!(
            "expm of a non-square {}x{} matrix",
            n,
            a.ncols()
        )));
    }
    check_finite("expm argument", a)?;
    if n == 0 {
        return Ok(Mat::zeros(0, 0));
    }
    // θ_m from Higham (2005), Table 2.3: the largest ‖A‖₁ for which the [m/m] Padé
    // approximant has backward error below unit roundoff.
    const THETA: [(usize, f64); 4] = [
        (3, 1.495585217958292e-2),
        (5, 2.53939833006323e-1),
        (7, 9.504178996162932e-1),
        (9, 2.097847961257068e0),
    ];
    const THETA13: f64 = 5.371920351148152;
    let nrm = norm1(a);
    for (deg, theta) in THETA {
        if nrm <= theta {
            return pade_expm(a, deg);
        }
    }
    let s = (nrm / THETA13).log2().ceil().max(0.0);
    if s > 1000.0 {
        return Err(Error::Numerical(format!(
            "expm: ‖A‖₁ = {nrm:.3e} is too large"
        )));
    }
    let scale = 0.5f64.powi(s as i32);
    let a_scaled = Mat::from_fn(n, n, |i, j| a[(i, j)] * scale);
    let mut r = pade_expm(a_scaled.as_ref(), 13)?;
    for _ in 0..(s as usize) {
        r = &r * &r;
    }
    check_finite("expm result", r.as_ref())
        .map_err(|_| Error::Numerical("expm: result overflowed".into()))?;
    Ok(r)
}

/// Gauss–Legendre nodes and weights on [0, 1] (Newton iteration on P_m).
fn gauss_legendre_01(m: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; m];
    let mut w = vec![0.0; m];
    for i in 0..m {
        // Initial guess (Tricomi), then Newton on P_m.
        let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (m as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, z);
            for k in 2..=m {
                let p2 = ((2 * k - 1) as f64 * z * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let pm = if m == 0 { 1.0 } else { p1 };
            let pm1 = if m <= 1 { 1.0 } else { p0 };
            dp = m as f64 * (z * pm - pm1) / (z * z - 1.0);
            let dz = pm / dp;
            z -= dz;
            if dz.abs() < 1e-16 {
                break;
            }
        }
        x[i] = 0.5 * (1.0 - z);
        w[i] = 1.0 / ((1.0 - z * z) * dp * dp);
    }
    (x, w)
}

/// One principal square root by the scaled product-form Denman–Beavers iteration.
fn sqrtm_db(a: &Mat<f64>) -> Result<Mat<f64>> {
    let n = a.nrows();
    let id = Mat::<f64>::identity(n, n);
    let mut mk = a.clone();
    let mut yk = a.clone();
    for _ in 0..100 {
        let lu = mk.partial_piv_lu();
        let u = lu.U();
        let logdet: f64 = (0..n).map(|i| u[(i, i)].abs().ln()).sum();
        if !logdet.is_finite() {
            return Err(Error::Numerical(
                "logm: singular matrix in square-root iteration (eigenvalue at 0)".into(),
            ));
        }
        let minv = lu.inverse();
        let dist = norm1((&mk - &id).as_ref());
        let mu = if dist > 1e-2 {
            (-logdet / (2.0 * n as f64)).exp()
        } else {
            1.0
        };
        let mu2 = mu * mu;
        // Y <- ½·μ·Y·(I + μ⁻²M⁻¹); M <- ½(I + (μ²M + μ⁻²M⁻¹)/2)
        let t = &id + &minv * faer::Scale(1.0 / mu2);
        yk = &yk * &t * faer::Scale(0.5 * mu);
        mk = (&id + (&mk * faer::Scale(mu2) + &minv * faer::Scale(1.0 / mu2)) * faer::Scale(0.5))
            * faer::Scale(0.5);
        check_finite("sqrtm", yk.as_ref())
            .map_err(|_| Error::Numerical("logm: square-root iteration diverged".into()))?;
        if norm1((&mk - &id).as_ref()) <= 4.0 * n as f64 * f64::EPSILON {
            return Ok(yk);
        }
    }
    Err(Error::Numerical(
        "logm: square-root iteration did not converge (eigenvalues near the negative real axis?)"
            .into(),
    ))
}

/// Principal matrix logarithm of a real square matrix with no eigenvalue on the closed negative
/// real axis (inverse scaling and squaring; see the module docs). Errors name the offending
/// eigenvalue.
pub fn logm(a: MatRef<'_, f64>) -> Result<Mat<f64>> {
    let n = a.nrows();
    if a.ncols() != n {
        return Err(Error::InvalidArgument(format!(
            "logm of a non-square {}x{} matrix",
            n,
            a.ncols()
        )));
    }
    check_finite("logm argument", a)?;
    if n == 0 {
        return Ok(Mat::zeros(0, 0));
    }
    for z in eigenvalues(a)? {
        let r = z.norm();
        if r <= 1e-300 || (z.re <= 0.0 && z.im.abs() <= 1e-12 * r) {
            return Err(Error::Numerical(format!(
                "logm: eigenvalue {z:.6e} on the closed negative real axis, no real principal \
                 logarithm"
            )));
        }
    }
    let id = Mat::<f64>::identity(n, n);
    let mut x = a.to_owned();
    let mut k = 0u32;
    while norm1((&x - &id).as_ref()) > 0.25 {
        if k >= 64 {
            return Err(Error::Numerical(
                "logm: too many square roots needed".into(),
            ));
        }
        x = sqrtm_db(&x)?;
        k += 1;
    }
    let y = &x - &id;
    let (nodes, weights) = gauss_legendre_01(10);
    let mut l = Mat::<f64>::zeros(n, n);
    for (&t, &w) in nodes.iter().zip(&weights) {
        let lhs = &id + &y * faer::Scale(t);
        let z = solve_square(lhs.as_ref(), y.as_ref(), "logm quadrature")?;
        l += &z * faer::Scale(w);
    }
    let l = l * faer::Scale(2f64.powi(k as i32));
    check_finite("logm result", l.as_ref())
        .map_err(|_| Error::Numerical("logm: result not finite".into()))?;
    Ok(l)
}
