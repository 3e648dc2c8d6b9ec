//! `rig.toml`: what a studio knows about its rig before anything is measured.
//!
//! A rig is the set of printed targets (family, ids, printed sizes, which printed sheet each
//! belongs to), the flash (its diffuser's diameter) and the reflectance standard (its BRDF and
//! size). Targets belong to a **group**, the frame their placement is given in
//! ([`TargetGroup`]): the reference structure (world), the headdress (head), the flash ring
//! (flash), the frame around the standard (standard).
//!
//! Placements are optional. A *surveyed* rig (`rig-measured.toml`) gives every target's corners
//! in its group's frame (or a sheet's placement, `group_from_sheet`, and its layout file); a
//! rig nobody measured (`rig.toml`) gives only ids and sizes, and a session written from it
//! lists those targets under `targets.unplaced` for the placement survey to fill in.
//!
//! ```toml
//! format_version = 1
//! description = "studio A, reference cage and headdress band"
//! family = "tag36h11"
//!
//! [[sheets]]                      # a printed sheet: its targets are rigid and coplanar
//! name = "cage-left"
//! group = "reference"
//! layout = "cage-left.layout.toml"   # from `skinbrdf targets` (sheet frame), relative to this file
//! # group_from_sheet = { rotation = [x, y, z, w], translation_m = [x, y, z] }   (surveyed)
//! # print_scale = 1.0             (the printed size over the nominal one; default 1)
//!
//! [[targets]]                     # a single target (a cut-out), or one of a sheet without layout
//! id = 40
//! size_m = 0.025
//! group = "headdress"
//! # sheet = "band"                (a sheet listed above without a layout)
//! # corners_m = [[..], [..], [..], [..]]   (surveyed; the session's corner order)
//!
//! [flash]
//! diameter_m = 0.082
//! light_centre_m = [0.0, 0.0, 0.0]   # the emitting point in the flash frame (default: origin)
//! # light_position_m = [0.61, 1.02, 0.05]   (measured: the emitting point, world frame)
//! # world_from_flash = { rotation = [x, y, z, w], translation_m = [x, y, z] }   (measured)
//!
//! [standard]
//! brdf = { model = "lambertian", albedo = [0.99, 0.99, 0.99] }
//! size_m = [0.12, 0.12]
//! # world_from_standard = { rotation = [x, y, z, w], translation_m = [x, y, z] }   (fixed, measured)
//!
//! # [camera]                      # optional: as session.toml's [camera]
//! # status = "to-be-calibrated"
//! # focal_guess_px = 8700.0       (where the calibration starts; the loaded images' pixels)
//! # or status = "calibrated" with width_px, height_px, fx_px, fy_px, cx_px, cy_px and
//! # [camera.distortion] k1, k2, k3, p1, p2
//!
//! # [geometry]                    # optional: an ideal sample instead of a scanned head
//! # kind = "sphere"                (or "cylinder" with axis and length_m), head frame
//! # centre_m = [0.0, 0.0, 0.0]
//! # radius_m = 0.09
//!
//! [roi]                           # optional: the forehead region, head frame
//! centre_m = [0.0, 0.09, 0.04]
//! radius_m = 0.03
//! ```
//!
//! # What the studio knows without targets
//!
//! A studio may know where something is without the targets that would locate it:
//!
//! * `[flash] light_position_m`: the flash's emitting point, measured in the world frame (the
//!   frame the placed reference targets define), metres; or `[flash] world_from_flash`, the
//!   flash's whole pose (the emitting point is then `light_centre_m` in it). Either lets the
//!   flash go without its ring of targets (group `flash`): the session states it as
//!   `known.light_position_m` / `known.world_from_flash` and the flash triangulation is
//!   skipped. Without either, the flash is located from its ring's placed targets in the
//!   light-position images; locating it from the light-position images without a ring (its
//!   diffuser's disc seen from several posed cameras) is not supported.
//! * `[standard] world_from_standard`: the standard's fixed pose in the world frame, so that
//!   it needs no frame of targets (group `standard`): the session's
//!   `known.world_from_standard`.
//! * `[camera]`: the camera as session.toml's `[camera]` table states it: a calibration
//!   (`status = "calibrated"`), or a camera to be calibrated with a starting focal length
//!   (`status = "to-be-calibrated"`, `focal_guess_px`, in the pixels of the images as the
//!   session loads them: 2x2 superpixels for camera raw files). The image size is optional
//!   there (ingest reads it from the photographs; a stated one must agree). A calibration file
//!   given to `skinbrdf ingest --camera` wins over it.
//!
//! [`Rig::load`] checks every field and reports every problem at once ([`SessionErrors`],
//! each naming the file and the field); [`Rig::session_parts`] turns a rig into the
//! `session.toml` sections (placed targets in their group's list, the rest unplaced, the
//! known poses under `[known]`); [`Rig::check_needs`] says what a session that states no pose
//! lacks to run every stage, naming the rig's keys.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::{Deserialize, Serialize};
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::untrusted;
use skinbrdf_core::{CameraModel, Pose};

use crate::checks::{check_id_and_size, check_pose, check_target, positive};
use crate::error::SessionErrors;
use crate::format::{
    FlashSpec, GeometrySpec, KnownQuantities, RegionOfInterest, StandardSpec, Target, TargetGroup,
    TargetLayouts, UnplacedTarget, TAG_FAMILY,
};

/// Current `rig.toml` format version.
pub const RIG_FORMAT_VERSION: u32 = 1;

/// A layout file written by `skinbrdf targets` (`FILE.layout.toml`): the targets of one sheet
/// in the sheet's frame (origin at its centre, x right, y up on the page, z out of the paper,
/// metres), and the `session.toml` table they belong in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayoutFile {
    /// The `session.toml` table the targets belong in (`targets.reference`, ...).
    pub section: String,
    /// The targets, sheet frame.
    pub targets: Vec<Target>,
}

/// One printed sheet of several targets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigSheet {
    /// The sheet's name (unique in the rig; targets refer to it).
    pub name: String,
    /// The part of the rig it is on.
    pub group: TargetGroup,
    /// Its layout file (from `skinbrdf targets`), relative to the rig file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layout: Option<String>,
    /// Where the sheet is, in its group's frame (a surveyed rig).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group_from_sheet: Option<Pose>,
    /// The printed size over the layout's nominal size (a printer's scale error).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub print_scale: Option<f64>,
}

/// One target listed on its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigTarget {
    /// tag36h11 code index (0..587).
    pub id: u32,
    /// Edge length of the black square, metres.
    pub size_m: f64,
    /// The part of the rig it is on.
    pub group: TargetGroup,
    /// The sheet it is printed on, if any (a sheet without a layout file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sheet: Option<String>,
    /// Its corners in the group's frame (a surveyed rig), in the session's corner order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corners_m: Option<[DVec3; 4]>,
}

/// The flash as the studio knows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigFlash {
    /// Diameter of the diffuser disc, metres.
    pub diameter_m: f64,
    /// The emitting point in the flash frame.
    #[serde(default)]
    pub light_centre_m: DVec3,
    /// The emitting point as measured in the world frame, metres: the flash needs no targets
    /// (`known.light_position_m`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_position_m: Option<DVec3>,
    /// The flash's pose as measured in the world frame (`known.world_from_flash`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_from_flash: Option<Pose>,
}

impl RigFlash {
    /// True when the rig states where the flash is (no triangulation needed).
    pub fn located(&self) -> bool {
        self.light_position_m.is_some() || self.world_from_flash.is_some()
    }
}

/// The reflectance standard as its certificate gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigStandard {
    /// Its calibrated BRDF.
    pub brdf: BrdfModel,
    /// Width and height of the reflecting area, metres.
    pub size_m: [f64; 2],
    /// Its fixed pose in the world frame, as measured: it needs no targets
    /// (`known.world_from_standard`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_from_standard: Option<Pose>,
}

/// The camera as the studio knows it (`[camera]`): session.toml's `[camera]`, except that a
/// camera to be calibrated need not state the image size (ingest reads it from the photographs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "kebab-case", deny_unknown_fields)]
pub enum RigCamera {
    /// Intrinsics and distortion known (the [`CameraModel`] fields).
    Calibrated(CameraModel),
    /// To be calibrated from the session's targets, optionally from a stated focal length.
    ToBeCalibrated {
        /// Image width in pixels, as the session loads the images (optional).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        width_px: Option<u32>,
        /// Image height in pixels, as the session loads the images (optional).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        height_px: Option<u32>,
        /// Where the calibration's focal length starts, pixels of the loaded images.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        focal_guess_px: Option<f64>,
    },
}

impl RigCamera {
    /// The image size it states, if any.
    pub fn size_px(&self) -> Option<(u32, u32)> {
        match *self {
            Self::Calibrated(m) => Some((m.width_px, m.height_px)),
            Self::ToBeCalibrated {
                width_px: Some(w),
                height_px: Some(h),
                ..
            } => Some((w, h)),
            Self::ToBeCalibrated { .. } => None,
        }
    }
}

impl std::fmt::Display for RigCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Calibrated(m) => write!(
                f,
                "calibrated, {}x{} px, fx {:.1} px",
                m.width_px, m.height_px, m.fx_px
            ),
            Self::ToBeCalibrated {
                focal_guess_px: Some(g),
                ..
            } => write!(f, "to be calibrated from focal_guess_px {g:.1}"),
            Self::ToBeCalibrated { .. } => write!(f, "to be calibrated"),
        }
    }
}

/// A studio's rig file (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigFile {
    /// [`RIG_FORMAT_VERSION`].
    pub format_version: u32,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// Target family; must be `tag36h11`.
    #[serde(default = "default_family")]
    pub family: String,
    /// Printed sheets.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sheets: Vec<RigSheet>,
    /// Targets listed one by one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub targets: Vec<RigTarget>,
    /// The flash.
    pub flash: RigFlash,
    /// The reflectance standard.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub standard: Option<RigStandard>,
    /// The camera, when the studio knows its calibration or a starting focal length.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<RigCamera>,
    /// The region of the subject to measure, head frame (where the headdress sits on the
    /// forehead fixes it); `None`: the whole scan.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roi: Option<RegionOfInterest>,
    /// The sample's shape when it is an ideal one (a calibration sphere or cylinder), head
    /// frame: the session then needs no scan. A head's shape comes from its scan.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub geometry: Option<GeometrySpec>,
}

fn default_family() -> String {
    TAG_FAMILY.to_string()
}

/// A loaded, validated rig: the file and its sheets' layouts.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    /// Where it was read from.
    pub path: PathBuf,
    /// The parsed file.
    pub file: RigFile,
    /// Each sheet's layout targets (sheet frame), by sheet name, for sheets with a layout.
    pub layouts: HashMap<String, Vec<Target>>,
}

/// What a rig gives a session: the placed targets in their sections, the unplaced ones, the
/// flash, the standard and what it knows of their poses.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionParts {
    /// Reference and headdress targets, and every unplaced target.
    pub targets: TargetLayouts,
    /// The flash with its placed targets.
    pub flash: FlashSpec,
    /// The standard with its placed targets.
    pub standard: Option<StandardSpec>,
    /// The light position, flash pose and standard pose the rig states (`[known]`); the rest
    /// unset.
    pub known: KnownQuantities,
}

impl RigFile {
    /// The same rig for a file written in `to_dir` instead of `from_dir`: every sheet's layout
    /// file (named relative to the rig file) named relative to `to_dir`, or absolute when the
    /// two share no root.
    pub fn moved(&self, from_dir: &Path, to_dir: &Path) -> Self {
        let mut out = self.clone();
        for s in &mut out.sheets {
            if let Some(l) = &s.layout {
                let abs = from_dir.join(l);
                let rel = crate::write::relative_path(&abs, to_dir);
                s.layout = Some(rel.to_string_lossy().into_owned());
            }
        }
        out
    }
}

impl SessionParts {
    /// True when every target has a placement.
    pub fn fully_placed(&self) -> bool {
        self.targets.unplaced.is_empty()
    }
}

impl Rig {
    /// Reads and validates a rig file and its layout files, reporting every problem.
    pub fn load(path: &Path) -> Result<Self, SessionErrors> {
        let mut errs = SessionErrors::default();
        let text = match untrusted::read_bounded_text(path, untrusted::SETTINGS_FILE) {
            Ok(t) => t,
            Err(e) => {
                errs.push(path, "", e.reason());
                return Err(errs);
            }
        };
        let file: RigFile = match toml::from_str(&text) {
            Ok(f) => f,
            Err(e) => {
                errs.push(path, "", format!("not a rig file: {}", e.message()));
                return Err(errs);
            }
        };
        let base = path.parent().unwrap_or(Path::new("."));
        let layouts = validate(&file, path, base, &mut errs);
        errs.into_result(Rig {
            path: path.to_path_buf(),
            file,
            layouts,
        })
    }

    /// Writes a rig file atomically.
    ///
    /// The sheets' layout files are named relative to the rig file: [`RigFile::moved`] names
    /// them for a rig written elsewhere.
    pub fn write_file(path: &Path, file: &RigFile) -> Result<(), crate::FileError> {
        let text = toml::to_string(file).map_err(|e| crate::FileError::Invalid {
            path: path.to_path_buf(),
            field: String::new(),
            problem: format!("cannot serialise the rig: {e}"),
        })?;
        crate::write::write_atomic(path, text.as_bytes())
    }

    /// The `session.toml` sections this rig gives (see [`SessionParts`]).
    pub fn session_parts(&self) -> SessionParts {
        let mut targets = TargetLayouts {
            family: self.file.family.clone(),
            ..TargetLayouts::default()
        };
        let mut flash = FlashSpec {
            diameter_m: self.file.flash.diameter_m,
            light_centre_m: self.file.flash.light_centre_m,
            targets: Vec::new(),
        };
        let mut standard = self.file.standard.as_ref().map(|s| StandardSpec {
            brdf: s.brdf.clone(),
            size_m: s.size_m,
            targets: Vec::new(),
        });
        let mut place = |group: TargetGroup, t: Target| match group {
            TargetGroup::Reference => targets.reference.push(t),
            TargetGroup::Headdress => targets.headdress.push(t),
            TargetGroup::Flash => flash.targets.push(t),
            TargetGroup::Standard => {
                if let Some(s) = standard.as_mut() {
                    s.targets.push(t);
                }
            }
        };
        let mut unplaced = Vec::new();
        for sheet in &self.file.sheets {
            let Some(layout) = self.layouts.get(&sheet.name) else {
                continue;
            };
            let scale = sheet.print_scale.unwrap_or(1.0);
            for t in layout {
                match &sheet.group_from_sheet {
                    Some(p) => {
                        let corners_m = t.corners_m.map(|c| p.transform_point(c * scale));
                        place(
                            sheet.group,
                            Target {
                                id: t.id,
                                size_m: t.size_m * scale,
                                corners_m,
                                centre_m: t.centre_m.map(|c| p.transform_point(c * scale)),
                            },
                        );
                    }
                    None => unplaced.push(UnplacedTarget {
                        id: t.id,
                        size_m: t.size_m * scale,
                        group: sheet.group,
                        sheet: Some(sheet.name.clone()),
                        sheet_corners_m: Some(t.corners_m.map(|c| c * scale)),
                    }),
                }
            }
        }
        for t in &self.file.targets {
            match t.corners_m {
                Some(corners_m) => place(
                    t.group,
                    Target {
                        id: t.id,
                        size_m: t.size_m,
                        corners_m,
                        centre_m: None,
                    },
                ),
                None => unplaced.push(UnplacedTarget {
                    id: t.id,
                    size_m: t.size_m,
                    group: t.group,
                    sheet: t.sheet.clone(),
                    sheet_corners_m: None,
                }),
            }
        }
        targets.unplaced = unplaced;
        let known = KnownQuantities {
            light_position_m: self.file.flash.light_position_m,
            world_from_flash: self.file.flash.world_from_flash,
            world_from_standard: self
                .file
                .standard
                .as_ref()
                .and_then(|s| s.world_from_standard),
            ..KnownQuantities::default()
        };
        SessionParts {
            targets,
            flash,
            standard,
            known,
        }
    }

    /// What a session that states no camera or head pose (as `skinbrdf ingest` writes one)
    /// needs of its rig for every stage to run, each problem naming this file and the key to
    /// state: reference targets with at least one placed (the world's origin), headdress
    /// targets, a flash located by its ring's placed targets or by a stated light position or
    /// pose, and a reflectance standard located by its frame's placed targets or a stated pose.
    /// Flash and standard targets must be placed (the placement survey places reference and
    /// headdress targets only), also where a stated pose makes them unnecessary.
    pub fn check_needs(&self) -> Result<(), SessionErrors> {
        let mut errs = SessionErrors::default();
        let path = self.path.as_path();
        let f = &self.file;
        let reference = self.declarations(TargetGroup::Reference);
        if reference.is_empty() {
            errs.push(
                path,
                "targets",
                "no target of group \"reference\": the camera poses (and the camera's \
                 calibration) come from the reference structure's targets",
            );
        } else if !reference.iter().any(|d| d.placed) {
            errs.push(
                path,
                "targets",
                "no reference target has a placement to fix the world's origin: state the \
                 corners_m of at least one reference target, or a reference sheet's \
                 group_from_sheet",
            );
        }
        if self.declarations(TargetGroup::Headdress).is_empty() {
            errs.push(
                path,
                "targets",
                "no target of group \"headdress\": head tracking follows the head by the \
                 headdress's targets",
            );
        }
        // The placement survey refuses unplaced flash and standard targets (their layouts
        // place them), also where a stated pose makes them unnecessary.
        let flash = self.declarations(TargetGroup::Flash);
        if !f.flash.located() && flash.is_empty() {
            errs.push(
                path,
                "flash",
                "no target of group \"flash\" and no light_position_m: the flash is located \
                 from its ring's targets in the light-position images; state the measured \
                 light position (light_position_m, world frame, metres) or the ring's targets \
                 (group \"flash\", placed in the flash frame). The light-position images \
                 alone, without the ring, do not locate it",
            );
        }
        let unplaced_flash = if f.flash.located() {
            "a flash target without a placement: the rig states where the flash is, so the \
             ring's targets are not needed; leave it out, or state its placement in the flash \
             frame (the survey places reference and headdress targets only)"
        } else {
            "a flash target without a placement: the ring's targets are placed in the flash \
             frame by their printed layout (the survey places reference and headdress targets \
             only); state it, or the measured light position ([flash] light_position_m)"
        };
        for d in flash.iter().filter(|d| !d.placed) {
            errs.push(path, d.placement_key(), unplaced_flash);
        }
        let standard = self.declarations(TargetGroup::Standard);
        match &f.standard {
            None => errs.push(
                path,
                "standard",
                "missing: the radiometric calibration (C) needs the reflectance standard (its \
                 brdf and size_m)",
            ),
            Some(s) if s.world_from_standard.is_none() && standard.is_empty() => errs.push(
                path,
                "standard",
                "no target of group \"standard\" and no world_from_standard: the standard is \
                 located from the targets framing it in the standard-position images; state \
                 its measured pose (world_from_standard, world frame) or its frame's targets \
                 (group \"standard\", placed in the standard frame)",
            ),
            Some(_) => {}
        }
        let unplaced_standard = if f
            .standard
            .as_ref()
            .is_some_and(|s| s.world_from_standard.is_some())
        {
            "a standard target without a placement: the rig states the standard's pose, so \
             its frame's targets are not needed; leave it out, or state its placement in the \
             standard frame (the survey places reference and headdress targets only)"
        } else {
            "a standard target without a placement: the frame's targets are placed in the \
             standard frame by their printed layout (the survey places reference and headdress \
             targets only); state it, or the standard's measured pose ([standard] \
             world_from_standard)"
        };
        for d in standard.iter().filter(|d| !d.placed) {
            errs.push(path, d.placement_key(), unplaced_standard);
        }
        errs.into_result(())
    }

    /// Where the rig declares a group's targets: each sheet with a layout file and each target
    /// listed on its own, with whether it places them.
    fn declarations(&self, group: TargetGroup) -> Vec<Declaration> {
        let sheets = self
            .file
            .sheets
            .iter()
            .enumerate()
            .filter(|(_, s)| s.group == group && s.layout.is_some())
            .map(|(i, s)| Declaration {
                key: format!("sheets[{i}]"),
                sheet: true,
                placed: s.group_from_sheet.is_some(),
            });
        let targets = self
            .file
            .targets
            .iter()
            .enumerate()
            .filter(|(_, t)| t.group == group)
            .map(|(i, t)| Declaration {
                key: format!("targets[{i}]"),
                sheet: false,
                placed: t.corners_m.is_some(),
            });
        sheets.chain(targets).collect()
    }

    /// The same rig without any placement (what a studio knows before the survey).
    pub fn without_placements(file: &RigFile) -> RigFile {
        let mut f = file.clone();
        for s in &mut f.sheets {
            s.group_from_sheet = None;
        }
        for t in &mut f.targets {
            t.corners_m = None;
        }
        f
    }
}

/// A sheet or a target of the rig file, for [`Rig::check_needs`].
struct Declaration {
    /// `sheets[i]` or `targets[i]`.
    key: String,
    /// A sheet (placed by `group_from_sheet`) or a target (by `corners_m`).
    sheet: bool,
    /// Whether the rig places it.
    placed: bool,
}

impl Declaration {
    /// The key that would place it.
    fn placement_key(&self) -> String {
        let what = if self.sheet {
            "group_from_sheet"
        } else {
            "corners_m"
        };
        format!("{}.{what}", self.key)
    }
}

/// Checks every field of a rig file and reads its sheets' layout files (by sheet name).
fn validate(
    f: &RigFile,
    path: &Path,
    base: &Path,
    errs: &mut SessionErrors,
) -> HashMap<String, Vec<Target>> {
    version_and_family(f, path, errs);
    check_flash(&f.flash, path, errs);
    if let Some(s) = &f.standard {
        check_standard(s, path, errs);
    }
    if let Some(c) = &f.camera {
        check_camera(c, path, errs);
    }
    if f.standard.is_none() {
        standard_targets_without_standard(f, path, errs);
    }
    shape_and_roi(f, path, errs);
    // Ids are checked against the family (and sizes) by `check_target` / `check_id_and_size`;
    // `ids` records which field used each, so that no two targets share one.
    let mut ids: HashMap<u32, String> = HashMap::new();
    let (layouts, sheet_names) = check_sheets(f, path, base, &mut ids, errs);
    check_targets(f, path, &sheet_names, &mut ids, errs);
    layouts
}

fn version_and_family(f: &RigFile, path: &Path, errs: &mut SessionErrors) {
    if f.format_version != RIG_FORMAT_VERSION {
        errs.push(
            path,
            "format_version",
            format!(
                "version {} is not supported (this build reads {RIG_FORMAT_VERSION})",
                f.format_version
            ),
        );
    }
    if f.family != TAG_FAMILY {
        errs.push(
            path,
            "family",
            format!("`{}` is not supported (only {TAG_FAMILY})", f.family),
        );
    }
}

/// `[flash]`: a positive diameter, finite points, a valid pose stated instead of (not with)
/// the light position.
fn check_flash(flash: &RigFlash, path: &Path, errs: &mut SessionErrors) {
    if !positive(flash.diameter_m) {
        errs.push(
            path,
            "flash.diameter_m",
            format!("must be positive, got {}", flash.diameter_m),
        );
    }
    if !flash.light_centre_m.is_finite() {
        errs.push(path, "flash.light_centre_m", "non-finite coordinate");
    }
    if flash.light_position_m.is_some_and(|p| !p.is_finite()) {
        errs.push(path, "flash.light_position_m", "non-finite coordinate");
    }
    if let Some(p) = &flash.world_from_flash {
        check_pose(p, path, "flash.world_from_flash", errs);
        if flash.light_position_m.is_some() {
            errs.push(
                path,
                "flash.world_from_flash",
                "given with light_position_m: state one of them (the emitting point, or the \
                 flash's pose with light_centre_m the emitting point in it)",
            );
        }
    }
}

/// `[standard]`: its BRDF, a positive size, a valid pose.
fn check_standard(s: &RigStandard, path: &Path, errs: &mut SessionErrors) {
    if let Err(e) = s.brdf.validate() {
        errs.push(path, "standard.brdf", e.to_string());
    }
    if !s.size_m.iter().all(|&v| positive(v)) {
        errs.push(
            path,
            "standard.size_m",
            format!("must be positive, got {} x {} m", s.size_m[0], s.size_m[1]),
        );
    }
    if let Some(p) = &s.world_from_standard {
        check_pose(p, path, "standard.world_from_standard", errs);
    }
}

/// Sheets and targets of group `standard` in a rig without `[standard]`.
fn standard_targets_without_standard(f: &RigFile, path: &Path, errs: &mut SessionErrors) {
    let on_standard = f
        .sheets
        .iter()
        .enumerate()
        .filter(|(_, s)| s.group == TargetGroup::Standard)
        .map(|(i, _)| format!("sheets[{i}].group"))
        .chain(
            f.targets
                .iter()
                .enumerate()
                .filter(|(_, t)| t.group == TargetGroup::Standard)
                .map(|(i, _)| format!("targets[{i}].group")),
        );
    for key in on_standard {
        errs.push(
            path,
            key,
            "`standard`, but the rig has no [standard] for the target to frame",
        );
    }
}

/// `[geometry]` (an ideal shape only) and `[roi]`.
fn shape_and_roi(f: &RigFile, path: &Path, errs: &mut SessionErrors) {
    match &f.geometry {
        Some(GeometrySpec::Scan { .. }) => errs.push(
            path,
            "geometry.kind",
            "a rig states only an ideal shape (sphere or cylinder); a scan is given to ingest",
        ),
        Some(shape) => crate::checks::check_shape(shape, path, errs),
        None => {}
    }
    if let Some(r) = &f.roi {
        if !r.centre_m.is_finite() {
            errs.push(path, "roi.centre_m", "non-finite coordinate");
        }
        if !positive(r.radius_m) {
            errs.push(
                path,
                "roi.radius_m",
                format!("must be positive, got {}", r.radius_m),
            );
        }
    }
}

/// Records that `field` uses `id`; reports it when another target used it first.
fn claim(
    ids: &mut HashMap<u32, String>,
    id: u32,
    field: String,
    path: &Path,
    errs: &mut SessionErrors,
) {
    if let Some(prev) = ids.insert(id, field.clone()) {
        errs.push(
            path,
            format!("{field}.id"),
            format!("id {id} is also used by {prev}"),
        );
    }
}

/// `[[sheets]]`: each sheet's fields, and its layout file read and its targets checked.
/// Returns the layouts by sheet name and the sheets' indices by name.
fn check_sheets<'a>(
    f: &'a RigFile,
    path: &Path,
    base: &Path,
    ids: &mut HashMap<u32, String>,
    errs: &mut SessionErrors,
) -> (HashMap<String, Vec<Target>>, HashMap<&'a str, usize>) {
    let mut layouts = HashMap::new();
    let mut sheet_names: HashMap<&str, usize> = HashMap::new();
    for (i, s) in f.sheets.iter().enumerate() {
        let field = format!("sheets[{i}]");
        if s.name.is_empty() {
            errs.push(path, format!("{field}.name"), "empty name");
        }
        if let Some(prev) = sheet_names.insert(s.name.as_str(), i) {
            errs.push(
                path,
                format!("{field}.name"),
                format!("`{}` is also the name of sheets[{prev}]", s.name),
            );
        }
        sheet_placement(s, &field, path, errs);
        let Some(rel) = &s.layout else { continue };
        match read_layout(base, rel) {
            Ok(l) => {
                for (k, t) in l.targets.iter().enumerate() {
                    claim(
                        ids,
                        t.id,
                        format!("{field}.layout.targets[{k}]"),
                        path,
                        errs,
                    );
                    check_target(t, path, &format!("{field}.layout.targets[{k}]"), errs);
                }
                layouts.insert(s.name.clone(), l.targets);
            }
            Err(problem) => errs.push(path, format!("{field}.layout"), problem),
        }
    }
    (layouts, sheet_names)
}

/// A sheet's placement (a unit pose, with a layout file to place) and print scale.
fn sheet_placement(s: &RigSheet, field: &str, path: &Path, errs: &mut SessionErrors) {
    if let Some(p) = &s.group_from_sheet {
        if !p.is_finite() || (p.rotation.length() - 1.0).abs() > 1e-6 {
            errs.push(
                path,
                format!("{field}.group_from_sheet"),
                "must be finite with a unit quaternion",
            );
        }
        if s.layout.is_none() {
            errs.push(
                path,
                format!("{field}.group_from_sheet"),
                "a sheet's placement needs its layout file (`layout`)",
            );
        }
    }
    if let Some(k) = s.print_scale {
        if !(k.is_finite() && (0.5..=2.0).contains(&k)) {
            errs.push(
                path,
                format!("{field}.print_scale"),
                format!("must be in [0.5, 2], got {k}"),
            );
        }
    }
}

/// A sheet's layout file `rel`: inside the rig's folder, a regular file of bounded size, a
/// layout file. The problem in words otherwise.
fn read_layout(base: &Path, rel: &str) -> Result<LayoutFile, String> {
    untrusted::confine(base, rel)
        .map_err(|e| e.to_string())
        .and_then(|lp| {
            untrusted::read_bounded_text(&lp, untrusted::LAYOUT_FILE)
                .map(|t| (lp, t))
                .map_err(|e| skinbrdf_core::error_text(&e))
        })
        .and_then(|(lp, t)| {
            toml::from_str::<LayoutFile>(&t)
                .map_err(|e| format!("`{}` is not a layout file: {}", lp.display(), e.message()))
        })
}

/// `[[targets]]`: unique ids, a sheet that exists, lists no layout and is of the target's
/// group, and a placement that is a square of the target's size.
fn check_targets(
    f: &RigFile,
    path: &Path,
    sheet_names: &HashMap<&str, usize>,
    ids: &mut HashMap<u32, String>,
    errs: &mut SessionErrors,
) {
    for (i, t) in f.targets.iter().enumerate() {
        let field = format!("targets[{i}]");
        claim(ids, t.id, field.clone(), path, errs);
        if t.corners_m.is_none() {
            check_id_and_size(t.id, t.size_m, path, &field, errs);
        }
        if let Some(name) = &t.sheet {
            match sheet_names.get(name.as_str()).map(|&k| &f.sheets[k]) {
                None => errs.push(
                    path,
                    format!("{field}.sheet"),
                    format!("no sheet is named `{name}`"),
                ),
                Some(s) if s.layout.is_some() => errs.push(
                    path,
                    format!("{field}.sheet"),
                    format!(
                        "sheet `{name}` has a layout file, which lists its targets; list the target there"
                    ),
                ),
                Some(s) if s.group != t.group => errs.push(
                    path,
                    format!("{field}.group"),
                    format!(
                        "`{}`, but its sheet `{name}` is in group `{}`",
                        t.group.name(),
                        s.group.name()
                    ),
                ),
                Some(_) => {}
            }
        }
        if let Some(corners_m) = t.corners_m {
            check_target(
                &Target {
                    id: t.id,
                    size_m: t.size_m,
                    corners_m,
                    centre_m: None,
                },
                path,
                &field,
                errs,
            );
        }
    }
}

/// A stated camera: a calibration's invariants, or a positive image size (both or neither)
/// and focal length.
fn check_camera(c: &RigCamera, path: &Path, errs: &mut SessionErrors) {
    match *c {
        RigCamera::Calibrated(m) => {
            if let Err(skinbrdf_core::CameraError::InvalidParameter { field, reason }) =
                m.validate()
            {
                errs.push(path, format!("camera.{field}"), reason);
            }
        }
        RigCamera::ToBeCalibrated {
            width_px,
            height_px,
            focal_guess_px,
        } => {
            match (width_px, height_px) {
                (Some(w), Some(h)) if w == 0 || h == 0 => errs.push(
                    path,
                    "camera.width_px",
                    format!("the image size must be positive, got {w} x {h}"),
                ),
                (Some(_), None) | (None, Some(_)) => errs.push(
                    path,
                    "camera.width_px",
                    "state both width_px and height_px, or neither (ingest reads the size from \
                     the photographs)",
                ),
                _ => {}
            }
            if let Some(g) = focal_guess_px {
                if !(g.is_finite() && g > 0.0) {
                    errs.push(
                        path,
                        "camera.focal_guess_px",
                        format!("must be positive and finite, got {g}"),
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
