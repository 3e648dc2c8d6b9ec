//! `skinbrdf survey SESSION_DIR`: survey the placements nobody measured (the reference
//! structure's targets in the world, the headdress in the head frame) from the session's
//! photographs, register the headdress to a textured scan, write `out/survey.json` (and
//! `out/registration.json`) and print every surveyed target with its standard deviation.
//! With `--rig R --write-rig OUT`, also writes the rig with the surveyed placements. The next
//! `skinbrdf process` or `skinbrdf poses` reuses this survey while the session is unchanged.

use std::path::PathBuf;

use anyhow::Context;
use skinbrdf_pipeline::process::ProcessConfig;
use skinbrdf_pipeline::survey::{survey, RigWriteBack};

/// Flags of `skinbrdf survey`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The session directory.
    pub session: PathBuf,
    /// Output directory (default SESSION/out).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The rig file the session was ingested with: write it back with the surveyed placements
    /// to `--write-rig`.
    #[arg(long, requires = "write_rig")]
    pub rig: Option<PathBuf>,
    /// Where the surveyed rig goes (with `--rig`).
    #[arg(long, requires = "rig")]
    pub write_rig: Option<PathBuf>,
    /// Score against this ground truth (a synthetic studio's `truth.json`).
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Survey again even if the ledger holds a current survey.
    #[arg(long)]
    pub force: bool,
    /// Print the survey as JSON instead of the table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut cfg = ProcessConfig::new();
    cfg.out_dir = args.out.clone();
    cfg.force = args.force;
    if let Some(t) = &args.truth {
        if !t.is_file() {
            anyhow::bail!("--truth {}: no such file", t.display());
        }
    }
    cfg.truth_file = args.truth.clone();
    let write_back = match (&args.rig, &args.write_rig) {
        (Some(rig), Some(out)) => Some(RigWriteBack {
            rig: rig.clone(),
            out: out.clone(),
        }),
        _ => None,
    };
    let mut progress = super::StageProgress::default();
    let out = survey(&args.session, &cfg, write_back.as_ref(), &mut |e| {
        super::process::print_event(&mut progress, e)
    })
    .with_context(|| format!("surveying {}", args.session.display()))?;
    progress.finish();
    let Some(s) = &out.surveyed else {
        println!("nothing to survey: every placement is given");
        return Ok(());
    };
    let sv = &s.survey;
    if args.json {
        super::print_json(sv)?;
        return Ok(());
    }
    println!(
        "{:>4}  {:<9}  {:<12}  {:>5}  {:>8}  {:>8}  {:>8}",
        "id", "group", "sheet", "views", "rms px", "sd mm", "sd deg"
    );
    for t in &sv.targets {
        println!(
            "{:>4}  {:<9}  {:<12}  {:>5}  {:>8.3}  {:>8.3}  {:>8.3}",
            t.id,
            t.group.name(),
            t.sheet.as_deref().unwrap_or("-"),
            t.views,
            t.rms_px,
            t.position_sigma_mm,
            t.orientation_sigma_deg
        );
    }
    for sh in &sv.sheets {
        println!(
            "sheet {}: print scale {:.5} ± {:.5}, sd {:.3} mm / {:.3} deg",
            sh.name,
            sh.print_scale,
            sh.print_scale_sigma,
            sh.position_sigma_mm,
            sh.orientation_sigma_deg
        );
    }
    for i in &sv.issues {
        println!("{}: {i}", i.label());
    }
    println!("head frame: {}", sv.head_gauge);
    if sv.intrinsics_restart {
        println!(
            "camera to be calibrated: surveyed twice, the second time from the intrinsics the \
             first refined"
        );
    }
    println!(
        "{} targets from {} images ({} survey images): reprojection rms {:.3} px, {} parameters, {:.2} s",
        sv.targets.len(),
        sv.images_used,
        sv.survey_images_used,
        sv.bundle.final_rms_px,
        sv.bundle.parameters,
        sv.timing.total_ms / 1e3
    );
    println!("survey: {}", out.out_dir.join("survey.json").display());
    if let Some(p) = &out.rig_written {
        println!("surveyed rig: {}", p.display());
    }
    Ok(())
}
