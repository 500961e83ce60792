//! Decimal text to `f32` for configuration values (command lines, settings frames), without
//! core's correctly rounded parser: `<f32 as FromStr>` links `dec2flt` and its 10.4 KB
//! power-of-five table into flash, which is a fifth of the power-up image.
//!
//! Grammar: `[+-] digits [. digits] [(e|E) [+-] digits]` with at least one mantissa digit (`.5`
//! and `5.` are accepted) and at most three exponent digits. No `inf`/`nan`, no separators, no
//! surrounding whitespace.
//!
//! Accuracy contract: the first 19 significant digits are kept exactly (u64 mantissa); the value
//! is formed in f64 (one division or multiplication by an exactly representable power of ten
//! for |exponent| ≤ 22, two otherwise) and rounded to f32. The result is within 1 ulp of the
//! correctly rounded f32 (checked against `str::parse` in `firmware/tests/decimal.rs`). Values
//! that overflow f32 give `None`; values below the smallest subnormal give ±0.
//!
//! No panic on any input; cost: a few hundred instructions plus soft-float f64 (once, at boot).

/// Exact powers of ten in f64: 10^0 ..= 10^22 (10^22 < 2^53·2^22 is the last exact one).
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Scales `m` by 10^`e` in f64 (exact steps of at most 10^22 each).
fn scale10(mut m: f64, e: i32) -> f64 {
    let mut left = e.unsigned_abs();
    while left > 0 && m != 0.0 && m.is_finite() {
        let step = left.min(22);
        let p = POW10.get(step as usize).copied().unwrap_or(1e22);
        m = if e < 0 { m / p } else { m * p };
        left -= step;
    }
    m
}

/// Parses a decimal number (grammar and accuracy in the module docs). `None` for malformed text
/// or a value beyond the f32 range.
pub fn parse_f32(s: &str) -> Option<f32> {
    let b = s.as_bytes();
    let mut i = 0;
    let negative = match b.first() {
        Some(b'-') => {
            i = 1;
            true
        }
        Some(b'+') => {
            i = 1;
            false
        }
        _ => false,
    };
    let mut mantissa: u64 = 0;
    let mut significant = 0u32;
    let mut exp10: i32 = 0;
    let mut digits = 0u32;
    let mut seen_point = false;
    while let Some(&c) = b.get(i) {
        match c {
            b'0'..=b'9' => {
                digits += 1;
                let d = u64::from(c - b'0');
                if significant < 19 {
                    if mantissa != 0 || d != 0 {
                        mantissa = mantissa * 10 + d;
                        significant += 1;
                    }
                    if seen_point {
                        exp10 -= 1;
                    }
                } else if !seen_point {
                    // Digits beyond the 19 kept ones still count for the magnitude.
                    exp10 = exp10.saturating_add(1);
                }
            }
            b'.' if !seen_point => seen_point = true,
            _ => break,
        }
        i += 1;
    }
    if digits == 0 {
        return None;
    }
    if let Some(&c) = b.get(i) {
        if c != b'e' && c != b'E' {
            return None;
        }
        i += 1;
        let exp_negative = match b.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let start = i;
        let mut e: i32 = 0;
        while let Some(&c) = b.get(i) {
            if !c.is_ascii_digit() || i - start >= 3 {
                return None;
            }
            e = e * 10 + i32::from(c - b'0');
            i += 1;
        }
        if i == start {
            return None;
        }
        exp10 = exp10.saturating_add(if exp_negative { -e } else { e });
    }
    let magnitude = scale10(mantissa as f64, exp10) as f32;
    if !magnitude.is_finite() {
        return None;
    }
    Some(if negative { -magnitude } else { magnitude })
}
