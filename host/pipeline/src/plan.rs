//! Deriving the stage plan from what a scene has and needs.
//!
//! The rules (each skipped stage carries its reason):
//!
//! | stage | skipped when |
//! |---|---|
//! | placement survey | every target's placement is given |
//! | camera calibration | the session states the intrinsics |
//! | camera poses | the session gives every camera pose |
//! | head tracking | head poses are given, or the sample is stationary |
//! | flash triangulation | the light position is given |
//! | radiometric calibration (C) | the session gives C |
//! | scan preparation | the sample is an ideal sphere or cylinder (no scan needed) |
//! | shadow rays | the region of interest is convex (it cannot shadow itself) |
//! | hemisphere smoothing | only the incidence plane is requested |
//!
//! Derendering, incidence-plane smoothing, fitting and the report always run.

use serde::{Deserialize, Serialize};

/// The stages of `skinbrdf process`, in execution order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stage {
    /// Placements of the targets nobody measured, from the images.
    PlacementSurvey,
    /// Camera intrinsics and distortion from the reference field.
    CameraCalibration,
    /// Camera pose per image from the reference targets.
    CameraPoses,
    /// Head pose per image from the headdress targets.
    HeadTracking,
    /// Flash position from the light-position images.
    FlashTriangulation,
    /// Calibration constant C from the reference standard (equation 3).
    RadiometricCalibration,
    /// Mesh loading, validation, planar-fit normals and the BVH.
    ScanPreparation,
    /// Shadow rays toward the light.
    ShadowRays,
    /// Pixels to BRDF samples (equation 2).
    Derender,
    /// Local quadratic regression on the incidence plane.
    SmoothIncidencePlane,
    /// Local quadratic regression over the (theta_i, theta_e, phi_d) hemisphere grid.
    SmoothHemisphere,
    /// Nonlinear least-squares model fit.
    Fit,
    /// Figures and the report.
    Report,
}

impl Stage {
    /// Every stage in execution order.
    pub const ALL: [Stage; 13] = [
        Stage::PlacementSurvey,
        Stage::CameraCalibration,
        Stage::CameraPoses,
        Stage::HeadTracking,
        Stage::FlashTriangulation,
        Stage::RadiometricCalibration,
        Stage::ScanPreparation,
        Stage::ShadowRays,
        Stage::Derender,
        Stage::SmoothIncidencePlane,
        Stage::SmoothHemisphere,
        Stage::Fit,
        Stage::Report,
    ];

    /// Short human-readable name.
    pub const fn name(self) -> &'static str {
        match self {
            Stage::PlacementSurvey => "placement survey",
            Stage::CameraCalibration => "camera calibration",
            Stage::CameraPoses => "camera poses",
            Stage::HeadTracking => "head tracking",
            Stage::FlashTriangulation => "flash triangulation",
            Stage::RadiometricCalibration => "radiometric calibration (C)",
            Stage::ScanPreparation => "scan preparation",
            Stage::ShadowRays => "shadow rays",
            Stage::Derender => "derender",
            Stage::SmoothIncidencePlane => "smoothing (incidence plane)",
            Stage::SmoothHemisphere => "smoothing (hemisphere)",
            Stage::Fit => "model fit",
            Stage::Report => "report",
        }
    }
}

/// The sample's geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Geometry {
    /// A range-scanned mesh.
    Scan,
    /// An ideal sphere with known pose.
    Sphere,
    /// An ideal cylinder with known pose.
    Cylinder,
}

/// What a scene already has: derived from the session by the caller.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneFacts {
    /// Every reference and headdress target has a placement (nothing to survey).
    #[serde(default = "yes")]
    pub placements_known: bool,
    /// The session states the camera intrinsics and distortion.
    pub intrinsics_known: bool,
    /// The session gives a camera pose for every image.
    pub camera_poses_known: bool,
    /// The session gives a head pose for every measurement image.
    pub head_poses_known: bool,
    /// The sample does not move between shots (no headdress tracking needed).
    pub stationary_sample: bool,
    /// The session gives the light position.
    pub light_position_known: bool,
    /// The session gives the calibration constant C.
    pub calibration_known: bool,
    /// The sample's geometry.
    pub geometry: Geometry,
    /// The region of interest is convex: known for ideal shapes, measured by scan preparation's
    /// convexity test for scans (`None` until then: shadow rays are then decided by that test).
    pub region_convex: Option<bool>,
}

/// What the user asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct PlanOptions {
    /// Only the incidence plane is wanted: skip hemisphere smoothing.
    pub incidence_plane_only: bool,
    /// Force shadow rays even for a convex region (a check of the convexity claim).
    pub force_shadow_rays: bool,
}

/// What happens to one stage.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "action", rename_all = "kebab-case")]
pub enum Action {
    /// The stage runs.
    Run,
    /// The stage is not needed; `reason` says why.
    Skip {
        /// Why.
        reason: String,
    },
}

/// One line of the plan.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PlannedStage {
    /// The stage.
    pub stage: Stage,
    /// Run or skip.
    #[serde(flatten)]
    pub action: Action,
}

/// The whole plan, in execution order.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Plan {
    /// Every stage with its action.
    pub stages: Vec<PlannedStage>,
    /// Shadow rays wait for the convexity test (a scan whose convexity is not yet known).
    #[serde(default)]
    pub convexity_pending: bool,
}

impl Plan {
    /// Derives the plan.
    pub fn derive(facts: &SceneFacts, options: &PlanOptions) -> Self {
        let stages = Stage::ALL
            .iter()
            .map(|&stage| PlannedStage {
                stage,
                action: match skip_reason(stage, facts, options) {
                    Some(reason) => Action::Skip {
                        reason: reason.to_string(),
                    },
                    None => Action::Run,
                },
            })
            .collect();
        Self {
            stages,
            convexity_pending: facts.region_convex.is_none() && !options.force_shadow_rays,
        }
    }

    /// True when the stage runs.
    pub fn runs(&self, stage: Stage) -> bool {
        self.stages
            .iter()
            .any(|s| s.stage == stage && s.action == Action::Run)
    }

    /// The plan as aligned text lines, for printing before the run.
    pub fn to_text(&self) -> String {
        let mut out = String::from("plan:\n");
        for s in &self.stages {
            match &s.action {
                Action::Run if s.stage == Stage::ShadowRays && self.convexity_pending => out
                    .push_str(&format!(
                        "  run?  {:<28} (if scan preparation's convexity test finds the region can shadow itself)\n",
                        s.stage.name()
                    )),
                Action::Run => out.push_str(&format!("  run   {}\n", s.stage.name())),
                Action::Skip { reason } => {
                    out.push_str(&format!("  skip  {:<28} ({reason})\n", s.stage.name()))
                }
            }
        }
        out
    }
}

fn yes() -> bool {
    true
}

fn skip_reason(stage: Stage, f: &SceneFacts, o: &PlanOptions) -> Option<&'static str> {
    match stage {
        Stage::PlacementSurvey if f.placements_known => Some("every target's placement is given"),
        Stage::CameraCalibration if f.intrinsics_known => {
            Some("the session states the camera intrinsics")
        }
        Stage::CameraPoses if f.camera_poses_known => Some("the session gives every camera pose"),
        Stage::HeadTracking if f.head_poses_known => Some("the session gives every head pose"),
        Stage::HeadTracking if f.stationary_sample => {
            Some("the sample is stationary: no head motion to track")
        }
        Stage::FlashTriangulation if f.light_position_known => {
            Some("the session gives the light position")
        }
        Stage::RadiometricCalibration if f.calibration_known => {
            Some("the session gives the calibration constant C")
        }
        Stage::ScanPreparation if f.geometry == Geometry::Sphere => {
            Some("an ideal sphere needs no scan")
        }
        Stage::ScanPreparation if f.geometry == Geometry::Cylinder => {
            Some("an ideal cylinder needs no scan")
        }
        Stage::ShadowRays if f.region_convex == Some(true) && !o.force_shadow_rays => {
            Some("the region is convex: it cannot shadow itself")
        }
        Stage::SmoothHemisphere if o.incidence_plane_only => {
            Some("only the incidence plane was requested")
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn full() -> SceneFacts {
        SceneFacts {
            placements_known: false,
            intrinsics_known: false,
            camera_poses_known: false,
            head_poses_known: false,
            stationary_sample: false,
            light_position_known: false,
            calibration_known: false,
            geometry: Geometry::Scan,
            region_convex: Some(false),
        }
    }

    #[test]
    fn a_scene_with_nothing_known_runs_everything() {
        let plan = Plan::derive(&full(), &PlanOptions::default());
        assert!(
            Stage::ALL.iter().all(|&s| plan.runs(s)),
            "{}",
            plan.to_text()
        );
    }

    #[test]
    fn each_known_quantity_skips_exactly_its_stage() {
        type Case = (fn(&mut SceneFacts), Stage);
        let cases: [Case; 8] = [
            (|f| f.placements_known = true, Stage::PlacementSurvey),
            (|f| f.intrinsics_known = true, Stage::CameraCalibration),
            (|f| f.camera_poses_known = true, Stage::CameraPoses),
            (|f| f.head_poses_known = true, Stage::HeadTracking),
            (|f| f.stationary_sample = true, Stage::HeadTracking),
            (|f| f.light_position_known = true, Stage::FlashTriangulation),
            (
                |f| f.calibration_known = true,
                Stage::RadiometricCalibration,
            ),
            (|f| f.region_convex = Some(true), Stage::ShadowRays),
        ];
        for (set, stage) in cases {
            let mut facts = full();
            set(&mut facts);
            let plan = Plan::derive(&facts, &PlanOptions::default());
            for s in Stage::ALL {
                assert_eq!(plan.runs(s), s != stage, "{s:?} with {facts:?}");
            }
        }
    }

    #[test]
    fn ideal_shapes_need_no_scan_and_options_are_followed() {
        let mut facts = full();
        facts.geometry = Geometry::Cylinder;
        facts.region_convex = Some(true);
        let plan = Plan::derive(
            &facts,
            &PlanOptions {
                incidence_plane_only: true,
                force_shadow_rays: true,
            },
        );
        assert!(!plan.runs(Stage::ScanPreparation));
        assert!(plan.runs(Stage::ShadowRays));
        assert!(!plan.runs(Stage::SmoothHemisphere));
        assert!(plan.to_text().contains("an ideal cylinder needs no scan"));
    }
}
