//! Textured head scans: the mesh with its colours, for finding printed targets on the scan.
//!
//! [`load_textured`] reads
//!
//! * **OBJ + MTL + texture**: `v`, `vt`, `f v/vt[/vn]`, `mtllib`, `usemtl` and the material's
//!   `map_Kd` image (PNG or JPEG, resolved against the MTL file's folder). Texture
//!   coordinates are kept per triangle corner (OBJ indexes them separately from the positions,
//!   so one vertex can have different coordinates in different triangles, at atlas seams);
//!   a face without `vt` shows its material's `Kd` colour.
//! * **PLY with vertex colours** (`red green blue`, any scalar type, see
//!   [`crate::ply::read_ply_coloured`]): colours interpolated barycentrically.
//! * **glTF 2.0**, binary (`.glb`, images in its binary chunk) or `.gltf` (external or
//!   data-URI buffers and images): every triangle primitive of the default scene with its node
//!   transforms, coloured by its material's base-colour texture (`TEXCOORD_0`), else its
//!   `COLOR_0` vertex colours (kept per triangle corner, so colours split at a seam stay
//!   apart), else its `baseColorFactor`; coordinates as stored, metres unless the caller's
//!   [`LengthUnit`] says otherwise (glTF is Y-up metres by specification). Details, and what is
//!   refused, in [`crate::gltf_scan`].
//!
//! The geometry goes through exactly the path of [`crate::load_mesh`] (same reader, unit
//! conversion and repair), so the mesh of a [`TexturedMesh`] equals the mesh `load_mesh` gives
//! for the same file; [`crate::validate::repair_tracked`] says where each repaired triangle
//! and vertex came from, so the colours follow dropped, welded and re-wound triangles.
//!
//! # Lookup
//!
//! [`TexturedMesh::colour_at`] takes a [`Hit`] (triangle and barycentrics `u`, `v` of its
//! second and third corner): the texture coordinate is `uv = (1-u-v) uv0 + u uv1 + v uv2` and
//! the texture is sampled bilinearly between the four nearest texel centres. OBJ puts `v = 0`
//! at the bottom of the image, texel `(i, j)` (column, row from the top) has its centre at
//! `((i + 0.5) / W, 1 - (j + 0.5) / H)`, and coordinates outside `[0, 1]` repeat (the OBJ
//! default). glTF puts `v = 0` at the top: its coordinates are flipped to the OBJ convention
//! on loading (`v = 1 - v_gltf`), so one lookup serves both.
//!
//! # Colour space
//!
//! Colours are display values, 0..1: what an OBJ's PNG or JPEG texture and a PLY's vertex
//! colours store (sRGB-encoded), scaled, with no gamma conversion. A glTF base-colour texture
//! is sRGB-encoded by specification and is kept as stored too; glTF's `COLOR_0` and
//! `baseColorFactor` are linear by specification and are encoded to sRGB on loading, so the
//! same print gives the same colour in every format. Finding targets needs only the print's
//! contrast, which either encoding keeps; what matters is that all formats agree.

use std::cell::RefCell;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use skinbrdf_core::untrusted::{self, confine, ConfineError};
use skinbrdf_core::TriMesh;

use crate::bvh::Hit;
use crate::load::{scale_to_metres, LengthUnit, LoadOptions};
use crate::validate::{repair_tracked, MeshReport, RepairMap};
use crate::MeshError;

/// Colour of a surface with no appearance (no texture, no vertex colours): a mid grey.
pub const UNTEXTURED_COLOUR: [f32; 3] = [0.5, 0.5, 0.5];

/// The most texels a texture may have (8192 x 4096). Held as 32-bit floats such a texture
/// takes 384 MiB; with the decoded image beside it while it is converted, loading one stays
/// well under a gigabyte, whatever a small compressed file states (docs/ingest.md, "Untrusted
/// files").
pub const MAX_TEXTURE_TEXELS: u64 = 1 << 25;

/// Refuses a texture of more than [`MAX_TEXTURE_TEXELS`], in words.
fn texels_within_limit(width: u32, height: u32) -> Result<(), String> {
    let texels = u64::from(width) * u64::from(height);
    if texels > MAX_TEXTURE_TEXELS {
        return Err(format!(
            "{width} x {height} texels, more than the {MAX_TEXTURE_TEXELS} a texture may have"
        ));
    }
    Ok(())
}

/// An RGB texture, row-major from the top row, values 0..1 as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureImage {
    /// Width, texels.
    pub width: u32,
    /// Height, texels.
    pub height: u32,
    /// Texels, row-major from the top.
    pub rgb: Vec<[f32; 3]>,
}

impl TextureImage {
    /// Loads a PNG or JPEG (any pixel type; alpha is dropped): a regular file within
    /// [`untrusted::TEXTURE_FILE`], decoded under the `image` crate's default memory limit.
    pub fn load(path: &Path) -> Result<Self, MeshError> {
        let bytes = untrusted::read_bounded(path, untrusted::TEXTURE_FILE)?;
        Self::decode(&bytes).map_err(|reason| MeshError::Texture {
            path: path.to_path_buf(),
            reason,
        })
    }

    /// Checks that a texture file is an image the loader decodes, by its header (format and
    /// size; the pixels are not decoded). Returns its width and height.
    pub fn check_header(path: &Path) -> Result<(u32, u32), MeshError> {
        let (file, _) = untrusted::open_regular(path)?;
        let bad = |reason: String| MeshError::Texture {
            path: path.to_path_buf(),
            reason,
        };
        let (w, h) = image::ImageReader::new(BufReader::new(file))
            .with_guessed_format()
            .map_err(|e| bad(e.to_string()))?
            .into_dimensions()
            .map_err(|e| bad(format!("not a PNG or JPEG image: {e}")))?;
        if w == 0 || h == 0 {
            return Err(bad("the image is empty".into()));
        }
        texels_within_limit(w, h).map_err(bad)?;
        Ok((w, h))
    }

    /// Decodes an encoded PNG or JPEG held in memory (a glTF's embedded image) exactly as
    /// [`Self::load`] decodes a file; the error is the decoder's complaint.
    pub fn decode(bytes: &[u8]) -> Result<Self, String> {
        // The size from the header first: a small file may state a huge image.
        let (w, h) = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())?
            .into_dimensions()
            .map_err(|e| e.to_string())?;
        texels_within_limit(w, h)?;
        let img = image::load_from_memory(bytes).map_err(|e| e.to_string())?;
        Self::from_image(&img)
    }

    fn from_image(img: &image::DynamicImage) -> Result<Self, String> {
        let (width, height) = (img.width(), img.height());
        if width == 0 || height == 0 {
            return Err("the image is empty".into());
        }
        texels_within_limit(width, height)?;
        // Converted in bands of rows, so the texels as floats are held once, not twice.
        const BAND_ROWS: u32 = 64;
        let mut rgb = Vec::with_capacity(width as usize * height as usize);
        let mut y = 0;
        while y < height {
            let rows = BAND_ROWS.min(height - y);
            let band = img.crop_imm(0, y, width, rows).to_rgb32f();
            rgb.extend(band.pixels().map(|p| p.0));
            y += rows;
        }
        Ok(Self { width, height, rgb })
    }

    /// Bilinear lookup at an OBJ texture coordinate (`v = 0` at the bottom, repeating outside
    /// `[0, 1]`; see the module docs). A non-finite coordinate gives texel `(0, 0)`.
    pub fn bilinear(&self, uv: Vec2) -> [f32; 3] {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = f64::from(uv.x) * w as f64 - 0.5;
        let y = (1.0 - f64::from(uv.y)) * h as f64 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return self.rgb[0];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let at = |i: i64, j: i64| self.rgb[(j.rem_euclid(h) * w + i.rem_euclid(w)) as usize];
        let (a, b, c, d) = (
            at(x0, y0),
            at(x0 + 1, y0),
            at(x0, y0 + 1),
            at(x0 + 1, y0 + 1),
        );
        std::array::from_fn(|k| {
            (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy
        })
    }
}

/// One material: its flat colour and optional texture (an OBJ's MTL entry, a glTF material).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Name (`newmtl`; glTF: `name`, else `material N`).
    pub name: String,
    /// `Kd`, or [`UNTEXTURED_COLOUR`] when absent (glTF: `baseColorFactor`, sRGB-encoded).
    pub diffuse: [f32; 3],
    /// The `map_Kd` image (glTF: the base-colour texture, `baseColorFactor` multiplied in).
    pub texture: Option<TextureImage>,
    /// Where the texture was read from (`None` for an image embedded in a glTF).
    pub texture_path: Option<PathBuf>,
}

/// How a scan's surface is coloured.
#[derive(Debug, Clone, PartialEq)]
pub enum Appearance {
    /// Texture-mapped (OBJ, glTF): per triangle its material and, when it has `vt` (glTF:
    /// texture coordinates for its material's texture), the texture coordinates of its three
    /// corners (in the order of the mesh's triangle, OBJ convention).
    Texture {
        /// Texture coordinates per triangle corner (`None`: the face has no `vt`).
        uv: Vec<Option<[Vec2; 3]>>,
        /// Material index per triangle (`None`: no `usemtl`; glTF: no material).
        material: Vec<Option<u32>>,
        /// The materials.
        materials: Vec<Material>,
        /// Colours per triangle corner, which win over the material (glTF `COLOR_0` on a
        /// primitive without a base-colour texture); empty for OBJ.
        corner_colours: Vec<Option<[[f32; 3]; 3]>>,
    },
    /// A colour per vertex (PLY `red green blue`).
    VertexColours(Vec<[f32; 3]>),
    /// No colour information.
    None,
}

/// A loaded scan in metres with its appearance.
#[derive(Debug, Clone)]
pub struct TexturedMesh {
    /// The mesh, metres (as [`crate::load_mesh`] loads it).
    pub mesh: TriMesh,
    /// Its colours.
    pub appearance: Appearance,
    /// The unit the file was read in.
    pub unit: LengthUnit,
    /// Validation and repair.
    pub report: MeshReport,
}

impl TexturedMesh {
    /// The surface colour at a ray hit (see the module docs). A hit on a triangle the mesh
    /// does not have gives [`UNTEXTURED_COLOUR`].
    pub fn colour_at(&self, hit: &Hit) -> [f32; 3] {
        let t = hit.triangle as usize;
        let w = [1.0 - hit.u - hit.v, hit.u, hit.v];
        match &self.appearance {
            Appearance::Texture {
                uv,
                material,
                materials,
                corner_colours,
            } => {
                if let Some(c) = corner_colours.get(t).copied().flatten() {
                    return std::array::from_fn(|k| {
                        w[0] * c[0][k] + w[1] * c[1][k] + w[2] * c[2][k]
                    });
                }
                let mat = material
                    .get(t)
                    .copied()
                    .flatten()
                    .and_then(|m| materials.get(m as usize));
                let Some(mat) = mat else {
                    return UNTEXTURED_COLOUR;
                };
                match (&mat.texture, uv.get(t).copied().flatten()) {
                    (Some(tex), Some(c)) => tex.bilinear(c[0] * w[0] + c[1] * w[1] + c[2] * w[2]),
                    _ => mat.diffuse,
                }
            }
            Appearance::VertexColours(colours) => {
                let Some(tri) = self.mesh.indices.get(t) else {
                    return UNTEXTURED_COLOUR;
                };
                let mut out = [0.0f32; 3];
                for (k, &v) in tri.iter().enumerate() {
                    let c = colours
                        .get(v as usize)
                        .copied()
                        .unwrap_or(UNTEXTURED_COLOUR);
                    for (o, ci) in out.iter_mut().zip(c) {
                        *o += w[k] * ci;
                    }
                }
                out
            }
            Appearance::None => UNTEXTURED_COLOUR,
        }
    }

    /// The luma (Rec. 709 weights) of [`Self::colour_at`].
    pub fn grey_at(&self, hit: &Hit) -> f32 {
        let [r, g, b] = self.colour_at(hit);
        0.2126 * r + 0.7152 * g + 0.0722 * b
    }
}

/// An OBJ file's geometry with its per-corner texture coordinates and per-triangle materials,
/// before units and repair.
#[derive(Debug, Clone)]
pub(crate) struct ObjData {
    pub(crate) mesh: TriMesh,
    pub(crate) uv: Vec<Option<[Vec2; 3]>>,
    pub(crate) material: Vec<Option<u32>>,
    /// The materials, or the MTL files that could not be read.
    pub(crate) materials: Result<Vec<tobj::Material>, Vec<PathBuf>>,
}

/// Reads an OBJ file: every object merged in file order, polygons triangulated.
pub(crate) fn read_obj_data(path: &Path) -> Result<ObjData, MeshError> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (file, _) = crate::open_scan(path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let failed: RefCell<Vec<PathBuf>> = RefCell::new(Vec::new());
    let refused: RefCell<Option<MeshError>> = RefCell::new(None);
    let parse = || {
        tobj::load_obj_buf(&mut BufReader::new(file), &opts, |mtl: &Path| {
            let written = mtl.to_string_lossy();
            match material_library(path, &dir, &written, "mtllib") {
                Ok((mtl_path, bytes)) => {
                    if let Some(e) = mtl_colour_problem(&mtl_path, &bytes) {
                        refused.borrow_mut().get_or_insert(e);
                        return Err(tobj::LoadError::OpenFileFailed);
                    }
                    tobj::load_mtl_buf(&mut bytes.as_slice())
                }
                Err(MeshError::Refused { path, key, reason }) => match *reason {
                    ConfineError::Missing { path: full, .. } => {
                        failed.borrow_mut().push(full);
                        Err(tobj::LoadError::OpenFileFailed)
                    }
                    other => {
                        refused.borrow_mut().get_or_insert(MeshError::Refused {
                            path,
                            key,
                            reason: Box::new(other),
                        });
                        Err(tobj::LoadError::OpenFileFailed)
                    }
                },
                Err(e) => {
                    refused.borrow_mut().get_or_insert(e);
                    Err(tobj::LoadError::OpenFileFailed)
                }
            }
        })
    };
    // tobj panics on some malformed lines; a panic is this file's parse error, not the end of
    // the program.
    let loaded =
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(parse)).map_err(|panic| {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a line it cannot read".into());
            MeshError::Parse {
                path: path.to_path_buf(),
                reason: format!("OBJ: the parser gave up ({what})"),
            }
        })?;
    if let Some(e) = refused.into_inner() {
        return Err(e);
    }
    let (models, materials) = loaded.map_err(|e| MeshError::Parse {
        path: path.to_path_buf(),
        reason: format!("OBJ: {e}"),
    })?;
    let failed = failed.into_inner();
    let materials = match materials {
        Ok(m) if failed.is_empty() => Ok(m),
        _ => Err(failed),
    };
    let mut out = ObjData {
        mesh: TriMesh::default(),
        uv: Vec::new(),
        material: Vec::new(),
        materials,
    };
    for m in models {
        let base = out.mesh.positions.len() as u32;
        let mm = &m.mesh;
        out.mesh.positions.extend(
            mm.positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2])),
        );
        out.mesh.indices.extend(
            mm.indices
                .chunks_exact(3)
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
        let n_tris = mm.indices.len() / 3;
        let material = mm.material_id.map(|i| i as u32);
        out.material.extend(std::iter::repeat_n(material, n_tris));
        if mm.texcoord_indices.is_empty() {
            out.uv.extend(std::iter::repeat_n(None, n_tris));
            continue;
        }
        if mm.texcoord_indices.len() != mm.indices.len() {
            return Err(MeshError::BadUv {
                path: path.to_path_buf(),
                reason: format!(
                    "object `{}`: {} texture-coordinate indices for {} face corners (some faces \
                     have `vt` indices, some not)",
                    m.name,
                    mm.texcoord_indices.len(),
                    mm.indices.len()
                ),
            });
        }
        let n_vt = mm.texcoords.len() / 2;
        for (f, t) in mm.texcoord_indices.chunks_exact(3).enumerate() {
            let mut c = [Vec2::ZERO; 3];
            for (k, &i) in t.iter().enumerate() {
                if i as usize >= n_vt {
                    return Err(MeshError::BadUv {
                        path: path.to_path_buf(),
                        reason: format!(
                            "object `{}`, triangle {f}: texture-coordinate index {} but the \
                             file has {n_vt} `vt` lines",
                            m.name,
                            i + 1
                        ),
                    });
                }
                let (u, v) = (
                    mm.texcoords[2 * i as usize],
                    mm.texcoords[2 * i as usize + 1],
                );
                if !(u.is_finite() && v.is_finite()) {
                    return Err(MeshError::BadUv {
                        path: path.to_path_buf(),
                        reason: format!("`vt` {} is not finite", i + 1),
                    });
                }
                c[k] = Vec2::new(u, v);
            }
            out.uv.push(Some(c));
        }
    }
    if out.mesh.indices.is_empty() {
        return Err(MeshError::Parse {
            path: path.to_path_buf(),
            reason: "OBJ has no faces".into(),
        });
    }
    Ok(out)
}

/// An OBJ's material library named `written` on a line of the OBJ (`key` says where): a
/// regular file inside the OBJ's folder ([`confine`]), read within
/// [`untrusted::MATERIAL_LIBRARY`]. Returns the file and its bytes.
/// The MTL colour keys whose values tobj reads as exactly three numbers.
const MTL_COLOUR_KEYS: [&str; 4] = ["Ka", "Kd", "Ks", "Ke"];

/// A colour line of a material library with fewer than three values (tobj panics on it),
/// as an error naming the file and the line.
fn mtl_colour_problem(mtl: &Path, bytes: &[u8]) -> Option<MeshError> {
    let text = String::from_utf8_lossy(bytes);
    text.lines().enumerate().find_map(|(i, line)| {
        let mut words = line.split_whitespace();
        let key = words.next()?;
        let values = words.count();
        (MTL_COLOUR_KEYS.contains(&key) && values < 3).then(|| MeshError::Parse {
            path: mtl.to_path_buf(),
            reason: format!(
                "line {}: `{key}` has {values} value(s); a colour needs three numbers",
                i + 1
            ),
        })
    })
}

fn material_library(
    obj: &Path,
    dir: &Path,
    written: &str,
    key: &str,
) -> Result<(PathBuf, Vec<u8>), MeshError> {
    let file = confine(dir, written).map_err(|reason| MeshError::Refused {
        path: obj.to_path_buf(),
        key: key.to_string(),
        reason: Box::new(reason),
    })?;
    let bytes = untrusted::read_bounded(&file, untrusted::MATERIAL_LIBRARY)?;
    Ok((file, bytes))
}

/// The texture file a material names: the `map_Kd` string as a path inside `dir`
/// ([`confine`]: not absolute, no `..`, no link out, a regular file; Windows separators read
/// as `/`); when that fails and the string has options before the name (`-bm 1.0 skin
/// tone.png`), the first tail of it after a space that names such a file (names may hold
/// spaces), else its last word.
fn texture_file(dir: &Path, map_kd: &str) -> Result<PathBuf, ConfineError> {
    let map_kd = map_kd.trim();
    let whole = confine(dir, map_kd);
    if whole.is_ok() || !map_kd.starts_with('-') {
        return whole;
    }
    let tails = map_kd
        .char_indices()
        .filter(|&(_, c)| c == ' ' || c == '\t')
        .map(|(i, _)| map_kd[i + 1..].trim_start())
        .filter(|t| !t.is_empty() && !t.starts_with('-'));
    let mut last = None;
    for t in tails {
        match confine(dir, t) {
            Ok(p) => return Ok(p),
            Err(e) => last = Some(e),
        }
    }
    match map_kd.split_whitespace().last() {
        Some(w) => confine(dir, w),
        None => Err(last.unwrap_or(ConfineError::Empty {
            written: map_kd.to_string(),
        })),
    }
}

/// The files that come with an OBJ scan, for copying it with them: every `mtllib` anywhere
/// in the OBJ and every `map_Kd` texture of those libraries, each a regular file inside the
/// OBJ's folder (refused by file, line and path otherwise), each texture's header decoded (a
/// file that is not a PNG or JPEG image is refused here, not when the scan's colours are
/// needed). Each entry is the path relative to the OBJ's folder (`/`-separated) and the file.
pub fn obj_companion_files(path: &Path) -> Result<Vec<(String, PathBuf)>, MeshError> {
    use std::io::BufRead;
    let (file, _) = crate::open_scan(path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let relative = |p: &Path| {
        p.strip_prefix(&dir)
            .unwrap_or(p)
            .to_string_lossy()
            .replace('\\', "/")
    };
    let mut out: Vec<(String, PathBuf)> = Vec::new();
    for (n, line) in BufReader::new(file).split(b'\n').enumerate() {
        let line = line.map_err(|source| MeshError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let line = String::from_utf8_lossy(&line);
        let mut words = line.split_whitespace();
        if words.next() != Some("mtllib") {
            continue;
        }
        let written = line.trim().split_once(' ').unwrap_or_default().1.trim();
        let key = format!("line {} mtllib", n + 1);
        let (mtl, bytes) = material_library(path, &dir, written, &key)?;
        if !out.iter().any(|(_, q)| q == &mtl) {
            out.push((relative(&mtl), mtl.clone()));
        }
        for (m, l) in String::from_utf8_lossy(&bytes).lines().enumerate() {
            let l = l.trim();
            if l.split_whitespace().next() != Some("map_Kd") {
                continue;
            }
            let refused = |reason| MeshError::Refused {
                path: mtl.clone(),
                key: format!("line {} map_Kd", m + 1),
                reason: Box::new(reason),
            };
            let tex = texture_file(&dir, l.get(6..).unwrap_or_default()).map_err(refused)?;
            TextureImage::check_header(&tex)?;
            if !out.iter().any(|(_, q)| q == &tex) {
                out.push((relative(&tex), tex));
            }
        }
    }
    Ok(out)
}

/// Loads a scan with its colours: `.obj` (with its MTL and textures), `.ply` (with vertex
/// colours when it has them), `.glb` or `.gltf` (with its base-colour textures or vertex
/// colours), in metres, repaired per `opts` exactly as [`crate::load_mesh`].
pub fn load_textured(path: &Path, opts: &LoadOptions) -> Result<TexturedMesh, MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let source = path.display().to_string();
    match ext.as_deref() {
        Some("ply") => {
            let (mut mesh, _, colours) = crate::ply::read_ply_coloured(path)?;
            let unit = scale_to_metres(&mut mesh, opts.unit);
            let (mesh, report, map) = repair_tracked(&mesh, opts.policy, &source)?;
            let appearance = match colours {
                Some(c) => Appearance::VertexColours(
                    map.vertices
                        .iter()
                        .map(|&v| c.get(v as usize).copied().unwrap_or(UNTEXTURED_COLOUR))
                        .collect(),
                ),
                None => Appearance::None,
            };
            Ok(TexturedMesh {
                mesh,
                appearance,
                unit,
                report,
            })
        }
        Some("obj") => {
            let mut data = read_obj_data(path)?;
            let materials = match std::mem::replace(&mut data.materials, Ok(Vec::new())) {
                Ok(m) => m,
                Err(files) => {
                    return Err(MeshError::MissingMaterialLibrary {
                        path: path.to_path_buf(),
                        libraries: files,
                    })
                }
            };
            let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
            let mut mats = Vec::with_capacity(materials.len());
            for m in materials {
                let (texture, texture_path) = match &m.diffuse_texture {
                    Some(t) if !t.trim().is_empty() => {
                        let file = match texture_file(&dir, t) {
                            Ok(f) => f,
                            Err(ConfineError::Missing { path: texture, .. }) => {
                                return Err(MeshError::MissingTexture {
                                    path: path.to_path_buf(),
                                    material: m.name.clone(),
                                    texture,
                                })
                            }
                            Err(reason) => {
                                return Err(MeshError::Refused {
                                    path: path.to_path_buf(),
                                    key: format!("material `{}` map_Kd", m.name),
                                    reason: Box::new(reason),
                                })
                            }
                        };
                        (Some(TextureImage::load(&file)?), Some(file))
                    }
                    _ => (None, None),
                };
                mats.push(Material {
                    name: m.name.clone(),
                    diffuse: m.diffuse.unwrap_or(UNTEXTURED_COLOUR),
                    texture,
                    texture_path,
                });
            }
            if let Some(t) = data
                .material
                .iter()
                .position(|m| m.is_some_and(|m| m as usize >= mats.len()))
            {
                return Err(MeshError::Parse {
                    path: path.to_path_buf(),
                    reason: format!("triangle {t} uses a material the MTL files do not define"),
                });
            }
            let unit = scale_to_metres(&mut data.mesh, opts.unit);
            let (mesh, report, map) = repair_tracked(&data.mesh, opts.policy, &source)?;
            let (uv, material) = follow_repair(&map, &data.uv, &data.material);
            let appearance = if mats.is_empty() && uv.iter().all(Option::is_none) {
                Appearance::None
            } else {
                Appearance::Texture {
                    uv,
                    material,
                    materials: mats,
                    corner_colours: Vec::new(),
                }
            };
            Ok(TexturedMesh {
                mesh,
                appearance,
                unit,
                report,
            })
        }
        Some("glb" | "gltf") => {
            let mut data = crate::gltf_scan::read_gltf(path, crate::gltf_scan::Detail::Appearance)?;
            let unit = scale_to_metres(&mut data.mesh, crate::load::gltf_unit(opts.unit));
            let (mesh, report, map) = repair_tracked(&data.mesh, opts.policy, &source)?;
            let (uv, material) = follow_repair(&map, &data.uv, &data.material);
            let corner_colours: Vec<Option<[[f32; 3]; 3]>> = map
                .triangles
                .iter()
                .map(|&(t, flipped)| {
                    data.corner_colours
                        .get(t as usize)
                        .copied()
                        .flatten()
                        .map(|c| std::array::from_fn(|k| c[RepairMap::input_corner(flipped, k)]))
                })
                .collect();
            let appearance =
                if data.materials.is_empty() && corner_colours.iter().all(Option::is_none) {
                    Appearance::None
                } else {
                    Appearance::Texture {
                        uv,
                        material,
                        materials: data.materials,
                        corner_colours,
                    }
                };
            Ok(TexturedMesh {
                mesh,
                appearance,
                unit,
                report,
            })
        }
        _ => Err(crate::load::unknown_format(path)),
    }
}

/// Per-triangle attributes of the input carried to the repaired mesh.
#[allow(clippy::type_complexity)]
fn follow_repair(
    map: &RepairMap,
    uv: &[Option<[Vec2; 3]>],
    material: &[Option<u32>],
) -> (Vec<Option<[Vec2; 3]>>, Vec<Option<u32>>) {
    map.triangles
        .iter()
        .map(|&(t, flipped)| {
            let t = t as usize;
            let c = uv
                .get(t)
                .copied()
                .flatten()
                .map(|c| std::array::from_fn(|k| c[RepairMap::input_corner(flipped, k)]));
            (c, material.get(t).copied().flatten())
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad_obj(dir: &Path, with_texture: bool) -> PathBuf {
        let obj = dir.join("quad.obj");
        std::fs::write(
            &obj,
            "mtllib quad.mtl\nv 0 0 0\nv 0.1 0 0\nv 0.1 0.1 0\nv 0 0.1 0\n\
             vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl paper\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
        )
        .expect("write obj");
        let map = if with_texture {
            "map_Kd quad.png\n"
        } else {
            ""
        };
        std::fs::write(
            dir.join("quad.mtl"),
            format!("newmtl paper\nKd 0.2 0.4 0.6\n{map}"),
        )
        .expect("write mtl");
        obj
    }

    #[test]
    fn obj_texture_is_sampled_bilinearly_with_v_up() {
        let dir = tempfile::tempdir().expect("tempdir");
        let obj = quad_obj(dir.path(), true);
        // 2 x 2 texels: top row black, white; bottom row red, blue.
        let mut img = image::RgbImage::new(2, 2);
        img.put_pixel(0, 0, image::Rgb([0, 0, 0]));
        img.put_pixel(1, 0, image::Rgb([255, 255, 255]));
        img.put_pixel(0, 1, image::Rgb([255, 0, 0]));
        img.put_pixel(1, 1, image::Rgb([0, 0, 255]));
        img.save(dir.path().join("quad.png")).expect("png");
        let t = load_textured(&obj, &LoadOptions::default()).expect("load");
        let plain = crate::load_mesh(&obj, &LoadOptions::default()).expect("load_mesh");
        assert_eq!(t.mesh, plain.mesh);
        let bvh = crate::MeshBvh::build(&t.mesh, crate::BuildQuality::Fast).expect("bvh");
        let at = |x: f32, y: f32| {
            let hit = bvh
                .intersect(Vec3::new(x, y, 1.0), -Vec3::Z, 10.0)
                .expect("hit");
            t.colour_at(&hit)
        };
        // Texel centres: (0.25, 0.75) is the top-left texel (black), (0.25, 0.25) the
        // bottom-left (red).
        let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4);
        assert!(
            close(at(0.025, 0.075), [0.0, 0.0, 0.0]),
            "{:?}",
            at(0.025, 0.075)
        );
        assert!(close(at(0.025, 0.025), [1.0, 0.0, 0.0]));
        assert!(close(at(0.075, 0.025), [0.0, 0.0, 1.0]));
        // Half-way between red and blue.
        assert!(
            close(at(0.05, 0.025), [0.5, 0.0, 0.5]),
            "{:?}",
            at(0.05, 0.025)
        );
    }

    #[test]
    fn a_jpeg_texture_loads() {
        let dir = tempfile::tempdir().expect("tempdir");
        let obj = quad_obj(dir.path(), false);
        std::fs::write(
            dir.path().join("quad.mtl"),
            "newmtl paper\nmap_Kd -bm 1.0 skin tone.jpg\n",
        )
        .expect("mtl");
        let img = image::RgbImage::from_pixel(16, 16, image::Rgb([200, 150, 100]));
        img.save(dir.path().join("skin tone.jpg")).expect("jpeg");
        let t = load_textured(&obj, &LoadOptions::default()).expect("load");
        let hit = Hit {
            t_m: 1.0,
            triangle: 1,
            u: 0.3,
            v: 0.3,
        };
        let c = t.colour_at(&hit);
        for (got, want) in c.iter().zip([200.0f32, 150.0, 100.0]) {
            assert!((got * 255.0 - want).abs() < 4.0, "{c:?}");
        }
    }

    #[test]
    fn a_material_without_texture_shows_its_kd() {
        let dir = tempfile::tempdir().expect("tempdir");
        let obj = quad_obj(dir.path(), false);
        let t = load_textured(&obj, &LoadOptions::default()).expect("load");
        let hit = Hit {
            t_m: 1.0,
            triangle: 0,
            u: 0.2,
            v: 0.2,
        };
        assert_eq!(t.colour_at(&hit), [0.2, 0.4, 0.6]);
    }

    #[test]
    fn missing_texture_and_library_and_bad_uv_name_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let obj = quad_obj(dir.path(), true);
        let e = load_textured(&obj, &LoadOptions::default()).expect_err("no png");
        assert!(matches!(e, MeshError::MissingTexture { .. }), "{e}");
        let s = e.to_string();
        assert!(
            s.contains("quad.obj") && s.contains("quad.png") && s.contains("paper"),
            "{s}"
        );
        // The geometry alone still loads.
        assert!(crate::load_mesh(&obj, &LoadOptions::default()).is_ok());

        std::fs::remove_file(dir.path().join("quad.mtl")).expect("rm");
        let e = load_textured(&obj, &LoadOptions::default()).expect_err("no mtl");
        assert!(e.to_string().contains("quad.mtl"), "{e}");
        assert!(crate::load_mesh(&obj, &LoadOptions::default()).is_ok());

        let bad = dir.path().join("bad.obj");
        std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/7\n").expect("w");
        let e = load_textured(&bad, &LoadOptions::default()).expect_err("bad vt");
        let s = e.to_string();
        assert!(
            matches!(e, MeshError::BadUv { .. }) || s.contains("bad.obj"),
            "{s}"
        );
        assert!(s.contains("bad.obj"), "{s}");
    }

    #[test]
    fn ply_vertex_colours_are_interpolated() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("c.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n\
             0 0 0 255 0 0\n0.1 0 0 0 255 0\n0 0.1 0 0 0 255\n3 0 1 2\n",
        )
        .expect("write");
        let t = load_textured(&p, &LoadOptions::default()).expect("load");
        assert!(matches!(t.appearance, Appearance::VertexColours(_)));
        let hit = Hit {
            t_m: 1.0,
            triangle: 0,
            u: 0.25,
            v: 0.5,
        };
        let c = t.colour_at(&hit);
        assert!((c[0] - 0.25).abs() < 1e-6 && (c[1] - 0.25).abs() < 1e-6);
        assert!((c[2] - 0.5).abs() < 1e-6, "{c:?}");
        assert!((t.grey_at(&hit) - (0.2126 * 0.25 + 0.7152 * 0.25 + 0.0722 * 0.5)).abs() < 1e-6);
    }
}
