//! What the survey tests share: a built-in scene's synthetic studio at half resolution, and
//! the session a user would ingest from it (unsurveyed).
#![allow(dead_code)] // each test file uses a part

use std::path::{Path, PathBuf};

use skinbrdf_ingest::ingest;
use skinbrdf_pipeline::demo::studio_ingest_config;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// Synthesizes `scene` into `dir/S` at half its image size, with the studio's files and the
/// generator's own session (for the layout-given comparisons); returns `dir/S`.
pub fn half_resolution_studio(dir: &Path, scene: &Scene) -> PathBuf {
    let s = dir.join("S");
    let half = (scene.camera.width_px / 2, scene.camera.height_px / 2);
    generate(
        scene,
        &SynthOptions {
            resolution: Some(half),
            studio: true,
            ..SynthOptions::default()
        },
        &s,
    )
    .expect("synthesis");
    s
}

/// [`half_resolution_studio`], then the studio ingested unsurveyed into `dir/S2` (with its
/// survey folder when it has one); returns both directories.
pub fn studio_session(dir: &Path, scene: &Scene) -> (PathBuf, PathBuf) {
    let s = half_resolution_studio(dir, scene);
    let s2 = dir.join("S2");
    ingest(&studio_ingest_config(&s, scene, s2.clone())).expect("ingest");
    (s, s2)
}
