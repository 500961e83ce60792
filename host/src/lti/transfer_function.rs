//! SISO transfer functions num/den and the conversions to and from state space.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::dense::{check_ts, eigenvalues, same_ts};
use super::polynomial::{poly_add, poly_eval, poly_from_roots, poly_mul, poly_roots};
use super::state_space::StateSpace;
use crate::error::{Error, Result};
use faer::Mat;
use num_complex::Complex64;
use serde::{Deserialize, Serialize};

impl StateSpace {
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
