//! The power-up check: the flashed model against a measured frequency response, within the
//! uncertainty weight |W_m| (moved here from the `powerup` image; the image keeps only the
//! hardware/QEMU glue).
//!
//! * [`C32`]: a minimal `f32` complex number.
//! * [`model_response`]: the flashed discrete model's frequency response
//!   `G0(z) = C (zI − A)⁻¹ B + D` at `z = e^{jθ}` (complex Gaussian elimination with partial
//!   pivoting in `f32`, no inverse); [`weight_magnitude`]: `|W_m(jω)|` from its coefficients.
//! * [`check_bin`] / [`judge`]: one check frequency, `|G_meas − G0| / |G0| <= |W_m|` where the
//!   coherence passes the gate and the estimate resolves a deviation of size |W_m|
//!   ([`RESOLUTION_SIGMAS`]); [`Overall`]: the verdict over all check frequencies;
//!   [`failed_hz`]: the failing frequencies as a `heapless::Vec`.
//! * [`CheckConfig`] (validated settings, borrowed from the generated module) and
//!   [`evaluate`]: every check frequency of a configuration from a measurement callback —
//!   the open-loop mode measures H1 of a `Welch` (multisine at the plant input), the
//!   closed-loop mode the indirect estimate of a [`ClosedLoopEstimator`] (multisine at the
//!   reference of the running loop, `G = S_ry / S_ru`).
//!
//! Nothing here panics or allocates: degenerate cases (singular `zI − A`, zero `|G0|`,
//! non-finite estimates) become [`Verdict::Undefined`], which fails the receipt; bad settings
//! are a [`CheckError`].
// `!(x >= limit)` is deliberate throughout: it rejects NaN, which `x < limit` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod closed_loop;
mod complex;
mod model;
mod verdict;

pub use closed_loop::{ratio_random_error, ClosedLoopEstimator};
pub use complex::C32;
pub use model::{model_response, weight_magnitude};
pub use verdict::{
    check_bin, failed_hz, h1_random_error, judge, CheckResult, Overall, Verdict, RESOLUTION_SIGMAS,
};

use core::fmt;

use crate::excitation::Line;

/// A rejected check setting (the field is named in [`fmt::Display`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CheckError {
    /// Sample rate not finite or not positive.
    SampleRate,
    /// Coherence gate outside (0, 1).
    Gate,
    /// No check frequency, or `min_checked` is 0 or exceeds the number of check frequencies.
    MinChecked,
    /// Check bin `index` is 0 or not below `N/2` (Nyquist), or the bins are not ascending.
    Bin {
        /// Position in the bin list.
        index: usize,
    },
    /// Excitation RMS not finite or not positive.
    ExcitationRms,
    /// The Welch estimator rejected its configuration.
    Welch(crate::Error),
}

impl fmt::Display for CheckError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CheckError::SampleRate => write!(f, "check: fs_hz must be finite and > 0"),
            CheckError::Gate => write!(f, "check: coherence gate must lie in (0, 1)"),
            CheckError::MinChecked => write!(
                f,
                "check: min_checked must be in 1..=number of check frequencies (at least one)"
            ),
            CheckError::Bin { index } => write!(
                f,
                "check: bin[{index}] must be in 1..N/2 and the bins strictly ascending"
            ),
            CheckError::ExcitationRms => {
                write!(f, "check: excitation RMS must be finite and > 0")
            }
            CheckError::Welch(e) => write!(f, "check: Welch configuration rejected: {e}"),
        }
    }
}

impl CheckError {
    /// The offending setting's name, for a log line without formatting machinery.
    pub fn field(&self) -> &'static str {
        match self {
            CheckError::SampleRate => "fs_hz",
            CheckError::Gate => "coherence_gate",
            CheckError::MinChecked => "min_checked",
            CheckError::Bin { .. } => "check_bin",
            CheckError::ExcitationRms => "excitation_rms",
            CheckError::Welch(_) => "welch",
        }
    }
}

/// Settings of one check (configuration, never mutated; the generated module's constants):
/// `C` check frequencies at bins `bins` of an `n`-point period at `fs_hz`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckConfig<'a, const C: usize> {
    /// Sample rate, Hz.
    pub fs_hz: f32,
    /// Welch segment length = multisine period, samples.
    pub n: usize,
    /// Check bins, ascending, each in `1..n/2`.
    pub bins: &'a [u16; C],
    /// The bins' frequencies, Hz (as generated; reported in the receipt).
    pub hz: &'a [f32; C],
    /// Magnitude-squared coherence a bin needs to count, in (0, 1).
    pub gate: f32,
    /// Fewest counted bins for a verdict, in `1..=C`.
    pub min_checked: usize,
}

impl<const C: usize> CheckConfig<'_, C> {
    /// Checks every field (see [`CheckError`]).
    ///
    /// # Errors
    /// The first bad field.
    pub fn validate(&self) -> Result<(), CheckError> {
        if !(self.fs_hz.is_finite() && self.fs_hz > 0.0) {
            return Err(CheckError::SampleRate);
        }
        if !(self.gate > 0.0 && self.gate < 1.0) {
            return Err(CheckError::Gate);
        }
        if C == 0 || self.min_checked == 0 || self.min_checked > C {
            return Err(CheckError::MinChecked);
        }
        let mut prev = 0u16;
        for (index, &b) in self.bins.iter().enumerate() {
            if b == 0 || usize::from(b) >= self.n / 2 || b <= prev {
                return Err(CheckError::Bin { index });
            }
            prev = b;
        }
        Ok(())
    }
}

/// The flashed discrete model (A, B, C, D), `NS` states, `M` inputs, `P` outputs; the check
/// uses input 0 and output 0.
#[derive(Debug, Clone, Copy)]
pub struct Model<'a, const NS: usize, const M: usize, const P: usize> {
    /// State matrix.
    pub a: &'a [[f32; NS]; NS],
    /// Input matrix.
    pub b: &'a [[f32; M]; NS],
    /// Output matrix.
    pub c: &'a [[f32; NS]; P],
    /// Feedthrough.
    pub d: &'a [[f32; M]; P],
}

/// The uncertainty weight `W_m(s) = num(s)/den(s)`, descending powers of s (rad/s).
#[derive(Debug, Clone, Copy)]
pub struct Weight<'a> {
    /// Numerator coefficients.
    pub num: &'a [f32],
    /// Denominator coefficients.
    pub den: &'a [f32],
}

/// What a measurement says at one bin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    /// Magnitude-squared coherence the gate is applied to.
    pub coherence: f32,
    /// Normalised random error of the estimate.
    pub sigma: f32,
    /// The estimate of G (None when undefined).
    pub g: Option<C32>,
}

/// Checks every frequency of `cfg`: the model's response at `z = e^{j2π·bin/n}`, |W_m| at
/// `ω = 2π·bin·fs/n`, and `measure(bin)` for the estimate, judged by [`judge`]. Call
/// [`CheckConfig::validate`] first (an unvalidated configuration still never panics: bad bins
/// give [`Verdict::Undefined`] or [`Verdict::Skipped`]).
pub fn evaluate<const C: usize, const NS: usize, const M: usize, const P: usize>(
    cfg: &CheckConfig<'_, C>,
    model: &Model<'_, NS, M, P>,
    weight: &Weight<'_>,
    mut measure: impl FnMut(usize) -> Measured,
) -> [CheckResult; C] {
    let mut out = [CheckResult::EMPTY; C];
    for ((r, &bin), &hz) in out.iter_mut().zip(cfg.bins.iter()).zip(cfg.hz.iter()) {
        let z = C32::unit_circle(u32::from(bin), cfg.n as u32);
        let g0 = model_response(model.a, model.b, model.c, model.d, z, 0, 0);
        let w = (2.0 * core::f64::consts::PI * f64::from(bin) * f64::from(cfg.fs_hz)
            / cfg.n.max(1) as f64) as f32;
        let wm = weight_magnitude(weight.num, weight.den, w);
        let m = measure(usize::from(bin));
        *r = judge(bin, hz, m.coherence, m.sigma, cfg.gate, m.g, g0, wm);
    }
    out
}

/// The check's excitation lines: bins `1..=L` with a flat amplitude `rms·√(2/L)`, so the
/// multisine's RMS is `rms` (a sine of amplitude a has RMS a/√2).
///
/// # Errors
/// [`CheckError::ExcitationRms`] for a non-finite or non-positive `rms`, or `L = 0`.
pub fn flat_lines<const L: usize>(rms: f32) -> Result<[Line; L], CheckError> {
    if L == 0 || !(rms.is_finite() && rms > 0.0) {
        return Err(CheckError::ExcitationRms);
    }
    let amplitude = rms * libm::sqrtf(2.0 / L as f32);
    let mut lines = [Line {
        bin: 0,
        amplitude: 0.0,
    }; L];
    for (i, l) in lines.iter_mut().enumerate() {
        *l = Line {
            bin: i + 1,
            amplitude,
        };
    }
    Ok(lines)
}

#[cfg(test)]
mod tests;
