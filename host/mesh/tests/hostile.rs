//! Hostile scan files (issue 31): paths an OBJ, MTL or glTF names that lead out of the scan's
//! folder, devices and FIFOs, and headers that state more than the file holds. Each is refused
//! with an error naming the file, where in it, and the path; none panics or reads what it names.
//! A texture stating more texels than a texture may have is refused by its header.

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

#[test]
fn a_texture_stating_more_texels_than_the_limit_is_refused_before_decoding() {
    let d = tempfile::tempdir().expect("tempdir");
    let obj = obj_scan(d.path(), "head.mtl", Some("bomb.png"));
    // 13000 x 13000: a 3 MB file whose pixels inflate to 507 MB (within the image crate's
    // allocation limit) and to 2 GB as floats.
    let bomb = png_of_zeros(13_000, 13_000);
    assert!(bomb.len() < 4 << 20, "{}", bomb.len());
    std::fs::write(d.path().join("scan/bomb.png"), &bomb).expect("png");
    for e in [
        obj_companion_files(&obj).expect_err("refused"),
        load_textured(&obj, &LoadOptions::default()).expect_err("refused"),
    ] {
        let t = text(&e);
        assert!(
            matches!(e, MeshError::Texture { .. })
                && t.contains("bomb.png")
                && t.contains("13000 x 13000 texels"),
            "{t}"
        );
    }
    // The geometry alone still loads.
    assert!(load_mesh(&obj, &LoadOptions::default()).is_ok());
}

#[test]
fn a_material_colour_with_fewer_than_three_numbers_is_a_parse_error_not_a_panic() {
    let d = tempfile::tempdir().expect("tempdir");
    let obj = obj_scan(d.path(), "head.mtl", Some("tex.png"));
    for kd in ["Kd 1 1", "Kd", "Ks 0.5"] {
        std::fs::write(
            d.path().join("scan/head.mtl"),
            format!("newmtl skin\n{kd}\n"),
        )
        .expect("mtl");
        for e in [
            load_mesh(&obj, &LoadOptions::default()).expect_err("refused"),
            load_textured(&obj, &LoadOptions::default()).expect_err("refused"),
        ] {
            let t = text(&e);
            assert!(
                matches!(e, MeshError::Parse { .. })
                    && t.contains("head.mtl")
                    && t.contains("line 2"),
                "{kd}: {t}"
            );
        }
    }
}

/// A GLB of one textured quad, its JSON chunk edited by `edit` and re-packed.
fn glb_edited(edit: impl Fn(&mut serde_json::Value)) -> Vec<u8> {
    use glam::{Vec2, Vec3};
    let mesh = skinbrdf_core::TriMesh {
        positions: vec![
            Vec3::ZERO,
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::new(0.1, 0.1, 0.0),
            Vec3::new(0.0, 0.1, 0.0),
        ],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        normals: None,
    };
    let uv = [[Vec2::ZERO, Vec2::X, Vec2::ONE]; 2];
    let glb = skinbrdf_mesh::encode_glb(&mesh, &uv, &png()).expect("glb");
    let json_len = u32::from_le_bytes(glb[12..16].try_into().expect("len")) as usize;
    let mut json: serde_json::Value =
        serde_json::from_slice(&glb[20..20 + json_len]).expect("json");
    edit(&mut json);
    let bin = &glb[20 + json_len..];
    let mut j = serde_json::to_vec(&json).expect("json");
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend(((12 + 8 + j.len() + bin.len()) as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&j);
    out.extend(bin);
    out
}

#[test]
fn gltf_documents_that_make_the_gltf_crate_index_unchecked_are_errors_not_panics() {
    let d = tempfile::tempdir().expect("tempdir");
    type Edit<'a> = &'a dyn Fn(&mut serde_json::Value);
    let cases: [(&str, Edit<'_>); 4] = [
        ("accessor", &|j| {
            j["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 4_294_967_295u64.into()
        }),
        ("no-accessors", &|j| j["accessors"] = serde_json::json!([])),
        ("image", &|j| {
            j["images"][0]
                .as_object_mut()
                .expect("image")
                .remove("bufferView");
        }),
        ("reused", &|j| {
            j["scenes"][0]["nodes"] = serde_json::json!(vec![0; 10_000])
        }),
    ];
    for (name, edit) in cases {
        let p = d.path().join(format!("{name}.glb"));
        std::fs::write(&p, glb_edited(edit)).expect("glb");
        // The geometry alone does not read the images.
        let geometry = load_mesh(&p, &LoadOptions::default()).map(|_| ());
        if name == "image" {
            assert!(geometry.is_ok());
        }
        let textured = load_textured(&p, &LoadOptions::default()).map(|_| ());
        for r in [geometry, textured]
            .into_iter()
            .skip(usize::from(name == "image"))
        {
            let e = r.expect_err("refused");
            let t = text(&e);
            assert!(t.contains(&format!("{name}.glb")), "{name}: {t}");
            if name == "reused" {
                assert!(t.contains("node 0 is reached twice"), "{t}");
            }
        }
    }
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 == 1 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// Bits of a DEFLATE stream, least significant first.
#[derive(Default)]
struct Bits {
    out: Vec<u8>,
    acc: u64,
    n: u32,
}

impl Bits {
    fn put(&mut self, v: u64, len: u32) {
        self.acc |= v << self.n;
        self.n += len;
        while self.n >= 8 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.n -= 8;
        }
    }
    /// A Huffman code, written most significant bit first.
    fn code(&mut self, code: u32, len: u32) {
        let rev = (0..len).fold(0u64, |r, i| {
            r | (u64::from((code >> i) & 1) << (len - 1 - i))
        });
        self.put(rev, len);
    }
}

/// A zlib stream of `n` zero bytes: one fixed-Huffman block of a literal 0 and matches of 258
/// bytes at distance 1 (13 bits per 258 bytes: a small file that inflates hugely).
fn zlib_zeros(n: usize) -> Vec<u8> {
    let mut b = Bits::default();
    b.put(1, 1); // the last block
    b.put(1, 2); // fixed Huffman codes
    let mut left = n;
    if left > 0 {
        b.code(0x30, 8); // literal 0
        left -= 1;
    }
    while left >= 258 {
        b.code(0xC5, 8); // length 258 (code 285)
        b.code(0, 5); // distance 1
        left -= 258;
    }
    for _ in 0..left {
        b.code(0x30, 8);
    }
    b.code(0, 7); // end of block
    if b.n > 0 {
        b.out.push(b.acc as u8);
    }
    let mut out = vec![0x78, 0x01];
    out.extend_from_slice(&b.out);
    // Adler-32 of zeros: a = 1, b = n.
    let adler = (((n % 65_521) as u32) << 16) | 1;
    out.extend_from_slice(&adler.to_be_bytes());
    out
}

/// A PNG chunk with its CRC.
fn png_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

/// A black 8-bit RGB PNG of `w` x `h` pixels, a few bytes per thousand pixels: a decompression
/// bomb for a decoder that trusts the stated size.
fn png_of_zeros(w: u32, h: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    png_chunk(&mut out, b"IHDR", &ihdr);
    let raw = h as usize * (1 + 3 * w as usize);
    png_chunk(&mut out, b"IDAT", &zlib_zeros(raw));
    png_chunk(&mut out, b"IEND", &[]);
    out
}
