//! BRDF sample files: the compact binary format, CSV export, Cornell `.brdf` import/export.
//!
//! * [`binary`]: the project's own sample file (`.skbs`): a small fixed header, a JSON
//!   provenance header and little-endian records of [`skinbrdf_core::BrdfSample`] with its
//!   surface point on the scan (version 2; version-1 files, without it, still read). Written
//!   atomically by a streaming [`SampleWriter`]; read by a streaming [`SampleReader`] or at once
//!   by [`read_samples`].
//! * [`csv`]: a plain CSV export of the same records (and its reader, old and new columns).
//! * [`cornell`]: the Cornell gonioreflectometer text format (spectral, 31 bands 400..700 nm),
//!   kept spectral on import ([`CornellBrdf`]) and converted to linear sRGB for RGB fitting with
//!   [`SpectrumToRgb`] (CIE 1931 2° observer; see [`color`]).
//!
//! Every error names the file and, for text formats, the line.

pub mod binary;
pub mod color;
pub mod cornell;
pub mod csv;
mod error;

pub use binary::{
    read_samples, record_size, write_samples, SampleHeader, SampleReader, SampleWriter,
    FORMAT_VERSION, MAGIC, OLDEST_FORMAT_VERSION, RECORD_SIZE, RECORD_SIZE_V1,
};
pub use color::{Illuminant, SpectrumToRgb};
pub use cornell::{CornellBrdf, SpectralSample};
pub use csv::{read_csv, write_csv};
pub use error::SamplesError;

use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, flushed and
/// synced, then renamed over `path`. Readers never see a half-written file.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), SamplesError> {
    skinbrdf_core::fsio::write_atomic_with(path, write).map_err(|e| SamplesError::Io {
        path: e.path,
        source: e.source,
    })
}
