//! `ingest --scan` with each scan format the synthetic studio writes: the OBJ (with its MTL
//! and texture), the binary glTF, a `.gltf` with its buffer and image in a subfolder, and the
//! PLY with vertex colours. Each becomes a session that loads, holding the scan and what it
//! refers to, and the glTF sessions' scans equal the OBJ session's.

use std::path::{Path, PathBuf};

use skinbrdf_ingest::{ingest, IngestConfig, IngestError};
use skinbrdf_mesh::{Appearance, Hit, LoadOptions, TexturedMesh};
use skinbrdf_session::{GeometrySpec, LengthUnit, Session};
use skinbrdf_synth::studio::STUDIO_DIR;
use skinbrdf_synth::textured_scan::ScanFormat;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// The OBJ (millimetres, 5 decimals) and the GLB (metres, f32) of the same scan agree within
/// this, metres (both round the same f64 point; see the synth crate's parity test).
const POS_TOL_M: f32 = 1e-6;
/// Their colours at the same hit agree within this (f32 rounding of the flipped `v`).
const COLOUR_TOL: f32 = 1e-3;

/// A small studio (6 measurement images at 200 x 133: ingest needs a card, not detail) whose
/// textured scan is also written as GLB and vertex-coloured PLY.
fn studio(dir: &Path) -> PathBuf {
    let mut scene = Scene::load("default").expect("default scene");
    scene.session.measurement_images = 6;
    scene.studio.scan_formats = vec![ScanFormat::Obj, ScanFormat::Glb, ScanFormat::Ply];
    let s = dir.join("S");
    generate(
        &scene,
        &SynthOptions {
            resolution: Some((200, 133)),
            capture: None,
            noise_free: false,
            samples_per_pixel: None,
            studio: true,
            studio_only: false,
        },
        &s,
    )
    .expect("synthesis");
    s.join(STUDIO_DIR)
}

fn config(studio: &Path, scan: PathBuf, units: Option<LengthUnit>, out: PathBuf) -> IngestConfig {
    let mut cfg = IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        studio.join("rig-measured.toml"),
        scan,
        out,
    );
    cfg.scan_units = units;
    cfg
}

/// The session's scan as `process` loads it (in the unit the session states).
fn session_scan(out: &Path) -> (String, LengthUnit, TexturedMesh) {
    let session = Session::load(out).expect("the session loads");
    let GeometrySpec::Scan { file, units, .. } = &session.file.geometry else {
        panic!("not a scan: {:?}", session.file.geometry);
    };
    let mesh = skinbrdf_mesh::load_textured(
        &session.path(file),
        &LoadOptions {
            unit: skinbrdf_mesh::LengthUnit::Custom(units.to_m()),
            ..Default::default()
        },
    )
    .expect("the session's scan loads textured");
    (file.clone(), *units, mesh)
}

fn assert_same_scan(a: &TexturedMesh, b: &TexturedMesh) {
    assert_eq!(a.mesh.indices.len(), b.mesh.indices.len());
    assert!(a.mesh.indices == b.mesh.indices, "same triangles");
    let worst = a
        .mesh
        .positions
        .iter()
        .zip(&b.mesh.positions)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0f32, f32::max);
    assert!(worst < POS_TOL_M, "{worst} m");
    for t in (0..a.mesh.indices.len() as u32).step_by(7) {
        let hit = Hit {
            t_m: 1.0,
            triangle: t,
            u: 0.3,
            v: 0.3,
        };
        let (x, y) = (a.colour_at(&hit), b.colour_at(&hit));
        for k in 0..3 {
            assert!(
                (x[k] - y[k]).abs() < COLOUR_TOL,
                "triangle {t}: {x:?} vs {y:?}"
            );
        }
    }
}

/// The GLB's JSON (parsed) and binary chunk.
fn split_glb(bytes: &[u8]) -> (serde_json::Value, Vec<u8>) {
    let u32_at =
        |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes")) as usize;
    let json_len = u32_at(12);
    let json = serde_json::from_slice(&bytes[20..20 + json_len]).expect("json chunk");
    let bin_at = 20 + json_len;
    let bin_len = u32_at(bin_at);
    (json, bytes[bin_at + 8..bin_at + 8 + bin_len].to_vec())
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn every_scan_format_is_ingested_with_its_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let studio = studio(dir.path());
    let scan_dir = studio.join("scan");

    // The OBJ with its MTL and texture, millimetres.
    let out_obj = dir.path().join("S-obj");
    ingest(&config(
        &studio,
        scan_dir.join("head.obj"),
        Some(LengthUnit::Mm),
        out_obj.clone(),
    ))
    .expect("obj ingested");
    assert!(out_obj.join("head.mtl").is_file() && out_obj.join("head.png").is_file());
    let (_, _, from_obj) = session_scan(&out_obj);

    // The GLB, no unit given: metres by specification; nothing comes with it.
    let out_glb = dir.path().join("S-glb");
    ingest(&config(
        &studio,
        scan_dir.join("head.glb"),
        None,
        out_glb.clone(),
    ))
    .expect("glb ingested");
    let (file, units, from_glb) = session_scan(&out_glb);
    assert_eq!((file.as_str(), units), ("head.glb", LengthUnit::M));
    assert!(!out_glb.join("head.png").exists());
    assert_same_scan(&from_glb, &from_obj);

    // A .gltf whose buffer and image are files in a subfolder (a name with a space,
    // %-escaped in the uri): both come along at the same relative paths.
    let src = dir.path().join("gltf-scan");
    std::fs::create_dir_all(src.join("parts")).expect("mkdir");
    let (mut json, bin) = split_glb(&std::fs::read(scan_dir.join("head.glb")).expect("glb"));
    json["buffers"][0] = serde_json::json!({"byteLength": bin.len(), "uri": "parts/head.bin"});
    json["images"][0] = serde_json::json!({"uri": "parts/head%20atlas.png"});
    std::fs::write(src.join("parts/head.bin"), &bin).expect("bin");
    std::fs::copy(scan_dir.join("head.png"), src.join("parts/head atlas.png")).expect("png");
    let gltf = src.join("head.gltf");
    std::fs::write(&gltf, serde_json::to_vec_pretty(&json).expect("json")).expect("gltf");
    let out_gltf = dir.path().join("S-gltf");
    ingest(&config(&studio, gltf.clone(), None, out_gltf.clone())).expect("gltf ingested");
    assert!(out_gltf.join("parts/head.bin").is_file());
    assert!(out_gltf.join("parts/head atlas.png").is_file());
    let (file, _, from_gltf) = session_scan(&out_gltf);
    assert_eq!(file, "head.gltf");
    let Appearance::Texture { materials, .. } = &from_gltf.appearance else {
        panic!("textured");
    };
    let texture = materials[0]
        .texture_path
        .clone()
        .expect("an external image");
    assert!(texture.starts_with(&out_gltf), "{}", texture.display());
    assert_same_scan(&from_gltf, &from_obj);

    // A uri that leaves the scan's folder is refused by name, and nothing is written.
    json["buffers"][0]["uri"] = serde_json::json!("../outside.bin");
    std::fs::write(dir.path().join("outside.bin"), &bin).expect("bin");
    std::fs::write(&gltf, serde_json::to_vec_pretty(&json).expect("json")).expect("gltf");
    let out_bad = dir.path().join("S-bad");
    let e = ingest(&config(&studio, gltf.clone(), None, out_bad.clone())).expect_err("refused");
    let text = skinbrdf_core::error_text(&e);
    assert!(matches!(e, IngestError::Scan { .. }), "{text}");
    assert!(
        text.contains("head.gltf") && text.contains("../outside.bin"),
        "{text}"
    );
    assert!(!out_bad.exists());

    // A missing buffer: the scan does not load, and the error names the file.
    std::fs::remove_file(src.join("parts/head.bin")).expect("rm");
    json["buffers"][0]["uri"] = serde_json::json!("parts/head.bin");
    std::fs::write(&gltf, serde_json::to_vec_pretty(&json).expect("json")).expect("gltf");
    let e = ingest(&config(&studio, gltf, None, out_bad.clone())).expect_err("refused");
    let text = skinbrdf_core::error_text(&e);
    assert!(matches!(e, IngestError::Scan { .. }), "{text}");
    assert!(text.contains("head.bin"), "{text}");

    // The PLY with vertex colours: its unit from its header comment.
    let out_ply = dir.path().join("S-ply");
    ingest(&config(
        &studio,
        scan_dir.join("head-colours.ply"),
        None,
        out_ply.clone(),
    ))
    .expect("ply ingested");
    let (file, units, from_ply) = session_scan(&out_ply);
    assert_eq!((file.as_str(), units), ("head-colours.ply", LengthUnit::Mm));
    assert!(matches!(from_ply.appearance, Appearance::VertexColours(_)));
}

#[test]
#[cfg_attr(debug_assertions, ignore = "renders a session: run with --release")]
fn a_rig_with_an_ideal_shape_needs_no_scan_and_a_head_rig_needs_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let studio = studio(dir.path());
    let scan = studio.join("scan").join("head.obj");

    // A head's rig states no shape: without a scan the ingest is refused, naming the rig.
    let mut cfg = config(
        &studio,
        scan.clone(),
        Some(LengthUnit::Mm),
        dir.path().join("A"),
    );
    cfg.scan = None;
    let e = ingest(&cfg).expect_err("refused");
    let text = skinbrdf_core::error_text(&e);
    assert!(
        text.contains("rig-measured.toml") && text.contains("no scan"),
        "{text}"
    );
    assert!(!dir.path().join("A").exists());

    // The same rig stating a calibration sphere: no scan needed, the session has the sphere.
    let rig_text = std::fs::read_to_string(studio.join("rig-measured.toml")).expect("rig");
    let sphere_rig = studio.join("rig-sphere.toml");
    std::fs::write(
        &sphere_rig,
        format!(
            "{rig_text}\n[geometry]\nkind = \"sphere\"\ncentre_m = [0.0, 0.0, 0.0]\nradius_m = 0.09\n"
        ),
    )
    .expect("write rig");
    cfg.rig = sphere_rig.clone();
    cfg.out_dir = dir.path().join("B");
    ingest(&cfg).expect("ingested without a scan");
    let session = Session::load(dir.path().join("B")).expect("the session loads");
    assert!(
        matches!(session.file.geometry, GeometrySpec::Sphere { radius_m, .. } if radius_m == 0.09)
    );

    // A shape in the rig and a scan too: ambiguous, refused.
    cfg.scan = Some(scan);
    cfg.out_dir = dir.path().join("C");
    let e = ingest(&cfg).expect_err("refused");
    assert!(skinbrdf_core::error_text(&e).contains("give one of them"));
    assert!(!dir.path().join("C").exists());
}
