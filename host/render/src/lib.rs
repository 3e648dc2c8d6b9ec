//! Ray-traced renderings of a head mesh lit by a point light, once with a Lambertian BRDF of the
//! measured albedo and once with the measured (fitted) BRDF, side by side: the method's
//! Figures 7 and 10.
//!
//! ## What is computed
//!
//! A pinhole camera looks at the mesh's bounding-sphere centre from [`RenderConfig::view_dir`]
//! (mesh frame; the synthetic head's face looks along +y). Each pixel is sampled on a regular
//! `s x s` grid ([`RenderConfig::supersample`]); every sample's primary ray is traced through
//! [`skinbrdf_mesh::MeshBvh`] (obvhs) and a shadow ray goes from the hit towards the point light. The light
//! sits at [`RenderConfig::light_distance_rel`] bounding radii from the centre, rotated from the
//! camera direction by [`RenderConfig::light_azimuth_deg`] about the up axis and raised by
//! [`RenderConfig::light_elevation_deg`] (0, 0 = a flash at the camera's side of the head).
//!
//! The reflected radiance of a lit sample is, per channel,
//!
//! ```text
//! L = f_r(w_i, w_e) I cos(theta_i) / d^2
//! ```
//!
//! with `I` chosen so that the irradiance at the centre's distance is 1 (`I = d_c^2`),
//! `w_i`, `w_e` expressed in the shading frame of the interpolated vertex normal (the BRDF
//! models are isotropic, so the tangent's direction does not matter). A sample whose shadow
//! ray hits the mesh, or whose shading normal faces away from the light, gets 0: there is no
//! ambient term, so shadows are black, as under a flash in a dark room.
//!
//! The **Lambertian** panel uses `f_r = a / pi` with `a` the measured model's directional
//! albedo at normal incidence ([`directional_albedo`], stratified quadrature in `sin^2 theta_e`
//! and `phi`; exact for a Lambertian model), so both panels reflect the same total energy under
//! frontal light and differ only in its angular distribution. The **measured** panel uses the
//! model itself ([`BrdfModel::eval`]).
//!
//! Both panels share one exposure (auto: the 99th percentile of the Lambertian panel's lit
//! luminance maps to 0.8) and one tone curve (extended Reinhard with white point 4, then the
//! sRGB transfer function), so brightness differences between the panels are real.
//!
//! ## Guarantees (tested)
//!
//! * A sphere rendered Lambertian follows the analytic cosine law `a/pi cos(theta_i) I / d^2`
//!   (to the tessellation's normal error).
//! * Points an occluder hides from the light are black; the same points without it are lit.
//! * With a strong forward lobe, the measured panel is brighter than the Lambertian one at the
//!   highlight and darker away from it.

mod scene;
mod tonemap;

pub use scene::{directional_albedo, Camera, RenderedPair, Scene};
pub use tonemap::{compose_side_by_side, tone_map, ToneMap};

use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::{Deserialize, Serialize};
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::TriMesh;

/// Errors of the renderer; each names the field or file and the problem.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A configuration value is out of range.
    #[error("render config: {field}: {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The mesh cannot be traced.
    #[error("mesh")]
    Mesh(#[from] skinbrdf_mesh::MeshError),
    /// The model is invalid.
    #[error("model")]
    Model(#[from] skinbrdf_brdf::BrdfError),
    /// An input file is missing or malformed.
    #[error("{path}: {problem}")]
    Input {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// Writing an output failed.
    #[error("{path}: {problem}")]
    Output {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        problem: String,
    },
}

/// Which shading normals the renderer interpolates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum NormalSource {
    /// The mesh's own vertex normals when it has them, else a plane fit over the scan's noise
    /// radius (a raw scan's face normals are too noisy to shade with).
    #[default]
    Auto,
    /// Area-weighted vertex normals (ignore the file's).
    Vertex,
    /// Plane fit with a radius from the scan's noise (noisy scans).
    PlanarFit,
}

/// How a rendering is made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderConfig {
    /// Width of one panel, pixels.
    pub width_px: u32,
    /// Height of one panel, pixels.
    pub height_px: u32,
    /// Samples per pixel along each axis (`s^2` rays per pixel).
    pub supersample: u32,
    /// Direction from the mesh centre towards the camera, mesh frame.
    pub view_dir: [f64; 3],
    /// Up direction of the image, mesh frame (made orthogonal to `view_dir`).
    pub up: [f64; 3],
    /// Vertical field of view, degrees.
    pub fov_y_deg: f64,
    /// Camera distance in bounding radii from the centre.
    pub camera_distance_rel: f64,
    /// Light rotation about the up axis from the camera direction, degrees (positive = to the
    /// image's right).
    pub light_azimuth_deg: f64,
    /// Light elevation above the camera's horizontal plane, degrees.
    pub light_elevation_deg: f64,
    /// Light distance in bounding radii from the centre.
    pub light_distance_rel: f64,
    /// Linear exposure multiplier; `None` = automatic (shared by both panels).
    pub exposure: Option<f64>,
    /// Shading normals.
    pub normals: NormalSource,
    /// Panel labels (Lambertian, measured).
    pub labels: [String; 2],
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            width_px: 480,
            height_px: 560,
            supersample: 2,
            view_dir: [0.0, 1.0, 0.0],
            up: [0.0, 0.0, 1.0],
            fov_y_deg: 30.0,
            camera_distance_rel: 4.0,
            light_azimuth_deg: 35.0,
            light_elevation_deg: 25.0,
            light_distance_rel: 6.0,
            exposure: None,
            normals: NormalSource::Auto,
            labels: [
                "Lambertian (measured albedo)".into(),
                "Measured BRDF".into(),
            ],
        }
    }
}

/// Pixel budget above which a rendering is refused (keeps a typo from allocating gigabytes).
pub const MAX_SAMPLES_PER_PANEL: u64 = 64_000_000;

impl RenderConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), RenderError> {
        let bad = |field, reason: &str| {
            Err(RenderError::InvalidConfig {
                field,
                reason: reason.to_owned(),
            })
        };
        if self.width_px == 0 || self.height_px == 0 {
            return bad("width_px/height_px", "must be positive");
        }
        if !(1..=8).contains(&self.supersample) {
            return bad("supersample", "must be in 1..=8");
        }
        let n = u64::from(self.width_px)
            * u64::from(self.height_px)
            * u64::from(self.supersample).pow(2);
        if n > MAX_SAMPLES_PER_PANEL {
            return bad(
                "width_px/height_px/supersample",
                &format!("{n} rays per panel exceed {MAX_SAMPLES_PER_PANEL}"),
            );
        }
        let v = DVec3::from(self.view_dir);
        let u = DVec3::from(self.up);
        if !v.is_finite() || v.length() < 1e-9 {
            return bad("view_dir", "must be a finite non-zero vector");
        }
        if !u.is_finite() || v.normalize().cross(u).length() < 1e-6 {
            return bad("up", "must be finite and not parallel to view_dir");
        }
        if !(self.fov_y_deg > 1.0 && self.fov_y_deg < 170.0) {
            return bad("fov_y_deg", "must be in (1, 170)");
        }
        if !(self.camera_distance_rel.is_finite() && self.camera_distance_rel > 1.0) {
            return bad(
                "camera_distance_rel",
                "must exceed 1 (the camera outside the bounding sphere)",
            );
        }
        if !(self.light_distance_rel.is_finite() && self.light_distance_rel > 1.0) {
            return bad(
                "light_distance_rel",
                "must exceed 1 (the light outside the bounding sphere)",
            );
        }
        if !(self.light_azimuth_deg.is_finite() && self.light_elevation_deg.abs() <= 90.0) {
            return bad(
                "light_azimuth_deg/light_elevation_deg",
                "must be finite, elevation within +-90",
            );
        }
        if let Some(e) = self.exposure {
            if !(e.is_finite() && e > 0.0) {
                return bad("exposure", "must be finite and positive");
            }
        }
        Ok(())
    }
}

/// The two renderings, the composed 8-bit image and what they cost.
#[derive(Debug, Clone)]
pub struct ComparisonImage {
    /// Linear radiance of both panels.
    pub pair: RenderedPair,
    /// The exposure used (linear multiplier).
    pub exposure: f64,
    /// Lambertian albedo used for the left panel (the model's directional albedo).
    pub lambertian_albedo: [f64; 3],
    /// Side-by-side, tone-mapped, labelled image (RGB8).
    pub image: image::RgbImage,
    /// Statistics of the run.
    pub stats: RenderStats,
}

/// Cost and coverage of a rendering.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RenderStats {
    /// Triangles traced.
    pub triangles: usize,
    /// Primary plus shadow rays.
    pub rays: u64,
    /// Fraction of primary rays that hit the mesh.
    pub hit_fraction: f64,
    /// Fraction of hits that are in shadow (occluded or facing away from the light).
    pub shadowed_fraction: f64,
    /// BVH build time, seconds.
    pub bvh_build_s: f64,
    /// Tracing and shading time, seconds.
    pub trace_s: f64,
    /// Tone mapping, composing and labelling, seconds.
    pub compose_s: f64,
}

/// Renders `mesh` with a Lambertian BRDF of `model`'s directional albedo and with `model`,
/// tone-maps both with one exposure and composes them side by side with labels.
pub fn render_comparison(
    mesh: &TriMesh,
    model: &BrdfModel,
    cfg: &RenderConfig,
) -> Result<ComparisonImage, RenderError> {
    cfg.validate()?;
    model.validate()?;
    let scene = Scene::new(mesh, cfg)?;
    let albedo = directional_albedo(model);
    let lambertian = BrdfModel::Lambertian { albedo };
    let t = std::time::Instant::now();
    let pair = scene.render_pair(&lambertian, model);
    let trace_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let exposure = cfg
        .exposure
        .unwrap_or_else(|| tonemap::auto_exposure(&pair.left));
    let tm = ToneMap::new(exposure);
    let left = tone_map(&pair.left, pair.width_px, pair.height_px, &tm);
    let right = tone_map(&pair.right, pair.width_px, pair.height_px, &tm);
    let image = compose_side_by_side(&left, &right, &cfg.labels)?;
    let stats = RenderStats {
        triangles: mesh.indices.len(),
        rays: pair.rays,
        hit_fraction: pair.hit_fraction,
        shadowed_fraction: pair.shadowed_fraction,
        bvh_build_s: scene.bvh_build_s(),
        trace_s,
        compose_s: t.elapsed().as_secs_f64(),
    };
    Ok(ComparisonImage {
        pair,
        exposure,
        lambertian_albedo: albedo,
        image,
        stats,
    })
}

impl ComparisonImage {
    /// Writes `stem.png` (the composed image) and `stem.svg` (the same image referenced by file
    /// name, with its size and labels as text), both atomically. Returns their paths.
    pub fn write(&self, stem: &Path, labels: &[String; 2]) -> Result<Vec<PathBuf>, RenderError> {
        let png = stem.with_extension("png");
        let svg = stem.with_extension("svg");
        let out_err = |path: &Path, problem: String| RenderError::Output {
            path: path.to_path_buf(),
            problem,
        };
        let mut bytes = Vec::new();
        self.image
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .map_err(|e| out_err(&png, e.to_string()))?;
        skinbrdf_samples::write_atomic(&png, |w| w.write_all(&bytes))
            .map_err(|e| out_err(&png, e.to_string()))?;
        let name = png
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or_else(|| out_err(&png, "no file name".into()))?;
        let (w, h) = self.image.dimensions();
        let esc = |s: &str| {
            s.replace('&', "&amp;")
                .replace('<', "&lt;")
                .replace('>', "&gt;")
                .replace('"', "&quot;")
        };
        let text = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" xmlns:xlink=\"http://www.w3.org/1999/xlink\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\">\n\
             <title>{} | {}</title>\n\
             <image x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" href=\"{n}\" xlink:href=\"{n}\"/>\n\
             </svg>\n",
            esc(&labels[0]),
            esc(&labels[1]),
            n = esc(&name),
        );
        skinbrdf_samples::write_atomic(&svg, |w| w.write_all(text.as_bytes()))
            .map_err(|e| out_err(&svg, e.to_string()))?;
        Ok(vec![png, svg])
    }
}

/// Reads a BRDF model from JSON: a bare [`BrdfModel`], a `skinbrdf fit` `params.json` (its
/// `fit.model`), or a `truth.json` (its `brdf`).
pub fn load_model(path: &Path) -> Result<BrdfModel, RenderError> {
    let err = |problem: String| RenderError::Input {
        path: path.to_path_buf(),
        problem,
    };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| err(format!("not JSON: {e}")))?;
    for pointer in ["", "/fit/model", "/model", "/brdf"] {
        if let Some(v) = value.pointer(pointer) {
            if let Ok(m) = serde_json::from_value::<BrdfModel>(v.clone()) {
                m.validate().map_err(|e| err(e.to_string()))?;
                return Ok(m);
            }
        }
    }
    Err(err(
        "no BRDF model found (expected a model object with a `model` tag, or one at `fit.model` or `brdf`)"
            .into(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use skinbrdf_brdf::{ChannelModel, LafortuneFit};
    use skinbrdf_mesh::shapes::uv_sphere;

    const R: f64 = 0.1;

    fn small_cfg(light_az: f64, light_el: f64) -> RenderConfig {
        RenderConfig {
            width_px: 64,
            height_px: 64,
            supersample: 1,
            light_azimuth_deg: light_az,
            light_elevation_deg: light_el,
            // An ideal tessellated sphere: its vertex normals are the analytic ones.
            normals: NormalSource::Vertex,
            ..RenderConfig::default()
        }
    }

    /// First intersection of a ray with a sphere, or `None`.
    fn ray_sphere(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<f64> {
        let oc = o - c;
        let b = oc.dot(d);
        let disc = b * b - (oc.length_squared() - r * r);
        (disc >= 0.0).then(|| -b - disc.sqrt()).filter(|t| *t > 0.0)
    }

    fn merged(a: TriMesh, b: TriMesh) -> TriMesh {
        let off = a.positions.len() as u32;
        let mut m = a;
        m.positions.extend(b.positions);
        m.indices
            .extend(b.indices.iter().map(|t| t.map(|i| i + off)));
        m.normals = None;
        m
    }

    #[test]
    fn a_lambertian_sphere_follows_the_cosine_law() {
        let mesh = uv_sphere(DVec3::ZERO, R, 96, 192);
        let cfg = small_cfg(40.0, 20.0);
        let albedo = [0.5, 0.4, 0.3];
        let scene = Scene::new(&mesh, &cfg).expect("scene");
        let lam = BrdfModel::Lambertian { albedo };
        let pair = scene.render_pair(&lam, &lam);
        let cam = scene.camera;
        let (mut lit, mut dark) = (0, 0);
        for y in 0..cam.height_px {
            for x in 0..cam.width_px {
                let d = cam.ray_dir(f64::from(x) + 0.5, f64::from(y) + 0.5);
                let Some(t) = ray_sphere(cam.position, d, DVec3::ZERO, R) else {
                    continue;
                };
                let p = cam.position + t * d;
                let n = p.normalize();
                // Skip the silhouette (tessellation error is largest there).
                if n.dot(-d) < 0.2 {
                    continue;
                }
                let to = scene.light_m - p;
                let cos = n.dot(to.normalize());
                let got = pair.left[(y * cam.width_px + x) as usize];
                if cos > 0.1 {
                    for c in 0..3 {
                        let want = albedo[c] / std::f64::consts::PI * scene.intensity * cos
                            / to.length_squared();
                        let rel = (f64::from(got[c]) - want).abs() / want;
                        assert!(rel < 0.02, "({x},{y}) c{c}: {} vs {want}", got[c]);
                    }
                    lit += 1;
                } else if cos < -0.05 {
                    assert_eq!(got, [0.0; 3], "({x},{y}) faces away from the light");
                    dark += 1;
                }
            }
        }
        assert!(lit > 800 && dark > 200, "lit {lit} dark {dark}");
    }

    #[test]
    fn points_an_occluder_hides_from_the_light_are_black() {
        // The light direction for azimuth 30, elevation 20 seen from +y (image right = -x).
        let (sa, ca) = 30f64.to_radians().sin_cos();
        let (se, ce) = 20f64.to_radians().sin_cos();
        let dir = DVec3::new(-ce * sa, ce * ca, se);
        let occ_c = dir * (R + 0.06);
        let occ_r = 0.03;
        let mesh = merged(
            uv_sphere(DVec3::ZERO, R, 64, 128),
            uv_sphere(occ_c, occ_r, 32, 64),
        );
        let cfg = small_cfg(30.0, 20.0);
        let scene = Scene::new(&mesh, &cfg).expect("scene");
        let lam = BrdfModel::Lambertian { albedo: [0.6; 3] };
        let pair = scene.render_pair(&lam, &lam);
        let cam = scene.camera;
        let (mut shadowed, mut lit) = (0, 0);
        for y in 0..cam.height_px {
            for x in 0..cam.width_px {
                let d = cam.ray_dir(f64::from(x) + 0.5, f64::from(y) + 0.5);
                let Some(t) = ray_sphere(cam.position, d, DVec3::ZERO, R) else {
                    continue;
                };
                // Seen past the occluder's silhouette, with a margin for tessellation.
                if ray_sphere(cam.position, d, occ_c, occ_r * 1.1).is_some() {
                    continue;
                }
                let p = cam.position + t * d;
                let to = scene.light_m - p;
                let l = to.normalize();
                if p.normalize().dot(l) < 0.2 || p.normalize().dot(-d) < 0.2 {
                    continue;
                }
                let got = pair.left[(y * cam.width_px + x) as usize];
                if ray_sphere(p, l, occ_c, occ_r * 0.9).is_some() {
                    assert_eq!(got, [0.0; 3], "({x},{y}) should be in the shadow");
                    shadowed += 1;
                } else if ray_sphere(p, l, occ_c, occ_r * 1.1).is_none() {
                    let want = 0.6 / std::f64::consts::PI * scene.intensity * p.normalize().dot(l)
                        / to.length_squared();
                    assert!(
                        f64::from(got[0]) > 0.9 * want,
                        "({x},{y}) should be lit: {got:?} vs {want}"
                    );
                    lit += 1;
                }
            }
        }
        assert!(shadowed > 30 && lit > 300, "shadowed {shadowed} lit {lit}");
        assert!(pair.shadowed_fraction > 0.0);
    }

    #[test]
    fn the_measured_rendering_differs_where_the_lobe_is_strong() {
        let mesh = uv_sphere(DVec3::ZERO, R, 96, 192);
        // Diffuse 0.3 plus a forward lobe (albedo 0.5, exponent 60): the highlight of a light
        // next to the camera is at the sphere's centre in the image.
        let lobe = LafortuneFit::standard(1)
            .to_model(&std::array::from_fn(|_| {
                vec![0.3, 0.5f64.ln(), -1.0, 60f64.ln()]
            }))
            .expect("model");
        let cfg = small_cfg(0.0, 0.0);
        let out = render_comparison(&mesh, &lobe, &cfg).expect("render");
        let w = out.pair.width_px as usize;
        let lum = |c: [f32; 3]| f64::from(c[0] + c[1] + c[2]);
        let centre = (w / 2) * w + w / 2;
        let (l, m) = (lum(out.pair.left[centre]), lum(out.pair.right[centre]));
        assert!(m > 2.0 * l, "highlight: measured {m} vs Lambertian {l}");
        // Near the limb the lobe contributes nothing: the measured image is darker there
        // (the Lambertian albedo carries the lobe's energy too).
        let mut darker = 0;
        for x in 0..w {
            let i = (w / 2) * w + x;
            if out.pair.coverage[i] == 1.0 && lum(out.pair.left[i]) > 0.0 {
                let (a, b) = (lum(out.pair.left[i]), lum(out.pair.right[i]));
                if b < 0.9 * a {
                    darker += 1;
                }
            }
        }
        assert!(darker >= 6, "only {darker} darker limb pixels");
        // The Lambertian albedo is the directional albedo at normal incidence: diffuse plus the
        // lobe's (a mirror lobe at normal incidence is a lobe about the normal, whose albedo is
        // exactly A = 0.5 in the normalised-Phong parametrisation).
        for a in out.lambertian_albedo {
            assert!((a - 0.8).abs() < 0.01, "{a}");
        }
        assert_eq!(
            out.image.dimensions(),
            (2 * 64 + 6, 64 + 30),
            "two panels, a gap and a label strip"
        );
    }

    #[test]
    fn outputs_are_written_and_models_are_read_from_fit_results() {
        let dir = tempfile::tempdir().expect("tmp");
        let model = BrdfModel::Lambertian {
            albedo: [0.5, 0.4, 0.3],
        };
        let fit_like = serde_json::json!({ "input": "x", "fit": { "model": model } });
        let p = dir.path().join("params.json");
        std::fs::write(&p, fit_like.to_string()).expect("write");
        assert_eq!(load_model(&p).expect("load"), model);
        let bad = dir.path().join("bad.json");
        std::fs::write(&bad, "{\"fit\": 3}").expect("write");
        let e = load_model(&bad).expect_err("no model");
        assert!(e.to_string().contains("bad.json"), "{e}");

        let mesh = uv_sphere(DVec3::ZERO, R, 24, 48);
        let cfg = RenderConfig {
            width_px: 40,
            height_px: 30,
            ..RenderConfig::default()
        };
        let out = render_comparison(&mesh, &model, &cfg).expect("render");
        let files = out
            .write(&dir.path().join("head_comparison"), &cfg.labels)
            .expect("write");
        let png = image::open(&files[0]).expect("png").to_rgb8();
        assert_eq!(png.dimensions(), (86, 60));
        let svg = std::fs::read_to_string(&files[1]).expect("svg");
        assert!(svg.contains("href=\"head_comparison.png\""), "{svg}");
        // Both panels of a Lambertian model are identical.
        assert_eq!(out.pair.left, out.pair.right);
        assert!(out.stats.hit_fraction > 0.05 && out.stats.rays > 40 * 30 * 4);
    }

    #[test]
    fn bad_configurations_are_named() {
        let mesh = uv_sphere(DVec3::ZERO, R, 8, 16);
        let model = BrdfModel::Lambertian { albedo: [0.5; 3] };
        for (cfg, field) in [
            (
                RenderConfig {
                    width_px: 0,
                    ..RenderConfig::default()
                },
                "width_px",
            ),
            (
                RenderConfig {
                    up: [0.0, 2.0, 0.0],
                    ..RenderConfig::default()
                },
                "up",
            ),
            (
                RenderConfig {
                    light_distance_rel: 0.5,
                    ..RenderConfig::default()
                },
                "light_distance_rel",
            ),
        ] {
            let e = render_comparison(&mesh, &model, &cfg).expect_err("invalid");
            assert!(e.to_string().contains(field), "{e}");
        }
        let empty = TriMesh {
            positions: vec![Vec3::ZERO],
            indices: vec![],
            normals: None,
        };
        assert!(render_comparison(&empty, &model, &RenderConfig::default()).is_err());
    }
}
