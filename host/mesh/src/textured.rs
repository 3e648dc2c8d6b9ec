//! Textured head scans: the mesh with its colours, for finding printed targets on the scan.
//!
//! [`load_textured`] reads
//!
//! * **OBJ + MTL + texture**: `v`, `vt`, `f v/vt[/vn]`, `mtllib`, `usemtl` and the material's
//!   `map_Kd` image (PNG or JPEG, resolved against the MTL file's folder). Texture
//!   coordinates are kept per triangle corner (OBJ indexes them separately from the positions,
//!   so one vertex can have different coordinates in different triangles, at atlas seams);
//!   a face without `vt` shows its material's `Kd` colour.
//! * **PLY with vertex colours** (`red green blue`, any scalar type, see
//!   [`crate::ply::read_ply_coloured`]): colours interpolated barycentrically.
//! * **glTF 2.0**, binary (`.glb`, images in its binary chunk) or `.gltf` (external or
//!   data-URI buffers and images): every triangle primitive of the default scene with its node
//!   transforms, coloured by its material's base-colour texture (`TEXCOORD_0`), else its
//!   `COLOR_0` vertex colours (kept per triangle corner, so colours split at a seam stay
//!   apart), else its `baseColorFactor`; coordinates as stored, metres unless the caller's
//!   [`LengthUnit`] says otherwise (glTF is Y-up metres by specification). Details, and what is
//!   refused, in [`crate::gltf_scan`].
//!
//! The geometry goes through exactly the path of [`crate::load_mesh`] (same reader, unit
//! conversion and repair), so the mesh of a [`TexturedMesh`] equals the mesh `load_mesh` gives
//! for the same file; [`crate::validate::repair_tracked`] says where each repaired triangle
//! and vertex came from, so the colours follow dropped, welded and re-wound triangles.
//!
//! # Lookup
//!
//! [`TexturedMesh::colour_at`] takes a [`Hit`] (triangle and barycentrics `u`, `v` of its
//! second and third corner): the texture coordinate is `uv = (1-u-v) uv0 + u uv1 + v uv2` and
//! the texture is sampled bilinearly between the four nearest texel centres. OBJ puts `v = 0`
//! at the bottom of the image, texel `(i, j)` (column, row from the top) has its centre at
//! `((i + 0.5) / W, 1 - (j + 0.5) / H)`, and coordinates outside `[0, 1]` repeat (the OBJ
//! default). glTF puts `v = 0` at the top: its coordinates are flipped to the OBJ convention
//! on loading (`v = 1 - v_gltf`), so one lookup serves both.
//!
//! # Colour space
//!
//! Colours are display values, 0..1: what an OBJ's PNG or JPEG texture and a PLY's vertex
//! colours store (sRGB-encoded), scaled, with no gamma conversion. A glTF base-colour texture
//! is sRGB-encoded by specification and is kept as stored too; glTF's `COLOR_0` and
//! `baseColorFactor` are linear by specification and are encoded to sRGB on loading, so the
//! same print gives the same colour in every format. Finding targets needs only the print's
//! contrast, which either encoding keeps; what matters is that all formats agree.

use std::path::Path;

use glam::Vec2;
use skinbrdf_core::untrusted::ConfineError;
use skinbrdf_core::TriMesh;

use crate::bvh::Hit;
use crate::error::{unknown_format, MeshError};
pub use crate::limits::MAX_TEXTURE_TEXELS;
use crate::load::LoadedMesh;
use crate::load_options::{gltf_unit, scale_to_metres, LengthUnit, LoadOptions};
pub use crate::material::{Material, TextureImage, UNTEXTURED_COLOUR};
pub use crate::obj::obj_companion_files;
use crate::obj::{read_obj_data, texture_file};
use crate::validate::{repair_tracked, MeshReport, RepairMap};

/// How a scan's surface is coloured.
#[derive(Debug, Clone, PartialEq)]
pub enum Appearance {
    /// Texture-mapped (OBJ, glTF): per triangle its material and, when it has `vt` (glTF:
    /// texture coordinates for its material's texture), the texture coordinates of its three
    /// corners (in the order of the mesh's triangle, OBJ convention).
    Texture {
        /// Texture coordinates per triangle corner (`None`: the face has no `vt`).
        uv: Vec<Option<[Vec2; 3]>>,
        /// Material index per triangle (`None`: no `usemtl`; glTF: no material).
        material: Vec<Option<u32>>,
        /// The materials.
        materials: Vec<Material>,
        /// Colours per triangle corner, which win over the material (glTF `COLOR_0` on a
        /// primitive without a base-colour texture); empty for OBJ.
        corner_colours: Vec<Option<[[f32; 3]; 3]>>,
    },
    /// A colour per vertex (PLY `red green blue`).
    VertexColours(Vec<[f32; 3]>),
    /// No colour information.
    None,
}

/// A loaded scan in metres with its appearance.
#[derive(Debug, Clone)]
pub struct TexturedMesh {
    /// The mesh, metres (as [`crate::load_mesh`] loads it).
    pub mesh: TriMesh,
    /// Its colours.
    pub appearance: Appearance,
    /// The unit the file was read in.
    pub unit: LengthUnit,
    /// Validation and repair.
    pub report: MeshReport,
}

impl TexturedMesh {
    /// The surface colour at a ray hit (see the module docs). A hit on a triangle the mesh
    /// does not have gives [`UNTEXTURED_COLOUR`].
    pub fn colour_at(&self, hit: &Hit) -> [f32; 3] {
        let t = hit.triangle as usize;
        let w = [1.0 - hit.u - hit.v, hit.u, hit.v];
        match &self.appearance {
            Appearance::Texture {
                uv,
                material,
                materials,
                corner_colours,
            } => {
                if let Some(c) = corner_colours.get(t).copied().flatten() {
                    return std::array::from_fn(|k| {
                        w[0] * c[0][k] + w[1] * c[1][k] + w[2] * c[2][k]
                    });
                }
                let mat = material
                    .get(t)
                    .copied()
                    .flatten()
                    .and_then(|m| materials.get(m as usize));
                let Some(mat) = mat else {
                    return UNTEXTURED_COLOUR;
                };
                match (&mat.texture, uv.get(t).copied().flatten()) {
                    (Some(tex), Some(c)) => tex.bilinear(c[0] * w[0] + c[1] * w[1] + c[2] * w[2]),
                    _ => mat.diffuse,
                }
            }
            Appearance::VertexColours(colours) => {
                let Some(tri) = self.mesh.indices.get(t) else {
                    return UNTEXTURED_COLOUR;
                };
                let mut out = [0.0f32; 3];
                for (k, &v) in tri.iter().enumerate() {
                    let c = colours
                        .get(v as usize)
                        .copied()
                        .unwrap_or(UNTEXTURED_COLOUR);
                    for (o, ci) in out.iter_mut().zip(c) {
                        *o += w[k] * ci;
                    }
                }
                out
            }
            Appearance::None => UNTEXTURED_COLOUR,
        }
    }

    /// The luma (Rec. 709 weights) of [`Self::colour_at`].
    pub fn grey_at(&self, hit: &Hit) -> f32 {
        let [r, g, b] = self.colour_at(hit);
        0.2126 * r + 0.7152 * g + 0.0722 * b
    }
}

/// Loads a scan with its colours: `.obj` (with its MTL and textures), `.ply` (with vertex
/// colours when it has them), `.glb` or `.gltf` (with its base-colour textures or vertex
/// colours), in metres, repaired per `opts` exactly as [`crate::load_mesh`].
pub fn load_textured(path: &Path, opts: &LoadOptions) -> Result<TexturedMesh, MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let source = path.display().to_string();
    match ext.as_deref() {
        Some("ply") => {
            let (mut mesh, _, colours) = crate::ply::read_ply_coloured(path)?;
            let unit = scale_to_metres(&mut mesh, opts.unit);
            let (mesh, report, map) = repair_tracked(&mesh, opts.policy, &source)?;
            let appearance = match colours {
                Some(c) => Appearance::VertexColours(
                    map.vertices
                        .iter()
                        .map(|&v| c.get(v as usize).copied().unwrap_or(UNTEXTURED_COLOUR))
                        .collect(),
                ),
                None => Appearance::None,
            };
            Ok(TexturedMesh {
                mesh,
                appearance,
                unit,
                report,
            })
        }
        Some("obj") => {
            let mut data = read_obj_data(path)?;
            let materials = match std::mem::replace(&mut data.materials, Ok(Vec::new())) {
                Ok(m) => m,
                Err(files) => {
                    return Err(MeshError::MissingMaterialLibrary {
                        path: path.to_path_buf(),
                        libraries: files,
                    })
                }
            };
            let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
            let mut mats = Vec::with_capacity(materials.len());
            for m in materials {
                let (texture, texture_path) = match &m.diffuse_texture {
                    Some(t) if !t.trim().is_empty() => {
                        let file = match texture_file(&dir, t) {
                            Ok(f) => f,
                            Err(ConfineError::Missing { path: texture, .. }) => {
                                return Err(MeshError::MissingTexture {
                                    path: path.to_path_buf(),
                                    material: m.name.clone(),
                                    texture,
                                })
                            }
                            Err(reason) => {
                                return Err(MeshError::Refused {
                                    path: path.to_path_buf(),
                                    key: format!("material `{}` map_Kd", m.name),
                                    reason: Box::new(reason),
                                })
                            }
                        };
                        (Some(TextureImage::load(&file)?), Some(file))
                    }
                    _ => (None, None),
                };
                mats.push(Material {
                    name: m.name.clone(),
                    diffuse: m.diffuse.unwrap_or(UNTEXTURED_COLOUR),
                    texture,
                    texture_path,
                });
            }
            if let Some(t) = data
                .material
                .iter()
                .position(|m| m.is_some_and(|m| m as usize >= mats.len()))
            {
                return Err(MeshError::Parse {
                    path: path.to_path_buf(),
                    reason: format!("triangle {t} uses a material the MTL files do not define"),
                });
            }
            let unit = scale_to_metres(&mut data.mesh, opts.unit);
            let (mesh, report, map) = repair_tracked(&data.mesh, opts.policy, &source)?;
            let (uv, material) = follow_repair(&map, &data.uv, &data.material);
            let appearance = if mats.is_empty() && uv.iter().all(Option::is_none) {
                Appearance::None
            } else {
                Appearance::Texture {
                    uv,
                    material,
                    materials: mats,
                    corner_colours: Vec::new(),
                }
            };
            Ok(TexturedMesh {
                mesh,
                appearance,
                unit,
                report,
            })
        }
        Some("glb" | "gltf") => {
            let mut data = crate::gltf_scan::read_gltf(path, crate::gltf_scan::Detail::Appearance)?;
            let unit = scale_to_metres(&mut data.mesh, gltf_unit(opts.unit));
            let (mesh, report, map) = repair_tracked(&data.mesh, opts.policy, &source)?;
            let (uv, material) = follow_repair(&map, &data.uv, &data.material);
            let corner_colours: Vec<Option<[[f32; 3]; 3]>> = map
                .triangles
                .iter()
                .map(|&(t, flipped)| {
                    data.corner_colours
                        .get(t as usize)
                        .copied()
                        .flatten()
                        .map(|c| std::array::from_fn(|k| c[RepairMap::input_corner(flipped, k)]))
                })
                .collect();
            let appearance =
                if data.materials.is_empty() && corner_colours.iter().all(Option::is_none) {
                    Appearance::None
                } else {
                    Appearance::Texture {
                        uv,
                        material,
                        materials: data.materials,
                        corner_colours,
                    }
                };
            Ok(TexturedMesh {
                mesh,
                appearance,
                unit,
                report,
            })
        }
        _ => Err(unknown_format(path)),
    }
}

/// Texture coordinates per triangle corner of a loaded mesh (`None`: the triangle has none),
/// OBJ convention (`v = 0` at the bottom of the image; glTF's are flipped on loading).
pub type CornerUv = Vec<Option<[Vec2; 3]>>;

/// [`crate::load_mesh`] (the same mesh, units and repair), with the texture coordinates of
/// each triangle's corners when the scan has them: an OBJ's `vt`, a glTF's `TEXCOORD_n` of
/// a base-colour texture (as [`load_textured`] reads them). No texture image is decoded and
/// a missing material library is no error, as for [`crate::load_mesh`]. `None` for a PLY,
/// and for a scan none of whose triangles has texture coordinates.
pub fn load_mesh_with_uv(
    path: &Path,
    opts: &LoadOptions,
) -> Result<(LoadedMesh, Option<CornerUv>), MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let source = path.display().to_string();
    let (mut mesh, uv, material, unit) = match ext.as_deref() {
        Some("obj") => {
            let data = read_obj_data(path)?;
            (data.mesh, data.uv, data.material, opts.unit)
        }
        Some("glb" | "gltf") => {
            let data = crate::gltf_scan::read_gltf(path, crate::gltf_scan::Detail::TexCoords)?;
            (data.mesh, data.uv, data.material, gltf_unit(opts.unit))
        }
        _ => return Ok((crate::load_mesh(path, opts)?, None)),
    };
    let unit = scale_to_metres(&mut mesh, unit);
    let (mesh, report, map) = repair_tracked(&mesh, opts.policy, &source)?;
    let (uv, _) = follow_repair(&map, &uv, &material);
    let uv = uv.iter().any(Option::is_some).then_some(uv);
    Ok((LoadedMesh { mesh, unit, report }, uv))
}

/// Per-triangle attributes of the input carried to the repaired mesh.
#[allow(clippy::type_complexity)]
fn follow_repair(
    map: &RepairMap,
    uv: &[Option<[Vec2; 3]>],
    material: &[Option<u32>],
) -> (Vec<Option<[Vec2; 3]>>, Vec<Option<u32>>) {
    map.triangles
        .iter()
        .map(|&(t, flipped)| {
            let t = t as usize;
            let c = uv
                .get(t)
                .copied()
                .flatten()
                .map(|c| std::array::from_fn(|k| c[RepairMap::input_corner(flipped, k)]));
            (c, material.get(t).copied().flatten())
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use std::path::PathBuf;

    fn quad_obj(dir: &Path, with_texture: bool) -> PathBuf {
        let obj = dir.join("quad.obj");
        std::fs::write(
            &obj,
            "mtllib quad.mtl\nv 0 0 0\nv 0.1 0 0\nv 0.1 0.1 0\nv 0 0.1 0\n\
             vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl paper\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
        )
        .expect("write obj");
        let map = if with_texture {
            "map_Kd quad.png\n"
        } else {
            ""
        };
        std::fs::write(
            dir.join("quad.mtl"),
            format!("newmtl paper\nKd 0.2 0.4 0.6\n{map}"),
        )
        .expect("write mtl");
        obj
    }

    #[test]
    fn texture_coordinates_load_without_the_texture() {
        let dir = tempfile::tempdir().expect("tempdir");
        // `map_Kd quad.png` names an image that is not there: no error, it is not read.
        let obj = quad_obj(dir.path(), true);
        let opts = LoadOptions::default();
        let (loaded, uv) = load_mesh_with_uv(&obj, &opts).expect("load with uv");
        assert_eq!(
            loaded.mesh,
            crate::load_mesh(&obj, &opts).expect("load_mesh").mesh
        );
        let uv = uv.expect("the quad has vt");
        // The corners' `vt` follow the mesh's triangles: uv = position / 0.1 on this quad.
        for (t, c) in uv.iter().enumerate() {
            let c = c.expect("every face has vt");
            for (k, p) in loaded.mesh.triangle(t).iter().enumerate() {
                assert!((c[k] - p.truncate() / 0.1).length() < 1e-6, "{t}/{k}");
            }
        }
        // No `vt`: no coordinates.
        let bare = dir.path().join("bare.obj");
        std::fs::write(&bare, "v 0 0 0\nv 0.1 0 0\nv 0.1 0.1 0\nf 1 2 3\n").expect("write");
        assert!(load_mesh_with_uv(&bare, &opts).expect("load").1.is_none());
    }

    #[test]
    fn obj_texture_is_sampled_bilinearly_with_v_up() {
        let dir = tempfile::tempdir().expect("tempdir");
        let obj = quad_obj(dir.path(), true);
        // 2 x 2 texels: top row black, white; bottom row red, blue.
        let mut img = image::RgbImage::new(2, 2);
        img.put_pixel(0, 0, image::Rgb([0, 0, 0]));
        img.put_pixel(1, 0, image::Rgb([255, 255, 255]));
        img.put_pixel(0, 1, image::Rgb([255, 0, 0]));
        img.put_pixel(1, 1, image::Rgb([0, 0, 255]));
        img.save(dir.path().join("quad.png")).expect("png");
        let t = load_textured(&obj, &LoadOptions::default()).expect("load");
        let plain = crate::load_mesh(&obj, &LoadOptions::default()).expect("load_mesh");
        assert_eq!(t.mesh, plain.mesh);
        let bvh = crate::MeshBvh::build(&t.mesh, crate::BuildQuality::Fast).expect("bvh");
        let at = |x: f32, y: f32| {
            let hit = bvh
                .intersect(Vec3::new(x, y, 1.0), -Vec3::Z, 10.0)
                .expect("hit");
            t.colour_at(&hit)
        };
        // Texel centres: (0.25, 0.75) is the top-left texel (black), (0.25, 0.25) the
        // bottom-left (red).
        let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4);
        assert!(
            close(at(0.025, 0.075), [0.0, 0.0, 0.0]),
            "{:?}",
            at(0.025, 0.075)
        );
        assert!(close(at(0.025, 0.025), [1.0, 0.0, 0.0]));
        assert!(close(at(0.075, 0.025), [0.0, 0.0, 1.0]));
        // Half-way between red and blue.
        assert!(
            close(at(0.05, 0.025), [0.5, 0.0, 0.5]),
            "{:?}",
            at(0.05, 0.025)
        );
    }

    #[test]
    fn a_jpeg_texture_loads() {
        let dir = tempfile::tempdir().expect("tempdir");
        let obj = quad_obj(dir.path(), false);
        std::fs::write(
            dir.path().join("quad.mtl"),
            "newmtl paper\nmap_Kd -bm 1.0 skin tone.jpg\n",
        )
        .expect("mtl");
        let img = image::RgbImage::from_pixel(16, 16, image::Rgb([200, 150, 100]));
        img.save(dir.path().join("skin tone.jpg")).expect("jpeg");
        let t = load_textured(&obj, &LoadOptions::default()).expect("load");
        let hit = Hit {
            t_m: 1.0,
            triangle: 1,
            u: 0.3,
            v: 0.3,
        };
        let c = t.colour_at(&hit);
        for (got, want) in c.iter().zip([200.0f32, 150.0, 100.0]) {
            assert!((got * 255.0 - want).abs() < 4.0, "{c:?}");
        }
    }

    #[test]
    fn a_material_without_texture_shows_its_kd() {
        let dir = tempfile::tempdir().expect("tempdir");
        let obj = quad_obj(dir.path(), false);
        let t = load_textured(&obj, &LoadOptions::default()).expect("load");
        let hit = Hit {
            t_m: 1.0,
            triangle: 0,
            u: 0.2,
            v: 0.2,
        };
        assert_eq!(t.colour_at(&hit), [0.2, 0.4, 0.6]);
    }

    #[test]
    fn missing_texture_and_library_and_bad_uv_name_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let obj = quad_obj(dir.path(), true);
        let e = load_textured(&obj, &LoadOptions::default()).expect_err("no png");
        assert!(matches!(e, MeshError::MissingTexture { .. }), "{e}");
        let s = e.to_string();
        assert!(
            s.contains("quad.obj") && s.contains("quad.png") && s.contains("paper"),
            "{s}"
        );
        // The geometry alone still loads.
        assert!(crate::load_mesh(&obj, &LoadOptions::default()).is_ok());

        std::fs::remove_file(dir.path().join("quad.mtl")).expect("rm");
        let e = load_textured(&obj, &LoadOptions::default()).expect_err("no mtl");
        assert!(e.to_string().contains("quad.mtl"), "{e}");
        assert!(crate::load_mesh(&obj, &LoadOptions::default()).is_ok());

        let bad = dir.path().join("bad.obj");
        std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/7\n").expect("w");
        let e = load_textured(&bad, &LoadOptions::default()).expect_err("bad vt");
        let s = e.to_string();
        assert!(
            matches!(e, MeshError::BadUv { .. }) || s.contains("bad.obj"),
            "{s}"
        );
        assert!(s.contains("bad.obj"), "{s}");
    }

    #[test]
    fn ply_vertex_colours_are_interpolated() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("c.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n\
             0 0 0 255 0 0\n0.1 0 0 0 255 0\n0 0.1 0 0 0 255\n3 0 1 2\n",
        )
        .expect("write");
        let t = load_textured(&p, &LoadOptions::default()).expect("load");
        assert!(matches!(t.appearance, Appearance::VertexColours(_)));
        let hit = Hit {
            t_m: 1.0,
            triangle: 0,
            u: 0.25,
            v: 0.5,
        };
        let c = t.colour_at(&hit);
        assert!((c[0] - 0.25).abs() < 1e-6 && (c[1] - 0.25).abs() < 1e-6);
        assert!((c[2] - 0.5).abs() < 1e-6, "{c:?}");
        assert!((t.grey_at(&hit) - (0.2126 * 0.25 + 0.7152 * 0.25 + 0.0722 * 0.5)).abs() < 1e-6);
    }
}
