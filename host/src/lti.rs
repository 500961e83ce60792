//! Linear time-invariant models: state space and transfer functions, their frequency
//! responses, simulation, discretisation (ZOH) and its inverse, and the interconnections
//! (series, parallel, negative feedback) that loop-shaping code builds on.
//!
//! Conventions: `ts == 0.0` means continuous time (x' = Ax + Bu), `ts > 0` discrete time with
//! sample time `ts` seconds (x[k+1] = Ax[k] + Bu[k]). Shapes: A n×n, B n×m, C p×n, D p×m, with
//! n >= 0 states, m >= 1 inputs and p >= 1 outputs. Angular frequencies are in rad/s
//! (`w_rad_s`), ordinary frequencies in Hz (`f_hz`). A discrete model is evaluated on the unit
//! circle, z = exp(j·ω·ts).
//!
//! Numerical contracts:
//! - Frequency responses solve (sI − A)X = B after an orthogonal Hessenberg reduction of A
//!   (done once per evaluator), with a pivoted O(n²) elimination per frequency; never an
//!   explicit inverse. Evaluating at a pole is an [`Error::Numerical`].
//! - [`expm`] is scaling and squaring with Padé approximants of degree 3..13 (Higham 2005,
//!   "The scaling and squaring method for the matrix exponential revisited").
//! - [`logm`] is inverse scaling and squaring: product-form Denman–Beavers square roots with
//!   determinant scaling until ‖X − I‖₁ ≤ 1/4, then a 10-point Gauss–Legendre quadrature of
//!   log(I+Y) = ∫₀¹ Y(I+tY)⁻¹dt (the [10/10] Padé approximant; Higham, "Functions of Matrices",
//!   ch. 11).
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use crate::error::{Error, Result};
use faer::linalg::solvers::{DenseSolveCore, Solve};
use faer::{Mat, MatRef};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// A state-space model (A, B, C, D) with its sample time.
#[derive(Debug, Clone)]
pub struct StateSpace {
    /// State matrix, n×n.
    pub a: Mat<f64>,
    /// Input matrix, n×m.
    pub b: Mat<f64>,
    /// Output matrix, p×n.
    pub c: Mat<f64>,
    /// Feedthrough matrix, p×m.
    pub d: Mat<f64>,
    /// Sample time in seconds; 0 for continuous time.
    pub ts: f64,
}

fn check_finite(name: &str, m: MatRef<'_, f64>) -> Result<()> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            let v = m[(i, j)];
            if !v.is_finite() {
                return Err(Error::InvalidArgument(format!(
                    "{name}[{i},{j}] = {v} is not finite"
                )));
            }
        }
    }
    Ok(())
}

fn check_ts(ts: f64) -> Result<()> {
    if !ts.is_finite() || ts < 0.0 {
        return Err(Error::InvalidArgument(format!(
            "sample time ts = {ts} s must be finite and >= 0 (0 = continuous time)"
        )));
    }
    Ok(())
}

fn same_ts(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

/// Induced 1-norm (largest column sum of absolute values).
pub(crate) fn norm1(m: MatRef<'_, f64>) -> f64 {
    let mut best = 0.0f64;
    for j in 0..m.ncols() {
        let s: f64 = (0..m.nrows()).map(|i| m[(i, j)].abs()).sum();
        best = best.max(s);
    }
    best
}

fn block2x2(
    a11: MatRef<'_, f64>,
    a12: MatRef<'_, f64>,
    a21: MatRef<'_, f64>,
    a22: MatRef<'_, f64>,
) -> Mat<f64> {
    let (r1, c1) = (a11.nrows(), a11.ncols());
    let (r2, c2) = (a22.nrows(), a22.ncols());
    Mat::from_fn(r1 + r2, c1 + c2, |i, j| match (i < r1, j < c1) {
        (true, true) => a11[(i, j)],
        (true, false) => a12[(i, j - c1)],
        (false, true) => a21[(i - r1, j)],
        (false, false) => a22[(i - r1, j - c1)],
    })
}

fn vstack(top: MatRef<'_, f64>, bottom: MatRef<'_, f64>) -> Mat<f64> {
    let r1 = top.nrows();
    let cols = top.ncols().max(bottom.ncols());
    Mat::from_fn(r1 + bottom.nrows(), cols, |i, j| {
        if i < r1 {
            top[(i, j)]
        } else {
            bottom[(i - r1, j)]
        }
    })
}

fn hstack(left: MatRef<'_, f64>, right: MatRef<'_, f64>) -> Mat<f64> {
    let c1 = left.ncols();
    let rows = left.nrows().max(right.nrows());
    Mat::from_fn(rows, c1 + right.ncols(), |i, j| {
        if j < c1 {
            left[(i, j)]
        } else {
            right[(i, j - c1)]
        }
    })
}

/// Solves `a · x = rhs` for square `a` by LU with partial pivoting, refusing singular or
/// non-finite results.
pub(crate) fn solve_square(
    a: MatRef<'_, f64>,
    rhs: MatRef<'_, f64>,
    what: &str,
) -> Result<Mat<f64>> {
    let n = a.nrows();
    if n == 0 {
        return Ok(Mat::zeros(0, rhs.ncols()));
    }
    let lu = a.partial_piv_lu();
    let u = lu.U();
    let scale = norm1(a).max(f64::MIN_POSITIVE);
    let min_piv = (0..n)
        .map(|i| u[(i, i)].abs())
        .fold(f64::INFINITY, f64::min);
    if !(min_piv > (n as f64) * f64::EPSILON * scale) {
        return Err(Error::Numerical(format!(
            "{what}: matrix is singular to working precision (smallest LU pivot {min_piv:.3e}, \
             norm {scale:.3e})"
        )));
    }
    let x = lu.solve(rhs);
    check_finite(what, x.as_ref()).map_err(|_| {
        Error::Numerical(format!(
            "{what}: solution is not finite (matrix nearly singular)"
        ))
    })?;
    Ok(x)
}

impl StateSpace {
    /// Builds a model after checking shapes (A n×n, B n×m, C p×n, D p×m, m, p >= 1), that every
    /// entry is finite and that `ts` is finite and >= 0 (seconds; 0 = continuous time).
    pub fn new(a: Mat<f64>, b: Mat<f64>, c: Mat<f64>, d: Mat<f64>, ts: f64) -> Result<Self> {
        let n = a.nrows();
        if a.ncols() != n {
            return Err(Error::InvalidArgument(format!(
                "A must be square, got {}x{}",
                a.nrows(),
                a.ncols()
            )));
        }
        if b.nrows() != n {
            return Err(Error::InvalidArgument(format!(
                "B must have n = {n} rows (one per state), got {}x{}",
                b.nrows(),
                b.ncols()
            )));
        }
        if c.ncols() != n {
            return Err(Error::InvalidArgument(format!(
                "C must have n = {n} columns (one per state), got {}x{}",
                c.nrows(),
                c.ncols()
            )));
        }
        let (m, p) = (d.ncols(), d.nrows());
        if m == 0 || p == 0 {
            return Err(Error::InvalidArgument(format!(
                "D must be p×m with at least one input and one output, got {p}x{m}"
            )));
        }
        if b.ncols() != m {
            return Err(Error::InvalidArgument(format!(
                "B has {} columns but D has {m} (inputs must agree)",
                b.ncols()
            )));
        }
        if c.nrows() != p {
            return Err(Error::InvalidArgument(format!(
                "C has {} rows but D has {p} (outputs must agree)",
                c.nrows()
            )));
        }
        check_finite("A", a.as_ref())?;
        check_finite("B", b.as_ref())?;
        check_finite("C", c.as_ref())?;
        check_finite("D", d.as_ref())?;
        check_ts(ts)?;
        Ok(Self { a, b, c, d, ts })
    }

    /// A static gain y = D·u (no states), p×m.
    pub fn gain(d: Mat<f64>, ts: f64) -> Result<Self> {
        let (p, m) = (d.nrows(), d.ncols());
        Self::new(Mat::zeros(0, 0), Mat::zeros(0, m), Mat::zeros(p, 0), d, ts)
    }

    /// The p×p identity as a static model (handy for S = (I + L)⁻¹ via [`Self::feedback`]).
    pub fn identity(p: usize, ts: f64) -> Result<Self> {
        Self::gain(Mat::identity(p, p), ts)
    }

    /// Checks the invariants of [`Self::new`] on a value built through the public fields.
    pub fn validate(&self) -> Result<()> {
        Self::new(
            self.a.clone(),
            self.b.clone(),
            self.c.clone(),
            self.d.clone(),
            self.ts,
        )
        .map(|_| ())
    }

    /// Number of states n.
    pub fn n_states(&self) -> usize {
        self.a.nrows()
    }
    /// Number of inputs m.
    pub fn n_inputs(&self) -> usize {
        self.d.ncols()
    }
    /// Number of outputs p.
    pub fn n_outputs(&self) -> usize {
        self.d.nrows()
    }
    /// True for a discrete-time model (`ts > 0`).
    pub fn is_discrete(&self) -> bool {
        self.ts > 0.0
    }
    /// True for a single-input single-output model.
    pub fn is_siso(&self) -> bool {
        self.n_inputs() == 1 && self.n_outputs() == 1
    }

    /// A reusable evaluator of the frequency response (Hessenberg reduction done once).
    pub fn freq_evaluator(&self) -> FreqEvaluator {
        FreqEvaluator::new(self)
    }

    /// G evaluated at an arbitrary complex point (s for continuous, z for discrete models):
    /// C(point·I − A)⁻¹B + D, p×m. Errors when `point` is (numerically) a pole.
    pub fn evaluate(&self, point: Complex64) -> Result<Mat<Complex64>> {
        self.freq_evaluator().at_point(point)
    }

    /// Frequency response at angular frequency `w_rad_s` (rad/s), p×m complex: s = jω for
    /// continuous models, z = exp(jω·ts) for discrete ones.
    pub fn freq_response(&self, w_rad_s: f64) -> Result<Mat<Complex64>> {
        self.freq_evaluator().at_rad_s(w_rad_s)
    }

    /// Frequency responses at the frequencies `f_hz` (Hz), one p×m matrix each.
    pub fn freq_responses_hz(&self, f_hz: &[f64]) -> Result<Vec<Mat<Complex64>>> {
        let ev = self.freq_evaluator();
        f_hz.iter()
            .map(|&f| ev.at_rad_s(2.0 * std::f64::consts::PI * f))
            .collect()
    }

    /// SISO frequency response at `f_hz` (Hz). Errors for a MIMO model.
    pub fn freq_response_siso(&self, f_hz: f64) -> Result<Complex64> {
        Ok(self.freq_responses_siso_hz(&[f_hz])?[0])
    }

    /// SISO frequency responses at the frequencies `f_hz` (Hz). Errors for a MIMO model.
    pub fn freq_responses_siso_hz(&self, f_hz: &[f64]) -> Result<Vec<Complex64>> {
        if !self.is_siso() {
            return Err(Error::InvalidArgument(format!(
                "SISO frequency response requested from a {}x{} model",
                self.n_outputs(),
                self.n_inputs()
            )));
        }
        let ev = self.freq_evaluator();
        f_hz.iter()
            .map(|&f| Ok(ev.at_rad_s(2.0 * std::f64::consts::PI * f)?[(0, 0)]))
            .collect()
    }

    /// Eigenvalues of A (poles; s-plane for continuous, z-plane for discrete models), least
    /// stable first: sorted by decreasing real part (continuous) or modulus (discrete), then by
    /// decreasing imaginary part.
    pub fn poles(&self) -> Result<Vec<Complex64>> {
        let mut p = eigenvalues(self.a.as_ref())?;
        let discrete = self.is_discrete();
        let key = |z: &Complex64| if discrete { z.norm() } else { z.re };
        p.sort_by(|x, y| key(y).total_cmp(&key(x)).then(y.im.total_cmp(&x.im)));
        Ok(p)
    }

    /// True when every pole lies inside the stability region shrunk by `margin`:
    /// Re(p) < −margin (rad/s) for continuous models, |p| < 1 − margin for discrete ones.
    /// A model without states is stable.
    pub fn is_stable(&self, margin: f64) -> Result<bool> {
        let p = self.poles()?;
        Ok(if self.is_discrete() {
            p.iter().all(|z| z.norm() < 1.0 - margin)
        } else {
            p.iter().all(|s| s.re < -margin)
        })
    }

    /// Steady-state gain G(0) (continuous) or G(1) (discrete), p×m. Errors when the model has
    /// a pole at s = 0 / z = 1 (integrator: infinite DC gain).
    pub fn dc_gain(&self) -> Result<Mat<f64>> {
        let point = if self.is_discrete() {
            Complex64::new(1.0, 0.0)
        } else {
            Complex64::new(0.0, 0.0)
        };
        let g = self.evaluate(point).map_err(|_| {
            Error::Numerical(
                "infinite DC gain: the model has a pole at s = 0 (z = 1), an integrator".into(),
            )
        })?;
        Ok(Mat::from_fn(g.nrows(), g.ncols(), |i, j| g[(i, j)].re))
    }

    /// Simulates a discrete model: `u[j]` is input channel j (m channels of equal length N),
    /// `x0` the initial state (zeros when `None`). Returns the p output channels, each of length
    /// N. Continuous models are refused: discretise with [`Self::c2d_zoh`] first.
    pub fn simulate<U: AsRef<[f64]>>(&self, u: &[U], x0: Option<&[f64]>) -> Result<Vec<Vec<f64>>> {
        if !self.is_discrete() {
            return Err(Error::InvalidArgument(
                "simulate needs a discrete-time model; discretise with c2d_zoh(ts) first".into(),
            ));
        }
        let (n, m, p) = (self.n_states(), self.n_inputs(), self.n_outputs());
        if u.len() != m {
            return Err(Error::InvalidArgument(format!(
                "simulate: model has {m} inputs but {} input channels were given",
                u.len()
            )));
        }
        let len = u[0].as_ref().len();
        for (j, ch) in u.iter().enumerate() {
            let ch = ch.as_ref();
            if ch.len() != len {
                return Err(Error::InvalidArgument(format!(
                    "simulate: input channel {j} has {} samples, channel 0 has {len}",
                    ch.len()
                )));
            }
            if let Some(k) = ch.iter().position(|v| !v.is_finite()) {
                return Err(Error::InvalidArgument(format!(
                    "simulate: input channel {j} sample {k} is not finite"
                )));
            }
        }
        let mut x = vec![0.0; n];
        if let Some(x0) = x0 {
            if x0.len() != n {
                return Err(Error::InvalidArgument(format!(
                    "simulate: x0 has {} entries, the model has {n} states",
                    x0.len()
                )));
            }
            x.copy_from_slice(x0);
        }
        let rm = |m: &Mat<f64>| -> Vec<f64> {
            let mut v = Vec::with_capacity(m.nrows() * m.ncols());
            for i in 0..m.nrows() {
                for j in 0..m.ncols() {
                    v.push(m[(i, j)]);
                }
            }
            v
        };
        let (a, b, c, d) = (rm(&self.a), rm(&self.b), rm(&self.c), rm(&self.d));
        let mut y = vec![vec![0.0; len]; p];
        let mut xn = vec![0.0; n];
        let mut uk = vec![0.0; m];
        for k in 0..len {
            for (j, ch) in u.iter().enumerate() {
                uk[j] = ch.as_ref()[k];
            }
            for (i, yi) in y.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (cij, xj) in c[i * n..(i + 1) * n].iter().zip(&x) {
                    acc += cij * xj;
                }
                for (dij, uj) in d[i * m..(i + 1) * m].iter().zip(&uk) {
                    acc += dij * uj;
                }
                yi[k] = acc;
            }
            for (i, xni) in xn.iter_mut().enumerate() {
                let mut acc = 0.0;
                for (aij, xj) in a[i * n..(i + 1) * n].iter().zip(&x) {
                    acc += aij * xj;
                }
                for (bij, uj) in b[i * m..(i + 1) * m].iter().zip(&uk) {
                    acc += bij * uj;
                }
                *xni = acc;
            }
            std::mem::swap(&mut x, &mut xn);
        }
        Ok(y)
    }

    /// SISO convenience for [`Self::simulate`].
    pub fn simulate_siso(&self, u: &[f64], x0: Option<&[f64]>) -> Result<Vec<f64>> {
        if !self.is_siso() {
            return Err(Error::InvalidArgument(format!(
                "simulate_siso on a {}x{} model",
                self.n_outputs(),
                self.n_inputs()
            )));
        }
        Ok(self.simulate(&[u], x0)?.remove(0))
    }

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

    /// Transfer function of a SISO model, from det(sI − A + BC) = det(sI − A)(1 + C(sI − A)⁻¹B):
    /// num = D·χ_A + χ_{A−BC} − χ_A, den = χ_A (monic). Polynomial coefficients lose accuracy for
    /// high orders; prefer the state space for computation.
    pub fn to_transfer_function(&self) -> Result<TransferFunction> {
        if !self.is_siso() {
            return Err(Error::InvalidArgument(format!(
                "to_transfer_function needs a SISO model, got {}x{}",
                self.n_outputs(),
                self.n_inputs()
            )));
        }
        let den = poly_from_roots(&eigenvalues(self.a.as_ref())?)?;
        let abc = &self.a - &(&self.b * &self.c);
        let chi_abc = poly_from_roots(&eigenvalues(abc.as_ref())?)?;
        let dd = self.d[(0, 0)];
        let num: Vec<f64> = den
            .iter()
            .zip(&chi_abc)
            .map(|(&a, &b)| dd * a + b - a)
            .collect();
        TransferFunction::new(num, den, self.ts)
    }
}

/// Serde-friendly row-major form of a [`StateSpace`] (for JSON model files and reports).
/// `a[i]` is row i of A, and so on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateSpaceData {
    /// A, n rows of n.
    pub a: Vec<Vec<f64>>,
    /// B, n rows of m.
    pub b: Vec<Vec<f64>>,
    /// C, p rows of n.
    pub c: Vec<Vec<f64>>,
    /// D, p rows of m.
    pub d: Vec<Vec<f64>>,
    /// Sample time in seconds; 0 for continuous time.
    pub ts: f64,
    /// The operating point and preprocessing the model was identified with (absent in files
    /// written before it existed, and for models not identified from logs). Apply it with
    /// [`crate::operating_point::simulate_raw`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operating_point: Option<crate::data::OperatingPoint>,
}

fn to_rows(m: &Mat<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

fn from_rows(name: &str, rows: &[Vec<f64>], ncols_if_empty: usize) -> Result<Mat<f64>> {
    let nc = rows.first().map_or(ncols_if_empty, |r| r.len());
    if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != nc) {
        return Err(Error::InvalidArgument(format!(
            "{name}: row {i} has {} entries, row 0 has {nc}",
            r.len()
        )));
    }
    Ok(Mat::from_fn(rows.len(), nc, |i, j| rows[i][j]))
}

impl From<&StateSpace> for StateSpaceData {
    fn from(s: &StateSpace) -> Self {
        Self {
            a: to_rows(&s.a),
            b: to_rows(&s.b),
            c: to_rows(&s.c),
            d: to_rows(&s.d),
            ts: s.ts,
            operating_point: None,
        }
    }
}

impl TryFrom<&StateSpaceData> for StateSpace {
    type Error = Error;
    fn try_from(s: &StateSpaceData) -> Result<Self> {
        let m = s.d.first().map_or(0, |r| r.len());
        let n = s.a.len();
        StateSpace::new(
            from_rows("A", &s.a, 0)?,
            from_rows("B", &s.b, m)?,
            from_rows("C", &s.c, n)?,
            from_rows("D", &s.d, 0)?,
            s.ts,
        )
    }
}

/// Frequency-response evaluator of a state-space model: A is reduced once to upper Hessenberg
/// form H = QᵀAQ (Householder), B̃ = QᵀB, C̃ = CQ; each evaluation then solves the Hessenberg
/// system (point·I − H)X = B̃ by Gaussian elimination with adjacent-row pivoting, O(n²m).
#[derive(Debug, Clone)]
pub struct FreqEvaluator {
    n: usize,
    m: usize,
    p: usize,
    ts: f64,
    /// H row-major n×n.
    h: Vec<f64>,
    /// B̃ row-major n×m.
    bt: Vec<f64>,
    /// C̃ row-major p×n.
    ct: Vec<f64>,
    /// D row-major p×m.
    d: Vec<f64>,
    scale: f64,
}

/// Householder reduction to upper Hessenberg form: returns (H row-major, Q row-major) with
/// A = Q·H·Qᵀ.
fn hessenberg(a: MatRef<'_, f64>) -> (Vec<f64>, Vec<f64>) {
    let n = a.nrows();
    let mut h: Vec<f64> = (0..n * n).map(|k| a[(k / n, k % n)]).collect();
    let mut q: Vec<f64> = (0..n * n)
        .map(|k| if k / n == k % n { 1.0 } else { 0.0 })
        .collect();
    let mut v = vec![0.0; n];
    for k in 0..n.saturating_sub(2) {
        let norm: f64 = ((k + 1)..n)
            .map(|i| h[i * n + k].powi(2))
            .sum::<f64>()
            .sqrt();
        if norm == 0.0 {
            continue;
        }
        let x0 = h[(k + 1) * n + k];
        let alpha = if x0 >= 0.0 { -norm } else { norm };
        for i in 0..n {
            v[i] = if i > k { h[i * n + k] } else { 0.0 };
        }
        v[k + 1] -= alpha;
        let vv: f64 = v[k + 1..].iter().map(|x| x * x).sum();
        if vv == 0.0 {
            continue;
        }
        let beta = 2.0 / vv;
        // H <- P H (rows k+1..n)
        for j in 0..n {
            let s: f64 = ((k + 1)..n).map(|i| v[i] * h[i * n + j]).sum::<f64>() * beta;
            for i in (k + 1)..n {
                h[i * n + j] -= s * v[i];
            }
        }
        // H <- H P, Q <- Q P (columns k+1..n)
        for row in [&mut h, &mut q] {
            for i in 0..n {
                let s: f64 = ((k + 1)..n).map(|j| row[i * n + j] * v[j]).sum::<f64>() * beta;
                for j in (k + 1)..n {
                    row[i * n + j] -= s * v[j];
                }
            }
        }
        for i in (k + 2)..n {
            h[i * n + k] = 0.0;
        }
    }
    (h, q)
}

impl FreqEvaluator {
    /// Prepares the evaluator (Hessenberg reduction of A).
    pub fn new(sys: &StateSpace) -> Self {
        let (n, m, p) = (sys.n_states(), sys.n_inputs(), sys.n_outputs());
        let (h, q) = hessenberg(sys.a.as_ref());
        let mut bt = vec![0.0; n * m];
        for i in 0..n {
            for j in 0..m {
                bt[i * m + j] = (0..n).map(|k| q[k * n + i] * sys.b[(k, j)]).sum();
            }
        }
        let mut ct = vec![0.0; p * n];
        for i in 0..p {
            for j in 0..n {
                ct[i * n + j] = (0..n).map(|k| sys.c[(i, k)] * q[k * n + j]).sum();
            }
        }
        let d = (0..p * m).map(|k| sys.d[(k / m, k % m)]).collect();
        let scale = h.iter().map(|x| x * x).sum::<f64>().sqrt();
        Self {
            n,
            m,
            p,
            ts: sys.ts,
            h,
            bt,
            ct,
            d,
            scale,
        }
    }

    /// Response at angular frequency `w_rad_s` (rad/s): s = jω, or z = exp(jω·ts) if discrete.
    pub fn at_rad_s(&self, w_rad_s: f64) -> Result<Mat<Complex64>> {
        if !w_rad_s.is_finite() {
            return Err(Error::InvalidArgument(format!(
                "frequency {w_rad_s} rad/s is not finite"
            )));
        }
        let point = if self.ts > 0.0 {
            Complex64::from_polar(1.0, w_rad_s * self.ts)
        } else {
            Complex64::new(0.0, w_rad_s)
        };
        self.at_point(point)
    }

    /// C(point·I − A)⁻¹B + D at a complex point (s or z), p×m.
    pub fn at_point(&self, point: Complex64) -> Result<Mat<Complex64>> {
        let (n, m, p) = (self.n, self.m, self.p);
        let mut t: Vec<Complex64> = self.h.iter().map(|&x| Complex64::new(-x, 0.0)).collect();
        for i in 0..n {
            t[i * n + i] += point;
        }
        let mut x: Vec<Complex64> = self.bt.iter().map(|&x| Complex64::new(x, 0.0)).collect();
        let tol = (n.max(1) as f64) * f64::EPSILON * (self.scale + point.norm());
        for k in 0..n {
            if k + 1 < n && t[(k + 1) * n + k].norm() > t[k * n + k].norm() {
                for j in k..n {
                    t.swap(k * n + j, (k + 1) * n + j);
                }
                for j in 0..m {
                    x.swap(k * m + j, (k + 1) * m + j);
                }
            }
            let piv = t[k * n + k];
            if !(piv.norm() > tol) {
                return Err(Error::Numerical(format!(
                    "frequency response evaluated at a pole (point {point:.6e})"
                )));
            }
            if k + 1 < n {
                let f = t[(k + 1) * n + k] / piv;
                if f != Complex64::new(0.0, 0.0) {
                    for j in k..n {
                        let tk = t[k * n + j];
                        t[(k + 1) * n + j] -= f * tk;
                    }
                    for j in 0..m {
                        let xk = x[k * m + j];
                        x[(k + 1) * m + j] -= f * xk;
                    }
                }
            }
        }
        for k in (0..n).rev() {
            for j in 0..m {
                let mut acc = x[k * m + j];
                for l in (k + 1)..n {
                    acc -= t[k * n + l] * x[l * m + j];
                }
                x[k * m + j] = acc / t[k * n + k];
            }
        }
        let g = Mat::from_fn(p, m, |i, j| {
            let mut acc = Complex64::new(self.d[i * m + j], 0.0);
            for k in 0..n {
                acc += self.ct[i * n + k] * x[k * m + j];
            }
            acc
        });
        for j in 0..m {
            for i in 0..p {
                if !(g[(i, j)].re.is_finite() && g[(i, j)].im.is_finite()) {
                    return Err(Error::Numerical(format!(
                        "frequency response not finite at point {point:.6e} (at a pole?)"
                    )));
                }
            }
        }
        Ok(g)
    }
}

/// Eigenvalues of a real square matrix (any order; empty for 0×0).
pub fn eigenvalues(a: MatRef<'_, f64>) -> Result<Vec<Complex64>> {
    if a.nrows() != a.ncols() {
        return Err(Error::InvalidArgument(format!(
            "eigenvalues of a non-square {}x{} matrix",
            a.nrows(),
            a.ncols()
        )));
    }
    if a.nrows() == 0 {
        return Ok(Vec::new());
    }
    check_finite("matrix", a)?;
    a.eigenvalues()
        .map_err(|e| Error::Numerical(format!("eigenvalue iteration did not converge: {e:?}")))
}

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

// ---------------------------------------------------------------------------------------------
// Polynomials (descending powers) and transfer functions.

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

/// A SISO transfer function num(s)/den(s) (or of z for discrete models), coefficients in
/// descending powers; `ts` as for [`StateSpace`] (seconds, 0 = continuous).
///
/// Invariants established by [`TransferFunction::new`]: both polynomials non-empty and finite,
/// no leading zeros (a zero numerator is `[0.0]`), den not identically zero.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransferFunction {
    /// Numerator coefficients, descending powers.
    pub num: Vec<f64>,
    /// Denominator coefficients, descending powers.
    pub den: Vec<f64>,
    /// Sample time in seconds; 0 for continuous time.
    pub ts: f64,
}

fn strip_leading_zeros(p: &[f64]) -> Vec<f64> {
    let start = p.iter().position(|&c| c != 0.0).unwrap_or(p.len());
    if start == p.len() {
        vec![0.0]
    } else {
        p[start..].to_vec()
    }
}

impl TransferFunction {
    /// Builds num/den after checking finiteness, a non-zero denominator and the sample time;
    /// leading zero coefficients are removed.
    pub fn new(num: Vec<f64>, den: Vec<f64>, ts: f64) -> Result<Self> {
        if num.is_empty() || den.is_empty() {
            return Err(Error::InvalidArgument(
                "transfer function: numerator and denominator must be non-empty".into(),
            ));
        }
        if let Some(i) = num.iter().position(|c| !c.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "transfer function: numerator coefficient {i} is not finite"
            )));
        }
        if let Some(i) = den.iter().position(|c| !c.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "transfer function: denominator coefficient {i} is not finite"
            )));
        }
        check_ts(ts)?;
        let den = strip_leading_zeros(&den);
        if den == [0.0] {
            return Err(Error::InvalidArgument(
                "transfer function: denominator is identically zero".into(),
            ));
        }
        Ok(Self {
            num: strip_leading_zeros(&num),
            den,
            ts,
        })
    }

    /// Re-checks the invariants (useful after building through the public fields).
    fn normalized(&self) -> Result<Self> {
        Self::new(self.num.clone(), self.den.clone(), self.ts)
    }

    /// Degree of the denominator (number of poles).
    pub fn order(&self) -> usize {
        strip_leading_zeros(&self.den).len() - 1
    }

    /// True when deg num <= deg den.
    pub fn is_proper(&self) -> bool {
        strip_leading_zeros(&self.num).len() <= strip_leading_zeros(&self.den).len()
    }

    /// Value at a complex point (s or z). Errors at a pole.
    pub fn evaluate(&self, point: Complex64) -> Result<Complex64> {
        let d = poly_eval(&self.den, point);
        let n = poly_eval(&self.num, point);
        let scale = self
            .den
            .iter()
            .rev()
            .enumerate()
            .map(|(k, c)| c.abs() * point.norm().powi(k as i32))
            .sum::<f64>();
        if !(d.norm() > 1e3 * f64::EPSILON * scale) {
            return Err(Error::Numerical(format!(
                "transfer function evaluated at a pole (point {point:.6e})"
            )));
        }
        Ok(n / d)
    }

    /// Frequency response at `w_rad_s` (rad/s): s = jω, or z = exp(jω·ts) if discrete.
    pub fn freq_response(&self, w_rad_s: f64) -> Result<Complex64> {
        let point = if self.ts > 0.0 {
            Complex64::from_polar(1.0, w_rad_s * self.ts)
        } else {
            Complex64::new(0.0, w_rad_s)
        };
        self.evaluate(point)
    }

    /// Frequency response at `f_hz` (Hz).
    pub fn freq_response_hz(&self, f_hz: f64) -> Result<Complex64> {
        self.freq_response(2.0 * std::f64::consts::PI * f_hz)
    }

    /// Poles (roots of den).
    pub fn poles(&self) -> Result<Vec<Complex64>> {
        poly_roots(&self.den)
    }

    /// Zeros (roots of num).
    pub fn zeros(&self) -> Result<Vec<Complex64>> {
        poly_roots(&self.num)
    }

    /// Steady-state gain G(0) (continuous) or G(1) (discrete). Errors for an integrator.
    pub fn dc_gain(&self) -> Result<f64> {
        let point = if self.ts > 0.0 { 1.0 } else { 0.0 };
        Ok(self.evaluate(Complex64::new(point, 0.0))?.re)
    }

    /// Controllable canonical realisation (den made monic: s^n + a1 s^(n−1) + … + an;
    /// A = [[−a1 … −an], [I 0]], B = e1, C = residual numerator, D = direct term).
    /// Errors for an improper transfer function (deg num > deg den).
    pub fn to_state_space(&self) -> Result<StateSpace> {
        let tf = self.normalized()?;
        if !tf.is_proper() {
            return Err(Error::InvalidArgument(format!(
                "improper transfer function (numerator degree {} > denominator degree {}) has \
                 no state-space realisation",
                tf.num.len() - 1,
                tf.den.len() - 1
            )));
        }
        let n = tf.den.len() - 1;
        let lead = tf.den[0];
        let den: Vec<f64> = tf.den.iter().map(|c| c / lead).collect();
        let mut num = vec![0.0; n + 1 - tf.num.len()];
        num.extend(tf.num.iter().map(|c| c / lead));
        let d0 = num[0];
        let resid: Vec<f64> = (1..=n).map(|k| num[k] - d0 * den[k]).collect();
        let a = Mat::from_fn(n, n, |i, j| {
            if i == 0 {
                -den[j + 1]
            } else if i == j + 1 {
                1.0
            } else {
                0.0
            }
        });
        let b = Mat::from_fn(n, 1, |i, _| if i == 0 { 1.0 } else { 0.0 });
        let c = Mat::from_fn(1, n, |_, j| resid[j]);
        let d = Mat::from_fn(1, 1, |_, _| d0);
        StateSpace::new(a, b, c, d, tf.ts)
    }

    fn check_ts_with(&self, other: &TransferFunction, op: &str) -> Result<()> {
        if !same_ts(self.ts, other.ts) {
            return Err(Error::InvalidArgument(format!(
                "{op}: sample times differ ({} s vs {} s)",
                self.ts, other.ts
            )));
        }
        Ok(())
    }

    /// Series connection (product self·other). No pole-zero cancellation is attempted.
    pub fn series(&self, other: &TransferFunction) -> Result<TransferFunction> {
        self.check_ts_with(other, "series")?;
        TransferFunction::new(
            poly_mul(&self.num, &other.num),
            poly_mul(&self.den, &other.den),
            self.ts,
        )
    }

    /// Parallel connection (sum self + other).
    pub fn parallel(&self, other: &TransferFunction) -> Result<TransferFunction> {
        self.check_ts_with(other, "parallel")?;
        TransferFunction::new(
            poly_add(
                &poly_mul(&self.num, &other.den),
                &poly_mul(&other.num, &self.den),
            ),
            poly_mul(&self.den, &other.den),
            self.ts,
        )
    }

    /// Negative feedback G/(1 + G·K) with G = self in the forward path and `k` in the return
    /// path.
    pub fn feedback(&self, k: &TransferFunction) -> Result<TransferFunction> {
        self.check_ts_with(k, "feedback")?;
        let num = poly_mul(&self.num, &k.den);
        let den = poly_add(&poly_mul(&self.den, &k.den), &poly_mul(&self.num, &k.num));
        TransferFunction::new(num, den, self.ts)
    }
}
