//! Head-scan meshes: loading with validation, normals by local planar fit, and an obvhs BVH for
//! ray casting.
//!
//! * [`bvh`]: [`MeshBvh`], build once and trace many (closest hit, occlusion, batched rays).

pub mod bvh;

pub use bvh::{BuildQuality, Hit, MeshBvh, MeshRay};

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
    /// A file is malformed.
    #[error("{path}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the line or element where it was found.
        reason: String,
    },
}
