//! The sessions the integration tests build: a valid four-image session file, its targets
//! and images, and a directory of distinct photographs for it. Each test binary uses a part.
#![allow(dead_code)] // each test binary uses some of these helpers, none uses all
#![allow(clippy::unwrap_used)] // test helpers

use std::path::Path;

use glam::DVec3;
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::CameraModel;
use skinbrdf_session::write::write_png_rgb16;
use skinbrdf_session::*;

/// A 4 cm tag36h11 target at `centre`, facing -z.
pub fn target(id: u32, centre: DVec3) -> Target {
    Target::square(id, 0.04, centre, DVec3::NEG_Z, DVec3::Y).unwrap()
}

/// An image entry with nothing but its file and role.
pub fn entry(file: &str, role: ImageRole) -> ImageEntry {
    ImageEntry {
        file: file.into(),
        role,
        exposure_index: None,
        linearization: None,
        mask: None,
        world_from_camera: None,
        world_from_head: None,
        exposure_scale: None,
    }
}

/// A valid session of four images (`images/m0`, `m1` measurements, `l0` light position,
/// `s0` reference standard, with extension `ext`) of a `width_px` x `height_px` camera: one
/// target per group, a sphere, a linear default linearization, nothing known.
pub fn session_file(width_px: u32, height_px: u32, ext: &str) -> SessionFile {
    let images = [
        ("m0", ImageRole::Measurement),
        ("m1", ImageRole::Measurement),
        ("l0", ImageRole::LightPosition),
        ("s0", ImageRole::ReferenceStandard),
    ]
    .into_iter()
    .map(|(name, role)| entry(&format!("images/{name}.{ext}"), role))
    .collect();
    SessionFile {
        format_version: SESSION_FORMAT_VERSION,
        description: "test".into(),
        capture: None,
        camera: CameraSpec::Calibrated(CameraModel::from_fov(width_px, height_px, 0.8)),
        linearization: Linearization::LINEAR,
        images,
        targets: TargetLayouts {
            family: TAG_FAMILY.into(),
            reference: vec![target(0, DVec3::new(0.0, 0.0, 2.0))],
            headdress: vec![target(10, DVec3::new(0.0, 0.1, 0.0))],
            unplaced: Vec::new(),
        },
        flash: FlashSpec {
            diameter_m: 0.082,
            light_centre_m: DVec3::ZERO,
            targets: vec![target(20, DVec3::new(0.08, 0.0, 0.0))],
        },
        standard: Some(StandardSpec {
            brdf: BrdfModel::Lambertian { albedo: [0.99; 3] },
            size_m: [0.1, 0.1],
            targets: vec![target(30, DVec3::new(0.08, 0.0, 0.0))],
        }),
        geometry: GeometrySpec::Sphere {
            centre_m: DVec3::ZERO,
            radius_m: 0.08,
        },
        roi: None,
        known: KnownQuantities::default(),
        registration: None,
    }
}

/// A distinct 16-bit `width_px` x `height_px` photograph per index `i` (identical contents
/// are themselves an error: the same image listed twice).
pub fn write_png(dir: &Path, rel: &str, i: usize, width_px: u32, height_px: u32) {
    let mut px = vec![1000u16; (3 * width_px * height_px) as usize];
    px[0] = i as u16;
    write_png_rgb16(&dir.join(rel), width_px, height_px, &px).unwrap();
}

/// Writes `f`'s `session.toml` and a distinct photograph for each of its images into `dir`.
pub fn write_dir(dir: &Path, f: &SessionFile, width_px: u32, height_px: u32) {
    for (i, im) in f.images.iter().enumerate() {
        write_png(dir, &im.file, i, width_px, height_px);
    }
    Session::write_file(dir, f).unwrap();
}
