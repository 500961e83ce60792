//! The crate's single error type.
//!
//! Every fallible constructor or call returns `Result<_, Error>`; nothing in this crate panics on
//! bad input. Variants carry the offending index where there is one, so a caller can name the
//! bad entry (for instance the `index` into a multisine line list).

use core::fmt;

/// Everything that can go wrong in `ferrosid-firmware`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// PRBS register length outside `5..=31` bits.
    InvalidRegisterLength {
        /// The rejected register length in bits.
        bits: u8,
    },
    /// PRBS seed is zero (the all-zero LFSR state never leaves itself) or does not fit in the
    /// register (`seed >= 2^bits`).
    InvalidSeed,
    /// Hold-clock divider (samples per PRBS chip) is zero.
    InvalidHold,
    /// Amplitude is not finite or not strictly positive.
    InvalidAmplitude,
    /// Sample rate (Hz) is not finite or outside the supported range.
    InvalidSampleRate,
    /// A frequency (Hz) is not finite, negative (or zero for a logarithmic law), or not below
    /// Nyquist (`fs/2`).
    InvalidFrequency,
    /// A duration (s) is not finite, too short, or the fades do not fit into it.
    InvalidDuration,
    /// Welch overlap (samples) is not smaller than the segment length `N`.
    InvalidOverlap,
    /// `u` and `y` slices passed together have different lengths.
    LengthMismatch {
        /// Length of the input (`u`) slice.
        u: usize,
        /// Length of the output (`y`) slice.
        y: usize,
    },
    /// A multisine line has a bin outside `1..N/2` or a non-finite / non-positive amplitude.
    InvalidLine {
        /// Index of the offending entry in the line list.
        index: usize,
    },
    /// The same FFT bin appears twice in a multisine line list.
    DuplicateLine {
        /// Index of the second occurrence in the line list.
        index: usize,
    },
    /// A multisine line list is empty.
    NoLines,
    /// Odd random-phase multisine group size `G` is below 2 (a group needs one detection line
    /// and at least one excited line).
    InvalidGroupSize,
    /// A caller-provided output buffer is too small for the result.
    BufferTooSmall {
        /// Number of entries that would have been needed.
        needed: usize,
    },
    /// A control-law parameter (PID gain, compensation parameter, sample time) is not finite
    /// or out of its range; `what` names it (e.g. `dead_zone_inverse.smoothing`).
    InvalidControlParameter {
        /// The offending field.
        what: &'static str,
    },
}

impl Error {
    /// A short, static description (usable with `defmt`'s `{=str}` without formatting machinery).
    pub const fn as_str(&self) -> &'static str {
        match self {
            Error::InvalidRegisterLength { .. } => "PRBS register length must be in 5..=31 bits",
            Error::InvalidSeed => "PRBS seed must be non-zero and below 2^bits",
            Error::InvalidHold => "PRBS hold (samples per chip) must be at least 1",
            Error::InvalidAmplitude => "amplitude must be finite and > 0",
            Error::InvalidSampleRate => "sample rate must be finite and in [1e-6, 1e12] Hz",
            Error::InvalidFrequency => {
                "frequency must be finite, in [0, fs/2) (> 0 for a log chirp)"
            }
            Error::InvalidDuration => {
                "duration must be finite, span >= 2 samples and fit both fades"
            }
            Error::InvalidOverlap => "Welch overlap must be smaller than the segment length N",
            Error::LengthMismatch { .. } => "u and y slices have different lengths",
            Error::InvalidLine { .. } => "multisine line: bin outside 1..N/2 or bad amplitude",
            Error::DuplicateLine { .. } => "multisine line: bin listed twice",
            Error::NoLines => "multisine line list is empty",
            Error::InvalidGroupSize => "odd multisine group size must be at least 2",
            Error::BufferTooSmall { .. } => "output buffer too small",
            Error::InvalidControlParameter { .. } => "control parameter not finite or out of range",
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())?;
        match *self {
            Error::InvalidRegisterLength { bits } => write!(f, " (bits = {bits})"),
            Error::LengthMismatch { u, y } => write!(f, " (u.len() = {u}, y.len() = {y})"),
            Error::InvalidLine { index } | Error::DuplicateLine { index } => {
                write!(f, " (lines[{index}])")
            }
            Error::BufferTooSmall { needed } => write!(f, " (needs {needed} entries)"),
            Error::InvalidControlParameter { what } => write!(f, " ({what})"),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_names_the_offending_value() {
        assert_eq!(
            Error::LengthMismatch { u: 3, y: 2 }.to_string(),
            "u and y slices have different lengths (u.len() = 3, y.len() = 2)"
        );
        assert!(Error::InvalidLine { index: 7 }
            .to_string()
            .ends_with("(lines[7])"));
        assert!(Error::InvalidRegisterLength { bits: 40 }
            .to_string()
            .contains("bits = 40"));
        assert!(Error::BufferTooSmall { needed: 12 }
            .to_string()
            .contains("12"));
        assert_eq!(Error::InvalidSeed.to_string(), Error::InvalidSeed.as_str());
    }
}
