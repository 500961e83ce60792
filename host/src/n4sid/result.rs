//! The identified model with its evidence, its serialisable summary, and the one-step-ahead
//! predictor of the innovation form.
use crate::error::{Error, Result};
use crate::lti::{StateSpace, StateSpaceData};
use faer::{Mat, MatRef};
use serde::Serialize;

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
