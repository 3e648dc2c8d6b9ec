//! Head-scan meshes: loading with validation, normals by local planar fit, and an obvhs BVH for
//! ray casting.
//!
//! * [`load`]: [`load_mesh`] reads PLY (ASCII, binary LE/BE), OBJ or glTF (`.glb`, `.gltf`),
//!   converts scanner units to metres and validates/repairs ([`validate`]: NaN vertices, degenerate and duplicate
//!   triangles, inconsistent winding — counted with examples).
//! * [`ply`]: the PLY reader and the atomic binary writer [`write_ply_binary`].
//! * [`normals`]: shading normals by a local planar fit over a radius (given or estimated from
//!   the scan's noise) or vertex normals; interpolated at ray hits.
//! * [`shapes`]: tessellated spheres and cylinders.
//! * [`textured`]: [`load_textured`], scans with their colours (OBJ + MTL + PNG/JPEG texture,
//!   PLY vertex colours, binary glTF or `.gltf` with its base-colour texture or vertex colours)
//!   and [`TexturedMesh::colour_at`] at a ray hit; [`load_mesh_with_uv`], the mesh with its
//!   texture coordinates only (no image decoded), for samples that record where they are.
//! * [`gltf_scan`]: the glTF reader behind both, and [`write_glb`], a textured GLB writer.
//! * [`bvh`]: [`MeshBvh`], build once and trace many (closest hit, occlusion, batched rays),
//!   build presets [`BuildQuality`].
//! * [`camera_rays`]: [`CameraRays`], per-pixel camera rays from a coarse exact undistortion
//!   table plus one Newton step (instead of a full Newton solve per pixel).
//! * [`coherent`]: [`MeshBvh::intersect_grid`], camera rays (one origin, a grid of directions)
//!   traced per tile with shared frustum culling: the fast path for whole images.

pub mod bvh;
pub mod camera_rays;
pub mod coherent;
mod error;
pub mod gltf_scan;
mod limits;
pub mod load;
mod load_options;
mod material;
pub mod normals;
mod obj;
mod open;
pub mod ply;
mod report;
pub mod shadow;
pub mod shapes;
pub mod textured;
mod tiled;
pub mod validate;

pub use bvh::{BuildQuality, Hit, MeshBvh, MeshRay};
pub use camera_rays::CameraRays;
pub use coherent::TraceScratch;
pub use error::MeshError;
pub use gltf_scan::{encode_glb, gltf_external_files, write_glb, GltfProblem};
pub use load::{load_mesh, LengthUnit, LoadOptions, LoadedMesh};
pub use normals::{estimate_noise, NoiseEstimate, NormalMethod, SurfaceNormals};
pub use ply::{
    read_ply, read_ply_coloured, write_ply_binary, write_ply_binary_coloured_in,
    write_ply_binary_in,
};
pub use shadow::{shadow_ray, ShadowScratch};
pub use textured::{
    load_mesh_with_uv, load_textured, obj_companion_files, Appearance, CornerUv, Material,
    TextureImage, TexturedMesh, MAX_TEXTURE_TEXELS,
};
pub use tiled::TileCounts;
pub use validate::{inspect, repair, repair_tracked, MeshReport, RepairMap, RepairPolicy};
