//! Polynomials with real coefficients in descending powers: products, sums, evaluation, and
//! the conversions between coefficients and roots.
use super::dense::eigenvalues;
use crate::error::{Error, Result};
use faer::Mat;
use num_complex::Complex64;

/// Product of two polynomials in descending powers.
pub fn poly_mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    let mut r = vec![0.0; a.len() + b.len() - 1];
    for (i, &x) in a.iter().enumerate() {
        for (j, &y) in b.iter().enumerate() {
            r[i + j] += x * y;
        }
    }
    r
}

/// Sum of two polynomials in descending powers (aligned at the constant term).
pub fn poly_add(a: &[f64], b: &[f64]) -> Vec<f64> {
    let n = a.len().max(b.len());
    let mut r = vec![0.0; n];
    for (i, &x) in a.iter().enumerate() {
        r[n - a.len() + i] += x;
    }
    for (i, &x) in b.iter().enumerate() {
        r[n - b.len() + i] += x;
    }
    r
}

/// Evaluates a polynomial (descending powers) at a complex point by Horner's rule.
pub fn poly_eval(p: &[f64], x: Complex64) -> Complex64 {
    p.iter()
        .fold(Complex64::new(0.0, 0.0), |acc, &c| acc * x + c)
}

/// Monic real polynomial (descending powers) with the given roots; complex roots must come in
/// conjugate pairs (checked to 1e-8 relative).
pub fn poly_from_roots(roots: &[Complex64]) -> Result<Vec<f64>> {
    let mut p = vec![Complex64::new(1.0, 0.0)];
    for &r in roots {
        let mut q = vec![Complex64::new(0.0, 0.0); p.len() + 1];
        for (i, &c) in p.iter().enumerate() {
            q[i] += c;
            q[i + 1] -= c * r;
        }
        p = q;
    }
    let scale = p.iter().map(|c| c.norm()).fold(1.0, f64::max);
    if p.iter().any(|c| c.im.abs() > 1e-8 * scale) {
        return Err(Error::InvalidArgument(
            "poly_from_roots: complex roots without their conjugates".into(),
        ));
    }
    Ok(p.iter().map(|c| c.re).collect())
}

/// Roots of a polynomial (descending powers) as eigenvalues of its companion matrix.
/// Leading zeros are ignored; a constant polynomial has no roots.
pub fn poly_roots(p: &[f64]) -> Result<Vec<Complex64>> {
    let start = p.iter().position(|&c| c != 0.0).unwrap_or(p.len());
    let p = &p[start..];
    if p.len() <= 1 {
        return Ok(Vec::new());
    }
    let n = p.len() - 1;
    let comp = Mat::from_fn(n, n, |i, j| {
        if i == 0 {
            -p[j + 1] / p[0]
        } else if i == j + 1 {
            1.0
        } else {
            0.0
        }
    });
    eigenvalues(comp.as_ref())
}
