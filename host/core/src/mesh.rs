//! Indexed triangle meshes (positions in metres).

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Problems found in a mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// A vertex has a NaN or infinite coordinate.
    #[error("vertex {index} is not finite: ({}, {}, {})", position[0], position[1], position[2])]
    NonFiniteVertex {
        /// Vertex index.
        index: usize,
        /// Its coordinates.
        position: [f32; 3],
    },
    /// A triangle refers to a vertex that does not exist.
    #[error(
        "triangle {triangle} refers to vertex {vertex}, but the mesh has {vertex_count} vertices"
    )]
    IndexOutOfRange {
        /// Triangle index.
        triangle: usize,
        /// Offending vertex index.
        vertex: u32,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// The mesh has no triangles.
    #[error("the mesh has no triangles")]
    Empty,
}

/// An indexed triangle mesh.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TriMesh {
    /// Vertex positions, metres.
    pub positions: Vec<Vec3>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub indices: Vec<[u32; 3]>,
    /// Optional per-vertex unit normals (same length as `positions` when present).
    #[serde(default)]
    pub normals: Option<Vec<Vec3>>,
}

impl TriMesh {
    /// The three corners of triangle `t`.
    pub fn triangle(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.indices[t];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// The unnormalised geometric normal (twice the area) of triangle `t`.
    pub fn face_normal_area2(&self, t: usize) -> Vec3 {
        let [a, b, c] = self.triangle(t);
        (b - a).cross(c - a)
    }

    /// Hard invariants every consumer relies on: finite vertices, indices in range, non-empty.
    /// Returns every violation (not just the first). Soft problems (degenerate or duplicate
    /// triangles, winding) are the mesh crate's business.
    pub fn validate(&self) -> Vec<MeshError> {
        let mut errors = Vec::new();
        if self.indices.is_empty() {
            errors.push(MeshError::Empty);
        }
        for (index, p) in self.positions.iter().enumerate() {
            if !p.is_finite() {
                errors.push(MeshError::NonFiniteVertex {
                    index,
                    position: p.to_array(),
                });
            }
        }
        let n = self.positions.len();
        for (triangle, tri) in self.indices.iter().enumerate() {
            for &vertex in tri {
                if vertex as usize >= n {
                    errors.push(MeshError::IndexOutOfRange {
                        triangle,
                        vertex,
                        vertex_count: n,
                    });
                }
            }
        }
        errors
    }

    /// Axis-aligned bounds `(min, max)`; `None` for an empty mesh.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut it = self.positions.iter();
        let first = *it.next()?;
        Some(it.fold((first, first), |(lo, hi), p| (lo.min(*p), hi.max(*p))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_reports_every_problem() {
        let m = TriMesh {
            positions: vec![Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::X],
            indices: vec![[0, 1, 2], [0, 2, 7]],
            normals: None,
        };
        let errs = m.validate();
        assert_eq!(errs.len(), 2, "{errs:?}");
        assert!(matches!(
            errs[0],
            MeshError::NonFiniteVertex { index: 1, .. }
        ));
        assert!(matches!(
            errs[1],
            MeshError::IndexOutOfRange {
                triangle: 1,
                vertex: 7,
                ..
            }
        ));
    }
}
