//! Streaming Welch estimator of auto/cross spectra, H1 frequency response and
//! magnitude-squared coherence, in memory fixed at compile time.
//!
//! # Conventions (those of `scipy.signal.csd`, `welch` and `coherence`)
//! For each segment of `N` samples (hop `N - overlap`), optionally minus its mean
//! (`detrend='constant'`), times the window `w`, with `U[k] = Σ_n w[n](u[n] - ū) e^{-j2πkn/N}`
//! and `Y[k]` likewise, the estimates are means over all accepted segments:
//! * `S_uu[k] = c_k · mean |U[k]|²`, `S_yy[k] = c_k · mean |Y[k]|²`,
//! * `S_uy[k] = c_k · mean conj(U[k])·Y[k]` (scipy's `csd(u, y)`: `Pxy = conj(X)·Y`),
//! * density scaling `c_k = 1 / (fs · Σ w²)`, doubled for the one-sided spectrum except at DC
//!   (`k = 0`) and Nyquist (`k = N/2`). Units: `signal² / Hz`.
//!
//! `H1[k] = S_uy[k] / S_uu[k]`: with the `conj(U)·Y` convention this is `mean(conj(U) Y) /
//! mean(|U|²)`, i.e. the least-squares estimate of the plant's frequency response `Y/U` (from
//! `u` to `y`), unbiased with respect to noise on `y`. (Bendat & Piersol write the same quantity
//! `G_xy / G_xx` and some texts `S_yu / S_uu`; all mean "output over input".)
//!
//! `γ²[k] = |S_uy|² / (S_uu · S_yy)` in `[0, 1]` (scaling cancels).
//!
//! # Statistics of the coherence estimate (document, not test, of what to expect)
//! With `n_d` independent averages (non-overlapping segments; with 50 % overlapped Hann
//! segments use `n_d ≈ n_avg / 1.06`, Welch 1967):
//! * It is biased upwards: one average gives exactly 1 in every bin, whatever the signals. For
//!   uncorrelated Gaussian `u`, `y`, `γ̂²` follows Beta(1, n_d - 1): `E[γ̂²] = 1/n_d`, and
//!   `P(γ̂² > t) = (1 - t)^(n_d - 1)`, so a gate at `t` lets through noise bins with that
//!   probability (e.g. `n_d = 32`, `t = 0.3`: 1.6e-5).
//! * For true coherence `γ²`, bias `≈ (1 - γ²)² / n_d` and normalised random error
//!   `≈ √2 (1 - γ²) / (|γ| √n_d)` (Bendat & Piersol, *Random Data*, 4th ed., Sec. 9.2.3).
//! * The normalised random error of `|H1|` is `≈ √(1 - γ²) / (|γ| √(2 n_d))`.
//!
//! # Robustness
//! A sample pair with a NaN or ±inf, or with `u² + y² >` [`MAX_ABS_SAMPLE`]`²`, is counted in
//! [`Welch::nonfinite_samples`], stored as 0, and every segment that contains it is dropped
//! (counted in [`Welch::dropped_segments`]), never accumulated. The accumulators are sums over at
//! most [`MAX_AVERAGES`] segments (later segments are not accumulated: the estimate is frozen,
//! which at `N = 1024`, 50 % overlap, takes 8.6e9 samples). With the sample bound this keeps every
//! intermediate (segment sums, FFT, squares, accumulated sums, scaled outputs for `fs >= 1e-6`
//! Hz) finite, so all outputs are finite for any input sequence.
//!
//! # Memory and speed
//! `size_of::<Welch<N>>() = 24·N + 64` bytes (history `u`, `y`; FFT buffers `U`, `Y`;
//! accumulators `S_uu`, `S_yy`, `S_uy`), nothing else: the window is a `const` table in flash.
//! `push` stores a sample pair and decrements a counter; every hop one segment is windowed, two
//! real FFTs (microfft) run, and the `N/2 + 1` bins are accumulated without divisions or `libm`.
//! [`Welch::push_slice`] is the faster entry point (the range check and copy run over contiguous
//! runs of samples, the counters stay in registers).

use microfft::Complex32;

use crate::fft;
use crate::gate::CoherenceGate;
use crate::window::{HannTable, Window};
use crate::Error;

/// Bound on the input: a sample pair is accepted when `u² + y² <= MAX_ABS_SAMPLE²` (see
/// [`accepts`]); other pairs (including NaN and ±inf) are counted and their segments dropped.
/// With [`MAX_AVERAGES`] it leaves every intermediate finite in `f32` for `N <= 4096`: a
/// segment's `|U[k]|² <= (2·1e11·N)² = 6.7e29`, times `2^24` segments `< 1.2e37`.
pub const MAX_ABS_SAMPLE: f32 = 1.0e11;
/// Segments accumulated at most (`2^24`); later segments are not accumulated (and beyond this
/// count an `f32` sum could not resolve one more segment anyway).
pub const MAX_AVERAGES: u32 = 1 << 24;
/// Smallest accepted sample rate (Hz).
pub const MIN_FS_HZ: f32 = 1.0e-6;
/// Largest accepted sample rate (Hz).
pub const MAX_FS_HZ: f32 = 1.0e12;

/// Configuration of a [`Welch`] estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WelchConfig {
    /// Sample rate `fs` (Hz), in `[1e-6, 1e12]`.
    pub fs_hz: f32,
    /// Samples shared by consecutive segments, `0 <= overlap < N` (scipy's `noverlap`);
    /// hop = `N - overlap`. Default `N/2`.
    pub overlap: usize,
    /// Segment window (default Hann).
    pub window: Window,
    /// Subtract each segment's mean before windowing (scipy's `detrend='constant'`, default).
    pub detrend_mean: bool,
}

impl WelchConfig {
    /// scipy's defaults for segment length `n`: Hann, overlap `n/2`, mean removal.
    pub const fn scipy_default(fs_hz: f32, n: usize) -> Self {
        Self {
            fs_hz,
            overlap: n / 2,
            window: Window::Hann,
            detrend_mean: true,
        }
    }
}

/// Streaming Welch estimator over segments of `N` samples (power of two, `64..=4096`, checked at
/// compile time). See the [module documentation](self) for conventions, statistics and costs.
pub struct Welch<const N: usize> {
    cfg: WelchConfig,
    /// Density scaling `1 / (fs Σw²)`.
    density: f32,
    hop: u32,
    /// Next write index into the histories (= oldest sample once they are full).
    pos: usize,
    /// Samples still to push before the next segment ends.
    until_segment: u32,
    /// Number of upcoming segment ends to drop (they contain a rejected sample).
    drop_ends: u32,
    averages: u32,
    dropped: u32,
    nonfinite: u32,
    /// `Σ |U[N/2]|²`, `Σ |Y[N/2]|²` (Nyquist; `acc` holds bins `0..N/2`).
    nyq_uu: f32,
    nyq_yy: f32,
    u_hist: [f32; N],
    y_hist: [f32; N],
    u_buf: [f32; N],
    y_buf: [f32; N],
    /// Unscaled sums over segments, four per bin `k = 0..N/2`:
    /// `acc[2k] = [Σ|U[k]|², Σ|Y[k]|²]`, `acc[2k+1] = [Σ Re conj(U[k])Y[k], Σ Im conj(U[k])Y[k]]`.
    /// The imaginary cross part of DC is identically 0, so `acc[1][1]` holds the (real)
    /// Nyquist cross sum `Σ U[N/2]·Y[N/2]` (microfft-style packing).
    acc: [[f32; 2]; N],
}

impl<const N: usize> Welch<N> {
    /// Compile-time check of `N`.
    const VALID_N: () = assert!(
        fft::is_supported_len(N),
        "Welch<N>: N must be a power of two in 64..=4096"
    );

    /// scipy's defaults for this `N` at sample rate `fs_hz` (see [`WelchConfig::scipy_default`]).
    pub const fn default_config(fs_hz: f32) -> WelchConfig {
        WelchConfig::scipy_default(fs_hz, N)
    }

    /// An estimator in the all-zero state, to be set up with [`Welch::configure`].
    ///
    /// This is the way to place a `Welch` in a `static` without costing flash: every field is
    /// zero, so `static mut W: Welch<1024> = Welch::unconfigured();` lands in `.bss`. (A static
    /// initialised from [`Welch::new`], or an `Option<Welch<N>>` such as
    /// `cortex_m::singleton!` uses, has non-zero bytes and goes to `.data`, i.e. its 24·N bytes
    /// are also stored in flash.) Until configured, `push` stores samples but never completes a
    /// segment, and every estimate reads as 0 / `None`.
    pub const fn unconfigured() -> Self {
        let () = Self::VALID_N;
        Self {
            cfg: WelchConfig {
                fs_hz: 0.0,
                overlap: 0,
                window: Window::Hann,
                detrend_mean: false,
            },
            density: 0.0,
            hop: 0,
            pos: 0,
            until_segment: 0,
            drop_ends: 0,
            averages: 0,
            dropped: 0,
            nonfinite: 0,
            nyq_uu: 0.0,
            nyq_yy: 0.0,
            u_hist: [0.0; N],
            y_hist: [0.0; N],
            u_buf: [0.0; N],
            y_buf: [0.0; N],
            acc: [[0.0; 2]; N],
        }
    }

    /// `true` once a valid configuration is in place ([`Welch::new`] or [`Welch::configure`]).
    pub fn is_configured(&self) -> bool {
        self.hop != 0
    }

    /// New estimator with empty accumulators. `const`; see [`Welch::unconfigured`] for statics.
    ///
    /// # Errors
    /// [`Error::InvalidSampleRate`] (`fs_hz` not finite or outside `[1e-6, 1e12]`),
    /// [`Error::InvalidOverlap`] (`overlap >= N`).
    pub const fn new(cfg: WelchConfig) -> Result<Self, Error> {
        let () = Self::VALID_N;
        let density = match density_scale::<N>(&cfg) {
            Ok(d) => d,
            Err(e) => return Err(e),
        };
        Ok(Self {
            cfg,
            density,
            hop: (N - cfg.overlap) as u32,
            pos: 0,
            until_segment: N as u32,
            drop_ends: 0,
            averages: 0,
            dropped: 0,
            nonfinite: 0,
            nyq_uu: 0.0,
            nyq_yy: 0.0,
            u_hist: [0.0; N],
            y_hist: [0.0; N],
            u_buf: [0.0; N],
            y_buf: [0.0; N],
            acc: [[0.0; 2]; N],
        })
    }

    /// Changes the configuration in place and [`reset`](Self::reset)s; on error nothing changes.
    ///
    /// # Errors
    /// As [`Welch::new`].
    pub fn configure(&mut self, cfg: WelchConfig) -> Result<(), Error> {
        self.density = density_scale::<N>(&cfg)?;
        self.cfg = cfg;
        self.hop = (N - cfg.overlap) as u32;
        self.reset();
        Ok(())
    }

    /// Forgets all samples, averages and counters (the configuration stays).
    pub fn reset(&mut self) {
        self.pos = 0;
        self.until_segment = if self.hop == 0 { 0 } else { N as u32 };
        self.drop_ends = 0;
        self.averages = 0;
        self.dropped = 0;
        self.nonfinite = 0;
        self.nyq_uu = 0.0;
        self.nyq_yy = 0.0;
        self.u_hist.fill(0.0);
        self.y_hist.fill(0.0);
        self.acc.fill([0.0; 2]);
    }

    /// Adds one input/output sample pair (signal units). Never panics.
    ///
    /// Every `N - overlap` samples (first after `N`) a segment is complete and accumulated, or
    /// dropped if it contains a rejected sample pair (see [`accepts`]).
    #[inline]
    pub fn push(&mut self, u: f32, y: f32) {
        let i = self.pos & (N - 1);
        if accepts(u, y) {
            self.u_hist[i] = u;
            self.y_hist[i] = y;
        } else {
            self.u_hist[i] = 0.0;
            self.y_hist[i] = 0.0;
            self.reject(self.until_segment);
        }
        self.pos = (i + 1) & (N - 1);
        self.until_segment = self.until_segment.wrapping_sub(1);
        if self.until_segment == 0 {
            self.segment_end();
        }
    }

    /// Books a rejected sample pair; `r` = samples until the next segment end, counting the
    /// rejected one (`1..=N`). The segment ends that contain it are the next one (after `r - 1`
    /// more samples) and every hop after it, up to `N - 1` samples ahead:
    /// `(N - r) / hop + 1` ends.
    #[cold]
    fn reject(&mut self, r: u32) {
        self.nonfinite = self.nonfinite.saturating_add(1);
        let r = r.clamp(1, N as u32);
        let ends = (N as u32 - r) / self.hop.max(1) + 1;
        self.drop_ends = self.drop_ends.max(ends);
    }

    /// A segment ends with the sample just stored.
    fn segment_end(&mut self) {
        self.until_segment = self.hop;
        if self.hop == 0 {
            // Unconfigured: never complete a segment.
            return;
        }
        if self.drop_ends > 0 {
            self.drop_ends -= 1;
            self.dropped = self.dropped.saturating_add(1);
        } else if self.averages < MAX_AVERAGES {
            self.process_segment();
        }
    }

    /// Adds equal-length slices of input and output samples; same result as calling
    /// [`Welch::push`] for each pair, faster.
    ///
    /// # Errors
    /// [`Error::LengthMismatch`] when `u.len() != y.len()`; no sample is consumed then.
    pub fn push_slice(&mut self, u: &[f32], y: &[f32]) -> Result<(), Error> {
        if u.len() != y.len() {
            return Err(Error::LengthMismatch {
                u: u.len(),
                y: y.len(),
            });
        }
        let (mut u, mut y) = (u, y);
        while !u.is_empty() {
            let pos = self.pos & (N - 1);
            // A run ends at the next segment end, at the ring's wrap, or with the input.
            let run = u.len().min(self.until_segment as usize).min(N - pos).max(1);
            let (Some((u_run, u_rest)), Some((y_run, y_rest))) =
                (u.split_at_checked(run), y.split_at_checked(run))
            else {
                break;
            };
            let (Some(hu), Some(hy)) = (
                self.u_hist.get_mut(pos..pos + run),
                self.y_hist.get_mut(pos..pos + run),
            ) else {
                break;
            };
            if !store_run(hu, hy, u_run, y_run) {
                // Cold: find the rejected pairs again to book them.
                let until = self.until_segment;
                for (j, (&a, &b)) in u_run.iter().zip(y_run).enumerate() {
                    if !accepts(a, b) {
                        self.reject(until.wrapping_sub(j as u32));
                    }
                }
            }
            self.pos = (pos + run) & (N - 1);
            self.until_segment = self.until_segment.wrapping_sub(run as u32);
            if self.until_segment == 0 {
                self.segment_end();
            }
            (u, y) = (u_rest, y_rest);
        }
        Ok(())
    }

    /// Windows the latest `N` samples, transforms them and adds them to the sums.
    fn process_segment(&mut self) {
        let start = self.pos & (N - 1);
        let (mu, my) = if self.cfg.detrend_mean {
            (mean(&self.u_hist), mean(&self.y_hist))
        } else {
            (0.0, 0.0)
        };
        match self.cfg.window {
            Window::Hann => {
                let w: &[f32; N] = &HannTable::<N>::TABLE;
                windowed(&mut self.u_buf, &self.u_hist, start, mu, w);
                windowed(&mut self.y_buf, &self.y_hist, start, my, w);
            }
            Window::Rectangular => {
                centred(&mut self.u_buf, &self.u_hist, start, mu);
                centred(&mut self.y_buf, &self.y_hist, start, my);
            }
        }
        let us = fft::rfft(&mut self.u_buf);
        let ys = fft::rfft(&mut self.y_buf);
        let (Some(u0), Some(y0)) = (us.first().copied(), ys.first().copied()) else {
            return;
        };
        accumulate(&mut self.acc, us, ys);
        // DC (re) and Nyquist (packed in im) are real.
        if let [dc_auto, dc_cross, ..] = &mut self.acc[..] {
            dc_auto[0] += u0.re * u0.re;
            dc_auto[1] += y0.re * y0.re;
            dc_cross[0] += u0.re * y0.re;
            dc_cross[1] += u0.im * y0.im;
        }
        self.nyq_uu += u0.im * u0.im;
        self.nyq_yy += y0.im * y0.im;
        self.averages += 1;
    }

    /// Unscaled sums `(Σ|U|², Σ|Y|², Σ Re conj(U)Y, Σ Im conj(U)Y)` of bin `k`, `None` if
    /// `k > N/2`.
    #[inline]
    fn raw(&self, k: usize) -> Option<(f32, f32, f32, f32)> {
        if k < N / 2 {
            let a = self.acc.get(2 * k)?;
            let c = self.acc.get(2 * k + 1)?;
            // DC's imaginary cross slot holds the Nyquist cross sum.
            let im = if k == 0 { 0.0 } else { c[1] };
            Some((a[0], a[1], c[0], im))
        } else if k == N / 2 {
            Some((self.nyq_uu, self.nyq_yy, self.acc.get(1)?[1], 0.0))
        } else {
            None
        }
    }

    /// Scaling of the sums of bin `k`: density over the number of averages, doubled except at
    /// DC and Nyquist; 0 before the first average.
    #[inline]
    fn scale(&self, k: usize) -> f32 {
        if self.averages == 0 {
            return 0.0;
        }
        let s = self.density / self.averages as f32;
        if k == 0 || k == N / 2 {
            s
        } else {
            2.0 * s
        }
    }

    /// The configuration.
    pub fn config(&self) -> &WelchConfig {
        &self.cfg
    }

    /// Segment length `N` (samples).
    pub const fn segment_len(&self) -> usize {
        N
    }

    /// Hop between segment starts, `N - overlap` (samples).
    pub fn hop(&self) -> usize {
        self.hop as usize
    }

    /// Number of segments accumulated so far (dropped ones excluded).
    pub fn averages(&self) -> u32 {
        self.averages
    }

    /// Number of segments dropped because they contained a rejected sample.
    pub fn dropped_segments(&self) -> u32 {
        self.dropped
    }

    /// Number of rejected sample pairs (NaN or ±inf in `u` or `y`, or `u² + y² >
    /// MAX_ABS_SAMPLE²`, see [`accepts`]).
    pub fn nonfinite_samples(&self) -> u32 {
        self.nonfinite
    }

    /// Number of frequency bins, `N/2 + 1` (DC to Nyquist).
    pub const fn bins(&self) -> usize {
        N / 2 + 1
    }

    /// Frequency of bin `k` (Hz): `k·fs/N`.
    pub fn bin_hz(&self, k: usize) -> f32 {
        k as f32 * (self.cfg.fs_hz / N as f32)
    }

    /// One-sided auto-spectral density of `u` at bin `k` (`signal²/Hz`); 0 for `k >= bins()`
    /// or before the first average.
    pub fn suu(&self, k: usize) -> f32 {
        self.raw(k).map_or(0.0, |r| r.0 * self.scale(k))
    }

    /// One-sided auto-spectral density of `y` at bin `k` (`signal²/Hz`); 0 when undefined.
    pub fn syy(&self, k: usize) -> f32 {
        self.raw(k).map_or(0.0, |r| r.1 * self.scale(k))
    }

    /// One-sided cross-spectral density `S_uy = c·mean conj(U)·Y` at bin `k` as `(re, im)`
    /// (`signal_u·signal_y/Hz`); `(0, 0)` when undefined.
    pub fn suy(&self, k: usize) -> (f32, f32) {
        self.raw(k).map_or((0.0, 0.0), |r| {
            let s = self.scale(k);
            (r.2 * s, r.3 * s)
        })
    }

    /// H1 estimate `S_uy/S_uu` of the frequency response from `u` to `y` at bin `k`, as
    /// `(re, im)` (units of `y/u`). `None` before the first average, for `k >= bins()`, when
    /// `S_uu[k] == 0`, or if the ratio is not representable in `f32`.
    pub fn h1(&self, k: usize) -> Option<(f32, f32)> {
        if self.averages == 0 {
            return None;
        }
        let (uu, _, re, im) = self.raw(k)?;
        if uu.is_nan() || uu <= 0.0 {
            return None;
        }
        let inv = 1.0 / uu;
        let h = (re * inv, im * inv);
        (h.0.is_finite() && h.1.is_finite()).then_some(h)
    }

    /// Magnitude-squared coherence `|S_uy|²/(S_uu S_yy)` at bin `k`, in `[0, 1]`. 0 when
    /// undefined (no average, `k >= bins()`, `S_uu` or `S_yy` zero or below the normal `f32`
    /// range). Exactly 1 after a single average (see the module docs on bias).
    pub fn coherence(&self, k: usize) -> f32 {
        if self.averages == 0 {
            return 0.0;
        }
        match self.raw(k) {
            Some((uu, yy, re, im)) => msc(uu, yy, re, im),
            None => 0.0,
        }
    }

    /// Bins with coherence `>= threshold` (all bins fail for a NaN threshold or before the
    /// first average). Mind the bias with few averages (module docs): the threshold should
    /// exceed the noise-only level, e.g. `P(γ̂² > t) = (1 - t)^(n_d - 1)`.
    pub fn gate(&self, threshold: f32) -> CoherenceGate {
        let mut g = CoherenceGate::empty(self.bins());
        if self.averages == 0 {
            return g;
        }
        for k in 0..self.bins() {
            if self.coherence(k) >= threshold {
                g.set(k);
            }
        }
        g
    }
}

/// Validates `cfg` for segment length `N` and returns the density scale `1/(fs Σw²)`.
const fn density_scale<const N: usize>(cfg: &WelchConfig) -> Result<f32, Error> {
    let fs = cfg.fs_hz;
    if !(fs.is_finite() && fs >= MIN_FS_HZ && fs <= MAX_FS_HZ) {
        return Err(Error::InvalidSampleRate);
    }
    if cfg.overlap >= N {
        return Err(Error::InvalidOverlap);
    }
    Ok(1.0 / (fs * cfg.window.sum_squares::<N>()))
}

/// `MAX_ABS_SAMPLE²` as the acceptance bound of `u² + y²`.
const MAX_NORM_SQ: f32 = MAX_ABS_SAMPLE * MAX_ABS_SAMPLE;

/// The acceptance test of a sample pair: `u² + y² <= MAX_ABS_SAMPLE²` evaluated in `f32`
/// (false for NaN and ±inf; implies `|u|, |y| <= MAX_ABS_SAMPLE`). Two multiplies, one add and
/// one compare, cheaper than two `abs` compares on a Cortex-M4F.
#[inline(always)]
pub fn accepts(u: f32, y: f32) -> bool {
    u * u + y * y <= MAX_NORM_SQ
}

/// Copies a run of sample pairs into the histories; rejected pairs (see [`accepts`]) are
/// replaced by 0. Returns `false` if any pair was rejected.
///
/// Fast path: copy and sum `u² + y²` over the run; if the sum passes the bound, every pair
/// does (the terms are non-negative and `f32` rounding is monotone). Otherwise a second pass
/// applies the exact per-pair test.
#[inline(never)]
fn store_run(hu: &mut [f32], hy: &mut [f32], u: &[f32], y: &[f32]) -> bool {
    let mut sum = 0.0f32;
    for (((du, dy), &a), &b) in hu.iter_mut().zip(hy.iter_mut()).zip(u).zip(y) {
        *du = a;
        *dy = b;
        sum += a * a + b * b;
    }
    if sum <= MAX_NORM_SQ {
        return true;
    }
    let mut all_ok = true;
    for (du, dy) in hu.iter_mut().zip(hy.iter_mut()) {
        if !accepts(*du, *dy) {
            *du = 0.0;
            *dy = 0.0;
            all_ok = false;
        }
    }
    all_ok
}

/// Adds one bin's products: `b[0] += [|U|², |Y|²]`, `b[1] += conj(U)·Y`.
#[inline(always)]
fn accumulate_bin(b: &mut [[f32; 2]; 2], u: &Complex32, y: &Complex32) {
    b[0][0] += u.re * u.re + u.im * u.im;
    b[0][1] += y.re * y.re + y.im * y.im;
    b[1][0] += u.re * y.re + u.im * y.im;
    b[1][1] += u.re * y.im - u.im * y.re;
}

/// Adds one segment's products to the sums of bins `1..N/2` (see `Welch::acc` for the layout).
/// Not inlined, so that the three streams get their own pointer registers; two bins per
/// iteration to halve the loop overhead.
#[inline(never)]
fn accumulate(acc: &mut [[f32; 2]], us: &[Complex32], ys: &[Complex32]) {
    let (bins, _) = acc.as_chunks_mut::<2>();
    let (Some(bins), Some(us), Some(ys)) = (bins.get_mut(1..), us.get(1..), ys.get(1..)) else {
        return;
    };
    let (b2, b_rest) = bins.as_chunks_mut::<2>();
    let (u2, u_rest) = us.as_chunks::<2>();
    let (y2, y_rest) = ys.as_chunks::<2>();
    for ((b, u), y) in b2.iter_mut().zip(u2).zip(y2) {
        let [b0, b1] = b;
        accumulate_bin(b0, &u[0], &y[0]);
        accumulate_bin(b1, &u[1], &y[1]);
    }
    for ((b, u), y) in b_rest.iter_mut().zip(u_rest).zip(y_rest) {
        accumulate_bin(b, u, y);
    }
}

/// Mean of a segment (4 partial sums: shorter dependency chains, smaller rounding error).
#[inline]
fn mean<const N: usize>(x: &[f32; N]) -> f32 {
    let (chunks, rest) = x.as_chunks::<4>();
    let mut acc = [0.0f32; 4];
    for c in chunks {
        acc[0] += c[0];
        acc[1] += c[1];
        acc[2] += c[2];
        acc[3] += c[3];
    }
    let tail: f32 = rest.iter().sum();
    ((acc[0] + acc[1]) + (acc[2] + acc[3]) + tail) * (1.0 / N as f32)
}

/// `dst[n] = (x[n] - mu)·w[n]` with `x` the ring `ring` read in time order from `start`.
#[inline(never)]
fn windowed<const N: usize>(
    dst: &mut [f32; N],
    ring: &[f32; N],
    start: usize,
    mu: f32,
    w: &[f32; N],
) {
    let (newest, oldest) = ring.split_at(start.min(N));
    let (d1, d2) = dst.split_at_mut(N - start.min(N));
    let (w1, w2) = w.split_at(N - start.min(N));
    for ((d, &x), &w) in d1.iter_mut().zip(oldest).zip(w1) {
        *d = (x - mu) * w;
    }
    for ((d, &x), &w) in d2.iter_mut().zip(newest).zip(w2) {
        *d = (x - mu) * w;
    }
}

/// `dst[n] = x[n] - mu` (rectangular window) with the ring read in time order from `start`.
#[inline(never)]
fn centred<const N: usize>(dst: &mut [f32; N], ring: &[f32; N], start: usize, mu: f32) {
    let (newest, oldest) = ring.split_at(start.min(N));
    let (d1, d2) = dst.split_at_mut(N - start.min(N));
    for (d, &x) in d1.iter_mut().zip(oldest) {
        *d = x - mu;
    }
    for (d, &x) in d2.iter_mut().zip(newest) {
        *d = x - mu;
    }
}

/// `(re² + im²)/(uu·yy)` computed after normalising by `max(uu, yy)` so that no intermediate
/// overflows; 0 when undefined, clamped to `[0, 1]` against rounding.
fn msc(uu: f32, yy: f32, re: f32, im: f32) -> f32 {
    if !(uu > 0.0 && yy > 0.0) {
        return 0.0;
    }
    let s = 1.0 / uu.max(yy);
    let (a, b, r, i) = (uu * s, yy * s, re * s, im * s);
    let den = a * b;
    if !(den > 0.0 && den.is_finite()) {
        return 0.0;
    }
    let g = (r * r + i * i) / den;
    if g.is_finite() {
        g.clamp(0.0, 1.0)
    } else {
        0.0
    }
}
