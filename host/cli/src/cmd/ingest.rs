//! `skinbrdf ingest CARD_DIR --capture capture.json --rig RIG.toml [--scan SCAN [--scan-points
//! POINTS.toml] [--similarity]] [--camera CAMERA.toml] [--survey DIR] --out SESSION`: the
//! camera's card (and the survey images) to a session (see `skinbrdf_ingest::ingest` and
//! docs/ingest.md). Prints the camera clock fit with every pair's residual, the survey images,
//! the files left out and why, the exposures without a file, and what the session still needs.

use std::path::PathBuf;

use anyhow::Context;
use skinbrdf_ingest::matching::MatchOptions;
use skinbrdf_ingest::{ingest, ExposurePolicy, IngestConfig};
use skinbrdf_session::{LengthUnit, RegistrationFit};

/// Flags of `skinbrdf ingest`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The camera's card (or a copy of it); searched recursively.
    pub card: PathBuf,
    /// The controller's record of the capture.
    #[arg(long)]
    pub capture: PathBuf,
    /// The rig file: targets, flash, standard (with placements when surveyed).
    #[arg(long)]
    pub rig: PathBuf,
    /// The head scan (PLY, OBJ, binary glTF .glb or .gltf with its files); not needed when the
    /// rig states an ideal sample's shape (`[geometry]`: a calibration sphere or cylinder).
    #[arg(long)]
    pub scan: Option<PathBuf>,
    /// The scan's length unit (default: from the file's header comment; glTF: metres).
    #[arg(long, value_enum)]
    pub scan_units: Option<Units>,
    /// Hand-picked target corners on the scan (a `[[points]]` TOML file, metres, scan frame):
    /// the surveyed headdress is registered to the scan by them (a scan without texture).
    #[arg(long)]
    pub scan_points: Option<PathBuf>,
    /// Register the headdress to the scan with a similarity (also a scale) instead of a rigid
    /// motion (a scan whose unit is not trusted).
    #[arg(long)]
    pub similarity: bool,
    /// A camera calibration: a TOML file with a `[camera]` table as in session.toml; it wins
    /// over the rig's `[camera]` (the summary says so).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// The session directory to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Copy the photographs into SESSION/images/ (default: reference them where they are).
    #[arg(long)]
    pub copy: bool,
    /// Replace an existing session in --out.
    #[arg(long)]
    pub overwrite: bool,
    /// Scale images exposed unlike the reference-standard image by t·ISO/N² instead of
    /// refusing them.
    #[arg(long)]
    pub normalise_exposure: bool,
    /// The session's camera body serial (default: the one most files carry).
    #[arg(long)]
    pub body_serial: Option<String>,
    /// A folder of survey images: shots taken by hand before the subject sits (room light, no
    /// flash, not in the capture record), same camera body; they strengthen the placement
    /// survey (role `survey`).
    #[arg(long, value_name = "DIR")]
    pub survey: Option<PathBuf>,
    /// Print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Length units of `--scan-units`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Units {
    /// Metres.
    M,
    /// Centimetres.
    Cm,
    /// Millimetres.
    Mm,
    /// Inches.
    In,
}

impl From<Units> for LengthUnit {
    fn from(u: Units) -> Self {
        match u {
            Units::M => Self::M,
            Units::Cm => Self::Cm,
            Units::Mm => Self::Mm,
            Units::In => Self::In,
        }
    }
}

/// Validates the flags into an ingest configuration.
pub fn config(args: &Args) -> IngestConfig {
    let mut cfg = IngestConfig::new(
        args.card.clone(),
        args.capture.clone(),
        args.rig.clone(),
        args.scan.clone(),
        args.out.clone(),
    );
    cfg.scan_units = args.scan_units.map(Into::into);
    cfg.scan_points = args.scan_points.clone();
    cfg.registration_fit = if args.similarity {
        RegistrationFit::Similarity
    } else {
        RegistrationFit::Rigid
    };
    cfg.camera = args.camera.clone();
    cfg.copy = args.copy;
    cfg.overwrite = args.overwrite;
    cfg.exposure = if args.normalise_exposure {
        ExposurePolicy::Normalise
    } else {
        ExposurePolicy::Refuse
    };
    cfg.matching = MatchOptions {
        expected_body_serial: args.body_serial.clone(),
        ..MatchOptions::default()
    };
    cfg.survey_dir = args.survey.clone();
    // Each raw file is decoded in a child process: one that makes the decoder abort or hang
    // fails only itself.
    cfg.decoder = super::internal_decode::isolation();
    cfg
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let cfg = config(&args);
    let r = ingest(&cfg).with_context(|| format!("skinbrdf ingest {}", args.card.display()))?;
    if args.json {
        super::print_json(&r)?;
        return Ok(());
    }
    let c = &r.matching.clock;
    println!("camera: {}, {}", r.camera_body, r.lens);
    println!(
        "camera clock: offset {:+.3} s, drift {:+.1} ppm{}, residual rms {:.1} ms, max {:.1} ms over {} pairs (time resolution {} ms)",
        c.offset_s,
        c.drift_ppm,
        if c.drift_fitted { "" } else { " (not fitted: too few pairs)" },
        c.residual_rms_s * 1e3,
        c.residual_max_s * 1e3,
        c.pairs_used,
        c.time_resolution_s * 1e3
    );
    println!(
        "{:<42} {:>8} {:<20} {:>10} {:>8}",
        "image", "exposure", "role", "resid ms", "scale"
    );
    for i in &r.images {
        println!(
            "{:<42} {:>8} {:<20} {:>10.2} {:>8.4}",
            i.card_file
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            i.exposure_index,
            i.role.name(),
            i.time_residual_s * 1e3,
            i.exposure_scale
        );
    }
    if !r.survey_images.is_empty() {
        println!(
            "survey images: {} (role survey; exposure not compared: geometry only)",
            r.survey_images.len()
        );
        for s in &r.survey_images {
            println!(
                "  {:<40} {:<24} {}",
                s.source_file.display(),
                s.settings.map_or("?".to_string(), |x| x.to_string()),
                if s.before_session {
                    "before the session"
                } else {
                    "after the session's first file"
                }
            );
        }
    }
    for (f, why) in &r.matching.extra_files {
        println!("left out: {f}: {why}");
    }
    for e in &r.matching.missing {
        println!("missing: exposure {e} fired the camera but has no file on the card");
    }
    if !r.matching.no_file_expected.is_empty() {
        let list: Vec<String> = r
            .matching
            .no_file_expected
            .iter()
            .map(ToString::to_string)
            .collect();
        println!(
            "no file expected (the camera did not fire): exposures {}",
            list.join(", ")
        );
    }
    for (f, what) in &r.skipped_files {
        println!("skipped: {f}: {what}");
    }
    if let Some(repair) = &r.scan_repair {
        println!("scan: repaired when loaded (process loads it the same way): {repair}");
    }
    match &r.camera {
        skinbrdf_ingest::ingest::CameraSource::File { path } => {
            println!("intrinsics: {} (--camera)", path.display())
        }
        skinbrdf_ingest::ingest::CameraSource::Rig { path } => {
            println!("intrinsics: the rig's [camera] ({})", path.display())
        }
        skinbrdf_ingest::ingest::CameraSource::ToBeCalibrated => {
            println!(
                "intrinsics: to be calibrated from the reference targets ({}x{} images as loaded)",
                r.image_size_px.0, r.image_size_px.1
            );
            match &r.focal_guess {
                Some(g) => println!("focal length to start from: {g}"),
                None => println!(
                    "focal length to start from: none in the files ({}); the calibration searches",
                    r.focal_guess_refused.join("; ")
                ),
            }
        }
    }
    for n in &r.camera_notes {
        println!("camera: {n}");
    }
    for k in &r.known_from_rig {
        println!("known from the rig: {k}");
    }
    if r.unplaced_targets > 0 {
        println!(
            "placements: {} targets placed, {} without a placement (listed as targets.unplaced: the placement survey fills them in)",
            r.placed_targets, r.unplaced_targets
        );
    } else {
        println!(
            "placements: all {} targets placed by the rig file",
            r.placed_targets
        );
    }
    println!(
        "session written to {} ({} images {}) in {:.2} s (metadata and matching {:.2} s, decoding {:.2} s)",
        r.session_dir.display(),
        r.images.len() + r.survey_images.len(),
        if r.copied { "copied" } else { "referenced in place" },
        r.total_s,
        r.metadata_s,
        r.decode_s
    );
    Ok(())
}
