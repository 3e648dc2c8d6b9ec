//! Error against run time: every stage reports how accurate it was and what it cost.

use serde::{Deserialize, Serialize};

use crate::metrics::StageMetrics;
use crate::plan::{Action, Plan, Stage};

/// What a metric measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MetricKind {
    /// An error against ground truth (smaller is better).
    Error,
    /// An internal quality figure (residual, spread) available without ground truth.
    Quality,
    /// A count (samples kept, targets found).
    Count,
    /// A cost (time, memory, rays).
    Cost,
}

/// One named figure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metric {
    /// Name, e.g. `camera_position_error_median`.
    pub name: String,
    /// Value.
    pub value: f64,
    /// Unit, e.g. `mm`, `deg`, `%`, `px`, `s`.
    pub unit: String,
    /// What it measures.
    pub kind: MetricKind,
    /// The target it must stay within, if one is stated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bound: Option<f64>,
}

impl Metric {
    /// A metric without a bound.
    pub fn new(name: &str, value: f64, unit: &str, kind: MetricKind) -> Self {
        Self {
            name: name.to_string(),
            value,
            unit: unit.to_string(),
            kind,
            bound: None,
        }
    }

    /// Sets the bound.
    pub fn with_bound(mut self, bound: f64) -> Self {
        self.bound = Some(bound);
        self
    }

    /// False when the value is not finite or exceeds its bound.
    pub fn within_bound(&self) -> bool {
        self.value.is_finite() && self.bound.is_none_or(|b| self.value <= b)
    }
}

/// How a stage ended up in this run.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "kebab-case")]
pub enum StageStatus {
    /// Ran now.
    Ran,
    /// Inputs unchanged: the previous result was reused.
    Reused,
    /// Not needed.
    Skipped {
        /// Why.
        reason: String,
    },
}

/// One stage's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageReport {
    /// The stage.
    pub stage: Stage,
    /// Ran, reused or skipped.
    #[serde(flatten)]
    pub status: StageStatus,
    /// Wall-clock time of the stage, seconds (0 when skipped or reused).
    pub run_time_s: f64,
    /// The stage's typed figures (what code reads).
    #[serde(default)]
    pub figures: StageMetrics,
    /// The same figures as rows for people and other tools (derived from `figures`).
    pub metrics: Vec<Metric>,
    /// Free-form notes (warnings, diagnostics).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// The stage's self-checks ([`crate::checks`]): one that failed marks the stage FAILED.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub checks: Vec<crate::checks::Check>,
}

impl StageReport {
    /// A stage that ran, with no metrics yet.
    pub fn ran(stage: Stage, run_time_s: f64) -> Self {
        Self {
            stage,
            status: StageStatus::Ran,
            run_time_s,
            figures: StageMetrics::None,
            metrics: Vec::new(),
            notes: Vec::new(),
            checks: Vec::new(),
        }
    }

    /// Sets the stage's typed figures (and the rows derived from them).
    pub fn with_figures(mut self, figures: StageMetrics) -> Self {
        self.metrics = figures.rows();
        self.figures = figures;
        self
    }

    /// A skipped stage.
    pub fn skipped(stage: Stage, reason: &str) -> Self {
        Self {
            stage,
            status: StageStatus::Skipped {
                reason: reason.to_string(),
            },
            run_time_s: 0.0,
            figures: StageMetrics::None,
            metrics: Vec::new(),
            notes: Vec::new(),
            checks: Vec::new(),
        }
    }

    /// Whether one of its self-checks failed.
    pub fn failed(&self) -> bool {
        self.checks.iter().any(crate::checks::Check::failed)
    }

    /// The status as one word or phrase: `ran`, `reused`, `skipped: why`, with `, FAILED its
    /// checks` when one failed.
    pub fn status_text(&self) -> String {
        let status = match &self.status {
            StageStatus::Ran => "ran".to_string(),
            StageStatus::Reused => "reused".to_string(),
            StageStatus::Skipped { reason } => format!("skipped: {reason}"),
        };
        if self.failed() {
            format!("FAILED its checks ({status})")
        } else {
            status
        }
    }

    /// Adds a metric.
    pub fn metric(mut self, m: Metric) -> Self {
        self.metrics.push(m);
        self
    }
}

/// The whole run's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// Session directory.
    pub session: String,
    /// The plan that was followed.
    pub plan: Plan,
    /// Stage reports in execution order.
    pub stages: Vec<StageReport>,
    /// Total wall-clock time, seconds.
    pub total_time_s: f64,
}

impl RunReport {
    /// The typed figures of a stage (`StageMetrics::None` when it did not run).
    pub fn figures(&self, stage: Stage) -> &StageMetrics {
        self.stages
            .iter()
            .find(|s| s.stage == stage)
            .map_or(&StageMetrics::None, |s| &s.figures)
    }

    /// The camera poses' figures, if that stage ran (or was reused).
    pub fn camera_poses(&self) -> Option<&crate::metrics::CameraPoseMetrics> {
        match self.figures(Stage::CameraPoses) {
            StageMetrics::CameraPoses(m) => Some(m),
            _ => None,
        }
    }

    /// Head tracking's figures.
    pub fn head_tracking(&self) -> Option<&crate::metrics::HeadTrackingMetrics> {
        match self.figures(Stage::HeadTracking) {
            StageMetrics::HeadTracking(m) => Some(m),
            _ => None,
        }
    }

    /// Flash triangulation's figures.
    pub fn flash(&self) -> Option<&crate::metrics::FlashMetrics> {
        match self.figures(Stage::FlashTriangulation) {
            StageMetrics::Flash(m) => Some(m),
            _ => None,
        }
    }

    /// Derendering's figures.
    pub fn derender(&self) -> Option<&crate::metrics::DerenderMetrics> {
        match self.figures(Stage::Derender) {
            StageMetrics::Derender(m) => Some(m),
            _ => None,
        }
    }

    /// The placement survey's figures.
    pub fn survey(&self) -> Option<&crate::metrics::SurveyMetrics> {
        match self.figures(Stage::PlacementSurvey) {
            StageMetrics::Survey(m) => Some(m),
            _ => None,
        }
    }

    /// The fit's figures.
    pub fn fit(&self) -> Option<&crate::metrics::FitMetrics> {
        match self.figures(Stage::Fit) {
            StageMetrics::Fit(m) => Some(m),
            _ => None,
        }
    }

    /// Skipped-stage reports for every stage the plan skips.
    pub fn skipped_from_plan(plan: &Plan) -> Vec<StageReport> {
        plan.stages
            .iter()
            .filter_map(|s| match &s.action {
                Action::Skip { reason } => Some(StageReport::skipped(s.stage, reason)),
                Action::Run => None,
            })
            .collect()
    }

    /// Every metric that is out of its bound or not finite.
    pub fn violations(&self) -> Vec<(&StageReport, &Metric)> {
        self.stages
            .iter()
            .flat_map(|s| s.metrics.iter().map(move |m| (s, m)))
            .filter(|(_, m)| !m.within_bound())
            .collect()
    }

    /// A terminal summary: one block per stage with its time and figures.
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        for s in &self.stages {
            let status = match &s.status {
                StageStatus::Ran => format!("{:>8.3} s", s.run_time_s),
                StageStatus::Reused => "  reused  ".to_string(),
                StageStatus::Skipped { reason } => format!("  skipped ({reason})"),
            };
            let status = if s.failed() {
                format!("{status}  FAILED its checks")
            } else {
                status
            };
            out.push_str(&format!("{:<30} {status}\n", s.stage.name()));
            for m in &s.metrics {
                out.push_str(&format!("    {:<40} {}\n", m.name, fmt_metric(m)));
            }
            for n in &s.notes {
                out.push_str(&format!("    note: {n}\n"));
            }
            for c in s.checks.iter().filter(|c| c.failed()) {
                out.push_str(&format!("    FAILED check {}\n", c.to_line()));
            }
        }
        out.push_str(&format!("{:<30} {:>8.3} s\n", "total", self.total_time_s));
        out
    }

    /// A Markdown table of every stage's figures.
    pub fn to_markdown(&self) -> String {
        let mut out = String::from("| stage | status | time (s) | figure | value | bound |\n|---|---|---:|---|---:|---:|\n");
        for s in &self.stages {
            let status = s.status_text();
            if s.metrics.is_empty() {
                out.push_str(&format!(
                    "| {} | {status} | {:.3} | | | |\n",
                    s.stage.name(),
                    s.run_time_s
                ));
            }
            for (i, m) in s.metrics.iter().enumerate() {
                let (name, st, t) = if i == 0 {
                    (
                        s.stage.name().to_string(),
                        status.clone(),
                        format!("{:.3}", s.run_time_s),
                    )
                } else {
                    (String::new(), String::new(), String::new())
                };
                let bound = m
                    .bound
                    .map(|b| format!("≤ {} {}", sig(b), m.unit))
                    .unwrap_or_default();
                out.push_str(&format!(
                    "| {name} | {st} | {t} | {} | {} {} | {bound} |\n",
                    m.name,
                    sig(m.value),
                    m.unit
                ));
            }
        }
        out.push_str(&format!(
            "| **total** | | {:.3} | | | |\n",
            self.total_time_s
        ));
        out
    }
}

impl RunReport {
    /// Every self-check of every stage, with its stage.
    pub fn checks(&self) -> impl Iterator<Item = (&StageReport, &crate::checks::Check)> {
        self.stages
            .iter()
            .flat_map(|s| s.checks.iter().map(move |c| (s, c)))
    }

    /// The checks that failed.
    pub fn failed_checks(&self) -> Vec<(&StageReport, &crate::checks::Check)> {
        self.checks().filter(|(_, c)| c.failed()).collect()
    }

    /// The self-checks as a Markdown table (empty when no stage has any).
    pub fn checks_markdown(&self) -> String {
        let rows: String = self
            .check_rows()
            .iter()
            .map(|r| {
                let verdict = r.verdict.text("**FAILED**", |t| t.to_string());
                let [stage, check, what, figure, bound] = &r.cells;
                format!("| {stage} | {check} | {what} | {figure} | {bound} | {verdict} |\n")
            })
            .collect();
        if rows.is_empty() {
            return rows;
        }
        format!(
            "| {} |\n|---|---|---|---:|---:|---|\n{rows}",
            CHECK_COLUMNS.join(" | ")
        )
    }

    /// The self-checks as an HTML table (empty when no stage has any).
    pub fn checks_html(&self) -> String {
        let rows: String = self
            .check_rows()
            .iter()
            .map(|r| {
                let verdict = r
                    .verdict
                    .text("<span class=\"bad\">FAILED</span>", html_escape);
                let [stage, check, what, figure, bound] = r.cells.each_ref().map(|c| html_escape(c));
                format!(
                    "<tr><td>{stage}</td><td>{check}</td><td>{what}</td><td class=\"num\">{figure}</td><td class=\"num\">{bound}</td><td>{verdict}</td></tr>\n"
                )
            })
            .collect();
        if rows.is_empty() {
            return rows;
        }
        let head: String = CHECK_COLUMNS
            .iter()
            .map(|c| format!("<th>{c}</th>"))
            .collect();
        format!("<h2>Self-checks</h2>\n<table>\n<tr>{head}</tr>\n{rows}</table>\n")
    }

    /// Every self-check as the report's tables show it, in plain text.
    fn check_rows(&self) -> Vec<CheckRow<'_>> {
        use crate::checks::Outcome;
        self.checks()
            .map(|(s, c)| CheckRow {
                cells: [
                    s.stage.name().to_string(),
                    c.name.clone(),
                    c.what.clone(),
                    c.figure
                        .map_or_else(String::new, |f| format!("{} {}", sig(f), c.unit)),
                    format!("≤ {} {}", sig(c.bound), c.unit),
                ],
                verdict: match &c.outcome {
                    Outcome::Passed => Verdict::Passed,
                    Outcome::Failed { likely_cause } => Verdict::Failed(likely_cause),
                    Outcome::NotChecked { why } => Verdict::NotChecked(why),
                },
            })
            .collect()
    }
}

/// The self-check tables' columns.
const CHECK_COLUMNS: [&str; 6] = ["stage", "check", "what", "figure", "bound", "outcome"];

/// One self-check in the report's tables: its text cells and its verdict (the one cell each
/// format marks up).
struct CheckRow<'a> {
    /// Stage, check, what, figure, bound.
    cells: [String; 5],
    /// The outcome.
    verdict: Verdict<'a>,
}

/// A self-check's outcome as the tables print it.
enum Verdict<'a> {
    Passed,
    Failed(&'a str),
    NotChecked(&'a str),
}

impl Verdict<'_> {
    /// The verdict's cell: `failed` marks a failure up; `escape` makes the cause or reason
    /// text safe for the format.
    fn text(&self, failed: &str, escape: impl Fn(&str) -> String) -> String {
        match self {
            Self::Passed => "passed".to_string(),
            Self::Failed(cause) => format!("{failed}: {}", escape(cause)),
            Self::NotChecked(why) => format!("not checked: {}", escape(why)),
        }
    }
}

/// Escapes text for HTML.
pub fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

impl RunReport {
    /// The stage table as HTML (one row per figure; out-of-bound figures marked).
    pub fn to_html_table(&self) -> String {
        let mut out = String::from(
            "<table>\n<tr><th>stage</th><th>status</th><th>time (s)</th><th>figure</th><th>value</th><th>bound</th></tr>\n",
        );
        for s in &self.stages {
            let status = s.status_text();
            let n = s.metrics.len().max(1) + s.notes.len();
            out.push_str(&format!(
                "<tr><td rowspan=\"{n}\">{}</td><td rowspan=\"{n}\">{}</td><td rowspan=\"{n}\" class=\"num\">{:.3}</td>",
                html_escape(s.stage.name()),
                if s.failed() {
                    format!("<span class=\"bad\">{}</span>", html_escape(&status))
                } else {
                    html_escape(&status)
                },
                s.run_time_s
            ));
            if s.metrics.is_empty() {
                out.push_str("<td></td><td></td><td></td></tr>\n");
            }
            for (i, m) in s.metrics.iter().enumerate() {
                if i > 0 {
                    out.push_str("<tr>");
                }
                let bound = m
                    .bound
                    .map(|b| format!("≤ {} {}", sig(b), html_escape(&m.unit)))
                    .unwrap_or_default();
                let class = if m.within_bound() { "num" } else { "num bad" };
                out.push_str(&format!(
                    "<td>{}</td><td class=\"{class}\">{} {}</td><td class=\"num\">{bound}</td></tr>\n",
                    html_escape(&m.name),
                    sig(m.value),
                    html_escape(&m.unit)
                ));
            }
            for note in &s.notes {
                out.push_str(&format!(
                    "<tr><td colspan=\"3\" class=\"note\">note: {}</td></tr>\n",
                    html_escape(note)
                ));
            }
        }
        out.push_str(&format!(
            "<tr><th>total</th><td></td><td class=\"num\">{:.3}</td><td></td><td></td><td></td></tr>\n</table>\n",
            self.total_time_s
        ));
        out
    }
}

/// A self-contained HTML page: a title, free HTML sections, the plan, the stage table and the
/// figures (`(caption, path relative to the page)`), shown inline.
pub fn html_page(
    title: &str,
    sections_html: &str,
    report: &RunReport,
    figures: &[(String, String)],
) -> String {
    let mut h = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title>\n<style>\nbody{{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}}\ntable{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #ccc;padding:2px 8px;vertical-align:top}}\n.num{{text-align:right;font-variant-numeric:tabular-nums}}.bad{{color:#b00;font-weight:bold}}.note{{color:#555;font-size:90%}}\nfigure{{margin:1em 0}}img{{max-width:100%;border:1px solid #eee}}pre{{background:#f6f6f6;padding:.5em}}\n</style></head><body>\n<h1>{t}</h1>\n",
        t = html_escape(title)
    );
    h.push_str(sections_html);
    h.push_str("<h2>Pipeline plan</h2>\n<pre>");
    h.push_str(&html_escape(&report.plan.to_text()));
    h.push_str("</pre>\n<h2>Stages: accuracy and run time</h2>\n");
    h.push_str(&report.to_html_table());
    h.push_str(&report.checks_html());
    let v = report.violations();
    if v.is_empty() {
        h.push_str("<p>Every figure with a stated bound is within it.</p>\n");
    } else {
        h.push_str("<p><b>Out of bounds:</b></p><ul>\n");
        for (st, m) in v {
            h.push_str(&format!(
                "<li>{}: {} = {} {}</li>\n",
                html_escape(st.stage.name()),
                html_escape(&m.name),
                sig(m.value),
                html_escape(&m.unit)
            ));
        }
        h.push_str("</ul>\n");
    }
    if !figures.is_empty() {
        h.push_str("<h2>Figures</h2>\n");
        for (caption, path) in figures {
            h.push_str(&format!(
                "<figure><img src=\"{p}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>\n",
                p = html_escape(path),
                c = html_escape(caption)
            ));
        }
    }
    h.push_str("</body></html>\n");
    h
}

fn sig(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor() as i32;
    let decimals = (3 - mag).clamp(0, 9) as usize;
    format!("{v:.decimals$}")
}

fn fmt_metric(m: &Metric) -> String {
    let mut s = format!("{} {}", sig(m.value), m.unit);
    if let Some(b) = m.bound {
        s.push_str(&format!(
            "  (bound {} {}: {})",
            sig(b),
            m.unit,
            if m.within_bound() { "ok" } else { "EXCEEDED" }
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{Geometry, PlanOptions, SceneFacts};

    #[test]
    fn violations_catch_exceeded_and_non_finite_figures() {
        let facts = SceneFacts {
            placements_known: true,
            intrinsics_known: true,
            camera_poses_known: true,
            head_poses_known: true,
            stationary_sample: false,
            light_position_known: true,
            calibration_known: true,
            geometry: Geometry::Sphere,
            region_convex: Some(true),
        };
        let plan = Plan::derive(&facts, &PlanOptions::default());
        let mut stages = RunReport::skipped_from_plan(&plan);
        stages.push(
            StageReport::ran(Stage::Derender, 1.0)
                .metric(
                    Metric::new("median_rel_error", 2.0, "%", MetricKind::Error).with_bound(3.0),
                )
                .metric(Metric::new("bad", f64::NAN, "%", MetricKind::Error))
                .metric(Metric::new("too_big", 5.0, "mm", MetricKind::Error).with_bound(1.0)),
        );
        let report = RunReport {
            session: "s".into(),
            plan,
            stages,
            total_time_s: 1.0,
        };
        let names: Vec<_> = report
            .violations()
            .iter()
            .map(|(_, m)| m.name.clone())
            .collect();
        assert_eq!(names, ["bad", "too_big"]);
        let md = report.to_markdown();
        assert!(
            md.contains("skipped: an ideal sphere needs no scan"),
            "{md}"
        );
        assert!(report.to_text().contains("EXCEEDED"));
        let html = html_page(
            "t <1>",
            "",
            &report,
            &[("a figure".into(), "fit/x.png".into())],
        );
        assert!(html.contains("<title>t &lt;1&gt;</title>"), "{html}");
        assert!(html.contains("class=\"num bad\">5.000 mm"), "{html}");
        assert!(html.contains("<img src=\"fit/x.png\""), "{html}");
        assert!(html.contains("skipped: an ideal sphere needs no scan"));
    }
}
