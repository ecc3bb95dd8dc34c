//! Errors, grouped by who is at fault. Every variant that concerns a file names it.

use std::path::PathBuf;

/// Everything that can go wrong in abysslight.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The user asked for something contradictory or impossible (bad option value, missing folder, ...).
    #[error("{0}")]
    Usage(String),

    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },

    /// A file is not a photo abysslight can read (corrupt, truncated, unsupported format or sample type).
    #[error("{}: cannot decode: {reason}", path.display())]
    Decode {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },

    /// A photo does not fit the mission (size or channel count differs from the first photo).
    #[error("{}: {reason}", path.display())]
    Mismatch {
        /// The file.
        path: PathBuf,
        /// How it differs.
        reason: String,
    },

    /// An output could not be encoded.
    #[error("{}: cannot encode: {reason}", path.display())]
    Encode {
        /// The output file.
        path: PathBuf,
        /// What the encoder said.
        reason: String,
    },

    /// The method's parameters are out of range ([`crate::method::params::Params::validate`]).
    #[error(transparent)]
    InvalidConfig(#[from] crate::method::params::InvalidConfig),

    /// A configuration file is malformed.
    #[error("{}: {reason}", path.display())]
    Config {
        /// The file.
        path: PathBuf,
        /// What is wrong in it.
        reason: String,
    },
}

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// The file this error is about (`None` for usage errors).
    pub fn path(&self) -> Option<&std::path::Path> {
        match self {
            Error::Io { path, .. }
            | Error::Decode { path, .. }
            | Error::Mismatch { path, .. }
            | Error::Encode { path, .. }
            | Error::Config { path, .. } => Some(path),
            Error::Usage(_) | Error::InvalidConfig(_) => None,
        }
    }

    /// The same error about `file` (for errors made without knowing the file, e.g. by the in-memory engine).
    pub fn about(self, file: &std::path::Path) -> Self {
        match self {
            Error::Mismatch { reason, .. } => Error::Mismatch {
                path: file.to_owned(),
                reason,
            },
            Error::Decode { reason, .. } => Error::Decode {
                path: file.to_owned(),
                reason,
            },
            Error::Encode { reason, .. } => Error::Encode {
                path: file.to_owned(),
                reason,
            },
            other => other,
        }
    }

    /// Short machine-readable kind, used in the run report.
    pub fn kind(&self) -> &'static str {
        match self {
            Error::Usage(_) | Error::InvalidConfig(_) => "usage",
            Error::Io { .. } => "io",
            Error::Decode { .. } => "decode",
            Error::Mismatch { .. } => "mismatch",
            Error::Encode { .. } => "encode",
            Error::Config { .. } => "config",
        }
    }
}

/// abysslight's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
