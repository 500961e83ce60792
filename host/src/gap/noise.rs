//! The noise floor: the NRMSE a perfect model would still leave on the validation log, estimated
//! from the data alone, so a verdict of `none` can be tied to "the linear re-fit reaches the
//! noise" (see [`crate::gap::diagnose`]).
//!
//! Methods, tried in this order, on the validation log first (the floor must describe the log
//! whose error it judges: a training log with heavy process noise says nothing of it) and on the
//! training logs only when the validation log gives none:
//! 1. **`periodic_scatter`** — when the input repeats exactly (a multisine played for several
//!    periods, detected by [`detect_period`]), the output of any time-invariant plant (linear or
//!    not) repeats too once the transient has died out, so what changes from period to period
//!    is noise: σ² from the differences of consecutive whole periods after the warm-up (rounded
//!    up to whole periods, at least one period skipped when three or more exist), each pair's
//!    mean removed (drift) and spikes left out ([`periodic_scatter`]).
//! 2. **`off_band_residual`** — else the residual of the linear re-fit on the validation log
//!    where the input has no power: Welch PSD of the residual on the bins whose input PSD is at
//!    most [`OFF_BAND_REL`] of its peak (DC excluded; at least [`MIN_OFF_BAND_BINS`] bins and
//!    5 % of all bins), σ² = median density there × fs/2 (white noise; the median keeps the
//!    harmonics a nonlinearity puts off the band from inflating it).
//! 3. **`unavailable`** — neither applies (broadband excitation without repetition): `nrmse`
//!    is NaN (null in JSON) and the verdict rule says so.
//!
//! The floor is σ over the standard deviation of the validation output after the warm-up (the
//! NRMSE's denominator), so it is on the same scale as `gap_linear`.
use super::locate::default_nperseg;
use crate::error::Result;
use crate::spectral::Welch;
use realfft::RealFftPlanner;
use serde::Serialize;

/// Shortest period [`detect_period`] considers, samples.
pub const MIN_PERIOD: usize = 16;

/// Relative RMS of the period-to-period difference of the input, RMS(u[k+P] − u[k]) /
/// RMS(u − mean u), below which the input counts as repeating with period P (a measured force
/// on a shaker repeats to a few per cent, a commanded signal exactly).
pub const REPEAT_TOL: f64 = 0.1;

/// Input PSD at most this fraction of its peak (−40 dB) marks an off-band bin.
pub const OFF_BAND_REL: f64 = 1e-4;

/// Fewest off-band bins the `off_band_residual` method needs.
pub const MIN_OFF_BAND_BINS: usize = 8;

/// The estimated noise floor (see the module docs).
#[derive(Debug, Clone, Serialize)]
pub struct NoiseFloor {
    /// NRMSE of the noise alone on the validation log (NaN → null when unavailable).
    pub nrmse: f64,
    /// `periodic_scatter`, `off_band_residual` or `unavailable`.
    pub method: String,
    /// Which log(s) it came from (`validation` or `training`).
    pub source: String,
    /// Period of the excitation, samples (periodic_scatter only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub period_samples: Option<usize>,
    /// Periods whose scatter was used (periodic_scatter only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub periods: Option<usize>,
}

impl NoiseFloor {
    /// Whether a floor was estimated.
    pub fn available(&self) -> bool {
        self.nrmse.is_finite()
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn variance(v: &[f64]) -> f64 {
    let m = mean(v);
    v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len().max(1) as f64
}

/// The period of `u` in samples when it repeats (see [`REPEAT_TOL`]) at least twice: the
/// smallest lag in [`MIN_PERIOD`]..=N/2 that is a local maximum of the (unbiased, FFT-computed)
/// autocorrelation and whose period-to-period difference passes the tolerance. `None` for a
/// constant or non-repeating input. Cost O(N log N).
pub fn detect_period(u: &[f64]) -> Option<usize> {
    let n = u.len();
    if n < 2 * MIN_PERIOD {
        return None;
    }
    let m = mean(u);
    let x: Vec<f64> = u.iter().map(|v| v - m).collect();
    let var = variance(u);
    if var.is_nan() || var <= 0.0 {
        return None;
    }
    let nfft = (2 * n).next_power_of_two();
    let mut planner = RealFftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(nfft);
    let inv = planner.plan_fft_inverse(nfft);
    let mut buf = fwd.make_input_vec();
    buf[..n].copy_from_slice(&x);
    let mut spec = fwd.make_output_vec();
    fwd.process(&mut buf, &mut spec).ok()?;
    for c in spec.iter_mut() {
        *c = num_complex::Complex64::new(c.norm_sqr(), 0.0);
    }
    let mut acf = inv.make_output_vec();
    inv.process(&mut spec, &mut acf).ok()?;
    let r0 = acf[0];
    if r0.is_nan() || r0 <= 0.0 {
        return None;
    }
    // Unbiased normalised autocorrelation.
    let rho = |t: usize| acf[t] / r0 * n as f64 / (n - t) as f64;
    // The difference test: RMS(u[k+P]-u[k])^2 / var ≈ 2(1 − ρ(P)) ≤ tol² ⇒ ρ ≥ 1 − tol²/2.
    let rho_min = 1.0 - 0.5 * REPEAT_TOL * REPEAT_TOL;
    for t in MIN_PERIOD..=n / 2 {
        let r = rho(t);
        if r >= rho_min && r >= rho(t - 1) && r >= rho(t + 1) {
            // Confirm in the time domain.
            let d2 = x[t..]
                .iter()
                .zip(&x)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                / (n - t) as f64;
            if d2 <= REPEAT_TOL * REPEAT_TOL * var {
                return Some(t);
            }
        }
    }
    None
}

/// The whole periods of length `p` a log of `len` samples averages over after `warmup`:
/// (periods skipped — the warm-up's, and at least the first when three or more fit —, periods
/// used), `None` when fewer than two remain.
pub fn whole_periods(len: usize, p: usize, warmup: usize) -> Option<(usize, usize)> {
    let total = len / p;
    let mut skip = warmup.div_ceil(p);
    if total >= 3 {
        skip = skip.max(1);
    }
    let m = total.checked_sub(skip)?;
    (m >= 2).then_some((skip, m))
}

/// Period-to-period scatter of `y` with period `p` after `warmup` samples: (σ², periods used),
/// `None` when fewer than two whole periods remain.
///
/// Read from the differences of consecutive periods, e_q[k] = y_{q+1}[k] − y_q[k] (variance 2σ²
/// for noise of variance σ²), each pair's own mean removed: a drift that moves the output by a
/// near-constant amount per period (a position output creeping) leaves no trace. Differences
/// beyond [`SCATTER_CLIP`] robust standard deviations (1.4826·MAD) are left out, so sensor spikes
/// do not set the floor; with no spread in the median (a coarse lattice) every difference counts.
pub fn periodic_scatter(y: &[f64], p: usize, warmup: usize) -> Option<(f64, usize)> {
    let (skip, m) = whole_periods(y.len(), p, warmup)?;
    let seg = &y[skip * p..(skip + m) * p];
    let mut diffs: Vec<f64> = Vec::with_capacity((m - 1) * p);
    for q in 0..m - 1 {
        let e: Vec<f64> = seg[(q + 1) * p..(q + 2) * p]
            .iter()
            .zip(&seg[q * p..(q + 1) * p])
            .map(|(b, a)| b - a)
            .collect();
        let mean = e.iter().sum::<f64>() / p as f64;
        diffs.extend(e.iter().map(|v| v - mean));
    }
    let mut abs: Vec<f64> = diffs.iter().map(|v| v.abs()).collect();
    let mid = abs.len() / 2;
    let mad = *abs.select_nth_unstable_by(mid, f64::total_cmp).1;
    let cut = if mad > 0.0 {
        SCATTER_CLIP * 1.4826 * mad
    } else {
        f64::INFINITY
    };
    let kept: Vec<f64> = diffs.into_iter().filter(|v| v.abs() <= cut).collect();
    // Degrees of freedom: one mean per period pair.
    let dof = kept.len().saturating_sub(m - 1).max(1);
    let ss: f64 = kept.iter().map(|v| v * v).sum();
    Some((ss / (2.0 * dof as f64), m))
}

/// Differences of consecutive periods beyond this many robust standard deviations are left out
/// of [`periodic_scatter`] (a Gaussian difference passes with probability 1 − 6e-7).
pub const SCATTER_CLIP: f64 = 5.0;

/// Off-band noise variance of the residual `r` of a model driven by `u` (see the module docs),
/// `None` when the input leaves too few bins without power.
pub fn off_band_variance(u: &[f64], r: &[f64], fs: f64) -> Result<Option<f64>> {
    let n = u.len().min(r.len());
    let nperseg = default_nperseg(n).min(n);
    if nperseg < 64 {
        return Ok(None);
    }
    let w = Welch::new(nperseg);
    let su = w.psd(&u[..n], fs)?;
    let sr = w.psd(&r[..n], fs)?;
    let top = su.density.iter().cloned().fold(0.0, f64::max);
    if top.is_nan() || top <= 0.0 {
        return Ok(None);
    }
    let mut off: Vec<f64> = (1..su.density.len())
        .filter(|&k| su.density[k] <= OFF_BAND_REL * top)
        .map(|k| sr.density[k])
        .filter(|v| v.is_finite())
        .collect();
    if off.len() < MIN_OFF_BAND_BINS.max(su.density.len() / 20) {
        return Ok(None);
    }
    off.sort_by(f64::total_cmp);
    let med = off[off.len() / 2];
    Ok(Some(med * fs / 2.0))
}

/// The noise floor on the validation log (module docs). `val` is the validation (u, y),
/// `val_resid` the linear re-fit's residual there; `train` and `train_resid` likewise for the
/// training logs; `warmup` samples are left out everywhere.
pub fn noise_floor(
    val: (&[f64], &[f64]),
    val_resid: &[f64],
    train: &[(&[f64], &[f64])],
    train_resid: &[&[f64]],
    warmup: usize,
    fs: f64,
) -> Result<NoiseFloor> {
    let y_var = variance(&val.1[warmup.min(val.1.len())..]);
    let floor = |sigma2: f64| (sigma2 / y_var).sqrt();
    // 1. Periodic scatter: validation, then the training logs pooled.
    if let Some(p) = detect_period(val.0) {
        if let Some((s2, m)) = periodic_scatter(val.1, p, warmup) {
            return Ok(NoiseFloor {
                nrmse: floor(s2),
                method: "periodic_scatter".into(),
                source: "validation".into(),
                period_samples: Some(p),
                periods: Some(m),
            });
        }
    }
    // 2. Off-band residual of the validation log: the floor of the log the verdict judges comes
    // before any training log's.
    let w = warmup.min(val.0.len());
    if let Some(s2) = off_band_variance(&val.0[w..], &val_resid[w..], fs)? {
        return Ok(NoiseFloor {
            nrmse: floor(s2),
            method: "off_band_residual".into(),
            source: "validation".into(),
            period_samples: None,
            periods: None,
        });
    }
    // 3. Training logs (their noise taken as the validation's): periodic scatter pooled, then
    // the off-band residual pooled.
    let mut pooled: Vec<(f64, usize, usize)> = Vec::new();
    for (u, y) in train {
        if let Some(p) = detect_period(u) {
            if let Some((s2, m)) = periodic_scatter(y, p, warmup) {
                pooled.push((s2, m, p));
            }
        }
    }
    if !pooled.is_empty() {
        let s2 = pooled.iter().map(|v| v.0).sum::<f64>() / pooled.len() as f64;
        return Ok(NoiseFloor {
            nrmse: floor(s2),
            method: "periodic_scatter".into(),
            source: "training".into(),
            period_samples: Some(pooled[0].2),
            periods: Some(pooled.iter().map(|v| v.1).sum()),
        });
    }
    let mut v = Vec::new();
    for ((u, _), r) in train.iter().zip(train_resid) {
        let w = warmup.min(u.len());
        if let Some(s2) = off_band_variance(&u[w..], &r[w..], fs)? {
            v.push(s2);
        }
    }
    if !v.is_empty() {
        return Ok(NoiseFloor {
            nrmse: floor(v.iter().sum::<f64>() / v.len() as f64),
            method: "off_band_residual".into(),
            source: "training".into(),
            period_samples: None,
            periods: None,
        });
    }
    Ok(NoiseFloor {
        nrmse: f64::NAN,
        method: "unavailable".into(),
        source: "none".into(),
        period_samples: None,
        periods: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::simulator::rng::Rng;

    fn multisine_period(p: usize, rng: &mut Rng) -> Vec<f64> {
        let mut v = vec![0.0; p];
        for k in 1..p / 8 {
            let ph = 2.0 * std::f64::consts::PI * rng.uniform();
            for (i, x) in v.iter_mut().enumerate() {
                *x += (2.0 * std::f64::consts::PI * (k * i) as f64 / p as f64 + ph).cos();
            }
        }
        v
    }

    #[test]
    fn detects_the_period_of_a_repeated_signal_and_not_of_noise() {
        let mut rng = Rng::new(3);
        let one = multisine_period(500, &mut rng);
        let u: Vec<f64> = (0..5).flat_map(|_| one.clone()).collect();
        assert_eq!(detect_period(&u), Some(500));
        let noise: Vec<f64> = (0..2500).map(|_| rng.normal()).collect();
        assert_eq!(detect_period(&noise), None);
        // A smooth (heavily oversampled) non-repeating signal: high autocorrelation at small lags
        // must not pass as a period.
        let mut s = 0.0;
        let smooth: Vec<f64> = (0..4000)
            .map(|_| {
                s = 0.999 * s + rng.normal();
                s
            })
            .collect();
        assert_eq!(detect_period(&smooth), None);
        assert_eq!(detect_period(&vec![1.0; 1000]), None);
    }

    #[test]
    fn periodic_scatter_recovers_the_noise_variance() {
        let mut rng = Rng::new(9);
        let one = multisine_period(400, &mut rng);
        let n = 400 * 12;
        let sigma = 0.05;
        let y: Vec<f64> = (0..n)
            .map(|k| one[k % 400] + sigma * rng.normal())
            .collect();
        let (s2, m) = periodic_scatter(&y, 400, 10).unwrap();
        assert_eq!(m, 11);
        // 11·400 samples, (m−1)·p = 4000 degrees of freedom: relative SE of σ² ≈ sqrt(2/4000).
        assert!((s2.sqrt() / sigma - 1.0).abs() < 0.05, "{}", s2.sqrt());
    }

    /// A position output creeping by 5σ per period and 0.5 % sensor spikes of 40σ: neither sets
    /// the floor (the scatter about the period average would read the drift's spread, ~16σ,
    /// and the spikes' 40σ·√0.005 ≈ 2.8σ).
    #[test]
    fn drift_between_periods_and_spikes_do_not_set_the_scatter() {
        let mut rng = Rng::new(13);
        let one = multisine_period(400, &mut rng);
        let (p, n, sigma) = (400, 400 * 12, 0.05);
        let drift: Vec<f64> = (0..n)
            .map(|k| one[k % p] + sigma * rng.normal() + 5.0 * sigma * k as f64 / p as f64)
            .collect();
        let (s2, _) = periodic_scatter(&drift, p, 10).unwrap();
        assert!(
            (s2.sqrt() / sigma - 1.0).abs() < 0.06,
            "drift: {}",
            s2.sqrt() / sigma
        );
        let mut spiky: Vec<f64> = (0..n).map(|k| one[k % p] + sigma * rng.normal()).collect();
        for k in (7..n).step_by(200) {
            spiky[k] += 40.0 * sigma;
        }
        let (s2, _) = periodic_scatter(&spiky, p, 10).unwrap();
        assert!(
            (s2.sqrt() / sigma - 1.0).abs() < 0.06,
            "spikes: {}",
            s2.sqrt() / sigma
        );
    }

    #[test]
    fn off_band_residual_recovers_white_noise_outside_the_excited_band() {
        let mut rng = Rng::new(5);
        let n = 16384;
        // Input: a multisine up to 1/16 of the sample rate (one period = whole record).
        let p = n;
        let mut u = vec![0.0; p];
        for k in 1..p / 32 {
            let ph = 2.0 * std::f64::consts::PI * rng.uniform();
            for (i, x) in u.iter_mut().enumerate().step_by(1) {
                *x += (2.0 * std::f64::consts::PI * ((k * i) % p) as f64 / p as f64 + ph).cos();
            }
        }
        let sigma = 0.3;
        let r: Vec<f64> = (0..n).map(|_| sigma * rng.normal()).collect();
        let s2 = off_band_variance(&u, &r, 1000.0).unwrap().unwrap();
        // Median of chi²₂-ish Welch bins is biased low by ln 2 at few averages; with ~15
        // averages the median of the averaged density is within a few per cent.
        assert!((s2.sqrt() / sigma - 1.0).abs() < 0.1, "{}", s2.sqrt());
        // Broadband input: no off-band bins.
        let w: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        assert!(off_band_variance(&w, &r, 1000.0).unwrap().is_none());
    }
}
