//! Empirical transfer-function estimates (ETFE) with coherence, in f64.
//!
//! * [`Welch`]: averaged, windowed auto/cross spectra and the H1 estimate
//!   `H(f) = S_uy(f) / S_uu(f)`, following scipy.signal's conventions exactly so that results
//!   agree with `scipy.signal.welch` / `csd` / `coherence` (tests pin 1e-9 relative):
//!   segments of `nperseg` samples starting every `nperseg - noverlap` samples (trailing samples
//!   that do not fill a segment are ignored), per-segment detrending *before* windowing,
//!   one-sided density scaling `2 / (fs * sum(w^2))` (DC, and Nyquist for even `nperseg`, not
//!   doubled), `S_uy = mean(conj(U) * Y)` (scipy's `csd(u, y)`), so that `H1 = Y/U` is the plant
//!   response from u to y, and magnitude-squared coherence `|S_uy|^2 / (S_uu S_yy)`. Windows
//!   are periodic (DFT-even, `scipy.signal.get_window(name, N)`).
//! * [`PeriodicAveraging`]: period-synchronous averaging for periodic excitation (multisines):
//!   the DFT of every period (rectangular window) is averaged, `H = Ȳ/Ū` at the excited lines,
//!   and the noise variances of `Ū`, `Ȳ` and `H` come from the spread over periods.
//! * Coherence gating: [`Etfe::gate`] / [`PeriodicFrf::gate`] (default threshold
//!   [`DEFAULT_COHERENCE_THRESHOLD`] = 0.85; the Welch gate also rejects bins without input
//!   power) and [`Etfe::excluded_bands`] / [`PeriodicFrf::excluded_bands`] for reports; the
//!   plain [`coherence_gate`] / [`excluded_bands`] work on any coherence vector.
//!
//! Frequencies are in Hz. One realfft plan and one set of buffers serve all segments of a call
//! (no allocation per segment). MIMO logs: estimate each (input, output) pair separately.
use num_complex::Complex64;
use realfft::{RealFftPlanner, RealToComplex};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

use crate::data::Log;
use crate::error::{Error, Result};
use crate::io::require_len;

/// Default coherence threshold for gating bins used in fitting and validation.
pub const DEFAULT_COHERENCE_THRESHOLD: f64 = 0.85;

/// Smallest accepted Welch segment length (samples).
pub const MIN_NPERSEG: usize = 8;

/// Largest accepted Welch segment length (samples, 2^22 ≈ 4.2 M; each of the five FFT buffers
/// then takes 32–64 MB).
pub const MAX_NPERSEG: usize = 1 << 22;

/// Fewest averaged Welch segments for which [`Etfe::gate`] passes any bin.
///
/// The rule: magnitude-squared coherence estimated from `n` averages is biased towards 1 (it is
/// identically 1 for `n = 1`); for uncorrelated input and output and `n` independent segments,
/// the estimate exceeds a threshold `c` with probability `(1 − c)^(n − 1)`. With 50 % overlapped
/// Hann segments (nearly independent) and the default gate 0.85, `n = 4` keeps that below
/// 0.15³ ≈ 0.3 % per bin. With fewer segments no bin passes the gate, and reports say why.
pub const MIN_WELCH_AVERAGES: usize = 4;

/// The power of two that brings `max_abs` (the largest |sample| of a signal) near 1, so that
/// products of samples neither overflow (signals near 1e300) nor underflow (near 1e-300).
/// Multiplying by a power of two is exact in binary floating point, so results computed on the
/// scaled signal are the unscaled results, scaled — numerics become scale-invariant. Returns
/// 1 for zero or non-finite `max_abs`.
pub fn power_of_two_scale(max_abs: f64) -> f64 {
    if !(max_abs.is_finite() && max_abs > 0.0) {
        return 1.0;
    }
    let e = max_abs.log2().floor().clamp(-1000.0, 1000.0) as i32;
    2f64.powi(-e)
}

/// Largest |x| of a signal (0 for an empty one).
pub fn max_abs(x: &[f64]) -> f64 {
    x.iter().fold(0.0f64, |m, v| m.max(v.abs()))
}

/// Data window applied to each segment. All built-in windows are periodic (DFT-even), as
/// `scipy.signal.get_window(name, N)` returns them.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Window {
    /// Hann: `w[n] = 0.5 - 0.5 cos(2 pi n / N)`.
    Hann,
    /// Hamming: `w[n] = 0.54 - 0.46 cos(2 pi n / N)`.
    Hamming,
    /// Blackman: `w[n] = 0.42 - 0.5 cos(2 pi n / N) + 0.08 cos(4 pi n / N)`.
    Blackman,
    /// Rectangular (scipy `boxcar`): all ones.
    Rectangular,
    /// Caller-supplied coefficients; length must equal `nperseg`, values finite, not all zero.
    Custom(Vec<f64>),
}

impl Window {
    /// The `n` window coefficients.
    pub fn coefficients(&self, n: usize) -> Result<Vec<f64>> {
        let cos_sum = |a: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    let x = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
                    a.iter()
                        .enumerate()
                        .map(|(k, &ak)| {
                            let s = if k % 2 == 0 { 1.0 } else { -1.0 };
                            s * ak * (k as f64 * x).cos()
                        })
                        .sum()
                })
                .collect()
        };
        match self {
            Window::Hann => Ok(cos_sum(&[0.5, 0.5])),
            Window::Hamming => Ok(cos_sum(&[0.54, 0.46])),
            Window::Blackman => Ok(cos_sum(&[0.42, 0.5, 0.08])),
            Window::Rectangular => Ok(vec![1.0; n]),
            Window::Custom(w) => {
                if w.len() != n {
                    return Err(Error::InvalidArgument(format!(
                        "custom window has {} coefficients but nperseg = {n}",
                        w.len()
                    )));
                }
                if w.iter().any(|v| !v.is_finite()) || w.iter().all(|&v| v == 0.0) {
                    return Err(Error::InvalidArgument(
                        "custom window must be finite and not all zero".into(),
                    ));
                }
                Ok(w.clone())
            }
        }
    }
}

/// Per-segment detrending applied before windowing (scipy's `detrend` argument). The same
/// type is the `--detrend` value of `ferrosid frf` (feature `cli`) and a serde value
/// (`"constant"`, `"linear"`, `"none"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum Detrend {
    /// Subtract the segment mean (scipy `'constant'`, the default).
    Constant,
    /// Subtract the least-squares straight line (scipy `'linear'`).
    Linear,
    /// No detrending (scipy `detrend=False`).
    None,
}

/// A named data window (the [`Window`]s without caller-supplied coefficients): the
/// `--window` value of `ferrosid frf`/`identify` (feature `cli`) and a serde value. The
/// rectangular window is spelled `boxcar` as in scipy; `rectangular` is accepted too.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum WindowName {
    /// Periodic Hann.
    Hann,
    /// Periodic Hamming.
    Hamming,
    /// Periodic Blackman.
    Blackman,
    /// Rectangular (scipy `boxcar`).
    #[serde(alias = "rectangular")]
    #[cfg_attr(feature = "cli", value(alias = "rectangular"))]
    Boxcar,
}

impl From<WindowName> for Window {
    fn from(w: WindowName) -> Self {
        match w {
            WindowName::Hann => Window::Hann,
            WindowName::Hamming => Window::Hamming,
            WindowName::Blackman => Window::Blackman,
            WindowName::Boxcar => Window::Rectangular,
        }
    }
}

/// Welch averaging settings. Defaults follow scipy: `nperseg` 256, `noverlap = nperseg / 2`,
/// Hann window, constant detrend, mean averaging, `nfft = nperseg`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Welch {
    /// Segment length in samples (any size >= [`MIN_NPERSEG`]); frequency resolution
    /// `fs / nperseg` Hz.
    pub nperseg: usize,
    /// Overlap between consecutive segments in samples (`< nperseg`); `None` = `nperseg / 2`.
    pub noverlap: Option<usize>,
    /// Data window.
    pub window: Window,
    /// Per-segment detrending.
    pub detrend: Detrend,
}

impl Default for Welch {
    fn default() -> Self {
        Self::new(256)
    }
}

/// Welch H1 estimate with its spectra. All vectors have `nperseg / 2 + 1` entries (one-sided
/// bins `k * fs / nperseg`, k = 0..=nperseg/2).
#[derive(Debug, Clone, PartialEq)]
pub struct Etfe {
    /// Sample rate in Hz.
    pub fs: f64,
    /// Segment length (samples).
    pub nperseg: usize,
    /// Overlap (samples).
    pub noverlap: usize,
    /// Number of segments averaged (over all records added).
    pub n_averages: usize,
    /// Bin frequencies in Hz.
    pub freq_hz: Vec<f64>,
    /// H1 = S_uy / S_uu (output units per input unit). NaN where S_uu = 0.
    pub h: Vec<Complex64>,
    /// Magnitude-squared coherence in [0, 1]; 0 where S_uu or S_yy is 0.
    pub coherence: Vec<f64>,
    /// One-sided input auto-spectral density (u units^2 / Hz).
    pub suu: Vec<f64>,
    /// One-sided output auto-spectral density (y units^2 / Hz).
    pub syy: Vec<f64>,
    /// One-sided cross-spectral density, `mean(conj(U) Y)` scaled (u·y units / Hz).
    pub suy: Vec<Complex64>,
    /// True where the input carries power: `S_uu >= MIN_RELATIVE_INPUT_POWER · max(S_uu)`,
    /// decided on the internally normalised spectra (so it holds even where a density over- or
    /// underflows f64 for signals near 1e±300).
    pub input_excited: Vec<bool>,
}

/// One-sided power spectral density (scipy.signal.welch).
#[derive(Debug, Clone, PartialEq)]
pub struct Psd {
    /// Bin frequencies in Hz.
    pub freq_hz: Vec<f64>,
    /// Density in units^2 / Hz.
    pub density: Vec<f64>,
    /// Number of segments averaged.
    pub n_averages: usize,
}

impl Welch {
    /// scipy defaults with the given segment length.
    pub fn new(nperseg: usize) -> Self {
        Self {
            nperseg,
            noverlap: None,
            window: Window::Hann,
            detrend: Detrend::Constant,
        }
    }

    /// The overlap actually used (samples).
    pub fn overlap(&self) -> usize {
        self.noverlap.unwrap_or(self.nperseg / 2)
    }

    /// Number of segments a record of `len` samples yields: `(len - noverlap) / step` for
    /// `len >= nperseg`, else 0.
    pub fn n_segments(&self, len: usize) -> usize {
        if len < self.nperseg || self.overlap() >= self.nperseg {
            return 0;
        }
        (len - self.overlap()) / (self.nperseg - self.overlap())
    }

    fn validate(&self) -> Result<()> {
        if !(MIN_NPERSEG..=MAX_NPERSEG).contains(&self.nperseg) {
            return Err(Error::InvalidArgument(format!(
                "Welch segment length must be >= {MIN_NPERSEG} and <= {MAX_NPERSEG} samples, got {}",
                self.nperseg
            )));
        }
        if self.overlap() >= self.nperseg {
            return Err(Error::InvalidArgument(format!(
                "Welch overlap {} must be smaller than the segment length {}",
                self.overlap(),
                self.nperseg
            )));
        }
        Ok(())
    }

    /// A reusable accumulator for pooling segments of several records (logs) at sample rate
    /// `fs` Hz into one estimate.
    pub fn accumulator(&self, fs: f64) -> Result<WelchAccumulator> {
        WelchAccumulator::new(self, fs)
    }

    /// H1 estimate and coherence from one record: `u` input, `y` output (same length, finite,
    /// at least `nperseg` samples), `fs` in Hz.
    pub fn etfe(&self, u: &[f64], y: &[f64], fs: f64) -> Result<Etfe> {
        let mut acc = self.accumulator(fs)?;
        acc.add(u, y)?;
        acc.finish()
    }

    /// H1 estimate for input channel `input` → output channel `output` of a log. Too short a
    /// log is an [`Error::Data`] naming the file.
    pub fn etfe_log(&self, log: &Log, input: usize, output: usize) -> Result<Etfe> {
        let (u, y) = pair(log, input, output)?;
        self.validate()?;
        require_len(
            log,
            self.nperseg,
            &format!("Welch with nperseg = {}", self.nperseg),
        )?;
        self.etfe(u, y, log.fs())
    }

    /// One-sided PSD of `x` (scipy.signal.welch with the same settings).
    pub fn psd(&self, x: &[f64], fs: f64) -> Result<Psd> {
        self.validate()?;
        check_signal(x, "x", self.nperseg)?;
        check_fs(fs)?;
        let n = self.nperseg;
        let win = self.window.coefficients(n)?;
        let mut planner = RealFftPlanner::<f64>::new();
        let r2c = planner.plan_fft_forward(n);
        let mut buf = r2c.make_input_vec();
        let mut spec = r2c.make_output_vec();
        let mut scratch = r2c.make_scratch_vec();
        let nb = n / 2 + 1;
        let mut acc = vec![0.0; nb];
        let step = n - self.overlap();
        let nseg = self.n_segments(x.len());
        let g = power_of_two_scale(max_abs(x));
        let xs: Vec<f64> = x.iter().map(|v| v * g).collect();
        for s in 0..nseg {
            prepare(&xs[s * step..s * step + n], &win, self.detrend, &mut buf);
            fft(&r2c, &mut buf, &mut spec, &mut scratch)?;
            for (a, z) in acc.iter_mut().zip(&spec) {
                *a += z.norm_sqr();
            }
        }
        let w2: f64 = win.iter().map(|w| w * w).sum();
        let scale = 1.0 / (w2 * nseg as f64);
        for (k, a) in acc.iter_mut().enumerate() {
            *a = *a * (scale * one_sided_factor(k, n)) / fs / g / g;
        }
        Ok(Psd {
            freq_hz: (0..nb).map(|k| bin_hz(k, n, fs)).collect(),
            density: acc,
            n_averages: nseg,
        })
    }
}

/// Accumulates Welch segments of one or more records, then yields the pooled [`Etfe`]
/// (the mean over all segments of all records). Created by [`Welch::accumulator`].
pub struct WelchAccumulator {
    settings: Welch,
    fs: f64,
    win: Vec<f64>,
    r2c: Arc<dyn RealToComplex<f64>>,
    buf: Vec<f64>,
    spec_u: Vec<Complex64>,
    spec_y: Vec<Complex64>,
    scratch: Vec<Complex64>,
    suu: Vec<f64>,
    syy: Vec<f64>,
    suy: Vec<Complex64>,
    n_avg: usize,
    /// Power-of-two normalisation of input and output, fixed by the first record added.
    scale: Option<(f64, f64)>,
    scaled: Vec<f64>,
}

impl std::fmt::Debug for WelchAccumulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WelchAccumulator")
            .field("settings", &self.settings)
            .field("fs", &self.fs)
            .field("n_averages", &self.n_avg)
            .finish()
    }
}

impl WelchAccumulator {
    fn new(settings: &Welch, fs: f64) -> Result<Self> {
        settings.validate()?;
        check_fs(fs)?;
        let n = settings.nperseg;
        let win = settings.window.coefficients(n)?;
        let mut planner = RealFftPlanner::<f64>::new();
        let r2c = planner.plan_fft_forward(n);
        let nb = n / 2 + 1;
        Ok(Self {
            settings: settings.clone(),
            fs,
            win,
            buf: r2c.make_input_vec(),
            spec_u: r2c.make_output_vec(),
            spec_y: r2c.make_output_vec(),
            scratch: r2c.make_scratch_vec(),
            r2c,
            suu: vec![0.0; nb],
            syy: vec![0.0; nb],
            suy: vec![Complex64::new(0.0, 0.0); nb],
            n_avg: 0,
            scale: None,
            scaled: Vec::new(),
        })
    }

    /// Adds all complete segments of one record (`u`, `y` of equal length >= `nperseg`, finite).
    pub fn add(&mut self, u: &[f64], y: &[f64]) -> Result<()> {
        let n = self.settings.nperseg;
        if u.len() != y.len() {
            return Err(Error::InvalidArgument(format!(
                "input and output lengths differ: {} vs {}",
                u.len(),
                y.len()
            )));
        }
        check_signal(u, "input", n)?;
        check_signal(y, "output", n)?;
        let step = n - self.settings.overlap();
        let nseg = self.settings.n_segments(u.len());
        // Internal normalisation (exact power-of-two scaling, undone in `finish`).
        let (gu, gy) = *self.scale.get_or_insert_with(|| {
            (
                power_of_two_scale(max_abs(u)),
                power_of_two_scale(max_abs(y)),
            )
        });
        self.scaled.clear();
        self.scaled.extend(u.iter().map(|v| v * gu));
        self.scaled.extend(y.iter().map(|v| v * gy));
        let (us, ys) = self.scaled.split_at(u.len());
        for s in 0..nseg {
            let r = s * step..s * step + n;
            prepare(
                &us[r.clone()],
                &self.win,
                self.settings.detrend,
                &mut self.buf,
            );
            fft(
                &self.r2c,
                &mut self.buf,
                &mut self.spec_u,
                &mut self.scratch,
            )?;
            prepare(&ys[r], &self.win, self.settings.detrend, &mut self.buf);
            fft(
                &self.r2c,
                &mut self.buf,
                &mut self.spec_y,
                &mut self.scratch,
            )?;
            for k in 0..self.suu.len() {
                let (a, b) = (self.spec_u[k], self.spec_y[k]);
                self.suu[k] += a.norm_sqr();
                self.syy[k] += b.norm_sqr();
                self.suy[k] += a.conj() * b;
            }
        }
        self.n_avg += nseg;
        if nseg == 0 && self.n_avg == 0 {
            self.scale = None;
        }
        Ok(())
    }

    /// Segments accumulated so far.
    pub fn n_averages(&self) -> usize {
        self.n_avg
    }

    /// The pooled estimate. Errors if no segment was added.
    pub fn finish(&self) -> Result<Etfe> {
        if self.n_avg == 0 {
            return Err(Error::InvalidArgument(
                "no Welch segment was accumulated".into(),
            ));
        }
        let n = self.settings.nperseg;
        let nb = n / 2 + 1;
        let w2: f64 = self.win.iter().map(|w| w * w).sum();
        let (gu, gy) = self.scale.unwrap_or((1.0, 1.0));
        // Densities in the log's units: the normalised sums, the density scale and the
        // normalisation undone (each factor applied separately so an intermediate does not
        // over- or underflow when the final value is representable).
        let per_avg = 1.0 / (w2 * self.n_avg as f64);
        let mut suu = Vec::with_capacity(nb);
        let mut syy = Vec::with_capacity(nb);
        let mut suy = Vec::with_capacity(nb);
        let mut h = Vec::with_capacity(nb);
        let mut coherence = Vec::with_capacity(nb);
        for k in 0..nb {
            // H and coherence from the normalised sums: the density scale cancels, and the
            // sums of O(1) signals neither overflow nor underflow.
            let (ru, ry, rc) = (self.suu[k], self.syy[k], self.suy[k]);
            h.push(if ru > 0.0 {
                rc / ru * (gu / gy)
            } else {
                Complex64::new(f64::NAN, f64::NAN)
            });
            coherence.push(if ru > 0.0 && ry > 0.0 {
                ((rc.norm() / ru) * (rc.norm() / ry)).min(1.0)
            } else {
                0.0
            });
            let c = per_avg * one_sided_factor(k, n);
            suu.push(ru * c / self.fs / gu / gu);
            syy.push(ry * c / self.fs / gy / gy);
            suy.push(rc * c / self.fs / gu / gy);
        }
        let input_excited = excited_bins(&self.suu);
        Ok(Etfe {
            fs: self.fs,
            nperseg: n,
            noverlap: self.settings.overlap(),
            n_averages: self.n_avg,
            freq_hz: (0..nb).map(|k| bin_hz(k, n, self.fs)).collect(),
            h,
            coherence,
            suu,
            syy,
            suy,
            input_excited,
        })
    }
}

impl Etfe {
    /// Bins usable for fitting/validation: `coherence >= threshold` **and** an excited input,
    /// `suu >= MIN_RELATIVE_INPUT_POWER * max(suu)`. The second condition matters for periodic
    /// or band-limited excitation: at a bin without input power S_uu is round-off, and a
    /// deterministic output component there (e.g. nonlinear distortion of a multisine) can show
    /// a spurious coherence near 1 with a meaningless H1.
    ///
    /// With fewer than [`MIN_WELCH_AVERAGES`] averaged segments no bin passes (see that
    /// constant for the rule; [`Etfe::too_few_averages`] says why in words).
    pub fn gate(&self, threshold: f64) -> Vec<bool> {
        let enough = self.n_averages >= MIN_WELCH_AVERAGES;
        coherence_gate(&self.coherence, threshold)
            .into_iter()
            .zip(&self.input_excited)
            .map(|(c, &e)| c && e && enough)
            .collect()
    }

    /// `Some(reason)` when the estimate averages fewer than [`MIN_WELCH_AVERAGES`] segments,
    /// so that [`Etfe::gate`] passes no bin.
    pub fn too_few_averages(&self) -> Option<String> {
        (self.n_averages < MIN_WELCH_AVERAGES).then(|| {
            format!(
                "only {} Welch segment(s) averaged: coherence from few averages is biased towards                  1 (identically 1 from one), so the gate needs at least {MIN_WELCH_AVERAGES}; no                  bin passes. Use a shorter --nperseg or a longer log",
                self.n_averages
            )
        })
    }

    /// Runs of bins rejected by [`Etfe::gate`], for reports.
    pub fn excluded_bands(&self, threshold: f64) -> Vec<ExcludedBand> {
        let gate = self.gate(threshold);
        let excited = &self.input_excited;
        bands_from_gate(&self.freq_hz, &self.coherence, &gate, excited)
    }
}

/// Input power below this fraction of the largest input auto-spectrum bin counts as "not
/// excited" in [`Etfe::gate`] (-100 dB; round-off leakage of a multisine sits near -150 dB).
pub const MIN_RELATIVE_INPUT_POWER: f64 = 1e-10;

fn excited_bins(suu: &[f64]) -> Vec<bool> {
    let top = suu.iter().cloned().fold(0.0, f64::max);
    suu.iter()
        .map(|&p| p > 0.0 && p >= MIN_RELATIVE_INPUT_POWER * top)
        .collect()
}

/// `true` where `coherence >= threshold` (NaN coherence is never accepted). The default
/// threshold is [`DEFAULT_COHERENCE_THRESHOLD`].
pub fn coherence_gate(coherence: &[f64], threshold: f64) -> Vec<bool> {
    coherence.iter().map(|&c| c >= threshold).collect()
}

/// A run of consecutive entries rejected by a gate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExcludedBand {
    /// Index of the first rejected entry.
    pub first: usize,
    /// Index of the last rejected entry (inclusive).
    pub last: usize,
    /// Frequency of the first entry in Hz.
    pub f_lo_hz: f64,
    /// Frequency of the last entry in Hz.
    pub f_hi_hz: f64,
    /// Lowest coherence in the run (NaN if any entry's coherence is NaN).
    pub min_coherence: f64,
    /// How many entries of the run were rejected because the input had no power there
    /// (see [`Etfe::gate`]); the others fell below the coherence threshold.
    pub unexcited: usize,
}

/// Runs of consecutive entries with `coherence < threshold` (or NaN), in increasing order.
/// `freq_hz` and `coherence` must have equal lengths (extra entries of the longer are ignored).
pub fn excluded_bands(freq_hz: &[f64], coherence: &[f64], threshold: f64) -> Vec<ExcludedBand> {
    let gate = coherence_gate(coherence, threshold);
    let all = vec![true; gate.len()];
    bands_from_gate(freq_hz, coherence, &gate, &all)
}

fn bands_from_gate(
    freq_hz: &[f64],
    coherence: &[f64],
    gate: &[bool],
    excited: &[bool],
) -> Vec<ExcludedBand> {
    let n = freq_hz.len().min(coherence.len()).min(gate.len());
    let mut out: Vec<ExcludedBand> = Vec::new();
    for k in 0..n {
        if gate[k] {
            continue;
        }
        let c = coherence[k];
        let unexcited = usize::from(!excited.get(k).copied().unwrap_or(true));
        match out.last_mut() {
            Some(b) if b.last + 1 == k => {
                b.last = k;
                b.f_hi_hz = freq_hz[k];
                b.min_coherence = if c.is_nan() || b.min_coherence.is_nan() {
                    f64::NAN
                } else {
                    b.min_coherence.min(c)
                };
                b.unexcited += unexcited;
            }
            _ => out.push(ExcludedBand {
                first: k,
                last: k,
                f_lo_hz: freq_hz[k],
                f_hi_hz: freq_hz[k],
                min_coherence: c,
                unexcited,
            }),
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Period-synchronous averaging
// ---------------------------------------------------------------------------------------------

/// Period-synchronous averaging settings for periodic excitation.
///
/// The record is cut into consecutive periods of `period` samples starting at sample
/// `skip_periods * period` (earlier periods are treated as transient); samples after the last
/// complete period are ignored. Each period's DFT is taken with a rectangular window, scaled by
/// `1/period` (a cosine of amplitude A on line k gives `|X[k]| = A/2`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PeriodicAveraging {
    /// Samples per period (>= 2).
    pub period: usize,
    /// Leading periods discarded as transient.
    pub skip_periods: usize,
    /// Use at most this many periods after the skipped ones (`None`: all complete periods).
    pub max_periods: Option<usize>,
    /// Line detection: a line k >= 1 is excited when `|Ū[k]|^2 >= min_relative_power *
    /// max_k |Ū[k]|^2` (default 1e-6, i.e. -60 dB) ...
    pub min_relative_power: f64,
    /// ... and `|Ū[k]|^2 >= min_snr * var(Ū[k])` (default 10; the variance of the mean from the
    /// spread over periods, so noise-only lines of a noisy measured input are rejected).
    pub min_snr: f64,
    /// Explicit excited lines (DFT bin indices 1..=period/2) instead of detection.
    pub lines: Option<Vec<usize>>,
}

impl PeriodicAveraging {
    /// Defaults: no skipped period, all periods, detection at -60 dB and SNR 10.
    pub fn new(period: usize) -> Self {
        Self {
            period,
            skip_periods: 0,
            max_periods: None,
            min_relative_power: 1e-6,
            min_snr: 10.0,
            lines: None,
        }
    }
}

/// Per-bin statistics over periods, for all one-sided bins `0..=period/2`.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodSpectra {
    /// Bin frequencies in Hz (`k * fs / period`).
    pub freq_hz: Vec<f64>,
    /// Mean input DFT over periods (scaled by 1/period).
    pub u: Vec<Complex64>,
    /// Mean output DFT over periods (scaled by 1/period).
    pub y: Vec<Complex64>,
    /// Noise variance of the mean `u` (sample variance over periods / n_periods).
    pub var_u: Vec<f64>,
    /// Noise variance of the mean `y` (sample variance over periods / n_periods).
    pub var_y: Vec<f64>,
    /// Noise covariance of the means, `cov(Ȳ, Ū) = E[(Ȳ - E Ȳ) conj(Ū - E Ū)]`.
    pub cov_yu: Vec<Complex64>,
}

/// Frequency response at the excited lines from period-synchronous averaging.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicFrf {
    /// Sample rate in Hz.
    pub fs: f64,
    /// Samples per period.
    pub period: usize,
    /// Periods averaged.
    pub n_periods: usize,
    /// Leading periods skipped as transient.
    pub skipped_periods: usize,
    /// Samples after the last complete period that were not used.
    pub unused_samples: usize,
    /// Excited lines (DFT bin indices into [`PeriodSpectra`]).
    pub lines: Vec<usize>,
    /// Frequencies of the excited lines in Hz.
    pub freq_hz: Vec<f64>,
    /// `H = Ȳ/Ū` at the excited lines.
    pub h: Vec<Complex64>,
    /// Noise variance of `H` (first-order propagation of the variances and covariance of the
    /// means: `|H|^2 (var_y/|Ȳ|^2 + var_u/|Ū|^2 - 2 Re(cov_yu / (Ȳ conj Ū)))`).
    pub var_h: Vec<f64>,
    /// Magnitude-squared coherence of the periods at each line (Welch with a rectangular window,
    /// one segment per period, no overlap): 1 for noise-free periodic data.
    pub coherence: Vec<f64>,
    /// Statistics of all bins (non-excited ones show noise and nonlinear distortion).
    pub spectra: PeriodSpectra,
}

impl PeriodicFrf {
    /// Lines usable for fitting/validation: `coherence >= threshold`.
    pub fn gate(&self, threshold: f64) -> Vec<bool> {
        coherence_gate(&self.coherence, threshold)
    }

    /// Runs of consecutive excited lines below the coherence threshold.
    pub fn excluded_bands(&self, threshold: f64) -> Vec<ExcludedBand> {
        excluded_bands(&self.freq_hz, &self.coherence, threshold)
    }
}

impl PeriodicAveraging {
    /// Period-synchronous FRF of `u` → `y` (equal lengths, finite) at `fs` Hz. Needs at least
    /// two periods after the skipped ones (the noise variance comes from their spread).
    ///
    /// The signals are normalised internally by exact powers of two ([`power_of_two_scale`])
    /// and the results scaled back, so the estimate does not depend on the signals' units.
    pub fn frf(&self, u: &[f64], y: &[f64], fs: f64) -> Result<PeriodicFrf> {
        let (gu, gy) = (
            power_of_two_scale(max_abs(u)),
            power_of_two_scale(max_abs(y)),
        );
        if gu == 1.0 && gy == 1.0 {
            return self.frf_unscaled(u, y, fs);
        }
        let us: Vec<f64> = u.iter().map(|v| v * gu).collect();
        let ys: Vec<f64> = y.iter().map(|v| v * gy).collect();
        let mut r = self.frf_unscaled(&us, &ys, fs)?;
        let gh = gu / gy;
        for h in &mut r.h {
            *h *= gh;
        }
        for v in &mut r.var_h {
            *v *= gh * gh;
        }
        let sp = &mut r.spectra;
        for z in &mut sp.u {
            *z /= gu;
        }
        for z in &mut sp.y {
            *z /= gy;
        }
        for v in &mut sp.var_u {
            *v = *v / gu / gu;
        }
        for v in &mut sp.var_y {
            *v = *v / gy / gy;
        }
        for z in &mut sp.cov_yu {
            *z = *z / gu / gy;
        }
        Ok(r)
    }

    fn frf_unscaled(&self, u: &[f64], y: &[f64], fs: f64) -> Result<PeriodicFrf> {
        let p = self.period;
        if p < 2 {
            return Err(Error::InvalidArgument(format!(
                "period must be >= 2 samples, got {p}"
            )));
        }
        check_fs(fs)?;
        if !(self.min_relative_power >= 0.0 && self.min_snr >= 0.0) {
            return Err(Error::InvalidArgument(
                "line-detection thresholds must be >= 0".into(),
            ));
        }
        if u.len() != y.len() {
            return Err(Error::InvalidArgument(format!(
                "input and output lengths differ: {} vs {}",
                u.len(),
                y.len()
            )));
        }
        let start = self.skip_periods.saturating_mul(p);
        let avail = u.len().saturating_sub(start) / p;
        let np = self.max_periods.map_or(avail, |m| m.min(avail));
        if np < 2 {
            return Err(Error::InvalidArgument(format!(
                "period-synchronous averaging needs at least 2 periods of {p} samples after \
                 skipping {}, the record of {} samples has {avail}",
                self.skip_periods,
                u.len()
            )));
        }
        let used = &u[start..start + np * p];
        let used_y = &y[start..start + np * p];
        check_signal(used, "input", p)?;
        check_signal(used_y, "output", p)?;
        let unused_samples = u.len() - start - np * p;

        let mut planner = RealFftPlanner::<f64>::new();
        let r2c = planner.plan_fft_forward(p);
        let mut buf = r2c.make_input_vec();
        let mut su = r2c.make_output_vec();
        let mut sy = r2c.make_output_vec();
        let mut scratch = r2c.make_scratch_vec();
        let nb = p / 2 + 1;
        let zero = Complex64::new(0.0, 0.0);
        let (mut mu, mut my) = (vec![zero; nb], vec![zero; nb]);
        let (mut m2u, mut m2y, mut cyu) = (vec![0.0; nb], vec![0.0; nb], vec![zero; nb]);
        let inv_p = 1.0 / p as f64;
        for q in 0..np {
            let r = q * p..(q + 1) * p;
            buf.copy_from_slice(&used[r.clone()]);
            fft(&r2c, &mut buf, &mut su, &mut scratch)?;
            buf.copy_from_slice(&used_y[r]);
            fft(&r2c, &mut buf, &mut sy, &mut scratch)?;
            // Welford updates (numerically stable mean, variance and co-moment).
            let cnt = (q + 1) as f64;
            for k in 0..nb {
                let (a, b) = (su[k] * inv_p, sy[k] * inv_p);
                let du = a - mu[k];
                let dy = b - my[k];
                mu[k] += du / cnt;
                my[k] += dy / cnt;
                let du_new = a - mu[k];
                m2u[k] += (du * du_new.conj()).re;
                m2y[k] += (dy * (b - my[k]).conj()).re;
                cyu[k] += dy * du_new.conj();
            }
        }
        let npf = np as f64;
        // Variance of the mean = sample variance / n_periods.
        let denom = (npf - 1.0) * npf;
        let var_u: Vec<f64> = m2u.iter().map(|v| v / denom).collect();
        let var_y: Vec<f64> = m2y.iter().map(|v| v / denom).collect();
        let cov_yu: Vec<Complex64> = cyu.iter().map(|v| v / denom).collect();

        let lines: Vec<usize> = match &self.lines {
            Some(l) => {
                if let Some(&bad) = l.iter().find(|&&k| k == 0 || k >= nb) {
                    return Err(Error::InvalidArgument(format!(
                        "excited line {bad} outside 1..={}",
                        nb - 1
                    )));
                }
                let mut l = l.clone();
                l.sort_unstable();
                l.dedup();
                l
            }
            None => {
                let pmax = mu[1..].iter().map(|z| z.norm_sqr()).fold(0.0_f64, f64::max);
                (1..nb)
                    .filter(|&k| {
                        let pk = mu[k].norm_sqr();
                        pk > 0.0
                            && pk >= self.min_relative_power * pmax
                            && pk >= self.min_snr * var_u[k]
                    })
                    .collect()
            }
        };
        if lines.is_empty() {
            return Err(Error::Data {
                file: "<signal>".into(),
                msg: format!(
                    "no excited lines found: is the input periodic with period {p} samples?"
                ),
            });
        }
        let mut h = Vec::with_capacity(lines.len());
        let mut var_h = Vec::with_capacity(lines.len());
        let mut coherence = Vec::with_capacity(lines.len());
        for &k in &lines {
            let (uk, yk) = (mu[k], my[k]);
            if uk.norm_sqr() == 0.0 {
                h.push(Complex64::new(f64::NAN, f64::NAN));
                var_h.push(f64::NAN);
                coherence.push(0.0);
                continue;
            }
            let hk = yk / uk;
            let vh = if yk.norm_sqr() > 0.0 {
                hk.norm_sqr()
                    * (var_y[k] / yk.norm_sqr() + var_u[k] / uk.norm_sqr()
                        - 2.0 * (cov_yu[k] / (yk * uk.conj())).re)
            } else {
                // H = 0: dH = dY / U.
                var_y[k] / uk.norm_sqr()
            }
            .max(0.0);
            // Coherence of the periods from the sums of products:
            // sum conj(U_q) Y_q = (n-1) n cov* + n conj(Ū) Ȳ, etc. (all / n).
            let cross = cov_yu[k] * (npf - 1.0) + yk * uk.conj();
            let puu = var_u[k] * (npf - 1.0) + uk.norm_sqr();
            let pyy = var_y[k] * (npf - 1.0) + yk.norm_sqr();
            let coh = if puu > 0.0 && pyy > 0.0 {
                (cross.norm_sqr() / (puu * pyy)).min(1.0)
            } else {
                0.0
            };
            h.push(hk);
            var_h.push(vh);
            coherence.push(coh);
        }
        let freq_all: Vec<f64> = (0..nb).map(|k| bin_hz(k, p, fs)).collect();
        Ok(PeriodicFrf {
            fs,
            period: p,
            n_periods: np,
            skipped_periods: self.skip_periods,
            unused_samples,
            freq_hz: lines.iter().map(|&k| freq_all[k]).collect(),
            lines,
            h,
            var_h,
            coherence,
            spectra: PeriodSpectra {
                freq_hz: freq_all,
                u: mu,
                y: my,
                var_u,
                var_y,
                cov_yu,
            },
        })
    }

    /// Period-synchronous FRF for channels `input` → `output` of a log; errors name the file.
    pub fn frf_log(&self, log: &Log, input: usize, output: usize) -> Result<PeriodicFrf> {
        let (u, y) = pair(log, input, output)?;
        let need = self
            .period
            .saturating_mul(self.skip_periods.saturating_add(2));
        require_len(
            log,
            need,
            &format!(
                "period-synchronous averaging (2 periods of {} samples after skipping {})",
                self.period, self.skip_periods
            ),
        )?;
        self.frf(u, y, log.fs()).map_err(|e| match e {
            Error::Data { msg, .. } => Error::Data {
                file: log.path.clone(),
                msg,
            },
            other => other,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

fn pair(log: &Log, input: usize, output: usize) -> Result<(&[f64], &[f64])> {
    let u = log.inputs.get(input).ok_or_else(|| {
        Error::InvalidArgument(format!(
            "{}: input index {input} out of range ({} inputs)",
            log.path.display(),
            log.inputs.len()
        ))
    })?;
    let y = log.outputs.get(output).ok_or_else(|| {
        Error::InvalidArgument(format!(
            "{}: output index {output} out of range ({} outputs)",
            log.path.display(),
            log.outputs.len()
        ))
    })?;
    Ok((&u.data, &y.data))
}

fn check_fs(fs: f64) -> Result<()> {
    if !(fs.is_finite() && fs > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "sample rate must be finite and > 0 Hz, got {fs}"
        )));
    }
    Ok(())
}

fn check_signal(x: &[f64], what: &str, min_len: usize) -> Result<()> {
    if x.len() < min_len {
        return Err(Error::InvalidArgument(format!(
            "{what} has {} samples, fewer than the {min_len} the analysis needs",
            x.len()
        )));
    }
    if let Some(k) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::InvalidArgument(format!(
            "{what} sample {k} is not finite ({})",
            x[k]
        )));
    }
    Ok(())
}

/// `k * fs / n` (Hz), computed as numpy's `rfftfreq` does.
fn bin_hz(k: usize, n: usize, fs: f64) -> f64 {
    k as f64 * (1.0 / (n as f64 / fs))
}

/// One-sided doubling: DC and (for even n) Nyquist are not doubled.
fn one_sided_factor(k: usize, n: usize) -> f64 {
    if k == 0 || (n.is_multiple_of(2) && k == n / 2) {
        1.0
    } else {
        2.0
    }
}

/// Copies a segment into `out`, detrends it and applies the window.
fn prepare(seg: &[f64], win: &[f64], detrend: Detrend, out: &mut [f64]) {
    let n = seg.len();
    match detrend {
        Detrend::None => {
            for ((o, &x), &w) in out.iter_mut().zip(seg).zip(win) {
                *o = x * w;
            }
        }
        Detrend::Constant => {
            let mean = seg.iter().sum::<f64>() / n as f64;
            for ((o, &x), &w) in out.iter_mut().zip(seg).zip(win) {
                *o = (x - mean) * w;
            }
        }
        Detrend::Linear => {
            // Least-squares line over t = 0..n-1, centred at tc = (n-1)/2.
            let nf = n as f64;
            let tc = (nf - 1.0) / 2.0;
            let mean = seg.iter().sum::<f64>() / nf;
            let (mut sxt, mut stt) = (0.0, 0.0);
            for (i, &x) in seg.iter().enumerate() {
                let t = i as f64 - tc;
                sxt += t * (x - mean);
                stt += t * t;
            }
            let slope = if stt > 0.0 { sxt / stt } else { 0.0 };
            for (i, ((o, &x), &w)) in out.iter_mut().zip(seg).zip(win).enumerate() {
                *o = (x - mean - slope * (i as f64 - tc)) * w;
            }
        }
    }
}

fn fft(
    r2c: &Arc<dyn RealToComplex<f64>>,
    buf: &mut [f64],
    out: &mut [Complex64],
    scratch: &mut [Complex64],
) -> Result<()> {
    r2c.process_with_scratch(buf, out, scratch)
        .map_err(|e| Error::Numerical(format!("FFT failed: {e}")))
}
