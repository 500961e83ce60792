//! Bilinear (Tustin) discretisation of continuous transfer functions, with optional frequency
//! prewarping, as used for controllers and weights that run or are evaluated in discrete time.
//!
//! s = c·(z − 1)/(z + 1) with c = 2/ts (plain Tustin) or c = ω_p / tan(ω_p·ts/2) (prewarped at
//! ω_p rad/s, 0 < ω_p < π/ts). The substitution maps the jω axis onto the unit circle with
//! ω_d = (2/ts)·atan(ω/c), so the discrete response equals the continuous one exactly at ω_p
//! (and at DC). It is a ring homomorphism: sums and products of transfer functions are
//! preserved, so a parallel-form controller discretised term by term equals the discretised
//! whole.
use crate::error::{Error, Result};
use crate::lti::{poly_add, poly_mul, solve_square, StateSpace, TransferFunction};
use faer::Mat;

/// The bilinear constant c (1/s) for sample time `ts` (s) and an optional prewarp frequency
/// `prewarp_rad_s` (rad/s, must lie in (0, π/ts)).
pub fn tustin_constant(ts: f64, prewarp_rad_s: Option<f64>) -> Result<f64> {
    if !(ts.is_finite() && ts > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "Tustin: sample time {ts} s must be finite and > 0"
        )));
    }
    match prewarp_rad_s {
        None => Ok(2.0 / ts),
        Some(w) => {
            let nyq = std::f64::consts::PI / ts;
            if !(w.is_finite() && w > 0.0 && w < nyq) {
                return Err(Error::InvalidArgument(format!(
                    "Tustin: prewarp frequency {w} rad/s must lie in (0, π/ts = {nyq} rad/s)"
                )));
            }
            Ok(w / (w * ts / 2.0).tan())
        }
    }
}

/// Tustin discretisation of a proper continuous transfer function (coefficients in descending
/// powers of s) with sample time `ts` seconds, optionally prewarped at `prewarp_rad_s`.
/// The result is in descending powers of z with the leading denominator coefficient 1, so the
/// coefficients are also those of z⁻¹ in ascending order (difference-equation form).
///
/// Errors: a discrete input, an improper transfer function, a pole at s = −c (it would map to
/// z = ∞, the leading coefficient vanishes) or an invalid `ts`/prewarp.
pub fn tustin(
    tf: &TransferFunction,
    ts: f64,
    prewarp_rad_s: Option<f64>,
) -> Result<TransferFunction> {
    if tf.ts != 0.0 {
        return Err(Error::InvalidArgument(
            "Tustin: the transfer function is already discrete".into(),
        ));
    }
    if !tf.is_proper() {
        return Err(Error::InvalidArgument(format!(
            "Tustin: improper transfer function (numerator degree {} > denominator degree {})",
            tf.num.len() - 1,
            tf.den.len() - 1
        )));
    }
    let c = tustin_constant(ts, prewarp_rad_s)?;
    let n = tf.den.len() - 1;
    let map = |p: &[f64]| -> Vec<f64> {
        // p has degree <= n; coefficient of s^i is p[len-1-i].
        let mut acc = vec![0.0; n + 1];
        for (k, &coef) in p.iter().rev().enumerate() {
            // coef · c^k (z − 1)^k (z + 1)^(n − k)
            let mut term = vec![coef * c.powi(k as i32)];
            for _ in 0..k {
                term = poly_mul(&term, &[1.0, -1.0]);
            }
            for _ in 0..(n - k) {
                term = poly_mul(&term, &[1.0, 1.0]);
            }
            acc = poly_add(&acc, &term);
        }
        acc
    };
    let num = map(&tf.num);
    let den = map(&tf.den);
    let lead = den[0];
    let scale = den.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if lead.abs().partial_cmp(&(1e-12 * scale)) != Some(std::cmp::Ordering::Greater) {
        return Err(Error::Numerical(format!(
            "Tustin: a pole at s = −{c:.6e} rad/s maps to z = ∞ (choose another ts or prewarp)"
        )));
    }
    TransferFunction::new(
        num.iter().map(|v| v / lead).collect(),
        den.iter().map(|v| v / lead).collect(),
        ts,
    )
}

/// Tustin discretisation of a continuous state-space model without forming polynomials in z:
/// with M = (cI − A)⁻¹, A_d = M(cI + A), B_d = √(2c)·M·B, C_d = √(2c)·C·M, D_d = D + C·M·B
/// (same transfer function as [`tustin`] of the model's transfer function, but the state
/// matrices stay as well conditioned as the continuous ones; polynomial coefficients of
/// fast-sampled models, with every pole clustered near z = 1, are not).
///
/// Errors: a discrete input, an eigenvalue of A at s = c (it maps to z = ∞), or invalid
/// `ts`/prewarp.
pub fn tustin_state_space(
    sys: &StateSpace,
    ts: f64,
    prewarp_rad_s: Option<f64>,
) -> Result<StateSpace> {
    if sys.is_discrete() {
        return Err(Error::InvalidArgument(
            "Tustin: the model is already discrete".into(),
        ));
    }
    let c = tustin_constant(ts, prewarp_rad_s)?;
    let n = sys.n_states();
    let ci = Mat::<f64>::identity(n, n) * faer::Scale(c);
    let m = solve_square(
        (&ci - &sys.a).as_ref(),
        Mat::<f64>::identity(n, n).as_ref(),
        "Tustin: cI − A (a pole at s = c maps to z = ∞)",
    )?;
    let k = (2.0 * c).sqrt();
    let ad = &m * (&ci + &sys.a);
    let mb = &m * &sys.b;
    let bd = &mb * faer::Scale(k);
    let cd = (&sys.c * &m) * faer::Scale(k);
    let dd = &sys.d + &sys.c * &mb;
    StateSpace::new(ad, bd, cd, dd, ts)
}
