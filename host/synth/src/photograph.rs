//! The synthetic photographer: image formation of the studio photographs.
//!
//! For every pixel, `n x n` stratified jittered rays (n = ceil(sqrt(samples_per_pixel)); one ray
//! through the pixel centre when n = 1) are traced through the true camera (pinhole + Brown-
//! Conrady distortion, [`CameraModel::pixel_ray`], through the camera's undistortion table
//! [`CameraRays`], equal to it within 1e-9 rad) against three obvhs BVHs ([`MeshBvh`]): the
//! skin and the headdress targets (head frame, moved by the head pose; absent from a survey
//! shot, taken before the subject sits, [`Shot::subject_present`]), the reference and flash
//! targets and the flash diffuser (world frame), and the reflectance standard (its own frame,
//! present only in the standard images). The pixel's value is the mean of the rays' values `V`
//! times the shot's exposure against the scene's ([`Shot::exposure_gain`], 1 but for the longer
//! exposure of a survey shot):
//!
//! * **skin**: `V = rho(w_i, w_e) cos(theta_i) / (C D²)` per channel (`rho` the true BRDF in the
//!   local frame of the analytic normal at the hit, `D` the distance to the flash's emitting
//!   point, `C` the calibration constant) when the flash fired and a shadow ray towards it (against
//!   the skin) is free; plus `ambient * albedo_d` when the room light is on;
//! * **printed targets**: Lambertian paper or ink (tag36h11 cells, white margin) lit the same way
//!   (targets cast and receive no shadows), each as the rig prints it ([`Rig::prints`]: another
//!   target's code, or two half-tags across a sheet's fold); a printed sheet's paper just behind
//!   its targets ([`crate::sheets::PAPER_BACKING_OFFSET_M`]);
//! * **standard**: its BRDF, lit the same way;
//! * **flash diffuser**: an emitter well above white when it fires, white plastic otherwise;
//! * **background**: black (0).
//!
//! Only pixels whose block (16 x 16) is touched by the projection of some object's bounds are
//! traced; the rest are background (exactly what tracing them would give, and tested so).
//!
//! Cost: the camera rays come from the undistortion table; every mesh (the large skin one and
//! the small ones) is traced for a band of `BAND_ROWS` pixel rows at once with the coherent
//! tile tracer ([`MeshBvh::intersect_grid_into`], the same closest hits as ray-by-ray
//! traversal; a tile that sees none of a mesh costs one frustum test); a skin hit is moved onto
//! the analytic surface by a Newton iteration along the ray that reuses one directional
//! derivative (`refine_on_ray`).

use std::sync::Arc;

use glam::{DMat3, DVec2, DVec3, Vec3};
use rayon::prelude::*;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::{CameraModel, Pose, ShadingFrame, TriMesh};
use skinbrdf_mesh::shadow::{shadow_ray, ShadowScratch};
use skinbrdf_mesh::{BuildQuality, CameraRays, Hit, MeshBvh, TraceScratch};
use skinbrdf_session::Target;

use crate::layout::{Rig, Shot};
use crate::scene::Scene;

/// Value of the flash diffuser when it fires (far above white: it saturates).
pub const FLASH_EMITTER_V: f32 = 8.0;
/// Albedo of the diffuser when it does not fire.
pub const DIFFUSER_ALBEDO: f64 = 0.9;
/// Shadow-ray start offset along the normal, metres: above the tessellation's sagitta (a few
/// µm at 1.5 mm spacing) and far below a pixel's footprint (~1 mm).
pub const SHADOW_OFFSET_M: f64 = 2e-5;
/// Culling block size, pixels.
const BLOCK_PX: u32 = 16;
/// Pixel rows per band of coherent tracing (one task; 8 rows x 2 strata = one super-tile band
/// of the grid tracer at 4 rays per pixel).
const BAND_ROWS: u32 = 8;
pub use crate::layout::{Layout, PAPER_HALF_EXTENT};

/// A printed target ready for shading, in its BVH's frame: the tag's square, of which the
/// paper between `u_range` (tag half-edges along x) is printed (all of it but for half of a
/// tag a sheet's fold crosses).
#[derive(Debug, Clone)]
struct PrintedTag {
    centre: DVec3,
    x: DVec3,
    y: DVec3,
    out: DVec3,
    half_m: f64,
    bits: [[bool; 10]; 10],
    u_range: [f64; 2],
}

impl PrintedTag {
    fn new(t: &Target, frame: &Pose) -> Self {
        Self::piece(t, t.id, [-PAPER_HALF_EXTENT, PAPER_HALF_EXTENT], frame)
    }

    /// The part `u_range` of the square `t` printed with the code `code`.
    fn piece(t: &Target, code: u32, u_range: [f64; 2], frame: &Pose) -> Self {
        let c = t.corners_m.map(|p| frame.transform_point(p));
        let centre = frame.transform_point(t.centre());
        let x = (c[1] - c[0]).normalize();
        let y = (c[0] - c[3]).normalize();
        let out = -(x.cross(y)).normalize();
        let bits = skinbrdf_targets::tag36h11::tag_bits(code as usize).unwrap_or([[true; 10]; 10]);
        Self {
            centre,
            x,
            y,
            out,
            half_m: 0.5 * t.size_m,
            bits,
            u_range,
        }
    }

    fn corner(&self, u: f64, v: f64) -> DVec3 {
        self.centre + self.x * (u * self.half_m) + self.y * (v * self.half_m)
    }

    /// Whether the paper is white at a point (tag units: black border at ±1).
    fn white_at(&self, p: DVec3) -> bool {
        let d = p - self.centre;
        let u = d.dot(self.x) / self.half_m;
        let v = d.dot(self.y) / self.half_m;
        let cw = 0.25;
        let col = ((u + 1.0) / cw + 1.0).floor();
        let row = ((v + 1.0) / cw + 1.0).floor();
        if !(0.0..10.0).contains(&col) || !(0.0..10.0).contains(&row) {
            return true;
        }
        self.bits[row as usize][col as usize]
    }

    fn push_quad(&self, mesh: &mut TriMesh) {
        let e = PAPER_HALF_EXTENT;
        let [u0, u1] = self.u_range;
        let base = mesh.positions.len() as u32;
        for (u, v) in [(u0, e), (u1, e), (u1, -e), (u0, -e)] {
            mesh.positions.push(self.corner(u, v).as_vec3());
        }
        mesh.indices.push([base, base + 1, base + 2]);
        mesh.indices.push([base, base + 2, base + 3]);
    }
}

/// What a BVH triangle belongs to.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Surface {
    Skin,
    Tag(Layout, u32),
    /// A printed sheet's paper (behind its targets), by index.
    Paper(u32),
    Diffuser,
    Standard,
}

#[derive(Debug)]
struct Group {
    bvh: MeshBvh,
    kinds: Vec<Surface>,
    lo: DVec3,
    hi: DVec3,
}

impl Group {
    fn build(mesh: &TriMesh, kinds: Vec<Surface>) -> Result<Self, skinbrdf_mesh::MeshError> {
        let (lo, hi) = mesh.bounds().unwrap_or((Vec3::ZERO, Vec3::ZERO));
        Ok(Self {
            bvh: MeshBvh::build(mesh, BuildQuality::Medium)?,
            kinds,
            lo: lo.as_dvec3(),
            hi: hi.as_dvec3(),
        })
    }
}

/// Everything needed to render any shot of a session: built once, shared by all images.
#[derive(Debug)]
pub struct Renderer {
    camera: CameraModel,
    camera_rays: CameraRays,
    skin: Group,
    head_tags: Group,
    world: Group,
    standard: Group,
    tags_head: Vec<PrintedTag>,
    tags_world: Vec<(Layout, PrintedTag)>,
    tags_standard: Vec<PrintedTag>,
    /// The reference sheets' papers (world frame): corners and outward normal.
    papers_world: Vec<([DVec3; 4], DVec3)>,
    target_ids: Vec<(Layout, u32)>,
    light_world: DVec3,
    flash_out_world: DVec3,
    skin_brdf: BrdfModel,
    standard_brdf: BrdfModel,
    c: [f64; 3],
    ambient: f64,
    paper: f64,
    ink: f64,
    spp_side: u32,
    roi_centre_head: DVec3,
    roi_radius_m: f64,
    shape: crate::shape::Shape,
    /// Triangles in the render mesh of the skin.
    pub skin_triangles: usize,
    /// The camera's rays about every pixel centre (see [`PixelRays`]), built on first use.
    pixel_rays: std::sync::OnceLock<PixelRays>,
}

/// The camera's undistorted normalized coordinates at every pixel centre and their derivatives
/// along x and y (central differences over ±0.5 px), f32: a sample at `(x + jx, y + jy)` of
/// pixel `(x, y)` (|jx|, |jy| ≤ 0.5) takes `n0 + jx ∂n/∂x + jy ∂n/∂y`. The undistortion map is
/// smooth on the pixel's scale: the neglected second-order term is under 1e-9 rad even for
/// the strong-distortion scene (k1 = -0.2: `3 |k1| r / f² · (0.5 px)²` with r ≤ 0.2 and
/// f ≈ 5000 px), as small as the undistortion table's own error (`CameraRays`), and f32 holds
/// the coordinates to ~6e-8 rad, 0.1 µm at the head. One Newton-refined undistortion per pixel
/// per session replaces one per sample per image; each image keeps its own jitter.
#[derive(Debug)]
struct PixelRays {
    width: u32,
    /// Per pixel `[n.x, n.y, ∂n.x/∂x, ∂n.y/∂x, ∂n.x/∂y, ∂n.y/∂y]`; NaN where any of the five
    /// positions has no camera ray (such a pixel's samples are undistorted one by one).
    coeffs: Vec<[f32; 6]>,
}

impl PixelRays {
    fn build(rays: &CameraRays, width: u32, height: u32) -> Self {
        let mut coeffs = vec![[f32::NAN; 6]; (width * height) as usize];
        coeffs
            .par_chunks_mut(width as usize)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, c) in row.iter_mut().enumerate() {
                    let p = DVec2::new(x as f64, y as f64);
                    let at = |dx: f64, dy: f64| rays.undistort_pixel(p + DVec2::new(dx, dy));
                    if let (Some(n0), Some(xp), Some(xm), Some(yp), Some(ym)) = (
                        at(0.0, 0.0),
                        at(0.5, 0.0),
                        at(-0.5, 0.0),
                        at(0.0, 0.5),
                        at(0.0, -0.5),
                    ) {
                        let (dx, dy) = (xp - xm, yp - ym);
                        *c = [n0.x, n0.y, dx.x, dx.y, dy.x, dy.y].map(|v| v as f32);
                    }
                }
            });
        Self { width, coeffs }
    }

    /// The unit camera-frame ray through `(x + j.x, y + j.y)`, or `None` where the table has
    /// no entry for pixel `(x, y)`.
    fn ray(&self, x: u32, y: u32, j: DVec2) -> Option<DVec3> {
        let c = self.coeffs[(y * self.width + x) as usize];
        if c[0].is_nan() {
            return None;
        }
        let c = c.map(f64::from);
        let n =
            DVec2::new(c[0], c[1]) + DVec2::new(c[2], c[3]) * j.x + DVec2::new(c[4], c[5]) * j.y;
        Some(DVec3::new(n.x, n.y, 1.0).normalize())
    }
}

/// The sub-pixel positions of pixel `(x, y)`'s `n x n` samples, row by row:
/// stratified, each jittered in its cell from a hash of `seed` and the pixel (independent of
/// which pixels are traced and of the thread schedule).
fn sub_pixel_positions(
    seed: u64,
    x: u32,
    y: u32,
    n: u32,
) -> impl Iterator<Item = (u32, u32, DVec2)> {
    let mut state = seed ^ (u64::from(y) << 32 | u64::from(x)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    (0..n)
        .flat_map(move |sy| (0..n).map(move |sx| (sx, sy)))
        .map(move |(sx, sy)| {
            let (jx, jy) = if n == 1 {
                (0.0, 0.0)
            } else {
                (
                    (f64::from(sx) + unit(&mut state)) / f64::from(n) - 0.5,
                    (f64::from(sy) + unit(&mut state)) / f64::from(n) - 0.5,
                )
            };
            (sx, sy, DVec2::new(f64::from(x) + jx, f64::from(y) + jy))
        })
}

/// One rendered image before sensor noise.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Noise-free linear values per pixel.
    pub v: Vec<[f32; 3]>,
    /// Pixels entirely on the skin's region of interest.
    pub forehead: Vec<bool>,
    /// Pixels touching any printed target.
    pub targets: Vec<bool>,
    /// Pixels entirely on the standard's reflecting area.
    pub standard: Vec<bool>,
    /// Rays traced (primary).
    pub rays: u64,
}

/// Per-shot frame data.
struct View {
    world_from_camera: Pose,
    head_from_world: Pose,
    standard_from_world: Pose,
    light_head: DVec3,
    light_std: DVec3,
    fired: bool,
    ambient: bool,
    standard_present: bool,
    subject_present: bool,
    exposure_gain: f64,
}

/// Where [`refine_on_ray`] stops: 0.1 nm from the analytic surface, a hundred times below the
/// f32 rounding of a mesh hit at the head's distance (~10 nm) and far below any effect on a
/// pixel. From a tessellation offset of a few µm the first Newton step lands within ~1e-11 m
/// (the error squared times the curvature), so one step and one check usually suffice.
const REFINE_TOLERANCE_M: f64 = 1e-10;

/// Moves a mesh hit near the surface along the ray `dir` (unit) onto the analytic surface:
/// Newton on `f(p + s·dir) = 0` ([`crate::shape::Shape::implicit`]) with the directional
/// derivative taken once from the analytic gradient (the start is within a few µm, over which it
/// does not change measurably): one gradient, then one evaluation per step. Stops at
/// |f| < [`REFINE_TOLERANCE_M`]; keeps the mesh hit when the ray is not near the surface.
fn refine_on_ray(shape: &crate::shape::Shape, mut p: DVec3, dir: DVec3) -> DVec3 {
    let dfds = shape.implicit_gradient(p).dot(dir);
    if !dfds.is_finite() || dfds.abs() < 1e-6 {
        return p;
    }
    for _ in 0..8 {
        let f = shape.implicit(p);
        if f.abs() < REFINE_TOLERANCE_M {
            break;
        }
        let step = f / dfds;
        if step.abs() > 1e-4 {
            break;
        }
        p -= dir * step;
    }
    p
}

/// SplitMix64 step mapped to `[0, 1)`.
fn unit(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// One rendered row: values, forehead/target/standard masks, rays traced.
type RowOut = (Vec<[f32; 3]>, Vec<bool>, Vec<bool>, Vec<bool>, u64);

enum Bounds {
    Nowhere,
    Anywhere,
    Rect(DVec2, DVec2),
}

struct Sample {
    v: [f64; 3],
    skin_roi: bool,
    target: bool,
    standard: bool,
}

impl Renderer {
    /// Builds the BVHs for a scene's rig.
    pub fn new(scene: &Scene, rig: &Rig) -> Result<Self, skinbrdf_mesh::MeshError> {
        use std::f64::consts::{FRAC_PI_2, PI};
        let skin_mesh = rig.shape.tessellate(
            scene.geometry.render_spacing_m,
            (-PI, PI),
            (-FRAC_PI_2, FRAC_PI_2),
        );
        let skin_triangles = skin_mesh.indices.len();
        let skin = Group::build(&skin_mesh, vec![Surface::Skin; skin_triangles])?;

        let tags_head: Vec<PrintedTag> = rig
            .headdress
            .iter()
            .map(|t| PrintedTag::new(t, &Pose::IDENTITY))
            .collect();
        let mut m = TriMesh::default();
        let mut kinds = Vec::new();
        for (i, t) in tags_head.iter().enumerate() {
            t.push_quad(&mut m);
            kinds.extend([Surface::Tag(Layout::Headdress, i as u32); 2]);
        }
        let head_tags = Group::build(&m, kinds)?;

        let mut tags_world = Vec::new();
        let mut target_ids = Vec::new();
        for t in &rig.reference {
            // A target is printed as its code on one or more flat pieces (crate::sheets).
            let print = rig.print_of(t);
            for piece in &print.pieces {
                tags_world.push((
                    Layout::Reference,
                    PrintedTag::piece(&piece.square, print.code, piece.u_range, &Pose::IDENTITY),
                ));
                target_ids.push((Layout::Reference, t.id));
            }
        }
        for t in &rig.flash_targets {
            tags_world.push((Layout::Flash, PrintedTag::new(t, &rig.world_from_flash)));
            target_ids.push((Layout::Flash, t.id));
        }
        let mut m = TriMesh::default();
        let mut kinds = Vec::new();
        for (i, (_, t)) in tags_world.iter().enumerate() {
            t.push_quad(&mut m);
            kinds.extend([Surface::Tag(Layout::Reference, i as u32); 2]);
        }
        // The reference sheets' papers, just behind their printed targets.
        let papers_world: Vec<([DVec3; 4], DVec3)> = rig
            .sheets
            .iter()
            .filter(|s| s.layout == Layout::Reference)
            .flat_map(|s| s.paper_quads())
            .map(|q| {
                let out = -((q[1] - q[0]).cross(q[3] - q[0])).normalize_or_zero();
                (
                    q.map(|p| p - out * crate::sheets::PAPER_BACKING_OFFSET_M),
                    out,
                )
            })
            .collect();
        for (i, (q, _)) in papers_world.iter().enumerate() {
            let base = m.positions.len() as u32;
            m.positions.extend(q.iter().map(|p| p.as_vec3()));
            m.indices.push([base, base + 1, base + 2]);
            m.indices.push([base, base + 2, base + 3]);
            kinds.extend([Surface::Paper(i as u32); 2]);
        }
        // The diffuser disc (a 32-gon fan, just in front of the flash plane).
        let f = rig.world_from_flash;
        let r = 0.5 * scene.session.flash_diameter_m;
        let base = m.positions.len() as u32;
        m.positions
            .push(f.transform_point(DVec3::new(0.0, 0.0, 1e-3)).as_vec3());
        for k in 0..32 {
            let a = k as f64 * std::f64::consts::TAU / 32.0;
            m.positions.push(
                f.transform_point(DVec3::new(r * a.cos(), r * a.sin(), 1e-3))
                    .as_vec3(),
            );
        }
        for k in 0..32u32 {
            m.indices
                .push([base, base + 1 + k, base + 1 + (k + 1) % 32]);
            kinds.push(Surface::Diffuser);
        }
        let world = Group::build(&m, kinds)?;

        let tags_standard: Vec<PrintedTag> = rig
            .standard_targets
            .iter()
            .map(|t| PrintedTag::new(t, &Pose::IDENTITY))
            .collect();
        let mut m = TriMesh::default();
        let mut kinds = Vec::new();
        let h = 0.5 * scene.standard.size_m;
        m.positions.extend([
            Vec3::new(-h as f32, -h as f32, 0.0),
            Vec3::new(h as f32, -h as f32, 0.0),
            Vec3::new(h as f32, h as f32, 0.0),
            Vec3::new(-h as f32, h as f32, 0.0),
        ]);
        m.indices.extend([[0, 1, 2], [0, 2, 3]]);
        kinds.extend([Surface::Standard; 2]);
        for (i, t) in tags_standard.iter().enumerate() {
            t.push_quad(&mut m);
            kinds.extend([Surface::Tag(Layout::Standard, i as u32); 2]);
        }
        let standard = Group::build(&m, kinds)?;

        let spp_side = (scene.sensor.samples_per_pixel as f64)
            .sqrt()
            .ceil()
            .max(1.0) as u32;
        Ok(Self {
            camera: rig.camera,
            camera_rays: CameraRays::new(&rig.camera),
            skin,
            head_tags,
            world,
            standard,
            tags_head,
            tags_world,
            tags_standard,
            papers_world,
            target_ids,
            light_world: rig.light_position_m(),
            flash_out_world: rig.world_from_flash.transform_vector(DVec3::Z),
            skin_brdf: scene.skin.clone(),
            standard_brdf: scene.standard.brdf.clone(),
            c: scene.radiometry.calibration_c,
            ambient: scene.radiometry.ambient,
            paper: scene.targets.paper_albedo,
            ink: scene.targets.ink_albedo,
            spp_side,
            roi_centre_head: rig.roi_centre_head,
            roi_radius_m: scene.geometry.roi_radius_m,
            shape: rig.shape.clone(),
            skin_triangles,
            pixel_rays: std::sync::OnceLock::new(),
        })
    }

    /// Rays per pixel actually used (a square number).
    pub fn samples_per_pixel(&self) -> u32 {
        self.spp_side * self.spp_side
    }

    /// Overrides the rays per pixel (rounded up to a square).
    pub fn set_samples_per_pixel(&mut self, spp: u32) {
        self.spp_side = (spp.max(1) as f64).sqrt().ceil() as u32;
    }

    /// The ids of the world-frame targets' printed pieces (reference then flash; a target a
    /// sheet's fold crosses has two), for tests.
    pub fn world_target_ids(&self) -> &[(Layout, u32)] {
        &self.target_ids
    }

    fn view(&self, shot: &Shot, rig: &Rig) -> View {
        let head_from_world = shot.world_from_head.inverse();
        let standard_from_world = rig.world_from_standard.inverse();
        View {
            world_from_camera: shot.world_from_camera,
            light_head: head_from_world.transform_point(self.light_world),
            light_std: standard_from_world.transform_point(self.light_world),
            head_from_world,
            standard_from_world,
            fired: shot.flash_fired,
            ambient: shot.ambient_on,
            standard_present: shot.standard_present,
            subject_present: shot.subject_present,
            exposure_gain: shot.exposure_gain,
        }
    }

    /// Lambertian-style lighting factor `cos(theta_i) / D²` from a light, zero behind.
    fn lit(&self, p: DVec3, n: DVec3, light: DVec3) -> (f64, DVec3, f64) {
        let to = light - p;
        let d = to.length();
        let wi = to / d;
        (n.dot(wi), wi, d)
    }

    fn shade_paper(
        &self,
        albedo: f64,
        p: DVec3,
        n_out: DVec3,
        ray_dir: DVec3,
        light: DVec3,
        view: &View,
    ) -> [f64; 3] {
        let n = if n_out.dot(ray_dir) < 0.0 {
            n_out
        } else {
            -n_out
        };
        let mut v = [0.0; 3];
        if view.fired {
            let (cos_i, _, d) = self.lit(p, n, light);
            if cos_i > 0.0 {
                for (k, vk) in v.iter_mut().enumerate() {
                    *vk += albedo * std::f64::consts::FRAC_1_PI * cos_i / (self.c[k] * d * d);
                }
            }
        }
        if view.ambient {
            for vk in &mut v {
                *vk += self.ambient * albedo;
            }
        }
        v
    }

    /// The skin's value at a head-frame hit (exposed for the exactness tests).
    pub fn skin_value(
        &self,
        p_head: DVec3,
        cam_head: DVec3,
        light_head: DVec3,
        fired: bool,
        ambient: bool,
    ) -> [f64; 3] {
        let n = self.shape.normal(p_head);
        self.skin_value_at(p_head, n, cam_head, light_head, fired, ambient, || {
            let origin = p_head + n * SHADOW_OFFSET_M;
            let (wi, t_max) =
                shadow_ray(origin.as_vec3(), light_head.as_vec3(), 0.0).unwrap_or((Vec3::Z, 0.0));
            self.skin.bvh.occluded(origin.as_vec3(), wi, t_max)
        })
    }

    /// The skin's value at head-frame point `p_head` with unit normal `n`; `occluded` answers
    /// whether the skin hides the light from it (asked only when the point faces the fired
    /// light): the shadow ray from `p_head + n SHADOW_OFFSET_M` to the light, traced ray by ray
    /// ([`Self::skin_value`]) or for a whole band at once ([`Self::render`]).
    #[allow(clippy::too_many_arguments)]
    fn skin_value_at(
        &self,
        p_head: DVec3,
        n: DVec3,
        cam_head: DVec3,
        light_head: DVec3,
        fired: bool,
        ambient: bool,
        occluded: impl FnOnce() -> bool,
    ) -> [f64; 3] {
        let mut v = [0.0; 3];
        if fired {
            let (cos_i, wi, d) = self.lit(p_head, n, light_head);
            // The shadow ray is asked only for a point facing the light.
            if cos_i > 0.0 && !occluded() {
                let we = (cam_head - p_head).normalize();
                let frame = ShadingFrame::from_normal(n);
                let rho = self.skin_brdf.eval(frame.to_local(wi), frame.to_local(we));
                for k in 0..3 {
                    v[k] = rho[k] * cos_i / (self.c[k] * d * d);
                }
            }
        }
        if ambient {
            let a = self.skin_brdf.diffuse_albedo();
            for k in 0..3 {
                v[k] += self.ambient * a[k];
            }
        }
        v
    }

    /// The closest of the precomputed hits `pre` (world, skin, headdress, standard) among the
    /// objects present in the view: distance, surface and frame (0 world, 1 head, 2 standard).
    fn closest(&self, view: &View, pre: &[Option<Hit>; 4]) -> (f32, Surface, u8) {
        let mut best = (f32::INFINITY, Surface::Skin, 0u8);
        for (k, (g, which)) in [
            (&self.world, 0u8),
            (&self.skin, 1),
            (&self.head_tags, 1),
            (&self.standard, 2),
        ]
        .into_iter()
        .enumerate()
        {
            if (k == 3 && !view.standard_present) || ((k == 1 || k == 2) && !view.subject_present) {
                continue;
            }
            if let Some(h) = pre[k] {
                if h.t_m < best.0 {
                    best = (h.t_m, g.kinds[h.triangle as usize], which);
                }
            }
        }
        best
    }

    /// The refined skin point (head frame) and its normal when the closest of `pre` is the
    /// skin (see [`refine_on_ray`]).
    fn skin_point(
        &self,
        o_w: DVec3,
        d_w: DVec3,
        view: &View,
        pre: &[Option<Hit>; 4],
    ) -> Option<(DVec3, DVec3)> {
        let (t, surf, _) = self.closest(view, pre);
        if !(t.is_finite() && matches!(surf, Surface::Skin)) {
            return None;
        }
        let oh = view.head_from_world.transform_point(o_w);
        let dh = view.head_from_world.transform_vector(d_w);
        let p = refine_on_ray(&self.shape, oh + dh * f64::from(t), dh);
        Some((p, self.shape.normal(p)))
    }

    /// The sample of one world ray. `pre` holds the closest hits of the world, skin, headdress
    /// and standard meshes, traced by the caller (coherently, with
    /// [`MeshBvh::intersect_grid_into`]). `skin` holds, when the closest hit is the skin and the caller has them, its refined
    /// point and normal and whether the skin hides the light from it.
    fn trace(
        &self,
        o_w: DVec3,
        d_w: DVec3,
        view: &View,
        pre: [Option<Hit>; 4],
        skin: Option<(DVec3, DVec3, bool)>,
    ) -> Sample {
        let head = || {
            (
                view.head_from_world.transform_point(o_w),
                view.head_from_world.transform_vector(d_w),
            )
        };
        let std_frame = || {
            (
                view.standard_from_world.transform_point(o_w),
                view.standard_from_world.transform_vector(d_w),
            )
        };
        let (t, surf, which) = self.closest(view, &pre);
        let none = Sample {
            v: [0.0; 3],
            skin_roi: false,
            target: false,
            standard: false,
        };
        if !t.is_finite() {
            return none;
        }
        let t = f64::from(t);
        match surf {
            Surface::Skin => {
                let (oh, dh) = head();
                let (p, v) = match skin {
                    Some((p, n, occluded)) => (
                        p,
                        self.skin_value_at(
                            p,
                            n,
                            oh,
                            view.light_head,
                            view.fired,
                            view.ambient,
                            || occluded,
                        ),
                    ),
                    None => {
                        // Refine onto the analytic surface along the ray (removes the
                        // tessellation's few-µm offset and the f32 hit's rounding): Newton on
                        // the implicit function.
                        let p = refine_on_ray(&self.shape, oh + dh * t, dh);
                        (
                            p,
                            self.skin_value(p, oh, view.light_head, view.fired, view.ambient),
                        )
                    }
                };
                Sample {
                    v,
                    skin_roi: p.distance(self.roi_centre_head) <= self.roi_radius_m,
                    target: false,
                    standard: false,
                }
            }
            Surface::Tag(layout, i) => {
                let (tag, (o, d), light) = match (which, layout) {
                    (1, _) => (&self.tags_head[i as usize], head(), view.light_head),
                    (2, _) => (&self.tags_standard[i as usize], std_frame(), view.light_std),
                    _ => (&self.tags_world[i as usize].1, (o_w, d_w), self.light_world),
                };
                let p = o + d * t;
                let albedo = if tag.white_at(p) {
                    self.paper
                } else {
                    self.ink
                };
                Sample {
                    v: self.shade_paper(albedo, p, tag.out, d, light, view),
                    skin_roi: false,
                    target: true,
                    standard: false,
                }
            }
            Surface::Paper(i) => {
                let p = o_w + d_w * t;
                let out = self.papers_world[i as usize].1;
                Sample {
                    v: self.shade_paper(self.paper, p, out, d_w, self.light_world, view),
                    skin_roi: false,
                    target: true,
                    standard: false,
                }
            }
            Surface::Diffuser => {
                let front = d_w.dot(self.flash_out_world) < 0.0;
                let v = if front && view.fired {
                    [f64::from(FLASH_EMITTER_V); 3]
                } else if front && view.ambient {
                    [self.ambient * DIFFUSER_ALBEDO; 3]
                } else {
                    [0.0; 3]
                };
                Sample {
                    v,
                    skin_roi: false,
                    target: false,
                    standard: false,
                }
            }
            Surface::Standard => {
                let (os, ds) = std_frame();
                let p = os + ds * t;
                let mut v = [0.0; 3];
                if ds.z < 0.0 {
                    if view.fired {
                        let (cos_i, wi, dist) = self.lit(p, DVec3::Z, view.light_std);
                        if cos_i > 0.0 {
                            let rho = self.standard_brdf.eval(wi, -ds);
                            for k in 0..3 {
                                v[k] = rho[k] * cos_i / (self.c[k] * dist * dist);
                            }
                        }
                    }
                    if view.ambient {
                        let a = self.standard_brdf.diffuse_albedo();
                        for k in 0..3 {
                            v[k] += self.ambient * a[k];
                        }
                    }
                }
                Sample {
                    v,
                    skin_roi: false,
                    target: false,
                    standard: ds.z < 0.0,
                }
            }
        }
    }

    /// Projects world points; returns their pixel bounding box, or `None` (= "could be
    /// anywhere") when a point is behind the camera or far outside the field of view, where
    /// the distortion polynomial is not trustworthy.
    fn project_bounds(&self, camera_from_world: &Pose, pts: &[DVec3]) -> Bounds {
        let cam = &self.camera;
        // Beyond 1.3x the image's half extent the distortion polynomial may fold back; points
        // out there are pulled radially onto that limit (their true images lie outside the
        // image, so the pulled point still bounds the object's visible part on that side).
        let lim_x = 1.3 * (cam.width_px as f64 / cam.fx_px);
        let lim_y = 1.3 * (cam.height_px as f64 / cam.fy_px);
        let mut lo = DVec2::splat(f64::INFINITY);
        let mut hi = DVec2::splat(f64::NEG_INFINITY);
        let mut behind = 0;
        for p in pts {
            let pc = camera_from_world.transform_point(*p);
            if pc.z <= 0.01 {
                behind += 1;
                continue;
            }
            let mut n = DVec2::new(pc.x / pc.z, pc.y / pc.z);
            let s = (n.x.abs() / lim_x).max(n.y.abs() / lim_y);
            if s > 1.0 {
                n /= s;
            }
            let px = cam.normalized_to_pixel(cam.distortion.distort(n));
            lo = lo.min(px);
            hi = hi.max(px);
        }
        if behind == pts.len() {
            Bounds::Nowhere
        } else if behind > 0 {
            Bounds::Anywhere
        } else {
            Bounds::Rect(lo, hi)
        }
    }

    fn box_points(lo: DVec3, hi: DVec3, frame: &Pose) -> Vec<DVec3> {
        let mut out = Vec::with_capacity(27);
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    let f = DVec3::new(i as f64, j as f64, k as f64) * 0.5;
                    out.push(frame.transform_point(lo + (hi - lo) * f));
                }
            }
        }
        out
    }

    /// Which 16 x 16 blocks need rays.
    fn coverage(&self, view: &View) -> (Vec<bool>, u32) {
        let cam = &self.camera;
        let bw = cam.width_px.div_ceil(BLOCK_PX);
        let bh = cam.height_px.div_ceil(BLOCK_PX);
        let mut blocks = vec![false; (bw * bh) as usize];
        let camera_from_world = view.world_from_camera.inverse();
        let world_from_head = view.head_from_world.inverse();
        let world_from_std = view.standard_from_world.inverse();
        let mut sets: Vec<Vec<DVec3>> = Vec::new();
        if view.subject_present {
            sets.push(Self::box_points(
                self.skin.lo,
                self.skin.hi,
                &world_from_head,
            ));
            sets.push(Self::box_points(
                self.head_tags.lo,
                self.head_tags.hi,
                &world_from_head,
            ));
        }
        // World group: one set per target (they spread over the room) plus the diffuser.
        let e = PAPER_HALF_EXTENT;
        for (_, t) in &self.tags_world {
            sets.push(
                [
                    (-e, -e),
                    (0.0, -e),
                    (e, -e),
                    (-e, 0.0),
                    (0.0, 0.0),
                    (e, 0.0),
                    (-e, e),
                    (0.0, e),
                    (e, e),
                ]
                .iter()
                .map(|&(u, v)| t.corner(u, v))
                .collect(),
            );
        }
        for (q, _) in &self.papers_world {
            let mid = |a: DVec3, b: DVec3| 0.5 * (a + b);
            let mut pts = q.to_vec();
            pts.extend((0..4).map(|k| mid(q[k], q[(k + 1) % 4])));
            pts.push(0.25 * (q[0] + q[1] + q[2] + q[3]));
            sets.push(pts);
        }
        let r = 0.06;
        let f = self.light_world;
        sets.push(
            (0..27)
                .map(|i| {
                    f + DVec3::new(
                        (i % 3) as f64 - 1.0,
                        ((i / 3) % 3) as f64 - 1.0,
                        (i / 9) as f64 - 1.0,
                    ) * r
                })
                .collect(),
        );
        if view.standard_present {
            sets.push(Self::box_points(
                self.standard.lo,
                self.standard.hi,
                &world_from_std,
            ));
        }
        let margin = 3.0;
        for pts in &sets {
            match self.project_bounds(&camera_from_world, pts) {
                Bounds::Nowhere => {}
                Bounds::Anywhere => {
                    blocks.iter_mut().for_each(|b| *b = true);
                    break;
                }
                Bounds::Rect(lo, hi) => {
                    if hi.x < -margin
                        || hi.y < -margin
                        || lo.x > cam.width_px as f64 + margin
                        || lo.y > cam.height_px as f64 + margin
                    {
                        continue;
                    }
                    let x0 = ((lo.x - margin).max(0.0) / BLOCK_PX as f64) as i64;
                    let y0 = ((lo.y - margin).max(0.0) / BLOCK_PX as f64) as i64;
                    let x1 = ((hi.x + margin) / BLOCK_PX as f64).min(bw as f64 - 1.0) as i64;
                    let y1 = ((hi.y + margin) / BLOCK_PX as f64).min(bh as f64 - 1.0) as i64;
                    for by in y0.max(0)..=y1 {
                        for bx in x0.max(0)..=x1 {
                            blocks[(by as u32 * bw + bx as u32) as usize] = true;
                        }
                    }
                }
            }
        }
        (blocks, bw)
    }

    /// Renders one shot (noise-free). `seed` makes the jitter reproducible; `cull = false`
    /// traces every pixel (for tests of the culling).
    pub fn render(&self, shot: &Shot, rig: &Rig, seed: u64, cull: bool) -> Rendered {
        let view = self.view(shot, rig);
        let (w, h) = (self.camera.width_px, self.camera.height_px);
        let (blocks, bw) = if cull {
            self.coverage(&view)
        } else {
            let bw = w.div_ceil(BLOCK_PX);
            (vec![true; (bw * h.div_ceil(BLOCK_PX)) as usize], bw)
        };
        let blocks = Arc::new(blocks);
        let n = self.spp_side;
        let pixel_rays = self
            .pixel_rays
            .get_or_init(|| PixelRays::build(&self.camera_rays, w, h));
        let inv = 1.0 / f64::from(n * n);
        let origin = view.world_from_camera.translation_m;
        let origin_head = view.head_from_world.transform_point(origin);
        let origin_std = view.standard_from_world.transform_point(origin);
        // Rotations as matrices (9 multiply-adds per direction instead of a quaternion product).
        let rot_wc = DMat3::from_quat(view.world_from_camera.rotation);
        let rot_hw = DMat3::from_quat(view.head_from_world.rotation);
        let rot_sw = DMat3::from_quat(view.standard_from_world.rotation);
        let nu = n as usize;
        let gw = w as usize * nu;
        // Bands of pixel rows; in each, every ray's direction on a grid of sub-pixel samples
        // (n x n per pixel), the skin (the big mesh) traced coherently for the whole band, the
        // small meshes ray by ray.
        let bands: Vec<Vec<RowOut>> = (0..h.div_ceil(BAND_ROWS))
            .into_par_iter()
            .map_init(
                || (TraceScratch::default(), ShadowScratch::default()),
                |(scratch, shadow_scratch), band| {
                    let y0 = band * BAND_ROWS;
                    let y1 = (y0 + BAND_ROWS).min(h);
                    let gh = (y1 - y0) as usize * nu;
                    let mut dirs_w = vec![DVec3::ZERO; gw * gh];
                    let mut dirs_wf = vec![Vec3::ZERO; gw * gh];
                    let mut dirs_h = vec![Vec3::ZERO; gw * gh];
                    let mut dirs_s = vec![Vec3::ZERO; gw * gh];
                    for y in y0..y1 {
                        for x in 0..w {
                            if !blocks[((y / BLOCK_PX) * bw + x / BLOCK_PX) as usize] {
                                continue;
                            }
                            for (sx, sy, px) in sub_pixel_positions(seed, x, y, n) {
                                let table = pixel_rays.ray(
                                    x,
                                    y,
                                    px - DVec2::new(f64::from(x), f64::from(y)),
                                );
                                let Some(dir_c) = table.or_else(|| self.camera_rays.pixel_ray(px))
                                else {
                                    continue;
                                };
                                let g = ((y - y0) * n + sy) as usize * gw + (x * n + sx) as usize;
                                let d = rot_wc * dir_c;
                                dirs_w[g] = d;
                                dirs_wf[g] = d.as_vec3();
                                dirs_h[g] = (rot_hw * d).as_vec3();
                                if view.standard_present {
                                    dirs_s[g] = (rot_sw * d).as_vec3();
                                }
                            }
                        }
                    }
                    // Closest hits per mesh: world, skin, headdress, standard.
                    let mut hits = [
                        vec![None; gw * gh],
                        vec![None; gw * gh],
                        vec![None; gw * gh],
                        vec![None; gw * gh],
                    ];
                    let [hw, hs, ht, hst] = &mut hits;
                    let trace_grid = |g: &Group,
                                      o: DVec3,
                                      d: &[Vec3],
                                      out: &mut [Option<Hit>],
                                      sc: &mut TraceScratch| {
                        g.bvh
                            .intersect_grid_into(o.as_vec3(), d, gw, f32::INFINITY, out, sc);
                    };
                    trace_grid(&self.world, origin, &dirs_wf, hw, scratch);
                    if view.subject_present {
                        trace_grid(&self.skin, origin_head, &dirs_h, hs, scratch);
                        trace_grid(&self.head_tags, origin_head, &dirs_h, ht, scratch);
                    }
                    if view.standard_present {
                        trace_grid(&self.standard, origin_std, &dirs_s, hst, scratch);
                    }
                    // The skin's points, normals and shadow rays: the shadow rays of the band
                    // towards the light traced together (coherently).
                    let mut skin_pn: Vec<Option<(DVec3, DVec3)>> = vec![None; gw * gh];
                    let mut occluded = vec![false; gw * gh];
                    if view.subject_present {
                        let mut origins = vec![Vec3::NAN; gw * gh];
                        let mut any = false;
                        for g in 0..gw * gh {
                            let d = dirs_w[g];
                            if d == DVec3::ZERO {
                                continue;
                            }
                            let pre = [hits[0][g], hits[1][g], hits[2][g], hits[3][g]];
                            let Some((p, n)) = self.skin_point(origin, d, &view, &pre) else {
                                continue;
                            };
                            skin_pn[g] = Some((p, n));
                            if view.fired && n.dot(view.light_head - p) > 0.0 {
                                origins[g] = (p + n * SHADOW_OFFSET_M).as_vec3();
                                any = true;
                            }
                        }
                        if any {
                            self.skin.bvh.occluded_toward_grid_into(
                                view.light_head.as_vec3(),
                                &origins,
                                gw,
                                0.0,
                                &mut occluded,
                                shadow_scratch,
                            );
                        }
                    }
                    (y0..y1)
                        .map(|y| {
                            let mut v = vec![[0.0f32; 3]; w as usize];
                            let mut fh = vec![false; w as usize];
                            let mut tg = vec![false; w as usize];
                            let mut st = vec![false; w as usize];
                            let mut rays = 0u64;
                            for x in 0..w {
                                if !blocks[((y / BLOCK_PX) * bw + x / BLOCK_PX) as usize] {
                                    continue;
                                }
                                let mut acc = [0.0f64; 3];
                                let (mut all_roi, mut any_tag, mut all_std) = (true, false, true);
                                for sy in 0..n {
                                    for sx in 0..n {
                                        let g = ((y - y0) * n + sy) as usize * gw
                                            + (x * n + sx) as usize;
                                        let d = dirs_w[g];
                                        if d == DVec3::ZERO {
                                            // No camera ray through this position.
                                            all_roi = false;
                                            all_std = false;
                                            continue;
                                        }
                                        rays += 1;
                                        let pre = [hits[0][g], hits[1][g], hits[2][g], hits[3][g]];
                                        let skin = skin_pn[g].map(|(p, n)| (p, n, occluded[g]));
                                        let s = self.trace(origin, d, &view, pre, skin);
                                        for (a, sv) in acc.iter_mut().zip(s.v) {
                                            *a += sv;
                                        }
                                        all_roi &= s.skin_roi;
                                        any_tag |= s.target;
                                        all_std &= s.standard;
                                    }
                                }
                                v[x as usize] = acc.map(|a| (a * inv * view.exposure_gain) as f32);
                                fh[x as usize] = all_roi;
                                tg[x as usize] = any_tag;
                                st[x as usize] = all_std;
                            }
                            (v, fh, tg, st, rays)
                        })
                        .collect()
                },
            )
            .collect();
        let rows = bands.into_iter().flatten();
        let mut out = Rendered {
            width: w,
            height: h,
            v: Vec::with_capacity((w * h) as usize),
            forehead: Vec::with_capacity((w * h) as usize),
            targets: Vec::with_capacity((w * h) as usize),
            standard: Vec::with_capacity((w * h) as usize),
            rays: 0,
        };
        for (v, fh, tg, st, rays) in rows {
            out.v.extend(v);
            out.forehead.extend(fh);
            out.targets.extend(tg);
            out.standard.extend(st);
            out.rays += rays;
        }
        out
    }

    /// The closest hit distance along a world ray (any object present in the shot), for
    /// visibility checks of target corners.
    pub fn first_hit_m(&self, shot: &Shot, rig: &Rig, o_w: DVec3, d_w: DVec3) -> Option<f64> {
        let view = self.view(shot, rig);
        let mut best = f32::INFINITY;
        let (oh, dh) = (
            view.head_from_world.transform_point(o_w),
            view.head_from_world.transform_vector(d_w),
        );
        let (os, ds) = (
            view.standard_from_world.transform_point(o_w),
            view.standard_from_world.transform_vector(d_w),
        );
        let mut groups: Vec<(&Group, DVec3, DVec3)> = vec![(&self.world, o_w, d_w)];
        if view.subject_present {
            groups.push((&self.skin, oh, dh));
            groups.push((&self.head_tags, oh, dh));
        }
        if view.standard_present {
            groups.push((&self.standard, os, ds));
        }
        for (g, o, d) in groups {
            if let Some(hh) = g.bvh.intersect(o.as_vec3(), d.as_vec3(), best) {
                best = best.min(hh.t_m);
            }
        }
        best.is_finite().then_some(f64::from(best))
    }

    /// Irradiance factor on a target's face from the flash (`cos / D²`, 0 when unlit) plus
    /// whether the room light is on: a target is detectable only when lit.
    pub fn target_lit(&self, shot: &Shot, centre_w: DVec3, out_w: DVec3) -> bool {
        let lit_by_flash =
            shot.flash_fired && out_w.dot((self.light_world - centre_w).normalize()) > 0.05;
        lit_by_flash || shot.ambient_on
    }
}
