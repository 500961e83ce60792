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

mod periodic;
mod welch;

pub use periodic::{PeriodSpectra, PeriodicAveraging, PeriodicFrf};
pub use welch::{Etfe, Psd, Welch, WelchAccumulator, MIN_RELATIVE_INPUT_POWER};

use num_complex::Complex64;
use realfft::RealToComplex;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

use crate::data::Log;
use crate::error::{Error, Result};

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
fn fft(
    r2c: &Arc<dyn RealToComplex<f64>>,
    buf: &mut [f64],
    out: &mut [Complex64],
    scratch: &mut [Complex64],
) -> Result<()> {
    r2c.process_with_scratch(buf, out, scratch)
        .map_err(|e| Error::Numerical(format!("FFT failed: {e}")))
}
