use super::*;

fn square(id: u32, size: f64, centre: DVec3) -> [DVec3; 4] {
    Target::square(id, size, centre, DVec3::Z, DVec3::Y)
        .map(|t| t.corners_m)
        .unwrap_or([DVec3::ZERO; 4])
}

fn rig_text() -> String {
    let c = square(3, 0.03, DVec3::new(0.1, 0.0, 0.0));
    format!(
        r#"format_version = 1
description = "test"

[[targets]]
id = 3
size_m = 0.03
group = "reference"
corners_m = [[{}, {}, {}], [{}, {}, {}], [{}, {}, {}], [{}, {}, {}]]

[[targets]]
id = 40
size_m = 0.025
group = "headdress"

[flash]
diameter_m = 0.082

[standard]
brdf = {{ model = "lambertian", albedo = [0.99, 0.99, 0.99] }}
size_m = [0.12, 0.12]
"#,
        c[0].x,
        c[0].y,
        c[0].z,
        c[1].x,
        c[1].y,
        c[1].z,
        c[2].x,
        c[2].y,
        c[2].z,
        c[3].x,
        c[3].y,
        c[3].z
    )
}

#[test]
fn a_rig_gives_placed_and_unplaced_targets() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("rig.toml");
    std::fs::write(&p, rig_text()).expect("write");
    let rig = Rig::load(&p).expect("rig");
    let parts = rig.session_parts();
    assert_eq!(parts.targets.reference.len(), 1);
    assert_eq!(parts.targets.unplaced.len(), 1);
    assert_eq!(parts.targets.unplaced[0].group, TargetGroup::Headdress);
    assert!(!parts.fully_placed());
    let bare = Rig::without_placements(&rig.file);
    Rig::write_file(&p, &bare).expect("write");
    let parts = Rig::load(&p).expect("rig").session_parts();
    assert_eq!(parts.targets.unplaced.len(), 2);
}

#[test]
fn a_sheet_layout_is_placed_by_its_pose_and_print_scale() {
    let dir = tempfile::tempdir().expect("tempdir");
    let layout = LayoutFile {
        section: "targets.reference".into(),
        targets: vec![Target {
            id: 7,
            size_m: 0.04,
            corners_m: square(7, 0.04, DVec3::new(0.05, 0.0, 0.0)),
            centre_m: None,
        }],
    };
    std::fs::write(
        dir.path().join("sheet.layout.toml"),
        toml::to_string(&layout).expect("toml"),
    )
    .expect("write");
    let pose = Pose::new(glam::DQuat::IDENTITY, DVec3::new(0.0, 0.0, 1.0));
    let file = RigFile {
        format_version: RIG_FORMAT_VERSION,
        description: String::new(),
        family: TAG_FAMILY.into(),
        sheets: vec![RigSheet {
            name: "s".into(),
            group: TargetGroup::Reference,
            layout: Some("sheet.layout.toml".into()),
            group_from_sheet: Some(pose),
            print_scale: Some(1.015),
        }],
        targets: Vec::new(),
        flash: RigFlash {
            diameter_m: 0.08,
            light_centre_m: DVec3::ZERO,
            light_position_m: None,
            world_from_flash: None,
        },
        standard: None,
        camera: None,
        roi: None,
        geometry: None,
    };
    let p = dir.path().join("rig.toml");
    Rig::write_file(&p, &file).expect("write");
    let parts = Rig::load(&p).expect("rig").session_parts();
    let t = &parts.targets.reference[0];
    assert!((t.size_m - 0.0406).abs() < 1e-12);
    let centre = t.centre();
    assert!((centre - DVec3::new(0.05 * 1.015, 0.0, 1.0)).length() < 1e-12);
}

/// Debug formatting's marks, which a message in words never holds.
fn assert_in_words(text: &str) {
    for mark in ["Some(", "None", "::", "{", "}", "[\"", "\\\""] {
        assert!(!text.contains(mark), "`{mark}` in: {text}");
    }
}

fn load_text(dir: &Path, text: &str) -> Result<Rig, SessionErrors> {
    let p = dir.join("rig.toml");
    std::fs::write(&p, text).expect("write");
    Rig::load(&p)
}

const KNOWN: &str = r#"
[camera]
status = "to-be-calibrated"
focal_guess_px = 2900.5
"#;

#[test]
fn what_the_studio_knows_goes_to_the_session_and_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = rig_text()
            .replace(
                "diameter_m = 0.082",
                "diameter_m = 0.082\nlight_position_m = [0.6, 1.1, 0.05]",
            )
            .replace(
                "size_m = [0.12, 0.12]",
                "size_m = [0.12, 0.12]\nworld_from_standard = { rotation = [0.0, 0.0, 0.6, 0.8], translation_m = [0.1, 0.2, 0.3] }",
            )
            + KNOWN;
    let rig = load_text(dir.path(), &text).expect("rig");
    let parts = rig.session_parts();
    assert_eq!(
        parts.known.light_position_m,
        Some(DVec3::new(0.6, 1.1, 0.05))
    );
    let standard = parts.known.world_from_standard.expect("standard pose");
    assert_eq!(standard.translation_m, DVec3::new(0.1, 0.2, 0.3));
    assert_eq!(
        standard.rotation,
        glam::DQuat::from_xyzw(0.0, 0.0, 0.6, 0.8)
    );
    assert_eq!(parts.known.world_from_flash, None);
    assert_eq!(
        rig.file.camera,
        Some(RigCamera::ToBeCalibrated {
            width_px: None,
            height_px: None,
            focal_guess_px: Some(2900.5)
        })
    );
    // Stated, nothing is missing: the flash and the standard need no targets.
    rig.check_needs()
        .expect("the rig states what the stages need");
    // Written and read back, the same rig.
    let p = dir.path().join("again.toml");
    Rig::write_file(&p, &rig.file).expect("write");
    assert_eq!(Rig::load(&p).expect("again").file, rig.file);

    // A flash pose and a calibrated camera instead.
    let camera = r#"
[camera]
status = "calibrated"
width_px = 600
height_px = 400
fx_px = 2900.0
fy_px = 2900.0
cx_px = 299.5
cy_px = 199.5
"#;
    let text = rig_text().replace(
            "diameter_m = 0.082",
            "diameter_m = 0.082\nworld_from_flash = { rotation = [0.0, 0.0, 0.0, 1.0], translation_m = [0.5, 1.0, 0.0] }",
        ) + camera;
    let rig = load_text(dir.path(), &text).expect("rig");
    let parts = rig.session_parts();
    let flash = parts.known.world_from_flash.expect("flash pose");
    assert_eq!(flash.translation_m, DVec3::new(0.5, 1.0, 0.0));
    assert!(matches!(rig.file.camera, Some(RigCamera::Calibrated(m)) if m.fx_px == 2900.0));
    assert_eq!(rig.file.camera.and_then(|c| c.size_px()), Some((600, 400)));
    Rig::write_file(&p, &rig.file).expect("write");
    assert_eq!(Rig::load(&p).expect("again").file, rig.file);
}

#[test]
fn a_rig_that_locates_neither_flash_nor_standard_is_refused_by_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rig = load_text(dir.path(), &rig_text()).expect("a valid rig");
    let errs = rig
        .check_needs()
        .expect_err("no flash ring, no standard frame");
    assert!(errs.has_field("flash"), "{errs}");
    assert!(errs.has_field("standard"), "{errs}");
    let text = errs.to_string();
    assert!(
        text.contains("rig.toml: `flash`: no target of group \"flash\" and no light_position_m"),
        "{text}"
    );
    assert!(text.contains("world_from_standard"), "{text}");
    for p in &errs.problems {
        assert_eq!(p.file, dir.path().join("rig.toml"));
        assert!(!p.problem.contains("known."), "{}", p.problem);
        assert_in_words(&p.problem);
    }

    // A flash target listed without corners: the key that would place it.
    let text = rig_text().replace(
        "[flash]",
        "[[targets]]\nid = 200\nsize_m = 0.012\ngroup = \"flash\"\n\n[flash]",
    );
    let errs = load_text(dir.path(), &text)
        .expect("a valid rig")
        .check_needs()
        .expect_err("an unplaced flash target");
    assert!(errs.has_field("targets[2].corners_m"), "{errs}");
    assert!(!errs.has_field("flash"), "{errs}");

    // No standard at all; no reference placement; no headdress.
    let text = rig_text()
        .replace("corners_m = [[", "# corners_m = [[")
        .replace("group = \"headdress\"", "group = \"reference\"");
    let text = &text[..text.find("[standard]").expect("standard")];
    let errs = load_text(dir.path(), text)
        .expect("a valid rig")
        .check_needs()
        .expect_err("nothing placed");
    let all = errs.to_string();
    assert!(all.contains("fix the world's origin"), "{all}");
    assert!(all.contains("no target of group \"headdress\""), "{all}");
    assert!(all.contains("`standard`: missing"), "{all}");
    for p in &errs.problems {
        assert_in_words(&p.problem);
    }
}

#[test]
fn what_the_studio_knows_is_checked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = rig_text()
            .replace(
                "diameter_m = 0.082",
                "diameter_m = 0.082\nlight_position_m = [0.6, 1.1, 0.05]\n\
                 world_from_flash = { rotation = [0.0, 0.0, 0.0, 1.0], translation_m = [0.5, 1.0, 0.0] }",
            )
            .replace(
                "size_m = [0.12, 0.12]",
                "size_m = [0.12, -0.12]\nworld_from_standard = { rotation = [0.0, 0.0, 0.0, 2.0], translation_m = [0.1, 0.2, 0.3] }",
            )
            + "\n[camera]\nstatus = \"to-be-calibrated\"\nwidth_px = 600\nfocal_guess_px = -3.0\n\n\
               [[targets]]\nid = 300\nsize_m = 0.02\ngroup = \"standard\"\n";
    let text = text.replace("[standard]", "[standardx]");
    let errs = load_text(dir.path(), &text).expect_err("unknown table");
    assert!(errs.to_string().contains("standardx"), "{errs}");
    let text = text.replace("[standardx]", "[standard]");
    let errs = load_text(dir.path(), &text).expect_err("invalid");
    for field in [
        "flash.world_from_flash",
        "standard.size_m",
        "standard.world_from_standard.rotation",
        "camera.width_px",
        "camera.focal_guess_px",
    ] {
        assert!(errs.has_field(field), "{field}: {errs}");
    }
    for p in &errs.problems {
        assert_in_words(&p.problem);
    }
    // A standard target needs a standard.
    let text = rig_text();
    let cut = &text[..text.find("[standard]").expect("standard")];
    let errs = load_text(
        dir.path(),
        &format!("{cut}[[targets]]\nid = 300\nsize_m = 0.02\ngroup = \"standard\"\n"),
    )
    .expect_err("a standard target without a standard");
    assert!(errs.has_field("targets[2].group"), "{errs}");
}

#[test]
fn every_problem_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("rig.toml");
    let text = rig_text()
            .replace("id = 40", "id = 3")
            .replace("diameter_m = 0.082", "diameter_m = -1.0")
            + "\n[[sheets]]\nname = \"band\"\ngroup = \"headdress\"\nlayout = \"missing.layout.toml\"\n";
    std::fs::write(&p, text).expect("write");
    let errs = Rig::load(&p).expect_err("invalid");
    assert!(errs.has_field("targets[1].id"), "{errs}");
    assert!(errs.has_field("flash.diameter_m"), "{errs}");
    assert!(errs.has_field("sheets[0].layout"), "{errs}");
    assert!(errs.to_string().contains("rig.toml"), "{errs}");
}
