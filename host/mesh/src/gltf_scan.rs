//! glTF 2.0 scans: binary `.glb` and `.gltf` with external or data-URI buffers and images, read
//! with the `gltf` crate; and [`write_glb`], a minimal textured GLB writer for tests and the
//! synthetic studio.
//!
//! # What is read
//!
//! Every mesh primitive reachable from the default scene (else the first scene; a file with no
//! scene at all: every root node), each transformed by its node's world transform (parents'
//! matrices composed in `f64`; a transform that mirrors reverses the winding so front faces
//! stay front faces, as the specification says). Coordinates are kept as stored: glTF is Y-up
//! metres by specification, so [`crate::LengthUnit::Auto`] means metres here, not a guess, and
//! an explicit unit scales as for any other format (for an exporter that wrote millimetres).
//! Only triangle lists are read (`mode` 4, indexed or not); points, lines, strips and fans are
//! refused. Skins and morph targets are ignored (the base geometry is read).
//!
//! Per triangle, the colour comes from the first of:
//!
//! 1. the material's base-colour texture at the texture-coordinate set it names (`TEXCOORD_0`
//!    normally), the image embedded in the GLB's binary chunk, an external file or a data URI;
//! 2. the primitive's `COLOR_0` vertex colours;
//! 3. the material's `baseColorFactor` (a primitive with no material has no colour, as an OBJ
//!    face without `usemtl`).
//!
//! The factor multiplies the texture or the vertex colours (the specification's base colour);
//! `COLOR_0` is not multiplied into a texture (scanners write one or the other). Samplers (wrap
//! modes, filters) and `KHR_texture_transform` are ignored: lookups repeat and are bilinear, as
//! for OBJ.
//!
//! # Conventions
//!
//! * **Texture coordinates**: glTF puts `v = 0` at the top of the image, OBJ at the bottom. They
//!   are stored in the OBJ convention (`v_obj = 1 - v_gltf`) so that one lookup
//!   ([`crate::TextureImage::bilinear`]) serves both; [`write_glb`] does the reverse.
//! * **Colour space**: every appearance of the crate holds display (sRGB-encoded) values, as an
//!   OBJ's PNG texture and a PLY's vertex colours store them. A glTF base-colour texture is
//!   sRGB-encoded by specification and is kept as stored; `COLOR_0` and `baseColorFactor` are
//!   linear by specification and are encoded to sRGB (after the factor's multiplication, done
//!   in linear light) so that all formats give the same value for the same print.
//! * **Invalid data**: the specification forbids non-finite accessor values and out-of-range
//!   indices, so a NaN position or an index past the vertices is an error naming the mesh and
//!   primitive (not a defect for the repair to drop, as in an OBJ or PLY).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::{Mode, Semantic};
use glam::{DMat4, DVec3, Vec2, Vec3};
use skinbrdf_core::TriMesh;

pub use crate::error::GltfProblem;
use crate::error::MeshError;
pub use crate::limits::READ_BYTES_PER_BUFFER_BYTE;
use crate::limits::{MAX_TEXTURE_TEXELS, READ_BYTES_SLACK};
use crate::material::{Material, TextureImage};

/// A glTF scan's geometry with per-triangle appearance, before units and repair.
#[derive(Debug, Clone, Default)]
pub(crate) struct GltfData {
    /// Positions as stored (after node transforms), triangles in file order.
    pub(crate) mesh: TriMesh,
    /// Per triangle, the texture coordinates of its corners (OBJ convention, `v` up) when its
    /// material's base-colour texture is used.
    pub(crate) uv: Vec<Option<[Vec2; 3]>>,
    /// Per triangle, its material (index into `materials`).
    pub(crate) material: Vec<Option<u32>>,
    /// Per triangle, its corners' colours (sRGB-encoded) when it shows `COLOR_0`.
    pub(crate) corner_colours: Vec<Option<[[f32; 3]; 3]>>,
    /// The document's materials (empty when only the geometry was read).
    pub(crate) materials: Vec<Material>,
}

/// How much of a glTF file to read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Detail {
    /// Positions and triangles only ([`crate::load_mesh`]): images are not decoded.
    Geometry,
    /// Also texture coordinates, vertex colours, materials and their images.
    Appearance,
}

/// sRGB-encoded to linear (the IEC 61966-2-1 curve).
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear to sRGB-encoded (the IEC 61966-2-1 curve), clamped to 0..1.
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

fn gltf_err(path: &Path, problem: GltfProblem) -> MeshError {
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

/// Runs a reader of the `gltf` crate's document and turns a panic inside that crate into this
/// file's error: its validation and accessors index unchecked on some malformed documents (a
/// primitive's attribute naming an accessor that does not exist, an image with no source).
fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T, MeshError>) -> Result<T, MeshError> {
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

fn parse_document(path: &Path, bytes: &[u8]) -> Result<::gltf::Gltf, MeshError> {
    if bytes.starts_with(b"glTF") {
        check_glb_container(bytes).map_err(|p| gltf_err(path, p))?;
    }
    ::gltf::Gltf::from_slice(bytes)
        .map_err(|e| gltf_err(path, GltfProblem::Document(e.to_string())))
}

/// Reads bytes behind a URI: a data URI through the `gltf` crate, a file directly.
fn read_uri(dir: &Path, uri: &str) -> Result<Vec<u8>, (Option<PathBuf>, String)> {
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
fn load_buffers(
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

/// A component type's name in the glTF specification.
fn data_type_name(t: DataType) -> &'static str {
    match t {
        DataType::I8 => "BYTE",
        DataType::U8 => "UNSIGNED_BYTE",
        DataType::I16 => "SHORT",
        DataType::U16 => "UNSIGNED_SHORT",
        DataType::U32 => "UNSIGNED_INT",
        DataType::F32 => "FLOAT",
    }
}

/// An accessor type's name in the glTF specification.
fn dimensions_name(d: Dimensions) -> &'static str {
    match d {
        Dimensions::Scalar => "SCALAR",
        Dimensions::Vec2 => "VEC2",
        Dimensions::Vec3 => "VEC3",
        Dimensions::Vec4 => "VEC4",
        Dimensions::Mat2 => "MAT2",
        Dimensions::Mat3 => "MAT3",
        Dimensions::Mat4 => "MAT4",
    }
}

/// A primitive mode's name in the glTF specification.
fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::Points => "POINTS",
        Mode::Lines => "LINES",
        Mode::LineLoop => "LINE_LOOP",
        Mode::LineStrip => "LINE_STRIP",
        Mode::Triangles => "TRIANGLES",
        Mode::TriangleStrip => "TRIANGLE_STRIP",
        Mode::TriangleFan => "TRIANGLE_FAN",
    }
}

/// Checks an accessor's type and that its bytes lie inside its buffer view and buffer (the
/// `gltf` crate's readers assume a valid file and panic or stop short otherwise).
fn check_accessor(
    acc: &::gltf::Accessor<'_>,
    buffers: &[Vec<u8>],
    types: &[DataType],
    dims: &[Dimensions],
    count: Option<usize>,
) -> Result<(), String> {
    if !types.contains(&acc.data_type()) || !dims.contains(&acc.dimensions()) {
        let names = |v: Vec<&str>| v.join(" or ");
        return Err(format!(
            "accessor {} is {} {}, expected {} and {}",
            acc.index(),
            data_type_name(acc.data_type()),
            dimensions_name(acc.dimensions()),
            names(types.iter().map(|&t| data_type_name(t)).collect()),
            names(dims.iter().map(|&d| dimensions_name(d)).collect()),
        ));
    }
    if let Some(n) = count {
        if acc.count() != n {
            return Err(format!(
                "accessor {} has {} elements for {n} vertices",
                acc.index(),
                acc.count()
            ));
        }
    }
    if acc.count() == 0 {
        return Err(format!("accessor {} is empty", acc.index()));
    }
    let elem = acc.size();
    let within = |view: &::gltf::buffer::View<'_>, offset: usize, count: usize, elem: usize| {
        let stride = view.stride().unwrap_or(elem).max(elem);
        let end = stride
            .checked_mul(count - 1)
            .and_then(|s| s.checked_add(offset))
            .and_then(|s| s.checked_add(elem));
        let buf_len = buffers.get(view.buffer().index()).map_or(0, Vec::len);
        matches!(end, Some(e) if e <= view.length())
            && view
                .offset()
                .checked_add(view.length())
                .is_some_and(|e| e <= buf_len)
    };
    match acc.view() {
        Some(view) if !within(&view, acc.offset(), acc.count(), elem) => {
            return Err(format!(
                "accessor {} ({} elements) reaches past its buffer view {} or buffer",
                acc.index(),
                acc.count(),
                view.index()
            ))
        }
        None if acc.sparse().is_none() => {
            return Err(format!("accessor {} has no data", acc.index()));
        }
        _ => {}
    }
    if let Some(sp) = acc.sparse() {
        let n = sp.count();
        let ok = n > 0
            && within(
                &sp.indices().view(),
                sp.indices().offset(),
                n,
                sp.indices().index_type().size(),
            )
            && within(&sp.values().view(), sp.values().offset(), n, elem);
        if !ok {
            return Err(format!(
                "accessor {}: its sparse substitution is empty or reaches past its buffer",
                acc.index()
            ));
        }
    }
    Ok(())
}

/// The primitives to read with their world transforms, in scene order.
fn scene_primitives<'a>(
    path: &Path,
    doc: &'a ::gltf::Document,
) -> Result<Vec<(::gltf::Mesh<'a>, DMat4)>, MeshError> {
    let roots: Vec<::gltf::Node<'a>> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => {
            let mut child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    child[c.index()] = true;
                }
            }
            doc.nodes().filter(|n| !child[n.index()]).collect()
        }
    };
    let mut reached = vec![false; doc.nodes().len()];
    let mut out = Vec::new();
    let mut stack: Vec<(::gltf::Node<'a>, DMat4)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, DMat4::IDENTITY))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        match reached.get_mut(node.index()) {
            Some(r) if !*r => *r = true,
            _ => {
                return Err(gltf_err(
                    path,
                    GltfProblem::NodeCycle { node: node.index() },
                ))
            }
        }
        let m = node.transform().matrix().map(|c| c.map(f64::from));
        let world = parent * DMat4::from_cols_array_2d(&m);
        if let Some(mesh) = node.mesh() {
            out.push((mesh, world));
        }
        let children: Vec<_> = node.children().collect();
        for c in children.into_iter().rev() {
            stack.push((c, world));
        }
    }
    Ok(out)
}

fn primitive_name(mesh: &::gltf::Mesh<'_>, p: usize) -> String {
    match mesh.name() {
        Some(n) => format!("mesh {} `{n}`, primitive {p}", mesh.index()),
        None => format!("mesh {}, primitive {p}", mesh.index()),
    }
}

/// Reads a `.glb` or `.gltf` (see the module docs).
pub(crate) fn read_gltf(path: &Path, detail: Detail) -> Result<GltfData, MeshError> {
    guarded(path, || read_gltf_unguarded(path, detail))
}

fn read_gltf_unguarded(path: &Path, detail: Detail) -> Result<GltfData, MeshError> {
    let bytes = skinbrdf_core::untrusted::read_bounded(path, skinbrdf_core::untrusted::SCAN_FILE)?;
    let ::gltf::Gltf {
        document: doc,
        blob,
    } = parse_document(path, &bytes)?;
    drop(bytes);
    let buffers = load_buffers(path, &doc, blob)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut out = GltfData::default();
    let mut images: HashMap<usize, TextureImage> = HashMap::new();
    if detail == Detail::Appearance {
        let mut texels = 0u64;
        for m in doc.materials() {
            let made = material(path, &dir, &buffers, &m, &mut images)?;
            if let Some(t) = &made.texture {
                texels += u64::from(t.width) * u64::from(t.height);
                if texels > MAX_TEXTURE_TEXELS {
                    return Err(gltf_err(
                        path,
                        GltfProblem::TooManyTexels {
                            material: m.index().unwrap_or(0),
                            texels,
                        },
                    ));
                }
            }
            out.materials.push(made);
        }
    }
    let buffer_bytes: u64 = buffers.iter().map(|b| b.len() as u64).sum();
    let max_read_bytes = buffer_bytes
        .saturating_mul(READ_BYTES_PER_BUFFER_BYTE)
        .saturating_add(READ_BYTES_SLACK);
    let mut read_bytes = 0u64;
    let bad = |at: &str, attribute: &str, reason: String| {
        gltf_err(
            path,
            GltfProblem::BadAccessor {
                at: at.to_string(),
                attribute: attribute.to_string(),
                reason,
            },
        )
    };
    for (mesh, world) in scene_primitives(path, &doc)? {
        let mirrored = world.determinant() < 0.0;
        let identity = world == DMat4::IDENTITY;
        for (pi, prim) in mesh.primitives().enumerate() {
            let at = primitive_name(&mesh, pi);
            if prim.mode() != Mode::Triangles {
                return Err(gltf_err(
                    path,
                    GltfProblem::UnsupportedMode {
                        at,
                        mode: mode_name(prim.mode()).to_string(),
                    },
                ));
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
            let Some(pos_acc) = prim.get(&Semantic::Positions) else {
                return Err(bad(&at, "POSITION", "the primitive has none".into()));
            };
            check_accessor(
                &pos_acc,
                &buffers,
                &[DataType::F32],
                &[Dimensions::Vec3],
                None,
            )
            .map_err(|r| bad(&at, "POSITION", r))?;
            let n = pos_acc.count();
            // What this primitive takes once read (positions, and triangles as three u32),
            // checked before it is read.
            let corners = prim.indices().map_or(n, |a| a.count()) as u64;
            read_bytes = read_bytes.saturating_add(12 * n as u64 + 4 * corners);
            if read_bytes > max_read_bytes {
                return Err(gltf_err(
                    path,
                    GltfProblem::TooMuchGeometry {
                        at,
                        bytes: read_bytes,
                        max: max_read_bytes,
                    },
                ));
            }
            let positions: Vec<[f32; 3]> = reader
                .read_positions()
                .ok_or_else(|| bad(&at, "POSITION", "unreadable".into()))?
                .collect();
            if positions.len() != n {
                return Err(bad(
                    &at,
                    "POSITION",
                    format!("{} of {n} read", positions.len()),
                ));
            }
            if let Some((vertex, &value)) = positions
                .iter()
                .enumerate()
                .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
            {
                return Err(gltf_err(
                    path,
                    GltfProblem::NonFinitePosition { at, vertex, value },
                ));
            }
            let tris: Vec<[u32; 3]> = match prim.indices() {
                Some(acc) => {
                    check_accessor(
                        &acc,
                        &buffers,
                        &[DataType::U8, DataType::U16, DataType::U32],
                        &[Dimensions::Scalar],
                        None,
                    )
                    .map_err(|r| bad(&at, "indices", r))?;
                    let idx: Vec<u32> = reader
                        .read_indices()
                        .ok_or_else(|| bad(&at, "indices", "unreadable".into()))?
                        .into_u32()
                        .collect();
                    if !idx.len().is_multiple_of(3) {
                        return Err(bad(
                            &at,
                            "indices",
                            format!("{} indices are not whole triangles", idx.len()),
                        ));
                    }
                    if let Some(i) = idx.iter().find(|&&i| i as usize >= n) {
                        return Err(bad(
                            &at,
                            "indices",
                            format!("index {i} past the primitive's {n} vertices"),
                        ));
                    }
                    idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect()
                }
                None => {
                    if !n.is_multiple_of(3) {
                        return Err(bad(
                            &at,
                            "POSITION",
                            format!("{n} vertices without indices are not whole triangles"),
                        ));
                    }
                    (0..n as u32 / 3)
                        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                        .collect()
                }
            };
            // Mirroring transforms reverse the winding (corners 1 and 2 swapped back).
            let tris: Vec<[u32; 3]> = if mirrored {
                tris.into_iter().map(|[a, b, c]| [a, c, b]).collect()
            } else {
                tris
            };
            let base = out.mesh.positions.len() as u32;
            out.mesh.positions.extend(positions.iter().map(|p| {
                if identity {
                    Vec3::from_array(*p)
                } else {
                    world
                        .transform_point3(DVec3::from_array(p.map(f64::from)))
                        .as_vec3()
                }
            }));
            out.mesh
                .indices
                .extend(tris.iter().map(|t| t.map(|v| v + base)));
            if detail == Detail::Geometry {
                continue;
            }
            let mat = prim.material();
            out.material.extend(std::iter::repeat_n(
                mat.index().map(|m| m as u32),
                tris.len(),
            ));
            let pbr = mat.pbr_metallic_roughness();
            let factor = pbr.base_color_factor();
            let uv_set = pbr.base_color_texture().map(|info| info.tex_coord());
            let uv_acc = uv_set.and_then(|s| prim.get(&Semantic::TexCoords(s)).map(|a| (s, a)));
            if let Some((set, acc)) = uv_acc {
                let name = format!("TEXCOORD_{set}");
                check_accessor(
                    &acc,
                    &buffers,
                    &[DataType::U8, DataType::U16, DataType::F32],
                    &[Dimensions::Vec2],
                    Some(n),
                )
                .map_err(|r| bad(&at, &name, r))?;
                let uv: Vec<[f32; 2]> = reader
                    .read_tex_coords(set)
                    .ok_or_else(|| bad(&at, &name, "unreadable".into()))?
                    .into_f32()
                    .collect();
                if let Some(k) = uv.iter().position(|c| !c.iter().all(|x| x.is_finite())) {
                    return Err(bad(&at, &name, format!("element {k} is not finite")));
                }
                if uv.len() != n {
                    return Err(bad(&at, &name, format!("{} of {n} read", uv.len())));
                }
                let corner = |v: u32| {
                    let [u, w] = uv[v as usize];
                    Vec2::new(u, 1.0 - w)
                };
                out.uv.extend(tris.iter().map(|t| Some(t.map(corner))));
                out.corner_colours
                    .extend(std::iter::repeat_n(None, tris.len()));
                continue;
            }
            out.uv.extend(std::iter::repeat_n(None, tris.len()));
            match prim.get(&Semantic::Colors(0)) {
                Some(acc) => {
                    check_accessor(
                        &acc,
                        &buffers,
                        &[DataType::U8, DataType::U16, DataType::F32],
                        &[Dimensions::Vec3, Dimensions::Vec4],
                        Some(n),
                    )
                    .map_err(|r| bad(&at, "COLOR_0", r))?;
                    let rgb: Vec<[f32; 3]> = reader
                        .read_colors(0)
                        .ok_or_else(|| bad(&at, "COLOR_0", "unreadable".into()))?
                        .into_rgb_f32()
                        .collect();
                    if rgb.len() != n {
                        return Err(bad(&at, "COLOR_0", format!("{} of {n} read", rgb.len())));
                    }
                    let encoded: Vec<[f32; 3]> = rgb
                        .iter()
                        .map(|c| std::array::from_fn(|k| linear_to_srgb(c[k] * factor[k])))
                        .collect();
                    out.corner_colours
                        .extend(tris.iter().map(|t| Some(t.map(|v| encoded[v as usize]))));
                }
                None => out
                    .corner_colours
                    .extend(std::iter::repeat_n(None, tris.len())),
            }
        }
    }
    if out.mesh.indices.is_empty() {
        return Err(MeshError::Parse {
            path: path.to_path_buf(),
            reason: "glTF has no triangles in its scene".into(),
        });
    }
    Ok(out)
}

/// One glTF material: its factor (encoded to sRGB) and its base-colour image (decoded once per
/// image, the factor multiplied in).
fn material(
    path: &Path,
    dir: &Path,
    buffers: &[Vec<u8>],
    m: &::gltf::Material<'_>,
    images: &mut HashMap<usize, TextureImage>,
) -> Result<Material, MeshError> {
    let index = m.index().unwrap_or(0);
    let name = m
        .name()
        .map_or_else(|| format!("material {index}"), str::to_string);
    let pbr = m.pbr_metallic_roughness();
    let f = pbr.base_color_factor();
    let diffuse = [f[0], f[1], f[2]].map(linear_to_srgb);
    let Some(info) = pbr.base_color_texture() else {
        return Ok(Material {
            name,
            diffuse,
            texture: None,
            texture_path: None,
        });
    };
    let image = info.texture().source();
    let img_index = image.index();
    let (bytes, where_, file) = match image.source() {
        ::gltf::image::Source::View { view, .. } => {
            let data = buffers
                .get(view.buffer().index())
                .and_then(|b| b.get(view.offset()..view.offset().checked_add(view.length())?));
            let Some(data) = data else {
                return Err(MeshError::Texture {
                    path: path.to_path_buf(),
                    reason: format!(
                        "image {img_index} (material `{name}`): its buffer view {} reaches past \
                         its buffer",
                        view.index()
                    ),
                });
            };
            (data.to_vec(), "embedded".to_string(), None)
        }
        ::gltf::image::Source::Uri { uri, .. } => match resolve_uri(dir, uri) {
            UriTarget::Refused(skinbrdf_core::untrusted::ConfineError::Missing {
                path: p, ..
            }) => {
                return Err(MeshError::MissingTexture {
                    path: path.to_path_buf(),
                    material: name,
                    texture: p,
                })
            }
            UriTarget::Refused(reason) => {
                return Err(MeshError::Refused {
                    path: path.to_path_buf(),
                    key: format!("image {img_index} uri (material `{name}`)"),
                    reason: Box::new(reason),
                })
            }
            UriTarget::File(p) => {
                let b = skinbrdf_core::untrusted::read_bounded(
                    &p,
                    skinbrdf_core::untrusted::TEXTURE_FILE,
                )?;
                (b, format!("{}", p.display()), Some(p))
            }
            _ => {
                let b = read_uri(dir, uri).map_err(|(_, reason)| MeshError::Texture {
                    path: path.to_path_buf(),
                    reason: format!("image {img_index} (material `{name}`): {reason}"),
                })?;
                (b, "data URI".to_string(), None)
            }
        },
    };
    let tex = match images.get(&img_index) {
        Some(t) => t.clone(),
        None => {
            let t = TextureImage::decode(&bytes).map_err(|reason| MeshError::Texture {
                path: file.clone().unwrap_or_else(|| path.to_path_buf()),
                reason: format!("image {img_index} ({where_}, material `{name}`): {reason}"),
            })?;
            images.insert(img_index, t.clone());
            t
        }
    };
    let tex = if f[..3] == [1.0, 1.0, 1.0] {
        tex
    } else {
        TextureImage {
            rgb: tex
                .rgb
                .iter()
                .map(|c| std::array::from_fn(|k| linear_to_srgb(srgb_to_linear(c[k]) * f[k])))
                .collect(),
            ..tex
        }
    };
    Ok(Material {
        name,
        diffuse,
        texture: Some(tex),
        texture_path: file,
    })
}

/// Writes `mesh` (metres) as a binary glTF with one triangle-list primitive, texture
/// coordinates per triangle corner (`uv[t][k]` of corner `k` of triangle `t`, OBJ convention:
/// `v = 0` at the image's bottom) and `texture_png` (an encoded PNG) embedded as the material's
/// base-colour texture, atomically. glTF keeps texture coordinates per vertex, so a vertex
/// whose corners have different coordinates is written once per coordinate. Vertices are
/// written in the order the triangles first use them (the order in which an OBJ reader numbers
/// them), so a loader that welds identical positions (as [`crate::load_textured`] does) gets
/// the vertices of the same mesh read from an OBJ back, in their order; vertices no triangle
/// uses are not written.
pub fn write_glb(
    path: &Path,
    mesh: &TriMesh,
    uv: &[[Vec2; 3]],
    texture_png: &[u8],
) -> Result<(), MeshError> {
    let bytes =
        encode_glb(mesh, uv, texture_png).map_err(|reason| MeshError::InvalidParameter {
            field: "write_glb",
            reason,
        })?;
    crate::ply::write_atomic(path, &bytes)
}

/// [`write_glb`] into memory.
pub fn encode_glb(mesh: &TriMesh, uv: &[[Vec2; 3]], texture_png: &[u8]) -> Result<Vec<u8>, String> {
    if uv.len() != mesh.indices.len() {
        return Err(format!(
            "{} texture-coordinate triples for {} triangles",
            uv.len(),
            mesh.indices.len()
        ));
    }
    if mesh.indices.is_empty() {
        return Err("the mesh has no triangles".into());
    }
    let nv = mesh.positions.len();
    if let Some(t) = mesh
        .indices
        .iter()
        .position(|t| t.iter().any(|&v| v as usize >= nv))
    {
        return Err(format!("triangle {t} indexes past the {nv} vertices"));
    }
    // Output vertices: (position, uv) pairs in the order the triangles first use them.
    let mut key_to_out: HashMap<(u32, [u32; 2]), u32> = HashMap::with_capacity(3 * nv);
    let mut corner_out: Vec<u32> = Vec::with_capacity(3 * mesh.indices.len());
    let mut out_pos: Vec<Vec3> = Vec::new();
    let mut out_uv: Vec<[f32; 2]> = Vec::new();
    for (t, tri) in mesh.indices.iter().enumerate() {
        for k in 0..3 {
            let v = tri[k];
            let c = uv[t][k];
            let (u, w) = (c.x, 1.0 - c.y);
            let next = out_pos.len() as u32;
            let o = *key_to_out
                .entry((v, [u.to_bits(), w.to_bits()]))
                .or_insert_with(|| {
                    out_pos.push(mesh.positions[v as usize]);
                    out_uv.push([u, w]);
                    next
                });
            corner_out.push(o);
        }
    }
    if let Some(p) = out_pos.iter().find(|p| !p.is_finite()) {
        return Err(format!("a position is not finite ({p})"));
    }
    let (lo, hi) = out_pos.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let mut bin: Vec<u8> = Vec::with_capacity(out_pos.len() * 20 + corner_out.len() * 4);
    let pos_off = bin.len();
    for p in &out_pos {
        for c in p.to_array() {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let uv_off = bin.len();
    for c in &out_uv {
        for x in c {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    let idx_off = bin.len();
    for i in &corner_out {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let img_off = bin.len();
    bin.extend_from_slice(texture_png);
    let img_len = texture_png.len();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let n_out = out_pos.len();
    let json = serde_json::json!({
        "asset": { "version": "2.0", "generator": "skinbrdf-mesh write_glb" },
        "scene": 0,
        "scenes": [ { "nodes": [0] } ],
        "nodes": [ { "mesh": 0, "name": "scan" } ],
        "meshes": [ { "name": "scan", "primitives": [ {
            "attributes": { "POSITION": 0, "TEXCOORD_0": 1 },
            "indices": 2,
            "material": 0,
            "mode": 4
        } ] } ],
        "materials": [ {
            "name": "scan",
            "pbrMetallicRoughness": {
                "baseColorTexture": { "index": 0 },
                "metallicFactor": 0.0,
                "roughnessFactor": 1.0
            }
        } ],
        "textures": [ { "source": 0 } ],
        "images": [ { "bufferView": 3, "mimeType": "image/png" } ],
        "buffers": [ { "byteLength": bin.len() } ],
        "bufferViews": [
            { "buffer": 0, "byteOffset": pos_off, "byteLength": uv_off - pos_off, "target": 34962 },
            { "buffer": 0, "byteOffset": uv_off, "byteLength": idx_off - uv_off, "target": 34962 },
            { "buffer": 0, "byteOffset": idx_off, "byteLength": img_off - idx_off, "target": 34963 },
            { "buffer": 0, "byteOffset": img_off, "byteLength": img_len }
        ],
        "accessors": [
            { "bufferView": 0, "componentType": 5126, "count": n_out, "type": "VEC3",
              "min": lo.to_array(), "max": hi.to_array() },
            { "bufferView": 1, "componentType": 5126, "count": n_out, "type": "VEC2" },
            { "bufferView": 2, "componentType": 5125, "count": corner_out.len(), "type": "SCALAR" }
        ]
    });
    let json = serde_json::to_vec(&json).map_err(|e| e.to_string())?;
    let glb = ::gltf::binary::Glb {
        header: ::gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0,
        },
        json: json.into(),
        bin: Some(bin.into()),
    };
    glb.to_vec().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::Hit;
    use crate::load::{LengthUnit, LoadOptions};
    use crate::textured::{load_textured, Appearance};
    use serde_json::json;

    /// Colours compared within this: an 8-bit texel is 1/255 apart, and the sRGB curve is
    /// evaluated in f32.
    const COLOUR_TOL: f32 = 1e-4;
    /// Positions compared within this, metres: f32 rounding of the transforms' products.
    const POS_TOL: f32 = 1e-6;

    /// A GLB container assembled by hand (independent of the `gltf` crate's writer).
    fn glb(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
        let mut j = serde_json::to_vec(json).expect("json");
        while !j.len().is_multiple_of(4) {
            j.push(b' ');
        }
        let mut b = bin.to_vec();
        while !b.len().is_multiple_of(4) {
            b.push(0);
        }
        let total = 12 + 8 + j.len() + 8 + b.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(j.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&j);
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&b);
        out
    }

    fn base64(bytes: &[u8]) -> String {
        const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut s = String::new();
        for c in bytes.chunks(3) {
            let n = (u32::from(c[0]) << 16)
                | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
                | u32::from(*c.get(2).unwrap_or(&0));
            for k in 0..4 {
                if k <= c.len() {
                    s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
                } else {
                    s.push('=');
                }
            }
        }
        s
    }

    fn f32s(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    /// 2 x 2 texels: top row black, white; bottom row red, blue.
    fn png_2x2() -> Vec<u8> {
        let mut img = image::RgbImage::new(2, 2);
        img.put_pixel(0, 0, image::Rgb([0, 0, 0]));
        img.put_pixel(1, 0, image::Rgb([255, 255, 255]));
        img.put_pixel(0, 1, image::Rgb([255, 0, 0]));
        img.put_pixel(1, 1, image::Rgb([0, 0, 255]));
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png)
            .expect("png");
        out.into_inner()
    }

    /// The 10 cm quad in z = 0 (two triangles, indexed u16), glTF texture coordinates with
    /// `v = 0` at the image's top (the quad's top edge, y = 0.1), the 2 x 2 PNG embedded.
    /// `edit` may change the JSON before it is packed.
    fn quad_glb(png: &[u8], edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
        let pos = f32s(&[0., 0., 0., 0.1, 0., 0., 0.1, 0.1, 0., 0., 0.1, 0.]);
        let uv = f32s(&[0., 1., 1., 1., 1., 0., 0., 0.]);
        let idx: Vec<u8> = [0u16, 1, 2, 0, 2, 3]
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        let mut bin = Vec::new();
        bin.extend_from_slice(&pos); // 0..48
        bin.extend_from_slice(&uv); // 48..80
        bin.extend_from_slice(&idx); // 80..92
        let img_off = bin.len();
        bin.extend_from_slice(png);
        let mut j = json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"name": "quad", "primitives": [{
                "attributes": {"POSITION": 0, "TEXCOORD_0": 1},
                "indices": 2, "material": 0}]}],
            "materials": [{"name": "paper", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
            "textures": [{"source": 0}],
            "images": [{"bufferView": 3, "mimeType": "image/png"}],
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 48},
                {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                {"buffer": 0, "byteOffset": 80, "byteLength": 12},
                {"buffer": 0, "byteOffset": img_off, "byteLength": png.len()}
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                 "min": [0, 0, 0], "max": [0.1, 0.1, 0]},
                {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}
            ]
        });
        edit(&mut j);
        glb(&j, &bin)
    }

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < COLOUR_TOL)
    }

    fn hit(triangle: u32, u: f32, v: f32) -> Hit {
        Hit {
            t_m: 1.0,
            triangle,
            u,
            v,
        }
    }

    #[test]
    fn a_hand_built_glb_loads_with_its_positions_uv_convention_and_colours() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("quad.glb");
        std::fs::write(&p, quad_glb(&png_2x2(), |_| {})).expect("write");
        let t = load_textured(&p, &LoadOptions::default()).expect("load");
        assert_eq!(t.unit, LengthUnit::Metres, "glTF is metres, not guessed");
        assert_eq!(t.mesh.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(t.mesh.positions[2], Vec3::new(0.1, 0.1, 0.0));
        let plain = crate::load_mesh(&p, &LoadOptions::default()).expect("load_mesh");
        assert_eq!(plain.mesh, t.mesh);
        let Appearance::Texture { uv, materials, .. } = &t.appearance else {
            panic!("{:?}", t.appearance);
        };
        assert_eq!(materials[0].name, "paper");
        assert!(materials[0].texture_path.is_none(), "embedded");
        // glTF v = 1 at vertex 0 (the image's bottom) is OBJ v = 0.
        assert_eq!(uv[0].expect("uv")[0], Vec2::new(0.0, 0.0));
        assert_eq!(uv[0].expect("uv")[2], Vec2::new(1.0, 1.0));
        // Known barycentrics on triangle 1 (corners 0, 2, 3: bottom-left, top-right,
        // top-left): u = 0.25, v = 0.5 is the point (0.025, 0.075), the top-left texel's
        // centre (black); triangle 0 (0, 1, 2) at u = 0.5, v = 0.25: (0.075, 0.025), bottom
        // right (blue); at u = 0, v = 0.25: (0.025, 0.025), bottom left (red).
        assert!(close(t.colour_at(&hit(1, 0.25, 0.5)), [0.0; 3]));
        assert!(close(t.colour_at(&hit(0, 0.5, 0.25)), [0.0, 0.0, 1.0]));
        assert!(close(t.colour_at(&hit(0, 0.0, 0.25)), [1.0, 0.0, 0.0]));
        // Half-way between the bottom texels' centres: (0.05, 0.025) on triangle 0 is
        // u = 0.25, v = 0.25.
        let c = t.colour_at(&hit(0, 0.25, 0.25));
        assert!(close(c, [0.5, 0.0, 0.5]), "{c:?}");
        // The same through a ray, as the OBJ test does.
        let bvh = crate::MeshBvh::build(&t.mesh, crate::BuildQuality::Fast).expect("bvh");
        let h = bvh
            .intersect(Vec3::new(0.075, 0.075, 1.0), -Vec3::Z, 10.0)
            .expect("hit");
        assert!(close(t.colour_at(&h), [1.0; 3]), "top-right texel is white");
        // An explicit unit scales as for any format.
        let mm = crate::load_mesh(
            &p,
            &LoadOptions {
                unit: LengthUnit::Millimetres,
                ..Default::default()
            },
        )
        .expect("mm");
        assert!((mm.mesh.positions[2].x - 1e-4).abs() < 1e-9);
    }

    #[test]
    fn the_base_colour_factor_multiplies_the_texture_in_linear_light() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("quad.glb");
        std::fs::write(
            &p,
            quad_glb(&png_2x2(), |j| {
                j["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] =
                    json!([0.5, 1.0, 1.0, 1.0]);
            }),
        )
        .expect("write");
        let t = load_textured(&p, &LoadOptions::default()).expect("load");
        // Red texel (1, 0, 0): linear 1 * 0.5 encodes to 0.7354.
        let c = t.colour_at(&hit(0, 0.0, 0.25));
        assert!(close(c, [linear_to_srgb(0.5), 0.0, 0.0]), "{c:?}");
        assert!((linear_to_srgb(0.5) - 0.735_357).abs() < 1e-5);
    }

    /// A `.gltf` with its buffer in a data URI: two primitives, one with linear float
    /// `COLOR_0`, one with only a `baseColorFactor`; the first instanced under a parent node
    /// with a translation and a child with a rotation and scale, the second mirrored.
    fn gltf_with_data_uri(extra_nodes: serde_json::Value) -> serde_json::Value {
        let pos = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
        let col = f32s(&[1., 0., 0., 0., 1., 0., 0.5, 0.5, 0.5]);
        let mut bin = pos.clone();
        bin.extend_from_slice(&col);
        json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": extra_nodes}],
            "nodes": [
                {"translation": [1.0, 2.0, 3.0], "children": [1]},
                {"mesh": 0, "scale": [2.0, 2.0, 2.0],
                 "rotation": [0.0, 0.0, 0.707_106_77, 0.707_106_77]},
                {"mesh": 1, "scale": [-1.0, 1.0, 1.0]}
            ],
            "meshes": [
                {"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1}}]},
                {"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}
            ],
            "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1.0, 1.0]}}],
            "buffers": [{"byteLength": bin.len(),
                         "uri": format!("data:application/octet-stream;base64,{}", base64(&bin))}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 36},
                {"buffer": 0, "byteOffset": 36, "byteLength": 36}
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 0]},
                {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}
            ]
        })
    }

    #[test]
    fn a_gltf_with_a_data_uri_buffer_applies_node_transforms_and_colours() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("scan.gltf");
        std::fs::write(
            &p,
            serde_json::to_vec(&gltf_with_data_uri(json!([0, 2]))).expect("json"),
        )
        .expect("write");
        let opts = LoadOptions {
            policy: crate::RepairPolicy {
                weld: false,
                ..crate::RepairPolicy::repair()
            },
            ..Default::default()
        };
        let t = load_textured(&p, &opts).expect("load");
        assert_eq!(t.mesh.indices.len(), 2);
        // Node 1: rotate 90 degrees about z, scale 2, then node 0 translates by (1, 2, 3):
        // (1, 0, 0) -> (0, 2, 0) -> (1, 4, 3); (0, 1, 0) -> (-2, 0, 0) -> (-1, 2, 3).
        let want = [
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(1.0, 4.0, 3.0),
            Vec3::new(-1.0, 2.0, 3.0),
        ];
        for (got, want) in t.mesh.positions[..3].iter().zip(want) {
            assert!((*got - want).length() < POS_TOL, "{got} vs {want}");
        }
        // The mirrored instance (x -> -x) keeps facing +z: its winding was reversed.
        let [a, b, c] = t.mesh.indices[1].map(|v| t.mesh.positions[v as usize]);
        assert!((b - a).cross(c - a).z > 0.0, "{a} {b} {c}");
        assert_eq!(t.mesh.positions[4], Vec3::new(-1.0, 0.0, 0.0));
        // COLOR_0 is linear: (0.5, 0.5, 0.5) is encoded to sRGB; corner colours interpolate.
        let c = t.colour_at(&hit(0, 0.0, 1.0));
        assert!(close(c, [linear_to_srgb(0.5); 3]), "{c:?}");
        let c = t.colour_at(&hit(0, 0.5, 0.0));
        assert!(close(c, [0.5, 0.5, 0.0]), "{c:?}");
        // The factor-only primitive shows its factor, encoded.
        let c = t.colour_at(&hit(1, 0.2, 0.2));
        assert!(close(c, [0.5f32, 0.25, 1.0].map(linear_to_srgb)), "{c:?}");
        let plain = crate::load_mesh(&p, &opts).expect("load_mesh");
        assert_eq!(plain.mesh, t.mesh);
    }

    #[test]
    fn an_external_buffer_and_image_are_read_beside_the_gltf() {
        let dir = tempfile::tempdir().expect("tempdir");
        let png = png_2x2();
        let bytes = quad_glb(&png, |_| {});
        let g = ::gltf::Gltf::from_slice(&bytes).expect("parse");
        let bin = g.blob.clone().expect("blob");
        let mut j = serde_json::to_value(g.document.into_json()).expect("json");
        std::fs::create_dir_all(dir.path().join("tex dir")).expect("mkdir");
        std::fs::write(dir.path().join("quad.bin"), &bin).expect("bin");
        std::fs::write(dir.path().join("tex dir/paper.png"), &png).expect("png");
        j["buffers"][0]["uri"] = json!("quad.bin");
        j["images"][0] = json!({"uri": "tex%20dir/paper.png"});
        let p = dir.path().join("quad.gltf");
        std::fs::write(&p, serde_json::to_vec(&j).expect("json")).expect("write");
        let t = load_textured(&p, &LoadOptions::default()).expect("load");
        assert!(close(t.colour_at(&hit(0, 0.0, 0.25)), [1.0, 0.0, 0.0]));
        let files = gltf_external_files(&p).expect("files");
        let names: Vec<&str> = files.iter().map(|(r, _)| r.as_str()).collect();
        assert_eq!(names, ["quad.bin", "tex dir/paper.png"]);
        // The missing image is named, the geometry still loads.
        std::fs::remove_file(dir.path().join("tex dir/paper.png")).expect("rm");
        let e = load_textured(&p, &LoadOptions::default()).expect_err("no png");
        assert!(matches!(e, MeshError::MissingTexture { .. }), "{e}");
        assert!(e.to_string().contains("paper.png") && e.to_string().contains("quad.gltf"));
        assert!(crate::load_mesh(&p, &LoadOptions::default()).is_ok());
        // The missing buffer is named.
        std::fs::remove_file(dir.path().join("quad.bin")).expect("rm");
        let e = crate::load_mesh(&p, &LoadOptions::default()).expect_err("no bin");
        let s = e.to_string();
        assert!(
            matches!(
                e,
                MeshError::Gltf {
                    problem: GltfProblem::MissingBuffer { buffer: 0, .. },
                    ..
                }
            ),
            "{s}"
        );
        assert!(s.contains("quad.gltf") && s.contains("quad.bin"), "{s}");
    }

    fn problem(e: &MeshError) -> Option<&GltfProblem> {
        match e {
            MeshError::Gltf { problem, .. } => Some(problem),
            _ => None,
        }
    }

    #[test]
    fn bad_glb_files_give_errors_naming_the_file_and_the_problem() {
        let dir = tempfile::tempdir().expect("tempdir");
        let load = |name: &str, bytes: &[u8]| {
            let p = dir.path().join(name);
            std::fs::write(&p, bytes).expect("write");
            let e = load_textured(&p, &LoadOptions::default()).expect_err(name);
            assert!(e.to_string().contains(name), "{e}");
            e
        };
        let good = quad_glb(&png_2x2(), |_| {});

        // Truncated: cut in the binary chunk, and inside the header.
        let e = load("cut.glb", &good[..good.len() - 40]);
        assert!(
            matches!(problem(&e), Some(GltfProblem::Truncated { .. })),
            "{e}"
        );
        assert!(e.to_string().contains("truncated GLB"), "{e}");
        let mut tiny = good.clone();
        tiny[8..12].copy_from_slice(&4u32.to_le_bytes());
        let e = load("tiny.glb", &tiny);
        assert!(e.to_string().contains("states 4 bytes"), "{e}");
        let e = load("stub.glb", &good[..10]);
        assert!(
            matches!(problem(&e), Some(GltfProblem::Truncated { .. })),
            "{e}"
        );

        // A binary chunk shorter than the buffer's byteLength.
        let short = quad_glb(&png_2x2(), |j| {
            j["buffers"][0]["byteLength"] = json!(100_000)
        });
        let e = load("short.glb", &short);
        assert!(
            matches!(problem(&e), Some(GltfProblem::ShortBuffer { .. })),
            "{e}"
        );

        // NaN positions.
        let mut nan = good.clone();
        let json_len = u32::from_le_bytes([nan[12], nan[13], nan[14], nan[15]]) as usize;
        let bin_start = 12 + 8 + json_len + 8;
        nan[bin_start + 12..bin_start + 16].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = load("nan.glb", &nan);
        assert!(
            matches!(
                problem(&e),
                Some(GltfProblem::NonFinitePosition { vertex: 1, .. })
            ),
            "{e}"
        );
        assert!(e.to_string().contains("mesh 0 `quad`, primitive 0"), "{e}");

        // Unsupported primitive modes.
        for (mode, name) in [(0, "POINTS"), (5, "TRIANGLE_STRIP")] {
            let m = quad_glb(&png_2x2(), |j| {
                j["meshes"][0]["primitives"][0]["mode"] = json!(mode)
            });
            let e = load("mode.glb", &m);
            assert!(
                matches!(problem(&e), Some(GltfProblem::UnsupportedMode { .. })),
                "{e}"
            );
            assert!(e.to_string().contains(name), "{e}");
        }

        // Indices past the vertices, and an accessor past its buffer view.
        let m = quad_glb(&png_2x2(), |j| j["accessors"][0]["count"] = json!(2));
        let e = load("idx.glb", &m);
        assert!(e.to_string().contains("index 2 past"), "{e}");
        let m = quad_glb(&png_2x2(), |j| j["accessors"][1]["count"] = json!(40));
        let e = load("uv.glb", &m);
        assert!(
            matches!(problem(&e), Some(GltfProblem::BadAccessor { .. })),
            "{e}"
        );
        assert!(e.to_string().contains("TEXCOORD_0"), "{e}");

        // A texture that does not decode: named, and the geometry alone still loads.
        let bad_png = b"\x89PNG\r\n\x1a\n not really a png".to_vec();
        let p = dir.path().join("badtex.glb");
        std::fs::write(&p, quad_glb(&bad_png, |_| {})).expect("write");
        let e = load_textured(&p, &LoadOptions::default()).expect_err("bad texture");
        assert!(matches!(e, MeshError::Texture { .. }), "{e}");
        let s = e.to_string();
        assert!(
            s.contains("badtex.glb") && s.contains("image 0") && s.contains("paper"),
            "{s}"
        );
        assert!(crate::load_mesh(&p, &LoadOptions::default()).is_ok());

        // Not glTF at all.
        let e = load("json.gltf", b"{\"asset\": 3}");
        assert!(matches!(problem(&e), Some(GltfProblem::Document(_))), "{e}");
    }

    #[test]
    fn write_glb_round_trips_with_a_seam_and_welds_back() {
        // Two triangles sharing an edge whose vertices have different texture coordinates in
        // each (an atlas seam), and an unused vertex.
        let mesh = TriMesh {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(0.1, 0.0, 0.0),
                Vec3::new(0.1, 0.1, 0.0),
                Vec3::new(0.0, 0.1, 0.0),
            ],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            normals: None,
        };
        let uv = vec![
            [
                Vec2::new(0.0, 0.0),
                Vec2::new(0.5, 0.0),
                Vec2::new(0.5, 0.5),
            ],
            [
                Vec2::new(0.5, 0.5),
                Vec2::new(1.0, 1.0),
                Vec2::new(0.5, 1.0),
            ],
        ];
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("seam.glb");
        write_glb(&p, &mesh, &uv, &png_2x2()).expect("write");
        let raw = read_gltf(&p, Detail::Appearance).expect("read");
        assert_eq!(
            raw.mesh.positions.len(),
            6,
            "two vertices split at the seam"
        );
        let t = load_textured(&p, &LoadOptions::default()).expect("load");
        assert_eq!(t.mesh, mesh, "welded back to the mesh's own vertices");
        let Appearance::Texture { uv: got, .. } = &t.appearance else {
            panic!("{:?}", t.appearance);
        };
        for (g, w) in got.iter().zip(&uv) {
            let g = g.expect("uv");
            for k in 0..3 {
                assert!((g[k] - w[k]).length() < 1e-7, "{g:?} vs {w:?}");
            }
        }
        assert!(write_glb(&p, &mesh, &uv[..1], &png_2x2()).is_err());
    }
}
