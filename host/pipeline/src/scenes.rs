//! `skinbrdf poses --scenes`: the per-scene pose benchmark. Renders each built-in scene (or the
//! named ones) into a work directory, runs the pipeline's pose stage on it and scores it against
//! the truth: one row per scene of the errors (medians over the images) and the cost.

use std::path::PathBuf;

use skinbrdf_core::stats::median;
use skinbrdf_poses::session::compare_truth;
use skinbrdf_poses::PoseConfig;
use skinbrdf_session::{ImageRole, Session};
use skinbrdf_synth::{generate, Scene, SynthOptions, BUILTIN_SCENES};

/// Errors of the scene benchmark, each naming its scene.
#[derive(Debug, thiserror::Error)]
pub enum ScenesError {
    /// The scene did not load.
    #[error("scene {scene}")]
    Scene {
        /// The scene.
        scene: String,
        /// Why.
        source: skinbrdf_synth::SceneError,
    },
    /// Rendering failed.
    #[error("rendering scene {scene} into {dir}")]
    Synth {
        /// The scene.
        scene: String,
        /// Its directory.
        dir: PathBuf,
        /// Why.
        source: Box<skinbrdf_synth::SynthError>,
    },
    /// The rendered session did not load.
    #[error("{dir}: the session is not valid")]
    Session {
        /// Its directory.
        dir: PathBuf,
        /// Every problem.
        source: skinbrdf_session::SessionErrors,
    },
    /// The truth did not load or is missing.
    #[error("{dir}: no readable truth.json")]
    Truth {
        /// The session directory.
        dir: PathBuf,
    },
    /// The pose stage failed.
    #[error("estimating the poses of {scene}")]
    Poses {
        /// The scene.
        scene: String,
        /// Why.
        source: skinbrdf_poses::PoseError,
    },
    /// The work directory could not be removed.
    #[error("removing {dir}")]
    Remove {
        /// The directory.
        dir: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Settings of the scene benchmark.
#[derive(Debug, Clone)]
pub struct ScenesConfig {
    /// Scene names; empty for every built-in scene.
    pub scenes: Vec<String>,
    /// Work directory (one subdirectory per scene).
    pub work: PathBuf,
    /// Reuse a scene's session already rendered there.
    pub reuse: bool,
    /// Keep the rendered sessions.
    pub keep: bool,
}

/// One scene's pose figures. An error statistic is `None` when no image had the pose it
/// compares (a statistic of nothing).
#[derive(Debug, Clone, serde::Serialize)]
pub struct SceneRow {
    pub scene: String,
    pub measurement_images: usize,
    pub images_with_camera_pose: usize,
    pub measurement_images_with_head_pose: usize,
    pub camera_position_error_median_mm: Option<f64>,
    pub camera_orientation_error_median_deg: Option<f64>,
    pub head_position_error_median_mm: Option<f64>,
    pub head_position_error_max_mm: Option<f64>,
    pub head_position_error_median_before_bundle_mm: Option<f64>,
    pub bundle_cost_before: Option<f64>,
    pub bundle_cost_after: Option<f64>,
    pub bundle_ms: Option<f64>,
    pub head_orientation_error_median_deg: Option<f64>,
    pub flash_position_error_mm: Option<f64>,
    pub standard_position_error_mm: Option<f64>,
    pub detect_plus_pose_per_image_median_ms: Option<f64>,
    pub poses_total_s: f64,
}

/// Runs the benchmark; `log` hears of each scene as it finishes.
pub fn pose_scenes(
    cfg: &ScenesConfig,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<SceneRow>, ScenesError> {
    let names: Vec<String> = if cfg.scenes.is_empty() {
        BUILTIN_SCENES.iter().map(|(n, _)| n.to_string()).collect()
    } else {
        cfg.scenes.clone()
    };
    let mut rows = Vec::new();
    for name in &names {
        let dir = cfg.work.join(name);
        if !(cfg.reuse && dir.join("session.toml").is_file()) {
            let scene = Scene::load(name).map_err(|source| ScenesError::Scene {
                scene: name.clone(),
                source,
            })?;
            generate(&scene, &SynthOptions::default(), &dir).map_err(|source| {
                ScenesError::Synth {
                    scene: name.clone(),
                    dir: dir.clone(),
                    source: Box::new(source),
                }
            })?;
        }
        let session = Session::load(&dir).map_err(|source| ScenesError::Session {
            dir: dir.clone(),
            source,
        })?;
        let truth = session
            .load_truth()
            .and_then(Result::ok)
            .ok_or_else(|| ScenesError::Truth { dir: dir.clone() })?;
        let (before, est) =
            skinbrdf_poses::session::estimate_session_stages(&session, &PoseConfig::default())
                .map_err(|source| ScenesError::Poses {
                    scene: name.clone(),
                    source,
                })?;
        let e = compare_truth(&est, &truth);
        let e0 = compare_truth(&before, &truth);
        let meas: Vec<usize> = est
            .images
            .iter()
            .enumerate()
            .filter(|(_, im)| im.role == ImageRole::Measurement)
            .map(|(i, _)| i)
            .collect();
        let head_mm: Vec<f64> = meas
            .iter()
            .map(|&i| e.head_position_error_m[i] * 1e3)
            .collect();
        let per_image: Vec<f64> = est
            .images
            .iter()
            .map(|im| im.detect_ms + im.pose_ms)
            .collect();
        // The median of no finite values is NaN: no figure.
        let stat = |v: f64| Some(v).filter(|v| v.is_finite());
        let row = SceneRow {
            scene: name.clone(),
            measurement_images: meas.len(),
            images_with_camera_pose: est
                .images
                .iter()
                .filter(|im| im.world_from_camera.is_some())
                .count(),
            measurement_images_with_head_pose: meas
                .iter()
                .filter(|&&i| est.images[i].world_from_head.is_some())
                .count(),
            camera_position_error_median_mm: stat(median(&e.camera_position_error_m) * 1e3),
            camera_orientation_error_median_deg: stat(median(&e.camera_orientation_error_deg)),
            head_position_error_median_mm: stat(median(&head_mm)),
            head_position_error_max_mm: head_mm
                .iter()
                .copied()
                .filter(|v| v.is_finite())
                .reduce(f64::max),
            head_position_error_median_before_bundle_mm: stat(median(
                &meas
                    .iter()
                    .map(|&i| e0.head_position_error_m[i] * 1e3)
                    .collect::<Vec<_>>(),
            )),
            bundle_cost_before: est.bundle.as_ref().map(|b| b.initial_cost),
            bundle_cost_after: est.bundle.as_ref().map(|b| b.final_cost),
            bundle_ms: est.bundle.as_ref().map(|b| b.time_ms),
            head_orientation_error_median_deg: stat(median(&e.head_orientation_error_deg)),
            flash_position_error_mm: e.light_position_error_m.map(|v| v * 1e3),
            standard_position_error_mm: e.standard_position_error_m.map(|v| v * 1e3),
            detect_plus_pose_per_image_median_ms: stat(median(&per_image)),
            poses_total_s: est.total_ms * 1e-3,
        };
        log(name);
        rows.push(row);
        if !cfg.keep {
            std::fs::remove_dir_all(&dir).map_err(|source| ScenesError::Remove {
                dir: dir.clone(),
                source,
            })?;
        }
    }
    Ok(rows)
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[SceneRow]) -> String {
    let mut md = String::from("| scene | camera pos. (mm) | camera orient. (deg) | head pos. median / max (mm) | head pos. before BA (mm) | head posed | head orient. (deg) | flash (mm) | standard (mm) | BA cost before -> after | BA (ms) | detect+pose per image (ms) | poses total (s) |\n");
    md.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    let digits =
        |v: Option<f64>, d: usize| v.map_or_else(|| "-".to_string(), |x| format!("{x:.d$}"));
    let opt = |v: Option<f64>| digits(v, 3);
    for r in rows {
        md.push_str(&format!(
            "| {} | {} | {} | {} / {} | {} | {}/{} | {} | {} | {} | {} | {} | {} | {:.1} |\n",
            r.scene,
            opt(r.camera_position_error_median_mm),
            digits(r.camera_orientation_error_median_deg, 4),
            opt(r.head_position_error_median_mm),
            opt(r.head_position_error_max_mm),
            opt(r.head_position_error_median_before_bundle_mm),
            r.measurement_images_with_head_pose,
            r.measurement_images,
            digits(r.head_orientation_error_median_deg, 4),
            opt(r.flash_position_error_mm),
            opt(r.standard_position_error_mm),
            match (r.bundle_cost_before, r.bundle_cost_after) {
                (Some(a), Some(b)) => format!("{a:.0} -> {b:.0}"),
                _ => "-".into(),
            },
            r.bundle_ms
                .map_or_else(|| "-".into(), |v| format!("{v:.0}")),
            digits(r.detect_plus_pose_per_image_median_ms, 0),
            r.poses_total_s
        ));
    }
    md
}
