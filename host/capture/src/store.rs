//! Writing `SESSION_DIR/capture.json` atomically.
//!
//! Every write serialises the whole [`CaptureRecord`] into a temporary file in the session
//! directory, flushes it to disk and renames it over `capture.json`. A rename within one
//! directory is atomic on POSIX file systems, so a reader (or a crash, or Ctrl-C) sees either the
//! previous complete file or the new complete file, never a torn one. The capture loop writes
//! after every shot, so an interrupted session keeps every shot the host received.

use std::io::Write;
use std::path::{Path, PathBuf};

use skinbrdf_session::capture::CaptureRecord;

/// File name of the capture record inside a session directory.
pub const CAPTURE_FILE_NAME: &str = "capture.json";

/// Why `capture.json` could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A file-system operation failed.
    #[error("{path}: cannot {action}")]
    Io {
        /// File or directory involved.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The record could not be serialised or parsed.
    #[error("{path}: {message}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The serde_json message.
        message: String,
    },
}

/// Writes `capture.json` into one session directory, atomically on each call.
#[derive(Debug, Clone)]
pub struct CaptureWriter {
    dir: PathBuf,
    path: PathBuf,
}

impl CaptureWriter {
    /// Creates the session directory if needed.
    pub fn create(session_dir: &Path) -> Result<Self, StoreError> {
        std::fs::create_dir_all(session_dir).map_err(|source| StoreError::Io {
            path: session_dir.to_path_buf(),
            action: "create the session directory",
            source,
        })?;
        Ok(Self {
            dir: session_dir.to_path_buf(),
            path: session_dir.join(CAPTURE_FILE_NAME),
        })
    }

    /// Path of the `capture.json` this writer replaces.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Replaces `capture.json` with `record` (temp file + fsync + rename).
    pub fn write(&self, record: &CaptureRecord) -> Result<(), StoreError> {
        let io = |action: &'static str, path: &Path| {
            let path = path.to_path_buf();
            move |source| StoreError::Io {
                path,
                action,
                source,
            }
        };
        let json = skinbrdf_core::json::to_vec_pretty(&self.path, record).map_err(|e| {
            StoreError::Json {
                path: self.path.clone(),
                message: e.problem(),
            }
        })?;
        let mut tmp = tempfile::Builder::new()
            .prefix(".capture.json.")
            .suffix(".tmp")
            .tempfile_in(&self.dir)
            .map_err(io("create a temporary file", &self.dir))?;
        tmp.write_all(&json)
            .and_then(|()| tmp.as_file().sync_all())
            .map_err(io("write a temporary file", tmp.path()))?;
        tmp.persist(&self.path)
            .map_err(|e| io("replace", &self.path)(e.error))?;
        // Make the rename itself durable (best effort: not all file systems allow it).
        if let Ok(d) = std::fs::File::open(&self.dir) {
            let _ = d.sync_all();
        }
        Ok(())
    }
}

/// Reads and parses a `capture.json`.
pub fn read_capture(path: &Path) -> Result<CaptureRecord, StoreError> {
    let text = std::fs::read_to_string(path).map_err(|source| StoreError::Io {
        path: path.to_path_buf(),
        action: "read",
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| StoreError::Json {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_session::capture::{
        CapturePlan, ClockModel, DeviceIdentity, Exposure, FlashMode, ImageRole, ShotGroup,
        ShotOutcome, CAPTURE_FORMAT_VERSION,
    };

    fn record(n: u32) -> CaptureRecord {
        CaptureRecord {
            format_version: CAPTURE_FORMAT_VERSION,
            plan: CapturePlan {
                groups: vec![ShotGroup {
                    label: "measurement".into(),
                    role: ImageRole::Measurement,
                    count: 3,
                    min_interval_us: 1_000_000,
                    pre_focus_us: 1000,
                    shutter_pulse_us: 1000,
                    xsync_timeout_us: 100_000,
                    flash_ready_timeout_us: 100_000,
                    flash_mode: FlashMode::CameraHotShoe,
                }],
                max_retries: 0,
            },
            device: DeviceIdentity {
                protocol_version: 1,
                firmware_version: "test".into(),
                serial: "X".into(),
                kind: "simulator".into(),
            },
            clock: ClockModel {
                device_ref_us: 0,
                host_ref_us: 1.7e15,
                drift_ppm: 0.0,
                residual_rms_us: 0.0,
                samples: 1,
            },
            exposures: (0..n)
                .map(|i| Exposure {
                    index: i,
                    group: 0,
                    role: ImageRole::Measurement,
                    shutter_command_us: u64::from(i) * 1_000_000,
                    xsync_us: Some(u64::from(i) * 1_000_000 + 80_000),
                    flash_fired_us: Some(u64::from(i) * 1_000_000 + 80_010),
                    recycle_us: None,
                    outcome: ShotOutcome::Ok,
                    host_time_us: 1.7e15,
                    image: None,
                })
                .collect(),
            complete: false,
        }
    }

    #[test]
    fn writes_and_replaces_without_leftovers() {
        let dir = tempfile::tempdir().expect("tempdir");
        let session = dir.path().join("s1");
        let w = CaptureWriter::create(&session).expect("create");
        for n in 0..4 {
            w.write(&record(n)).expect("write");
            let back = read_capture(w.path()).expect("read back");
            assert_eq!(back, record(n));
        }
        let names: Vec<_> = std::fs::read_dir(&session)
            .expect("list")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from(CAPTURE_FILE_NAME)]);
    }

    #[test]
    fn a_nan_time_is_refused_with_its_field_and_the_record_stays() {
        let dir = tempfile::tempdir().expect("tempdir");
        let w = CaptureWriter::create(&dir.path().join("s1")).expect("create");
        w.write(&record(3)).expect("write");
        let mut bad = record(3);
        bad.exposures[2].host_time_us = f64::NAN;
        let err = w.write(&bad).expect_err("NaN").to_string();
        assert!(err.contains("exposures[2].host_time_us"), "{err}");
        assert!(err.contains(CAPTURE_FILE_NAME), "{err}");
        assert_eq!(read_capture(w.path()).expect("the old record"), record(3));
    }

    #[test]
    fn unwritable_dir_is_named() {
        let err = CaptureWriter::create(Path::new("/proc/no-such/s"))
            .expect_err("cannot create")
            .to_string();
        assert!(err.contains("/proc/no-such/s"), "{err}");
    }
}
