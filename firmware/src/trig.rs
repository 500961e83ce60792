//! Sine and cosine without `libm` in the hot path.
//!
//! * [`sin_frac`] / [`cos_frac`]: `sin(2π·num/den)` in `f64`, usable in `const` context. Used to
//!   build every table of this crate at compile time (window tables, the oscillator table), so
//!   tables live in flash and cost no start-up time. Exact integer range reduction to one octant,
//!   then a Taylor series to `x^17` on `|x| <= π/4`: absolute error below `1e-15`.
//! * [`sin_turns`] / [`cos_turns`]: fast `f32` sine of a 32-bit phase (`2^32` = one cycle), for
//!   oscillators driven by a phase accumulator. A 256-entry table gives `sin` and `cos` of the
//!   coarse angle; the remaining fine angle `b < 2π/256` is added with the angle-sum identity and
//!   `sin b ≈ b - b³/6`, `cos b ≈ 1 - b²/2` (truncation below `1e-9`). Measured worst-case error
//!   against `f64` sine is below `2.5e-7` (test `sin_turns_accuracy`), i.e. below -130 dB
//!   relative to full scale. About 15 instructions on a Cortex-M4F, no division, no `libm`.

use core::f64::consts::FRAC_PI_4;

/// Horner form of `Σ_{k=0..8} (-1)^k x^(2k) / (2k + odd)!` for `x2 = x²`: the series of
/// `sin(x)/x` (`odd = 1`) or of `cos(x)` (`odd = 0`), highest term first.
const fn alternating_series(x2: f64, odd: u32) -> f64 {
    let mut acc = 0.0;
    let mut k = 8u32; // highest term x^(2·8+odd)
    loop {
        // coefficient (-1)^k / (2k+odd)!
        let mut fact = 1.0f64;
        let mut i = 2;
        while i <= 2 * k + odd {
            fact *= i as f64;
            i += 1;
        }
        let c = if k.is_multiple_of(2) {
            1.0 / fact
        } else {
            -1.0 / fact
        };
        acc = acc * x2 + c;
        if k == 0 {
            break;
        }
        k -= 1;
    }
    acc
}

/// Odd Taylor series of `sin(x)` for `|x| <= π/4` (terms to `x^17`), in `f64`.
const fn sin_taylor(x: f64) -> f64 {
    // x·(1 - x²/3! + x⁴/5! - ...), coefficients 1/(2k+1)! with alternating sign.
    alternating_series(x * x, 1) * x
}

/// Even Taylor series of `cos(x)` for `|x| <= π/4` (terms to `x^16`), in `f64`.
const fn cos_taylor(x: f64) -> f64 {
    alternating_series(x * x, 0)
}

/// `sin(2π·num/den)` in `f64`, for any `num` and `den > 0` (`den == 0` returns 0).
///
/// Range reduction is exact integer arithmetic (`num mod den`, then the octant), so the result
/// is accurate to about `1e-16` absolute for every `num`, however large.
pub const fn sin_frac(num: u64, den: u64) -> f64 {
    if den == 0 {
        return 0.0;
    }
    // Work in u128 so that 8·num cannot overflow for any u64 inputs.
    let den128 = den as u128;
    let n8 = (num as u128 % den128) * 8;
    let octant = n8 / den128; // 0..=7
    let rem = n8 - octant * den128; // in [0, den)
                                    // angle = (π/4)·(octant + rem/den)
    let r = rem as f64 / den as f64; // [0, 1)
    let r_rev = (den128 - rem) as f64 / den as f64; // (0, 1]
    let v = match octant % 4 {
        0 => sin_taylor(FRAC_PI_4 * r),
        1 => cos_taylor(FRAC_PI_4 * r_rev),
        2 => cos_taylor(FRAC_PI_4 * r),
        _ => sin_taylor(FRAC_PI_4 * r_rev),
    };
    if octant >= 4 {
        -v
    } else {
        v
    }
}

/// `cos(2π·num/den)` in `f64` (see [`sin_frac`]).
pub const fn cos_frac(num: u64, den: u64) -> f64 {
    if den == 0 {
        return 1.0;
    }
    // cos(2π n/d) = sin(2π (4n + d)/(4d)); 4·num + den is done modulo 4·den in u128 to avoid
    // overflow, which does not change the angle.
    let d4 = 4 * den as u128;
    let n = (4 * (num as u128 % den as u128) + den as u128) % d4;
    // n < 4·den ≤ 2^66: reduce by 4 where possible to stay in u64.
    if n.is_multiple_of(4) {
        sin_frac((n / 4) as u64, den)
    } else if d4 <= u64::MAX as u128 {
        sin_frac(n as u64, d4 as u64)
    } else {
        // den > 2^62: the quarter-turn shift is below f64 resolution of the angle anyway.
        sin_frac((n / 4) as u64, den)
    }
}

/// log2 of the oscillator table length.
const TABLE_BITS: u32 = 8;
/// Oscillator table length (entries per cycle).
const TABLE_LEN: usize = 1 << TABLE_BITS;

/// `SINE_TABLE[i] = sin(2π i / 256)`, rounded to `f32`, built at compile time (1 KiB of flash).
static SINE_TABLE: [f32; TABLE_LEN] = {
    let mut t = [0.0f32; TABLE_LEN];
    let mut i = 0;
    while i < TABLE_LEN {
        t[i] = sin_frac(i as u64, TABLE_LEN as u64) as f32;
        i += 1;
    }
    t
};

/// Radians per least significant bit of a 32-bit phase: `2π / 2^32`.
const RAD_PER_LSB: f32 = (2.0 * core::f64::consts::PI / 4_294_967_296.0) as f32;

/// `sin(2π·phase/2^32)` in `f32`; `phase` is a 32-bit phase accumulator value (one cycle =
/// `2^32`). Absolute error below `2.5e-7`. No division, no `libm`, no panics.
#[inline]
pub fn sin_turns(phase: u32) -> f32 {
    let idx = (phase >> (32 - TABLE_BITS)) as usize;
    let s0 = SINE_TABLE[idx & (TABLE_LEN - 1)];
    let c0 = SINE_TABLE[(idx + TABLE_LEN / 4) & (TABLE_LEN - 1)];
    // Fine angle: the low 24 bits, exactly representable in f32.
    let b = (phase & ((1 << (32 - TABLE_BITS)) - 1)) as f32 * RAD_PER_LSB;
    let b2 = b * b;
    // sin(a + b) = sin a cos b + cos a sin b, cos b = 1 - b²/2, sin b = b (1 - b²/6)
    s0 + (c0 * b * (1.0 - b2 * (1.0 / 6.0)) - s0 * (0.5 * b2))
}

/// `cos(2π·phase/2^32)` in `f32` (a quarter-cycle shift of [`sin_turns`]).
#[inline]
pub fn cos_turns(phase: u32) -> f32 {
    sin_turns(phase.wrapping_add(1 << 30))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn const_sin_cos_match_std_f64() {
        // Reference: std's f64 sin/cos (an independent implementation). Tolerance 1e-15 abs.
        for den in [1u64, 3, 7, 64, 1000, 4096, 1 << 32] {
            for k in 0..2000u64 {
                let num = k.wrapping_mul(2_654_435_761) % (3 * den) + k; // spread, beyond 1 turn
                let ang = 2.0 * std::f64::consts::PI * ((num % den) as f64 / den as f64);
                let (s, c) = (sin_frac(num, den), cos_frac(num, den));
                assert!(
                    (s - ang.sin()).abs() < 1e-15,
                    "sin {num}/{den}: {s} vs {}",
                    ang.sin()
                );
                assert!(
                    (c - ang.cos()).abs() < 1e-15,
                    "cos {num}/{den}: {c} vs {}",
                    ang.cos()
                );
            }
        }
        assert_eq!(sin_frac(5, 0), 0.0);
        assert_eq!(cos_frac(5, 0), 1.0);
        assert!((cos_frac(u64::MAX, u64::MAX) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn sin_turns_accuracy() {
        // Sweep 2^22 phases (every 1024th LSB plus an odd offset) against f64 sine.
        let mut max_err = 0.0f64;
        let mut p: u32 = 12345;
        for _ in 0..(1u32 << 22) {
            let exact = (2.0 * std::f64::consts::PI * p as f64 / 4_294_967_296.0).sin();
            let err = (sin_turns(p) as f64 - exact).abs();
            max_err = max_err.max(err);
            let exact_c = (2.0 * std::f64::consts::PI * p as f64 / 4_294_967_296.0).cos();
            max_err = max_err.max((cos_turns(p) as f64 - exact_c).abs());
            p = p.wrapping_add(1024 + 1);
        }
        assert!(max_err < 2.5e-7, "max error {max_err:e}");
    }
}
