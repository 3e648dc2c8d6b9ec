//! Errors, each naming the file.

use std::path::PathBuf;

/// What went wrong reading a raw file with LibRaw.
#[derive(Debug, thiserror::Error)]
pub enum LibRawError {
    /// The file could not be read.
    #[error("{}: cannot read the file: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is larger than LibRaw is given in memory.
    #[error("{}: the file has {size_bytes} bytes, more than the {max_bytes} read for LibRaw", path.display())]
    TooLarge {
        path: PathBuf,
        size_bytes: u64,
        max_bytes: u64,
    },
    /// LibRaw could not allocate its state.
    #[error("{}: LibRaw could not allocate its state", path.display())]
    Init { path: PathBuf },
    /// LibRaw did not identify the file as a raw file it reads.
    #[error("{}: LibRaw cannot read it: {message} (LibRaw error {code})", path.display())]
    Open {
        path: PathBuf,
        code: i32,
        message: String,
    },
    /// LibRaw identified the file but could not unpack its image data.
    #[error("{}: LibRaw cannot unpack its image data: {message} (LibRaw error {code})", path.display())]
    Unpack {
        path: PathBuf,
        code: i32,
        message: String,
    },
    /// LibRaw unpacked the image data but reported it corrupt or cut short.
    #[error("{}: LibRaw found the image data {}", path.display(), data_problem(*count, *first_offset))]
    CorruptData {
        path: PathBuf,
        count: u32,
        first_offset: Option<i64>,
    },
    /// The image data is not a one-colour-per-photosite mosaic.
    #[error("{}: LibRaw unpacked {layout}, not a colour filter mosaic", path.display())]
    NotMosaic { path: PathBuf, layout: &'static str },
    /// LibRaw's sizes do not describe the data it unpacked.
    #[error("{}: LibRaw's sizes do not fit its image data: {detail}", path.display())]
    Sizes { path: PathBuf, detail: String },
}

impl LibRawError {
    /// The file the error is about.
    pub fn path(&self) -> &std::path::Path {
        match self {
            LibRawError::Io { path, .. }
            | LibRawError::TooLarge { path, .. }
            | LibRawError::Init { path }
            | LibRawError::Open { path, .. }
            | LibRawError::Unpack { path, .. }
            | LibRawError::CorruptData { path, .. }
            | LibRawError::NotMosaic { path, .. }
            | LibRawError::Sizes { path, .. } => path,
        }
    }

    /// The error in words without the file's name (for a message that names it already).
    pub fn reason(&self) -> String {
        let text = self.to_string();
        let prefix = format!("{}: ", self.path().display());
        match text.strip_prefix(&prefix) {
            Some(rest) => rest.to_string(),
            None => text,
        }
    }
}

/// A data error in words.
fn data_problem(count: u32, first_offset: Option<i64>) -> String {
    let first = match first_offset {
        Some(offset) => format!("corrupt at byte {offset}"),
        None => "ending before the image is complete".to_string(),
    };
    match count {
        0 | 1 => first,
        n => format!("{first} ({n} errors in all)"),
    }
}

/// The step a [`Failure`] happened in.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Step {
    Open,
    Unpack,
}

/// A failure inside the FFI layer, before the file's path is attached.
#[derive(Debug)]
pub(crate) enum Failure {
    Init,
    Code {
        code: i32,
        message: String,
    },
    Data {
        count: u32,
        first_offset: Option<i64>,
    },
    NotMosaic(&'static str),
    Sizes(String),
}

impl Failure {
    /// The failure as an error naming `path`.
    pub(crate) fn at(self, path: &std::path::Path, step: Step) -> LibRawError {
        let path = path.to_path_buf();
        match (self, step) {
            (Failure::Init, _) => LibRawError::Init { path },
            (Failure::Code { code, message }, Step::Open) => LibRawError::Open {
                path,
                code,
                message,
            },
            (Failure::Code { code, message }, Step::Unpack) => LibRawError::Unpack {
                path,
                code,
                message,
            },
            (
                Failure::Data {
                    count,
                    first_offset,
                },
                _,
            ) => LibRawError::CorruptData {
                path,
                count,
                first_offset,
            },
            (Failure::NotMosaic(layout), _) => LibRawError::NotMosaic { path, layout },
            (Failure::Sizes(detail), _) => LibRawError::Sizes { path, detail },
        }
    }
}
