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
//!   and [`TexturedMesh::colour_at`] at a ray hit.
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
pub mod gltf_scan;
pub mod load;
pub mod normals;
pub mod ply;
pub mod shadow;
pub mod shapes;
pub mod textured;
pub mod validate;

pub use bvh::{BuildQuality, Hit, MeshBvh, MeshRay};
pub use camera_rays::CameraRays;
pub use coherent::TraceScratch;
pub use gltf_scan::{encode_glb, gltf_external_files, write_glb, GltfProblem};
pub use load::{load_mesh, LengthUnit, LoadOptions, LoadedMesh};
pub use normals::{estimate_noise, NoiseEstimate, NormalMethod, SurfaceNormals};
pub use ply::{
    read_ply, read_ply_coloured, write_ply_binary, write_ply_binary_coloured_in,
    write_ply_binary_in,
};
pub use shadow::{shadow_ray, ShadowScratch};
pub use textured::{
    load_textured, obj_companion_files, Appearance, Material, TextureImage, TexturedMesh,
    MAX_TEXTURE_TEXELS,
};
pub use validate::{inspect, repair, repair_tracked, MeshReport, RepairMap, RepairPolicy};

use std::path::{Path, PathBuf};

impl From<skinbrdf_core::untrusted::ReadError> for MeshError {
    /// A plain I/O failure stays [`MeshError::Io`]; a refusal (not a regular file, too large)
    /// is [`MeshError::Read`].
    fn from(e: skinbrdf_core::untrusted::ReadError) -> Self {
        match e {
            skinbrdf_core::untrusted::ReadError::Io { path, source } => Self::Io { path, source },
            other => Self::Read(other),
        }
    }
}

/// Opens a scan file for reading: a regular file within [`skinbrdf_core::untrusted::SCAN_FILE`]
/// (a device or FIFO is refused at once). Returns the file and its length.
pub(crate) fn open_scan(path: &Path) -> Result<(std::fs::File, u64), MeshError> {
    use skinbrdf_core::untrusted::{open_regular, ReadError, SCAN_FILE};
    let (file, len) = open_regular(path)?;
    if len > SCAN_FILE.max_bytes {
        return Err(ReadError::TooLarge {
            path: path.to_path_buf(),
            kind: SCAN_FILE.kind,
            size_bytes: len,
            max_bytes: SCAN_FILE.max_bytes,
        }
        .into());
    }
    Ok((file, len))
}

/// Errors of the mesh crate. Each names the file (where there is one) and the problem.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The mesh breaks a hard invariant (see [`skinbrdf_core::TriMesh::validate`]).
    #[error("invalid mesh: {} problem(s), first: {}", problems.len(), problems.first().map(|p| p.to_string()).unwrap_or_default())]
    Invalid {
        /// Every problem found.
        problems: Vec<skinbrdf_core::MeshError>,
    },
    /// No triangle is left (none in the file, or none survived the repair).
    #[error("{source_name}: the mesh has no usable triangle (of {triangles_in} read)")]
    Empty {
        /// File or mesh name.
        source_name: String,
        /// Triangles in the input.
        triangles_in: usize,
    },
    /// Reading or writing a file failed.
    #[error("{path}")]
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
    /// An OBJ's material names a texture file that does not exist.
    #[error("{path}: material `{material}` names the texture {texture}, which does not exist")]
    MissingTexture {
        /// The OBJ file.
        path: PathBuf,
        /// The material.
        material: String,
        /// The texture file looked for.
        texture: PathBuf,
    },
    /// An OBJ's `mtllib` file could not be read.
    #[error("{path}: cannot read its material library {}", libraries.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "))]
    MissingMaterialLibrary {
        /// The OBJ file.
        path: PathBuf,
        /// The MTL files that failed.
        libraries: Vec<PathBuf>,
    },
    /// A texture image could not be decoded.
    #[error("texture {path}: {reason}")]
    Texture {
        /// The image file.
        path: PathBuf,
        /// The decoder's complaint.
        reason: String,
    },
    /// Texture coordinates that do not fit the faces.
    #[error("{path}: bad texture coordinates: {reason}")]
    BadUv {
        /// The OBJ file.
        path: PathBuf,
        /// What is wrong, with the object and face.
        reason: String,
    },
    /// A glTF file is malformed or uses what the loader does not read.
    #[error("{path}: glTF: {problem}")]
    Gltf {
        /// The `.glb` or `.gltf` file.
        path: PathBuf,
        /// What is wrong.
        problem: gltf_scan::GltfProblem,
    },
    /// A file could not be read within its limits (not a regular file, or too large).
    #[error(transparent)]
    Read(skinbrdf_core::untrusted::ReadError),
    /// A path a scan file names (an OBJ's `mtllib`, an MTL's `map_Kd`, a glTF's URI) leads
    /// outside the scan's folder or to something other than a regular file.
    #[error("{}: {key}: {reason}", path.display())]
    Refused {
        /// The file that names the path.
        path: PathBuf,
        /// Where in it (`line 3 mtllib`, `buffer 0 uri`).
        key: String,
        /// Why it is refused.
        reason: Box<skinbrdf_core::untrusted::ConfineError>,
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
