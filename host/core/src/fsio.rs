//! Durable, atomic output files: the one way every skinbrdf stage writes a file.
//!
//! [`write_atomic_with`] streams the contents into a temporary file beside the target
//! (`.NAME.PID.tmp`, in the same directory so the final `rename` never crosses a file system),
//! flushes and `fsync`s it, renames it over the target, and `fsync`s the directory so the rename
//! itself survives a power cut. A reader therefore sees either the old file or the complete new
//! one, never a partial write. On any error the temporary file is removed and the target is left
//! as it was.
//!
//! The file is created with the process's default permissions (`0666` less the umask, `0644`
//! under the usual umask), the same as any other file the tools write: no output is more or less
//! private than another.
//!
//! Only a regular file is replaced: a target that is a device (`/dev/full`), a FIFO, a
//! directory or a symbolic link is refused before anything is written ([`check_replaceable`]).
//!
//! A run that dies between creating and renaming leaves its temporary file behind;
//! [`remove_stale_temp_files`] removes those of processes that no longer exist.
//!
//! [`create_new_with_contents`] creates a file that must not exist yet with its contents in
//! one step (a lock file holding its owner's process id: no reader ever sees it empty).

use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// A failed atomic write, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("writing {path}")]
pub struct WriteError {
    /// The file that was to be written.
    pub path: PathBuf,
    /// The I/O error.
    #[source]
    pub source: io::Error,
}

/// The directory a path lives in (`.` for a bare file name).
fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// The temporary file name used for `path` by this process.
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    parent_dir(path).join(format!(".{name}.{}.tmp", std::process::id()))
}

/// Writes `bytes` to `path` atomically and durably (see the module docs). Creates the parent
/// directory if needed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Streams a file's contents through `write` into `path`, atomically and durably (see the
/// module docs). Creates the parent directory if needed.
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), WriteError> {
    let mut file = AtomicFile::create(path)?;
    let mut buf = BufWriter::new(&mut file);
    write(&mut buf).map_err(|source| WriteError {
        path: path.to_path_buf(),
        source,
    })?;
    buf.flush().map_err(|source| WriteError {
        path: path.to_path_buf(),
        source,
    })?;
    drop(buf);
    file.commit()
}

/// A file being written atomically: a temporary file beside the target that becomes the target
/// on [`commit`](Self::commit). Dropped without a commit, it removes the temporary file and the
/// target is left as it was. It is `Write` and `Seek`, so a writer can go back and fill in a
/// header (a record count) before committing.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    tmp: PathBuf,
    file: Option<std::fs::File>,
}

impl AtomicFile {
    /// Starts writing `path` (creating its parent directory if needed).
    pub fn create(path: &Path) -> Result<Self, WriteError> {
        let err = |source| WriteError {
            path: path.to_path_buf(),
            source,
        };
        check_replaceable(path).map_err(err)?;
        std::fs::create_dir_all(parent_dir(path)).map_err(err)?;
        let tmp = temp_path(path);
        let file = std::fs::File::create(&tmp).map_err(err)?;
        Ok(Self {
            target: path.to_path_buf(),
            tmp,
            file: Some(file),
        })
    }

    /// The file that [`commit`](Self::commit) replaces.
    pub fn target(&self) -> &Path {
        &self.target
    }

    fn file(&mut self) -> io::Result<&mut std::fs::File> {
        self.file
            .as_mut()
            .ok_or_else(|| io::Error::other("the atomic file was already committed"))
    }

    /// `fsync`s the contents, renames the temporary file over the target and `fsync`s the
    /// directory.
    pub fn commit(mut self) -> Result<(), WriteError> {
        let err = |source| WriteError {
            path: self.target.clone(),
            source,
        };
        let file = self
            .file
            .take()
            .ok_or_else(|| err(io::Error::other("already committed")))?;
        file.sync_all().map_err(err)?;
        drop(file);
        check_replaceable(&self.target).map_err(err)?;
        std::fs::rename(&self.tmp, &self.target).map_err(err)?;
        sync_dir(parent_dir(&self.target)).map_err(err)
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file()?.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file()?.flush()
    }
}

impl io::Seek for AtomicFile {
    fn seek(&mut self, pos: io::SeekFrom) -> io::Result<u64> {
        self.file()?.seek(pos)
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            // Not committed: nothing of this write may remain.
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Whether the atomic writer may replace `path`: it does not exist, or it is a regular file
/// (not a device, FIFO, socket, directory or symbolic link, which a rename would replace
/// instead of writing to).
pub fn check_replaceable(path: &Path) -> io::Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if !m.file_type().is_file() => Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "it is {}, not a regular file: only a regular file is replaced",
                crate::untrusted::file_type_words(m.file_type())
            ),
        )),
        _ => Ok(()),
    }
}

/// Creates `path` holding `bytes`, only if it does not exist, in one step: the contents go
/// into a temporary file beside it, which is then hard-linked to `path` (a link never replaces
/// an existing file) and removed. Returns `false` when `path` already exists. A reader sees
/// either no file or the whole contents.
pub fn create_new_with_contents(path: &Path, bytes: &[u8]) -> io::Result<bool> {
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        match std::fs::hard_link(&tmp, path) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(false),
            Err(e) => Err(e),
        }
    })();
    let _ = std::fs::remove_file(&tmp);
    result
}

/// `fsync`s a directory so that a rename into it is durable (a no-op where directories cannot
/// be opened as files).
fn sync_dir(dir: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        std::fs::File::open(dir)?.sync_all()
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

/// Removes the temporary files (`.NAME.PID.tmp`) that runs which no longer exist left in `dir`
/// and its subdirectories (one level deep). Returns the files removed. A file whose process id
/// is still alive (another run writing right now) is left alone.
pub fn remove_stale_temp_files(dir: &Path) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    let mut dirs = vec![dir.to_path_buf()];
    if let Ok(rd) = std::fs::read_dir(dir) {
        dirs.extend(
            rd.filter_map(Result::ok)
                .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
                .map(|e| e.path()),
        );
    }
    for d in dirs {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.filter_map(Result::ok) {
            let name = e.file_name().to_string_lossy().into_owned();
            let Some(pid) = temp_file_pid(&name) else {
                continue;
            };
            if pid != std::process::id()
                && !process_alive(pid)
                && std::fs::remove_file(e.path()).is_ok()
            {
                removed.push(e.path());
            }
        }
    }
    removed
}

/// The process id in a temporary file's name `.NAME.PID.tmp`.
fn temp_file_pid(name: &str) -> Option<u32> {
    let rest = name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (_, pid) = rest.rsplit_once('.')?;
    pid.parse().ok()
}

/// Whether a process with this id exists (Linux: `/proc/PID`; elsewhere assumed alive, so
/// nothing is removed or taken over that might be in use).
pub fn process_alive(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new(&format!("/proc/{pid}")).exists()
    } else {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmpdir() -> PathBuf {
        let d = std::env::temp_dir().join(format!(
            "skinbrdf-fsio-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos())
                .unwrap_or(0)
        ));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn writes_replaces_and_leaves_no_temp_file() {
        let d = tmpdir();
        let p = d.join("sub/a.json");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(d.join("sub"))
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_failed_write_keeps_the_old_file() {
        let d = tmpdir();
        let p = d.join("a.bin");
        write_atomic(&p, b"old").unwrap();
        let e = write_atomic_with(&p, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(e.path, p);
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn mode_is_the_default_for_new_files() {
        use std::os::unix::fs::PermissionsExt;
        let d = tmpdir();
        let a = d.join("a");
        let b = d.join("b");
        write_atomic(&a, b"x").unwrap();
        std::fs::write(&b, b"x").unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&a), mode(&b));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn stale_temp_files_of_dead_runs_are_removed() {
        let d = tmpdir();
        // Process ids are below 2^22 on Linux: this one cannot exist.
        let dead = d.join(".poses.json.4294967295.tmp");
        let mine = d.join(format!(".x.{}.tmp", std::process::id()));
        let other = d.join("poses.json");
        for p in [&dead, &mine, &other] {
            std::fs::write(p, b"x").unwrap();
        }
        let removed = remove_stale_temp_files(&d);
        if cfg!(target_os = "linux") {
            assert_eq!(removed, vec![dead.clone()]);
            assert!(!dead.exists());
        }
        assert!(mine.exists() && other.exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn only_a_regular_file_is_replaced() {
        let e = write_atomic(Path::new("/dev/full"), b"x").unwrap_err();
        assert_eq!(e.path, Path::new("/dev/full"));
        assert!(e.source.to_string().contains("a device"), "{}", e.source);
        let d = tmpdir();
        let e = write_atomic(&d, b"x").unwrap_err();
        assert!(e.source.to_string().contains("a directory"), "{}", e.source);
        std::os::unix::fs::symlink("/dev/null", d.join("link")).unwrap();
        assert!(write_atomic(&d.join("link"), b"x").is_err());
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_new_file_appears_with_its_contents_or_not_at_all() {
        let d = tmpdir();
        let p = d.join(".lock");
        assert!(create_new_with_contents(&p, b"123\n").unwrap());
        assert!(!create_new_with_contents(&p, b"456\n").unwrap());
        assert_eq!(std::fs::read(&p).unwrap(), b"123\n");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn temp_names_parse() {
        assert_eq!(temp_file_pid(".a.b.json.123.tmp"), Some(123));
        assert_eq!(temp_file_pid("a.123.tmp"), None);
        assert_eq!(temp_file_pid(".a.tmp"), None);
    }
}
