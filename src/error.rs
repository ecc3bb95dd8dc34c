//! Errors, grouped by who is at fault. Every variant that concerns a file names it.

use std::path::PathBuf;

use crate::limits::{DEGREE as MAX_DEGREE, DOWNSAMPLE as MAX_DOWNSAMPLE, WINDOW as MAX_WINDOW};

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

    /// The method's parameters are out of range ([`Params::validate`](crate::Params::validate)).
    #[error(transparent)]
    InvalidConfig(#[from] InvalidConfig),

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

/// Why [`Params`](crate::Params) cannot run ([`Params::validate`](crate::Params::validate)): each variant names the option and the value, in the
/// command line's words.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum InvalidConfig {
    /// The window is not an odd number of photos from 1 to [`limits::WINDOW`](crate::limits::WINDOW).
    #[error("--window must be an odd number of photos from 1 to {MAX_WINDOW}, got {0}")]
    Window(usize),
    /// The contamination rate is not in `[0, 0.5)`.
    #[error(
        "--contamination must be in [0, 0.5), got {0}{hint}: a median breaks down once half its samples are \
         contaminated, so no window size can help; {DENSE_HINT}",
        hint = percent_hint(*.0)
    )]
    Contamination(f64),
    /// The breakdown probability is not in `(0, 1)`.
    #[error("--risk must be in (0, 1), got {0}")]
    Risk(f64),
    /// No window up to [`limits::WINDOW`](crate::limits::WINDOW) photos keeps the breakdown probability at `risk`.
    #[error(
        "no window up to {MAX_WINDOW} photos brings P_half below {risk} at contamination {contamination}; \
         {DENSE_HINT}"
    )]
    NoWindow {
        /// The contamination rate.
        contamination: f64,
        /// The breakdown probability asked.
        risk: f64,
    },
    /// The block size is above [`limits::DOWNSAMPLE`](crate::limits::DOWNSAMPLE).
    #[error("--downsample must be auto or 1 to {MAX_DOWNSAMPLE}, got {0}")]
    Downsample(usize),
    /// The near window is not off, auto or an odd number of photos up to
    /// [`limits::WINDOW`](crate::limits::WINDOW).
    #[error("--near-window must be auto, 0 (off) or an odd number of photos up to {MAX_WINDOW}, got {0}")]
    NearWindow(usize),
    /// The factor floor is not in `(0, 1]`.
    #[error("--factor-floor must be above 0 and at most 1, got {0}")]
    FactorFloor(f32),
    /// The relative floor is not in `(0, 1)`.
    #[error("--relative-floor must be above 0 and below 1, got {0}")]
    RelativeFloor(f32),
    /// The scale of `S` is not in `(0, 2]`.
    #[error("--backscatter-scale must be above 0 and at most 2 (or auto), got {0}")]
    BackscatterScale(f32),
    /// The polynomial's degree is not 1 to [`limits::DEGREE`](crate::limits::DEGREE).
    #[error("--degree must be 1 to {MAX_DEGREE}, got {0}")]
    Degree(usize),
}

/// What to do instead when `--contamination` asks for more than the median's window rule can give.
const DENSE_HINT: &str = "for dark clutter this dense (a nodule field) give no --contamination and no --window: the \
     default (--window auto) surveys the photos and takes a higher quantile of a shorter window per stretch";

/// For a contamination given in per cent (`--contamination 20`): `" (did you mean 0.2, that is 20 %?)"`; else
/// nothing. A share is a number below 1, so 1 to 100 reads as per cent.
fn percent_hint(c: f64) -> String {
    match (1.0..=100.0).contains(&c) {
        true => format!(" (did you mean {}, that is {c} %?)", c / 100.0),
        false => String::new(),
    }
}
