//! Poses as plain, already-resolved data: what derendering needs to know about where things
//! are, each quantity with where it came from ([`PoseSource`]).
//!
//! Derendering does not decide where poses come from: the caller resolves them (the pipeline's
//! `pose_inputs::resolve_poses` applies the precedence session → pose stage → truth) and hands
//! over a [`ResolvedPoses`]. [`DerenderInputs::new`] is the one place that turns it, with the
//! session's radiometric quantities (known C or the reflectance standard), into the
//! [`DerenderInputs`] of [`crate::derender_with_loader`].
//!
//! [`ResolvedPoses::from_truth`] takes every pose from `truth.json`, marked as truth: for
//! examples and tests that derender a synthetic session in isolation from the pose stage.

use glam::DVec3;
use serde::Serialize;
use skinbrdf_core::{CameraModel, Pose};
use skinbrdf_session::{ImageRole, Session, Truth, SESSION_FILE};

use crate::session::{CalibrationInput, DerenderInputs, ImagePoses, PoseSource};
use crate::{DerenderError, MissingInput};

/// A value with where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sourced<T> {
    /// The value.
    pub value: T,
    /// Where it came from.
    pub source: PoseSource,
}

impl<T> Sourced<T> {
    /// `value` from `source`.
    pub fn new(value: T, source: PoseSource) -> Self {
        Self { value, source }
    }
}

/// The poses of one measurement image.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ResolvedImage {
    /// Session image index.
    pub image_index: usize,
    /// World from camera.
    pub world_from_camera: Sourced<Pose>,
    /// World from head (a stationary sample's one head pose, or the identity).
    pub world_from_head: Sourced<Pose>,
}

/// Where the reflectance standard is, and the camera poses of its images.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ResolvedStandard {
    /// World from the standard's frame.
    pub world_from_standard: Sourced<Pose>,
    /// `(session image index, world_from_camera)` per reference-standard image with a camera
    /// pose.
    pub images: Vec<(usize, Sourced<Pose>)>,
}

/// Every pose-like quantity derendering needs, resolved.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ResolvedPoses {
    /// The calibrated camera.
    pub camera: Sourced<CameraModel>,
    /// Measurement images with both poses, in session order.
    pub measurements: Vec<ResolvedImage>,
    /// Measurement images left out because a pose is unknown (the pose stage reports why).
    pub unposed: Vec<usize>,
    /// Light (flash emitting point), world frame, metres.
    pub light_position_m: Sourced<DVec3>,
    /// World from flash (locates the flash's printed targets for the target mask); `None`
    /// leaves the flash's targets unmasked.
    pub world_from_flash: Option<Sourced<Pose>>,
    /// The standard's pose and its images' camera poses; `None` when C is known (not needed)
    /// or they are unknown.
    pub standard: Option<ResolvedStandard>,
}

impl ResolvedPoses {
    /// The least direct source among the measurement images' poses (session before pose stage
    /// before truth): `Truth` as soon as one pose came from `truth.json`.
    pub fn pose_source(&self) -> PoseSource {
        self.measurements
            .iter()
            .flat_map(|m| [m.world_from_camera.source, m.world_from_head.source])
            .max()
            .unwrap_or(PoseSource::Session)
    }

    /// The poses of session image `index`, if it is a posed measurement image.
    pub fn image(&self, index: usize) -> Option<ImagePoses> {
        self.measurements
            .iter()
            .find(|m| m.image_index == index)
            .map(|m| ImagePoses {
                world_from_camera: m.world_from_camera.value,
                world_from_head: m.world_from_head.value,
            })
    }

    /// Every quantity from `truth.json` (camera, per-image poses, light, flash, standard),
    /// marked [`PoseSource::Truth`]: derendering a synthetic session in isolation.
    pub fn from_truth(session: &Session, truth: &Truth) -> Result<Self, DerenderError> {
        let truth_of = |i: usize| {
            let file = &session.file.images[i].file;
            truth.image(file).ok_or_else(|| DerenderError::Missing {
                file: session.truth_path(),
                missing: MissingInput::ImageTruth {
                    index: i,
                    image: file.clone(),
                },
            })
        };
        let t = |value| Sourced::new(value, PoseSource::Truth);
        let mut measurements = Vec::new();
        for (i, _) in session.images_with_role(ImageRole::Measurement) {
            let it = truth_of(i)?;
            measurements.push(ResolvedImage {
                image_index: i,
                world_from_camera: t(it.world_from_camera),
                world_from_head: t(it.world_from_head),
            });
        }
        let mut images = Vec::new();
        for (i, _) in session.images_with_role(ImageRole::ReferenceStandard) {
            images.push((i, t(truth_of(i)?.world_from_camera)));
        }
        Ok(Self {
            camera: Sourced::new(truth.camera, PoseSource::Truth),
            measurements,
            unposed: Vec::new(),
            light_position_m: Sourced::new(truth.light_position_m, PoseSource::Truth),
            world_from_flash: Some(t(truth.world_from_flash)),
            standard: Some(ResolvedStandard {
                world_from_standard: t(truth.world_from_standard),
                images,
            }),
        })
    }
}

impl DerenderInputs {
    /// The one constructor from a session: the resolved poses, and C known
    /// (`known.calibration_c`) or from the reflectance standard (`[standard]`'s BRDF and size
    /// with the resolved standard poses).
    pub fn new(session: &Session, poses: &ResolvedPoses) -> Result<Self, DerenderError> {
        let f = &session.file;
        let missing = |missing| DerenderError::Missing {
            file: session.dir.join(SESSION_FILE),
            missing,
        };
        if poses.measurements.is_empty() {
            return Err(missing(MissingInput::PosedMeasurement {
                unposed: poses.unposed.len(),
            }));
        }
        let calibration = match (f.known.calibration_c, &f.standard, &poses.standard) {
            (Some(c), _, _) => CalibrationInput::Known(c),
            (None, None, _) => return Err(missing(MissingInput::Calibration)),
            (None, Some(_), None) => return Err(missing(MissingInput::StandardPoses)),
            (None, Some(_), Some(s)) if s.images.is_empty() => {
                return Err(missing(MissingInput::StandardPoses))
            }
            (None, Some(std), Some(s)) => CalibrationInput::Standard {
                brdf: std.brdf.clone(),
                size_m: std.size_m,
                world_from_standard: s.world_from_standard.value,
                images: s.images.iter().map(|(i, p)| (*i, p.value)).collect(),
            },
        };
        Ok(Self {
            camera: poses.camera.value,
            light_position_m: poses.light_position_m.value,
            calibration,
            measurements: poses
                .measurements
                .iter()
                .map(|m| {
                    (
                        m.image_index,
                        ImagePoses {
                            world_from_camera: m.world_from_camera.value,
                            world_from_head: m.world_from_head.value,
                        },
                    )
                })
                .collect(),
            pose_source: poses.pose_source(),
        })
    }
}
