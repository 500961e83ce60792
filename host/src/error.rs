//! The crate's one error type. Every variant that concerns input data names the file and, where
//! it applies, the line (CSV/text) or variable (.mat) at fault. New variants are appended.
use std::path::PathBuf;

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in ferrosid, with enough context to act on it.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file could not be opened or read.
    #[error("{}: {source}", file.display())]
    Io {
        /// File concerned.
        file: PathBuf,
        /// Underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A text/CSV file has a malformed or invalid entry at a given line (1-based).
    #[error("{}:{line}: {msg}", file.display())]
    Parse {
        /// File concerned.
        file: PathBuf,
        /// 1-based line number in the file.
        line: usize,
        /// What is wrong.
        msg: String,
    },
    /// A .mat variable is missing or unusable.
    #[error("{}: variable `{var}`: {msg}", file.display())]
    MatVar {
        /// File concerned.
        file: PathBuf,
        /// Variable name.
        var: String,
        /// What is wrong.
        msg: String,
    },
    /// The data as a whole is unusable for the requested analysis (constant input, too short,
    /// mismatched lengths, ...).
    #[error("{}: {msg}", file.display())]
    Data {
        /// File (or log name) concerned.
        file: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// Caller asked for something inconsistent (bad option values, order range, ...).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A numerical step failed or its result cannot be trusted (ill-conditioned, unstable, ...).
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// Longest excerpt of user data (a field, a name) that an error message quotes, in characters.
pub const EXCERPT_CHARS: usize = 60;

/// `s` as quoted in an error message: control characters (NUL, escapes, newlines) escaped, and
/// cut to [`EXCERPT_CHARS`] characters with an ellipsis and the full length, so that a 50 MB
/// field or 50 kB of NULs never ends up whole on the terminal.
pub fn excerpt(s: &str) -> String {
    excerpt_n(s, EXCERPT_CHARS)
}

/// [`excerpt`] with a caller-chosen length (e.g. longer for a list of names).
pub fn excerpt_n(s: &str, max_chars: usize) -> String {
    let mut out = String::new();
    for (shown, c) in s.chars().enumerate() {
        if shown >= max_chars {
            out.push_str(&format!("… ({} bytes in all)", s.len()));
            return out;
        }
        if c.is_control() {
            out.extend(c.escape_debug());
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn excerpts_are_short_and_printable() {
        assert_eq!(excerpt("1.5x"), "1.5x");
        assert_eq!(excerpt("a\0b"), "a\\0b");
        let long = "9".repeat(10_000);
        let e = excerpt(&long);
        assert!(e.starts_with(&"9".repeat(EXCERPT_CHARS)));
        assert!(e.ends_with("… (10000 bytes in all)"), "{e}");
        let nuls = "\0".repeat(50_000);
        assert!(excerpt(&nuls).len() < 4 * EXCERPT_CHARS);
    }
}
