//! Reading files the user hands over (a card, a scan, a record, a rig): bounded reads of regular
//! files only, and paths that one file names confined to its own folder.
//!
//! # Bounded reads
//!
//! [`read_bounded`] opens a file without waiting (`O_NONBLOCK`, so a FIFO cannot block the
//! open), checks on the open handle that it is a regular file (a device such as `/dev/zero`, a
//! FIFO, a socket or a directory is refused at once, by name), checks its length against the
//! maximum its [`ReadLimit`] states, and reads at most that many bytes (a file that grows while
//! it is read is refused too). The limits are stated in docs/ingest.md ("Untrusted files").
//!
//! # Confined paths
//!
//! [`confine`] resolves a path written inside a file (an OBJ's `mtllib`, an MTL's `map_Kd`, a
//! rig's layout file, a glTF's URI) against the folder it must stay in. Refused, each with its
//! reason: an absolute path (`/etc/passwd`, `C:\x`, `\\server\x`), a `..` component, a path
//! whose real location (symbolic links followed) is outside the folder, and anything but a
//! regular file. Windows separators (`.\tex.jpg`, `maps\skin.png`) are read as `/`.

use std::fs::{File, FileType};
use std::io::{self, Read};
use std::path::{Component, Path, PathBuf};

/// How much of one kind of file is read at most.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReadLimit {
    /// What the file is, in words (`capture record`, `rig file`), for the error.
    pub kind: &'static str,
    /// The largest file read, bytes.
    pub max_bytes: u64,
}

const MIB: u64 = 1 << 20;

/// A controller's `capture.json` (a session of 30 exposures is about 10 KiB).
pub const CAPTURE_RECORD: ReadLimit = ReadLimit {
    kind: "capture record",
    max_bytes: 16 * MIB,
};
/// A capture plan, a camera calibration, a rig file, scan points: small hand-edited files.
pub const SETTINGS_FILE: ReadLimit = ReadLimit {
    kind: "settings file",
    max_bytes: 4 * MIB,
};
/// A target layout file a rig names.
pub const LAYOUT_FILE: ReadLimit = ReadLimit {
    kind: "layout file",
    max_bytes: 16 * MIB,
};
/// An OBJ's material library.
pub const MATERIAL_LIBRARY: ReadLimit = ReadLimit {
    kind: "material library",
    max_bytes: 16 * MIB,
};
/// A scan (PLY, OBJ, glTF) or a glTF's external buffer.
pub const SCAN_FILE: ReadLimit = ReadLimit {
    kind: "scan file",
    max_bytes: 2048 * MIB,
};
/// A scan's texture image.
pub const TEXTURE_FILE: ReadLimit = ReadLimit {
    kind: "texture",
    max_bytes: 512 * MIB,
};

/// A file that could not be read within its limits.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// Opening or reading failed.
    #[error("{}: cannot read it", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: io::Error,
    },
    /// Not a regular file.
    #[error("{}: is {what}, not a regular file: only regular files are read", path.display())]
    NotRegular {
        /// The file.
        path: PathBuf,
        /// What it is (`a FIFO`, `a device`).
        what: &'static str,
    },
    /// Larger than its kind may be.
    #[error("{}: {size_bytes} bytes or more, larger than the {max_bytes} bytes a {kind} may have", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its kind.
        kind: &'static str,
        /// Its size (at least), bytes.
        size_bytes: u64,
        /// The limit, bytes.
        max_bytes: u64,
    },
}

impl ReadError {
    /// What is wrong, without the file's name (for a message that names the file already).
    pub fn reason(&self) -> String {
        match self {
            Self::Io { source, .. } => format!("cannot read it: {source}"),
            Self::NotRegular { what, .. } => {
                format!("it is {what}, not a regular file: only regular files are read")
            }
            Self::TooLarge {
                kind,
                size_bytes,
                max_bytes,
                ..
            } => format!(
                "{size_bytes} bytes or more, larger than the {max_bytes} bytes a {kind} may have"
            ),
        }
    }

    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            Self::Io { path, .. } | Self::NotRegular { path, .. } | Self::TooLarge { path, .. } => {
                path
            }
        }
    }
}

/// What a file type is, in words, for an error (`a FIFO`, `a device`, `a directory`).
pub fn file_type_words(t: FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else if t.is_symlink() {
        "a symbolic link"
    } else if t.is_file() {
        "a regular file"
    } else {
        "a special file"
    }
}

/// Opens a regular file for reading without blocking on a FIFO; anything else is refused.
/// Returns the file and its length.
pub fn open_regular(path: &Path) -> Result<(File, u64), ReadError> {
    let io_err = |source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut opts = std::fs::OpenOptions::new();
    opts.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // O_NONBLOCK: opening a FIFO returns at once instead of waiting for a writer (it has no
        // effect on the regular files that are then read).
        opts.custom_flags(O_NONBLOCK);
    }
    let file = opts.open(path).map_err(io_err)?;
    let meta = file.metadata().map_err(io_err)?;
    if !meta.file_type().is_file() {
        return Err(ReadError::NotRegular {
            path: path.to_path_buf(),
            what: file_type_words(meta.file_type()),
        });
    }
    Ok((file, meta.len()))
}

/// `O_NONBLOCK` of the platform's `open(2)`.
#[cfg(all(
    unix,
    any(target_os = "macos", target_os = "ios", target_os = "freebsd")
))]
const O_NONBLOCK: i32 = 0x0004;
/// `O_NONBLOCK` of the platform's `open(2)`.
#[cfg(all(
    unix,
    not(any(target_os = "macos", target_os = "ios", target_os = "freebsd"))
))]
const O_NONBLOCK: i32 = 0o4000;

/// Reads a whole regular file of at most `limit.max_bytes` bytes (see the module docs).
pub fn read_bounded(path: &Path, limit: ReadLimit) -> Result<Vec<u8>, ReadError> {
    let (file, len) = open_regular(path)?;
    let too_large = |size_bytes| ReadError::TooLarge {
        path: path.to_path_buf(),
        kind: limit.kind,
        size_bytes,
        max_bytes: limit.max_bytes,
    };
    if len > limit.max_bytes {
        return Err(too_large(len));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(limit.max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    if bytes.len() as u64 > limit.max_bytes {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// [`read_bounded`] as UTF-8 text.
pub fn read_bounded_text(path: &Path, limit: ReadLimit) -> Result<String, ReadError> {
    let bytes = read_bounded(path, limit)?;
    String::from_utf8(bytes).map_err(|e| ReadError::Io {
        path: path.to_path_buf(),
        source: io::Error::new(io::ErrorKind::InvalidData, e.utf8_error()),
    })
}

/// [`read_bounded_text`] with a refusal as an `io::Error` holding its reason (not the file's
/// name), for a reader whose own error names the file and carries an `io::Error`.
pub fn read_text_io(path: &Path, limit: ReadLimit) -> io::Result<String> {
    read_bounded_text(path, limit).map_err(|e| match e {
        ReadError::Io { source, .. } => source,
        other => io::Error::new(io::ErrorKind::InvalidInput, other.reason()),
    })
}

/// Why a path written in a file is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfineError {
    /// The path is empty.
    #[error("`{written}` is empty")]
    Empty {
        /// The path as written.
        written: String,
    },
    /// An absolute path (or a Windows drive or network path).
    #[error("`{written}` is an absolute path: only a path inside {} is read", dir.display())]
    Absolute {
        /// The path as written.
        written: String,
        /// The folder it must stay in.
        dir: PathBuf,
    },
    /// A `..` component.
    #[error("`{written}` climbs out with `..`: only a path inside {} is read", dir.display())]
    ParentDir {
        /// The path as written.
        written: String,
        /// The folder it must stay in.
        dir: PathBuf,
    },
    /// Its real location (symbolic links followed) is outside the folder.
    #[error("`{written}` leads to {}, outside {} (a symbolic link out): only a path inside the folder is read", real.display(), dir.display())]
    Outside {
        /// The path as written.
        written: String,
        /// Where it really is.
        real: PathBuf,
        /// The folder it must stay in.
        dir: PathBuf,
    },
    /// Not a regular file.
    #[error("`{written}` is {what}, not a regular file")]
    NotRegular {
        /// The path as written.
        written: String,
        /// What it is.
        what: &'static str,
    },
    /// It does not exist.
    #[error("`{written}` does not exist ({})", path.display())]
    Missing {
        /// The path as written.
        written: String,
        /// The file looked for.
        path: PathBuf,
    },
}

/// The path as written with Windows separators read as `/`, and whether it is absolute on any
/// platform (`/x`, `\x`, `C:x`, `C:\x`).
fn normalise_separators(written: &str) -> (String, bool) {
    let s = written.trim().replace('\\', "/");
    let b = s.as_bytes();
    let drive = b.len() >= 2 && b[0].is_ascii_alphabetic() && b[1] == b':';
    let absolute = s.starts_with('/') || drive || Path::new(&s).is_absolute();
    (s, absolute)
}

/// Checks the syntax of a path written in a file: relative, without `..` (Windows separators
/// read as `/`). Returns the relative path. Nothing is looked up on disk.
pub fn relative_inside(dir: &Path, written: &str) -> Result<PathBuf, ConfineError> {
    let (s, absolute) = normalise_separators(written);
    if s.is_empty() {
        return Err(ConfineError::Empty {
            written: written.to_string(),
        });
    }
    if absolute {
        return Err(ConfineError::Absolute {
            written: written.to_string(),
            dir: dir.to_path_buf(),
        });
    }
    let rel = PathBuf::from(&s);
    for c in rel.components() {
        match c {
            Component::Normal(_) | Component::CurDir => {}
            Component::ParentDir => {
                return Err(ConfineError::ParentDir {
                    written: written.to_string(),
                    dir: dir.to_path_buf(),
                })
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err(ConfineError::Absolute {
                    written: written.to_string(),
                    dir: dir.to_path_buf(),
                })
            }
        }
    }
    Ok(rel
        .components()
        .filter(|c| !matches!(c, Component::CurDir))
        .collect())
}

/// Resolves a path written in a file against `dir` and checks that it stays inside it and is a
/// regular file (see the module docs). Returns the path (`dir` joined with the relative path,
/// not the canonical one, so messages show what the user wrote).
pub fn confine(dir: &Path, written: &str) -> Result<PathBuf, ConfineError> {
    let rel = relative_inside(dir, written)?;
    let path = dir.join(&rel);
    let meta = match std::fs::metadata(&path) {
        Ok(m) => m,
        Err(_) => {
            return Err(ConfineError::Missing {
                written: written.to_string(),
                path,
            })
        }
    };
    let dir_real = std::fs::canonicalize(if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    })
    .map_err(|_| ConfineError::Missing {
        written: written.to_string(),
        path: dir.to_path_buf(),
    })?;
    let real = std::fs::canonicalize(&path).map_err(|_| ConfineError::Missing {
        written: written.to_string(),
        path: path.clone(),
    })?;
    if !real.starts_with(&dir_real) {
        return Err(ConfineError::Outside {
            written: written.to_string(),
            real,
            dir: dir.to_path_buf(),
        });
    }
    if !meta.file_type().is_file() {
        return Err(ConfineError::NotRegular {
            written: written.to_string(),
            what: file_type_words(meta.file_type()),
        });
    }
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmpdir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!(
            "skinbrdf-untrusted-{tag}-{}-{}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos())
                .unwrap_or(0)
        ));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    const TINY: ReadLimit = ReadLimit {
        kind: "test file",
        max_bytes: 8,
    };

    #[test]
    fn bounded_reads_take_regular_files_within_the_limit() {
        let d = tmpdir("read");
        let ok = d.join("ok");
        let big = d.join("big");
        std::fs::write(&ok, b"12345678").unwrap();
        std::fs::write(&big, b"123456789").unwrap();
        assert_eq!(read_bounded(&ok, TINY).unwrap(), b"12345678");
        let e = read_bounded(&big, TINY).unwrap_err();
        assert!(
            matches!(e, ReadError::TooLarge { size_bytes: 9, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("big"), "{e}");
        let e = read_bounded(&d, TINY).unwrap_err();
        assert!(
            matches!(
                e,
                ReadError::NotRegular {
                    what: "a directory",
                    ..
                }
            ),
            "{e}"
        );
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn devices_are_refused_at_once() {
        let e = read_bounded(Path::new("/dev/zero"), SCAN_FILE).unwrap_err();
        assert!(
            matches!(
                e,
                ReadError::NotRegular {
                    what: "a device",
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("/dev/zero"), "{e}");
    }

    #[test]
    fn written_paths_stay_inside_their_folder() {
        let d = tmpdir("confine");
        std::fs::create_dir_all(d.join("maps")).unwrap();
        std::fs::write(d.join("maps/tex.jpg"), b"x").unwrap();
        std::fs::write(d.join("tex.jpg"), b"x").unwrap();
        assert_eq!(
            confine(&d, "maps\\tex.jpg").unwrap(),
            d.join("maps/tex.jpg")
        );
        assert_eq!(confine(&d, ".\\tex.jpg").unwrap(), d.join("tex.jpg"));
        for (w, absolute) in [
            ("/etc/passwd", true),
            ("C:\\x.png", true),
            ("\\\\server\\x.png", true),
            ("../../../../etc/passwd", false),
            ("maps/../../x", false),
        ] {
            let e = confine(&d, w).unwrap_err();
            if absolute {
                assert!(matches!(e, ConfineError::Absolute { .. }), "{w}: {e}");
            } else {
                assert!(matches!(e, ConfineError::ParentDir { .. }), "{w}: {e}");
            }
            assert!(e.to_string().contains(w), "{e}");
        }
        assert!(matches!(
            confine(&d, "nope.png").unwrap_err(),
            ConfineError::Missing { .. }
        ));
        assert!(matches!(
            confine(&d, "maps").unwrap_err(),
            ConfineError::NotRegular { .. }
        ));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink("/etc/hostname", d.join("out.png")).unwrap();
            let e = confine(&d, "out.png").unwrap_err();
            assert!(matches!(e, ConfineError::Outside { .. }), "{e}");
            std::os::unix::fs::symlink("/dev/zero", d.join("zero.png")).unwrap();
            assert!(confine(&d, "zero.png").is_err());
        }
        std::fs::remove_dir_all(&d).unwrap();
    }
}
