//! Derendering one measurement image: pixels to BRDF samples (the method's equation 2).
//!
//! For each pixel that can see the region of interest:
//!
//! 1. **Which pixels.** The region's scan vertices are projected into the image (through the
//!    lens distortion); only the bounding box of their projections, grown by
//!    [`BBOX_MARGIN_PX`], gets rays. Pixels off the user mask or on a target (when masks are
//!    given) are dropped before any ray.
//! 2. **Ray.** `CameraModel::pixel_ray` undistorts the pixel centre (Newton on Brown–Conrady);
//!    the ray moves to the head frame by `head_from_camera = world_from_head⁻¹ · world_from_camera`.
//! 3. **Surface.** Closest hit on the scan's BVH; the hit must face the camera (a back face means
//!    the ray leaked through the mesh) and lie inside the region sphere. Its normal is the
//!    barycentric blend of the per-vertex planar-fit normals.
//! 4. **Light and camera.** `w_i` towards the light (head frame), `D` its distance, `w_e`
//!    towards the camera centre. Samples with `cos θ_i` or `cos θ_e` below `cos(grazing limit)`
//!    are dropped: `1/cos θ_i` amplifies noise and normal error without bound near grazing
//!    (a normal error `δ` gives a relative error `tan θ · δ`), so the limit bounds it.
//! 5. **Shadow.** Only when the geometry can shadow the region (see [`crate::geometry`]), a ray
//!    from the point (offset [`SHADOW_OFFSET_M`] along the normal) to the light.
//! 6. **Value.** The linearized pixel value `V`; saturated pixels and pixels with any channel
//!    below the noise floor are dropped; `rho_c = C_c · D² · V_c / cos θ_i`.
//!
//! Every dropped pixel is counted under exactly one reason (the first that applies, in the
//! order of [`FilterCounts`]).

use glam::{DVec2, DVec3, Vec3};
use rayon::prelude::*;
use serde::Serialize;
use skinbrdf_core::{BrdfAngles, BrdfSample, CameraModel, Pose};

use crate::geometry::Geometry;
use crate::DerenderConfig;

/// Pixels added around the projected region's bounding box (vertex spacing and rounding).
pub const BBOX_MARGIN_PX: f64 = 3.0;
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
    /// Linear RGB per pixel.
    pub rgb: &'a [[f32; 3]],
    /// Saturation flag per pixel (any channel at or above the saturation level).
    pub saturated: Option<&'a [bool]>,
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
    /// Pixels on printed targets (true = on a target); `None` = unknown.
    pub targets: Option<&'a [bool]>,
}

/// Why pixels were dropped, and how many were kept.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FilterCounts {
    /// Pixels considered (inside the projected region's bounding box, at the stride).
    pub considered: u64,
    /// Outside the user mask.
    pub off_mask: u64,
    /// On a printed target.
    pub on_target: u64,
    /// Ray hit nothing.
    pub no_surface: u64,
    /// Hit a back face (ray leaked through the mesh, or the scan's winding is wrong).
    pub back_facing: u64,
    /// Hit outside the region of interest.
    pub off_region: u64,
    /// `cos θ_i` or `cos θ_e` below the grazing bound.
    pub grazing: u64,
    /// Shadowed from the light.
    pub shadowed: u64,
    /// Saturated pixel.
    pub saturated: u64,
    /// A channel below the noise floor.
    pub below_noise_floor: u64,
    /// Pixels with no valid camera ray (outside the distortion model's invertible range).
    pub no_ray: u64,
    /// Samples kept.
    pub kept: u64,
}

impl FilterCounts {
    /// Adds another set of counts.
    pub fn add(&mut self, o: &Self) {
        self.considered += o.considered;
        self.off_mask += o.off_mask;
        self.on_target += o.on_target;
        self.no_surface += o.no_surface;
        self.back_facing += o.back_facing;
        self.off_region += o.off_region;
        self.grazing += o.grazing;
        self.shadowed += o.shadowed;
        self.saturated += o.saturated;
        self.below_noise_floor += o.below_noise_floor;
        self.no_ray += o.no_ray;
        self.kept += o.kept;
    }

    /// The drop reasons and counts, in filter order.
    pub fn reasons(&self) -> [(&'static str, u64); 10] {
        [
            ("off_mask", self.off_mask),
            ("on_target", self.on_target),
            ("no_ray", self.no_ray),
            ("no_surface", self.no_surface),
            ("back_facing", self.back_facing),
            ("off_region", self.off_region),
            ("grazing", self.grazing),
            ("shadowed", self.shadowed),
            ("saturated", self.saturated),
            ("below_noise_floor", self.below_noise_floor),
        ]
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
}

/// Bounding box of the region's vertices projected into the image.
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

/// Derenders one image. `light_world_m` is the light's position in the world frame and
/// `calibration_c` the per-channel constant C.
pub fn derender_image(
    geom: &Geometry,
    camera: &CameraModel,
    light_world_m: DVec3,
    calibration_c: [f64; 3],
    m: &Measurement<'_>,
    cfg: &DerenderConfig,
) -> ImageSamples {
    let head_from_world = m.world_from_head.inverse();
    let head_from_camera = head_from_world * m.world_from_camera;
    let camera_from_head = head_from_camera.inverse();
    let light = head_from_world.transform_point(light_world_m);
    let origin = head_from_camera.translation_m;
    let Some(bbox) = region_bbox(geom, camera, &camera_from_head) else {
        return ImageSamples::default();
    };
    let [x0, y0, x1, y1] = bbox;
    let stride = cfg.stride.max(1);
    let cos_limit = cfg.grazing_limit_deg.to_radians().cos();
    let shadows = cfg.shadows.needs_rays(geom.can_self_shadow);
    let w = m.image.width as usize;
    // Aligned to a global grid (x, y multiples of the stride) so images subsample alike.
    let align = |v: u32| v.div_ceil(stride) * stride;
    let rows: Vec<u32> = (align(y0)..=y1).step_by(stride as usize).collect();
    let per_row: Vec<(Vec<BrdfSample>, FilterCounts, u64)> = rows
        .par_iter()
        .map(|&y| {
            let mut out = Vec::new();
            let mut c = FilterCounts::default();
            let mut shadow_rays = 0u64;
            for x in (align(x0)..=x1).step_by(stride as usize) {
                c.considered += 1;
                let idx = y as usize * w + x as usize;
                if m.mask.is_some_and(|mk| !mk[idx]) {
                    c.off_mask += 1;
                    continue;
                }
                if m.targets.is_some_and(|t| t[idx]) {
                    c.on_target += 1;
                    continue;
                }
                let Some(d_cam) = camera.pixel_ray(DVec2::new(x as f64, y as f64)) else {
                    c.no_ray += 1;
                    continue;
                };
                let d = head_from_camera.transform_vector(d_cam);
                let Some(hit) = geom
                    .bvh
                    .intersect(origin.as_vec3(), d.as_vec3(), f32::INFINITY)
                else {
                    c.no_surface += 1;
                    continue;
                };
                let ng = geom
                    .mesh
                    .face_normal_area2(hit.triangle as usize)
                    .as_dvec3();
                if ng.dot(d) >= 0.0 {
                    c.back_facing += 1;
                    continue;
                }
                let p = origin + d * hit.t_m as f64;
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
                if shadows {
                    shadow_rays += 1;
                    let o = p + n * SHADOW_OFFSET_M;
                    let len = (light - o).length() - SHADOW_OFFSET_M;
                    let dir: Vec3 = ((light - o) / (light - o).length()).as_vec3();
                    if geom.bvh.occluded(o.as_vec3(), dir, len as f32) {
                        c.shadowed += 1;
                        continue;
                    }
                }
                let v = m.image.rgb[idx];
                // +inf is an overflowed (saturated) value whatever the saturation mask says.
                if m.image.saturated.is_some_and(|s| s[idx]) || v.contains(&f32::INFINITY) {
                    c.saturated += 1;
                    continue;
                }
                if v.iter()
                    .any(|&ch| ch.is_nan() || (ch as f64) < cfg.noise_floor)
                {
                    c.below_noise_floor += 1;
                    continue;
                }
                let k = dist * dist / cos_i;
                let rho: [f32; 3] =
                    std::array::from_fn(|ch| (calibration_c[ch] * k * v[ch] as f64) as f32);
                let angles = BrdfAngles::from_world(n, wi, we);
                let mut s = BrdfSample::from_angles(&angles, rho);
                s.image_index = m.image_index;
                s.pixel = [x as u16, y as u16];
                out.push(s);
                c.kept += 1;
            }
            (out, c, shadow_rays)
        })
        .collect();
    let mut result = ImageSamples {
        bbox_px: Some(bbox),
        ..Default::default()
    };
    for (s, c, sr) in per_row {
        result.samples.extend(s);
        result.counts.add(&c);
        result.shadow_rays += sr;
    }
    result
}
