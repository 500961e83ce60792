//! Power-up self-identification: the algorithms of the `powerup` image, free of hardware.
//!
//! * [`C32`]: a minimal `f32` complex number.
//! * [`model_response`]: the flashed discrete model's frequency response
//!   `G0(z) = C (zI − A)⁻¹ B + D` at `z = e^{jθ}`, by complex Gaussian elimination with partial
//!   pivoting in `f32` (no inverse), on target.
//! * [`weight_magnitude`]: `|W_m(jω)|` of the continuous uncertainty weight from its
//!   coefficients (Horner in `s = jω`, rad/s).
//! * [`check_bin`]: one check of the receipt, `|G_meas − G0| / |G0| <= |W_m|` where the
//!   coherence passes the gate and the estimate is precise enough to resolve a deviation of
//!   size |W_m| ([`RESOLUTION_SIGMAS`]), and [`Overall`] for the verdict over all check
//!   frequencies.
//! * [`plant`]: the discrete plant simulations that stand in for hardware under QEMU.
//!
//! Nothing here panics on any input: degenerate cases (singular `zI − A`, zero `|G0|`,
//! non-finite estimates) become [`Verdict::Undefined`], which fails the receipt.
#![no_std]
#![forbid(unsafe_code)]
// `!(x >= limit)` is deliberate throughout: it rejects NaN, which `x < limit` would let through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use core::ops::{Add, Mul, Sub};

pub mod plant;

/// A complex number in `f32`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct C32 {
    /// Real part.
    pub re: f32,
    /// Imaginary part.
    pub im: f32,
}

impl C32 {
    /// `re + j·im`.
    pub const fn new(re: f32, im: f32) -> Self {
        Self { re, im }
    }
    /// Product with a real number.
    pub fn scale(self, k: f32) -> Self {
        Self::new(self.re * k, self.im * k)
    }
    /// `|z|²`.
    pub fn norm_sqr(self) -> f32 {
        self.re * self.re + self.im * self.im
    }
    /// `|z|` (scaled to avoid overflow of the squares).
    pub fn abs(self) -> f32 {
        let m = self.re.abs().max(self.im.abs());
        if m == 0.0 || !m.is_finite() {
            return m;
        }
        let (r, i) = (self.re / m, self.im / m);
        m * libm::sqrtf(r * r + i * i)
    }
    /// Quotient (Smith's algorithm); `None` for a zero or non-finite divisor or result.
    pub fn checked_div(self, o: Self) -> Option<Self> {
        let q = if o.re.abs() >= o.im.abs() {
            if o.re == 0.0 {
                return None;
            }
            let r = o.im / o.re;
            let den = o.re + o.im * r;
            Self::new((self.re + self.im * r) / den, (self.im - self.re * r) / den)
        } else {
            let r = o.re / o.im;
            let den = o.re * r + o.im;
            Self::new((self.re * r + self.im) / den, (self.im * r - self.re) / den)
        };
        (q.re.is_finite() && q.im.is_finite()).then_some(q)
    }
    /// `e^{jθ}` for `θ = 2π·num/den`: exact rational range reduction and an `f64` series
    /// ([`ferrosid_firmware::trig::cos_frac`], error below 1e-15), rounded once to `f32`.
    pub fn unit_circle(num: u32, den: u32) -> Self {
        let (n, d) = (u64::from(num), u64::from(den.max(1)));
        Self::new(
            ferrosid_firmware::trig::cos_frac(n, d) as f32,
            ferrosid_firmware::trig::sin_frac(n, d) as f32,
        )
    }
}

impl Add for C32 {
    type Output = C32;
    fn add(self, o: C32) -> C32 {
        C32::new(self.re + o.re, self.im + o.im)
    }
}

impl Sub for C32 {
    type Output = C32;
    fn sub(self, o: C32) -> C32 {
        C32::new(self.re - o.re, self.im - o.im)
    }
}

impl Mul for C32 {
    type Output = C32;
    fn mul(self, o: C32) -> C32 {
        C32::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
}

/// Frequency response of the discrete model (A, B, C, D) from `input` to `output` at the point
/// `z` (on the unit circle `z = e^{jωT}` for a frequency response):
/// `C (zI − A)⁻¹ B + D`, solving `(zI − A) x = B[:, input]` by Gaussian elimination with
/// partial pivoting (complex `f32`, `N×N` on the stack).
///
/// Returns `None` when `zI − A` is singular to working precision (z at a pole), when
/// `input`/`output` is out of range, or when the result is not finite.
pub fn model_response<const N: usize, const M: usize, const P: usize>(
    a: &[[f32; N]; N],
    b: &[[f32; M]; N],
    c: &[[f32; N]; P],
    d: &[[f32; M]; P],
    z: C32,
    input: usize,
    output: usize,
) -> Option<C32> {
    if input >= M || output >= P {
        return None;
    }
    let mut m = [[C32::default(); N]; N];
    let mut x = [C32::default(); N];
    let mut scale = 0.0f32;
    for i in 0..N {
        for j in 0..N {
            let diag = if i == j { z } else { C32::default() };
            m[i][j] = diag - C32::new(a[i][j], 0.0);
            scale = scale.max(m[i][j].abs());
        }
        x[i] = C32::new(b[i][input], 0.0);
    }
    let tiny = scale * f32::EPSILON * N as f32;
    for k in 0..N {
        // Pivot: largest |m[i][k]| for i >= k.
        let mut p = k;
        let mut best = m[k][k].abs();
        for (i, row) in m.iter().enumerate().skip(k + 1) {
            let v = row[k].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        if !(best > tiny) {
            return None;
        }
        m.swap(k, p);
        x.swap(k, p);
        let piv = m[k][k];
        let xk = x[k];
        let (top, bottom) = m.split_at_mut_checked(k + 1)?;
        let prow = top.last()?;
        for (row, xi) in bottom.iter_mut().zip(x.iter_mut().skip(k + 1)) {
            let f = row[k].checked_div(piv)?;
            for (a, &b) in row.iter_mut().zip(prow.iter()).skip(k) {
                *a = *a - f * b;
            }
            *xi = *xi - f * xk;
        }
    }
    // Back substitution.
    for k in (0..N).rev() {
        let mut s = x[k];
        for j in k + 1..N {
            s = s - m[k][j] * x[j];
        }
        x[k] = s.checked_div(m[k][k])?;
    }
    let mut g = C32::new(d[output][input], 0.0);
    for j in 0..N {
        g = g + x[j].scale(c[output][j]);
    }
    (g.re.is_finite() && g.im.is_finite()).then_some(g)
}

/// Evaluates a polynomial with real coefficients (descending powers) at `s` (Horner).
fn poly_at(p: &[f32], s: C32) -> C32 {
    p.iter()
        .fold(C32::default(), |acc, &k| acc * s + C32::new(k, 0.0))
}

/// `|W_m(jω)|` for `W_m(s) = num(s)/den(s)` (descending powers of s, s in rad/s) at
/// `w_rad_s`; `None` when the denominator vanishes there or the result is not finite.
pub fn weight_magnitude(num: &[f32], den: &[f32], w_rad_s: f32) -> Option<f32> {
    let s = C32::new(0.0, w_rad_s);
    let q = poly_at(num, s).checked_div(poly_at(den, s))?;
    let m = q.abs();
    m.is_finite().then_some(m)
}

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
