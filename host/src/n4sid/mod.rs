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
//!
//! # Module layout
//! One step of the algorithm per module: [`channels`] (step 1), [`hankel`] (step 2, LQ),
//! [`order`] (steps 3–5: weighted SVDs, order rules, Γ and the fit of one order),
//! [`stability`] (step 6), [`output_error`] (step 7, B/D/x0), [`kalman`] (step 8, noise
//! model); [`options`] and [`result`] hold the public types, [`linalg`] the dense helpers.
//! This file composes the steps in [`identify`]. Everything public is re-exported here, so
//! `crate::n4sid::X` paths are unchanged.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod channels;
pub mod hankel;
pub mod kalman;
pub mod linalg;
pub mod options;
pub mod order;
pub mod output_error;
pub mod result;
pub mod stability;

pub use channels::{ChannelSet, LogChannels};
pub use kalman::{kalman_filter_gain, KalmanFilter};
pub(crate) use linalg::dot;
pub use options::{Factorization, N4sidOptions, OrderSelection, Weighting, MAX_BLOCK_ROWS};
pub use output_error::estimate_x0;
pub use result::{one_step_predictor, N4sidResult, N4sidSummary};

use crate::data::Log;
use crate::error::Result;
use crate::lti::StateSpace;
use faer::Mat;
use std::path::Path;

/// Identifies a model from a [`Log`] (inputs → outputs); errors name `log.path` and the channel.
pub fn n4sid(log: &Log, opts: &N4sidOptions) -> Result<N4sidResult> {
    identify(&LogChannels::of(log).set(), opts)
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
    let data = ChannelSet {
        source: Path::new("<in-memory data>"),
        ts,
        u,
        y,
        u_names: &un,
        y_names: &yn,
    };
    identify(&data, opts)
}

/// Identifies a model from named channels (the algorithm of the module docs, steps 1–8).
/// Errors name `data.source` and the channel; options out of range are
/// [`crate::error::Error::InvalidArgument`].
pub fn identify(data: &ChannelSet<'_>, opts: &N4sidOptions) -> Result<N4sidResult> {
    let problem = channels::check_problem(data, opts)?;
    let (k, m, p, len) = (problem.k, problem.m, problem.p, problem.len);
    let mut warnings = Vec::new();

    // 1. Scaling.
    let scaled = channels::scale(data);
    let w = &scaled.w;
    let jcols = len - 2 * k + 1;

    // 2. LQ factor and persistent excitation (the input rows of L).
    let rows = hankel::row_order(k, m, p);
    let (l, fact_used) = hankel::lq_factor(w, k, &rows, opts.factorization)?;
    warnings.extend(hankel::excitation_warning(&l, k, m));

    // 3. Weighted SVDs.
    let svds = order::weighted_svds(&l, k, m, p)?;

    // 4.–7. Order and the fit of that order.
    let sv_weighted: Vec<f64> = match opts.weighting {
        Weighting::Moesp => svds.moesp.s.clone(),
        Weighting::Cva => svds.cc.clone(),
    };
    let search = order::OrderSearch {
        sub: order::Subspace {
            weighting: opts.weighting,
            moesp: &svds.moesp,
            m_svd: &svds.m_svd,
            cc_svd: &svds.cc_svd,
            rank_m: svds.rank_m,
            yf: k * p,
            p,
        },
        sv: &sv_weighted,
        cc: &svds.cc,
        lo: problem.n_lo,
        hi: problem.n_hi,
        fixed: problem.fixed,
        jcols,
    };
    let choice = order::choose_order(&search, &w[..m], &w[m..], opts)?;
    warnings.extend(choice.warning);
    let fit = choice.fit;
    let n = fit.n;
    if sv_weighted[n - 1] <= 1e-10 * sv_weighted[0] {
        warnings.push(format!(
            "order {n} exceeds the numerical rank of the projection (σ{n}/σ1 = {:.1e}): the \
             extra states are fitted to round-off",
            sv_weighted[n - 1] / sv_weighted[0]
        ));
    }
    warnings.extend(fit.notes.iter().cloned());

    // 8. Kalman gain.
    let kalman = if opts.estimate_kalman_gain {
        match kalman::innovation_model(&l, &fit, w, k, m) {
            Ok(inn) => Some(inn),
            Err(e) => {
                warnings.push(format!("Kalman gain not estimated: {e}"));
                None
            }
        }
    } else {
        None
    };

    // Unscale: B·diag(1/su), diag(sy)·C, diag(sy)·D·diag(1/su), K·diag(1/sy).
    let (su, sy) = (scaled.input_scale, scaled.output_scale);
    let b = Mat::from_fn(n, m, |i, j| fit.b[(i, j)] / su[j]);
    let c = Mat::from_fn(p, n, |i, j| fit.c[(i, j)] * sy[i]);
    let d = Mat::from_fn(p, m, |i, j| fit.d[(i, j)] * (sy[i] / su[j]));
    let model = StateSpace::new(fit.a, b, c, d, data.ts)?;
    let (kalman_gain, innovation_cov) = match kalman {
        Some(inn) => (
            Some(Mat::from_fn(n, p, |i, j| inn.gain[(i, j)] / sy[j])),
            Some(Mat::from_fn(p, p, |i, j| inn.cov[(i, j)] * sy[i] * sy[j])),
        ),
        None => (None, None),
    };
    Ok(N4sidResult {
        model,
        order: n,
        order_reason: choice.reason,
        singular_values: sv_weighted,
        canonical_correlations: svds.cc,
        order_criterion: choice.svc,
        order_bic: choice.bic,
        x0: fit.x0,
        kalman_gain,
        innovation_cov,
        stability_enforced: fit.stability_enforced,
        d_fixed_by_test: fit.d_fixed_by_test,
        warnings,
        input_scale: su,
        output_scale: sy,
        factorization_used: fact_used,
        block_rows: k,
    })
}
