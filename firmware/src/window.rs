//! Segment windows for the Welch estimator, as compile-time tables in flash.
//!
//! The Hann window is the *periodic* ("DFT-even") Hann of `scipy.signal.get_window('hann', N)`
//! (the default of `scipy.signal.welch/csd/coherence`):
//! `w[n] = 0.5 - 0.5·cos(2π n / N) = sin²(π n / N)`, `n = 0..N-1`.
//! It is evaluated in `f64` by the `const fn` sine of [`crate::trig`] and rounded once to `f32`
//! (error below one `f32` ulp), so the table is a `const` in flash, never a RAM copy.

use crate::trig::sin_frac;

/// Data window applied to each Welch segment before its FFT.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Window {
    /// Periodic Hann, `w[n] = sin²(π n / N)`. Default: sidelobes fall at 18 dB/octave, the
    /// choice for random or non-synchronous excitation.
    #[default]
    Hann,
    /// Rectangular (all ones). Use it for period-synchronous averaging of a periodic excitation
    /// (multisine, PRBS) whose period divides `N`: then there is no leakage at all.
    Rectangular,
}

/// Compile-time periodic Hann table of length `N` (see the module documentation).
pub struct HannTable<const N: usize>;

impl<const N: usize> HannTable<N> {
    /// `TABLE[n] = sin²(π n / N)` rounded to `f32`.
    pub const TABLE: [f32; N] = {
        let mut t = [0.0f32; N];
        let mut n = 0;
        while n < N {
            let s = sin_frac(n as u64, 2 * N as u64); // sin(π n / N)
            t[n] = (s * s) as f32;
            n += 1;
        }
        t
    };
    /// `Σ w[n]²` of the `f32` table, summed in `f64` (= `3N/8` up to rounding).
    pub const SUM_SQUARES: f32 = {
        let mut acc = 0.0f64;
        let mut n = 0;
        while n < N {
            let w = Self::TABLE[n] as f64;
            acc += w * w;
            n += 1;
        }
        acc as f32
    };
}

impl Window {
    /// `Σ w[n]²` over one segment of length `N` (the `S2` of the density scaling
    /// `1 / (fs · S2)`): `3N/8` for Hann, `N` for rectangular.
    pub const fn sum_squares<const N: usize>(self) -> f32 {
        match self {
            Window::Hann => HannTable::<N>::SUM_SQUARES,
            Window::Rectangular => N as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hann_matches_closed_form() {
        // Reference: std f64 cosine, periodic Hann definition; tolerance 1 f32 ulp of 1.0.
        fn check<const N: usize>() {
            let t = &HannTable::<N>::TABLE;
            for (n, &w) in t.iter().enumerate() {
                let e = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * n as f64 / N as f64).cos();
                assert!((w as f64 - e).abs() <= 6e-8, "N={N} n={n}: {w} vs {e}");
            }
            let s2 = HannTable::<N>::SUM_SQUARES as f64;
            assert!(
                (s2 - 3.0 * N as f64 / 8.0).abs() < 1e-6 * N as f64,
                "N={N}: S2={s2}"
            );
        }
        check::<64>();
        check::<256>();
        check::<1024>();
        check::<4096>();
        assert_eq!(Window::Rectangular.sum_squares::<128>(), 128.0);
    }

    #[test]
    fn table_is_a_promoted_constant() {
        // A `'static` borrow compiles only if the table is a constant in the image (flash),
        // not a per-call stack copy.
        let t: &'static [f32; 512] = &HannTable::<512>::TABLE;
        assert_eq!(t[0], 0.0);
        assert_eq!(t[256], 1.0);
    }
}
