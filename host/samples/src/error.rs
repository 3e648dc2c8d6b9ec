use std::path::PathBuf;

/// Errors reading or writing sample files. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum SamplesError {
    /// An I/O error on the file.
    #[error("{path}", path = path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file does not start with the sample-file magic.
    #[error("{path}: not a skinbrdf sample file (first bytes {}, expected {})", hex(found), hex(expected), path = path.display())]
    BadMagic {
        /// The file.
        path: PathBuf,
        /// The first eight bytes found.
        found: [u8; 8],
        /// The magic expected.
        expected: [u8; 8],
    },
    /// A format version this build does not read.
    #[error("{path}: sample file version {found} is not supported (this build reads versions {oldest} to {supported})", oldest = crate::binary::OLDEST_FORMAT_VERSION, path = path.display())]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// Version in the file.
        found: u32,
        /// The newest version this build reads.
        supported: u32,
    },
    /// The fixed header is inconsistent (record size, header length, record count).
    #[error("{path}: corrupt header: {problem}", path = path.display())]
    BadHeader {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// The file is shorter than its header says.
    #[error("{path}: truncated: the header announces {expected} records but the file holds {found}", path = path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Records announced.
        expected: u64,
        /// Complete records present.
        found: u64,
    },
    /// The file holds more than its header announces (the count was not patched after an
    /// interrupted write, or records were appended).
    #[error("{path}: {extra_bytes} bytes ({extra_records} whole records) follow the {count} records the header announces", path = path.display())]
    TrailingData {
        /// The file.
        path: PathBuf,
        /// Records announced.
        count: u64,
        /// Bytes after the announced records.
        extra_bytes: u64,
        /// Whole records in them.
        extra_records: u64,
    },
    /// A text file has a malformed line.
    #[error("{path}:{line}: {problem}", path = path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        problem: String,
    },
    /// A spectral conversion was asked for wavelengths outside the colour tables.
    #[error("{path}: wavelength {wavelength_nm} nm is outside the CIE table range 400..700 nm", path = path.display())]
    WavelengthOutOfRange {
        /// The file.
        path: PathBuf,
        /// The offending wavelength.
        wavelength_nm: f64,
    },
}

/// Bytes as hexadecimal pairs (`53 4b 42 ...`), for messages.
fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}
