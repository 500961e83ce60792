//! N4SID-family subspace identification of discrete-time state-space models from
//! input/output data, with automatic order selection.
//!
//! # Algorithm (what is computed, in order)
//! 1. **Checks and scaling.** Every channel must be finite, non-constant and of equal length N.
//!    Each input and output channel is divided by its RMS value, so amplitudes of 1e3 or 1e-4
//!    and any sample time give the same conditioning; the model is scaled back at the end.
//!    Means are *not* removed: detrend in [`crate::preprocess`] first.
//! 2. **Block Hankel data and LQ factor.** With `i` block rows (default 20) and
//!    J = N − 2i + 1 columns, the data matrix is ordered [U_f; U_p; Y_p; Y_f] (future inputs,
//!    past inputs, past outputs, future outputs; W_p = [U_p; Y_p]). Its lower-triangular LQ
//!    factor L is obtained, by default, from the Cholesky factor of the correlation matrix
//!    H·Hᵀ/J, which is computed in O(N·i·(m+p)²) from lagged cross-correlations and the Hankel
//!    shift recursion (as SLICOT IB01MD's fast path does) instead of forming H. If that matrix
//!    is not numerically positive definite (e.g. noise-free data) the LQ factor is computed by a
//!    Householder QR of Hᵀ instead ([`Factorization::Qr`] forces this path).
//! 3. **Weighting and SVD.** [`Weighting::Moesp`] (default; PO-MOESP, Verhaegen 1994, SLICOT
//!    IB01AD METH='M'): SVD of L₃₂ = the part of the future outputs, orthogonal to the future
//!    inputs, explained by the past. Γ = U_n·Σ_n^½. [`Weighting::Cva`] (canonical variate
//!    analysis, Larimore): W₁ = (Y_f Π⊥_{U_f} Y_fᵀ)^(−½); Γ = W₁⁻¹·U_n·Σ_n^½.
//!    The canonical correlations (the CVA singular values, in [0, 1]) are always computed for
//!    order selection.
//! 4. **Order selection** (unless fixed), two rules combined:
//!    (a) Bauer's singular-value criterion on the canonical correlations ρ,
//!    SVC(n) = ρ²_{n+1} + d(n)·ln(J)/J with d(n) = n(2p + m) (the free parameters of an
//!    innovation-form model of order n), minimised over the allowed range → n_svc;
//!    (b) the dominant-dynamics boundary: the chosen order is the n in n_min..=n_svc with the
//!    largest gap σ_n/σ_{n+1} of the weighted singular values (SLICOT IB01AD's TOL < 0 rule,
//!    restricted to the statistically supported orders). The reason string names n_svc and
//!    the weaker, supported states left out, so the caller can fix the order to include them.
//! 5. **A, C** from the extended observability matrix Γ (i·p × n): C = Γ[0..p], A the least-
//!    squares solution of Γ_up·A = Γ_down (shift invariance).
//! 6. **Stability** (when a margin is given): poles with |z| >= 1 are reflected to 1/z̄, then
//!    any pole with |z| > 1 − margin is pulled radially to 1 − margin (its frequency is kept);
//!    every change is reported. Without a margin, an unstable A is reported as a warning.
//! 7. **B, D and x0** by linear least squares on the simulation (output) error:
//!    y(t) = C·Aᵗ·x0 + Σ C·A^(t−1−τ)·B·u(τ) + D·u(t), exact for the given (A, C) and
//!    unbiased for white output noise in open loop. D can be fixed to zero.
//! 8. **Kalman gain** (optional): states x̂(t) = Γ⁺·L₃₂·L₂₂⁻¹·w_p(t) from the oblique
//!    projection (the finite-memory Kalman-filter states of Van Overschee & De Moor); the
//!    residuals ŵ of x̂(t+1) − A x̂(t) − B u(t) and ê of y(t) − C x̂(t) − D u(t) give the
//!    noise covariances Q, S, R, and the filter Riccati equation (solved by doubling, see
//!    [`kalman_filter_gain`]) gives K and the innovation covariance, as SLICOT IB01BD does.
//!    Skipped with a warning when the past data are rank deficient (noise-free data) or no
//!    stabilising solution exists.
//!
//! All models are discrete with the data's sample time `ts` (seconds); continuous
//! equivalents come from [`StateSpace::d2c_zoh`].
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use crate::data::Log;
use crate::error::{Error, Result};
use crate::lti::{eigenvalues, StateSpace, StateSpaceData};
use faer::linalg::solvers::{Solve, SolveLstsq};
use faer::{Mat, MatRef, Side};
use num_complex::Complex64;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// How the weighted projection is formed before the SVD (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Weighting {
    /// PO-MOESP: SVD of L₃₂ (W₁ = I, W₂ = Π⊥_{U_f}). Default.
    Moesp,
    /// Canonical variate analysis: W₁ = (Y_f Π⊥_{U_f} Y_fᵀ)^(−½), W₂ = Π⊥_{U_f}.
    Cva,
}

/// How the LQ factor of the block Hankel matrix is obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Factorization {
    /// Cholesky of the correlation matrix (fast), Householder QR if that fails. Default.
    Auto,
    /// Householder QR of the J × 2i(m+p) data matrix (slower, never squares the conditioning).
    Qr,
}

/// Model order: fixed, or selected automatically within a range (rule in the module docs:
/// the largest singular-value gap among the orders supported by Bauer's SVC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum OrderSelection {
    /// Automatic over 1..=min((i−1)·p, 20).
    Auto,
    /// Automatic within `min..=max` (both >= 1, max <= (i−1)·p).
    Range {
        /// Smallest order considered.
        min: usize,
        /// Largest order considered.
        max: usize,
    },
    /// Exactly this order (1..=(i−1)·p).
    Fixed(usize),
}

/// Largest accepted number of block rows i. The data matrix has 2·i·(m+p) rows and its
/// correlation matrix (2·i·(m+p))² entries: i = 1000 with one input and one output is already a
/// 4000 × 4000 matrix (128 MB), beyond anything a plant model of order ≤ (i−1)·p needs.
pub const MAX_BLOCK_ROWS: usize = 1000;

/// Options of [`n4sid`]. `Default` gives i = 20, automatic order, MOESP weighting, D and x0
/// estimated, no stability enforcement, Kalman gain estimated.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct N4sidOptions {
    /// Number of block rows i (past and future horizon), in 2..=[`MAX_BLOCK_ROWS`].
    pub block_rows: usize,
    /// Order choice.
    pub order: OrderSelection,
    /// Weighting of the projection before the SVD.
    pub weighting: Weighting,
    /// LQ factor computation.
    pub factorization: Factorization,
    /// Estimate the feedthrough D (false: D = 0).
    pub estimate_d: bool,
    /// With `estimate_d`, a significance test on the estimate: `Some(k)` fixes D = 0 (and re-fits
    /// B and x0) when every entry of D lies within k standard errors of zero. The standard errors
    /// come from the output-error least squares, σ²·diag((ΦᵀΦ)⁻¹) with σ² the pooled residual
    /// variance (exact for white output noise on a SISO log). A strictly proper plant sampled
    /// with a zero-order hold has D = 0; an insignificant D estimate only adds noise where the
    /// plant's gain is small. `None` (default): D is kept as estimated.
    pub d_significance: Option<f64>,
    /// Estimate the initial state x0 together with B and D (false: x0 = 0).
    pub estimate_x0: bool,
    /// If set, enforce every discrete pole to satisfy |z| <= 1 − margin (0 < margin < 1).
    pub stability_margin: Option<f64>,
    /// Estimate the steady-state Kalman gain (innovation form) for one-step prediction.
    pub estimate_kalman_gain: bool,
}

impl Default for N4sidOptions {
    fn default() -> Self {
        Self {
            block_rows: 20,
            order: OrderSelection::Auto,
            weighting: Weighting::Moesp,
            factorization: Factorization::Auto,
            estimate_d: true,
            d_significance: None,
            estimate_x0: true,
            stability_margin: None,
            estimate_kalman_gain: true,
        }
    }
}

/// The identified model and the evidence behind it.
#[derive(Debug, Clone)]
pub struct N4sidResult {
    /// Discrete model (sample time of the data), in the data's physical units.
    pub model: StateSpace,
    /// Chosen order n.
    pub order: usize,
    /// Why this order (human-readable).
    pub order_reason: String,
    /// Singular values of the weighted projection (i·p of them; MOESP: of L₃₂, CVA: the
    /// canonical correlations), computed on RMS-normalised data.
    pub singular_values: Vec<f64>,
    /// Canonical correlations between past data and future outputs (orthogonal to future
    /// inputs), in [0, 1], used by the order criterion.
    pub canonical_correlations: Vec<f64>,
    /// Orders considered and their SVC values (empty for a fixed order).
    pub order_criterion: Vec<(usize, f64)>,
    /// (order, BIC) of the output-error fits compared when no singular-value gap was clear
    /// (empty otherwise).
    pub order_bic: Vec<(usize, f64)>,
    /// Estimated initial state (state coordinates of `model`), zeros if not estimated.
    pub x0: Vec<f64>,
    /// Steady-state Kalman gain K (n×p) of the innovation form x⁺ = Ax + Bu + Ke,
    /// y = Cx + Du + e, if estimated.
    pub kalman_gain: Option<Mat<f64>>,
    /// Innovation covariance E[e·eᵀ] (p×p, output units squared), if K was estimated.
    pub innovation_cov: Option<Mat<f64>>,
    /// True when stability was enforced and at least one pole moved.
    pub stability_enforced: bool,
    /// True when D was estimated, found insignificant by the test of
    /// [`N4sidOptions::d_significance`], and fixed to zero.
    pub d_fixed_by_test: bool,
    /// Non-fatal findings: stability changes, unstable poles, conditioning, order-rule
    /// disagreement, fallbacks taken.
    pub warnings: Vec<String>,
    /// RMS scale divided out of each input channel.
    pub input_scale: Vec<f64>,
    /// RMS scale divided out of each output channel.
    pub output_scale: Vec<f64>,
    /// Which LQ path was used ("cholesky" or "qr").
    pub factorization_used: &'static str,
    /// Block rows used.
    pub block_rows: usize,
}

/// Serialisable summary of an [`N4sidResult`] (for `--json` and reports).
#[derive(Debug, Clone, Serialize)]
pub struct N4sidSummary {
    /// The model, row-major.
    pub model: StateSpaceData,
    /// Chosen order.
    pub order: usize,
    /// Why this order.
    pub order_reason: String,
    /// Weighted singular values.
    pub singular_values: Vec<f64>,
    /// Canonical correlations.
    pub canonical_correlations: Vec<f64>,
    /// (order, SVC) pairs.
    pub order_criterion: Vec<(usize, f64)>,
    /// (order, BIC) pairs when the order was chosen by BIC.
    pub order_bic: Vec<(usize, f64)>,
    /// Initial state.
    pub x0: Vec<f64>,
    /// Kalman gain rows (n rows of p), if estimated.
    pub kalman_gain: Option<Vec<Vec<f64>>>,
    /// Poles as (re, im) pairs, z-plane.
    pub poles: Vec<(f64, f64)>,
    /// True when stability was enforced.
    pub stability_enforced: bool,
    /// D was estimated, found insignificant and fixed to zero.
    pub d_fixed_by_test: bool,
    /// Warnings.
    pub warnings: Vec<String>,
    /// Block rows used.
    pub block_rows: usize,
    /// LQ path used.
    pub factorization_used: &'static str,
}

impl N4sidResult {
    /// Serialisable summary.
    pub fn summary(&self) -> N4sidSummary {
        let rows = |m: &Mat<f64>| -> Vec<Vec<f64>> {
            (0..m.nrows())
                .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
                .collect()
        };
        N4sidSummary {
            model: StateSpaceData::from(&self.model),
            order: self.order,
            order_reason: self.order_reason.clone(),
            singular_values: self.singular_values.clone(),
            canonical_correlations: self.canonical_correlations.clone(),
            order_criterion: self.order_criterion.clone(),
            order_bic: self.order_bic.clone(),
            x0: self.x0.clone(),
            kalman_gain: self.kalman_gain.as_ref().map(rows),
            poles: self
                .model
                .poles()
                .unwrap_or_default()
                .iter()
                .map(|z| (z.re, z.im))
                .collect(),
            stability_enforced: self.stability_enforced,
            d_fixed_by_test: self.d_fixed_by_test,
            warnings: self.warnings.clone(),
            block_rows: self.block_rows,
            factorization_used: self.factorization_used,
        }
    }

    /// The innovation-form one-step-ahead predictor as a state-space model with inputs
    /// [u; y] and output ŷ(t|t−1): x⁺ = (A − KC)x + (B − KD)u + Ky, ŷ = Cx + Du.
    /// `None` when no Kalman gain was estimated.
    pub fn predictor(&self) -> Option<Result<StateSpace>> {
        self.kalman_gain
            .as_ref()
            .map(|k| one_step_predictor(&self.model, k.as_ref()))
    }
}

/// Builds the one-step-ahead predictor (inputs [u; y], output ŷ(t|t−1)) of the innovation
/// model (A, B, C, D, K): x⁺ = (A − KC)x + (B − KD)u + Ky, ŷ = Cx + Du.
pub fn one_step_predictor(model: &StateSpace, k: MatRef<'_, f64>) -> Result<StateSpace> {
    let (n, m, p) = (model.n_states(), model.n_inputs(), model.n_outputs());
    if k.nrows() != n || k.ncols() != p {
        return Err(Error::InvalidArgument(format!(
            "Kalman gain must be {n}x{p}, got {}x{}",
            k.nrows(),
            k.ncols()
        )));
    }
    let a = &model.a - k * &model.c;
    let bkd = &model.b - k * &model.d;
    let b = Mat::from_fn(
        n,
        m + p,
        |i, j| if j < m { bkd[(i, j)] } else { k[(i, j - m)] },
    );
    let d = Mat::from_fn(p, m + p, |i, j| if j < m { model.d[(i, j)] } else { 0.0 });
    StateSpace::new(a, b, model.c.clone(), d, model.ts)
}

/// Identifies a model from a [`Log`] (inputs → outputs); errors name `log.path` and the channel.
pub fn n4sid(log: &Log, opts: &N4sidOptions) -> Result<N4sidResult> {
    let u: Vec<&[f64]> = log.inputs.iter().map(|c| c.data.as_slice()).collect();
    let y: Vec<&[f64]> = log.outputs.iter().map(|c| c.data.as_slice()).collect();
    let un: Vec<String> = log.inputs.iter().map(|c| c.name.clone()).collect();
    let yn: Vec<String> = log.outputs.iter().map(|c| c.name.clone()).collect();
    identify(&log.path, log.ts, &u, &y, &un, &yn, opts)
}

/// Identifies a model from in-memory channels: `u[j]` input channel j, `y[i]` output channel i,
/// all of equal length; `ts` the sample time in seconds.
pub fn n4sid_slices(
    ts: f64,
    u: &[&[f64]],
    y: &[&[f64]],
    opts: &N4sidOptions,
) -> Result<N4sidResult> {
    let un: Vec<String> = (0..u.len()).map(|j| format!("u{j}")).collect();
    let yn: Vec<String> = (0..y.len()).map(|j| format!("y{j}")).collect();
    identify(Path::new("<in-memory data>"), ts, u, y, &un, &yn, opts)
}

fn data_err(source: &Path, msg: String) -> Error {
    Error::Data {
        file: PathBuf::from(source),
        msg,
    }
}

/// Root mean square, computed on the signal normalised by an exact power of two so that the
/// squares neither overflow (|x| near 1e300) nor underflow (near 1e-300).
fn rms(x: &[f64]) -> f64 {
    let g = crate::spectral::power_of_two_scale(crate::spectral::max_abs(x));
    (x.iter().map(|v| (v * g) * (v * g)).sum::<f64>() / x.len() as f64).sqrt() / g
}

fn check_channels(
    source: &Path,
    u: &[&[f64]],
    y: &[&[f64]],
    un: &[String],
    yn: &[String],
) -> Result<usize> {
    if u.is_empty() || y.is_empty() {
        return Err(data_err(
            source,
            format!(
                "need at least one input and one output channel, got {} and {}",
                u.len(),
                y.len()
            ),
        ));
    }
    let n = u[0].len();
    for (ch, name, kind) in u
        .iter()
        .zip(un)
        .map(|(c, n)| (c, n, "input"))
        .chain(y.iter().zip(yn).map(|(c, n)| (c, n, "output")))
    {
        if ch.len() != n {
            return Err(data_err(
                source,
                format!(
                    "{kind} `{name}` has {} samples but `{}` has {n} (mismatched lengths)",
                    ch.len(),
                    un[0]
                ),
            ));
        }
        if let Some(k) = ch.iter().position(|v| !v.is_finite()) {
            return Err(data_err(
                source,
                format!("{kind} `{name}` sample {k} is {} (not finite)", ch[k]),
            ));
        }
        if n > 0 {
            let g = crate::spectral::power_of_two_scale(crate::spectral::max_abs(ch));
            let mean = ch.iter().map(|v| v * g).sum::<f64>() / n as f64;
            let var = ch.iter().map(|v| (v * g - mean).powi(2)).sum::<f64>() / n as f64;
            let r = rms(ch) * g;
            if !(var.sqrt() > 1e-12 * r) {
                let what = if kind == "input" {
                    "no excitation"
                } else {
                    "nothing to identify"
                };
                return Err(data_err(
                    source,
                    format!("{kind} `{name}` is constant ({what})"),
                ));
            }
        }
    }
    Ok(n)
}

/// 8-lane dot product (vectorisable without reassociation by the compiler).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut s = (acc[0] + acc[4]) + (acc[1] + acc[5]) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// Row ordering of the data matrix: for each row, (block index j in 0..2i, channel index in
/// w = [u; y]). Order [U_f; U_p; Y_p; Y_f].
fn row_order(k: usize, m: usize, p: usize) -> Vec<(usize, usize)> {
    let mut rows = Vec::with_capacity(2 * k * (m + p));
    for j in k..2 * k {
        for a in 0..m {
            rows.push((j, a));
        }
    }
    for j in 0..k {
        for a in 0..m {
            rows.push((j, a));
        }
    }
    for j in 0..k {
        for a in m..m + p {
            rows.push((j, a));
        }
    }
    for j in k..2 * k {
        for a in m..m + p {
            rows.push((j, a));
        }
    }
    rows
}

/// Correlation matrix H·Hᵀ/J of the block Hankel matrix in the given row order, computed from
/// lagged cross-correlations of the channels plus the shift recursion
/// R(j+1, l+1) = R(j, l) − w(j)w(l)ᵀ + w(j+J)w(l+J)ᵀ.
fn hankel_correlation(w: &[Vec<f64>], k: usize, rows: &[(usize, usize)]) -> Mat<f64> {
    let q = w.len();
    let nb = 2 * k;
    let n = w[0].len();
    let jcols = n - nb + 1;
    // s[(j*q + a), (l*q + b)] for block pairs with j <= l, unnormalised.
    let dim = nb * q;
    let mut s = Mat::<f64>::zeros(dim, dim);
    // First block row: lags l = 0..2i.
    for a in 0..q {
        for b in 0..q {
            for l in 0..nb {
                s[(a, l * q + b)] = dot(&w[a][..jcols], &w[b][l..l + jcols]);
            }
        }
    }
    for j in 0..nb - 1 {
        for l in j..nb - 1 {
            for a in 0..q {
                for b in 0..q {
                    let prev = s[(j * q + a, l * q + b)];
                    s[((j + 1) * q + a, (l + 1) * q + b)] =
                        prev - w[a][j] * w[b][l] + w[a][j + jcols] * w[b][l + jcols];
                }
            }
        }
    }
    let inv = 1.0 / jcols as f64;
    let get = |(j, a): (usize, usize), (l, b): (usize, usize)| {
        if j <= l {
            s[(j * q + a, l * q + b)]
        } else {
            s[(l * q + b, j * q + a)]
        }
    };
    Mat::from_fn(rows.len(), rows.len(), |r, c| get(rows[r], rows[c]) * inv)
}

/// LQ factor by Householder QR of Hᵀ/√J (J × rows).
fn lq_by_qr(w: &[Vec<f64>], k: usize, rows: &[(usize, usize)]) -> Result<Mat<f64>> {
    let n = w[0].len();
    let jcols = n - 2 * k + 1;
    let sc = 1.0 / (jcols as f64).sqrt();
    let ht = Mat::from_fn(jcols, rows.len(), |t, c| {
        let (j, a) = rows[c];
        w[a][t + j] * sc
    });
    let qr = ht.qr();
    let r = qr.thin_R();
    let l = r.transpose().to_owned();
    for j in 0..l.ncols() {
        for i in 0..l.nrows() {
            if !l[(i, j)].is_finite() {
                return Err(Error::Numerical(
                    "QR of the block Hankel matrix failed".into(),
                ));
            }
        }
    }
    Ok(l)
}

struct Svd {
    u: Mat<f64>,
    s: Vec<f64>,
    v: Mat<f64>,
}

fn thin_svd(m: MatRef<'_, f64>, what: &str) -> Result<Svd> {
    let svd = m
        .thin_svd()
        .map_err(|e| Error::Numerical(format!("SVD of {what} did not converge: {e:?}")))?;
    let s: Vec<f64> = svd.S().column_vector().iter().copied().collect();
    Ok(Svd {
        u: svd.U().to_owned(),
        s,
        v: svd.V().to_owned(),
    })
}

/// Least squares min ‖A x − B‖ by column-pivoted QR; errors when A is rank deficient to
/// working precision.
fn lstsq(a: MatRef<'_, f64>, b: MatRef<'_, f64>, what: &str) -> Result<Mat<f64>> {
    let qr = a.col_piv_qr();
    let r = qr.R();
    let d = a.ncols().min(a.nrows());
    if d == 0 {
        return Ok(Mat::zeros(a.ncols(), b.ncols()));
    }
    let r0 = r[(0, 0)].abs();
    let rmin = (0..d)
        .map(|i| r[(i, i)].abs())
        .fold(f64::INFINITY, f64::min);
    if !(rmin > 1e-13 * r0) || a.nrows() < a.ncols() {
        return Err(Error::Numerical(format!(
            "{what}: regressors are rank deficient (pivot ratio {:.1e})",
            rmin / r0
        )));
    }
    let x = qr.solve_lstsq(b);
    for j in 0..x.ncols() {
        for i in 0..x.nrows() {
            if !x[(i, j)].is_finite() {
                return Err(Error::Numerical(format!("{what}: solution not finite")));
            }
        }
    }
    Ok(x)
}

fn fmt_pole(z: Complex64) -> String {
    format!(
        "{:.6}{:+.6}j (|z| = {:.6}, angle {:.2}°)",
        z.re,
        z.im,
        z.norm(),
        z.arg().to_degrees()
    )
}

/// Moves poles inside |z| <= 1 − margin: reflection 1/z̄ for |z| >= 1, then radial pull to the
/// margin circle. Returns the new A (same state basis) and the change descriptions.
fn enforce_stability(a: &Mat<f64>, margin: f64) -> Result<(Mat<f64>, Vec<String>)> {
    let n = a.nrows();
    let rmax = 1.0 - margin;
    let target = |z: Complex64| -> Complex64 {
        let mut t = z;
        if t.norm() >= 1.0 {
            t = Complex64::new(1.0, 0.0) / t.conj();
        }
        if t.norm() > rmax {
            t *= rmax / t.norm();
        }
        t
    };
    let poles = eigenvalues(a.as_ref())?;
    if poles.iter().all(|z| z.norm() <= rmax) {
        return Ok((a.clone(), Vec::new()));
    }
    let mut changes = Vec::new();
    let eig = a
        .eigen()
        .map_err(|e| Error::Numerical(format!("eigendecomposition of A failed: {e:?}")))?;
    let v = eig.U().to_owned();
    let lam: Vec<Complex64> = eig.S().column_vector().iter().copied().collect();
    let sv = v
        .singular_values()
        .map_err(|e| Error::Numerical(format!("SVD of eigenvectors failed: {e:?}")))?;
    let cond = sv[0] / sv[sv.len() - 1];
    if cond.is_finite() && cond < 1e8 {
        let new_lam: Vec<Complex64> = lam.iter().map(|&z| target(z)).collect();
        for (&z, &t) in lam.iter().zip(&new_lam) {
            if (z - t).norm() > 0.0 && z.im >= 0.0 {
                changes.push(format!("pole {} moved to {}", fmt_pole(z), fmt_pole(t)));
            }
        }
        // A' = V Λ' V⁻¹  ⇔  Vᵀ A'ᵀ = (V Λ')ᵀ.
        let vl = Mat::from_fn(n, n, |i, j| v[(i, j)] * new_lam[j]);
        let vt = v.transpose().to_owned();
        let rhs = vl.transpose().to_owned();
        let at = vt.partial_piv_lu().solve(&rhs);
        let scale = crate::lti::norm1(a.as_ref()).max(1.0);
        let mut a_new = Mat::<f64>::zeros(n, n);
        for i in 0..n {
            for j in 0..n {
                let z = at[(j, i)];
                if !(z.im.abs() <= 1e-8 * scale) || !z.re.is_finite() {
                    return Err(Error::Numerical(
                        "stability enforcement produced a complex A (unpaired poles)".into(),
                    ));
                }
                a_new[(i, j)] = z.re;
            }
        }
        Ok((a_new, changes))
    } else {
        // Nearly defective A: scale the whole matrix so that its spectral radius is rmax.
        let rho = poles.iter().map(|z| z.norm()).fold(0.0, f64::max);
        let f = rmax / rho;
        changes.push(format!(
            "A is nearly defective (eigenvector condition {cond:.1e}); all poles scaled by \
             {f:.6} so that the spectral radius {rho:.6} becomes {rmax:.6}"
        ));
        Ok((a * faer::Scale(f), changes))
    }
}

/// Output-error regressors for (x0, B, D) given (A, C) over `len` samples, column-major in a
/// flat buffer: (len·p) rows × (n + n·m + p·m) columns (x0 entries if `with_x0`, B entries
/// column-major by input, D entries if `with_d`), rows ordered output-major (row = i·len + t).
/// Returns (buffer, rows, cols); view it with `MatRef::from_column_major_slice`.
fn oe_regressors(
    a: &Mat<f64>,
    c: &Mat<f64>,
    u: &[Vec<f64>],
    len: usize,
    with_x0: bool,
    with_d: bool,
) -> (Vec<f64>, usize, usize) {
    let n = a.nrows();
    let p = c.nrows();
    let m = u.len();
    let rows = len * p;
    let ncols = if with_x0 { n } else { 0 } + n * m + if with_d { p * m } else { 0 };
    let mut buf = vec![0.0; rows * ncols];
    let ar: Vec<f64> = (0..n * n).map(|k| a[(k / n, k % n)]).collect();
    let cr: Vec<f64> = (0..p * n).map(|k| c[(k / n, k % n)]).collect();
    if rows == 0 || ncols == 0 {
        return (buf, rows, ncols);
    }
    let mut cols = buf.chunks_mut(rows);
    if with_x0 {
        let mut block: Vec<&mut [f64]> = cols.by_ref().take(n).collect();
        unit_direction_responses(&ar, &cr, n, p, None, len, &mut block);
    }
    for uj in u {
        let mut block: Vec<&mut [f64]> = cols.by_ref().take(n).collect();
        unit_direction_responses(&ar, &cr, n, p, Some(uj), len, &mut block);
    }
    if with_d {
        for uj in u {
            for i in 0..p {
                if let Some(col) = cols.next() {
                    col[i * len..(i + 1) * len].copy_from_slice(uj);
                }
            }
        }
    }
    (buf, rows, ncols)
}

/// Output-error regressors of one input (or of the initial state) for every state direction:
/// `cols[d][i·len + t]`, d in 0..n. `ar`, `cr` are row-major.
///
/// With `input = Some(u)`: the response of output i at time t to u entering state d,
/// Σ_{τ<t} (C A^{t−1−τ})[i, d]·u(τ); with `None`: the free response (C Aᵗ)[i, d] from
/// x(0) = e_d. Both are rows of R(t) = C·X(t) where X(t) is a polynomial in A, so X commutes
/// with A and R obeys the p×n recursion R(t+1) = R(t)·A + u(t)·C (R(0) = 0), resp.
/// R(t+1) = R(t)·A (R(0) = C): O(p·n²) per sample instead of simulating n systems.
fn unit_direction_responses(
    ar: &[f64],
    cr: &[f64],
    n: usize,
    p: usize,
    input: Option<&[f64]>,
    len: usize,
    cols: &mut [&mut [f64]],
) {
    let mut r = if input.is_none() {
        cr.to_vec()
    } else {
        vec![0.0; p * n]
    };
    let mut rn = vec![0.0; p * n];
    for t in 0..len {
        for i in 0..p {
            for (d, col) in cols.iter_mut().enumerate() {
                col[i * len + t] = r[i * n + d];
            }
        }
        let ut = input.map_or(0.0, |s| s[t]);
        for i in 0..p {
            let ri = &r[i * n..(i + 1) * n];
            let row = &mut rn[i * n..(i + 1) * n];
            for (d, v) in row.iter_mut().enumerate() {
                *v = ut * cr[i * n + d];
            }
            for (k, &rik) in ri.iter().enumerate() {
                let ak = &ar[k * n..(k + 1) * n];
                for (v, &akd) in row.iter_mut().zip(ak) {
                    *v += rik * akd;
                }
            }
        }
        std::mem::swap(&mut r, &mut rn);
    }
}

/// Estimates the initial state x0 (state coordinates of `model`) that makes the free-run
/// simulation of the discrete `model` driven by `u` best match `y` in least squares.
/// `u[j]`, `y[i]` are channels of equal length.
pub fn estimate_x0<U: AsRef<[f64]>, Y: AsRef<[f64]>>(
    model: &StateSpace,
    u: &[U],
    y: &[Y],
) -> Result<Vec<f64>> {
    if !model.is_discrete() {
        return Err(Error::InvalidArgument(
            "estimate_x0 needs a discrete-time model".into(),
        ));
    }
    let (n, p) = (model.n_states(), model.n_outputs());
    if y.len() != p {
        return Err(Error::InvalidArgument(format!(
            "estimate_x0: model has {p} outputs, {} output channels given",
            y.len()
        )));
    }
    let y0 = model.simulate(u, None)?;
    let len = y0[0].len();
    if n == 0 {
        return Ok(Vec::new());
    }
    for (i, yi) in y.iter().enumerate() {
        let yi = yi.as_ref();
        if yi.len() != len {
            return Err(Error::InvalidArgument(format!(
                "estimate_x0: output channel {i} has {} samples, inputs have {len}",
                yi.len()
            )));
        }
        if let Some(k) = yi.iter().position(|v| !v.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "estimate_x0: output channel {i} sample {k} is not finite"
            )));
        }
    }
    let (buf, rows, cols) = oe_regressors(&model.a, &model.c, &[], len, true, false);
    let phi = MatRef::from_column_major_slice(&buf, rows, cols);
    let rhs = Mat::from_fn(len * p, 1, |r, _| {
        let (i, t) = (r / len, r % len);
        y[i].as_ref()[t] - y0[i][t]
    });
    let x = lstsq(phi.as_ref(), rhs.as_ref(), "estimate_x0")?;
    Ok((0..n).map(|i| x[(i, 0)]).collect())
}

#[allow(clippy::too_many_arguments)]
fn identify(
    source: &Path,
    ts: f64,
    u: &[&[f64]],
    y: &[&[f64]],
    un: &[String],
    yn: &[String],
    opts: &N4sidOptions,
) -> Result<N4sidResult> {
    if !(ts.is_finite() && ts > 0.0) {
        return Err(data_err(
            source,
            format!("sample time {ts} s must be finite and > 0"),
        ));
    }
    let k = opts.block_rows;
    if !(2..=MAX_BLOCK_ROWS).contains(&k) {
        return Err(Error::InvalidArgument(format!(
            "block_rows (i) must be in 2..={MAX_BLOCK_ROWS}, got {k}"
        )));
    }
    if let Some(mg) = opts.stability_margin {
        if !(mg > 0.0 && mg < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "stability margin must be in (0, 1), got {mg}"
            )));
        }
    }
    let len = check_channels(source, u, y, un, yn)?;
    let (m, p) = (u.len(), y.len());
    let q = m + p;
    let max_order = (k - 1) * p;
    let (n_lo, n_hi, fixed) = match opts.order {
        OrderSelection::Auto => (1, max_order.min(20), None),
        OrderSelection::Range { min, max } => {
            if min == 0 || min > max || max > max_order {
                return Err(Error::InvalidArgument(format!(
                    "order range {min}..={max} invalid: need 1 <= min <= max <= (i−1)·p = \
                     {max_order} (increase block_rows for higher orders)"
                )));
            }
            (min, max, None)
        }
        OrderSelection::Fixed(n) => {
            if n == 0 || n > max_order {
                return Err(Error::InvalidArgument(format!(
                    "order {n} invalid: need 1 <= n <= (i−1)·p = {max_order} (increase \
                     block_rows for higher orders)"
                )));
            }
            (n, n, Some(n))
        }
    };
    let nrows = 2 * k * q;
    let min_len = 2 * k - 1 + nrows.max(2 * k * q + n_hi);
    if len < min_len {
        return Err(data_err(
            source,
            format!(
                "too few samples for N4SID with i = {k} block rows and {m} input(s), {p} \
                 output(s): have {len}, need at least {min_len} (reduce block_rows or record \
                 longer)"
            ),
        ));
    }
    let mut warnings = Vec::new();

    // 1. Scaling.
    let su: Vec<f64> = u.iter().map(|c| rms(c)).collect();
    let sy: Vec<f64> = y.iter().map(|c| rms(c)).collect();
    let w: Vec<Vec<f64>> = u
        .iter()
        .zip(&su)
        .chain(y.iter().zip(&sy))
        .map(|(c, s)| c.iter().map(|v| v / s).collect())
        .collect();
    let us: &[Vec<f64>] = &w[..m];
    let jcols = len - 2 * k + 1;

    // 2. LQ factor.
    let rows = row_order(k, m, p);
    let mut fact_used = "cholesky";
    let l = match opts.factorization {
        Factorization::Auto => {
            let r = hankel_correlation(&w, k, &rows);
            match r.llt(Side::Lower) {
                Ok(ch) => {
                    let l = ch.L().to_owned();
                    let d: Vec<f64> = (0..nrows).map(|i| l[(i, i)]).collect();
                    let dmax = d.iter().fold(0.0f64, |a, &b| a.max(b));
                    let dmin = d.iter().fold(f64::INFINITY, |a, &b| a.min(b));
                    if dmin > 1e-7 * dmax {
                        l
                    } else {
                        fact_used = "qr";
                        lq_by_qr(&w, k, &rows)?
                    }
                }
                Err(_) => {
                    fact_used = "qr";
                    lq_by_qr(&w, k, &rows)?
                }
            }
        }
        Factorization::Qr => {
            fact_used = "qr";
            lq_by_qr(&w, k, &rows)?
        }
    };
    let (uf, wp, yf) = (k * m, k * q, k * p);
    // Persistent excitation: the input rows of L.
    {
        let dins: Vec<f64> = (0..uf)
            .chain(uf..uf + k * m)
            .map(|i| l[(i, i)].abs())
            .collect();
        let dmax = dins.iter().fold(0.0f64, |a, &b| a.max(b));
        let dmin = dins.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        if dmin < 1e-6 * dmax {
            warnings.push(format!(
                "the input is not persistently exciting of order 2i = {} (input-row LQ pivot \
                 ratio {:.1e}); the model may be poorly determined: use a broadband input or \
                 fewer block rows",
                2 * k,
                dmin / dmax
            ));
        }
    }
    let l32 = l.as_ref().submatrix(uf + wp, uf, yf, wp);
    let l33 = l.as_ref().submatrix(uf + wp, uf + wp, yf, yf);

    // 3. Weighted SVDs.
    let svd_moesp = thin_svd(l32, "L32")?;
    // CVA: SVD of M = [L32 L33] = U_M Σ_M V_Mᵀ; canonical correlations = SVs of V_M1ᵀ.
    let mfull = Mat::from_fn(yf, wp + yf, |i, j| {
        if j < wp {
            l32[(i, j)]
        } else {
            l33[(i, j - wp)]
        }
    });
    let svd_m = thin_svd(mfull.as_ref(), "[L32 L33]")?;
    let rank_m = svd_m
        .s
        .iter()
        .take_while(|&&s| s > 1e-7 * svd_m.s[0])
        .count()
        .max(1);
    let g_t = Mat::from_fn(rank_m, wp, |i, j| svd_m.v[(j, i)]);
    let svd_cc = thin_svd(g_t.as_ref(), "canonical correlations")?;
    let mut cc: Vec<f64> = svd_cc.s.iter().map(|s| s.min(1.0)).collect();
    cc.resize(yf, 0.0);

    // 4. Order.
    let sv_weighted: Vec<f64> = match opts.weighting {
        Weighting::Moesp => svd_moesp.s.clone(),
        Weighting::Cva => cc.clone(),
    };
    let sub = Subspace {
        weighting: opts.weighting,
        moesp: &svd_moesp,
        m_svd: &svd_m,
        cc_svd: &svd_cc,
        rank_m,
        yf,
        p,
    };
    let ys: &[Vec<f64>] = &w[m..];
    let mut order_bic = Vec::new();
    let (fit, order_reason, criterion) = if let Some(n) = fixed {
        let fit = fit_order(n, &sub, us, ys, opts)?;
        (fit, format!("order {n} fixed by the caller"), Vec::new())
    } else {
        let sel = select_order(&sv_weighted, &cc, n_lo, n_hi, jcols, m, p);
        if sel.gap >= CLEAR_GAP {
            let fit = fit_order(sel.order, &sub, us, ys, opts)?;
            (fit, sel.reason, sel.svc)
        } else {
            // No clear gap: compare the candidate orders by BIC on their output-error fits.
            let mut best: Option<(f64, OrderFit)> = None;
            let mut failures = Vec::new();
            for n in n_lo..=sel.n_svc {
                match fit_order(n, &sub, us, ys, opts) {
                    Ok(f) => {
                        let k = n * (m + p) + if opts.estimate_d { p * m } else { 0 };
                        let bic = len as f64 * f.resid_logdet + k as f64 * (len as f64).ln();
                        order_bic.push((n, bic));
                        if best.as_ref().is_none_or(|(b, _)| bic < *b) {
                            best = Some((bic, f));
                        }
                    }
                    Err(e) => failures.push(format!("n = {n}: {e}")),
                }
            }
            let Some((_, fit)) = best else {
                return Err(Error::Numerical(format!(
                    "no candidate order could be fitted: {}",
                    failures.join("; ")
                )));
            };
            let n = fit.n;
            warnings.push(format!(
                "no clear singular-value gap (largest σn/σn+1 = {:.2} < {CLEAR_GAP} among the \
                 orders {n_lo}..={} supported by SVC): order {n} chosen by BIC on the \
                 output-error fit; the data may not support a low-order model",
                sel.gap, sel.n_svc
            ));
            let reason = format!(
                "order {n}: minimises BIC(n) = N·ln det Σ̂(n) + (n(m+p) + pm)·ln N of the \
                 output-error residual over {n_lo}..={} (the orders supported by Bauer's SVC on \
                 the canonical correlations, J = {jcols}); no clear singular-value gap (largest \
                 σ{}/σ{} = {:.3})",
                sel.n_svc,
                sel.order,
                sel.order + 1,
                sel.gap
            );
            (fit, reason, sel.svc)
        }
    };
    let n = fit.n;
    if sv_weighted[n - 1] <= 1e-10 * sv_weighted[0] {
        warnings.push(format!(
            "order {n} exceeds the numerical rank of the projection (σ{n}/σ1 = {:.1e}): the \
             extra states are fitted to round-off",
            sv_weighted[n - 1] / sv_weighted[0]
        ));
    }
    warnings.extend(fit.notes.iter().cloned());
    let stability_enforced = fit.stability_enforced;
    let d_fixed_by_test = fit.d_fixed_by_test;
    let OrderFit {
        a: a_s,
        b: b_s,
        c: c_s,
        d: d_s,
        x0,
        gamma,
        ..
    } = fit;

    // 8. Kalman gain.
    let mut kalman = None;
    if opts.estimate_kalman_gain {
        match kalman_gain(&l, &gamma, &a_s, &b_s, &c_s, &d_s, &w, k, m, p) {
            Ok((kg, re)) => {
                let pred = &a_s - &kg * &c_s;
                let ok = eigenvalues(pred.as_ref())?.iter().all(|z| z.norm() < 1.0);
                if ok {
                    kalman = Some((kg, re));
                } else {
                    warnings.push(
                        "Kalman gain dropped: A − KC is not stable (predictor would diverge)"
                            .into(),
                    );
                }
            }
            Err(e) => warnings.push(format!("Kalman gain not estimated: {e}")),
        }
    }

    // Unscale: B·diag(1/su), diag(sy)·C, diag(sy)·D·diag(1/su), K·diag(1/sy).
    let b = Mat::from_fn(n, m, |i, j| b_s[(i, j)] / su[j]);
    let c = Mat::from_fn(p, n, |i, j| c_s[(i, j)] * sy[i]);
    let d = Mat::from_fn(p, m, |i, j| d_s[(i, j)] * (sy[i] / su[j]));
    let model = StateSpace::new(a_s, b, c, d, ts)?;
    let (kalman_gain, innovation_cov) = match kalman {
        Some((kg, re)) => (
            Some(Mat::from_fn(n, p, |i, j| kg[(i, j)] / sy[j])),
            Some(Mat::from_fn(p, p, |i, j| re[(i, j)] * sy[i] * sy[j])),
        ),
        None => (None, None),
    };
    Ok(N4sidResult {
        model,
        order: n,
        order_reason,
        singular_values: sv_weighted,
        canonical_correlations: cc,
        order_criterion: criterion,
        order_bic,
        x0,
        kalman_gain,
        innovation_cov,
        stability_enforced,
        d_fixed_by_test,
        warnings,
        input_scale: su,
        output_scale: sy,
        factorization_used: fact_used,
        block_rows: k,
    })
}

/// A largest singular-value gap below this ratio is not "clear": the order is then chosen by
/// BIC on the output-error fits of the candidate orders.
const CLEAR_GAP: f64 = 10.0;

/// The SVD results from which Γ is formed for any order.
struct Subspace<'a> {
    weighting: Weighting,
    moesp: &'a Svd,
    m_svd: &'a Svd,
    cc_svd: &'a Svd,
    rank_m: usize,
    yf: usize,
    p: usize,
}

impl Subspace<'_> {
    /// Extended observability matrix Γ (i·p × n) for order n.
    fn gamma(&self, n: usize) -> Result<Mat<f64>> {
        Ok(match self.weighting {
            Weighting::Moesp => Mat::from_fn(self.yf, n, |i, j| {
                self.moesp.u[(i, j)] * self.moesp.s[j].sqrt()
            }),
            Weighting::Cva => {
                // Γ = U_M Σ_M P_n S_n^½ (P: left singular vectors of G^T).
                if n > self.rank_m {
                    return Err(Error::Numerical(format!(
                        "CVA: order {n} exceeds the rank {} of the future-output projection",
                        self.rank_m
                    )));
                }
                let um_s = Mat::from_fn(self.yf, self.rank_m, |i, j| {
                    self.m_svd.u[(i, j)] * self.m_svd.s[j]
                });
                let pn = Mat::from_fn(self.rank_m, n, |i, j| {
                    self.cc_svd.u[(i, j)] * self.cc_svd.s[j].sqrt()
                });
                &um_s * &pn
            }
        })
    }
}

/// A model of one order in scaled units, with its output-error residual statistics.
struct OrderFit {
    n: usize,
    a: Mat<f64>,
    b: Mat<f64>,
    c: Mat<f64>,
    d: Mat<f64>,
    x0: Vec<f64>,
    gamma: Mat<f64>,
    /// ln det of the output-error residual covariance (scaled units).
    resid_logdet: f64,
    notes: Vec<String>,
    /// D was dropped by the significance test.
    d_fixed_by_test: bool,
    stability_enforced: bool,
}

/// Steps 5–7 of the module docs for order n: A, C by shift invariance, stability handling,
/// then B, D, x0 by output-error least squares.
fn fit_order(
    n: usize,
    sub: &Subspace<'_>,
    us: &[Vec<f64>],
    ys: &[Vec<f64>],
    opts: &N4sidOptions,
) -> Result<OrderFit> {
    let (p, yf) = (sub.p, sub.yf);
    let m = us.len();
    let len = us[0].len();
    let mut notes = Vec::new();
    let gamma = sub.gamma(n)?;
    // 5. A, C.
    let c_s = gamma.as_ref().submatrix(0, 0, p, n).to_owned();
    let g_up = gamma.as_ref().submatrix(0, 0, yf - p, n);
    let g_dn = gamma.as_ref().submatrix(p, 0, yf - p, n);
    let g_up_sv = g_up
        .singular_values()
        .map_err(|e| Error::Numerical(format!("SVD of Γ failed: {e:?}")))?;
    let cond_up = g_up_sv[0] / g_up_sv[n - 1];
    if !(cond_up < 1e10) {
        return Err(Error::Numerical(format!(
            "ill-conditioned fit: the shifted observability matrix has condition {cond_up:.1e} \
             for order {n}; choose a lower order"
        )));
    }
    if cond_up > 1e6 {
        notes.push(format!(
            "the shifted observability matrix is ill-conditioned (condition {cond_up:.1e}); A \
             is poorly determined at order {n}"
        ));
    }
    let mut a_s = lstsq(g_up, g_dn, "shift invariance Γ_up·A = Γ_down")?;

    // 6. Stability.
    let mut stability_enforced = false;
    let poles = eigenvalues(a_s.as_ref())?;
    let rho = poles.iter().map(|z| z.norm()).fold(0.0, f64::max);
    if let Some(mg) = opts.stability_margin {
        let (a_new, changes) = enforce_stability(&a_s, mg)?;
        if !changes.is_empty() {
            stability_enforced = true;
            for ch in changes {
                notes.push(format!("stability enforced (margin {mg}): {ch}"));
            }
            a_s = a_new;
        }
    } else if rho >= 1.0 {
        let bad: Vec<String> = poles
            .iter()
            .filter(|z| z.norm() >= 1.0 && z.im >= 0.0)
            .map(|&z| fmt_pole(z))
            .collect();
        notes.push(format!(
            "identified model is unstable: pole(s) {}; set a stability margin to enforce \
             stability",
            bad.join(", ")
        ));
    }

    // 7. B, D, x0 by output-error least squares.
    let ybig = Mat::from_fn(len * p, 1, |r, _| ys[r / len][r % len]);
    // θ, the output-error residual y − Φθ and, when D is estimated and tested, its largest
    // |D|/SE; for D estimated or fixed to zero.
    let solve = |with_d: bool| -> Result<(Mat<f64>, Mat<f64>, Option<f64>)> {
        let (buf, rows, cols) = oe_regressors(&a_s, &c_s, us, len, opts.estimate_x0, with_d);
        let phi = MatRef::from_column_major_slice(&buf, rows, cols);
        let theta = lstsq(phi, ybig.as_ref(), "B/D least squares").map_err(|e| {
            if rho >= 1.0 && opts.stability_margin.is_none() {
                Error::Numerical(format!(
                    "unstable fit (spectral radius {rho:.6}): {e}; set a stability margin"
                ))
            } else {
                e
            }
        })?;
        let mut resid = ybig.clone();
        faer::linalg::matmul::matmul(
            resid.as_mut(),
            faer::Accum::Add,
            phi,
            theta.as_ref(),
            -1.0,
            faer::Par::Seq,
        );
        let t_ratio = match opts.d_significance {
            Some(_) if with_d => d_t_ratio(phi, resid.as_ref(), theta.as_ref(), p * m)?,
            _ => None,
        };
        Ok((theta, resid, t_ratio))
    };
    let (mut theta, mut resid, t_ratio) = solve(opts.estimate_d)?;
    let mut with_d = opts.estimate_d;
    if let (Some(k), Some(worst)) = (opts.d_significance, t_ratio) {
        if worst <= k {
            (theta, resid, _) = solve(false)?;
            with_d = false;
            notes.push(format!(
                "feedthrough D fixed to zero: every entry lies within {k} standard errors \
                 of zero (largest |D|/SE = {worst:.2})"
            ));
        }
    }
    let mut idx = 0;
    let x0: Vec<f64> = if opts.estimate_x0 {
        idx = n;
        (0..n).map(|i| theta[(i, 0)]).collect()
    } else {
        vec![0.0; n]
    };
    let mut b_s = Mat::<f64>::zeros(n, m);
    for j in 0..m {
        for i in 0..n {
            b_s[(i, j)] = theta[(idx + j * n + i, 0)];
        }
    }
    idx += n * m;
    let mut d_s = Mat::<f64>::zeros(p, m);
    if with_d {
        for j in 0..m {
            for i in 0..p {
                d_s[(i, j)] = theta[(idx + j * p + i, 0)];
            }
        }
    }
    // Residual covariance of the output error.
    let rv = resid.col_as_slice(0);
    let sigma = Mat::from_fn(p, p, |i, j| {
        dot(&rv[i * len..(i + 1) * len], &rv[j * len..(j + 1) * len]) / len as f64
    });
    let lu = sigma.partial_piv_lu();
    let resid_logdet: f64 = (0..p)
        .map(|i| lu.U()[(i, i)].abs().max(f64::MIN_POSITIVE).ln())
        .sum();
    Ok(OrderFit {
        n,
        a: a_s,
        b: b_s,
        c: c_s,
        d: d_s,
        x0,
        gamma,
        resid_logdet,
        notes,
        stability_enforced,
        d_fixed_by_test: opts.estimate_d && !with_d,
    })
}

/// Largest |θ_k|/SE(θ_k) over the last `n_d` parameters (the D entries) of the least-squares fit
/// `phi · theta ≈ y` with residual `resid` = y − Φθ: SE² = σ²·[(ΦᵀΦ)⁻¹]_kk, σ² the residual
/// variance (rows − cols degrees of freedom). `None` when there are no D entries or no residual
/// degrees of freedom.
fn d_t_ratio(
    phi: MatRef<'_, f64>,
    resid: MatRef<'_, f64>,
    theta: MatRef<'_, f64>,
    n_d: usize,
) -> Result<Option<f64>> {
    let (rows, cols) = (phi.nrows(), phi.ncols());
    if n_d == 0 || n_d > cols || rows <= cols {
        return Ok(None);
    }
    let s2 = resid.col(0).iter().map(|r| r * r).sum::<f64>() / (rows - cols) as f64;
    let gram = phi.transpose() * phi;
    let inv = crate::lti::solve_square(
        gram.as_ref(),
        Mat::<f64>::identity(cols, cols).as_ref(),
        "B/D least squares: normal matrix for the D significance test",
    )?;
    let mut worst = 0.0f64;
    for k in cols - n_d..cols {
        let se = (s2 * inv[(k, k)]).sqrt();
        let t = theta[(k, 0)].abs() / se;
        if !t.is_finite() {
            return Ok(None);
        }
        worst = worst.max(t);
    }
    Ok(Some(worst))
}

/// Outcome of the singular-value rules.
struct OrderRule {
    /// Largest-gap order among n_lo..=n_svc.
    order: usize,
    /// Its gap σ_n/σ_{n+1}.
    gap: f64,
    /// SVC minimiser.
    n_svc: usize,
    reason: String,
    svc: Vec<(usize, f64)>,
}

/// Order rule (documented in the module docs): Bauer's SVC on the canonical correlations gives
/// the largest statistically supported order n_svc; the chosen order is the largest log-gap
/// σ_n/σ_{n+1} of the weighted singular values among n_lo..=n_svc. Returns (order, reason, SVC
/// values).
fn select_order(
    sv: &[f64],
    cc: &[f64],
    n_lo: usize,
    n_hi: usize,
    jcols: usize,
    m: usize,
    p: usize,
) -> OrderRule {
    let jf = jcols as f64;
    let pen = jf.ln() / jf;
    let d = |n: usize| (n * (2 * p + m)) as f64;
    let crit: Vec<(usize, f64)> = (n_lo..=n_hi)
        .map(|n| {
            let next = cc.get(n).copied().unwrap_or(0.0);
            (n, next * next + d(n) * pen)
        })
        .collect();
    let (n_svc, _) = crit
        .iter()
        .copied()
        .fold((n_lo, f64::INFINITY), |best, (n, v)| {
            if v < best.1 {
                (n, v)
            } else {
                best
            }
        });
    // Singular values below round-off level are treated as equal (no gap among them).
    let tiny = sv[0] * 1e-14;
    let gap = |n: usize| -> f64 {
        let a = sv[n - 1].max(tiny);
        let b = sv.get(n).copied().unwrap_or(0.0).max(tiny);
        a / b
    };
    // Largest gap; on a tie the smaller order.
    let best_gap =
        |hi: usize| (n_lo..=hi).fold(n_lo, |best, n| if gap(n) > gap(best) { n } else { best });
    let n = best_gap(n_svc);
    let mut reason = format!(
        "order {n}: the largest singular-value gap σ{n}/σ{} = {:.3e} among the orders \
         {n_lo}..={n_svc} supported by Bauer's SVC(n) = ρ²(n+1) + n(2p+m)·ln(J)/J on the \
         canonical correlations ρ (minimal at n = {n_svc}, J = {jcols}; range searched \
         {n_lo}..={n_hi})",
        n + 1,
        gap(n)
    );
    if n < n_svc {
        reason.push_str(&format!(
            "; σ{}..σ{n_svc} ({:.3e}..{:.3e}) are statistically supported but weaker than the \
             dominant dynamics: fix the order to {n_svc} to include them",
            n + 1,
            sv[n],
            sv[n_svc - 1]
        ));
    }
    let n_all = best_gap(n_hi);
    if n_all > n_svc {
        reason.push_str(&format!(
            "; a larger gap σ{n_all}/σ{} = {:.3e} lies beyond what SVC supports",
            n_all + 1,
            gap(n_all)
        ));
    }
    OrderRule {
        order: n,
        gap: gap(n),
        n_svc,
        reason,
        svc: crit,
    }
}

/// Kalman gain from the oblique-projection states (see the module docs); scaled units.
#[allow(clippy::too_many_arguments)]
fn kalman_gain(
    l: &Mat<f64>,
    gamma: &Mat<f64>,
    a: &Mat<f64>,
    b: &Mat<f64>,
    c: &Mat<f64>,
    d: &Mat<f64>,
    w: &[Vec<f64>],
    k: usize,
    m: usize,
    p: usize,
) -> Result<(Mat<f64>, Mat<f64>)> {
    let q = m + p;
    let (uf, wp, yf) = (k * m, k * q, k * p);
    let n = a.nrows();
    let len = w[0].len();
    let l22 = l.as_ref().submatrix(uf, uf, wp, wp);
    let l32 = l.as_ref().submatrix(uf + wp, uf, yf, wp);
    let dmax = (0..wp).map(|i| l22[(i, i)].abs()).fold(0.0, f64::max);
    let dmin = (0..wp)
        .map(|i| l22[(i, i)].abs())
        .fold(f64::INFINITY, f64::min);
    if !(dmin > 1e-8 * dmax) {
        return Err(Error::Numerical(
            "past data are rank deficient (noise-free data?)".into(),
        ));
    }
    // X = L32 L22⁻¹  ⇔  L22ᵀ Xᵀ = L32ᵀ.
    let mut xt = l32.transpose().to_owned();
    faer::linalg::triangular_solve::solve_upper_triangular_in_place(
        l22.transpose(),
        xt.as_mut(),
        faer::Par::Seq,
    );
    let proj = xt.transpose().to_owned(); // yf × wp
                                          // Γ⁺ by least squares: F = Γ⁺·proj (n × wp).
    let f = lstsq(gamma.as_ref(), proj.as_ref(), "Γ⁺")?;
    // x̂(k + s) = F·w_p(s) for s in 0..count: F split per channel times that channel's
    // Hankel view (k × count, element (j, s) = w[a][s + j]) — one GEMM per channel.
    let count = len - k + 1;
    let mut states = Mat::<f64>::zeros(n, count);
    for (a_, wa) in w.iter().enumerate() {
        let fa = Mat::from_fn(n, k, |i, j| {
            let col = if a_ < m {
                j * m + a_
            } else {
                k * m + j * p + (a_ - m)
            };
            f[(i, col)]
        });
        let hankel = MatRef::from_column_major_slice_with_stride(&wa[..count + k - 1], k, count, 1);
        faer::linalg::matmul::matmul(
            states.as_mut(),
            faer::Accum::Add,
            fa.as_ref(),
            hankel,
            1.0,
            faer::Par::Seq,
        );
    }
    // Residuals for t = k .. len−2 (x̂(t+1) needed): e = y − C x̂ − D u, ŵ = x̂⁺ − A x̂ − B u,
    // accumulated into Σŵŵᵀ, Σŵeᵀ, Σeeᵀ without storing them.
    let nres = count - 1;
    let rm = |x: &Mat<f64>| -> Vec<f64> {
        (0..x.nrows() * x.ncols())
            .map(|k| x[(k / x.ncols(), k % x.ncols())])
            .collect()
    };
    let (ar, br, cr, dr) = (rm(a), rm(b), rm(c), rm(d));
    let mut qww = Mat::<f64>::zeros(n, n);
    let mut sww = Mat::<f64>::zeros(n, p);
    let mut see = Mat::<f64>::zeros(p, p);
    let (mut qacc, mut sacc, mut racc) = (vec![0.0; n * n], vec![0.0; n * p], vec![0.0; p * p]);
    let mut e = vec![0.0; p];
    let mut wv = vec![0.0; n];
    let mut ut = vec![0.0; m];
    for s_ in 0..nres {
        let t = k + s_;
        let xs = states.col_as_slice(s_);
        let xs1 = states.col_as_slice(s_ + 1);
        for (j, v) in ut.iter_mut().enumerate() {
            *v = w[j][t];
        }
        for i in 0..p {
            e[i] =
                w[m + i][t] - dot(&cr[i * n..(i + 1) * n], xs) - dot(&dr[i * m..(i + 1) * m], &ut);
        }
        for i in 0..n {
            wv[i] = xs1[i] - dot(&ar[i * n..(i + 1) * n], xs) - dot(&br[i * m..(i + 1) * m], &ut);
        }
        for i in 0..n {
            for j in 0..n {
                qacc[i * n + j] += wv[i] * wv[j];
            }
            for j in 0..p {
                sacc[i * p + j] += wv[i] * e[j];
            }
        }
        for i in 0..p {
            for j in 0..p {
                racc[i * p + j] += e[i] * e[j];
            }
        }
    }
    for i in 0..n {
        for j in 0..n {
            qww[(i, j)] = qacc[i * n + j];
        }
        for j in 0..p {
            sww[(i, j)] = sacc[i * p + j];
        }
    }
    for i in 0..p {
        for j in 0..p {
            see[(i, j)] = racc[i * p + j];
        }
    }
    let inv = 1.0 / nres as f64;
    let q = Mat::from_fn(n, n, |i, j| qww[(i, j)] * inv);
    let s = Mat::from_fn(n, p, |i, j| sww[(i, j)] * inv);
    let r = Mat::from_fn(p, p, |i, j| see[(i, j)] * inv);
    let kf = kalman_filter_gain(a.as_ref(), c.as_ref(), q.as_ref(), s.as_ref(), r.as_ref())?;
    Ok((kf.gain, kf.innovation_cov))
}

/// Steady-state Kalman filter (innovation form) of x⁺ = Ax + w, y = Cx + v with
/// E[wwᵀ] = Q (n×n), E[wvᵀ] = S (n×p), E[vvᵀ] = R (p×p, positive definite).
#[derive(Debug, Clone)]
pub struct KalmanFilter {
    /// Stabilising solution P (n×n) of the filter Riccati equation
    /// P = APAᵀ + Q − (APCᵀ + S)(CPCᵀ + R)⁻¹(APCᵀ + S)ᵀ.
    pub p: Mat<f64>,
    /// Gain K = (APCᵀ + S)(CPCᵀ + R)⁻¹ (n×p) of the predictor x⁺ = Ax + K(y − Cx).
    pub gain: Mat<f64>,
    /// Innovation covariance CPCᵀ + R (p×p).
    pub innovation_cov: Mat<f64>,
}

/// Solves the filter DARE by the structure-preserving doubling algorithm (Chu, Fan & Lin
/// 2005) after removing the cross term (Ā = A − SR⁻¹C, Q̄ = Q − SR⁻¹Sᵀ, with Q̄'s negative
/// eigenvalues, which only estimation error produces, clipped to 0). Converges quadratically;
/// errors if R is not positive definite, if the iteration does not converge in 100 steps, or
/// if A − KC is not stable.
pub fn kalman_filter_gain(
    a: MatRef<'_, f64>,
    c: MatRef<'_, f64>,
    q: MatRef<'_, f64>,
    s: MatRef<'_, f64>,
    r: MatRef<'_, f64>,
) -> Result<KalmanFilter> {
    let n = a.nrows();
    let p = c.nrows();
    let shapes_ok = a.ncols() == n
        && c.ncols() == n
        && q.nrows() == n
        && q.ncols() == n
        && s.nrows() == n
        && s.ncols() == p
        && r.nrows() == p
        && r.ncols() == p;
    if !shapes_ok {
        return Err(Error::InvalidArgument(format!(
            "kalman_filter_gain: shapes must be A {n}x{n}, C {p}x{n}, Q {n}x{n}, S {n}x{p},              R {p}x{p}"
        )));
    }
    let sym =
        |m: &Mat<f64>| Mat::from_fn(m.nrows(), m.ncols(), |i, j| 0.5 * (m[(i, j)] + m[(j, i)]));
    let r = sym(&r.to_owned());
    let r_llt = r.llt(Side::Lower).map_err(|_| {
        Error::Numerical("measurement noise covariance R is not positive definite".into())
    })?;
    // R⁻¹C and R⁻¹Sᵀ.
    let rinv_c = r_llt.solve(c);
    let rinv_st = r_llt.solve(s.transpose());
    let abar = a - s * &rinv_c;
    let qbar = sym(&(q - s * &rinv_st));
    // Clip Q̄ to the positive semidefinite cone.
    let eig = qbar
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| Error::Numerical(format!("eigendecomposition of Q failed: {e:?}")))?;
    let (uq, sq) = (eig.U(), eig.S().column_vector());
    let qbar = Mat::from_fn(n, n, |i, j| {
        (0..n)
            .map(|k| uq[(i, k)] * sq[k].max(0.0) * uq[(j, k)])
            .sum::<f64>()
    });
    // Dual control-form data: A_k = Āᵀ, G_k = CᵀR⁻¹C, H_k = Q̄; H_k → P.
    let id = Mat::<f64>::identity(n, n);
    let mut ak = abar.transpose().to_owned();
    let mut gk = sym(&(c.transpose() * &rinv_c));
    let mut hk = qbar;
    let mut converged = false;
    for _ in 0..100 {
        let wmat = &id + &gk * &hk;
        let lu = wmat.partial_piv_lu();
        let w_a = lu.solve(&ak); // W⁻¹A_k
        let w_g = lu.solve(&gk); // W⁻¹G_k
        let a_next = &ak * &w_a;
        let g_next = sym(&(&gk + &ak * &w_g * ak.transpose()));
        let h_next = sym(&(&hk + ak.transpose() * &hk * &w_a));
        let diff = crate::lti::norm1((&h_next - &hk).as_ref());
        let scale = crate::lti::norm1(h_next.as_ref()).max(f64::MIN_POSITIVE);
        let finite = (0..n).all(|i| (0..n).all(|j| h_next[(i, j)].is_finite()));
        if !finite {
            return Err(Error::Numerical(
                "Riccati doubling iteration diverged".into(),
            ));
        }
        ak = a_next;
        gk = g_next;
        hk = h_next;
        if diff <= 1e-13 * scale {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(Error::Numerical(
            "Riccati doubling iteration did not converge (is (A, C) detectable?)".into(),
        ));
    }
    let pmat = hk;
    let re = sym(&(&(c * &pmat) * c.transpose() + &r));
    let apct_s = &(a * &pmat) * c.transpose() + s;
    // K = (APCᵀ + S) Re⁻¹  ⇔  Re Kᵀ = (APCᵀ + S)ᵀ.
    let kt = crate::lti::solve_square(re.as_ref(), apct_s.transpose(), "innovation covariance")?;
    let gain = kt.transpose().to_owned();
    let closed = a - &gain * c;
    if !eigenvalues(closed.as_ref())?.iter().all(|z| z.norm() < 1.0) {
        return Err(Error::Numerical(
            "Kalman predictor A − KC is not stable (no stabilising Riccati solution)".into(),
        ));
    }
    Ok(KalmanFilter {
        p: pmat,
        gain,
        innovation_cov: re,
    })
}
