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

/// Writes `head.obj`, `head.mtl`, `head.png` and `scan-truth.json` into `dir` (see the module
/// docs).
pub fn write_textured_scan(
    dir: &Path,
    scene: &Scene,
    rig: &Rig,
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

    // Geometry.
    let head = rig.shape.tessellate(
        g.scan_spacing_m,
        (-80f64.to_radians(), 80f64.to_radians()),
        (-35f64.to_radians(), 75f64.to_radians()),
    );
    let mut obj = String::with_capacity(64 * (head.positions.len() + 100 * n_tiles));
    let mut vt_lines = String::new();
    let _ = writeln!(
        obj,
        "# skinbrdf synthetic textured head scan, {} (scanner frame)",
        unit_word(scene)
    );
    let _ = writeln!(obj, "mtllib head.mtl\no head");
    let mut n_v = 0usize;
    let mut n_vt = 0usize;
    let mut faces = String::new();
    let mut n_f = 0usize;
    let skin_uv = uv_of(tile(n_tiles - 1), 0.5, 0.5);
    let _ = writeln!(vt_lines, "vt {:.7} {:.7}", skin_uv.x, skin_uv.y);
    n_vt += 1;
    let skin_vt = n_vt;
    for p in &head.positions {
        let q = noisy(p.as_dvec3()) * scale;
        let _ = writeln!(obj, "v {:.5} {:.5} {:.5}", q.x, q.y, q.z);
    }
    for tri in &head.indices {
        let [a, b, c] = tri.map(|i| i as usize + 1 + n_v);
        let _ = writeln!(faces, "f {a}/{skin_vt} {b}/{skin_vt} {c}/{skin_vt}");
        n_f += 1;
    }
    n_v += head.positions.len();
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
        for j in 0..n {
            for i in 0..n {
                let (fx, fy) = (i as f64 / PAPER_CELLS as f64, j as f64 / PAPER_CELLS as f64);
                let (u, v) = ((2.0 * fx - 1.0) * e, (2.0 * fy - 1.0) * e);
                let depth: f64 = StandardNormal.sample(&mut paper_rng);
                let p = centre + x * (u * half) + y * (v * half) + out * (depth * noise_m);
                let q = pose.transform_point(p) * scale;
                let _ = writeln!(obj, "v {:.5} {:.5} {:.5}", q.x, q.y, q.z);
                let uv = uv_of(tl, fx, fy);
                let _ = writeln!(vt_lines, "vt {:.7} {:.7}", uv.x, uv.y);
            }
        }
        let vi = |i: usize, j: usize| (n_v + j * n + i + 1, n_vt + j * n + i + 1);
        for j in 0..PAPER_CELLS {
            for i in 0..PAPER_CELLS {
                let (a, b, c, d) = (vi(i, j), vi(i + 1, j), vi(i + 1, j + 1), vi(i, j + 1));
                // Counter-clockwise seen from the printed side (x right, y down, out = -x×y).
                for [p, q, r] in [[a, c, b], [a, d, c]] {
                    let _ = writeln!(faces, "f {}/{} {}/{} {}/{}", p.0, p.1, q.0, q.1, r.0, r.1);
                    n_f += 1;
                }
            }
        }
        n_v += n * n;
        n_vt += n * n;
    }
    obj.push_str(&vt_lines);
    obj.push_str("usemtl scan\n");
    obj.push_str(&faces);
    let obj_path = dir.join("head.obj");
    skinbrdf_session::write_atomic(&obj_path, obj.as_bytes())?;
    let mtl_path = dir.join("head.mtl");
    skinbrdf_session::write_atomic(
        &mtl_path,
        b"# skinbrdf synthetic textured head scan\nnewmtl scan\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nmap_Kd head.png\n",
    )?;
    let truth_path = dir.join("scan-truth.json");
    skinbrdf_session::write_json_atomic(&truth_path, &truth)?;
    Ok(TexturedScanFiles {
        obj: obj_path,
        mtl: mtl_path,
        png,
        truth: truth_path,
        vertices: n_v,
        triangles: n_f,
        texture_px: (w as u32, h as u32),
    })
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

    #[test]
    fn the_scan_loads_textured_and_the_papers_show_their_tags() {
        let scene = Scene::load("default").expect("scene");
        let rig = crate::layout::build_rig(&scene);
        let dir = tempfile::tempdir().expect("tempdir");
        let t0 = std::time::Instant::now();
        let files = write_textured_scan(dir.path(), &scene, &rig).expect("write");
        let took = t0.elapsed();
        let size: u64 = [&files.obj, &files.mtl, &files.png]
            .iter()
            .map(|p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0))
            .sum();
        assert!(size < 30_000_000, "{size} bytes");
        eprintln!("textured scan: {size} bytes, {took:?}, {files:?}");
        let opts = skinbrdf_mesh::LoadOptions::default();
        let scan = skinbrdf_mesh::load_textured(&files.obj, &opts).expect("load");
        assert_eq!(scan.mesh.indices.len(), files.triangles);
        let plain = skinbrdf_mesh::load_mesh(&files.obj, &opts).expect("load_mesh");
        assert_eq!(plain.mesh, scan.mesh);
        // A ray onto each paper's centre cell hits ink or paper as printed.
        let truth = scan_truth(&scene, &rig);
        let bvh = skinbrdf_mesh::MeshBvh::build(&scan.mesh, skinbrdf_mesh::BuildQuality::Fast)
            .expect("bvh");
        let mut checked = 0;
        for t in &truth.targets {
            let [c0, c1, c2, c3] = t.corners_m;
            let out = -((c1 - c0).cross(c0 - c3)).normalize();
            let bits = skinbrdf_targets::tag36h11::tag_bits(t.id as usize).expect("id");
            // Border cell near corner 0 (black) and the white ring beyond it.
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
}
