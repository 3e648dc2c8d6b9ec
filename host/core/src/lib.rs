//! Domain types shared by every skinbrdf stage.
//!
//! Conventions used throughout the project (every crate follows them):
//!
//! * **Units** are SI and appear in names: metres (`_m`), radians (`_rad`), pixels (`_px`),
//!   microseconds (`_us`). Meshes are stored in metres; a scan in other units is converted at load.
//! * **Frames.** A [`Pose`] named `a_from_b` maps coordinates in frame `b` to frame `a`
//!   (`p_a = a_from_b * p_b`). The world frame is the reference structure's frame. The camera
//!   frame is OpenCV's: x right, y down, z forward (optical axis). The head frame is the head
//!   scan's frame.
//! * **BRDF directions** are unit vectors pointing *away* from the surface, expressed in the local
//!   shading frame whose +z is the surface normal (see [`angles`]).

pub mod angles;
pub mod camera;
pub mod fsio;
pub mod json;
pub mod mesh;
pub mod pose;
pub mod sample;
pub mod stats;
pub mod untrusted;

pub use angles::{BrdfAngles, ShadingFrame};
pub use camera::{BrownConrady, CameraError, CameraModel};
pub use mesh::{MeshError, TriMesh};
pub use pose::Pose;
pub use sample::{BrdfSample, SurfacePoint};

/// Re-export of the vector math the domain types are built on.
pub use glam;

/// An error and its causes, joined by `": "` (what `anyhow`'s `{:#}` prints).
///
/// Every error in the workspace either names its cause in its own message or exposes it as
/// [`std::error::Error::source`], never both, so this text names each cause once. Use it wherever
/// an error becomes text (a report entry, a log line, another error's `problem` string).
pub fn error_text(err: &dyn std::error::Error) -> String {
    let mut text = err.to_string();
    let mut cause = err.source();
    while let Some(c) = cause {
        text.push_str(": ");
        text.push_str(&c.to_string());
        cause = c.source();
    }
    text
}

#[cfg(test)]
mod error_text_tests {
    #[derive(Debug, thiserror::Error)]
    #[error("reading a.png")]
    struct Outer {
        source: std::io::Error,
    }

    #[test]
    fn each_cause_follows_its_error() {
        let err = Outer {
            source: std::io::Error::other("disk full"),
        };
        assert_eq!(super::error_text(&err), "reading a.png: disk full");
    }
}
