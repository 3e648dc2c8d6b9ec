//! What a glTF's URIs point at, confined to the file's folder: the buffers' bytes and the
//! external files that come with a scan.

use std::path::{Path, PathBuf};

use super::document::{gltf_err, guarded, parse_document};
use crate::error::{GltfProblem, MeshError};
use crate::material::TextureImage;

/// Decodes `%XX` escapes of a relative URI (`None`: a bad escape or not UTF-8).
fn percent_decode(uri: &str) -> Option<String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Where a URI of a `.gltf` points.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum UriTarget {
    /// `data:` (embedded, base64).
    Data,
    /// A regular file inside the glTF file's folder.
    File(PathBuf),
    /// A file path that is absolute, climbs out, leads out through a link, is not a regular
    /// file or does not exist.
    Refused(skinbrdf_core::untrusted::ConfineError),
    /// A scheme the loader does not read, or a malformed escape.
    Unsupported(String),
}

/// Resolves a buffer or image URI against the glTF file's folder: a file must be a regular
/// file inside it ([`skinbrdf_core::untrusted::confine`], after `%`-decoding; a `file:` URI
/// is held to the same rule, so `file:///etc/passwd` is refused as absolute).
pub(crate) fn resolve_uri(dir: &Path, uri: &str) -> UriTarget {
    if uri.starts_with("data:") {
        return UriTarget::Data;
    }
    let rest = if let Some(r) = uri.strip_prefix("file://") {
        r
    } else if let Some(r) = uri.strip_prefix("file:") {
        r
    } else if uri.contains(':') {
        return UriTarget::Unsupported(format!("URI scheme of `{uri}` is not read"));
    } else {
        uri
    };
    match percent_decode(rest) {
        Some(p) => match skinbrdf_core::untrusted::confine(dir, &p) {
            Ok(file) => UriTarget::File(file),
            Err(e) => UriTarget::Refused(e),
        },
        None => UriTarget::Unsupported(format!("`{uri}` has a malformed %-escape")),
    }
}

/// The external files a `.gltf` refers to (buffers and images with a file URI), for copying a
/// scan with what comes with it; a `.glb` normally has none. Each entry is the path relative to
/// the glTF file's folder (decoded, `/`-separated) and the resolved path; a URI leading outside
/// the folder, or to anything but a regular file, is refused ([`resolve_uri`]).
pub fn gltf_external_files(path: &Path) -> Result<Vec<(String, PathBuf)>, MeshError> {
    guarded(path, || external_files(path))
}

fn external_files(path: &Path) -> Result<Vec<(String, PathBuf)>, MeshError> {
    let bytes = skinbrdf_core::untrusted::read_bounded(path, skinbrdf_core::untrusted::SCAN_FILE)?;
    let doc = parse_document(path, &bytes)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut uris: Vec<(&str, String)> = Vec::new();
    for b in doc.document.buffers() {
        if let ::gltf::buffer::Source::Uri(u) = b.source() {
            uris.push((u, format!("buffer {}", b.index())));
        }
    }
    for im in doc.document.images() {
        if let ::gltf::image::Source::Uri { uri, .. } = im.source() {
            uris.push((uri, format!("image {}", im.index())));
        }
    }
    let mut out = Vec::new();
    for (u, what) in uris {
        match resolve_uri(&dir, u) {
            UriTarget::Data => {}
            UriTarget::File(p) => {
                if what.starts_with("image") {
                    TextureImage::check_header(&p)?;
                }
                let rel = p
                    .strip_prefix(&dir)
                    .unwrap_or(&p)
                    .to_string_lossy()
                    .replace('\\', "/");
                if !out.iter().any(|(_, q)| q == &p) {
                    out.push((rel, p));
                }
            }
            UriTarget::Refused(reason) => {
                return Err(MeshError::Refused {
                    path: path.to_path_buf(),
                    key: format!("{what} uri"),
                    reason: Box::new(reason),
                })
            }
            UriTarget::Unsupported(reason) => {
                return Err(gltf_err(
                    path,
                    GltfProblem::Document(format!("{what}: {reason}")),
                ))
            }
        }
    }
    Ok(out)
}

/// Reads bytes behind a URI: a data URI through the `gltf` crate, a file directly.
pub(super) fn read_uri(dir: &Path, uri: &str) -> Result<Vec<u8>, (Option<PathBuf>, String)> {
    match resolve_uri(dir, uri) {
        UriTarget::Data => {
            ::gltf::buffer::Data::from_source(::gltf::buffer::Source::Uri(uri), Some(dir))
                .map(|d| d.0)
                .map_err(|e| (None, format!("data URI: {e}")))
        }
        UriTarget::File(p) => {
            skinbrdf_core::untrusted::read_bounded(&p, skinbrdf_core::untrusted::SCAN_FILE)
                .map_err(|e| (Some(p), skinbrdf_core::error_text(&e)))
        }
        UriTarget::Refused(skinbrdf_core::untrusted::ConfineError::Missing { path, .. }) => {
            Err((Some(path), "it does not exist".into()))
        }
        UriTarget::Refused(e) => Err((None, e.to_string())),
        UriTarget::Unsupported(reason) => Err((None, reason)),
    }
}

/// The buffers' bytes, each at least its `byteLength`.
pub(super) fn load_buffers(
    path: &Path,
    doc: &::gltf::Document,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>, MeshError> {
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut out = Vec::new();
    for b in doc.buffers() {
        let data = match b.source() {
            ::gltf::buffer::Source::Bin => blob.take().ok_or_else(|| {
                gltf_err(
                    path,
                    GltfProblem::BadBuffer {
                        buffer: b.index(),
                        reason: "it refers to the GLB binary chunk, which the file does not have"
                            .into(),
                    },
                )
            })?,
            ::gltf::buffer::Source::Uri(uri) => {
                read_uri(&dir, uri).map_err(|(file, reason)| match file {
                    Some(file) => gltf_err(
                        path,
                        GltfProblem::MissingBuffer {
                            buffer: b.index(),
                            file,
                            reason,
                        },
                    ),
                    None => gltf_err(
                        path,
                        GltfProblem::BadBuffer {
                            buffer: b.index(),
                            reason,
                        },
                    ),
                })?
            }
        };
        if data.len() < b.length() {
            return Err(gltf_err(
                path,
                GltfProblem::ShortBuffer {
                    buffer: b.index(),
                    stated: b.length(),
                    actual: data.len(),
                },
            ));
        }
        out.push(data);
    }
    Ok(out)
}
