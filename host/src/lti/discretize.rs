//! Zero-order-hold discretisation of a continuous model and its inverse.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::dense::block2x2;
use super::matrix_function::{expm, logm};
use super::state_space::StateSpace;
use crate::error::{Error, Result};
use faer::Mat;

impl StateSpace {
    /// Zero-order-hold discretisation with sample time `ts` seconds: exp([[A, B], [0, 0]]·ts)
    /// = [[Ad, Bd], [0, I]]; C and D unchanged. Refuses a discrete model.
    pub fn c2d_zoh(&self, ts: f64) -> Result<StateSpace> {
        if self.is_discrete() {
            return Err(Error::InvalidArgument(
                "c2d_zoh: model is already discrete".into(),
            ));
        }
        if !(ts.is_finite() && ts > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "c2d_zoh: sample time {ts} s must be finite and > 0"
            )));
        }
        let (n, m) = (self.n_states(), self.n_inputs());
        let mut aug = block2x2(
            self.a.as_ref(),
            self.b.as_ref(),
            Mat::<f64>::zeros(m, n).as_ref(),
            Mat::<f64>::zeros(m, m).as_ref(),
        );
        for j in 0..n + m {
            for i in 0..n + m {
                aug[(i, j)] *= ts;
            }
        }
        let e = expm(aug.as_ref())?;
        let ad = e.as_ref().submatrix(0, 0, n, n).to_owned();
        let bd = e.as_ref().submatrix(0, n, n, m).to_owned();
        StateSpace::new(ad, bd, self.c.clone(), self.d.clone(), ts)
    }

    /// Inverse of [`Self::c2d_zoh`]: the continuous model whose ZOH discretisation at this
    /// model's `ts` is this model, from the principal logarithm of [[A, B], [0, I]].
    ///
    /// Errors (no real continuous equivalent exists) when a discrete pole lies at z ≈ 0 or on
    /// the negative real axis; the message names the pole.
    pub fn d2c_zoh(&self) -> Result<StateSpace> {
        if !self.is_discrete() {
            return Err(Error::InvalidArgument(
                "d2c_zoh: model is already continuous".into(),
            ));
        }
        let (n, m) = (self.n_states(), self.n_inputs());
        for z in self.poles()? {
            let r = z.norm();
            if r <= 1e-10 {
                return Err(Error::Numerical(format!(
                    "no continuous-time ZOH equivalent: discrete pole at z = {z:.3e} (≈ 0) would \
                     need a continuous pole at s = −∞"
                )));
            }
            if z.re < 0.0 && z.im.abs() <= 1e-9 * r {
                return Err(Error::Numerical(format!(
                    "no real continuous-time ZOH equivalent: discrete pole at z = {:.6} on the \
                     negative real axis (it would need s = {:.6e} ± jπ/ts, a complex pole \
                     without its conjugate)",
                    z.re,
                    r.ln() / self.ts
                )));
            }
        }
        let aug = block2x2(
            self.a.as_ref(),
            self.b.as_ref(),
            Mat::<f64>::zeros(m, n).as_ref(),
            Mat::<f64>::identity(m, m).as_ref(),
        );
        let l = logm(aug.as_ref())?;
        let ac = Mat::from_fn(n, n, |i, j| l[(i, j)] / self.ts);
        let bc = Mat::from_fn(n, m, |i, j| l[(i, n + j)] / self.ts);
        StateSpace::new(ac, bc, self.c.clone(), self.d.clone(), 0.0)
    }
}
