//! `skinbrdf bench`: error against run time.
//!
//! Sweeps the settings that trade accuracy for time on one synthetic session with ground truth,
//! one setting at a time around the defaults, and records for each the error against the truth
//! and the run time of the stage it affects:
//!
//! | stage | setting | error |
//! |---|---|---|
//! | derender | pixel stride, grazing limit, normals (vertex / planar fit radius) | samples' median relative error vs the true BRDF |
//! | fit | number of lobes, LM iteration cap, multi-start subsample | fitted model's median relative error vs the true BRDF at the samples |
//!
//! Photogrammetry runs once (its figures are reported alongside). Each row keeps its time and
//! error; rows not dominated by another row of the same stage (faster *and* more accurate)
//! form the Pareto front, marked in the table and drawn in `pareto.png`/`pareto.svg`.

use std::path::PathBuf;
use std::time::Instant;

use skinbrdf_brdf::{BrdfModel, ModelSpec};
use skinbrdf_core::BrdfSample;
use skinbrdf_derender::{DerenderConfig, PoseChoice, SessionOptions};
use skinbrdf_fit::plot::{write_figure, Figure, Panel, Series, SeriesKind};
use skinbrdf_fit::{fit_rgb, FitConfig};
use skinbrdf_mesh::NormalMethod;
use skinbrdf_poses::{PoseConfig, SessionPoses};
use skinbrdf_session::Session;
use skinbrdf_synth::{generate, Scene, SynthOptions};

use crate::ledger::write_atomic;

/// Errors of the benchmark.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// Scene.
    #[error("scene: {0}")]
    Scene(#[from] skinbrdf_synth::SceneError),
    /// Synthesis.
    #[error("synthesis: {0}")]
    Synth(#[from] skinbrdf_synth::SynthError),
    /// The session did not load.
    #[error("session: {0}")]
    Session(String),
    /// The bench needs a `truth.json`.
    #[error("{0}: the bench needs a synthetic session with truth.json")]
    NoTruth(PathBuf),
    /// Photogrammetry.
    #[error("photogrammetry: {0}")]
    Poses(#[from] skinbrdf_poses::PoseError),
    /// Derendering.
    #[error("derendering: {0}")]
    Derender(#[from] skinbrdf_derender::DerenderError),
    /// Fitting.
    #[error("fitting: {0}")]
    Fit(#[from] skinbrdf_fit::FitError),
    /// Figures.
    #[error(transparent)]
    Plot(#[from] skinbrdf_fit::plot::PlotError),
    /// Output.
    #[error(transparent)]
    Output(#[from] crate::ledger::LedgerError),
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

/// One measured setting.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchRow {
    /// Stage affected.
    pub stage: &'static str,
    /// Setting swept.
    pub setting: &'static str,
    /// Its value.
    pub value: String,
    /// Error figure's name.
    pub error_name: &'static str,
    /// Error, percent.
    pub error_pct: f64,
    /// Run time of the stage, seconds.
    pub time_s: f64,
    /// Not dominated within its stage.
    pub pareto: bool,
}

/// What the bench produced.
#[derive(Debug)]
pub struct BenchOutput {
    /// All rows.
    pub rows: Vec<BenchRow>,
    /// Photogrammetry, run once: (time s, camera position error median mm).
    pub poses: (f64, f64),
    /// The Markdown table.
    pub table_md: String,
    /// Files written.
    pub files: Vec<PathBuf>,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
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
    median(errs) * 100.0
}

fn mark_pareto(rows: &mut [BenchRow]) {
    let snapshot: Vec<(String, f64, f64)> = rows
        .iter()
        .map(|r| (r.stage.to_string(), r.time_s, r.error_pct))
        .collect();
    for r in rows.iter_mut() {
        r.pareto = r.error_pct.is_finite()
            && !snapshot.iter().any(|(st, t, e)| {
                st == r.stage
                    && *t <= r.time_s
                    && *e <= r.error_pct
                    && (*t < r.time_s || *e < r.error_pct)
            });
    }
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
                },
                &d,
            )?;
            d
        }
    };
    let session = Session::load(&dir).map_err(|e| BenchError::Session(e.to_string()))?;
    let truth = match session.load_truth() {
        Some(Ok(t)) => t,
        _ => return Err(BenchError::NoTruth(dir.clone())),
    };

    log("photogrammetry (once)");
    let t = Instant::now();
    let poses: SessionPoses = skinbrdf_poses::estimate_session(&session, &PoseConfig::DEFAULT)?;
    let poses_s = t.elapsed().as_secs_f64();
    let cam_err_mm =
        median(skinbrdf_poses::session::compare_truth(&poses, &truth).camera_position_error_m)
            * 1e3;

    let opts = SessionOptions {
        poses: PoseChoice::Estimated,
        skip_target_mask: false,
        estimated: Some(poses),
    };
    let mut rows = Vec::new();
    let derender = |setting: &'static str,
                    value: String,
                    c: DerenderConfig,
                    rows: &mut Vec<BenchRow>,
                    log: &mut dyn FnMut(&str)|
     -> Result<Vec<BrdfSample>, BenchError> {
        log(&format!("derender {setting} = {value}"));
        let run = skinbrdf_derender::derender_session(&session, &opts, &c)?;
        let err = run
            .report
            .truth_error
            .as_ref()
            .map_or(f64::NAN, |e| e.median_rel_error * 100.0);
        rows.push(BenchRow {
            stage: "derender",
            setting,
            value,
            error_name: "sample median rel. error",
            error_pct: err,
            time_s: run.report.times.total_s,
            pareto: false,
        });
        Ok(run.report.samples)
    };
    let base = DerenderConfig::DEFAULT;
    let strides: &[u32] = if cfg.quick { &[2, 8] } else { &[1, 2, 4, 8] };
    let mut fit_samples = Vec::new();
    for &s in strides {
        let samples = derender(
            "pixel stride",
            s.to_string(),
            DerenderConfig { stride: s, ..base },
            &mut rows,
            log,
        )?;
        if s == 2 || fit_samples.is_empty() {
            fit_samples = samples;
        }
    }
    let sweep_stride = if cfg.quick { 4 } else { 2 };
    let grazing: &[f64] = if cfg.quick {
        &[60.0, 85.0]
    } else {
        &[60.0, 75.0, 85.0]
    };
    for &g in grazing {
        derender(
            "grazing limit (deg)",
            format!("{g}"),
            DerenderConfig {
                stride: sweep_stride,
                grazing_limit_deg: g,
                ..base
            },
            &mut rows,
            log,
        )?;
    }
    let normals: Vec<(String, NormalMethod)> = if cfg.quick {
        vec![
            ("vertex".into(), NormalMethod::Vertex),
            (
                "planar fit, auto radius".into(),
                NormalMethod::PlanarFitAuto,
            ),
        ]
    } else {
        vec![
            ("vertex".into(), NormalMethod::Vertex),
            (
                "planar fit 2 mm".into(),
                NormalMethod::PlanarFit { radius_m: 0.002 },
            ),
            (
                "planar fit 5 mm".into(),
                NormalMethod::PlanarFit { radius_m: 0.005 },
            ),
            (
                "planar fit 10 mm".into(),
                NormalMethod::PlanarFit { radius_m: 0.010 },
            ),
            (
                "planar fit, auto radius".into(),
                NormalMethod::PlanarFitAuto,
            ),
        ]
    };
    for (label, n) in normals {
        derender(
            "normals",
            label,
            DerenderConfig {
                stride: sweep_stride,
                normals: n,
                ..base
            },
            &mut rows,
            log,
        )?;
    }

    // Fits on the stride-2 samples.
    let fit = |setting: &'static str,
               value: String,
               spec: ModelSpec,
               c: FitConfig,
               rows: &mut Vec<BenchRow>,
               log: &mut dyn FnMut(&str)|
     -> Result<(), BenchError> {
        log(&format!("fit {setting} = {value}"));
        let t = Instant::now();
        let model = spec.channel_model();
        // A setting that makes the fit fail loudly (e.g. too few iterations) is a row with
        // its failure, not the end of the sweep.
        let (error_pct, value) = match fit_rgb(model.as_ref(), &fit_samples, &c) {
            Ok(f) => (model_error_pct(&f.model, &truth.brdf, &fit_samples), value),
            Err(e) => (f64::NAN, format!("{value} (failed: {e})")),
        };
        let time_s = t.elapsed().as_secs_f64();
        rows.push(BenchRow {
            stage: "fit",
            setting,
            value,
            error_name: "model median rel. error",
            error_pct,
            time_s,
            pareto: false,
        });
        Ok(())
    };
    let lobes: &[usize] = if cfg.quick { &[1, 2] } else { &[1, 2, 3] };
    for &l in lobes {
        fit(
            "Lafortune lobes",
            l.to_string(),
            ModelSpec::Lafortune { lobes: l },
            FitConfig::default(),
            &mut rows,
            log,
        )?;
    }
    let iters: &[usize] = if cfg.quick {
        &[5, 200]
    } else {
        &[3, 10, 30, 200]
    };
    for &it in iters {
        let mut c = FitConfig::default();
        c.lm.max_iterations = it;
        fit(
            "LM iteration cap",
            it.to_string(),
            ModelSpec::Lafortune { lobes: 2 },
            c,
            &mut rows,
            log,
        )?;
    }
    let subs: &[usize] = if cfg.quick {
        &[2_000]
    } else {
        &[2_000, 20_000, 100_000]
    };
    for &n in subs {
        let c = FitConfig {
            subsample: n,
            ..FitConfig::default()
        };
        fit(
            "multi-start subsample",
            n.to_string(),
            ModelSpec::Lafortune { lobes: 2 },
            c,
            &mut rows,
            log,
        )?;
    }
    mark_pareto(&mut rows);

    // Outputs.
    let mut files = Vec::new();
    let mut md = format!(
        "Session: `{}` ({} images). Photogrammetry (run once): {:.2} s, camera position error median {:.3} mm.\n\n| stage | setting | value | error | time (s) | Pareto |\n|---|---|---|---:|---:|:-:|\n",
        dir.display(),
        session.file.images.len(),
        poses_s,
        cam_err_mm
    );
    let mut csv = String::from("stage,setting,value,error_name,error_pct,time_s,pareto\n");
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {} | {:.3} % ({}) | {:.3} | {} |\n",
            r.stage,
            r.setting,
            r.value,
            r.error_pct,
            r.error_name,
            r.time_s,
            if r.pareto { "★" } else { "" }
        ));
        csv.push_str(&format!(
            "{},{},{},{},{},{},{}\n",
            r.stage,
            r.setting,
            r.value.replace(',', ";"),
            r.error_name,
            r.error_pct,
            r.time_s,
            r.pareto
        ));
    }
    let p = cfg.out_dir.join("table.md");
    write_atomic(&p, md.as_bytes())?;
    files.push(p);
    let p = cfg.out_dir.join("table.csv");
    write_atomic(&p, csv.as_bytes())?;
    files.push(p);
    let panel = |stage: &str| -> Panel {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.stage == stage)
            .map(|r| (r.time_s, r.error_pct))
            .collect();
        let mut front: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.stage == stage && r.pareto)
            .map(|r| (r.time_s, r.error_pct))
            .collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        Panel {
            title: format!("{stage}: error against run time"),
            x_label: "run time (s)".into(),
            y_label: "median relative error (%)".into(),
            x_range: None,
            y_range: None,
            axes: true,
            series: vec![
                Series {
                    label: "settings".into(),
                    color: 0,
                    kind: SeriesKind::Points(pts),
                },
                Series {
                    label: "Pareto front".into(),
                    color: 1,
                    kind: SeriesKind::Line(front),
                },
            ],
        }
    };
    let fig = Figure {
        panels: vec![panel("derender"), panel("fit")],
        panel_px: (640, 480),
    };
    files.extend(write_figure(&cfg.out_dir.join("pareto"), &fig)?);
    Ok(BenchOutput {
        rows,
        poses: (poses_s, cam_err_mm),
        table_md: md,
        files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(stage: &'static str, t: f64, e: f64) -> BenchRow {
        BenchRow {
            stage,
            setting: "s",
            value: String::new(),
            error_name: "e",
            error_pct: e,
            time_s: t,
            pareto: false,
        }
    }

    #[test]
    fn pareto_front_keeps_only_undominated_rows_per_stage() {
        let mut rows = vec![
            row("a", 1.0, 5.0),
            row("a", 2.0, 3.0),
            row("a", 3.0, 4.0),
            row("b", 10.0, 10.0),
            row("a", 0.5, f64::NAN),
        ];
        mark_pareto(&mut rows);
        let front: Vec<bool> = rows.iter().map(|r| r.pareto).collect();
        assert_eq!(front, [true, true, false, true, false]);
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
