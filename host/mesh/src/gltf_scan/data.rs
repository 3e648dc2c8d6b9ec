//! What the reader gives: a scan's geometry with its per-triangle appearance, and how much of
//! it to read.

use glam::Vec2;
use skinbrdf_core::TriMesh;

use crate::material::Material;

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
    /// Also the texture coordinates of triangles whose material has a base-colour texture
    /// ([`crate::textured::load_mesh_with_uv`]): no image decoded, no vertex colour read.
    TexCoords,
    /// Also texture coordinates, vertex colours, materials and their images.
    Appearance,
}
