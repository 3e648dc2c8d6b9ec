//! The `session.toml` data types (format version [`SESSION_FORMAT_VERSION`]).
//!
//! Every table rejects unknown keys (a typo is an error, not a silently ignored setting).
//! Vectors are `[x, y, z]` arrays in metres; poses are
//! `{ rotation = [x, y, z, w], translation_m = [x, y, z] }` (unit quaternion, `a_from_b`
//! convention of [`skinbrdf_core::Pose`]). See `docs/session-format.md` for the full format.

use glam::DVec3;
use serde::{Deserialize, Serialize};
use skinbrdf_brdf::BrdfModel;
use skinbrdf_core::{CameraModel, Pose};

pub use crate::capture::ImageRole;
pub use crate::linear::{Linearization, ResponseTable, ToneCurve};

/// Current `session.toml` format version.
pub const SESSION_FORMAT_VERSION: u32 = 1;
/// Name of the session description file inside a session directory.
pub const SESSION_FILE: &str = "session.toml";
/// Name of the ground-truth file (synthetic sessions only).
pub const TRUTH_FILE: &str = "truth.json";
/// The only coded-target family the project uses.
pub const TAG_FAMILY: &str = "tag36h11";

/// The whole `session.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionFile {
    /// Format version ([`SESSION_FORMAT_VERSION`]).
    pub format_version: u32,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// The trigger controller's record, relative to the session directory (`capture.json`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub capture: Option<String>,
    /// The camera.
    pub camera: CameraSpec,
    /// Default linearization for every image (an image may override it).
    pub linearization: Linearization,
    /// The images.
    pub images: Vec<ImageEntry>,
    /// Reference and headdress target layouts (absent: none; needed unless every pose they
    /// would give is known, see [`crate::SectionNeeds`]).
    #[serde(default, skip_serializing_if = "TargetLayouts::is_empty")]
    pub targets: TargetLayouts,
    /// The flash: its emitting disc and its targets (absent: [`FlashSpec::default`]; needed
    /// unless the light position is known).
    #[serde(default, skip_serializing_if = "FlashSpec::is_unstated")]
    pub flash: FlashSpec,
    /// The reflectance standard (needed unless `known.calibration_c` is given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub standard: Option<StandardSpec>,
    /// The sample's geometry.
    pub geometry: GeometrySpec,
    /// The region of interest (in the head frame); absent = the whole geometry.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roi: Option<RegionOfInterest>,
    /// Quantities known in advance (each lets the pipeline skip a stage).
    #[serde(default)]
    pub known: KnownQuantities,
    /// How the surveyed headdress is registered to the scan (absent: by the scan's texture,
    /// rigidly).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub registration: Option<RegistrationSpec>,
}

/// How the placement survey's headdress is registered to the head scan (`[registration]`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegistrationSpec {
    /// Hand-picked target corners on the scan, relative to the session directory (the
    /// `[[points]]` file of `skinbrdf_register::points`): for a scan without texture; when
    /// given, used instead of the texture.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<String>,
    /// The fit: rigid (default), or a similarity (also a scale, for a scan whose unit is not
    /// trusted).
    #[serde(default)]
    pub fit: RegistrationFit,
}

/// The transform fitted between the survey's headdress and the scan's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RegistrationFit {
    /// Rotation and translation.
    #[default]
    Rigid,
    /// Rotation, translation and one scale.
    Similarity,
}

/// The camera: calibrated, or to be calibrated from the session's own targets.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "kebab-case")]
pub enum CameraSpec {
    /// Intrinsics and distortion known (`[camera] status = "calibrated"`, the
    /// [`CameraModel`] fields, `[camera.distortion]` with k1, k2, k3, p1, p2).
    Calibrated(CameraModel),
    /// Only the image size (and optionally a focal-length guess) is known.
    ToBeCalibrated {
        /// Image width in pixels.
        width_px: u32,
        /// Image height in pixels.
        height_px: u32,
        /// A starting guess for the focal length in pixels, if known (e.g. from EXIF).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        focal_guess_px: Option<f64>,
    },
}

impl CameraSpec {
    /// Image size `(width, height)` in pixels.
    pub fn size_px(&self) -> (u32, u32) {
        match self {
            Self::Calibrated(m) => (m.width_px, m.height_px),
            Self::ToBeCalibrated {
                width_px,
                height_px,
                ..
            } => (*width_px, *height_px),
        }
    }

    /// The calibrated model, if any.
    pub fn model(&self) -> Option<&CameraModel> {
        match self {
            Self::Calibrated(m) => Some(m),
            Self::ToBeCalibrated { .. } => None,
        }
    }
}

/// One image of the session.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageEntry {
    /// Image file, relative to the session directory (PNG, TIFF, EXR, JPEG or a camera raw file).
    pub file: String,
    /// What the image is for.
    pub role: ImageRole,
    /// Index of the matching exposure in `capture.json`, if the session has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_index: Option<u32>,
    /// Overrides the session's default linearization for this image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linearization: Option<Linearization>,
    /// A user mask of the region of interest (PNG, non-zero = use), relative to the session.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<String>,
    /// Known camera pose (world from camera); skips pose estimation for this image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_from_camera: Option<Pose>,
    /// Known head pose (world from head); skips head tracking for this image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_from_head: Option<Pose>,
    /// A positive finite factor that multiplies the image's linear values `V` (written by
    /// `skinbrdf ingest` when it normalises a different exposure to the reference-standard
    /// image's); absent = 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_scale: Option<f64>,
}

/// One AprilTag tag36h11 target with its 3D geometry in its layout's frame.
///
/// `size_m` is the edge of the tag's black square (the quad a detector finds). `corners_m` are
/// in the order of the AprilTag reference library: in the tag's own frame (x right, y down on the
/// upright printed tag, z into the surface) the corners are `(-s/2, +s/2)`, `(+s/2, +s/2)`,
/// `(+s/2, -s/2)`, `(-s/2, -s/2)`: bottom-left, bottom-right, top-right, top-left.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// tag36h11 code index (0..587).
    pub id: u32,
    /// Edge length of the black square, metres.
    pub size_m: f64,
    /// The four corners in the layout's frame, metres (order above).
    pub corners_m: [DVec3; 4],
    /// The centre, metres; defaults to the mean of the corners.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub centre_m: Option<DVec3>,
}

impl Target {
    /// The centre (given, or the corners' mean).
    pub fn centre(&self) -> DVec3 {
        self.centre_m
            .unwrap_or_else(|| self.corners_m.iter().copied().sum::<DVec3>() * 0.25)
    }

    /// The unit normal of the printed face (pointing out of the surface, towards a viewer).
    pub fn outward_normal(&self) -> DVec3 {
        let [c0, c1, _, c3] = self.corners_m;
        // Tag frame: x = c0->c1, y = c3->c0 (down); z into the surface = x × y; out = −z.
        let x = c1 - c0;
        let y = c0 - c3;
        -(x.cross(y)).normalize_or_zero()
    }

    /// A target of edge `size_m` centred at `centre_m`, its printed face looking along
    /// `outward` with the tag's "up" as close to `up` as possible.
    pub fn square(
        id: u32,
        size_m: f64,
        centre_m: DVec3,
        outward: DVec3,
        up: DVec3,
    ) -> Option<Self> {
        // The tag frame is the camera frame of a viewer facing the tag: x right, y down,
        // z into the tag (right-handed).
        let z_in = -outward.try_normalize()?;
        let x = z_in.cross(up).try_normalize()?;
        let y = z_in.cross(x);
        let h = 0.5 * size_m;
        let c = |sx: f64, sy: f64| centre_m + x * (sx * h) + y * (sy * h);
        Some(Self {
            id,
            size_m,
            corners_m: [c(-1.0, 1.0), c(1.0, 1.0), c(1.0, -1.0), c(-1.0, -1.0)],
            centre_m: Some(centre_m),
        })
    }
}

/// The target layouts that live on the reference structure and the headdress.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetLayouts {
    /// Target family; must be `tag36h11`.
    #[serde(default = "default_family")]
    pub family: String,
    /// Targets on the fixed reference structure, world frame (this defines the world frame).
    #[serde(default)]
    pub reference: Vec<Target>,
    /// Targets on the headdress, head (scan) frame.
    #[serde(default)]
    pub headdress: Vec<Target>,
    /// Targets of any group whose placement nobody has measured yet (a rig without
    /// placements, as `skinbrdf ingest` writes it from `rig.toml`): the placement survey fills
    /// them in. A stage that needs a group's placements refuses to run while any of that
    /// group's targets is here.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unplaced: Vec<UnplacedTarget>,
}

/// The frame a target is placed in: which part of the rig it is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TargetGroup {
    /// The fixed reference structure (world frame).
    Reference,
    /// The headdress (head frame).
    Headdress,
    /// Around the flash (flash frame).
    Flash,
    /// Framing the reflectance standard (standard frame).
    Standard,
}

impl TargetGroup {
    /// Every group, in the order the rig lists them.
    pub const ALL: [Self; 4] = [
        Self::Reference,
        Self::Headdress,
        Self::Flash,
        Self::Standard,
    ];

    /// The group's name in files (`reference`, `headdress`, `flash`, `standard`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Reference => "reference",
            Self::Headdress => "headdress",
            Self::Flash => "flash",
            Self::Standard => "standard",
        }
    }

    /// The frame the group's placements are given in.
    pub const fn frame(self) -> &'static str {
        match self {
            Self::Reference => "world",
            Self::Headdress => "head",
            Self::Flash => "flash",
            Self::Standard => "standard",
        }
    }
}

/// A target whose printed size is known but whose placement is not.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnplacedTarget {
    /// tag36h11 code index (0..587).
    pub id: u32,
    /// Edge length of the black square, metres.
    pub size_m: f64,
    /// The part of the rig it is on.
    pub group: TargetGroup,
    /// The printed sheet it belongs to, if it shares one with other targets (its targets are
    /// rigid and coplanar relative to each other).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sheet: Option<String>,
    /// Its corners in the sheet's own frame (from the sheet's layout file, times the rig's
    /// stated print scale), when the sheet has a layout: the survey then places the sheet as one rigid body.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sheet_corners_m: Option<[DVec3; 4]>,
}

impl Default for TargetLayouts {
    /// No targets (a session whose poses are all known).
    fn default() -> Self {
        Self {
            family: default_family(),
            reference: Vec::new(),
            headdress: Vec::new(),
            unplaced: Vec::new(),
        }
    }
}

impl TargetLayouts {
    /// True when neither layout has a target.
    pub fn is_empty(&self) -> bool {
        self.reference.is_empty()
            && self.headdress.is_empty()
            && self.unplaced.is_empty()
            && self.family == TAG_FAMILY
    }

    /// The ids of the unplaced targets of one group.
    pub fn unplaced_ids(&self, group: TargetGroup) -> Vec<u32> {
        self.unplaced
            .iter()
            .filter(|t| t.group == group)
            .map(|t| t.id)
            .collect()
    }
}

fn default_family() -> String {
    TAG_FAMILY.to_string()
}

/// The flash: a diffused disc light, and the targets around it, in the flash frame.
///
/// Flash frame: origin at the disc's centre, +z the emission direction (out of the diffuser).
/// For shading the flash is an isotropic point emitter at `light_centre_m` (see the radiometric
/// convention in `docs/session-format.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlashSpec {
    /// Diameter of the diffuser disc, metres (0.082 for the method's flash).
    pub diameter_m: f64,
    /// The emitting point in the flash frame (normally the origin).
    #[serde(default)]
    pub light_centre_m: DVec3,
    /// Targets around the flash, flash frame.
    #[serde(default)]
    pub targets: Vec<Target>,
}

impl Default for FlashSpec {
    /// No `[flash]` section (the light position is known): no targets, the emitting point at
    /// the flash frame's origin, diameter 0 (not stated; nothing downstream uses it).
    fn default() -> Self {
        Self {
            diameter_m: 0.0,
            light_centre_m: DVec3::ZERO,
            targets: Vec::new(),
        }
    }
}

impl FlashSpec {
    /// True for [`FlashSpec::default`], the value of an absent `[flash]` section.
    pub fn is_unstated(&self) -> bool {
        *self == Self::default()
    }
}

/// The calibrated reflectance standard and its targets, in the standard's frame.
///
/// Standard frame: the reflecting surface is the plane z = 0, normal +z, centred on the origin.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StandardSpec {
    /// Its known BRDF (e.g. Lambertian with albedo 0.99).
    pub brdf: BrdfModel,
    /// Width and height of the reflecting area, metres.
    pub size_m: [f64; 2],
    /// Targets framing the standard, standard frame.
    #[serde(default)]
    pub targets: Vec<Target>,
}

/// Length units of a scan file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LengthUnit {
    /// Metres.
    M,
    /// Centimetres.
    Cm,
    /// Millimetres.
    Mm,
    /// Inches.
    In,
}

impl LengthUnit {
    /// Factor that converts a value in this unit to metres.
    pub const fn to_m(self) -> f64 {
        match self {
            Self::M => 1.0,
            Self::Cm => 0.01,
            Self::Mm => 0.001,
            Self::In => 0.0254,
        }
    }
}

/// The sample's geometry, in the head frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum GeometrySpec {
    /// A head scan (PLY, OBJ, `.glb` or `.gltf`) whose frame is the head frame; load it with
    /// `skinbrdf-mesh`.
    Scan {
        /// Scan file relative to the session directory.
        file: String,
        /// The scan's length unit.
        units: LengthUnit,
        /// Largest fraction of the scan's triangles its repair may drop (triangles on
        /// non-finite vertices or with bad indices) before loading fails; default 1 %. Stating
        /// a larger one is the user's acceptance of a damaged scan.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        accept_repair_loss: Option<f64>,
    },
    /// An ideal sphere.
    Sphere {
        /// Centre, head frame, metres.
        centre_m: DVec3,
        /// Radius, metres.
        radius_m: f64,
    },
    /// An ideal (capped-length) cylinder.
    Cylinder {
        /// Centre of the axis segment, head frame, metres.
        centre_m: DVec3,
        /// Axis direction (need not be unit length).
        axis: DVec3,
        /// Radius, metres.
        radius_m: f64,
        /// Length along the axis, metres.
        length_m: f64,
    },
}

/// The region of interest: the part of the geometry within `radius_m` of `centre_m`
/// (head frame). Per-image user masks (`images[].mask`) restrict it further.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionOfInterest {
    /// Centre, head frame, metres.
    pub centre_m: DVec3,
    /// Radius, metres.
    pub radius_m: f64,
}

/// Quantities known in advance; each lets the pipeline skip the stage that would estimate it.
/// (Per-image camera and head poses are in `[[images]]`.)
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KnownQuantities {
    /// Light (flash emitting point) position, world frame, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_position_m: Option<DVec3>,
    /// World from flash pose (locates the flash targets too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_from_flash: Option<Pose>,
    /// The radiometric calibration constant C per RGB channel (see the radiometric convention).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_c: Option<[f64; 3]>,
    /// World from standard pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_from_standard: Option<Pose>,
    /// The sample does not move between images (skips head tracking: `world_from_head` of the
    /// first image, or identity, applies to all).
    #[serde(default)]
    pub stationary_sample: bool,
}
