//! `skinbrdf bench`: error against run time.
//!
//! Sweeps the settings that trade accuracy for time on one synthetic session with ground truth,
//! **one setting at a time around the defaults** (every other setting at its default), and
//! records for each the error against the truth and the run time of the stage it affects:
//!
//! | stage | settings | error |
//! |---|---|---|
//! | derender | images used, pixel stride, region size, grazing limit, normals (vertex / planar-fit radius), BVH build quality | samples' median relative error vs the true BRDF |
//! | ray casting | BVH build quality (build + every measurement image's primary rays at stride 2, per-ray traversal) | the derender's error (traversal is exact: every quality returns the same hits, checked) |
//! | smoothing | loess span (bandwidth), smoother subsample | smoothed log-BRDF's median relative error vs the true BRDF at held-out samples |
//! | fit | number of lobes, LM iteration cap, number of starts, multi-start subsample | fitted model's median relative error vs the true BRDF at the samples |
//!
//! Photogrammetry runs once (its figures are reported alongside). Each row keeps its time and
//! error; rows not dominated by another row of the same stage (faster *and* more accurate)
//! form the Pareto front, marked in the table and drawn in `pareto.png`/`pareto.svg`.

use std::path::PathBuf;
use std::time::Instant;

use glam::{DVec2, Vec3};
use skinbrdf_brdf::{BrdfModel, ChannelModel, Geom, ModelSpec, ParamBound, StartHint};
use skinbrdf_core::stats::median;
use skinbrdf_core::BrdfSample;
use skinbrdf_derender::DerenderConfig;
use skinbrdf_fit::loess::Loess;
use skinbrdf_fit::plot::{write_figure, Figure, Panel, Series, SeriesKind};
use skinbrdf_fit::smooth::{smooth, SmoothConfig, SpanChoice, SPAN_CANDIDATES};
use skinbrdf_fit::{fit_rgb, FitConfig};
use skinbrdf_mesh::{BuildQuality, MeshBvh, MeshRay, NormalMethod};
use skinbrdf_poses::{PoseConfig, SessionPoses};
use skinbrdf_session::{ImageRole, Session, Truth};
use skinbrdf_synth::{generate, Scene, SynthOptions};

use crate::ledger::write_atomic;

/// Errors of the benchmark.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// Scene.
    #[error("scene")]
    Scene(#[from] skinbrdf_synth::SceneError),
    /// Synthesis.
    #[error("synthesis")]
    Synth(#[from] skinbrdf_synth::SynthError),
    /// The session did not load.
    #[error("{dir}: the session is not valid")]
    Session {
        /// Session directory.
        dir: PathBuf,
        /// Every problem.
        source: skinbrdf_session::SessionErrors,
    },
    /// The bench needs a `truth.json`.
    #[error("{0}: the bench needs a synthetic session with truth.json")]
    NoTruth(PathBuf),
    /// Photogrammetry.
    #[error("photogrammetry")]
    Poses(#[from] skinbrdf_poses::PoseError),
    /// Derendering.
    #[error("derendering")]
    Derender(#[from] skinbrdf_derender::DerenderError),
    /// Resolving the poses for derendering, or derendering, failed.
    #[error(transparent)]
    DerenderSession(#[from] crate::pose_inputs::DerenderSessionError),
    /// Ray casting.
    #[error("ray casting")]
    Mesh(#[from] skinbrdf_mesh::MeshError),
    /// Fitting.
    #[error("fitting")]
    Fit(#[from] skinbrdf_fit::FitError),
    /// Smoothing.
    #[error("smoothing")]
    Smooth(#[from] skinbrdf_fit::loess::LoessError),
    /// Figures.
    #[error(transparent)]
    Plot(#[from] skinbrdf_fit::plot::PlotError),
    /// Output.
    #[error(transparent)]
    Output(#[from] crate::ledger::LedgerError),
    #[error(transparent)]
    Stage(#[from] Box<crate::process::ProcessError>),
}

/// Settings of the bench.
#[derive(Debug, Clone)]
pub struct BenchConfig {
    /// Output directory (`session/`, `table.md`, `table.csv`, `pareto.*`).
    pub out_dir: PathBuf,
    /// Scene to generate when `session` is `None`.
    pub scene: String,
    /// Use this existing synthetic session instead of generating one.
    pub session: Option<PathBuf>,
    /// Image size override for the generated session.
    pub resolution: Option<(u32, u32)>,
    /// Fewer settings per sweep (for CI smoke runs).
    pub quick: bool,
}

/// The stage a bench row measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BenchStage {
    /// Pixels to samples.
    Derender,
    /// BVH build and primary-ray traversal.
    RayCasting,
    /// Local quadratic regression.
    Smoothing,
    /// The model fit.
    Fit,
}

impl std::fmt::Display for BenchStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            BenchStage::Derender => "derender",
            BenchStage::RayCasting => "ray casting",
            BenchStage::Smoothing => "smoothing",
            BenchStage::Fit => "fit",
        })
    }
}

/// One measured setting.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchRow {
    /// Stage affected.
    pub stage: BenchStage,
    /// Setting swept.
    pub setting: &'static str,
    /// Its value.
    pub value: String,
    /// Error figure's name.
    pub error_name: &'static str,
    /// Error, percent; `None` where the row has none: the setting made the stage fail, its
    /// hits differ from the reference build, or nothing was compared.
    pub error_pct: Option<f64>,
    /// Run time of the stage, seconds.
    pub time_s: f64,
    /// Samples produced (derender) or used (smoothing, fit).
    pub samples: usize,
    /// This row is the defaults (every setting at its default value).
    pub default: bool,
    /// Not dominated within its stage.
    pub pareto: bool,
}

/// What the bench produced.
#[derive(Debug, serde::Serialize)]
pub struct BenchOutput {
    /// All rows.
    pub rows: Vec<BenchRow>,
    /// Photogrammetry, run once: (time s, camera position error median mm; `None` when no
    /// camera was posed).
    pub poses: (f64, Option<f64>),
    /// The Markdown table.
    pub table_md: String,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// Median relative error (percent) of `model` against `truth` at the samples' angles.
pub fn model_error_pct(model: &BrdfModel, truth: &BrdfModel, samples: &[BrdfSample]) -> f64 {
    let step = (samples.len() / 20_000).max(1);
    let errs: Vec<f64> = samples
        .iter()
        .step_by(step)
        .flat_map(|s| {
            let a = [
                f64::from(s.theta_i_rad),
                f64::from(s.theta_e_rad),
                f64::from(s.phi_d_rad),
            ];
            let f = model.eval_angles(a[0], a[1], a[2]);
            let t = truth.eval_angles(a[0], a[1], a[2]);
            (0..3)
                .filter(move |&c| t[c] > 0.0)
                .map(move |c| ((f[c] - t[c]) / t[c]).abs())
        })
        .collect();
    median(&errs) * 100.0
}

/// An error figure that is a number, or `None` (a median of nothing is NaN).
fn measured(error_pct: f64) -> Option<f64> {
    Some(error_pct).filter(|e| e.is_finite())
}

fn mark_pareto(rows: &mut [BenchRow]) {
    let snapshot: Vec<(BenchStage, f64, f64)> = rows
        .iter()
        .filter_map(|r| Some((r.stage, r.time_s, r.error_pct?)))
        .collect();
    for r in rows.iter_mut() {
        r.pareto = r.error_pct.is_some_and(|error_pct| {
            !snapshot.iter().any(|(st, t, e)| {
                *st == r.stage
                    && *t <= r.time_s
                    && *e <= error_pct
                    && (*t < r.time_s || *e < error_pct)
            })
        });
    }
}

/// A channel model that keeps only `max` of another model's starting points, evenly spread
/// over its list (the number-of-starts axis of the sweep).
#[derive(Debug)]
pub struct LimitedStarts<'a> {
    /// The model.
    pub inner: &'a dyn ChannelModel,
    /// Starting points kept (at least 1).
    pub max: usize,
}

impl ChannelModel for LimitedStarts<'_> {
    fn name(&self) -> String {
        self.inner.name()
    }
    fn n_params(&self) -> usize {
        self.inner.n_params()
    }
    fn param_names(&self) -> Vec<String> {
        self.inner.param_names()
    }
    fn bounds(&self) -> Vec<ParamBound> {
        self.inner.bounds()
    }
    fn eval(&self, p: &[f64], g: &Geom) -> f64 {
        self.inner.eval(p, g)
    }
    fn eval_grad(&self, p: &[f64], g: &Geom, grad: &mut [f64]) -> f64 {
        self.inner.eval_grad(p, g, grad)
    }
    fn starting_points(&self, hint: &StartHint) -> Vec<Vec<f64>> {
        let all = self.inner.starting_points(hint);
        let k = self.max.clamp(1, all.len().max(1));
        (0..k)
            .filter_map(|i| all.get(i * all.len() / k).cloned())
            .collect()
    }
    fn to_model(&self, params: &[Vec<f64>; 3]) -> Result<BrdfModel, skinbrdf_brdf::BrdfError> {
        self.inner.to_model(params)
    }
    fn params_from_model(&self, model: &BrdfModel, channel: usize) -> Option<Vec<f64>> {
        self.inner.params_from_model(model, channel)
    }
}

/// Keeps `k` of the measurement images that have estimated poses (evenly spread along the
/// session, so the arc stays covered) and drops the others from both the session and the poses.
fn keep_images(session: &Session, poses: &SessionPoses, k: usize) -> (Session, SessionPoses) {
    let usable: Vec<usize> = session
        .file
        .images
        .iter()
        .enumerate()
        .filter(|(i, e)| {
            e.role == ImageRole::Measurement
                && poses
                    .images
                    .get(*i)
                    .is_some_and(|p| p.world_from_camera.is_some() && p.world_from_head.is_some())
        })
        .map(|(i, _)| i)
        .collect();
    let k = k.clamp(1, usable.len().max(1));
    let chosen: Vec<usize> = (0..k)
        .filter_map(|j| usable.get(j * usable.len() / k).copied())
        .collect();
    let keep =
        |i: usize| session.file.images[i].role != ImageRole::Measurement || chosen.contains(&i);
    let mut s = session.clone();
    let mut p = poses.clone();
    s.file.images = (0..session.file.images.len())
        .filter(|&i| keep(i))
        .map(|i| session.file.images[i].clone())
        .collect();
    p.images = (0..poses.images.len())
        .filter(|&i| keep(i))
        .map(|i| poses.images[i].clone())
        .collect();
    (s, p)
}

/// Primary rays (head frame) of every `stride`-th pixel of every measurement image with
/// estimated poses: the ray-casting workload of the BVH sweep.
fn primary_rays(session: &Session, poses: &SessionPoses, stride: u32) -> Vec<MeshRay> {
    let cam = &poses.camera;
    let mut rays = Vec::new();
    for (i, e) in session.file.images.iter().enumerate() {
        if e.role != ImageRole::Measurement {
            continue;
        }
        let Some(p) = poses.images.get(i) else {
            continue;
        };
        let (Some(c), Some(h)) = (&p.world_from_camera, &p.world_from_head) else {
            continue;
        };
        let head_from_cam = h.pose.inverse() * c.pose;
        let o = head_from_cam.transform_point(glam::DVec3::ZERO).as_vec3();
        for y in (0..cam.height_px).step_by(stride as usize) {
            for x in (0..cam.width_px).step_by(stride as usize) {
                if let Some(d) = cam.pixel_ray(DVec2::new(f64::from(x), f64::from(y))) {
                    let d: Vec3 = head_from_cam.transform_vector(d).normalize().as_vec3();
                    rays.push(MeshRay::new(o, d));
                }
            }
        }
    }
    rays
}

/// Median relative error (percent) of a log-domain smoother of the channel mean against the
/// true BRDF's channel mean, at `held_out` samples.
fn smoother_error_pct(l: &Loess, floor: f64, truth: &BrdfModel, held_out: &[BrdfSample]) -> f64 {
    let errs: Vec<f64> = held_out
        .iter()
        .filter_map(|s| {
            let a = [
                f64::from(s.theta_i_rad),
                f64::from(s.theta_e_rad),
                f64::from(s.phi_d_rad),
            ];
            let t = truth.eval_angles(a[0], a[1], a[2]);
            let t = (t[0] + t[1] + t[2]) / 3.0;
            let v = l.predict(&a)?.value.exp() - floor;
            (t > 0.0 && v.is_finite()).then(|| ((v - t) / t).abs())
        })
        .collect();
    median(&errs) * 100.0
}

fn write_outputs(
    cfg: &BenchConfig,
    dir: &std::path::Path,
    images: usize,
    poses: (f64, Option<f64>),
    rows: &[BenchRow],
) -> Result<(String, Vec<PathBuf>), BenchError> {
    let mut files = Vec::new();
    let mut md = format!(
        "Session: `{}` ({} images). Photogrammetry (run once): {:.2} s, camera position error median {} mm. \
         Each row changes one setting from the defaults (the row marked `default` has them all).\n\n\
         | stage | setting | value | error (%) | time (s) | samples | Pareto |\n|---|---|---|---:|---:|---:|:-:|\n",
        dir.display(),
        images,
        poses.0,
        poses.1.map_or_else(|| "-".to_string(), |e| format!("{e:.3}"))
    );
    let mut csv =
        String::from("stage,setting,value,error_name,error_pct,time_s,samples,default,pareto\n");
    let mut last_stage = None;
    for r in rows {
        if Some(r.stage) != last_stage {
            md.push_str(&format!(
                "| **{}** | | | *{}* | | | |\n",
                r.stage, r.error_name
            ));
            last_stage = Some(r.stage);
        }
        md.push_str(&format!(
            "| {} | {} | {}{} | {} | {:.3} | {} | {} |\n",
            r.stage,
            r.setting,
            r.value,
            if r.default { " (default)" } else { "" },
            r.error_pct
                .map_or_else(|| "-".to_string(), |e| format!("{e:.3}")),
            r.time_s,
            r.samples,
            if r.pareto { "★" } else { "" }
        ));
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            r.stage,
            r.setting,
            r.value.replace(',', ";"),
            r.error_name,
            r.error_pct.map_or_else(String::new, |e| e.to_string()),
            r.time_s,
            r.samples,
            r.default,
            r.pareto
        ));
    }
    let p = cfg.out_dir.join("table.md");
    write_atomic(&p, md.as_bytes())?;
    files.push(p);
    let p = cfg.out_dir.join("table.csv");
    write_atomic(&p, csv.as_bytes())?;
    files.push(p);
    let panel = |stage: BenchStage| -> Panel {
        let mut settings: Vec<&'static str> = Vec::new();
        for r in rows.iter().filter(|r| r.stage == stage) {
            if !settings.contains(&r.setting) {
                settings.push(r.setting);
            }
        }
        let mut series: Vec<Series> = settings
            .iter()
            .enumerate()
            .map(|(k, setting)| Series {
                label: (*setting).to_string(),
                color: k as i32,
                kind: SeriesKind::Points(
                    rows.iter()
                        .filter(|r| r.stage == stage && r.setting == *setting)
                        .filter_map(|r| Some((r.time_s, r.error_pct?)))
                        .collect(),
                ),
            })
            .collect();
        let mut front: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.stage == stage && r.pareto)
            .filter_map(|r| Some((r.time_s, r.error_pct?)))
            .collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        series.push(Series {
            label: "Pareto front".into(),
            color: -1,
            kind: SeriesKind::Line(front),
        });
        Panel {
            title: format!("{stage}: error against run time"),
            x_label: "run time (s)".into(),
            y_label: "median relative error (%)".into(),
            x_range: None,
            y_range: None,
            axes: true,
            series,
        }
    };
    let mut stages: Vec<BenchStage> = Vec::new();
    for r in rows {
        if !stages.contains(&r.stage) {
            stages.push(r.stage);
        }
    }
    let fig = Figure {
        panels: stages.iter().map(|&s| panel(s)).collect(),
        panel_px: (640, 480),
    };
    files.extend(write_figure(&cfg.out_dir.join("pareto"), &fig)?);
    Ok((md, files))
}

/// Runs the sweep.
pub fn run_bench(cfg: &BenchConfig, log: &mut dyn FnMut(&str)) -> Result<BenchOutput, BenchError> {
    std::fs::create_dir_all(&cfg.out_dir).map_err(|source| crate::ledger::LedgerError::Io {
        path: cfg.out_dir.clone(),
        source,
    })?;
    let dir = match &cfg.session {
        Some(d) => d.clone(),
        None => {
            let d = cfg.out_dir.join("session");
            log("generating the synthetic session");
            let scene = Scene::load(&cfg.scene)?;
            generate(
                &scene,
                &SynthOptions {
                    resolution: cfg.resolution,
                    capture: None,
                    noise_free: false,
                    samples_per_pixel: None,
                    studio: false,
                    studio_only: false,
                },
                &d,
            )?;
            d
        }
    };
    let session = Session::load(&dir).map_err(|source| BenchError::Session {
        dir: dir.clone(),
        source,
    })?;
    let truth = match session.load_truth() {
        Some(Ok(t)) => t,
        _ => return Err(BenchError::NoTruth(dir.clone())),
    };

    log("photogrammetry (once)");
    let t = Instant::now();
    let poses: SessionPoses = skinbrdf_poses::estimate_session(&session, &PoseConfig::DEFAULT)?;
    let poses_s = t.elapsed().as_secs_f64();
    let cam_err_mm = measured(
        median(&skinbrdf_poses::session::compare_truth(&poses, &truth).camera_position_error_m)
            * 1e3,
    );

    let mut rows = Vec::new();
    let base_samples = sweep_derender(cfg, &session, &poses, &mut rows, log)?;
    sweep_smoothing(cfg, &base_samples, &truth, &mut rows, log)?;
    sweep_fit(cfg, &base_samples, &truth, &mut rows, log)?;
    mark_pareto(&mut rows);
    let (table_md, files) = write_outputs(
        cfg,
        &dir,
        session.file.images.len(),
        (poses_s, cam_err_mm),
        &rows,
    )?;
    Ok(BenchOutput {
        rows,
        poses: (poses_s, cam_err_mm),
        table_md,
        files,
    })
}

/// Derender and ray-casting rows; returns the default configuration's samples.
fn sweep_derender(
    cfg: &BenchConfig,
    session: &Session,
    poses: &SessionPoses,
    rows: &mut Vec<BenchRow>,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<BrdfSample>, BenchError> {
    // Measurement images without estimated poses are left out of every row (the pose stage
    // reports them), so each row derenders the same usable images.
    let usable = poses
        .images
        .iter()
        .zip(&session.file.images)
        .filter(|(p, e)| {
            e.role == ImageRole::Measurement
                && p.world_from_camera.is_some()
                && p.world_from_head.is_some()
        })
        .count();
    let (session, poses) = &keep_images(session, poses, usable);
    let base = DerenderConfig::DEFAULT;
    let mut derender = |setting: &'static str,
                        value: String,
                        s: &Session,
                        p: &SessionPoses,
                        c: DerenderConfig,
                        default: bool|
     -> Result<Vec<BrdfSample>, BenchError> {
        log(&format!("derender {setting} = {value}"));
        // The pipeline's own derender stage, with this row's settings.
        let (run, samples) =
            crate::stages::derender_stage(s, Some(p), &c, &crate::plan::PlanOptions::default())
                .map_err(Box::new)?;
        let err = run
            .report
            .truth_error
            .as_ref()
            .map(|e| e.median_rel_error * 100.0);
        rows.push(BenchRow {
            stage: BenchStage::Derender,
            setting,
            value,
            error_name: "sample median rel. error vs true BRDF",
            error_pct: err,
            time_s: run.report.times.total_s,
            samples: samples.len(),
            default,
            pareto: false,
        });
        Ok(samples)
    };
    let base_samples = derender("defaults", "-".into(), session, poses, base, true)?;

    // Images used.
    let counts: &[usize] = if cfg.quick { &[5] } else { &[3, 6, 12, 20] };
    for &k in counts.iter().filter(|&&k| k < usable) {
        let (s, p) = keep_images(session, poses, k);
        derender(
            "images used",
            format!("{k} of {usable}"),
            &s,
            &p,
            base,
            false,
        )?;
    }

    // Pixel stride.
    let strides: &[u32] = if cfg.quick { &[4] } else { &[2, 3, 4, 8] };
    for &st in strides {
        derender(
            "pixel stride",
            st.to_string(),
            session,
            poses,
            DerenderConfig { stride: st, ..base },
            false,
        )?;
    }

    // Region size.
    if let Some(roi) = session.file.roi {
        let radii_mm: &[f64] = if cfg.quick {
            &[15.0]
        } else {
            &[10.0, 15.0, 20.0, 25.0, 40.0]
        };
        for &r in radii_mm {
            let mut s = session.clone();
            s.file.roi = Some(skinbrdf_session::format::RegionOfInterest {
                centre_m: roi.centre_m,
                radius_m: r * 1e-3,
            });
            derender(
                "region radius (mm)",
                format!("{r} (default {:.0})", roi.radius_m * 1e3),
                &s,
                poses,
                base,
                false,
            )?;
        }
    }

    // Grazing limit.
    let grazing: &[f64] = if cfg.quick {
        &[60.0]
    } else {
        &[45.0, 60.0, 85.0]
    };
    for &g in grazing {
        derender(
            "grazing limit (deg)",
            format!("{g}"),
            session,
            poses,
            DerenderConfig {
                grazing_limit_deg: g,
                ..base
            },
            false,
        )?;
    }

    // Normals.
    let normals: Vec<(String, NormalMethod)> = if cfg.quick {
        vec![("vertex".into(), NormalMethod::Vertex)]
    } else {
        let mut v = vec![("vertex".into(), NormalMethod::Vertex)];
        for r_mm in [2.0, 5.0, 10.0, 20.0] {
            v.push((
                format!("planar fit {r_mm} mm"),
                NormalMethod::PlanarFit {
                    radius_m: r_mm * 1e-3,
                },
            ));
        }
        v
    };
    for (label, n) in normals {
        derender(
            "normals",
            label,
            session,
            poses,
            DerenderConfig { normals: n, ..base },
            false,
        )?;
    }
    // BVH build quality inside the derender (build + all rays of every image).
    let qualities: &[BuildQuality] = if cfg.quick {
        &[BuildQuality::Fastest]
    } else {
        &BuildQuality::ALL
    };
    for &q in qualities.iter().filter(|&&q| q != base.bvh_quality) {
        derender(
            "BVH build quality",
            q.name().to_string(),
            session,
            poses,
            DerenderConfig {
                bvh_quality: q,
                ..base
            },
            false,
        )?;
    }
    let base_err = rows
        .iter()
        .find(|r| r.default && r.stage == BenchStage::Derender)
        .and_then(|r| r.error_pct);

    // BVH build quality: build over the session's geometry, then cast the primary rays of
    // every measurement image (stride 2). Traversal is exact, so every quality must return the
    // same hits; the error is the default derender's, and a mismatch is reported in the row.
    log("ray casting: BVH build quality");
    let (geom, _, _) = skinbrdf_derender::from_session::session_geometry(session, &base)?;
    let rays = primary_rays(session, poses, 2);
    let qualities: &[BuildQuality] = if cfg.quick {
        &[BuildQuality::Fastest, BuildQuality::Medium]
    } else {
        &BuildQuality::ALL
    };
    let mut reference: Option<Vec<Option<u32>>> = None;
    for &q in qualities {
        let t = Instant::now();
        let bvh = MeshBvh::build(&geom.mesh, q)?;
        let build_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let hits: Vec<Option<u32>> = bvh
            .intersect_batch(&rays)
            .into_iter()
            .map(|h| h.map(|h| h.triangle))
            .collect();
        let trace_s = t.elapsed().as_secs_f64();
        let mismatches = reference
            .as_ref()
            .map_or(0, |r| r.iter().zip(&hits).filter(|(a, b)| a != b).count());
        if reference.is_none() {
            reference = Some(hits);
        }
        rows.push(BenchRow {
            stage: BenchStage::RayCasting,
            setting: "BVH build quality",
            value: format!(
                "{}: build {:.1} ms + {:.2} M rays {:.1} ms ({:.1} Mrays/s){}",
                q.name(),
                build_s * 1e3,
                rays.len() as f64 * 1e-6,
                trace_s * 1e3,
                rays.len() as f64 * 1e-6 / trace_s.max(1e-9),
                if mismatches > 0 {
                    format!(", {mismatches} hits differ from the cheapest build")
                } else {
                    String::new()
                }
            ),
            error_name: "derender sample error (identical hits)",
            error_pct: if mismatches == 0 { base_err } else { None },
            time_s: build_s + trace_s,
            samples: rays.len(),
            default: q == BuildQuality::Medium,
            pareto: false,
        });
    }
    Ok(base_samples)
}

/// Smoothing rows: loess span and subsample, scored on held-out samples.
fn sweep_smoothing(
    cfg: &BenchConfig,
    samples: &[BrdfSample],
    truth: &Truth,
    rows: &mut Vec<BenchRow>,
    log: &mut dyn FnMut(&str),
) -> Result<(), BenchError> {
    // Held out: 2 000 samples offset half a stride from the smoother's own subsets.
    let step = (samples.len() / 2_000).max(1);
    let held_out: Vec<BrdfSample> = samples
        .iter()
        .skip(step / 2 + 1)
        .step_by(step)
        .copied()
        .collect();
    let default_n = skinbrdf_fit::report::SMOOTH_MAX_SAMPLES;
    let mut run = |setting: &'static str,
                   value: String,
                   n: usize,
                   span: Option<f64>,
                   default: bool|
     -> Result<(), BenchError> {
        log(&format!("smoothing {setting} = {value}"));
        let sm = smooth(
            samples,
            &SmoothConfig {
                max_samples: n,
                span: span.map_or(SpanChoice::Gcv(SPAN_CANDIDATES.to_vec()), SpanChoice::Fixed),
                ..SmoothConfig::default()
            },
        )?;
        let span = sm.metrics.span;
        rows.push(BenchRow {
            stage: BenchStage::Smoothing,
            setting,
            value: if default {
                format!("{value} (chose {span})")
            } else {
                value
            },
            error_name: "smoothed BRDF median rel. error at held-out samples",
            error_pct: measured(smoother_error_pct(
                &sm.loess,
                sm.metrics.floor_rho,
                &truth.brdf,
                &held_out,
            )),
            time_s: sm.metrics.run_time_s,
            samples: sm.metrics.samples_used,
            default,
            pareto: false,
        });
        Ok(())
    };
    run("loess span", "GCV".into(), default_n, None, true)?;
    let spans: &[f64] = if cfg.quick {
        &[0.05]
    } else {
        &[0.01, 0.02, 0.05, 0.1, 0.2, 0.4]
    };
    for &s in spans {
        run("loess span", format!("{s}"), default_n, Some(s), false)?;
    }
    let subs: &[usize] = if cfg.quick {
        &[5_000]
    } else {
        &[2_000, 5_000, 10_000, 50_000]
    };
    for &n in subs.iter().filter(|&&n| n < samples.len()) {
        run("smoother subsample", n.to_string(), n, None, false)?;
    }
    Ok(())
}

/// Fit rows on the default derender's samples.
fn sweep_fit(
    cfg: &BenchConfig,
    samples: &[BrdfSample],
    truth: &Truth,
    rows: &mut Vec<BenchRow>,
    log: &mut dyn FnMut(&str),
) -> Result<(), BenchError> {
    let mut fit = |setting: &'static str,
                   value: String,
                   model: &dyn ChannelModel,
                   c: FitConfig,
                   default: bool|
     -> Result<(), BenchError> {
        log(&format!("fit {setting} = {value}"));
        let t = Instant::now();
        // A setting that makes the fit fail loudly (e.g. too few iterations) is a row with
        // its failure, not the end of the sweep.
        let (error_pct, value) = match fit_rgb(model, samples, &c) {
            Ok(f) => (
                measured(model_error_pct(&f.model, &truth.brdf, samples)),
                value,
            ),
            Err(e) => (
                None,
                format!("{value} (failed: {})", skinbrdf_core::error_text(&e)),
            ),
        };
        let time_s = t.elapsed().as_secs_f64();
        rows.push(BenchRow {
            stage: BenchStage::Fit,
            setting,
            value,
            error_name: "model median rel. error vs true BRDF",
            error_pct,
            time_s,
            samples: samples.len(),
            default,
            pareto: false,
        });
        Ok(())
    };
    let two = ModelSpec::Lafortune { lobes: 2 }.channel_model();
    fit(
        "defaults (Lafortune, 2 lobes)",
        "-".into(),
        two.as_ref(),
        FitConfig::default(),
        true,
    )?;
    let lobes: &[usize] = if cfg.quick { &[1] } else { &[1, 3] };
    for &l in lobes {
        let m = ModelSpec::Lafortune { lobes: l }.channel_model();
        fit(
            "Lafortune lobes",
            l.to_string(),
            m.as_ref(),
            FitConfig::default(),
            false,
        )?;
    }
    let iters: &[usize] = if cfg.quick { &[5] } else { &[3, 5, 10, 30] };
    for &it in iters {
        let mut c = FitConfig::default();
        c.lm.max_iterations = it;
        fit("LM iteration cap", it.to_string(), two.as_ref(), c, false)?;
    }
    let n_starts = two
        .starting_points(&StartHint {
            diffuse_rho: 0.1,
            peak_rho: 1.0,
        })
        .len();
    let starts: &[usize] = if cfg.quick { &[1] } else { &[1, 2, 4] };
    for &k in starts.iter().filter(|&&k| k < n_starts) {
        let m = LimitedStarts {
            inner: two.as_ref(),
            max: k,
        };
        fit(
            "starts",
            format!("{k} of {n_starts}"),
            &m,
            FitConfig::default(),
            false,
        )?;
    }
    let subs: &[usize] = if cfg.quick {
        &[2_000]
    } else {
        &[2_000, 5_000, 100_000]
    };
    for &n in subs {
        let c = FitConfig {
            subsample: n,
            ..FitConfig::default()
        };
        fit(
            "multi-start subsample",
            n.to_string(),
            two.as_ref(),
            c,
            false,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(stage: BenchStage, t: f64, e: f64) -> BenchRow {
        BenchRow {
            stage,
            setting: "s",
            value: String::new(),
            error_name: "e",
            error_pct: measured(e),
            time_s: t,
            samples: 0,
            default: false,
            pareto: false,
        }
    }

    #[test]
    fn pareto_front_keeps_only_undominated_rows_per_stage() {
        let mut rows = vec![
            row(BenchStage::Derender, 1.0, 5.0),
            row(BenchStage::Derender, 2.0, 3.0),
            row(BenchStage::Derender, 3.0, 4.0),
            row(BenchStage::Fit, 10.0, 10.0),
            row(BenchStage::Derender, 0.5, f64::NAN),
        ];
        mark_pareto(&mut rows);
        let front: Vec<bool> = rows.iter().map(|r| r.pareto).collect();
        assert_eq!(front, [true, true, false, true, false]);
    }

    #[test]
    fn limited_starts_keep_a_spread_subset() {
        let m = ModelSpec::Lafortune { lobes: 2 }.channel_model();
        let hint = StartHint {
            diffuse_rho: 0.1,
            peak_rho: 1.0,
        };
        let all = m.starting_points(&hint);
        assert!(all.len() >= 4);
        for k in 1..=all.len() {
            let l = LimitedStarts {
                inner: m.as_ref(),
                max: k,
            };
            let got = l.starting_points(&hint);
            assert_eq!(got.len(), k);
            assert!(got.iter().all(|s| all.contains(s)));
            assert_eq!(got[0], all[0]);
        }
        let l = LimitedStarts {
            inner: m.as_ref(),
            max: 0,
        };
        assert_eq!(l.starting_points(&hint).len(), 1);
    }

    #[test]
    fn model_error_is_zero_for_the_truth_and_positive_otherwise() {
        let truth = BrdfModel::Lambertian { albedo: [0.5; 3] };
        let other = BrdfModel::Lambertian { albedo: [0.55; 3] };
        let s: Vec<BrdfSample> = (0..100)
            .map(|i| {
                let a = skinbrdf_core::BrdfAngles::from_local(
                    skinbrdf_core::BrdfAngles::canonical_directions(0.01 * i as f64, 0.3, 1.0).0,
                    skinbrdf_core::BrdfAngles::canonical_directions(0.01 * i as f64, 0.3, 1.0).1,
                );
                BrdfSample::from_angles(&a, [0.1; 3])
            })
            .collect();
        assert!(model_error_pct(&truth, &truth, &s) < 1e-9);
        assert!((model_error_pct(&other, &truth, &s) - 10.0).abs() < 1e-6);
    }
}
