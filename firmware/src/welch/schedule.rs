//! The work of one completed segment as a sequence of phases, executed in slices of bounded
//! cost ("ticks", calibrated to Cortex-M4F instructions under QEMU `-icount`).
//!
//! Phases, for the bank holding the completed segment (the *work bank*) and the bank now being
//! filled by `push` (the *fill bank*):
//! 1. `Copy`: the `overlap` newest samples of the work bank become the first samples of the
//!    fill bank (pushes write behind them, so this never races with `push`), and their sums are
//!    kept for the next segment's mean.
//! 2. `Sum`: the rest of the segment's samples are summed (only with mean removal); with the
//!    sums from the previous copy this gives the segment mean.
//! 3. `Stage(s)`: the radix-4 FFT stages of [`super::kernels`] (the first one centres and
//!    windows).
//! 4. `Combine`: the final radix-2 stage if any, recombination to the real spectrum, products
//!    added to the sums.
//! 5. `Edges`: DC, Nyquist and `N/4`; the segment counts as one more average.
//!
//! A dropped segment (it contains a rejected sample) and a segment beyond `MAX_AVERAGES` only
//! run `Copy`.

use super::kernels::Pair;
use super::tables::Tables;

/// Phase of the segment in work.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Phase {
    /// No segment in work.
    Idle,
    /// Copying the overlap into the fill bank.
    Copy,
    /// Summing the segment for its mean.
    Sum,
    /// FFT stage `s` (0 = first, windowed).
    Stage(u8),
    /// Recombination and accumulation of the mirror-pair bins.
    Combine,
    /// DC, Nyquist and `N/4` bins; completes the segment.
    Edges,
}

/// State of the segment in work.
#[derive(Debug, Clone, Copy)]
pub(super) struct Job {
    /// Current phase.
    pub phase: Phase,
    /// Work items of the current phase already done.
    pub done: u32,
    /// Work items of the current phase and ticks per item (set on entering the phase).
    pub items: u32,
    /// Ticks per work item of the current phase.
    pub cost: i32,
    /// Unspent work credit (ticks).
    pub credit: i32,
    /// First sample of the work bank that was written by `push` (0 for the first segment
    /// after a reset, `overlap` afterwards); samples before it came from the copy.
    pub seg_start: u32,
    /// Sums of the deviations of the segment's samples `(u, y)` from its first sample, turned
    /// into the means when the FFT starts.
    pub sum: Pair,
    /// The segment is transformed and accumulated (not dropped, not beyond the cap).
    pub accept: bool,
}

impl Job {
    /// No segment in work (all-zero bits, so that an unconfigured estimator is `.bss`).
    pub const IDLE: Job = Job {
        phase: Phase::Idle,
        done: 0,
        items: 0,
        cost: 1,
        credit: 0,
        seg_start: 0,
        sum: [0.0; 2],
        accept: false,
    };
}

/// Work-item costs in ticks (≈ Cortex-M4F instructions, both channels, measured by the QEMU
/// bench). Only the pacing depends on them: whatever their values, every segment's work is
/// complete before the next segment ends.
pub(super) mod cost {
    /// Copy of one overlap sample, even hop (two samples per quad move).
    pub const COPY_EVEN: i32 = 11;
    /// Copy of one overlap sample, odd hop (sample by sample).
    pub const COPY_ODD: i32 = 20;
    /// Copy of one overlap sample without sums (four pairs per block move), when the sums of
    /// the overlap come from the `Sum` phase or are not needed.
    pub const COPY_PLAIN: i32 = 3;
    /// Sum of one sample.
    pub const SUM: i32 = 6;
    /// First-stage radix-4 butterfly with centring and window.
    pub const FIRST: i32 = 175;
    /// Radix-4 butterfly with twiddles.
    pub const RADIX4: i32 = 110;
    /// Radix-4 butterfly with unit twiddles.
    pub const UNIT4: i32 = 70;
    /// Recombination and accumulation of one mirror pair (two bins); twice that for an item
    /// of the recombination fused with the radix-2 stage.
    pub const PAIR: i32 = 88;
    /// The edge bins and the bookkeeping of a completed segment.
    pub const EDGES: i32 = 150;
    /// Entering a phase (slice set-up).
    pub const PHASE: i32 = 150;
}

/// `true` when `log2(N/2)` is odd: the FFT ends with a radix-2 stage, which is fused into the
/// recombination (`kernels::combine_radix2`).
pub(super) const fn fused_radix2<const N: usize>() -> bool {
    Tables::<N>::LOG2_M % 2 == 1
}

/// Number of FFT stages run as phases: the radix-4 stages (a final radix-2 stage, when there
/// is one, is part of the recombination).
pub(super) const fn fft_stages<const N: usize>() -> u32 {
    Tables::<N>::RADIX4_STAGES
}

/// Length `L` of FFT stage `s` (`M, M/4, …`).
pub(super) const fn stage_len<const N: usize>(s: u32) -> usize {
    (N / 2) >> (2 * s)
}

/// `(items, ticks per item)` of phase `p` for segment length `N`.
pub(super) const fn phase_size<const N: usize>(
    p: Phase,
    overlap: usize,
    hop: usize,
    seg_start: usize,
    hann: bool,
    copy_sums: bool,
) -> (u32, i32) {
    let m = N / 2;
    match p {
        Phase::Idle => (0, 1),
        Phase::Copy => (
            overlap as u32,
            if !copy_sums {
                cost::COPY_PLAIN
            } else if hop.is_multiple_of(2) {
                cost::COPY_EVEN
            } else {
                cost::COPY_ODD
            },
        ),
        Phase::Sum => ((N - seg_start) as u32, cost::SUM),
        Phase::Stage(s) => {
            let l = stage_len::<N>(s as u32);
            if s == 0 {
                (
                    (m / 4) as u32,
                    if hann { cost::FIRST } else { cost::RADIX4 },
                )
            } else if l == 4 {
                ((m / 4) as u32, cost::UNIT4)
            } else if l == 8 {
                ((m / 8) as u32, 2 * cost::RADIX4)
            } else {
                ((m / 4) as u32, cost::RADIX4)
            }
        }
        Phase::Combine if fused_radix2::<N>() => ((m / 4) as u32, 2 * cost::PAIR),
        Phase::Combine => ((m / 2 - 1) as u32, cost::PAIR),
        Phase::Edges => (1, cost::EDGES),
    }
}

/// Ticks of work for one accepted segment with mean removal (the largest case; the first
/// segment after a reset sums all `N` samples), phase set-ups included.
pub(super) const fn segment_ticks<const N: usize>(overlap: usize, hop: usize, hann: bool) -> i64 {
    let mut total = 0i64;
    let copy_sums = copy_sums(true, true, hop, overlap);
    let phases = [Phase::Copy, Phase::Sum, Phase::Combine, Phase::Edges];
    let mut i = 0;
    while i < phases.len() {
        let (n, c) = phase_size::<N>(phases[i], overlap, hop, 0, hann, copy_sums);
        total += n as i64 * c as i64 + cost::PHASE as i64;
        i += 1;
    }
    let mut s = 0;
    while s < fft_stages::<N>() {
        let (n, c) = phase_size::<N>(Phase::Stage(s as u8), overlap, hop, 0, hann, copy_sums);
        total += n as i64 * c as i64 + cost::PHASE as i64;
        s += 1;
    }
    total
}

/// `true` when the `Copy` phase must sum the samples it copies (the next segment's mean
/// needs them and this segment's `Sum` phase will not see them): with mean removal, for a
/// segment that is not transformed (no `Sum` phase) or whose copied samples `hop..N` reach
/// before the samples it summed itself (`seg_start..N`, i.e. overlap above 50 %). Otherwise
/// the `Sum` phase keeps the sum of `hop..N` apart ([`Phase::Sum`]) and the copy is a plain
/// block move.
pub(super) const fn copy_sums(
    detrend_mean: bool,
    accept: bool,
    hop: usize,
    seg_start: usize,
) -> bool {
    detrend_mean && !(accept && hop >= seg_start)
}

/// Work is granted at *grant points*: the pushes after which the fill index `w + 1` is a
/// multiple of `S` pushes (`S` a power of two, at most `N`, so every segment end is one). A
/// grant point adds `S · budget` ticks to the credit and runs work items up to it; other pushes
/// do no scheduling at all (one mask test on the index they already hold).
///
/// Returns `(S - 1, S · budget)`: the largest `S <= 64` whose grant stays within
/// [`SLICE_TICKS`] (which bounds the largest push), with `budget` such that the
/// `G = ⌊(hop - 1)/S⌋` grant points strictly between two segment ends cover the segment's ticks
/// plus [`GRANT_MARGIN`] (unspent credit is less than one item). The segment end itself
/// completes any remainder ([`super::Welch::flush`]), so the cost model only paces the work; it
/// never decides whether the work is done.
pub(super) const fn grant_plan<const N: usize>(
    overlap: usize,
    hop: usize,
    hann: bool,
) -> (usize, i32) {
    if hop == 0 {
        return (0, 0);
    }
    let t = segment_ticks::<N>(overlap, hop, hann) + GRANT_MARGIN as i64;
    // At least one grant point between two segment ends: `S <= hop - 1` (or 1).
    let mut s = 64;
    while s > 1 && (s > N || s + 1 > hop) {
        s /= 2;
    }
    loop {
        // Checked divisions (`s >= 1`, `pushes >= 1`, but the compiler cannot see it): no
        // panic path in `new`/`configure`.
        let g = match (hop - 1).checked_div(s) {
            Some(g) if g >= 1 => g,
            _ => 1,
        };
        let pushes = (g * s) as i64;
        let b = match (t + pushes - 1).checked_div(pushes) {
            Some(b) => b,
            None => t,
        };
        let grant = b * s as i64;
        if grant <= SLICE_TICKS as i64 || s == 1 {
            let grant = if grant > i32::MAX as i64 / 4 {
                i32::MAX / 4
            } else {
                grant as i32
            };
            return (s - 1, grant);
        }
        s /= 2;
    }
}

/// Ticks a single grant may add at most (when the segment's work allows): it bounds the
/// largest push at about this many ticks plus one work item plus the push itself.
pub(super) const SLICE_TICKS: i32 = 3840;

/// Margin added to a segment's ticks when sizing the grants: the credit left unspent at the
/// end of a grant is less than one work item (at most `EDGES + PHASE`, 300 ticks).
pub(super) const GRANT_MARGIN: i32 = 512;

#[cfg(test)]
mod tests {
    use super::*;

    /// The grant points: a power of two `S <= N`, at least one strictly between two segment
    /// ends (`S <= hop - 1`, or `S = 1`), each within the slice bound unless `S = 1`; at
    /// N = 1024 with 50 % overlap, every 16 pushes.
    fn check<const N: usize>() {
        for hop in 1..=N {
            for hann in [true, false] {
                let (mask, grant) = grant_plan::<N>(N - hop, hop, hann);
                let s = mask + 1;
                assert!(s.is_power_of_two() && s <= N, "N={N} hop={hop}: S={s}");
                assert!(s == 1 || s < hop, "N={N} hop={hop}: S={s}");
                assert!(
                    grant > 0 && (grant <= SLICE_TICKS || s == 1),
                    "N={N} hop={hop}"
                );
                let g = if hop > s { (hop - 1) / s } else { 1 };
                let ticks = segment_ticks::<N>(N - hop, hop, hann);
                assert!(
                    g as i64 * grant as i64 >= ticks,
                    "N={N} hop={hop}: grants too small"
                );
            }
        }
    }

    #[test]
    fn grant_points_cover_a_segment_within_the_slice_bound() {
        check::<64>();
        check::<256>();
        check::<1024>();
        check::<4096>();
        assert_eq!(grant_plan::<1024>(512, 512, true).0, 15);
    }
}
