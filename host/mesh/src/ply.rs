//! PLY (Stanford polygon format) reading and writing: ASCII, binary little- and big-endian.
//!
//! A streaming parser written for this job rather than a generic PLY crate: generic readers
//! build a map of named properties per element, which costs seconds on a million-vertex scan,
//! and their errors do not say which element broke. This one decodes the header into a fixed
//! layout, reads `vertex` positions (and `nx ny nz` when present) and `face` index lists
//! (`vertex_indices` or `vertex_index`, any integer types), skips every other element and
//! property, fan-triangulates polygons, and names the element index and problem on error.
//!
//! The writer emits binary little-endian (`float x y z`, optional `float nx ny nz`,
//! `uchar`-counted `int` triangles) atomically: a temporary file in the target directory,
//! renamed over the destination only once complete.

use std::io::{BufRead, BufReader};
use std::path::Path;

use glam::Vec3;
use skinbrdf_core::TriMesh;

use crate::error::MeshError;

/// Storage format of a PLY file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyFormat {
    /// Whitespace-separated text.
    Ascii,
    /// Binary, little-endian.
    BinaryLittleEndian,
    /// Binary, big-endian.
    BinaryBigEndian,
}

/// Scalar types of PLY properties.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    const fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }
}

#[derive(Debug, Clone)]
enum Property {
    Scalar {
        name: String,
        ty: Scalar,
    },
    List {
        name: String,
        count: Scalar,
        item: Scalar,
    },
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// What a PLY file held besides the mesh itself.
#[derive(Debug, Clone, PartialEq)]
pub struct PlyInfo {
    /// The file's storage format.
    pub format: PlyFormat,
    /// Polygons with more than three corners, fan-triangulated.
    pub polygons_triangulated: usize,
    /// Faces with fewer than three corners, dropped.
    pub faces_dropped: usize,
    /// `comment` lines of the header.
    pub comments: Vec<String>,
}

struct Reader<'a, R> {
    r: R,
    path: &'a Path,
    format: PlyFormat,
    /// Pending tokens of the current ASCII line.
    tokens: std::vec::IntoIter<String>,
    line: String,
    /// ASCII: the next token starts an element, so it must start a new line (one element per
    /// line: a face with an index short must not borrow the next face's values).
    element_start: bool,
}

impl<R: BufRead> Reader<'_, R> {
    fn err(&self, reason: impl Into<String>) -> MeshError {
        MeshError::Parse {
            path: self.path.to_path_buf(),
            reason: reason.into(),
        }
    }

    /// Marks the start of an element (ASCII: it must begin on a new line).
    fn begin_element(&mut self) {
        self.element_start = true;
    }

    fn next_token(&mut self, what: &dyn Fn() -> String) -> Result<String, MeshError> {
        if std::mem::take(&mut self.element_start) {
            if let Some(extra) = self.tokens.next() {
                return Err(self.err(format!(
                    "{}: the line before holds more values than its element (`{extra}` left over)",
                    what()
                )));
            }
        } else if self.tokens.len() == 0 && !self.line.is_empty() {
            return Err(self.err(format!(
                "{}: the line ends before the element's values do (a value short?)",
                what()
            )));
        }
        loop {
            if let Some(t) = self.tokens.next() {
                return Ok(t);
            }
            self.line.clear();
            let n = self
                .r
                .read_line(&mut self.line)
                .map_err(|e| self.err(format!("{}: {e}", what())))?;
            if n == 0 {
                return Err(self.err(format!("{}: unexpected end of file", what())));
            }
            self.tokens = self
                .line
                .split_whitespace()
                .map(str::to_owned)
                .collect::<Vec<_>>()
                .into_iter();
        }
    }

    /// Reads one scalar as f64 (exact for every PLY integer type).
    fn read(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<f64, MeshError> {
        if self.format == PlyFormat::Ascii {
            let t = self.next_token(what)?;
            return t
                .parse::<f64>()
                .map_err(|_| self.err(format!("{}: `{t}` is not a number", what())));
        }
        let mut b = [0u8; 8];
        let n = ty.size();
        self.r.read_exact(&mut b[..n]).map_err(|e| {
            self.err(format!(
                "{}: {}",
                what(),
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    "unexpected end of file".to_string()
                } else {
                    e.to_string()
                }
            ))
        })?;
        let le = self.format == PlyFormat::BinaryLittleEndian;
        macro_rules! conv {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                (if le {
                    <$t>::from_le_bytes(a)
                } else {
                    <$t>::from_be_bytes(a)
                }) as f64
            }};
        }
        Ok(match ty {
            Scalar::I8 => conv!(i8, 1),
            Scalar::U8 => conv!(u8, 1),
            Scalar::I16 => conv!(i16, 2),
            Scalar::U16 => conv!(u16, 2),
            Scalar::I32 => conv!(i32, 4),
            Scalar::U32 => conv!(u32, 4),
            Scalar::F32 => conv!(f32, 4),
            Scalar::F64 => conv!(f64, 8),
        })
    }
}

fn parse_header<R: BufRead>(
    r: &mut R,
    path: &Path,
) -> Result<(PlyFormat, Vec<Element>, Vec<String>), MeshError> {
    let err = |reason: String| MeshError::Parse {
        path: path.to_path_buf(),
        reason,
    };
    let mut line = String::new();
    let mut read_line = |line: &mut String, n: usize| -> Result<(), MeshError> {
        line.clear();
        let k = r
            .read_line(line)
            .map_err(|e| err(format!("header line {n}: {e}")))?;
        if k == 0 {
            return Err(err(format!("header ends at line {n} without `end_header`")));
        }
        Ok(())
    };
    read_line(&mut line, 1)?;
    if line.trim_end() != "ply" {
        return Err(err("not a PLY file: first line is not `ply`".into()));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut comments = Vec::new();
    for n in 2.. {
        read_line(&mut line, n)?;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] => {}
            ["end_header"] => break,
            ["comment", ..] => comments.push(line.trim()["comment".len()..].trim().to_string()),
            ["obj_info", ..] => {}
            ["format", f, version] => {
                if *version != "1.0" {
                    return Err(err(format!(
                        "header line {n}: PLY version {version} (only 1.0)"
                    )));
                }
                format = Some(match *f {
                    "ascii" => PlyFormat::Ascii,
                    "binary_little_endian" => PlyFormat::BinaryLittleEndian,
                    "binary_big_endian" => PlyFormat::BinaryBigEndian,
                    other => return Err(err(format!("header line {n}: unknown format `{other}`"))),
                });
            }
            ["element", name, count] => {
                let count = count.parse::<usize>().map_err(|_| {
                    err(format!(
                        "header line {n}: element count `{count}` is not a count"
                    ))
                })?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            ["property", "list", count, item, name] => {
                let (Some(count_ty), Some(item_ty)) = (Scalar::parse(count), Scalar::parse(item))
                else {
                    return Err(err(format!(
                        "header line {n}: unknown list types `{count} {item}`"
                    )));
                };
                if matches!(count_ty, Scalar::F32 | Scalar::F64) {
                    return Err(err(format!(
                        "header line {n}: list count type must be an integer"
                    )));
                }
                let el = elements
                    .last_mut()
                    .ok_or_else(|| err(format!("header line {n}: property before any element")))?;
                el.properties.push(Property::List {
                    name: name.to_string(),
                    count: count_ty,
                    item: item_ty,
                });
            }
            ["property", ty, name] => {
                let ty = Scalar::parse(ty)
                    .ok_or_else(|| err(format!("header line {n}: unknown property type `{ty}`")))?;
                let el = elements
                    .last_mut()
                    .ok_or_else(|| err(format!("header line {n}: property before any element")))?;
                el.properties.push(Property::Scalar {
                    name: name.to_string(),
                    ty,
                });
            }
            _ => {
                return Err(err(format!(
                    "header line {n}: cannot parse `{}`",
                    line.trim()
                )))
            }
        }
    }
    let format = format.ok_or_else(|| err("header has no `format` line".into()))?;
    Ok((format, elements, comments))
}

/// Reads a PLY file into a mesh (coordinates as stored: apply units afterwards).
/// Vertex normals are kept when the file has `nx ny nz`. Does not validate beyond what parsing
/// needs (indices are checked against the vertex count; see [`crate::validate`]).
pub fn read_ply(path: &Path) -> Result<(TriMesh, PlyInfo), MeshError> {
    read_ply_coloured(path).map(|(m, i, _)| (m, i))
}

/// Reads PLY from any buffered reader; `path` names the source in errors.
pub fn read_ply_from<R: BufRead>(r: R, path: &Path) -> Result<(TriMesh, PlyInfo), MeshError> {
    read_ply_coloured_from(r, path).map(|(m, i, _)| (m, i))
}

/// Per-vertex colours of a PLY file, `[r, g, b]` scaled to 0..1 as stored (integer types by
/// their maximum: `uchar` by 255, `ushort` by 65535; floating-point values as they are). No
/// gamma conversion: scanners store display (sRGB-encoded) values.
pub type VertexColours = Vec<[f32; 3]>;

/// [`read_ply`], also returning the vertex colours when the `vertex` element has `red`,
/// `green` and `blue` (or `r`, `g`, `b`) properties.
pub fn read_ply_coloured(
    path: &Path,
) -> Result<(TriMesh, PlyInfo, Option<VertexColours>), MeshError> {
    let (file, len) = crate::open::open_scan(path)?;
    read_ply_sized(BufReader::with_capacity(1 << 20, file), path, Some(len))
}

/// [`read_ply_coloured`] from any buffered reader; `path` names the source in errors.
pub fn read_ply_coloured_from<R: BufRead>(
    r: R,
    path: &Path,
) -> Result<(TriMesh, PlyInfo, Option<VertexColours>), MeshError> {
    read_ply_sized(r, path, None)
}

/// The fewest bytes one element can take: its scalars' sizes and its lists' counts in binary;
/// in ASCII, a character and a separator per value.
fn min_element_bytes(el: &Element, format: PlyFormat) -> u64 {
    match format {
        PlyFormat::Ascii => 2 * el.properties.len() as u64,
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => el
            .properties
            .iter()
            .map(|p| match p {
                Property::Scalar { ty, .. } => ty.size() as u64,
                Property::List { count, .. } => count.size() as u64,
            })
            .sum(),
    }
}

/// Refuses a header whose element counts need more bytes than the file holds (before anything
/// is allocated for them).
fn check_counts_fit(
    path: &Path,
    format: PlyFormat,
    elements: &[Element],
    file_bytes: u64,
) -> Result<(), MeshError> {
    let mut need = 0u64;
    for el in elements {
        need = need.saturating_add((el.count as u64).saturating_mul(min_element_bytes(el, format)));
        if need > file_bytes {
            return Err(MeshError::Parse {
                path: path.to_path_buf(),
                reason: format!(
                    "the header states {} `{}` elements, which need at least {need} bytes; the \
                     file has {file_bytes}",
                    el.count, el.name
                ),
            });
        }
    }
    Ok(())
}

/// The most elements reserved ahead of reading them (more grow the vectors as they come, so a
/// header's count alone never allocates).
const MAX_RESERVED_ELEMENTS: usize = 1 << 20;

fn read_ply_sized<R: BufRead>(
    mut r: R,
    path: &Path,
    file_bytes: Option<u64>,
) -> Result<(TriMesh, PlyInfo, Option<VertexColours>), MeshError> {
    let (format, elements, comments) = parse_header(&mut r, path)?;
    if let Some(n) = file_bytes {
        check_counts_fit(path, format, &elements, n)?;
    }
    let mut rd = Reader {
        r,
        path,
        format,
        tokens: Vec::new().into_iter(),
        line: String::new(),
        element_start: false,
    };
    let mut mesh = TriMesh::default();
    let mut info = PlyInfo {
        format,
        polygons_triangulated: 0,
        faces_dropped: 0,
        comments,
    };
    let mut normals: Vec<Vec3> = Vec::new();
    let mut colours: VertexColours = Vec::new();
    let mut have_colours = false;
    let mut have_normals = false;
    let mut saw_vertex = false;
    let mut saw_face = false;
    for el in &elements {
        match el.name.as_str() {
            "vertex" => {
                saw_vertex = true;
                (have_normals, have_colours) =
                    read_vertices(&mut rd, el, &mut mesh, &mut normals, &mut colours)?;
            }
            "face" => {
                saw_face = true;
                read_faces(&mut rd, el, &mut mesh, &mut info)?;
            }
            _ => skip_element(&mut rd, el)?,
        }
    }
    if !saw_vertex {
        return Err(rd.err("no `vertex` element"));
    }
    if !saw_face {
        return Err(rd.err("no `face` element (a point cloud is not a mesh)"));
    }
    let n = mesh.positions.len();
    if let Some((t, tri)) = mesh
        .indices
        .iter()
        .enumerate()
        .find(|(_, tri)| tri.iter().any(|&v| v as usize >= n))
    {
        return Err(rd.err(format!(
            "triangle {t} refers to vertex {} but there are {n} vertices",
            tri.iter().copied().max().unwrap_or(0)
        )));
    }
    if have_normals {
        mesh.normals = Some(normals);
    }
    Ok((mesh, info, have_colours.then_some(colours)))
}

/// Reads the `vertex` element: positions, and the normals and colours when it has them
/// (returned: whether it has normals, whether it has colours).
fn read_vertices<R: BufRead>(
    rd: &mut Reader<'_, R>,
    el: &Element,
    mesh: &mut TriMesh,
    normals: &mut Vec<Vec3>,
    colours: &mut VertexColours,
) -> Result<(bool, bool), MeshError> {
    let prop_index = |n: &str| {
        el.properties
            .iter()
            .position(|p| matches!(p, Property::Scalar { name, .. } if name == n))
    };
    let xyz = [prop_index("x"), prop_index("y"), prop_index("z")];
    let [Some(ix), Some(iy), Some(iz)] = xyz else {
        return Err(rd.err("element `vertex` lacks one of the properties x, y, z"));
    };
    let nrm = [prop_index("nx"), prop_index("ny"), prop_index("nz")];
    let have_normals = nrm.iter().all(Option::is_some);
    let colour_prop = |long: &str, short: &str| {
        el.properties.iter().position(
            |p| matches!(p, Property::Scalar { name, .. } if name == long || name == short),
        )
    };
    let rgb = [
        colour_prop("red", "r"),
        colour_prop("green", "g"),
        colour_prop("blue", "b"),
    ];
    let rgb_scale = rgb.map(|k| match k.map(|k| &el.properties[k]) {
        Some(Property::Scalar { ty, .. }) => match ty {
            Scalar::U8 | Scalar::I8 => 1.0 / 255.0,
            Scalar::U16 | Scalar::I16 => 1.0 / 65535.0,
            Scalar::U32 | Scalar::I32 => 1.0 / f64::from(u32::MAX),
            Scalar::F32 | Scalar::F64 => 1.0,
        },
        _ => 1.0,
    });
    let have_colours = rgb.iter().all(Option::is_some);
    mesh.positions.reserve(el.count.min(MAX_RESERVED_ELEMENTS));
    let mut vals = vec![0.0f64; el.properties.len()];
    for i in 0..el.count {
        rd.begin_element();
        for (k, p) in el.properties.iter().enumerate() {
            let what = || format!("vertex {i}");
            match p {
                Property::Scalar { ty, .. } => vals[k] = rd.read(*ty, &what)?,
                Property::List { count, item, .. } => {
                    let c = rd.read(*count, &what)?;
                    for _ in 0..c as usize {
                        rd.read(*item, &what)?;
                    }
                }
            }
        }
        mesh.positions
            .push(Vec3::new(vals[ix] as f32, vals[iy] as f32, vals[iz] as f32));
        if let [Some(a), Some(b), Some(c)] = nrm {
            normals.push(Vec3::new(vals[a] as f32, vals[b] as f32, vals[c] as f32));
        }
        if let [Some(a), Some(b), Some(c)] = rgb {
            colours.push([
                (vals[a] * rgb_scale[0]) as f32,
                (vals[b] * rgb_scale[1]) as f32,
                (vals[c] * rgb_scale[2]) as f32,
            ]);
        }
    }
    Ok((have_normals, have_colours))
}

/// Reads the `face` element: polygons fanned into triangles, faces of fewer than three corners
/// dropped (both counted in `info`).
fn read_faces<R: BufRead>(
    rd: &mut Reader<'_, R>,
    el: &Element,
    mesh: &mut TriMesh,
    info: &mut PlyInfo,
) -> Result<(), MeshError> {
    let list = el.properties.iter().position(|p| {
        matches!(p, Property::List { name, .. } if name == "vertex_indices" || name == "vertex_index")
    });
    let Some(list) = list else {
        return Err(
            rd.err("element `face` has no list property `vertex_indices` or `vertex_index`")
        );
    };
    mesh.indices.reserve(el.count.min(MAX_RESERVED_ELEMENTS));
    let mut corners: Vec<u32> = Vec::with_capacity(8);
    for i in 0..el.count {
        rd.begin_element();
        for (k, p) in el.properties.iter().enumerate() {
            let what = || format!("face {i}");
            match p {
                Property::Scalar { ty, .. } => {
                    rd.read(*ty, &what)?;
                }
                Property::List { count, item, .. } => {
                    let c = rd.read(*count, &what)?;
                    if !(0.0..=1e6).contains(&c) {
                        return Err(rd.err(format!("face {i}: list length {c}")));
                    }
                    corners.clear();
                    for _ in 0..c as usize {
                        let v = rd.read(*item, &what)?;
                        if k == list {
                            if v < 0.0 || v.fract() != 0.0 || v > u32::MAX as f64 {
                                return Err(rd.err(format!(
                                    "face {i}: vertex index {v} is not a valid index"
                                )));
                            }
                            corners.push(v as u32);
                        }
                    }
                }
            }
        }
        if corners.len() < 3 {
            info.faces_dropped += 1;
            continue;
        }
        if corners.len() > 3 {
            info.polygons_triangulated += 1;
        }
        for w in 1..corners.len() - 1 {
            mesh.indices.push([corners[0], corners[w], corners[w + 1]]);
        }
    }
    Ok(())
}

/// Reads past an element the mesh does not use.
fn skip_element<R: BufRead>(rd: &mut Reader<'_, R>, el: &Element) -> Result<(), MeshError> {
    for i in 0..el.count {
        rd.begin_element();
        for p in &el.properties {
            let what = || format!("element `{}` {i}", el.name);
            match p {
                Property::Scalar { ty, .. } => {
                    rd.read(*ty, &what)?;
                }
                Property::List { count, item, .. } => {
                    let c = rd.read(*count, &what)?;
                    for _ in 0..c as usize {
                        rd.read(*item, &what)?;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Writes the mesh as binary little-endian PLY, atomically (temporary file + rename).
/// Vertex normals are written when the mesh has them.
pub fn write_ply_binary(path: &Path, mesh: &TriMesh) -> Result<(), MeshError> {
    write_ply_binary_in(path, mesh, "metres")
}

/// [`write_ply_binary`] for coordinates in another unit, named in the header's comment
/// (`comment skinbrdf mesh, millimetres`).
pub fn write_ply_binary_in(path: &Path, mesh: &TriMesh, units: &str) -> Result<(), MeshError> {
    let mut buf = Vec::with_capacity(64 + mesh.positions.len() * 24 + mesh.indices.len() * 13);
    write_ply_binary_units_to(&mut buf, mesh, units);
    write_atomic(path, &buf)
}

/// Encodes the mesh (coordinates in metres) as binary little-endian PLY into `out`.
pub fn write_ply_binary_to(out: &mut Vec<u8>, mesh: &TriMesh) {
    write_ply_binary_units_to(out, mesh, "metres")
}

fn write_ply_binary_units_to(out: &mut Vec<u8>, mesh: &TriMesh, units: &str) {
    let normals = mesh
        .normals
        .as_ref()
        .filter(|n| n.len() == mesh.positions.len());
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment skinbrdf mesh, {units}\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        mesh.positions.len()
    );
    if normals.is_some() {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    header.push_str(&format!(
        "element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.indices.len()
    ));
    out.extend_from_slice(header.as_bytes());
    for (i, p) in mesh.positions.iter().enumerate() {
        for c in p.to_array() {
            out.extend_from_slice(&c.to_le_bytes());
        }
        if let Some(n) = normals {
            for c in n[i].to_array() {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    for t in &mesh.indices {
        out.push(3);
        for &v in t {
            out.extend_from_slice(&(v as i32).to_le_bytes());
        }
    }
}

/// Writes the mesh with an 8-bit colour per vertex (`red green blue` as `uchar`, display
/// values as a scanner stores them) as binary little-endian PLY in `units` (named in the
/// header's comment, as [`write_ply_binary_in`]), atomically. Normals are not written.
pub fn write_ply_binary_coloured_in(
    path: &Path,
    mesh: &TriMesh,
    colours: &[[u8; 3]],
    units: &str,
) -> Result<(), MeshError> {
    if colours.len() != mesh.positions.len() {
        return Err(MeshError::InvalidParameter {
            field: "colours",
            reason: format!(
                "{} colours for {} vertices",
                colours.len(),
                mesh.positions.len()
            ),
        });
    }
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment skinbrdf mesh, {units}\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nproperty uchar red\n\
         property uchar green\nproperty uchar blue\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.indices.len()
    );
    let mut out =
        Vec::with_capacity(header.len() + mesh.positions.len() * 15 + mesh.indices.len() * 13);
    out.extend_from_slice(header.as_bytes());
    for (p, c) in mesh.positions.iter().zip(colours) {
        for x in p.to_array() {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.extend_from_slice(c);
    }
    for t in &mesh.indices {
        out.push(3);
        for &v in t {
            out.extend_from_slice(&(v as i32).to_le_bytes());
        }
    }
    write_atomic(path, &out)
}

/// Writes ASCII PLY (for tests and small hand-inspected meshes), atomically.
pub fn write_ply_ascii(path: &Path, mesh: &TriMesh) -> Result<(), MeshError> {
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.indices.len()
    );
    for p in &mesh.positions {
        s.push_str(&format!("{} {} {}\n", p.x, p.y, p.z));
    }
    for t in &mesh.indices {
        s.push_str(&format!("3 {} {} {}\n", t[0], t[1], t[2]));
    }
    write_atomic(path, s.as_bytes())
}

/// Writes bytes to `path` through a temporary file in the same directory and a rename.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), MeshError> {
    skinbrdf_core::fsio::write_atomic(path, bytes).map_err(|e| MeshError::Io {
        path: e.path,
        source: e.source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> TriMesh {
        TriMesh {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(0.1, 0.0, 0.0),
                Vec3::new(0.1, 0.1, 0.0),
                Vec3::new(0.0, 0.1, 0.012_345),
            ],
            indices: vec![[0, 1, 2], [0, 2, 3]],
            normals: None,
        }
    }

    #[test]
    fn binary_round_trip_with_and_without_normals() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        let mut m = quad();
        write_ply_binary(&p, &m).unwrap();
        let (back, info) = read_ply(&p).unwrap();
        assert_eq!(back, m);
        assert_eq!(info.format, PlyFormat::BinaryLittleEndian);
        m.normals = Some(vec![Vec3::Z; 4]);
        write_ply_binary(&p, &m).unwrap();
        assert_eq!(read_ply(&p).unwrap().0, m);
        // No temporary file is left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn ascii_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        write_ply_ascii(&p, &quad()).unwrap();
        let (back, info) = read_ply(&p).unwrap();
        assert_eq!(back, quad());
        assert_eq!(info.format, PlyFormat::Ascii);
    }

    #[test]
    fn big_endian_doubles_quads_and_extra_properties() {
        let mut b = b"ply\nformat binary_big_endian 1.0\ncomment scanner mm\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\nelement face 1\nproperty uchar flags\nproperty list uchar uint vertex_indices\nelement edge 1\nproperty int a\nproperty int b\nend_header\n".to_vec();
        let pts: [[f64; 3]; 4] = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        for p in pts {
            for c in p {
                b.extend_from_slice(&c.to_be_bytes());
            }
            b.push(200);
        }
        b.push(7);
        b.push(4);
        for i in [0u32, 1, 2, 3] {
            b.extend_from_slice(&i.to_be_bytes());
        }
        b.extend_from_slice(&[0; 8]);
        let (m, info) = read_ply_from(&b[..], Path::new("be.ply")).unwrap();
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(info.polygons_triangulated, 1);
        assert_eq!(info.comments, vec!["scanner mm".to_string()]);
    }

    #[test]
    fn errors_name_the_element_and_problem() {
        let cases: &[(&str, &str)] = &[
            ("plx\n", "not a PLY file"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 0\nproperty list uchar int vertex_indices\n", "without `end_header`"),
            ("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 zz 0\n", "vertex 1: `zz` is not a number"),
            ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n", "triangle 0 refers to vertex 9 but there are 3 vertices"),
            ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1\n", "face 1: the line ends before the element's values do"),
            ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 3\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1\n3 0 1 2\n", "face 1: the line ends before the element's values do"),
            ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 2\n3 0 1 2\n", "face 1: the line before holds more values"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n", "lacks one of the properties x, y, z"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n", "no `face` element"),
            ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "face 0: vertex index -1"),
        ];
        for (text, expected) in cases {
            let e = read_ply_from(text.as_bytes(), Path::new("bad.ply")).unwrap_err();
            let msg = e.to_string();
            assert!(msg.starts_with("bad.ply: "), "{msg}");
            assert!(msg.contains(expected), "expected `{expected}` in `{msg}`");
        }
        let e = read_ply(Path::new("/nonexistent/x.ply")).unwrap_err();
        assert!(matches!(e, MeshError::Io { .. }));
    }

    #[test]
    fn binary_truncation_is_reported() {
        let mut buf = Vec::new();
        write_ply_binary_to(&mut buf, &quad());
        buf.truncate(buf.len() - 5);
        let e = read_ply_from(&buf[..], Path::new("t.ply")).unwrap_err();
        assert!(
            e.to_string().contains("face 1: unexpected end of file"),
            "{e}"
        );
    }
}
