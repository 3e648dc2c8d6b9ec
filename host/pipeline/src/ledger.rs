//! Resumability: a stage whose inputs have not changed is not run again.
//!
//! Each stage's inputs (file contents and the stage's configuration) are hashed with BLAKE3
//! into a [`Fingerprint`]. After a stage runs, its fingerprint, its output files and its report
//! are recorded in `out/ledger.json` (written atomically). On the next run a stage is reused
//! when its fingerprint is unchanged *and* every output it recorded still exists.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::plan::Stage;
use crate::report::StageReport;

/// Errors of the ledger.
#[derive(Debug, thiserror::Error)]
pub enum LedgerError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The ledger file is not valid JSON of the expected shape.
    #[error("{path}: not a valid ledger: {source}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// The parse error.
        #[source]
        source: serde_json::Error,
    },
}

/// A BLAKE3 digest (hex) of a stage's inputs.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Fingerprint(pub String);

/// Accumulates a stage's inputs into a [`Fingerprint`].
#[derive(Debug, Default)]
pub struct FingerprintBuilder {
    hasher: blake3::Hasher,
}

impl FingerprintBuilder {
    /// A new, empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a labelled byte string (the label keeps `("a","bc")` apart from `("ab","c")`).
    pub fn bytes(mut self, label: &str, bytes: &[u8]) -> Self {
        self.hasher.update(&(label.len() as u64).to_le_bytes());
        self.hasher.update(label.as_bytes());
        self.hasher.update(&(bytes.len() as u64).to_le_bytes());
        self.hasher.update(bytes);
        self
    }

    /// Adds a serialisable value (e.g. the stage's config) by its JSON form.
    pub fn value<T: Serialize>(self, label: &str, value: &T) -> Self {
        let json = serde_json::to_vec(value).unwrap_or_default();
        self.bytes(label, &json)
    }

    /// Adds a file's contents, streamed.
    pub fn file(mut self, path: &Path) -> Result<Self, LedgerError> {
        let io = |source| LedgerError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut f = std::fs::File::open(path).map_err(io)?;
        let label = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        self.hasher.update(label.as_bytes());
        let mut buf = vec![0u8; 1 << 20];
        loop {
            let n = f.read(&mut buf).map_err(io)?;
            if n == 0 {
                break;
            }
            self.hasher.update(&buf[..n]);
        }
        Ok(self)
    }

    /// Adds another stage's fingerprint (stages downstream depend on upstream results).
    pub fn upstream(self, fp: &Fingerprint) -> Self {
        self.bytes("upstream", fp.0.as_bytes())
    }

    /// The digest.
    pub fn finish(self) -> Fingerprint {
        Fingerprint(self.hasher.finalize().to_hex().to_string())
    }
}

/// What the ledger remembers of one stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LedgerEntry {
    /// Fingerprint of the inputs it ran on.
    pub fingerprint: Fingerprint,
    /// Output files, relative to the `out/` directory.
    pub outputs: Vec<String>,
    /// Its report from that run.
    pub report: StageReport,
}

/// `out/ledger.json`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Ledger {
    /// Entries by stage.
    pub stages: BTreeMap<Stage, LedgerEntry>,
}

impl Ledger {
    /// The ledger file in an output directory.
    pub fn path(out_dir: &Path) -> PathBuf {
        out_dir.join("ledger.json")
    }

    /// Loads the ledger; a missing file is an empty ledger.
    pub fn load(out_dir: &Path) -> Result<Self, LedgerError> {
        let path = Self::path(out_dir);
        match std::fs::read(&path) {
            Ok(bytes) => serde_json::from_slice(&bytes)
                .map_err(|source| LedgerError::Corrupt { path, source }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Self::default()),
            Err(source) => Err(LedgerError::Io { path, source }),
        }
    }

    /// Saves atomically (temp file + rename).
    pub fn save(&self, out_dir: &Path) -> Result<(), LedgerError> {
        let path = Self::path(out_dir);
        let json = serde_json::to_vec_pretty(self).map_err(|source| LedgerError::Corrupt {
            path: path.clone(),
            source,
        })?;
        write_atomic(&path, &json)
    }

    /// The recorded entry if the stage can be reused: same fingerprint, outputs all present.
    pub fn reusable(&self, stage: Stage, fp: &Fingerprint, out_dir: &Path) -> Option<&LedgerEntry> {
        let entry = self.stages.get(&stage)?;
        let fresh =
            entry.fingerprint == *fp && entry.outputs.iter().all(|o| out_dir.join(o).exists());
        fresh.then_some(entry)
    }

    /// Records a stage's run.
    pub fn record(
        &mut self,
        stage: Stage,
        fingerprint: Fingerprint,
        outputs: Vec<String>,
        report: StageReport,
    ) {
        self.stages.insert(
            stage,
            LedgerEntry {
                fingerprint,
                outputs,
                report,
            },
        );
    }
}

/// Writes a file atomically: a temp file in the same directory, then a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), LedgerError> {
    skinbrdf_core::fsio::write_atomic(path, bytes).map_err(|e| LedgerError::Io {
        path: e.path,
        source: e.source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report() -> StageReport {
        StageReport::ran(Stage::Derender, 0.5)
    }

    #[test]
    fn reuse_needs_same_inputs_and_existing_outputs() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("input.bin");
        std::fs::write(&input, b"abc").unwrap();
        std::fs::write(dir.path().join("samples.bin"), b"xyz").unwrap();
        let fp = FingerprintBuilder::new()
            .file(&input)
            .unwrap()
            .value("cfg", &3)
            .finish();

        let mut ledger = Ledger::default();
        ledger.record(
            Stage::Derender,
            fp.clone(),
            vec!["samples.bin".into()],
            report(),
        );
        ledger.save(dir.path()).unwrap();
        let ledger = Ledger::load(dir.path()).unwrap();
        assert!(ledger.reusable(Stage::Derender, &fp, dir.path()).is_some());

        // Changed input: new fingerprint, not reusable.
        std::fs::write(&input, b"abd").unwrap();
        let fp2 = FingerprintBuilder::new()
            .file(&input)
            .unwrap()
            .value("cfg", &3)
            .finish();
        assert_ne!(fp, fp2);
        assert!(ledger.reusable(Stage::Derender, &fp2, dir.path()).is_none());

        // Changed config: new fingerprint.
        let fp3 = FingerprintBuilder::new()
            .file(&input)
            .unwrap()
            .value("cfg", &4)
            .finish();
        assert_ne!(fp2, fp3);

        // Missing output: not reusable.
        std::fs::remove_file(dir.path().join("samples.bin")).unwrap();
        assert!(ledger.reusable(Stage::Derender, &fp, dir.path()).is_none());
    }

    #[test]
    fn corrupt_ledger_is_a_precise_error() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(Ledger::path(dir.path()), b"{not json").unwrap();
        let err = Ledger::load(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("ledger.json") && err.contains("not a valid ledger"),
            "{err}"
        );
    }

    #[test]
    fn labels_separate_fields() {
        let a = FingerprintBuilder::new().bytes("a", b"bc").finish();
        let b = FingerprintBuilder::new().bytes("ab", b"c").finish();
        assert_ne!(a, b);
    }
}
