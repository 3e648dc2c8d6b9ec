//! The figures of a fit (part of the report stage): the polar plot of the incidence plane at
//! [`POLAR_THETA_I_DEG`] (the method's Fig. 6: the fitted model, and the smoothed samples where
//! samples lie within [`POLAR_DATA_TOL_DEG`] of the panel's incident angle) and the samples near
//! the incidence plane at [`SCATTER_THETA_I_DEG`] with the smoothed curve, its band and the
//! model (Fig. 11), the curves only over the samples' support
//! ([`crate::plot::support_intervals`]). Drawing is [`crate::plot`]'s; this module chooses what
//! is drawn.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use skinbrdf_core::BrdfSample;

use crate::fit::Fitted;
use crate::plot::{self, PlaneCurve, PlotError};
use crate::smooth::Smoothed;

/// Incident angles of the polar figure (the method's Fig. 6).
pub const POLAR_THETA_I_DEG: [f64; 3] = [0.0, 30.0, 60.0];
/// A polar panel shows the smoothed samples when some sample's incident angle is this close to
/// the panel's, degrees.
pub const POLAR_DATA_TOL_DEG: f64 = 10.0;
/// Incident angle of the scatter figure, degrees.
pub const SCATTER_THETA_I_DEG: f64 = 30.0;
/// Half-width of the theta_i / incidence-plane window for the scatter figure, degrees.
pub const PLANE_TOL_DEG: f64 = 5.0;

/// What [`write_figures`] wrote.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Figures {
    /// The files (PNG and SVG of each figure).
    pub files: Vec<PathBuf>,
    /// Samples drawn in the scatter figure.
    pub scatter_samples: usize,
    /// Wall time, seconds.
    pub run_time_s: f64,
}

/// Draws the polar figure (`polar_incidence.{png,svg}`) and the scatter figure
/// (`scatter_theta_i_30.{png,svg}`) into `dir` (which must exist).
pub fn write_figures(
    smoothed: &Smoothed,
    fitted: &Fitted,
    samples: &[BrdfSample],
    dir: &Path,
) -> Result<Figures, PlotError> {
    let t = Instant::now();
    let fit = &fitted.fit;
    let model_label = format!("{} fit", fit.model_name);
    let eval = |a: [f64; 3]| fit.model.eval_angles(a[0], a[1], a[2]);
    let has_data = |ti_deg: f64| {
        samples
            .iter()
            .any(|s| (f64::from(s.theta_i_rad).to_degrees() - ti_deg).abs() <= POLAR_DATA_TOL_DEG)
    };
    let per_angle: Vec<(f64, Vec<PlaneCurve>)> = POLAR_THETA_I_DEG
        .iter()
        .map(|&ti| {
            let mut v = vec![plot::model_curve(&model_label, eval, ti, 3)];
            if has_data(ti) {
                v.push(smoothed.plane_curve("loess", ti));
            }
            (ti, v)
        })
        .collect();
    let mut files = plot::write_figure(
        &dir.join("polar_incidence"),
        &plot::polar_figure(&per_angle, "channel mean, 1/sr"),
    )?;
    let ti = SCATTER_THETA_I_DEG;
    let pts = plot::plane_samples(samples, ti, PLANE_TOL_DEG);
    let curves = vec![
        smoothed.plane_curve("loess", ti),
        plot::model_curve(&model_label, eval, ti, 3),
    ];
    let fig = plot::scatter_figure(
        &format!(
            "{} samples within {PLANE_TOL_DEG} deg of theta_i = {ti} deg and the incidence plane",
            pts.len()
        ),
        &pts,
        &curves,
        "rho (channel mean, 1/sr)",
    );
    files.extend(plot::write_figure(&dir.join("scatter_theta_i_30"), &fig)?);
    Ok(Figures {
        files,
        scatter_samples: pts.len(),
        run_time_s: t.elapsed().as_secs_f64(),
    })
}
