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
