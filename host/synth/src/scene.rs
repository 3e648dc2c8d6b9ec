//! Scene files: the data a synthetic session is generated from.
//!
//! A scene is a TOML file. The built-in scenes live in the repository's `scenes/` directory and
//! are embedded into the binary ([`BUILTIN_SCENES`]), so `skinbrdf synth --scene default` works
//! from any directory. Every scene is merged on top of `scenes/default.toml`: tables merge key
//! by key, the BRDF tables (`skin`, `standard.brdf`) are replaced as a whole. A user scene thus
//! states only what differs. Unknown keys are errors.

use std::path::Path;

use serde::{Deserialize, Serialize};
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::BrownConrady;

/// The built-in scenes: `(name, TOML text)`.
pub const BUILTIN_SCENES: &[(&str, &str)] = &[
    ("default", include_str!("../../../scenes/default.toml")),
    (
        "studio-faults",
        include_str!("../../../scenes/studio-faults.toml"),
    ),
    ("sphere", include_str!("../../../scenes/sphere.toml")),
    ("cylinder", include_str!("../../../scenes/cylinder.toml")),
    ("oily", include_str!("../../../scenes/oily.toml")),
    (
        "near-mirror",
        include_str!("../../../scenes/near-mirror.toml"),
    ),
    ("grazing", include_str!("../../../scenes/grazing.toml")),
    ("dark-skin", include_str!("../../../scenes/dark-skin.toml")),
    (
        "strong-distortion",
        include_str!("../../../scenes/strong-distortion.toml"),
    ),
    (
        "head-motion",
        include_str!("../../../scenes/head-motion.toml"),
    ),
    (
        "survey-moved",
        include_str!("../../../scenes/survey-moved.toml"),
    ),
    (
        "survey-sheets",
        include_str!("../../../scenes/survey-sheets.toml"),
    ),
    (
        "survey-faults",
        include_str!("../../../scenes/survey-faults.toml"),
    ),
    (
        "survey-images",
        include_str!("../../../scenes/survey-images.toml"),
    ),
    (
        "survey-flash",
        include_str!("../../../scenes/survey-flash.toml"),
    ),
    ("long-lens", include_str!("../../../scenes/long-lens.toml")),
];

/// Largest image side, pixels (a 100-megapixel frame is 12000 px wide).
pub const MAX_SIDE_PX: f64 = 20000.0;
/// Most rays per pixel (32 x 32 strata; the default is 2 x 2).
pub const MAX_SAMPLES_PER_PIXEL: f64 = 1024.0;
/// Most measurement images (the method takes about 30).
pub const MAX_MEASUREMENT_IMAGES: f64 = 1000.0;
/// Most survey images: the survey-shot planner chooses among a few hundred candidate positions,
/// and a few dozen shots already see every reachable target from every direction it offers.
pub const MAX_SURVEY_IMAGES: f64 = 64.0;
/// Most reference targets on one printed sheet (a row of the cage holds about a dozen; a sheet
/// wider than a few targets no longer fits the cage's curve).
pub const MAX_SHEET_TARGETS: f64 = 6.0;
/// Finest render or scan tessellation, metres (0.1 mm: finer than any pixel's footprint).
pub const MIN_SPACING_M: f64 = 1e-4;

/// Errors reading a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// Neither a built-in scene nor a readable file.
    #[error("no built-in scene `{name}` (built-in: {known}) and no file of that name")]
    NotFound {
        /// What was asked for.
        name: String,
        /// The built-in names.
        known: String,
        /// Why the file could not be read.
        source: std::io::Error,
    },
    /// The TOML is malformed or a field is wrong.
    #[error("scene `{origin}`: {problem}")]
    Invalid {
        /// Scene name or file.
        origin: String,
        /// What is wrong (with the field, from the TOML parser).
        problem: String,
    },
}

/// Camera of the scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraScene {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Lens distortion.
    pub distortion: BrownConrady,
}

/// How images are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// 16-bit PNG.
    Png16,
    /// 8-bit PNG.
    Png8,
    /// 32-bit float OpenEXR (linear; curve, black and white levels do not apply).
    Exr,
}

/// Tone curve of stored images.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CurveScene {
    /// Linear.
    Linear,
    /// sRGB.
    Srgb,
    /// Power law with `gamma`.
    Gamma,
}

/// The sensor and image encoding.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorScene {
    /// Jittered rays per pixel (rounded up to a square number of strata).
    pub samples_per_pixel: u32,
    /// Electrons at the white level (shot noise).
    pub full_well_e: f64,
    /// Read noise, linear units.
    pub read_noise: f64,
    /// Stored format.
    pub encoding: Encoding,
    /// Tone curve.
    pub curve: CurveScene,
    /// Exponent for `curve = "gamma"`.
    pub gamma: f64,
    /// Stored code of black.
    pub black_level: f64,
    /// Stored code of white.
    pub white_level: f64,
}

/// Radiometry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RadiometryScene {
    /// Calibration constant C per channel.
    pub calibration_c: [f64; 3],
    /// Room light in light-position and standard-position images: the linear value of a
    /// white Lambertian surface (albedo 1).
    pub ambient: f64,
}

/// Kind of sample geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GeometryKind {
    /// Procedural head with a brow ridge, scanned.
    Head,
    /// Ideal sphere (no scan).
    Sphere,
    /// Ideal vertical cylinder (no scan).
    Cylinder,
}

/// Sample geometry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeometryScene {
    /// Kind.
    pub kind: GeometryKind,
    /// Head semi-axes x, y, z (ear to ear, back to front, down to up), metres.
    pub semi_axes_m: [f64; 3],
    /// Superellipsoid exponent (2 = ellipsoid).
    pub superellipse_exponent: f64,
    /// Brow ridge height, metres.
    pub brow_height_m: f64,
    /// Brow ridge elevation, degrees.
    pub brow_elevation_deg: f64,
    /// Brow ridge width in elevation (Gaussian sigma), degrees.
    pub brow_width_deg: f64,
    /// Brow ridge half extent in azimuth, degrees.
    pub brow_half_azimuth_deg: f64,
    /// Sphere radius, metres.
    pub sphere_radius_m: f64,
    /// Cylinder radius, metres.
    pub cylinder_radius_m: f64,
    /// Cylinder length, metres.
    pub cylinder_length_m: f64,
    /// Tessellation of the true surface, metres.
    pub render_spacing_m: f64,
    /// Scan vertex spacing, metres.
    pub scan_spacing_m: f64,
    /// Scan noise standard deviation, metres.
    pub scan_noise_m: f64,
    /// Units the scan file is written in.
    pub scan_units: skinbrdf_session::LengthUnit,
    /// Elevation of the region of interest's centre, degrees.
    pub roi_elevation_deg: f64,
    /// Radius of the region of interest, metres.
    pub roi_radius_m: f64,
}

/// Session layout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionScene {
    /// Number of measurement images.
    pub measurement_images: u32,
    /// Camera circle radius, metres.
    pub camera_radius_m: f64,
    /// Camera height above the head centre, metres.
    pub camera_height_m: f64,
    /// First camera azimuth, degrees (0 = in front of the face).
    pub arc_start_deg: f64,
    /// Last camera azimuth, degrees.
    pub arc_end_deg: f64,
    /// Random camera placement error, metres.
    pub position_jitter_m: f64,
    /// Random aim error, metres at the head.
    pub aim_jitter_m: f64,
    /// Flash azimuth, degrees.
    pub flash_azimuth_deg: f64,
    /// Flash distance from the head axis, metres.
    pub flash_distance_m: f64,
    /// Flash height above the head centre, metres.
    pub flash_height_m: f64,
    /// Diffuser diameter, metres.
    pub flash_diameter_m: f64,
    /// Head sway amplitude, metres.
    pub head_motion_m: f64,
    /// Head sway amplitude, degrees.
    pub head_motion_deg: f64,
    /// Time between shots, seconds.
    pub shot_interval_s: f64,
    /// Survey images: shots taken before the subject sits (no head, no flash, the room light
    /// on) from positions that see the reference targets the measurement arc sees poorly
    /// ([`crate::survey_shots`]); 0: none.
    #[serde(default)]
    pub survey_images: u32,
}

/// Printed targets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetsScene {
    /// Reference target size (black square), metres.
    pub reference_size_m: f64,
    /// Headdress target size, metres.
    pub headdress_size_m: f64,
    /// Flash target size, metres.
    pub flash_size_m: f64,
    /// Standard target size, metres.
    pub standard_size_m: f64,
    /// Reference cage targets printed per sheet: neighbours along a row in groups of this many
    /// on one flat sheet with a layout file (1: every target a cut-out; see `crate::sheets`).
    pub reference_sheet_targets: u32,
    /// Albedo of the paper (white cells).
    pub paper_albedo: f64,
    /// Albedo of the ink (black cells).
    pub ink_albedo: f64,
}

/// The reflectance standard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StandardScene {
    /// Edge of the square reflecting area, metres.
    pub size_m: f64,
    /// Its BRDF.
    pub brdf: BrdfModel,
}

/// A whole scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Name.
    pub name: String,
    /// What it shows.
    pub description: String,
    /// Random seed.
    pub seed: u64,
    /// Camera.
    pub camera: CameraScene,
    /// Sensor and encoding.
    pub sensor: SensorScene,
    /// Radiometry.
    pub radiometry: RadiometryScene,
    /// The skin's true BRDF.
    pub skin: BrdfModel,
    /// Geometry.
    pub geometry: GeometryScene,
    /// Session layout.
    pub session: SessionScene,
    /// Targets.
    pub targets: TargetsScene,
    /// Reflectance standard.
    pub standard: StandardScene,
    /// The synthetic studio (`synth --studio`).
    pub studio: crate::studio::StudioScene,
}

/// Keys whose tables are replaced, not merged.
const REPLACED: &[&str] = &["skin", "brdf"];

fn merge(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o))
                if !REPLACED.contains(&k.as_str()) =>
            {
                merge(b, o)
            }
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

impl Scene {
    /// Parses a scene (merged over the default scene) and validates it.
    pub fn from_toml(text: &str, origin: &str) -> Result<Scene, SceneError> {
        let invalid = |problem: String| SceneError::Invalid {
            origin: origin.to_string(),
            problem,
        };
        let mut base: toml::Table = BUILTIN_SCENES[0]
            .1
            .parse()
            .map_err(|e: toml::de::Error| invalid(format!("built-in default: {e}")))?;
        let over: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| invalid(e.to_string()))?;
        merge(&mut base, over);
        let merged = toml::Value::Table(base);
        let scene: Scene = merged
            .clone()
            .try_into()
            .map_err(|e: toml::de::Error| invalid(e.to_string()))?;
        // `deny_unknown_fields` does not reach the BRDF tables and the distortion (other
        // crates' types): the round trip finds what nothing read.
        let unknown = skinbrdf_session::toml_unknown_keys(&merged, &scene);
        if !unknown.is_empty() {
            return Err(invalid(format!(
                "unknown field(s): {}",
                unknown
                    .iter()
                    .map(|k| format!("`{k}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        let problems = scene.problems();
        if problems.is_empty() {
            Ok(scene)
        } else {
            Err(invalid(problems.join("; ")))
        }
    }

    /// A built-in scene by name, or a scene file by path.
    pub fn load(name_or_path: &str) -> Result<Scene, SceneError> {
        if let Some((_, text)) = BUILTIN_SCENES.iter().find(|(n, _)| *n == name_or_path) {
            return Self::from_toml(text, name_or_path);
        }
        let text = std::fs::read_to_string(Path::new(name_or_path)).map_err(|source| {
            SceneError::NotFound {
                name: name_or_path.to_string(),
                known: BUILTIN_SCENES
                    .iter()
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
                    .join(", "),
                source,
            }
        })?;
        Self::from_toml(&text, name_or_path)
    }

    /// Every invariant violation, as `field: problem` strings.
    pub fn problems(&self) -> Vec<String> {
        let mut out = Vec::new();
        // Sizes and counts that set the work and the memory: each within a stated range.
        let mut within = |field: &str, v: f64, lo: f64, hi: f64| {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                out.push(format!("`{field}` must be in [{lo}, {hi}], got {v}"));
            }
        };
        within(
            "camera.width_px",
            self.camera.width_px as f64,
            16.0,
            MAX_SIDE_PX,
        );
        within(
            "camera.height_px",
            self.camera.height_px as f64,
            16.0,
            MAX_SIDE_PX,
        );
        within("camera.hfov_deg", self.camera.hfov_deg, 0.1, 170.0);
        within(
            "targets.reference_sheet_targets",
            f64::from(self.targets.reference_sheet_targets),
            1.0,
            MAX_SHEET_TARGETS,
        );
        within(
            "sensor.samples_per_pixel",
            self.sensor.samples_per_pixel as f64,
            1.0,
            MAX_SAMPLES_PER_PIXEL,
        );
        within(
            "session.measurement_images",
            self.session.measurement_images as f64,
            1.0,
            MAX_MEASUREMENT_IMAGES,
        );
        within(
            "session.survey_images",
            f64::from(self.session.survey_images),
            0.0,
            MAX_SURVEY_IMAGES,
        );
        within(
            "geometry.render_spacing_m",
            self.geometry.render_spacing_m,
            MIN_SPACING_M,
            0.05,
        );
        within(
            "geometry.scan_spacing_m",
            self.geometry.scan_spacing_m,
            MIN_SPACING_M,
            0.05,
        );
        within(
            "session.camera_radius_m",
            self.session.camera_radius_m,
            0.1,
            100.0,
        );
        within(
            "session.flash_distance_m",
            self.session.flash_distance_m,
            0.05,
            100.0,
        );
        let mut pos = |field: &str, v: f64| {
            if !(v.is_finite() && v > 0.0) {
                out.push(format!("`{field}` must be positive and finite, got {v}"));
            }
        };
        pos("sensor.full_well_e", self.sensor.full_well_e);
        pos("sensor.gamma", self.sensor.gamma);
        pos(
            "geometry.superellipse_exponent",
            self.geometry.superellipse_exponent,
        );
        pos("geometry.sphere_radius_m", self.geometry.sphere_radius_m);
        pos(
            "geometry.cylinder_radius_m",
            self.geometry.cylinder_radius_m,
        );
        pos(
            "geometry.cylinder_length_m",
            self.geometry.cylinder_length_m,
        );
        pos("geometry.roi_radius_m", self.geometry.roi_radius_m);
        pos("geometry.brow_width_deg", self.geometry.brow_width_deg);
        pos(
            "geometry.brow_half_azimuth_deg",
            self.geometry.brow_half_azimuth_deg,
        );
        for (i, a) in self.geometry.semi_axes_m.iter().enumerate() {
            pos(&format!("geometry.semi_axes_m[{i}]"), *a);
        }
        pos("session.flash_diameter_m", self.session.flash_diameter_m);
        pos("session.shot_interval_s", self.session.shot_interval_s);
        pos("targets.reference_size_m", self.targets.reference_size_m);
        pos("targets.headdress_size_m", self.targets.headdress_size_m);
        pos("targets.flash_size_m", self.targets.flash_size_m);
        pos("targets.standard_size_m", self.targets.standard_size_m);
        pos("standard.size_m", self.standard.size_m);
        for (i, c) in self.radiometry.calibration_c.iter().enumerate() {
            pos(&format!("radiometry.calibration_c[{i}]"), *c);
        }
        let nonneg = [
            ("sensor.read_noise", self.sensor.read_noise),
            ("sensor.black_level", self.sensor.black_level),
            ("radiometry.ambient", self.radiometry.ambient),
            ("geometry.scan_noise_m", self.geometry.scan_noise_m),
            ("geometry.brow_height_m", self.geometry.brow_height_m),
            ("session.head_motion_m", self.session.head_motion_m),
            ("session.head_motion_deg", self.session.head_motion_deg),
            ("session.position_jitter_m", self.session.position_jitter_m),
            ("session.aim_jitter_m", self.session.aim_jitter_m),
        ];
        for (field, v) in nonneg {
            if !(v.is_finite() && v >= 0.0) {
                out.push(format!("`{field}` must be finite and >= 0, got {v}"));
            }
        }
        let max = match self.sensor.encoding {
            Encoding::Png16 => 65535.0,
            Encoding::Png8 => 255.0,
            Encoding::Exr => f64::INFINITY,
        };
        if self.sensor.encoding != Encoding::Exr
            && !(self.sensor.white_level > self.sensor.black_level
                && self.sensor.white_level <= max)
        {
            out.push(format!(
                "`sensor.white_level` must be above black_level and at most {max}, got {}",
                self.sensor.white_level
            ));
        }
        for (field, a) in [
            ("targets.paper_albedo", self.targets.paper_albedo),
            ("targets.ink_albedo", self.targets.ink_albedo),
        ] {
            if !(0.0..=1.0).contains(&a) {
                out.push(format!("`{field}` must be in [0, 1], got {a}"));
            }
        }
        if self.targets.ink_albedo >= self.targets.paper_albedo {
            out.push("`targets.ink_albedo` must be below paper_albedo (no contrast)".into());
        }
        if let Err(e) = self.skin.validate() {
            out.push(format!("`skin`: {e}"));
        }
        if let Err(e) = self.standard.brdf.validate() {
            out.push(format!("`standard.brdf`: {e}"));
        }
        if self.camera.distortion.k1.abs() > 1.0 {
            out.push("`camera.distortion.k1` beyond +-1 is not a lens".into());
        }
        out.extend(self.studio.problems());
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_scene_loads_and_differs_from_default_where_it_says() {
        let default = Scene::load("default").unwrap();
        for (name, _) in BUILTIN_SCENES {
            let s = Scene::load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(&s.name, name);
            if *name != "default" {
                assert_ne!(s, default, "{name} changes nothing");
            }
        }
        let mirror = Scene::load("near-mirror").unwrap();
        match mirror.skin {
            BrdfModel::Lafortune(l) => assert_eq!(l.lobes[0].exponent, [2000.0; 3]),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn scene_files_on_disk_match_the_embedded_ones() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
        let mut on_disk = 0;
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                on_disk += 1;
                let s = Scene::load(p.to_str().unwrap())
                    .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                assert!(
                    BUILTIN_SCENES.iter().any(|(n, _)| *n == s.name),
                    "{} not embedded",
                    s.name
                );
            }
        }
        assert_eq!(on_disk, BUILTIN_SCENES.len());
    }

    #[test]
    fn bad_scenes_are_rejected_with_the_field() {
        let e = Scene::from_toml("[session]\nmeasurement_imagez = 3\n", "x").unwrap_err();
        assert!(e.to_string().contains("measurement_imagez"), "{e}");
        let e = Scene::from_toml(
            "[targets]\nink_albedo = 0.9\n[sensor]\nfull_well_e = -1\n",
            "x",
        )
        .unwrap_err();
        let t = e.to_string();
        assert!(t.contains("ink_albedo") && t.contains("full_well_e"), "{t}");
        assert!(matches!(
            Scene::load("no-such-scene"),
            Err(SceneError::NotFound { .. })
        ));
        // Keys nothing reads, also inside the BRDF and the distortion (other crates' types).
        for (text, key) in [
            (
                "[skin]\nmodel = \"lambertian\"\nalbedo = [0.5, 0.4, 0.3]\nalbdo = 1\n",
                "skin.albdo",
            ),
            ("[camera.distortion]\nk4 = 0.1\n", "camera.distortion.k4"),
        ] {
            let e = Scene::from_toml(text, "x").unwrap_err();
            assert!(e.to_string().contains(key), "{key}: {e}");
        }
        // Sizes and counts beyond their stated ranges, before any work.
        for (text, field) in [
            (
                "[session]\nmeasurement_images = 4294967295\n",
                "session.measurement_images",
            ),
            (
                "[sensor]\nsamples_per_pixel = 4294967295\n",
                "sensor.samples_per_pixel",
            ),
            ("[camera]\nwidth_px = 100000\n", "camera.width_px"),
            (
                "[geometry]\nrender_spacing_m = 1e-7\n",
                "geometry.render_spacing_m",
            ),
        ] {
            let e = Scene::from_toml(text, "x").unwrap_err();
            assert!(e.to_string().contains(field), "{field}: {e}");
        }
        // A user scene replaces the BRDF as a whole.
        let s = Scene::from_toml(
            "[skin]\nmodel = \"lambertian\"\nalbedo = [0.5, 0.4, 0.3]\n",
            "x",
        )
        .unwrap();
        assert_eq!(
            s.skin,
            BrdfModel::Lambertian {
                albedo: [0.5, 0.4, 0.3]
            }
        );
    }
}
