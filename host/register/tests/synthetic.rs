//! The registration on the default scene's synthetic textured scan, scored against its truth.

use std::sync::OnceLock;

use glam::DVec3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use skinbrdf_register::{
    align, align_points, find_scan_targets, load_point_pairs, AlignConfig, AlignKind,
    ScanTargetConfig, ScanTargets,
};
use skinbrdf_synth::layout::{build_rig, Rig};
use skinbrdf_synth::textured_scan::{write_textured_scan_as, ScanFormat, ScanTruth};
use skinbrdf_synth::Scene;

/// A ray from 10 cm along a target's normal that meets it at 10 cm within this (1 mm) is
/// unobstructed.
const UNOBSTRUCTED_TOL_M: f64 = 1e-3;
/// Corners found on the textured scan against their truth, mm: the survey's headdress bound.
const CORNER_MAX_MM: f64 = 0.5;
/// Registration rotation error, degrees: well below what changes a sample's angles visibly.
const ROTATION_MAX_DEG: f64 = 0.05;
/// Registration translation error, mm: within the survey's reference-target accuracy.
const TRANSLATION_MAX_MM: f64 = 0.3;
/// A similarity between frames of equal units recovers a scale of 1 within this (0.2 %).
const SCALE_TOL: f64 = 2e-3;
/// Corners found on the GLB against those found on the OBJ of the same scan, mm: the two load
/// to the same mesh and colours within f32 rounding, so the renderings and detections agree
/// to far below the corner bound (1/25 of [`CORNER_MAX_MM`]).
const FORMAT_PARITY_MM: f64 = 0.02;
/// Registration from the GLB's corners against the OBJ's: rotation, degrees.
const FORMAT_PARITY_DEG: f64 = 0.002;
/// Rotation error from picked corners (a points file, picked to about a millimetre), degrees.
const PICKED_ROTATION_MAX_DEG: f64 = 0.5;
/// Translation error from picked corners, mm.
const PICKED_TRANSLATION_MAX_MM: f64 = 3.0;

struct Fixture {
    rig: Rig,
    truth: ScanTruth,
    found: ScanTargets,
    visible: Vec<u32>,
    /// The same scan's files as binary glTF and as PLY with vertex colours.
    glb: std::path::PathBuf,
    ply: std::path::PathBuf,
    _dir: tempfile::TempDir,
}

/// Targets whose centre a camera 10 cm along the target's normal sees unobstructed.
fn visible_targets(scan: &skinbrdf_mesh::TexturedMesh, truth: &ScanTruth) -> Vec<u32> {
    let bvh =
        skinbrdf_mesh::MeshBvh::build(&scan.mesh, skinbrdf_mesh::BuildQuality::Fast).expect("bvh");
    truth
        .targets
        .iter()
        .filter(|t| {
            let [c0, c1, c2, c3] = t.corners_m;
            let centre = (c0 + c1 + c2 + c3) * 0.25;
            let out = -((c1 - c0).cross(c0 - c3)).normalize();
            let eye = centre + out * 0.1;
            let hit = bvh.intersect(eye.as_vec3(), (-out).as_vec3(), 1.0);
            hit.is_some_and(|h| (f64::from(h.t_m) - 0.1).abs() < UNOBSTRUCTED_TOL_M)
        })
        .map(|t| t.id)
        .collect()
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let scene = Scene::load("default").expect("scene");
        let rig = build_rig(&scene);
        let dir = tempfile::tempdir().expect("tempdir");
        let files = write_textured_scan_as(
            dir.path(),
            &scene,
            &rig,
            &[ScanFormat::Obj, ScanFormat::Glb, ScanFormat::Ply],
        )
        .expect("write scan");
        let truth: ScanTruth =
            serde_json::from_slice(&std::fs::read(&files.truth).expect("truth")).expect("json");
        let scan = skinbrdf_mesh::load_textured(&files.obj, &Default::default()).expect("load");
        let wanted: Vec<(u32, f64)> = rig.headdress.iter().map(|t| (t.id, t.size_m)).collect();
        let found = find_scan_targets(&scan, &wanted, &ScanTargetConfig::default()).expect("find");
        let visible = visible_targets(&scan, &truth);
        Fixture {
            rig,
            truth,
            found,
            visible,
            glb: files.glb.expect("glb"),
            ply: files.ply.expect("ply"),
            _dir: dir,
        }
    })
}

fn survey_with_noise(rig: &Rig, sigma_m: f64, seed: u64) -> Vec<(u32, [DVec3; 4])> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, sigma_m).expect("normal");
    rig.headdress
        .iter()
        .map(|t| {
            (
                t.id,
                t.corners_m.map(|c| {
                    c + DVec3::new(n.sample(&mut rng), n.sample(&mut rng), n.sample(&mut rng))
                }),
            )
        })
        .collect()
}

fn scan_corners(found: &ScanTargets) -> Vec<(u32, [DVec3; 4])> {
    found.targets.iter().map(|t| (t.id, t.corners_m)).collect()
}

#[test]
fn every_visible_target_is_found_within_half_a_millimetre() {
    let f = fixture();
    assert!(!f.visible.is_empty());
    let mut errs = Vec::new();
    for id in &f.visible {
        let t = f
            .found
            .targets
            .iter()
            .find(|t| t.id == *id)
            .unwrap_or_else(|| panic!("target {id} not found; missing {:?}", f.found.missing));
        let truth = f.truth.targets.iter().find(|x| x.id == *id).expect("truth");
        for k in 0..4 {
            let e = t.corners_m[k].distance(truth.corners_m[k]) * 1e3;
            assert!(
                e < CORNER_MAX_MM,
                "target {id} corner {k}: {e:.3} mm ({t:?})"
            );
            errs.push(e);
        }
    }
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
    let max = errs.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "scan targets: {} of {} found ({} visible), corner error max {max:.3} mm, rms {rms:.3} mm, \
         {} views, timing {:?}",
        f.found.targets.len(),
        f.rig.headdress.len(),
        f.visible.len(),
        f.found.views_rendered,
        f.found.timing
    );
    for t in &f.found.targets {
        eprintln!(
            "  {}: views {}, fit {:.3} mm, spread {:.3?} mm, samples {:?}, errors {:.3?} mm",
            t.id,
            t.views,
            t.fit_residual_mm,
            t.corner_spread_mm,
            t.corner_samples,
            {
                let truth = f
                    .truth
                    .targets
                    .iter()
                    .find(|x| x.id == t.id)
                    .expect("truth");
                let e: Vec<f64> = (0..4)
                    .map(|k| t.corners_m[k].distance(truth.corners_m[k]) * 1e3)
                    .collect();
                e
            }
        );
    }
}

#[test]
fn aligning_the_true_corners_recovers_scanner_from_head() {
    let f = fixture();
    let survey = survey_with_noise(&f.rig, 1e-4, 7);
    let a = align(
        &survey,
        &scan_corners(&f.found),
        AlignKind::Rigid,
        &AlignConfig::default(),
    )
    .expect("align");
    let truth = f.truth.scanner_from_head;
    let rot_deg = a.scan_from_survey.angle_to_rad(&truth).to_degrees();
    let t_mm = a.scan_from_survey.distance_to_m(&truth) * 1e3;
    eprintln!(
        "alignment: rotation error {rot_deg:.4} deg, translation error {t_mm:.3} mm, rms {:.3} mm, \
         sd {:.4} deg / {:.3} mm (centroid {:.3} mm), dropped {:?}",
        a.rms_mm, a.rotation_sd_deg, a.translation_sd_mm, a.centroid_sd_mm, a.dropped
    );
    assert!(rot_deg < ROTATION_MAX_DEG, "{rot_deg} deg");
    assert!(t_mm < TRANSLATION_MAX_MM, "{t_mm} mm");
    assert!(a.dropped.is_empty(), "{:?}", a.dropped);
    assert!(a.rotation_sd_deg > 0.0 && a.rotation_sd_deg < ROTATION_MAX_DEG);

    // A similarity fit finds scale 1.
    let s = align(
        &survey,
        &scan_corners(&f.found),
        AlignKind::Similarity,
        &AlignConfig::default(),
    )
    .expect("similarity");
    assert!((s.scale - 1.0).abs() < SCALE_TOL, "{}", s.scale);
}

#[test]
fn a_corrupted_target_is_dropped_by_name() {
    // Moved by 5 mm, and by 2 mm (twice the threshold's floor).
    for shift in [
        DVec3::new(0.003, -0.004, 0.0),
        DVec3::new(0.0, 0.0012, 0.0016),
    ] {
        corrupted_target_is_dropped(shift);
    }
}

fn corrupted_target_is_dropped(shift: DVec3) {
    let f = fixture();
    let survey = survey_with_noise(&f.rig, 1e-4, 8);
    let mut scan = scan_corners(&f.found);
    let victim = scan[scan.len() / 2].0;
    for (id, c) in &mut scan {
        if *id == victim {
            *c = c.map(|p| p + shift);
        }
    }
    let a = align(&survey, &scan, AlignKind::Rigid, &AlignConfig::default()).expect("align");
    assert_eq!(a.dropped.len(), 1, "{:?}", a.dropped);
    assert_eq!(a.dropped[0].id, victim);
    assert!(
        a.dropped[0].residual_mm > 0.7 * shift.length() * 1e3,
        "{:?}",
        a.dropped
    );
    assert!(a.residuals.iter().all(|r| r.id != victim));
    let truth = f.truth.scanner_from_head;
    let rot_deg = a.scan_from_survey.angle_to_rad(&truth).to_degrees();
    let t_mm = a.scan_from_survey.distance_to_m(&truth) * 1e3;
    eprintln!(
        "corrupted by {:.1} mm: rotation error {rot_deg:.4} deg, translation error {t_mm:.3} mm, \
         rms {:.3} mm, robust median {:.3} mm, dropped {:?}",
        shift.length() * 1e3,
        a.rms_mm,
        a.robust_median_mm,
        a.dropped
    );
    assert!(rot_deg < ROTATION_MAX_DEG, "{rot_deg} deg");
    assert!(t_mm < TRANSLATION_MAX_MM, "{t_mm} mm");
}

#[test]
fn the_points_file_path_aligns_by_picked_corners() {
    let f = fixture();
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("picked.toml");
    // Three targets, two corners each, picked to 0.2 mm.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let n = Normal::new(0.0, 2e-4).expect("normal");
    let mut text = String::new();
    for t in f.truth.targets.iter().step_by(5).take(3) {
        for k in [0usize, 2] {
            let p = t.corners_m[k]
                + DVec3::new(n.sample(&mut rng), n.sample(&mut rng), n.sample(&mut rng));
            text.push_str(&format!(
                "[[points]]\ntarget = {}\ncorner = {k}\nscan_m = [{}, {}, {}]\n\n",
                t.id, p.x, p.y, p.z
            ));
        }
    }
    std::fs::write(&path, &text).expect("write");
    let points = load_point_pairs(&path).expect("points");
    assert_eq!(points.len(), 6);
    let survey = survey_with_noise(&f.rig, 0.0, 0);
    let a =
        align_points(&survey, &points, AlignKind::Rigid, &AlignConfig::default()).expect("align");
    let truth = f.truth.scanner_from_head;
    let rot_deg = a.scan_from_survey.angle_to_rad(&truth).to_degrees();
    let t_mm = a.scan_from_survey.distance_to_m(&truth) * 1e3;
    eprintln!(
        "points: rotation error {rot_deg:.4} deg, translation {t_mm:.3} mm, rms {:.3} mm",
        a.rms_mm
    );
    assert!(
        rot_deg < PICKED_ROTATION_MAX_DEG && t_mm < PICKED_TRANSLATION_MAX_MM,
        "{rot_deg} deg {t_mm} mm"
    );

    // A bad file names itself and the field.
    std::fs::write(&path, text.replacen("corner = 2", "corner = 9", 1)).expect("write");
    let e = load_point_pairs(&path).expect_err("bad corner").to_string();
    assert!(
        e.contains("picked.toml") && e.contains("points[1].corner"),
        "{e}"
    );
    let e = load_point_pairs(&dir.path().join("absent.toml"))
        .expect_err("absent")
        .to_string();
    assert!(e.contains("absent.toml"), "{e}");
}

#[test]
fn the_glb_gives_the_same_targets_corners_and_registration_as_the_obj() {
    let f = fixture();
    let scan = skinbrdf_mesh::load_textured(&f.glb, &Default::default()).expect("load glb");
    let wanted: Vec<(u32, f64)> = f.rig.headdress.iter().map(|t| (t.id, t.size_m)).collect();
    let found = find_scan_targets(&scan, &wanted, &ScanTargetConfig::default()).expect("find");
    let ids = |s: &ScanTargets| s.targets.iter().map(|t| t.id).collect::<Vec<_>>();
    assert_eq!(ids(&found), ids(&f.found), "missing {:?}", found.missing);
    let mut worst = 0.0f64;
    for (a, b) in found.targets.iter().zip(&f.found.targets) {
        for k in 0..4 {
            worst = worst.max(a.corners_m[k].distance(b.corners_m[k]) * 1e3);
        }
    }
    eprintln!(
        "glb against obj: {} targets, corners differ by at most {worst:.5} mm",
        found.targets.len()
    );
    assert!(worst < FORMAT_PARITY_MM, "{worst} mm");
    let survey = survey_with_noise(&f.rig, 1e-4, 7);
    let fit = |s: &ScanTargets| {
        align(
            &survey,
            &scan_corners(s),
            AlignKind::Rigid,
            &AlignConfig::default(),
        )
        .expect("align")
    };
    let (a, b) = (fit(&found), fit(&f.found));
    let deg = a
        .scan_from_survey
        .angle_to_rad(&b.scan_from_survey)
        .to_degrees();
    let mm = a.scan_from_survey.distance_to_m(&b.scan_from_survey) * 1e3;
    assert!(deg < FORMAT_PARITY_DEG, "{deg} deg");
    assert!(mm < FORMAT_PARITY_MM, "{mm} mm");
    assert_eq!(a.dropped, b.dropped);
}

#[test]
fn the_vertex_coloured_ply_gives_the_targets_within_the_corner_bound() {
    let f = fixture();
    let scan = skinbrdf_mesh::load_textured(&f.ply, &Default::default()).expect("load ply");
    assert!(matches!(
        scan.appearance,
        skinbrdf_mesh::Appearance::VertexColours(_)
    ));
    let wanted: Vec<(u32, f64)> = f.rig.headdress.iter().map(|t| (t.id, t.size_m)).collect();
    let found = find_scan_targets(&scan, &wanted, &ScanTargetConfig::default()).expect("find");
    let mut errs = Vec::new();
    for id in &f.visible {
        let t = found
            .targets
            .iter()
            .find(|t| t.id == *id)
            .unwrap_or_else(|| panic!("target {id} not found; missing {:?}", found.missing));
        let truth = f.truth.targets.iter().find(|x| x.id == *id).expect("truth");
        for k in 0..4 {
            errs.push(t.corners_m[k].distance(truth.corners_m[k]) * 1e3);
        }
    }
    let max = errs.iter().copied().fold(0.0, f64::max);
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
    eprintln!(
        "ply vertex colours: {} of {} found, corner error max {max:.3} mm, rms {rms:.3} mm",
        found.targets.len(),
        f.rig.headdress.len()
    );
    assert!(max < CORNER_MAX_MM, "{max} mm");
}
