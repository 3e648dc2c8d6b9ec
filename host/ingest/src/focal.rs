//! Where the lens is: a starting focal length for a camera to be calibrated, in the pixels of
//! the session's images, from what the photographs' metadata say.
//!
//! # Why
//!
//! The method's lens is long (about 10 degrees across at 2 m). A calibration that starts from a
//! generic field of view (20 degrees and more) converges to a focal length several times wrong,
//! while the files state the lens's focal length and the scale that turns it into pixels. The
//! ingest writes the guess into the session (`[camera] focal_guess_px`), and the calibration
//! starts there.
//!
//! # The two sources
//!
//! The focal-plane resolution is preferred; the 35 mm equivalent is used when it gives none.
//! A focal length the rig file states (`[camera] focal_guess_px`) is preferred to both
//! ([`stated_focal_guess`]; the files' value is noted where the two differ).
//!
//! 1. **Focal-plane resolution** (`FocalLength` `f_mm` and `FocalPlaneXResolution` `rho_x`,
//!    pixels of the camera's image per millimetre of the focal plane: photosites, for a raw
//!    file; [`ExposureMeta::focal_plane_px_per_mm_x`] has its unit applied). The session's
//!    image covers `W_sensor` of those pixels with `W_session` of its own (a raw file loads as
//!    2x2 superpixels, so `W_sensor = 2 W_session`), hence
//!
//!    ```text
//!    f_session_px = f_mm · rho_x · W_session / W_sensor
//!    ```
//!
//! 2. **35 mm equivalent** (`FocalLengthIn35mmFilm` `f_35`): the focal length that gives the
//!    same diagonal field of view on a 36 x 24 mm frame, whose diagonal is
//!    `D_35 = sqrt(36² + 24²) = 43.27 mm`. The same angle on the session's image, diagonal
//!    `d_session = hypot(W_session, H_session)` pixels, means `f_35 / D_35 = f_px / d_session`:
//!
//!    ```text
//!    f_session_px = f_35 · hypot(W_session, H_session) / D_35
//!    ```
//!
//!    It needs neither the physical focal length nor the sensor's size, but EXIF rounds `f_35`
//!    to whole millimetres (0.25 % at 200 mm) and the camera's image may be cropped slightly
//!    inside the active area the session covers.
//!
//! When both give a value and they differ by more than [`SOURCES_AGREE_REL`], the guess says
//! so in its notes (the focal-plane resolution is still used).
//!
//! # Refusals
//!
//! A value that is missing, not finite, zero or negative, or absurd gives no guess from its
//! source, with the reason: a focal length beyond [`MAX_FOCAL_LENGTH_MM`], `FocalPlaneX` and
//! `YResolution` differing by more than [`SQUARE_PIXELS_REL`] (non-square pixels or a wrong
//! tag: one focal length cannot serve both axes), a focal plane whose diagonal is outside
//! [`SENSOR_DIAGONAL_MM`] (exiftool's range for a sensor; a wrong unit lands outside it), and a
//! guess whose horizontal field of view is outside [`HFOV_DEG`]. Never a panic: with no source
//! left the caller gets [`NoFocalGuess`] listing every reason, and the session starts from the
//! calibration's own guess as before.

use serde::{Deserialize, Serialize};
use skinbrdf_raw::{ExposureMeta, FULL_FRAME_DIAGONAL_MM};

/// The longest focal length believed, millimetres (the longest photographic lenses made are
/// near 5 m; anything beyond is a wrong tag).
pub const MAX_FOCAL_LENGTH_MM: f64 = 5000.0;
/// `FocalPlaneXResolution` and `FocalPlaneYResolution` may differ by this fraction (rounding of
/// the camera's rationals); more is non-square pixels or a wrong tag.
pub const SQUARE_PIXELS_REL: f64 = 0.02;
/// The focal plane's diagonal the resolution implies must lie in this range, millimetres
/// (exiftool's check: from small phone sensors to medium format backs).
pub const SENSOR_DIAGONAL_MM: std::ops::RangeInclusive<f64> = 1.0..=100.0;
/// A guess's horizontal field of view must lie in this range, degrees (the synthetic scenes'
/// range for `hfov_deg`).
pub const HFOV_DEG: std::ops::RangeInclusive<f64> = 0.1..=170.0;
/// The two sources are said to disagree beyond this relative difference.
pub const SOURCES_AGREE_REL: f64 = 0.05;

/// Where a focal-length guess comes from, with the values it was computed from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "from", rename_all = "kebab-case")]
pub enum FocalGuessSource {
    /// `FocalLength` times the focal-plane resolution.
    FocalPlaneResolution {
        /// `FocalLength`, millimetres.
        focal_length_mm: f64,
        /// `FocalPlaneXResolution`, pixels (photosites) per millimetre.
        px_per_mm: f64,
        /// Session pixels per pixel the resolution counts (`W_session / W_sensor`; 0.5 for a
        /// raw file's superpixels).
        session_px_per_sensor_px: f64,
    },
    /// `FocalLengthIn35mmFilm` over the 36 x 24 mm frame's diagonal.
    Equivalent35mm {
        /// `FocalLengthIn35mmFilm`, millimetres.
        focal_length_35mm_mm: f64,
    },
    /// The rig file's `[camera] focal_guess_px` (preferred to the metadata: the studio knows
    /// its lens).
    Rig,
}

/// A starting focal length for the calibration, in the session's image pixels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FocalGuess {
    /// The focal length, session image pixels.
    pub focal_px: f64,
    /// The horizontal field of view it means across the session's image, degrees.
    pub hfov_deg: f64,
    /// Where it comes from.
    pub source: FocalGuessSource,
    /// The preferred source passed over and why, or the other source's value where the two
    /// disagree.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl std::fmt::Display for FocalGuess {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.1} px ({:.2} degrees across) from ",
            self.focal_px, self.hfov_deg
        )?;
        match self.source {
            FocalGuessSource::FocalPlaneResolution {
                focal_length_mm,
                px_per_mm,
                session_px_per_sensor_px,
            } => write!(
                f,
                "FocalLength {focal_length_mm:.2} mm x FocalPlaneXResolution {px_per_mm:.4} \
                 px/mm x {session_px_per_sensor_px} session px per sensor px"
            )?,
            FocalGuessSource::Equivalent35mm {
                focal_length_35mm_mm,
            } => write!(
                f,
                "FocalLengthIn35mmFilm {focal_length_35mm_mm} mm over the 36 x 24 mm frame's \
                 {FULL_FRAME_DIAGONAL_MM:.2} mm diagonal"
            )?,
            FocalGuessSource::Rig => write!(f, "the rig's [camera] focal_guess_px")?,
        }
        for n in &self.notes {
            write!(f, "; {n}")?;
        }
        Ok(())
    }
}

/// Why the metadata give no focal-length guess: every source's reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("no focal-length guess from the metadata: {}", .reasons.join("; "))]
pub struct NoFocalGuess {
    /// One reason per source.
    pub reasons: Vec<String>,
}

/// The focal length in the session image's pixels from `meta` (see the module docs), for
/// session images of `session_size_px` (width, height) that cover `sensor_size_px` of the
/// pixels the focal-plane resolution counts (for a raw file, the photosites: twice the
/// superpixel image's size).
pub fn focal_guess_px(
    meta: &ExposureMeta,
    session_size_px: (u32, u32),
    sensor_size_px: (u32, u32),
) -> Result<FocalGuess, NoFocalGuess> {
    let (w, h) = (f64::from(session_size_px.0), f64::from(session_size_px.1));
    if !(w > 0.0 && h > 0.0) {
        return Err(NoFocalGuess {
            reasons: vec![format!(
                "the session's image size {}x{} is empty",
                session_size_px.0, session_size_px.1
            )],
        });
    }
    let plane = from_focal_plane(meta, w, sensor_size_px);
    let equivalent = from_35mm(meta, (w, h));
    match (plane, equivalent) {
        (Ok(mut g), other) => {
            if let Ok(o) = other {
                if (o.focal_px / g.focal_px - 1.0).abs() > SOURCES_AGREE_REL {
                    g.notes.push(format!(
                        "the 35 mm equivalent gives {:.1} px ({:+.1} %): the focal-plane \
                         resolution is preferred",
                        o.focal_px,
                        100.0 * (o.focal_px / g.focal_px - 1.0)
                    ));
                }
            }
            Ok(g)
        }
        (Err(why), Ok(mut g)) => {
            g.notes
                .push(format!("focal-plane resolution passed over: {why}"));
            Ok(g)
        }
        (Err(a), Err(b)) => Err(NoFocalGuess {
            reasons: vec![
                format!("focal-plane resolution: {a}"),
                format!("35 mm equivalent: {b}"),
            ],
        }),
    }
}

/// Whether `v` is a usable positive number.
fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

/// The rig's stated focal length as a guess, with the metadata's own guess (`files`) in its
/// notes when the two differ by more than [`SOURCES_AGREE_REL`].
pub fn stated_focal_guess(focal_px: f64, width_px: u32, files: Option<&FocalGuess>) -> FocalGuess {
    let mut notes = Vec::new();
    if let Some(g) = files {
        if (g.focal_px - focal_px).abs() > SOURCES_AGREE_REL * focal_px {
            notes.push(format!(
                "the files give {:.1} px ({:.2} degrees across)",
                g.focal_px, g.hfov_deg
            ));
        }
    }
    FocalGuess {
        focal_px,
        hfov_deg: hfov_deg(focal_px, f64::from(width_px)),
        source: FocalGuessSource::Rig,
        notes,
    }
}

/// The horizontal field of view of focal length `f_px` across `w_px`, degrees.
fn hfov_deg(f_px: f64, w_px: f64) -> f64 {
    2.0 * (0.5 * w_px / f_px).atan().to_degrees()
}

/// `f_px` if its field of view across `w_px` is believable.
fn check_fov(f_px: f64, w_px: f64) -> Result<f64, String> {
    let fov = hfov_deg(f_px, w_px);
    if positive(f_px) && HFOV_DEG.contains(&fov) {
        Ok(fov)
    } else {
        Err(format!(
            "{f_px:.4} px is {fov:.3} degrees across a {w_px}-pixel image, outside {}..{} degrees",
            HFOV_DEG.start(),
            HFOV_DEG.end()
        ))
    }
}

fn from_focal_plane(
    meta: &ExposureMeta,
    w: f64,
    sensor_size_px: (u32, u32),
) -> Result<FocalGuess, String> {
    let f_mm = match meta.focal_length_mm {
        None => return Err("no FocalLength".into()),
        Some(f) if !positive(f) || f > MAX_FOCAL_LENGTH_MM => {
            return Err(format!(
                "FocalLength {f} mm is not in (0, {MAX_FOCAL_LENGTH_MM}] mm"
            ))
        }
        Some(f) => f,
    };
    let rho_x = match meta.focal_plane_px_per_mm_x {
        None => {
            return Err(match meta.focal_plane_resolution_unit {
                Some(u) if skinbrdf_raw::focal_plane_unit_mm(Some(u)).is_none() => format!(
                    "FocalPlaneResolutionUnit {u} is no unit EXIF defines (2 inch, 3 cm, 4 mm, \
                     5 um)"
                ),
                _ => "no FocalPlaneXResolution".into(),
            })
        }
        Some(r) if !positive(r) => {
            return Err(format!(
                "FocalPlaneXResolution {r} px/mm is not positive and finite"
            ))
        }
        Some(r) => r,
    };
    let rho_y = match meta.focal_plane_px_per_mm_y {
        None => rho_x,
        Some(r) if !positive(r) => {
            return Err(format!(
                "FocalPlaneYResolution {r} px/mm is not positive and finite"
            ))
        }
        Some(r) => {
            if (rho_x / r - 1.0).abs() > SQUARE_PIXELS_REL {
                return Err(format!(
                    "FocalPlaneXResolution {rho_x:.4} and YResolution {r:.4} px/mm differ by \
                     more than {} % (non-square pixels or a wrong tag)",
                    100.0 * SQUARE_PIXELS_REL
                ));
            }
            r
        }
    };
    let (sw, sh) = (f64::from(sensor_size_px.0), f64::from(sensor_size_px.1));
    if !(sw > 0.0 && sh > 0.0) {
        return Err(format!(
            "the sensor's size {}x{} px is empty",
            sensor_size_px.0, sensor_size_px.1
        ));
    }
    let diagonal_mm = (sw / rho_x).hypot(sh / rho_y);
    if !SENSOR_DIAGONAL_MM.contains(&diagonal_mm) {
        return Err(format!(
            "{}x{} px at {rho_x:.4} px/mm is a focal plane of {diagonal_mm:.3} mm diagonal, \
             outside {}..{} mm (a wrong unit or size)",
            sensor_size_px.0,
            sensor_size_px.1,
            SENSOR_DIAGONAL_MM.start(),
            SENSOR_DIAGONAL_MM.end()
        ));
    }
    let scale = w / sw;
    let focal_px = f_mm * rho_x * scale;
    let fov = check_fov(focal_px, w)?;
    Ok(FocalGuess {
        focal_px,
        hfov_deg: fov,
        source: FocalGuessSource::FocalPlaneResolution {
            focal_length_mm: f_mm,
            px_per_mm: rho_x,
            session_px_per_sensor_px: scale,
        },
        notes: Vec::new(),
    })
}

fn from_35mm(meta: &ExposureMeta, (w, h): (f64, f64)) -> Result<FocalGuess, String> {
    let f35 = match meta.focal_length_35mm_mm {
        None => return Err("no FocalLengthIn35mmFilm".into()),
        Some(f) if !positive(f) || f > MAX_FOCAL_LENGTH_MM => {
            return Err(format!(
                "FocalLengthIn35mmFilm {f} mm is not in (0, {MAX_FOCAL_LENGTH_MM}] mm"
            ))
        }
        Some(f) => f,
    };
    let focal_px = f35 * w.hypot(h) / FULL_FRAME_DIAGONAL_MM;
    let fov = check_fov(focal_px, w)?;
    Ok(FocalGuess {
        focal_px,
        hfov_deg: fov,
        source: FocalGuessSource::Equivalent35mm {
            focal_length_35mm_mm: f35,
        },
        notes: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A full-frame body (36 mm across 6000 photosites: 6 um) with an 85 mm lens, its raw
    /// files loaded as 3000 x 2000 superpixels.
    fn full_frame() -> ExposureMeta {
        ExposureMeta {
            focal_length_mm: Some(85.0),
            focal_plane_px_per_mm_x: Some(6000.0 / 36.0),
            focal_plane_px_per_mm_y: Some(4000.0 / 24.0),
            focal_plane_resolution_unit: Some(4),
            focal_length_35mm_mm: Some(85.0),
            ..ExposureMeta::default()
        }
    }

    const SESSION: (u32, u32) = (3000, 2000);
    const SENSOR: (u32, u32) = (6000, 4000);

    #[test]
    fn the_focal_plane_resolution_gives_superpixels() {
        let g = focal_guess_px(&full_frame(), SESSION, SENSOR).unwrap();
        // 85 mm / 6 um = 14166.7 photosites = 7083.3 superpixels.
        assert!((g.focal_px - 85.0 / 0.006 / 2.0).abs() < 1e-9, "{g}");
        assert!(matches!(
            g.source,
            FocalGuessSource::FocalPlaneResolution { session_px_per_sensor_px, .. }
                if session_px_per_sensor_px == 0.5
        ));
        // 36 mm across at 85 mm: 2 atan(18 / 85) = 23.91 degrees.
        assert!((g.hfov_deg - 2.0 * (18.0f64 / 85.0).atan().to_degrees()).abs() < 1e-9);
        assert!(g.notes.is_empty(), "{:?}", g.notes);
        // A JPEG of the same body: the image is the sensor's pixels.
        let j = focal_guess_px(&full_frame(), SENSOR, SENSOR).unwrap();
        assert!((j.focal_px - 2.0 * g.focal_px).abs() < 1e-9);
    }

    #[test]
    fn the_35mm_equivalent_keeps_the_diagonal() {
        let meta = ExposureMeta {
            focal_plane_px_per_mm_x: None,
            focal_plane_px_per_mm_y: None,
            ..full_frame()
        };
        let g = focal_guess_px(&meta, SESSION, SENSOR).unwrap();
        // A full frame's 35 mm equivalent is its focal length: the same 7083.3 superpixels.
        assert!((g.focal_px - 85.0 / 0.006 / 2.0).abs() < 1e-6, "{g}");
        assert_eq!(
            g.source,
            FocalGuessSource::Equivalent35mm {
                focal_length_35mm_mm: 85.0
            }
        );
        assert_eq!(
            g.notes,
            ["focal-plane resolution passed over: no FocalPlaneXResolution"]
        );
        // An APS-C body (crop 1.5: 24 x 16 mm, 4 um photosites) with a 200 mm lens says 300 mm.
        let aps = ExposureMeta {
            focal_length_mm: Some(200.0),
            focal_plane_px_per_mm_x: Some(250.0),
            focal_plane_px_per_mm_y: Some(250.0),
            focal_length_35mm_mm: Some(300.0),
            ..ExposureMeta::default()
        };
        let plane = focal_guess_px(&aps, SESSION, SENSOR).unwrap();
        let only_35 = focal_guess_px(
            &ExposureMeta {
                focal_plane_px_per_mm_x: None,
                ..aps.clone()
            },
            SESSION,
            SENSOR,
        )
        .unwrap();
        // 200 mm / 4 um / 2 = 25000 superpixels, both ways.
        assert!((plane.focal_px - 25_000.0).abs() < 1e-6, "{plane}");
        assert!((only_35.focal_px - 25_000.0).abs() < 1e-6, "{only_35}");
        assert!(plane.notes.is_empty());
    }

    #[test]
    fn the_focal_plane_resolution_is_preferred_and_a_disagreement_is_noted() {
        let meta = ExposureMeta {
            focal_length_35mm_mm: Some(120.0),
            ..full_frame()
        };
        let g = focal_guess_px(&meta, SESSION, SENSOR).unwrap();
        assert!(matches!(
            g.source,
            FocalGuessSource::FocalPlaneResolution { .. }
        ));
        assert_eq!(g.notes.len(), 1);
        assert!(
            g.notes[0].contains("35 mm equivalent gives"),
            "{:?}",
            g.notes
        );
    }

    #[test]
    fn nonsense_gives_no_guess_and_says_why() {
        let refuse = |meta: ExposureMeta, words: &[&str]| {
            let e = focal_guess_px(&meta, SESSION, SENSOR).unwrap_err();
            let msg = e.to_string();
            assert_eq!(e.reasons.len(), 2, "{msg}");
            for w in words {
                assert!(msg.contains(w), "`{w}` not in: {msg}");
            }
        };
        let no_35 = |m: ExposureMeta| ExposureMeta {
            focal_length_35mm_mm: None,
            ..m
        };
        refuse(
            ExposureMeta::default(),
            &["no FocalLength", "no FocalLengthIn35mmFilm"],
        );
        for f in [0.0, -85.0, f64::NAN, f64::INFINITY, 1e6] {
            refuse(
                ExposureMeta {
                    focal_length_mm: Some(f),
                    focal_length_35mm_mm: Some(f),
                    ..full_frame()
                },
                &["FocalLength ", "FocalLengthIn35mmFilm "],
            );
        }
        // A zero denominator, read as written.
        for r in [f64::INFINITY, f64::NAN, 0.0, -10.0] {
            refuse(
                no_35(ExposureMeta {
                    focal_plane_px_per_mm_x: Some(r),
                    ..full_frame()
                }),
                &["FocalPlaneXResolution", "not positive and finite"],
            );
        }
        refuse(
            no_35(ExposureMeta {
                focal_plane_px_per_mm_x: None,
                focal_plane_resolution_unit: Some(7),
                ..full_frame()
            }),
            &["FocalPlaneResolutionUnit 7"],
        );
        refuse(
            no_35(ExposureMeta {
                focal_plane_px_per_mm_y: Some(83.3),
                ..full_frame()
            }),
            &["non-square"],
        );
        // A unit wrong by a factor 1000 (micrometres for millimetres): a focal plane of
        // 0.04 mm diagonal.
        refuse(
            no_35(ExposureMeta {
                focal_plane_px_per_mm_x: Some(6000.0 / 36.0 * 1000.0),
                focal_plane_px_per_mm_y: Some(4000.0 / 24.0 * 1000.0),
                ..full_frame()
            }),
            &["diagonal"],
        );
    }

    #[test]
    fn empty_sizes_and_absurd_fields_of_view_are_refused() {
        let e = focal_guess_px(&full_frame(), (0, 2000), SENSOR).unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        let e = focal_guess_px(
            &ExposureMeta {
                focal_length_35mm_mm: None,
                ..full_frame()
            },
            SESSION,
            (0, 0),
        )
        .unwrap_err();
        assert!(e.to_string().contains("sensor's size 0x0"), "{e}");
        // A 1 mm lens on a full frame sees more than 170 degrees.
        let e = focal_guess_px(
            &ExposureMeta {
                focal_length_mm: Some(1.0),
                focal_length_35mm_mm: Some(1.0),
                ..full_frame()
            },
            SESSION,
            SENSOR,
        )
        .unwrap_err();
        assert!(e.to_string().contains("degrees across"), "{e}");
    }
}
