//! Exposure, tone curve, sRGB encoding and the labelled side-by-side composition.

use plotters::prelude::*;

use crate::RenderError;

/// Linear value the auto exposure maps the 99th-percentile lit luminance to (before the tone
/// curve): leaves headroom for highlights of the measured panel.
const AUTO_TARGET: f64 = 0.8;
/// White point of the extended Reinhard curve (linear values at or above it map to 1).
const WHITE_POINT: f64 = 4.0;
/// Height of the label strip above the panels, pixels.
const LABEL_STRIP_PX: u32 = 30;
/// Gap between the panels, pixels.
const GAP_PX: u32 = 6;

/// An exposure and the tone curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToneMap {
    /// Linear multiplier applied before the curve.
    pub exposure: f64,
}

impl ToneMap {
    /// A tone map with the given exposure.
    pub fn new(exposure: f64) -> Self {
        Self { exposure }
    }

    /// Linear radiance to an 8-bit sRGB value: exposure, extended Reinhard
    /// `x (1 + x / w^2) / (1 + x)` (monotone, 0 at 0, 1 at `w`), sRGB transfer function.
    pub fn encode(&self, v: f32) -> u8 {
        let x = (f64::from(v) * self.exposure).max(0.0);
        let y = (x * (1.0 + x / (WHITE_POINT * WHITE_POINT)) / (1.0 + x)).min(1.0);
        let s = if y <= 0.003_130_8 {
            12.92 * y
        } else {
            1.055 * y.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0).round().clamp(0.0, 255.0) as u8
    }
}

/// Luminance (Rec. 709 weights) of a linear RGB value.
fn luminance(c: &[f32; 3]) -> f64 {
    0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2])
}

/// The exposure that maps the 99th percentile of the lit pixels' luminance to [`AUTO_TARGET`]
/// (1 when nothing is lit).
pub(crate) fn auto_exposure(radiance: &[[f32; 3]]) -> f64 {
    let mut l: Vec<f64> = radiance
        .iter()
        .map(luminance)
        .filter(|v| *v > 0.0)
        .collect();
    if l.is_empty() {
        return 1.0;
    }
    let k = ((l.len() - 1) as f64 * 0.99).round() as usize;
    let (_, p99, _) = l.select_nth_unstable_by(k, f64::total_cmp);
    AUTO_TARGET / *p99
}

/// Tone-maps a panel to RGB8.
pub fn tone_map(
    radiance: &[[f32; 3]],
    width_px: u32,
    height_px: u32,
    tm: &ToneMap,
) -> image::RgbImage {
    image::RgbImage::from_fn(width_px, height_px, |x, y| {
        let c = radiance[(y * width_px + x) as usize];
        image::Rgb(c.map(|v| tm.encode(v)))
    })
}

/// Two panels side by side on a dark background, each labelled above (text by plotters, a
/// system sans-serif font).
pub fn compose_side_by_side(
    left: &image::RgbImage,
    right: &image::RgbImage,
    labels: &[String; 2],
) -> Result<image::RgbImage, RenderError> {
    let (w, h) = left.dimensions();
    if right.dimensions() != (w, h) {
        return Err(RenderError::InvalidConfig {
            field: "panels",
            reason: format!(
                "panel sizes differ: {w}x{h} vs {}x{}",
                right.dimensions().0,
                right.dimensions().1
            ),
        });
    }
    let (tw, th) = (2 * w + GAP_PX, h + LABEL_STRIP_PX);
    let mut out = image::RgbImage::from_pixel(tw, th, image::Rgb([24, 24, 24]));
    image::imageops::replace(&mut out, left, 0, i64::from(LABEL_STRIP_PX));
    image::imageops::replace(
        &mut out,
        right,
        i64::from(w + GAP_PX),
        i64::from(LABEL_STRIP_PX),
    );
    let err = |e: String| RenderError::Output {
        path: "<label drawing>".into(),
        problem: e,
    };
    {
        let buf: &mut [u8] = &mut out;
        let root = BitMapBackend::with_buffer(buf, (tw, th)).into_drawing_area();
        let style = ("sans-serif", 18)
            .into_font()
            .color(&RGBColor(235, 235, 235));
        for (k, label) in labels.iter().enumerate() {
            let x0 = (k as u32 * (w + GAP_PX)) as i32;
            root.draw(&Text::new(label.clone(), (x0 + 8, 6), style.clone()))
                .map_err(|e| err(e.to_string()))?;
        }
        root.present().map_err(|e| err(e.to_string()))?;
    }
    Ok(out)
}
