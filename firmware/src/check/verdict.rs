//! One check frequency's verdict and the receipt's overall verdict.
use super::C32;

/// A check frequency counts only when its estimate's normalised random error σ (see
/// [`h1_random_error`]) satisfies `RESOLUTION_SIGMAS·σ <= |W_m|`: the measurement must be able
/// to tell a deviation of size |W_m| from noise, else the bin is [`Verdict::Unresolved`].
pub const RESOLUTION_SIGMAS: f32 = 3.0;

/// Normalised random error of an H1 magnitude estimate from `averages` independent segments
/// at magnitude-squared coherence `coherence` (Bendat & Piersol, *Random Data*, 4th ed.,
/// eq. 9.73): `σ = √(1 − γ²) / (|γ|·√(2·n_d))`, also the standard deviation of the phase in
/// radians. `f32::INFINITY` for γ² <= 0 or no average.
pub fn h1_random_error(coherence: f32, averages: u32) -> f32 {
    if !(coherence > 0.0) || averages == 0 {
        return f32::INFINITY;
    }
    let g2 = coherence.min(1.0);
    libm::sqrtf((1.0 - g2) / (2.0 * averages as f32 * g2))
}

/// Outcome of one check frequency.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Coherence passed the gate and `|G_meas − G0|/|G0| <= |W_m|`.
    Pass,
    /// Coherence passed the gate and the relative deviation exceeds `|W_m|`.
    Fail,
    /// Coherence below the gate: no evidence at this frequency (not counted).
    Skipped,
    /// Coherence passed the gate, but the estimate's random error is too large to resolve a
    /// deviation of size |W_m| (`RESOLUTION_SIGMAS·σ > |W_m|`): not counted.
    Unresolved,
    /// G0, W_m or the estimate could not be evaluated (singular model at this frequency, zero
    /// |G0|, non-finite estimate): counts as a failure.
    Undefined,
}

impl Verdict {
    /// `true` for verdicts that count as evidence (pass, fail, undefined); `false` for
    /// skipped and unresolved frequencies.
    pub fn counts(self) -> bool {
        !matches!(self, Verdict::Skipped | Verdict::Unresolved)
    }

    /// Upper-case name used in the receipt.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Pass => "PASS",
            Verdict::Fail => "FAIL",
            Verdict::Skipped => "SKIP",
            Verdict::Unresolved => "UNRESOLVED",
            Verdict::Undefined => "UNDEFINED",
        }
    }
}

/// Everything the receipt reports about one check frequency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckResult {
    /// Welch bin.
    pub bin: u16,
    /// Bin frequency, Hz.
    pub hz: f32,
    /// Magnitude-squared coherence at the bin.
    pub coherence: f32,
    /// The flashed model's response G0 (zero when undefined).
    pub g0: C32,
    /// The measured H1 estimate (zero when undefined).
    pub g_meas: C32,
    /// `|G_meas − G0| / |G0|` (NaN when undefined).
    pub rel_error: f32,
    /// `|W_m(j2πf)|` (NaN when undefined).
    pub wm: f32,
    /// Normalised random error σ of the estimate ([`h1_random_error`]).
    pub sigma: f32,
    /// The outcome.
    pub verdict: Verdict,
}

impl CheckResult {
    /// A placeholder (bin 0, undefined) for initialising arrays.
    pub const EMPTY: CheckResult = CheckResult {
        bin: 0,
        hz: 0.0,
        coherence: 0.0,
        g0: C32::new(0.0, 0.0),
        g_meas: C32::new(0.0, 0.0),
        rel_error: 0.0,
        wm: 0.0,
        sigma: 0.0,
        verdict: Verdict::Undefined,
    };
}

/// Checks one frequency: bin `bin` of an `n`-point Welch estimate at `fs_hz`, with the
/// measured `h1` and `coherence` there from `averages` segments, against the model response
/// `g0` and the weight magnitude `wm` (both evaluated by the caller at `z = e^{j2π·bin/n}`
/// resp. `ω = 2π·bin·fs/n`). Below the coherence `gate` the check is [`Verdict::Skipped`];
/// when `RESOLUTION_SIGMAS·σ > |W_m|` it is [`Verdict::Unresolved`]; otherwise the deviation
/// decides.
#[allow(clippy::too_many_arguments)]
pub fn check_bin(
    bin: u16,
    hz: f32,
    coherence: f32,
    averages: u32,
    gate: f32,
    h1: Option<C32>,
    g0: Option<C32>,
    wm: Option<f32>,
) -> CheckResult {
    let sigma = h1_random_error(coherence, averages);
    judge(bin, hz, coherence, sigma, gate, h1, g0, wm)
}

/// The decision of [`check_bin`] with the estimate's normalised random error `sigma` given:
/// below the coherence `gate` [`Verdict::Skipped`]; `RESOLUTION_SIGMAS·σ > |W_m|`
/// [`Verdict::Unresolved`]; otherwise `|G_meas − G0|/|G0| <= |W_m|` decides. Shared by the
/// open-loop check (σ of H1) and the closed-loop check (σ of the ratio of two H1 estimates,
/// [`super::ClosedLoopEstimator`]).
#[allow(clippy::too_many_arguments)]
pub fn judge(
    bin: u16,
    hz: f32,
    coherence: f32,
    sigma: f32,
    gate: f32,
    h1: Option<C32>,
    g0: Option<C32>,
    wm: Option<f32>,
) -> CheckResult {
    let mut r = CheckResult {
        bin,
        hz,
        coherence,
        g0: g0.unwrap_or_default(),
        g_meas: h1.unwrap_or_default(),
        rel_error: f32::NAN,
        wm: wm.unwrap_or(f32::NAN),
        sigma,
        verdict: Verdict::Undefined,
    };
    if !(coherence >= gate) {
        r.verdict = Verdict::Skipped;
        return r;
    }
    let (Some(h1), Some(g0), Some(wm)) = (h1, g0, wm) else {
        return r;
    };
    let g0_abs = g0.abs();
    if !(g0_abs > 0.0) {
        return r;
    }
    let rel = (h1 - g0).abs() / g0_abs;
    r.rel_error = rel;
    r.verdict = if !rel.is_finite() {
        Verdict::Undefined
    } else if !(RESOLUTION_SIGMAS * sigma <= wm) {
        Verdict::Unresolved
    } else if rel <= wm {
        Verdict::Pass
    } else {
        Verdict::Fail
    };
    r
}

/// The frequencies (Hz) of the check results that failed or are undefined, in order: the
/// `VERDICT` line's `failed_hz` list (capacity `C`, so every one fits).
pub fn failed_hz<const C: usize>(results: &[CheckResult; C]) -> heapless::Vec<f32, C> {
    let mut failed = heapless::Vec::new();
    for r in results {
        if matches!(r.verdict, Verdict::Fail | Verdict::Undefined) {
            // Cannot be full: at most C of the C results are pushed.
            let _ = failed.push(r.hz);
        }
    }
    failed
}

/// The receipt's verdict over all check frequencies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Overall {
    /// Enough frequencies counted (gated and resolved) and every one of them passed.
    Pass,
    /// At least one gated frequency failed (or was undefined).
    Fail,
    /// Fewer than the required number of frequencies counted (passed the coherence gate and
    /// were resolved): the measurement cannot vouch for the model either way.
    Inconclusive,
}

impl Overall {
    /// From the per-frequency verdicts: `min_checked` counted frequencies are needed.
    pub fn from_checks(checks: &[CheckResult], min_checked: usize) -> Self {
        let failed = checks
            .iter()
            .any(|c| matches!(c.verdict, Verdict::Fail | Verdict::Undefined));
        let checked = checks.iter().filter(|c| c.verdict.counts()).count();
        if failed {
            Overall::Fail
        } else if checked < min_checked {
            Overall::Inconclusive
        } else {
            Overall::Pass
        }
    }
    /// Upper-case name used in the receipt.
    pub fn as_str(self) -> &'static str {
        match self {
            Overall::Pass => "PASS",
            Overall::Fail => "FAIL",
            Overall::Inconclusive => "INCONCLUSIVE",
        }
    }
    /// Process exit code: 0 pass, 1 fail, 2 inconclusive.
    pub fn exit_code(self) -> i32 {
        match self {
            Overall::Pass => 0,
            Overall::Fail => 1,
            Overall::Inconclusive => 2,
        }
    }
}
