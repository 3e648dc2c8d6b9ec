//! Synthetic measurement sessions with ground truth: scenes, procedural head, physically based
//! image formation.
//!
//! * [`scene`]: scene files (TOML, built-ins embedded from the repository's `scenes/`),
//!   [`Scene::load`] by name or path.
//! * [`shape`]: the true surface (procedural head with a brow ridge, sphere, cylinder) with
//!   analytic normals, tessellation and an independent analytic ray intersection.
//! * [`layout`]: the set-up (reference structure, headdress, flash, standard), the shot list
//!   (30 measurement + 6 extra images, or one per exposure of a `capture.json`) and head motion.
//! * [`framing`]: how the rig follows a lens narrower than the one its constants are laid out
//!   for (a cage planned for the frames, the flash stand's panel in the frame the ring leaves).
//! * [`sheets`]: printed sheets of the rig (cage targets flattened onto sheets, the headdress
//!   band) and how a real sheet differs from its layout (tilt, print scale, fold, wrap).
//! * [`photograph`]: the synthetic photographer: ray casting (obvhs through `skinbrdf-mesh`,
//!   rayon over rows) and shading of the studio photographs.
//! * [`mod@generate`]: writes a session directory that `skinbrdf_session::Session::load` accepts,
//!   with `truth.json` and truth masks. Entry point: [`generate::generate`].
//! * [`studio`]: with `--studio`, what a studio holds after the capture: the camera's raw
//!   files (DNG), the controller's record, the rig files and the scan.
//! * [`survey_shots`]: survey shots (`[session] survey_images`): taken before the subject sits,
//!   from positions chosen to see the reference targets the measurement arc sees poorly.
//! * [`textured_scan`]: the head scan as a textured OBJ in a scanner frame, headdress papers
//!   included, with its truth (`studio/scan/`).
//!
//! The radiometric convention (what `C` means) is in `docs/session-format.md`: a skin point
//! renders to `V = rho cos(theta_i) / (C D²)`, so the method's equation 2 inverts the renderer
//! exactly (tested at sampled pixels in `tests/forward_model.rs`).

pub mod framing;
pub mod generate;
pub mod layout;
pub mod photograph;
pub mod scene;
pub mod shape;
pub mod sheets;
pub mod studio;
pub mod survey_shots;
pub mod textured_scan;
pub mod visibility;

pub use generate::{generate, SynthError, SynthOptions, SynthSummary};
pub use scene::{Scene, SceneError, BUILTIN_SCENES};
