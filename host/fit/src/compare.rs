//! `skinbrdf compare`: overlays several inputs' smoothed incidence-plane curves and tests every
//! pair for a difference beyond the bands ([`compare`]).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::input::Input;
use crate::loess::{Bandwidth, Loess, LoessConfig};
use crate::plot;
use crate::report::{create_out_dir, write_json, ReportError};
use crate::smooth::{log_design, smooth, SmoothConfig, FIT_SIGMA_POINTS};

/// Samples per session the pairwise difference test uses at most (the pooled pilot smooth is
/// predicted at every one of them).
pub const COMPARE_MAX_SAMPLES: usize = 10_000;

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
        max_sigma_points: FIT_SIGMA_POINTS,
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
    create_out_dir(out_dir)?;
    let mut curves = Vec::new();
    let mut smooths = Vec::new();
    for inp in inputs {
        let sm = smooth(&inp.samples, &SmoothConfig::default())?;
        curves.push(sm.plane_curve(&inp.label, theta_i_deg));
        smooths.push((sm.metrics.span, sm.metrics.floor_rho));
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
    write_json(&json_path, &report)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::load_input;
    use std::path::PathBuf;

    fn cornell(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/cornell")
            .join(name)
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
}
