//! Interconnections of state-space models: series, parallel and negative feedback.
use super::dense::{block2x2, hstack, same_ts, solve_square, vstack};
use super::state_space::StateSpace;
use crate::error::{Error, Result};
use faer::Mat;

impl StateSpace {
    fn check_compatible(&self, other: &StateSpace, op: &str) -> Result<()> {
        if !same_ts(self.ts, other.ts) {
            return Err(Error::InvalidArgument(format!(
                "{op}: sample times differ ({} s vs {} s)",
                self.ts, other.ts
            )));
        }
        Ok(())
    }

    /// Series connection u → self → next (the transfer matrix next·self). Requires
    /// `next.n_inputs() == self.n_outputs()` and equal sample times. States: [x_self; x_next].
    pub fn series(&self, next: &StateSpace) -> Result<StateSpace> {
        self.check_compatible(next, "series")?;
        if next.n_inputs() != self.n_outputs() {
            return Err(Error::InvalidArgument(format!(
                "series: first model has {} outputs, second has {} inputs",
                self.n_outputs(),
                next.n_inputs()
            )));
        }
        let (n1, n2) = (self.n_states(), next.n_states());
        let b2c1 = &next.b * &self.c;
        let a = block2x2(
            self.a.as_ref(),
            Mat::<f64>::zeros(n1, n2).as_ref(),
            b2c1.as_ref(),
            next.a.as_ref(),
        );
        let b = vstack(self.b.as_ref(), (&next.b * &self.d).as_ref());
        let c = hstack((&next.d * &self.c).as_ref(), next.c.as_ref());
        let d = &next.d * &self.d;
        StateSpace::new(a, b, c, d, self.ts)
    }

    /// Parallel connection: y = self(u) + other(u). Requires equal shapes and sample times.
    pub fn parallel(&self, other: &StateSpace) -> Result<StateSpace> {
        self.check_compatible(other, "parallel")?;
        if other.n_inputs() != self.n_inputs() || other.n_outputs() != self.n_outputs() {
            return Err(Error::InvalidArgument(format!(
                "parallel: shapes differ ({}x{} vs {}x{})",
                self.n_outputs(),
                self.n_inputs(),
                other.n_outputs(),
                other.n_inputs()
            )));
        }
        let (n1, n2) = (self.n_states(), other.n_states());
        let a = block2x2(
            self.a.as_ref(),
            Mat::<f64>::zeros(n1, n2).as_ref(),
            Mat::<f64>::zeros(n2, n1).as_ref(),
            other.a.as_ref(),
        );
        let b = vstack(self.b.as_ref(), other.b.as_ref());
        let c = hstack(self.c.as_ref(), other.c.as_ref());
        let d = &self.d + &other.d;
        StateSpace::new(a, b, c, d, self.ts)
    }

    /// Negative feedback: the closed loop r → y of y = self(e), e = r − k(y), i.e.
    /// (I + G·K)⁻¹·G with G = self (p×m) and K = `k` (m×p). States: [x_self; x_k].
    ///
    /// With G = L and K = I this is T = L(I+L)⁻¹; with G = I and K = L it is S = (I+L)⁻¹.
    /// Errors when I + D_G·D_K is singular (an ill-posed algebraic loop).
    pub fn feedback(&self, k: &StateSpace) -> Result<StateSpace> {
        self.check_compatible(k, "feedback")?;
        let (m, p) = (self.n_inputs(), self.n_outputs());
        if k.n_inputs() != p || k.n_outputs() != m {
            return Err(Error::InvalidArgument(format!(
                "feedback: forward model is {p}x{m}, feedback model must be {m}x{p}, got {}x{}",
                k.n_outputs(),
                k.n_inputs()
            )));
        }
        let (a1, b1, c1, d1) = (&self.a, &self.b, &self.c, &self.d);
        let (a2, b2, c2, d2) = (&k.a, &k.b, &k.c, &k.d);
        let i_p = Mat::<f64>::identity(p, p);
        let i_m = Mat::<f64>::identity(m, m);
        let loop_m = &i_p + d1 * d2;
        let f =
            solve_square(loop_m.as_ref(), i_p.as_ref(), "feedback: I + D_G·D_K").map_err(|_| {
                Error::Numerical(
                    "feedback: I + D_G·D_K is singular (algebraic loop is ill-posed)".into(),
                )
            })?;
        let fc1 = &f * c1;
        let fd1 = &f * d1;
        let fd1c2 = &fd1 * c2;
        let a11 = a1 - &(&(b1 * d2) * &fc1);
        let a12 = -(&(b1 * &(c2 - &(d2 * &fd1c2))));
        let a21 = b2 * &fc1;
        let a22 = a2 - &(b2 * &fd1c2);
        let a = block2x2(a11.as_ref(), a12.as_ref(), a21.as_ref(), a22.as_ref());
        let b = vstack((b1 * &(&i_m - &(d2 * &fd1))).as_ref(), (b2 * &fd1).as_ref());
        let c = hstack(fc1.as_ref(), (-&fd1c2).as_ref());
        StateSpace::new(a, b, c, fd1, self.ts)
    }
}
