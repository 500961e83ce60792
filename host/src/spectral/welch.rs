//! Welch averaging: H1, coherence and PSD from windowed, overlapped segments (scipy's
//! conventions; see the [parent module](super)).
use num_complex::Complex64;
use realfft::{RealFftPlanner, RealToComplex};
use serde::Serialize;
use std::sync::Arc;

use super::{
    bands_from_gate, bin_hz, check_fs, check_signal, coherence_gate, fft, max_abs,
    one_sided_factor, pair, power_of_two_scale, Detrend, ExcludedBand, Window, MAX_NPERSEG,
    MIN_NPERSEG, MIN_WELCH_AVERAGES,
};
use crate::data::Log;
use crate::error::{Error, Result};
use crate::io::require_len;

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
