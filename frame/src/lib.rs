//! The spectra frame a target emits after its power-up self-identification: the one definition
//! of its wire format, shared by the emitter (`firmware/app`, through defmt) and the host parser
//! (`ferrosid::target_frame`).
//!
//! The target logs text lines; the frame is the block
//!
//! ```text
//! FRAME_BEGIN fs=<Hz> n=<N> averages=<a> dropped=<d> window=<w> overlap=<o> detrend=<m> excited_max_bin=<b> gate=<g>
//! FRAME <bin> <S_uu> <S_yy> <Re S_uy> <Im S_uy> <coherence>      (bins 0..=N/2, ascending)
//! FRAME_END bins=<N/2+1>
//! ```
//!
//! with one-sided Welch densities (units²/Hz) and magnitude-squared coherence, preceded by the
//! receipt lines of the on-target check (`RECEIPT` with [`RECEIPT_FIELDS`], one per check
//! frequency) and followed by one `VERDICT <word> ...` line. Lines may carry a prefix (log level,
//! time stamp): a line is recognised by its first whitespace-separated token that is a
//! [`Keyword`] ([`split_line`]).
//!
//! `no_std`, no dependencies, no allocation, no panic path: the firmware links it.
#![cfg_attr(not(test), no_std)]

/// The keyword that starts each kind of frame line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Keyword {
    /// `FRAME_BEGIN key=value ...`: the frame header ([`HEADER_KEYS`]).
    Begin,
    /// `FRAME <bin> ...`: one frequency bin ([`BIN_FIELDS`]).
    Bin,
    /// `FRAME_END bins=<count>` ([`END_COUNT_PREFIX`]).
    End,
    /// `RECEIPT ...`: one check frequency of the on-target check ([`RECEIPT_FIELDS`]).
    Receipt,
    /// `VERDICT <word> ...`: the overall verdict of the check.
    Verdict,
}

impl Keyword {
    /// Every keyword.
    pub const ALL: [Keyword; 5] = [
        Keyword::Begin,
        Keyword::Bin,
        Keyword::End,
        Keyword::Receipt,
        Keyword::Verdict,
    ];

    /// The token on the wire.
    pub const fn as_str(self) -> &'static str {
        match self {
            Keyword::Begin => "FRAME_BEGIN",
            Keyword::Bin => "FRAME",
            Keyword::End => "FRAME_END",
            Keyword::Receipt => "RECEIPT",
            Keyword::Verdict => "VERDICT",
        }
    }

    /// The keyword spelled exactly `token`, if any.
    pub fn from_token(token: &str) -> Option<Keyword> {
        Keyword::ALL.into_iter().find(|k| k.as_str() == token)
    }
}

/// Header keys of `FRAME_BEGIN`, in the order the firmware writes them (`key=value` tokens).
/// `fs` (sample rate, Hz) and `n` (Welch segment length) are required; the others optional.
pub const HEADER_KEYS: [&str; 9] = [
    KEY_FS,
    KEY_N,
    KEY_AVERAGES,
    "dropped",
    "window",
    "overlap",
    "detrend",
    KEY_EXCITED_MAX_BIN,
    KEY_GATE,
];
/// Header key: sample rate in Hz (required, finite, > 0).
pub const KEY_FS: &str = "fs";
/// Header key: Welch segment length N (required, [`segment_length_ok`]).
pub const KEY_N: &str = "n";
/// Header key: number of segments averaged.
pub const KEY_AVERAGES: &str = "averages";
/// Header key: highest bin the excitation drives.
pub const KEY_EXCITED_MAX_BIN: &str = "excited_max_bin";
/// Header key: the target's coherence gate, in [0, 1].
pub const KEY_GATE: &str = "gate";

/// Fields of a `FRAME` line after the keyword: bin index, S_uu, S_yy, Re S_uy, Im S_uy
/// (units²/Hz) and coherence.
pub const BIN_FIELDS: [&str; 6] = ["bin", "S_uu", "S_yy", "Re S_uy", "Im S_uy", "coherence"];

/// Fields of a `RECEIPT` line after the keyword: Welch bin, frequency (Hz), coherence, the
/// flashed model G0 (re, im), the measured H1 (re, im), |G_meas − G0|/|G0|, |W_m|, the
/// estimate's normalised random error σ, and the verdict word.
pub const RECEIPT_FIELDS: [&str; 11] = [
    "bin",
    "hz",
    "coherence",
    "G0 re",
    "G0 im",
    "Gmeas re",
    "Gmeas im",
    "relative error",
    "|W_m|",
    "sigma",
    "verdict",
];

/// Prefix of the count token of `FRAME_END` (`bins=<N/2+1>`).
pub const END_COUNT_PREFIX: &str = "bins=";

/// Smallest Welch segment length a target uses.
pub const MIN_SEGMENT: usize = 64;
/// Largest Welch segment length a target uses.
pub const MAX_SEGMENT: usize = 4096;

/// True for the segment lengths a target uses: powers of two in
/// [`MIN_SEGMENT`]..=[`MAX_SEGMENT`].
pub const fn segment_length_ok(n: usize) -> bool {
    n.is_power_of_two() && n >= MIN_SEGMENT && n <= MAX_SEGMENT
}

/// Number of one-sided bins of a segment of length `n`: N/2 + 1.
pub const fn bin_count(n: usize) -> usize {
    n / 2 + 1
}

/// Splits a decoded log line at its first token that is a [`Keyword`]: returns the keyword and
/// the whitespace-separated tokens after it, or `None` for a line that is not part of a frame.
pub fn split_line(line: &str) -> Option<(Keyword, core::str::SplitWhitespace<'_>)> {
    let mut tokens = line.split_whitespace();
    for t in tokens.by_ref() {
        if let Some(k) = Keyword::from_token(t) {
            return Some((k, tokens));
        }
    }
    None
}

/// Splits a `FRAME_BEGIN` token into (key, value); `None` when it is not `key=value`.
pub fn header_field(token: &str) -> Option<(&str, &str)> {
    token.split_once('=')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keywords_round_trip_and_are_distinct() {
        for k in Keyword::ALL {
            assert_eq!(Keyword::from_token(k.as_str()), Some(k));
        }
        assert_eq!(Keyword::from_token("FRAMES"), None);
        assert_eq!(Keyword::from_token("frame"), None);
    }

    #[test]
    fn split_line_skips_a_prefix_and_keeps_the_rest() {
        let (k, rest) = split_line("[INFO ] 0.25 FRAME 3 1 2 3 4 0.5").unwrap();
        assert_eq!(k, Keyword::Bin);
        assert_eq!(rest.collect::<Vec<_>>(), ["3", "1", "2", "3", "4", "0.5"]);
        let (k, rest) = split_line("FRAME_END bins=33").unwrap();
        assert_eq!((k, rest.count()), (Keyword::End, 1));
        assert!(split_line("STACK 1024").is_none());
        assert!(split_line("").is_none());
    }

    #[test]
    fn segment_lengths_and_bin_counts() {
        let ok: Vec<usize> = (0..=8192).filter(|&n| segment_length_ok(n)).collect();
        assert_eq!(ok, [64, 128, 256, 512, 1024, 2048, 4096]);
        assert_eq!(bin_count(64), 33);
        assert_eq!(header_field("fs=1000"), Some(("fs", "1000")));
        assert_eq!(header_field("fs"), None);
    }
}
