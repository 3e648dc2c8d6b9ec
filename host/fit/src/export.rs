//! Export of a fitted model where renderers and viewers can use it.
//!
//! * [`write_merl`]: the MERL binary table (Matusik et al. 2003): three little-endian `i32`
//!   dimensions `90, 90, 180`, then `3 x 1_458_000` `f64` values (all red, then green, then blue),
//!   index `phi_d + 180 (theta_d + 90 theta_h)`. `theta_h = (i/90)^2 pi/2` (the table's
//!   square-root spacing), `theta_d = j pi/180`, `phi_d = k pi/180` (reciprocity folds `phi_d`
//!   into `[0, pi)`). Values are stored divided by MERL's channel scales `1/1500, 1.15/1500,
//!   1.66/1500`, so standard readers, which multiply by them, get the model's 1/sr back.
//!   Directions below the horizon get 0.
//! * [`model_to_cornell`]: the model sampled on the Cornell grid of an existing file (or a
//!   regular grid), as a 3-band RGB `.brdf` ([`skinbrdf_samples::CornellBrdf::from_rgb`]).
//! * [`export`]: the report stage's export of a fit: `model.brdf`, and `model.binary` on request.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec3;
use serde::{Deserialize, Serialize};
use skinbrdf_brdf::BrdfModel;
use skinbrdf_samples::{write_atomic, CornellBrdf, SamplesError};

use crate::fit::Fitted;

/// MERL table sizes.
pub const MERL_THETA_H: usize = 90;
/// MERL theta_d bins.
pub const MERL_THETA_D: usize = 90;
/// MERL phi_d bins.
pub const MERL_PHI_D: usize = 180;
/// MERL channel scales (a reader multiplies stored values by these).
pub const MERL_SCALE: [f64; 3] = [1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0];

/// The two local directions of MERL half/difference angles (`phi_h = 0`).
pub fn merl_directions(theta_h: f64, theta_d: f64, phi_d: f64) -> (DVec3, DVec3) {
    let d = DVec3::new(
        theta_d.sin() * phi_d.cos(),
        theta_d.sin() * phi_d.sin(),
        theta_d.cos(),
    );
    // Rotate d about y by theta_h: the half vector goes from +z to (sin th, 0, cos th).
    let (s, c) = theta_h.sin_cos();
    let wi = DVec3::new(c * d.x + s * d.z, d.y, -s * d.x + c * d.z);
    let h = DVec3::new(s, 0.0, c);
    let we = 2.0 * wi.dot(h) * h - wi;
    (wi, we)
}

/// The MERL table of a model (values in 1/sr, before scaling), channel-major.
pub fn merl_table(model: &BrdfModel) -> Vec<f64> {
    use rayon::prelude::*;
    let n = MERL_THETA_H * MERL_THETA_D * MERL_PHI_D;
    let mut out = vec![0.0; 3 * n];
    let vals: Vec<[f64; 3]> = (0..n)
        .into_par_iter()
        .map(|idx| {
            let k = idx % MERL_PHI_D;
            let j = (idx / MERL_PHI_D) % MERL_THETA_D;
            let i = idx / (MERL_PHI_D * MERL_THETA_D);
            let th = (i as f64 / MERL_THETA_H as f64).powi(2) * std::f64::consts::FRAC_PI_2;
            let td = j as f64 * std::f64::consts::FRAC_PI_2 / MERL_THETA_D as f64;
            let pd = k as f64 * std::f64::consts::PI / MERL_PHI_D as f64;
            let (wi, we) = merl_directions(th, td, pd);
            model.eval(wi, we)
        })
        .collect();
    for (idx, v) in vals.iter().enumerate() {
        for c in 0..3 {
            out[c * n + idx] = v[c];
        }
    }
    out
}

/// Writes the MERL binary file atomically.
pub fn write_merl(path: &Path, model: &BrdfModel) -> Result<(), SamplesError> {
    let table = merl_table(model);
    let n = MERL_THETA_H * MERL_THETA_D * MERL_PHI_D;
    write_atomic(path, |w: &mut dyn Write| {
        for d in [MERL_THETA_H, MERL_THETA_D, MERL_PHI_D] {
            w.write_all(&(d as i32).to_le_bytes())?;
        }
        for (k, v) in table.iter().enumerate() {
            w.write_all(&(v / MERL_SCALE[k / n]).to_le_bytes())?;
        }
        Ok(())
    })
}

/// The model sampled at the angles of `grid` (e.g. a Cornell file that was fitted), as a
/// 3-band RGB Cornell table.
pub fn model_to_cornell(model: &BrdfModel, grid: &CornellBrdf, title: &str) -> CornellBrdf {
    let dir = |t: f64, p: f64| DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
    CornellBrdf::from_rgb(
        vec![
            format!(" {title}"),
            " RGB (linear sRGB) model values; bands = channels R G B".into(),
        ],
        grid.samples.iter().map(|s| {
            let v = model.eval(
                dir(s.theta_i_rad, s.phi_i_rad),
                dir(s.theta_s_rad, s.phi_s_rad),
            );
            ([s.theta_i_rad, s.phi_i_rad, s.theta_s_rad, s.phi_s_rad], v)
        }),
    )
}

/// A regular Cornell-style grid (theta_i 10..80 deg by 10, theta_s 0..85 by 5, phi_s 0..180 by
/// 15) for models fitted to data without a grid of their own.
pub fn regular_cornell_grid() -> CornellBrdf {
    let mut rows = Vec::new();
    for ti in (10..=80).step_by(10) {
        for ts in (0..=85).step_by(5) {
            for ps in (0..=180).step_by(15) {
                rows.push((
                    [
                        f64::from(ti).to_radians(),
                        0.0,
                        f64::from(ts).to_radians(),
                        f64::from(ps).to_radians(),
                    ],
                    [0.0; 3],
                ));
            }
        }
    }
    CornellBrdf::from_rgb(Vec::new(), rows)
}

/// What [`export`] writes.
#[derive(Debug, Clone, Copy, Default)]
pub struct ExportOptions<'a> {
    /// The Cornell grid to sample the model on (the fitted file's own, for a Cornell input);
    /// `None` = [`regular_cornell_grid`].
    pub cornell_grid: Option<&'a CornellBrdf>,
    /// Also write the MERL table `model.binary` (35 MB).
    pub merl: bool,
    /// What was fitted (goes into the `.brdf` header).
    pub source_label: &'a str,
}

/// What [`export`] wrote.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Exported {
    /// The files.
    pub files: Vec<PathBuf>,
    /// Wall time, seconds.
    pub run_time_s: f64,
}

/// Writes the fitted model as `dir/model.brdf` (and `dir/model.binary` with
/// [`ExportOptions::merl`]), each atomically; `dir` must exist.
pub fn export(
    fitted: &Fitted,
    dir: &Path,
    opts: &ExportOptions<'_>,
) -> Result<Exported, SamplesError> {
    let t = Instant::now();
    let fit = &fitted.fit;
    let regular;
    let grid = match opts.cornell_grid {
        Some(g) => g,
        None => {
            regular = regular_cornell_grid();
            &regular
        }
    };
    let cornell = model_to_cornell(
        &fit.model,
        grid,
        &format!("skinbrdf {} fit of {}", fit.model_name, opts.source_label),
    );
    let brdf_path = dir.join("model.brdf");
    cornell.write(&brdf_path)?;
    let mut files = vec![brdf_path];
    if opts.merl {
        let merl_path = dir.join("model.binary");
        write_merl(&merl_path, &fit.model)?;
        files.push(merl_path);
    }
    Ok(Exported {
        files,
        run_time_s: t.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_core::BrdfAngles;

    #[test]
    fn merl_directions_have_the_requested_half_difference_angles() {
        for (th, td, pd) in [(0.3, 0.5, 1.0), (0.1, 1.2, 2.5), (0.7, 0.2, 0.3)] {
            let (wi, we) = merl_directions(th, td, pd);
            let a = BrdfAngles::from_local(wi, we);
            assert!((a.theta_h_rad - th).abs() < 1e-9);
            assert!((a.theta_diff_rad - td).abs() < 1e-9);
            assert!(
                (a.phi_diff_rad - pd).abs() < 1e-9
                    || (a.phi_diff_rad - (pd - std::f64::consts::PI)).abs() < 1e-9
            );
        }
    }

    #[test]
    fn merl_file_has_the_standard_layout_and_scales() {
        let model = BrdfModel::Lambertian {
            albedo: [0.5, 0.25, 0.1],
        };
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("m.binary");
        write_merl(&p, &model).expect("write");
        let bytes = std::fs::read(&p).expect("read");
        let n = 90 * 90 * 180;
        assert_eq!(bytes.len(), 12 + 3 * n * 8);
        let dims: Vec<i32> = (0..3)
            .map(|k| i32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().expect("4")))
            .collect();
        assert_eq!(dims, [90, 90, 180]);
        let at = |c: usize, idx: usize| {
            let o = 12 + 8 * (c * n + idx);
            f64::from_le_bytes(bytes[o..o + 8].try_into().expect("8")) * MERL_SCALE[c]
        };
        // theta_h = 0, theta_d = 10 bins, phi_d = 90 bins: a valid direction.
        let idx = 90 + 180 * 10;
        for (c, a) in [0.5, 0.25, 0.1].iter().enumerate() {
            assert!((at(c, idx) - a / std::f64::consts::PI).abs() < 1e-12);
        }
    }

    #[test]
    fn cornell_export_round_trips_model_values() {
        let model = BrdfModel::Lambertian {
            albedo: [0.5, 0.25, 0.1],
        };
        let grid = regular_cornell_grid();
        let c = model_to_cornell(&model, &grid, "test");
        let back = CornellBrdf::parse(&c.to_text(), Path::new("x")).expect("parse");
        assert_eq!(back.samples.len(), grid.samples.len());
        assert!((back.samples[5].values[0] - 0.5 / std::f64::consts::PI).abs() < 1e-6);
    }
}
