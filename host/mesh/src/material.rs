//! A scan's materials and their textures: [`Material`] (an OBJ's MTL entry, a glTF
//! material) and [`TextureImage`] with its bilinear lookup (conventions in
//! [`crate::textured`]).

use std::io::BufReader;
use std::path::{Path, PathBuf};

use glam::Vec2;
use skinbrdf_core::untrusted;

use crate::error::MeshError;
use crate::limits::MAX_TEXTURE_TEXELS;

/// Colour of a surface with no appearance (no texture, no vertex colours): a mid grey.
pub const UNTEXTURED_COLOUR: [f32; 3] = [0.5, 0.5, 0.5];

/// Refuses a texture of more than [`MAX_TEXTURE_TEXELS`], in words.
fn texels_within_limit(width: u32, height: u32) -> Result<(), String> {
    let texels = u64::from(width) * u64::from(height);
    if texels > MAX_TEXTURE_TEXELS {
        return Err(format!(
            "{width} x {height} texels, more than the {MAX_TEXTURE_TEXELS} a texture may have"
        ));
    }
    Ok(())
}

/// An RGB texture, row-major from the top row, values 0..1 as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureImage {
    /// Width, texels.
    pub width: u32,
    /// Height, texels.
    pub height: u32,
    /// Texels, row-major from the top.
    pub rgb: Vec<[f32; 3]>,
}

impl TextureImage {
    /// Loads a PNG or JPEG (any pixel type; alpha is dropped): a regular file within
    /// [`untrusted::TEXTURE_FILE`], decoded under the `image` crate's default memory limit.
    pub fn load(path: &Path) -> Result<Self, MeshError> {
        let bytes = untrusted::read_bounded(path, untrusted::TEXTURE_FILE)?;
        Self::decode(&bytes).map_err(|reason| MeshError::Texture {
            path: path.to_path_buf(),
            reason,
        })
    }

    /// Checks that a texture file is an image the loader decodes, by its header (format and
    /// size; the pixels are not decoded). Returns its width and height.
    pub fn check_header(path: &Path) -> Result<(u32, u32), MeshError> {
        let (file, _) = untrusted::open_regular(path)?;
        let bad = |reason: String| MeshError::Texture {
            path: path.to_path_buf(),
            reason,
        };
        let (w, h) = image::ImageReader::new(BufReader::new(file))
            .with_guessed_format()
            .map_err(|e| bad(e.to_string()))?
            .into_dimensions()
            .map_err(|e| bad(format!("not a PNG or JPEG image: {e}")))?;
        if w == 0 || h == 0 {
            return Err(bad("the image is empty".into()));
        }
        texels_within_limit(w, h).map_err(bad)?;
        Ok((w, h))
    }

    /// Decodes an encoded PNG or JPEG held in memory (a glTF's embedded image) exactly as
    /// [`Self::load`] decodes a file; the error is the decoder's complaint.
    pub fn decode(bytes: &[u8]) -> Result<Self, String> {
        // The size from the header first: a small file may state a huge image.
        let (w, h) = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())?
            .into_dimensions()
            .map_err(|e| e.to_string())?;
        texels_within_limit(w, h)?;
        let img = image::load_from_memory(bytes).map_err(|e| e.to_string())?;
        Self::from_image(&img)
    }

    fn from_image(img: &image::DynamicImage) -> Result<Self, String> {
        let (width, height) = (img.width(), img.height());
        if width == 0 || height == 0 {
            return Err("the image is empty".into());
        }
        texels_within_limit(width, height)?;
        // Converted in bands of rows, so the texels as floats are held once, not twice.
        const BAND_ROWS: u32 = 64;
        let mut rgb = Vec::with_capacity(width as usize * height as usize);
        let mut y = 0;
        while y < height {
            let rows = BAND_ROWS.min(height - y);
            let band = img.crop_imm(0, y, width, rows).to_rgb32f();
            rgb.extend(band.pixels().map(|p| p.0));
            y += rows;
        }
        Ok(Self { width, height, rgb })
    }

    /// Bilinear lookup at an OBJ texture coordinate (`v = 0` at the bottom, repeating outside
    /// `[0, 1]`; see the module docs). A non-finite coordinate gives texel `(0, 0)`.
    pub fn bilinear(&self, uv: Vec2) -> [f32; 3] {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = f64::from(uv.x) * w as f64 - 0.5;
        let y = (1.0 - f64::from(uv.y)) * h as f64 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return self.rgb[0];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let at = |i: i64, j: i64| self.rgb[(j.rem_euclid(h) * w + i.rem_euclid(w)) as usize];
        let (a, b, c, d) = (
            at(x0, y0),
            at(x0 + 1, y0),
            at(x0, y0 + 1),
            at(x0 + 1, y0 + 1),
        );
        std::array::from_fn(|k| {
            (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy
        })
    }
}

/// One material: its flat colour and optional texture (an OBJ's MTL entry, a glTF material).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Name (`newmtl`; glTF: `name`, else `material N`).
    pub name: String,
    /// `Kd`, or [`UNTEXTURED_COLOUR`] when absent (glTF: `baseColorFactor`, sRGB-encoded).
    pub diffuse: [f32; 3],
    /// The `map_Kd` image (glTF: the base-colour texture, `baseColorFactor` multiplied in).
    pub texture: Option<TextureImage>,
    /// Where the texture was read from (`None` for an image embedded in a glTF).
    pub texture_path: Option<PathBuf>,
}
