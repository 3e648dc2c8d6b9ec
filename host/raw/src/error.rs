//! The crate's error type: every variant names the file and the problem.

use std::path::PathBuf;

use crate::kind::FileKind;

/// Why a file could not be sniffed, decoded, read or written.
#[derive(Debug, thiserror::Error)]
pub enum RawError {
    /// The file could not be read.
    #[error("{path}: cannot read")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The content is none of the kinds this crate knows.
    #[error(
        "{path}: unrecognised file content (not PNG, JPEG, TIFF, OpenEXR or a camera raw file)"
    )]
    UnrecognisedContent {
        /// The file.
        path: PathBuf,
    },
    /// A raw file whose extension says another kind, or a non-raw file named like a raw file.
    #[error("{path}: the file is {actual} but its name says {named}")]
    WrongExtension {
        /// The file.
        path: PathBuf,
        /// What the content is.
        actual: FileKind,
        /// What the extension says (the extension itself when it names no known kind).
        named: String,
    },
    /// The file is not a raw file (where one was needed).
    #[error("{path}: not a camera raw file (its content is {actual})")]
    NotRaw {
        /// The file.
        path: PathBuf,
        /// What it is.
        actual: FileKind,
    },
    /// The raw decoder failed (truncated or corrupt data, unsupported camera or compression).
    #[error("{path}: cannot decode the raw image: {reason}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The decoder's message.
        reason: String,
    },
    /// The header states what the file cannot hold (a directory chain that loops, an image
    /// larger than the file or than any camera's), or the file is not a regular file: refused
    /// before a decoder reads it.
    #[error("{path}: refused before decoding: {problem}")]
    Implausible {
        /// The file.
        path: PathBuf,
        /// What the header states and why it cannot be.
        problem: String,
    },
    /// The file is shorter than its own structure says.
    #[error("{path}: truncated: {what}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// What is missing.
        what: String,
    },
    /// A CFA layout other than a 2x2 Bayer pattern, or non-mosaic data.
    #[error("{path}: unsupported sensor layout {layout}: only 2x2 Bayer CFAs (RGGB, BGGR, GRBG, GBRG) are decoded")]
    UnsupportedLayout {
        /// The file.
        path: PathBuf,
        /// The layout found (e.g. `X-Trans 6x6 CFA`, `linear raw, 3 samples per pixel`).
        layout: String,
    },
    /// Black or white levels that leave no range (white <= black), or that are not finite.
    #[error("{path}: bad levels: {problem}")]
    BadLevels {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// An EXIF field that is present but cannot be read as its type (never guessed).
    #[error("{path}: EXIF {tag} = \"{value}\" cannot be read: {problem}")]
    BadExif {
        /// The file.
        path: PathBuf,
        /// The tag's name.
        tag: &'static str,
        /// The value as stored.
        value: String,
        /// What is wrong.
        problem: &'static str,
    },
    /// A [`crate::dng::DngImage`] that cannot be written as described.
    #[error("{path}: cannot write this DNG: {problem}")]
    BadDngImage {
        /// The target file.
        path: PathBuf,
        /// What is inconsistent.
        problem: String,
    },
    /// Writing a file failed.
    #[error(transparent)]
    Write(#[from] skinbrdf_core::fsio::WriteError),
}
