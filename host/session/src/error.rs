//! Errors of the session crate.
//!
//! Loading a session collects *every* problem it finds into [`SessionErrors`]: each
//! [`SessionProblem`] names the file (relative to the session directory where possible), the
//! field (a dotted/indexed path such as `images[3].linearization.white_level`) and what is wrong.

use std::fmt;
use std::path::PathBuf;

/// One problem found in a session directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SessionProblem {
    /// The file the problem is in (as given or as resolved inside the session directory).
    pub file: PathBuf,
    /// The field path, e.g. `images[3].role`; empty for whole-file problems.
    pub field: String,
    /// What is wrong, in words.
    pub problem: String,
}

impl fmt::Display for SessionProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            write!(f, "{}: {}", self.file.display(), self.problem)
        } else {
            write!(
                f,
                "{}: `{}`: {}",
                self.file.display(),
                self.field,
                self.problem
            )
        }
    }
}

/// Every problem found while loading a session (never empty when returned as an error).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SessionErrors {
    /// The problems, in the order they were found.
    pub problems: Vec<SessionProblem>,
}

impl SessionErrors {
    /// Records a problem.
    pub fn push(
        &mut self,
        file: impl Into<PathBuf>,
        field: impl Into<String>,
        problem: impl Into<String>,
    ) {
        self.problems.push(SessionProblem {
            file: file.into(),
            field: field.into(),
            problem: problem.into(),
        });
    }

    /// True when no problem was recorded.
    pub fn is_empty(&self) -> bool {
        self.problems.is_empty()
    }

    /// Number of problems.
    pub fn len(&self) -> usize {
        self.problems.len()
    }

    /// True if some problem's field path equals `field` (handy in tests and tools).
    pub fn has_field(&self, field: &str) -> bool {
        self.problems.iter().any(|p| p.field == field)
    }

    /// `Ok(value)` when empty, else `Err(self)`.
    pub fn into_result<T>(self, value: T) -> Result<T, SessionErrors> {
        if self.is_empty() {
            Ok(value)
        } else {
            Err(self)
        }
    }
}

impl fmt::Display for SessionErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} problem(s):", self.problems.len())?;
        for p in &self.problems {
            write!(f, "\n  - {p}")?;
        }
        Ok(())
    }
}

impl std::error::Error for SessionErrors {}

/// Errors reading or writing one file (images, masks, truth, atomic writes).
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be read or written.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The image could not be decoded or encoded.
    #[error("{path}: image")]
    Image {
        /// The file.
        path: PathBuf,
        /// The codec error.
        source: image::ImageError,
    },
    /// The file's content is not what the format requires.
    #[error("{path}: `{field}`: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field (or pixel format aspect) at fault.
        field: String,
        /// What is wrong.
        problem: String,
    },
    /// A camera raw file could not be sniffed or decoded, or its name disagrees with its
    /// content (the message names the file).
    #[error(transparent)]
    Raw(#[from] skinbrdf_raw::RawError),
    /// JSON (de)serialisation failed.
    #[error("{path}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The serde_json error (with line and column).
        source: serde_json::Error,
    },
    /// A value could not be written as JSON: a NaN or infinity (named by its field's path), or
    /// a value serde_json refuses. The message names the file.
    #[error(transparent)]
    JsonOut(#[from] skinbrdf_core::json::JsonError),
}
