//! Algebraic Riccati equations: continuous (CARE) and discrete (DARE), stabilising solutions.
//!
//! # Equations
//! - CARE: Aᵀ X + X A − X G X + Q = 0 with G = B R⁻¹ Bᵀ ([`care`]) or any symmetric G, also
//!   indefinite as in H∞ synthesis ([`care_g`]); stabilising: A − G X Hurwitz.
//! - DARE: Aᵀ X A − X − Aᵀ X B (R + Bᵀ X B)⁻¹ Bᵀ X A + Q = 0 ([`dare`]); stabilising:
//!   A − B K Schur-stable with K = (R + Bᵀ X B)⁻¹ Bᵀ X A.
//!
//! # Method
//! The stable invariant subspace [I; X] of the Hamiltonian H = [[A, −G], [−Q, −Aᵀ]] (CARE), or
//! of the Cayley transform (M + L)⁻¹(M − L) of the symplectic pencil M − zL with
//! M = [[A, 0], [−Q, I]], L = [[I, G], [0, Aᵀ]] (DARE; |z| < 1 maps to Re s < 0), is found with
//! the matrix sign function W = sign(·) by the Newton iteration with determinant scaling
//! (Roberts 1971; Byers 1987, "Solving the algebraic Riccati equation with the matrix sign
//! function"). Since (W + I)[I; X] = 0, X is the least-squares solution of
//! [W₁₂; W₂₂ + I] X = −[W₁₁ + I; W₂₁] (QR). X is symmetrised and refined by Newton steps
//! (Kleinman for the CARE, Hewer for the DARE; each a Lyapunov/Stein solve of
//! [`super::lyapunov`]) while the residual decreases.
//!
//! # Accuracy contract
//! A returned solution is symmetric and stabilising, and its relative residual
//! ‖Aᵀ X + X A − X G X + Q‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²) (CARE; the DARE analogue
//! divides by ‖Q‖_F + ‖X‖_F + ‖A‖_F²‖X‖_F + ‖AᵀXB K‖_F) is at most [`RICCATI_RESIDUAL_TOL`].
//! Every other outcome is an [`Error::Numerical`] naming the reason: Hamiltonian eigenvalues
//! on or near the imaginary axis / unit circle (no stabilising solution, or not stabilisable /
//! detectable), a stable subspace that is not a graph (ill-conditioned X), a solution that is
//! not stabilising, or a residual above the tolerance. Never a silently wrong X.
use super::lyapunov::{lyap, stein};
use super::{asymmetry, check_symmetric, fro, inverse_logdet, sym};
use crate::error::{Error, Result};
use crate::lti::{eigenvalues, solve_square};
use faer::linalg::solvers::SolveLstsq;
use faer::{Mat, MatRef};

/// Largest relative residual a returned Riccati solution may have.
pub const RICCATI_RESIDUAL_TOL: f64 = 1e-9;

/// Most Newton steps of the sign iteration.
const MAX_SIGN_STEPS: usize = 100;

/// A stabilising Riccati solution with its evidence.
#[derive(Debug, Clone)]
pub struct RiccatiSolution {
    /// The stabilising solution X (n×n, symmetric).
    pub x: Mat<f64>,
    /// Relative residual (see the module docs), after refinement.
    pub residual_rel: f64,
    /// Relative asymmetry ‖X − Xᵀ‖_F/‖X‖_F of the unsymmetrised sign-function solution.
    pub asymmetry_before_symmetrising: f64,
    /// Largest real part (CARE, rad/s) or modulus (DARE) of the closed-loop eigenvalues.
    pub closed_loop_abscissa: f64,
    /// Newton steps of the sign iteration.
    pub sign_steps: usize,
    /// Newton refinement steps accepted.
    pub refinement_steps: usize,
}

/// Matrix sign function by the scaled Newton iteration; errors when it fails (an eigenvalue
/// on or near the imaginary axis).
pub(crate) fn matrix_sign(z0: MatRef<'_, f64>, what: &str) -> Result<(Mat<f64>, usize)> {
    let n = z0.nrows();
    let mut z = z0.to_owned();
    let mut scaling = true;
    let mut prev_change = f64::INFINITY;
    for k in 0..MAX_SIGN_STEPS {
        let (inv, logdet) = inverse_logdet(z.as_ref(), what).map_err(|e| {
            Error::Numerical(format!(
                "{what}: the sign iteration met a singular matrix at step {k} (an eigenvalue \
                 on the imaginary axis: no stabilising solution): {e}"
            ))
        })?;
        let c = if scaling {
            (logdet / n as f64).exp()
        } else {
            1.0
        };
        let next = (&z * faer::Scale(1.0 / c) + &inv * faer::Scale(c)) * faer::Scale(0.5);
        let change = fro((&next - &z).as_ref()) / fro(next.as_ref()).max(f64::MIN_POSITIVE);
        z = next;
        if change < 1e-2 {
            scaling = false;
        }
        // Converged, or stagnating at rounding level in the quadratic phase.
        if change < 1e-14 * (n as f64) || (change < 1e-9 && change > 0.5 * prev_change) {
            let z2 = &z * &z - Mat::<f64>::identity(n, n);
            let dev = fro(z2.as_ref()) / (n as f64).sqrt();
            if !(dev < 1e-6) {
                return Err(Error::Numerical(format!(
                    "{what}: sign iteration ended with ‖W² − I‖ = {dev:.3e} (eigenvalues near \
                     the imaginary axis: no reliable stabilising solution)"
                )));
            }
            return Ok((z, k + 1));
        }
        prev_change = change;
    }
    Err(Error::Numerical(format!(
        "{what}: sign iteration did not converge in {MAX_SIGN_STEPS} steps (eigenvalues on or \
         near the imaginary axis: no stabilising solution)"
    )))
}

/// X from the sign W of a 2n×2n matrix whose stable invariant subspace is [I; X].
fn graph_from_sign(w: &Mat<f64>, n: usize, what: &str) -> Result<Mat<f64>> {
    let lhs = Mat::from_fn(2 * n, n, |i, j| {
        w[(i, j + n)] + if i == j + n { 1.0 } else { 0.0 }
    });
    let rhs = Mat::from_fn(2 * n, n, |i, j| {
        -(w[(i, j)] + if i == j { 1.0 } else { 0.0 })
    });
    let qr = lhs.qr();
    let r = qr.R();
    let diag: Vec<f64> = (0..n).map(|i| r[(i, i)].abs()).collect();
    let (lo, hi) = diag
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), &d| (l.min(d), h.max(d)));
    if !(lo > 1e-12 * hi) {
        return Err(Error::Numerical(format!(
            "{what}: the stable invariant subspace is not the graph of a matrix (QR diagonal \
             ratio {:.3e}): no stabilising solution, or (A, B) not stabilisable / (A, Q) with \
             an unobservable mode on the imaginary axis",
            lo / hi.max(f64::MIN_POSITIVE)
        )));
    }
    let x = qr.solve_lstsq(rhs.as_ref());
    crate::lti::dense::check_finite("Riccati solution", x.as_ref())
        .map_err(|_| Error::Numerical(format!("{what}: solution is not finite")))?;
    Ok(x)
}

/// CARE residual Aᵀ X + X A − X G X + Q.
pub fn care_residual(
    a: MatRef<'_, f64>,
    g: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
    x: MatRef<'_, f64>,
) -> Mat<f64> {
    a.transpose() * x + x * a - x * g * x + q
}

fn care_rel(a: MatRef<'_, f64>, g: MatRef<'_, f64>, q: MatRef<'_, f64>, x: MatRef<'_, f64>) -> f64 {
    let nx = fro(x);
    let scale = fro(q) + 2.0 * fro(a) * nx + fro(g) * nx * nx;
    fro(care_residual(a, g, q, x).as_ref()) / scale.max(f64::MIN_POSITIVE)
}

/// An [`Error::InvalidArgument`] "`name` must be `shape`" with the size of `x` unless
/// `shape_ok`; then `x`'s entries must be finite.
fn check_input(name: &str, x: MatRef<'_, f64>, shape_ok: bool, shape: &str) -> Result<()> {
    if !shape_ok {
        return Err(Error::InvalidArgument(format!(
            "Riccati equation: {name} must be {shape}, got {}x{}",
            x.nrows(),
            x.ncols()
        )));
    }
    crate::lti::dense::check_finite(name, x)
}

fn check_a(a: MatRef<'_, f64>) -> Result<usize> {
    let n = a.nrows();
    check_input("A", a, a.ncols() == n && n != 0, "square with n >= 1")?;
    Ok(n)
}

/// (n, G = B R⁻¹ Bᵀ) after checking A (n×n), B (n×m) and R (m×m, symmetric positive
/// definite).
fn gain_weight(
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    r: MatRef<'_, f64>,
) -> Result<(usize, Mat<f64>)> {
    let n = check_a(a)?;
    let m = b.ncols();
    check_input(
        "B",
        b,
        b.nrows() == n && m != 0,
        &format!("{n}xm with m >= 1"),
    )?;
    check_symmetric("R", r, m)?;
    let r_sym = sym(r);
    let ev = r_sym
        .as_ref()
        .self_adjoint_eigenvalues(faer::Side::Lower)
        .map_err(|e| {
            Error::Numerical(format!("R: symmetric eigenvalue iteration failed: {e:?}"))
        })?;
    let lo = ev.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = ev.iter().copied().fold(0.0f64, |h, v| h.max(v.abs()));
    if !(lo > 1e-12 * hi) {
        return Err(Error::InvalidArgument(format!(
            "R must be positive definite and well conditioned (eigenvalues {lo:.3e} .. \
             {hi:.3e})"
        )));
    }
    let rinv_bt = solve_square(r_sym.as_ref(), b.transpose(), "R")?;
    Ok((n, sym((b * &rinv_bt).as_ref())))
}

/// Stabilising solution of Aᵀ X + X A − X B R⁻¹ Bᵀ X + Q = 0 (LQR: u = −R⁻¹BᵀX x). `q`
/// symmetric n×n, `r` symmetric positive definite m×m. See the module docs.
pub fn care(
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
    r: MatRef<'_, f64>,
) -> Result<RiccatiSolution> {
    let (_, g) = gain_weight(a, b, r)?;
    care_g(a, g.as_ref(), q)
}

/// Stabilising solution of Aᵀ X + X A − X G X + Q = 0 for symmetric (possibly indefinite) G and
/// Q: A − G X is Hurwitz. See the module docs.
pub fn care_g(
    a: MatRef<'_, f64>,
    g: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
) -> Result<RiccatiSolution> {
    let n = check_a(a)?;
    check_symmetric("G", g, n)?;
    check_symmetric("Q", q, n)?;
    let (g, q) = (sym(g), sym(q));
    let h = Mat::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
        (true, true) => a[(i, j)],
        (true, false) => -g[(i, j - n)],
        (false, true) => -q[(i - n, j)],
        (false, false) => -a[(j - n, i - n)],
    });
    let (w, sign_steps) = matrix_sign(h.as_ref(), "CARE")?;
    let x0 = graph_from_sign(&w, n, "CARE")?;
    let mut asym = asymmetry(x0.as_ref());
    let mut x = sym(x0.as_ref());
    // With Q ≈ 0 and a stable A the stabilising solution is X = 0, and the sign function
    // returns rounding noise whose relative residual is O(1): snap a solution that is
    // negligible against its natural scale ‖A‖/‖G‖ to zero (its residual is then ‖Q‖).
    let x_nat = fro(a) / fro(g.as_ref()).max(f64::MIN_POSITIVE);
    if fro(x.as_ref()) <= 1e-10 * x_nat && fro(q.as_ref()) <= 1e-14 * fro(a) * x_nat {
        x = Mat::zeros(n, n);
        asym = 0.0;
    }
    let rel_at = |x: &Mat<f64>| care_rel(a, g.as_ref(), q.as_ref(), x.as_ref());
    let first = (rel_at(&x), ());
    let (x, rel, (), refinement_steps) = refine(
        x,
        first,
        |x| Some((rel_at(x), ())),
        |x, ()| {
            // Kleinman step: (A − G X)ᵀ Δ + Δ (A − G X) + res = 0.
            let ac = a - &g * x;
            let res = care_residual(a, g.as_ref(), q.as_ref(), x.as_ref());
            lyap(ac.transpose(), res.as_ref()).ok().map(|d| d.x)
        },
    );
    let ac = a - &g * &x;
    let abscissa = eigenvalues(ac.as_ref())?
        .iter()
        .map(|l| l.re)
        .fold(f64::NEG_INFINITY, f64::max);
    let hn = crate::lti::norm1(h.as_ref());
    if !(abscissa < -1e-10 * hn) {
        return Err(Error::Numerical(format!(
            "CARE: the solution is not stabilising (A − G X has an eigenvalue with real part \
             {abscissa:.3e}): no stabilising solution"
        )));
    }
    checked_solution("CARE", x, rel, asym, abscissa, sign_steps, refinement_steps)
}

/// Newton refinement of a Riccati solution `x` (Kleinman's for the CARE, Hewer's for the
/// DARE): at most four steps X ← sym(X + Δ) with Δ = `delta`(X, state), each kept only when it
/// at least halves the relative residual; stops early below 1e-15, or when Δ or the evaluation
/// fails. `first` is (relative residual, state) at `x`, `eval` the same at another X. Returns
/// (X, relative residual, state, steps kept).
fn refine<E>(
    mut x: Mat<f64>,
    first: (f64, E),
    eval: impl Fn(&Mat<f64>) -> Option<(f64, E)>,
    delta: impl Fn(&Mat<f64>, &E) -> Option<Mat<f64>>,
) -> (Mat<f64>, f64, E, usize) {
    let (mut rel, mut state) = first;
    let mut steps = 0;
    for _ in 0..4 {
        if rel < 1e-15 {
            break;
        }
        let Some(d) = delta(&x, &state) else {
            break;
        };
        let x2 = sym((&x + &d).as_ref());
        let Some((rel2, state2)) = eval(&x2) else {
            break;
        };
        if !(rel2 < 0.5 * rel) {
            break;
        }
        (x, rel, state) = (x2, rel2, state2);
        steps += 1;
    }
    (x, rel, state, steps)
}

/// The solution `x` of a `what` equation with its evidence (relative residual `rel`,
/// asymmetry `asym` before symmetrising, closed-loop abscissa or spectral radius `stability`,
/// step counts), or an [`Error::Numerical`] when the residual or the asymmetry is too large.
fn checked_solution(
    what: &str,
    x: Mat<f64>,
    rel: f64,
    asym: f64,
    stability: f64,
    sign_steps: usize,
    refinement_steps: usize,
) -> Result<RiccatiSolution> {
    if !(rel <= RICCATI_RESIDUAL_TOL) {
        return Err(Error::Numerical(format!(
            "{what}: relative residual {rel:.3e} exceeds {RICCATI_RESIDUAL_TOL:.0e} after \
             refinement (ill-conditioned: closed-loop eigenvalues near the stability boundary)"
        )));
    }
    if !(asym <= 1e-6) {
        return Err(Error::Numerical(format!(
            "{what}: the sign-function solution was far from symmetric (relative asymmetry \
             {asym:.3e}): ill-conditioned"
        )));
    }
    Ok(RiccatiSolution {
        x,
        residual_rel: rel,
        asymmetry_before_symmetrising: asym,
        closed_loop_abscissa: stability,
        sign_steps,
        refinement_steps,
    })
}

/// DARE quantities at X: (residual, K, relative residual).
fn dare_eval(
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
    r: MatRef<'_, f64>,
    x: MatRef<'_, f64>,
) -> Result<(Mat<f64>, Mat<f64>, f64)> {
    let btx = b.transpose() * x;
    let rr = r + &btx * b;
    let k = solve_square(rr.as_ref(), (&btx * a).as_ref(), "DARE: R + BᵀXB")?;
    let atxa = a.transpose() * x * a;
    let corr = a.transpose() * btx.transpose() * &k;
    let res = sym((&atxa - x - &corr + q).as_ref());
    let na = fro(a);
    let scale = fro(q) + fro(x) * (1.0 + na * na) + fro(corr.as_ref());
    let rel = fro(res.as_ref()) / scale.max(f64::MIN_POSITIVE);
    Ok((res, k, rel))
}

/// Stabilising solution of Aᵀ X A − X − Aᵀ X B (R + Bᵀ X B)⁻¹ Bᵀ X A + Q = 0 (discrete LQR:
/// u[k] = −K x[k], K = (R + BᵀXB)⁻¹BᵀXA). See the module docs.
pub fn dare(
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
    r: MatRef<'_, f64>,
) -> Result<RiccatiSolution> {
    let (n, g) = gain_weight(a, b, r)?;
    check_symmetric("Q", q, n)?;
    let q = sym(q);
    let i = Mat::<f64>::identity(n, n);
    let at = a.transpose().to_owned();
    // M ± L with M = [[A, 0], [−Q, I]], L = [[I, G], [0, Aᵀ]].
    let block = |s: f64| {
        Mat::from_fn(2 * n, 2 * n, |r_, c| match (r_ < n, c < n) {
            (true, true) => a[(r_, c)] + s * i[(r_, c)],
            (true, false) => s * g[(r_, c - n)],
            (false, true) => -q[(r_ - n, c)],
            (false, false) => i[(r_ - n, c - n)] + s * at[(r_ - n, c - n)],
        })
    };
    let (mpl_inv, _) = inverse_logdet(block(1.0).as_ref(), "DARE: M + L").map_err(|_| {
        Error::Numerical(
            "DARE: the symplectic pencil has an eigenvalue at z = −1 (M + L singular); the \
             Cayley map used here cannot treat it"
                .into(),
        )
    })?;
    let hd = &mpl_inv * block(-1.0);
    let (w, sign_steps) = matrix_sign(hd.as_ref(), "DARE")?;
    let x0 = graph_from_sign(&w, n, "DARE")?;
    let asym = asymmetry(x0.as_ref());
    let x = sym(x0.as_ref());
    let eval = |x: &Mat<f64>| {
        dare_eval(a, b, q.as_ref(), r, x.as_ref()).map(|(res, k, rel)| (rel, (res, k)))
    };
    let first = eval(&x)?;
    let (x, rel, (_, k), refinement_steps) = refine(
        x,
        first,
        |x| eval(x).ok(),
        |_, (res, k)| {
            // Hewer step: (A − BK)ᵀ Δ (A − BK) − Δ + res = 0.
            let ac = a - b * k;
            stein(ac.transpose(), res.as_ref()).ok().map(|d| d.x)
        },
    );
    let ac = a - b * &k;
    let radius = eigenvalues(ac.as_ref())?
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max);
    if !(radius < 1.0 - 1e-10) {
        return Err(Error::Numerical(format!(
            "DARE: the solution is not stabilising (A − B K has spectral radius \
             {radius:.6e}): no stabilising solution"
        )));
    }
    checked_solution("DARE", x, rel, asym, radius, sign_steps, refinement_steps)
}
