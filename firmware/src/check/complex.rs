//! [`C32`]: a minimal `f32` complex number for the check's few per-frequency evaluations.
use core::ops::{Add, Mul, Sub};

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
    /// `e^{jθ}` for `θ = 2π·num/den`. For a power-of-two `den` (every Welch segment length)
    /// `num/den` of a turn is an exact 32-bit phase and the firmware's oscillator table gives
    /// it ([`crate::trig::cos_turns`], error below 2.5e-7, about 50 instructions on the M4F);
    /// otherwise exact rational range reduction and an `f64` series ([`crate::trig::cos_frac`],
    /// error below 1e-15, rounded once to `f32`; about 5,400 instructions, software `f64`).
    /// micromath's `sin`/`cos` (1.1e-3 off on the unit circle) was measured too and rejected:
    /// docs/firmware.md "Design-card crates on the target".
    pub fn unit_circle(num: u32, den: u32) -> Self {
        if den.is_power_of_two() {
            // num·2^32/den mod 2^32; den = 1 gives shift 32: phase 0 (a whole number of turns).
            let phase = num.checked_shl(32 - den.trailing_zeros()).unwrap_or(0);
            return Self::new(crate::trig::cos_turns(phase), crate::trig::sin_turns(phase));
        }
        let (n, d) = (u64::from(num), u64::from(den.max(1)));
        Self::new(
            crate::trig::cos_frac(n, d) as f32,
            crate::trig::sin_frac(n, d) as f32,
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
