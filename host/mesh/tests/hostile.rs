//! Hostile scan files (issue 31): paths an OBJ, MTL or glTF names that lead out of the scan's
//! folder, devices and FIFOs, and headers that state more than the file holds. Each is refused
//! with an error naming the file, where in it, and the path; none panics or reads what it names.

use std::path::{Path, PathBuf};

use skinbrdf_core::untrusted::ConfineError;
use skinbrdf_mesh::{load_mesh, load_textured, obj_companion_files, LoadOptions, MeshError};

/// A 2x2 PNG texture.
fn png() -> Vec<u8> {
    let img = image::RgbImage::from_pixel(2, 2, image::Rgb([200, 150, 120]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("png");
    out.into_inner()
}

const QUAD: &str = "v 0 0 0\nv 0.1 0 0\nv 0.1 0.1 0\nv 0 0.1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
                    usemtl skin\nf 1/1 2/2 3/3 4/4\n";

/// `scan/head.obj` naming `mtllib`, and `scan/head.mtl` with `map_kd` (when given).
fn obj_scan(root: &Path, mtllib: &str, map_kd: Option<&str>) -> PathBuf {
    let dir = root.join("scan");
    std::fs::create_dir_all(&dir).expect("mkdir");
    std::fs::write(dir.join("tex.png"), png()).expect("png");
    if let Some(m) = map_kd {
        std::fs::write(dir.join("head.mtl"), format!("newmtl skin\nmap_Kd {m}\n")).expect("mtl");
    }
    let obj = dir.join("head.obj");
    std::fs::write(&obj, format!("# units mm\nmtllib {mtllib}\n{QUAD}")).expect("obj");
    obj
}

fn text(e: &MeshError) -> String {
    skinbrdf_core::error_text(e)
}

/// A refusal naming `file`, `key` and the path as written.
fn assert_refused(e: &MeshError, file: &str, key: &str, written: &str) {
    let t = text(e);
    assert!(matches!(e, MeshError::Refused { .. }), "{t}");
    assert!(
        t.contains(file) && t.contains(key) && t.contains(written),
        "{file} / {key} / {written}: {t}"
    );
}

#[test]
fn a_texture_outside_the_folder_is_refused_by_the_mtl_line() {
    let d = tempfile::tempdir().expect("tempdir");
    let obj = obj_scan(d.path(), "head.mtl", Some("/etc/shadow"));
    let e = obj_companion_files(&obj).expect_err("refused");
    assert_refused(&e, "head.mtl", "line 2 map_Kd", "/etc/shadow");
    let e = load_textured(&obj, &LoadOptions::default()).expect_err("refused");
    assert_refused(&e, "head.obj", "map_Kd", "/etc/shadow");
    // With options before the name, the name is still what is refused.
    let obj = obj_scan(d.path(), "head.mtl", Some("-bm 1.0 ../../../../etc/passwd"));
    let e = obj_companion_files(&obj).expect_err("refused");
    assert_refused(&e, "head.mtl", "map_Kd", "../../../../etc/passwd");
}

#[test]
fn a_material_library_outside_the_folder_or_a_device_is_refused() {
    let d = tempfile::tempdir().expect("tempdir");
    for lib in [
        "../../../../etc/passwd",
        "/dev/zero",
        "/etc/passwd",
        "C:\\x.mtl",
    ] {
        let obj = obj_scan(d.path(), lib, None);
        let e = obj_companion_files(&obj).expect_err("refused");
        assert_refused(&e, "head.obj", "line 2 mtllib", lib);
        let e = load_mesh(&obj, &LoadOptions::default()).expect_err("refused");
        assert_refused(&e, "head.obj", "mtllib", lib);
        let e = load_textured(&obj, &LoadOptions::default()).expect_err("refused");
        assert_refused(&e, "head.obj", "mtllib", lib);
    }
}

#[cfg(unix)]
#[test]
fn a_symbolic_link_out_and_a_fifo_are_refused() {
    let d = tempfile::tempdir().expect("tempdir");
    let outside = d.path().join("secret.mtl");
    std::fs::write(&outside, "newmtl skin\nKd 1 0 0\n").expect("secret");
    let obj = obj_scan(d.path(), "link.mtl", None);
    std::os::unix::fs::symlink(&outside, d.path().join("scan/link.mtl")).expect("symlink");
    let e = obj_companion_files(&obj).expect_err("refused");
    assert_refused(&e, "head.obj", "mtllib", "link.mtl");
    assert!(
        matches!(&e, MeshError::Refused { reason, .. } if matches!(**reason, ConfineError::Outside { .. })),
        "{}",
        text(&e)
    );
    // A FIFO inside the folder: refused at once (never opened, so nothing blocks).
    let fifo = d.path().join("scan/pipe.mtl");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success());
    if made {
        let obj = obj_scan(d.path(), "pipe.mtl", None);
        let e = obj_companion_files(&obj).expect_err("refused");
        assert_refused(&e, "head.obj", "mtllib", "pipe.mtl");
        assert!(text(&e).contains("FIFO"), "{}", text(&e));
        // The scan itself as a FIFO.
        let scan_fifo = d.path().join("scan/fifo.ply");
        assert!(std::process::Command::new("mkfifo")
            .arg(&scan_fifo)
            .status()
            .is_ok_and(|s| s.success()));
        let e = load_mesh(&scan_fifo, &LoadOptions::default()).expect_err("refused");
        assert!(
            matches!(e, MeshError::Read(_)) && text(&e).contains("fifo.ply"),
            "{}",
            text(&e)
        );
    }
}

#[test]
fn windows_separators_and_a_late_mtllib_resolve() {
    let d = tempfile::tempdir().expect("tempdir");
    let obj = obj_scan(d.path(), "head.mtl", Some(".\\tex.png"));
    let t = load_textured(&obj, &LoadOptions::default()).expect("loads");
    assert!(!matches!(t.appearance, skinbrdf_mesh::Appearance::None));
    let files = obj_companion_files(&obj).expect("companions");
    let names: Vec<&str> = files.iter().map(|(r, _)| r.as_str()).collect();
    assert_eq!(names, ["head.mtl", "tex.png"]);

    // An `mtllib` after 64 KiB of comments is still found.
    let padding = "# padding line of an exporter's long header\n".repeat(2000);
    assert!(padding.len() > 64 * 1024);
    std::fs::write(&obj, format!("{padding}mtllib head.mtl\n{QUAD}")).expect("obj");
    let files = obj_companion_files(&obj).expect("companions");
    assert_eq!(files.len(), 2, "{files:?}");
}

#[test]
fn a_texture_that_is_not_an_image_is_refused_by_its_header() {
    let d = tempfile::tempdir().expect("tempdir");
    let obj = obj_scan(d.path(), "head.mtl", Some("notes.png"));
    std::fs::write(
        d.path().join("scan/notes.png"),
        b"these are notes, not pixels",
    )
    .expect("w");
    let e = obj_companion_files(&obj).expect_err("refused");
    let t = text(&e);
    assert!(
        matches!(e, MeshError::Texture { .. }) && t.contains("notes.png"),
        "{t}"
    );
}

#[test]
fn a_ply_header_stating_more_than_the_file_holds_is_refused_before_allocating() {
    let d = tempfile::tempdir().expect("tempdir");
    for format in ["ascii", "binary_little_endian"] {
        let ply = d.path().join(format!("huge-{format}.ply"));
        std::fs::write(
            &ply,
            format!(
                "ply\nformat {format} 1.0\nelement vertex 4294967295\nproperty float x\n\
                 property float y\nproperty float z\nelement face 1\n\
                 property list uchar int vertex_indices\nend_header\n"
            ),
        )
        .expect("ply");
        let e = load_mesh(&ply, &LoadOptions::default()).expect_err("refused");
        let t = text(&e);
        assert!(matches!(e, MeshError::Parse { .. }), "{t}");
        assert!(
            t.contains(&format!("huge-{format}.ply")) && t.contains("4294967295"),
            "{t}"
        );
    }
}

#[test]
fn gltf_uris_leading_out_or_to_a_device_are_refused() {
    let d = tempfile::tempdir().expect("tempdir");
    let scan = d.path().join("scan");
    std::fs::create_dir_all(&scan).expect("mkdir");
    // Each URI and the path its error names (after `file:` and `%`-escapes are read).
    for (uri, named) in [
        ("file:///dev/zero", "/dev/zero"),
        ("/dev/zero", "/dev/zero"),
        ("../outside.bin", "../outside.bin"),
        ("%2E%2E/outside.bin", "../outside.bin"),
    ] {
        let gltf = scan.join("head.gltf");
        let json = serde_json::json!({
            "asset": {"version": "2.0"},
            "buffers": [{"byteLength": 36, "uri": uri}],
        });
        std::fs::write(&gltf, serde_json::to_vec(&json).expect("json")).expect("gltf");
        let e = load_mesh(&gltf, &LoadOptions::default()).expect_err("refused");
        let t = text(&e);
        assert!(
            t.contains("head.gltf") && t.contains("buffer 0"),
            "{uri}: {t}"
        );
        let e = skinbrdf_mesh::gltf_external_files(&gltf).expect_err("refused");
        assert_refused(&e, "head.gltf", "buffer 0 uri", named);
    }
}
