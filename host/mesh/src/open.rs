//! Opening a scan file, an untrusted input: a regular file within its size limit.

use std::path::Path;

use skinbrdf_core::untrusted::{open_regular, ReadError, SCAN_FILE};

use crate::error::MeshError;

/// Opens a scan file for reading: a regular file within [`skinbrdf_core::untrusted::SCAN_FILE`]
/// (a device or FIFO is refused at once). Returns the file and its length.
pub(crate) fn open_scan(path: &Path) -> Result<(std::fs::File, u64), MeshError> {
    let (file, len) = open_regular(path)?;
    if len > SCAN_FILE.max_bytes {
        return Err(ReadError::TooLarge {
            path: path.to_path_buf(),
            kind: SCAN_FILE.kind,
            size_bytes: len,
            max_bytes: SCAN_FILE.max_bytes,
        }
        .into());
    }
    Ok((file, len))
}
