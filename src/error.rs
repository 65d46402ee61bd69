//! The library's error type. Every variant names what was wrong and why, so the CLI (and later
//! the daemon) can pass the message straight to the user.

use std::path::PathBuf;

/// Errors from building or using omniwarp's objects.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A parameter was missing, non-finite, out of range or inconsistent with another.
    #[error("invalid `{name}`: {reason}")]
    Invalid {
        /// What was wrong: a parameter, JSON field or pointer, CLI flag, or a format (`png`).
        name: String,
        /// Why, in words a user can act on.
        reason: String,
    },
    /// A direction or screen position lies outside a projection's domain.
    #[error(transparent)]
    Outside(#[from] Outside),
    /// The work was given up because whoever asked for it no longer wants it (a daemon client
    /// went away).
    #[error("cancelled")]
    Cancelled,
    /// A file could not be read or written. `kind` is the operating system's reason where there
    /// was one, so callers can tell a missing file from a full disk or a closed pipe.
    #[error("{path}: {reason}")]
    File {
        /// The file (or directory) that could not be read or written.
        path: PathBuf,
        /// Why, as text (the operating system's message or a reader's).
        reason: String,
        /// The operating system's error kind, when the failure came from an I/O call.
        kind: Option<std::io::ErrorKind>,
    },
}

impl Error {
    /// Shorthand for [`Error::Invalid`].
    pub fn invalid(name: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Invalid {
            name: name.into(),
            reason: reason.into(),
        }
    }

    /// The reason alone, for callers that name the field themselves (a CLI flag, a JSON
    /// pointer).
    pub fn reason(self) -> String {
        match self {
            Error::Invalid { reason, .. } => reason,
            other => other.to_string(),
        }
    }

    /// Shorthand for [`Error::File`]; an [`std::io::Error`] as the reason keeps its kind.
    pub fn file(path: impl Into<PathBuf>, reason: impl std::fmt::Display + 'static) -> Self {
        let kind = (&reason as &dyn std::any::Any)
            .downcast_ref::<std::io::Error>()
            .map(std::io::Error::kind);
        Error::File {
            path: path.into(),
            reason: reason.to_string(),
            kind,
        }
    }

    /// The operating system's reason for a failed file operation, if that is what this is.
    pub fn io_kind(&self) -> Option<std::io::ErrorKind> {
        match self {
            Error::File { kind, .. } => *kind,
            _ => None,
        }
    }
}

/// A point outside a projection's domain: the named projection cannot represent it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("outside the domain of projection `{projection}`: {reason}")]
pub struct Outside {
    /// The projection's name as the CLI and JSON documents spell it (`equirect`, `fisheye`).
    pub projection: &'static str,
    /// Why the point is outside, e.g. "outside the image circle".
    pub reason: &'static str,
}

/// The library's result type; the error is [`Error`] unless given.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Rejects NaN and infinities, naming the parameter.
pub fn finite(name: &str, v: f64) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::invalid(
            name,
            format!("must be a finite number, got {v}"),
        ))
    }
}
