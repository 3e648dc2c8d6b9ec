//! `skinbrdf derender`: the text report of one derendering.

use std::path::Path;

use skinbrdf_derender::calibrate::CEstimator;
use skinbrdf_derender::{DerenderConfig, DerenderReport, SessionRun};

/// The report on stdout: counts, bounds, shadow rays, normals, C, times, errors against the
/// truth and the samples file.
pub fn text(session_dir: &Path, run: &SessionRun, cfg: &DerenderConfig, samples_file: &Path) {
    let r = &run.report;
    let c = &r.counts;
    println!(
        "derender {}: {} measurement images, {} triangles, poses from {}",
        session_dir.display(),
        r.images.len(),
        run.triangles,
        r.pose_source
    );
    if let Some(m) = &run.mesh_report {
        println!("  scan: {}", m.summary());
    }
    println!(
        "  samples kept {} of {} pixels considered ({} primary rays; {} pixels of the projected region)",
        c.kept, c.considered, r.primary_rays, r.region_pixels
    );
    for (reason, n) in c.reasons() {
        if n > 0 {
            println!("    dropped {reason:<18} {n}");
        }
    }
    geometry(r, cfg);
    calibration(run);
    times(r, cfg);
    truth(r);
    println!("  wrote {}", samples_file.display());
}

/// The grazing bound, the shadow rays and the normals.
fn geometry(r: &DerenderReport, cfg: &DerenderConfig) {
    println!(
        "  grazing bound: theta_i, theta_e < {}° (1/cos theta <= {:.2})",
        cfg.grazing_limit_deg,
        1.0 / cfg.grazing_limit_deg.to_radians().cos()
    );
    println!(
        "  shadow rays: {} ({})",
        if r.shadow_rays { "cast" } else { "skipped" },
        if r.region_can_self_shadow {
            format!(
                "geometry can shadow the region; {} rays",
                r.shadow_rays_cast
            )
        } else {
            "region is convex: nothing can shadow it".to_string()
        }
    );
    println!(
        "  normals: {}, radius {:.2} mm",
        cfg.normals,
        r.normal_radius_m * 1e3
    );
}

fn calibration(run: &SessionRun) {
    let r = &run.report;
    match &r.calibration {
        Some(cal) => println!(
            "  C = [{:.5}, {:.5}, {:.5}] from {} standard pixels ({}); relative spread (MAD sigma) [{:.2}%, {:.2}%, {:.2}%]",
            cal.c[0],
            cal.c[1],
            cal.c[2],
            cal.pixels,
            match cal.estimator {
                CEstimator::Median => "median",
                CEstimator::TrimmedMean => "trimmed mean",
            },
            cal.rel_spread[0] * 100.0,
            cal.rel_spread[1] * 100.0,
            cal.rel_spread[2] * 100.0
        ),
        None => println!(
            "  C = [{:.5}, {:.5}, {:.5}] ({})",
            r.c[0], r.c[1], r.c[2], run.c_source
        ),
    }
}

fn times(r: &DerenderReport, cfg: &DerenderConfig) {
    let t = &r.times;
    println!(
        "  time: mesh {:.3} s, bvh ({}) {:.3} s, normals {:.3} s, convexity {:.3} s, images {:.3} s, C {:.3} s, rays+samples {:.3} s (of which primary rays {:.3} s), total {:.3} s",
        t.mesh_load_s, cfg.bvh_quality.name(), t.bvh_s, t.normals_s, t.convexity_s, t.image_load_s, t.calibration_s, t.derender_s, t.rays_s, t.total_s
    );
    if t.derender_s > 0.0 && t.rays_s > 0.0 {
        println!(
            "  throughput: {:.2} M primary rays/s traced, {:.2} M pixels/s derendered (rays + samples)",
            r.primary_rays as f64 / t.rays_s / 1e6,
            r.primary_rays as f64 / t.derender_s / 1e6
        );
    }
}

fn truth(r: &DerenderReport) {
    let Some(e) = &r.truth_error else {
        return;
    };
    // A channel the true BRDF is zero in has no relative error: "-".
    let rgb = e
        .median_rel_error_rgb
        .map(|m| m.map_or_else(|| "-".to_string(), |m| format!("{:.3}%", m * 100.0)));
    println!(
        "  vs truth: median relative error {:.3}% (p90 {:.3}%, bias {:+.3}%, RGB [{}, {}, {}]) over {} samples",
        e.median_rel_error * 100.0,
        e.p90_rel_error * 100.0,
        e.median_signed_rel_error * 100.0,
        rgb[0],
        rgb[1],
        rgb[2],
        e.samples
    );
}
