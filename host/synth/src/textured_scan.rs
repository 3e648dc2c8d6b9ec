//! The studio's textured head scan: what a structured-light scanner with a colour camera writes
//! when it scans the head wearing the headdress.
//!
//! [`write_textured_scan`] writes `head.obj`, `head.mtl` and `head.png` (one texture atlas):
//!
//! * the **head**: the true surface's front part tessellated at `geometry.scan_spacing_m` with
//!   Gaussian noise of `geometry.scan_noise_m` per vertex coordinate (as `scan.ply`, see
//!   [`crate::generate::make_scan`]), a plain skin colour;
//! * every **headdress target's paper**: the true target plane ([`Rig::headdress`]), a square
//!   [`PAPER_HALF_EXTENT`] tag half-edges wide, tessellated [`PAPER_CELLS`] x [`PAPER_CELLS`]
//!   with noise of the same size along the paper's normal only, textured with the printed
//!   tag36h11 pattern (black border, data cells, white ring and paper) at about [`TEXEL_M`] per
//!   texel, each texel the [`SUPERSAMPLE`]² box-filtered print (a scanner's camera averages
//!   over its pixel). A scanner projects its colour images onto the measured surface, so its
//!   error moves the print with the surface along the viewing direction (depth, here the
//!   paper's normal), not sideways across the paper.
//!
//! Everything is in the **scanner frame**: `scanner_from_head` ([`scanner_from_head`]) is a
//! rotation of tens of degrees and a translation of tens of centimetres drawn from the scene's
//! seed, so nothing downstream can lean on the scan sharing the head frame. Coordinates are
//! written in the scene's `geometry.scan_units`.
//!
//! The same scan in other formats, when the scene's `[studio] scan_formats` (or
//! [`write_textured_scan_as`]) asks for them: `head.glb`, binary glTF in metres with the atlas
//! embedded, which loads to the OBJ's mesh vertex for vertex
//! ([`skinbrdf_mesh::write_glb`]); `head-colours.ply`, PLY with vertex colours, the same
//! surface with each paper cell's triangles subdivided [`PLY_SUBDIVISION`] times per side on
//! their own planes so that colours per vertex carry the print.
//!
//! `scan-truth.json` beside them ([`ScanTruth`]) holds `scanner_from_head` and each headdress
//! target's true corners in the scanner frame (metres), for scoring only.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::{DQuat, DVec2, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use skinbrdf_core::Pose;
use skinbrdf_session::write::write_png_rgb8;

use crate::generate::SynthError;
use crate::layout::{Rig, PAPER_HALF_EXTENT};
use crate::scene::Scene;

/// Texture resolution on the target papers, metres per texel (0.2 mm: a 25 mm tag's 3.1 mm
/// cells are ~16 texels, as a scanner's colour camera at ~30 cm resolves them).
pub const TEXEL_M: f64 = 0.0002;
/// Box-filter samples per texel side when painting the print.
pub const SUPERSAMPLE: usize = 4;
/// Quads per side of a paper's tessellation (a scanner samples a flat paper densely; the
/// vertex noise then bends it slightly).
pub const PAPER_CELLS: usize = 8;
/// Blank texels around each paper's tile in the atlas (bilinear lookups at a tile's edge stay
/// inside the tile's own paper colour).
const GUTTER_TX: usize = 2;
/// The skin's colour in the texture (sRGB-encoded 8-bit).
pub const SKIN_RGB8: [u8; 3] = [204, 156, 132];
/// The paper's white and the ink's black (8-bit grey).
pub const PAPER_WHITE8: u8 = 235;
/// See [`PAPER_WHITE8`].
pub const INK_BLACK8: u8 = 20;
/// Subdivisions per paper-cell side in `head-colours.ply`: a scan that stores its colour per
/// vertex needs vertices as dense as the print's detail, so the papers' cells (about 4.7 mm
/// for a 25 mm tag) are cut into 8 x 8 on their own triangles' planes (the same surface):
/// colours about 0.6 mm apart, five per 3.1 mm tag cell.
pub const PLY_SUBDIVISION: usize = 8;
/// Seed salt of the scanner pose and the scan noise.
const SEED_SALT: u64 = 0x5ca9_7e57;

/// The files [`write_textured_scan`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct TexturedScanFiles {
    /// The OBJ mesh.
    pub obj: PathBuf,
    /// Its material library.
    pub mtl: PathBuf,
    /// The texture atlas.
    pub png: PathBuf,
    /// The same scan as binary glTF (`head.glb`, metres, the atlas embedded), when asked for.
    pub glb: Option<PathBuf>,
    /// The same surface as PLY with vertex colours (`head-colours.ply`, the papers subdivided
    /// by [`PLY_SUBDIVISION`]), when asked for.
    pub ply: Option<PathBuf>,
    /// The scoring truth.
    pub truth: PathBuf,
    /// Vertices written.
    pub vertices: usize,
    /// Triangles written.
    pub triangles: usize,
    /// Texture size, texels.
    pub texture_px: (u32, u32),
}

/// One headdress target's truth in the scanner frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanTruthTarget {
    /// tag36h11 id.
    pub id: u32,
    /// Black-square edge, metres.
    pub size_m: f64,
    /// The four corners (session order: bottom-left, bottom-right, top-right, top-left),
    /// scanner frame, metres.
    pub corners_m: [DVec3; 4],
}

/// `scan-truth.json`: where the scan really is (scoring only).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanTruth {
    /// Scanner from head.
    pub scanner_from_head: Pose,
    /// Every headdress target, scanner frame.
    pub targets: Vec<ScanTruthTarget>,
}

/// The scan's frame relative to the head frame: a rotation of 20..60 degrees about a random
/// axis and a translation of 10..40 cm along each axis (random signs), from the scene's seed.
pub fn scanner_from_head(scene: &Scene) -> Pose {
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed ^ SEED_SALT);
    let axis = loop {
        let a = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        if (0.1..=1.0).contains(&a.length()) {
            break a.normalize();
        }
    };
    let angle = rng.random_range(20f64..60.0).to_radians();
    let t = DVec3::from_array(std::array::from_fn(|_| {
        let s = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        s * rng.random_range(0.1..0.4)
    }));
    Pose::new(DQuat::from_axis_angle(axis, angle), t)
}

/// The truth of the scan of `scene`.
pub fn scan_truth(scene: &Scene, rig: &Rig) -> ScanTruth {
    let pose = scanner_from_head(scene);
    ScanTruth {
        scanner_from_head: pose,
        targets: rig
            .headdress
            .iter()
            .map(|t| ScanTruthTarget {
                id: t.id,
                size_m: t.size_m,
                corners_m: t.corners_m.map(|c| pose.transform_point(c)),
            })
            .collect(),
    }
}

/// A paper's tile in the atlas.
#[derive(Debug, Clone, Copy)]
struct Tile {
    x0: usize,
    y0: usize,
}

/// The formats a textured scan is written in (`[studio] scan_formats`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScanFormat {
    /// `head.obj` + `head.mtl` + `head.png` (always written).
    Obj,
    /// `head.glb`: binary glTF, metres, the atlas embedded.
    Glb,
    /// `head-colours.ply`: PLY with vertex colours.
    Ply,
}

impl ScanFormat {
    /// The format's name in a scene file (`obj`, `glb`, `ply`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Obj => "obj",
            Self::Glb => "glb",
            Self::Ply => "ply",
        }
    }
}

/// Writes `head.obj`, `head.mtl`, `head.png` and `scan-truth.json` into `dir` (see the module
/// docs), and `head.glb` and `head-colours.ply` when the scene's `[studio] scan_formats` asks
/// for them.
pub fn write_textured_scan(
    dir: &Path,
    scene: &Scene,
    rig: &Rig,
) -> Result<TexturedScanFiles, SynthError> {
    write_textured_scan_as(dir, scene, rig, &scene.studio.scan_formats)
}

/// [`write_textured_scan`] with the formats given (the OBJ is written whatever they say).
pub fn write_textured_scan_as(
    dir: &Path,
    scene: &Scene,
    rig: &Rig,
    formats: &[ScanFormat],
) -> Result<TexturedScanFiles, SynthError> {
    std::fs::create_dir_all(dir).map_err(|source| skinbrdf_session::FileError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let g = &scene.geometry;
    let truth = scan_truth(scene, rig);
    let pose = truth.scanner_from_head;
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed ^ SEED_SALT ^ 0x0b1);
    let noise_m = g.scan_noise_m;
    let mut noisy = |p: DVec3| {
        let n: [f64; 3] = std::array::from_fn(|_| StandardNormal.sample(&mut rng));
        pose.transform_point(p) + DVec3::from_array(n) * noise_m
    };
    let mut paper_rng = ChaCha8Rng::seed_from_u64(scene.seed ^ SEED_SALT ^ 0x0b2);
    let scale = 1.0 / g.scan_units.to_m();

    // Atlas layout: one tile per paper, then a small skin tile.
    let paper_edge_m = |size_m: f64| size_m * PAPER_HALF_EXTENT;
    let tile_tx = rig
        .headdress
        .iter()
        .map(|t| (paper_edge_m(t.size_m) / TEXEL_M).round() as usize)
        .max()
        .unwrap_or(16)
        .max(16);
    let pitch = tile_tx + 2 * GUTTER_TX;
    let n_tiles = rig.headdress.len() + 1;
    let cols = (n_tiles as f64).sqrt().ceil() as usize;
    let rows = n_tiles.div_ceil(cols);
    let (w, h) = (cols * pitch, rows * pitch);
    let tile = |k: usize| Tile {
        x0: (k % cols) * pitch + GUTTER_TX,
        y0: (k / cols) * pitch + GUTTER_TX,
    };
    let uv_of = |t: Tile, fx: f64, fy: f64| {
        // fx, fy in [0, 1] across the tile, fy down the image.
        DVec2::new(
            (t.x0 as f64 + fx * tile_tx as f64) / w as f64,
            1.0 - (t.y0 as f64 + fy * tile_tx as f64) / h as f64,
        )
    };

    // Texture.
    let mut rgb = vec![0u8; 3 * w * h];
    for px in rgb.chunks_exact_mut(3) {
        px.copy_from_slice(&SKIN_RGB8);
    }
    let bits: Vec<Option<[[bool; 10]; 10]>> = rig
        .headdress
        .iter()
        .map(|t| skinbrdf_targets::tag36h11::tag_bits(t.id as usize))
        .collect();
    let row_len = 3 * w;
    rgb.par_chunks_mut(row_len)
        .enumerate()
        .for_each(|(y, row)| {
            for (k, b) in bits.iter().enumerate() {
                let t = tile(k);
                if y + GUTTER_TX < t.y0 || y >= t.y0 + tile_tx + GUTTER_TX {
                    continue;
                }
                for x in t.x0.saturating_sub(GUTTER_TX)..t.x0 + tile_tx + GUTTER_TX {
                    let mut acc = 0.0;
                    for sy in 0..SUPERSAMPLE {
                        for sx in 0..SUPERSAMPLE {
                            let fx = (x as f64 - t.x0 as f64
                                + (sx as f64 + 0.5) / SUPERSAMPLE as f64)
                                / tile_tx as f64;
                            let fy = (y as f64 - t.y0 as f64
                                + (sy as f64 + 0.5) / SUPERSAMPLE as f64)
                                / tile_tx as f64;
                            let uv = DVec2::new(fx, fy) * (2.0 * PAPER_HALF_EXTENT)
                                - DVec2::splat(PAPER_HALF_EXTENT);
                            let white = match b {
                                Some(bits) => {
                                    skinbrdf_targets::render::tag_value_at(bits, uv).unwrap_or(true)
                                }
                                None => true,
                            };
                            acc += if white { PAPER_WHITE8 } else { INK_BLACK8 } as f64;
                        }
                    }
                    let v = (acc / (SUPERSAMPLE * SUPERSAMPLE) as f64).round() as u8;
                    row[3 * x..3 * x + 3].copy_from_slice(&[v, v, v]);
                }
            }
        });
    let png = dir.join("head.png");
    write_png_rgb8(&png, w as u32, h as u32, &rgb)?;

    // Geometry, scanner frame, metres: the head, then each paper's (PAPER_CELLS + 1)² grid.
    let head = rig.shape.tessellate(
        g.scan_spacing_m,
        (-80f64.to_radians(), 80f64.to_radians()),
        (-35f64.to_radians(), 75f64.to_radians()),
    );
    let mut model = ScanModel::default();
    let skin_uv = uv_of(tile(n_tiles - 1), 0.5, 0.5);
    model.vt.push(skin_uv);
    for p in &head.positions {
        model.positions_m.push(noisy(p.as_dvec3()));
        model.vertex_vt.push(0);
    }
    for tri in &head.indices {
        model.triangles.push(*tri);
    }
    let e = PAPER_HALF_EXTENT;
    for (k, t) in rig.headdress.iter().enumerate() {
        let [c0, c1, _, c3] = t.corners_m;
        let x = (c1 - c0).normalize_or(DVec3::X);
        let y = (c0 - c3).normalize_or(DVec3::Y);
        let out = -(x.cross(y));
        let centre = t.centre();
        let half = 0.5 * t.size_m;
        let tl = tile(k);
        let n = PAPER_CELLS + 1;
        let v0 = model.positions_m.len();
        for j in 0..n {
            for i in 0..n {
                let (fx, fy) = (i as f64 / PAPER_CELLS as f64, j as f64 / PAPER_CELLS as f64);
                let (u, v) = ((2.0 * fx - 1.0) * e, (2.0 * fy - 1.0) * e);
                let depth: f64 = StandardNormal.sample(&mut paper_rng);
                let p = centre + x * (u * half) + y * (v * half) + out * (depth * noise_m);
                model.positions_m.push(pose.transform_point(p));
                model.vertex_vt.push(model.vt.len());
                model.vt.push(uv_of(tl, fx, fy));
            }
        }
        model.papers.push(PaperGrid {
            first_vertex: v0,
            first_triangle: model.triangles.len(),
            uv_corner: [uv_of(tl, 0.0, 0.0), uv_of(tl, 1.0, 1.0)],
        });
        let vi = |i: usize, j: usize| (v0 + j * n + i) as u32;
        for j in 0..PAPER_CELLS {
            for i in 0..PAPER_CELLS {
                let (a, b, c, d) = (vi(i, j), vi(i + 1, j), vi(i + 1, j + 1), vi(i, j + 1));
                // Counter-clockwise seen from the printed side (x right, y down, out = -x×y).
                model.triangles.push([a, c, b]);
                model.triangles.push([a, d, c]);
            }
        }
    }
    let obj_path = dir.join("head.obj");
    skinbrdf_session::write_atomic(
        &obj_path,
        model.obj_text(unit_word(scene), scale).as_bytes(),
    )?;
    let mtl_path = dir.join("head.mtl");
    skinbrdf_session::write_atomic(
        &mtl_path,
        b"# skinbrdf synthetic textured head scan\nnewmtl scan\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nmap_Kd head.png\n",
    )?;
    let glb = if formats.contains(&ScanFormat::Glb) {
        let path = dir.join("head.glb");
        let png_bytes = std::fs::read(&png).map_err(|source| skinbrdf_session::FileError::Io {
            path: png.clone(),
            source,
        })?;
        let (mesh, uv) = model.mesh_with_corner_uv();
        skinbrdf_mesh::write_glb(&path, &mesh, &uv, &png_bytes)?;
        Some(path)
    } else {
        None
    };
    let ply = if formats.contains(&ScanFormat::Ply) {
        let path = dir.join("head-colours.ply");
        let texture = skinbrdf_mesh::TextureImage {
            width: w as u32,
            height: h as u32,
            rgb: rgb
                .chunks_exact(3)
                .map(|c| std::array::from_fn(|k| f32::from(c[k]) / 255.0))
                .collect(),
        };
        let (mesh, colours) = model.vertex_coloured(&texture, scale);
        skinbrdf_mesh::write_ply_binary_coloured_in(&path, &mesh, &colours, unit_word(scene))?;
        Some(path)
    } else {
        None
    };
    let truth_path = dir.join("scan-truth.json");
    skinbrdf_session::write_json_atomic(&truth_path, &truth)?;
    Ok(TexturedScanFiles {
        obj: obj_path,
        mtl: mtl_path,
        png,
        glb,
        ply,
        truth: truth_path,
        vertices: model.positions_m.len(),
        triangles: model.triangles.len(),
        texture_px: (w as u32, h as u32),
    })
}

/// A paper's vertex grid in a [`ScanModel`].
#[derive(Debug, Clone, Copy)]
struct PaperGrid {
    /// Its vertex (0, 0); the grid is (PAPER_CELLS + 1)² row-major.
    first_vertex: usize,
    /// Its first triangle; two per cell, row-major.
    first_triangle: usize,
    /// Texture coordinates of grid corners (0, 0) and (n, n) (linear in between).
    uv_corner: [DVec2; 2],
}

/// The textured scan before it is written: positions in the scanner frame (metres), one
/// texture coordinate per vertex (OBJ convention; the head's vertices share the skin's).
#[derive(Debug, Default)]
struct ScanModel {
    positions_m: Vec<DVec3>,
    /// Per vertex, its index into `vt`.
    vertex_vt: Vec<usize>,
    vt: Vec<DVec2>,
    triangles: Vec<[u32; 3]>,
    papers: Vec<PaperGrid>,
}

impl ScanModel {
    /// The OBJ text: vertices in `scale` units per metre, then texture coordinates, then faces.
    fn obj_text(&self, unit_word: &str, scale: f64) -> String {
        let mut obj = String::with_capacity(64 * (self.positions_m.len() + 2 * self.vt.len()));
        let _ = writeln!(
            obj,
            "# skinbrdf synthetic textured head scan, {unit_word} (scanner frame)"
        );
        let _ = writeln!(obj, "mtllib head.mtl\no head");
        for p in &self.positions_m {
            let q = *p * scale;
            let _ = writeln!(obj, "v {:.5} {:.5} {:.5}", q.x, q.y, q.z);
        }
        for uv in &self.vt {
            let _ = writeln!(obj, "vt {:.7} {:.7}", uv.x, uv.y);
        }
        obj.push_str("usemtl scan\n");
        for t in &self.triangles {
            let [a, b, c] = t.map(|v| (v as usize + 1, self.vertex_vt[v as usize] + 1));
            let _ = writeln!(obj, "f {}/{} {}/{} {}/{}", a.0, a.1, b.0, b.1, c.0, c.1);
        }
        obj
    }

    /// The mesh in metres with each triangle's corners' texture coordinates (for GLB).
    fn mesh_with_corner_uv(&self) -> (skinbrdf_core::TriMesh, Vec<[glam::Vec2; 3]>) {
        let mesh = skinbrdf_core::TriMesh {
            positions: self.positions_m.iter().map(|p| p.as_vec3()).collect(),
            indices: self.triangles.clone(),
            normals: None,
        };
        let uv = self
            .triangles
            .iter()
            .map(|t| t.map(|v| self.vt[self.vertex_vt[v as usize]].as_vec2()))
            .collect();
        (mesh, uv)
    }

    /// The same surface with a colour per vertex (in `scale` units per metre, for PLY): the
    /// head as it is (its vertices the skin's colour), each paper cell's two triangles
    /// subdivided [`PLY_SUBDIVISION`] times along each side on their own planes, each vertex
    /// the texture's bilinear value at its texture coordinate.
    fn vertex_coloured(
        &self,
        texture: &skinbrdf_mesh::TextureImage,
        scale: f64,
    ) -> (skinbrdf_core::TriMesh, Vec<[u8; 3]>) {
        let to8 = |c: [f32; 3]| c.map(|x| (x * 255.0).round().clamp(0.0, 255.0) as u8);
        let first_paper_vertex = self
            .papers
            .first()
            .map_or(self.positions_m.len(), |p| p.first_vertex);
        let first_paper_tri = self
            .papers
            .first()
            .map_or(self.triangles.len(), |p| p.first_triangle);
        let mut mesh = skinbrdf_core::TriMesh::default();
        let mut colours = Vec::new();
        for p in &self.positions_m[..first_paper_vertex] {
            mesh.positions.push((*p * scale).as_vec3());
            colours.push(SKIN_RGB8);
        }
        mesh.indices
            .extend_from_slice(&self.triangles[..first_paper_tri]);
        let n = PAPER_CELLS + 1;
        let s = PLY_SUBDIVISION;
        let fine = PAPER_CELLS * s + 1;
        for paper in &self.papers {
            let coarse = |i: usize, j: usize| self.positions_m[paper.first_vertex + j * n + i];
            let base = mesh.positions.len() as u32;
            for jj in 0..fine {
                for ii in 0..fine {
                    let (i, j) = ((ii / s).min(PAPER_CELLS - 1), (jj / s).min(PAPER_CELLS - 1));
                    let (fs, ft) = (
                        (ii - i * s) as f64 / s as f64,
                        (jj - j * s) as f64 / s as f64,
                    );
                    let (a, b, c, d) = (
                        coarse(i, j),
                        coarse(i + 1, j),
                        coarse(i + 1, j + 1),
                        coarse(i, j + 1),
                    );
                    // The cell's triangles [a, c, b] (fs >= ft) and [a, d, c] (ft >= fs).
                    let p = if fs >= ft {
                        a + (b - a) * fs + (c - b) * ft
                    } else {
                        a + (d - a) * ft + (c - d) * fs
                    };
                    let f = DVec2::new(ii as f64, jj as f64) / (fine - 1) as f64;
                    let uv = paper.uv_corner[0] + (paper.uv_corner[1] - paper.uv_corner[0]) * f;
                    mesh.positions.push((p * scale).as_vec3());
                    colours.push(to8(texture.bilinear(uv.as_vec2())));
                }
            }
            let vi = |i: usize, j: usize| base + (j * fine + i) as u32;
            for j in 0..fine - 1 {
                for i in 0..fine - 1 {
                    let (a, b, c, d) = (vi(i, j), vi(i + 1, j), vi(i + 1, j + 1), vi(i, j + 1));
                    mesh.indices.push([a, c, b]);
                    mesh.indices.push([a, d, c]);
                }
            }
        }
        (mesh, colours)
    }
}

fn unit_word(scene: &Scene) -> &'static str {
    use skinbrdf_session::LengthUnit;
    match scene.geometry.scan_units {
        LengthUnit::M => "metres",
        LengthUnit::Cm => "centimetres",
        LengthUnit::Mm => "millimetres",
        LengthUnit::In => "inches",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_mesh::{Appearance, Hit, LoadOptions, TexturedMesh};

    /// OBJ and GLB positions agree within this, metres: the OBJ's 5 decimals of a millimetre
    /// and the f32 rounding of both (a few 1e-8 m at the scan's 0.5 m from the scanner's
    /// origin).
    const PARITY_POS_M: f32 = 1e-6;
    /// OBJ and GLB colours at the same hit agree within this: their texture coordinates differ
    /// by f32 rounding (glTF stores `1 - v`), a 1e-4 texel shift at most in a ~1000-texel atlas
    /// against a print contrast of 0.85.
    const PARITY_COLOUR: f32 = 1e-3;

    /// Probes three points of every target's print (a border cell near corner 0, the white ring
    /// beyond it, a data cell) with rays along its normal; returns how many were seen, after
    /// asserting each shows ink or paper as printed.
    fn probe_prints(scan: &TexturedMesh, truth: &ScanTruth) -> usize {
        let bvh = skinbrdf_mesh::MeshBvh::build(&scan.mesh, skinbrdf_mesh::BuildQuality::Fast)
            .expect("bvh");
        let mut checked = 0;
        for t in &truth.targets {
            let [c0, c1, c2, c3] = t.corners_m;
            let out = -((c1 - c0).cross(c0 - c3)).normalize();
            let bits = skinbrdf_targets::tag36h11::tag_bits(t.id as usize).expect("id");
            let centre = (c0 + c1 + c2 + c3) * 0.25;
            for (tag_uv, white) in [
                (DVec2::new(-0.875, 0.875), false),
                (DVec2::new(-1.125, 1.125), true),
                (DVec2::new(-0.375, -0.375), bits[3][3]),
            ] {
                let x = (c1 - c0).normalize();
                let y = (c0 - c3).normalize();
                let p = centre + (x * tag_uv.x + y * tag_uv.y) * (0.5 * t.size_m);
                let o = p + out * 0.05;
                let Some(hit) = bvh.intersect(o.as_vec3(), (-out).as_vec3(), 1.0) else {
                    continue;
                };
                let g = scan.grey_at(&hit);
                assert_eq!(g > 0.5, white, "target {} at {tag_uv:?}: grey {g}", t.id);
                checked += 1;
            }
        }
        checked
    }

    #[test]
    fn the_scan_loads_textured_and_the_papers_show_their_tags() {
        let scene = Scene::load("default").expect("scene");
        let rig = crate::layout::build_rig(&scene);
        let dir = tempfile::tempdir().expect("tempdir");
        let t0 = std::time::Instant::now();
        let files = write_textured_scan(dir.path(), &scene, &rig).expect("write");
        let took = t0.elapsed();
        assert!(
            files.glb.is_none() && files.ply.is_none(),
            "OBJ only by default"
        );
        let size: u64 = [&files.obj, &files.mtl, &files.png]
            .iter()
            .map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0))
            .sum();
        assert!(size < 30_000_000, "{size} bytes");
        eprintln!("textured scan: {size} bytes, {took:?}, {files:?}");
        let opts = LoadOptions::default();
        let scan = skinbrdf_mesh::load_textured(&files.obj, &opts).expect("load");
        assert_eq!(scan.mesh.indices.len(), files.triangles);
        let plain = skinbrdf_mesh::load_mesh(&files.obj, &opts).expect("load_mesh");
        assert_eq!(plain.mesh, scan.mesh);
        let truth = scan_truth(&scene, &rig);
        let checked = probe_prints(&scan, &truth);
        assert!(checked >= 3 * truth.targets.len() / 2, "{checked}");
        let back: ScanTruth =
            serde_json::from_slice(&std::fs::read(&files.truth).expect("read")).expect("json");
        assert_eq!(back.targets.len(), rig.headdress.len());
        let angle = truth
            .scanner_from_head
            .rotation
            .angle_between(DQuat::IDENTITY);
        assert!((20f64.to_radians()..60f64.to_radians()).contains(&angle));
    }

    #[test]
    fn the_glb_and_the_obj_give_the_same_mesh_and_colours_and_the_ply_shows_the_print() {
        let scene = Scene::load("default").expect("scene");
        let rig = crate::layout::build_rig(&scene);
        let dir = tempfile::tempdir().expect("tempdir");
        let only_obj = tempfile::tempdir().expect("tempdir");
        let t0 = std::time::Instant::now();
        write_textured_scan_as(only_obj.path(), &scene, &rig, &[ScanFormat::Obj]).expect("obj");
        let t_obj = t0.elapsed();
        let t0 = std::time::Instant::now();
        let files = write_textured_scan_as(
            dir.path(),
            &scene,
            &rig,
            &[ScanFormat::Obj, ScanFormat::Glb, ScanFormat::Ply],
        )
        .expect("write");
        let t_all = t0.elapsed();
        let (glb, ply) = (
            files.glb.clone().expect("glb"),
            files.ply.clone().expect("ply"),
        );
        let size = |p: &Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
        // The OBJ is the same whatever else is written.
        assert_eq!(
            std::fs::read(&files.obj).expect("obj"),
            std::fs::read(only_obj.path().join("head.obj")).expect("obj")
        );
        let opts = LoadOptions::default();
        let time = |p: &Path| {
            let t0 = std::time::Instant::now();
            let s = skinbrdf_mesh::load_textured(p, &opts).expect("load");
            (s, t0.elapsed())
        };
        let (from_obj, l_obj) = time(&files.obj);
        let (from_glb, l_glb) = time(&glb);
        let (from_ply, l_ply) = time(&ply);
        eprintln!(
            "write: obj+mtl+png {t_obj:?}, with glb and ply {t_all:?}; sizes: obj {} + png {}, \
             glb {}, ply {}; load_textured: obj {l_obj:?}, glb {l_glb:?}, ply {l_ply:?}",
            size(&files.obj),
            size(&files.png),
            size(&glb),
            size(&ply)
        );

        // Vertex for vertex, triangle for triangle.
        assert_eq!(from_glb.unit, skinbrdf_mesh::LengthUnit::Metres);
        assert_eq!(from_obj.unit, skinbrdf_mesh::LengthUnit::Millimetres);
        assert_eq!(from_glb.report, from_obj.report);
        assert_eq!(from_glb.mesh.positions.len(), from_obj.mesh.positions.len());
        assert_eq!(from_glb.mesh.indices.len(), from_obj.mesh.indices.len());
        let differ = (0..from_obj.mesh.indices.len())
            .find(|&t| from_glb.mesh.indices[t] != from_obj.mesh.indices[t]);
        assert!(
            differ.is_none(),
            "triangle {differ:?}: glb {:?}, obj {:?}",
            differ.map(|t| from_glb.mesh.indices[t]),
            differ.map(|t| from_obj.mesh.indices[t])
        );
        let worst = from_glb
            .mesh
            .positions
            .iter()
            .zip(&from_obj.mesh.positions)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0f32, f32::max);
        assert!(worst < PARITY_POS_M, "{worst} m");
        let plain = skinbrdf_mesh::load_mesh(&glb, &opts).expect("load_mesh");
        assert_eq!(plain.mesh, from_glb.mesh);

        // The same colour at the same hits: every triangle at its centroid and at two other
        // barycentrics near its corners.
        let mut worst = 0.0f32;
        let mut dark = 0;
        for t in 0..from_obj.mesh.indices.len() as u32 {
            for (u, v) in [(1.0 / 3.0, 1.0 / 3.0), (0.1, 0.05), (0.05, 0.85)] {
                let hit = Hit {
                    t_m: 1.0,
                    triangle: t,
                    u,
                    v,
                };
                let (a, b) = (from_obj.colour_at(&hit), from_glb.colour_at(&hit));
                for k in 0..3 {
                    worst = worst.max((a[k] - b[k]).abs());
                }
                dark += usize::from(a[0] < 0.2);
            }
        }
        assert!(worst < PARITY_COLOUR, "{worst}");
        assert!(dark > 1000, "the hits sample the print's ink too ({dark})");

        // The PLY: vertex colours, the same surface with the papers subdivided, the print
        // where it is printed.
        assert!(matches!(from_ply.appearance, Appearance::VertexColours(_)));
        let head_tris = from_obj.mesh.indices.len() - rig.headdress.len() * 2 * PAPER_CELLS.pow(2);
        assert_eq!(
            from_ply.mesh.indices.len(),
            head_tris + rig.headdress.len() * 2 * (PAPER_CELLS * PLY_SUBDIVISION).pow(2)
        );
        let truth = scan_truth(&scene, &rig);
        assert!(probe_prints(&from_ply, &truth) >= 3 * truth.targets.len() / 2);
        assert!(probe_prints(&from_glb, &truth) >= 3 * truth.targets.len() / 2);
    }
}
