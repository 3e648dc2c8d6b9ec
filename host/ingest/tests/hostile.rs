//! Hostile inputs to `ingest` (issue 31): a scan whose material or texture paths lead out of
//! its folder, records and settings that are devices, too large, carry unknown keys or
//! impossible values, card entries that are FIFOs or links out, and photographs that cannot be
//! read. Each is refused with an error naming the file and the key or path (or listed as a
//! skip), nothing outside the inputs' folders is copied, and no session is written.

use std::path::{Path, PathBuf};

use skinbrdf_core::CameraModel;
use skinbrdf_ingest::{ingest, IngestConfig, IngestError};
use skinbrdf_session::{CameraSpec, LengthUnit};
use skinbrdf_synth::studio::STUDIO_DIR;
use skinbrdf_synth::textured_scan::ScanFormat;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// A small studio (6 measurement images at 200 x 133) with its OBJ scan.
fn studio(dir: &Path) -> PathBuf {
    let mut scene = Scene::load("default").expect("default scene");
    scene.session.measurement_images = 6;
    scene.studio.scan_formats = vec![ScanFormat::Obj];
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

fn config(studio: &Path, scan: PathBuf, out: PathBuf) -> IngestConfig {
    let mut cfg = IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        studio.join("rig-measured.toml"),
        scan,
        out,
    );
    cfg.scan_units = Some(LengthUnit::Mm);
    cfg
}

/// A copy of the studio's scan folder under `name`, its MTL and OBJ edited.
fn scan_copy(studio: &Path, dir: &Path, name: &str, mtl: Option<&str>, obj_head: &str) -> PathBuf {
    let to = dir.join(name);
    std::fs::create_dir_all(&to).expect("mkdir");
    for f in ["head.obj", "head.mtl", "head.png"] {
        std::fs::copy(studio.join("scan").join(f), to.join(f)).expect("copy");
    }
    if let Some(m) = mtl {
        std::fs::write(to.join("head.mtl"), m).expect("mtl");
    }
    let obj = std::fs::read_to_string(to.join("head.obj")).expect("obj");
    let obj: String = obj
        .lines()
        .filter(|l| !l.starts_with("mtllib"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(to.join("head.obj"), format!("{obj_head}{obj}")).expect("obj");
    to.join("head.obj")
}

/// Every file under `dir` whose name contains `word`.
fn files_named(dir: &Path, word: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let t = e.file_type().expect("type");
            if t.is_dir() {
                stack.push(e.path());
            } else if e.file_name().to_string_lossy().contains(word) {
                out.push(e.path());
            }
        }
    }
    out
}

/// The error's text contains every word; no session was written.
fn refused(cfg: &IngestConfig, words: &[&str]) -> IngestError {
    let e = ingest(cfg).expect_err("refused");
    let text = skinbrdf_core::error_text(&e);
    for w in words {
        assert!(text.contains(w), "`{w}` not in: {text}");
    }
    assert!(!text.contains('\n') || matches!(e, IngestError::UnreadablePhotographs { .. }));
    assert!(!cfg.out_dir.exists(), "{}", cfg.out_dir.display());
    e
}

#[test]
fn hostile_inputs_are_refused_by_name_and_nothing_leaks_into_a_session() {
    let dir = tempfile::tempdir().expect("tempdir");
    let studio = studio(dir.path());
    let out = dir.path().join("OUT");

    // Scan paths out of the folder, and a device.
    let obj = scan_copy(
        &studio,
        dir.path(),
        "shadow",
        Some("newmtl skin\nmap_Kd /etc/shadow\n"),
        "mtllib head.mtl\n",
    );
    refused(
        &config(&studio, obj, out.clone()),
        &["head.mtl", "map_Kd", "/etc/shadow"],
    );
    for (name, lib) in [("passwd", "../../../../etc/passwd"), ("zero", "/dev/zero")] {
        let obj = scan_copy(&studio, dir.path(), name, None, &format!("mtllib {lib}\n"));
        refused(
            &config(&studio, obj, out.clone()),
            &["head.obj", "mtllib", lib],
        );
    }
    #[cfg(unix)]
    {
        let obj = scan_copy(&studio, dir.path(), "link", None, "mtllib link.mtl\n");
        std::os::unix::fs::symlink("/etc/passwd", dir.path().join("link/link.mtl"))
            .expect("symlink");
        refused(
            &config(&studio, obj, out.clone()),
            &["head.obj", "mtllib", "link.mtl", "outside"],
        );
    }
    assert!(files_named(dir.path(), "shadow")
        .iter()
        .all(|p| !p.ends_with("shadow")));
    assert!(files_named(dir.path(), "passwd").is_empty());

    // Records that are devices, too large, or carry unknown keys or impossible values.
    let mut cfg = config(&studio, studio.join("scan/head.obj"), out.clone());
    cfg.capture = PathBuf::from("/dev/zero");
    refused(&cfg, &["/dev/zero", "not a regular file"]);
    let capture: serde_json::Value =
        serde_json::from_slice(&std::fs::read(studio.join("capture.json")).expect("capture"))
            .expect("json");
    let edited = |name: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        let mut c = capture.clone();
        edit(&mut c);
        let p = dir.path().join(name);
        std::fs::write(&p, serde_json::to_vec(&c).expect("json")).expect("write");
        let mut cfg = config(&studio, studio.join("scan/head.obj"), out.clone());
        cfg.capture = p;
        cfg
    };
    refused(
        &edited("unknown.json", &|c| c["clock"]["drift"] = 1.0.into()),
        &["unknown.json", "clock.drift"],
    );
    refused(
        &edited("drift.json", &|c| c["clock"]["drift_ppm"] = 1e30.into()),
        &["drift.json", "clock.drift_ppm"],
    );
    refused(
        &edited("many.json", &|c| {
            let one = c["exposures"][0].clone();
            c["exposures"] = serde_json::Value::Array(vec![one; 200_001]);
        }),
        &["many.json", "capture record"],
    );

    // A camera file with a key session.toml does not have.
    let mut spec = toml::Table::new();
    spec.insert(
        "camera".into(),
        toml::Value::try_from(CameraSpec::Calibrated(CameraModel::from_fov(200, 133, 0.8)))
            .expect("toml"),
    );
    spec["camera"]["distortion"]
        .as_table_mut()
        .expect("distortion")
        .insert("k4".into(), 0.1.into());
    let camera = dir.path().join("camera.toml");
    std::fs::write(&camera, toml::to_string(&spec).expect("toml")).expect("camera");
    let mut cfg = config(&studio, studio.join("scan/head.obj"), out.clone());
    cfg.camera = Some(camera);
    refused(&cfg, &["camera.toml", "camera.distortion.k4"]);

    // Scan points on one line, and a target no rig has.
    let points = |name: &str, rows: &[(u32, u8, [f64; 3])]| {
        let p = dir.path().join(name);
        let text: String = rows
            .iter()
            .map(|(t, c, m)| {
                format!(
                    "[[points]]\ntarget = {t}\ncorner = {c}\nscan_m = [{}, {}, {}]\n",
                    m[0], m[1], m[2]
                )
            })
            .collect();
        std::fs::write(&p, text).expect("points");
        let mut cfg = config(&studio, studio.join("scan/head.obj"), out.clone());
        cfg.scan_points = Some(p);
        cfg
    };
    refused(
        &points(
            "line.toml",
            &[
                (1, 0, [0.0; 3]),
                (1, 1, [0.01, 0.0, 0.0]),
                (1, 2, [0.02, 0.0, 0.0]),
            ],
        ),
        &["line.toml", "one line"],
    );
    refused(
        &points(
            "stranger.toml",
            &[
                (4000, 0, [0.0; 3]),
                (4000, 1, [0.01, 0.0, 0.0]),
                (4000, 2, [0.0, 0.01, 0.0]),
            ],
        ),
        &["stranger.toml", "points[0].target", "4000"],
    );
}

#[cfg(unix)]
#[test]
fn card_fifos_links_out_and_unreadable_photographs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let studio = studio(dir.path());
    let out = dir.path().join("OUT");
    let card = studio.join("card");
    // The card's photographs (in its DCIM folders).
    let mut files: Vec<PathBuf> = files_named(&card, ".")
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("dng")))
        .collect();
    files.sort();

    // A FIFO and a link out of the card are listed as skipped, never read; the ingest goes on.
    assert!(std::process::Command::new("mkfifo")
        .arg(card.join("pipe.dng"))
        .status()
        .is_ok_and(|s| s.success()));
    std::os::unix::fs::symlink("/etc/passwd", card.join("passwd.jpg")).expect("symlink");
    let r = ingest(&config(&studio, studio.join("scan/head.obj"), out.clone())).expect("ingest");
    let skip = |name: &str| {
        r.skipped_files
            .iter()
            .find(|(f, _)| f == name)
            .map(|(_, why)| why.clone())
            .unwrap_or_else(|| panic!("{name} not listed: {:?}", r.skipped_files))
    };
    assert!(skip("pipe.dng").contains("FIFO"));
    assert!(skip("passwd.jpg").contains("outside the folder"));
    assert!(files_named(&out, "passwd").is_empty());
    std::fs::remove_dir_all(&out).expect("rm");

    // A session photograph replaced by a PNG under its name: its exposure has no file, and the
    // file could be it, so the ingest fails naming it.
    // One in the middle of the session (the first may be a test shot before it).
    let victim = files[files.len() / 2].clone();
    std::fs::write(&victim, png_bytes()).expect("png");
    let e =
        ingest(&config(&studio, studio.join("scan/head.obj"), out.clone())).expect_err("refused");
    let text = skinbrdf_core::error_text(&e);
    assert!(
        matches!(e, IngestError::UnreadablePhotographs { .. }),
        "{text}"
    );
    let name = victim
        .file_name()
        .expect("name")
        .to_string_lossy()
        .into_owned();
    assert!(text.contains(&name) && text.contains("PNG"), "{text}");
    // Cut short to 200 bytes: the same.
    let original =
        std::fs::read(files.iter().find(|p| **p != victim).expect("another")).expect("read");
    std::fs::write(&victim, &original[..200]).expect("cut");
    let e =
        ingest(&config(&studio, studio.join("scan/head.obj"), out.clone())).expect_err("refused");
    let text = skinbrdf_core::error_text(&e);
    assert!(text.contains(&name), "{text}");
    assert!(!out.exists());
}

/// A 2x2 PNG.
fn png_bytes() -> Vec<u8> {
    let img = image::RgbImage::from_pixel(2, 2, image::Rgb([1, 2, 3]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("png");
    out.into_inner()
}
