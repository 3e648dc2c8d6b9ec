//! Writing a whole synthetic session: images, scan, `session.toml`, `capture.json`,
//! `truth.json` and the truth masks.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{DVec2, DVec3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use skinbrdf_core::{CameraModel, TriMesh};
use skinbrdf_session::capture::CaptureRecord;
use skinbrdf_session::write::{write_exr_rgb32f, write_png_rgb16, write_png_rgb8};
use skinbrdf_session::{
    CameraSpec, FlashSpec, GeometrySpec, ImageEntry, ImageRole, ImageTruth, KnownQuantities,
    Linearization, RegionOfInterest, RenderTruth, SessionFile, StandardSpec, StoredFormat,
    SurfaceTruth, TargetLayouts, TargetTruth, ToneCurve, Truth, SESSION_FORMAT_VERSION, TAG_FAMILY,
    TRUTH_FILE, TRUTH_FORMAT_VERSION,
};

use crate::layout::{build_rig, plan_shots, shots_from_capture, Layout, Rig, Shot};
use crate::photograph::{Rendered, Renderer};
use crate::scene::{CurveScene, Encoding, GeometryKind, Scene};
use crate::shape::Shape;

/// How far inside a target's outline the truth's visibility rays aim, metres: far below a
/// pixel's footprint (0.3..1 mm), far above the ray tracer's single-precision resolution.
const VISIBILITY_INSET_M: f64 = 1e-4;

/// Errors of the generator.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// Writing a file failed.
    #[error(transparent)]
    File(#[from] skinbrdf_session::FileError),
    /// Building or writing a mesh failed.
    #[error("mesh")]
    Mesh(#[from] skinbrdf_mesh::MeshError),
    /// The scene (with the options applied) has values outside their stated ranges.
    #[error("the scene is not valid: {}", problems.join("; "))]
    Scene {
        /// Every problem, each naming its field and range.
        problems: Vec<String>,
    },
    /// Writing a raw image of the synthetic studio failed.
    #[error("studio raw image")]
    Raw {
        /// The writer's error (it names the file).
        source: skinbrdf_raw::RawError,
    },
    /// An option is out of range.
    #[error("{field}: {problem}")]
    Invalid {
        /// The option.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
}

/// Generator options (beyond the scene).
#[derive(Debug, Clone, Default)]
pub struct SynthOptions {
    /// Overrides the scene's image size (the field of view is kept).
    pub resolution: Option<(u32, u32)>,
    /// Render one image per usable exposure of this record and copy it into the session.
    pub capture: Option<CaptureRecord>,
    /// No sensor noise and no scanner noise (quantisation remains).
    pub noise_free: bool,
    /// Overrides the scene's rays per pixel.
    pub samples_per_pixel: Option<u32>,
    /// Also write `studio/`: the camera's raw files, the controller's record, the rig files
    /// and the scan, as a studio holds them after the capture ([`crate::studio`]). Without a
    /// `capture` record the generator writes the one a controller would for the shot list.
    pub studio: bool,
    /// With `studio`: write only what the studio holds and the truth, leaving out the
    /// generator's own session (its linear images and `session.toml`), which the studio's path
    /// never reads.
    pub studio_only: bool,
}

/// What was generated and what it cost.
#[derive(Debug, Clone)]
pub struct SynthSummary {
    /// Session directory.
    pub dir: PathBuf,
    /// Images written.
    pub images: usize,
    /// Image size.
    pub resolution: (u32, u32),
    /// Primary rays traced.
    pub rays: u64,
    /// Skin triangles of the render mesh.
    pub render_triangles: usize,
    /// Scan vertices (0 for ideal shapes).
    pub scan_vertices: usize,
    /// Seconds building the rig and BVHs.
    pub setup_s: f64,
    /// Seconds rendering (ray casting and shading).
    pub render_s: f64,
    /// Seconds adding noise, encoding and writing.
    pub write_s: f64,
    /// Total seconds.
    pub total_s: f64,
}

/// Applies the options to a scene (resolution, samples).
pub fn apply_options(scene: &Scene, opts: &SynthOptions) -> Result<Scene, SynthError> {
    let mut s = scene.clone();
    if let Some((w, h)) = opts.resolution {
        if w < 16 || h < 16 || w > 20000 || h > 20000 {
            return Err(SynthError::Invalid {
                field: "resolution",
                problem: format!("{w}x{h} is outside 16..20000 pixels per side"),
            });
        }
        s.camera.width_px = w;
        s.camera.height_px = h;
    }
    if let Some(n) = opts.samples_per_pixel {
        s.sensor.samples_per_pixel = n;
    }
    if opts.noise_free {
        s.geometry.scan_noise_m = 0.0;
    }
    // Every value against its range before any work (a flag can break a valid scene).
    let problems = s.problems();
    if !problems.is_empty() {
        return Err(SynthError::Scene { problems });
    }
    Ok(s)
}

fn linearization(scene: &Scene) -> (Linearization, StoredFormat) {
    let se = &scene.sensor;
    match se.encoding {
        // Float files hold V itself, clipped where the sensor saturates (V = 1).
        Encoding::Exr => (
            Linearization {
                saturation_level: Some(1.0),
                ..Linearization::LINEAR
            },
            StoredFormat::F32,
        ),
        enc => {
            let (curve, gamma) = match se.curve {
                CurveScene::Linear => (ToneCurve::Linear, None),
                CurveScene::Srgb => (ToneCurve::Srgb, None),
                CurveScene::Gamma => (ToneCurve::Gamma, Some(se.gamma)),
            };
            let lin = Linearization {
                curve,
                gamma,
                response: None,
                black_level: se.black_level,
                white_level: Some(se.white_level),
                saturation_level: Some(se.white_level),
            };
            (
                lin,
                if enc == Encoding::Png8 {
                    StoredFormat::U8
                } else {
                    StoredFormat::U16
                },
            )
        }
    }
}

/// Adds shot and read noise (unless `noise_free`), clips at the white level, applies the tone
/// curve and quantises. Returns the stored values, row-major RGB.
pub fn encode_image(r: &Rendered, scene: &Scene, noise_free: bool, seed: u64) -> Vec<f32> {
    let (lin, fmt) = linearization(scene);
    let w = r.width as usize;
    let full_well = scene.sensor.full_well_e;
    let read = scene.sensor.read_noise;
    let white = lin.white_for(fmt);
    let max_code = fmt.max_code();
    let mut out = vec![0.0f32; 3 * r.v.len()];
    out.par_chunks_mut(3 * w).enumerate().for_each(|(y, row)| {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ((y as u64) << 20) ^ 0x0bad_5eed);
        for (x, px) in row.chunks_mut(3).enumerate() {
            let v = r.v[y * w + x];
            for k in 0..3 {
                let mut val = f64::from(v[k]);
                if !noise_free {
                    let sigma = (val.max(0.0) / full_well + read * read).sqrt();
                    let z: f64 = StandardNormal.sample(&mut rng);
                    val += sigma * z;
                }
                px[k] = match max_code {
                    Some(max) => {
                        let raw = lin.encode(val.min(1.0), fmt).round();
                        raw.clamp(0.0, white.min(max)) as f32
                    }
                    None => val.min(1.0) as f32,
                };
            }
        }
    });
    out
}

fn write_image(path: &Path, r: &Rendered, stored: &[f32], scene: &Scene) -> Result<(), SynthError> {
    match scene.sensor.encoding {
        Encoding::Png16 => {
            let v: Vec<u16> = stored.iter().map(|&c| c as u16).collect();
            write_png_rgb16(path, r.width, r.height, &v)?
        }
        Encoding::Png8 => {
            let v: Vec<u8> = stored.iter().map(|&c| c as u8).collect();
            write_png_rgb8(path, r.width, r.height, &v)?
        }
        Encoding::Exr => write_exr_rgb32f(path, r.width, r.height, stored)?,
    }
    Ok(())
}

/// The head scan: the true surface's front part, tessellated at `scan_spacing_m`, with
/// Gaussian noise on every vertex coordinate, in the scan's units.
pub fn make_scan(shape: &Shape, scene: &Scene, rng: &mut ChaCha8Rng) -> TriMesh {
    let g = &scene.geometry;
    let mut mesh = shape.tessellate(
        g.scan_spacing_m,
        (-80f64.to_radians(), 80f64.to_radians()),
        (-35f64.to_radians(), 75f64.to_radians()),
    );
    let scale = 1.0 / g.scan_units.to_m();
    for p in &mut mesh.positions {
        let mut q = p.as_dvec3();
        if g.scan_noise_m > 0.0 {
            let n: [f64; 3] = std::array::from_fn(|_| StandardNormal.sample(rng));
            q += DVec3::from_array(n) * g.scan_noise_m;
        }
        *p = (q * scale).as_vec3();
    }
    mesh
}

/// The unit's name in a PLY header's comment.
pub(crate) fn unit_name(u: skinbrdf_session::LengthUnit) -> &'static str {
    use skinbrdf_session::LengthUnit;
    match u {
        LengthUnit::M => "metres",
        LengthUnit::Cm => "centimetres",
        LengthUnit::Mm => "millimetres",
        LengthUnit::In => "inches",
    }
}

fn target_truths(
    renderer: &Renderer,
    rig: &Rig,
    shot: &Shot,
    cam: &CameraModel,
) -> Vec<TargetTruth> {
    let camera_from_world = shot.world_from_camera.inverse();
    let eye = shot.world_from_camera.translation_m;
    let groups = rig.target_groups(shot);
    let mut out = Vec::new();
    for (layout, list, frame) in groups {
        for t in list {
            let centre = frame.transform_point(t.centre());
            let out_n = frame.transform_vector(t.outward_normal());
            if out_n.dot(eye - centre) <= 0.0 {
                continue;
            }
            let Some(centre_px) = cam.project(camera_from_world.transform_point(centre)) else {
                continue;
            };
            if !cam.contains(centre_px) {
                continue;
            }
            let corners_w = t.corners_m.map(|c| frame.transform_point(c));
            let corners_px: Vec<Option<DVec2>> = corners_w
                .iter()
                .map(|c| cam.project(camera_from_world.transform_point(*c)))
                .collect();
            let Some(corners_px) = corners_px.iter().copied().collect::<Option<Vec<_>>>() else {
                continue;
            };
            // The border's outline: each corner and each side's midpoint, aimed a tenth of a
            // millimetre inside so the outline's own edge does not count (aiming a fraction of
            // the size inside, 0.4 mm on a 30 mm tag, let a neighbouring stand-off paper hide
            // a pixel of a border unseen).
            let sides = (0..4).map(|k| 0.5 * (corners_w[k] + corners_w[(k + 1) % 4]));
            let unoccluded = corners_w.iter().copied().chain(sides).all(|c| {
                let p = c + (centre - c).normalize_or_zero() * VISIBILITY_INSET_M;
                let d = p - eye;
                let dist = d.length();
                renderer
                    .first_hit_m(shot, rig, eye, d / dist)
                    .is_none_or(|t| t >= dist - 1e-3)
            });
            let fully_visible = unoccluded
                && corners_px.iter().all(|p| cam.contains(*p))
                && renderer.target_lit(shot, centre, out_n);
            out.push(TargetTruth {
                layout: layout.name().to_string(),
                id: t.id,
                corners_px: [corners_px[0], corners_px[1], corners_px[2], corners_px[3]],
                centre_px,
                fully_visible,
            });
        }
    }
    out
}

/// Generates a session into `dir` (created if needed; existing files are overwritten). The
/// scene and options are validated before anything is written; a directory this call created
/// is removed again if generation fails later.
pub fn generate(
    scene: &Scene,
    opts: &SynthOptions,
    dir: &Path,
) -> Result<SynthSummary, SynthError> {
    let created = !dir.exists();
    let result = generate_into(scene, opts, dir);
    if result.is_err() && created && dir.exists() {
        let _ = std::fs::remove_dir_all(dir);
    }
    result
}

fn generate_into(
    scene: &Scene,
    opts: &SynthOptions,
    dir: &Path,
) -> Result<SynthSummary, SynthError> {
    let t_start = Instant::now();
    let scene = apply_options(scene, opts)?;
    let rig = build_rig(&scene);
    let problems = crate::studio::rig_problems(&scene, &rig);
    if !problems.is_empty() {
        return Err(SynthError::Scene { problems });
    }
    let planned;
    let capture = match (&opts.capture, opts.studio) {
        (Some(rec), _) => Some(rec),
        (None, true) => {
            planned = crate::studio::planned_capture(&scene);
            Some(&planned)
        }
        (None, false) => None,
    };
    let mut shots = match capture {
        Some(rec) => shots_from_capture(&scene, &rig, rec),
        None => plan_shots(&scene, &rig),
    };
    if shots.is_empty() {
        return Err(SynthError::Invalid {
            field: "capture",
            problem: "the capture record has no usable exposure".into(),
        });
    }
    let renderer = Renderer::new(&scene, &rig)?;
    // Survey shots (taken before the session, without the subject) follow the capture's shots
    // in the render order, so a shot index of the scene (`moved_target.from_shot`) keeps its
    // meaning; the session lists them first, in the order they were taken.
    let n_capture = shots.len();
    let survey = crate::survey_shots::survey_shots(&scene, &rig, &renderer, &shots);
    shots.extend(survey);
    let capture_shots = &shots[..n_capture];
    // A target that moves mid-session: the shots from the move on see a second rig (and a
    // renderer built from it); the per-image truth follows the rig each shot was rendered with.
    let moved = match (&scene.studio.moved_target, opts.studio) {
        (Some(m), true) => {
            let r = m.apply(&rig);
            let ren = Renderer::new(&scene, &r)?;
            Some((m.from_shot, r, ren))
        }
        _ => None,
    };
    let rig_of = |i: usize| -> (&Rig, &Renderer) {
        match &moved {
            Some((from, r, ren)) if i >= *from && i < n_capture => (r, ren),
            _ => (&rig, &renderer),
        }
    };
    std::fs::create_dir_all(dir).map_err(|source| skinbrdf_session::FileError::Io {
        path: dir.to_path_buf(),
        source,
    })?;

    let mut rng = ChaCha8Rng::seed_from_u64(scene.seed ^ 0x5ca7);
    let (geometry, scan_vertices, scan_spacing) = match scene.geometry.kind {
        GeometryKind::Head => {
            let scan = make_scan(&rig.shape, &scene, &mut rng);
            skinbrdf_mesh::write_ply_binary_in(
                &dir.join("scan.ply"),
                &scan,
                unit_name(scene.geometry.scan_units),
            )?;
            (
                GeometrySpec::Scan {
                    file: "scan.ply".into(),
                    units: scene.geometry.scan_units,
                    accept_repair_loss: None,
                },
                scan.positions.len(),
                scene.geometry.scan_spacing_m,
            )
        }
        GeometryKind::Sphere | GeometryKind::Cylinder => (
            analytic_geometry(&scene).ok_or(SynthError::Invalid {
                field: "geometry.kind",
                problem: "not an ideal shape".into(),
            })?,
            0,
            0.0,
        ),
    };
    let studio = match (capture, opts.studio) {
        (Some(rec), true) => Some((
            crate::studio::write_studio_files(
                dir,
                &scene,
                &rig,
                rec,
                &[
                    crate::studio::origin_ids(&renderer, &rig, capture_shots, &scene),
                    crate::studio::stated_panel_ids(&rig),
                ]
                .concat(),
                &crate::studio::most_seen(
                    &renderer,
                    &rig,
                    capture_shots,
                    Layout::Headdress,
                    crate::studio::declared_headdress_count(&scene),
                ),
            )?,
            crate::studio::card_files(&scene, rec, &shots),
        )),
        _ => None,
    };
    let setup_s = t_start.elapsed().as_secs_f64();
    let studio_only = opts.studio_only && studio.is_some();

    let mut render_s = 0.0;
    let mut write_s = 0.0;
    let mut rays = 0;
    let mut image_truths = Vec::new();
    let mut entries = Vec::new();
    // Post-processing of image i (noise, encoding, files, truth) runs while image i + 1 renders.
    let finish = |i: usize, shot: &Shot, r: Rendered| -> Result<(ImageTruth, f64), SynthError> {
        let t1 = Instant::now();
        if !studio_only {
            let stored = encode_image(
                &r,
                &scene,
                opts.noise_free,
                scene.seed ^ (i as u64).wrapping_mul(0x1234_5678_9abc),
            );
            write_image(&dir.join(&shot.file), &r, &stored, &scene)?;
        }
        if let Some((studio_dir, card)) = &studio {
            for c in card.iter().filter(|c| c.shot == i) {
                let seed = scene.seed ^ u64::from(c.shutter_count).wrapping_mul(0x9e37_79b9);
                crate::studio::write_card_file(studio_dir, &r, &scene, c, opts.noise_free, seed)?;
            }
        }
        let stem = Path::new(&shot.file)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| format!("img{i}"));
        let mask = |name: &str, m: &[bool]| -> Result<Option<String>, SynthError> {
            if !m.iter().any(|&b| b) {
                return Ok(None);
            }
            let rel = format!("truth/{stem}_{name}.png");
            skinbrdf_session::write_mask_png(&dir.join(&rel), r.width, r.height, m)?;
            Ok(Some(rel))
        };
        let truth = ImageTruth {
            file: shot.file.clone(),
            role: shot.role,
            exposure_us: shot.exposure_us,
            exposure_index: shot.exposure_index,
            world_from_camera: shot.world_from_camera,
            world_from_head: shot.world_from_head,
            forehead_mask: mask("forehead", &r.forehead)?,
            targets_mask: mask("targets", &r.targets)?,
            standard_mask: mask("standard", &r.standard)?,
            targets: {
                let (rig_i, renderer_i) = rig_of(i);
                target_truths(renderer_i, rig_i, shot, &rig.camera)
            },
        };
        Ok((truth, t1.elapsed().as_secs_f64()))
    };
    let render_one = |i: usize| -> (Rendered, f64) {
        let t0 = Instant::now();
        let (rig_i, renderer_i) = rig_of(i);
        let r = renderer_i.render(
            &shots[i],
            rig_i,
            scene.seed.wrapping_mul(1000).wrapping_add(i as u64),
            true,
        );
        (r, t0.elapsed().as_secs_f64())
    };
    let mut pending: Option<(usize, Rendered)> = None;
    for i in 0..=shots.len() {
        let (done, next) = rayon::join(
            || pending.take().map(|(j, r)| finish(j, &shots[j], r)),
            || (i < shots.len()).then(|| render_one(i)),
        );
        if let Some(done) = done {
            let (truth, secs) = done?;
            image_truths.push(truth);
            write_s += secs;
        }
        if let Some((r, secs)) = next {
            rays += r.rays;
            render_s += secs;
            pending = Some((i, r));
        }
    }
    // The order the images were taken: the survey before the session.
    let order: Vec<usize> = (n_capture..shots.len()).chain(0..n_capture).collect();
    let image_truths: Vec<ImageTruth> = {
        let mut by_shot: Vec<Option<ImageTruth>> = image_truths.into_iter().map(Some).collect();
        order
            .iter()
            .filter_map(|&i| by_shot.get_mut(i).and_then(Option::take))
            .collect()
    };
    for shot in order.iter().map(|&i| &shots[i]) {
        entries.push(ImageEntry {
            file: shot.file.clone(),
            role: shot.role,
            exposure_index: shot.exposure_index,
            linearization: None,
            mask: None,
            world_from_camera: None,
            world_from_head: None,
            exposure_scale: None,
        });
    }

    let t2 = Instant::now();
    let capture_file = match capture {
        Some(rec) => {
            let mut rec = rec.clone();
            for e in &mut rec.exposures {
                if let Some(s) = shots.iter().find(|s| s.exposure_index == Some(e.index)) {
                    e.image = Some(s.file.clone());
                }
            }
            skinbrdf_session::write_json_atomic(&dir.join("capture.json"), &rec)?;
            Some("capture.json".to_string())
        }
        None => None,
    };
    let (lin, _) = linearization(&scene);
    let session = SessionFile {
        format_version: SESSION_FORMAT_VERSION,
        description: format!(
            "synthetic session, scene `{}`: {}",
            scene.name, scene.description
        ),
        capture: capture_file,
        camera: CameraSpec::Calibrated(rig.camera),
        linearization: lin,
        images: entries,
        targets: TargetLayouts {
            family: TAG_FAMILY.into(),
            reference: rig.reference.clone(),
            headdress: rig.headdress.clone(),
            unplaced: Vec::new(),
        },
        flash: FlashSpec {
            diameter_m: scene.session.flash_diameter_m,
            light_centre_m: DVec3::ZERO,
            targets: rig.flash_targets.clone(),
        },
        standard: Some(StandardSpec {
            brdf: scene.standard.brdf.clone(),
            size_m: [scene.standard.size_m; 2],
            targets: rig.standard_targets.clone(),
        }),
        geometry,
        roi: Some(RegionOfInterest {
            centre_m: rig.roi_centre_head,
            radius_m: scene.geometry.roi_radius_m,
        }),
        known: KnownQuantities::default(),
        registration: None,
    };
    if !studio_only {
        skinbrdf_session::Session::write_file(dir, &session)?;
    }
    let truth = Truth {
        format_version: TRUTH_FORMAT_VERSION,
        scene: scene.name.clone(),
        seed: scene.seed,
        camera: rig.camera,
        brdf: scene.skin.clone(),
        standard_brdf: scene.standard.brdf.clone(),
        calibration_c: scene.radiometry.calibration_c,
        light_position_m: rig.light_position_m(),
        world_from_flash: rig.world_from_flash,
        world_from_standard: rig.world_from_standard,
        surface: SurfaceTruth {
            shape: rig.shape.describe(),
            scan_noise_m: if scene.geometry.kind == GeometryKind::Head {
                scene.geometry.scan_noise_m
            } else {
                0.0
            },
            scan_spacing_m: scan_spacing,
            scan_vertices,
        },
        images: image_truths,
        render: RenderTruth {
            samples_per_pixel: renderer.samples_per_pixel(),
            sensor_noise: !opts.noise_free,
            read_noise: scene.sensor.read_noise,
            full_well_e: scene.sensor.full_well_e,
            render_seconds: render_s,
        },
        placements: [
            (skinbrdf_session::TargetGroup::Reference, &rig.reference),
            (skinbrdf_session::TargetGroup::Headdress, &rig.headdress),
            (skinbrdf_session::TargetGroup::Flash, &rig.flash_targets),
            (
                skinbrdf_session::TargetGroup::Standard,
                &rig.standard_targets,
            ),
        ]
        .into_iter()
        .flat_map(|(group, list)| {
            list.iter().map(move |t| skinbrdf_session::PlacementTruth {
                id: t.id,
                group,
                corners_m: t.corners_m,
            })
        })
        .collect(),
        head_point_m: None,
        sheets: crate::studio::sheet_truths(&rig),
    };
    truth.write(&dir.join(TRUTH_FILE))?;
    if let Some((_, card)) = &studio {
        // The studio's head frame is its textured scan's: its truth says so. A survey image
        // has no exposure to pair it with an ingested session's image by, so the studio's truth
        // names it by its raw file (`Truth::keyed_to` pairs it by file name).
        let head_from_scanner = crate::studio::scanner_from_head(&scene).inverse();
        let mut studio_truth = truth.clone().with_head_frame(&head_from_scanner);
        for t in &mut studio_truth.images {
            let raw = card
                .iter()
                .find(|c| c.exposure_index.is_none() && shots[c.shot].file == t.file);
            if let (ImageRole::Survey, Some(c)) = (t.role, raw) {
                t.file = c.file.clone();
            }
        }
        studio_truth.write(&dir.join(crate::studio::STUDIO_DIR).join(TRUTH_FILE))?;
    }
    write_s += t2.elapsed().as_secs_f64();
    Ok(SynthSummary {
        dir: dir.to_path_buf(),
        images: shots.len(),
        resolution: (rig.camera.width_px, rig.camera.height_px),
        rays,
        render_triangles: renderer.skin_triangles,
        scan_vertices,
        setup_s,
        render_s,
        write_s,
        total_s: t_start.elapsed().as_secs_f64(),
    })
}

/// The sample's shape in the head frame when the scene's geometry is an ideal one (a
/// calibration sphere or cylinder about the head frame's origin); `None` for a head.
pub fn analytic_geometry(scene: &Scene) -> Option<GeometrySpec> {
    let g = &scene.geometry;
    match g.kind {
        GeometryKind::Head => None,
        GeometryKind::Sphere => Some(GeometrySpec::Sphere {
            centre_m: DVec3::ZERO,
            radius_m: g.sphere_radius_m,
        }),
        GeometryKind::Cylinder => Some(GeometrySpec::Cylinder {
            centre_m: DVec3::ZERO,
            axis: DVec3::Z,
            radius_m: g.cylinder_radius_m,
            length_m: g.cylinder_length_m,
        }),
    }
}
