//! Excitation signals of the independent family: band-limited Gaussian noise, a log-spaced
//! random-phase multisine, and odd random-phase multisines with detection lines (several
//! periods, for noise and distortion estimates from the data).
use crate::rng::Xoshiro;
use std::f64::consts::PI;

/// Second-order section (direct form I), coefficients normalised by a0.
#[derive(Debug, Clone, Copy)]
struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
}

impl Biquad {
    /// Butterworth low-pass (Q = 1/√2) at `f` Hz, bilinear transform with prewarping.
    fn low_pass(f: f64, ts: f64) -> Self {
        let w0 = 2.0 * PI * f * ts;
        let (s, c) = w0.sin_cos();
        let alpha = s / std::f64::consts::SQRT_2;
        let a0 = 1.0 + alpha;
        Self {
            b: [(1.0 - c) / 2.0 / a0, (1.0 - c) / a0, (1.0 - c) / 2.0 / a0],
            a: [-2.0 * c / a0, (1.0 - alpha) / a0],
        }
    }
    /// Butterworth high-pass at `f` Hz.
    fn high_pass(f: f64, ts: f64) -> Self {
        let w0 = 2.0 * PI * f * ts;
        let (s, c) = w0.sin_cos();
        let alpha = s / std::f64::consts::SQRT_2;
        let a0 = 1.0 + alpha;
        Self {
            b: [(1.0 + c) / 2.0 / a0, -(1.0 + c) / a0, (1.0 + c) / 2.0 / a0],
            a: [-2.0 * c / a0, (1.0 - alpha) / a0],
        }
    }
    fn run(&self, x: &mut [f64]) {
        let (mut x1, mut x2, mut y1, mut y2) = (0.0, 0.0, 0.0, 0.0);
        for v in x.iter_mut() {
            let y =
                self.b[0] * *v + self.b[1] * x1 + self.b[2] * x2 - self.a[0] * y1 - self.a[1] * y2;
            x2 = x1;
            x1 = *v;
            y2 = y1;
            y1 = y;
            *v = y;
        }
    }
}

/// Root mean square.
pub fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Standard deviation (population, mean removed).
pub fn std_dev(v: &[f64]) -> f64 {
    let n = v.len().max(1) as f64;
    let m = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
}

fn remove_mean_and_scale(v: &mut [f64], target: f64) {
    let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
    v.iter_mut().for_each(|x| *x -= m);
    let r = rms(v);
    if r > 0.0 {
        v.iter_mut().for_each(|x| *x *= target / r);
    }
}

/// Gaussian noise through a 4th-order Butterworth low-pass at `f_hi` Hz (two sections) and,
/// when `f_lo` > 0, a 4th-order Butterworth high-pass at `f_lo` Hz; zero mean, RMS `rms_target`.
/// A 2 s lead-in is run and discarded so the filters start in steady state.
pub fn band_noise(
    n: usize,
    ts: f64,
    f_lo: f64,
    f_hi: f64,
    rms_target: f64,
    rng: &mut Xoshiro,
) -> Vec<f64> {
    let lead = (2.0 / ts) as usize;
    let mut v: Vec<f64> = (0..n + lead).map(|_| rng.normal()).collect();
    let lp = Biquad::low_pass(f_hi, ts);
    lp.run(&mut v);
    lp.run(&mut v);
    if f_lo > 0.0 {
        let hp = Biquad::high_pass(f_lo, ts);
        hp.run(&mut v);
        hp.run(&mut v);
    }
    let mut out = v.split_off(lead);
    remove_mean_and_scale(&mut out, rms_target);
    out
}

/// Random-phase multisine with `n_lines` lines log-spaced in [`f_lo`, `f_hi`] Hz on the DFT grid
/// of the whole record (duplicates merged), equal amplitudes, zero mean, RMS `rms_target`.
pub fn log_multisine(
    n: usize,
    ts: f64,
    f_lo: f64,
    f_hi: f64,
    n_lines: usize,
    rms_target: f64,
    rng: &mut Xoshiro,
) -> Vec<f64> {
    let df = 1.0 / (n as f64 * ts);
    let mut bins: Vec<usize> = (0..n_lines)
        .map(|i| {
            let f = f_lo * (f_hi / f_lo).powf(i as f64 / (n_lines.max(2) - 1) as f64);
            ((f / df).round() as usize).max(1)
        })
        .collect();
    bins.dedup();
    let mut v = vec![0.0; n];
    for &b in &bins {
        let ph = 2.0 * PI * rng.uniform();
        let w = 2.0 * PI * b as f64 / n as f64;
        for (t, x) in v.iter_mut().enumerate() {
            *x += (w * t as f64 + ph).cos();
        }
    }
    remove_mean_and_scale(&mut v, rms_target);
    v
}

/// An odd random-phase multisine with detection lines.
#[derive(Debug, Clone)]
pub struct OddMultisine {
    /// The signal: `periods` repetitions of one period.
    pub signal: Vec<f64>,
    /// Samples per period.
    pub period: usize,
    /// Excited harmonics (of 1/(period·ts)), all odd.
    pub excited: Vec<usize>,
    /// Odd harmonics in the band left out on purpose (detection lines).
    pub detection: Vec<usize>,
}

/// Odd random-phase multisine: harmonics k of f0 = 1/(`period`·ts), only odd k with k·f0 in
/// [`f_lo`, `f_hi`], in each group of `group` consecutive odd harmonics one (chosen at random)
/// left out as a detection line; repeated `periods` times; RMS `rms_target`.
#[allow(clippy::too_many_arguments)]
pub fn odd_multisine(
    period: usize,
    periods: usize,
    ts: f64,
    f_lo: f64,
    f_hi: f64,
    group: usize,
    rms_target: f64,
    rng: &mut Xoshiro,
) -> OddMultisine {
    let f0 = 1.0 / (period as f64 * ts);
    let odd: Vec<usize> = (1..period / 2)
        .filter(|k| k % 2 == 1)
        .filter(|&k| {
            let f = k as f64 * f0;
            f >= f_lo && f <= f_hi
        })
        .collect();
    let mut excited = Vec::new();
    let mut detection = Vec::new();
    for chunk in odd.chunks(group.max(2)) {
        let skip = if chunk.len() == group.max(2) {
            Some((rng.uniform() * chunk.len() as f64) as usize % chunk.len())
        } else {
            None
        };
        for (i, &k) in chunk.iter().enumerate() {
            if Some(i) == skip {
                detection.push(k);
            } else {
                excited.push(k);
            }
        }
    }
    let mut one = vec![0.0; period];
    for &k in &excited {
        let ph = 2.0 * PI * rng.uniform();
        let w = 2.0 * PI * k as f64 / period as f64;
        for (t, x) in one.iter_mut().enumerate() {
            *x += (w * t as f64 + ph).cos();
        }
    }
    let r = rms(&one);
    if r > 0.0 {
        one.iter_mut().for_each(|x| *x *= rms_target / r);
    }
    let mut signal = Vec::with_capacity(period * periods);
    for _ in 0..periods {
        signal.extend_from_slice(&one);
    }
    OddMultisine {
        signal,
        period,
        excited,
        detection,
    }
}
