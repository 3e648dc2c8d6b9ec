//! The `skinbrdf fit` report: what a fit run produced ([`FitReport`]), as JSON (`params.json`)
//! and Markdown (`report.md`) ([`write_report`]), and [`fit_and_report`], the composition of the
//! stages a `skinbrdf fit` run makes:
//!
//! 1. fit ([`crate::fit::fit_model`]),
//! 2. score against the truth, when known ([`crate::score::score_against_truth`]),
//! 3. smooth ([`crate::smooth::smooth`]),
//! 4. figures ([`crate::figures::write_figures`]), optional,
//! 5. export ([`crate::export::export`]),
//! 6. the report itself ([`write_report`]).
//!
//! Each stage is a public function over domain types returning a typed result with its own run
//! time; a pipeline can call them one per stage instead.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use skinbrdf_brdf::ModelSpec;

use crate::export::{export, ExportOptions, Exported};
use crate::figures::{write_figures, Figures};
use crate::fit::{fit_model, FitConfig, Fitted, RgbFit};
use crate::score::score_against_truth;
use crate::smooth::{smooth, SmoothConfig, SmoothMetrics, Smoothed};

pub use crate::compare::{compare, CompareReport, COMPARE_MAX_SAMPLES};
pub use crate::figures::{PLANE_TOL_DEG, POLAR_THETA_I_DEG};
pub use crate::input::{load_input, Input};
pub use crate::score::TruthScore;
pub use crate::smooth::{SMOOTH_MAX_SAMPLES, SPAN_CANDIDATES};

/// Errors of the fit and compare commands.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The input path does not exist.
    #[error("{path}: no such file or directory", path = path.display())]
    NotFound {
        /// The input.
        path: PathBuf,
    },
    /// A session directory without samples.
    #[error("{dir}: no samples found (expected out/samples.skbs from `skinbrdf derender`, or one .skbs file)", dir = dir.display())]
    NoSamples {
        /// The directory.
        dir: PathBuf,
    },
    /// `truth.json` could not be read.
    #[error("{path}: cannot read", path = path.display())]
    TruthRead {
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// `truth.json` is not JSON, or its field is missing or not a BRDF model.
    #[error("{path}: {}", match field { Some(f) => format!("field `{f}` is missing or not a BRDF model"), None => "not JSON".to_owned() }, path = path.display())]
    TruthJson {
        /// The file.
        path: PathBuf,
        /// The field (`None`: the file as a whole).
        field: Option<&'static str>,
        /// The cause (`None`: the field is missing).
        #[source]
        source: Option<serde_json::Error>,
    },
    /// Reading samples, or writing an output file, failed.
    #[error(transparent)]
    Samples(#[from] skinbrdf_samples::SamplesError),
    /// The fit failed.
    #[error("fit of {input}", input = input.display())]
    Fit {
        /// The input.
        input: PathBuf,
        /// The cause.
        #[source]
        source: crate::fit::FitError,
    },
    /// The smoother failed.
    #[error(transparent)]
    Loess(#[from] crate::loess::LoessError),
    /// Drawing failed.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// The output directory could not be created.
    #[error("{path}: cannot create the output directory", path = path.display())]
    CreateDir {
        /// The directory.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A report could not be serialised: a NaN or infinity (named by its field's path), or a
    /// value serde_json refuses. The message names the output.
    #[error(transparent)]
    Serialize(#[from] skinbrdf_core::json::JsonError),
}

/// Seconds per stage of a fit run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitTimings {
    /// The fit ([`Fitted::run_time_s`]).
    pub fit_s: f64,
    /// Scoring against the truth, when it was known.
    pub truth_score_s: Option<f64>,
    /// The smoother ([`SmoothMetrics::run_time_s`]).
    pub smooth_s: f64,
    /// The figures, when drawn.
    pub figures_s: Option<f64>,
    /// The export ([`Exported::run_time_s`]).
    pub export_s: f64,
}

impl FitTimings {
    /// `(stage, seconds)` of the stages that ran, in order (for display).
    pub fn rows(&self) -> Vec<(&'static str, f64)> {
        [
            ("fit", Some(self.fit_s)),
            ("truth score", self.truth_score_s),
            ("smooth", Some(self.smooth_s)),
            ("figures", self.figures_s),
            ("export", Some(self.export_s)),
        ]
        .into_iter()
        .filter_map(|(k, v)| v.map(|v| (k, v)))
        .collect()
    }
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
    /// The smoother's span, residual scale, floor, samples and time.
    pub smooth: SmoothMetrics,
    /// Against `truth.json`, when present.
    pub truth: Option<TruthScore>,
    /// Seconds per stage.
    pub timings: FitTimings,
    /// Files written by the figures and export stages.
    pub files: Vec<String>,
}

impl FitReport {
    /// Gathers the stages' results.
    pub fn new(
        input: &Input,
        fitted: Fitted,
        truth: Option<TruthScore>,
        smoothed: &Smoothed,
        figures: Option<&Figures>,
        exported: &Exported,
    ) -> Self {
        let timings = FitTimings {
            fit_s: fitted.run_time_s,
            truth_score_s: truth.as_ref().map(|t| t.run_time_s),
            smooth_s: smoothed.metrics.run_time_s,
            figures_s: figures.map(|f| f.run_time_s),
            export_s: exported.run_time_s,
        };
        let files = figures
            .map_or(&[][..], |f| &f.files[..])
            .iter()
            .chain(&exported.files)
            .map(|p| p.display().to_string())
            .collect();
        Self {
            input: input.path.display().to_string(),
            n_samples: input.samples.len(),
            fit: fitted.fit,
            smooth: smoothed.metrics,
            truth,
            timings,
            files,
        }
    }
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

/// Writes `text` to `path` atomically.
pub(crate) fn write_text(path: &Path, text: &str) -> Result<(), ReportError> {
    Ok(skinbrdf_samples::write_atomic(path, |w| {
        w.write_all(text.as_bytes())
    })?)
}

/// Serialises `value` as pretty JSON to `path` atomically, through the checked writer
/// ([`skinbrdf_core::json`]: a NaN or infinity is refused with its field's path).
pub(crate) fn write_json(path: &Path, value: &impl Serialize) -> Result<(), ReportError> {
    let json = skinbrdf_core::json::to_vec_pretty(path, value)?;
    Ok(skinbrdf_samples::write_atomic(path, |w| {
        w.write_all(&json)
    })?)
}

/// Creates `dir` (and its parents) if needed.
pub fn create_out_dir(dir: &Path) -> Result<(), ReportError> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::CreateDir {
        path: dir.to_path_buf(),
        source,
    })
}

/// Files [`write_report`] wrote.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReportFiles {
    /// `params.json`: the whole [`FitReport`] (the fitted model at `fit.model`).
    pub params_json: PathBuf,
    /// `report.md`: [`markdown`].
    pub report_md: PathBuf,
}

/// Writes `dir/params.json` and `dir/report.md`, each atomically; `dir` must exist.
pub fn write_report(report: &FitReport, dir: &Path) -> Result<ReportFiles, ReportError> {
    let params_json = dir.join("params.json");
    write_json(&params_json, report)?;
    let report_md = dir.join("report.md");
    write_text(&report_md, &markdown(report))?;
    Ok(ReportFiles {
        params_json,
        report_md,
    })
}

/// Fits, scores, smooths, draws and exports one input into `out_dir`, then writes the report:
/// the stages above, one after another.
pub fn fit_and_report(
    input: &Input,
    out_dir: &Path,
    opts: &ReportOptions,
) -> Result<FitReport, ReportError> {
    create_out_dir(out_dir)?;
    let fitted =
        fit_model(&input.samples, &opts.fit, opts.model).map_err(|source| ReportError::Fit {
            input: input.path.clone(),
            source,
        })?;
    let truth = input
        .truth
        .as_ref()
        .map(|t| score_against_truth(&fitted, t, &input.samples));
    let smoothed = smooth(&input.samples, &SmoothConfig::default())?;
    let figures = if opts.figures {
        Some(write_figures(&smoothed, &fitted, &input.samples, out_dir)?)
    } else {
        None
    };
    let exported = export(
        &fitted,
        out_dir,
        &ExportOptions {
            cornell_grid: input.cornell.as_ref(),
            merl: opts.merl,
            source_label: &input.label,
        },
    )?;
    let report = FitReport::new(input, fitted, truth, &smoothed, figures.as_ref(), &exported);
    write_report(&report, out_dir)?;
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
        "- samples: {}\n- model: `{}`\n- residual: {}\n- fit time: {:.3} s\n",
        r.n_samples,
        f.model_name,
        f.residuals
            .first()
            .map_or_else(|| "none".to_string(), |k| k.to_string()),
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
            "| {} | {:.4} | {:.4} | {} | {} | {} |",
            ["R", "G", "B"][c],
            ch.error.log_rmse,
            ch.error.median_rel_err,
            ch.iterations,
            ch.status,
            crate::fit::condition_text(ch.condition_number)
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
    let _ = writeln!(s, "\n## Smoothing\n\nloess (degree 2, tricube) on the channel mean over (theta_i, theta_e, phi_d), span {} by GCV on {} samples, residual s.e. {:.4} (natural-log units, i.e. relative).\n", r.smooth.span, r.smooth.samples_used, r.smooth.residual_sigma_log);
    if !f.warnings.is_empty() {
        let _ = writeln!(s, "## Warnings\n");
        for w in &f.warnings {
            let _ = writeln!(s, "- {w}");
        }
        s.push('\n');
    }
    let _ = writeln!(s, "## Cost\n\n| stage | seconds |\n|---|---|");
    for (k, v) in r.timings.rows() {
        let _ = writeln!(s, "| {k} | {v:.3} |");
    }
    let _ = writeln!(s, "\n## Files\n");
    for p in &r.files {
        let _ = writeln!(s, "- `{p}`");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_samples::CornellBrdf;

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
            r.smooth.residual_sigma_log.is_finite()
                && r.smooth.residual_sigma_log > 0.0
                && r.smooth.residual_sigma_log < 1.0,
            "{}",
            r.smooth.residual_sigma_log
        );
        let md = std::fs::read_to_string(dir.path().join("report.md")).expect("md");
        assert!(md.contains("ln_exponent_0") && md.contains("log-RMSE"));
    }
}
