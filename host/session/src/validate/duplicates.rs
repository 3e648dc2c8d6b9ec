//! Images listed twice under different names: files of identical contents.

use std::collections::HashMap;
use std::path::Path;

use crate::error::SessionErrors;
use crate::format::SessionFile;

/// Reports images whose files have identical contents (the same photograph listed twice under
/// different names: a copy, or a hard link the canonical path does not reveal). Only files of
/// equal length are read and compared.
pub(super) fn report_identical_contents(
    dir: &Path,
    s: &SessionFile,
    existing: &[usize],
    file: &Path,
    errs: &mut SessionErrors,
) {
    let mut by_len: HashMap<u64, Vec<usize>> = HashMap::new();
    for &i in existing {
        if let Ok(m) = std::fs::metadata(dir.join(&s.images[i].file)) {
            by_len.entry(m.len()).or_default().push(i);
        }
    }
    let mut groups: Vec<Vec<usize>> = by_len.into_values().filter(|g| g.len() > 1).collect();
    groups.sort();
    let path_of = |i: usize| dir.join(&s.images[i].file);
    for group in groups {
        // A digest per file, streamed (a session's raw files are tens of MB each, all of one
        // length); files are compared byte for byte only when their digests agree.
        let mut seen: Vec<(usize, u64)> = Vec::new();
        for i in group {
            let Some(digest) = stream_digest(&path_of(i)) else {
                continue;
            };
            let twin = seen
                .iter()
                .find(|(j, d)| *d == digest && same_contents(&path_of(*j), &path_of(i)));
            if let Some((prev, _)) = twin {
                errs.push(
                    file,
                    format!("images[{i}].file"),
                    format!(
                        "`{}` has the same contents as images[{prev}] (`{}`): the same photograph listed twice",
                        s.images[i].file, s.images[*prev].file
                    ),
                );
            } else {
                seen.push((i, digest));
            }
        }
    }
}

/// A 64-bit digest of a file's contents, read in chunks (`None` when unreadable).
fn stream_digest(path: &Path) -> Option<u64> {
    use std::hash::Hasher;
    use std::io::Read;
    let mut f = std::fs::File::open(path).ok()?;
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).ok()?;
        if n == 0 {
            return Some(h.finish());
        }
        h.write(&buf[..n]);
    }
}

/// Whether two files have the same bytes, compared in chunks.
fn same_contents(a: &Path, b: &Path) -> bool {
    let (Ok(mut fa), Ok(mut fb)) = (std::fs::File::open(a), std::fs::File::open(b)) else {
        return false;
    };
    let (mut ba, mut bb) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    loop {
        let (Ok(na), Ok(nb)) = (read_full(&mut fa, &mut ba), read_full(&mut fb, &mut bb)) else {
            return false;
        };
        if na != nb || ba[..na] != bb[..nb] {
            return false;
        }
        if na == 0 {
            return true;
        }
    }
}

/// Fills `buf` as far as the file allows; the number of bytes read.
fn read_full(f: &mut std::fs::File, buf: &mut [u8]) -> std::io::Result<usize> {
    use std::io::Read;
    let mut n = 0;
    while n < buf.len() {
        let k = f.read(&mut buf[n..])?;
        if k == 0 {
            break;
        }
        n += k;
    }
    Ok(n)
}
