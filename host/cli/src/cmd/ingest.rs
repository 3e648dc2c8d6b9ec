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
    crate::print::ingest::text(&r);
    Ok(())
}
