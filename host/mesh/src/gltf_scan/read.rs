//! Reading a `.glb` or `.gltf` (see [`crate::gltf_scan`]): the document, its buffers, its
//! materials when the appearance is wanted, then every primitive of the scene.

use std::collections::HashMap;
use std::path::Path;

use super::data::{Detail, GltfData};
use super::document::{gltf_err, guarded, parse_document};
use super::material::material;
use super::primitive::PrimitiveReader;
use super::scene::scene_primitives;
use super::uri::load_buffers;
use crate::error::{GltfProblem, MeshError};
use crate::limits::MAX_TEXTURE_TEXELS;
use crate::material::{Material, TextureImage};

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
    let mut out = GltfData::default();
    if detail == Detail::Appearance {
        out.materials = materials(path, &doc, &buffers)?;
    }
    let mut reader = PrimitiveReader::new(path, &buffers, detail);
    for (mesh, world) in scene_primitives(path, &doc)? {
        reader.read_mesh(&mesh, world, &mut out)?;
    }
    if out.mesh.indices.is_empty() {
        return Err(MeshError::Parse {
            path: path.to_path_buf(),
            reason: "glTF has no triangles in its scene".into(),
        });
    }
    Ok(out)
}

/// The document's materials with their images, the texels of all their textures together
/// within [`MAX_TEXTURE_TEXELS`].
fn materials(
    path: &Path,
    doc: &::gltf::Document,
    buffers: &[Vec<u8>],
) -> Result<Vec<Material>, MeshError> {
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut images: HashMap<usize, TextureImage> = HashMap::new();
    let mut out = Vec::new();
    let mut texels = 0u64;
    for m in doc.materials() {
        let made = material(path, &dir, buffers, &m, &mut images)?;
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
        out.push(made);
    }
    Ok(out)
}
