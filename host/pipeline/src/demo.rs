//! `skinbrdf demo`: the whole system on the built-in default scene.
//!
//! 1. **Capture**: the firmware simulator (the firmware's own sequencer with camera and flash
//!    models, on a pseudo-terminal, faster than real time) runs the method's capture plan
//!    (`plans/method.toml`: 30 measurement shots, 3 light-position, 1 reference-standard,
//!    2 standard-position) through the host capture client, exactly as a board would.
//! 2. **Synthesis**: the generator renders one image per recorded exposure of the default scene
//!    into `generated/`, and with it what a studio holds after the shoot (`generated/studio/`:
//!    the camera's raw files on a card, formed as the session reads them ([`card_mosaic`]: one
//!    rendered pixel per photosite by default), the controller's record, a rig file stating only the
//!    declared origin and the printed flash ring and standard frame, the textured head scan in
//!    its scanner's frame) and the ground truth for scoring.
//! 3. **Ingest**: [`skinbrdf_ingest::ingest()`] matches the card's raw files to the controller's
//!    record and writes `session/` from the studio's files alone: no target placement, no
//!    registered scan, nothing of the truth.
//! 4. **Processing**: the planned pipeline ([`crate::process()`]) surveys the unmeasured targets,
//!    registers the headdress to the textured scan, recovers poses from the images, derenders,
//!    smooths and fits, scored against the studio's truth.
//! 5. **Report**: `report.md` with every stage's accuracy against the ground truth and its run
//!    time, and the figures.
//!
//! The simulator runs faster than real time ([`DemoConfig::time_scale`]), so the host clock
//! of its record advances `time_scale` times slower than the device's: shots 4 s apart on the
//! device are 80 ms apart on the host, closer than a camera's release jitter and time-stamp
//! resolution can tell apart. The studio is the session as it would have happened in real
//! time ([`real_time_record`]): the record's clock model gets the rate of the simulated world
//! (its offset kept) and every exposure's host time follows from it.
//!
//! [`DemoConfig::given_layout`] keeps the earlier path for comparison: the generator's PNG
//! session with every placement given is processed directly (no ingest, no survey).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use skinbrdf_capture::{parse_plan, run_capture, CaptureOptions, SerialConnector, Unattended};
use skinbrdf_ingest::{ingest, IngestConfig, IngestReport};
use skinbrdf_session::capture::{CaptureRecord, ShotOutcome};
use skinbrdf_session::RawMode;
use skinbrdf_synth::studio::{Mosaic, STUDIO_DIR};
use skinbrdf_synth::{generate, Scene, SynthOptions, SynthSummary};

use crate::ledger::write_atomic;
use crate::process::{process, Event, ProcessConfig, ProcessOutput};
use crate::report::{Metric, MetricKind};

/// The method's capture plan, built in.
pub const METHOD_PLAN: &str = include_str!("../../../plans/method.toml");

/// Errors of the demo, each naming its step.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// The simulator did not start.
    #[error("simulator")]
    Sim(#[from] skinbrdf_sim::SimError),
    /// The built-in plan did not parse.
    #[error("capture plan")]
    Plan(#[from] skinbrdf_capture::PlanError),
    /// The capture failed.
    #[error("capture")]
    Capture(#[from] skinbrdf_capture::CaptureError),
    /// The scene did not load.
    #[error("scene")]
    Scene(#[from] skinbrdf_synth::SceneError),
    /// Synthesis failed.
    #[error("synthesis")]
    Synth(#[from] skinbrdf_synth::SynthError),
    /// Ingesting the synthetic studio failed.
    #[error("ingest of the synthetic studio")]
    Ingest(#[from] skinbrdf_ingest::IngestError),
    /// Processing failed.
    #[error(transparent)]
    Process(#[from] crate::process::ProcessError),
    /// Writing the report failed.
    #[error(transparent)]
    Output(#[from] crate::ledger::LedgerError),
}

/// Settings of the demo.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    /// Output directory (`session/` and `report.md` inside).
    pub out_dir: PathBuf,
    /// Scene name or path.
    pub scene: String,
    /// Simulated device time per host time (50: a 75 s session captures in 1.5 s).
    pub time_scale: f64,
    /// Image size override.
    pub resolution: Option<(u32, u32)>,
    /// Pipeline settings.
    pub process: ProcessConfig,
    /// Process the generator's session with every placement given (no studio, no ingest, no
    /// survey) instead of the studio's path.
    pub given_layout: bool,
}

impl DemoConfig {
    /// The built-in default.
    pub fn new(out_dir: PathBuf) -> Self {
        Self {
            out_dir,
            scene: "default".into(),
            time_scale: 50.0,
            resolution: None,
            process: ProcessConfig::new(),
            given_layout: false,
        }
    }
}

/// Progress of the demo.
#[derive(Debug)]
pub enum DemoEvent<'a> {
    /// A step starts.
    Step(&'static str),
    /// The capture finished.
    Captured(&'a CaptureRecord, f64),
    /// The session was rendered.
    Synthesized(&'a SynthSummary),
    /// The studio's files became a session.
    Ingested(&'a IngestReport),
    /// A pipeline event.
    Process(Event<'a>),
}

/// What the demo produced.
#[derive(Debug)]
pub struct DemoOutput {
    /// The capture record.
    pub capture: CaptureRecord,
    /// Wall time of the capture, seconds.
    pub capture_s: f64,
    /// The synthesis summary.
    pub synth: SynthSummary,
    /// The ingest of the studio (`None` with the layout given).
    pub ingest: Option<IngestReport>,
    /// The pipeline's output.
    pub process: ProcessOutput,
    /// `report.md`.
    pub report_path: PathBuf,
    /// Wall time of the whole demo, seconds.
    pub total_s: f64,
}

/// Runs the demo.
pub fn run_demo(
    cfg: &DemoConfig,
    on_event: &mut dyn FnMut(DemoEvent<'_>),
) -> Result<DemoOutput, DemoError> {
    let t0 = Instant::now();
    let session_dir = cfg.out_dir.join("session");
    let generated_dir = if cfg.given_layout {
        session_dir.clone()
    } else {
        cfg.out_dir.join("generated")
    };

    // 1. capture against the simulator, exactly as against a board
    on_event(DemoEvent::Step(
        "capture: firmware simulator on a pseudo-terminal",
    ));
    let t = Instant::now();
    let plan = parse_plan(METHOD_PLAN, Path::new("plans/method.toml"))?;
    let sim_cfg = skinbrdf_sim::SimConfig {
        time_scale: cfg.time_scale,
        ..Default::default()
    };
    let (sim, port) = skinbrdf_sim::spawn_pty(sim_cfg)?;
    let options = CaptureOptions {
        out_dir: Some(generated_dir.clone()),
        request_timeout: Duration::from_secs(5),
        ..Default::default()
    };
    let capture = run_capture(
        SerialConnector { path: port },
        &plan,
        &options,
        &mut Unattended,
    );
    let _ = sim.stop();
    let capture = capture?;
    let capture_s = t.elapsed().as_secs_f64();
    on_event(DemoEvent::Captured(&capture, capture_s));

    // 2. render the session the capture describes
    on_event(DemoEvent::Step(if cfg.given_layout {
        "synthesis: rendering one image per exposure, every placement given"
    } else {
        "synthesis: rendering one image per exposure, and the studio's card, rig and scan"
    }));
    let mut scene = Scene::load(&cfg.scene)?;
    scene.studio.mosaic = card_mosaic(cfg.process.raw_mode);
    let synth = generate(
        &scene,
        &SynthOptions {
            resolution: cfg.resolution,
            capture: Some(real_time_record(&capture, cfg.time_scale)),
            noise_free: false,
            samples_per_pixel: None,
            studio: !cfg.given_layout,
            // The studio's path reads only what the studio holds: the generator's own
            // session (linear images, session.toml) would be written for nothing.
            studio_only: !cfg.given_layout,
        },
        &generated_dir,
    )?;
    on_event(DemoEvent::Synthesized(&synth));

    // 3. the studio's files become a session: raw files matched to the controller's record
    let ingested = if cfg.given_layout {
        None
    } else {
        on_event(DemoEvent::Step(
            "ingest: the card's raw files, the controller's record, the rig and the scan",
        ));
        let mut icfg = studio_ingest_config(&generated_dir, &scene, session_dir.clone());
        icfg.overwrite = true;
        let report = ingest(&icfg)?;
        on_event(DemoEvent::Ingested(&report));
        Some(report)
    };

    // 4. process
    on_event(DemoEvent::Step("process: the planned pipeline"));
    let mut pcfg = cfg.process.clone();
    pcfg.force = true;
    if !cfg.given_layout && pcfg.truth_file.is_none() {
        // Scoring only: the studio's truth, in the textured scan's frame.
        pcfg.truth_file = Some(generated_dir.join(STUDIO_DIR).join("truth.json"));
    }
    let out = process(&session_dir, &pcfg, &mut |e| {
        on_event(DemoEvent::Process(e))
    })?;

    // 5. report
    let total_s = t0.elapsed().as_secs_f64();
    let report_path = cfg.out_dir.join("report.md");
    let md = demo_markdown(
        &capture,
        capture_s,
        &synth,
        ingested.as_ref(),
        &out,
        total_s,
    );
    write_atomic(&report_path, md.as_bytes())?;
    let html = demo_html(
        &capture,
        capture_s,
        &synth,
        ingested.as_ref(),
        &out,
        total_s,
    );
    write_atomic(&cfg.out_dir.join("report.html"), html.as_bytes())?;
    Ok(DemoOutput {
        capture,
        capture_s,
        synth,
        ingest: ingested,
        process: out,
        report_path,
        total_s,
    })
}

/// How the studio forms its card for the raw mode the session is read in: per photosite, as a
/// camera's sensor records it, when it is read per photosite (the default; the scene's image
/// size is then the sensor's photosites); from 2x2 quads of one rendered pixel, exactly the
/// render, when it is read as superpixels. A quad card read per photosite holds no photosite's
/// own value (`docs/derender.md`, "Why photosites are the default").
pub fn card_mosaic(raw_mode: RawMode) -> Mosaic {
    match raw_mode {
        RawMode::Photosite => Mosaic::Photosite,
        RawMode::Superpixel => Mosaic::Quad,
    }
}

/// The ingest of a synthetic studio from what a studio holds: the card, the controller's
/// record, the rig nobody measured (`rig.toml`), the survey images when the studio took any
/// (`studio/survey/`) and the textured scan in its scanner's frame (none for an ideal sample:
/// its rig states its shape), with the lens calibration a studio
/// keeps from its own calibration shoot (the generated session's `[camera]` table: ingest reads
/// nothing else of that file) and the scan's unit.
pub fn studio_ingest_config(generated_dir: &Path, scene: &Scene, out_dir: PathBuf) -> IngestConfig {
    let studio = generated_dir.join(STUDIO_DIR);
    let scan = skinbrdf_synth::generate::analytic_geometry(scene)
        .is_none()
        .then(|| studio.join("scan").join("head.obj"));
    let mut cfg = IngestConfig::new(
        studio.join("card"),
        studio.join("capture.json"),
        studio.join("rig.toml"),
        scan.clone(),
        out_dir,
    );
    cfg.camera = Some(studio.join(skinbrdf_synth::studio::CAMERA_FILE));
    cfg.scan_units = scan.map(|_| scene.geometry.scan_units);
    let survey = studio.join(skinbrdf_synth::studio::SURVEY_DIR);
    cfg.survey_dir = survey.is_dir().then_some(survey);
    cfg
}

/// The record as the controller would have written it had the simulated session run in real
/// time: the host clock's rate per device microsecond, `(1 + drift) time_scale`, becomes the
/// drift of the new model, and every exposure's host time (its X-sync, else its shutter
/// command) is mapped through it. Device times, outcomes and everything else are kept.
pub fn real_time_record(record: &CaptureRecord, time_scale: f64) -> CaptureRecord {
    let mut out = record.clone();
    let rate = (1.0 + record.clock.drift_ppm * 1e-6) * time_scale;
    out.clock.drift_ppm = (rate - 1.0) * 1e6;
    out.clock.residual_rms_us = record.clock.residual_rms_us * time_scale;
    for e in &mut out.exposures {
        e.host_time_us = out
            .clock
            .to_host_us(e.xsync_us.unwrap_or(e.shutter_command_us));
    }
    out
}

/// Capture figures: shots, faults, shutter lag, recycle time, clock-model residual.
pub fn capture_metrics(c: &CaptureRecord, capture_s: f64) -> Vec<Metric> {
    let ok = c
        .exposures
        .iter()
        .filter(|e| e.outcome == ShotOutcome::Ok)
        .count();
    let lags: Vec<f64> = c
        .exposures
        .iter()
        .filter_map(|e| {
            e.xsync_us
                .map(|x| x.saturating_sub(e.shutter_command_us) as f64 / 1e3)
        })
        .collect();
    let recycles: Vec<f64> = c
        .exposures
        .iter()
        .filter_map(|e| e.recycle_us.map(|r| r as f64 / 1e6))
        .collect();
    // A mean of no values is no figure: the row is left out (never a NaN).
    let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    let span_s = match (c.exposures.first(), c.exposures.last()) {
        (Some(a), Some(b)) => {
            b.shutter_command_us.saturating_sub(a.shutter_command_us) as f64 / 1e6
        }
        _ => 0.0,
    };
    [
        Some(Metric::new(
            "exposures",
            c.exposures.len() as f64,
            "",
            MetricKind::Count,
        )),
        Some(Metric::new(
            "exposures_ok",
            ok as f64,
            "",
            MetricKind::Count,
        )),
        mean(&lags).map(|v| Metric::new("shutter_lag_mean", v, "ms", MetricKind::Quality)),
        mean(&recycles).map(|v| Metric::new("recycle_mean", v, "s", MetricKind::Quality)),
        Some(Metric::new(
            "session_device_time",
            span_s,
            "s",
            MetricKind::Quality,
        )),
        Some(Metric::new(
            "clock_model_residual_rms",
            c.clock.residual_rms_us,
            "us",
            MetricKind::Quality,
        )),
        Some(Metric::new(
            "capture_wall_time",
            capture_s,
            "s",
            MetricKind::Cost,
        )),
    ]
    .into_iter()
    .flatten()
    .collect()
}

/// What the demo did, in one sentence.
fn summary_sentence(studio: bool) -> String {
    if studio {
        "The firmware simulator captured a timed session; the generator rendered it as a studio \
         holds it (raw files on a card, the controller's record, a rig nobody measured, a \
         textured scan in its scanner's frame); ingest made a session of those files alone; the \
         pipeline surveyed the targets, registered the headdress to the scan, recovered poses, \
         derendered, smoothed and fitted, scored against the generator's truth."
            .into()
    } else {
        "The firmware simulator captured a timed session; the generator rendered it with every \
         target placement given; the pipeline recovered poses from the images, derendered, \
         smoothed and fitted."
            .into()
    }
}

/// The ingest's figures: files matched, clock fit, placements left to the survey, cost.
fn ingest_rows(i: &IngestReport) -> Vec<(String, String)> {
    vec![
        ("photographs matched".into(), i.images.len().to_string()),
        ("camera".into(), format!("{} ({})", i.camera_body, i.lens)),
        (
            "image size".into(),
            format!("{} x {} px", i.image_size_px.0, i.image_size_px.1),
        ),
        (
            "camera clock: offset, drift, residual rms".into(),
            format!(
                "{:.3} s, {:.1} ppm, {:.1} ms",
                i.matching.clock.offset_s,
                i.matching.clock.drift_ppm,
                i.matching.clock.residual_rms_s * 1e3
            ),
        ),
        (
            "exposures without a file".into(),
            i.matching.missing.len().to_string(),
        ),
        (
            "files without an exposure".into(),
            i.matching.extra_files.len().to_string(),
        ),
        (
            "targets placed by the rig".into(),
            i.placed_targets.to_string(),
        ),
        (
            "targets left to the survey".into(),
            i.unplaced_targets.to_string(),
        ),
        (
            "metadata and matching".into(),
            format!("{:.2} s", i.metadata_s),
        ),
        ("decoding".into(), format!("{:.2} s", i.decode_s)),
        ("total".into(), format!("{:.2} s", i.total_s)),
    ]
}

fn metric_rows(ms: &[Metric]) -> String {
    ms.iter()
        .map(|m| format!("| {} | {:.4} {} |\n", m.name, m.value, m.unit))
        .collect()
}

fn demo_html(
    c: &CaptureRecord,
    capture_s: f64,
    s: &SynthSummary,
    ingest: Option<&IngestReport>,
    out: &ProcessOutput,
    total_s: f64,
) -> String {
    use crate::report::html_escape;
    let mut h = format!(
        "<p>{} Total {total_s:.1} s.</p>\n<h2>Capture ({} {}, firmware {})</h2>\n<table>\n",
        html_escape(&summary_sentence(ingest.is_some())),
        html_escape(&c.device.kind),
        html_escape(&c.device.serial),
        html_escape(&c.device.firmware_version)
    );
    for m in capture_metrics(c, capture_s) {
        h.push_str(&format!(
            "<tr><td>{}</td><td class=\"num\">{:.4} {}</td></tr>\n",
            html_escape(&m.name),
            m.value,
            html_escape(&m.unit)
        ));
    }
    h.push_str(&format!(
        "</table>\n<h2>Synthesis</h2>\n<table>\n<tr><td>images</td><td class=\"num\">{}</td></tr>\n<tr><td>resolution</td><td class=\"num\">{} x {}</td></tr>\n<tr><td>primary rays</td><td class=\"num\">{}</td></tr>\n<tr><td>render time</td><td class=\"num\">{:.2} s</td></tr>\n<tr><td>total time</td><td class=\"num\">{:.2} s</td></tr>\n</table>\n",
        s.images, s.resolution.0, s.resolution.1, s.rays, s.render_s, s.total_s
    ));
    if let Some(i) = ingest {
        h.push_str("<h2>Ingest</h2>\n<table>\n");
        for (name, value) in ingest_rows(i) {
            h.push_str(&format!(
                "<tr><td>{}</td><td class=\"num\">{}</td></tr>\n",
                html_escape(&name),
                html_escape(&value)
            ));
        }
        h.push_str("</table>\n");
    }
    let mut figures: Vec<(String, String)> = crate::process::png_figures(&out.out_dir, "fit")
        .into_iter()
        .map(|rel| (rel.clone(), format!("session/out/{rel}")))
        .collect();
    if out.out_dir.join(crate::process::RENDER_FIGURE).is_file() {
        figures.insert(
            0,
            (
                "head rendered with a Lambertian BRDF (left) and the fitted one (right), the method's Figures 7 and 10".into(),
                format!("session/out/{}", crate::process::RENDER_FIGURE),
            ),
        );
    }
    crate::report::html_page("skinbrdf demo", &h, &out.report, &figures)
}

fn demo_markdown(
    c: &CaptureRecord,
    capture_s: f64,
    s: &SynthSummary,
    ingest: Option<&IngestReport>,
    out: &ProcessOutput,
    total_s: f64,
) -> String {
    let mut md = String::from("# skinbrdf demo\n\n");
    md.push_str(&format!(
        "{} Total {total_s:.1} s.\n\n",
        summary_sentence(ingest.is_some())
    ));
    md.push_str(&format!(
        "## Capture ({} {}, firmware {})\n\n| figure | value |\n|---|---:|\n",
        c.device.kind, c.device.serial, c.device.firmware_version
    ));
    md.push_str(&metric_rows(&capture_metrics(c, capture_s)));
    md.push_str(&format!(
        "\n## Synthesis\n\n| figure | value |\n|---|---:|\n| images | {} |\n| resolution | {} x {} |\n| render triangles | {} |\n| scan vertices | {} |\n| primary rays | {} |\n| render time | {:.2} s |\n| total time | {:.2} s |\n",
        s.images, s.resolution.0, s.resolution.1, s.render_triangles, s.scan_vertices, s.rays, s.render_s, s.total_s
    ));
    if let Some(i) = ingest {
        md.push_str("\n## Ingest\n\n| figure | value |\n|---|---:|\n");
        for (name, value) in ingest_rows(i) {
            md.push_str(&format!("| {name} | {value} |\n"));
        }
    }
    md.push_str("\n## Pipeline plan\n\n```text\n");
    md.push_str(&out.report.plan.to_text());
    md.push_str("```\n\n## Stages: accuracy against ground truth and run time\n\n");
    md.push_str(&out.report.to_markdown());
    let v = out.report.violations();
    if v.is_empty() {
        md.push_str("\nEvery figure with a stated bound is within it.\n");
    } else {
        md.push_str("\n**Out of bounds:**\n\n");
        for (st, m) in v {
            md.push_str(&format!(
                "- {}: {} = {} {} (bound {})\n",
                st.stage.name(),
                m.name,
                m.value,
                m.unit,
                m.bound.map_or("none".to_string(), |b| b.to_string())
            ));
        }
    }
    if out.out_dir.join(crate::process::RENDER_FIGURE).is_file() {
        md.push_str(&format!(
            "\n## Head rendering (the method's Figures 7 and 10)\n\nLambertian (left) against the fitted BRDF (right), same light and exposure:\n\n![head](session/out/{})\n",
            crate::process::RENDER_FIGURE
        ));
    }
    if let Some(f) = &out.fit {
        md.push_str("\n## Figures\n\n");
        for file in f.files.iter().filter(|p| p.ends_with(".png")) {
            let rel = Path::new(file)
                .strip_prefix(
                    out.out_dir
                        .parent()
                        .and_then(|p| p.parent())
                        .unwrap_or(Path::new("")),
                )
                .map(|p| p.display().to_string())
                .unwrap_or_else(|_| file.clone());
            md.push_str(&format!("![{rel}]({rel})\n\n"));
        }
        md.push_str(&format!(
            "Fitted model `{}`: parameters, uncertainties and convergence in `session/out/fit/params.json` and `session/out/fit/report.md`.\n",
            f.fit.model_name
        ));
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_session::capture::{ClockModel, Exposure, ImageRole};

    /// The clock's rate after re-timing is that of the simulated world to this many ppm
    /// (floating-point rounding of the rate only).
    const RATE_PPM: f64 = 1e-3;

    fn record(drift_ppm: f64, xsyncs_us: &[u64]) -> CaptureRecord {
        let clock = ClockModel {
            device_ref_us: 1_000_000,
            host_ref_us: 1.7e15,
            drift_ppm,
            residual_rms_us: 10.0,
            samples: 40,
        };
        let exposures = xsyncs_us
            .iter()
            .enumerate()
            .map(|(i, &x)| Exposure {
                index: i as u32,
                group: 0,
                role: ImageRole::Measurement,
                shutter_command_us: x - 60_000,
                xsync_us: Some(x),
                flash_fired_us: Some(x + 180),
                recycle_us: None,
                outcome: ShotOutcome::Ok,
                host_time_us: clock.to_host_us(x),
                image: None,
            })
            .collect();
        let mut r = skinbrdf_synth::studio::planned_capture(
            &Scene::load("default").expect("the built-in scene"),
        );
        r.clock = clock;
        r.exposures = exposures;
        r
    }

    #[test]
    fn a_time_compressed_record_is_re_timed_to_the_device_rate() {
        // 50 times faster than real time: the host sees 2 % of the device's time.
        let r = record(-980_000.0, &[1_000_000, 5_300_000, 9_600_000]);
        let dt_host_s = (r.exposures[1].host_time_us - r.exposures[0].host_time_us) / 1e6;
        assert!((dt_host_s - 0.086).abs() < 1e-6, "{dt_host_s}");
        let rt = real_time_record(&r, 50.0);
        assert!(
            rt.clock.drift_ppm.abs() < RATE_PPM,
            "{}",
            rt.clock.drift_ppm
        );
        for (a, b) in rt.exposures.iter().zip(rt.exposures.iter().skip(1)) {
            let dt_s = (b.host_time_us - a.host_time_us) / 1e6;
            let dev_s = (b.xsync_us.unwrap_or(0) - a.xsync_us.unwrap_or(0)) as f64 / 1e6;
            assert!((dt_s - dev_s).abs() < 1e-6, "{dt_s} vs {dev_s}");
        }
        // The reference point (the offset between the clocks) is kept.
        assert_eq!(rt.clock.host_ref_us, r.clock.host_ref_us);
        assert_eq!(rt.exposures[0].host_time_us, r.exposures[0].host_time_us);
    }

    #[test]
    fn a_real_time_record_is_unchanged() {
        let r = record(3.1, &[1_000_000, 5_300_000]);
        let rt = real_time_record(&r, 1.0);
        assert!((rt.clock.drift_ppm - 3.1).abs() < RATE_PPM);
        for (a, b) in r.exposures.iter().zip(&rt.exposures) {
            assert!((a.host_time_us - b.host_time_us).abs() < 1e-3);
        }
    }
}
