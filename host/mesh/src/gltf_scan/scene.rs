//! The scene's node hierarchy walked to the meshes it draws, each with its world transform.

use std::path::Path;

use glam::DMat4;

use super::document::gltf_err;
use crate::error::{GltfProblem, MeshError};

/// The primitives to read with their world transforms, in scene order.
pub(super) fn scene_primitives<'a>(
    path: &Path,
    doc: &'a ::gltf::Document,
) -> Result<Vec<(::gltf::Mesh<'a>, DMat4)>, MeshError> {
    let roots: Vec<::gltf::Node<'a>> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => {
            let mut child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    child[c.index()] = true;
                }
            }
            doc.nodes().filter(|n| !child[n.index()]).collect()
        }
    };
    let mut reached = vec![false; doc.nodes().len()];
    let mut out = Vec::new();
    let mut stack: Vec<(::gltf::Node<'a>, DMat4)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, DMat4::IDENTITY))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        match reached.get_mut(node.index()) {
            Some(r) if !*r => *r = true,
            _ => {
                return Err(gltf_err(
                    path,
                    GltfProblem::NodeCycle { node: node.index() },
                ))
            }
        }
        let m = node.transform().matrix().map(|c| c.map(f64::from));
        let world = parent * DMat4::from_cols_array_2d(&m);
        if let Some(mesh) = node.mesh() {
            out.push((mesh, world));
        }
        let children: Vec<_> = node.children().collect();
        for c in children.into_iter().rev() {
            stack.push((c, world));
        }
    }
    Ok(out)
}
