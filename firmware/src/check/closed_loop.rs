//! The closed-loop check's estimator: the plant's frequency response measured while the
//! generated controller holds the loop, with the excitation as instrument.
//!
//! # Where the excitation enters, and why the reference
//! The multisine `r` is added to the loop's reference; the controller (with its compensation,
//! if flashed) runs unchanged, `u` is the controller's command to the (compensated) plant —
//! the PID's part, the signal the model's input stands for — and `y` the measured output.
//! The reference is chosen over adding to the command because (1) the flashed control law is
//! exercised exactly as in operation, through its only entry point `step(r, y)`, including the
//! compensation's view of the PID command (the lag-aware friction feedforward keys its stuck
//! branch on it); (2) the amplitude is set in output units and held by the loop, so the
//! mechanism moves by a known, safe amount; (3) `r` is generated on target, noise-free and
//! independent of the plant's noise — the ideal instrument.
//!
//! # The estimate (indirect / joint input-output)
//! With output noise `v`, `y = S·G·C·r + S·v` and `u = S·C·r − S·C·v` (`S = 1/(1 + G·C)`): the
//! noise reaches `u` through the controller, so the open-loop H1 `S_uy / S_uu` is biased
//! towards `−1/C` where the noise matters (at the limit, it measures the controller's inverse).
//! `r` is uncorrelated with `v`, so `S_ry = S_rr·S·G·C` and `S_ru = S_rr·S·C`, and
//! `G = S_ry / S_ru` at the excited lines (the indirect, or joint input-output, spectral
//! estimate of closed-loop identification with an external excitation: Wellstead, Automatica
//! 17(1), 1981; Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*,
//! on identification in feedback). The two
//! cross-spectra are two streaming [`Welch`] estimators fed `(r, y)` and `(r, u)`, rectangular
//! window, no overlap, one multisine period per segment (period-synchronous: no leakage at the
//! excited lines), so `G = H1_ry / H1_ru` through the public `Welch` API.
//!
//! A nonlinear loop (friction, a limit cycle) is not a `G`: the ratio then measures the best
//! linear approximation of the plant at the excitation's amplitude, plus the cycle's
//! non-synchronous power as noise, and the check fails where that differs from the model by
//! more than |W_m|.
use super::{h1_random_error, judge, CheckConfig, CheckError, CheckResult, Measured, C32};
use crate::{Welch, WelchConfig, Window};

/// Normalised random error bound of the ratio `G = H_ry / H_ru` of two H1 estimates at
/// coherences `coh_ry`, `coh_ru` from `averages` segments: `σ_ry + σ_ru` (first-order: the
/// relative errors of a quotient add; their sum bounds the combined error whatever their
/// correlation), each by [`h1_random_error`]. Infinite when either is.
pub fn ratio_random_error(coh_ry: f32, coh_ru: f32, averages: u32) -> f32 {
    h1_random_error(coh_ry, averages) + h1_random_error(coh_ru, averages)
}

/// Streaming state of the closed-loop estimate: two Welch estimators of `N`-sample segments
/// (`48·N` bytes). Configuration (the sample rate) is set once; [`push`](Self::push) is the
/// per-sample work (two Welch pushes, bounded cost, never panics).
pub struct ClosedLoopEstimator<const N: usize> {
    ry: Welch<N>,
    ru: Welch<N>,
}

impl<const N: usize> ClosedLoopEstimator<N> {
    /// All-zero, unconfigured state (a `static` in .bss); [`configure`](Self::configure) it.
    pub const fn unconfigured() -> Self {
        Self {
            ry: Welch::unconfigured(),
            ru: Welch::unconfigured(),
        }
    }

    /// The Welch settings of the check: `fs_hz`, rectangular window, no overlap, mean removed.
    pub fn welch_config(fs_hz: f32) -> WelchConfig {
        WelchConfig {
            fs_hz,
            overlap: 0,
            window: Window::Rectangular,
            detrend_mean: true,
        }
    }

    /// Configures both estimators for `fs_hz` and forgets all data.
    ///
    /// # Errors
    /// [`CheckError::SampleRate`] for a non-finite or non-positive rate,
    /// [`CheckError::Welch`] when the estimator rejects it.
    pub fn configure(&mut self, fs_hz: f32) -> Result<(), CheckError> {
        if !(fs_hz.is_finite() && fs_hz > 0.0) {
            return Err(CheckError::SampleRate);
        }
        let cfg = Self::welch_config(fs_hz);
        self.ry.configure(cfg).map_err(CheckError::Welch)?;
        self.ru.configure(cfg).map_err(CheckError::Welch)?;
        Ok(())
    }

    /// One sample: the injected excitation `r`, the controller's command `u`, the output `y`.
    #[inline]
    pub fn push(&mut self, r: f32, u: f32, y: f32) {
        self.ry.push(r, y);
        self.ru.push(r, u);
    }

    /// Completes the segments in work (call after the last push, before reading).
    pub fn flush(&mut self) {
        self.ry.flush();
        self.ru.flush();
    }

    /// Segments averaged (the smaller of the two estimators' counts; they agree unless a
    /// non-finite `u` or `y` dropped a segment of one of them).
    pub fn averages(&self) -> u32 {
        self.ry.averages().min(self.ru.averages())
    }

    /// Segments dropped (non-finite samples), both estimators together.
    pub fn dropped_segments(&self) -> u32 {
        self.ry.dropped_segments() + self.ru.dropped_segments()
    }

    /// `S_ry[k]` and `S_ru[k]` (one-sided densities, `conj(R)·Y` convention).
    pub fn cross_spectra(&self, k: usize) -> (C32, C32) {
        let (a, b) = self.ry.suy(k);
        let (c, d) = self.ru.suy(k);
        (C32::new(a, b), C32::new(c, d))
    }

    /// Coherences `γ²_ry[k]`, `γ²_ru[k]`.
    pub fn coherences(&self, k: usize) -> (f32, f32) {
        (self.ry.coherence(k), self.ru.coherence(k))
    }

    /// `G[k] = S_ry[k] / S_ru[k]`; `None` when not finite or `S_ru[k] = 0`.
    pub fn estimate(&self, k: usize) -> Option<C32> {
        let (ry, ru) = self.cross_spectra(k);
        ry.checked_div(ru)
    }

    /// The measurement at bin `k` for [`super::evaluate`]: the estimate, the smaller of the two
    /// coherences (the gate must hold for both), and [`ratio_random_error`].
    pub fn measured(&self, k: usize) -> Measured {
        let (a, b) = self.coherences(k);
        Measured {
            coherence: a.min(b),
            sigma: ratio_random_error(a, b, self.averages()),
            g: self.estimate(k),
        }
    }

    /// One bin checked against `g0` and `wm` (as [`judge`]) with `cfg`'s gate.
    pub fn check<const C: usize>(
        &self,
        cfg: &CheckConfig<'_, C>,
        bin: u16,
        hz: f32,
        g0: Option<C32>,
        wm: Option<f32>,
    ) -> CheckResult {
        let m = self.measured(usize::from(bin));
        judge(bin, hz, m.coherence, m.sigma, cfg.gate, m.g, g0, wm)
    }
}
