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

use crate::report::StageReport;

/// Errors of the ledger.
#[derive(Debug, thiserror::Error)]
pub enum LedgerError {
    /// A file could not be read or written.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// Another run is processing the same output directory.
    #[error("{path}: another run (process {pid}) is using this output directory; wait for it or stop it")]
    Locked {
        /// The lock file.
        path: PathBuf,
        /// The process holding it.
        pid: u32,
    },
    /// The ledger file is not valid JSON of the expected shape.
    #[error("{path}: not a valid ledger")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// The parse error.
        #[source]
        source: serde_json::Error,
    },
    /// The ledger could not be written as JSON (a NaN or infinity in a recorded figure, named by
    /// its field's path). The message names the file.
    #[error(transparent)]
    Json(#[from] skinbrdf_core::json::JsonError),
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
        let label = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        self.hasher.update(label.as_bytes());
        hash_file_into(&mut self.hasher, path)?;
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

/// The typed units of work the ledger remembers: each produces one or more stages' reports
/// and a set of output files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Unit {
    /// The placement survey (`survey.json`).
    Survey,
    /// Photogrammetry: calibration, camera and head poses, flash, the standard's pose
    /// (`poses.json`).
    Poses,
    /// Scan preparation, shadow rays and derendering (`samples.skbs`).
    Derender,
    /// Smoothing and the model fit (`fit/`).
    Fit,
    /// The head rendering of the report (`render/`).
    Render,
}

/// An output file and the BLAKE3 digest of its contents when it was written.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputDigest {
    /// The file, relative to the output directory.
    pub file: String,
    /// BLAKE3 (hex) of its contents.
    pub blake3: String,
}

/// What the ledger remembers of one unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LedgerEntry {
    /// Fingerprint of every input it read.
    pub fingerprint: Fingerprint,
    /// Every file it wrote, with its digest.
    pub outputs: Vec<OutputDigest>,
    /// Its stages' reports from that run.
    pub reports: Vec<StageReport>,
}

/// The ledger's format version: a ledger of another version is ignored (everything reruns).
pub const LEDGER_VERSION: u32 = 2;

/// `out/ledger.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Ledger {
    /// Format version ([`LEDGER_VERSION`]).
    pub version: u32,
    /// Entries by unit.
    pub units: BTreeMap<Unit, LedgerEntry>,
}

impl Default for Ledger {
    fn default() -> Self {
        Self {
            version: LEDGER_VERSION,
            units: BTreeMap::new(),
        }
    }
}

/// Streams a file's contents into a hasher.
fn hash_file_into(hasher: &mut blake3::Hasher, path: &Path) -> Result<(), LedgerError> {
    let io = |source| LedgerError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut f = std::fs::File::open(path).map_err(io)?;
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).map_err(io)?;
        if n == 0 {
            return Ok(());
        }
        hasher.update(&buf[..n]);
    }
}

/// BLAKE3 (hex) of a file's contents.
pub fn digest_file(path: &Path) -> Result<String, LedgerError> {
    let mut hasher = blake3::Hasher::new();
    hash_file_into(&mut hasher, path)?;
    Ok(hasher.finalize().to_hex().to_string())
}

impl Ledger {
    /// The ledger file in an output directory.
    pub fn path(out_dir: &Path) -> PathBuf {
        out_dir.join("ledger.json")
    }

    /// Loads the ledger. A missing file, or one of another format version, is an empty ledger
    /// (so everything reruns); a file that is not a ledger at all is an error.
    pub fn load(out_dir: &Path) -> Result<Self, LedgerError> {
        #[derive(Deserialize)]
        struct Version {
            #[serde(default)]
            version: u32,
        }
        let path = Self::path(out_dir);
        match std::fs::read(&path) {
            Ok(bytes) => {
                let v: Version =
                    serde_json::from_slice(&bytes).map_err(|source| LedgerError::Corrupt {
                        path: path.clone(),
                        source,
                    })?;
                if v.version != LEDGER_VERSION {
                    return Ok(Self::default());
                }
                serde_json::from_slice(&bytes)
                    .map_err(|source| LedgerError::Corrupt { path, source })
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Self::default()),
            Err(source) => Err(LedgerError::Io { path, source }),
        }
    }

    /// Saves atomically (temp file + rename, both synced).
    pub fn save(&self, out_dir: &Path) -> Result<(), LedgerError> {
        let path = Self::path(out_dir);
        let json = skinbrdf_core::json::to_vec_pretty(&path, self)?;
        write_atomic(&path, &json)
    }

    /// The recorded entry if the unit can be reused: the same fingerprint, and every output it
    /// recorded still on disk with the digest it had when written.
    pub fn reusable(&self, unit: Unit, fp: &Fingerprint, out_dir: &Path) -> Option<&LedgerEntry> {
        let entry = self.units.get(&unit)?;
        if entry.fingerprint != *fp {
            return None;
        }
        let intact = entry
            .outputs
            .iter()
            .all(|o| digest_file(&out_dir.join(&o.file)).is_ok_and(|d| d == o.blake3));
        intact.then_some(entry)
    }

    /// Forgets a unit (it is about to rerun: a crash midway must not leave its old entry
    /// pointing at half-replaced outputs).
    pub fn forget(&mut self, unit: Unit) {
        self.units.remove(&unit);
    }

    /// Records a unit's run: digests its outputs as they are now.
    pub fn record(
        &mut self,
        unit: Unit,
        fingerprint: Fingerprint,
        outputs: &[String],
        reports: Vec<StageReport>,
        out_dir: &Path,
    ) -> Result<(), LedgerError> {
        let outputs = outputs
            .iter()
            .map(|f| {
                Ok(OutputDigest {
                    file: f.clone(),
                    blake3: digest_file(&out_dir.join(f))?,
                })
            })
            .collect::<Result<Vec<_>, LedgerError>>()?;
        self.units.insert(
            unit,
            LedgerEntry {
                fingerprint,
                outputs,
                reports,
            },
        );
        Ok(())
    }
}

/// Exclusive use of an output directory by one run: `out/.lock` holds the run's process id.
/// A second run on the same directory is refused while the first is alive; a lock left by a
/// run that died is taken over. Dropping the lock removes the file.
#[derive(Debug)]
pub struct RunLock {
    path: PathBuf,
}

impl RunLock {
    /// Takes the lock of `out_dir` or says which process holds it. The lock file appears with
    /// the owner's process id in it (never empty: [`skinbrdf_core::fsio::create_new_with_contents`]);
    /// a lock of a run that no longer exists is moved aside under a name of this run's own
    /// before it is removed, so two runs taking over the same stale lock cannot remove each
    /// other's.
    pub fn acquire(out_dir: &Path) -> Result<Self, LedgerError> {
        let path = out_dir.join(".lock");
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| LedgerError::Io { path, source }
        };
        let me = std::process::id();
        let holder_of = |p: &Path| {
            std::fs::read_to_string(p)
                .ok()
                .and_then(|s| s.trim().parse::<u32>().ok())
        };
        let alive = |pid: u32| pid == me || skinbrdf_core::fsio::process_alive(pid);
        for _ in 0..3 {
            if skinbrdf_core::fsio::create_new_with_contents(&path, format!("{me}\n").as_bytes())
                .map_err(io(&path))?
            {
                return Ok(Self { path });
            }
            match holder_of(&path) {
                Some(pid) if alive(pid) => return Err(LedgerError::Locked { path, pid }),
                // Gone (or removed meanwhile): take it over.
                _ => {
                    let aside = out_dir.join(format!(".lock.{me}.stale"));
                    if std::fs::rename(&path, &aside).is_err() {
                        continue;
                    }
                    match holder_of(&aside) {
                        // Another run took the lock over in between: give it back.
                        Some(pid) if alive(pid) => {
                            let _ = std::fs::hard_link(&aside, &path);
                            let _ = std::fs::remove_file(&aside);
                            return Err(LedgerError::Locked { path, pid });
                        }
                        _ => {
                            let _ = std::fs::remove_file(&aside);
                        }
                    }
                }
            }
        }
        Err(LedgerError::Locked { path, pid: 0 })
    }
}

impl Drop for RunLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
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
    use crate::plan::Stage;

    fn report() -> Vec<StageReport> {
        vec![StageReport::ran(Stage::Derender, 0.5)]
    }

    #[test]
    fn reuse_needs_same_inputs_and_unchanged_outputs() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("input.bin");
        std::fs::write(&input, b"abc").unwrap();
        let out = dir.path().join("samples.bin");
        std::fs::write(&out, b"xyz").unwrap();
        let fp = FingerprintBuilder::new()
            .file(&input)
            .unwrap()
            .value("cfg", &3)
            .finish();

        let mut ledger = Ledger::default();
        ledger
            .record(
                Unit::Derender,
                fp.clone(),
                &["samples.bin".into()],
                report(),
                dir.path(),
            )
            .unwrap();
        ledger.save(dir.path()).unwrap();
        let ledger = Ledger::load(dir.path()).unwrap();
        assert!(ledger.reusable(Unit::Derender, &fp, dir.path()).is_some());

        // Changed input: new fingerprint, not reusable.
        std::fs::write(&input, b"abd").unwrap();
        let fp2 = FingerprintBuilder::new()
            .file(&input)
            .unwrap()
            .value("cfg", &3)
            .finish();
        assert_ne!(fp, fp2);
        assert!(ledger.reusable(Unit::Derender, &fp2, dir.path()).is_none());

        // Changed config: new fingerprint.
        let fp3 = FingerprintBuilder::new()
            .file(&input)
            .unwrap()
            .value("cfg", &4)
            .finish();
        assert_ne!(fp2, fp3);

        // An output changed behind the ledger's back: not reusable.
        std::fs::write(&out, b"xyZ").unwrap();
        assert!(ledger.reusable(Unit::Derender, &fp, dir.path()).is_none());
        std::fs::write(&out, b"xyz").unwrap();
        assert!(ledger.reusable(Unit::Derender, &fp, dir.path()).is_some());

        // Missing output: not reusable.
        std::fs::remove_file(&out).unwrap();
        assert!(ledger.reusable(Unit::Derender, &fp, dir.path()).is_none());
    }

    #[test]
    fn corrupt_ledger_is_a_precise_error_and_an_old_one_is_ignored() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(Ledger::path(dir.path()), b"{not json").unwrap();
        let err = Ledger::load(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("ledger.json") && err.contains("not a valid ledger"),
            "{err}"
        );
        std::fs::write(Ledger::path(dir.path()), br#"{"stages": {}}"#).unwrap();
        assert_eq!(Ledger::load(dir.path()).unwrap(), Ledger::default());
    }

    #[test]
    fn a_second_run_is_refused_while_the_first_holds_the_lock() {
        let dir = tempfile::tempdir().unwrap();
        let lock = RunLock::acquire(dir.path()).unwrap();
        let err = RunLock::acquire(dir.path()).unwrap_err().to_string();
        assert!(err.contains("another run"), "{err}");
        drop(lock);
        // A lock left by a dead process is taken over.
        std::fs::write(dir.path().join(".lock"), "4294967295\n").unwrap();
        assert!(RunLock::acquire(dir.path()).is_ok());
    }

    #[test]
    fn labels_separate_fields() {
        let a = FingerprintBuilder::new().bytes("a", b"bc").finish();
        let b = FingerprintBuilder::new().bytes("ab", b"c").finish();
        assert_ne!(a, b);
    }
}
