//! Discrete-time rational fit of a measured frequency response: Sanathanan–Koerner iteration
//! of Levy's linearised least squares.
//!
//! Model (q = z⁻¹ = e^{−jωT}):
//!
//! ```text
//! Ĥ(z) = q^nk · (b0 + b1 q + … + b_nb q^nb) / (1 + a1 q + … + a_na q^na)
//! ```
//!
//! Levy (1959) makes the fit linear by minimising Σ w_k² |A(q_k) H_k − q_k^nk B(q_k)|²;
//! Sanathanan & Koerner (1963) remove the |A|² bias by dividing each term by |A_{i−1}(q_k)|
//! from the previous iterate, so at convergence the objective is the output-error
//! Σ w_k² |H_k − Ĥ(q_k)|² up to the (small) difference of the stationary points. Each
//! iteration is one real least-squares problem (real and imaginary parts stacked, columns
//! scaled to unit norm, solved by column-pivoted QR).
//!
//! Weights: `w_k = 1/|H_k|` by default (relative error: the power-up check and W_m are
//! relative), times optional user weights. Units: frequencies in Hz, `ts` in s.
//!
//! The result must be stable (every pole strictly inside the unit circle): an unstable fit of
//! a measured stable plant is a wrong model, so it is an [`Error::Numerical`], never returned.
use crate::error::{Error, Result};
use crate::lti::{poly_roots, StateSpace, TransferFunction};
use faer::linalg::solvers::SolveLstsq;
use faer::Mat;
use num_complex::Complex64;
use serde::Serialize;

/// Largest accepted denominator or numerator order (a power-up frame has at most 2049 bins;
/// polynomials of higher degree in q⁻¹ are numerically meaningless on the unit circle).
pub const MAX_ORDER: usize = 40;
/// Largest accepted input delay, samples.
pub const MAX_DELAY: usize = 512;

/// Orders and iteration limits of [`fit_discrete_rational`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RationalFitOptions {
    /// Denominator order na (1..=[`MAX_ORDER`]).
    pub na: usize,
    /// Numerator order nb (b0..b_nb: nb + 1 coefficients; 0..=[`MAX_ORDER`]).
    pub nb: usize,
    /// Input delay nk in samples (the numerator starts at q^nk; 1 for a ZOH plant;
    /// 0..=[`MAX_DELAY`]).
    pub nk: usize,
    /// Largest number of SK iterations (default 50).
    pub max_iterations: usize,
    /// Convergence: relative change of the coefficient vector below this (default 1e-10).
    pub tolerance: f64,
}

impl RationalFitOptions {
    /// Orders (na, nb, nk) with default iteration settings.
    pub fn new(na: usize, nb: usize, nk: usize) -> Self {
        Self {
            na,
            nb,
            nk,
            max_iterations: 50,
            tolerance: 1e-10,
        }
    }
}

/// A fitted discrete rational model with its fit statistics.
#[derive(Debug, Clone, Serialize)]
pub struct RationalFit {
    /// Orders used.
    pub options: RationalFitOptions,
    /// Sample time, s.
    pub ts: f64,
    /// `[1, a1, …, a_na]`.
    pub a: Vec<f64>,
    /// `[b0, …, b_nb]` (coefficients of q^nk … q^(nk+nb)).
    pub b: Vec<f64>,
    /// Poles (z-plane).
    pub poles: Vec<[f64; 2]>,
    /// RMS over the points of |Ĥ − H|/|H|.
    pub rms_rel_error: f64,
    /// Largest |Ĥ − H|/|H| over the points.
    pub max_rel_error: f64,
    /// SK iterations run.
    pub iterations: usize,
    /// Whether the coefficient change fell below the tolerance.
    pub converged: bool,
    /// Number of frequency points fitted.
    pub points: usize,
}

impl RationalFit {
    /// Ĥ at `f_hz` (Hz).
    pub fn response_hz(&self, f_hz: f64) -> Complex64 {
        let q = Complex64::from_polar(1.0, -2.0 * std::f64::consts::PI * f_hz * self.ts);
        eval(&self.a, &self.b, self.options.nk, q)
    }

    /// The fit as a discrete transfer function in z (descending powers, equal lengths).
    pub fn transfer_function(&self) -> Result<TransferFunction> {
        let (na, nb, nk) = (self.options.na, self.options.nb, self.options.nk);
        let n = na.max(nk + nb);
        let mut den = vec![0.0; n + 1];
        den[..=na].copy_from_slice(&self.a);
        let mut num = vec![0.0; n + 1];
        num[nk..=nk + nb].copy_from_slice(&self.b);
        TransferFunction::new(num, den, self.ts)
    }

    /// The fit as a discrete state-space model (sample time `ts`).
    pub fn state_space(&self) -> Result<StateSpace> {
        self.transfer_function()?.to_state_space()
    }
}

/// Ĥ(q) for coefficients a (with a0 = 1), b and delay nk.
fn eval(a: &[f64], b: &[f64], nk: usize, q: Complex64) -> Complex64 {
    poly_q(b, q) * q.powu(nk as u32) / poly_q(a, q)
}

/// Σ c_i q^i.
fn poly_q(c: &[f64], q: Complex64) -> Complex64 {
    c.iter()
        .rev()
        .fold(Complex64::new(0.0, 0.0), |acc, &v| acc * q + v)
}

fn check_inputs(
    freq_hz: &[f64],
    h: &[Complex64],
    weights: Option<&[f64]>,
    ts: f64,
    o: &RationalFitOptions,
) -> Result<()> {
    if !(ts.is_finite() && ts > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "rational fit: sample time {ts} s must be finite and > 0"
        )));
    }
    if !(1..=MAX_ORDER).contains(&o.na) {
        return Err(Error::InvalidArgument(format!(
            "rational fit: denominator order na must be in 1..={MAX_ORDER}, got {}",
            o.na
        )));
    }
    if o.nb > MAX_ORDER {
        return Err(Error::InvalidArgument(format!(
            "rational fit: numerator order nb must be in 0..={MAX_ORDER}, got {}",
            o.nb
        )));
    }
    if o.nk > MAX_DELAY {
        return Err(Error::InvalidArgument(format!(
            "rational fit: delay nk must be in 0..={MAX_DELAY} samples, got {}",
            o.nk
        )));
    }
    if freq_hz.len() != h.len() {
        return Err(Error::InvalidArgument(format!(
            "rational fit: {} frequencies but {} responses",
            freq_hz.len(),
            h.len()
        )));
    }
    if let Some(w) = weights {
        if w.len() != h.len() {
            return Err(Error::InvalidArgument(format!(
                "rational fit: {} weights for {} points",
                w.len(),
                h.len()
            )));
        }
        if let Some((i, v)) = w
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v > 0.0))
        {
            return Err(Error::InvalidArgument(format!(
                "rational fit: weight {i} = {v} must be finite and > 0"
            )));
        }
    }
    let params = o.na + o.nb + 1;
    if 2 * h.len() < params + 1 {
        return Err(Error::InvalidArgument(format!(
            "rational fit: {} points (2 real equations each) cannot determine {params} \
             coefficients with a residual; need at least {}",
            h.len(),
            params.div_ceil(2) + 1
        )));
    }
    let nyq = 0.5 / ts;
    for (i, (&f, g)) in freq_hz.iter().zip(h).enumerate() {
        if !(f.is_finite() && f > 0.0 && f < nyq) {
            return Err(Error::InvalidArgument(format!(
                "rational fit: frequency {i} = {f} Hz must lie in (0, {nyq}) Hz (Nyquist)"
            )));
        }
        if !(g.re.is_finite() && g.im.is_finite()) || g.norm() == 0.0 {
            return Err(Error::InvalidArgument(format!(
                "rational fit: response {i} at {f} Hz is {g}, must be finite and non-zero"
            )));
        }
    }
    Ok(())
}

/// Fits `Ĥ` (module docs) to the points `(freq_hz[k], h[k])` with relative weights (times
/// `weights` when given).
///
/// # Errors
/// [`Error::InvalidArgument`] for inconsistent inputs (lengths, non-finite or zero responses,
/// frequencies outside (0, Nyquist), too few points for the orders, na = 0);
/// [`Error::Numerical`] when the regression is rank deficient (e.g. orders too high for the
/// data) or the converged fit is unstable.
pub fn fit_discrete_rational(
    freq_hz: &[f64],
    h: &[Complex64],
    weights: Option<&[f64]>,
    ts: f64,
    opts: &RationalFitOptions,
) -> Result<RationalFit> {
    check_inputs(freq_hz, h, weights, ts, opts)?;
    let (na, nb, nk) = (opts.na, opts.nb, opts.nk);
    let np = na + nb + 1;
    let npts = h.len();
    let qs: Vec<Complex64> = freq_hz
        .iter()
        .map(|&f| Complex64::from_polar(1.0, -2.0 * std::f64::consts::PI * f * ts))
        .collect();
    let w: Vec<f64> = (0..npts)
        .map(|k| weights.map_or(1.0, |w| w[k]) / h[k].norm())
        .collect();
    let mut a = vec![1.0; 1];
    a.resize(na + 1, 0.0);
    let mut b = vec![0.0; nb + 1];
    let mut theta_prev: Option<Vec<f64>> = None;
    let mut iterations = 0;
    let mut converged = false;
    for it in 0..opts.max_iterations.max(1) {
        iterations = it + 1;
        let mut m = Mat::<f64>::zeros(2 * npts, np);
        let mut rhs = Mat::<f64>::zeros(2 * npts, 1);
        for k in 0..npts {
            let q = qs[k];
            let sk = w[k] / poly_q(&a, q).norm();
            let hk = h[k];
            let mut qi = q;
            for i in 0..na {
                let v = qi * hk * sk;
                m[(2 * k, i)] = v.re;
                m[(2 * k + 1, i)] = v.im;
                qi *= q;
            }
            let mut qb = q.powu(nk as u32);
            for i in 0..=nb {
                let v = -qb * sk;
                m[(2 * k, na + i)] = v.re;
                m[(2 * k + 1, na + i)] = v.im;
                qb *= q;
            }
            let r = -hk * sk;
            rhs[(2 * k, 0)] = r.re;
            rhs[(2 * k + 1, 0)] = r.im;
        }
        // Column scaling to unit norm, then column-pivoted QR least squares.
        let mut scale = vec![1.0; np];
        for (j, s) in scale.iter_mut().enumerate() {
            let nrm = (0..2 * npts)
                .map(|i| m[(i, j)] * m[(i, j)])
                .sum::<f64>()
                .sqrt();
            if !(nrm > 0.0 && nrm.is_finite()) {
                return Err(Error::Numerical(format!(
                    "rational fit: regressor column {j} is zero or not finite"
                )));
            }
            *s = nrm;
            for i in 0..2 * npts {
                m[(i, j)] /= nrm;
            }
        }
        let qr = m.col_piv_qr();
        let rr = qr.R();
        let r0 = rr[(0, 0)].abs();
        let rmin = (0..np)
            .map(|i| rr[(i, i)].abs())
            .fold(f64::INFINITY, f64::min);
        if rmin.is_nan() || rmin <= 1e-12 * r0 {
            return Err(Error::Numerical(format!(
                "rational fit: regression is rank deficient (pivot ratio {:.1e}); lower the \
                 orders (na = {na}, nb = {nb}) or add frequency points",
                rmin / r0
            )));
        }
        let x = qr.solve_lstsq(&rhs);
        let theta: Vec<f64> = (0..np).map(|j| x[(j, 0)] / scale[j]).collect();
        if theta.iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical(
                "rational fit: coefficients not finite".into(),
            ));
        }
        a[1..].copy_from_slice(&theta[..na]);
        b.copy_from_slice(&theta[na..]);
        if let Some(prev) = &theta_prev {
            let d: f64 = theta
                .iter()
                .zip(prev)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
                .sqrt();
            let n: f64 = theta.iter().map(|x| x * x).sum::<f64>().sqrt();
            if d <= opts.tolerance * n.max(1e-300) {
                converged = true;
                break;
            }
        }
        theta_prev = Some(theta);
    }
    // Stability: roots of z^na + a1 z^(na-1) + … + a_na.
    let poles = poly_roots(&a)?;
    if let Some(p) = poles.iter().find(|p| p.norm() >= 1.0) {
        return Err(Error::Numerical(format!(
            "rational fit (na = {na}, nb = {nb}, nk = {nk}): unstable fit, pole {p:.6} has \
             |z| = {:.6} >= 1; the data do not support this model structure",
            p.norm()
        )));
    }
    let rel: Vec<f64> = (0..npts)
        .map(|k| (eval(&a, &b, nk, qs[k]) - h[k]).norm() / h[k].norm())
        .collect();
    let rms = (rel.iter().map(|r| r * r).sum::<f64>() / npts as f64).sqrt();
    let max = rel.iter().copied().fold(0.0f64, f64::max);
    Ok(RationalFit {
        options: *opts,
        ts,
        a,
        b,
        poles: poles.iter().map(|p| [p.re, p.im]).collect(),
        rms_rel_error: rms,
        max_rel_error: max,
        iterations,
        converged,
        points: npts,
    })
}

/// [`fit_discrete_rational`] for every delay `nk` in `nk_range` (same na, nb), keeping the fit
/// with the smallest RMS relative error (all candidates have the same number of coefficients,
/// so the comparison is fair). Unstable or rank-deficient candidates are skipped; the error of
/// the last one is returned when none succeeds.
pub fn fit_discrete_rational_delay_search(
    freq_hz: &[f64],
    h: &[Complex64],
    weights: Option<&[f64]>,
    ts: f64,
    opts: &RationalFitOptions,
    nk_range: std::ops::RangeInclusive<usize>,
) -> Result<RationalFit> {
    if *nk_range.end() > MAX_DELAY {
        return Err(Error::InvalidArgument(format!(
            "rational fit: delays up to {} samples requested; the largest accepted is \
             {MAX_DELAY}",
            nk_range.end()
        )));
    }
    let mut best: Option<RationalFit> = None;
    let mut last_err = None;
    for nk in nk_range.clone() {
        let o = RationalFitOptions { nk, ..*opts };
        match fit_discrete_rational(freq_hz, h, weights, ts, &o) {
            Ok(f) => {
                if best
                    .as_ref()
                    .is_none_or(|b| f.rms_rel_error < b.rms_rel_error)
                {
                    best = Some(f);
                }
            }
            Err(e @ Error::InvalidArgument(_)) => return Err(e),
            Err(e) => last_err = Some(e),
        }
    }
    best.ok_or_else(|| {
        last_err.unwrap_or_else(|| {
            Error::InvalidArgument(format!("rational fit: empty delay range {nk_range:?}"))
        })
    })
}
