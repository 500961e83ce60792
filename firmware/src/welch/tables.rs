//! Compile-time twiddle tables of the segment transform (flash, one pair per segment length).
//!
//! The transform of a segment of `N` real samples is a complex FFT of `M = N/2` points (radix-4
//! decimation in frequency, output in bit-reversed order, see [`super::kernels`]) followed by the
//! real-signal recombination. Both tables are read strictly in the order the kernels visit them,
//! so every access is a sequential load. Values are `f64` sines from [`crate::trig`] rounded once
//! to `f32`.

use crate::trig::{cos_frac, sin_frac};

/// Twiddle tables for segment length `N` (a power of two, `64..=4096`).
pub(super) struct Tables<const N: usize>;

/// `rev_bits(k, bits)`: the low `bits` bits of `k` in reverse order.
pub(super) const fn rev_bits(k: usize, bits: u32) -> usize {
    if bits == 0 {
        return 0;
    }
    ((k as u32).reverse_bits() >> (32 - bits)) as usize
}

impl<const N: usize> Tables<N> {
    /// `log2(M)`, `M = N/2` complex points.
    pub const LOG2_M: u32 = (N / 2).trailing_zeros();

    /// Radix-4 stage twiddles. For every stage of length `L = M, M/4, …` with `L >= 8` (the
    /// stage of length 4 has only unit twiddles), for `n = 0..L/4`, six values
    /// `[cos θ, sin θ, cos 2θ, sin 2θ, cos 3θ, sin 3θ]` with `θ = 2πn/L`. Stage `s` starts at
    /// entry [`Self::stage_offset`]`(s)` (in units of six). Uses `6·Σ L/4 < 2M = N` values.
    pub const FFT: [f32; N] = {
        let mut t = [0.0f32; N];
        let mut at = 0;
        let mut l = N / 2;
        while l >= 8 {
            let mut n = 0;
            while n < l / 4 {
                let mut j = 1;
                while j <= 3 {
                    t[at] = cos_frac((j * n) as u64, l as u64) as f32;
                    t[at + 1] = sin_frac((j * n) as u64, l as u64) as f32;
                    at += 2;
                    j += 1;
                }
                n += 1;
            }
            l /= 4;
        }
        t
    };

    /// Recombination twiddles `[cos φ, sin φ]`, `φ = 2πk/N`, for the bins `k = rev(p)` of the
    /// positions `p` visited by the recombination in order: for each level `l = 1..log2 M`,
    /// `p = 2^l + i`, `i = 0..2^(l-1)` (see [`super::kernels::combine`]). `M - 2` values used.
    pub const COMBINE: [f32; N] = {
        let mut t = [0.0f32; N];
        let bits = Self::LOG2_M;
        let mut at = 0;
        let mut l = 1;
        while l < bits {
            let b = 1usize << l;
            let mut i = 0;
            while i < b / 2 {
                let k = rev_bits(b + i, bits);
                t[at] = cos_frac(k as u64, N as u64) as f32;
                t[at + 1] = sin_frac(k as u64, N as u64) as f32;
                at += 2;
                i += 1;
            }
            l += 1;
        }
        t
    };

    /// Number of radix-4 stages (`⌊log2(M)/2⌋`); a final radix-2 stage follows when `log2 M`
    /// is odd.
    pub const RADIX4_STAGES: u32 = Self::LOG2_M / 2;

    /// Start of stage `s`'s twiddles in [`Self::FFT`], in units of six values.
    pub const fn stage_offset(s: u32) -> usize {
        let mut off = 0;
        let mut l = N / 2;
        let mut i = 0;
        while i < s {
            off += l / 4;
            l /= 4;
            i += 1;
        }
        off
    }
}
