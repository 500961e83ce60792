//! Pseudo-random binary sequence from a maximum-length linear feedback shift register.

use super::Excitation;
use crate::Error;

/// Feedback taps of maximum-length LFSRs, `TAPS[n - 5]` for register length `n` in `5..=31`.
///
/// Source: Xilinx application note XAPP052, P. Alfke, "Efficient Shift Registers, LFSR
/// Counters, and Long Pseudo-Random Sequence Generators" (1996), Table 3. Taps are numbered
/// 1..n; the feedback polynomial is `x^n + Σ x^t + 1` over the listed taps `t < n`, which is
/// primitive over GF(2) (checked for every `n` by the test `taps_are_primitive`), hence the
/// period `2^n - 1` for every non-zero state.
const TAPS: [&[u8]; 27] = [
    &[5, 3],
    &[6, 5],
    &[7, 6],
    &[8, 6, 5, 4],
    &[9, 5],
    &[10, 7],
    &[11, 9],
    &[12, 6, 4, 1],
    &[13, 4, 3, 1],
    &[14, 5, 3, 1],
    &[15, 14],
    &[16, 15, 13, 4],
    &[17, 14],
    &[18, 11],
    &[19, 6, 2, 1],
    &[20, 17],
    &[21, 19],
    &[22, 21],
    &[23, 18],
    &[24, 23, 22, 17],
    &[25, 22],
    &[26, 6, 2, 1],
    &[27, 5, 2, 1],
    &[28, 25],
    &[29, 27],
    &[30, 6, 4, 1],
    &[31, 28],
];

/// Smallest supported register length (bits).
pub const MIN_BITS: u8 = 5;
/// Largest supported register length (bits).
pub const MAX_BITS: u8 = 31;

/// Taps of the maximum-length register of `bits` bits (XAPP052), or `None` outside `5..=31`.
pub fn taps(bits: u8) -> Option<&'static [u8]> {
    if !(MIN_BITS..=MAX_BITS).contains(&bits) {
        return None;
    }
    TAPS.get(usize::from(bits - MIN_BITS)).copied()
}

/// Galois-form toggle mask of the register: bit `t-1` set for every tap `t`.
const fn galois_mask(taps: &[u8]) -> u32 {
    let mut m = 0u32;
    let mut i = 0;
    while i < taps.len() {
        m |= 1 << (taps[i] - 1);
        i += 1;
    }
    m
}

/// Maximum-length binary sequence (MLS) generator.
///
/// * Galois LFSR of `n` bits (`5..=31`): each chip the register shifts right by one, and when
///   the bit shifted out is 1 the tap mask is XORed in. The bit shifted out is the chip.
/// * One period is `2^n - 1` chips: `2^(n-1)` ones and `2^(n-1) - 1` zeros. Chip 1 is output as
///   `+amplitude`, chip 0 as `-amplitude`, so a period sums to `+amplitude` (one more `+`).
/// * Periodic autocorrelation is two-valued (`P·a²` at lag 0, `-a²` elsewhere), so the DFT of
///   one period (hold 1) is flat: `|X[k]|² = (P + 1)·a²` for `k ≠ 0`, `X[0] = a`.
/// * Hold-clock divider `hold`: each chip is repeated for `hold` samples, so one period lasts
///   `(2^n - 1)·hold` samples and the spectrum follows `|sin(πk/P) / sin(πk/(P·hold))|`, with
///   nulls at multiples of the chip rate `fs/hold`: choose `hold` to place the bandwidth
///   (useful band up to about `0.4·fs/hold`).
#[derive(Debug, Clone)]
pub struct Prbs {
    state: u32,
    seed: u32,
    mask: u32,
    bits: u8,
    amplitude: f32,
    hold: u32,
    remaining: u32,
    current: f32,
}

impl Prbs {
    /// New generator.
    ///
    /// * `bits`: register length `n` in `5..=31`, period `2^n - 1` chips.
    /// * `seed`: initial register state, must satisfy `1 <= seed < 2^n` (0 is the LFSR's
    ///   lock-up state and is rejected, as are seeds that do not fit; nothing is silently
    ///   masked). Different seeds give cyclic shifts of the same sequence.
    /// * `amplitude`: output level (finite, > 0); the output is `±amplitude`.
    /// * `hold`: samples per chip (>= 1).
    ///
    /// # Errors
    /// [`Error::InvalidRegisterLength`], [`Error::InvalidSeed`], [`Error::InvalidAmplitude`],
    /// [`Error::InvalidHold`].
    pub fn new(bits: u8, seed: u32, amplitude: f32, hold: u32) -> Result<Prbs, Error> {
        let taps = taps(bits).ok_or(Error::InvalidRegisterLength { bits })?;
        if seed == 0 || u64::from(seed) >= (1u64 << bits) {
            return Err(Error::InvalidSeed);
        }
        if !(amplitude.is_finite() && amplitude > 0.0) {
            return Err(Error::InvalidAmplitude);
        }
        if hold == 0 {
            return Err(Error::InvalidHold);
        }
        Ok(Prbs {
            state: seed,
            seed,
            mask: galois_mask(taps),
            bits,
            amplitude,
            hold,
            remaining: 0,
            current: 0.0,
        })
    }

    /// Register length `n` (bits).
    pub fn bits(&self) -> u8 {
        self.bits
    }

    /// Chips per period: `2^n - 1`.
    pub fn period_chips(&self) -> u32 {
        ((1u64 << self.bits) - 1) as u32
    }

    /// Samples per period: `(2^n - 1)·hold` (u64: up to `(2^31 - 1)·(2^32 - 1)`).
    pub fn period_samples(&self) -> u64 {
        u64::from(self.period_chips()) * u64::from(self.hold)
    }

    /// Samples per chip.
    pub fn hold(&self) -> u32 {
        self.hold
    }

    /// Current register state (never 0).
    pub fn state(&self) -> u32 {
        self.state
    }

    /// Restart from the seed (the sequence repeats exactly).
    pub fn reset(&mut self) {
        self.state = self.seed;
        self.remaining = 0;
        self.current = 0.0;
    }

    /// Advances the register by one chip and returns the chip bit (0 or 1).
    #[inline]
    pub fn next_chip(&mut self) -> u32 {
        let bit = self.state & 1;
        self.state = (self.state >> 1) ^ (self.mask & bit.wrapping_neg());
        bit
    }
}

impl Excitation for Prbs {
    /// `±amplitude`, each chip held for `hold` samples.
    #[inline]
    fn next_sample(&mut self) -> f32 {
        if self.remaining == 0 {
            let bit = self.next_chip();
            self.current = if bit == 1 {
                self.amplitude
            } else {
                -self.amplitude
            };
            self.remaining = self.hold;
        }
        self.remaining -= 1;
        self.current
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_covers_every_length_with_top_tap_n() {
        for n in MIN_BITS..=MAX_BITS {
            let t = taps(n).unwrap();
            assert_eq!(t[0], n, "first tap must be the register length");
            assert!(t.iter().all(|&x| x >= 1 && x <= n));
        }
        assert!(taps(4).is_none() && taps(32).is_none());
    }
}
