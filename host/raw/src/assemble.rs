//! A whole-sensor mosaic's active area to a [`RawFrame`]: black subtraction and scaling to the
//! white level per CFA position, as superpixels or photosites (shared by the rawler and the
//! LibRaw paths); or to a [`RawMosaic`], the active area's stored values with the levels.

use std::path::Path;

use crate::bayer::BayerPhase;
use crate::error::RawError;
use crate::frame::{RawFrame, RawLayout};
use crate::kind::FileKind;
use crate::mosaic::{MosaicSamples, RawMosaic};

/// Where the active area is and which Bayer phase starts it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Geometry {
    pub left: usize,
    pub top: usize,
    pub aw: usize,
    pub ah: usize,
    pub phase: BayerPhase,
}

/// The levels of a decode: per CFA position of a 2x2 quad, its black level and the scale to
/// the white level; and where red, the two greens and blue sit in the quad.
pub(crate) struct QuadLevels {
    black: [f64; 4],
    scale: [f64; 4],
    white: f64,
    positions: [usize; 4],
    /// The channel (0 red, 1 green, 2 blue) of each quad position, reading order.
    channels: [usize; 4],
}

impl QuadLevels {
    pub(crate) fn new(black: [f64; 4], white: f64, phase: BayerPhase) -> Self {
        Self {
            black,
            scale: black.map(|b| 1.0 / (white - b)),
            white,
            positions: phase.positions(),
            channels: phase.quad().map(|c| usize::from(c.dng_code())),
        }
    }

    /// The normalised value of a stored value `raw` at quad position `k` (reading order), as
    /// every layout computes it.
    #[inline]
    pub(crate) fn value(&self, k: usize, raw: f64) -> f32 {
        ((raw - self.black[k]) * self.scale[k]) as f32
    }

    /// Whether a stored value is at or above the white level.
    #[inline]
    pub(crate) fn saturates(&self, raw: f64) -> bool {
        raw >= self.white
    }

    /// One RGB pixel per 2x2 quad of the active area (`w` x `h` quads from column `left`,
    /// row `top` of a sensor `sw` samples wide): red, the mean of the greens and blue, each
    /// black-subtracted and scaled to the white level; saturated where any sample reaches it.
    /// Generic over the sample type so that the inner loop is monomorphic.
    fn superpixels<T: Copy + Into<f64>>(
        &self,
        data: &[T],
        sw: usize,
        left: usize,
        top: usize,
        w: usize,
        h: usize,
    ) -> (Vec<[f32; 3]>, Vec<bool>) {
        let mut rgb = Vec::with_capacity(w * h);
        let mut saturated = Vec::with_capacity(w * h);
        let [pr, pg1, pg2, pb] = self.positions;
        for v in 0..h {
            let y = top + 2 * v;
            let row0 = &data[y * sw + left..y * sw + left + 2 * w];
            let row1 = &data[(y + 1) * sw + left..(y + 1) * sw + left + 2 * w];
            for (a, b) in row0.chunks_exact(2).zip(row1.chunks_exact(2)) {
                let q: [f64; 4] = [a[0].into(), a[1].into(), b[0].into(), b[1].into()];
                let n = |k: usize| (q[k] - self.black[k]) * self.scale[k];
                rgb.push([n(pr) as f32, (0.5 * (n(pg1) + n(pg2))) as f32, n(pb) as f32]);
                saturated.push(q.iter().any(|&r| r >= self.white));
            }
        }
        (rgb, saturated)
    }

    /// One pixel per photosite of the active area's `2w` x `2h` photosites from column
    /// `left`, row `top`: its own channel black-subtracted and scaled to the white level, the
    /// other two NaN (not measured there); saturated where its own value reaches the white
    /// level.
    fn photosites<T: Copy + Into<f64>>(
        &self,
        data: &[T],
        sw: usize,
        left: usize,
        top: usize,
        w: usize,
        h: usize,
    ) -> (Vec<[f32; 3]>, Vec<bool>) {
        let (pw, ph) = (2 * w, 2 * h);
        let mut rgb = Vec::with_capacity(pw * ph);
        let mut saturated = Vec::with_capacity(pw * ph);
        for y in 0..ph {
            let row = &data[(top + y) * sw + left..(top + y) * sw + left + pw];
            for (x, &raw) in row.iter().enumerate() {
                let k = (y % 2) * 2 + x % 2;
                let raw: f64 = raw.into();
                let mut px = [f32::NAN; 3];
                px[self.channels[k]] = self.value(k, raw);
                rgb.push(px);
                saturated.push(self.saturates(raw));
            }
        }
        (rgb, saturated)
    }
}

/// Refuses levels that leave no range (white at or below a black level) or are not finite.
pub(crate) fn check_levels(
    path: &Path,
    black_levels: [f64; 4],
    white_level: f64,
) -> Result<(), RawError> {
    for (k, &b) in black_levels.iter().enumerate() {
        if !b.is_finite() || !white_level.is_finite() || white_level <= b {
            return Err(RawError::BadLevels {
                path: path.to_path_buf(),
                problem: format!(
                    "white level {white_level} is not above the black level {b} of CFA position {k}"
                ),
            });
        }
    }
    Ok(())
}

/// The sensor a mosaic was read from.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sensor {
    pub kind: FileKind,
    /// Photosites per row of the mosaic.
    pub width: usize,
    /// Rows of the mosaic.
    pub height: usize,
    pub bits_per_sample: usize,
}

/// The frame of a whole-sensor mosaic (`sensor.width * sensor.height` values, checked by the
/// caller), its active area `g` normalised with the given levels.
pub(crate) fn assemble<T: Copy + Into<f64>>(
    data: &[T],
    sensor: &Sensor,
    g: &Geometry,
    black_levels: [f64; 4],
    white_level: f64,
    layout: RawLayout,
) -> RawFrame {
    let (w, h) = (g.aw / 2, g.ah / 2);
    let levels = QuadLevels::new(black_levels, white_level, g.phase);
    let (left, top) = (g.left, g.top);
    let sw = sensor.width;
    let (rgb, saturated) = match layout {
        RawLayout::Superpixel => levels.superpixels(data, sw, left, top, w, h),
        RawLayout::Photosite => levels.photosites(data, sw, left, top, w, h),
    };
    let to_u32 = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
    let (width_px, height_px) = match layout {
        RawLayout::Superpixel => (w, h),
        RawLayout::Photosite => (2 * w, 2 * h),
    };
    RawFrame {
        kind: sensor.kind,
        layout,
        width_px: to_u32(width_px),
        height_px: to_u32(height_px),
        rgb,
        saturated,
        cfa: g.phase,
        black_levels,
        white_level,
        bits_per_sample: to_u32(sensor.bits_per_sample),
        sensor_width_px: to_u32(sw),
        sensor_height_px: to_u32(sensor.height),
        active_left_px: to_u32(left),
        active_top_px: to_u32(top),
    }
}

/// The mosaic of a whole-sensor decode (`sensor.width * sensor.height` values, checked by the
/// caller): its active area `g`, cropped to an even size, with the levels it is normalised with.
pub(crate) fn crop<T: Copy>(
    data: &[T],
    sensor: &Sensor,
    g: &Geometry,
    black_levels: [f64; 4],
    white_level: f64,
    wrap: impl FnOnce(Vec<T>) -> MosaicSamples,
) -> RawMosaic {
    let (pw, ph) = (g.aw / 2 * 2, g.ah / 2 * 2);
    let sw = sensor.width;
    let mut values = Vec::with_capacity(pw * ph);
    for y in g.top..g.top + ph {
        values.extend_from_slice(&data[y * sw + g.left..y * sw + g.left + pw]);
    }
    let to_u32 = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
    RawMosaic {
        kind: sensor.kind,
        width_px: to_u32(pw),
        height_px: to_u32(ph),
        samples: wrap(values),
        cfa: g.phase,
        black_levels,
        white_level,
        bits_per_sample: to_u32(sensor.bits_per_sample),
        sensor_width_px: to_u32(sw),
        sensor_height_px: to_u32(sensor.height),
        active_left_px: to_u32(g.left),
        active_top_px: to_u32(g.top),
    }
}
