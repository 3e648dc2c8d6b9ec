//! Figures (PNG and SVG through plotters): polar plots of the incidence plane (the method's
//! Fig. 6), raw samples with the smoothed curve and its band (Fig. 11), and overlays of several
//! sessions (Figs. 8, 9) with a test of whether two sessions differ beyond their bands.
//!
//! Guarantees: a polar panel's drawing area holds the whole upper half-plane with its horizon,
//! angle labels and ring values (nothing is clipped; circles are round); the scatter draws a
//! curve only over the samples' support ([`support_intervals`]), never across a gap of more
//! than [`SUPPORT_GAP_DEG`] without samples, and states the sample count.
//!
//! A figure is described as data ([`Figure`], [`Panel`], [`Series`]) and drawn twice, once per
//! backend, by [`write_figure`]. Text uses plotters' `ttf` feature (fontconfig finds a system
//! sans-serif font; DejaVu on Debian).

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use serde::{Deserialize, Serialize};
use skinbrdf_core::BrdfSample;

use crate::loess::{Loess, LoessPoint};

/// Errors of figure drawing.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {problem}", path = path.display())]
pub struct PlotError {
    /// The output file.
    pub path: PathBuf,
    /// What went wrong.
    pub problem: String,
}

/// What one series draws.
#[derive(Debug, Clone, PartialEq)]
pub enum SeriesKind {
    /// A polyline.
    Line(Vec<(f64, f64)>),
    /// Dots.
    Points(Vec<(f64, f64)>),
    /// A shaded band `(x, lower, upper)`.
    Band(Vec<(f64, f64, f64)>),
    /// Text centred on `(x, y)`.
    Text(Vec<(f64, f64, String)>),
}

/// One labelled series; `color` indexes a fixed palette (negative = light grey guides).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label (empty = no legend entry).
    pub label: String,
    /// Palette index.
    pub color: i32,
    /// The data.
    pub kind: SeriesKind,
}

/// One plot area.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// Caption.
    pub title: String,
    /// Axis labels.
    pub x_label: String,
    /// Axis labels.
    pub y_label: String,
    /// Ranges (`None` = from the data).
    pub x_range: Option<(f64, f64)>,
    /// Ranges (`None` = from the data).
    pub y_range: Option<(f64, f64)>,
    /// Draw axes and mesh (off for polar plots, which draw their own guides).
    pub axes: bool,
    /// The series.
    pub series: Vec<Series>,
}

/// Panels side by side.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// The panels, left to right.
    pub panels: Vec<Panel>,
    /// Pixel size of one panel.
    pub panel_px: (u32, u32),
}

fn palette(i: i32) -> RGBColor {
    const P: [RGBColor; 6] = [
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(255, 127, 14),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
    ];
    if i < 0 {
        RGBColor(200, 200, 200)
    } else if i >= 100 {
        // A lighter shade of palette colour i - 100 (band edges).
        let c = P[(i - 100) as usize % P.len()];
        RGBColor(
            ((c.0 as u16 + 2 * 255) / 3) as u8,
            ((c.1 as u16 + 2 * 255) / 3) as u8,
            ((c.2 as u16 + 2 * 255) / 3) as u8,
        )
    } else {
        P[i as usize % P.len()]
    }
}

fn data_range(panel: &Panel) -> ((f64, f64), (f64, f64)) {
    let mut xs = (f64::INFINITY, f64::NEG_INFINITY);
    let mut ys = (f64::INFINITY, f64::NEG_INFINITY);
    let mut add = |x: f64, y: f64| {
        if x.is_finite() && y.is_finite() {
            xs = (xs.0.min(x), xs.1.max(x));
            ys = (ys.0.min(y), ys.1.max(y));
        }
    };
    for s in &panel.series {
        match &s.kind {
            SeriesKind::Line(v) | SeriesKind::Points(v) => v.iter().for_each(|&(x, y)| add(x, y)),
            SeriesKind::Band(v) => v.iter().for_each(|&(x, lo, hi)| {
                add(x, lo);
                add(x, hi)
            }),
            SeriesKind::Text(v) => v.iter().for_each(|(x, y, _)| add(*x, *y)),
        }
    }
    let fix = |r: (f64, f64)| {
        if r.0 < r.1 {
            r
        } else if r.0.is_finite() {
            (r.0 - 1.0, r.0 + 1.0)
        } else {
            (0.0, 1.0)
        }
    };
    (
        panel.x_range.unwrap_or(fix(xs)),
        panel.y_range.unwrap_or(fix(ys)),
    )
}

/// Above this many points a point series is drawn as small translucent dots.
const DENSE_POINTS: usize = 500;
/// Caption font size of a panel, pixels.
const CAPTION_FONT_PX: u32 = 17;
/// Margin around a panel's chart, pixels.
const PANEL_MARGIN_PX: u32 = 10;
/// Pixels a caption takes above the chart (font size plus plotters' padding).
const CAPTION_AREA_PX: u32 = CAPTION_FONT_PX + 10;

/// A tick label with as many decimals as a tenth of the axis span needs (`-80`, not `-80.0`;
/// `0.13`, not `0.130000`).
fn tick_label(v: f64, span: f64) -> String {
    let decimals = if span > 0.0 && span.is_finite() {
        (-(span / 10.0).log10().floor()).clamp(0.0, 9.0) as usize
    } else {
        3
    };
    format!("{v:.decimals$}")
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
) -> Result<(), String> {
    let ((x0, x1), (y0, y1)) = data_range(panel);
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, ("sans-serif", CAPTION_FONT_PX))
        .margin(PANEL_MARGIN_PX)
        .x_label_area_size(if panel.axes { 35 } else { 0 })
        .y_label_area_size(if panel.axes { 55 } else { 0 })
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    if panel.axes {
        let x_fmt = |v: &f64| tick_label(*v, x1 - x0);
        let y_fmt = |v: &f64| tick_label(*v, y1 - y0);
        chart
            .configure_mesh()
            .x_label_formatter(&x_fmt)
            .y_label_formatter(&y_fmt)
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 14))
            .x_desc(panel.x_label.as_str())
            .y_desc(panel.y_label.as_str())
            .draw()
            .map_err(|e| e.to_string())?;
    }
    let mut legend = false;
    for s in &panel.series {
        let col = palette(s.color);
        match &s.kind {
            SeriesKind::Band(v) => {
                let mut poly: Vec<(f64, f64)> = v.iter().map(|&(x, _, hi)| (x, hi)).collect();
                poly.extend(v.iter().rev().map(|&(x, lo, _)| (x, lo)));
                let ann = chart
                    .draw_series(std::iter::once(Polygon::new(poly, col.mix(0.25).filled())))
                    .map_err(|e| e.to_string())?;
                if !s.label.is_empty() {
                    legend = true;
                    ann.label(s.label.as_str()).legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 15, y + 5)], col.mix(0.25).filled())
                    });
                }
            }
            SeriesKind::Line(v) => {
                let ann = chart
                    .draw_series(LineSeries::new(
                        v.iter().copied(),
                        col.stroke_width(if s.color < 0 || s.color >= 100 { 1 } else { 3 }),
                    ))
                    .map_err(|e| e.to_string())?;
                if !s.label.is_empty() {
                    legend = true;
                    ann.label(s.label.as_str()).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 15, y)], col.stroke_width(2))
                    });
                }
            }
            SeriesKind::Text(v) => {
                let style = TextStyle::from(("sans-serif", 13).into_font())
                    .color(&RGBColor(90, 90, 90))
                    .pos(Pos::new(HPos::Center, VPos::Center));
                chart
                    .draw_series(
                        v.iter()
                            .map(|(x, y, t)| Text::new(t.clone(), (*x, *y), style.clone())),
                    )
                    .map_err(|e| e.to_string())?;
            }
            SeriesKind::Points(v) => {
                // Thousands of samples: small, translucent dots, so the curves stay visible
                // and the density shows.
                let (radius, alpha) = if v.len() > DENSE_POINTS {
                    (2, 0.25)
                } else {
                    (3, 0.8)
                };
                let ann = chart
                    .draw_series(
                        v.iter()
                            .map(|&(x, y)| Circle::new((x, y), radius, col.mix(alpha).filled())),
                    )
                    .map_err(|e| e.to_string())?;
                if !s.label.is_empty() {
                    legend = true;
                    ann.label(s.label.as_str())
                        .legend(move |(x, y)| Circle::new((x + 7, y), 3, col.filled()));
                }
            }
        }
    }
    if legend {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn draw_figure<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    fig: &Figure,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let areas = root.split_evenly((1, fig.panels.len().max(1)));
    for (a, p) in areas.iter().zip(&fig.panels) {
        draw_panel(a, p)?;
    }
    root.present().map_err(|e| e.to_string())
}

/// Writes `stem.png` and `stem.svg`; returns their paths. The PNG is written to a temporary
/// name and renamed (atomic); the SVG is rendered to memory and written atomically.
pub fn write_figure(stem: &Path, fig: &Figure) -> Result<Vec<PathBuf>, PlotError> {
    let w = fig.panel_px.0 * fig.panels.len().max(1) as u32;
    let h = fig.panel_px.1;
    let png = stem.with_extension("png");
    let svg = stem.with_extension("svg");
    let err = |path: &Path, problem: String| PlotError {
        path: path.to_path_buf(),
        problem,
    };
    let tmp_png = stem.with_extension("tmp.png");
    draw_figure(
        BitMapBackend::new(&tmp_png, (w, h)).into_drawing_area(),
        fig,
    )
    .map_err(|e| err(&png, e))?;
    std::fs::rename(&tmp_png, &png).map_err(|e| err(&png, e.to_string()))?;
    let mut text = String::new();
    draw_figure(
        SVGBackend::with_string(&mut text, (w, h)).into_drawing_area(),
        fig,
    )
    .map_err(|e| err(&svg, e))?;
    skinbrdf_samples::write_atomic(&svg, |out| out.write_all(text.as_bytes()))
        .map_err(|e| err(&svg, e.to_string()))?;
    Ok(vec![png, svg])
}

/// A curve of the incidence plane: `(signed theta_e in degrees, value, optional band)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlaneCurve {
    /// Label.
    pub label: String,
    /// Incident angle, degrees.
    pub theta_i_deg: f64,
    /// `(signed theta_e deg, value, lower, upper)`; negative angles on the light's side.
    pub points: Vec<(f64, f64, f64, f64)>,
}

/// Signed exitant angles of the incidence plane, degrees.
pub fn plane_angles_deg(step_deg: f64) -> Vec<f64> {
    let n = (178.0 / step_deg).round() as usize;
    (0..=n).map(|k| -89.0 + k as f64 * step_deg).collect()
}

/// `(theta_i, theta_e, phi_d)` in radians of a signed incidence-plane angle.
pub fn plane_point(theta_i_deg: f64, signed_theta_e_deg: f64) -> [f64; 3] {
    let phi = if signed_theta_e_deg >= 0.0 {
        std::f64::consts::PI
    } else {
        0.0
    };
    [
        theta_i_deg.to_radians(),
        signed_theta_e_deg.abs().to_radians(),
        phi,
    ]
}

/// A model's incidence-plane curve (one channel, or the channel mean with `channel = 3`).
pub fn model_curve(
    label: &str,
    f: impl Fn([f64; 3]) -> [f64; 3],
    theta_i_deg: f64,
    channel: usize,
) -> PlaneCurve {
    let points = plane_angles_deg(1.0)
        .into_iter()
        .map(|t| {
            let v = f(plane_point(theta_i_deg, t));
            let y = if channel < 3 {
                v[channel]
            } else {
                (v[0] + v[1] + v[2]) / 3.0
            };
            (t, y, y, y)
        })
        .collect();
    PlaneCurve {
        label: label.into(),
        theta_i_deg,
        points,
    }
}

/// Largest standard error (log units: the smoother works on `ln(rho + floor)`) at which a
/// smoothed point is drawn. Beyond it the local quadratic is extrapolating into a part of the
/// plane without samples (its 95% band is wider than a factor of about 1.27 each way), and the
/// curve would show the polynomial, not the skin.
pub const LOESS_MAX_LOG_STD_ERROR: f64 = 0.12;

/// A smoothed incidence-plane curve with its band (3-predictor smoother on
/// `(theta_i, theta_e, phi_d)` in radians), only where the data support it (see
/// [`LOESS_MAX_LOG_STD_ERROR`]); `back` maps the smoother's scale to the plotted one (e.g.
/// `exp(v) - floor` for a smoother of `ln(rho + floor)`; monotone, so bands map to bands).
pub fn loess_curve(
    label: &str,
    l: &Loess,
    theta_i_deg: f64,
    back: impl Fn(f64) -> f64,
) -> PlaneCurve {
    let xs: Vec<Vec<f64>> = plane_angles_deg(2.0)
        .into_iter()
        .map(|t| plane_point(theta_i_deg, t).to_vec())
        .collect();
    let preds = l.predict_many(&xs);
    let points = plane_angles_deg(2.0)
        .into_iter()
        .zip(preds)
        .filter_map(|(t, p): (f64, Option<LoessPoint>)| {
            p.filter(|p| p.std_error.is_finite() && p.std_error <= LOESS_MAX_LOG_STD_ERROR)
                .map(|p| (t, back(p.value), back(p.lower), back(p.upper)))
        })
        .collect();
    PlaneCurve {
        label: label.into(),
        theta_i_deg,
        points,
    }
}

/// Extent of a polar panel in units of its largest plotted value `rmax`: the x range is
/// `+-POLAR_HALF_WIDTH`, the y range `[POLAR_BELOW_HORIZON, POLAR_TOP]`: room for the ring values
/// under the horizon, the angle labels outside the outer ring, and the legend in the upper right
/// corner, above the 30 degree label and the clipped band edges (which end at `y <= 1.05 rmax`
/// there).
pub const POLAR_HALF_WIDTH: f64 = 1.32;
/// See [`POLAR_HALF_WIDTH`].
pub const POLAR_BELOW_HORIZON: f64 = -0.2;
/// See [`POLAR_HALF_WIDTH`].
pub const POLAR_TOP: f64 = 1.6;
/// Band edges of a polar plot are clipped at this multiple of `rmax`.
pub const POLAR_BAND_CLIP: f64 = 1.1;
/// Radius of the angle labels, in units of `rmax`.
const POLAR_LABEL_RADIUS: f64 = 1.19;
/// Width of one polar panel, pixels (its height follows from the ranges: circles stay round).
const POLAR_PANEL_WIDTH_PX: u32 = 440;

/// A value with three significant digits.
fn sig3(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor() as i32;
    let decimals = (2 - mag).clamp(0, 9) as usize;
    format!("{v:.decimals$}")
}

/// Polar plot of the incidence plane, one panel per incident angle (the method's Fig. 6):
/// the value is the radius, the angle from the vertical is the signed exitant angle (negative on
/// the light's side). Guides: rings at quarters of the largest value (labelled under the
/// horizon), spokes every 30 degrees (labelled outside the outer ring), the horizon, and the
/// light direction as a grey ray.
pub fn polar_figure(curves_per_angle: &[(f64, Vec<PlaneCurve>)], scale_label: &str) -> Figure {
    let panels = curves_per_angle
        .iter()
        .map(|(ti, curves)| {
            let rmax = curves
                .iter()
                .flat_map(|c| c.points.iter().map(|p| p.1))
                .filter(|v| v.is_finite())
                .fold(1e-12, f64::max);
            let guide = |points: Vec<(f64, f64)>| Series {
                label: String::new(),
                color: -1,
                kind: SeriesKind::Line(points),
            };
            let polar_xy = |deg: f64, r: f64| {
                let a = deg.to_radians();
                (r * a.sin(), r * a.cos())
            };
            let mut series = Vec::new();
            let mut labels = Vec::new();
            for k in 1..=4 {
                let r = rmax * k as f64 / 4.0;
                series.push(guide(
                    (0..=90)
                        .map(|a| polar_xy(-90.0 + 2.0 * a as f64, r))
                        .collect(),
                ));
                labels.push((r, -0.08 * rmax, sig3(r)));
            }
            series.push(guide(vec![(-rmax, 0.0), (rmax, 0.0)]));
            for deg in [-60.0, -30.0, 0.0, 30.0, 60.0] {
                series.push(guide(vec![(0.0, 0.0), polar_xy(deg, rmax)]));
            }
            for deg in [-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0] {
                let (x, y) = polar_xy(deg, POLAR_LABEL_RADIUS * rmax);
                // The +-90 degree labels sit just above the horizon line.
                let y = if f64::abs(deg) == 90.0 {
                    0.06 * rmax
                } else {
                    y
                };
                labels.push((x, y, format!("{deg:.0}°")));
            }
            series.push(Series {
                label: String::new(),
                color: -1,
                kind: SeriesKind::Text(labels),
            });
            series.push(Series {
                label: "light".into(),
                color: -1,
                kind: SeriesKind::Line(vec![(0.0, 0.0), polar_xy(-ti, POLAR_BAND_CLIP * rmax)]),
            });
            for (k, c) in curves.iter().enumerate() {
                let to_xy = |t: f64, r: f64| polar_xy(t, r.max(0.0));
                if c.points.iter().any(|p| p.2 != p.3) {
                    // The band's edges as thin lines (clipped to the plot), upper then lower.
                    let clip = |r: f64| r.min(POLAR_BAND_CLIP * rmax);
                    let upper: Vec<(f64, f64)> =
                        c.points.iter().map(|p| to_xy(p.0, clip(p.3))).collect();
                    let lower: Vec<(f64, f64)> =
                        c.points.iter().map(|p| to_xy(p.0, clip(p.2))).collect();
                    for edge in [upper, lower] {
                        series.push(Series {
                            label: String::new(),
                            color: 100 + k as i32,
                            kind: SeriesKind::Line(edge),
                        });
                    }
                }
                series.push(Series {
                    label: c.label.clone(),
                    color: k as i32,
                    kind: SeriesKind::Line(c.points.iter().map(|p| to_xy(p.0, p.1)).collect()),
                });
            }
            Panel {
                title: format!("theta_i = {ti:.0} deg ({scale_label})"),
                x_label: String::new(),
                y_label: String::new(),
                x_range: Some((-POLAR_HALF_WIDTH * rmax, POLAR_HALF_WIDTH * rmax)),
                y_range: Some((POLAR_BELOW_HORIZON * rmax, POLAR_TOP * rmax)),
                axes: false,
                series,
            }
        })
        .collect();
    // Equal scales on both axes: the chart's pixel aspect matches the ranges'.
    let chart_w = f64::from(POLAR_PANEL_WIDTH_PX - 2 * PANEL_MARGIN_PX);
    let chart_h = chart_w * (POLAR_TOP - POLAR_BELOW_HORIZON) / (2.0 * POLAR_HALF_WIDTH);
    Figure {
        panels,
        panel_px: (
            POLAR_PANEL_WIDTH_PX,
            chart_h.round() as u32 + 2 * PANEL_MARGIN_PX + CAPTION_AREA_PX,
        ),
    }
}

/// Largest gap between neighbouring samples' angles, degrees, that a curve of the scatter
/// figure is drawn across: the same tolerance the polar figure uses to decide whether an
/// incident angle has data. A curve over a wider gap would show the smoother's or the model's
/// extrapolation, not a measurement.
pub const SUPPORT_GAP_DEG: f64 = 10.0;
/// Fewest samples a stretch of support needs (fewer: a stray sample, not a curve's support).
pub const SUPPORT_MIN_SAMPLES: usize = 3;

/// The stretches of `xs` covered by samples: the sorted values split wherever neighbours are
/// more than `max_gap` apart, each stretch `(first, last)`, stretches with fewer than
/// `min_samples` values dropped. Non-finite values are ignored.
pub fn support_intervals(xs: &[f64], max_gap: f64, min_samples: usize) -> Vec<(f64, f64)> {
    let mut v: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..=v.len() {
        if i == v.len() || v[i] - v[i - 1] > max_gap {
            if i - start >= min_samples.max(1) {
                out.push((v[start], v[i - 1]));
            }
            start = i;
        }
    }
    out
}

/// The pieces of `curve` inside `support`, one per stretch that holds at least one of its points.
pub fn clip_to_support(curve: &PlaneCurve, support: &[(f64, f64)]) -> Vec<PlaneCurve> {
    support
        .iter()
        .map(|&(lo, hi)| PlaneCurve {
            label: curve.label.clone(),
            theta_i_deg: curve.theta_i_deg,
            points: curve
                .points
                .iter()
                .copied()
                .filter(|p| p.0 >= lo && p.0 <= hi)
                .collect(),
        })
        .filter(|c| !c.points.is_empty())
        .collect()
}

/// The series of a curve drawn piece by piece (legend entries on the first piece only).
fn curve_series(k: usize, label: &str, pieces: &[PlaneCurve]) -> Vec<Series> {
    let mut series = Vec::new();
    let banded = pieces.iter().any(|c| c.points.iter().any(|p| p.2 != p.3));
    for (j, c) in pieces.iter().enumerate() {
        let named = |s: String| if j == 0 { s } else { String::new() };
        if banded {
            series.push(Series {
                label: named(format!("{label} 95% band")),
                color: k as i32,
                kind: SeriesKind::Band(c.points.iter().map(|p| (p.0, p.2, p.3)).collect()),
            });
        }
        series.push(Series {
            label: named(label.to_owned()),
            color: k as i32,
            kind: SeriesKind::Line(c.points.iter().map(|p| (p.0, p.1)).collect()),
        });
    }
    series
}

fn plane_figure(
    title: &str,
    samples: &[(f64, f64)],
    curves: &[PlaneCurve],
    support: Option<&[(f64, f64)]>,
    y_label: &str,
) -> Figure {
    let mut series = Vec::new();
    if !samples.is_empty() {
        series.push(Series {
            label: format!("samples (n = {})", samples.len()),
            color: 5,
            kind: SeriesKind::Points(samples.to_vec()),
        });
    }
    for (k, c) in curves.iter().enumerate() {
        let pieces = match support {
            Some(s) => clip_to_support(c, s),
            None => vec![c.clone()],
        };
        series.extend(curve_series(k, &c.label, &pieces));
    }
    Figure {
        panels: vec![Panel {
            title: title.into(),
            x_label: "signed exitant angle theta_e (deg; < 0 on the light's side)".into(),
            y_label: y_label.into(),
            x_range: Some((-90.0, 90.0)),
            y_range: None,
            axes: true,
            series,
        }],
        panel_px: (760, 480),
    }
}

/// Raw samples near the incidence plane at `theta_i_deg` with smoothed curves and bands
/// (the method's Fig. 11), Cartesian: signed exitant angle against value. Curves are drawn only
/// over the samples' support ([`support_intervals`] with [`SUPPORT_GAP_DEG`] and
/// [`SUPPORT_MIN_SAMPLES`]); the legend states the sample count.
pub fn scatter_figure(
    title: &str,
    samples: &[(f64, f64)],
    curves: &[PlaneCurve],
    y_label: &str,
) -> Figure {
    let xs: Vec<f64> = samples.iter().map(|p| p.0).collect();
    let support = support_intervals(&xs, SUPPORT_GAP_DEG, SUPPORT_MIN_SAMPLES);
    plane_figure(title, samples, curves, Some(&support), y_label)
}

/// Samples within `tol_deg` of `theta_i_deg` and of the incidence plane, as
/// `(signed theta_e deg, channel mean)`.
pub fn plane_samples(samples: &[BrdfSample], theta_i_deg: f64, tol_deg: f64) -> Vec<(f64, f64)> {
    let tol = tol_deg.to_radians();
    let scale = crate::smooth::GreyScale::of(samples);
    samples
        .iter()
        .filter(|s| (f64::from(s.theta_i_rad) - theta_i_deg.to_radians()).abs() <= tol)
        .filter(|s| {
            let pd = f64::from(s.phi_d_rad);
            pd <= tol || pd >= std::f64::consts::PI - tol
        })
        .map(|s| {
            let signed = s.angles().signed_theta_e_rad().to_degrees();
            (signed, scale.grey(s))
        })
        .collect()
}

/// Whether two smoothed curves differ beyond their confidence bands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Difference {
    /// Labels compared.
    pub a: String,
    /// Labels compared.
    pub b: String,
    /// Largest `|a - b| / sqrt(se_a^2 + se_b^2)` over the common angles.
    pub max_z: f64,
    /// Fraction of common angles where the 95% bands do not overlap.
    pub fraction_disjoint: f64,
    /// Verdict: the curves differ where `max_z` exceeds the Bonferroni-corrected two-sided 95%
    /// normal quantile for the number of angles compared.
    pub differ: bool,
    /// The threshold used.
    pub z_threshold: f64,
}

/// Compares two curves at their common angles (points matched by angle).
pub fn compare_curves(a: &PlaneCurve, b: &PlaneCurve) -> Difference {
    let mut max_z = 0.0f64;
    let mut disjoint = 0usize;
    let mut n = 0usize;
    for pa in &a.points {
        if let Some(pb) = b.points.iter().find(|pb| (pb.0 - pa.0).abs() < 1e-9) {
            n += 1;
            // Band half-width = 1.96 se.
            let sa = (pa.3 - pa.2) / (2.0 * 1.959964);
            let sb = (pb.3 - pb.2) / (2.0 * 1.959964);
            let s = (sa * sa + sb * sb).sqrt();
            if s > 0.0 {
                max_z = max_z.max((pa.1 - pb.1).abs() / s);
            }
            if pa.2 > pb.3 || pb.2 > pa.3 {
                disjoint += 1;
            }
        }
    }
    // Bonferroni: per-angle level 0.05 / n; the normal quantile of 1 - 0.025/n (approximation
    // sqrt(2 ln(n/0.05)) is close; use the exact quantile through erfc bisection).
    let p = 0.025 / n.max(1) as f64;
    let z_threshold = {
        let (mut lo, mut hi) = (0.0f64, 10.0f64);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if 0.5 * erfc(mid / std::f64::consts::SQRT_2) > p {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    Difference {
        a: a.label.clone(),
        b: b.label.clone(),
        max_z,
        fraction_disjoint: if n > 0 {
            disjoint as f64 / n as f64
        } else {
            0.0
        },
        differ: max_z > z_threshold,
        z_threshold,
    }
}

/// Complementary error function (Numerical Recipes' Chebyshev fit, relative error < 1.2e-7).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398
                                    + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277)))))))))
            .exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Overlay of several sessions' curves with bands (the method's Figs. 8, 9).
pub fn overlay_figure(title: &str, curves: &[PlaneCurve], y_label: &str) -> Figure {
    plane_figure(title, &[], curves, None, y_label)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(label: &str, offset: f64, se: f64) -> PlaneCurve {
        PlaneCurve {
            label: label.into(),
            theta_i_deg: 30.0,
            points: plane_angles_deg(2.0)
                .into_iter()
                .map(|t| {
                    let v = 0.3 + offset + 0.1 * (t / 90.0);
                    (t, v, v - 1.96 * se, v + 1.96 * se)
                })
                .collect(),
        }
    }

    #[test]
    fn curves_differ_only_beyond_their_bands() {
        let a = curve("a", 0.0, 0.01);
        let same = curve("b", 0.005, 0.01);
        let far = curve("c", 0.1, 0.01);
        assert!(!compare_curves(&a, &same).differ);
        let d = compare_curves(&a, &far);
        assert!(d.differ && d.fraction_disjoint > 0.99, "{d:?}");
        assert!(d.z_threshold > 2.5 && d.z_threshold < 4.0);
    }

    #[test]
    fn figures_are_written_as_png_and_svg() {
        let dir = tempfile::tempdir().expect("tempdir");
        let fig = polar_figure(
            &[
                (0.0, vec![curve("a", 0.0, 0.01)]),
                (30.0, vec![curve("a", 0.0, 0.0)]),
            ],
            "1/sr",
        );
        let files = write_figure(&dir.path().join("polar"), &fig).expect("write");
        for f in &files {
            assert!(std::fs::metadata(f).expect("exists").len() > 1000, "{f:?}");
        }
        let svg = std::fs::read_to_string(&files[1]).expect("svg");
        assert!(svg.contains("theta_i = 30 deg"));
        let fig = scatter_figure(
            "s",
            &[(0.0, 0.3), (10.0, 0.35)],
            &[curve("smooth", 0.0, 0.01)],
            "rho",
        );
        write_figure(&dir.path().join("scatter"), &fig).expect("write");
    }

    /// Every `(x, y)` a series draws (text anchors included).
    fn drawn_points(s: &Series) -> Vec<(f64, f64)> {
        match &s.kind {
            SeriesKind::Line(v) | SeriesKind::Points(v) => v.clone(),
            SeriesKind::Band(v) => v
                .iter()
                .flat_map(|&(x, lo, hi)| [(x, lo), (x, hi)])
                .collect(),
            SeriesKind::Text(v) => v.iter().map(|&(x, y, _)| (x, y)).collect(),
        }
    }

    #[test]
    fn support_splits_at_gaps_wider_than_the_limit_and_drops_strays() {
        let xs = [-45.0, -43.0, -41.0, -39.0, 5.0, 30.0, 31.0, 33.0, f64::NAN];
        assert_eq!(
            support_intervals(&xs, 10.0, 3),
            vec![(-45.0, -39.0), (30.0, 33.0)]
        );
        // A gap of exactly the limit is bridged, one just over it is not.
        assert_eq!(
            support_intervals(&[0.0, 10.0, 20.0], 10.0, 3),
            vec![(0.0, 20.0)]
        );
        assert!(support_intervals(&[0.0, 10.5, 21.0], 10.0, 3).is_empty());
        assert!(support_intervals(&[], 10.0, 3).is_empty());
    }

    #[test]
    fn scatter_curves_lie_within_the_samples_support() {
        // The session of the issue: samples at theta_i = 30 only near -40 degrees, plus a
        // second cluster near +20 degrees; the curves are defined from -89 to +89.
        let mut pts: Vec<(f64, f64)> = (0..40).map(|k| (-46.0 + 0.3 * k as f64, 0.3)).collect();
        pts.extend((0..10).map(|k| (18.0 + 0.4 * k as f64, 0.4)));
        let support = support_intervals(
            &pts.iter().map(|p| p.0).collect::<Vec<_>>(),
            SUPPORT_GAP_DEG,
            SUPPORT_MIN_SAMPLES,
        );
        assert_eq!(support.len(), 2, "{support:?}");
        let curves = [curve("loess", 0.0, 0.01), curve("model", 0.0, 0.0)];
        let fig = scatter_figure("s", &pts, &curves, "rho");
        let panel = &fig.panels[0];
        let mut drawn = 0;
        for s in &panel.series {
            if matches!(s.kind, SeriesKind::Points(_)) {
                assert_eq!(s.label, "samples (n = 50)");
                continue;
            }
            let xs: Vec<f64> = drawn_points(s).iter().map(|p| p.0).collect();
            let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            // Each piece lies within one stretch of support: none crosses the gap.
            assert!(
                support.iter().any(|&(a, b)| lo >= a && hi <= b),
                "{}: {lo}..{hi} outside {support:?}",
                s.label
            );
            drawn += 1;
        }
        // Loess: band and line per stretch; model: line per stretch.
        assert_eq!(drawn, 6);
        // The overlay of sessions (no samples) draws the curves whole.
        let overlay = overlay_figure("o", &curves, "rho");
        let first = drawn_points(&overlay.panels[0].series[1]);
        assert_eq!((first[0].0, first[first.len() - 1].0), (-89.0, 89.0));
    }

    #[test]
    fn polar_panels_hold_the_horizon_labels_and_every_curve() {
        // A curve with a wide band (clipped) and values at +-89 degrees, on the horizon.
        let fig = polar_figure(
            &[
                (0.0, vec![curve("a", 0.0, 0.2)]),
                (60.0, vec![curve("a", 0.0, 0.0), curve("b", 0.1, 0.01)]),
            ],
            "1/sr",
        );
        for panel in &fig.panels {
            let ((x0, x1), (y0, y1)) = data_range(panel);
            let rmax = x1 / POLAR_HALF_WIDTH;
            // Room under the horizon for the ring values: a tenth of rmax at least.
            assert!(y0 <= -0.1 * rmax, "{}: horizon at the edge", panel.title);
            let mut texts = 0;
            for s in &panel.series {
                let margin = if matches!(s.kind, SeriesKind::Text(_)) {
                    texts += 1;
                    // Text is centred on its anchor: keep half a label's width clear.
                    0.05 * rmax
                } else {
                    0.0
                };
                for (x, y) in drawn_points(s) {
                    assert!(
                        x >= x0 + margin
                            && x <= x1 - margin
                            && y >= y0 + margin
                            && y <= y1 - margin,
                        "{}: ({x}, {y}) outside the panel",
                        panel.title
                    );
                }
            }
            assert_eq!(texts, 1, "ring and angle labels");
        }
        // Equal scales: the chart's pixel aspect matches the ranges' to 2% (round rings).
        const ASPECT_TOL: f64 = 0.02;
        let (w, h) = fig.panel_px;
        let px = f64::from(w - 2 * PANEL_MARGIN_PX)
            / f64::from(h - 2 * PANEL_MARGIN_PX - CAPTION_AREA_PX);
        let data = 2.0 * POLAR_HALF_WIDTH / (POLAR_TOP - POLAR_BELOW_HORIZON);
        assert!((px / data - 1.0).abs() < ASPECT_TOL, "{px} vs {data}");
    }

    #[test]
    fn tick_labels_carry_the_decimals_the_span_needs() {
        assert_eq!(tick_label(-80.0, 180.0), "-80");
        assert_eq!(tick_label(0.13, 0.1), "0.13");
        assert_eq!(tick_label(0.135, 0.05), "0.135");
        assert_eq!(tick_label(2.5, 5.0), "2.5");
    }
}
