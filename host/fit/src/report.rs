//! The `skinbrdf fit` and `skinbrdf compare` work: load samples from any supported input, fit,
//! smooth, draw the figures, export, and write the parameters (JSON) and a Markdown report.
//!
//! Inputs ([`load_input`]): a sample file (`.skbs`), a Cornell `.brdf` file (converted to linear
//! sRGB under D65), or a session directory (`DIR/out/samples.skbs`, or the only `.skbs` in `DIR`
//! or `DIR/out`; `DIR/truth.json`, when present, supplies the true BRDF for scoring).
//!
//! The smoother runs on an evenly strided subset of at most [`SMOOTH_MAX_SAMPLES`] samples
//! (plenty for a curve and its band; its cost grows with `n x neighbours`), on
//! `ln(channel mean + floor)` (floor 1% of the median): BRDF noise is multiplicative and a
//! specular peak would otherwise set one residual scale for the whole domain. The span is chosen
//! by GCV among [`SPAN_CANDIDATES`]. Curves and bands are mapped back with `exp(v) - floor`;
//! session comparisons are made in the log domain.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use skinbrdf_brdf::{BrdfModel, ModelSpec};
use skinbrdf_core::BrdfSample;
use skinbrdf_samples::{CornellBrdf, Illuminant};

use crate::export;
use crate::fit::{error_metrics, fit_rgb, ErrorMetrics, FitConfig, RgbFit};
use crate::loess::{choose_span_gcv, Bandwidth, Loess, LoessConfig};
use crate::plot::{self, PlaneCurve};

/// Samples the smoother uses at most.
pub const SMOOTH_MAX_SAMPLES: usize = 20_000;
/// Spans tried by GCV.
pub const SPAN_CANDIDATES: [f64; 4] = [0.02, 0.05, 0.1, 0.2];
/// Incident angles of the polar figure (the method's Fig. 6).
pub const POLAR_THETA_I_DEG: [f64; 3] = [0.0, 30.0, 60.0];
/// Half-width of the theta_i / incidence-plane window for the scatter figure, degrees.
pub const PLANE_TOL_DEG: f64 = 5.0;

/// Errors of the fit command.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The input could not be found or read.
    #[error("{path}: {problem}", path = path.display())]
    Input {
        /// The input.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// Reading samples failed.
    #[error(transparent)]
    Samples(#[from] skinbrdf_samples::SamplesError),
    /// The fit failed.
    #[error("fit of {input}: {source}", input = input.display())]
    Fit {
        /// The input.
        input: PathBuf,
        /// The cause.
        source: crate::fit::FitError,
    },
    /// The smoother failed.
    #[error(transparent)]
    Loess(#[from] crate::loess::LoessError),
    /// Drawing failed.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// Writing an output failed.
    #[error("{path}: {problem}", path = path.display())]
    Output {
        /// The output.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
}

/// A loaded input.
#[derive(Debug, Clone)]
pub struct Input {
    /// Where it came from.
    pub path: PathBuf,
    /// Short label (file or directory name).
    pub label: String,
    /// The samples (linear sRGB, 1/sr).
    pub samples: Vec<BrdfSample>,
    /// The Cornell grid, if the input was a `.brdf` file.
    pub cornell: Option<CornellBrdf>,
    /// The true BRDF, if a `truth.json` was found.
    pub truth: Option<BrdfModel>,
}

fn find_skbs(dir: &Path) -> Option<PathBuf> {
    let direct = dir.join("out").join("samples.skbs");
    if direct.is_file() {
        return Some(direct);
    }
    for d in [dir.to_path_buf(), dir.join("out")] {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        let found: Vec<PathBuf> = rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "skbs"))
            .collect();
        if found.len() == 1 {
            return found.into_iter().next();
        }
    }
    None
}

/// Loads a sample file, Cornell file or session directory.
pub fn load_input(path: &Path) -> Result<Input, ReportError> {
    let label = path.file_stem().map_or_else(
        || path.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    );
    if path.is_dir() {
        let skbs = find_skbs(path).ok_or_else(|| ReportError::Input {
            path: path.to_path_buf(),
            problem: "no samples found (expected out/samples.skbs from `skinbrdf derender`, or one .skbs file)".into(),
        })?;
        let (_, samples) = skinbrdf_samples::read_samples(&skbs)?;
        let truth_path = path.join("truth.json");
        let truth = if truth_path.is_file() {
            let text = std::fs::read_to_string(&truth_path).map_err(|e| ReportError::Input {
                path: truth_path.clone(),
                problem: e.to_string(),
            })?;
            let v: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| ReportError::Input {
                    path: truth_path.clone(),
                    problem: e.to_string(),
                })?;
            let brdf = v.get("brdf").cloned().ok_or_else(|| ReportError::Input {
                path: truth_path.clone(),
                problem: "no `brdf` field".into(),
            })?;
            Some(
                serde_json::from_value(brdf).map_err(|e| ReportError::Input {
                    path: truth_path.clone(),
                    problem: format!("brdf: {e}"),
                })?,
            )
        } else {
            None
        };
        return Ok(Input {
            path: path.to_path_buf(),
            label,
            samples,
            cornell: None,
            truth,
        });
    }
    if !path.is_file() {
        return Err(ReportError::Input {
            path: path.to_path_buf(),
            problem: "no such file or directory".into(),
        });
    }
    if path
        .extension()
        .is_some_and(|x| x.eq_ignore_ascii_case("brdf"))
    {
        let c = CornellBrdf::read(path)?;
        let conv = c.rgb_converter(Illuminant::D65, path)?;
        let samples = c.to_rgb_samples(&conv);
        return Ok(Input {
            path: path.to_path_buf(),
            label,
            samples,
            cornell: Some(c),
            truth: None,
        });
    }
    let (_, samples) = skinbrdf_samples::read_samples(path)?;
    Ok(Input {
        path: path.to_path_buf(),
        label,
        samples,
        cornell: None,
        truth: None,
    })
}

/// A smoother of `ln(channel mean + floor)` over `(theta_i, theta_e, phi_d)`: returns the
/// smoother, its span and the floor.
pub fn smooth(samples: &[BrdfSample]) -> Result<(Loess, f64, f64), ReportError> {
    let n = samples.len();
    let k = n.min(SMOOTH_MAX_SAMPLES);
    let idx: Vec<usize> = (0..k)
        .map(|i| ((i as u128 * n as u128) / k as u128) as usize)
        .collect();
    let x: Vec<Vec<f64>> = idx
        .iter()
        .map(|&i| {
            let s = &samples[i];
            vec![
                f64::from(s.theta_i_rad),
                f64::from(s.theta_e_rad),
                f64::from(s.phi_d_rad),
            ]
        })
        .collect();
    let raw: Vec<f64> = idx
        .iter()
        .map(|&i| f64::from(samples[i].rho.iter().sum::<f32>()) / 3.0)
        .collect();
    let mut sorted = raw.clone();
    sorted.sort_by(f64::total_cmp);
    let floor = (0.01 * sorted.get(sorted.len() / 2).copied().unwrap_or(0.0)).max(1e-9);
    let y: Vec<f64> = raw.iter().map(|v| (v.max(0.0) + floor).ln()).collect();
    let base = LoessConfig {
        max_sigma_points: 2000,
        ..LoessConfig::default()
    };
    let (span, _) = choose_span_gcv(&x, &y, &SPAN_CANDIDATES, base)?;
    let l = Loess::fit(
        &x,
        &y,
        LoessConfig {
            bandwidth: Bandwidth::Span(span),
            max_sigma_points: 5000,
            ..base
        },
    )?;
    Ok((l, span, floor))
}

/// Samples per session the pairwise difference test uses at most (the pooled pilot smooth is
/// predicted at every one of them).
pub const COMPARE_MAX_SAMPLES: usize = 10_000;

/// `(theta_i, theta_e, phi_d)` and `ln(channel mean + floor)` of an evenly strided subset.
fn log_design(samples: &[BrdfSample], k_max: usize, floor: f64) -> (Vec<Vec<f64>>, Vec<f64>) {
    let n = samples.len();
    let k = n.min(k_max);
    (0..k)
        .map(|i| {
            let s = &samples[((i as u128 * n as u128) / k as u128) as usize];
            let x = vec![
                f64::from(s.theta_i_rad),
                f64::from(s.theta_e_rad),
                f64::from(s.phi_d_rad),
            ];
            let mean = f64::from(s.rho.iter().sum::<f32>()) / 3.0;
            (x, (mean.max(0.0) + floor).ln())
        })
        .unzip()
}

/// Whether two sessions differ beyond their confidence bands, free of smoothing bias.
///
/// Comparing the two sessions' own loess curves is biased: a loess estimate's bias depends on
/// where the samples happen to lie, so two noisy samplings of one BRDF differ at a steep flank by
/// more than their (variance-only) bands allow. Instead both are compared against one pilot
/// smooth of the pooled samples: each session's residuals from the pilot are smoothed with the
/// same span, and the two residual curves (nearly flat, so nearly free of smoothing bias) are
/// compared with their bands ([`plot::compare_curves`]: largest `|z|` against the
/// Bonferroni-corrected 95% quantile over the angles of the incidence plane).
fn compare_pair(
    a: &Input,
    b: &Input,
    theta_i_deg: f64,
    span: f64,
    floor: f64,
) -> Result<plot::Difference, ReportError> {
    let (xa, ya) = log_design(&a.samples, COMPARE_MAX_SAMPLES, floor);
    let (xb, yb) = log_design(&b.samples, COMPARE_MAX_SAMPLES, floor);
    let cfg = LoessConfig {
        bandwidth: Bandwidth::Span(span),
        max_sigma_points: 5000,
        ..LoessConfig::default()
    };
    let xp: Vec<Vec<f64>> = xa.iter().chain(&xb).cloned().collect();
    let yp: Vec<f64> = ya.iter().chain(&yb).copied().collect();
    let pilot = Loess::fit(&xp, &yp, cfg)?;
    let residual_curve = |label: &str, x: Vec<Vec<f64>>, y: Vec<f64>| {
        let pred = pilot.predict_many(&x);
        let (xr, r): (Vec<Vec<f64>>, Vec<f64>) = x
            .into_iter()
            .zip(y)
            .zip(pred)
            .filter_map(|((x, y), p)| p.map(|p| (x, y - p.value)))
            .unzip();
        let l = Loess::fit(&xr, &r, cfg)?;
        Ok::<_, ReportError>(plot::loess_curve(label, &l, theta_i_deg, |v| v))
    };
    let ca = residual_curve(&a.label, xa, ya)?;
    let cb = residual_curve(&b.label, xb, yb)?;
    Ok(plot::compare_curves(&ca, &cb))
}

/// Accuracy of the fitted model against a true model at the samples' angles.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthScore {
    /// Per channel.
    pub channels: [ErrorMetrics; 3],
}

/// What `skinbrdf fit` produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitReport {
    /// The input.
    pub input: String,
    /// Samples read.
    pub n_samples: usize,
    /// The fit.
    pub fit: RgbFit,
    /// The smoother's GCV-chosen span and residual standard error.
    pub smooth_span: f64,
    /// Residual standard error of the smoother (log units: a relative error).
    pub smooth_sigma: f64,
    /// Against `truth.json`, when present.
    pub truth: Option<TruthScore>,
    /// Seconds per stage: load, fit, smooth, figures, export.
    pub timings_s: Vec<(String, f64)>,
    /// Files written.
    pub files: Vec<String>,
}

/// Options of [`fit_and_report`].
#[derive(Debug, Clone)]
pub struct ReportOptions {
    /// The model.
    pub model: ModelSpec,
    /// Fit settings.
    pub fit: FitConfig,
    /// Write the MERL table (35 MB).
    pub merl: bool,
    /// Draw figures.
    pub figures: bool,
}

fn write_text(path: &Path, text: &str) -> Result<(), ReportError> {
    skinbrdf_samples::write_atomic(path, |w| w.write_all(text.as_bytes())).map_err(|e| {
        ReportError::Output {
            path: path.to_path_buf(),
            problem: e.to_string(),
        }
    })
}

/// Fits, smooths, draws and exports one input into `out_dir`.
pub fn fit_and_report(
    input: &Input,
    out_dir: &Path,
    opts: &ReportOptions,
) -> Result<FitReport, ReportError> {
    std::fs::create_dir_all(out_dir).map_err(|e| ReportError::Output {
        path: out_dir.to_path_buf(),
        problem: e.to_string(),
    })?;
    let mut timings = Vec::new();
    let mut files = Vec::new();
    let t = Instant::now();
    let model = opts.model.channel_model();
    let fit =
        fit_rgb(model.as_ref(), &input.samples, &opts.fit).map_err(|source| ReportError::Fit {
            input: input.path.clone(),
            source,
        })?;
    timings.push(("fit".to_owned(), t.elapsed().as_secs_f64()));

    let truth = input.truth.as_ref().map(|tm| {
        let fitted = &fit.model;
        let ch = |c: usize| {
            let y: Vec<f64> = input
                .samples
                .iter()
                .map(|s| {
                    tm.eval_angles(
                        f64::from(s.theta_i_rad),
                        f64::from(s.theta_e_rad),
                        f64::from(s.phi_d_rad),
                    )[c]
                })
                .collect();
            let floor = 1e-3 * y.iter().sum::<f64>() / y.len().max(1) as f64;
            error_metrics(
                |i| {
                    let s = &input.samples[i];
                    fitted.eval_angles(
                        f64::from(s.theta_i_rad),
                        f64::from(s.theta_e_rad),
                        f64::from(s.phi_d_rad),
                    )[c]
                },
                &y,
                floor,
            )
        };
        TruthScore {
            channels: [ch(0), ch(1), ch(2)],
        }
    });

    let t = Instant::now();
    let (loess, span, floor) = smooth(&input.samples)?;
    let back = move |v: f64| v.exp() - floor;
    timings.push(("smooth".to_owned(), t.elapsed().as_secs_f64()));

    if opts.figures {
        let t = Instant::now();
        let eval = |a: [f64; 3]| fit.model.eval_angles(a[0], a[1], a[2]);
        let has_data = |ti: f64| {
            input
                .samples
                .iter()
                .any(|s| (f64::from(s.theta_i_rad).to_degrees() - ti).abs() <= 10.0)
        };
        let per_angle: Vec<(f64, Vec<PlaneCurve>)> = POLAR_THETA_I_DEG
            .iter()
            .map(|&ti| {
                let mut v = vec![plot::model_curve(
                    &format!("{} fit", fit.model_name),
                    eval,
                    ti,
                    3,
                )];
                if has_data(ti) {
                    v.push(plot::loess_curve("loess", &loess, ti, back));
                }
                (ti, v)
            })
            .collect();
        for p in plot::write_figure(
            &out_dir.join("polar_incidence"),
            &plot::polar_figure(&per_angle, "channel mean, 1/sr"),
        )? {
            files.push(p.display().to_string());
        }
        let ti = 30.0;
        let pts = plot::plane_samples(&input.samples, ti, PLANE_TOL_DEG);
        let curves = vec![
            plot::loess_curve("loess", &loess, ti, back),
            plot::model_curve(&format!("{} fit", fit.model_name), eval, ti, 3),
        ];
        let fig = plot::scatter_figure(&format!("{}: samples within {PLANE_TOL_DEG} deg of theta_i = {ti} deg and the incidence plane", input.label), &pts, &curves, "rho (channel mean, 1/sr)");
        for p in plot::write_figure(&out_dir.join("scatter_theta_i_30"), &fig)? {
            files.push(p.display().to_string());
        }
        timings.push(("figures".to_owned(), t.elapsed().as_secs_f64()));
    }

    let t = Instant::now();
    let grid = input
        .cornell
        .clone()
        .unwrap_or_else(export::regular_cornell_grid);
    let cornell = export::model_to_cornell(
        &fit.model,
        &grid,
        &format!("skinbrdf {} fit of {}", fit.model_name, input.label),
    );
    let brdf_path = out_dir.join("model.brdf");
    cornell.write(&brdf_path)?;
    files.push(brdf_path.display().to_string());
    if opts.merl {
        let merl_path = out_dir.join("model.binary");
        export::write_merl(&merl_path, &fit.model)?;
        files.push(merl_path.display().to_string());
    }
    timings.push(("export".to_owned(), t.elapsed().as_secs_f64()));

    let report = FitReport {
        input: input.path.display().to_string(),
        n_samples: input.samples.len(),
        fit,
        smooth_span: span,
        smooth_sigma: loess.sigma,
        truth,
        timings_s: timings,
        files,
    };
    let json_path = out_dir.join("params.json");
    let json = serde_json::to_string_pretty(&report).map_err(|e| ReportError::Output {
        path: json_path.clone(),
        problem: e.to_string(),
    })?;
    write_text(&json_path, &json)?;
    let md_path = out_dir.join("report.md");
    write_text(&md_path, &markdown(&report))?;
    Ok(report)
}

/// The Markdown report.
pub fn markdown(r: &FitReport) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let f = &r.fit;
    let _ = writeln!(s, "# BRDF fit: {}\n", r.input);
    let _ = writeln!(
        s,
        "- samples: {}\n- model: `{}`\n- residual: {:?}\n- fit time: {:.3} s\n",
        r.n_samples,
        f.model_name,
        f.residuals.first(),
        f.fit_time_s
    );
    let _ = writeln!(s, "## Parameters (per channel, value ± standard error)\n");
    let _ = writeln!(s, "| parameter | R | G | B |\n|---|---|---|---|");
    for (j, name) in f.param_names.iter().enumerate() {
        let cell = |c: usize| {
            let ch = &f.channels[c];
            match ch.std_errors[j] {
                Some(se) => format!("{:.5} ± {:.2e}", ch.params[j], se),
                None => format!("{:.5} (undetermined)", ch.params[j]),
            }
        };
        let _ = writeln!(s, "| {name} | {} | {} | {} |", cell(0), cell(1), cell(2));
    }
    let _ = writeln!(s, "\n## Fit error against the samples\n");
    let _ = writeln!(s, "| channel | log-RMSE | median rel. error | iterations | status | condition number |\n|---|---|---|---|---|---|");
    for (c, ch) in f.channels.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {} | {:.4} | {:.4} | {} | {:?} | {:.2e} |",
            ["R", "G", "B"][c],
            ch.error.log_rmse,
            ch.error.median_rel_err,
            ch.iterations,
            ch.status,
            ch.condition_number
        );
    }
    if let Some(t) = &r.truth {
        let _ = writeln!(
            s,
            "\n## Against the true BRDF (truth.json) at the samples' angles\n"
        );
        let _ = writeln!(
            s,
            "| channel | log-RMSE | median rel. error |\n|---|---|---|"
        );
        for (c, m) in t.channels.iter().enumerate() {
            let _ = writeln!(
                s,
                "| {} | {:.4} | {:.4} |",
                ["R", "G", "B"][c],
                m.log_rmse,
                m.median_rel_err
            );
        }
    }
    let _ = writeln!(s, "\n## Smoothing\n\nloess (degree 2, tricube) on the channel mean over (theta_i, theta_e, phi_d), span {} by GCV, residual s.e. {:.4} (natural-log units, i.e. relative).\n", r.smooth_span, r.smooth_sigma);
    if !f.warnings.is_empty() {
        let _ = writeln!(s, "## Warnings\n");
        for w in &f.warnings {
            let _ = writeln!(s, "- {w}");
        }
        s.push('\n');
    }
    let _ = writeln!(s, "## Cost\n\n| stage | seconds |\n|---|---|");
    for (k, v) in &r.timings_s {
        let _ = writeln!(s, "| {k} | {v:.3} |");
    }
    let _ = writeln!(s, "\n## Files\n");
    for p in &r.files {
        let _ = writeln!(s, "- `{p}`");
    }
    s
}

/// What `skinbrdf compare` produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompareReport {
    /// Inputs.
    pub inputs: Vec<String>,
    /// Incident angle compared, degrees.
    pub theta_i_deg: f64,
    /// Pairwise differences.
    pub differences: Vec<plot::Difference>,
    /// Files written.
    pub files: Vec<String>,
}

/// Overlays the smoothed incidence-plane curves of several inputs at `theta_i_deg` and tests
/// every pair for a difference beyond the bands.
pub fn compare(
    inputs: &[Input],
    theta_i_deg: f64,
    out_dir: &Path,
) -> Result<CompareReport, ReportError> {
    std::fs::create_dir_all(out_dir).map_err(|e| ReportError::Output {
        path: out_dir.to_path_buf(),
        problem: e.to_string(),
    })?;
    let mut curves = Vec::new();
    let mut smooths = Vec::new();
    for inp in inputs {
        let (l, span, floor) = smooth(&inp.samples)?;
        curves.push(plot::loess_curve(
            &inp.label,
            &l,
            theta_i_deg,
            move |v: f64| v.exp() - floor,
        ));
        smooths.push((span, floor));
    }
    let mut differences = Vec::new();
    for a in 0..inputs.len() {
        for b in a + 1..inputs.len() {
            let span = smooths[a].0.max(smooths[b].0);
            let floor = smooths[a].1.max(smooths[b].1);
            differences.push(compare_pair(
                &inputs[a],
                &inputs[b],
                theta_i_deg,
                span,
                floor,
            )?);
        }
    }
    let fig = plot::overlay_figure(
        &format!("incidence plane, theta_i = {theta_i_deg} deg (loess, 95% bands)"),
        &curves,
        "rho (channel mean, 1/sr)",
    );
    let mut files: Vec<String> = plot::write_figure(&out_dir.join("overlay"), &fig)?
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let polar = plot::polar_figure(&[(theta_i_deg, curves.clone())], "channel mean, 1/sr");
    files.extend(
        plot::write_figure(&out_dir.join("overlay_polar"), &polar)?
            .iter()
            .map(|p| p.display().to_string()),
    );
    let report = CompareReport {
        inputs: inputs
            .iter()
            .map(|i| i.path.display().to_string())
            .collect(),
        theta_i_deg,
        differences,
        files,
    };
    let json_path = out_dir.join("compare.json");
    let json = serde_json::to_string_pretty(&report).map_err(|e| ReportError::Output {
        path: json_path.clone(),
        problem: e.to_string(),
    })?;
    write_text(&json_path, &json)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cornell(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/cornell")
            .join(name)
    }

    #[test]
    fn fit_report_on_a_cornell_file_writes_everything() {
        let input = load_input(&cornell("garnet_red.brdf")).expect("load");
        let dir = tempfile::tempdir().expect("tempdir");
        let opts = ReportOptions {
            model: ModelSpec::Lafortune { lobes: 1 },
            fit: FitConfig::default(),
            merl: false,
            figures: true,
        };
        let r = fit_and_report(&input, dir.path(), &opts).expect("report");
        for f in [
            "params.json",
            "report.md",
            "model.brdf",
            "polar_incidence.png",
            "polar_incidence.svg",
            "scatter_theta_i_30.png",
            "scatter_theta_i_30.svg",
        ] {
            assert!(dir.path().join(f).is_file(), "{f}");
        }
        let back = CornellBrdf::read(dir.path().join("model.brdf")).expect("brdf");
        assert_eq!(back.samples.len(), input.samples.len());
        assert!(
            r.smooth_sigma.is_finite() && r.smooth_sigma > 0.0 && r.smooth_sigma < 1.0,
            "{}",
            r.smooth_sigma
        );
        let md = std::fs::read_to_string(dir.path().join("report.md")).expect("md");
        assert!(md.contains("ln_exponent_0") && md.contains("log-RMSE"));
    }

    #[test]
    fn compare_tells_two_materials_apart_and_a_material_from_itself_not() {
        let a = load_input(&cornell("garnet_red.brdf")).expect("a");
        let b = load_input(&cornell("krylon_blue.brdf")).expect("b");
        let dir = tempfile::tempdir().expect("tempdir");
        let r = compare(&[a.clone(), b, a], 30.0, dir.path()).expect("compare");
        assert_eq!(r.differences.len(), 3);
        assert!(r.differences[0].differ, "{:?}", r.differences[0]);
        assert!(!r.differences[1].differ || r.differences[1].a != r.differences[1].b);
        let same = r
            .differences
            .iter()
            .find(|d| d.a == d.b)
            .expect("self pair");
        assert!(!same.differ && same.max_z < 1e-9);
        assert!(dir.path().join("overlay.svg").is_file());
    }

    fn synthetic_input(label: &str, seed: u64, scale: f32) -> Input {
        let (_, mut samples) = crate::synthetic::lafortune2_samples(3_000, 0.1, seed);
        for s in &mut samples {
            s.rho = s.rho.map(|v| v * scale);
        }
        Input {
            path: PathBuf::from(label),
            label: label.to_owned(),
            samples,
            cornell: None,
            truth: None,
        }
    }

    #[test]
    fn compare_separates_a_real_difference_from_noise() {
        // Two independent noisy sessions of one BRDF must not differ (their bands overlap);
        // the same BRDF 30% brighter must.
        let a = synthetic_input("a", 1, 1.0);
        let a2 = synthetic_input("a2", 2, 1.0);
        let b = synthetic_input("b", 3, 1.3);
        let dir = tempfile::tempdir().expect("tempdir");
        let r = compare(&[a, a2, b], 30.0, dir.path()).expect("compare");
        let find = |x: &str, y: &str| {
            r.differences
                .iter()
                .find(|d| d.a == x && d.b == y)
                .expect("pair")
                .clone()
        };
        let same = find("a", "a2");
        assert!(!same.differ, "{same:?}");
        assert!(same.max_z > 0.0, "independent noise gives some difference");
        for (x, y) in [("a", "b"), ("a2", "b")] {
            let d = find(x, y);
            assert!(d.differ && d.fraction_disjoint > 0.5, "{d:?}");
        }
    }

    #[test]
    fn missing_inputs_are_named() {
        let e = load_input(Path::new("/nonexistent/x.skbs")).expect_err("missing");
        assert!(e.to_string().contains("/nonexistent/x.skbs"));
        let dir = tempfile::tempdir().expect("tempdir");
        let e = load_input(dir.path()).expect_err("empty dir");
        assert!(e.to_string().contains("no samples found"));
    }
}
