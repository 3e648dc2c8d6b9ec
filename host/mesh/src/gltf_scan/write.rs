//! [`write_glb`]: a minimal textured GLB writer for tests and the synthetic studio.

use std::collections::HashMap;
use std::path::Path;

use glam::{Vec2, Vec3};
use skinbrdf_core::TriMesh;

use crate::error::MeshError;

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
