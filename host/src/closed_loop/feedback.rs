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
//! does (the motor bench's two logs are flagged; docs/identification.md).
use crate::error::{Error, Result};
use crate::n4sid::linalg::dots_shifted4;
use faer::Mat;
use serde::Serialize;
use std::collections::HashMap;

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

/// Regressors whose columns are runs of a few series: column `c` is
/// `series[cols[c].0][cols[c].1..cols[c].1 + rows]` (lagged copies of the channels), never
/// materialised.
struct Shifted<'a> {
    series: Vec<&'a [f64]>,
    cols: Vec<(usize, usize)>,
    rows: usize,
}

impl Shifted<'_> {
    /// Column index of each (series, start).
    fn index(&self) -> HashMap<(usize, usize), usize> {
        self.cols.iter().enumerate().map(|(c, &k)| (k, c)).collect()
    }

    fn col(&self, c: usize) -> &[f64] {
        let (s, start) = self.cols[c];
        &self.series[s][start..start + self.rows]
    }

    /// `dot(x, col(c))` for every column c, the same sums as [`crate::n4sid::dot`] (which
    /// is symmetric to the bit: `dot(a, b) == dot(b, a)`), four at a time where four columns
    /// are consecutive windows of one series ([`dots_shifted4`]: one pass over `x`).
    fn dots_with(&self, x: &[f64], index: &HashMap<(usize, usize), usize>) -> Vec<f64> {
        let q = self.cols.len();
        let mut out = vec![f64::NAN; q];
        let mut done = vec![false; q];
        for c in 0..q {
            if done[c] {
                continue;
            }
            let (s, t) = self.cols[c];
            let group: Option<Vec<usize>> =
                (0..4).map(|j| index.get(&(s, t + j)).copied()).collect();
            match group {
                Some(g) if g.iter().all(|&c| !done[c]) => {
                    let v = dots_shifted4(x, self.series[s], t);
                    for (&cj, vj) in g.iter().zip(v) {
                        out[cj] = vj;
                        done[cj] = true;
                    }
                }
                _ => {
                    out[c] = crate::n4sid::dot(x, self.col(c));
                    done[c] = true;
                }
            }
        }
        out
    }

    /// `XᵀX` from the shift structure: with `a⁺`, `b⁺` the columns one sample later in the same
    /// series, `G[a][b] = G[a⁺][b⁺] + x_a[0]·x_b[0] − x_a[rows]·x_b[rows]` (an `O(1)` update);
    /// only the pairs without such a successor are full dot products. For the 40-column ARX
    /// predictor of a SISO log that is 79 dot products instead of 820, and no `rows × q` copy.
    fn gram(&self) -> Mat<f64> {
        let q = self.cols.len();
        let index = self.index();
        // The full products: every pair with a column that has no successor, from that
        // column's products with all columns.
        let last: HashMap<usize, Vec<f64>> = (0..q)
            .filter(|&c| !index.contains_key(&(self.cols[c].0, self.cols[c].1 + 1)))
            .map(|c| (c, self.dots_with(self.col(c), &index)))
            .collect();
        let mut pairs: Vec<(usize, usize)> =
            (0..q).flat_map(|a| (a..q).map(move |b| (a, b))).collect();
        // Successor pairs have a larger start sum: visit those first.
        pairs.sort_by_key(|&(a, b)| std::cmp::Reverse(self.cols[a].1 + self.cols[b].1));
        let mut g = Mat::zeros(q, q);
        for (a, b) in pairs {
            let ((sa, ta), (sb, tb)) = (self.cols[a], self.cols[b]);
            let next = (index.get(&(sa, ta + 1)), index.get(&(sb, tb + 1)));
            let v = match next {
                (Some(&a1), Some(&b1)) => {
                    let (xa, xb) = (self.series[sa], self.series[sb]);
                    g[(a1, b1)] + xa[ta] * xb[tb] - xa[ta + self.rows] * xb[tb + self.rows]
                }
                _ => match (last.get(&a), last.get(&b)) {
                    (Some(da), _) => da[b],
                    (None, Some(db)) => db[a],
                    (None, None) => crate::n4sid::dot(self.col(a), self.col(b)),
                },
            };
            g[(a, b)] = v;
            g[(b, a)] = v;
        }
        g
    }
}

/// Least squares of `target` on the columns of `x` (scaled to unit norm, so the normal
/// equations are well scaled): the coefficients' explained sum of squares and the residual.
/// `None` when a column is zero.
fn regress(x: &Shifted<'_>, target: &[f64]) -> Result<Option<(f64, Vec<f64>)>> {
    let q = x.cols.len();
    let gram = x.gram();
    let norms: Vec<f64> = (0..q).map(|c| gram[(c, c)].sqrt()).collect();
    if norms.iter().any(|v| !(*v > 0.0)) {
        return Ok(None);
    }
    let gram = Mat::from_fn(q, q, |a, b| gram[(a, b)] / (norms[a] * norms[b]));
    let xt = x.dots_with(target, &x.index());
    let rhs = Mat::from_fn(q, 1, |c, _| xt[c] / norms[c]);
    let beta = crate::lti::dense::solve_square(gram.as_ref(), rhs.as_ref(), "feedback test")?;
    let explained: f64 = (0..q).map(|c| beta[(c, 0)] * rhs[(c, 0)]).sum();
    let ks: Vec<f64> = (0..q).map(|c| beta[(c, 0)] / norms[c]).collect();
    let cols: Vec<&[f64]> = (0..q).map(|c| x.col(c)).collect();
    let resid = subtract_columns(target, &ks, &cols);
    Ok(Some((explained, resid)))
}

/// `target − Σ_c k_c·x_c` with the columns subtracted in order `c = 0..q` from each element, as
/// one pass per column would do it (the same bits), but in blocks of rows that stay in the L1
/// cache: one pass over the data instead of q. Columns shorter than `target` leave the rest
/// of it unchanged.
fn subtract_columns(target: &[f64], ks: &[f64], cols: &[&[f64]]) -> Vec<f64> {
    crate::n4sid::linalg::with_avx(
        #[inline(always)]
        || subtract_columns_body(target, ks, cols),
    )
}

/// [`subtract_columns`]' loop (compiled for AVX2 and for the baseline: the same bits).
#[inline(always)]
fn subtract_columns_body(target: &[f64], ks: &[f64], cols: &[&[f64]]) -> Vec<f64> {
    const BLOCK: usize = 512;
    let mut resid = target.to_vec();
    for (b, rb) in resid.chunks_mut(BLOCK).enumerate() {
        let at = b * BLOCK;
        for (&k, col) in ks.iter().zip(cols) {
            if let Some(cb) = col.get(at..(at + rb.len()).min(col.len())) {
                rb.iter_mut().zip(cb).for_each(|(r, v)| *r -= k * v);
            }
        }
    }
    resid
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
    // Series 0..p are the outputs, p..p+m the inputs. ARX column (ch, lag) starts at na − lag;
    // future-input column (j, τ) at na + τ (rows t = na..len − max_lag).
    let series: Vec<&[f64]> = yc.iter().chain(&uc).map(Vec::as_slice).collect();
    let arx = Shifted {
        series: series.clone(),
        cols: (0..q_arx).map(|c| (c / na, na - (c % na + 1))).collect(),
        rows,
    };
    let q = m * max_lag;
    let future = Shifted {
        series,
        cols: (0..q)
            .map(|c| (p + c / max_lag, na + 1 + c % max_lag))
            .collect(),
        rows,
    };
    let alpha = FEEDBACK_SIGNIFICANCE;
    let threshold = chi_square_quantile(1.0 - alpha / p as f64, q);
    let constant = || Error::Numerical("feedback test: a channel is constant".into());
    let mut outputs = Vec::with_capacity(p);
    for yi in &yc {
        let (_, e) = regress(&arx, &yi[na..na + rows])?.ok_or_else(constant)?;
        let total: f64 = e.iter().map(|v| v * v).sum();
        if !(total > 0.0) {
            return Err(Error::Numerical(
                "feedback test: the ARX residual is identically zero".into(),
            ));
        }
        let (explained, _) = regress(&future, &e)?.ok_or_else(constant)?;
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

    /// The blocked residual equals one pass per column, to the bit (1,000 rows: two full
    /// blocks and a partial one).
    #[test]
    fn blocked_residual_equals_column_passes() {
        let rows = 1000;
        let series: Vec<f64> = (0..rows + 30)
            .map(|i| ((i * 7919) % 1009) as f64 / 1009.0 - 0.5)
            .collect();
        let target: Vec<f64> = (0..rows).map(|i| (i as f64 * 0.37).sin()).collect();
        let cols: Vec<&[f64]> = (0..25).map(|c| &series[c..c + rows]).collect();
        let ks: Vec<f64> = (0..25).map(|c| 0.1 * c as f64 - 1.3).collect();
        let mut want = target.clone();
        for (k, col) in ks.iter().zip(&cols) {
            want.iter_mut().zip(*col).for_each(|(r, v)| *r -= k * v);
        }
        let got = subtract_columns(&target, &ks, &cols);
        assert_eq!(got.len(), rows);
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(g.to_bits(), w.to_bits(), "row {i}");
        }
    }

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

    /// The shift-structured Gram matrix equals the one from direct dot products (to 1e-12
    /// relative), for lagged (ARX) and leading (future-input) columns of two series.
    #[test]
    fn shifted_gram_equals_direct_products() {
        let mut uniform = crate::n4sid::linalg::test_uniform(7);
        let mut next = || uniform() - 0.3;
        let a: Vec<f64> = (0..5_000).map(|_| next()).collect();
        let b: Vec<f64> = (0..5_000).map(|_| 3.0 * next()).collect();
        let (na, lags, rows) = (6, 5, 5_000 - 6 - 5);
        let mut cols: Vec<(usize, usize)> =
            (0..2 * na).map(|c| (c / na, na - (c % na + 1))).collect();
        cols.extend((0..lags).map(|c| (1, na + 1 + c)));
        let x = Shifted {
            series: vec![&a, &b],
            cols,
            rows,
        };
        let g = x.gram();
        let q = x.cols.len();
        // The grouped products equal one dot product per column to the bit.
        let target: Vec<f64> = (0..rows).map(|i| (i as f64 * 0.01).cos()).collect();
        let grouped = x.dots_with(&target, &x.index());
        for (c, v) in grouped.iter().enumerate() {
            let want = crate::n4sid::dot(x.col(c), &target);
            assert_eq!(v.to_bits(), want.to_bits(), "column {c}");
        }
        for i in 0..q {
            for j in 0..q {
                let direct: f64 = x.col(i).iter().zip(x.col(j)).map(|(u, v)| u * v).sum();
                let scale = (g[(i, i)] * g[(j, j)]).sqrt();
                assert!(
                    (g[(i, j)] - direct).abs() <= 1e-12 * scale,
                    "G[{i}][{j}] = {} vs direct {direct}",
                    g[(i, j)]
                );
            }
        }
    }
}
