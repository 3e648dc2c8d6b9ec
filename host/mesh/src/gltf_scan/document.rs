//! The glTF document: the GLB container checked, the JSON parsed by the `gltf` crate, and
//! that crate's panics on malformed documents turned into this file's error.

use std::path::Path;

use crate::error::{GltfProblem, MeshError};

/// The error for `path` with `problem`.
pub(super) fn gltf_err(path: &Path, problem: GltfProblem) -> MeshError {
    MeshError::Gltf {
        path: path.to_path_buf(),
        problem,
    }
}

/// GLB header and chunk lengths against the file's size, with a clear message for a cut file
/// (the crate's own message does not say which length is short).
fn check_glb_container(bytes: &[u8]) -> Result<(), GltfProblem> {
    let u32_at = |o: usize| {
        bytes
            .get(o..o + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let available = bytes.len() as u64;
    let Some(total) = u32_at(8) else {
        return Err(GltfProblem::Truncated {
            what: "the GLB header",
            stated: 12,
            available,
        });
    };
    if u64::from(total) > available {
        return Err(GltfProblem::Truncated {
            what: "the GLB header",
            stated: u64::from(total),
            available,
        });
    }
    if total < 20 {
        return Err(GltfProblem::Document(format!(
            "the GLB header states {total} bytes, less than a header and a chunk header"
        )));
    }
    let mut at = 12usize;
    for what in ["the JSON chunk", "the binary chunk"] {
        let Some(len) = u32_at(at) else {
            if what == "the JSON chunk" {
                return Err(GltfProblem::Truncated {
                    what,
                    stated: 8,
                    available: available.saturating_sub(at as u64),
                });
            }
            break;
        };
        let stated = u64::from(len) + 8;
        let left = (total as u64).saturating_sub(at as u64);
        if stated > left {
            return Err(GltfProblem::Truncated {
                what,
                stated,
                available: left,
            });
        }
        at += stated as usize;
    }
    Ok(())
}

/// Runs a reader of the `gltf` crate's document and turns a panic inside that crate into this
/// file's error: its validation and accessors index unchecked on some malformed documents (a
/// primitive's attribute naming an accessor that does not exist, an image with no source).
pub(super) fn guarded<T>(
    path: &Path,
    f: impl FnOnce() -> Result<T, MeshError>,
) -> Result<T, MeshError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|panic| {
        let what = panic
            .downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "an index it did not check".into());
        Err(gltf_err(
            path,
            GltfProblem::Document(format!("the glTF reader gave up ({what})")),
        ))
    })
}

/// Parses a `.glb` or `.gltf` held in memory.
pub(super) fn parse_document(path: &Path, bytes: &[u8]) -> Result<::gltf::Gltf, MeshError> {
    if bytes.starts_with(b"glTF") {
        check_glb_container(bytes).map_err(|p| gltf_err(path, p))?;
    }
    ::gltf::Gltf::from_slice(bytes)
        .map_err(|e| gltf_err(path, GltfProblem::Document(e.to_string())))
}
