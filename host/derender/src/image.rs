//! Derendering one measurement image: pixels to BRDF samples (the method's equation 2).
//!
//! For each pixel that can see the region of interest:
//!
//! 1. **Which pixels.** The triangles that reach into the region are projected into the image
//!    (through the lens distortion, [`region_pixels`]); only pixel centres inside one of their
//!    bounding boxes, grown by [`REGION_MARGIN_PX`], get rays — no ray is spent on pixels that
//!    cannot see the region. Pixels off the user mask (when given) are dropped before any ray.
//!    Pixels under a printed target's projection are traced and dropped when the target lies
//!    in front of the surface point (within [`TARGET_DEPTH_TOL_M`]); a ray that misses the scan
//!    is `no_surface` whether or not a target projects there.
//! 2. **Ray.** The pixel centre is undistorted with the camera's table
//!    ([`skinbrdf_mesh::CameraRays`]: exact nodes every 8 px, bilinear, one Newton step; equal
//!    to `CameraModel::pixel_ray` within 1e-9 rad); the ray moves to the head frame by
//!    `head_from_camera = world_from_head⁻¹ · world_from_camera`.
//! 3. **Surface.** Closest hit on the scan's BVH, all rays of the image at once with the
//!    coherent tile tracer ([`skinbrdf_mesh::MeshBvh::intersect_grid`], rayon over tiles); the hit must face the camera (a back face means
//!    the ray leaked through the mesh) and lie inside the region sphere. Its normal is the
//!    barycentric blend of the per-vertex planar-fit normals.
//! 4. **Light and camera.** `w_i` towards the light (head frame), `D` its distance, `w_e`
//!    towards the camera centre. Samples with `cos θ_i` or `cos θ_e` below `cos(grazing limit)`
//!    are dropped: `1/cos θ_i` amplifies noise and normal error without bound near grazing
//!    (a normal error `δ` gives a relative error `tan θ · δ`), so the limit bounds it.
//! 5. **Shadow.** Only when the geometry can shadow the region (see [`crate::geometry`]), a ray
//!    from the point (offset [`SHADOW_OFFSET_M`] along the normal) to the light; all of an
//!    image's shadow rays at once with the coherent any-hit tracer
//!    ([`skinbrdf_mesh::MeshBvh::occluded_toward_grid`], the per-ray verdict exactly).
//! 6. **Value.** The linearized pixel value `V`; saturated pixels, pixels with a NaN or −∞
//!    channel and pixels with any channel below the noise floor are dropped;
//!    `rho_c = C_c · D² · V_c / cos θ_i`. A camera raw image loaded per photosite
//!    ([`ImageView::cfa`]) measures one channel per pixel: the checks apply to that channel,
//!    and the sample is *partial*, its other two channels NaN (see
//!    [`skinbrdf_core::BrdfSample::measured`]). Its ray is the photosite's own (step 2, in the
//!    photosite image's camera), so no value is moved from where it was measured.
//!
//! Each sample keeps where it was measured: the hit's triangle and barycentrics, and the
//! scan's texture coordinates there when it has them ([`Geometry::surface_point`],
//! [`skinbrdf_core::SurfacePoint`]).
//!
//! Every dropped pixel is counted under exactly one reason: the first that is true of it, in
//! the order documented on [`FilterCounts`].

use glam::{DVec2, DVec3, Vec3};
use rayon::prelude::*;
use serde::Serialize;
use skinbrdf_core::{BrdfAngles, BrdfSample, CameraModel, Pose};
use skinbrdf_mesh::{CameraRays, Hit};
use skinbrdf_session::BayerPhase;

use crate::geometry::Geometry;
use crate::DerenderConfig;

/// Pixels added around the projected region's bounding box (vertex spacing and rounding).
pub const BBOX_MARGIN_PX: f64 = 3.0;
/// A printed target hides a pixel's surface point unless it lies at least this far behind it
/// along the pixel's ray, metres: head pose, target layout and scan registration are good to
/// about a millimetre; 5 mm keeps a wide margin, while a target on the far side of the head
/// (tens of millimetres and more behind the forehead) never masks the forehead.
pub const TARGET_DEPTH_TOL_M: f64 = 0.005;
/// Offset of a shadow ray's origin along the normal: well above f32 resolution at a metre
/// (0.1 µm) and below any geometry that matters.
pub const SHADOW_OFFSET_M: f64 = 1e-5;

/// A linear image as plain data: `V` per pixel (1.0 = white), row-major.
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Linear RGB per pixel (NaN in a channel a photosite image did not measure there).
    pub rgb: &'a [[f32; 3]],
    /// Saturation flag per pixel (any measured channel at or above the saturation level).
    pub saturated: Option<&'a [bool]>,
    /// A camera raw mosaic loaded per photosite: the Bayer phase at pixel `(0, 0)`; pixel
    /// `(x, y)` measures only the channel of its filter. `None`: every pixel measures all
    /// three channels.
    pub cfa: Option<BayerPhase>,
}

impl ImageView<'_> {
    /// The channels pixel `(x, y)` measured.
    pub fn measured(&self, x: u32, y: u32) -> [bool; 3] {
        skinbrdf_session::measured_channels(self.cfa, x, y)
    }
}

/// One measurement image with its poses and masks.
#[derive(Debug, Clone, Copy)]
pub struct Measurement<'a> {
    /// Index of the image in the session (recorded in each sample).
    pub image_index: u16,
    /// The pixels.
    pub image: ImageView<'a>,
    /// World from camera for this image.
    pub world_from_camera: Pose,
    /// World from head for this image.
    pub world_from_head: Pose,
    /// User mask of the region (true = use), row-major; `None` = no user mask.
    pub mask: Option<&'a [bool]>,
    /// Printed targets: per pixel, the distance from the camera centre to the nearest target
    /// along the pixel's ray, metres (`f32::INFINITY` = no target projects there; 0 = the
    /// pixel is on a target whatever lies behind it); `None` = unknown. A pixel is dropped as
    /// `on_target` when the target is not behind the surface it sees by more than
    /// [`TARGET_DEPTH_TOL_M`] (see `from_session::target_depths`).
    pub targets: Option<&'a [f32]>,
}

/// Why pixels were dropped, and how many were kept.
///
/// Every considered pixel is counted exactly once: under the first of these reasons that is
/// true of it, in this order (the order of the fields and of [`FilterCounts::reasons`]), or as
/// `kept`. The order follows what is known about the pixel: the mask before any ray, the ray,
/// what the ray meets, the geometry of the sample, and only then the pixel's value.
///
/// 1. `off_mask`: outside the user mask;
/// 2. `no_ray`: no camera ray (outside the distortion model's invertible range);
/// 3. `no_surface`: the ray misses the scan (whether or not a printed target projects there:
///    a target over empty background hides no skin);
/// 4. `on_target`: a printed target lies in front of the surface point the ray meets;
/// 5. `back_facing`, 6. `off_region`, 7. `grazing`, 8. `shadowed`: the surface point;
/// 9. `saturated`: flagged saturated, or a channel is +∞ (an overflowed value);
/// 10. `non_finite`: a channel is NaN or −∞ (a broken value, not a dark one);
/// 11. `below_noise_floor`: a finite channel below the noise floor.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FilterCounts {
    /// Pixels considered (inside the projected region's bounding box, at the stride).
    pub considered: u64,
    /// Outside the user mask.
    pub off_mask: u64,
    /// Pixels with no valid camera ray (outside the distortion model's invertible range).
    pub no_ray: u64,
    /// Ray hit nothing (a printed target projecting there does not change that).
    pub no_surface: u64,
    /// On a printed target that lies in front of the surface point the ray meets.
    pub on_target: u64,
    /// Hit a back face (ray leaked through the mesh, or the scan's winding is wrong).
    pub back_facing: u64,
    /// Hit outside the region of interest.
    pub off_region: u64,
    /// `cos θ_i` or `cos θ_e` below the grazing bound.
    pub grazing: u64,
    /// Shadowed from the light.
    pub shadowed: u64,
    /// Saturated pixel (flagged, or a channel +∞).
    pub saturated: u64,
    /// A channel NaN or −∞.
    pub non_finite: u64,
    /// A channel below the noise floor.
    pub below_noise_floor: u64,
    /// Samples kept.
    pub kept: u64,
}

impl FilterCounts {
    /// Adds another set of counts.
    pub fn add(&mut self, o: &Self) {
        self.considered += o.considered;
        self.off_mask += o.off_mask;
        self.no_ray += o.no_ray;
        self.no_surface += o.no_surface;
        self.on_target += o.on_target;
        self.back_facing += o.back_facing;
        self.off_region += o.off_region;
        self.grazing += o.grazing;
        self.shadowed += o.shadowed;
        self.saturated += o.saturated;
        self.non_finite += o.non_finite;
        self.below_noise_floor += o.below_noise_floor;
        self.kept += o.kept;
    }

    /// The drop reasons and counts, in filter order (see [`FilterCounts`]).
    pub fn reasons(&self) -> [(&'static str, u64); 11] {
        [
            ("off_mask", self.off_mask),
            ("no_ray", self.no_ray),
            ("no_surface", self.no_surface),
            ("on_target", self.on_target),
            ("back_facing", self.back_facing),
            ("off_region", self.off_region),
            ("grazing", self.grazing),
            ("shadowed", self.shadowed),
            ("saturated", self.saturated),
            ("non_finite", self.non_finite),
            ("below_noise_floor", self.below_noise_floor),
        ]
    }

    /// Pixels dropped, all reasons.
    pub fn dropped(&self) -> u64 {
        self.reasons().iter().map(|(_, n)| n).sum()
    }
}

/// Result of derendering one image.
#[derive(Debug, Clone, Default)]
pub struct ImageSamples {
    /// The samples, row-major pixel order.
    pub samples: Vec<BrdfSample>,
    /// Filter counts.
    pub counts: FilterCounts,
    /// Pixel bounding box that got rays: `[x0, y0, x1, y1]` inclusive; `None` if the region
    /// does not project into the image.
    pub bbox_px: Option<[u32; 4]>,
    /// Shadow rays cast.
    pub shadow_rays: u64,
    /// Pixels of the projected region (before the stride).
    pub region_pixels: u64,
    /// Wall time of the primary rays (coherent grid tracing), seconds.
    pub rays_s: f64,
    /// Wall time of the shadow rays (coherent any-hit tracing), seconds.
    pub shadow_s: f64,
}

/// Bounding box of the region's vertices projected into the image (grown by
/// [`BBOX_MARGIN_PX`]); [`region_pixels`] gives the pixels themselves.
pub fn region_bbox(
    geom: &Geometry,
    camera: &CameraModel,
    camera_from_head: &Pose,
) -> Option<[u32; 4]> {
    let (lo, hi) = geom
        .roi_vertices
        .par_iter()
        .filter_map(|&i| {
            let p = camera_from_head.transform_point(geom.mesh.positions[i as usize].as_dvec3());
            camera.project(p)
        })
        .fold(
            || (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(p), hi.max(p)),
        )
        .reduce(
            || (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let max = DVec2::new(camera.width_px as f64 - 1.0, camera.height_px as f64 - 1.0);
    let lo = (lo - BBOX_MARGIN_PX).floor().max(DVec2::ZERO);
    let hi = (hi + BBOX_MARGIN_PX).ceil().min(max);
    if lo.x > hi.x || lo.y > hi.y {
        return None;
    }
    Some([lo.x as u32, lo.y as u32, hi.x as u32, hi.y as u32])
}

/// Pixels added around each projected region triangle's bounding box (rounding, and the lens
/// bending the triangle's edges between its projected corners).
pub const REGION_MARGIN_PX: f64 = 1.5;

/// The pixels that can see the region of interest in one image.
#[derive(Debug, Clone)]
pub struct RegionPixels {
    /// Bounding box `[x0, y0, x1, y1]`, inclusive.
    pub bbox_px: [u32; 4],
    /// Row-major over the box: true where a region triangle's projection (grown by
    /// [`REGION_MARGIN_PX`]) covers the pixel centre.
    pub mask: Vec<bool>,
    /// True when some region vertex did not project (behind the camera or outside the lens
    /// model's range) and the whole box is used instead.
    pub whole_box: bool,
}

impl RegionPixels {
    /// Whether pixel `(x, y)` (image coordinates) can see the region.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        let [x0, y0, x1, y1] = self.bbox_px;
        if x < x0 || y < y0 || x > x1 || y > y1 {
            return false;
        }
        self.mask[((y - y0) * (x1 - x0 + 1) + (x - x0)) as usize]
    }

    /// Pixels marked.
    pub fn count(&self) -> usize {
        self.mask.iter().filter(|&&b| b).count()
    }
}

/// Projects the region's triangles into the image: only the pixels they cover need rays.
pub fn region_pixels(
    geom: &Geometry,
    camera: &CameraModel,
    camera_from_head: &Pose,
) -> Option<RegionPixels> {
    let proj: Vec<Option<DVec2>> = geom
        .region_vertices
        .par_iter()
        .map(|&i| {
            camera.project(
                camera_from_head.transform_point(geom.mesh.positions[i as usize].as_dvec3()),
            )
        })
        .collect();
    let (lo, hi) = proj.iter().flatten().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let max = DVec2::new(camera.width_px as f64 - 1.0, camera.height_px as f64 - 1.0);
    let blo = (lo - REGION_MARGIN_PX).ceil().max(DVec2::ZERO);
    let bhi = (hi + REGION_MARGIN_PX).floor().min(max);
    if blo.x > bhi.x || blo.y > bhi.y {
        return None;
    }
    let (x0, y0, x1, y1) = (blo.x as u32, blo.y as u32, bhi.x as u32, bhi.y as u32);
    let bw = (x1 - x0 + 1) as usize;
    let bh = (y1 - y0 + 1) as usize;
    let mut mask = vec![false; bw * bh];
    let mut whole_box = false;
    for t in &geom.region_triangles {
        let (Some(a), Some(b), Some(c)) = (
            proj[t[0] as usize],
            proj[t[1] as usize],
            proj[t[2] as usize],
        ) else {
            whole_box = true;
            break;
        };
        let tlo = (a.min(b).min(c) - REGION_MARGIN_PX).ceil().max(blo);
        let thi = (a.max(b).max(c) + REGION_MARGIN_PX).floor().min(bhi);
        if tlo.x > thi.x || tlo.y > thi.y {
            continue;
        }
        let (xa, xb) = (tlo.x as usize - x0 as usize, thi.x as usize - x0 as usize);
        for y in tlo.y as usize..=thi.y as usize {
            let row = (y - y0 as usize) * bw;
            mask[row + xa..=row + xb].fill(true);
        }
    }
    if whole_box {
        mask.fill(true);
    }
    Some(RegionPixels {
        bbox_px: [x0, y0, x1, y1],
        mask,
        whole_box,
    })
}

/// Derenders one image. `light_world_m` is the light's position in the world frame and
/// `calibration_c` the per-channel constant C. Builds the camera's undistortion table; for
/// many images of one camera use [`derender_image_with_rays`].
pub fn derender_image(
    geom: &Geometry,
    camera: &CameraModel,
    light_world_m: DVec3,
    calibration_c: [f64; 3],
    m: &Measurement<'_>,
    cfg: &DerenderConfig,
) -> ImageSamples {
    derender_image_with_rays(
        geom,
        &CameraRays::new(camera),
        light_world_m,
        calibration_c,
        m,
        cfg,
    )
}

/// A surface point that passed every filter before the shadow test.
#[derive(Debug, Clone, Copy)]
struct Pending {
    /// Column in the ray grid.
    k: usize,
    x: u32,
    y: u32,
    /// Pixel index in the image.
    idx: usize,
    /// The ray's hit (the sample's surface point).
    hit: Hit,
    p: DVec3,
    n: DVec3,
    wi: DVec3,
    we: DVec3,
    dist: f64,
    cos_i: f64,
}

/// Why a grid pixel got no ray (or that it got one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PixelState {
    Outside,
    OffMask,
    NoRay,
    Traced,
}

/// [`derender_image`] with a prepared undistortion table of the camera.
pub fn derender_image_with_rays(
    geom: &Geometry,
    rays: &CameraRays,
    light_world_m: DVec3,
    calibration_c: [f64; 3],
    m: &Measurement<'_>,
    cfg: &DerenderConfig,
) -> ImageSamples {
    let camera = rays.camera();
    let head_from_world = m.world_from_head.inverse();
    let head_from_camera = head_from_world * m.world_from_camera;
    let camera_from_head = head_from_camera.inverse();
    let light = head_from_world.transform_point(light_world_m);
    let origin = head_from_camera.translation_m;
    let Some(region) = region_pixels(geom, camera, &camera_from_head) else {
        return ImageSamples::default();
    };
    let [x0, y0, x1, y1] = region.bbox_px;
    let stride = cfg.stride.max(1);
    let cos_limit = cfg.grazing_limit_deg.to_radians().cos();
    let shadows = cfg
        .shadows
        .needs_rays(geom.can_shadow_within(cfg.grazing_limit_deg));
    let w = m.image.width as usize;
    // Aligned to a global grid (x, y multiples of the stride) so images subsample alike.
    let align = |v: u32| v.div_ceil(stride) * stride;
    let xs: Vec<u32> = (align(x0)..=x1).step_by(stride as usize).collect();
    let ys: Vec<u32> = (align(y0)..=y1).step_by(stride as usize).collect();
    let gw = xs.len();
    let mut result = ImageSamples {
        bbox_px: Some(region.bbox_px),
        region_pixels: region.count() as u64,
        ..Default::default()
    };
    if gw == 0 || ys.is_empty() {
        return result;
    }
    // 1. Which pixels get a ray (camera rays from the table, moved to the head frame).
    let mut dirs = vec![Vec3::ZERO; gw * ys.len()];
    let mut state = vec![PixelState::Outside; gw * ys.len()];
    dirs.par_chunks_mut(gw)
        .zip(state.par_chunks_mut(gw))
        .zip(ys.par_iter())
        .for_each(|((drow, srow), &y)| {
            for (k, &x) in xs.iter().enumerate() {
                if !region.contains(x, y) {
                    continue;
                }
                let idx = y as usize * w + x as usize;
                srow[k] = if m.mask.is_some_and(|mk| !mk[idx]) {
                    PixelState::OffMask
                } else if let Some(d_cam) = rays.pixel_ray(DVec2::new(x as f64, y as f64)) {
                    drow[k] = head_from_camera.transform_vector(d_cam).as_vec3();
                    PixelState::Traced
                } else {
                    PixelState::NoRay
                };
            }
        });
    // 2. Closest hits, tile by tile.
    let t = std::time::Instant::now();
    let hits = geom
        .bvh
        .intersect_grid(origin.as_vec3(), &dirs, gw, f32::INFINITY);
    result.rays_s = t.elapsed().as_secs_f64();
    // 3. Surface points, filtered up to the shadow test.
    let per_row: Vec<(Vec<Pending>, FilterCounts)> = hits
        .par_chunks(gw)
        .zip(state.par_chunks(gw))
        .zip(dirs.par_chunks(gw))
        .zip(ys.par_iter())
        .map(|(((hrow, srow), drow), &y)| {
            let mut out = Vec::new();
            let mut c = FilterCounts::default();
            for (k, &x) in xs.iter().enumerate() {
                match srow[k] {
                    PixelState::Outside => continue,
                    PixelState::OffMask => c.off_mask += 1,
                    PixelState::NoRay | PixelState::Traced => {}
                }
                c.considered += 1;
                if srow[k] == PixelState::OffMask {
                    continue;
                }
                if srow[k] == PixelState::NoRay {
                    c.no_ray += 1;
                    continue;
                }
                let Some(hit) = hrow[k] else {
                    c.no_surface += 1;
                    continue;
                };
                let idx = y as usize * w + x as usize;
                // The nearest printed target along the ray, if any.
                let target_m = m.targets.map_or(f32::INFINITY, |t| t[idx]);
                let hidden_by_target = |surface_m: f64| {
                    target_m.is_finite() && f64::from(target_m) <= surface_m + TARGET_DEPTH_TOL_M
                };
                let d_ray = drow[k].as_dvec3();
                if hidden_by_target(f64::from(hit.t_m) * d_ray.length()) {
                    c.on_target += 1;
                    continue;
                }
                let d = d_ray.normalize();
                let ng = geom
                    .mesh
                    .face_normal_area2(hit.triangle as usize)
                    .as_dvec3();
                if ng.dot(d) >= 0.0 {
                    c.back_facing += 1;
                    continue;
                }
                let p = origin + d_ray * hit.t_m as f64;
                if geom.roi.is_some_and(|r| !r.contains(p)) {
                    c.off_region += 1;
                    continue;
                }
                let n = geom.normals.at(&geom.mesh, &hit).as_dvec3();
                let to_light = light - p;
                let dist = to_light.length();
                let wi = to_light / dist;
                let we = -d;
                let (cos_i, cos_e) = (n.dot(wi), n.dot(we));
                if !(cos_i > cos_limit && cos_e > cos_limit) {
                    c.grazing += 1;
                    continue;
                }
                out.push(Pending {
                    k,
                    x,
                    y,
                    idx,
                    hit,
                    p,
                    n,
                    wi,
                    we,
                    dist,
                    cos_i,
                });
            }
            (out, c)
        })
        .collect();
    // 4. Shadow rays, when needed: all of the image's points towards the light at once with the
    // coherent any-hit tracer (the same verdict as one `occluded` per point).
    let occluded: Option<Vec<bool>> = shadows.then(|| {
        let mut origins = vec![Vec3::NAN; gw * ys.len()];
        for (r, (pending, _)) in per_row.iter().enumerate() {
            for q in pending {
                origins[r * gw + q.k] = (q.p + q.n * SHADOW_OFFSET_M).as_vec3();
            }
        }
        let t = std::time::Instant::now();
        let o =
            geom.bvh
                .occluded_toward_grid(light.as_vec3(), &origins, gw, SHADOW_OFFSET_M as f32);
        result.shadow_s = t.elapsed().as_secs_f64();
        o
    });
    // 5. Samples.
    let finished: Vec<(Vec<BrdfSample>, FilterCounts, u64)> = per_row
        .into_par_iter()
        .enumerate()
        .map(|(r, (pending, mut c))| {
            let mut out = Vec::with_capacity(pending.len());
            let mut shadow_rays = 0u64;
            for q in pending {
                let Pending {
                    k,
                    x,
                    y,
                    idx,
                    hit,
                    n,
                    wi,
                    we,
                    dist,
                    cos_i,
                    ..
                } = q;
                if let Some(occ) = &occluded {
                    shadow_rays += 1;
                    if occ[r * gw + k] {
                        c.shadowed += 1;
                        continue;
                    }
                }
                // Only the channels the pixel measured (a photosite's own) count; the others
                // stay NaN in the sample.
                let measured = m.image.measured(x, y);
                let v = m.image.rgb[idx];
                let values = || v.iter().zip(measured).filter(|(_, m)| *m).map(|(v, _)| *v);
                // +inf is an overflowed (saturated) value whatever the saturation mask says.
                if m.image.saturated.is_some_and(|s| s[idx])
                    || values().any(|ch| ch == f32::INFINITY)
                {
                    c.saturated += 1;
                    continue;
                }
                if !values().all(|ch| ch.is_finite()) {
                    c.non_finite += 1;
                    continue;
                }
                if values().any(|ch| f64::from(ch) < cfg.noise_floor) {
                    c.below_noise_floor += 1;
                    continue;
                }
                let kk = dist * dist / cos_i;
                let rho: [f32; 3] = std::array::from_fn(|ch| {
                    if measured[ch] {
                        (calibration_c[ch] * kk * v[ch] as f64) as f32
                    } else {
                        f32::NAN
                    }
                });
                let angles = BrdfAngles::from_world(n, wi, we);
                let mut s = BrdfSample::from_angles(&angles, rho);
                s.image_index = m.image_index;
                s.pixel = [x as u16, y as u16];
                s.surface = geom.surface_point(&hit);
                out.push(s);
                c.kept += 1;
            }
            (out, c, shadow_rays)
        })
        .collect();
    for (s, c, sr) in finished {
        result.samples.extend(s);
        result.counts.add(&c);
        result.shadow_rays += sr;
    }
    result
}
