//! The physical set-up of a synthetic session: where the targets, the flash, the standard and
//! the camera are for every shot, and how the head moves.
//!
//! World frame: origin at the nominal head centre, +z up, +y the direction the face looks.
//! Azimuths are measured about +z from +y towards +x.
//!
//! The framing is an operator's: a long lens (default `hfov_deg = 16`, ~0.37 mm per pixel at
//! 2 m) aimed at the forehead, so the forehead region covers ~20 000 pixels per image. So
//! everything the poses need sits close around the head ([`build_rig`]): a cage of reference
//! targets (which defines the world frame) on a cylinder of radius 0.22 m about the head's
//! axis, rows above, beside and below the face, leaning towards the cameras and the flash; a
//! small reference panel around the flash for the light-position images; a headdress with
//! rows of 25 mm tags (quiet paper between them) above and beside the forehead region. The
//! flash stands at `flash_azimuth_deg`, `flash_distance_m` from the head axis, aimed at the
//! forehead, with a ring of eight targets around its 82 mm diffuser. The camera moves on the
//! circle (2 m) from near the flash (retro-reflection) to the far side (grazing), always aimed
//! at the forehead; then the six extra images: three of the flash (light position, from 1.4 m),
//! one of the standard under the flash (reference standard) and two more of the standard
//! (standard position), from 2 m. The cage's neighbours can be printed on shared sheets
//! ([`crate::sheets`]). [`crate::visibility::usable_targets`] says which targets a shot can use; the
//! tests check every shot of every built-in scene sees enough of them.
//!
//! **The layout follows the lens.** The constants above are laid out for the default lens;
//! every lens that frames as much at the head or more (the default's 16 degrees at 2 m, the
//! wide lens of `strong-distortion` from 0.9 m) gets them exactly. The method's own optics see
//! about 10 degrees across at 2 m: a frame about 0.35 x 0.23 m at the head, little wider than
//! the head with its headdress, which the cylinder of radius 0.22 m mostly misses (and one
//! shrunk to fit hides the forehead or the headdress from part of the arc). For a lens that
//! frames less ([`crate::framing::follows_lens`], scene `long-lens`) a studio puts each
//! reference target where the cameras frame it: the cage is planned for the nominal
//! measurement and standard images' frames ([`crate::framing::plan_cage`]: candidates around
//! the head that pass the same occlusion rule, chosen greedily until every frame holds a dozen
//! or no more fit); the reference targets (cage and relay) shrink with the framing
//! ([`crate::framing::reference_size_m`]), so that they keep their pixel size and more of them
//! fit beside the head; and the flash stand's panel, smaller in the same ratio, takes the room
//! the flash's target ring leaves in the light-position frames
//! ([`crate::framing::framed_panel`]); the standard images are taken from further back
//! ([`standard_camera_distance_m`]), so that they frame the standard with as much of the cage as
//! at the design lens. The headdress, the flash ring, the standard and the other cameras' places
//! do not change (their targets stay in frame).

use std::collections::BTreeMap;

use glam::{DVec2, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_session::capture::{CaptureRecord, ShotOutcome};
use skinbrdf_session::{ImageRole, Target};

use crate::scene::{Encoding, Scene};
use crate::shape::Shape;
use crate::sheets::{CageTarget, PrintedSheet, SheetFaults, TagPrint};

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
    /// The printed sheets (reference sheets of the cage, the headdress band): each target of
    /// a sheet is also in `reference` or `headdress` with its true corners.
    pub sheets: Vec<PrintedSheet>,
    /// Reference targets printed other than as a flat square of their own code (folded across
    /// a sheet's fold, or printed with another target's code), by id.
    pub prints: BTreeMap<u32, TagPrint>,
    /// The relay's reference targets (`studio.flash_relay_targets`, `relay_targets`): on a
    /// low stand between the head and the flash, linking the flash stand's panel to the cage
    /// in survey shots. Empty without a relay.
    pub relay_ids: Vec<u32>,
}

impl Rig {
    /// Every target group a shot sees, with the frame that places it in the world: the
    /// reference structure, the headdress (the shot's head pose) when the subject sits, the
    /// flash and, when the shot has it, the standard.
    pub fn target_groups(&self, shot: &Shot) -> Vec<(Layout, &Vec<Target>, Pose)> {
        let mut groups = vec![(Layout::Reference, &self.reference, Pose::IDENTITY)];
        if shot.subject_present {
            groups.push((Layout::Headdress, &self.headdress, shot.world_from_head));
        }
        groups.push((Layout::Flash, &self.flash_targets, self.world_from_flash));
        if shot.standard_present {
            groups.push((
                Layout::Standard,
                &self.standard_targets,
                self.world_from_standard,
            ));
        }
        groups
    }

    /// The flash's emitting point, world frame.
    pub fn light_position_m(&self) -> DVec3 {
        self.world_from_flash.translation_m
    }

    /// The sheet a target is printed on, if any.
    pub fn sheet_of(&self, layout: Layout, id: u32) -> Option<&PrintedSheet> {
        self.sheets
            .iter()
            .find(|s| s.layout == layout && s.targets.iter().any(|t| t.id == id))
    }

    /// The ids of the body a reference target belongs to: its sheet's, or its own.
    pub fn reference_body(&self, id: u32) -> Vec<u32> {
        self.sheet_of(Layout::Reference, id)
            .map_or_else(|| vec![id], PrintedSheet::ids)
    }

    /// How a reference target is printed: its code and its flat pieces.
    pub fn print_of(&self, t: &Target) -> TagPrint {
        self.prints
            .get(&t.id)
            .cloned()
            .unwrap_or_else(|| TagPrint::plain(t))
    }

    /// The sheet named so, or the `index`-th (in the rig's order).
    pub fn find_sheet(&self, which: &crate::studio::SheetRef) -> Option<&PrintedSheet> {
        self.sheets
            .iter()
            .enumerate()
            .find(|(k, s)| which.names(&s.name, *k))
            .map(|(_, s)| s)
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
    /// Whether the subject sits in the scene: false for a survey shot, taken before the subject
    /// sits (no head, no headdress: the renderer skips their geometry).
    pub subject_present: bool,
    /// The shot's exposure against the scene's (`t ISO / N²` over the scene's settings): every
    /// rendered value is multiplied by it. 1 for the flash shots; a survey shot, lit by the room
    /// light alone, is exposed longer ([`crate::survey_shots::SURVEY_EXPOSURE_GAIN`]).
    pub exposure_gain: f64,
}

fn camera_model(scene: &Scene) -> CameraModel {
    let c = &scene.camera;
    let mut m = CameraModel::from_fov(c.width_px, c.height_px, c.hfov_deg.to_radians());
    m.distortion = c.distortion;
    m
}

/// Distance of the reference structure's targets from the head's vertical axis, metres: outside
/// the head and the headdress, inside the field of view of the measurement images on both sides
/// of the head at the design lens (a lens that frames less gets a planned cage,
/// [`crate::framing`]).
pub const REFERENCE_RADIUS_M: f64 = 0.22;
/// Heights of the reference structure's rows relative to the forehead's centre, metres (two
/// rows above/below the face, two beside it).
pub const REFERENCE_ROWS_M: [f64; 4] = [-0.13, -0.045, 0.045, 0.13];
/// Azimuth step of the reference structure's targets, degrees.
pub const REFERENCE_STEP_DEG: f64 = 15.0;
/// Quiet paper between two printed targets, metres (beyond each tag's own white ring).
pub const TARGET_GAP_M: f64 = 0.006;
/// Distance of the light-position cameras from the flash, metres.
pub const LIGHT_CAMERA_DISTANCE_M: f64 = 1.4;
/// Distance of the standard cameras from the standard at the design lens, metres
/// ([`standard_camera_distance_m`]).
pub const STANDARD_CAMERA_DISTANCE_M: f64 = 2.0;

/// Paper half-diagonal of a printed target of edge `size_m` (the paper is
/// [`PAPER_HALF_EXTENT`] tag half-edges wide).
pub fn paper_half_diagonal_m(size_m: f64) -> f64 {
    0.5 * size_m * PAPER_HALF_EXTENT * std::f64::consts::SQRT_2
}

/// Centre-to-centre distance two printed targets of edge `size_m` need (paper edge to edge
/// plus [`TARGET_GAP_M`]).
pub fn target_pitch_m(size_m: f64) -> f64 {
    size_m * PAPER_HALF_EXTENT + TARGET_GAP_M
}

/// The azimuth (degrees) every reference and headdress target leans towards: lit by the flash
/// (within 85 degrees of it) and seen by every camera of the arc (within 65 degrees of its far
/// end) when both are possible.
pub fn facing_azimuth_deg(scene: &Scene) -> f64 {
    let s = &scene.session;
    let lo = s.arc_end_deg.max(s.arc_start_deg) - 65.0;
    let hi = s.flash_azimuth_deg + 85.0;
    0.5 * (lo + hi)
}

/// A protected object for the occlusion check: a ball that no reference target may hide from
/// a camera.
struct Protected {
    centre: DVec3,
    radius_m: f64,
}

/// Whether a ball at `c` (radius `r`) hides any protected ball from the camera at `eye`.
fn hides(eye: DVec3, c: DVec3, r: f64, protected: &[Protected]) -> bool {
    let dc = c - eye;
    let dist_c = dc.length();
    protected.iter().any(|p| {
        let dp = p.centre - eye;
        let dist_p = dp.length();
        if dist_c >= dist_p {
            return false;
        }
        let angle = dc.angle_between(dp);
        angle < (r / dist_c).asin() + (p.radius_m / dist_p).min(1.0).asin()
    })
}

/// Builds the fixed set-up of a scene.
///
/// The framing is an operator's: a long lens (the scene's `hfov_deg`) aimed at the forehead
/// from the arc, so the forehead fills a large part of the frame. Everything the poses need is
/// therefore close around the head:
/// * the **reference structure**: a cage of targets on a cylinder of radius
///   [`REFERENCE_RADIUS_M`] about the head's axis, rows [`REFERENCE_ROWS_M`] above, beside and
///   below the forehead, every [`REFERENCE_STEP_DEG`]; each target leans towards
///   [`facing_azimuth_deg`] (lit by the flash, seen by the whole arc). A candidate that would
///   hide the forehead region, a headdress target, the flash or the standard from any nominal
///   camera, or that collides with the standard, is left out. With
///   `targets.reference_sheet_targets = N > 1`, neighbours along a row are printed N to a
///   flat sheet with a layout file where that is safe ([`crate::sheets`]: the flattened
///   targets pass the same occlusion checks, and no paper touches another), each sheet tilted,
///   scaled or folded as the scene's `[studio]` says. Plus a small panel of reference targets
///   around the flash (at two depths, so not coplanar, always cut-outs) for the light-position
///   images. A lens that frames less than the design lens gets a cage planned for its frames,
///   smaller reference targets and a panel where the flash ring leaves room
///   ([`crate::framing`]; the module docs).
/// * the **headdress**: rows of targets on the head above and beside the forehead region, one
///   pitch ([`target_pitch_m`]) apart, leaning towards the cameras and the flash, none within
///   the region of interest; with `studio.headdress_band`, stated as one printed band whose
///   layout is the headdress unrolled ([`crate::sheets::headdress_band`]).
/// * a reference target of `studio.duplicate_id` printed with the other target's code
///   ([`Rig::prints`]).
pub fn build_rig(scene: &Scene) -> Rig {
    let camera = camera_model(scene);
    let shape = Shape::from_scene(&scene.geometry);
    let g = &scene.geometry;
    let t = &scene.targets;
    let s = &scene.session;
    let roi_centre_head = shape.point(0.0, g.roi_elevation_deg.to_radians());
    let face_az = facing_azimuth_deg(scene).to_radians();
    let facing = crate::shape::direction(face_az, 0.0);

    // Flash: aimed at the forehead.
    let fa = s.flash_azimuth_deg.to_radians();
    let flash_pos =
        crate::shape::direction(fa, 0.0) * s.flash_distance_m + DVec3::Z * s.flash_height_m;
    let world_from_flash =
        Pose::look_at(flash_pos, roi_centre_head, DVec3::Z).unwrap_or(Pose::IDENTITY);

    // Headdress: rows above and beside the forehead region.
    let head_tags = headdress_targets(scene, &shape, roi_centre_head, facing);
    let headdress: Vec<Target> = head_tags.iter().map(|(t, _)| *t).collect();

    // Standard: in front of the head, towards the flash, facing between the flash and the
    // reference-standard camera.
    let roi_world = roi_centre_head;
    let to_flash_h = (flash_pos - roi_world)
        .truncate()
        .extend(0.0)
        .normalize_or(DVec3::Y);
    let std_pos = roi_world + to_flash_h * 0.15 + DVec3::Y * 0.05;
    let cam_rs = reference_standard_camera_position(scene, std_pos);
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
    let standard_radius_m =
        off * std::f64::consts::SQRT_2 + paper_half_diagonal_m(t.standard_size_m);
    // Half-edge of the standard with its targets' papers, as a square plate.
    let standard_half_m = off + 0.5 * t.standard_size_m * PAPER_HALF_EXTENT;

    // Reference cage around the head.
    let mut protected = vec![
        Protected {
            centre: roi_centre_head,
            radius_m: g.roi_radius_m + 0.01,
        },
        Protected {
            centre: flash_pos,
            radius_m: 0.5 * s.flash_diameter_m + 1.5 * t.flash_size_m + 0.02,
        },
        Protected {
            centre: std_pos,
            radius_m: standard_radius_m,
        },
    ];
    protected.extend(headdress.iter().map(|h| Protected {
        centre: h.centre(),
        radius_m: paper_half_diagonal_m(t.headdress_size_m),
    }));
    let cams = nominal_cameras(scene, roi_centre_head, flash_pos, std_pos);
    let mut cage = Vec::new();
    let mut id = REFERENCE_ID0;
    let ref_size = crate::framing::reference_size_m(scene);
    let ref_r = paper_half_diagonal_m(ref_size) + 0.005;
    let safe = |centre: DVec3| {
        centre.distance(std_pos) >= standard_radius_m + ref_r
            && !cams
                .iter()
                .any(|eye| hides(*eye, centre, ref_r, &protected))
    };
    let framing_camera = crate::framing::framing_camera(scene);
    if crate::framing::follows_lens(scene) {
        let framing_cams = framing_cameras(scene, &framing_camera, roi_centre_head, std_pos);
        let inputs = crate::framing::CageInputs {
            scene,
            camera: &framing_camera,
            shape: &shape,
            roi_centre: roi_centre_head,
            facing,
            headdress: &headdress,
            standard: (world_from_standard, standard_half_m),
            cameras: &framing_cams,
            safe: &safe,
        };
        cage = crate::framing::plan_cage(&inputs, id);
        id += cage.len() as u32;
    } else {
        for (row, dz) in REFERENCE_ROWS_M.into_iter().enumerate() {
            let zc = roi_centre_head.z + dz;
            let mut b_deg = -180.0
                + if dz.abs() < 0.1 {
                    0.5 * REFERENCE_STEP_DEG
                } else {
                    0.0
                };
            let mut step = 0i64;
            while b_deg < 180.0 - 1e-9 {
                let centre = crate::shape::direction(b_deg.to_radians(), 0.0) * REFERENCE_RADIUS_M
                    + DVec3::Z * zc;
                b_deg += REFERENCE_STEP_DEG;
                step += 1;
                if !safe(centre) {
                    continue;
                }
                // Lean towards the arc's height at 2 m.
                let out = (facing + DVec3::Z * ((s.camera_height_m - zc) / 2.0)).normalize();
                if let Some(tg) = Target::square(id, ref_size, centre, out, DVec3::Z) {
                    cage.push(CageTarget {
                        target: tg,
                        row,
                        step,
                    });
                    id += 1;
                }
            }
        }
    }
    // Groups of neighbours printed on sheets (crate::sheets), where that is safe.
    let st = &scene.studio;
    let printed = crate::sheets::print_cage(
        &cage,
        t.reference_sheet_targets as usize,
        &SheetFaults {
            tilt_deg: st.sheet_tilt_deg,
            seed: scene.seed,
            print_scale: st.print_scale.as_ref().map(|f| (f.sheet.clone(), f.scale)),
            bend: st
                .bent_sheet
                .as_ref()
                .map(|f| (f.sheet.clone(), f.bend_deg)),
        },
        &|tg: &Target| safe(tg.centre()),
    );
    let mut reference = printed.targets;
    let mut sheets = printed.sheets;
    let mut prints = printed.prints;
    // Flash targets: a ring of eight around the diffuser, in the flash frame (+z out).
    let flash_targets: Vec<Target> = (0..8)
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

    // Reference panel around the flash, for the light-position images: two columns each side
    // of the flash's target ring, the outer ones on 4 cm stand-offs (not coplanar).
    // Smaller than the head cage's: the light-position cameras are closer. A lens that frames
    // less takes smaller ones where its frame leaves room (crate::framing).
    let flash_ref_size = (0.7 * t.flash_size_m).min(t.reference_size_m);
    if crate::framing::follows_lens(scene) {
        let light_cams: Vec<crate::framing::FramingCamera> = (0..3)
            .filter_map(|k| {
                crate::framing::FramingCamera::aimed(
                    &framing_camera,
                    light_camera_eye(scene, flash_pos, roi_centre_head, k),
                    flash_pos,
                    LIGHT_CAMERA_AIM_JITTER_M,
                    false,
                )
            })
            .collect();
        let panel = crate::framing::framed_panel(
            &crate::framing::PanelInputs {
                camera: &framing_camera,
                world_from_flash,
                ring: &flash_targets,
                diffuser_radius_m: 0.5 * s.flash_diameter_m,
                cameras: &light_cams,
                size_m: flash_ref_size * crate::framing::framing_scale(scene),
            },
            id,
            FLASH_PANEL_TARGETS,
        );
        id += panel.len() as u32;
        reference.extend(panel);
    } else {
        let ring_outer =
            0.5 * s.flash_diameter_m + 0.9 * t.flash_size_m + 0.01 + 0.75 * t.flash_size_m;
        let col_in = ring_outer + 0.75 * flash_ref_size + TARGET_GAP_M;
        let col_out = col_in + target_pitch_m(flash_ref_size);
        let toward_head = world_from_flash.transform_vector(DVec3::Z);
        let right = world_from_flash.transform_vector(DVec3::X);
        let up = world_from_flash.transform_vector(DVec3::NEG_Y);
        let dz_row = 0.5 * target_pitch_m(flash_ref_size);
        for (dx, standoff) in [
            (-col_out, 0.04),
            (-col_in, 0.0),
            (col_in, 0.0),
            (col_out, 0.04),
        ] {
            for dz in [-dz_row, dz_row] {
                let centre = flash_pos + right * dx + up * dz + toward_head * standoff;
                if let Some(tg) = Target::square(id, flash_ref_size, centre, toward_head, DVec3::Z)
                {
                    reference.push(tg);
                    id += 1;
                }
            }
        }
    }

    // The relay between the flash stand's panel and the cage, when the scene has one.
    let relay = relay_targets(
        scene,
        id.min(HEADDRESS_ID0),
        flash_pos,
        roi_centre_head,
        &[roi_centre_head, std_pos],
    );
    let relay_ids: Vec<u32> = relay.iter().map(|t| t.id).collect();
    reference.extend(relay);

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

    if scene.studio.headdress_band {
        let tags: Vec<(&Target, DVec2)> = head_tags.iter().map(|(t, p)| (t, *p)).collect();
        sheets.extend(crate::sheets::headdress_band(&tags));
    }
    if let Some(d) = &scene.studio.duplicate_id {
        if let Some(x) = reference.iter().find(|r| r.id == d.id) {
            prints
                .entry(d.id)
                .or_insert_with(|| TagPrint::plain(x))
                .code = d.printed_as;
        }
    }

    Rig {
        camera,
        shape,
        roi_centre_head,
        reference,
        headdress,
        flash_targets,
        standard_targets,
        world_from_flash,
        world_from_standard,
        sheets,
        prints,
        relay_ids,
    }
}

/// Distance of the relay's centre from the forehead's centre towards the flash (horizontally),
/// metres: beyond the standard (0.15 m that way) and the head, within a survey camera's frame
/// of the cage's near side.
pub const RELAY_DISTANCE_M: f64 = 0.38;
/// Height of the relay's centre below the forehead's centre, metres: under the flash's beam to
/// the forehead and the standard (about 0.1 m above the forehead's height there), out of the
/// measurement and light-position images' frames.
pub const RELAY_DROP_M: f64 = 0.24;
/// How far the relay's targets are turned from facing straight away from the flash towards
/// the cage's facing azimuth, degrees: a survey camera behind the relay sees them with the
/// panel beyond, one to the cage's facing side sees them with the cage.
pub const RELAY_TURN_DEG: f64 = 35.0;
/// Centre-to-centre spacing of the relay's targets, metres: wider than the paper needs, because
/// the relay's orientation, known only as well as its targets' spread allows, is carried
/// 1.2 m to the panel (a 0.05 mm error across 0.1 m is a 0.6 mm error there).
pub const RELAY_SPACING_M: f64 = 0.15;
/// Least distance of a relay target from the flash's beam to the forehead or the standard,
/// metres (its shadow must not fall on either).
pub const RELAY_BEAM_CLEARANCE_M: f64 = 0.06;

/// The relay (`studio.flash_relay_targets` targets, ids from `first_id`): reference targets in
/// a row, two rows when there are more than three, [`RELAY_SPACING_M`] apart, on a low stand
/// [`RELAY_DISTANCE_M`] from the forehead towards the flash and [`RELAY_DROP_M`] below it,
/// facing away from the flash turned [`RELAY_TURN_DEG`] towards the cage's facing azimuth.
///
/// Why it is there: the light-position images see the flash stand's panel and the flash ring
/// and nothing of the cage (the cage's targets face the measurement arc, the panel faces the
/// head, and at the long lens's 16 degrees no frame holds both 1.5 m apart). Without a link
/// the panel's placement must be measured and stated. With the relay, a survey shot from
/// behind it sees it with the panel beyond, and one from the cage's facing side sees it with
/// the cage ([`crate::survey_shots::link_shots`]), so the survey chains the panel to the world.
/// A target that would shadow the forehead or the standard (`lit`: the points the flash
/// must reach), or whose id would reach the headdress's, is left out.
fn relay_targets(
    scene: &Scene,
    first_id: u32,
    flash_pos: DVec3,
    roi: DVec3,
    lit: &[DVec3],
) -> Vec<Target> {
    let n = scene.studio.flash_relay_targets;
    let size = crate::framing::reference_size_m(scene);
    let pitch = RELAY_SPACING_M.max(target_pitch_m(size));
    let u = (flash_pos - roi)
        .truncate()
        .extend(0.0)
        .normalize_or(DVec3::Y);
    let away = -u;
    let facing = crate::shape::direction(facing_azimuth_deg(scene).to_radians(), 0.0);
    // Turn `away` towards `facing` about the vertical, on the shorter side.
    let side = away.cross(facing).z.signum();
    let turn = glam::DQuat::from_rotation_z(side * RELAY_TURN_DEG.to_radians());
    let normal = turn * away;
    let right = DVec3::Z.cross(normal).normalize_or(DVec3::X);
    let centre = roi + u * RELAY_DISTANCE_M - DVec3::Z * RELAY_DROP_M;
    let rows = if n > 3 { 2 } else { 1 };
    let cols = n.div_ceil(rows);
    let beam_clear = |c: DVec3| {
        lit.iter().all(|&p| {
            let d = p - flash_pos;
            let t = ((c - flash_pos).dot(d) / d.length_squared()).clamp(0.0, 1.0);
            c.distance(flash_pos + d * t) > RELAY_BEAM_CLEARANCE_M + paper_half_diagonal_m(size)
        })
    };
    let mut out = Vec::new();
    for k in 0..n {
        let (r, c) = (k / cols, k % cols);
        let dx = (f64::from(c) - 0.5 * f64::from(cols - 1)) * pitch;
        let dz = (0.5 * f64::from(rows - 1) - f64::from(r)) * pitch;
        let p = centre + right * dx + DVec3::Z * dz;
        let id = first_id + out.len() as u32;
        if id >= HEADDRESS_ID0 || !beam_clear(p) {
            continue;
        }
        if let Some(tg) = Target::square(id, size, p, normal, DVec3::Z) {
            out.push(tg);
        }
    }
    out
}

/// Headdress targets (head frame): rows at fixed elevations (or heights on a cylinder), one
/// pitch apart along each row, rows staggered; a tag too close to an earlier one or to the
/// region of interest is left out. Each leans half-way from the surface's outward direction
/// towards `facing` and up (stand-off wedges keep the paper off the skin).
///
/// With each target its place on the headdress unrolled flat (the band's layout,
/// `studio.headdress_band`): the arc length along its row's ring on the surface, and the arc
/// length along the surface's front meridian from the lowest row up to its row.
fn headdress_targets(
    scene: &Scene,
    shape: &Shape,
    roi_centre_head: DVec3,
    facing: DVec3,
) -> Vec<(Target, DVec2)> {
    let t = &scene.targets;
    let size = t.headdress_size_m;
    let pitch = target_pitch_m(size);
    let paper_half = 0.5 * size * PAPER_HALF_EXTENT;
    let roi_clear = scene.geometry.roi_radius_m + paper_half_diagonal_m(size) + 0.003;
    // (elevation, azimuth limit) per row, degrees; on a cylinder the elevation is that of a
    // height on its side.
    let rows: Vec<(f64, f64)> = match *shape {
        Shape::Cylinder { length_m, radius_m } => {
            let top = 0.5 * length_m - paper_half - 0.004;
            [0.0, top - pitch, top]
                .into_iter()
                .map(|z| ((z / radius_m).atan().to_degrees(), 110.0))
                .collect()
        }
        Shape::Star { .. } => vec![(12.0, 110.0), (38.0, 110.0), (60.0, 110.0)],
    };
    let mut placed: Vec<(Target, DVec2)> = Vec::new();
    let mut hid = HEADDRESS_ID0;
    let el0 = rows.first().map_or(0.0, |r| r.0.to_radians());
    for (row, (el_deg, limit_deg)) in rows.into_iter().enumerate() {
        let el = el_deg.to_radians();
        let up_arc = meridian_arc_m(shape, el0, el);
        let ring_r = shape.point(0.0, el).truncate().length().max(1e-3);
        let step = 2.0 * (0.5 * pitch / ring_r).min(1.0).asin();
        let limit = limit_deg.to_radians();
        let offset = if row % 2 == 1 { 0.5 * step } else { 0.0 };
        let n = (limit / step).floor() as i32 + 1;
        for k in -n..=n {
            let az = offset + k as f64 * step;
            if az.abs() > limit {
                continue;
            }
            let p = shape.point(az, el);
            let n_surf = shape.normal(p);
            let radial = crate::shape::direction(az, 0.0);
            let out = (radial + facing + DVec3::Z * 0.4).normalize();
            let tilt = n_surf.dot(out).clamp(-1.0, 1.0).acos();
            let centre = p + n_surf * (0.002 + paper_half * tilt.sin());
            if centre.distance(roi_centre_head) < roi_clear
                || placed.iter().any(|q| q.0.centre().distance(centre) < pitch)
            {
                continue;
            }
            if let Some(tg) = Target::square(hid, size, centre, out, DVec3::Z) {
                placed.push((tg, DVec2::new(az * ring_r, up_arc)));
                hid += 1;
            }
        }
    }
    placed
}

/// Arc length along the surface's front meridian (azimuth 0) between two elevations, metres.
fn meridian_arc_m(shape: &Shape, el_from: f64, el_to: f64) -> f64 {
    /// Chords per meridian arc: the rows are tens of degrees apart, the curvature mild.
    const STEPS: usize = 64;
    (0..STEPS)
        .map(|k| {
            let f = |k: usize| el_from + (el_to - el_from) * k as f64 / STEPS as f64;
            shape.point(0.0, f(k)).distance(shape.point(0.0, f(k + 1)))
        })
        .sum::<f64>()
        * (el_to - el_from).signum()
}

/// Nominal (jitter-free) camera centres of a scene: the arc's ends and points between, the
/// light-position and the standard cameras.
pub(crate) fn nominal_cameras(
    scene: &Scene,
    roi: DVec3,
    flash_pos: DVec3,
    std_pos: DVec3,
) -> Vec<DVec3> {
    let s = &scene.session;
    let mut cams: Vec<DVec3> = (0..=12)
        .map(|k| {
            let f = f64::from(k) / 12.0;
            let az = (s.arc_start_deg + (s.arc_end_deg - s.arc_start_deg) * f).to_radians();
            crate::shape::direction(az, 0.0) * s.camera_radius_m + DVec3::Z * s.camera_height_m
        })
        .collect();
    let _ = roi;
    for k in 0..3 {
        cams.push(light_camera_eye(scene, flash_pos, roi, k));
    }
    for (az, dz) in standard_camera_offsets() {
        cams.push(standard_camera_eye(scene, std_pos, az, dz));
    }
    cams
}

/// The cameras the rig's targets must be framed by when the rig follows the lens
/// ([`crate::framing`]): every measurement image's nominal camera (no jitter) aimed at the
/// forehead, and the standard images' cameras.
fn framing_cameras(
    scene: &Scene,
    camera: &CameraModel,
    roi: DVec3,
    std_pos: DVec3,
) -> Vec<crate::framing::FramingCamera> {
    let s = &scene.session;
    let n = s.measurement_images.max(1) as usize;
    let mut out: Vec<crate::framing::FramingCamera> = (0..n)
        .filter_map(|k| {
            let f = if n > 1 {
                k as f64 / (n - 1) as f64
            } else {
                0.5
            };
            let az = (s.arc_start_deg + (s.arc_end_deg - s.arc_start_deg) * f).to_radians();
            let eye =
                crate::shape::direction(az, 0.0) * s.camera_radius_m + DVec3::Z * s.camera_height_m;
            crate::framing::FramingCamera::aimed(camera, eye, roi, s.aim_jitter_m, false)
        })
        .collect();
    out.extend(
        standard_camera_offsets()
            .into_iter()
            .filter_map(|(az, dz)| {
                crate::framing::FramingCamera::aimed(
                    camera,
                    standard_camera_eye(scene, std_pos, az, dz),
                    standard_aim(std_pos),
                    STANDARD_CAMERA_JITTER_M,
                    true,
                )
            }),
    );
    out
}

/// How far a light-position camera's aim wanders from the flash, metres (per axis).
pub const LIGHT_CAMERA_AIM_JITTER_M: f64 = 0.005;
/// How far a light-position camera stands from its nominal place, metres (per axis).
pub const LIGHT_CAMERA_JITTER_M: f64 = 0.01;
/// How far a standard image's camera stands from its nominal place, metres (per axis); its aim
/// is exact.
pub const STANDARD_CAMERA_JITTER_M: f64 = 0.005;
/// Reference targets of the flash stand's panel: two columns of two each side of the ring.
pub const FLASH_PANEL_TARGETS: usize = 8;

/// The light-position cameras' azimuth offsets and heights.
fn light_camera_eye(scene: &Scene, flash_pos: DVec3, roi: DVec3, k: usize) -> DVec3 {
    let _ = scene;
    let fwd = (roi - flash_pos).normalize_or(DVec3::Y);
    let right = fwd.cross(DVec3::Z).normalize_or(DVec3::X);
    let offsets = [(-0.2, 0.05), (0.0, -0.06), (0.2, 0.08)];
    let (dx, dz) = offsets[k % 3];
    flash_pos + fwd * LIGHT_CAMERA_DISTANCE_M + right * dx + DVec3::Z * dz
}

/// Azimuth (degrees) and height offsets of the reference-standard camera, then the two
/// standard-position cameras.
const fn standard_camera_offsets() -> [(f64, f64); 3] {
    [(10.0, 0.0), (-8.0, 0.12), (22.0, 0.06)]
}

/// Where the standard cameras aim: a third of the way from the standard to the head's axis,
/// so the reference cage around the head is in the frame too.
fn standard_aim(std_pos: DVec3) -> DVec3 {
    std_pos.lerp(DVec3::new(0.0, 0.0, std_pos.z), 0.35)
}

/// The standard cameras look down on the standard from this height above it, metres (whatever
/// the arc's height: the reference cage behind the head stays in view).
pub const STANDARD_CAMERA_HEIGHT_M: f64 = 0.10;

/// Distance of the standard cameras from the standard, metres: [`STANDARD_CAMERA_DISTANCE_M`]
/// at the design lens; a lens that frames less steps back in proportion
/// ([`crate::framing::framing_scale`]), so that its frame holds the standard with as much of
/// the cage around the head as the design lens's does.
pub fn standard_camera_distance_m(scene: &Scene) -> f64 {
    if crate::framing::follows_lens(scene) {
        STANDARD_CAMERA_DISTANCE_M / crate::framing::framing_scale(scene)
    } else {
        STANDARD_CAMERA_DISTANCE_M
    }
}

fn standard_camera_eye(scene: &Scene, std_pos: DVec3, az_deg: f64, dz: f64) -> DVec3 {
    std_pos
        + crate::shape::direction(az_deg.to_radians(), 0.0) * standard_camera_distance_m(scene)
        + DVec3::Z * (STANDARD_CAMERA_HEIGHT_M + dz)
}

fn reference_standard_camera_position(scene: &Scene, std_pos: DVec3) -> DVec3 {
    let (az, dz) = standard_camera_offsets()[0];
    standard_camera_eye(scene, std_pos, az, dz)
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
            let flash = rig.world_from_flash.translation_m;
            let eye = light_camera_eye(scene, flash, roi, k) + jitter(rng, LIGHT_CAMERA_JITTER_M);
            Pose::look_at(
                eye,
                flash + jitter(rng, LIGHT_CAMERA_AIM_JITTER_M),
                DVec3::Z,
            )
            .unwrap_or(fallback)
        }
        ImageRole::ReferenceStandard | ImageRole::StandardPosition => {
            let offsets = standard_camera_offsets();
            let (az_deg, dz) = match (role, k % 2) {
                (ImageRole::ReferenceStandard, _) => offsets[0],
                (_, 0) => offsets[1],
                _ => offsets[2],
            };
            let std_pos = rig.world_from_standard.translation_m;
            let eye = standard_camera_eye(scene, std_pos, az_deg, dz)
                + jitter(rng, STANDARD_CAMERA_JITTER_M);
            Pose::look_at(eye, standard_aim(std_pos), DVec3::Z).unwrap_or(fallback)
        }
        // Never reached: no exposure has this role (`shots_from` skips them); survey shots are
        // planned from the rig by `crate::survey_shots`.
        ImageRole::Survey => fallback,
    }
}

/// The image file of shot `k` of a role, with the extension of the scene's encoding.
pub(crate) fn file_name(role: ImageRole, k: usize, scene: &Scene) -> String {
    let ext = match scene.sensor.encoding {
        Encoding::Png16 | Encoding::Png8 => "png",
        Encoding::Exr => "exr",
    };
    match role {
        ImageRole::Measurement => format!("images/m{k:02}.{ext}"),
        ImageRole::LightPosition => format!("images/light{k}.{ext}"),
        ImageRole::ReferenceStandard => format!("images/standard{k}.{ext}"),
        ImageRole::StandardPosition => format!("images/standard_pos{k}.{ext}"),
        ImageRole::Survey => format!("images/survey{k:02}.{ext}"),
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
        .filter(|e| e.0.fired_by_controller())
        .map(|&(role, t_us, index, fired)| {
            let k = {
                let c = seen.entry(role).or_insert(0);
                *c += 1;
                *c - 1
            };
            let world_from_camera = camera_for(scene, rig, role, k, count(role), &mut rng);
            let t_s = t_us.saturating_sub(t0) as f64 * 1e-6;
            Shot {
                file: file_name(role, k, scene),
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
                subject_present: true,
                exposure_gain: 1.0,
            }
        })
        .collect()
}

/// Half extent of a printed target's paper in tag units (the black border is at ±1, the tag's
/// white ring ends at ±1.25; a quarter cell more of paper around it).
pub const PAPER_HALF_EXTENT: f64 = 1.5;

/// Which frame a target lives in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Reference structure (world frame).
    Reference,
    /// Headdress (head frame).
    Headdress,
    /// Flash (flash frame).
    Flash,
    /// Standard (standard frame).
    Standard,
}

impl Layout {
    /// Name used in `truth.json`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Reference => "reference",
            Self::Headdress => "headdress",
            Self::Flash => "flash",
            Self::Standard => "standard",
        }
    }
}
