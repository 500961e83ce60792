//! Feedback detector: does the input depend on past output noise?
//!
//! In open loop the innovations ε(t) of the data are independent of the input at every lag.
//! Under feedback the controller turns ε(t) into later inputs, so ε(t) is correlated with
//! u(t+1), …, u(t+M) (Ljung 1999, §16.6). The innovations are taken from a long ARX predictor
//! of the data itself, y(t) on y(t−1..t−[`ARX_ORDER`]) and u(t−1..t−[`ARX_ORDER`]) by least
//! squares — not from the identified model, whose bias under feedback absorbs part of the very
//! correlation the test looks for (a high-order ARX is consistent in closed loop, its residual
//! approaches the true innovation). The test regresses each output's ARX residual on the
//! future inputs u_j(t+τ), τ = 1..=M, j = 1..=m (mean-removed) and uses the Lagrange-multiplier
//! statistic N·R², which is χ²(m·M) when ε is white and independent of future inputs —
//! whatever the input's colour, because the regression accounts for the correlation between
//! lags. The threshold is the χ² quantile at 1 − α/p (Bonferroni over the p outputs;
//! Wilson–Hilferty approximation, relative error < 1 % for m·M ≥ 3), with
//! α = [`FEEDBACK_SIGNIFICANCE`].
//!
//! Assumptions: no direct feedthrough from u(t) to y(t) at the sample (true of a ZOH-sampled
//! physical plant; a plant with feedthrough driven by a coloured input can be flagged wrongly),
//! and a linear plant: an unmodelled nonlinearity under a periodic input leaves a periodic
//! function of the input in the ARX residual, which correlates with future inputs as feedback
//! does (the motor bench's two logs are flagged; README).
use crate::error::{Error, Result};
use faer::{ColRef, Mat};
use serde::Serialize;

/// Significance level α of the feedback test (probability of flagging an open-loop log).
pub const FEEDBACK_SIGNIFICANCE: f64 = 0.01;

/// Lags of y and of each u in the ARX predictor whose residual stands for the innovations.
pub const ARX_ORDER: usize = 20;

/// The test on one output channel.
#[derive(Debug, Clone, Serialize)]
pub struct FeedbackStatistic {
    /// N·R² of the innovation regressed on the future inputs.
    pub statistic: f64,
    /// Degrees of freedom m·M.
    pub dof: usize,
    /// χ² quantile at 1 − α/p.
    pub threshold: f64,
    /// `statistic > threshold`.
    pub detected: bool,
}

/// Result of [`feedback_test`].
#[derive(Debug, Clone, Serialize)]
pub struct FeedbackTest {
    /// Residual used: the ARX predictor's, with its order (lags of y and of each u).
    pub arx_order: usize,
    /// Future input lags 1..=M regressed on.
    pub max_lag: usize,
    /// Significance level α (over all outputs together).
    pub significance: f64,
    /// Samples used in each regression (N − M).
    pub n_samples: usize,
    /// One entry per output channel.
    pub outputs: Vec<FeedbackStatistic>,
    /// True when any output's statistic exceeds its threshold: the input depends on past
    /// output noise (the log was recorded in closed loop), open-loop estimates are biased.
    pub detected: bool,
}

/// Upper quantile of χ²(k) at probability `q` (Wilson–Hilferty).
pub fn chi_square_quantile(q: f64, k: usize) -> f64 {
    let z = crate::greybox::normal_quantile_two_sided(2.0 * q - 1.0);
    let k = k as f64;
    let h = 2.0 / (9.0 * k);
    k * (1.0 - h + z * h.sqrt()).powi(3)
}

/// Least squares of `target` on the columns of `x` (`rows × q`, scaled here to unit norm, so the
/// normal equations are well scaled): the coefficients' explained sum of squares and the
/// residual. `None` when a column is zero. The normal equations are formed by one matrix
/// product (faer's blocked GEMM): `O(rows·q²)` flops, 0.16 G for the 100k-sample, 40-regressor
/// ARX predictor.
fn regress(mut x: Mat<f64>, target: &[f64]) -> Result<Option<(f64, Vec<f64>)>> {
    let q = x.ncols();
    let mut norms = Vec::with_capacity(q);
    for c in 0..q {
        let norm = x.col(c).norm_l2();
        if !(norm > 0.0) {
            return Ok(None);
        }
        x.col_mut(c).iter_mut().for_each(|v| *v /= norm);
        norms.push(norm);
    }
    let t = ColRef::from_slice(target);
    let gram = x.transpose() * &x;
    let rhs = x.transpose() * t;
    let rhs = Mat::from_fn(q, 1, |c, _| rhs[c]);
    let beta = crate::lti::dense::solve_square(gram.as_ref(), rhs.as_ref(), "feedback test")?;
    let explained: f64 = (0..q).map(|c| beta[(c, 0)] * rhs[(c, 0)]).sum();
    let fitted = &x * beta.col(0);
    let resid = target
        .iter()
        .zip(fitted.iter())
        .map(|(t, f)| t - f)
        .collect();
    Ok(Some((explained, resid)))
}

/// The `rows × q` matrix whose column `c` is the first `rows` samples of `run(c)`.
fn lagged<'a>(rows: usize, q: usize, run: impl Fn(usize) -> &'a [f64]) -> Mat<f64> {
    let mut x = Mat::zeros(rows, q);
    for c in 0..q {
        let src = &run(c)[..rows];
        x.col_mut(c).iter_mut().zip(src).for_each(|(d, s)| *d = *s);
    }
    x
}

/// Tests whether the inputs `u` depend on past output noise in the data `u`, `y` (equal-length
/// channels), with future lags 1..=`max_lag` (1..=N/10).
///
/// # Errors
/// [`Error::InvalidArgument`] for no channel, unequal lengths, or a lag out of range (or a log
/// shorter than 10·([`ARX_ORDER`]·(m+p) + M) samples); [`Error::Numerical`] for a constant
/// channel or collinear regressors.
pub fn feedback_test<U: AsRef<[f64]>, Y: AsRef<[f64]>>(
    u: &[U],
    y: &[Y],
    max_lag: usize,
) -> Result<FeedbackTest> {
    let len = y.first().map_or(0, |c| c.as_ref().len());
    if u.is_empty() || y.is_empty() {
        return Err(Error::InvalidArgument(
            "feedback test needs at least one input and one output".into(),
        ));
    }
    if u.iter()
        .map(|c| c.as_ref().len())
        .chain(y.iter().map(|c| c.as_ref().len()))
        .any(|l| l != len)
    {
        return Err(Error::InvalidArgument(
            "feedback test: channels of unequal length".into(),
        ));
    }
    let uc: Vec<Vec<f64>> = u
        .iter()
        .map(|c| crate::validate::demeaned(c.as_ref()))
        .collect();
    let yc: Vec<Vec<f64>> = y
        .iter()
        .map(|c| crate::validate::demeaned(c.as_ref()))
        .collect();
    let (m, p) = (uc.len(), yc.len());
    let na = ARX_ORDER;
    let q_arx = na * (m + p);
    if max_lag == 0 || len < 10 * (q_arx + max_lag) || max_lag > len / 10 {
        return Err(Error::InvalidArgument(format!(
            "feedback test: {len} samples are too few for {max_lag} future lags and an ARX \
             predictor with {q_arx} regressors (need 10x their sum, and 1 <= lag <= N/10)"
        )));
    }
    // Rows t = na..len−max_lag: the ARX needs na past samples, the test max_lag future ones.
    let rows = len - na - max_lag;
    // Column c of either regressor is a contiguous run of one channel: (channel, first sample).
    let arx_cols = || {
        lagged(rows, q_arx, |c| {
            let (ch, lag) = (c / na, c % na + 1);
            let series = if ch < p { &yc[ch] } else { &uc[ch - p] };
            &series[na - lag..]
        })
    };
    let q = m * max_lag;
    let fut_cols = || lagged(rows, q, |c| &uc[c / max_lag][na + 1 + c % max_lag..]);
    let alpha = FEEDBACK_SIGNIFICANCE;
    let threshold = chi_square_quantile(1.0 - alpha / p as f64, q);
    let constant = || Error::Numerical("feedback test: a channel is constant".into());
    let mut outputs = Vec::with_capacity(p);
    for yi in &yc {
        let (_, e) = regress(arx_cols(), &yi[na..na + rows])?.ok_or_else(constant)?;
        let total: f64 = e.iter().map(|v| v * v).sum();
        if !(total > 0.0) {
            return Err(Error::Numerical(
                "feedback test: the ARX residual is identically zero".into(),
            ));
        }
        let (explained, _) = regress(fut_cols(), &e)?.ok_or_else(constant)?;
        let statistic = rows as f64 * explained / total;
        outputs.push(FeedbackStatistic {
            statistic,
            dof: q,
            threshold,
            detected: statistic > threshold,
        });
    }
    Ok(FeedbackTest {
        arx_order: na,
        max_lag,
        significance: alpha,
        n_samples: rows,
        detected: outputs.iter().any(|o| o.detected),
        outputs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against tabulated χ² quantiles (Abramowitz & Stegun, table 26.8), within 1 %.
    #[test]
    fn chi_square_quantiles() {
        for (q, k, want) in [
            (0.99, 10, 23.209),
            (0.99, 25, 44.314),
            (0.95, 5, 11.070),
            (0.995, 50, 79.490),
        ] {
            let got = chi_square_quantile(q, k);
            assert!((got / want - 1.0).abs() < 0.01, "{q} {k}: {got} vs {want}");
        }
    }
}
