//! One mesh primitive read into the scan: its positions (node transform applied), its
//! triangles (winding reversed under a mirroring transform) and, for the appearance, its
//! material with its texture coordinates or its vertex colours.

use std::path::Path;

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::{Mode, Semantic};
use glam::{DMat4, DVec3, Vec2, Vec3};

use super::accessor::{check_accessor, mode_name};
use super::colour::linear_to_srgb;
use super::data::{Detail, GltfData};
use super::document::gltf_err;
use crate::error::{GltfProblem, MeshError};
use crate::limits::{READ_BYTES_PER_BUFFER_BYTE, READ_BYTES_SLACK};

/// Reads the primitives of one file into a [`GltfData`], holding the geometry read to its
/// limit ([`READ_BYTES_PER_BUFFER_BYTE`]).
pub(super) struct PrimitiveReader<'a> {
    path: &'a Path,
    buffers: &'a [Vec<u8>],
    detail: Detail,
    /// Bytes of vertices and triangles the primitives may take as read.
    max_read_bytes: u64,
    /// Bytes they take so far.
    read_bytes: u64,
}

/// A primitive's node transform and what it does to the winding.
struct Placement {
    world: DMat4,
    mirrored: bool,
    identity: bool,
}

impl<'a> PrimitiveReader<'a> {
    pub(super) fn new(path: &'a Path, buffers: &'a [Vec<u8>], detail: Detail) -> Self {
        let buffer_bytes: u64 = buffers.iter().map(|b| b.len() as u64).sum();
        let max_read_bytes = buffer_bytes
            .saturating_mul(READ_BYTES_PER_BUFFER_BYTE)
            .saturating_add(READ_BYTES_SLACK);
        Self {
            path,
            buffers,
            detail,
            max_read_bytes,
            read_bytes: 0,
        }
    }

    /// Reads every primitive of `mesh`, placed by its node's world transform, into `out`.
    pub(super) fn read_mesh(
        &mut self,
        mesh: &::gltf::Mesh<'_>,
        world: DMat4,
        out: &mut GltfData,
    ) -> Result<(), MeshError> {
        let placement = Placement {
            world,
            mirrored: world.determinant() < 0.0,
            identity: world == DMat4::IDENTITY,
        };
        for (pi, prim) in mesh.primitives().enumerate() {
            let at = primitive_name(mesh, pi);
            self.read_primitive(&prim, at, &placement, out)?;
        }
        Ok(())
    }

    fn read_primitive(
        &mut self,
        prim: &::gltf::Primitive<'_>,
        at: String,
        placement: &Placement,
        out: &mut GltfData,
    ) -> Result<(), MeshError> {
        if prim.mode() != Mode::Triangles {
            return Err(gltf_err(
                self.path,
                GltfProblem::UnsupportedMode {
                    at,
                    mode: mode_name(prim.mode()).to_string(),
                },
            ));
        }
        let positions = self.positions(prim, at.clone())?;
        let n = positions.len();
        let tris = self.triangles(prim, &at, n)?;
        // Mirroring transforms reverse the winding (corners 1 and 2 swapped back).
        let tris: Vec<[u32; 3]> = if placement.mirrored {
            tris.into_iter().map(|[a, b, c]| [a, c, b]).collect()
        } else {
            tris
        };
        let base = out.mesh.positions.len() as u32;
        out.mesh.positions.extend(positions.iter().map(|p| {
            if placement.identity {
                Vec3::from_array(*p)
            } else {
                placement
                    .world
                    .transform_point3(DVec3::from_array(p.map(f64::from)))
                    .as_vec3()
            }
        }));
        out.mesh
            .indices
            .extend(tris.iter().map(|t| t.map(|v| v + base)));
        if self.detail == Detail::Geometry {
            return Ok(());
        }
        self.appearance(prim, &at, n, &tris, out)
    }

    /// An accessor of the primitive that cannot be read as a scan needs it.
    fn bad(&self, at: &str, attribute: &str, reason: String) -> MeshError {
        gltf_err(
            self.path,
            GltfProblem::BadAccessor {
                at: at.to_string(),
                attribute: attribute.to_string(),
                reason,
            },
        )
    }

    /// The primitive's `POSITION`s as stored, all finite, after checking that it and its
    /// triangles fit in what the primitives may take.
    fn positions(
        &mut self,
        prim: &::gltf::Primitive<'_>,
        at: String,
    ) -> Result<Vec<[f32; 3]>, MeshError> {
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let Some(pos_acc) = prim.get(&Semantic::Positions) else {
            return Err(self.bad(&at, "POSITION", "the primitive has none".into()));
        };
        check_accessor(
            &pos_acc,
            buffers,
            &[DataType::F32],
            &[Dimensions::Vec3],
            None,
        )
        .map_err(|r| self.bad(&at, "POSITION", r))?;
        let n = pos_acc.count();
        // What this primitive takes once read (positions, and triangles as three u32),
        // checked before it is read.
        let corners = prim.indices().map_or(n, |a| a.count()) as u64;
        self.read_bytes = self.read_bytes.saturating_add(12 * n as u64 + 4 * corners);
        if self.read_bytes > self.max_read_bytes {
            return Err(gltf_err(
                self.path,
                GltfProblem::TooMuchGeometry {
                    at,
                    bytes: self.read_bytes,
                    max: self.max_read_bytes,
                },
            ));
        }
        let positions: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or_else(|| self.bad(&at, "POSITION", "unreadable".into()))?
            .collect();
        if positions.len() != n {
            return Err(self.bad(&at, "POSITION", format!("{} of {n} read", positions.len())));
        }
        if let Some((vertex, &value)) = positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(gltf_err(
                self.path,
                GltfProblem::NonFinitePosition { at, vertex, value },
            ));
        }
        Ok(positions)
    }

    /// The primitive's triangles over its `n` vertices: its indices, or consecutive vertices
    /// when it has none.
    fn triangles(
        &self,
        prim: &::gltf::Primitive<'_>,
        at: &str,
        n: usize,
    ) -> Result<Vec<[u32; 3]>, MeshError> {
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let Some(acc) = prim.indices() else {
            if !n.is_multiple_of(3) {
                return Err(self.bad(
                    at,
                    "POSITION",
                    format!("{n} vertices without indices are not whole triangles"),
                ));
            }
            return Ok((0..n as u32 / 3)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect());
        };
        check_accessor(
            &acc,
            buffers,
            &[DataType::U8, DataType::U16, DataType::U32],
            &[Dimensions::Scalar],
            None,
        )
        .map_err(|r| self.bad(at, "indices", r))?;
        let idx: Vec<u32> = reader
            .read_indices()
            .ok_or_else(|| self.bad(at, "indices", "unreadable".into()))?
            .into_u32()
            .collect();
        if !idx.len().is_multiple_of(3) {
            return Err(self.bad(
                at,
                "indices",
                format!("{} indices are not whole triangles", idx.len()),
            ));
        }
        if let Some(i) = idx.iter().find(|&&i| i as usize >= n) {
            return Err(self.bad(
                at,
                "indices",
                format!("index {i} past the primitive's {n} vertices"),
            ));
        }
        Ok(idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect())
    }

    /// Per triangle of the primitive: its material, and its corners' texture coordinates (when
    /// its material's base-colour texture has them) or else their `COLOR_0` colours.
    fn appearance(
        &self,
        prim: &::gltf::Primitive<'_>,
        at: &str,
        n: usize,
        tris: &[[u32; 3]],
        out: &mut GltfData,
    ) -> Result<(), MeshError> {
        let mat = prim.material();
        out.material.extend(std::iter::repeat_n(
            mat.index().map(|m| m as u32),
            tris.len(),
        ));
        let pbr = mat.pbr_metallic_roughness();
        let uv_set = pbr.base_color_texture().map(|info| info.tex_coord());
        let uv_acc = uv_set.and_then(|s| prim.get(&Semantic::TexCoords(s)).map(|a| (s, a)));
        if let Some((set, acc)) = uv_acc {
            let uv = self.texture_coordinates(prim, at, n, set, &acc)?;
            let corner = |v: u32| {
                let [u, w] = uv[v as usize];
                Vec2::new(u, 1.0 - w)
            };
            out.uv.extend(tris.iter().map(|t| Some(t.map(corner))));
            out.corner_colours
                .extend(std::iter::repeat_n(None, tris.len()));
            return Ok(());
        }
        out.uv.extend(std::iter::repeat_n(None, tris.len()));
        if self.detail == Detail::TexCoords {
            out.corner_colours
                .extend(std::iter::repeat_n(None, tris.len()));
            return Ok(());
        }
        match prim.get(&Semantic::Colors(0)) {
            Some(acc) => {
                let encoded = self.vertex_colours(prim, at, n, &acc, pbr.base_color_factor())?;
                out.corner_colours
                    .extend(tris.iter().map(|t| Some(t.map(|v| encoded[v as usize]))));
            }
            None => out
                .corner_colours
                .extend(std::iter::repeat_n(None, tris.len())),
        }
        Ok(())
    }

    /// The `TEXCOORD_<set>` of the primitive's `n` vertices, as stored (glTF convention).
    fn texture_coordinates(
        &self,
        prim: &::gltf::Primitive<'_>,
        at: &str,
        n: usize,
        set: u32,
        acc: &::gltf::Accessor<'_>,
    ) -> Result<Vec<[f32; 2]>, MeshError> {
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let name = format!("TEXCOORD_{set}");
        check_accessor(
            acc,
            buffers,
            &[DataType::U8, DataType::U16, DataType::F32],
            &[Dimensions::Vec2],
            Some(n),
        )
        .map_err(|r| self.bad(at, &name, r))?;
        let uv: Vec<[f32; 2]> = reader
            .read_tex_coords(set)
            .ok_or_else(|| self.bad(at, &name, "unreadable".into()))?
            .into_f32()
            .collect();
        if let Some(k) = uv.iter().position(|c| !c.iter().all(|x| x.is_finite())) {
            return Err(self.bad(at, &name, format!("element {k} is not finite")));
        }
        if uv.len() != n {
            return Err(self.bad(at, &name, format!("{} of {n} read", uv.len())));
        }
        Ok(uv)
    }

    /// The `COLOR_0` of the primitive's `n` vertices times the material's `factor`, encoded to
    /// sRGB.
    fn vertex_colours(
        &self,
        prim: &::gltf::Primitive<'_>,
        at: &str,
        n: usize,
        acc: &::gltf::Accessor<'_>,
        factor: [f32; 4],
    ) -> Result<Vec<[f32; 3]>, MeshError> {
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        check_accessor(
            acc,
            buffers,
            &[DataType::U8, DataType::U16, DataType::F32],
            &[Dimensions::Vec3, Dimensions::Vec4],
            Some(n),
        )
        .map_err(|r| self.bad(at, "COLOR_0", r))?;
        let rgb: Vec<[f32; 3]> = reader
            .read_colors(0)
            .ok_or_else(|| self.bad(at, "COLOR_0", "unreadable".into()))?
            .into_rgb_f32()
            .collect();
        if rgb.len() != n {
            return Err(self.bad(at, "COLOR_0", format!("{} of {n} read", rgb.len())));
        }
        Ok(rgb
            .iter()
            .map(|c| std::array::from_fn(|k| linear_to_srgb(c[k] * factor[k])))
            .collect())
    }
}

/// A primitive's name in errors: its mesh (index and name) and its index.
fn primitive_name(mesh: &::gltf::Mesh<'_>, p: usize) -> String {
    match mesh.name() {
        Some(n) => format!("mesh {} `{n}`, primitive {p}", mesh.index()),
        None => format!("mesh {}, primitive {p}", mesh.index()),
    }
}
