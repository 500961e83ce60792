//! Coherence gate: a fixed-size bit mask over frequency bins.

/// Most bins a gate can hold: `N/2 + 1` for the largest segment `N = 4096`.
pub const MAX_GATE_BINS: usize = crate::fft::MAX_LEN / 2 + 1;
const WORDS: usize = MAX_GATE_BINS.div_ceil(32);

/// Bins whose magnitude-squared coherence reached a threshold (from
/// [`crate::welch::Welch::gate`]). Bit `k` set means bin `k` (frequency `k·fs/N`) passed.
///
/// Fixed size (65 words, 264 bytes) whatever `N`, so it can be copied, stored, or sent as is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CoherenceGate {
    words: [u32; WORDS],
    bins: usize,
}

impl CoherenceGate {
    /// Gate over `bins` bins (clamped to [`MAX_GATE_BINS`]) with no bin passing.
    pub const fn empty(bins: usize) -> Self {
        Self {
            words: [0; WORDS],
            bins: if bins > MAX_GATE_BINS {
                MAX_GATE_BINS
            } else {
                bins
            },
        }
    }

    /// Marks bin `k` as passing; ignored when `k >= bins()`.
    pub fn set(&mut self, k: usize) {
        if k < self.bins {
            if let Some(w) = self.words.get_mut(k / 32) {
                *w |= 1 << (k % 32);
            }
        }
    }

    /// `true` when bin `k` passed (`false` for `k >= bins()`).
    pub fn passes(&self, k: usize) -> bool {
        k < self.bins
            && self
                .words
                .get(k / 32)
                .is_some_and(|w| w & (1 << (k % 32)) != 0)
    }

    /// Number of bins the gate covers (`N/2 + 1`).
    pub fn bins(&self) -> usize {
        self.bins
    }

    /// Number of passing bins.
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// The raw mask words (bit `k % 32` of word `k / 32` is bin `k`).
    pub fn words(&self) -> &[u32] {
        &self.words
    }

    /// Passing bins in increasing order.
    pub fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.bins).filter(move |&k| self.passes(k))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_passes_count_iter() {
        let mut g = CoherenceGate::empty(513);
        for k in [0, 31, 32, 33, 512, 513, 10_000] {
            g.set(k);
        }
        assert_eq!(g.count(), 5);
        assert!(g.passes(512) && !g.passes(513) && !g.passes(1));
        assert_eq!(g.iter().collect::<Vec<_>>(), vec![0, 31, 32, 33, 512]);
        assert_eq!(CoherenceGate::empty(1 << 20).bins(), MAX_GATE_BINS);
    }
}
