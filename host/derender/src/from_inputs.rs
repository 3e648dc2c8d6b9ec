//! The whole derender of a session as plain data: geometry, camera, light, C (known or from the
//! standard), one pose pair per image, and images loaded one at a time (a 36-image session of
//! 24 MP images never sits in memory at once).

use std::time::{Duration, Instant};

use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::{BrdfSample, CameraModel, Pose};
use skinbrdf_mesh::CameraRays;

use crate::calibrate::{calibrate_c, Calibration, StandardImage};
use crate::geometry::Geometry;
use crate::image::{derender_image_with_rays, FilterCounts, ImageView, Measurement};
use crate::{DerenderConfig, DerenderError};

/// Poses of one image.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ImagePoses {
    /// World from camera.
    pub world_from_camera: Pose,
    /// World from head.
    pub world_from_head: Pose,
}

/// Where a pose (or the camera, the light, the standard's pose) came from. Ordered from the
/// most direct to the least: a set of poses is reported by its least direct member.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub enum PoseSource {
    /// Known in `session.toml` (a stationary sample's head frame included).
    Session,
    /// The pose stage's result (`poses.json`).
    Estimated,
    /// `truth.json` (synthetic sessions; only when asked for).
    Truth,
}

impl std::fmt::Display for PoseSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Session => "session.toml",
            Self::Estimated => "the pose stage",
            Self::Truth => "truth.json",
        })
    }
}

/// Where C came from (reported).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum CalibrationSource {
    /// `known.calibration_c` in `session.toml`.
    Known,
    /// The reference standard's images (equation 3).
    Standard,
}

impl std::fmt::Display for CalibrationSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Known => "session known.calibration_c",
            Self::Standard => "reference standard (equation 3)",
        })
    }
}

/// A decoded linear image owned by the caller's loader.
#[derive(Debug, Clone)]
pub struct OwnedImage {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Linear RGB.
    pub rgb: Vec<[f32; 3]>,
    /// Saturation flags.
    pub saturated: Vec<bool>,
    /// The mosaic of a camera raw image loaded per photosite (see [`ImageView::cfa`]).
    pub cfa: Option<skinbrdf_session::BayerPhase>,
    /// Optional user mask (true = use).
    pub mask: Option<Vec<bool>>,
    /// Optional printed-target depths: distance from the camera centre to the nearest printed
    /// target along each pixel's ray, metres (`f32::INFINITY` = none; see
    /// [`crate::image::Measurement::targets`]).
    pub targets: Option<Vec<f32>>,
}

impl OwnedImage {
    /// A view for [`crate::image::derender_image`].
    pub fn view(&self) -> ImageView<'_> {
        ImageView {
            width: self.width,
            height: self.height,
            rgb: &self.rgb,
            saturated: Some(&self.saturated),
            cfa: self.cfa,
        }
    }
}

/// How C is obtained.
#[derive(Debug, Clone)]
pub enum CalibrationInput {
    /// Known per channel.
    Known([f64; 3]),
    /// From the standard: its BRDF, size, pose, and the session indices of its images.
    Standard {
        /// Its BRDF.
        brdf: BrdfModel,
        /// Reflecting area, metres.
        size_m: [f64; 2],
        /// World from standard.
        world_from_standard: Pose,
        /// `(session image index, world_from_camera)` per standard image.
        images: Vec<(usize, Pose)>,
    },
}

impl CalibrationInput {
    /// Where C comes from.
    pub fn source(&self) -> CalibrationSource {
        match self {
            Self::Known(_) => CalibrationSource::Known,
            Self::Standard { .. } => CalibrationSource::Standard,
        }
    }
}

/// Everything derendering needs besides the geometry and the pixels (built from a session by
/// [`DerenderInputs::new`]).
#[derive(Debug, Clone)]
pub struct DerenderInputs {
    /// The calibrated camera.
    pub camera: CameraModel,
    /// Light (flash emitting point), world frame, metres.
    pub light_position_m: DVec3,
    /// C.
    pub calibration: CalibrationInput,
    /// `(session image index, poses)` per measurement image.
    pub measurements: Vec<(usize, ImagePoses)>,
    /// Where the measurement poses came from (the least direct of them).
    pub pose_source: PoseSource,
}

/// Wall time per stage.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StageTimes {
    /// Loading and repairing the scan, seconds.
    pub mesh_load_s: f64,
    /// Building the BVH, seconds.
    pub bvh_s: f64,
    /// Shading normals, seconds.
    pub normals_s: f64,
    /// Convexity test, seconds.
    pub convexity_s: f64,
    /// Decoding and linearizing images, seconds.
    pub image_load_s: f64,
    /// Estimating C, seconds.
    pub calibration_s: f64,
    /// Rays and samples, seconds (camera table, region projection, rays, samples).
    pub derender_s: f64,
    /// Of which the primary rays (coherent grid tracing), seconds.
    pub rays_s: f64,
    /// Of which the shadow rays (coherent any-hit tracing), seconds.
    pub shadow_rays_s: f64,
    /// Everything, seconds.
    pub total_s: f64,
}

/// Per-image summary.
#[derive(Debug, Clone, Serialize)]
pub struct ImageReport {
    /// Session image index.
    pub image_index: usize,
    /// Filter counts.
    pub counts: FilterCounts,
    /// Pixel box that got rays.
    pub bbox_px: Option<[u32; 4]>,
}

/// The result of derendering a session.
#[derive(Debug, Clone, Serialize)]
pub struct DerenderReport {
    /// The samples.
    #[serde(skip)]
    pub samples: Vec<BrdfSample>,
    /// Counts over all images.
    pub counts: FilterCounts,
    /// Per image.
    pub images: Vec<ImageReport>,
    /// Pixels of the projected region summed over images (before the stride).
    pub region_pixels: u64,
    /// C used.
    pub c: [f64; 3],
    /// C estimated from the standard (with its spread), when it was.
    pub calibration: Option<Calibration>,
    /// Whether shadow rays were cast, and why.
    pub shadow_rays: bool,
    /// Shadow rays cast.
    pub shadow_rays_cast: u64,
    /// The convexity verdict at the configured grazing limit.
    pub region_can_self_shadow: bool,
    /// Largest elevation of the geometry above the region's tangent planes, degrees (the
    /// convexity test's measure, see [`crate::geometry`]).
    pub region_shadow_elevation_deg: f64,
    /// Normal fit radius used, metres (0 for vertex normals).
    pub normal_radius_m: f64,
    /// Poses used.
    pub pose_source: PoseSource,
    /// The configuration.
    pub config: DerenderConfig,
    /// Timings.
    pub times: StageTimes,
    /// Primary rays cast.
    pub primary_rays: u64,
    /// Error against truth, when known.
    pub truth_error: Option<crate::TruthError>,
}

/// Derenders from plain data. `load(i)` decodes session image `i`.
pub fn derender_with_loader(
    geom: &Geometry,
    inputs: &DerenderInputs,
    cfg: &DerenderConfig,
    load: impl Fn(usize) -> Result<OwnedImage, DerenderError> + Sync,
) -> Result<DerenderReport, DerenderError> {
    cfg.validate()?;
    let start = Instant::now();
    let mut times = StageTimes {
        bvh_s: geom.bvh_time.as_secs_f64(),
        normals_s: geom.normals_time.as_secs_f64(),
        convexity_s: geom.convexity_time.as_secs_f64(),
        ..Default::default()
    };
    let mut load_time = Duration::ZERO;
    let (c, calibration) = match &inputs.calibration {
        CalibrationInput::Known(c) => (*c, None),
        CalibrationInput::Standard {
            brdf,
            size_m,
            world_from_standard,
            images,
        } => {
            let t = Instant::now();
            let owned: Vec<(OwnedImage, Pose)> = images
                .par_iter()
                .map(|(i, wfc)| Ok((load(*i)?, *wfc)))
                .collect::<Result<_, DerenderError>>()?;
            load_time += t.elapsed();
            let t = Instant::now();
            let views: Vec<StandardImage<'_>> = owned
                .iter()
                .map(|(img, wfc)| StandardImage {
                    image: img.view(),
                    world_from_camera: *wfc,
                    world_from_standard: *world_from_standard,
                    mask: img.mask.as_deref(),
                })
                .collect();
            let cal = calibrate_c(
                &inputs.camera,
                inputs.light_position_m,
                brdf,
                *size_m,
                &views,
                cfg.c_estimator,
                cfg,
            )?;
            times.calibration_s = t.elapsed().as_secs_f64();
            (cal.c, Some(cal))
        }
    };
    let mut samples = Vec::new();
    let mut counts = FilterCounts::default();
    let mut images = Vec::new();
    let mut shadow_rays_cast = 0;
    let mut derender_time = Duration::ZERO;
    let mut rays_s = 0.0;
    let mut region_pixels = 0;
    let t = Instant::now();
    let camera_rays = CameraRays::new(&inputs.camera);
    derender_time += t.elapsed();
    // Decoding dominates on small regions: decode a batch of images in parallel (one per
    // rayon thread, bounding memory to that many images), then trace them one by one (the
    // tracing itself is parallel over rows).
    let batch = rayon::current_num_threads().max(1);
    for chunk in inputs.measurements.chunks(batch) {
        let t = Instant::now();
        let loaded: Vec<Result<OwnedImage, DerenderError>> =
            chunk.par_iter().map(|(i, _)| load(*i)).collect();
        load_time += t.elapsed();
        for ((i, poses), img) in chunk.iter().zip(loaded) {
            let img = img?;
            let t = Instant::now();
            let index = u16::try_from(*i).map_err(|_| DerenderError::ImageIndex { index: *i })?;
            let m = Measurement {
                image_index: index,
                image: img.view(),
                world_from_camera: poses.world_from_camera,
                world_from_head: poses.world_from_head,
                mask: img.mask.as_deref(),
                targets: img.targets.as_deref(),
            };
            let r =
                derender_image_with_rays(geom, &camera_rays, inputs.light_position_m, c, &m, cfg);
            derender_time += t.elapsed();
            rays_s += r.rays_s;
            times.shadow_rays_s += r.shadow_s;
            region_pixels += r.region_pixels;
            counts.add(&r.counts);
            shadow_rays_cast += r.shadow_rays;
            images.push(ImageReport {
                image_index: *i,
                counts: r.counts,
                bbox_px: r.bbox_px,
            });
            samples.extend(r.samples);
        }
    }
    times.image_load_s = load_time.as_secs_f64();
    times.derender_s = derender_time.as_secs_f64();
    times.rays_s = rays_s;
    times.total_s =
        start.elapsed().as_secs_f64() + times.bvh_s + times.normals_s + times.convexity_s;
    // Pixels under a target's projection are traced too (the target hides them only when it lies
    // in front of the surface their ray meets).
    let primary_rays = counts.considered - counts.off_mask - counts.no_ray;
    Ok(DerenderReport {
        samples,
        counts,
        images,
        region_pixels,
        c,
        calibration,
        shadow_rays: cfg
            .shadows
            .needs_rays(geom.can_shadow_within(cfg.grazing_limit_deg)),
        shadow_rays_cast,
        region_can_self_shadow: geom.can_shadow_within(cfg.grazing_limit_deg),
        region_shadow_elevation_deg: geom.shadow_elevation_deg,
        normal_radius_m: geom.normals.radius_m,
        pose_source: inputs.pose_source,
        config: *cfg,
        times,
        primary_rays,
        truth_error: None,
    })
}
