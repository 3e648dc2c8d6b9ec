//! Registering the head scan to the headdress.
//!
//! A session's head frame is the head scan's frame: the derendering looks up the surface behind
//! each pixel on the scan, placed in the world by the head pose, which the headdress targets
//! give. The targets' placements in the head frame are what this crate produces: the
//! photogrammetric survey estimates the headdress targets' corners in a provisional frame of
//! its own, and the scan, which shows the band and its printed targets, says where the same
//! corners are on the scan. A least-squares fit of one set to the other ([`align()`]) maps the
//! survey's frame onto the scan's, so the placements can be stated in the scan's frame
//! ([`RegistrationReport::survey_in_scan`]).
//!
//! Two ways to find the corners on the scan ([`RegistrationMethod`]):
//!
//! * **Texture** ([`find_scan_targets`]): the scan's colours (any scan
//!   [`skinbrdf_mesh::load_textured`] reads: OBJ + MTL + texture image, PLY with vertex
//!   colours, binary glTF or `.gltf`) are rendered from virtual pinhole cameras, the tags are
//!   detected in the renderings with the project's detector, and each detected corner is cast
//!   back onto the mesh (see [`scan_targets`]).
//! * **Points** ([`load_point_pairs`], [`align_points`]): for an untextured scan, an operator
//!   picks at least three non-collinear target corners on the scan and lists them in a small
//!   TOML file.
//!
//! Modules: [`scan_targets`] (finding the targets on a textured scan, the square fit),
//! [`align`](mod@align) (Kabsch/Umeyama, rejection, uncertainty), [`points`] (the points file).

pub mod align;
pub mod points;
pub mod scan_targets;

use std::path::PathBuf;

use glam::DVec3;
use serde::{Deserialize, Serialize};

pub use align::{
    AlignConfig, AlignKind, Alignment, Correspondence, DroppedTarget, TargetResidual,
    MAX_TARGET_RESIDUAL_MM,
};
pub use points::{align_points, load_point_pairs, parse_point_pairs, ScanPoint};
pub use scan_targets::{find_scan_targets, ScanTarget, ScanTargetConfig, ScanTargets};

/// Errors of the registration. Each names what it is about (file and field, target, count).
#[derive(Debug, thiserror::Error)]
pub enum RegisterError {
    /// Loading the scan or building its BVH failed.
    #[error(transparent)]
    Mesh(#[from] skinbrdf_mesh::MeshError),
    /// The scan has no colours to find printed targets in.
    #[error("the scan has no texture or vertex colours: its targets cannot be found by their print (list picked corners in a points file instead)")]
    Untextured,
    /// None of the wanted targets was found on the scan.
    #[error("none of the {} wanted headdress targets ({}) was found on the scan ({views} views rendered)", wanted.len(), wanted.iter().map(u32::to_string).collect::<Vec<_>>().join(", "))]
    NoTargetsFound {
        /// The ids looked for.
        wanted: Vec<u32>,
        /// Views rendered.
        views: usize,
    },
    /// Too few correspondences to fit.
    #[error("{points} corresponding point(s): at least 3 non-collinear points are needed")]
    TooFewPoints {
        /// Points available.
        points: usize,
    },
    /// The points are (nearly) collinear: the rotation about their line is undetermined.
    #[error("the corresponding points are (nearly) collinear: they spread {spread_mm:.3} mm off their best line, at least {min_spread_mm} mm is needed")]
    Degenerate {
        /// Second singular value of the centred points (RMS), millimetres.
        spread_mm: f64,
        /// The minimum.
        min_spread_mm: f64,
    },
    /// A numerical step failed.
    #[error("numerical failure: {what}")]
    Numerical {
        /// Which step.
        what: &'static str,
    },
    /// A parameter is out of range.
    #[error("{field}: {reason}")]
    InvalidParameter {
        /// Which parameter.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The points file cannot be read.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The points file is malformed.
    #[error("{path}: `{field}`: {reason}")]
    PointsFile {
        /// The file.
        path: PathBuf,
        /// The field (`points[2].scan_m`), or the whole file's section.
        field: String,
        /// What is wrong.
        reason: String,
    },
}

/// How the scan's target corners were found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegistrationMethod {
    /// Detected in renderings of the scan's texture ([`find_scan_targets`]).
    Texture,
    /// Picked by hand and listed in a points file ([`load_point_pairs`]).
    Points,
}

impl std::fmt::Display for RegistrationMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Texture => "targets found in its texture",
            Self::Points => "picked points",
        })
    }
}

/// A registration: the method, the alignment and what was found on the scan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegistrationReport {
    /// How the scan's corners were found.
    pub method: RegistrationMethod,
    /// The fit of the survey's corners to the scan's.
    pub alignment: Alignment,
    /// The targets found on the scan (texture method).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan_targets: Option<ScanTargets>,
    /// The points file (points method).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points_file: Option<PathBuf>,
}

impl RegistrationReport {
    /// The survey's targets mapped into the scan frame with the alignment (the placements the
    /// session's rig gets).
    pub fn survey_in_scan(&self, survey: &[(u32, [DVec3; 4])]) -> Vec<(u32, [DVec3; 4])> {
        let a = &self.alignment;
        survey
            .iter()
            .map(|(id, c)| {
                (
                    *id,
                    c.map(|p| {
                        a.scan_from_survey.rotation * (p * a.scale)
                            + a.scan_from_survey.translation_m
                    }),
                )
            })
            .collect()
    }
}

/// Least-squares fit of the survey's target corners (survey frame) to the same targets' corners
/// on the scan (scan frame), matched by id, with rejection of targets that do not fit (see
/// [`align`](mod@align)). `scan_from_survey` of the result maps survey points into the scan
/// frame.
pub fn align(
    survey: &[(u32, [DVec3; 4])],
    scan: &[(u32, [DVec3; 4])],
    kind: AlignKind,
    cfg: &AlignConfig,
) -> Result<Alignment, RegisterError> {
    let (pairs, unmatched) = align::match_targets(survey, scan);
    let mut a = align::fit_correspondences(&pairs, kind, cfg)?;
    a.unmatched = unmatched;
    Ok(a)
}

/// The texture path end to end: finds `survey`'s targets on the scan (each of edge
/// `sizes_m`, by id) and aligns the survey to them.
pub fn register_by_texture(
    survey: &[(u32, [DVec3; 4])],
    sizes_m: &[(u32, f64)],
    scan: &skinbrdf_mesh::TexturedMesh,
    kind: AlignKind,
    find: &ScanTargetConfig,
    cfg: &AlignConfig,
) -> Result<RegistrationReport, RegisterError> {
    let found = find_scan_targets(scan, sizes_m, find)?;
    let scan_corners: Vec<(u32, [DVec3; 4])> =
        found.targets.iter().map(|t| (t.id, t.corners_m)).collect();
    let alignment = align(survey, &scan_corners, kind, cfg)?;
    Ok(RegistrationReport {
        method: RegistrationMethod::Texture,
        alignment,
        scan_targets: Some(found),
        points_file: None,
    })
}

/// The points path end to end: reads the points file and aligns the survey to its points.
pub fn register_by_points(
    survey: &[(u32, [DVec3; 4])],
    points_file: &std::path::Path,
    kind: AlignKind,
    cfg: &AlignConfig,
) -> Result<RegistrationReport, RegisterError> {
    let points = load_point_pairs(points_file)?;
    let alignment = align_points(survey, &points, kind, cfg)?;
    Ok(RegistrationReport {
        method: RegistrationMethod::Points,
        alignment,
        scan_targets: None,
        points_file: Some(points_file.to_path_buf()),
    })
}
