//! The library's error type. Every variant names what was wrong and why, so the CLI (and later
//! the daemon) can pass the message straight to the user.

use std::path::PathBuf;

/// Errors from building or using omniwarp's objects.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A parameter was missing, non-finite, out of range or inconsistent with another.
    #[error("invalid `{name}`: {reason}")]
    Invalid { name: String, reason: String },
    /// A direction or screen position lies outside a projection's domain.
    #[error(transparent)]
    Outside(#[from] Outside),
    /// A file could not be read or written.
    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },
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

    /// Shorthand for [`Error::File`].
    pub fn file(path: impl Into<PathBuf>, reason: impl std::fmt::Display) -> Self {
        Error::File {
            path: path.into(),
            reason: reason.to_string(),
        }
    }
}

/// A point outside a projection's domain: the named projection cannot represent it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("outside the domain of projection `{projection}`: {reason}")]
pub struct Outside {
    pub projection: &'static str,
    pub reason: &'static str,
}

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
