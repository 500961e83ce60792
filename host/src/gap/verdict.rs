//! The verdict rule (effect, none or unexplained) and the statistics that separate nested
//! effects (the training likelihood ratio with an effective sample count).
use super::evidence::Evidence;
use super::fit::AugmentedModel;
use super::noise::NoiseFloor;
use crate::error::Result;

/// What the verdict rule decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// The best candidate (or combination) is the verdict.
    Effect,
    /// The linear re-fit reaches the noise floor: no unmodelled effect.
    None,
    /// A gap above the noise floor that no candidate closes.
    Unexplained,
}

/// The verdict rule (docs/gap.md, "Verdict"). With `floor` the noise-floor NRMSE on the
/// validation log and `best` the best candidate's validation NRMSE:
/// 0. a floor above [`FLOOR_CONTRADICTION`]·gap_linear is contradicted by the data: **effect**
///    when the candidate passes rule 1 with the floor taken as 0, else **unexplained**;
/// 1. **effect** when the candidate improves on the linear re-fit by at least `margin`
///    (relative) *and* removes at least `min_excess_closed` of the excess
///    gap_linear − floor (floor taken as 0 when it could not be estimated);
/// 2. else **none** when gap_linear ≤ `noise_factor`·floor;
/// 3. else, when the floor could not be estimated, **none** unless the evidence shows a
///    nonlinearity (amplitude dependence, nonlinear distortion, residual concentration);
/// 4. else **unexplained**.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VerdictRule {
    /// Relative improvement over the linear re-fit an effect needs.
    pub margin: f64,
    /// gap_linear ≤ noise_factor·floor means "at the noise floor".
    pub noise_factor: f64,
    /// Share of the excess above the floor an effect must remove.
    pub min_excess_closed: f64,
}

impl VerdictRule {
    /// Decides (see the type docs). `has_candidate`: whether `best` belongs to a fitted effect.
    pub fn decide(
        &self,
        gap_linear: f64,
        best: f64,
        has_candidate: bool,
        floor: &NoiseFloor,
        evidence: &Evidence,
    ) -> Decision {
        let f = if floor.available() { floor.nrmse } else { 0.0 };
        if floor_contradicted(gap_linear, floor) {
            // A floor above what the linear re-fit reaches describes some other noise: no
            // licence for `none`, and no share of the excess taken off.
            let effect = has_candidate
                && best.is_finite()
                && (gap_linear - best) >= self.margin * gap_linear
                && (gap_linear - best) >= self.min_excess_closed * gap_linear;
            return if effect {
                Decision::Effect
            } else {
                Decision::Unexplained
            };
        }
        if has_candidate
            && best.is_finite()
            && (gap_linear - best) >= self.margin * gap_linear
            && (gap_linear - best) >= self.min_excess_closed * (gap_linear - f)
        {
            return Decision::Effect;
        }
        if floor.available() {
            if gap_linear <= self.noise_factor * floor.nrmse {
                Decision::None
            } else {
                Decision::Unexplained
            }
        } else if evidence.nonlinear() {
            Decision::Unexplained
        } else {
            Decision::None
        }
    }

    /// A one-line reason for notes (why not an effect, why none/unexplained).
    pub fn explain(
        &self,
        gap_linear: f64,
        best: f64,
        floor: &NoiseFloor,
        d: Decision,
    ) -> Option<String> {
        let fl = floor.nrmse;
        match d {
            Decision::Effect => None,
            Decision::None if floor.available() => Some(format!(
                "verdict none: the linear re-fit ({gap_linear:.4}) is within {}x the noise floor \
                 ({fl:.4}, {})",
                self.noise_factor, floor.method
            )),
            Decision::None => Some(format!(
                "verdict none: no noise floor could be estimated (no repeating input, no \
                 off-band bins) and no evidence of a nonlinearity; the linear re-fit leaves \
                 {gap_linear:.4}"
            )),
            Decision::Unexplained if floor_contradicted(gap_linear, floor) => Some(format!(
                "verdict unexplained: the noise floor ({fl:.4}, {} of the {} log) lies above what \
                 the linear re-fit reaches ({gap_linear:.4}): it cannot describe the validation \
                 log's noise, so it licenses no `none`; the best candidate ({best:.4}) does not \
                 remove {:.0}% of the gap",
                floor.method,
                floor.source,
                100.0 * self.min_excess_closed
            )),
            Decision::Unexplained => Some(format!(
                "verdict unexplained: the linear re-fit leaves {gap_linear:.4}{}, and the best \
                 candidate ({best:.4}) does not improve on it by {:.0}% while removing {:.0}% of \
                 the excess over the floor",
                if floor.available() {
                    format!(" against a noise floor of {fl:.4}")
                } else {
                    String::new()
                },
                100.0 * self.margin,
                100.0 * self.min_excess_closed
            )),
        }
    }
}

/// A noise floor above [`FLOOR_CONTRADICTION`] times the linear re-fit's validation NRMSE
/// contradicts it (no model can do better than the noise): the floor describes other noise
/// (another log, process noise, drift) and is no licence for `none`.
pub const FLOOR_CONTRADICTION: f64 = 1.2;

/// Whether `floor` contradicts the linear re-fit's validation NRMSE `gap_linear`
/// ([`FLOOR_CONTRADICTION`]).
pub fn floor_contradicted(gap_linear: f64, floor: &NoiseFloor) -> bool {
    floor.available() && floor.nrmse > FLOOR_CONTRADICTION * gap_linear
}

/// Likelihood-ratio threshold for the nested pair (stiction over Coulomb friction) when the
/// validation log cannot separate them: the χ² quantile with one degree of freedom (the extra
/// breakaway parameter) at p = 0.001. See [`nested_likelihood_ratio`].
pub const NESTED_LR_THRESHOLD: f64 = 10.83;

/// [`NESTED_LR_THRESHOLD`] for two extra parameters (stiction with a Stribeck curve over
/// Coulomb friction: breakaway and Stribeck velocity): the χ² quantile with two degrees of
/// freedom at p = 0.001.
pub const NESTED_LR_THRESHOLD_2: f64 = 13.82;

/// Longest lag of the residual autocorrelation used by [`effective_samples`], samples.
pub const MAX_CORRELATION_LAG: usize = 2000;

/// Effective number of independent samples of a residual sequence: N/τ with the integrated
/// autocorrelation time τ = 1 + 2·Σ ρ_k, summed over Geyer's initial positive sequence (pairs
/// ρ_{2m+1} + ρ_{2m+2} while positive, at most [`MAX_CORRELATION_LAG`] lags). White residuals
/// give about N; residuals dominated by slow model error give far fewer. At least 1.
pub fn effective_samples(r: &[f64]) -> f64 {
    let n = r.len();
    if n < 4 {
        return n.max(1) as f64;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    let d: Vec<f64> = r.iter().map(|v| v - mean).collect();
    let c0: f64 = d.iter().map(|v| v * v).sum();
    if c0.is_nan() || c0 <= 0.0 {
        return 1.0;
    }
    let rho = |k: usize| d.iter().zip(&d[k..]).map(|(a, b)| a * b).sum::<f64>() / c0;
    let mut tau = 1.0;
    let mut k = 1;
    while k + 1 < n.min(MAX_CORRELATION_LAG) {
        let pair = rho(k) + rho(k + 1);
        if pair.is_nan() || pair <= 0.0 {
            break;
        }
        tau += 2.0 * pair;
        k += 2;
    }
    (n as f64 / tau).max(1.0)
}

/// Likelihood-ratio statistic of the nested model `rich` over `simple` on the training logs in
/// the metric both were fitted in: Λ = (Σ_logs N_eff) · ln(C_simple / C_rich), with
/// C = Σ_logs SSE/SST the fit's cost (Σ NRMSE², each log's squared error over its output's
/// scored sum of squares about the mean) and N_eff the [`effective_samples`] of the simple
/// model's residual on each log (Gaussian residuals with a variance proportional to the log's
/// output variance, scale unknown; the effective count keeps correlated model error from
/// passing as evidence). Under the simple model Λ is about χ² with one degree of freedom per
/// extra parameter. A per-log variance (Σ N_eff·ln(SSE_simple/SSE_rich) over the logs) would
/// test a likelihood neither model maximised: a fit that trades a little of the high-amplitude
/// log for the low one lowers the fitted cost yet scores negative there. With `drift_window` (a model with
/// an integrator) the residuals are taken drift-free ([`crate::gap::drift::detrended`]), the
/// metric the models were fitted in: a free run's drift would otherwise swamp both sums and
/// shrink N_eff to a handful of samples.
pub fn nested_likelihood_ratio(
    simple: &AugmentedModel,
    rich: &AugmentedModel,
    u: &[Vec<f64>],
    y: &[Vec<f64>],
    warmup: usize,
    drift_window: Option<usize>,
) -> Result<f64> {
    let residual = |m: &AugmentedModel, ul: &[f64], yl: &[f64]| -> Result<Vec<f64>> {
        let r: Vec<f64> = yl
            .iter()
            .zip(&m.simulate(ul)?)
            .skip(warmup)
            .map(|(a, b)| a - b)
            .collect();
        Ok(match drift_window {
            Some(w) => crate::gap::drift::detrended(&r, w),
            None => r,
        })
    };
    let mut logs = Vec::with_capacity(u.len());
    for (ul, yl) in u.iter().zip(y) {
        let scored = yl.get(warmup..).unwrap_or(&[]);
        let mean = scored.iter().sum::<f64>() / scored.len().max(1) as f64;
        let rs = residual(simple, ul, yl)?;
        let rr = residual(rich, ul, yl)?;
        logs.push(LogFit {
            n_eff: effective_samples(&rs),
            sse_simple: rs.iter().map(|v| v * v).sum(),
            sse_rich: rr.iter().map(|v| v * v).sum(),
            sst: scored.iter().map(|v| (v - mean) * (v - mean)).sum(),
        });
    }
    Ok(pooled_likelihood_ratio(&logs))
}

/// One training log's share of [`pooled_likelihood_ratio`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogFit {
    /// Effective independent samples of the simple model's residual ([`effective_samples`]).
    pub n_eff: f64,
    /// Squared error of the simple model over the scored samples.
    pub sse_simple: f64,
    /// Squared error of the rich model over the same samples.
    pub sse_rich: f64,
    /// Scored sum of squares of the output about its mean (the log's NRMSE² denominator).
    pub sst: f64,
}

/// Λ = (Σ n_eff) · ln(Σ sse_simple/sst / Σ sse_rich/sst) over the logs with sst > 0, clamped
/// at 0 (the rich model nests the simple one, so at its optimum Λ >= 0; a negative value means
/// its fit stopped short of the simple one's: no evidence) and 0 when not finite. See
/// [`nested_likelihood_ratio`].
pub fn pooled_likelihood_ratio(logs: &[LogFit]) -> f64 {
    let (mut n_eff, mut cost_simple, mut cost_rich) = (0.0, 0.0, 0.0);
    for l in logs.iter().filter(|l| l.sst > 0.0) {
        n_eff += l.n_eff;
        cost_simple += l.sse_simple / l.sst;
        cost_rich += l.sse_rich / l.sst;
    }
    let lr = if cost_simple > 0.0 && cost_rich > 0.0 {
        n_eff * (cost_simple / cost_rich).ln()
    } else {
        0.0
    };
    if lr.is_finite() {
        lr.max(0.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log(n_eff: f64, sse_simple: f64, sse_rich: f64, sst: f64) -> LogFit {
        LogFit {
            n_eff,
            sse_simple,
            sse_rich,
            sst,
        }
    }

    /// A floor above 1.2× what the linear re-fit reaches is contradicted (issue case: a
    /// training log's scatter of 0.67 against a validation gap of 0.30), one at or below it
    /// is not, and no floor contradicts nothing.
    #[test]
    fn a_floor_above_the_linear_gap_is_contradicted() {
        let floor = |nrmse: f64| NoiseFloor {
            nrmse,
            method: "periodic_scatter".into(),
            source: "training".into(),
            period_samples: None,
            periods: None,
        };
        assert!(floor_contradicted(0.30, &floor(0.67)));
        assert!(!floor_contradicted(0.30, &floor(0.30)));
        assert!(!floor_contradicted(0.30, &floor(0.35)));
        assert!(floor_contradicted(0.30, &floor(0.37)));
        assert!(!floor_contradicted(0.30, &floor(f64::NAN)));
    }

    /// One log: Λ = N_eff·ln(SSE_simple/SSE_rich) whatever the output's scale.
    #[test]
    fn one_log_is_the_gaussian_likelihood_ratio() {
        for sst in [1e-6, 1.0, 1e9] {
            let lr = pooled_likelihood_ratio(&[log(100.0, 2.0, 1.0, sst)]);
            assert!((lr - 100.0 * 2f64.ln()).abs() < 1e-12, "{lr}");
        }
    }

    /// The residual sums of issue 9's flexure/karnopp/1 case (a stiction fit that trades part
    /// of the high-amplitude log, whose output variance is ten times larger, for the low one
    /// and lowers the fitted cost Σ NRMSE²): the statistic in the fit's metric is the closed
    /// form below and well above the threshold, where the per-log sum
    /// Σ N_eff·ln(SSE_simple/SSE_rich) is negative (no evidence).
    #[test]
    fn two_logs_are_weighed_as_the_fit_weighs_them() {
        let logs = [
            log(245.9, 5.933709e3, 4.989256e3, 1e5),
            log(251.1, 6.187077e3, 8.034900e3, 1e6),
        ];
        let per_log: f64 = logs
            .iter()
            .map(|l| l.n_eff * (l.sse_simple / l.sse_rich).ln())
            .sum();
        assert!(per_log < 0.0, "{per_log}");
        let cost_simple: f64 = 5.933709e3 / 1e5 + 6.187077e3 / 1e6;
        let cost_rich = 4.989256e3 / 1e5 + 8.034900e3 / 1e6;
        let expected = (245.9 + 251.1) * (cost_simple / cost_rich).ln();
        let lr = pooled_likelihood_ratio(&logs);
        assert!(
            (lr - expected).abs() < 1e-9 * expected,
            "{lr} vs {expected}"
        );
        assert!(lr > NESTED_LR_THRESHOLD, "{lr}");
    }

    /// A rich fit worse than the simple one is no evidence (0); logs without output variance
    /// are skipped; non-finite sums give 0.
    #[test]
    fn no_evidence_is_zero() {
        assert_eq!(pooled_likelihood_ratio(&[log(50.0, 1.0, 2.0, 1.0)]), 0.0);
        assert_eq!(pooled_likelihood_ratio(&[]), 0.0);
        let skipped = pooled_likelihood_ratio(&[log(50.0, 2.0, 1.0, 1.0), log(9e9, 1.0, 9.0, 0.0)]);
        assert!((skipped - 50.0 * 2f64.ln()).abs() < 1e-12);
        assert_eq!(
            pooled_likelihood_ratio(&[log(50.0, f64::NAN, 1.0, 1.0)]),
            0.0
        );
        assert_eq!(
            pooled_likelihood_ratio(&[log(f64::INFINITY, 2.0, 1.0, 1.0)]),
            0.0
        );
    }
}
