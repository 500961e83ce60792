//! Detection of a self-sustained oscillation in the steady-state tail of a simulated signal.
//!
//! On the last `tail_fraction` of the signal (mean removed):
//! 1. **Present**: its peak-to-peak exceeds `min_rel` of the whole run's peak-to-peak (and is
//!    not zero): a loop that settles (or sticks) leaves a flat tail.
//! 2. **Sustained**: the RMS of the tail's second half is at least `min_persistence` of the
//!    first half's (a decaying transient fails; a growing oscillation passes).
//! 3. **Periodic**: the normalised autocorrelation has a peak ≥ `min_periodicity` after its
//!    first zero crossing; the first such peak is the period (parabolic interpolation between
//!    lags), so broadband chatter without a period is not reported.
//!
//! The frequency is 1/period; the amplitude is the first-harmonic amplitude at that frequency
//! over the whole periods of the tail (the quantity a describing function predicts), with the
//! half peak-to-peak beside it.
// `!(x > y)` comparisons are deliberate: they are also true when x is NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Largest number of (block-averaged) samples the autocorrelation runs on.
pub const MAX_AUTOCORR_SAMPLES: usize = 16_384;

/// Settings of [`detect`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DetectOptions {
    /// Fraction of the run analysed at its end (default 0.4).
    pub tail_fraction: f64,
    /// Smallest tail peak-to-peak relative to the whole run's (default 1e-3).
    pub min_rel: f64,
    /// Smallest RMS ratio second half / first half of the tail (default 0.8).
    pub min_persistence: f64,
    /// Smallest normalised autocorrelation at the period (default 0.5).
    pub min_periodicity: f64,
}

impl Default for DetectOptions {
    fn default() -> Self {
        Self {
            tail_fraction: 0.4,
            min_rel: 1e-3,
            min_persistence: 0.8,
            min_periodicity: 0.5,
        }
    }
}

/// An oscillation found in a simulated run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimulatedLimitCycle {
    /// Fundamental frequency, Hz.
    pub freq_hz: f64,
    /// First-harmonic amplitude (units of the signal).
    pub amplitude: f64,
    /// Half the peak-to-peak over the tail.
    pub half_peak_to_peak: f64,
    /// Mean of the tail (the oscillation's centre).
    pub mean: f64,
    /// Normalised autocorrelation at the period (1 = perfectly periodic).
    pub periodicity: f64,
    /// RMS of the second half of the tail over the first.
    pub persistence: f64,
}

/// The oscillation in the tail of `x` (sampled every `ts` seconds), or `None` when the tail is
/// flat, decaying or aperiodic (module docs). Never panics; returns `None` for fewer than 64
/// tail samples or non-finite data.
pub fn detect(x: &[f64], ts: f64, opts: &DetectOptions) -> Option<SimulatedLimitCycle> {
    if !(ts.is_finite() && ts > 0.0) || x.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let frac = opts.tail_fraction.clamp(0.05, 1.0);
    let nt = ((x.len() as f64) * frac) as usize;
    if nt < 64 {
        return None;
    }
    let tail = &x[x.len() - nt..];
    let ptp = |s: &[f64]| {
        let (lo, hi) = s
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
        hi - lo
    };
    let whole = ptp(x);
    let tp = ptp(tail);
    if !(tp > 0.0 && tp >= opts.min_rel * whole) {
        return None;
    }
    let mean = tail.iter().sum::<f64>() / nt as f64;
    let z: Vec<f64> = tail.iter().map(|v| v - mean).collect();
    let rms = |s: &[f64]| (s.iter().map(|v| v * v).sum::<f64>() / s.len() as f64).sqrt();
    let (h1, h2) = z.split_at(nt / 2);
    let persistence = rms(h2) / rms(h1).max(1e-300);
    if !(persistence >= opts.min_persistence) {
        return None;
    }
    // Normalised autocorrelation up to a third of the tail (at least 3 periods seen), on
    // block means of q samples when the tail is long (bounded cost; the period is refined by
    // parabolic interpolation and the amplitude is computed on the full-rate tail).
    let q = nt.div_ceil(MAX_AUTOCORR_SAMPLES).max(1);
    let zq: Vec<f64> = z
        .chunks(q)
        .map(|c| c.iter().sum::<f64>() / c.len() as f64)
        .collect();
    let nq = zq.len();
    let max_lag = nq / 3;
    let r0: f64 = zq.iter().map(|v| v * v).sum();
    if !(r0 > 0.0) {
        return None;
    }
    let r = |lag: usize| -> f64 {
        zq[..nq - lag]
            .iter()
            .zip(&zq[lag..])
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / r0
    };
    let mut lag = 1;
    let mut prev = r(1);
    while lag < max_lag && prev > 0.0 {
        lag += 1;
        prev = r(lag);
    }
    if lag >= max_lag {
        return None;
    }
    // First local maximum after the zero crossing.
    let mut best: Option<(usize, f64)> = None;
    let mut cur = prev;
    while lag + 1 < max_lag {
        let next = r(lag + 1);
        if cur >= prev && cur >= next && cur > 0.0 {
            best = Some((lag, cur));
            break;
        }
        prev = cur;
        cur = next;
        lag += 1;
    }
    let (l0, rpk) = best?;
    if rpk < opts.min_periodicity {
        return None;
    }
    let (ra, rb) = (r(l0 - 1), r(l0 + 1));
    let den = ra - 2.0 * rpk + rb;
    let off = if den.abs() > 1e-300 {
        (0.5 * (ra - rb) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    let mut period = (l0 as f64 + off) * ts * q as f64;
    // A period within 1 % of two samples is the Nyquist frequency itself (the sampled signal
    // alternates; lags of unequal overlap bias the interpolation slightly).
    let nyquist = (period / ts - 2.0).abs() < 0.02;
    if nyquist {
        period = 2.0 * ts;
    }
    let freq_hz = 1.0 / period;
    // First harmonic over whole periods at the end of the tail.
    let per = period / ts;
    let whole_periods = (nt as f64 / per).floor().max(1.0);
    let len = ((whole_periods * per).round() as usize).min(nt);
    let seg = &z[nt - len..];
    let w = 2.0 * PI * freq_hz * ts;
    let (mut s, mut cc) = (0.0, 0.0);
    for (k, v) in seg.iter().enumerate() {
        s += v * (w * k as f64).sin();
        cc += v * (w * k as f64).cos();
    }
    // At the Nyquist frequency the sampled fundamental is Y·(−1)^k: its amplitude is |S|/N,
    // not 2|S|/N (the positive and negative frequencies coincide).
    let factor = if nyquist { 1.0 } else { 2.0 };
    let amplitude = factor * (s * s + cc * cc).sqrt() / len as f64;
    Some(SimulatedLimitCycle {
        freq_hz,
        amplitude,
        half_peak_to_peak: 0.5 * tp,
        mean,
        periodicity: rpk,
        persistence,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_sine_and_a_square_wave() {
        let ts = 1e-3;
        let x: Vec<f64> = (0..20000)
            .map(|k| 0.3 + 2.0 * (2.0 * PI * 17.3 * k as f64 * ts).sin())
            .collect();
        let c = detect(&x, ts, &DetectOptions::default()).unwrap();
        assert!((c.freq_hz / 17.3 - 1.0).abs() < 0.01, "{c:?}");
        assert!((c.amplitude / 2.0 - 1.0).abs() < 0.01, "{c:?}");
        assert!((c.mean - 0.3).abs() < 0.01);
        // Square wave of amplitude 1: first harmonic 4/π.
        let x: Vec<f64> = (0..20000)
            .map(|k| (2.0 * PI * 9.0 * k as f64 * ts).sin().signum())
            .collect();
        let c = detect(&x, ts, &DetectOptions::default()).unwrap();
        assert!((c.freq_hz / 9.0 - 1.0).abs() < 0.01, "{c:?}");
        assert!((c.amplitude / (4.0 / PI) - 1.0).abs() < 0.03, "{c:?}");
        // Period of two samples (Nyquist toggling), amplitude 1.
        let x: Vec<f64> = (0..4000)
            .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let c = detect(&x, ts, &DetectOptions::default()).unwrap();
        assert_eq!(c.freq_hz, 500.0, "{c:?}");
        assert!((c.amplitude - 1.0).abs() < 1e-12, "{c:?}");
    }

    #[test]
    fn rejects_decay_flat_and_noise() {
        let ts = 1e-3;
        let decaying: Vec<f64> = (0..20000)
            .map(|k| {
                let t = k as f64 * ts;
                (-t / 2.0).exp() * (2.0 * PI * 10.0 * t).sin()
            })
            .collect();
        assert!(detect(&decaying, ts, &DetectOptions::default()).is_none());
        let mut settled: Vec<f64> = (0..20000).map(|k| (0.01 * k as f64).sin()).collect();
        settled[10000..].iter_mut().for_each(|v| *v = 0.25);
        assert!(detect(&settled, ts, &DetectOptions::default()).is_none());
        let mut rng = ferrosid_firmware::rng::SplitMix64::new(12345);
        let noise: Vec<f64> = (0..20000).map(|_| rng.next_f64() - 0.5).collect();
        assert!(detect(&noise, ts, &DetectOptions::default()).is_none());
        assert!(detect(&[1.0, f64::NAN], ts, &DetectOptions::default()).is_none());
        assert!(detect(&[], ts, &DetectOptions::default()).is_none());
    }
}
