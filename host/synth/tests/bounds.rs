//! Scene and option values outside their stated ranges are errors before any work, and a
//! failed generation leaves no output directory behind.
#![allow(clippy::unwrap_used)] // test helpers

use skinbrdf_synth::{generate, Scene, SynthError, SynthOptions};

#[test]
fn out_of_range_options_write_nothing() {
    let scene = Scene::load("default").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("session");
    let opts = SynthOptions {
        samples_per_pixel: Some(u32::MAX),
        ..SynthOptions::default()
    };
    let e = generate(&scene, &opts, &out).unwrap_err();
    assert!(matches!(e, SynthError::Scene { .. }), "{e}");
    assert!(e.to_string().contains("sensor.samples_per_pixel"), "{e}");
    assert!(!out.exists(), "a rejected scene wrote {}", out.display());

    let opts = SynthOptions {
        samples_per_pixel: Some(0),
        ..SynthOptions::default()
    };
    assert!(generate(&scene, &opts, &out).is_err());
    assert!(!out.exists());
}
