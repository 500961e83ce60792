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
//! # Real-time cost: every `push` is bounded
//! Samples go into one of two *banks* of `N` sample pairs. When a bank is full (a segment has
//! ended), `push` switches to the other bank, and the completed segment's work (copy of the
//! overlap into the new bank, mean, window, FFT, recombination, accumulation) is done **in
//! slices by the following `hop` pushes**: every `S` pushes (a power of two, 16 at N = 1024
//! with 50 % overlap; see `schedule::grant_plan`) a *grant point* adds a fixed budget of work
//! credit (the segment's cost spread over the grant points of one hop, with margin, at most
//! about 3,800 instructions) and runs work items up to it; the other pushes only store the
//! sample. The work is complete before the next segment ends (the segment end completes any
//! remainder), so no push ever does a whole segment. Measured under QEMU `-icount` on the
//! Cortex-M4F (N = 1024, Hann, 50 % overlap): the largest single push costs 3,560 instructions
//! and the mean 195.9 per sample (N = 256: 3,720 and 178.3), while one segment's work done at
//! once costs 87,160 (figures and commands: `docs/firmware-performance.md`). There is no separate
//! background call to make; an ISR simply calls [`Welch::push`].
//!
//! Consequences of the pipeline, all explicit in the API:
//! * A segment counts in [`Welch::averages`] once its work is complete, i.e. up to `hop`
//!   pushes after it ended. While it is folded in, bins already done use one more average than
//!   the others (each bin's estimate is always a mean over the segments it contains).
//! * [`Welch::flush`] completes the segment in work at once (cost up to one segment's work):
//!   call it, outside the ISR, before reading the final estimates after the last push.
//! * [`Welch::push_slice`] is the batch entry point: it completes every segment inside the call
//!   (it is not meant for an ISR), so after it all ended segments are included.
//!
//! # Memory and speed
//! `size_of::<Welch<N>>()` is `24·N` bytes plus about 100 bytes of state: two banks of `N`
//! pairs `(u, y)` and the sums of `N/2 + 1` bins, four `f32` each, nothing else. The window and twiddle tables are `const`
//! tables in flash. The transform is a radix-4 complex FFT of `N/2` points per channel (both
//! channels in one pass, bit-reversed output) with the real-signal recombination fused into the
//! accumulation; see the `kernels` submodule.

mod kernels;
mod schedule;
mod tables;

use crate::gate::CoherenceGate;
use crate::window::{HannTable, Window};
use crate::Error;

use kernels::Pair;
use schedule::{Job, Phase};
use tables::Tables;

/// Bound on the input: a sample pair is accepted when `u² + y² <= MAX_ABS_SAMPLE²` (see
/// [`accepts`]); other pairs (including NaN and ±inf) are counted and their segments dropped.
/// With [`MAX_AVERAGES`] it leaves every intermediate finite in `f32` for `N <= 4096`: a
/// segment's doubled spectrum `|2U[k]|² <= (2·2e11·N)² = 2.7e30`, times `2^24` segments
/// `< 4.6e37`.
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
#[repr(C)]
pub struct Welch<const N: usize> {
    // Field order (`repr(C)`): the state every `push` touches comes first, within the
    // immediate-offset range of a Cortex-M load/store from `self` (the banks and sums, 24·N
    // bytes, come last); this saves address arithmetic in `push` and in every work slice.
    /// Ticks each grant point adds to the credit: `budget` while a segment is in work, else 0.
    grant: i32,
    /// Grant points are the pushes after which `(w + 1) & grant_mask == 0` (see
    /// [`schedule::grant_plan`]); segment ends are among them.
    grant_mask: usize,
    /// Next write index into the two banks seen as one array of `2N` pairs: bank
    /// `w / N` is being filled (the other one holds the segment in work), at index `w % N`.
    /// One index instead of a bank number and a position saves address arithmetic in `push`.
    w: usize,
    /// The segment in work.
    job: Job,
    hop: u32,
    /// Work ticks granted per grant point while a segment is in work.
    budget: i32,
    /// First index of the fill bank written by `push` (0 after a reset, then `overlap`).
    fill_start: usize,
    /// Number of upcoming segment ends to drop (they contain a rejected sample).
    drop_ends: u32,
    averages: u32,
    dropped: u32,
    nonfinite: u32,
    /// `[Σ|2U[N/2]|², Σ|2Y[N/2]|²]` (Nyquist; the other bins are in `acc`).
    nyq: Pair,
    /// Sums of the deviations `(u, y)` of the samples copied into the fill bank (its first
    /// `fill_start`) from its first sample.
    head_sum: Pair,
    cfg: WelchConfig,
    /// Density scaling `1 / (fs Σw²)`.
    density: f32,
    /// Two banks of `N` samples of both channels (layout: see `kernels`).
    banks: [[Pair; N]; 2],
    /// Sums over segments of the doubled spectra's products, four per bin, in bit-reversed
    /// bin order: position `p` holds bin `rev(p)` as `[Σ|2U|², Σ|2Y|², Σ Re conj(2U)·2Y,
    /// Σ Im conj(2U)·2Y]`. Position 0 is DC, whose imaginary cross slot holds the (real)
    /// Nyquist cross sum.
    acc: [Pair; N],
}

impl<const N: usize> Welch<N> {
    /// Compile-time check of `N`.
    const VALID_N: () = assert!(
        crate::fft::is_supported_len(N),
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
            budget: 0,
            grant: 0,
            grant_mask: 0,
            w: 0,
            fill_start: 0,
            drop_ends: 0,
            averages: 0,
            dropped: 0,
            nonfinite: 0,
            nyq: [0.0; 2],
            head_sum: [0.0; 2],
            job: Job::IDLE,
            banks: [[[0.0; 2]; N]; 2],
            acc: [[0.0; 2]; N],
        }
    }

    /// The bank being filled (0 or 1).
    #[inline(always)]
    fn fill(&self) -> usize {
        (self.w / N) & 1
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
        let mut w = Self::unconfigured();
        let density = match density_scale::<N>(&cfg) {
            Ok(d) => d,
            Err(e) => return Err(e),
        };
        w.cfg = cfg;
        w.density = density;
        w.hop = (N - cfg.overlap) as u32;
        (w.grant_mask, w.budget) = Self::grant_plan(&cfg);
        Ok(w)
    }

    /// `(grant mask, ticks per grant point)` for `cfg` (valid overlap).
    const fn grant_plan(cfg: &WelchConfig) -> (usize, i32) {
        let hann = matches!(cfg.window, Window::Hann);
        schedule::grant_plan::<N>(cfg.overlap, N - cfg.overlap, hann)
    }

    /// Changes the configuration in place and [`reset`](Self::reset)s; on error nothing changes.
    ///
    /// # Errors
    /// As [`Welch::new`].
    pub fn configure(&mut self, cfg: WelchConfig) -> Result<(), Error> {
        self.density = density_scale::<N>(&cfg)?;
        self.cfg = cfg;
        self.hop = (N - cfg.overlap) as u32;
        (self.grant_mask, self.budget) = Self::grant_plan(&cfg);
        self.reset();
        Ok(())
    }

    /// Forgets all samples, averages and counters, and drops the segment in work (the
    /// configuration stays).
    pub fn reset(&mut self) {
        self.w = 0;
        self.fill_start = 0;
        self.drop_ends = 0;
        self.averages = 0;
        self.dropped = 0;
        self.nonfinite = 0;
        self.nyq = [0.0; 2];
        self.head_sum = [0.0; 2];
        self.job = Job::IDLE;
        self.grant = 0;
        for b in &mut self.banks {
            b.fill([0.0; 2]);
        }
        self.acc.fill([0.0; 2]);
    }

    /// Adds one input/output sample pair (signal units). Never panics; bounded cost.
    ///
    /// Every `N - overlap` samples (first after `N`) a segment ends. Its work is spread over
    /// the next `hop` pushes (see the [module documentation](self)); a segment containing a
    /// rejected sample pair (see [`accepts`]) is dropped instead.
    #[inline]
    pub fn push(&mut self, u: f32, y: f32) {
        let w = self.w & (2 * N - 1);
        let slot = &mut self.banks.as_flattened_mut()[w];
        if accepts(u, y) {
            *slot = [u, y];
        } else {
            *slot = [0.0, 0.0];
            self.reject((N - w % N) as u32);
        }
        if (w + 1) & self.grant_mask == 0 {
            self.grant_point(w + 1);
        } else {
            self.w = w + 1;
        }
    }

    /// A grant point (every `grant_mask + 1` pushes, see [`schedule::grant_plan`]): runs the
    /// segment in work's share (the grant, 0 when there is none, plus the unspent credit), then
    /// ends the segment if the fill bank is full (`next`: the fill index after this push).
    ///
    /// The work runs before `w` advances to `next`: at a segment end `next` is already in the
    /// other bank, and the kernels tell the work bank from the fill bank by `w`.
    #[inline(never)]
    fn grant_point(&mut self, next: usize) {
        let end = next.is_multiple_of(N);
        if self.grant > 0 {
            let credit = self.job.credit.saturating_add(self.grant);
            self.job.credit = if end {
                self.flush();
                0
            } else {
                self.work(credit)
            };
        }
        self.w = next;
        if end {
            self.segment_end();
        }
    }

    /// Completes the segment in work, if any, so that the estimates include every segment that
    /// has ended. Costs up to one segment's work (N = 1024: about 87,200 instructions on a
    /// Cortex-M4F): call it outside time-critical code, e.g. after the last `push` and before
    /// reading the estimates.
    pub fn flush(&mut self) {
        if self.job.phase != Phase::Idle {
            self.work(i32::MAX);
            self.job.credit = 0;
        }
    }

    /// `true` while an ended segment is still being folded into the estimates (it will be
    /// within the next `hop` pushes, or at once by [`Welch::flush`]).
    pub fn segment_in_work(&self) -> bool {
        self.job.phase != Phase::Idle
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

    /// The fill bank is full: a segment ends with the sample just stored. Switches banks and
    /// starts the segment's work.
    #[inline(never)]
    fn segment_end(&mut self) {
        if self.hop == 0 {
            // Unconfigured: never complete a segment (stay at the start of the same bank).
            self.w = ((self.w.wrapping_sub(1) / N) & 1) * N;
            return;
        }
        // The previous segment's work is complete by now (its credit covered it); this only
        // finishes a remainder smaller than one slice.
        self.flush();
        let accept = if self.drop_ends > 0 {
            self.drop_ends -= 1;
            self.dropped = self.dropped.saturating_add(1);
            false
        } else {
            self.averages < MAX_AVERAGES
        };
        let overlap = N - (self.hop as usize).min(N);
        self.job = Job {
            phase: Phase::Copy,
            done: 0,
            items: 0,
            cost: 1,
            credit: 0,
            seg_start: self.fill_start as u32,
            sum: self.head_sum,
            accept,
        };
        (self.job.items, self.job.cost) = self.phase_size();
        self.head_sum = [0.0; 2];
        self.grant = self.budget;
        // `w` has just left the bank that was filled, i.e. it is at the other bank's start
        // (`N`, or `2N` for bank 0).
        self.fill_start = overlap;
        self.w = ((self.w / N) & 1) * N + overlap;
    }

    /// Runs work items of the segment in work for up to `credit` ticks; returns the unspent
    /// credit (less than one item's cost, or everything once the segment is complete).
    fn work(&mut self, mut credit: i32) -> i32 {
        loop {
            let (items, cost) = (self.job.items, self.job.cost);
            if self.job.phase == Phase::Idle {
                return 0;
            }
            let left = items.saturating_sub(self.job.done);
            let n = if (left as i64) * (cost as i64) <= credit as i64 {
                left
            } else {
                (credit / cost.max(1)) as u32
            };
            if n == 0 && left > 0 {
                return credit;
            }
            self.run_items(self.job.done as usize, n as usize);
            credit -= (n as i32) * cost;
            self.job.done += n;
            if self.job.done >= items {
                self.next_phase();
            }
        }
    }

    /// `(items, ticks per item)` of the current phase (entered once per phase).
    #[inline(never)]
    fn phase_size(&self) -> (u32, i32) {
        let overlap = self.cfg.overlap;
        let hop = N - overlap.min(N - 1);
        schedule::phase_size::<N>(
            self.job.phase,
            overlap,
            hop,
            self.job.seg_start as usize,
            self.cfg.window == Window::Hann,
            self.copy_sums(hop),
        )
    }

    /// Whether the segment in work's `Copy` phase sums what it copies ([`schedule::copy_sums`]).
    #[inline(always)]
    fn copy_sums(&self, hop: usize) -> bool {
        schedule::copy_sums(
            self.cfg.detrend_mean,
            self.job.accept,
            hop,
            self.job.seg_start as usize,
        )
    }

    /// Moves the job to its next phase, skipping empty ones; completes the segment after
    /// `Edges`.
    fn next_phase(&mut self) {
        let j = &mut self.job;
        j.done = 0;
        j.phase = match j.phase {
            Phase::Idle => Phase::Idle,
            Phase::Copy if !j.accept => Phase::Idle,
            Phase::Copy if self.cfg.detrend_mean => Phase::Sum,
            Phase::Copy => {
                j.sum = [0.0; 2];
                Phase::Stage(0)
            }
            Phase::Sum => {
                // Mean = reference + mean deviation (see kernels::sum_range).
                let work = &self.banks[((self.w / N) & 1) ^ 1];
                let r = kernels::first_sample(work);
                let hop = N - self.cfg.overlap.min(N - 1);
                if !schedule::copy_sums(true, j.accept, hop, j.seg_start as usize) {
                    // `head_sum` holds the sum over `hop..N` (the next segment's head) about
                    // this bank's first sample: add it here, then refer it to the next bank's
                    // first sample `work[hop]`.
                    let (u, y) = kernels::sample(work, hop);
                    let k = (N - hop) as f32;
                    let tail = self.head_sum;
                    j.sum = [j.sum[0] + tail[0], j.sum[1] + tail[1]];
                    self.head_sum = [tail[0] - k * (u - r[0]), tail[1] - k * (y - r[1])];
                }
                let inv_n = 1.0 / N as f32;
                j.sum = [r[0] + j.sum[0] * inv_n, r[1] + j.sum[1] * inv_n];
                Phase::Stage(0)
            }
            Phase::Stage(s) if (s as u32) + 1 < schedule::fft_stages::<N>() => Phase::Stage(s + 1),
            Phase::Stage(_) => Phase::Combine,
            Phase::Combine => Phase::Edges,
            Phase::Edges => {
                self.averages += 1;
                Phase::Idle
            }
        };
        if j.phase == Phase::Idle {
            j.credit = 0;
            self.grant = 0;
        }
        (self.job.items, self.job.cost) = self.phase_size();
    }

    /// Runs items `start..start + count` of the current phase.
    fn run_items(&mut self, start: usize, count: usize) {
        let fill_bank = self.fill();
        let [b0, b1] = &mut self.banks;
        let (work, fill) = if fill_bank == 0 { (b1, b0) } else { (b0, b1) };
        let j = &mut self.job;
        match j.phase {
            Phase::Idle => {}
            Phase::Copy => {
                let hop = N - self.cfg.overlap.min(N - 1);
                let sums =
                    schedule::copy_sums(self.cfg.detrend_mean, j.accept, hop, j.seg_start as usize);
                if sums {
                    kernels::copy_range(work, fill, hop, start, start + count, &mut self.head_sum);
                } else {
                    kernels::copy_block(work, fill, hop, start, start + count);
                }
            }
            Phase::Sum => {
                let (a, b) = (
                    j.seg_start as usize + start,
                    j.seg_start as usize + start + count,
                );
                let r = kernels::first_sample(work);
                let hop = N - self.cfg.overlap.min(N - 1);
                if schedule::copy_sums(true, j.accept, hop, j.seg_start as usize) {
                    kernels::sum_range(work, a, b, r, &mut j.sum);
                } else {
                    // Samples `hop..N` are the next segment's head: summed apart.
                    kernels::sum_range(work, a, b.min(hop), r, &mut j.sum);
                    kernels::sum_range(work, a.max(hop), b, r, &mut self.head_sum);
                }
            }
            Phase::Stage(s) => {
                let z = kernels::quads_mut(work);
                let l = schedule::stage_len::<N>(s as u32);
                if s == 0 {
                    let hann: &'static [f32; N] = &HannTable::<N>::TABLE;
                    let window = match self.cfg.window {
                        Window::Hann => Some(hann.as_chunks::<2>().0),
                        Window::Rectangular => None,
                    };
                    let tw = kernels::stage_twiddles::<N>(0);
                    kernels::first_stage(z, window, j.sum, tw, start, count);
                } else if l == 4 {
                    kernels::unit4_stage(z, start, count);
                } else if l == 8 {
                    let tw = kernels::stage_twiddles::<N>(s as u32);
                    kernels::radix4_stage8(z, tw, start, count);
                } else {
                    let tw = kernels::stage_twiddles::<N>(s as u32);
                    kernels::radix4_stage(z, l, tw, start, count);
                }
            }
            Phase::Combine => {
                let acc = kernels::quads_mut(&mut self.acc);
                let (z, tw) = (kernels::quads(work), kernels::combine_twiddles::<N>());
                if schedule::fused_radix2::<N>() {
                    kernels::combine_radix2(z, acc, tw, start, count);
                } else {
                    kernels::combine(z, acc, tw, start, count);
                }
            }
            Phase::Edges => {
                let acc = kernels::quads_mut(&mut self.acc);
                let fused = schedule::fused_radix2::<N>();
                kernels::edge_bins(kernels::quads(work), acc, &mut self.nyq, fused);
            }
        }
    }

    /// Adds equal-length slices of input and output samples. Every segment that ends inside
    /// the call is completed inside it (batch entry point, not bounded per sample); the
    /// estimates equal those after calling [`Welch::push`] for each pair and then
    /// [`Welch::flush`].
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
        self.flush();
        let (mut u, mut y) = (u, y);
        while !u.is_empty() {
            let pos = self.w % N;
            // A run ends at the end of the bank or with the input.
            let run = u.len().min(N - pos).max(1);
            let (Some((u_run, u_rest)), Some((y_run, y_rest))) =
                (u.split_at_checked(run), y.split_at_checked(run))
            else {
                break;
            };
            let fill = self.fill();
            let bank = &mut self.banks[fill];
            if !store_run(bank, pos, u_run, y_run) {
                // Cold: find the rejected pairs again to book them.
                for (j, (&a, &b)) in u_run.iter().zip(y_run).enumerate() {
                    if !accepts(a, b) {
                        self.reject((N - pos - j) as u32);
                    }
                }
            }
            self.w = fill * N + pos + run;
            if pos + run >= N {
                self.segment_end();
                self.flush();
            }
            (u, y) = (u_rest, y_rest);
        }
        Ok(())
    }

    /// Number of segments whose products the bin at position `p` contains: the completed
    /// averages, plus the segment in work once its recombination has passed `p` (positions 0
    /// and 1 are done in `Edges`, which also completes the segment).
    #[inline]
    fn count(&self, p: usize) -> u32 {
        let n = self.averages;
        if p < 2 {
            return n;
        }
        match self.job.phase {
            Phase::Edges => n + 1,
            Phase::Combine => {
                let b = 1usize << (usize::BITS - 1 - p.leading_zeros());
                let half = b / 2;
                let i = if p < b + half { p - b } else { 2 * b - 1 - p };
                let t = half - 1 + i;
                let item = if schedule::fused_radix2::<N>() {
                    kernels::fused_item(t)
                } else {
                    t
                };
                n + u32::from((item as u32) < self.job.done)
            }
            _ => n,
        }
    }

    /// Position of bin `k` in the sums (`k < N/2`): `rev(k)` over `log2(N/2)` bits.
    #[inline]
    fn position(k: usize) -> usize {
        tables::rev_bits(k, Tables::<N>::LOG2_M)
    }

    /// Unscaled sums `(Σ|2U|², Σ|2Y|², Σ Re conj(2U)2Y, Σ Im conj(2U)2Y)` of bin `k` and the
    /// number of segments they contain; `None` if `k > N/2`.
    #[inline]
    fn raw(&self, k: usize) -> Option<(f32, f32, f32, f32, u32)> {
        let acc = kernels::quads(&self.acc);
        if k < N / 2 {
            let p = Self::position(k);
            let a = acc.get(p)?;
            // DC's imaginary cross slot holds the Nyquist cross sum.
            let im = if k == 0 { 0.0 } else { a[3] };
            Some((a[0], a[1], a[2], im, self.count(p)))
        } else if k == N / 2 {
            Some((
                self.nyq[0],
                self.nyq[1],
                acc.first()?[3],
                0.0,
                self.averages,
            ))
        } else {
            None
        }
    }

    /// Scaling of the sums of bin `k` over `n` segments: density over `n`, a quarter for the
    /// doubled spectra, doubled except at DC and Nyquist; 0 for `n = 0`.
    #[inline]
    fn scale(&self, k: usize, n: u32) -> f32 {
        if n == 0 {
            return 0.0;
        }
        let s = 0.25 * self.density / n as f32;
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

    /// Number of segments accumulated so far (dropped ones excluded; a segment counts once its
    /// work is complete, see [`Welch::flush`]).
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
        self.raw(k).map_or(0.0, |r| r.0 * self.scale(k, r.4))
    }

    /// One-sided auto-spectral density of `y` at bin `k` (`signal²/Hz`); 0 when undefined.
    pub fn syy(&self, k: usize) -> f32 {
        self.raw(k).map_or(0.0, |r| r.1 * self.scale(k, r.4))
    }

    /// One-sided cross-spectral density `S_uy = c·mean conj(U)·Y` at bin `k` as `(re, im)`
    /// (`signal_u·signal_y/Hz`); `(0, 0)` when undefined.
    pub fn suy(&self, k: usize) -> (f32, f32) {
        self.raw(k).map_or((0.0, 0.0), |r| {
            let s = self.scale(k, r.4);
            (r.2 * s, r.3 * s)
        })
    }

    /// H1 estimate `S_uy/S_uu` of the frequency response from `u` to `y` at bin `k`, as
    /// `(re, im)` (units of `y/u`). `None` before the first average, for `k >= bins()`, when
    /// `S_uu[k] == 0`, or if the ratio is not representable in `f32`.
    pub fn h1(&self, k: usize) -> Option<(f32, f32)> {
        let (uu, _, re, im, n) = self.raw(k)?;
        if n == 0 || uu.is_nan() || uu <= 0.0 {
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
        match self.raw(k) {
            Some((uu, yy, re, im, n)) if n > 0 => msc(uu, yy, re, im),
            _ => 0.0,
        }
    }

    /// Bins with coherence `>= threshold` (all bins fail for a NaN threshold or before the
    /// first average). Mind the bias with few averages (module docs): the threshold should
    /// exceed the noise-only level, e.g. `P(γ̂² > t) = (1 - t)^(n_d - 1)`.
    pub fn gate(&self, threshold: f32) -> CoherenceGate {
        let mut g = CoherenceGate::empty(self.bins());
        for k in 0..self.bins() {
            if let Some((uu, yy, re, im, n)) = self.raw(k) {
                if n > 0 && msc(uu, yy, re, im) >= threshold {
                    g.set(k);
                }
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

/// Copies a run of sample pairs into `bank` from index `pos`; rejected pairs (see [`accepts`])
/// are stored as 0. Returns `false` if any pair was rejected.
///
/// Fast path: copy and sum `u² + y²` over the run; if the sum passes the bound, every pair
/// does (the terms are non-negative and `f32` rounding is monotone). Otherwise a second pass
/// applies the exact per-pair test.
#[inline(never)]
fn store_run<const N: usize>(bank: &mut [Pair; N], pos: usize, u: &[f32], y: &[f32]) -> bool {
    let mut sum = 0.0f32;
    for (j, (&a, &b)) in u.iter().zip(y).enumerate() {
        kernels::set_sample(bank, pos + j, a, b);
        sum += a * a + b * b;
    }
    if sum <= MAX_NORM_SQ {
        return true;
    }
    let mut all_ok = true;
    for (j, (&a, &b)) in u.iter().zip(y).enumerate() {
        if !accepts(a, b) {
            kernels::set_sample(bank, pos + j, 0.0, 0.0);
            all_ok = false;
        }
    }
    all_ok
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
