//! Pixel linearization: from stored code values to linear relative radiance.
//!
//! A stored channel value `raw` (integer code for 8/16-bit files, float for OpenEXR) becomes
//!
//! ```text
//! n = (raw - black_level) / (white_level - black_level)      (normalised code)
//! V = curve⁻¹(n)                                            (linear value, 1.0 = white)
//! ```
//!
//! `V` is the *linearized pixel value* `L_pixel` of the method's equation 2: linear in scene
//! radiance, with 1.0 at the white level. A pixel is *saturated* when any channel's `raw` is at or
//! above `saturation_level` (default: the white level for integer files, never for float files).
//! Curves: `linear` (identity), `srgb` (IEC 61966-2-1), `gamma` (`n = V^(1/gamma)`), `table` (a
//! measured camera response: piecewise-linear, strictly increasing `code -> linear` samples,
//! both normalised to `[0, 1]`, as for 8-bit JPEGs). Negative `n` (noise below the black level)
//! stays negative and odd-symmetric so averages remain unbiased.
//!
//! # Camera raw files
//!
//! A raw file (DNG, CR2, NEF, ARW...; recognised by its content, see [`skinbrdf_raw::sniff`])
//! is decoded with `V = (raw - black_c) / (white - black_c)` per CFA position with the file's
//! own levels, in one of two [`RawMode`]s:
//!
//! * **`photosite`** (the default): one pixel per photosite of the active area, at full
//!   resolution ([`skinbrdf_raw::decode_photosites`]). Each pixel holds its own channel (the
//!   colour of its filter) with its own CFA position's levels; its other two channels are NaN,
//!   not interpolated: the derender makes of each photosite a sample of one channel, with the
//!   ray through the photosite's own centre. [`LinearImage::cfa`] names the mosaic, and
//!   [`LinearImage::geometry_grey`] gives target detection a full-resolution image (green,
//!   interpolated at the red and blue photosites). Saturated where the photosite itself is at
//!   or above the white level.
//! * **`superpixel`** (faster, a quarter of the pixels): 2x2 superpixels at half resolution
//!   ([`skinbrdf_raw::decode_superpixel`]): red, the mean of the greens and blue of each quad,
//!   saturated where any photosite of the quad is at or above the white level. Red and blue
//!   were measured half a photosite from the superpixel's centre in x and y.
//!
//! A session states the camera of a raw session in superpixel units (half the active area,
//! what `skinbrdf ingest` writes and [`read_header`] reports); in photosite mode the session
//! converts it to the photosite image as it loads (`f = 2 f'`, `c = 2 c' + 0.5`, size
//! doubled; [`skinbrdf_raw::superpixel_camera_to_sensor`]), so every stage sees the camera of
//! the image as loaded.
//!
//! No session-wide `[linearization]` applies to a raw file. An image's own `linearization` may
//! override its levels: it must have `curve = "linear"`, and it overrides only when it states
//! `white_level` (then `black_level`, default 0, and `white_level` replace the file's levels for
//! every CFA position); `gamma`, `response` and `saturation_level` are errors on a raw file.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::decoded::DecodeCache;
use crate::error::FileError;
use skinbrdf_raw::RawMosaic;

pub use skinbrdf_raw::{BayerPhase, RawLayout};

/// How camera raw files load (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RawMode {
    /// One pixel per photosite, its own channel only, full resolution.
    #[default]
    Photosite,
    /// One RGB pixel per 2x2 quad, half resolution.
    Superpixel,
}

impl RawMode {
    /// Every mode.
    pub const ALL: [Self; 2] = [Self::Photosite, Self::Superpixel];

    /// The decoder's layout.
    pub const fn layout(self) -> RawLayout {
        match self {
            Self::Photosite => RawLayout::Photosite,
            Self::Superpixel => RawLayout::Superpixel,
        }
    }

    /// The name used in files and on the command line (`photosite`, `superpixel`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Photosite => "photosite",
            Self::Superpixel => "superpixel",
        }
    }

    /// The mode of a name, if it is one.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

impl std::fmt::Display for RawMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The tone curve of the stored values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ToneCurve {
    /// Values are linear.
    Linear,
    /// The sRGB transfer function.
    Srgb,
    /// A pure power law, `n = V^(1/gamma)`; needs `gamma`.
    Gamma,
    /// A measured response table; needs `response`.
    Table,
}

impl ToneCurve {
    /// The curve's name as session.toml writes it.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Linear => "linear",
            Self::Srgb => "srgb",
            Self::Gamma => "gamma",
            Self::Table => "table",
        }
    }
}

/// A measured camera response: normalised code values and the linear values they stand for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResponseTable {
    /// Normalised codes in `[0, 1]`, strictly increasing.
    pub code: Vec<f64>,
    /// Linear values in `[0, 1]`, strictly increasing, same length.
    pub linear: Vec<f64>,
}

/// How to turn an image's stored values into linear values (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Linearization {
    /// The tone curve.
    pub curve: ToneCurve,
    /// Exponent for `curve = "gamma"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gamma: Option<f64>,
    /// Table for `curve = "table"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub response: Option<ResponseTable>,
    /// Stored value of black (sensor offset), in stored units.
    #[serde(default)]
    pub black_level: f64,
    /// Stored value of white; default: 255 (8-bit), 65535 (16-bit), 1.0 (float).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub white_level: Option<f64>,
    /// Stored value at or above which a channel is clipped; default: the white level for
    /// integer files, none for float files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturation_level: Option<f64>,
}

impl Default for Linearization {
    fn default() -> Self {
        Self::LINEAR
    }
}

impl Linearization {
    /// Linear values, black 0, white at the file's full scale.
    pub const LINEAR: Self = Self {
        curve: ToneCurve::Linear,
        gamma: None,
        response: None,
        black_level: 0.0,
        white_level: None,
        saturation_level: None,
    };

    /// Checks the invariants; returns every problem as `(field, problem)`.
    pub fn problems(&self) -> Vec<(&'static str, String)> {
        let mut out = Vec::new();
        match self.curve {
            ToneCurve::Gamma => match self.gamma {
                Some(g) if g.is_finite() && g > 0.0 => {}
                Some(g) => out.push(("gamma", format!("must be positive and finite, got {g}"))),
                None => out.push(("gamma", "curve = \"gamma\" needs `gamma`".to_string())),
            },
            ToneCurve::Table => match &self.response {
                Some(t) => {
                    if t.code.len() != t.linear.len() || t.code.len() < 2 {
                        out.push((
                            "response",
                            format!(
                                "`code` and `linear` need the same length (at least 2), got {} and {}",
                                t.code.len(),
                                t.linear.len()
                            ),
                        ));
                    } else {
                        let inc = |v: &[f64]| {
                            v.iter().all(|x| x.is_finite()) && v.windows(2).all(|w| w[1] > w[0])
                        };
                        if !inc(&t.code) {
                            out.push((
                                "response.code",
                                "must be finite and strictly increasing".into(),
                            ));
                        }
                        if !inc(&t.linear) {
                            out.push((
                                "response.linear",
                                "must be finite and strictly increasing".into(),
                            ));
                        }
                    }
                }
                None => out.push(("response", "curve = \"table\" needs `response`".to_string())),
            },
            ToneCurve::Linear | ToneCurve::Srgb => {}
        }
        if self.curve != ToneCurve::Gamma && self.gamma.is_some() {
            out.push(("gamma", "only meaningful with curve = \"gamma\"".into()));
        }
        if !self.black_level.is_finite() || self.black_level < 0.0 {
            out.push((
                "black_level",
                format!("must be finite and >= 0, got {}", self.black_level),
            ));
        }
        if let Some(w) = self.white_level {
            if !w.is_finite() || w <= self.black_level {
                out.push((
                    "white_level",
                    format!(
                        "must be finite and above black_level ({}), got {w}",
                        self.black_level
                    ),
                ));
            }
        }
        if let Some(s) = self.saturation_level {
            if s.is_nan() || s <= self.black_level {
                out.push((
                    "saturation_level",
                    format!("must be above black_level ({}), got {s}", self.black_level),
                ));
            }
        }
        out
    }

    /// Problems specific to a stored pixel format (levels beyond the full scale).
    pub fn problems_for(&self, format: StoredFormat) -> Vec<(&'static str, String)> {
        let mut out = Vec::new();
        if let Some(max) = format.max_code() {
            for (field, v) in [
                ("black_level", Some(self.black_level)),
                ("white_level", self.white_level),
            ] {
                if let Some(v) = v {
                    if v > max {
                        out.push((
                            field,
                            format!("{v} exceeds the {} full scale {max}", format.describe()),
                        ));
                    }
                }
            }
        }
        out
    }

    /// The white level for a stored format.
    pub fn white_for(&self, format: StoredFormat) -> f64 {
        self.white_level.unwrap_or(format.max_code().unwrap_or(1.0))
    }

    /// The saturation level for a stored format (`+inf` = never saturates).
    pub fn saturation_for(&self, format: StoredFormat) -> f64 {
        self.saturation_level.unwrap_or(match format.max_code() {
            Some(_) => self.white_for(format),
            None => f64::INFINITY,
        })
    }

    /// Normalised code `n` to linear value `V` (odd-symmetric for negative `n`).
    pub fn curve_to_linear(&self, n: f64) -> f64 {
        let s = n.signum();
        let a = n.abs();
        s * match self.curve {
            ToneCurve::Linear => a,
            ToneCurve::Srgb => {
                if a <= 0.04045 {
                    a / 12.92
                } else {
                    ((a + 0.055) / 1.055).powf(2.4)
                }
            }
            ToneCurve::Gamma => a.powf(self.gamma.unwrap_or(1.0)),
            ToneCurve::Table => match &self.response {
                Some(t) => interp(&t.code, &t.linear, a),
                None => a,
            },
        }
    }

    /// Linear value `V` to normalised code `n` (inverse of [`Self::curve_to_linear`]).
    pub fn linear_to_curve(&self, v: f64) -> f64 {
        let s = v.signum();
        let a = v.abs();
        s * match self.curve {
            ToneCurve::Linear => a,
            ToneCurve::Srgb => {
                if a <= 0.0031308 {
                    a * 12.92
                } else {
                    1.055 * a.powf(1.0 / 2.4) - 0.055
                }
            }
            ToneCurve::Gamma => a.powf(1.0 / self.gamma.unwrap_or(1.0)),
            ToneCurve::Table => match &self.response {
                Some(t) => interp(&t.linear, &t.code, a),
                None => a,
            },
        }
    }

    /// Stored value to linear value for a stored format.
    pub fn decode(&self, raw: f64, format: StoredFormat) -> f64 {
        let white = self.white_for(format);
        self.curve_to_linear((raw - self.black_level) / (white - self.black_level))
    }

    /// Linear value to stored value (unquantised, unclipped) for a stored format.
    pub fn encode(&self, v: f64, format: StoredFormat) -> f64 {
        let white = self.white_for(format);
        self.black_level + (white - self.black_level) * self.linear_to_curve(v)
    }
}

/// Piecewise-linear interpolation on strictly increasing `xs`, extrapolating linearly from the
/// end segments.
fn interp(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let n = xs.len();
    if n < 2 {
        return x;
    }
    let i = match xs.iter().position(|&v| v > x) {
        Some(0) => 1,
        Some(i) => i,
        None => n - 1,
    };
    let (x0, x1, y0, y1) = (xs[i - 1], xs[i], ys[i - 1], ys[i]);
    y0 + (y1 - y0) * (x - x0) / (x1 - x0)
}

/// The stored sample type of an image file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoredFormat {
    /// 8-bit integer codes.
    U8,
    /// 16-bit integer codes.
    U16,
    /// 32-bit float values (OpenEXR).
    F32,
    /// Camera raw photosites of this many bits.
    Raw {
        /// Bits per stored sample.
        bits: u32,
    },
}

/// An image pixel layout in words ("8-bit grey", "16-bit RGBA", ...).
fn color_type_in_words(color: image::ColorType) -> String {
    let channels = match color.channel_count() {
        1 => "grey",
        2 => "grey with alpha",
        3 => "RGB",
        4 => "RGBA",
        _ => "multi-channel",
    };
    let bits = color.bits_per_pixel() / u16::from(color.channel_count().max(1));
    format!("{bits}-bit {channels}")
}

impl StoredFormat {
    /// Full-scale code for integer formats.
    pub const fn max_code(self) -> Option<f64> {
        match self {
            Self::U8 => Some(255.0),
            Self::U16 => Some(65535.0),
            Self::F32 => None,
            Self::Raw { bits } => Some(((1u64 << if bits < 32 { bits } else { 32 }) - 1) as f64),
        }
    }
}

impl StoredFormat {
    /// "8-bit", "16-bit", "32-bit float" or "camera raw".
    pub const fn describe(self) -> &'static str {
        match self {
            Self::U8 => "8-bit",
            Self::U16 => "16-bit",
            Self::F32 => "32-bit float",
            Self::Raw { .. } => "camera raw",
        }
    }

    fn of(color: image::ColorType) -> Option<Self> {
        match color.bytes_per_pixel() / color.channel_count().max(1) {
            1 => Some(Self::U8),
            2 => Some(Self::U16),
            4 => Some(Self::F32),
            _ => None,
        }
    }
}

/// What an image file's header says: its size and stored sample type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageHeader {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The stored sample type.
    pub format: StoredFormat,
}

/// The file's kind when its content is a camera raw file (its name checked against it), else
/// `None` (other images are read by the `image` crate, which reports their problems). A non-raw
/// file named like a raw file is an error naming the file.
pub fn raw_kind(path: &Path) -> Result<Option<skinbrdf_raw::FileKind>, FileError> {
    match skinbrdf_raw::sniff(path) {
        Ok(kind) => {
            skinbrdf_raw::check_extension(path, kind)?;
            Ok(kind.is_raw().then_some(kind))
        }
        Err(skinbrdf_raw::RawError::UnrecognisedContent { .. }) => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// The level overrides a raw file takes from a linearization (see the module docs), or the
/// `(field, problem)` that forbids it.
pub fn raw_options(
    lin: &Linearization,
) -> Result<skinbrdf_raw::RawOptions, (&'static str, String)> {
    if lin.curve != ToneCurve::Linear {
        return Err((
            "curve",
            format!(
                "curve = \"{}\" on a camera raw file: raw values are linear, only curve = \"linear\" applies",
                lin.curve.name()
            ),
        ));
    }
    if lin.response.is_some() {
        return Err(("response", "not meaningful for a camera raw file".into()));
    }
    if lin.saturation_level.is_some() {
        return Err((
            "saturation_level",
            "not used for a camera raw file: a quad is saturated at the white level".into(),
        ));
    }
    match lin.white_level {
        Some(w) => Ok(skinbrdf_raw::RawOptions {
            black_levels: Some([lin.black_level; 4]),
            white_level: Some(w),
        }),
        None if lin.black_level != 0.0 => Err((
            "black_level",
            "overrides a camera raw file's levels only together with `white_level`".into(),
        )),
        None => Ok(skinbrdf_raw::RawOptions::default()),
    }
}

/// Reads an image file's header only (no pixel data; a raw file's size is its superpixel
/// size, the unit a session states a raw camera in: see the module docs).
pub fn read_header(path: &Path) -> Result<ImageHeader, FileError> {
    use image::ImageDecoder;
    if raw_kind(path)?.is_some() {
        let hd = skinbrdf_raw::read_raw_header(path)?;
        return Ok(ImageHeader {
            width: hd.width_px,
            height: hd.height_px,
            format: StoredFormat::Raw {
                bits: hd.bits_per_sample,
            },
        });
    }
    let img_err = |source| FileError::Image {
        path: path.to_path_buf(),
        source,
    };
    let decoder = image::ImageReader::open(path)
        .map_err(|source| FileError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .with_guessed_format()
        .map_err(|source| FileError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .into_decoder()
        .map_err(img_err)?;
    let (width, height) = decoder.dimensions();
    let color = decoder.color_type();
    let format = StoredFormat::of(color).ok_or_else(|| FileError::Invalid {
        path: path.to_path_buf(),
        field: "pixel format".into(),
        problem: format!("unsupported pixel layout ({})", color_type_in_words(color)),
    })?;
    Ok(ImageHeader {
        width,
        height,
        format,
    })
}

/// A linearized RGB image (row-major, top row first).
#[derive(Debug, Clone, PartialEq)]
pub struct LinearImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear values `V` per pixel (1.0 = white level); NaN in a channel a photosite image
    /// did not measure there.
    pub rgb: Vec<[f32; 3]>,
    /// True where any measured channel is at or above the saturation level.
    pub saturated: Vec<bool>,
    /// The stored format the values came from.
    pub format: StoredFormat,
    /// A camera raw file loaded per photosite: its Bayer phase at pixel `(0, 0)`; pixel
    /// `(x, y)` measures the channel `cfa.colour_at(x, y)` only. `None`: every pixel measures
    /// all three channels.
    pub cfa: Option<BayerPhase>,
}

impl LinearImage {
    /// The channels pixel `(x, y)` measured: all three, or a photosite's own.
    pub fn measured_channels(&self, x: u32, y: u32) -> [bool; 3] {
        measured_channels(self.cfa, x, y)
    }

    /// A full-resolution single-channel image for geometry (target detection): the mean of
    /// the channels of an RGB image; for a photosite image the green channel, measured at the
    /// green photosites and at a red or blue photosite the mean of its green neighbours (its
    /// four edge neighbours inside the image), so that every pixel keeps its own place.
    pub fn geometry_grey(&self) -> Vec<f32> {
        let Some(phase) = self.cfa else {
            return self
                .rgb
                .iter()
                .map(|p| (p[0] + p[1] + p[2]) / 3.0)
                .collect();
        };
        let w = self.width as usize;
        let mut out: Vec<f32> = self.rgb.iter().map(|p| p[GREEN]).collect();
        let is_green = |x: usize, y: usize| usize::from(phase.colour_at(x, y).dng_code()) == GREEN;
        fill_green_at_red_and_blue(&mut out, w, self.height as usize, is_green);
        out
    }

    /// The pixel at column `x`, row `y`.
    pub fn get(&self, x: u32, y: u32) -> Option<[f32; 3]> {
        (x < self.width && y < self.height).then(|| self.rgb[(y * self.width + x) as usize])
    }

    /// Whether the pixel at column `x`, row `y` is saturated.
    pub fn is_saturated(&self, x: u32, y: u32) -> bool {
        x < self.width && y < self.height && self.saturated[(y * self.width + x) as usize]
    }
}

/// The channels a pixel `(x, y)` of an image with mosaic `cfa` measured (see
/// [`LinearImage::cfa`]).
pub fn measured_channels(cfa: Option<BayerPhase>, x: u32, y: u32) -> [bool; 3] {
    match cfa {
        None => [true; 3],
        Some(phase) => {
            let c = usize::from(phase.colour_at(x as usize, y as usize).dng_code());
            std::array::from_fn(|k| k == c)
        }
    }
}

/// Decodes a camera raw file in `mode` with the level overrides of `lin` (see the module
/// docs).
pub fn load_raw_image(
    path: &Path,
    lin: &Linearization,
    mode: RawMode,
) -> Result<LinearImage, FileError> {
    let opts = raw_options(lin).map_err(|(field, problem)| FileError::Invalid {
        path: path.to_path_buf(),
        field: format!("linearization.{field}"),
        problem,
    })?;
    let f = skinbrdf_raw::decode_raw(path, &opts, mode.layout())?;
    Ok(LinearImage {
        width: f.width_px,
        height: f.height_px,
        rgb: f.rgb,
        saturated: f.saturated,
        format: StoredFormat::Raw {
            bits: f.bits_per_sample,
        },
        cfa: (mode == RawMode::Photosite).then_some(f.cfa),
    })
}

/// Decodes a camera raw file to its compact mosaic with the level overrides of `lin` (see the
/// module docs), through `cache` when given (read back when it holds the file).
pub fn load_raw_mosaic(
    path: &Path,
    lin: &Linearization,
    cache: Option<&DecodeCache>,
) -> Result<RawMosaic, FileError> {
    let opts = raw_options(lin).map_err(|(field, problem)| FileError::Invalid {
        path: path.to_path_buf(),
        field: format!("linearization.{field}"),
        problem,
    })?;
    Ok(match cache {
        Some(c) => c.mosaic(path, &opts)?,
        None => skinbrdf_raw::decode_mosaic(path, &opts)?,
    })
}

impl LinearImage {
    /// The image a raw file whose mosaic is `m` loads as in `mode`: what [`load_raw_image`]
    /// gives for the file, value for value.
    pub fn from_mosaic(m: &RawMosaic, mode: RawMode) -> Self {
        let f = m.frame(mode.layout());
        Self {
            width: f.width_px,
            height: f.height_px,
            rgb: f.rgb,
            saturated: f.saturated,
            format: StoredFormat::Raw {
                bits: f.bits_per_sample,
            },
            cfa: (mode == RawMode::Photosite).then_some(f.cfa),
        }
    }
}

/// [`LinearImage::geometry_grey`] of the photosite image of mosaic `m`, its values multiplied
/// by `scale` when given (an image's `exposure_scale`), computed from the mosaic without the
/// RGB image (a quarter of its memory): the same values, bit for bit.
pub fn photosite_geometry_grey(m: &RawMosaic, scale: Option<f32>) -> Vec<f32> {
    let (w, h) = (m.width_px as usize, m.height_px as usize);
    let mut out = vec![0.0f32; w * h];
    for (y, row) in out.chunks_exact_mut(w.max(1)).enumerate().take(h) {
        m.photosite_row(y, row);
        if let Some(k) = scale {
            row.iter_mut().for_each(|v| *v *= k);
        }
    }
    fill_green_at_red_and_blue(&mut out, w, h, |x, y| m.channel_at(x, y) == GREEN);
    out
}

/// The green channel's index in an RGB pixel and a photosite's channel.
const GREEN: usize = 1;

/// The green channel of a Bayer mosaic `w` x `h`, row-major in `grey` (its green photosites'
/// values; the others are overwritten): each red or blue photosite gets the mean of its edge
/// neighbours inside the image, which are green in a Bayer mosaic and so never overwritten here.
fn fill_green_at_red_and_blue(
    grey: &mut [f32],
    w: usize,
    h: usize,
    is_green: impl Fn(usize, usize) -> bool,
) {
    for y in 0..h {
        for x in 0..w {
            if is_green(x, y) {
                continue;
            }
            let mut sum = 0.0f32;
            let mut n = 0u8;
            let mut add = |xx: usize, yy: usize| {
                sum += grey[yy * w + xx];
                n += 1;
            };
            if x > 0 {
                add(x - 1, y);
            }
            if x + 1 < w {
                add(x + 1, y);
            }
            if y > 0 {
                add(x, y - 1);
            }
            if y + 1 < h {
                add(x, y + 1);
            }
            grey[y * w + x] = if n > 0 { sum / f32::from(n) } else { f32::NAN };
        }
    }
}

/// Reads an image and linearizes it: camera raw files (by content) with [`load_raw_image`] in
/// `raw_mode`, others (PNG, TIFF, JPEG, OpenEXR; grey or RGB, alpha ignored) with `lin`.
pub fn load_linear_image(
    path: &Path,
    lin: &Linearization,
    raw_mode: RawMode,
) -> Result<LinearImage, FileError> {
    if raw_kind(path)?.is_some() {
        return load_raw_image(path, lin, raw_mode);
    }
    let img = image::open(path).map_err(|source| FileError::Image {
        path: path.to_path_buf(),
        source,
    })?;
    let (width, height) = (img.width(), img.height());
    let color = img.color();
    let Some(format) = StoredFormat::of(color) else {
        return Err(FileError::Invalid {
            path: path.to_path_buf(),
            field: "pixel format".into(),
            problem: format!("unsupported pixel layout ({})", color_type_in_words(color)),
        });
    };
    let raw: Vec<[f32; 3]> = match format {
        StoredFormat::U8 => img.to_rgb8().pixels().map(|p| p.0.map(f32::from)).collect(),
        StoredFormat::U16 => img
            .to_rgb16()
            .pixels()
            .map(|p| p.0.map(f32::from))
            .collect(),
        // `of` never gives `Raw` (raw files are decoded above).
        StoredFormat::F32 | StoredFormat::Raw { .. } => {
            img.to_rgb32f().pixels().map(|p| p.0).collect()
        }
    };
    if let Some((field, problem)) = lin
        .problems()
        .into_iter()
        .chain(lin.problems_for(format))
        .next()
    {
        return Err(FileError::Invalid {
            path: path.to_path_buf(),
            field: format!("linearization.{field}"),
            problem,
        });
    }
    let sat = lin.saturation_for(format) as f32;
    let saturated = raw.iter().map(|p| p.iter().any(|&c| c >= sat)).collect();
    let rgb = raw
        .iter()
        .map(|p| p.map(|c| lin.decode(f64::from(c), format) as f32))
        .collect();
    Ok(LinearImage {
        width,
        height,
        rgb,
        saturated,
        format,
        cfa: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn curves() -> Vec<Linearization> {
        vec![
            Linearization::LINEAR,
            Linearization {
                curve: ToneCurve::Srgb,
                ..Linearization::LINEAR
            },
            Linearization {
                curve: ToneCurve::Gamma,
                gamma: Some(2.2),
                black_level: 512.0,
                white_level: Some(60000.0),
                ..Linearization::LINEAR
            },
            Linearization {
                curve: ToneCurve::Table,
                response: Some(ResponseTable {
                    code: vec![0.0, 0.3, 0.7, 1.0],
                    linear: vec![0.0, 0.05, 0.4, 1.0],
                }),
                ..Linearization::LINEAR
            },
        ]
    }

    proptest! {
        #[test]
        fn encode_decode_round_trip(v in -0.05..1.2f64) {
            for lin in curves() {
                prop_assert!(lin.problems().is_empty());
                let raw = lin.encode(v, StoredFormat::U16);
                let back = lin.decode(raw, StoredFormat::U16);
                prop_assert!((back - v).abs() < 1e-9, "{:?}: {} -> {} -> {}", lin.curve, v, raw, back);
            }
        }
    }

    #[test]
    fn srgb_matches_the_standard_at_mid_grey() {
        let lin = Linearization {
            curve: ToneCurve::Srgb,
            ..Linearization::LINEAR
        };
        // sRGB code 0.5 is linear 0.2140 (IEC 61966-2-1).
        assert!((lin.curve_to_linear(0.5) - 0.21404).abs() < 1e-4);
    }

    #[test]
    fn problems_are_all_reported() {
        let lin = Linearization {
            curve: ToneCurve::Gamma,
            gamma: None,
            black_level: -1.0,
            white_level: Some(f64::NAN),
            ..Linearization::LINEAR
        };
        let p = lin.problems();
        let fields: Vec<_> = p.iter().map(|(f, _)| *f).collect();
        assert_eq!(fields, ["gamma", "black_level", "white_level"], "{p:?}");
    }
}
