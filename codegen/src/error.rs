//! The crate's single error type.
use std::path::PathBuf;

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong while generating headers.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A field of the [`crate::CodegenInput`] is unusable; `field` names it (e.g. `model.a[1][0]`).
    #[error("codegen input `{field}`: {msg}")]
    Input {
        /// Path of the offending field.
        field: String,
        /// What is wrong.
        msg: String,
    },
    /// A template could not be read.
    #[error("{}: {source}", file.display())]
    TemplateIo {
        /// Template file.
        file: PathBuf,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A template failed to render (syntax error, unknown variable); the message names the
    /// template and, for user templates, the line.
    #[error("template {template}: {msg}")]
    Render {
        /// Template name or path.
        template: String,
        /// Engine message.
        msg: String,
    },
}

impl Error {
    pub(crate) fn input(field: impl Into<String>, msg: impl Into<String>) -> Self {
        Error::Input {
            field: field.into(),
            msg: msg.into(),
        }
    }
}
