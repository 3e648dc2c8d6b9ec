//! How the rig follows the lens: where a studio puts the reference targets when the camera
//! frames less than the lens the rig's constants were laid out for.
//!
//! # The design lens
//!
//! The reference cage's constants ([`crate::layout::REFERENCE_RADIUS_M`],
//! [`crate::layout::REFERENCE_ROWS_M`], [`crate::layout::REFERENCE_STEP_DEG`]) and the flash
//! stand's panel are laid out for the default scene's lens: [`DESIGN_HFOV_DEG`] across a
//! [`DESIGN_ASPECT`] frame from the [`DESIGN_CAMERA_RADIUS_M`] circle. [`framing_scale`] compares a
//! scene's framing at the head (the frame's half-width and half-height at the camera circle's
//! radius) with that one. A lens that frames as much or more (within [`FRAMING_TOLERANCE`])
//! keeps the constants exactly (the built-in scenes' rigs do not change); a narrower one (the method's own optics see about 10
//! degrees across at 2 m) cannot hold the cage in its frame: at 2 m the frame is then little
//! wider than the head with its headdress, a cylinder about the head's axis lies mostly behind
//! the head or outside the frame, and one that hugs the head hides the forehead or the
//! headdress from some camera of the arc.
//!
//! # Smaller reference targets ([`reference_size_m`])
//!
//! The reference targets (the cage's and the relay's) are printed at the scene's
//! `targets.reference_size_m` times the framing scale: they keep the pixel size they have at
//! the design lens (the detector reads them as well), and more of them fit the narrower frame
//! beside the head. The headdress, the flash ring and the standard keep their sizes: they stay
//! in their frames as they are.
//!
//! # A cage planned for the frames ([`plan_cage`])
//!
//! A studio with such a lens puts each target on its own stand where the cameras frame it. The
//! planner does the same. The candidates are points on cylinders about the head's axis, radii
//! half a target pitch apart out to twice the frame's half-width, azimuths half a pitch apart
//! along each, at heights a quarter pitch apart within the frame's half-height of the
//! forehead; each leans as the design cage's targets do. Each candidate is tested against the
//! nominal cameras that must see the cage (every measurement image's, without jitter, and the
//! standard images'): facing within [`crate::visibility::USABLE_VIEW_MAX_DEG`] less
//! [`FACING_MARGIN_DEG`], all four corners inside the frame less the aim jitter's reach, and
//! no corner behind the head (sight lines stepped through it, [`SIGHT_LINE_STEP_M`]), behind a
//! headdress target's paper or, in the standard images, behind the standard. A candidate is
//! kept when at least [`MIN_PLANNED_VIEWS`] cameras see it, its paper clears the head and the
//! headdress by [`HEAD_CLEARANCE_M`], and it passes the design cage's own occlusion rule (it
//! hides neither the forehead region, the headdress, the flash nor the standard from any
//! nominal camera, nor collides with the standard). The cage is then chosen greedily: each
//! next target is the admissible candidate that fills the most of what the cameras seeing it
//! still lack of [`CAGE_TARGETS_PER_FRAME`] (summed over them, so that the frames with the
//! fewest targets, the standard images' among them, come first; the earlier candidate on
//! ties), admissible when it keeps a target pitch from every chosen one and neither hides a
//! corner of one nor has one hidden by it from a camera that counts either; it stops when no
//! candidate adds anything or at
//! [`MAX_PLANNED_CAGE_TARGETS`]. Everything is a function of the scene.
//!
//! A planned cage has no rows of neighbours, so it is never printed on sheets (every target is
//! a cut-out, whatever `targets.reference_sheet_targets` says).
//!
//! # The flash stand's panel ([`framed_panel`])
//!
//! The light-position cameras stand at the head, [`crate::layout::LIGHT_CAMERA_DISTANCE_M`] from
//! the flash (they cannot step back: the head is behind them). At the design lens their frame
//! holds the flash's target ring and two columns of panel targets each side; at a narrower one
//! the ring alone nearly fills it. The panel's targets then take the places the ring leaves
//! in the frame: places on a half-pitch grid in the flash's plane where the paper clears the
//! ring's papers and the diffuser, nearest the flash first, each taken when it keeps a pitch
//! from those already taken and the tag lies inside every nominal light-position frame less
//! the aim jitter's reach; every other one taken stands off towards the head by
//! [`PANEL_STANDOFF_M`] (not coplanar, as the design panel's outer columns), at most
//! [`crate::layout::FLASH_PANEL_TARGETS`]. They are printed at the design panel's size times
//! the framing scale (the pixel size the design panel's targets have in the design lens's
//! light-position images): the ring leaves too little room for as many larger ones.

use glam::{DVec2, DVec3};
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_session::Target;

use crate::layout::{paper_half_diagonal_m, target_pitch_m};
use crate::scene::Scene;
use crate::shape::Shape;
use crate::sheets::CageTarget;

/// The horizontal field of view the rig's constants are laid out for, degrees: the default
/// scene's long lens.
pub const DESIGN_HFOV_DEG: f64 = 16.0;
/// The frame's height over its width the rig's constants are laid out for: the default scene's
/// 1524 x 1012 sensor (the method's Kodak DCS 520).
pub const DESIGN_ASPECT: f64 = 1012.0 / 1524.0;
/// The camera circle's radius the rig's constants are laid out for, metres: the default
/// scene's (the method's 2 m).
pub const DESIGN_CAMERA_RADIUS_M: f64 = 2.0;

/// Targets a planned cage gives every camera that must see it, when the room allows: well over
/// the handful a pose needs, so that the arc's jitter (which moves the frame by up to the aim
/// jitter) and the detector's misses leave plenty.
pub const CAGE_TARGETS_PER_FRAME: usize = 12;
/// Most targets of a planned cage: with the flash stand's panel and the largest relay, the
/// reference ids stay below the headdress's ([`crate::layout::HEADDRESS_ID0`]).
pub const MAX_PLANNED_CAGE_TARGETS: usize = (crate::layout::HEADDRESS_ID0
    - crate::layout::REFERENCE_ID0
    - crate::studio::MAX_RELAY_TARGETS) as usize
    - crate::layout::FLASH_PANEL_TARGETS;
/// Fewest nominal cameras that must see a candidate of the planned cage: the survey places a
/// target from two views at least, and to its accuracy target only from a few (it names one
/// seen in fewer not seen, or uncertain), so a target fewer would see is not worth its place.
pub const MIN_PLANNED_VIEWS: usize = 3;
/// Least gap between a planned cage target's paper and the head's surface or a headdress
/// target's paper, metres: the head sways by a few millimetres, and a stand needs room.
pub const HEAD_CLEARANCE_M: f64 = 0.01;
/// How much more squarely than the usable limit a planned target must face a nominal camera,
/// degrees: the jittered cameras look from a little further round.
pub const FACING_MARGIN_DEG: f64 = 5.0;
/// Share of the frame's width kept free at its edge beyond the aim jitter's reach (the tag's
/// corner must be inside the image with its edge's gradient window): a few pixels at the
/// scenes' resolutions.
pub const FRAME_EDGE_MARGIN: f64 = 0.003;
/// How far alternate columns of a framed panel stand off towards the head, metres: as the
/// design panel's outer columns, so that the panel is not one plane.
pub const PANEL_STANDOFF_M: f64 = 0.04;

/// The scene's framing at the head against the design's: the smaller of the ratios of the
/// frame's half-width and half-height at the camera circle's radius. At 1 or more the rig's
/// constants hold as they are; below 1 the rig follows the lens (the module docs).
pub fn framing_scale(scene: &Scene) -> f64 {
    let c = &scene.camera;
    let half_width = |hfov_deg: f64, radius_m: f64| radius_m * (0.5 * hfov_deg.to_radians()).tan();
    let w = half_width(c.hfov_deg, scene.session.camera_radius_m);
    let w0 = half_width(DESIGN_HFOV_DEG, DESIGN_CAMERA_RADIUS_M);
    let aspect = f64::from(c.height_px) / f64::from(c.width_px.max(1));
    (w / w0).min(w * aspect / (w0 * DESIGN_ASPECT))
}

/// The printed edge of the reference targets (the cage's, the relay's), metres: the scene's
/// `targets.reference_size_m` at the design lens; a lens that frames less gets them scaled by
/// its [`framing_scale`], so that they keep the pixel size they have at the design lens (the
/// detector reads them as well) and as many fit its smaller frame beside the head.
pub fn reference_size_m(scene: &Scene) -> f64 {
    let t = scene.targets.reference_size_m;
    if follows_lens(scene) {
        t * framing_scale(scene)
    } else {
        t
    }
}

/// How much less than the design lens a lens may frame and keep the design rig: a rendering
/// resolution whose height rounds down (`synth --resolution 1000x664` is 0.006 % shorter than
/// the design's aspect) or a sensor a little wider than the design's is the same studio.
pub const FRAMING_TOLERANCE: f64 = 0.02;

/// Whether the scene's lens frames less than the design lens (by more than
/// [`FRAMING_TOLERANCE`]), so that the rig follows it.
pub fn follows_lens(scene: &Scene) -> bool {
    framing_scale(scene) < 1.0 - FRAMING_TOLERANCE
}

/// Width of the model camera the framing tests project through, pixels: they compare places
/// with the frame, not pixel sizes, so any width serves, and a fixed one gives a scene the same
/// rig at every rendering resolution (`synth --resolution`).
pub const FRAMING_WIDTH_PX: u32 = 1000;

/// The scene's lens (field of view, aspect, distortion) as a camera of
/// [`FRAMING_WIDTH_PX`] pixels across: what the framing tests project through.
pub fn framing_camera(scene: &Scene) -> CameraModel {
    let c = &scene.camera;
    let aspect = f64::from(c.height_px) / f64::from(c.width_px.max(1));
    let height_px = (f64::from(FRAMING_WIDTH_PX) * aspect).round().max(1.0) as u32;
    let mut m = CameraModel::from_fov(FRAMING_WIDTH_PX, height_px, c.hfov_deg.to_radians());
    m.distortion = c.distortion;
    m
}

/// The frame's half-width and half-height at the camera circle's radius, metres.
fn frame_half_extent_m(scene: &Scene) -> DVec2 {
    let c = &scene.camera;
    let w = scene.session.camera_radius_m * (0.5 * c.hfov_deg.to_radians()).tan();
    DVec2::new(w, w * f64::from(c.height_px) / f64::from(c.width_px.max(1)))
}

/// A camera that must see the targets, with the pixels its frame's edge keeps free.
#[derive(Debug, Clone, Copy)]
pub struct FramingCamera {
    /// World from camera.
    pub pose: Pose,
    /// Camera from world (the inverse, kept for the projections).
    camera_from_world: Pose,
    /// Pixels kept free at each edge of the frame.
    pub margin_px: f64,
    /// Whether the reflectance standard is in this camera's images (it may hide targets).
    pub sees_standard: bool,
}

impl FramingCamera {
    /// A camera at `eye` aimed at `aim` whose aim wanders by up to `aim_jitter_m` (per axis).
    pub fn aimed(
        camera: &CameraModel,
        eye: DVec3,
        aim: DVec3,
        aim_jitter_m: f64,
        sees_standard: bool,
    ) -> Option<Self> {
        let pose = Pose::look_at(eye, aim, DVec3::Z)?;
        let range_m = eye.distance(aim).max(1e-6);
        Some(Self {
            pose,
            camera_from_world: pose.inverse(),
            margin_px: camera.fx_px * aim_jitter_m / range_m
                + FRAME_EDGE_MARGIN * f64::from(camera.width_px),
            sees_standard,
        })
    }

    fn eye(&self) -> DVec3 {
        self.pose.translation_m
    }

    /// Whether every point projects inside the frame less the margin.
    fn frames(&self, camera: &CameraModel, points: &[DVec3]) -> bool {
        let (w, h) = (f64::from(camera.width_px), f64::from(camera.height_px));
        let m = self.margin_px;
        points.iter().all(|p| {
            camera
                .project(self.camera_from_world.transform_point(*p))
                .is_some_and(|q| q.x >= m && q.y >= m && q.x <= w - 1.0 - m && q.y <= h - 1.0 - m)
        })
    }
}

/// A ball that may stand between a camera and a target.
#[derive(Debug, Clone, Copy)]
pub struct Ball {
    /// Centre, world frame.
    pub centre: DVec3,
    /// Radius, metres.
    pub radius_m: f64,
}

/// Whether `ball` stands between `eye` and `point` (the segment passes through it).
fn blocks(eye: DVec3, point: DVec3, ball: Ball) -> bool {
    let d = point - eye;
    let len = d.length();
    if len <= 0.0 {
        return false;
    }
    let u = d / len;
    let t = (ball.centre - eye).dot(u);
    t > 0.0 && t < len && (ball.centre - eye - u * t).length() < ball.radius_m
}

/// Whether any corner of `target` is hidden from `eye` by `ball`.
fn corners_blocked(eye: DVec3, target: &Target, ball: Ball) -> bool {
    target.corners_m.iter().any(|c| blocks(eye, *c, ball))
}

/// Semi-axes of an ellipsoid about the origin that encloses the shape, metres.
fn enclosing_ellipsoid_m(shape: &Shape) -> DVec3 {
    match *shape {
        Shape::Star {
            semi_axes_m,
            exponent,
            brow_height_m,
            ..
        } => {
            // A superellipsoid of exponent e > 2 lies within the ellipsoid of its semi-axes
            // scaled by 3^(1/2 - 1/e) (its corner direction); for e <= 2 within that ellipsoid.
            let k = 3f64.powf((0.5 - 1.0 / exponent).max(0.0));
            DVec3::from_array(semi_axes_m) * k + DVec3::splat(brow_height_m)
        }
        Shape::Cylinder { radius_m, length_m } => {
            DVec3::new(radius_m, radius_m, 0.5 * length_m) * std::f64::consts::SQRT_2
        }
    }
}

/// The part of the segment from `a` to `b` (parameters in 0..1) inside the ellipsoid of
/// semi-axes `axes` about the origin, if any.
fn ellipsoid_span(a: DVec3, b: DVec3, axes: DVec3) -> Option<(f64, f64)> {
    let (p, d) = (a / axes, (b - a) / axes);
    let (qa, qb, qc) = (d.dot(d), 2.0 * p.dot(d), p.dot(p) - 1.0);
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 || qa <= 0.0 {
        return None;
    }
    let root = disc.sqrt();
    let (t0, t1) = ((-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa));
    let (t0, t1) = (t0.max(0.0), t1.min(1.0));
    (t0 < t1).then_some((t0, t1))
}

/// Whether the segment from `a` to `b` crosses the square plate of half-edge `half_m` in the
/// z = 0 plane of `world_from_plate`.
fn segment_meets_plate(world_from_plate: Pose, half_m: f64, a: DVec3, b: DVec3) -> bool {
    let inv = world_from_plate.inverse();
    let (pa, pb) = (inv.transform_point(a), inv.transform_point(b));
    if pa.z * pb.z >= 0.0 {
        return false;
    }
    let q = pa.lerp(pb, pa.z / (pa.z - pb.z));
    q.x.abs() <= half_m && q.y.abs() <= half_m
}

/// Step along a sight line when testing it against the head's surface, metres: finer than the
/// tessellation the renderer casts against is not needed, coarser could step over the rim of
/// the silhouette.
pub const SIGHT_LINE_STEP_M: f64 = 0.002;

/// Whether the segment from `a` to `b` passes through the shape: stepping along the part of
/// it inside an ellipsoid that encloses the shape (most sight lines miss that).
fn segment_meets_shape(shape: &Shape, axes: DVec3, a: DVec3, b: DVec3) -> bool {
    let Some((t0, t1)) = ellipsoid_span(a, b, axes) else {
        return false;
    };
    let (p0, p1) = (a.lerp(b, t0), a.lerp(b, t1));
    let n = (p0.distance(p1) / SIGHT_LINE_STEP_M).ceil().max(1.0) as usize;
    (0..=n).any(|k| {
        let p = p0.lerp(p1, k as f64 / n as f64);
        // The segment's own end (a target's corner) is never inside the head: a corner that
        // is, the clearance test has already refused.
        shape.implicit(p) < 0.0
    })
}

/// What the cage planner needs of the rig built so far.
pub struct CageInputs<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// The lens the framing tests project through ([`framing_camera`]).
    pub camera: &'a CameraModel,
    /// The sample's surface (head frame, the nominal head pose being the identity).
    pub shape: &'a Shape,
    /// Centre of the region of interest (the arc's aim).
    pub roi_centre: DVec3,
    /// The horizontal direction every cage target leans towards.
    pub facing: DVec3,
    /// The headdress targets (nominal head pose).
    pub headdress: &'a [Target],
    /// The reflectance standard with its targets, as a square plate: world from its frame
    /// (the plate is its z = 0 plane) and the half-edge, metres. It hides targets in the
    /// standard images.
    pub standard: (Pose, f64),
    /// The cameras that must see the cage.
    pub cameras: &'a [FramingCamera],
    /// The design cage's occlusion rule: whether a target of the cage's size centred here
    /// hides nothing that must be seen and collides with nothing.
    pub safe: &'a dyn Fn(DVec3) -> bool,
}

impl std::fmt::Debug for CageInputs<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CageInputs")
            .field("scene", &self.scene.name)
            .field("roi_centre", &self.roi_centre)
            .field("facing", &self.facing)
            .field("headdress", &self.headdress.len())
            .field("cameras", &self.cameras.len())
            .finish_non_exhaustive()
    }
}

/// A candidate of the planned cage with the cameras that see it.
struct Candidate {
    target: Target,
    ball: Ball,
    row: usize,
    step: i64,
    seen_by: Vec<usize>,
}

/// The cage of a scene whose lens frames less than the design lens (the module docs): cut-outs,
/// world frame, ids from `first_id` in the order of their rows (heights) and azimuths.
pub fn plan_cage(inp: &CageInputs<'_>, first_id: u32) -> Vec<CageTarget> {
    let scene = inp.scene;
    let t = &scene.targets;
    let size = reference_size_m(scene);
    let pitch = target_pitch_m(size);
    let paper_r = paper_half_diagonal_m(size);
    let head_paper_r = paper_half_diagonal_m(t.headdress_size_m);
    let half = frame_half_extent_m(scene);
    let step_m = 0.5 * pitch;
    let axes = enclosing_ellipsoid_m(inp.shape);
    let cos_facing = (crate::visibility::USABLE_VIEW_MAX_DEG - FACING_MARGIN_DEG)
        .to_radians()
        .cos();
    let headdress_balls: Vec<Ball> = inp
        .headdress
        .iter()
        .map(|h| Ball {
            centre: h.centre(),
            radius_m: head_paper_r,
        })
        .collect();
    let max_dz = (half.y - 0.5 * size).max(0.0);
    let dz_m = 0.5 * step_m;
    let rows = (max_dz / dz_m).floor() as i64;
    let max_r = 2.0 * half.x;
    let mut cands: Vec<Candidate> = Vec::new();
    for (row, j) in (-rows..=rows).enumerate() {
        let zc = inp.roi_centre.z + j as f64 * dz_m;
        let out = (inp.facing + DVec3::Z * ((scene.session.camera_height_m - zc) / 2.0))
            .normalize_or(inp.facing);
        let mut ring = 1;
        while ring as f64 * step_m <= max_r {
            let r = ring as f64 * step_m;
            let n_az = (std::f64::consts::TAU * r / step_m).ceil().max(1.0) as i64;
            for k in 0..n_az {
                let az = -std::f64::consts::PI + std::f64::consts::TAU * k as f64 / n_az as f64;
                let centre = crate::shape::direction(az, 0.0) * r + DVec3::Z * zc;
                let clear = inp.shape.implicit(centre) > paper_r + HEAD_CLEARANCE_M
                    && headdress_balls.iter().all(|h| {
                        h.centre.distance(centre) > h.radius_m + paper_r + HEAD_CLEARANCE_M
                    });
                if !clear {
                    continue;
                }
                let Some(target) = Target::square(0, size, centre, out, DVec3::Z) else {
                    continue;
                };
                let ball = Ball {
                    centre,
                    radius_m: paper_r,
                };
                let seen_by: Vec<usize> = inp
                    .cameras
                    .iter()
                    .enumerate()
                    .filter(|(_, cam)| {
                        let eye = cam.eye();
                        target
                            .outward_normal()
                            .dot((eye - centre).normalize_or_zero())
                            >= cos_facing
                            && cam.frames(inp.camera, &target.corners_m)
                            && !target
                                .corners_m
                                .iter()
                                .any(|c| segment_meets_shape(inp.shape, axes, eye, *c))
                            && !headdress_balls
                                .iter()
                                .any(|h| corners_blocked(eye, &target, *h))
                            && !(cam.sees_standard
                                && target.corners_m.iter().any(|c| {
                                    segment_meets_plate(inp.standard.0, inp.standard.1, eye, *c)
                                }))
                    })
                    .map(|(i, _)| i)
                    .collect();
                // The design cage's occlusion rule last: it is the dearest test.
                if seen_by.len() >= MIN_PLANNED_VIEWS && (inp.safe)(centre) {
                    cands.push(Candidate {
                        target,
                        ball,
                        row,
                        step: ring * 10_000 + k,
                        seen_by,
                    });
                }
            }
            ring += 1;
        }
    }
    // Greedy cover: each camera up to CAGE_TARGETS_PER_FRAME targets. A candidate that is not
    // admissible stays so (the chosen set only grows).
    let mut count = vec![0usize; inp.cameras.len()];
    let mut chosen: Vec<usize> = Vec::new();
    let mut dead = vec![false; cands.len()];
    let admissible = |c: &Candidate, chosen: &[usize]| {
        chosen.iter().all(|&j| {
            let o = &cands[j];
            o.ball.centre.distance(c.ball.centre) >= pitch
                && !c
                    .seen_by
                    .iter()
                    .filter(|k| o.seen_by.contains(k))
                    .any(|&k| {
                        let eye = inp.cameras[k].eye();
                        corners_blocked(eye, &c.target, o.ball)
                            || corners_blocked(eye, &o.target, c.ball)
                    })
        })
    };
    while chosen.len() < MAX_PLANNED_CAGE_TARGETS {
        let gain = |c: &Candidate| {
            c.seen_by
                .iter()
                .map(|&k| CAGE_TARGETS_PER_FRAME.saturating_sub(count[k]))
                .sum::<usize>()
        };
        let mut order: Vec<(usize, usize)> = (0..cands.len())
            .filter(|&i| !dead[i])
            .map(|i| (gain(&cands[i]), i))
            .filter(|(g, _)| *g > 0)
            .collect();
        order.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        let mut pick = None;
        for (_, i) in order {
            dead[i] = true;
            if admissible(&cands[i], &chosen) {
                pick = Some(i);
                break;
            }
        }
        let Some(i) = pick else { break };
        for &k in &cands[i].seen_by {
            count[k] += 1;
        }
        chosen.push(i);
    }
    chosen.sort_by_key(|&i| (cands[i].row, cands[i].step));
    chosen
        .into_iter()
        .zip(first_id..)
        .map(|(i, id)| {
            let c = &cands[i];
            CageTarget {
                target: Target { id, ..c.target },
                row: c.row,
                step: c.step,
            }
        })
        .collect()
}

/// What the framed panel needs of the rig built so far.
#[derive(Debug, Clone, Copy)]
pub struct PanelInputs<'a> {
    /// The lens the framing tests project through ([`framing_camera`]).
    pub camera: &'a CameraModel,
    /// World from flash (+z towards the head, x right, -y up).
    pub world_from_flash: Pose,
    /// The flash's target ring, flash frame.
    pub ring: &'a [Target],
    /// The flash diffuser's radius, metres.
    pub diffuser_radius_m: f64,
    /// The light-position cameras.
    pub cameras: &'a [FramingCamera],
    /// The panel targets' printed edge, metres.
    pub size_m: f64,
}

/// The flash stand's panel for a lens that frames less than the design lens (the module docs):
/// world frame, ids from `first_id`, at most `max_targets`.
pub fn framed_panel(inp: &PanelInputs<'_>, first_id: u32, max_targets: usize) -> Vec<Target> {
    let PanelInputs {
        camera,
        world_from_flash,
        ring,
        diffuser_radius_m,
        cameras,
        size_m,
    } = *inp;
    let pitch = target_pitch_m(size_m);
    let half_paper = 0.5 * size_m * crate::layout::PAPER_HALF_EXTENT;
    let toward_head = world_from_flash.transform_vector(DVec3::Z);
    let right = world_from_flash.transform_vector(DVec3::X);
    let up = world_from_flash.transform_vector(DVec3::NEG_Y);
    // The ring's papers as squares in the flash plane (x right, y up; centre, half-edge).
    let ring_boxes: Vec<(DVec2, f64)> = ring
        .iter()
        .map(|r| {
            let c = r.centre();
            (
                DVec2::new(c.x, -c.y),
                0.5 * r.size_m * crate::layout::PAPER_HALF_EXTENT,
            )
        })
        .collect();
    let clear_of_ring = |p: DVec2| {
        p.length() > diffuser_radius_m + half_paper * std::f64::consts::SQRT_2
            && ring_boxes.iter().all(|(c, h)| {
                let d = (p - *c).abs();
                d.x >= h + half_paper || d.y >= h + half_paper
            })
    };
    let place = |p: DVec2, standoff: f64| {
        world_from_flash.translation_m + right * p.x + up * p.y + toward_head * standoff
    };
    // Places on a half-pitch grid out to beyond the ring, nearest the flash first.
    let reach = ring_boxes
        .iter()
        .map(|(c, h)| c.length() + h * std::f64::consts::SQRT_2)
        .fold(diffuser_radius_m, f64::max)
        + 2.0 * pitch;
    let grid = 0.5 * pitch;
    let n = (reach / grid).ceil() as i64;
    let mut places: Vec<(i64, i64, DVec2)> = Vec::new();
    for ix in -n..=n {
        for iy in -n..=n {
            let p = DVec2::new(ix as f64, iy as f64) * grid;
            if clear_of_ring(p) {
                places.push((ix, iy, p));
            }
        }
    }
    places.sort_by(|a, b| {
        a.2.length()
            .total_cmp(&b.2.length())
            .then(a.1.cmp(&b.1))
            .then(a.0.cmp(&b.0))
    });
    // Packed one pitch apart (papers edge to edge plus the gap); every other one taken stands
    // off towards the head, so that each side of the flash has both depths.
    let mut taken: Vec<(DVec2, DVec3)> = Vec::new();
    for (_, _, p) in places {
        if taken.len() >= max_targets {
            break;
        }
        if taken.iter().any(|(q, _)| {
            let d = (p - *q).abs();
            d.x < pitch && d.y < pitch
        }) {
            continue;
        }
        let standoff = if taken.len() % 2 == 1 {
            PANEL_STANDOFF_M
        } else {
            0.0
        };
        let centre = place(p, standoff);
        let framed = Target::square(0, size_m, centre, toward_head, DVec3::Z)
            .is_some_and(|tg| cameras.iter().all(|c| c.frames(camera, &tg.corners_m)));
        if framed {
            taken.push((p, centre));
        }
    }
    // In columns from the left, each from the bottom, as the design panel's ids run.
    taken.sort_by(|a, b| a.0.x.total_cmp(&b.0.x).then(a.0.y.total_cmp(&b.0.y)));
    taken
        .into_iter()
        .zip(first_id..)
        .filter_map(|((_, centre), id)| Target::square(id, size_m, centre, toward_head, DVec3::Z))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::build_rig;

    #[test]
    fn only_a_lens_that_frames_less_moves_the_rig() {
        let default = Scene::load("default").expect("scene");
        assert!(!follows_lens(&default));
        assert_eq!(reference_size_m(&default), default.targets.reference_size_m);
        let mut rounded = default.clone();
        (rounded.camera.width_px, rounded.camera.height_px) = (1000, 664);
        assert!(!follows_lens(&rounded), "{}", framing_scale(&rounded));
        let wide = Scene::load("strong-distortion").expect("scene");
        assert!(!follows_lens(&wide), "{}", framing_scale(&wide));
        let long = Scene::load("long-lens").expect("scene");
        assert!(follows_lens(&long));
        let s = framing_scale(&long);
        assert!((0.6..0.65).contains(&s), "{s}");
    }

    /// The framing tests project through a fixed-width model of the lens, so rendering a scene
    /// at half its pixels (as `tests/scenes.rs` does) keeps its rig.
    #[test]
    fn a_planned_rig_does_not_depend_on_the_rendering_resolution() {
        let full = Scene::load("long-lens").expect("scene");
        let mut half = full.clone();
        half.camera.width_px /= 2;
        half.camera.height_px /= 2;
        let centres = |s: &Scene| -> Vec<(u32, [f64; 3])> {
            build_rig(s)
                .reference
                .iter()
                .map(|t| (t.id, t.centre().to_array()))
                .collect()
        };
        assert_eq!(centres(&full), centres(&half));
    }
}
