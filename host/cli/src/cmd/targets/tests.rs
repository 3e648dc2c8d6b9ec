//! The scene cut-outs against the scene's rig.

use super::*;

#[test]
fn scene_cutouts_carry_the_scene_rigs_layout() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("headdress.svg");
    scene_cutouts("default", SheetKind::Headdress, &out).expect("cutouts");
    let text = std::fs::read_to_string(out.with_extension("layout.toml")).expect("layout");
    let layout: LayoutFile = toml::from_str(&text).expect("parse");
    assert_eq!(layout.section, "targets.headdress");
    let scene = skinbrdf_synth::Scene::load("default").expect("scene");
    let rig = skinbrdf_synth::layout::build_rig(&scene);
    assert_eq!(layout.targets.len(), rig.headdress.len());
    for (a, b) in layout.targets.iter().zip(&rig.headdress) {
        assert_eq!(a.id, b.id);
        assert!((a.size_m - b.size_m).abs() < 1e-12);
        for (p, q) in a.corners_m.iter().zip(&b.corners_m) {
            assert!(p.distance(*q) < 1e-12, "tag {}", a.id);
        }
    }
    // Every tag is on the printed page(s) once, with its ID.
    let svg = std::fs::read_to_string(&out).expect("svg");
    for t in &rig.headdress {
        assert!(svg.contains(&format!(">{}</text>", t.id)), "tag {}", t.id);
    }
    // A board has no place in a scene: a clear error.
    let err =
        scene_cutouts("default", SheetKind::Board, &dir.path().join("b.pdf")).expect_err("board");
    assert!(err.to_string().contains("calibration board"), "{err}");
}
