//! The error of an integrating model's free run with its drift left out (see
//! [`nrmse_drift_free`]): the validation NRMSE and the training cost of the diagnosis when the
//! sim has an integrator.
use super::modal::nrmse;

/// [`nrmse`] with the drift of a free run left out, for models with an integrator (a position
/// output): the error minus its local linear trend (the least-squares line over a centred
/// window of `window` samples, shortened at the ends; in the interior this is the moving
/// average), over samples `warmup..`, divided by RMS(y − mean y) as in [`nrmse`]. A free run of
/// an integrating model carries every velocity error below the excited band into a position
/// offset that never decays (the integrator's unknown start, a constant velocity bias, the sum
/// of the small position errors of each stick); over a long log that drift dominates the plain
/// NRMSE whatever the model does in the excited band. With `window` of at least the warm-up
/// (five time constants of the slowest stable pole) the trend holds only content well below
/// the band the log excites, and white measurement noise keeps its NRMSE (less about
/// 1/`window`). `window` < 3: [`nrmse`].
pub fn nrmse_drift_free(y: &[f64], yhat: &[f64], warmup: usize, window: usize) -> f64 {
    let n = y.len().min(yhat.len());
    if window < 3 || n <= warmup {
        return nrmse(y, yhat, warmup);
    }
    let s = &y[warmup..n];
    let mean = s.iter().sum::<f64>() / s.len() as f64;
    let den: f64 = s.iter().map(|v| (v - mean).powi(2)).sum();
    let r: Vec<f64> = s.iter().zip(&yhat[warmup..n]).map(|(a, b)| a - b).collect();
    let num: f64 = detrended(&r, window).iter().map(|v| v * v).sum();
    (num / den).sqrt()
}

/// `r` minus its local linear trend: at each sample the least-squares line over the centred
/// window of `window` samples (shortened at the ends) evaluated there (see
/// [`nrmse_drift_free`]); `r` itself when `window` < 3.
pub fn detrended(r: &[f64], window: usize) -> Vec<f64> {
    if window < 3 {
        return r.to_vec();
    }
    // Prefix sums of r_j and j·r_j; sums of j and j² in closed form.
    let mut p0 = vec![0.0; r.len() + 1];
    let mut p1 = vec![0.0; r.len() + 1];
    for (j, v) in r.iter().enumerate() {
        p0[j + 1] = p0[j] + v;
        p1[j + 1] = p1[j] + j as f64 * v;
    }
    let s2 = |x: f64| x * (x + 1.0) * (2.0 * x + 1.0) / 6.0;
    let half = window / 2;
    (0..r.len())
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(r.len()));
            let (m, kf) = ((b - a) as f64, k as f64);
            let (af, bf) = (a as f64, b as f64);
            let sum_j = (af + bf - 1.0) * m / 2.0;
            let sum_jj = s2(bf - 1.0) - if a > 0 { s2(af - 1.0) } else { 0.0 };
            // Offsets d = j − k: Σd, Σd², Σr, Σd·r.
            let sd = sum_j - kf * m;
            let sdd = sum_jj - 2.0 * kf * sum_j + kf * kf * m;
            let sr = p0[b] - p0[a];
            let sdr = (p1[b] - p1[a]) - kf * sr;
            let det = m * sdd - sd * sd;
            let trend = if det > 0.0 {
                (sdd * sr - sd * sdr) / det
            } else {
                sr / m
            };
            r[k] - trend
        })
        .collect()
}

/// Σ over samples `warmup..` of the squared error y − ŷ, detrended over `drift_window` samples
/// when given ([`detrended`]): the training cost of one log in the metric of
/// [`validation_nrmse`].
pub fn scored_sse(y: &[f64], yhat: &[f64], warmup: usize, drift_window: Option<usize>) -> f64 {
    let r = y.iter().zip(yhat).skip(warmup).map(|(a, b)| a - b);
    match drift_window {
        Some(w) => detrended(&r.collect::<Vec<_>>(), w)
            .iter()
            .map(|v| v * v)
            .sum(),
        None => r.map(|v| v * v).sum(),
    }
}

/// The validation NRMSE of the diagnosis: [`nrmse_drift_free`] over `drift_window` samples
/// when given (models with an integrator), else [`nrmse`].
pub fn validation_nrmse(
    y: &[f64],
    yhat: &[f64],
    warmup: usize,
    drift_window: Option<usize>,
) -> f64 {
    match drift_window {
        Some(w) => nrmse_drift_free(y, yhat, warmup, w),
        None => nrmse(y, yhat, warmup),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::gap::simulator::uniform_noise;

    /// A position output y = sin at 5 Hz (1 kHz) against a model that adds drift (a ramp, a
    /// 0.02 Hz sine, a random walk) plus an in-band error of amplitude 0.01 at 20 Hz: the
    /// drift-free NRMSE keeps the in-band error (0.01 relative to RMS(y), within 3 %: the
    /// moving average's side lobe at 20 Hz takes 1.7 %) and drops the drift (the plain NRMSE
    /// is above 1); on a zero error it is zero, and window < 3 is the plain one.
    #[test]
    fn drift_free_nrmse_keeps_the_band_and_drops_the_drift() {
        let n = 16384;
        let ts = 1e-3;
        let tau = std::f64::consts::TAU;
        let y: Vec<f64> = (0..n).map(|k| (tau * 5.0 * k as f64 * ts).sin()).collect();
        let mut walk = 0.0;
        let steps = uniform_noise(n, 9);
        let yhat: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 * ts;
                walk += 2e-4 * steps[k];
                let slow = 0.3 * t + (tau * 0.02 * t).sin() + walk;
                y[k] + slow + 0.01 * (tau * 20.0 * t).sin()
            })
            .collect();
        let plain = nrmse(&y, &yhat, 500);
        let free = nrmse_drift_free(&y, &yhat, 500, 833);
        let expected = 0.01 / std::f64::consts::SQRT_2 / (0.5f64).sqrt();
        assert!(plain > 1.0, "plain {plain}");
        assert!(
            (free - expected).abs() < 0.03 * expected,
            "{free} vs {expected}"
        );
        assert_eq!(nrmse_drift_free(&y, &y, 500, 833), 0.0);
        assert_eq!(nrmse_drift_free(&y, &yhat, 500, 2), plain);
        assert_eq!(validation_nrmse(&y, &yhat, 500, None), plain);
    }
}
