//! Which targets of a shot a detector can use: the synthetic session's own visibility test
//! (facing the camera, inside the image, unoccluded, lit), shared by the generator's framing
//! checks and its truth. It needs both the rig ([`crate::layout`]) and the renderer
//! ([`crate::photograph`]), which is why it lives apart from either.

use glam::DVec3;

use crate::layout::{Layout, Rig, Shot};
use crate::photograph::Renderer;

/// Most oblique view of a target counted as usable by [`usable_targets`], degrees (the pose
/// stage warns at 70).
pub const USABLE_VIEW_MAX_DEG: f64 = 70.0;

/// The targets of a shot a detector can use: facing the camera within
/// [`USABLE_VIEW_MAX_DEG`], all four corners inside the image, not hidden by anything, and lit.
/// Returns `(layout, id, centre in the world)`.
pub fn usable_targets(renderer: &Renderer, rig: &Rig, shot: &Shot) -> Vec<(Layout, u32, DVec3)> {
    let cam = &rig.camera;
    let camera_from_world = shot.world_from_camera.inverse();
    let eye = shot.world_from_camera.translation_m;
    let groups = rig.target_groups(shot);
    let cos_max = USABLE_VIEW_MAX_DEG.to_radians().cos();
    let mut out = Vec::new();
    for (layout, list, frame) in groups {
        for t in list {
            let centre = frame.transform_point(t.centre());
            let out_n = frame.transform_vector(t.outward_normal());
            if out_n.dot((eye - centre).normalize()) < cos_max {
                continue;
            }
            let corners_w = t.corners_m.map(|c| frame.transform_point(c));
            let inside = corners_w.iter().all(|c| {
                cam.project(camera_from_world.transform_point(*c))
                    .is_some_and(|p| cam.contains(p))
            });
            let unoccluded = corners_w.iter().all(|c| {
                let p = *c + (centre - *c) * 0.02;
                let d = p - eye;
                let dist = d.length();
                renderer
                    .first_hit_m(shot, rig, eye, d / dist)
                    .is_none_or(|t| t >= dist - 1e-3)
            });
            if inside && unoccluded && renderer.target_lit(shot, centre, out_n) {
                out.push((layout, t.id, centre));
            }
        }
    }
    out
}

#[cfg(test)]
mod framing_tests {
    use super::*;
    use crate::layout::*;
    use crate::scene::{Scene, BUILTIN_SCENES};
    use skinbrdf_session::ImageRole;

    /// Minimum usable reference targets per image (well over the 1-2 PnP needs, for accuracy).
    const MIN_REFERENCE: usize = 5;
    /// Minimum usable headdress targets per measurement image.
    const MIN_HEADDRESS: usize = 3;

    fn spread_m(pts: &[DVec3]) -> f64 {
        let c = pts.iter().copied().sum::<DVec3>() / pts.len().max(1) as f64;
        pts.iter().map(|p| p.distance(c)).fold(0.0, f64::max)
    }

    #[test]
    fn every_shot_of_every_scene_sees_enough_well_spread_targets() {
        let mut report = String::new();
        let mut failures = Vec::new();
        for (name, _) in BUILTIN_SCENES {
            let scene = Scene::load(name).expect("builtin scene");
            let rig = build_rig(&scene);
            let shots = plan_shots(&scene, &rig);
            let renderer = Renderer::new(&scene, &rig).expect("renderer");
            let mut min_ref = usize::MAX;
            let mut min_head = usize::MAX;
            for shot in &shots {
                let vis = usable_targets(&renderer, &rig, shot);
                let of = |l: Layout| -> Vec<DVec3> {
                    vis.iter().filter(|v| v.0 == l).map(|v| v.2).collect()
                };
                let (r, h, f, s) = (
                    of(Layout::Reference),
                    of(Layout::Headdress),
                    of(Layout::Flash),
                    of(Layout::Standard),
                );
                min_ref = min_ref.min(r.len());
                let mut bad = Vec::new();
                if r.len() < MIN_REFERENCE || spread_m(&r) < 0.08 {
                    bad.push(format!(
                        "reference {} (spread {:.3} m)",
                        r.len(),
                        spread_m(&r)
                    ));
                }
                match shot.role {
                    ImageRole::Measurement => {
                        min_head = min_head.min(h.len());
                        if h.len() < MIN_HEADDRESS {
                            bad.push(format!("headdress {}", h.len()));
                        }
                    }
                    ImageRole::LightPosition if f.len() < 4 => {
                        bad.push(format!("flash {}", f.len()))
                    }
                    ImageRole::StandardPosition | ImageRole::ReferenceStandard if s.len() < 4 => {
                        bad.push(format!("standard {}", s.len()))
                    }
                    _ => {}
                }
                if !bad.is_empty() {
                    failures.push(format!("{name} {}: {}", shot.file, bad.join(", ")));
                }
            }
            report += &format!(
                "{name}: {} reference, {} headdress targets; per image min reference {min_ref}, min headdress {min_head}\n",
                rig.reference.len(),
                rig.headdress.len()
            );
        }
        eprintln!("{report}");
        assert!(failures.is_empty(), "{}", failures.join("\n"));
    }

    #[test]
    fn no_headdress_target_reaches_into_the_region_of_interest() {
        for (name, _) in BUILTIN_SCENES {
            let scene = Scene::load(name).expect("builtin scene");
            let rig = build_rig(&scene);
            for t in &rig.headdress {
                for c in t.corners_m.iter().chain([t.centre()].iter()) {
                    let d = c.distance(rig.roi_centre_head);
                    assert!(
                        d > scene.geometry.roi_radius_m,
                        "{name}: headdress tag {} is {d:.4} m from the region's centre",
                        t.id
                    );
                }
            }
        }
    }

    #[test]
    fn printed_targets_do_not_overlap() {
        for (name, _) in BUILTIN_SCENES {
            let scene = Scene::load(name).expect("builtin scene");
            let rig = build_rig(&scene);
            for list in [&rig.reference, &rig.headdress] {
                for (i, a) in list.iter().enumerate() {
                    for b in &list[i + 1..] {
                        let need = 0.5 * (target_pitch_m(a.size_m) + target_pitch_m(b.size_m))
                            - TARGET_GAP_M;
                        assert!(
                            a.centre().distance(b.centre()) >= need - 1e-9,
                            "{name}: targets {} and {} overlap",
                            a.id,
                            b.id
                        );
                    }
                }
            }
        }
    }
}
