//! Survey shots: photographs taken by hand before the subject sits, to strengthen the
//! placement survey's geometry (`[session] survey_images = N`).
//!
//! # What a survey shot is
//!
//! The subject is absent (no head, no headdress: [`Shot::subject_present`] is false, so the
//! renderer skips their geometry), the flash does not fire and the room light is on. Lit by
//! the room light alone (`radiometry.ambient`, the level of the light-position images) the
//! paper would be a dark grey at the flash shots' exposure, so a survey shot is exposed
//! [`SURVEY_EXPOSURE_GAIN`] times longer (its EXIF exposure time says so; the ingest does not
//! compare it with the flash images': survey images serve the geometry only).
//!
//! # Where they are taken from
//!
//! Every reference target of the cage faces one azimuth ([`crate::layout::facing_azimuth_deg`]),
//! so a camera sees it only within [`crate::visibility::USABLE_VIEW_MAX_DEG`] of that direction.
//! The measurement arc sees the cage from one height and through the head: the targets behind
//! the head are hidden in most of its images, and those at the cage's sides are seen from a
//! narrow range of directions, so their depth is poorly determined. Without the subject nothing
//! hides the targets behind the head, and cameras above and below the arc's height and at its
//! sides triangulate every target from directions the arc does not offer.
//!
//! The candidates are the cameras at [`SURVEY_DISTANCES_M`] from an aim point, at
//! [`SURVEY_ELEVATIONS_DEG`] above the horizontal and [`SURVEY_AZIMUTH_OFFSETS_DEG`] from the
//! facing azimuth, aimed at the cage's centroid or at the centroid of one quarter of the cage
//! (its targets by azimuth about the head's axis), so that at the lens's narrow field a shot
//! can frame either the whole cage or a part of it from nearer. For each candidate the
//! synthetic visibility test ([`crate::visibility::usable_targets`], with the subject absent)
//! says which cage targets it sees, and from which direction.
//!
//! A target is *well surveyed* when [`SURVEY_MIN_VIEWS`] survey shots see it from directions
//! pairwise at least [`SURVEY_MIN_SEPARATION_DEG`] apart (a triangulation angle that fixes its
//! depth; nearer directions add little). The shots are chosen greedily: each next shot is the
//! candidate that brings the most targets closer to well surveyed (counting distinct
//! directions up to [`SURVEY_MIN_VIEWS`] per target), targets the measurement arc sees in fewer
//! than [`ARC_POORLY_SEEN_VIEWS`] images counting [`POORLY_SEEN_WEIGHT`] times; ties go to the
//! candidate seeing more cage targets, then to the earlier candidate. When no candidate brings
//! anything more, the rest are the candidates seeing the most cage targets. Everything is a
//! function of the scene, so the choice is deterministic.

use std::collections::BTreeMap;

use glam::DVec3;
use skinbrdf_core::Pose;
use skinbrdf_session::ImageRole;

use crate::layout::{facing_azimuth_deg, file_name, Layout, Rig, Shot};
use crate::photograph::Renderer;
use crate::scene::Scene;

/// A survey shot's exposure over the flash shots' (`t ISO / N²`): the room light
/// (`radiometry.ambient`, a quarter of white on white paper) times 0.8 paper albedo puts the
/// paper at a fifth of white at the flash shots' exposure; 2.5 times longer (1/50 s for the
/// studio's 1/125 s) makes it half of white, mid-grey and well above the detector's contrast
/// needs, with room to spare below clipping for the white diffuser.
pub const SURVEY_EXPOSURE_GAIN: f64 = 2.5;

/// Survey shots that see a target for it to count as well surveyed: three rays fix a point in
/// space with one degree of redundancy, so one bad view can be told from the others.
pub const SURVEY_MIN_VIEWS: usize = 3;

/// Directions to a target closer than this, degrees, count as one: a triangulation angle of
/// 15 degrees fixes the depth to about four times the lateral precision, and the measurement
/// arc's own neighbouring images are a few degrees apart.
pub const SURVEY_MIN_SEPARATION_DEG: f64 = 15.0;

/// Camera distances from the aim point, metres: the range a photographer works at with the
/// studio's long lens (at 1.5 m the cage just fills the frame; beyond 2.5 m the tags get
/// small in a half-resolution image).
pub const SURVEY_DISTANCES_M: [f64; 3] = [1.6, 2.0, 2.4];

/// Camera elevations above the horizontal through the aim point, degrees: below, near and
/// above the measurement arc's height (a tripod's range; the cage's targets lean towards the
/// arc's height, so steeper views foreshorten them beyond use).
pub const SURVEY_ELEVATIONS_DEG: [f64; 3] = [-15.0, 5.0, 25.0];

/// Camera azimuths relative to the cage's facing azimuth, degrees: every target faces that
/// way, and is usable within 70 degrees of its normal; 60 degrees either side leaves room for
/// the elevation and the target's lean.
pub const SURVEY_AZIMUTH_OFFSETS_DEG: [f64; 9] =
    [-60.0, -45.0, -30.0, -15.0, 0.0, 15.0, 30.0, 45.0, 60.0];

/// A target seen in fewer measurement images than this is poorly seen by the arc: the
/// placement survey typically places it less certainly than its accuracy target.
pub const ARC_POORLY_SEEN_VIEWS: usize = 6;

/// How much more a poorly seen target's new survey direction counts in the greedy choice.
pub const POORLY_SEEN_WEIGHT: f64 = 2.0;

/// Gap between survey shots, seconds (a photographer walking the tripod round the cage).
pub const SURVEY_INTERVAL_S: f64 = 20.0;

/// The survey ends this long before the session's first exposure, seconds (the subject sits
/// and is fitted with the headdress in between).
pub const SURVEY_LEAD_S: f64 = 600.0;

/// The cage's targets: the reference targets but the flash stand's panel and the relay.
pub fn cage_ids(rig: &Rig) -> Vec<u32> {
    let panel = crate::studio::flash_panel_ids(rig);
    rig.reference
        .iter()
        .map(|t| t.id)
        .filter(|id| !panel.contains(id) && !rig.relay_ids.contains(id))
        .collect()
}

/// Link shots per link (relay and panel; relay and cage).
pub const LINK_SHOTS: usize = 4;

/// The survey shots a scene plans: `survey_images` for the cage and, with a relay,
/// [`LINK_SHOTS`] per link.
pub fn planned_count(scene: &Scene) -> usize {
    scene.session.survey_images as usize
        + if scene.studio.flash_relay_targets > 0 {
            2 * LINK_SHOTS
        } else {
            0
        }
}

/// Targets of each kind a link shot must see: two targets on each side of a link fix the
/// relative pose with one to spare.
pub const LINK_MIN_TARGETS: usize = 2;

/// Distances of the panel link's cameras behind the relay (away from the flash), metres.
const PANEL_LINK_DISTANCES_M: [f64; 3] = [0.9, 1.3, 1.7];
/// Sideways offsets of the panel link's cameras from the flash-relay line, metres: as wide as
/// the relay's targets allow, so that the shots see the panel from different directions (one
/// direction leaves its depth to the tags' apparent size).
const PANEL_LINK_SIDEWAYS_M: [f64; 7] = [-0.6, -0.4, -0.2, 0.0, 0.2, 0.4, 0.6];
/// Vertical offsets of the panel link's cameras from the flash-relay line, metres.
const PANEL_LINK_HEIGHTS_M: [f64; 3] = [-0.2, 0.0, 0.2];
/// Distances of the cage link's cameras from the point between the relay and the cage, metres.
const CAGE_LINK_DISTANCES_M: [f64; 3] = [1.8, 2.2, 2.6];
/// Azimuths of the cage link's cameras relative to the cage's facing azimuth, degrees.
const CAGE_LINK_AZIMUTHS_DEG: [f64; 9] = [-40.0, -30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0];
/// Elevations of the cage link's cameras, degrees.
const CAGE_LINK_ELEVATIONS_DEG: [f64; 3] = [-10.0, 0.0, 10.0];
/// The cage's near side, which the cage link's cameras frame with the relay: its targets
/// within this of the relay's centre, metres (about the width of the frame at the cameras'
/// distance, less the relay's own half-width).
const CAGE_NEAR_SIDE_M: f64 = 0.6;

/// The link shots of a scene with a relay (`studio.flash_relay_targets`; none without): the
/// light-position images see the flash stand's panel and nothing of the cage, so without a
/// chain of shots the survey cannot place the panel. [`LINK_SHOTS`] shots from behind the relay
/// (away from the flash, aimed so that the relay and the panel beyond it share the frame) and
/// [`LINK_SHOTS`] from the cage's facing side (the relay and the cage's near side), each seeing
/// at least [`LINK_MIN_TARGETS`] targets of either side: the one seeing the most, then those
/// seeing the far side (panel or cage) from the directions farthest from the kept ones'. The
/// candidates are a fixed grid, so the choice is deterministic. Files are numbered after the
/// scene's other survey shots.
pub fn link_shots(scene: &Scene, rig: &Rig, renderer: &Renderer) -> Vec<Shot> {
    if rig.relay_ids.is_empty() {
        return Vec::new();
    }
    let panel = crate::studio::flash_panel_ids(rig);
    let cage = cage_ids(rig);
    let centre_of = |ids: &[u32]| mean(&centres_of(rig, ids));
    let relay_c = centre_of(&rig.relay_ids);
    let panel_c = centre_of(&panel);
    let near: Vec<u32> = rig
        .reference
        .iter()
        .filter(|t| cage.contains(&t.id) && t.centre().distance(relay_c) < CAGE_NEAR_SIDE_M)
        .map(|t| t.id)
        .collect();
    let cage_c = centre_of(if near.is_empty() { &cage } else { &near });
    // An aim that puts two points at equal angles from the frame's centre.
    let between = |eye: DVec3, a: DVec3, b: DVec3| {
        eye + (a - eye).normalize_or_zero() + (b - eye).normalize_or_zero()
    };
    let mut panel_cands = Vec::new();
    let back = (relay_c - panel_c).normalize_or(DVec3::Y);
    let side = DVec3::Z.cross(back).normalize_or(DVec3::X);
    for d in PANEL_LINK_DISTANCES_M {
        for dx in PANEL_LINK_SIDEWAYS_M {
            for dz in PANEL_LINK_HEIGHTS_M {
                let eye = relay_c + back * d + side * dx + DVec3::Z * dz;
                panel_cands.push((eye, between(eye, relay_c, panel_c)));
            }
        }
    }
    let mut cage_cands = Vec::new();
    let mid = 0.5 * (relay_c + cage_c);
    let face = facing_azimuth_deg(scene);
    for d in CAGE_LINK_DISTANCES_M {
        for el in CAGE_LINK_ELEVATIONS_DEG {
            for off in CAGE_LINK_AZIMUTHS_DEG {
                let dir = crate::shape::direction((face + off).to_radians(), el.to_radians());
                let eye = mid + dir * d;
                cage_cands.push((eye, between(eye, relay_c, cage_c)));
            }
        }
    }
    let mut out = Vec::new();
    for (cands, other, far_c) in [(panel_cands, &panel, panel_c), (cage_cands, &cage, cage_c)] {
        let mut scored: Vec<(usize, usize, Shot)> = cands
            .into_iter()
            .filter_map(|(eye, aim)| survey_shot(scene, eye, aim, 0))
            .filter_map(|shot| {
                let seen = crate::visibility::usable_targets(renderer, rig, &shot);
                let count = |ids: &[u32]| {
                    seen.iter()
                        .filter(|(l, id, _)| *l == Layout::Reference && ids.contains(id))
                        .count()
                };
                let (r, o) = (count(&rig.relay_ids), count(other));
                (r >= LINK_MIN_TARGETS && o >= LINK_MIN_TARGETS).then_some((r, o, shot))
            })
            .collect();
        // The first: most of the scarcer side, then of the other (the earlier candidate on
        // ties). Each next: of those seeing as many of the scarcer side as the first or one
        // fewer, the one whose direction from the far side's centre is farthest from the kept
        // shots' (the triangulation angle that fixes the far side's depth).
        scored.sort_by_key(|(r, o, _)| std::cmp::Reverse(((*r).min(*o), *r + *o)));
        let Some(best) = scored.first().map(|(r, o, _)| (*r).min(*o)) else {
            continue;
        };
        let dir = |s: &Shot| (s.world_from_camera.translation_m - far_c).normalize_or_zero();
        let mut pool: Vec<Shot> = scored
            .into_iter()
            .filter(|(r, o, _)| (*r).min(*o) + 1 >= best)
            .map(|x| x.2)
            .collect();
        let mut kept: Vec<Shot> = vec![pool.remove(0)];
        while kept.len() < LINK_SHOTS && !pool.is_empty() {
            let spread = |s: &Shot| {
                kept.iter()
                    .map(|k| dir(k).angle_between(dir(s)))
                    .fold(f64::INFINITY, f64::min)
            };
            let k = (0..pool.len())
                .max_by(|&a, &b| {
                    spread(&pool[a])
                        .total_cmp(&spread(&pool[b]))
                        .then(b.cmp(&a))
                })
                .unwrap_or(0);
            kept.push(pool.remove(k));
        }
        out.extend(kept);
    }
    out
}

/// A survey shot from `eye` aimed at `aim` (no subject, no flash, room light, longer exposure),
/// the `k`-th of the scene's survey shots.
fn survey_shot(scene: &Scene, eye: DVec3, aim: DVec3, k: usize) -> Option<Shot> {
    Some(Shot {
        file: file_name(ImageRole::Survey, k, scene),
        role: ImageRole::Survey,
        exposure_us: 0,
        exposure_index: None,
        world_from_camera: Pose::look_at(eye, aim, DVec3::Z)?,
        world_from_head: Pose::IDENTITY,
        flash_fired: false,
        ambient_on: true,
        standard_present: false,
        subject_present: false,
        exposure_gain: SURVEY_EXPOSURE_GAIN,
    })
}

/// The aim points: the cage's centroid, then the centroid of each quarter of the cage (its
/// targets by azimuth about the head's axis, quarters starting at the facing azimuth).
fn aim_points(scene: &Scene, rig: &Rig) -> Vec<DVec3> {
    let centres = centres_of(rig, &cage_ids(rig));
    let mut out = vec![mean(&centres)];
    let face = facing_azimuth_deg(scene).to_radians();
    let mut quarters: [Vec<DVec3>; 4] = Default::default();
    for c in &centres {
        let az = c.x.atan2(c.y) - face;
        let q = (az.rem_euclid(std::f64::consts::TAU) / std::f64::consts::FRAC_PI_2) as usize;
        quarters[q.min(3)].push(*c);
    }
    out.extend(quarters.iter().filter(|q| !q.is_empty()).map(|q| mean(q)));
    out
}

/// The centres of the reference targets `ids`, in the rig's order.
fn centres_of(rig: &Rig, ids: &[u32]) -> Vec<DVec3> {
    rig.reference
        .iter()
        .filter(|t| ids.contains(&t.id))
        .map(skinbrdf_session::Target::centre)
        .collect()
}

/// The mean of points (the origin for none).
fn mean(v: &[DVec3]) -> DVec3 {
    v.iter().copied().sum::<DVec3>() / v.len().max(1) as f64
}

/// Every candidate survey shot, in a fixed order (aim point, distance, elevation, azimuth).
pub fn candidates(scene: &Scene, rig: &Rig) -> Vec<Shot> {
    let face = facing_azimuth_deg(scene);
    let mut out = Vec::new();
    for aim in aim_points(scene, rig) {
        for d in SURVEY_DISTANCES_M {
            for el in SURVEY_ELEVATIONS_DEG {
                for off in SURVEY_AZIMUTH_OFFSETS_DEG {
                    let dir = crate::shape::direction((face + off).to_radians(), el.to_radians());
                    if let Some(s) = survey_shot(scene, aim + dir * d, aim, out.len()) {
                        out.push(s);
                    }
                }
            }
        }
    }
    out
}

/// The cage targets a shot can use, with the unit direction from each to the camera.
pub fn cage_views(renderer: &Renderer, rig: &Rig, shot: &Shot, cage: &[u32]) -> Vec<(u32, DVec3)> {
    let eye = shot.world_from_camera.translation_m;
    crate::visibility::usable_targets(renderer, rig, shot)
        .into_iter()
        .filter(|(l, id, _)| *l == Layout::Reference && cage.contains(id))
        .map(|(_, id, c)| (id, (eye - c).normalize_or_zero()))
        .collect()
}

/// Per cage target: the directions of the shots that see it, pairwise at least
/// [`SURVEY_MIN_SEPARATION_DEG`] apart (kept greedily in the shots' order).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Coverage {
    /// Target id → kept directions.
    pub directions: BTreeMap<u32, Vec<DVec3>>,
    /// Target id → shots that see it.
    pub views: BTreeMap<u32, usize>,
}

impl Coverage {
    /// Whether `dir` is a new direction for target `id`.
    fn is_new(&self, id: u32, dir: DVec3) -> bool {
        let min_cos = SURVEY_MIN_SEPARATION_DEG.to_radians().cos();
        self.directions
            .get(&id)
            .is_none_or(|v| v.iter().all(|d| d.dot(dir) < min_cos))
    }

    /// Adds a shot's views.
    pub fn add(&mut self, views: &[(u32, DVec3)]) {
        for &(id, dir) in views {
            *self.views.entry(id).or_insert(0) += 1;
            if self.is_new(id, dir) {
                self.directions.entry(id).or_default().push(dir);
            }
        }
    }

    /// Distinct directions of target `id`.
    pub fn distinct(&self, id: u32) -> usize {
        self.directions.get(&id).map_or(0, Vec::len)
    }

    /// Of `ids`, the targets with at least [`SURVEY_MIN_VIEWS`] distinct directions.
    pub fn well_surveyed(&self, ids: &[u32]) -> usize {
        ids.iter()
            .filter(|&&id| self.distinct(id) >= SURVEY_MIN_VIEWS)
            .count()
    }
}

/// The scene's survey shots (see the module docs): `scene.session.survey_images` of the
/// candidates, chosen for the targets the measurement shots `arc` see poorly. Files are
/// numbered in the order chosen.
pub fn survey_shots(scene: &Scene, rig: &Rig, renderer: &Renderer, arc: &[Shot]) -> Vec<Shot> {
    let mut out = chosen_shots(scene, rig, renderer, arc);
    let links = link_shots(scene, rig, renderer);
    let n0 = out.len();
    out.extend(links.into_iter().enumerate().map(|(j, s)| Shot {
        file: file_name(ImageRole::Survey, n0 + j, scene),
        ..s
    }));
    out
}

/// The `survey_images` shots chosen for the cage (the module docs).
fn chosen_shots(scene: &Scene, rig: &Rig, renderer: &Renderer, arc: &[Shot]) -> Vec<Shot> {
    let n = scene.session.survey_images as usize;
    if n == 0 {
        return Vec::new();
    }
    let cage = cage_ids(rig);
    let mut arc_views: BTreeMap<u32, usize> = BTreeMap::new();
    for shot in arc.iter().filter(|s| s.role == ImageRole::Measurement) {
        for (id, _) in cage_views(renderer, rig, shot, &cage) {
            *arc_views.entry(id).or_insert(0) += 1;
        }
    }
    let weight = |id: u32| {
        if arc_views.get(&id).copied().unwrap_or(0) < ARC_POORLY_SEEN_VIEWS {
            POORLY_SEEN_WEIGHT
        } else {
            1.0
        }
    };
    let cands = candidates(scene, rig);
    let views: Vec<Vec<(u32, DVec3)>> = cands
        .iter()
        .map(|s| cage_views(renderer, rig, s, &cage))
        .collect();
    let mut chosen: Vec<usize> = Vec::new();
    let mut cov = Coverage::default();
    while chosen.len() < n.min(cands.len()) {
        let gain = |k: usize| -> f64 {
            views[k]
                .iter()
                .filter(|(id, dir)| cov.distinct(*id) < SURVEY_MIN_VIEWS && cov.is_new(*id, *dir))
                .map(|(id, _)| weight(*id))
                .sum()
        };
        let best = (0..cands.len())
            .filter(|k| !chosen.contains(k))
            .max_by(|&a, &b| {
                gain(a)
                    .total_cmp(&gain(b))
                    .then(views[a].len().cmp(&views[b].len()))
                    .then(b.cmp(&a))
            });
        let Some(k) = best else { break };
        cov.add(&views[k]);
        chosen.push(k);
    }
    chosen
        .into_iter()
        .enumerate()
        .map(|(j, k)| Shot {
            file: file_name(ImageRole::Survey, j, scene),
            ..cands[k].clone()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::layout::{build_rig, plan_shots};

    /// The default scene with 8 survey shots: every shot sees several cage targets, none sees
    /// the (absent) headdress, and every cage target is well surveyed (three directions at
    /// least 15 degrees apart).
    #[test]
    fn survey_shots_see_the_cage_from_new_directions() {
        let mut scene = Scene::load("default").expect("scene");
        scene.session.survey_images = 8;
        scene.studio.flash_relay_targets = 0;
        let rig = build_rig(&scene);
        let renderer = Renderer::new(&scene, &rig).expect("renderer");
        let arc = plan_shots(&scene, &rig);
        let shots = survey_shots(&scene, &rig, &renderer, &arc);
        assert_eq!(shots.len(), 8);
        let cage = cage_ids(&rig);
        let mut cov = Coverage::default();
        for (k, s) in shots.iter().enumerate() {
            assert_eq!(s.file, format!("images/survey{k:02}.png"));
            assert!(!s.subject_present && !s.flash_fired && s.ambient_on);
            let vis = crate::visibility::usable_targets(&renderer, &rig, s);
            assert!(vis.iter().all(|v| v.0 != Layout::Headdress));
            let v = cage_views(&renderer, &rig, s, &cage);
            assert!(v.len() >= 5, "{} sees {} cage targets", s.file, v.len());
            cov.add(&v);
            let eye = s.world_from_camera.translation_m;
            eprintln!(
                "{}: {} cage targets, {:.2} m from the head centre, azimuth {:.0} deg, {:+.2} m \
                 above it; {} of {} cage targets well surveyed so far",
                s.file,
                v.len(),
                eye.length(),
                eye.x.atan2(eye.y).to_degrees(),
                eye.z,
                cov.well_surveyed(&cage),
                cage.len()
            );
        }
        let mut arc_cov = Coverage::default();
        for s in arc.iter().filter(|s| s.role == ImageRole::Measurement) {
            arc_cov.add(&cage_views(&renderer, &rig, s, &cage));
        }
        let poor: Vec<u32> = cage
            .iter()
            .copied()
            .filter(|id| arc_cov.views.get(id).copied().unwrap_or(0) < ARC_POORLY_SEEN_VIEWS)
            .collect();
        let well = cov.well_surveyed(&cage);
        let well_poor = cov.well_surveyed(&poor);
        eprintln!(
            "{} cage targets: {well} well surveyed; {} poorly seen by the arc, {well_poor} of them well surveyed",
            cage.len(),
            poor.len()
        );
        for id in &cage {
            eprintln!(
                "  target {id}: arc {} views, survey {} views, {} directions",
                arc_cov.views.get(id).copied().unwrap_or(0),
                cov.views.get(id).copied().unwrap_or(0),
                cov.distinct(*id)
            );
        }
        assert_eq!(well, cage.len(), "{well} of {} well surveyed", cage.len());
    }

    /// The default scene with a relay of four targets: the link shots see the relay with the
    /// flash stand's panel (from behind the relay) and with the cage (from its facing side),
    /// and the measurement and light-position images' usable targets are those without it.
    #[test]
    fn link_shots_see_the_relay_with_the_panel_and_with_the_cage() {
        let mut scene = Scene::load("default").expect("scene");
        scene.studio.flash_relay_targets = 4;
        let rig = build_rig(&scene);
        assert_eq!(rig.relay_ids.len(), 4, "{:?}", rig.relay_ids);
        let renderer = Renderer::new(&scene, &rig).expect("renderer");
        let shots = survey_shots(&scene, &rig, &renderer, &[]);
        assert_eq!(shots.len(), 2 * LINK_SHOTS);
        let panel = crate::studio::flash_panel_ids(&rig);
        let cage = cage_ids(&rig);
        for (k, s) in shots.iter().enumerate() {
            assert_eq!(s.file, format!("images/survey{k:02}.png"));
            let seen: Vec<u32> = crate::visibility::usable_targets(&renderer, &rig, s)
                .into_iter()
                .map(|v| v.1)
                .collect();
            let n = |ids: &[u32]| seen.iter().filter(|id| ids.contains(id)).count();
            let other = if k < LINK_SHOTS { &panel } else { &cage };
            let eye = s.world_from_camera.translation_m;
            eprintln!(
                "{}: relay {}, panel {}, cage {}; eye {eye:.2}",
                s.file,
                n(&rig.relay_ids),
                n(&panel),
                n(&cage)
            );
            assert!(n(&rig.relay_ids) >= LINK_MIN_TARGETS && n(other) >= LINK_MIN_TARGETS);
        }
        let mut no_relay = scene.clone();
        no_relay.studio.flash_relay_targets = 0;
        let without = build_rig(&no_relay);
        let ren0 = Renderer::new(&no_relay, &without).expect("renderer");
        for shot in plan_shots(&scene, &rig) {
            let ids = |r: &Rig, ren: &Renderer| -> Vec<u32> {
                crate::visibility::usable_targets(ren, r, &shot)
                    .into_iter()
                    .filter(|v| !rig.relay_ids.contains(&v.1) || v.0 != Layout::Reference)
                    .map(|v| v.1)
                    .collect()
            };
            assert_eq!(ids(&rig, &renderer), ids(&without, &ren0), "{}", shot.file);
        }
    }

    #[test]
    fn no_survey_images_no_shots() {
        let mut scene = Scene::load("default").expect("scene");
        scene.studio.flash_relay_targets = 0;
        let rig = build_rig(&scene);
        let renderer = Renderer::new(&scene, &rig).expect("renderer");
        assert!(survey_shots(&scene, &rig, &renderer, &[]).is_empty());
    }
}
