//! The poses derendering uses, resolved from the session, the pose stage and (only when asked
//! for) the ground truth: [`resolve_poses`], and [`derender_session`] on top of it.
//!
//! Every quantity is taken from the first source that has it, and the result records which
//! ([`PoseSource`]):
//!
//! 1. **`session.toml`**: what the session states as known;
//! 2. **the pose stage's result** ([`SessionPoses`]), when given ([`PoseChoice::Auto`],
//!    [`PoseChoice::Estimated`]);
//! 3. **`truth.json`**, only with [`PoseChoice::Truth`] (synthetic sessions, to derender in
//!    isolation from the pose stage); such values are marked [`PoseSource::Truth`].
//!
//! Per quantity, the session's own entries are:
//!
//! | quantity | `session.toml` |
//! |---|---|
//! | camera model | `[camera]` when calibrated |
//! | `world_from_camera` of image i | `images[i].world_from_camera` |
//! | `world_from_head` of image i | `images[i].world_from_head`; for a stationary sample (`known.stationary_sample`) the one head pose: the first measurement image's stated `world_from_head`, else the identity (the head frame is the world frame) |
//! | light | `known.light_position_m`, else `known.world_from_flash` applied to `flash.light_centre_m` |
//! | world from flash (masks the flash's targets) | `known.world_from_flash` |
//! | world from standard (only when C is not known) | `known.world_from_standard` |
//!
//! A stationary sample's head pose always comes from the session: the pose stage does not
//! track the head then (nothing moves), so session poses and estimated poses agree on it.
//!
//! A measurement image without both poses is an error naming the image, except when the pose
//! stage's result is used: the pose stage may fail on some images (it reports why), and those
//! are left out ([`ResolvedPoses::unposed`]); at least one must remain.

use std::path::PathBuf;

use serde::Serialize;
use skinbrdf_core::Pose;
use skinbrdf_derender::{
    DerenderConfig, DerenderError, PoseSource, ResolvedImage, ResolvedPoses, ResolvedStandard,
    SessionRun, Sourced, TargetMask,
};
use skinbrdf_poses::SessionPoses;
use skinbrdf_session::{FileError, ImageRole, Session, Truth, SESSION_FILE};

/// Which sources [`resolve_poses`] may use besides `session.toml`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum PoseChoice {
    /// `session.toml`, then the pose stage's result when one is given; never the truth.
    #[default]
    Auto,
    /// Only `session.toml`.
    Session,
    /// `session.toml`, then the pose stage's result (which must be given).
    Estimated,
    /// `session.toml`, then `truth.json` (which must be given); values from it are marked
    /// [`PoseSource::Truth`].
    Truth,
}

/// A quantity [`resolve_poses`] could not find.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Quantity {
    /// The camera model.
    Camera,
    /// The light position.
    Light,
    /// An image's camera pose.
    WorldFromCamera {
        /// Session image index.
        index: usize,
        /// Its file.
        image: String,
    },
    /// A measurement image's head pose.
    WorldFromHead {
        /// Session image index.
        index: usize,
        /// Its file.
        image: String,
    },
    /// The reflectance standard's pose.
    WorldFromStandard,
    /// A camera pose for any reference-standard image.
    StandardImageCamera,
}

impl std::fmt::Display for Quantity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Camera => f.write_str("camera model"),
            Self::Light => f.write_str("light position"),
            Self::WorldFromCamera { index, image } => {
                write!(f, "world_from_camera for images[{index}] ({image})")
            }
            Self::WorldFromHead { index, image } => {
                write!(f, "world_from_head for images[{index}] ({image})")
            }
            Self::WorldFromStandard => f.write_str("world_from_standard"),
            Self::StandardImageCamera => {
                f.write_str("world_from_camera for any reference-standard image")
            }
        }
    }
}

fn sources_list(s: &[PoseSource]) -> String {
    s.iter()
        .map(|p| p.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Errors of [`resolve_poses`].
#[derive(Debug, thiserror::Error)]
pub enum PoseInputError {
    /// The session has no measurement image.
    #[error("{file}: the session has no measurement images", file = file.display())]
    NoMeasurementImages {
        /// `session.toml`.
        file: PathBuf,
    },
    /// [`PoseChoice::Estimated`] without the pose stage's result.
    #[error("poses from the pose stage were asked for, but no pose stage result was given (run the pose stage, or give its poses.json)")]
    NoEstimate,
    /// [`PoseChoice::Truth`] without `truth.json`.
    #[error("{file}: poses from the truth were asked for, but there is none", file = file.display())]
    NoTruth {
        /// The `truth.json` path looked at.
        file: PathBuf,
    },
    /// The pose stage's result does not belong to this session.
    #[error(
        "the pose stage's result has {estimated} images but {file} has {session}",
        file = file.display()
    )]
    ImageCount {
        /// `session.toml`.
        file: PathBuf,
        /// Images in the pose stage's result.
        estimated: usize,
        /// Images in the session.
        session: usize,
    },
    /// A quantity is in none of the allowed sources.
    #[error(
        "{file}: no {quantity} in {} (run the pose stage, or state it as known)",
        sources_list(looked_in),
        file = file.display()
    )]
    Unknown {
        /// `session.toml`.
        file: PathBuf,
        /// What is missing.
        quantity: Quantity,
        /// The sources consulted, in order.
        looked_in: Vec<PoseSource>,
    },
}

/// Resolves every pose-like quantity derendering needs (see the module docs for the
/// precedence). `estimated` is used with [`PoseChoice::Auto`] and [`PoseChoice::Estimated`],
/// `truth` only with [`PoseChoice::Truth`].
pub fn resolve_poses(
    session: &Session,
    choice: PoseChoice,
    estimated: Option<&SessionPoses>,
    truth: Option<&Truth>,
) -> Result<ResolvedPoses, PoseInputError> {
    let f = &session.file;
    let file = session.dir.join(SESSION_FILE);
    let est = match choice {
        PoseChoice::Auto => estimated,
        PoseChoice::Estimated => Some(estimated.ok_or(PoseInputError::NoEstimate)?),
        PoseChoice::Session | PoseChoice::Truth => None,
    };
    let truth = match choice {
        PoseChoice::Truth => Some(truth.ok_or_else(|| PoseInputError::NoTruth {
            file: session.truth_path(),
        })?),
        _ => None,
    };
    if let Some(e) = est {
        if e.images.len() != f.images.len() {
            return Err(PoseInputError::ImageCount {
                file,
                estimated: e.images.len(),
                session: f.images.len(),
            });
        }
    }
    let mut looked_in = vec![PoseSource::Session];
    looked_in.extend(est.map(|_| PoseSource::Estimated));
    looked_in.extend(truth.map(|_| PoseSource::Truth));
    let unknown = |quantity| PoseInputError::Unknown {
        file: file.clone(),
        quantity,
        looked_in: looked_in.clone(),
    };
    // The first of (session, estimate, truth) that has the value.
    let first = |s: Option<Pose>, e: Option<Pose>, t: Option<Pose>| {
        s.map(|v| Sourced::new(v, PoseSource::Session))
            .or(e.map(|v| Sourced::new(v, PoseSource::Estimated)))
            .or(t.map(|v| Sourced::new(v, PoseSource::Truth)))
    };
    let image_truth = |i: usize| truth.and_then(|t| t.image(&f.images[i].file));
    let est_camera = |i: usize| {
        est.and_then(|e| e.images[i].world_from_camera.as_ref())
            .map(|p| p.pose)
    };
    let world_from_camera = |i: usize| {
        first(
            f.images[i].world_from_camera,
            est_camera(i),
            image_truth(i).map(|t| t.world_from_camera),
        )
    };

    let camera = f
        .camera
        .model()
        .map(|m| Sourced::new(*m, PoseSource::Session))
        .or(est.map(|e| Sourced::new(e.camera, PoseSource::Estimated)))
        .or(truth.map(|t| Sourced::new(t.camera, PoseSource::Truth)))
        .ok_or_else(|| unknown(Quantity::Camera))?;

    let meas: Vec<usize> = session
        .images_with_role(ImageRole::Measurement)
        .map(|(i, _)| i)
        .collect();
    if meas.is_empty() {
        return Err(PoseInputError::NoMeasurementImages { file: file.clone() });
    }
    // A stationary sample's one head pose (the pose stage does not track it).
    let stationary_head = f.known.stationary_sample.then(|| {
        meas.iter()
            .find_map(|&i| f.images[i].world_from_head)
            .unwrap_or(Pose::IDENTITY)
    });
    let mut measurements = Vec::new();
    let mut unposed = Vec::new();
    for &i in &meas {
        let head = first(
            f.images[i].world_from_head.or(stationary_head),
            est.and_then(|e| e.images[i].world_from_head.as_ref())
                .map(|p| p.pose),
            image_truth(i).map(|t| t.world_from_head),
        );
        match (world_from_camera(i), head) {
            (Some(c), Some(h)) => measurements.push(ResolvedImage {
                image_index: i,
                world_from_camera: c,
                world_from_head: h,
            }),
            // The pose stage reports why it found no pose for this image.
            _ if est.is_some() => unposed.push(i),
            (c, _) => {
                let image = f.images[i].file.clone();
                return Err(unknown(if c.is_none() {
                    Quantity::WorldFromCamera { index: i, image }
                } else {
                    Quantity::WorldFromHead { index: i, image }
                }));
            }
        }
    }

    let light_position_m = f
        .known
        .light_position_m
        .or(f
            .known
            .world_from_flash
            .map(|p| p.transform_point(f.flash.light_centre_m)))
        .map(|l| Sourced::new(l, PoseSource::Session))
        .or(est
            .and_then(|e| e.light_position_m)
            .map(|l| Sourced::new(l, PoseSource::Estimated)))
        .or(truth.map(|t| Sourced::new(t.light_position_m, PoseSource::Truth)))
        .ok_or_else(|| unknown(Quantity::Light))?;

    let world_from_flash = first(
        f.known.world_from_flash,
        est.and_then(|e| e.world_from_flash.as_ref())
            .map(|p| p.pose),
        truth.map(|t| t.world_from_flash),
    );

    // The standard's poses, only when C is to come from it.
    let standard = match (&f.standard, f.known.calibration_c) {
        (Some(_), None) => {
            let world_from_standard = first(
                f.known.world_from_standard,
                est.and_then(|e| e.world_from_standard.as_ref())
                    .map(|p| p.pose),
                truth.map(|t| t.world_from_standard),
            )
            .ok_or_else(|| unknown(Quantity::WorldFromStandard))?;
            let mut images = Vec::new();
            for (i, e) in session.images_with_role(ImageRole::ReferenceStandard) {
                match world_from_camera(i) {
                    Some(p) => images.push((i, p)),
                    None if est.is_some() => {}
                    None => {
                        return Err(unknown(Quantity::WorldFromCamera {
                            index: i,
                            image: e.file.clone(),
                        }))
                    }
                }
            }
            if images.is_empty() {
                return Err(unknown(Quantity::StandardImageCamera));
            }
            Some(ResolvedStandard {
                world_from_standard,
                images,
            })
        }
        _ => None,
    };

    Ok(ResolvedPoses {
        camera,
        measurements,
        unposed,
        light_position_m,
        world_from_flash,
        standard,
    })
}

/// Options of [`derender_session`] besides the [`DerenderConfig`].
#[derive(Debug, Clone, Default)]
pub struct SessionOptions {
    /// Which sources the poses may come from.
    pub poses: PoseChoice,
    /// Do not mask the printed targets.
    pub skip_target_mask: bool,
    /// The pose stage's result (`skinbrdf_poses::estimate_session`, or `out/poses.json`).
    pub estimated: Option<SessionPoses>,
}

/// Errors of [`derender_session`].
#[derive(Debug, thiserror::Error)]
pub enum DerenderSessionError {
    /// The poses could not be resolved.
    #[error(transparent)]
    Poses(#[from] PoseInputError),
    /// `truth.json` (asked for with [`PoseChoice::Truth`]) could not be read.
    #[error("poses from the truth: {error}")]
    Truth {
        /// The loader's error (names the file).
        error: FileError,
    },
    /// Derendering failed.
    #[error("derendering: {0}")]
    Derender(DerenderError),
}

impl From<DerenderError> for DerenderSessionError {
    fn from(e: DerenderError) -> Self {
        Self::Derender(e)
    }
}

/// Resolves the poses ([`resolve_poses`]; `truth.json` is read only for [`PoseChoice::Truth`])
/// and derenders the session ([`skinbrdf_derender::derender_session`]).
pub fn derender_session(
    session: &Session,
    opts: &SessionOptions,
    cfg: &DerenderConfig,
) -> Result<SessionRun, DerenderSessionError> {
    let truth = match opts.poses {
        PoseChoice::Truth => session
            .load_truth()
            .transpose()
            .map_err(|error| DerenderSessionError::Truth { error })?,
        _ => None,
    };
    let poses = resolve_poses(session, opts.poses, opts.estimated.as_ref(), truth.as_ref())?;
    let mask = if opts.skip_target_mask {
        TargetMask::Skip
    } else {
        TargetMask::Printed
    };
    Ok(skinbrdf_derender::derender_session(
        session, &poses, mask, cfg,
    )?)
}

#[cfg(test)]
pub(crate) mod tests {
    use std::collections::HashMap;

    use glam::DVec3;
    use skinbrdf_brdf::BrdfModel;
    use skinbrdf_core::CameraModel;
    use skinbrdf_derender::{DerenderInputs, MissingInput};
    use skinbrdf_poses::session::{ImagePoses, PoseWithCov};
    use skinbrdf_session::{
        CameraSpec, FlashSpec, GeometrySpec, ImageEntry, KnownQuantities, Linearization,
        SessionFile, StandardSpec, TargetLayouts, SESSION_FORMAT_VERSION,
    };

    use super::*;

    const ROLES: [ImageRole; 4] = [
        ImageRole::Measurement,
        ImageRole::Measurement,
        ImageRole::Measurement,
        ImageRole::ReferenceStandard,
    ];

    pub(crate) fn camera_pose(i: usize) -> Pose {
        Pose::look_at(DVec3::new(0.1 * i as f64, 0.0, 0.6), DVec3::ZERO, DVec3::Y)
            .expect("camera pose")
    }

    /// Three measurement images and one standard image; nothing known but `known`.
    pub(crate) fn session(known: KnownQuantities) -> Session {
        let images = ROLES
            .iter()
            .enumerate()
            .map(|(i, &role)| ImageEntry {
                file: format!("images/{i}.png"),
                role,
                exposure_index: None,
                linearization: None,
                mask: None,
                world_from_camera: None,
                world_from_head: None,
                exposure_scale: None,
            })
            .collect();
        Session::from_parts(
            PathBuf::from("/nonexistent/session"),
            SessionFile {
                format_version: SESSION_FORMAT_VERSION,
                description: "pose inputs".into(),
                capture: None,
                camera: CameraSpec::ToBeCalibrated {
                    width_px: 64,
                    height_px: 48,
                    focal_guess_px: None,
                },
                linearization: Linearization::LINEAR,
                images,
                targets: TargetLayouts::default(),
                flash: FlashSpec {
                    diameter_m: 0.08,
                    light_centre_m: DVec3::ZERO,
                    targets: Vec::new(),
                },
                standard: Some(StandardSpec {
                    brdf: BrdfModel::Lambertian { albedo: [0.99; 3] },
                    size_m: [0.1, 0.1],
                    targets: Vec::new(),
                }),
                geometry: GeometrySpec::Sphere {
                    centre_m: DVec3::ZERO,
                    radius_m: 0.08,
                },
                roi: None,
                known,
                registration: None,
            },
            None,
        )
    }

    fn estimated_pose(pose: Pose) -> PoseWithCov {
        PoseWithCov {
            pose,
            covariance: Vec::new(),
            rms_px: 0.2,
            targets_used: 4,
            source: "estimated".into(),
        }
    }

    /// What the pose stage returns for [`session`]: every camera pose, head poses only when
    /// `heads` (a stationary sample's head is not tracked), the light and the standard.
    fn estimate(heads: bool) -> SessionPoses {
        SessionPoses {
            camera: CameraModel::from_fov(64, 48, 0.8),
            calibration: None,
            images: ROLES
                .iter()
                .enumerate()
                .map(|(i, &role)| ImagePoses {
                    file: format!("images/{i}.png"),
                    role,
                    targets_found: HashMap::new(),
                    world_from_camera: Some(estimated_pose(camera_pose(i))),
                    world_from_head: (heads && role == ImageRole::Measurement)
                        .then(|| estimated_pose(Pose::IDENTITY)),
                    world_from_flash: None,
                    world_from_standard: None,
                    detect_ms: 0.0,
                    pose_ms: 0.0,
                    diagnostics: Vec::new(),
                    errors: Vec::new(),
                    detections: Vec::new(),
                })
                .collect(),
            light_position_m: Some(DVec3::new(0.1, 0.2, 0.5)),
            light_position_cov_m2: Vec::new(),
            light_agreement: None,
            world_from_flash: None,
            world_from_standard: Some(estimated_pose(Pose::IDENTITY)),
            skipped: Vec::new(),
            total_ms: 0.0,
            bundle: None,
        }
    }

    fn stationary() -> KnownQuantities {
        KnownQuantities {
            stationary_sample: true,
            ..Default::default()
        }
    }

    /// Resume never reuses derendering over a changed scan or mask: both are inputs of the
    /// derender unit's fingerprint.
    #[test]
    fn the_derender_fingerprint_covers_the_scan_and_the_masks() {
        use crate::stages::{Ctx, DerenderUnit, StageUnit};
        let dir = tempfile::tempdir().expect("tempdir");
        let mut s = session(KnownQuantities::default());
        s.dir = dir.path().to_path_buf();
        s.file.images[0].mask = Some("masks/m0.png".into());
        s.file.geometry = GeometrySpec::Scan {
            file: "scan.ply".into(),
            units: skinbrdf_session::LengthUnit::Mm,
            accept_repair_loss: None,
        };
        let files = crate::stages::session_input_files(&s);
        for f in &files {
            std::fs::create_dir_all(f.parent().expect("parent")).expect("dir");
            std::fs::write(f, b"v1").expect("write");
        }
        assert!(files.contains(&dir.path().join("scan.ply")));
        assert!(files.contains(&dir.path().join("masks/m0.png")));
        let cfg = crate::process::ProcessConfig::new();
        let facts = crate::process::scene_facts(&s);
        let fp = |s: &Session| {
            let ctx = Ctx {
                session: s,
                truth: None,
                cfg: &cfg,
                out_dir: dir.path().join("out"),
                facts,
                plan: crate::plan::Plan::derive(&facts, &cfg.plan),
                survey: None,
                detections: None,
                stated_camera: s.file.camera,
                poses: None,
                samples: None,
                fit: None,
            };
            DerenderUnit.fingerprint(&ctx).expect("fingerprint")
        };
        let a = fp(&s);
        std::fs::write(dir.path().join("scan.ply"), b"v2").expect("write");
        let b = fp(&s);
        assert_ne!(a, b, "a replaced scan changes the fingerprint");
        std::fs::write(dir.path().join("masks/m0.png"), b"v2").expect("write");
        let c = fp(&s);
        assert_ne!(b, c, "a changed mask changes the fingerprint");
        assert_eq!(c, fp(&s), "unchanged inputs give the same fingerprint");
    }

    /// A scan whose repair loses more than the default 1 % of its triangles fails to load;
    /// stating `geometry.accept_repair_loss` above the loss is the user's acceptance.
    #[test]
    fn a_damaged_scan_loads_only_when_its_loss_is_accepted() {
        let dir = tempfile::tempdir().expect("tempdir");
        // A 20 x 20 vertex grid (722 triangles) with every tenth vertex NaN.
        let n = 20u32;
        let mut positions = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let k = j * n + i;
                positions.push(if k % 10 == 3 {
                    glam::Vec3::splat(f32::NAN)
                } else {
                    glam::Vec3::new(i as f32, j as f32, 0.0)
                });
            }
        }
        let mut indices = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = j * n + i;
                indices.push([a, a + 1, a + n + 1]);
                indices.push([a, a + n + 1, a + n]);
            }
        }
        let mesh = skinbrdf_core::TriMesh {
            positions,
            indices,
            normals: None,
        };
        skinbrdf_mesh::write_ply_binary_in(&dir.path().join("scan.ply"), &mesh, "mm")
            .expect("write scan");
        let mut s = session(KnownQuantities::default());
        s.dir = dir.path().to_path_buf();
        let with = |accept: Option<f64>| {
            let mut s = s.clone();
            s.file.geometry = GeometrySpec::Scan {
                file: "scan.ply".into(),
                units: skinbrdf_session::LengthUnit::Mm,
                accept_repair_loss: accept,
            };
            skinbrdf_derender::from_session::session_geometry(&s, &DerenderConfig::DEFAULT)
        };
        let err = with(None)
            .expect_err("a 30 % loss is refused by default")
            .to_string();
        assert!(err.contains("more than the 1.0 % accepted"), "{err}");
        assert!(with(Some(0.02)).is_err(), "2 % does not cover the loss");
        let (_, report, _) = with(Some(0.5)).expect("accepted");
        let report = report.expect("a scan's repair report");
        assert!(report.lost_triangles() > report.triangles_in / 10);
    }

    #[test]
    fn a_stationary_sample_derenders_from_estimated_camera_poses() {
        let s = session(stationary());
        let est = estimate(false);
        let p = resolve_poses(&s, PoseChoice::Estimated, Some(&est), None).expect("resolves");
        assert_eq!(p.measurements.len(), 3, "{p:?}");
        assert!(p.unposed.is_empty());
        for m in &p.measurements {
            assert_eq!(m.world_from_head.value, Pose::IDENTITY);
            assert_eq!(m.world_from_head.source, PoseSource::Session);
            assert_eq!(m.world_from_camera.source, PoseSource::Estimated);
        }
        assert_eq!(p.pose_source(), PoseSource::Estimated);
        let inputs = DerenderInputs::new(&s, &p).expect("inputs");
        assert_eq!(inputs.measurements.len(), 3);
    }

    #[test]
    fn session_and_estimated_paths_agree_on_a_stationary_head() {
        let head = Pose::look_at(DVec3::new(0.0, 0.01, 0.02), DVec3::Z, DVec3::Y).expect("pose");
        // The session states the camera, the light, the standard's pose, the one head pose on
        // one image and every camera pose.
        let mut s = session(KnownQuantities {
            light_position_m: Some(DVec3::new(0.1, 0.2, 0.5)),
            world_from_standard: Some(Pose::IDENTITY),
            ..stationary()
        });
        s.file.camera = CameraSpec::Calibrated(CameraModel::from_fov(64, 48, 0.8));
        s.file.images[1].world_from_head = Some(head);
        for (i, e) in s.file.images.iter_mut().enumerate() {
            e.world_from_camera = Some(camera_pose(i));
        }
        let from_session = resolve_poses(&s, PoseChoice::Session, None, None).expect("session");
        let est = estimate(false);
        let from_estimate =
            resolve_poses(&s, PoseChoice::Estimated, Some(&est), None).expect("estimated");
        for p in [&from_session, &from_estimate] {
            assert_eq!(p.measurements.len(), 3);
            for m in &p.measurements {
                assert_eq!(m.world_from_head, Sourced::new(head, PoseSource::Session));
                assert_eq!(m.world_from_camera.source, PoseSource::Session);
            }
        }
        assert_eq!(from_session.measurements, from_estimate.measurements);
    }

    #[test]
    fn a_moving_sample_without_head_poses_is_a_precise_error() {
        let s = session(KnownQuantities::default());
        let est = estimate(false);
        // With the pose stage's result: every image left out, then no posed image.
        let p = resolve_poses(&s, PoseChoice::Estimated, Some(&est), None).expect("resolves");
        assert_eq!(p.unposed, vec![0, 1, 2]);
        assert!(matches!(
            DerenderInputs::new(&s, &p),
            Err(DerenderError::Missing {
                missing: MissingInput::PosedMeasurement { unposed: 3 },
                ..
            })
        ));
        // From the session alone: the first image and what it lacks.
        let e = resolve_poses(&s, PoseChoice::Session, None, None).unwrap_err();
        assert!(
            matches!(
                &e,
                PoseInputError::Unknown { quantity: Quantity::Camera, looked_in, .. }
                    if looked_in == &[PoseSource::Session]
            ),
            "{e}"
        );
    }

    #[test]
    fn session_known_quantities_come_first() {
        let light = DVec3::new(-0.3, 0.0, 0.4);
        let mut s = session(KnownQuantities {
            light_position_m: Some(light),
            ..stationary()
        });
        let cam = CameraModel::from_fov(64, 48, 0.5);
        s.file.camera = CameraSpec::Calibrated(cam);
        s.file.images[2].world_from_camera = Some(camera_pose(7));
        let est = estimate(true);
        let p = resolve_poses(&s, PoseChoice::Auto, Some(&est), None).expect("resolves");
        assert_eq!(p.camera, Sourced::new(cam, PoseSource::Session));
        assert_eq!(p.light_position_m, Sourced::new(light, PoseSource::Session));
        assert_eq!(
            p.measurements[2].world_from_camera,
            Sourced::new(camera_pose(7), PoseSource::Session)
        );
        assert_eq!(
            p.measurements[0].world_from_camera.source,
            PoseSource::Estimated
        );
        let std = p.standard.as_ref().expect("standard");
        assert_eq!(std.world_from_standard.source, PoseSource::Estimated);
        assert_eq!(std.images.len(), 1);
    }

    #[test]
    fn the_truth_is_used_only_when_asked_for() {
        let s = session(stationary());
        // Auto never falls back to the truth: without an estimate the camera is unknown.
        assert!(matches!(
            resolve_poses(&s, PoseChoice::Auto, None, None),
            Err(PoseInputError::Unknown {
                quantity: Quantity::Camera,
                ..
            })
        ));
        assert!(matches!(
            resolve_poses(&s, PoseChoice::Truth, None, None),
            Err(PoseInputError::NoTruth { .. })
        ));
        assert!(matches!(
            resolve_poses(&s, PoseChoice::Estimated, None, None),
            Err(PoseInputError::NoEstimate)
        ));
    }

    #[test]
    fn an_estimate_of_another_session_is_refused() {
        let s = session(stationary());
        let mut est = estimate(false);
        est.images.pop();
        let e = resolve_poses(&s, PoseChoice::Estimated, Some(&est), None).unwrap_err();
        assert!(
            matches!(
                e,
                PoseInputError::ImageCount {
                    estimated: 3,
                    session: 4,
                    ..
                }
            ),
            "{e}"
        );
    }
}
