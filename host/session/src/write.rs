//! Atomic writers: every file is written to a temporary file in the same directory, flushed,
//! then renamed over the destination, so readers never see a half-written file.

use std::path::Path;

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use serde::Serialize;

use crate::error::FileError;

/// Writes `bytes` to `path` atomically (temp file in the same directory + rename). Creates the
/// parent directory if needed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    skinbrdf_core::fsio::write_atomic(path, bytes).map_err(|e| FileError::Io {
        path: e.path,
        source: e.source,
    })
}

/// Writes a value as pretty JSON, atomically, through the checked writer
/// ([`skinbrdf_core::json`]): a NaN or infinity is refused with its field's path, and nothing is
/// written.
pub fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), FileError> {
    let bytes = skinbrdf_core::json::to_vec_pretty(path, value)?;
    write_atomic(path, &bytes)
}

/// Writes a value as TOML, atomically.
pub fn write_toml_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), FileError> {
    let text = toml::to_string_pretty(value).map_err(|e| FileError::Invalid {
        path: path.to_path_buf(),
        field: String::new(),
        problem: format!("cannot serialise to TOML: {e}"),
    })?;
    write_atomic(path, text.as_bytes())
}

fn png_bytes(
    path: &Path,
    width: u32,
    height: u32,
    data: &[u8],
    color: ExtendedColorType,
) -> Result<Vec<u8>, FileError> {
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Adaptive)
        .write_image(data, width, height, color)
        .map_err(|source| FileError::Image {
            path: path.to_path_buf(),
            source,
        })?;
    Ok(out)
}

fn check_len(path: &Path, got: usize, want: usize) -> Result<(), FileError> {
    if got == want {
        Ok(())
    } else {
        Err(FileError::Invalid {
            path: path.to_path_buf(),
            field: "pixels".into(),
            problem: format!("expected {want} values, got {got}"),
        })
    }
}

/// Writes a 16-bit RGB PNG (row-major RGB triples), atomically.
pub fn write_png_rgb16(path: &Path, width: u32, height: u32, rgb: &[u16]) -> Result<(), FileError> {
    check_len(path, rgb.len(), 3 * width as usize * height as usize)?;
    // PNG stores 16-bit samples big-endian; the encoder takes native-endian bytes of u16.
    let bytes: Vec<u8> = rgb.iter().flat_map(|v| v.to_ne_bytes()).collect();
    let png = png_bytes(path, width, height, &bytes, ExtendedColorType::Rgb16)?;
    write_atomic(path, &png)
}

/// Writes an 8-bit RGB PNG, atomically.
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), FileError> {
    check_len(path, rgb.len(), 3 * width as usize * height as usize)?;
    let png = png_bytes(path, width, height, rgb, ExtendedColorType::Rgb8)?;
    write_atomic(path, &png)
}

/// Writes a mask as an 8-bit grey PNG (255 = in, 0 = out), atomically.
pub fn write_mask_png(
    path: &Path,
    width: u32,
    height: u32,
    mask: &[bool],
) -> Result<(), FileError> {
    check_len(path, mask.len(), width as usize * height as usize)?;
    let bytes: Vec<u8> = mask.iter().map(|&m| if m { 255 } else { 0 }).collect();
    let png = png_bytes(path, width, height, &bytes, ExtendedColorType::L8)?;
    write_atomic(path, &png)
}

/// Writes a float RGB OpenEXR image, atomically.
pub fn write_exr_rgb32f(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[f32],
) -> Result<(), FileError> {
    check_len(path, rgb.len(), 3 * width as usize * height as usize)?;
    let buf = image::Rgb32FImage::from_raw(width, height, rgb.to_vec()).ok_or_else(|| {
        FileError::Invalid {
            path: path.to_path_buf(),
            field: "pixels".into(),
            problem: "buffer does not match the size".into(),
        }
    })?;
    let mut out = std::io::Cursor::new(Vec::new());
    image::DynamicImage::ImageRgb32F(buf)
        .write_to(&mut out, image::ImageFormat::OpenExr)
        .map_err(|source| FileError::Image {
            path: path.to_path_buf(),
            source,
        })?;
    write_atomic(path, out.get_ref())
}

/// A binary mask (row-major).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mask {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// True = in the mask.
    pub data: Vec<bool>,
}

impl Mask {
    /// Whether the pixel at column `x`, row `y` is in the mask (false outside the image).
    pub fn get(&self, x: u32, y: u32) -> bool {
        x < self.width && y < self.height && self.data[(y * self.width + x) as usize]
    }

    /// Number of pixels in the mask.
    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&b| b).count()
    }
}

/// Reads a mask image (any format; non-zero grey = in).
pub fn load_mask(path: &Path) -> Result<Mask, FileError> {
    let img = image::open(path).map_err(|source| FileError::Image {
        path: path.to_path_buf(),
        source,
    })?;
    let g = img.to_luma8();
    Ok(Mask {
        width: g.width(),
        height: g.height(),
        data: g.pixels().map(|p| p.0[0] > 0).collect(),
    })
}

/// `target` as a path relative to `base` when they share a root (else `target` absolute).
pub fn relative_path(target: &Path, base: &Path) -> std::path::PathBuf {
    let (Ok(t), Ok(b)) = (std::fs::canonicalize(target), std::fs::canonicalize(base)) else {
        return target.to_path_buf();
    };
    let tc: Vec<std::path::Component<'_>> = t.components().collect();
    let bc: Vec<std::path::Component<'_>> = b.components().collect();
    let common = tc.iter().zip(&bc).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return t;
    }
    let mut rel = std::path::PathBuf::new();
    for _ in common..bc.len() {
        rel.push("..");
    }
    for c in &tc[common..] {
        rel.push(c.as_os_str());
    }
    rel
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths_climb_to_the_common_root() {
        let dir = tempfile::tempdir().expect("tempdir");
        let card = dir.path().join("S/studio/card");
        std::fs::create_dir_all(&card).expect("mkdir");
        std::fs::write(card.join("a.dng"), b"x").expect("write");
        let rel = relative_path(&card.join("a.dng"), dir.path());
        assert_eq!(rel, std::path::PathBuf::from("S/studio/card/a.dng"));
        let up = relative_path(dir.path(), &card);
        assert_eq!(up, std::path::PathBuf::from("../../.."));
    }
    use crate::linear::{load_linear_image, Linearization};

    #[test]
    fn png16_round_trips_through_the_linear_loader() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        let rgb: Vec<u16> = (0..3 * 4 * 2).map(|i| (i * 2700) as u16).collect();
        write_png_rgb16(&p, 4, 2, &rgb).unwrap();
        let img = load_linear_image(
            &p,
            &Linearization::LINEAR,
            crate::linear::RawMode::Superpixel,
        )
        .unwrap();
        for (i, px) in img.rgb.iter().enumerate() {
            for c in 0..3 {
                let want = rgb[3 * i + c] as f32 / 65535.0;
                assert!((px[c] - want).abs() < 1e-7);
            }
        }
        assert!(!dir.path().join(".a.png.tmp").exists());
    }

    #[test]
    fn exr_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.exr");
        let rgb: Vec<f32> = (0..3 * 3 * 2).map(|i| i as f32 * 0.37).collect();
        write_exr_rgb32f(&p, 3, 2, &rgb).unwrap();
        let img = load_linear_image(
            &p,
            &Linearization::LINEAR,
            crate::linear::RawMode::Superpixel,
        )
        .unwrap();
        assert_eq!(img.rgb[5][1], rgb[16]);
        assert!(!img.saturated.iter().any(|&s| s));
    }

    #[test]
    fn masks_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.png");
        let m = vec![true, false, false, true, true, false];
        write_mask_png(&p, 3, 2, &m).unwrap();
        let back = load_mask(&p).unwrap();
        assert_eq!(back.data, m);
        assert_eq!(back.count(), 3);
    }
}
