//! The OBJ reader: geometry, per-corner texture coordinates and per-triangle materials
//! (through `tobj`), with its material libraries and textures held inside the scan's folder.

use std::cell::RefCell;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use skinbrdf_core::untrusted::{self, confine, ConfineError};
use skinbrdf_core::TriMesh;

use crate::error::MeshError;
use crate::material::TextureImage;

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
    let (file, _) = crate::open::open_scan(path)?;
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

/// An OBJ's material library named `written` on a line of the OBJ (`key` says where): a
/// regular file inside the OBJ's folder ([`confine`]), read within
/// [`untrusted::MATERIAL_LIBRARY`]. Returns the file and its bytes.
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
pub(crate) fn texture_file(dir: &Path, map_kd: &str) -> Result<PathBuf, ConfineError> {
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
    let (file, _) = crate::open::open_scan(path)?;
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
