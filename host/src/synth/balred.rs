//! Balanced truncation of a stable LTI model (Moore 1981; square-root method of Tombs &
//! Postlethwaite 1987 / Laub et al. 1987).
//!
//! Gramians: continuous A P + P Aᵀ + B Bᵀ = 0, Aᵀ Q + Q A + Cᵀ C = 0 ([`super::lyapunov::lyap`]);
//! discrete A P Aᵀ − P + B Bᵀ = 0, Aᵀ Q A − Q + Cᵀ C = 0 ([`super::lyapunov::stein`]). With
//! symmetric square-root factors P = L_P L_Pᵀ, Q = L_Q L_Qᵀ (from symmetric eigen-decompositions,
//! negative rounding eigenvalues clipped to 0) and the SVD L_Qᵀ L_P = U Σ Vᵀ, the Hankel singular
//! values are diag Σ, and the order-r model is
//! A_r = W_rᵀ A T_r, B_r = W_rᵀ B, C_r = C T_r, D_r = D with T_r = L_P V_r Σ_r^{-1/2},
//! W_r = L_Q U_r Σ_r^{-1/2}.
//!
//! Error bound (Glover 1984; Al-Saggaf & Franklin 1987 for discrete time): the reduced model is
//! stable and σ_{r+1} ≤ ‖G − G_r‖∞ ≤ 2·Σ_{i>r} σ_i.
use super::lyapunov::{lyap, stein};
use super::sym;
use crate::error::{Error, Result};
use crate::lti::StateSpace;
use faer::Mat;

/// A balanced truncation with its a-priori error bound.
#[derive(Debug, Clone)]
pub struct BalancedReduction {
    /// The reduced model (same sample time as the input).
    pub reduced: StateSpace,
    /// Hankel singular values of the full model, decreasing.
    pub hankel_singular_values: Vec<f64>,
    /// 2·Σ of the discarded Hankel singular values: ‖G − G_r‖∞ ≤ this.
    pub error_bound: f64,
    /// Relative residuals of the two Gramian equations.
    pub gramian_residuals: (f64, f64),
}

fn sqrt_factor(p: &Mat<f64>) -> Result<Mat<f64>> {
    let e = sym(p.as_ref())
        .as_ref()
        .self_adjoint_eigen(faer::Side::Lower)
        .map_err(|e| Error::Numerical(format!("Gramian eigen-decomposition failed: {e:?}")))?;
    let (u, s) = (e.U(), e.S());
    let n = p.nrows();
    Ok(Mat::from_fn(n, n, |i, j| u[(i, j)] * s[j].max(0.0).sqrt()))
}

/// Hankel singular values and the balancing data of a stable model.
/// Hankel singular values, the balancing factors T = L_P V and W = L_Q U, and the Gramian
/// residuals.
type BalanceData = (Vec<f64>, Mat<f64>, Mat<f64>, (f64, f64));

fn balance_data(sys: &StateSpace) -> Result<BalanceData> {
    if !sys.is_stable(0.0)? {
        return Err(Error::InvalidArgument(
            "balanced truncation needs a stable model (separate the unstable part first)".into(),
        ));
    }
    let bb = &sys.b * sys.b.transpose();
    let cc = sys.c.transpose() * &sys.c;
    let (p, q) = if sys.is_discrete() {
        (
            stein(sys.a.as_ref(), bb.as_ref())?,
            stein(sys.a.transpose(), cc.as_ref())?,
        )
    } else {
        (
            lyap(sys.a.as_ref(), bb.as_ref())?,
            lyap(sys.a.transpose(), cc.as_ref())?,
        )
    };
    let lp = sqrt_factor(&p.x)?;
    let lq = sqrt_factor(&q.x)?;
    let m = lq.transpose() * &lp;
    let svd = m
        .svd()
        .map_err(|e| Error::Numerical(format!("SVD of L_Qᵀ L_P did not converge: {e:?}")))?;
    let n = sys.n_states();
    let hsv: Vec<f64> = (0..n).map(|i| svd.S()[i]).collect();
    let t = &lp * svd.V();
    let w = &lq * svd.U();
    Ok((hsv, t, w, (p.residual_rel, q.residual_rel)))
}

/// Hankel singular values of a stable model, decreasing.
pub fn hankel_singular_values(sys: &StateSpace) -> Result<Vec<f64>> {
    Ok(balance_data(sys)?.0)
}

/// Balanced truncation of a stable model to `order` states (0 < order <= n; Hankel singular
/// values at index `order − 1` must be nonzero). See the module docs.
pub fn balanced_truncation(sys: &StateSpace, order: usize) -> Result<BalancedReduction> {
    sys.validate()?;
    let n = sys.n_states();
    if order == 0 || order > n {
        return Err(Error::InvalidArgument(format!(
            "balanced truncation order {order} must lie in 1..={n}"
        )));
    }
    let (hsv, t, w, res) = balance_data(sys)?;
    let s_r = hsv[order - 1];
    if !(s_r > 1e-14 * hsv[0]) {
        return Err(Error::InvalidArgument(format!(
            "balanced truncation to order {order}: Hankel singular value σ_{order} = {s_r:.3e} \
             is negligible (≤ 1e-14·σ_1); the model has fewer than {order} controllable and \
             observable states"
        )));
    }
    let scale: Vec<f64> = hsv[..order].iter().map(|s| 1.0 / s.sqrt()).collect();
    let tr = Mat::from_fn(n, order, |i, j| t[(i, j)] * scale[j]);
    let wr = Mat::from_fn(n, order, |i, j| w[(i, j)] * scale[j]);
    let ar = wr.transpose() * &sys.a * &tr;
    let br = wr.transpose() * &sys.b;
    let cr = &sys.c * &tr;
    let reduced = StateSpace::new(ar, br, cr, sys.d.clone(), sys.ts)?;
    let error_bound = 2.0 * hsv[order..].iter().sum::<f64>();
    Ok(BalancedReduction {
        reduced,
        hankel_singular_values: hsv,
        error_bound,
        gramian_residuals: res,
    })
}

/// The smallest order whose bound 2·Σ(discarded σ) is at most `max_error` (absolute, same units
/// as G), and that truncation.
pub fn balanced_truncation_to_bound(sys: &StateSpace, max_error: f64) -> Result<BalancedReduction> {
    if !(max_error.is_finite() && max_error > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "balanced truncation error bound {max_error} must be finite and > 0"
        )));
    }
    let hsv = hankel_singular_values(sys)?;
    let n = hsv.len();
    let order = (1..=n)
        .find(|&r| 2.0 * hsv[r..].iter().sum::<f64>() <= max_error)
        .unwrap_or(n);
    balanced_truncation(sys, order.max(1))
}
