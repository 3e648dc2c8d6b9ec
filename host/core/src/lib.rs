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
pub mod mesh;
pub mod pose;
pub mod sample;
pub mod stats;

pub use angles::{BrdfAngles, ShadingFrame};
pub use camera::{BrownConrady, CameraError, CameraModel};
pub use mesh::{MeshError, TriMesh};
pub use pose::Pose;
pub use sample::BrdfSample;

/// Re-export of the vector math the domain types are built on.
pub use glam;
