//! Coverage figures, like the method's Figures 4 and 5.
//!
//! * [`pixels_used_rgb8`]: the pixels that became samples, overlaid in green on a tone-mapped
//!   grey copy of the image (Figure 4).
//! * [`hemisphere_svg`] / [`hemisphere_rgb8`]: the exitant hemisphere for a chosen incident
//!   angle θ_i (Figure 5). A sample is drawn at polar radius θ_e / 90° and azimuth φ_d, the
//!   light's side (φ_d = 0, retro-reflection) on the left and the mirror side (φ_d = π) on the
//!   right, mirrored top/bottom (isotropy). Samples with θ_i within the tolerance are blue;
//!   **reciprocal** samples — θ_e within the tolerance, so light and camera swap roles
//!   (Helmholtz reciprocity) — are drawn at (θ_i, φ_d) in orange.

use std::fmt::Write as _;

use skinbrdf_core::BrdfSample;

use crate::image::ImageView;

/// Green overlay of the used pixels of image `image_index` on a grey copy of the image
/// (`sqrt` tone map, scaled to the 99th percentile). Returns RGB8, row-major.
pub fn pixels_used_rgb8(
    image: &ImageView<'_>,
    samples: &[BrdfSample],
    image_index: u16,
) -> Vec<u8> {
    let n = image.rgb.len();
    // A photosite image shows each photosite's own channel (a mosaic of grey levels).
    let mut lum: Vec<f32> = image
        .rgb
        .iter()
        .map(|p| match image.cfa {
            Some(_) => p
                .iter()
                .copied()
                .find(|v| !v.is_nan())
                .unwrap_or(0.0)
                .max(0.0),
            None => (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).max(0.0),
        })
        .collect();
    let mut sorted: Vec<f32> = lum.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let p99 = sorted
        .get((sorted.len() as f64 * 0.99) as usize)
        .copied()
        .unwrap_or(1.0)
        .max(1e-6);
    for v in &mut lum {
        *v = (*v / p99).clamp(0.0, 1.0).sqrt();
    }
    let mut out = Vec::with_capacity(n * 3);
    for v in &lum {
        let g = (v * 200.0) as u8;
        out.extend_from_slice(&[g, g, g]);
    }
    let w = image.width as usize;
    for s in samples.iter().filter(|s| s.image_index == image_index) {
        let i = s.pixel[1] as usize * w + s.pixel[0] as usize;
        if i < n {
            let g = lum[i];
            out[3 * i] = (g * 60.0) as u8;
            out[3 * i + 1] = 120 + (g * 135.0) as u8;
            out[3 * i + 2] = (g * 60.0) as u8;
        }
    }
    out
}

/// The points of the hemisphere figure: `(x, y, reciprocal)` in the unit disc.
pub fn hemisphere_points(
    samples: &[BrdfSample],
    theta_i_deg: f64,
    tol_deg: f64,
) -> Vec<(f64, f64, bool)> {
    let ti = theta_i_deg.to_radians();
    let tol = tol_deg.to_radians();
    let half_pi = std::f64::consts::FRAC_PI_2;
    let mut pts = Vec::new();
    for s in samples {
        let (a, b, phi) = (
            s.theta_i_rad as f64,
            s.theta_e_rad as f64,
            s.phi_d_rad as f64,
        );
        let (r, reciprocal) = if (a - ti).abs() <= tol {
            (b / half_pi, false)
        } else if (b - ti).abs() <= tol {
            (a / half_pi, true)
        } else {
            continue;
        };
        let x = -r * phi.cos();
        let y = r * phi.sin();
        pts.push((x, y, reciprocal));
        pts.push((x, -y, reciprocal));
    }
    pts
}

/// The hemisphere figure as SVG text.
pub fn hemisphere_svg(samples: &[BrdfSample], theta_i_deg: f64, tol_deg: f64) -> String {
    let size = 520.0;
    let c = size / 2.0;
    let r0 = 230.0;
    let pts = hemisphere_points(samples, theta_i_deg, tol_deg);
    let direct = pts.iter().filter(|p| !p.2).count() / 2;
    let recip = pts.len() / 2 - direct;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{}" viewBox="0 0 {size} {}">"#,
        size + 40.0,
        size + 40.0
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    for deg in [30.0, 60.0, 90.0] {
        let _ = writeln!(
            s,
            r##"<circle cx="{c}" cy="{c}" r="{:.1}" fill="none" stroke="#999" stroke-width="1"/>"##,
            r0 * deg / 90.0
        );
    }
    let _ = writeln!(
        s,
        r##"<line x1="{}" y1="{c}" x2="{}" y2="{c}" stroke="#999"/>"##,
        c - r0,
        c + r0
    );
    // Light direction marker on the retro side.
    let lx = c - r0 * theta_i_deg / 90.0;
    let _ = writeln!(
        s,
        r##"<circle cx="{lx:.1}" cy="{c}" r="6" fill="none" stroke="#d00" stroke-width="2"/>"##
    );
    for (x, y, recip) in &pts {
        let fill = if *recip { "#f80" } else { "#15c" };
        let _ = writeln!(
            s,
            r#"<circle cx="{:.1}" cy="{:.1}" r="1.2" fill="{fill}" fill-opacity="0.5"/>"#,
            c + x * r0,
            c - y * r0
        );
    }
    let _ = writeln!(
        s,
        r##"<text x="10" y="{}" font-family="sans-serif" font-size="13">θi = {theta_i_deg}° ± {tol_deg}°: {direct} samples (blue), {recip} reciprocal (orange); rings θe = 30/60/90°, light ○ left (retro), mirror side right</text>"##,
        size + 25.0
    );
    s.push_str("</svg>\n");
    s
}

/// The hemisphere figure rasterized (RGB8, `size` x `size`).
pub fn hemisphere_rgb8(
    samples: &[BrdfSample],
    theta_i_deg: f64,
    tol_deg: f64,
    size: u32,
) -> Vec<u8> {
    let mut img = vec![255u8; (size * size * 3) as usize];
    let c = size as f64 / 2.0;
    let r0 = c * 0.9;
    let mut put = |x: f64, y: f64, rgb: [u8; 3]| {
        let (px, py) = (x.round(), y.round());
        if px >= 0.0 && py >= 0.0 && px < size as f64 && py < size as f64 {
            let i = ((py as u32 * size + px as u32) * 3) as usize;
            img[i..i + 3].copy_from_slice(&rgb);
        }
    };
    for deg in [30.0, 60.0, 90.0] {
        let r = r0 * deg / 90.0;
        for k in 0..2000 {
            let a = std::f64::consts::TAU * k as f64 / 2000.0;
            put(c + r * a.cos(), c + r * a.sin(), [150, 150, 150]);
        }
    }
    for (x, y, recip) in hemisphere_points(samples, theta_i_deg, tol_deg) {
        let rgb = if recip { [255, 136, 0] } else { [17, 85, 204] };
        put(c + x * r0, c - y * r0, rgb);
    }
    let lx = c - r0 * theta_i_deg / 90.0;
    for k in 0..200 {
        let a = std::f64::consts::TAU * k as f64 / 200.0;
        put(lx + 5.0 * a.cos(), c + 5.0 * a.sin(), [220, 0, 0]);
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_core::BrdfAngles;

    #[test]
    fn hemisphere_places_direct_and_reciprocal_samples() {
        let a = BrdfAngles::from_local(
            BrdfAngles::canonical_directions(0.5, 0.9, std::f64::consts::PI).0,
            BrdfAngles::canonical_directions(0.5, 0.9, std::f64::consts::PI).1,
        );
        let direct = BrdfSample::from_angles(&a, [0.1; 3]);
        let b = BrdfAngles::from_local(
            BrdfAngles::canonical_directions(0.9, 0.5, 0.0).0,
            BrdfAngles::canonical_directions(0.9, 0.5, 0.0).1,
        );
        let recip = BrdfSample::from_angles(&b, [0.1; 3]);
        let pts = hemisphere_points(&[direct, recip], 0.5f64.to_degrees(), 1.0);
        assert_eq!(pts.len(), 4);
        // Direct: mirror side (right), radius 0.9 / (pi/2).
        assert!(!pts[0].2 && (pts[0].0 - 0.9 / std::f64::consts::FRAC_PI_2).abs() < 1e-5);
        // Reciprocal: drawn at theta_i = 0.9 on the retro side (left).
        assert!(pts[2].2 && (pts[2].0 + 0.9 / std::f64::consts::FRAC_PI_2).abs() < 1e-5);
        let svg = hemisphere_svg(&[direct, recip], 0.5f64.to_degrees(), 1.0);
        assert!(svg.contains("1 samples (blue), 1 reciprocal"));
        assert_eq!(hemisphere_rgb8(&[direct], 30.0, 2.0, 64).len(), 64 * 64 * 3);
    }

    #[test]
    fn used_pixels_are_green() {
        let rgb = vec![[0.5f32; 3]; 4 * 3];
        let img = ImageView {
            width: 4,
            height: 3,
            rgb: &rgb,
            saturated: None,
            cfa: None,
        };
        let s = BrdfSample {
            image_index: 2,
            pixel: [1, 2],
            ..Default::default()
        };
        let out = pixels_used_rgb8(&img, &[s], 2);
        let i = 3 * (2 * 4 + 1);
        assert!(out[i + 1] > out[i] && out[i + 1] > out[i + 2]);
        assert_eq!(out[0], out[1]);
    }
}
