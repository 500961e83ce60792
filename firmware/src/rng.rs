//! Small seeded pseudo-random generator (SplitMix64) for reproducible random phases and line
//! choices. Not cryptographic; deterministic for a given seed on every platform.
//!
//! This is the workspace's one generator: the dev crate `ferrosid-sim` builds its uniform and
//! normal draws (`ferrosid_sim::rng::Rng`) on it, and every test, benchmark and example uses one
//! of the two (`host/tests/layers.rs` fails on a second SplitMix64 or xorshift/LCG constant).

/// SplitMix64 (Steele, Lea & Flood 2014; the seeding generator of xoshiro): 64-bit state,
/// passes BigCrush, every seed (including 0) is valid.
#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// Generator seeded with `seed` (any value).
    pub const fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// Next 64 uniformly distributed bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Next 32 uniformly distributed bits (the high half of [`Self::next_u64`]).
    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    /// Uniform `f64` in `[0, 1)` from the high 53 bits of [`Self::next_u64`] (every value a
    /// multiple of 2⁻⁵³).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform integer in `0..n` by multiply-shift (bias below `n / 2^32`); `n == 0` gives 0.
    pub fn below(&mut self, n: u32) -> u32 {
        ((self.next_u32() as u64 * n as u64) >> 32) as u32
    }
}
