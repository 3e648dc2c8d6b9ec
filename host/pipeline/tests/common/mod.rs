//! What the survey tests share: a built-in scene's synthetic studio at half resolution, and
//! the session a user would ingest from it (unsurveyed).
#![allow(dead_code)] // each test file uses a part

use std::path::{Path, PathBuf};

use skinbrdf_ingest::ingest;
use skinbrdf_pipeline::demo::studio_ingest_config;
use skinbrdf_synth::studio::Mosaic;
use skinbrdf_synth::{generate, Scene, SynthOptions};

/// Synthesizes `scene` into `dir/S` with the studio's files and the generator's own session
/// (for the layout-given comparisons); returns `dir/S`. The card is formed per photosite, as a
/// camera's sensor records it and as `process` loads it by default (`[studio] mosaic =
/// "photosite"`), one rendered pixel per photosite at the scene's pixel count: a sensor of half
/// the scene's size in superpixels (762 x 506 for the default scene). Half the pixel count in
/// photosites is not enough for the scenes' bounds (`docs/derender.md`, "Why photosites are the
/// default").
pub fn half_resolution_studio(dir: &Path, scene: &Scene) -> PathBuf {
    let s = dir.join("S");
    let mut scene = scene.clone();
    scene.studio.mosaic = Mosaic::Photosite;
    let size = (scene.camera.width_px, scene.camera.height_px);
    generate(
        &scene,
        &SynthOptions {
            resolution: Some(size),
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
