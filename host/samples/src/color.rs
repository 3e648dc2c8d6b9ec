//! Spectral to linear sRGB conversion for the Cornell data.
//!
//! A BRDF spectrum `rho(lambda)` is a reflectance-like quantity, so it is converted the way a
//! reflectance spectrum is: under an illuminant `S(lambda)`,
//!
//! ```text
//! XYZ = sum_k rho(l_k) S(l_k) cmf(l_k) / sum_k S(l_k) ybar(l_k)      (CIE 1931 2° observer)
//! rgb_lin = M_sRGB * XYZ                                               (IEC 61966-2-1 matrix)
//! rgb_c  /= white_c   where white = rgb_lin of rho == 1
//! ```
//!
//! The final white normalisation makes a spectrally flat BRDF map to `R = G = B` equal to its
//! value exactly, whatever the illuminant and the band truncation (the Cornell data stop at
//! 400 and 700 nm); it is a von Kries-style adaptation in the sRGB primaries. The default
//! illuminant is **D65** (the sRGB white); equal-energy (E) is available.
//!
//! **Gamut.** Saturated paints fall outside the sRGB gamut: some linear sRGB components come out
//! negative (Cornell krylon_blue: red < 0 for about two thirds of the samples). Because BRDF
//! models are non-negative, [`SpectrumToRgb::convert`] maps such colours into the gamut by
//! desaturating towards the grey of equal luminance `Y` just enough that the smallest component
//! is zero (`rgb' = Y + (rgb - Y) Y / (Y - min)`), which keeps luminance and hue;
//! [`SpectrumToRgb::convert_unclipped`] gives the raw values.
//!
//! Tables: CIE 1931 2° colour matching functions and CIE D65 at 10 nm from 400 to 700 nm;
//! other wavelengths inside that range are interpolated linearly.

use std::path::Path;

use crate::SamplesError;

/// CIE 1931 2° colour-matching functions (xbar, ybar, zbar), 400..700 nm in 10 nm steps.
const CMF_1931: [[f64; 3]; 31] = [
    [0.01431, 0.000396, 0.06785],
    [0.04351, 0.00121, 0.2074],
    [0.13438, 0.004, 0.6456],
    [0.2839, 0.0116, 1.3856],
    [0.34828, 0.023, 1.74706],
    [0.3362, 0.038, 1.77211],
    [0.2908, 0.06, 1.6692],
    [0.19536, 0.09098, 1.28764],
    [0.09564, 0.13902, 0.81295],
    [0.03201, 0.20802, 0.46518],
    [0.0049, 0.323, 0.272],
    [0.0093, 0.503, 0.1582],
    [0.06327, 0.71, 0.07825],
    [0.1655, 0.862, 0.04216],
    [0.2904, 0.954, 0.0203],
    [0.43345, 0.99495, 0.00875],
    [0.5945, 0.995, 0.0039],
    [0.7621, 0.952, 0.0021],
    [0.9163, 0.87, 0.00165],
    [1.0263, 0.757, 0.0011],
    [1.0622, 0.631, 0.0008],
    [1.0026, 0.503, 0.00034],
    [0.85445, 0.381, 0.00019],
    [0.6424, 0.265, 0.00005],
    [0.4479, 0.175, 0.00002],
    [0.2835, 0.107, 0.0],
    [0.1649, 0.061, 0.0],
    [0.0874, 0.032, 0.0],
    [0.04677, 0.017, 0.0],
    [0.0227, 0.00821, 0.0],
    [0.011359, 0.004102, 0.0],
];

/// CIE standard illuminant D65 relative spectral power, 400..700 nm in 10 nm steps.
const D65: [f64; 31] = [
    82.7549, 91.486, 93.4318, 86.6823, 104.865, 117.008, 117.812, 114.861, 115.923, 108.811,
    109.354, 107.802, 104.790, 107.689, 104.405, 104.046, 100.000, 96.3342, 95.788, 88.6856,
    90.0062, 89.5991, 87.6987, 83.2886, 83.6992, 80.0268, 80.2146, 82.2778, 78.2842, 69.7213,
    71.6091,
];

/// XYZ to linear sRGB (IEC 61966-2-1, D65 white).
const XYZ_TO_SRGB: [[f64; 3]; 3] = [
    [3.2404542, -1.5371385, -0.4985314],
    [-0.9692660, 1.8760108, 0.0415560],
    [0.0556434, -0.2040259, 1.0572252],
];

const TABLE_START_NM: f64 = 400.0;
const TABLE_STEP_NM: f64 = 10.0;

/// The illuminant under which spectra are integrated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Illuminant {
    /// CIE D65 (the sRGB white point); the default.
    #[default]
    D65,
    /// Equal-energy illuminant E.
    EqualEnergy,
}

fn table_at<const N: usize>(table: &[[f64; N]; 31], wl_nm: f64) -> Option<[f64; N]> {
    let x = (wl_nm - TABLE_START_NM) / TABLE_STEP_NM;
    if !(-1e-9..=30.0 + 1e-9).contains(&x) {
        return None;
    }
    let x = x.clamp(0.0, 30.0);
    let i = (x.floor() as usize).min(29);
    let t = x - i as f64;
    Some(std::array::from_fn(|c| {
        table[i][c] * (1.0 - t) + table[i + 1][c] * t
    }))
}

/// Per-band weights mapping a sampled spectrum to white-normalised linear sRGB.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectrumToRgb {
    /// `weights[k][c]`: contribution of band `k` to channel `c`. Each channel's weights sum to 1.
    pub weights: Vec<[f64; 3]>,
    /// The illuminant used.
    pub illuminant: Illuminant,
}

impl SpectrumToRgb {
    /// Builds the weights for the given band wavelengths. `path` only names the file in errors.
    pub fn new(
        wavelengths_nm: &[f64],
        illuminant: Illuminant,
        path: &Path,
    ) -> Result<Self, SamplesError> {
        let d65: [[f64; 1]; 31] = D65.map(|v| [v]);
        let mut xyz_w = Vec::with_capacity(wavelengths_nm.len());
        let mut norm = 0.0;
        for &wl in wavelengths_nm {
            let cmf =
                table_at(&CMF_1931, wl).ok_or_else(|| SamplesError::WavelengthOutOfRange {
                    path: path.to_path_buf(),
                    wavelength_nm: wl,
                })?;
            let s = match illuminant {
                Illuminant::D65 => table_at(&d65, wl).map_or(0.0, |v| v[0]),
                Illuminant::EqualEnergy => 1.0,
            };
            norm += s * cmf[1];
            xyz_w.push(cmf.map(|v| v * s));
        }
        let to_rgb = |xyz: [f64; 3]| -> [f64; 3] {
            std::array::from_fn(|r| (0..3).map(|c| XYZ_TO_SRGB[r][c] * xyz[c]).sum())
        };
        let mut weights: Vec<[f64; 3]> =
            xyz_w.iter().map(|x| to_rgb(x.map(|v| v / norm))).collect();
        let white: [f64; 3] = std::array::from_fn(|c| weights.iter().map(|w| w[c]).sum());
        for w in &mut weights {
            for c in 0..3 {
                w[c] /= white[c];
            }
        }
        Ok(Self {
            weights,
            illuminant,
        })
    }

    /// Converts one spectrum (same bands as at construction) to linear sRGB, mapped into the
    /// gamut (see the module docs).
    pub fn convert(&self, spectrum: &[f64]) -> [f64; 3] {
        let rgb = self.convert_unclipped(spectrum);
        let min = rgb[0].min(rgb[1]).min(rgb[2]);
        if min >= 0.0 {
            return rgb;
        }
        // Luminance of linear sRGB (Rec. 709 weights); the white normalisation keeps Y unchanged.
        let y = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
        if y <= 0.0 {
            return [0.0; 3];
        }
        let k = y / (y - min);
        rgb.map(|v| (y + (v - y) * k).max(0.0))
    }

    /// Converts one spectrum to linear sRGB without gamut mapping (components may be negative).
    pub fn convert_unclipped(&self, spectrum: &[f64]) -> [f64; 3] {
        std::array::from_fn(|c| {
            self.weights
                .iter()
                .zip(spectrum)
                .map(|(w, v)| w[c] * v)
                .sum()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cornell_bands() -> Vec<f64> {
        (0..31).map(|k| 400.0 + 10.0 * k as f64).collect()
    }

    #[test]
    fn flat_spectrum_is_grey() {
        for ill in [Illuminant::D65, Illuminant::EqualEnergy] {
            let conv = SpectrumToRgb::new(&cornell_bands(), ill, Path::new("x")).expect("conv");
            let rgb = conv.convert(&[0.37; 31]);
            for c in rgb {
                assert!((c - 0.37).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn red_spectrum_is_red_and_blue_is_blue() {
        let conv =
            SpectrumToRgb::new(&cornell_bands(), Illuminant::D65, Path::new("x")).expect("conv");
        let red: Vec<f64> = cornell_bands()
            .iter()
            .map(|&l| if l >= 600.0 { 1.0 } else { 0.02 })
            .collect();
        let rgb = conv.convert(&red);
        assert!(rgb[0] > 3.0 * rgb[1] && rgb[0] > 3.0 * rgb[2], "{rgb:?}");
        let blue: Vec<f64> = cornell_bands()
            .iter()
            .map(|&l| if l <= 480.0 { 1.0 } else { 0.02 })
            .collect();
        let rgb = conv.convert(&blue);
        assert!(rgb[2] > 3.0 * rgb[0] && rgb[2] > rgb[1], "{rgb:?}");
    }

    #[test]
    fn out_of_gamut_colours_are_desaturated_keeping_luminance() {
        let conv =
            SpectrumToRgb::new(&cornell_bands(), Illuminant::D65, Path::new("x")).expect("conv");
        let narrow: Vec<f64> = cornell_bands()
            .iter()
            .map(|&l| {
                if (500.0..=520.0).contains(&l) {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        let raw = conv.convert_unclipped(&narrow);
        assert!(raw.iter().any(|&v| v < 0.0), "{raw:?}");
        let mapped = conv.convert(&narrow);
        assert!(
            mapped.iter().all(|&v| v >= 0.0) && mapped.iter().any(|&v| v < 1e-12),
            "{mapped:?}"
        );
        let lum = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        assert!((lum(raw) - lum(mapped)).abs() < 1e-12);
        assert!(mapped[1] > mapped[0] && mapped[1] > mapped[2]);
    }

    #[test]
    fn out_of_range_wavelength_is_an_error() {
        let e =
            SpectrumToRgb::new(&[380.0], Illuminant::D65, Path::new("f.brdf")).expect_err("range");
        assert!(e.to_string().contains("f.brdf") && e.to_string().contains("380"));
    }
}
