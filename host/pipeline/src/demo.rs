//! `skinbrdf demo`: the whole system on the built-in default scene.
//!
//! 1. **Capture**: the firmware simulator (the firmware's own sequencer with camera and flash
//!    models, on a pseudo-terminal, faster than real time) runs the method's capture plan
//!    (`plans/method.toml`: 30 measurement shots, 3 light-position, 1 reference-standard,
//!    2 standard-position) through the host capture client, exactly as a board would.
//! 2. **Synthesis**: the generator renders one image per recorded exposure of the default scene,
//!    with ground truth.
//! 3. **Processing**: the planned pipeline ([`crate::process`]) recovers poses from the images,
//!    derenders, smooths and fits.
//! 4. **Report**: `report.md` with every stage's accuracy against the ground truth and its run
//!    time, and the figures.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use skinbrdf_capture::{parse_plan, run_capture, CaptureOptions, SerialConnector, Unattended};
use skinbrdf_session::capture::{CaptureRecord, ShotOutcome};
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
    #[error("simulator: {0}")]
    Sim(#[from] skinbrdf_sim::SimError),
    /// The built-in plan did not parse.
    #[error("capture plan: {0}")]
    Plan(#[from] skinbrdf_capture::PlanError),
    /// The capture failed.
    #[error("capture: {0}")]
    Capture(#[from] skinbrdf_capture::CaptureError),
    /// The scene did not load.
    #[error("scene: {0}")]
    Scene(#[from] skinbrdf_synth::SceneError),
    /// Synthesis failed.
    #[error("synthesis: {0}")]
    Synth(#[from] skinbrdf_synth::SynthError),
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
        out_dir: Some(session_dir.clone()),
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
    on_event(DemoEvent::Step(
        "synthesis: rendering one image per exposure",
    ));
    let scene = Scene::load(&cfg.scene)?;
    let synth = generate(
        &scene,
        &SynthOptions {
            resolution: cfg.resolution,
            capture: Some(capture.clone()),
            noise_free: false,
            samples_per_pixel: None,
            studio: false,
        },
        &session_dir,
    )?;
    on_event(DemoEvent::Synthesized(&synth));

    // 3. process
    on_event(DemoEvent::Step("process: the planned pipeline"));
    let mut pcfg = cfg.process.clone();
    pcfg.force = true;
    let out = process(&session_dir, &pcfg, &mut |e| {
        on_event(DemoEvent::Process(e))
    })?;

    // 4. report
    let total_s = t0.elapsed().as_secs_f64();
    let report_path = cfg.out_dir.join("report.md");
    let md = demo_markdown(&capture, capture_s, &synth, &out, total_s);
    write_atomic(&report_path, md.as_bytes())?;
    let html = demo_html(&capture, capture_s, &synth, &out, total_s);
    write_atomic(&cfg.out_dir.join("report.html"), html.as_bytes())?;
    Ok(DemoOutput {
        capture,
        capture_s,
        synth,
        process: out,
        report_path,
        total_s,
    })
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
    let mean = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let span_s = match (c.exposures.first(), c.exposures.last()) {
        (Some(a), Some(b)) => {
            b.shutter_command_us.saturating_sub(a.shutter_command_us) as f64 / 1e6
        }
        _ => 0.0,
    };
    vec![
        Metric::new("exposures", c.exposures.len() as f64, "", MetricKind::Count),
        Metric::new("exposures_ok", ok as f64, "", MetricKind::Count),
        Metric::new("shutter_lag_mean", mean(&lags), "ms", MetricKind::Quality),
        Metric::new("recycle_mean", mean(&recycles), "s", MetricKind::Quality),
        Metric::new("session_device_time", span_s, "s", MetricKind::Quality),
        Metric::new(
            "clock_model_residual_rms",
            c.clock.residual_rms_us,
            "us",
            MetricKind::Quality,
        ),
        Metric::new("capture_wall_time", capture_s, "s", MetricKind::Cost),
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
    out: &ProcessOutput,
    total_s: f64,
) -> String {
    use crate::report::html_escape;
    let mut h = format!(
        "<p>The firmware simulator captured a timed session; the generator rendered it; the \
         pipeline recovered poses from the images, derendered, smoothed and fitted. Total \
         {total_s:.1} s.</p>\n<h2>Capture ({} {}, firmware {})</h2>\n<table>\n",
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
    out: &ProcessOutput,
    total_s: f64,
) -> String {
    let mut md = String::from("# skinbrdf demo\n\n");
    md.push_str(&format!(
        "The firmware simulator captured a timed session; the generator rendered it; the pipeline \
         recovered poses from the images, derendered, smoothed and fitted. Total {total_s:.1} s.\n\n"
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
                "- {}: {} = {} {} (bound {:?})\n",
                st.stage.name(),
                m.name,
                m.value,
                m.unit,
                m.bound
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
