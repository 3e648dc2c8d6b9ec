//! Tests of the glTF reader and writer, through the loaders.

use super::*;
use crate::bvh::Hit;
use crate::error::MeshError;
use crate::load::{LengthUnit, LoadOptions};
use crate::textured::{load_textured, Appearance};
use glam::{Vec2, Vec3};
use serde_json::json;
use skinbrdf_core::TriMesh;

/// Colours compared within this: an 8-bit texel is 1/255 apart, and the sRGB curve is
/// evaluated in f32.
const COLOUR_TOL: f32 = 1e-4;
/// Positions compared within this, metres: f32 rounding of the transforms' products.
const POS_TOL: f32 = 1e-6;

/// A GLB container assembled by hand (independent of the `gltf` crate's writer).
fn glb(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(json).expect("json");
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// 2 x 2 texels: top row black, white; bottom row red, blue.
fn png_2x2() -> Vec<u8> {
    let mut img = image::RgbImage::new(2, 2);
    img.put_pixel(0, 0, image::Rgb([0, 0, 0]));
    img.put_pixel(1, 0, image::Rgb([255, 255, 255]));
    img.put_pixel(0, 1, image::Rgb([255, 0, 0]));
    img.put_pixel(1, 1, image::Rgb([0, 0, 255]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("png");
    out.into_inner()
}

/// The 10 cm quad in z = 0 (two triangles, indexed u16), glTF texture coordinates with
/// `v = 0` at the image's top (the quad's top edge, y = 0.1), the 2 x 2 PNG embedded.
/// `edit` may change the JSON before it is packed.
fn quad_glb(png: &[u8], edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
    let pos = f32s(&[0., 0., 0., 0.1, 0., 0., 0.1, 0.1, 0., 0., 0.1, 0.]);
    let uv = f32s(&[0., 1., 1., 1., 1., 0., 0., 0.]);
    let idx: Vec<u8> = [0u16, 1, 2, 0, 2, 3]
        .iter()
        .flat_map(|i| i.to_le_bytes())
        .collect();
    let mut bin = Vec::new();
    bin.extend_from_slice(&pos); // 0..48
    bin.extend_from_slice(&uv); // 48..80
    bin.extend_from_slice(&idx); // 80..92
    let img_off = bin.len();
    bin.extend_from_slice(png);
    let mut j = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"name": "quad", "primitives": [{
            "attributes": {"POSITION": 0, "TEXCOORD_0": 1},
            "indices": 2, "material": 0}]}],
        "materials": [{"name": "paper", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}],
        "images": [{"bufferView": 3, "mimeType": "image/png"}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 32},
            {"buffer": 0, "byteOffset": 80, "byteLength": 12},
            {"buffer": 0, "byteOffset": img_off, "byteLength": png.len()}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [0, 0, 0], "max": [0.1, 0.1, 0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ]
    });
    edit(&mut j);
    glb(&j, &bin)
}

fn close(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < COLOUR_TOL)
}

fn hit(triangle: u32, u: f32, v: f32) -> Hit {
    Hit {
        t_m: 1.0,
        triangle,
        u,
        v,
    }
}

#[test]
fn a_hand_built_glb_loads_with_its_positions_uv_convention_and_colours() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("quad.glb");
    std::fs::write(&p, quad_glb(&png_2x2(), |_| {})).expect("write");
    let t = load_textured(&p, &LoadOptions::default()).expect("load");
    assert_eq!(t.unit, LengthUnit::Metres, "glTF is metres, not guessed");
    assert_eq!(t.mesh.indices, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(t.mesh.positions[2], Vec3::new(0.1, 0.1, 0.0));
    let plain = crate::load_mesh(&p, &LoadOptions::default()).expect("load_mesh");
    assert_eq!(plain.mesh, t.mesh);
    let Appearance::Texture { uv, materials, .. } = &t.appearance else {
        panic!("{:?}", t.appearance);
    };
    assert_eq!(materials[0].name, "paper");
    assert!(materials[0].texture_path.is_none(), "embedded");
    // glTF v = 1 at vertex 0 (the image's bottom) is OBJ v = 0.
    assert_eq!(uv[0].expect("uv")[0], Vec2::new(0.0, 0.0));
    assert_eq!(uv[0].expect("uv")[2], Vec2::new(1.0, 1.0));
    // Known barycentrics on triangle 1 (corners 0, 2, 3: bottom-left, top-right,
    // top-left): u = 0.25, v = 0.5 is the point (0.025, 0.075), the top-left texel's
    // centre (black); triangle 0 (0, 1, 2) at u = 0.5, v = 0.25: (0.075, 0.025), bottom
    // right (blue); at u = 0, v = 0.25: (0.025, 0.025), bottom left (red).
    assert!(close(t.colour_at(&hit(1, 0.25, 0.5)), [0.0; 3]));
    assert!(close(t.colour_at(&hit(0, 0.5, 0.25)), [0.0, 0.0, 1.0]));
    assert!(close(t.colour_at(&hit(0, 0.0, 0.25)), [1.0, 0.0, 0.0]));
    // Half-way between the bottom texels' centres: (0.05, 0.025) on triangle 0 is
    // u = 0.25, v = 0.25.
    let c = t.colour_at(&hit(0, 0.25, 0.25));
    assert!(close(c, [0.5, 0.0, 0.5]), "{c:?}");
    // The same through a ray, as the OBJ test does.
    let bvh = crate::MeshBvh::build(&t.mesh, crate::BuildQuality::Fast).expect("bvh");
    let h = bvh
        .intersect(Vec3::new(0.075, 0.075, 1.0), -Vec3::Z, 10.0)
        .expect("hit");
    assert!(close(t.colour_at(&h), [1.0; 3]), "top-right texel is white");
    // An explicit unit scales as for any format.
    let mm = crate::load_mesh(
        &p,
        &LoadOptions {
            unit: LengthUnit::Millimetres,
            ..Default::default()
        },
    )
    .expect("mm");
    assert!((mm.mesh.positions[2].x - 1e-4).abs() < 1e-9);
}

#[test]
fn the_base_colour_factor_multiplies_the_texture_in_linear_light() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("quad.glb");
    std::fs::write(
        &p,
        quad_glb(&png_2x2(), |j| {
            j["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] =
                json!([0.5, 1.0, 1.0, 1.0]);
        }),
    )
    .expect("write");
    let t = load_textured(&p, &LoadOptions::default()).expect("load");
    // Red texel (1, 0, 0): linear 1 * 0.5 encodes to 0.7354.
    let c = t.colour_at(&hit(0, 0.0, 0.25));
    assert!(close(c, [linear_to_srgb(0.5), 0.0, 0.0]), "{c:?}");
    assert!((linear_to_srgb(0.5) - 0.735_357).abs() < 1e-5);
}

/// A `.gltf` with its buffer in a data URI: two primitives, one with linear float
/// `COLOR_0`, one with only a `baseColorFactor`; the first instanced under a parent node
/// with a translation and a child with a rotation and scale, the second mirrored.
fn gltf_with_data_uri(extra_nodes: serde_json::Value) -> serde_json::Value {
    let pos = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    let col = f32s(&[1., 0., 0., 0., 1., 0., 0.5, 0.5, 0.5]);
    let mut bin = pos.clone();
    bin.extend_from_slice(&col);
    json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": extra_nodes}],
        "nodes": [
            {"translation": [1.0, 2.0, 3.0], "children": [1]},
            {"mesh": 0, "scale": [2.0, 2.0, 2.0],
             "rotation": [0.0, 0.0, 0.707_106_77, 0.707_106_77]},
            {"mesh": 1, "scale": [-1.0, 1.0, 1.0]}
        ],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1}}]},
            {"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}
        ],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1.0, 1.0]}}],
        "buffers": [{"byteLength": bin.len(),
                     "uri": format!("data:application/octet-stream;base64,{}", base64(&bin))}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 36}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}
        ]
    })
}

#[test]
fn a_gltf_with_a_data_uri_buffer_applies_node_transforms_and_colours() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("scan.gltf");
    std::fs::write(
        &p,
        serde_json::to_vec(&gltf_with_data_uri(json!([0, 2]))).expect("json"),
    )
    .expect("write");
    let opts = LoadOptions {
        policy: crate::RepairPolicy {
            weld: false,
            ..crate::RepairPolicy::repair()
        },
        ..Default::default()
    };
    let t = load_textured(&p, &opts).expect("load");
    assert_eq!(t.mesh.indices.len(), 2);
    // Node 1: rotate 90 degrees about z, scale 2, then node 0 translates by (1, 2, 3):
    // (1, 0, 0) -> (0, 2, 0) -> (1, 4, 3); (0, 1, 0) -> (-2, 0, 0) -> (-1, 2, 3).
    let want = [
        Vec3::new(1.0, 2.0, 3.0),
        Vec3::new(1.0, 4.0, 3.0),
        Vec3::new(-1.0, 2.0, 3.0),
    ];
    for (got, want) in t.mesh.positions[..3].iter().zip(want) {
        assert!((*got - want).length() < POS_TOL, "{got} vs {want}");
    }
    // The mirrored instance (x -> -x) keeps facing +z: its winding was reversed.
    let [a, b, c] = t.mesh.indices[1].map(|v| t.mesh.positions[v as usize]);
    assert!((b - a).cross(c - a).z > 0.0, "{a} {b} {c}");
    assert_eq!(t.mesh.positions[4], Vec3::new(-1.0, 0.0, 0.0));
    // COLOR_0 is linear: (0.5, 0.5, 0.5) is encoded to sRGB; corner colours interpolate.
    let c = t.colour_at(&hit(0, 0.0, 1.0));
    assert!(close(c, [linear_to_srgb(0.5); 3]), "{c:?}");
    let c = t.colour_at(&hit(0, 0.5, 0.0));
    assert!(close(c, [0.5, 0.5, 0.0]), "{c:?}");
    // The factor-only primitive shows its factor, encoded.
    let c = t.colour_at(&hit(1, 0.2, 0.2));
    assert!(close(c, [0.5f32, 0.25, 1.0].map(linear_to_srgb)), "{c:?}");
    let plain = crate::load_mesh(&p, &opts).expect("load_mesh");
    assert_eq!(plain.mesh, t.mesh);
}

#[test]
fn an_external_buffer_and_image_are_read_beside_the_gltf() {
    let dir = tempfile::tempdir().expect("tempdir");
    let png = png_2x2();
    let bytes = quad_glb(&png, |_| {});
    let g = ::gltf::Gltf::from_slice(&bytes).expect("parse");
    let bin = g.blob.clone().expect("blob");
    let mut j = serde_json::to_value(g.document.into_json()).expect("json");
    std::fs::create_dir_all(dir.path().join("tex dir")).expect("mkdir");
    std::fs::write(dir.path().join("quad.bin"), &bin).expect("bin");
    std::fs::write(dir.path().join("tex dir/paper.png"), &png).expect("png");
    j["buffers"][0]["uri"] = json!("quad.bin");
    j["images"][0] = json!({"uri": "tex%20dir/paper.png"});
    let p = dir.path().join("quad.gltf");
    std::fs::write(&p, serde_json::to_vec(&j).expect("json")).expect("write");
    let t = load_textured(&p, &LoadOptions::default()).expect("load");
    assert!(close(t.colour_at(&hit(0, 0.0, 0.25)), [1.0, 0.0, 0.0]));
    let files = gltf_external_files(&p).expect("files");
    let names: Vec<&str> = files.iter().map(|(r, _)| r.as_str()).collect();
    assert_eq!(names, ["quad.bin", "tex dir/paper.png"]);
    // The missing image is named, the geometry still loads.
    std::fs::remove_file(dir.path().join("tex dir/paper.png")).expect("rm");
    let e = load_textured(&p, &LoadOptions::default()).expect_err("no png");
    assert!(matches!(e, MeshError::MissingTexture { .. }), "{e}");
    assert!(e.to_string().contains("paper.png") && e.to_string().contains("quad.gltf"));
    assert!(crate::load_mesh(&p, &LoadOptions::default()).is_ok());
    // The missing buffer is named.
    std::fs::remove_file(dir.path().join("quad.bin")).expect("rm");
    let e = crate::load_mesh(&p, &LoadOptions::default()).expect_err("no bin");
    let s = e.to_string();
    assert!(
        matches!(
            e,
            MeshError::Gltf {
                problem: GltfProblem::MissingBuffer { buffer: 0, .. },
                ..
            }
        ),
        "{s}"
    );
    assert!(s.contains("quad.gltf") && s.contains("quad.bin"), "{s}");
}

fn problem(e: &MeshError) -> Option<&GltfProblem> {
    match e {
        MeshError::Gltf { problem, .. } => Some(problem),
        _ => None,
    }
}

#[test]
fn bad_glb_files_give_errors_naming_the_file_and_the_problem() {
    let dir = tempfile::tempdir().expect("tempdir");
    let load = |name: &str, bytes: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).expect("write");
        let e = load_textured(&p, &LoadOptions::default()).expect_err(name);
        assert!(e.to_string().contains(name), "{e}");
        e
    };
    let good = quad_glb(&png_2x2(), |_| {});

    // Truncated: cut in the binary chunk, and inside the header.
    let e = load("cut.glb", &good[..good.len() - 40]);
    assert!(
        matches!(problem(&e), Some(GltfProblem::Truncated { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("truncated GLB"), "{e}");
    let mut tiny = good.clone();
    tiny[8..12].copy_from_slice(&4u32.to_le_bytes());
    let e = load("tiny.glb", &tiny);
    assert!(e.to_string().contains("states 4 bytes"), "{e}");
    let e = load("stub.glb", &good[..10]);
    assert!(
        matches!(problem(&e), Some(GltfProblem::Truncated { .. })),
        "{e}"
    );

    // A binary chunk shorter than the buffer's byteLength.
    let short = quad_glb(&png_2x2(), |j| {
        j["buffers"][0]["byteLength"] = json!(100_000)
    });
    let e = load("short.glb", &short);
    assert!(
        matches!(problem(&e), Some(GltfProblem::ShortBuffer { .. })),
        "{e}"
    );

    // NaN positions.
    let mut nan = good.clone();
    let json_len = u32::from_le_bytes([nan[12], nan[13], nan[14], nan[15]]) as usize;
    let bin_start = 12 + 8 + json_len + 8;
    nan[bin_start + 12..bin_start + 16].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = load("nan.glb", &nan);
    assert!(
        matches!(
            problem(&e),
            Some(GltfProblem::NonFinitePosition { vertex: 1, .. })
        ),
        "{e}"
    );
    assert!(e.to_string().contains("mesh 0 `quad`, primitive 0"), "{e}");

    // Unsupported primitive modes.
    for (mode, name) in [(0, "POINTS"), (5, "TRIANGLE_STRIP")] {
        let m = quad_glb(&png_2x2(), |j| {
            j["meshes"][0]["primitives"][0]["mode"] = json!(mode)
        });
        let e = load("mode.glb", &m);
        assert!(
            matches!(problem(&e), Some(GltfProblem::UnsupportedMode { .. })),
            "{e}"
        );
        assert!(e.to_string().contains(name), "{e}");
    }

    // Indices past the vertices, and an accessor past its buffer view.
    let m = quad_glb(&png_2x2(), |j| j["accessors"][0]["count"] = json!(2));
    let e = load("idx.glb", &m);
    assert!(e.to_string().contains("index 2 past"), "{e}");
    let m = quad_glb(&png_2x2(), |j| j["accessors"][1]["count"] = json!(40));
    let e = load("uv.glb", &m);
    assert!(
        matches!(problem(&e), Some(GltfProblem::BadAccessor { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("TEXCOORD_0"), "{e}");

    // A texture that does not decode: named, and the geometry alone still loads.
    let bad_png = b"\x89PNG\r\n\x1a\n not really a png".to_vec();
    let p = dir.path().join("badtex.glb");
    std::fs::write(&p, quad_glb(&bad_png, |_| {})).expect("write");
    let e = load_textured(&p, &LoadOptions::default()).expect_err("bad texture");
    assert!(matches!(e, MeshError::Texture { .. }), "{e}");
    let s = e.to_string();
    assert!(
        s.contains("badtex.glb") && s.contains("image 0") && s.contains("paper"),
        "{s}"
    );
    assert!(crate::load_mesh(&p, &LoadOptions::default()).is_ok());

    // Not glTF at all.
    let e = load("json.gltf", b"{\"asset\": 3}");
    assert!(matches!(problem(&e), Some(GltfProblem::Document(_))), "{e}");
}

#[test]
fn write_glb_round_trips_with_a_seam_and_welds_back() {
    // Two triangles sharing an edge whose vertices have different texture coordinates in
    // each (an atlas seam), and an unused vertex.
    let mesh = TriMesh {
        positions: vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::new(0.1, 0.1, 0.0),
            Vec3::new(0.0, 0.1, 0.0),
        ],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        normals: None,
    };
    let uv = vec![
        [
            Vec2::new(0.0, 0.0),
            Vec2::new(0.5, 0.0),
            Vec2::new(0.5, 0.5),
        ],
        [
            Vec2::new(0.5, 0.5),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.5, 1.0),
        ],
    ];
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("seam.glb");
    write_glb(&p, &mesh, &uv, &png_2x2()).expect("write");
    let raw = read_gltf(&p, Detail::Appearance).expect("read");
    assert_eq!(
        raw.mesh.positions.len(),
        6,
        "two vertices split at the seam"
    );
    let t = load_textured(&p, &LoadOptions::default()).expect("load");
    assert_eq!(t.mesh, mesh, "welded back to the mesh's own vertices");
    let Appearance::Texture { uv: got, .. } = &t.appearance else {
        panic!("{:?}", t.appearance);
    };
    for (g, w) in got.iter().zip(&uv) {
        let g = g.expect("uv");
        for k in 0..3 {
            assert!((g[k] - w[k]).length() < 1e-7, "{g:?} vs {w:?}");
        }
    }
    assert!(write_glb(&p, &mesh, &uv[..1], &png_2x2()).is_err());

    // The texture coordinates alone: the same mesh and coordinates, no image decoded.
    let (plain, only_uv) =
        crate::load_mesh_with_uv(&p, &LoadOptions::default()).expect("load with uv");
    assert_eq!(plain.mesh, mesh);
    assert_eq!(only_uv.as_ref(), Some(got));
}
