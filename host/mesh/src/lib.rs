//! Head-scan meshes: loading with validation, normals by local planar fit, and an obvhs BVH for
//! ray casting.
//!
//! * [`load`]: [`load_mesh`] reads PLY (ASCII, binary LE/BE) or OBJ, converts scanner units to
//!   metres and validates/repairs ([`validate`]: NaN vertices, degenerate and duplicate
//!   triangles, inconsistent winding — counted with examples).
//! * [`ply`]: the PLY reader and the atomic binary writer [`write_ply_binary`].
//! * [`normals`]: shading normals by a local planar fit over a radius (given or estimated from
//!   the scan's noise) or vertex normals; interpolated at ray hits.
//! * [`shapes`]: tessellated spheres and cylinders.
//! * [`bvh`]: [`MeshBvh`], build once and trace many (closest hit, occlusion, batched rays),
//!   build presets [`BuildQuality`].
//! * [`camera_rays`]: [`CameraRays`], per-pixel camera rays from a coarse exact undistortion
//!   table plus one Newton step (instead of a full Newton solve per pixel).
//! * [`coherent`]: [`MeshBvh::intersect_grid`], camera rays (one origin, a grid of directions)
//!   traced per tile with shared frustum culling: the fast path for whole images.

pub mod bvh;
pub mod camera_rays;
pub mod coherent;
pub mod load;
pub mod normals;
pub mod ply;
pub mod shadow;
pub mod shapes;
pub mod validate;

pub use bvh::{BuildQuality, Hit, MeshBvh, MeshRay};
pub use camera_rays::CameraRays;
pub use coherent::TraceScratch;
pub use load::{load_mesh, LengthUnit, LoadOptions, LoadedMesh};
pub use normals::{estimate_noise, NoiseEstimate, NormalMethod, SurfaceNormals};
pub use ply::{read_ply, write_ply_binary, write_ply_binary_in};
pub use shadow::{shadow_ray, ShadowScratch};
pub use validate::{inspect, repair, MeshReport, RepairPolicy};

use std::path::PathBuf;

/// Errors of the mesh crate. Each names the file (where there is one) and the problem.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The mesh breaks a hard invariant (see [`skinbrdf_core::TriMesh::validate`]).
    #[error("invalid mesh: {} problem(s), first: {}", problems.len(), problems.first().map(|p| p.to_string()).unwrap_or_default())]
    Invalid {
        /// Every problem found.
        problems: Vec<skinbrdf_core::MeshError>,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The mesh has defects and the policy was strict.
    #[error("{source_name}: mesh defects: {}", report.summary())]
    Defects {
        /// File or mesh name.
        source_name: String,
        /// What was found.
        report: Box<crate::validate::MeshReport>,
    },
    /// Repairing the mesh would drop more triangles than the policy accepts.
    #[error("{source_name}: repairing the mesh loses {} of its {} triangles, more than the {:.1} % accepted ({})", report.lost_triangles(), report.triangles_in, max_fraction * 100.0, report.summary())]
    TooManyDropped {
        /// File or mesh name.
        source_name: String,
        /// The policy's limit (fraction of the triangles).
        max_fraction: f64,
        /// What was found (`lost_triangles()` of `triangles_in`).
        report: Box<crate::validate::MeshReport>,
    },
    /// A parameter is out of range.
    #[error("{field}: {reason}")]
    InvalidParameter {
        /// Which parameter.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// A file is malformed.
    #[error("{path}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the line or element where it was found.
        reason: String,
    },
}
