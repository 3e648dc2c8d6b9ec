//! The physical set-up of a synthetic session: where the targets, the flash, the standard and
//! the camera are for every shot, and how the head moves.
//!
//! World frame: origin at the nominal head centre, +z up, +y the direction the face looks.
//! Azimuths are measured about +z from +y towards +x. The reference structure (which defines
//! the world frame) carries an arc of targets above and around the head, facing outwards and
//! slightly down, plus a bar of targets above the flash, facing the head. The flash stands at
//! `flash_azimuth_deg`, `flash_distance_m` from the head axis, aimed at the forehead, with a ring
//! of eight targets around its 82 mm diffuser. The headdress carries two rows of targets on a
//! band above the forehead. The camera moves on the circle (2 m) from near the flash (retro-
//! reflection) to the far side (grazing), always aimed at the forehead; then the six extra
//! images: three of the flash (light position), one of the standard under the flash
//! (reference standard) and two more of the standard (standard position).

use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_session::capture::{CaptureRecord, ShotOutcome};
use skinbrdf_session::{ImageRole, Target};

use crate::scene::Scene;
use crate::shape::Shape;

/// First id of each target group (tag36h11 ids are unique across the session).
pub const REFERENCE_ID0: u32 = 0;
/// First headdress id.
pub const HEADDRESS_ID0: u32 = 100;
/// First flash id.
pub const FLASH_ID0: u32 = 200;
/// First standard id.
pub const STANDARD_ID0: u32 = 300;

/// The fixed parts of the set-up.
#[derive(Debug, Clone)]
pub struct Rig {
    /// The true camera.
    pub camera: CameraModel,
    /// The sample's true surface (head frame).
    pub shape: Shape,
    /// Centre of the region of interest, head frame.
    pub roi_centre_head: DVec3,
    /// Reference targets, world frame.
    pub reference: Vec<Target>,
    /// Headdress targets, head frame.
    pub headdress: Vec<Target>,
    /// Flash targets, flash frame.
    pub flash_targets: Vec<Target>,
    /// Standard targets, standard frame.
    pub standard_targets: Vec<Target>,
    /// World from flash (+z = emission direction, towards the forehead).
    pub world_from_flash: Pose,
    /// World from standard (its surface is z = 0, normal +z).
    pub world_from_standard: Pose,
}

impl Rig {
    /// The flash's emitting point, world frame.
    pub fn light_position_m(&self) -> DVec3 {
        self.world_from_flash.translation_m
    }
}

/// One shot.
#[derive(Debug, Clone, PartialEq)]
pub struct Shot {
    /// Image file, relative to the session.
    pub file: String,
    /// Role.
    pub role: ImageRole,
    /// Exposure time, device microseconds.
    pub exposure_us: u64,
    /// Index of the exposure in the capture record, if rendered from one.
    pub exposure_index: Option<u32>,
    /// World from camera.
    pub world_from_camera: Pose,
    /// World from head.
    pub world_from_head: Pose,
    /// Whether the flash fired.
    pub flash_fired: bool,
    /// Whether the room light is on.
    pub ambient_on: bool,
    /// Whether the reflectance standard is in the scene.
    pub standard_present: bool,
}

fn camera_model(scene: &Scene) -> CameraModel {
    let c = &scene.camera;
    let mut m = CameraModel::from_fov(c.width_px, c.height_px, c.hfov_deg.to_radians());
    m.distortion = c.distortion;
    m
}

/// Builds the fixed set-up of a scene.
pub fn build_rig(scene: &Scene) -> Rig {
    let shape = Shape::from_scene(&scene.geometry);
    let g = &scene.geometry;
    let t = &scene.targets;
    let s = &scene.session;
    let roi_centre_head = shape.point(0.0, g.roi_elevation_deg.to_radians());
    let head_top = shape.bounding_radius();

    // Reference arc: two rows above the head, facing outwards and 15 degrees down.
    let mut reference = Vec::new();
    let mut id = REFERENCE_ID0;
    let ring_r = 0.45;
    for (row, z) in [head_top + 0.08, head_top + 0.16].into_iter().enumerate() {
        let mut az_deg = -60.0 + 5.0 * row as f64;
        while az_deg <= 100.0 {
            let radial = crate::shape::direction(az_deg.to_radians(), 0.0);
            let out = (radial * 15f64.to_radians().cos() - DVec3::Z * 15f64.to_radians().sin())
                .normalize();
            let centre = radial * ring_r + DVec3::Z * z;
            if let Some(tg) = Target::square(id, t.reference_size_m, centre, out, DVec3::Z) {
                reference.push(tg);
                id += 1;
            }
            az_deg += 10.0;
        }
    }

    // Flash: aimed at the forehead.
    let fa = s.flash_azimuth_deg.to_radians();
    let flash_pos =
        crate::shape::direction(fa, 0.0) * s.flash_distance_m + DVec3::Z * s.flash_height_m;
    let world_from_flash =
        Pose::look_at(flash_pos, roi_centre_head, DVec3::Z).unwrap_or(Pose::IDENTITY);
    // Bar of reference targets above the flash, facing the head.
    let toward_head = world_from_flash.transform_vector(DVec3::Z);
    let right = world_from_flash.transform_vector(DVec3::X);
    let up = world_from_flash.transform_vector(DVec3::NEG_Y);
    for dz in [0.16, 0.26] {
        for k in 0..4 {
            let dx = -0.24 + 0.16 * k as f64;
            let centre = flash_pos + right * dx + up * dz;
            if let Some(tg) = Target::square(id, t.reference_size_m, centre, toward_head, DVec3::Z)
            {
                reference.push(tg);
                id += 1;
            }
        }
    }

    // Flash targets: a ring of eight around the diffuser, in the flash frame (+z out).
    let flash_targets = (0..8)
        .filter_map(|k| {
            let a = k as f64 * std::f64::consts::FRAC_PI_4;
            let r = 0.5 * s.flash_diameter_m + 0.9 * t.flash_size_m + 0.01;
            let centre = DVec3::new(r * a.cos(), r * a.sin(), 0.0);
            Target::square(
                FLASH_ID0 + k,
                t.flash_size_m,
                centre,
                DVec3::Z,
                DVec3::NEG_Y,
            )
        })
        .collect();

    // Headdress: two rows on a band above the forehead.
    let mut headdress = Vec::new();
    let mut hid = HEADDRESS_ID0;
    let bounds_el = match shape {
        Shape::Cylinder { .. } => [(0.0, 0.0), (0.0, 0.0)],
        Shape::Star { .. } => [(38f64, 20.0), (54.0, 20.0)],
    };
    for (row, (el_deg, step)) in bounds_el.into_iter().enumerate() {
        let (el, half) = match shape {
            Shape::Cylinder { length_m, radius_m } => {
                // On a cylinder the band sits near the top of the side.
                let z = 0.5 * length_m - 0.02 - 0.03 * row as f64;
                ((z / radius_m).atan(), 90.0)
            }
            Shape::Star { .. } => (el_deg.to_radians(), if row == 0 { 90.0 } else { 80.0 }),
        };
        let step = if step > 0.0 { step } else { 20.0 };
        let mut az_deg: f64 = -half + if row == 1 { 10.0 } else { 0.0 };
        while az_deg <= half + 1e-9 {
            let az = az_deg.to_radians();
            let p = shape.point(az, el);
            let n_surf = shape.normal(p);
            let radial = crate::shape::direction(az, 0.0);
            let out = (radial + DVec3::Z * 0.35).normalize();
            let half_extent = 0.5 * t.headdress_size_m * 1.5;
            let tilt = n_surf.dot(out).clamp(-1.0, 1.0).acos();
            let centre = p + n_surf * (0.002 + half_extent * tilt.sin());
            if let Some(tg) = Target::square(hid, t.headdress_size_m, centre, out, DVec3::Z) {
                headdress.push(tg);
                hid += 1;
            }
            az_deg += step;
        }
    }

    // Standard: in front of the head, towards the flash, facing between the flash and the
    // reference-standard camera.
    let roi_world = roi_centre_head;
    let to_flash_h = (flash_pos - roi_world)
        .truncate()
        .extend(0.0)
        .normalize_or(DVec3::Y);
    let std_pos = roi_world + to_flash_h * 0.15 + DVec3::Y * 0.05;
    let cam_rs = reference_standard_camera_position(scene);
    let normal = ((flash_pos - std_pos).normalize() + (cam_rs - std_pos).normalize()).normalize();
    let z = normal;
    let x = DVec3::Z.cross(z).normalize_or(DVec3::X);
    let y = z.cross(x);
    let world_from_standard = Pose::new(
        glam::DQuat::from_mat3(&glam::DMat3::from_cols(x, y, z)),
        std_pos,
    );
    let half = 0.5 * scene.standard.size_m;
    let off = half + 0.75 * t.standard_size_m + 0.006;
    let standard_targets = [
        (-1.0, -1.0),
        (0.0, -1.0),
        (1.0, -1.0),
        (1.0, 0.0),
        (1.0, 1.0),
        (0.0, 1.0),
        (-1.0, 1.0),
        (-1.0, 0.0),
    ]
    .iter()
    .enumerate()
    .filter_map(|(k, (u, v))| {
        let centre = DVec3::new(u * off, v * off, 0.0);
        Target::square(
            STANDARD_ID0 + k as u32,
            t.standard_size_m,
            centre,
            DVec3::Z,
            DVec3::NEG_Y,
        )
    })
    .collect();

    Rig {
        camera: camera_model(scene),
        shape,
        roi_centre_head,
        reference,
        headdress,
        flash_targets,
        standard_targets,
        world_from_flash,
        world_from_standard,
    }
}

fn reference_standard_camera_position(scene: &Scene) -> DVec3 {
    crate::shape::direction(10f64.to_radians(), 0.0) * 1.4
        + DVec3::Z * scene.session.camera_height_m
}

/// Smooth pseudo-random head sway: a sum of slow sinusoids per axis, amplitude-normalised.
#[derive(Debug, Clone)]
pub struct HeadMotion {
    terms: Vec<[(f64, f64, f64); 3]>,
    amp_m: f64,
    amp_rad: f64,
}

impl HeadMotion {
    /// Motion with the scene's amplitudes.
    pub fn new(scene: &Scene, rng: &mut ChaCha8Rng) -> Self {
        let terms = (0..6)
            .map(|_| {
                std::array::from_fn(|_| {
                    let period_s = rng.random_range(8.0..40.0);
                    let phase = rng.random_range(0.0..std::f64::consts::TAU);
                    let weight = rng.random_range(0.5..1.0);
                    (period_s, phase, weight)
                })
            })
            .collect();
        Self {
            terms,
            amp_m: scene.session.head_motion_m,
            amp_rad: scene.session.head_motion_deg.to_radians(),
        }
    }

    fn signal(&self, k: usize, t_s: f64) -> DVec3 {
        let tr = &self.terms[3 * k..3 * k + 3];
        let mut v = [0.0; 3];
        for (axis, out) in v.iter_mut().enumerate() {
            let mut norm = 0.0;
            for term in tr {
                let (period, phase, w) = term[axis];
                *out += w * (std::f64::consts::TAU * t_s / period + phase).sin();
                norm += w;
            }
            *out /= norm;
        }
        DVec3::from_array(v)
    }

    /// World from head at time `t_s` (rotation about the head centre).
    pub fn world_from_head(&self, t_s: f64) -> Pose {
        let rot = self.signal(0, t_s) * self.amp_rad;
        let tr = self.signal(1, t_s) * self.amp_m;
        Pose::from_rotation_vector(rot, tr)
    }
}

fn jitter(rng: &mut ChaCha8Rng, amp: f64) -> DVec3 {
    DVec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    ) * amp
}

/// Camera pose for a role's `k`-th image out of `n`.
fn camera_for(
    scene: &Scene,
    rig: &Rig,
    role: ImageRole,
    k: usize,
    n: usize,
    rng: &mut ChaCha8Rng,
) -> Pose {
    let s = &scene.session;
    let roi = rig.roi_centre_head;
    let fallback = Pose::IDENTITY;
    match role {
        ImageRole::Measurement => {
            let f = if n > 1 {
                k as f64 / (n - 1) as f64
            } else {
                0.5
            };
            let az = (s.arc_start_deg + (s.arc_end_deg - s.arc_start_deg) * f).to_radians();
            let eye = crate::shape::direction(az, 0.0) * s.camera_radius_m
                + DVec3::Z * s.camera_height_m
                + jitter(rng, s.position_jitter_m);
            Pose::look_at(eye, roi + jitter(rng, s.aim_jitter_m), DVec3::Z).unwrap_or(fallback)
        }
        ImageRole::LightPosition => {
            let f = rig.world_from_flash;
            let flash = f.translation_m;
            let fwd = f.transform_vector(DVec3::Z);
            let right = f.transform_vector(DVec3::X);
            let offsets = [(-0.25, 0.05), (0.0, -0.08), (0.25, 0.10)];
            let (dx, dz) = offsets[k % 3];
            let eye = flash + fwd * 1.0 + right * dx + DVec3::Z * dz + jitter(rng, 0.01);
            Pose::look_at(eye, flash + DVec3::Z * 0.08, DVec3::Z).unwrap_or(fallback)
        }
        ImageRole::ReferenceStandard | ImageRole::StandardPosition => {
            let (az_deg, r, dz) = match (role, k % 2) {
                (ImageRole::ReferenceStandard, _) => (10.0, 1.4, 0.0),
                (_, 0) => (-8.0, 1.6, 0.12),
                _ => (30.0, 1.6, -0.05),
            };
            let eye = crate::shape::direction(f64::to_radians(az_deg), 0.0) * r
                + DVec3::Z * (s.camera_height_m + dz)
                + jitter(rng, 0.005);
            let target = rig.world_from_standard.translation_m;
            Pose::look_at(eye, target, DVec3::Z).unwrap_or(fallback)
        }
    }
}

fn file_name(role: ImageRole, k: usize) -> String {
    match role {
        ImageRole::Measurement => format!("images/m{k:02}.png"),
        ImageRole::LightPosition => format!("images/light{k}.png"),
        ImageRole::ReferenceStandard => format!("images/standard{k}.png"),
        ImageRole::StandardPosition => format!("images/standard_pos{k}.png"),
    }
}

/// The method's shot list: the measurement images, then 3 light-position, 1 reference-standard
/// and 2 standard-position images, one every `shot_interval_s`.
pub fn plan_shots(scene: &Scene, rig: &Rig) -> Vec<Shot> {
    let n = scene.session.measurement_images as usize;
    let mut roles: Vec<ImageRole> = vec![ImageRole::Measurement; n];
    roles.extend([ImageRole::LightPosition; 3]);
    roles.push(ImageRole::ReferenceStandard);
    roles.extend([ImageRole::StandardPosition; 2]);
    let interval_us = (scene.session.shot_interval_s * 1e6) as u64;
    let exposures: Vec<(ImageRole, u64, Option<u32>, bool)> = roles
        .into_iter()
        .enumerate()
        .map(|(i, r)| (r, 1_000_000 + i as u64 * interval_us, None, true))
        .collect();
    shots_from(scene, rig, &exposures)
}

/// One shot per usable exposure of a capture record (roles and times from the record; an
/// exposure whose camera did not fire gets no image; one whose flash misfired is rendered
/// without the flash).
pub fn shots_from_capture(scene: &Scene, rig: &Rig, rec: &CaptureRecord) -> Vec<Shot> {
    let exposures: Vec<(ImageRole, u64, Option<u32>, bool)> = rec
        .exposures
        .iter()
        .filter_map(|e| {
            let t = e.xsync_us.unwrap_or(e.shutter_command_us);
            match e.outcome {
                ShotOutcome::Ok => Some((e.role, t, Some(e.index), true)),
                ShotOutcome::MissingFlash => Some((e.role, t, Some(e.index), false)),
                _ => None,
            }
        })
        .collect();
    shots_from(scene, rig, &exposures)
}

fn shots_from(
    scene: &Scene,
    rig: &Rig,
    exposures: &[(ImageRole, u64, Option<u32>, bool)],
) -> Vec<Shot> {
    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed ^ 0x5eed_1a70);
    let motion = HeadMotion::new(scene, &mut rng);
    let t0 = exposures.first().map(|e| e.1).unwrap_or(0);
    let count = |role| exposures.iter().filter(|e| e.0 == role).count();
    let mut seen = std::collections::HashMap::<ImageRole, usize>::new();
    exposures
        .iter()
        .map(|&(role, t_us, index, fired)| {
            let k = {
                let c = seen.entry(role).or_insert(0);
                *c += 1;
                *c - 1
            };
            let world_from_camera = camera_for(scene, rig, role, k, count(role), &mut rng);
            let t_s = t_us.saturating_sub(t0) as f64 * 1e-6;
            Shot {
                file: file_name(role, k),
                role,
                exposure_us: t_us,
                exposure_index: index,
                world_from_camera,
                world_from_head: motion.world_from_head(t_s),
                flash_fired: fired,
                ambient_on: matches!(role, ImageRole::LightPosition | ImageRole::StandardPosition),
                standard_present: matches!(
                    role,
                    ImageRole::ReferenceStandard | ImageRole::StandardPosition
                ),
            }
        })
        .collect()
}
