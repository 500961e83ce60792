//! Frequency evaluation of a state-space model: the once-reduced Hessenberg form
//! ([`FreqEvaluator`]) and the [`StateSpace`] methods built on it.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use super::state_space::StateSpace;
use crate::error::{Error, Result};
use faer::{Mat, MatRef};
use num_complex::Complex64;

impl StateSpace {
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
