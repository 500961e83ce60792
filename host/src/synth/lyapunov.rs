//! Lyapunov and Stein equations.
//!
//! - [`lyap`]: A X + X Aᵀ + Q = 0 for a Hurwitz A. Method: the matrix sign function of the
//!   block-triangular Z = [[A, Q], [0, −Aᵀ]], whose sign is [[−I, 2X], [0, I]] (Roberts 1971;
//!   Benner & Quintana-Ortí 1999), by the Newton iteration with determinant scaling
//!   A ← (A/c + c·A⁻¹)/2, Q ← (Q/c + c·A⁻¹·Q·A⁻ᵀ)/2, c = |det A|^{1/n}. One step of
//!   iterative refinement (solving for the residual) follows.
//! - [`stein`]: A X Aᵀ − X + Q = 0 for a Schur-stable A, by Smith's doubling
//!   X ← X + A_k X A_kᵀ, A_k ← A_k² (X = Σ_j Aʲ Q Aʲᵀ, 2ᵏ terms after k steps), then one
//!   refinement step.
//!
//! Accuracy contract: the returned solution's relative residual
//! ‖res‖_F / (2‖A‖_F‖X‖_F + ‖Q‖_F) (continuous) or ‖res‖_F / ((‖A‖_F² + 1)‖X‖_F + ‖Q‖_F)
//! (discrete) is at most [`LYAP_RESIDUAL_TOL`]; otherwise an [`Error::Numerical`] says so. A
//! non-stable A is refused up front (the solution would not be the Gramian / cost matrix).
use super::{fro, inverse_logdet};
use crate::error::{Error, Result};
use crate::lti::eigenvalues;
use faer::{Mat, MatRef};

/// Largest relative residual accepted from [`lyap`] and [`stein`].
pub const LYAP_RESIDUAL_TOL: f64 = 1e-10;

/// Most Newton sign steps / doubling steps before giving up.
const MAX_STEPS: usize = 100;

/// A solved Lyapunov/Stein equation with its accuracy evidence.
#[derive(Debug, Clone)]
pub struct LyapunovSolution {
    /// The solution X (n×n; symmetric when Q is).
    pub x: Mat<f64>,
    /// Relative residual after refinement (see the module docs).
    pub residual_rel: f64,
    /// Iterations (sign steps or doubling steps) of the main solve.
    pub iterations: usize,
}

fn check_square(name: &str, a: MatRef<'_, f64>, q: MatRef<'_, f64>) -> Result<usize> {
    let n = a.nrows();
    if a.ncols() != n || q.nrows() != n || q.ncols() != n {
        return Err(Error::InvalidArgument(format!(
            "{name}: A must be square and Q the same size, got A {}x{}, Q {}x{}",
            a.nrows(),
            a.ncols(),
            q.nrows(),
            q.ncols()
        )));
    }
    crate::lti::dense::check_finite("A", a)?;
    crate::lti::dense::check_finite("Q", q)?;
    Ok(n)
}

/// Residual A X + X Aᵀ + Q.
pub fn lyap_residual(a: MatRef<'_, f64>, x: MatRef<'_, f64>, q: MatRef<'_, f64>) -> Mat<f64> {
    a * x + x * a.transpose() + q
}

/// Residual A X Aᵀ − X + Q.
pub fn stein_residual(a: MatRef<'_, f64>, x: MatRef<'_, f64>, q: MatRef<'_, f64>) -> Mat<f64> {
    a * x * a.transpose() - x + q
}

fn lyap_rel(a: MatRef<'_, f64>, x: MatRef<'_, f64>, q: MatRef<'_, f64>) -> f64 {
    let scale = 2.0 * fro(a) * fro(x) + fro(q);
    fro(lyap_residual(a, x, q).as_ref()) / scale.max(f64::MIN_POSITIVE)
}

fn stein_rel(a: MatRef<'_, f64>, x: MatRef<'_, f64>, q: MatRef<'_, f64>) -> f64 {
    let na = fro(a);
    let scale = (na * na + 1.0) * fro(x) + fro(q);
    fro(stein_residual(a, x, q).as_ref()) / scale.max(f64::MIN_POSITIVE)
}

/// The sign-function core: X with A X + X Aᵀ + Q = 0, and the step count.
fn lyap_sign(a: MatRef<'_, f64>, q: MatRef<'_, f64>) -> Result<(Mat<f64>, usize)> {
    let n = a.nrows();
    let mut ak = a.to_owned();
    let mut qk = q.to_owned();
    let mut scaling = true;
    for k in 0..MAX_STEPS {
        let (inv, logdet) = inverse_logdet(ak.as_ref(), "Lyapunov sign iteration")?;
        let c = if scaling {
            (logdet / n as f64).exp()
        } else {
            1.0
        };
        let a_next = (&ak * faer::Scale(1.0 / c) + &inv * faer::Scale(c)) * faer::Scale(0.5);
        let q_next = (&qk * faer::Scale(1.0 / c) + &inv * &qk * inv.transpose() * faer::Scale(c))
            * faer::Scale(0.5);
        let change = fro((&a_next - &ak).as_ref()) / fro(a_next.as_ref()).max(f64::MIN_POSITIVE);
        ak = a_next;
        qk = q_next;
        if change < 1e-2 {
            scaling = false;
        }
        if change < 1e-13 * (n as f64).sqrt().max(1.0) {
            let dist = fro((&ak + Mat::<f64>::identity(n, n)).as_ref());
            if dist > 1e-6 * (n as f64).sqrt() {
                return Err(Error::Numerical(format!(
                    "Lyapunov sign iteration converged to a matrix {dist:.3e} away from −I: A \
                     is not stable"
                )));
            }
            return Ok((qk * faer::Scale(0.5), k + 1));
        }
    }
    Err(Error::Numerical(format!(
        "Lyapunov sign iteration did not converge in {MAX_STEPS} steps (eigenvalues of A on or \
         near the imaginary axis)"
    )))
}

fn require_stable(a: MatRef<'_, f64>, discrete: bool) -> Result<()> {
    for l in eigenvalues(a)? {
        let bad = if discrete {
            l.norm() >= 1.0
        } else {
            l.re >= 0.0
        };
        if bad {
            return Err(Error::Numerical(format!(
                "{} equation needs a {} A; eigenvalue {l:.6e} is not",
                if discrete { "Stein" } else { "Lyapunov" },
                if discrete {
                    "Schur-stable (|λ| < 1)"
                } else {
                    "Hurwitz (Re λ < 0)"
                }
            )));
        }
    }
    Ok(())
}

/// Solves A X + X Aᵀ + Q = 0 for a Hurwitz `a` (see the module docs for the method and the
/// accuracy contract).
pub fn lyap(a: MatRef<'_, f64>, q: MatRef<'_, f64>) -> Result<LyapunovSolution> {
    solve_refined(&LYAPUNOV, a, q)
}

/// A core solver: (A, Q) → (X, iterations).
type CoreSolver = fn(MatRef<'_, f64>, MatRef<'_, f64>) -> Result<(Mat<f64>, usize)>;

/// One of the two equations: its name, stability region, core solver and residual.
struct Equation {
    what: &'static str,
    discrete: bool,
    core: CoreSolver,
    residual: fn(MatRef<'_, f64>, MatRef<'_, f64>, MatRef<'_, f64>) -> Mat<f64>,
    rel: fn(MatRef<'_, f64>, MatRef<'_, f64>, MatRef<'_, f64>) -> f64,
}

const LYAPUNOV: Equation = Equation {
    what: "Lyapunov",
    discrete: false,
    core: lyap_sign,
    residual: lyap_residual,
    rel: lyap_rel,
};

const STEIN: Equation = Equation {
    what: "Stein",
    discrete: true,
    core: stein_doubling,
    residual: stein_residual,
    rel: stein_rel,
};

/// Checks, solves, then one refinement step (the same solver applied to the residual, kept
/// when it lowers the residual), then the accuracy contract.
fn solve_refined(
    eq: &Equation,
    a: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
) -> Result<LyapunovSolution> {
    let n = check_square(&format!("{} equation", eq.what), a, q)?;
    if n == 0 {
        return Ok(LyapunovSolution {
            x: Mat::zeros(0, 0),
            residual_rel: 0.0,
            iterations: 0,
        });
    }
    require_stable(a, eq.discrete)?;
    let (mut x, iterations) = (eq.core)(a, q)?;
    let mut rel = (eq.rel)(a, x.as_ref(), q);
    if rel > 1e-15 {
        let res = (eq.residual)(a, x.as_ref(), q);
        let (dx, _) = (eq.core)(a, res.as_ref())?;
        let x2 = &x + &dx;
        let rel2 = (eq.rel)(a, x2.as_ref(), q);
        if rel2 < rel {
            x = x2;
            rel = rel2;
        }
    }
    finish(x, rel, iterations, eq.what)
}

fn finish(x: Mat<f64>, rel: f64, iterations: usize, what: &str) -> Result<LyapunovSolution> {
    if !(rel <= LYAP_RESIDUAL_TOL) {
        return Err(Error::Numerical(format!(
            "{what} equation: relative residual {rel:.3e} exceeds {LYAP_RESIDUAL_TOL:.0e} \
             (ill-conditioned: eigenvalues of A close to the stability boundary or to each \
             other's mirror images)"
        )));
    }
    Ok(LyapunovSolution {
        x,
        residual_rel: rel,
        iterations,
    })
}

fn stein_doubling(a: MatRef<'_, f64>, q: MatRef<'_, f64>) -> Result<(Mat<f64>, usize)> {
    let mut ak = a.to_owned();
    let mut x = q.to_owned();
    for k in 0..MAX_STEPS {
        let add = &ak * &x * ak.transpose();
        x = &x + &add;
        ak = &ak * &ak;
        let nx = fro(x.as_ref()).max(f64::MIN_POSITIVE);
        if !nx.is_finite() {
            break;
        }
        if fro(add.as_ref()) <= 1e-17 * nx && fro(ak.as_ref()) < 1e-3 {
            return Ok((x, k + 1));
        }
    }
    Err(Error::Numerical(format!(
        "Stein doubling did not converge in {MAX_STEPS} steps (spectral radius of A too close \
         to 1)"
    )))
}

/// Solves A X Aᵀ − X + Q = 0 for a Schur-stable `a` (see the module docs).
pub fn stein(a: MatRef<'_, f64>, q: MatRef<'_, f64>) -> Result<LyapunovSolution> {
    solve_refined(&STEIN, a, q)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent reference: vec(X) from the Kronecker system (I⊗A + A⊗I) vec X = −vec Q
    /// (continuous) or (A⊗A − I) vec X = −vec Q (discrete).
    fn kron_solve(a: &Mat<f64>, q: &Mat<f64>, discrete: bool) -> Mat<f64> {
        let n = a.nrows();
        let big = Mat::from_fn(n * n, n * n, |r, c| {
            let (i, k) = (r % n, r / n); // row index of vec: X[i,k]
            let (j, l) = (c % n, c / n); // column index: X[j,l]
            if discrete {
                a[(i, j)] * a[(k, l)] - if r == c { 1.0 } else { 0.0 }
            } else {
                (if k == l { a[(i, j)] } else { 0.0 }) + if i == j { a[(k, l)] } else { 0.0 }
            }
        });
        let rhs = Mat::from_fn(n * n, 1, |r, _| -q[(r % n, r / n)]);
        let v = crate::lti::solve_square(big.as_ref(), rhs.as_ref(), "kron").unwrap();
        Mat::from_fn(n, n, |i, k| v[(i + k * n, 0)])
    }

    fn test_a() -> Mat<f64> {
        Mat::from_fn(4, 4, |i, j| {
            let v = [
                [-1.0, 2.0, 0.3, 0.0],
                [-3.0, -0.5, 1.0, 0.2],
                [0.0, 0.4, -2.0, 5.0],
                [0.1, 0.0, -5.0, -0.1],
            ];
            v[i][j]
        })
    }

    #[test]
    fn lyap_matches_kronecker_reference() {
        let a = test_a();
        let b = Mat::from_fn(4, 2, |i, j| {
            (i as f64 + 1.0) * if j == 0 { 1.0 } else { -0.3 }
        });
        let q = &b * b.transpose();
        let s = lyap(a.as_ref(), q.as_ref()).unwrap();
        let r = kron_solve(&a, &q, false);
        let err = fro((&s.x - &r).as_ref()) / fro(r.as_ref());
        assert!(err < 1e-11, "relative difference {err:.3e}");
        assert!(s.residual_rel < 1e-14, "{:.3e}", s.residual_rel);
    }

    #[test]
    fn stein_matches_kronecker_reference() {
        let a = test_a() * faer::Scale(0.15);
        let q = Mat::from_fn(4, 4, |i, j| if i == j { 1.0 + i as f64 } else { 0.2 });
        let s = stein(a.as_ref(), q.as_ref()).unwrap();
        let r = kron_solve(&a, &q, true);
        let err = fro((&s.x - &r).as_ref()) / fro(r.as_ref());
        assert!(err < 1e-12, "relative difference {err:.3e}");
    }

    #[test]
    fn unstable_a_is_refused() {
        let a = Mat::from_fn(2, 2, |i, j| if i == j { 0.5 } else { 1.0 });
        let q = Mat::<f64>::identity(2, 2);
        let e = lyap(a.as_ref(), q.as_ref()).unwrap_err().to_string();
        assert!(e.contains("Hurwitz"), "{e}");
        let e = stein(a.as_ref(), q.as_ref()).unwrap_err().to_string();
        assert!(e.contains("Schur-stable"), "{e}");
    }
}
