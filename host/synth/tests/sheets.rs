//! The synthetic rig's printed sheets (`skinbrdf_synth::sheets`): flat where they say so, their
//! layout files load through `skinbrdf_session::rig`, the studio's rig files with the measured
//! poses give exactly the true corners, a duplicated id is printed with the other target's
//! code, and no paper touches another.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers

use std::path::Path;

use glam::DVec3;
use skinbrdf_session::rig::{LayoutFile, RigFile};
use skinbrdf_session::{Rig as RigIo, Target, TargetGroup};
use skinbrdf_synth::layout::{build_rig, plan_shots, Layout, Rig};
use skinbrdf_synth::photograph::Renderer;
use skinbrdf_synth::sheets::{cutout_paper, quad_distance_m, PAPER_CLEARANCE_M};
use skinbrdf_synth::studio::{
    layout_file, layout_path, layout_text, rig_file, unmeasured_rig, LAYOUTS_DIR,
};
use skinbrdf_synth::visibility::usable_targets;
use skinbrdf_synth::Scene;

/// A flat sheet's targets lie in its plane to rounding (metres).
const PLANE_TOL_M: f64 = 1e-9;
/// Corners placed from a rig file agree with the truth to rounding (metres).
const CORNER_TOL_M: f64 = 1e-9;
/// A fold of several degrees moves a sheet's outer corners by millimetres: the flat layout
/// misses them by more than this (metres).
const BENT_MIN_MISS_M: f64 = 5e-4;

/// A flattened target's edges turn by a few degrees at most (its normal to the sheet's):
/// the cosine against the cut-out's edge stays above this.
const FLATTEN_MIN_EDGE_COS: f64 = 0.95;

/// The scenes with sheets: the default cage printed two and three to a sheet, and the two
/// survey scenes.
fn sheet_scenes() -> Vec<Scene> {
    let mut out = Vec::new();
    for n in [2, 3] {
        let mut s = Scene::load("default").unwrap();
        s.targets.reference_sheet_targets = n;
        s.name = format!("default-sheets-{n}");
        out.push(s);
    }
    out.push(Scene::load("survey-sheets").unwrap());
    out.push(Scene::load("survey-faults").unwrap());
    out
}

fn truth_of(rig: &Rig, layout: Layout, id: u32) -> &Target {
    let list = match layout {
        Layout::Headdress => &rig.headdress,
        _ => &rig.reference,
    };
    list.iter()
        .find(|t| t.id == id)
        .expect("a sheet's target is in the rig")
}

#[test]
fn flat_sheets_are_planar_and_bent_ones_are_not() {
    for scene in sheet_scenes() {
        let rig = build_rig(&scene);
        assert!(
            rig.sheets.iter().any(|s| s.layout == Layout::Reference),
            "{}: no sheet",
            scene.name
        );
        for sheet in &rig.sheets {
            let pose = sheet.group_from_sheet;
            let n = pose.transform_vector(DVec3::Z);
            let off_plane = sheet
                .ids()
                .iter()
                .flat_map(|id| truth_of(&rig, sheet.layout, *id).corners_m)
                .map(|c| n.dot(c - pose.translation_m).abs())
                .fold(0.0, f64::max);
            if sheet.rigid() {
                assert!(
                    off_plane < PLANE_TOL_M,
                    "{} {}: a corner {off_plane} m off its plane",
                    scene.name,
                    sheet.name
                );
                // The layout, placed and scaled, is the truth.
                for t in &sheet.targets {
                    let truth = truth_of(&rig, sheet.layout, t.id);
                    assert!((truth.size_m - t.size_m * sheet.print_scale).abs() < 1e-15);
                    for k in 0..4 {
                        let d = sheet.place(t.corners_m[k]).distance(truth.corners_m[k]);
                        assert!(d < CORNER_TOL_M, "{} {}: {d}", sheet.name, t.id);
                    }
                }
            } else if sheet.layout == Layout::Reference {
                assert!(
                    off_plane > BENT_MIN_MISS_M,
                    "{} {}: bent, yet within {off_plane} m of its plane",
                    scene.name,
                    sheet.name
                );
            }
        }
    }
    // Flattening keeps a target's orientation: its edges point as the cut-out's do (a tag
    // turned on the page would reverse them).
    let mut cut = Scene::load("default").unwrap();
    cut.targets.reference_sheet_targets = 1;
    let cutouts = build_rig(&cut);
    for scene in sheet_scenes().iter().take(2) {
        let rig = build_rig(scene);
        for sheet in &rig.sheets {
            for id in sheet.ids() {
                let (a, b) = (
                    truth_of(&rig, Layout::Reference, id),
                    truth_of(&cutouts, Layout::Reference, id),
                );
                for k in 0..4 {
                    let edge = |t: &Target| (t.corners_m[(k + 1) % 4] - t.corners_m[k]).normalize();
                    let cos = edge(a).dot(edge(b));
                    assert!(
                        cos > FLATTEN_MIN_EDGE_COS,
                        "{} {id} edge {k}: cos {cos}",
                        sheet.name
                    );
                }
            }
        }
    }
    // The faults the survey scenes ask for are where they say.
    let rig = build_rig(&Scene::load("survey-sheets").unwrap());
    let scaled: Vec<_> = rig.sheets.iter().filter(|s| s.print_scale != 1.0).collect();
    assert_eq!(scaled.len(), 1);
    assert_eq!(scaled[0].print_scale, 1.015);
    assert!(rig.sheets.iter().any(|s| s.tilt_deg.abs() > 1.0));
    assert!(rig.sheets.iter().all(|s| s.tilt_deg.abs() <= 4.0));
    let rig = build_rig(&Scene::load("survey-faults").unwrap());
    assert_eq!(rig.sheets.iter().filter(|s| !s.rigid()).count(), 2);
    assert!(rig.sheets.iter().any(|s| s.layout == Layout::Headdress));
}

/// Writes a scene's layout files and both rig files into `dir`, as the studio does.
fn write_rigs(dir: &Path, scene: &Scene, rig: &Rig, origin: &[u32]) -> (RigFile, RigFile) {
    std::fs::create_dir_all(dir.join(LAYOUTS_DIR)).unwrap();
    for sheet in &rig.sheets {
        std::fs::write(
            dir.join(layout_path(sheet)),
            layout_text(scene, sheet).unwrap(),
        )
        .unwrap();
    }
    let measured = rig_file(scene, rig);
    let scanner_from_head = skinbrdf_synth::textured_scan::scanner_from_head(scene);
    let bare = unmeasured_rig(scene, rig, origin, &[], &scanner_from_head);
    RigIo::write_file(&dir.join("rig-measured.toml"), &measured).unwrap();
    RigIo::write_file(&dir.join("rig.toml"), &bare).unwrap();
    (measured, bare)
}

#[test]
fn the_rig_files_and_layouts_load_and_give_the_true_corners() {
    for scene in sheet_scenes() {
        let rig = build_rig(&scene);
        let dir = tempfile::tempdir().unwrap();
        let misprinted = scene.studio.duplicate_id.as_ref().map(|d| d.id);
        // An origin cut-out, as the studio declares one.
        let origin: Vec<u32> = rig
            .reference
            .iter()
            .filter(|t| rig.sheet_of(Layout::Reference, t.id).is_none())
            .map(|t| t.id)
            .filter(|id| Some(*id) != misprinted)
            .take(1)
            .collect();
        let (measured, bare) = write_rigs(dir.path(), &scene, &rig, &origin);

        // Every layout file round-trips, in the format `skinbrdf targets` writes.
        for sheet in &rig.sheets {
            let text = std::fs::read_to_string(dir.path().join(layout_path(sheet))).unwrap();
            let back: LayoutFile = toml::from_str(&text).unwrap();
            assert_eq!(back, layout_file(&scene, sheet), "{}", sheet.name);
            assert!(back
                .targets
                .iter()
                .all(|t| t.corners_m.iter().all(|c| c.z == 0.0)));
        }

        // The surveyed rig places every listed target exactly where it is.
        let m = RigIo::load(&dir.path().join("rig-measured.toml"))
            .unwrap_or_else(|e| panic!("{}: {e}", scene.name));
        let parts = m.session_parts();
        assert!(parts.fully_placed(), "{}", scene.name);
        let placed: Vec<(Layout, &Target)> = parts
            .targets
            .reference
            .iter()
            .map(|t| (Layout::Reference, t))
            .chain(
                parts
                    .targets
                    .headdress
                    .iter()
                    .map(|t| (Layout::Headdress, t)),
            )
            .collect();
        assert_eq!(
            placed.len(),
            rig.reference.len() + rig.headdress.len() - usize::from(misprinted.is_some()),
            "{}",
            scene.name
        );
        for (l, t) in &placed {
            let truth = truth_of(&rig, *l, t.id);
            for k in 0..4 {
                assert!(
                    t.corners_m[k].distance(truth.corners_m[k]) < CORNER_TOL_M,
                    "{}: {} {}",
                    scene.name,
                    l.name(),
                    t.id
                );
            }
        }
        assert_eq!(
            measured.sheets.len(),
            rig.sheets.iter().filter(|s| s.rigid()).count()
        );

        // The studio's rig states every sheet by its layout, unplaced (but an origin sheet).
        let b = RigIo::load(&dir.path().join("rig.toml"))
            .unwrap_or_else(|e| panic!("{}: {e}", scene.name));
        assert_eq!(b.file.sheets.len(), rig.sheets.len());
        assert!(b.file.sheets.iter().all(|s| s.group_from_sheet.is_none()
            && s.print_scale.is_none()
            && s.layout.is_some()));
        let unplaced = b.session_parts().targets.unplaced;
        for sheet in &rig.sheets {
            for id in sheet.ids().into_iter().filter(|id| Some(*id) != misprinted) {
                let u = unplaced.iter().find(|u| u.id == id).expect("unplaced");
                assert_eq!(u.sheet.as_deref(), Some(sheet.name.as_str()));
                assert!(u.sheet_corners_m.is_some());
            }
        }

        // rig.toml and its layouts, with rig-measured's sheet poses and print scales, give the
        // true corners: tilt and print scale included.
        let mut posed = bare.clone();
        for s in &mut posed.sheets {
            if let Some(ms) = measured.sheets.iter().find(|ms| ms.name == s.name) {
                s.group_from_sheet = ms.group_from_sheet;
                s.print_scale = ms.print_scale;
            }
        }
        RigIo::write_file(&dir.path().join("rig-posed.toml"), &posed).unwrap();
        let parts = RigIo::load(&dir.path().join("rig-posed.toml"))
            .unwrap()
            .session_parts();
        for sheet in rig.sheets.iter().filter(|s| s.rigid()) {
            for id in sheet.ids().into_iter().filter(|id| Some(*id) != misprinted) {
                let t = parts
                    .targets
                    .reference
                    .iter()
                    .find(|t| t.id == id)
                    .expect("placed by its sheet");
                let truth = truth_of(&rig, sheet.layout, id);
                assert!((t.size_m - truth.size_m).abs() < 1e-15);
                for k in 0..4 {
                    assert!(
                        t.corners_m[k].distance(truth.corners_m[k]) < CORNER_TOL_M,
                        "{} {} {id}",
                        scene.name,
                        sheet.name
                    );
                }
            }
        }
        // ... but a folded sheet's flat layout, placed by its flat pose, misses its targets.
        for sheet in rig
            .sheets
            .iter()
            .filter(|s| !s.rigid() && s.layout == Layout::Reference)
        {
            let miss = sheet
                .targets
                .iter()
                .flat_map(|t| {
                    let truth = truth_of(&rig, sheet.layout, t.id);
                    (0..4).map(move |k| {
                        sheet
                            .group_from_sheet
                            .transform_point(t.corners_m[k] * sheet.print_scale)
                            .distance(truth.corners_m[k])
                    })
                })
                .fold(0.0, f64::max);
            assert!(miss > BENT_MIN_MISS_M, "{}: {miss}", sheet.name);
        }

        // A misprinted target is listed nowhere; the code it carries once.
        if let Some(d) = &scene.studio.duplicate_id {
            for f in [&m, &b] {
                let parts = f.session_parts();
                let ids: Vec<u32> = parts
                    .targets
                    .reference
                    .iter()
                    .map(|t| t.id)
                    .chain(
                        parts
                            .targets
                            .unplaced
                            .iter()
                            .filter(|u| u.group == TargetGroup::Reference)
                            .map(|u| u.id),
                    )
                    .collect();
                assert!(!ids.contains(&d.id));
                assert_eq!(ids.iter().filter(|i| **i == d.printed_as).count(), 1);
            }
        }
    }
}

#[test]
fn no_paper_touches_another() {
    for scene in sheet_scenes() {
        let rig = build_rig(&scene);
        let mut bodies: Vec<(String, Vec<[DVec3; 4]>)> = rig
            .sheets
            .iter()
            .filter(|s| s.layout == Layout::Reference)
            .map(|s| (s.name.clone(), s.paper_quads()))
            .collect();
        let cutouts: Vec<&Target> = rig
            .reference
            .iter()
            .filter(|t| rig.sheet_of(Layout::Reference, t.id).is_none())
            .collect();
        let sheets = bodies.len();
        bodies.extend(
            cutouts
                .iter()
                .map(|t| (format!("target {}", t.id), vec![cutout_paper(t)])),
        );
        // Every pair with a sheet in it (the cut-outs are the cage's own, checked by the
        // framing tests).
        for i in 0..sheets {
            for j in i + 1..bodies.len() {
                let d = bodies[i]
                    .1
                    .iter()
                    .flat_map(|a| bodies[j].1.iter().map(move |b| quad_distance_m(a, b)))
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    d >= PAPER_CLEARANCE_M - 1e-12,
                    "{}: {} and {} are {d} m apart",
                    scene.name,
                    bodies[i].0,
                    bodies[j].0
                );
            }
        }
        // On each sheet, no target's paper overlaps another's.
        for s in &rig.sheets {
            for (i, a) in s.targets.iter().enumerate() {
                for b in &s.targets[i + 1..] {
                    assert!(
                        quad_distance_m(&cutout_paper(a), &cutout_paper(b)) > 0.0,
                        "{}: {} and {} overlap on the page",
                        s.name,
                        a.id,
                        b.id
                    );
                }
            }
        }
    }
}

#[test]
fn a_duplicated_id_is_printed_with_the_other_code() {
    let scene = Scene::load("survey-faults").unwrap();
    let d = scene
        .studio
        .duplicate_id
        .clone()
        .expect("the scene's duplicate");
    let rig = build_rig(&scene);
    let shots = plan_shots(&scene, &rig);
    let renderer = Renderer::new(&scene, &rig).unwrap();
    // A shot that sees both targets.
    let shot = shots
        .iter()
        .find(|s| {
            let u = usable_targets(&renderer, &rig, s);
            [d.id, d.printed_as]
                .iter()
                .all(|id| u.iter().any(|(l, i, _)| *l == Layout::Reference && i == id))
        })
        .expect("a shot sees both");
    let r = renderer.render(shot, &rig, 7, true);
    let grey: Vec<f32> = r.v.iter().map(|v| (v[0] + v[1] + v[2]) / 3.0).collect();
    let img = skinbrdf_targets::GrayF32::new(r.width as usize, r.height as usize, grey).unwrap();
    let dets = skinbrdf_targets::detect::detect(&img, &skinbrdf_targets::DetectorConfig::DEFAULT);
    assert!(
        !dets.iter().any(|t| t.id == d.id),
        "target {} detected under its own code",
        d.id
    );
    let cam = &rig.camera;
    let camera_from_world = shot.world_from_camera.inverse();
    let project = |t: &Target| -> Vec<glam::DVec2> {
        t.corners_m
            .iter()
            .map(|c| cam.project(camera_from_world.transform_point(*c)).unwrap())
            .collect()
    };
    for id in [d.id, d.printed_as] {
        let truth = project(rig.reference.iter().find(|t| t.id == id).unwrap());
        let found = dets.iter().any(|t| {
            t.id == d.printed_as && (0..4).all(|k| t.corners_px[k].distance(truth[k]) < 2.0)
        });
        assert!(
            found,
            "target {id} is not seen as {} where it is",
            d.printed_as
        );
    }
}

#[test]
fn a_moved_target_on_a_sheet_moves_its_sheet() {
    let mut scene = Scene::load("survey-sheets").unwrap();
    scene.studio.moved_target = Some(skinbrdf_synth::studio::MovedTarget {
        id: 42,
        from_shot: 3,
        shift_mm: [3.0, 0.0, -1.5],
        rotate_deg: 2.0,
    });
    let rig = build_rig(&scene);
    let m = scene.studio.moved_target.as_ref().unwrap();
    let moved = m.apply(&rig);
    let sheet = moved
        .sheet_of(Layout::Reference, 42)
        .expect("42 is on a sheet");
    assert_eq!(sheet.ids(), vec![41, 42, 43]);
    // Its layout, placed by the moved sheet's pose and scale, is where every target of the
    // sheet went; the rest of the cage stayed.
    for t in &sheet.targets {
        let truth = truth_of(&moved, Layout::Reference, t.id);
        let before = truth_of(&rig, Layout::Reference, t.id);
        assert!(truth.centre().distance(before.centre()) > 1e-3);
        for k in 0..4 {
            assert!(sheet.place(t.corners_m[k]).distance(truth.corners_m[k]) < CORNER_TOL_M);
        }
    }
    for (a, b) in rig.reference.iter().zip(&moved.reference) {
        if !sheet.ids().contains(&a.id) {
            assert_eq!(a, b);
        }
    }
}
