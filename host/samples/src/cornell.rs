//! The Cornell gonioreflectometer `.brdf` text format (as distributed with pbrt-v2).
//!
//! ```text
//! # <title comment lines>
//!
//! # num wls
//! 31
//!
//! # wls
//! 400 410 ... 580
//! 590 ... 700
//!
//! # theta i, phi i, theta s, phi_s, spectral sample values
//!
//! theta_i phi_i theta_s phi_s v_1 ... v_n      (one sample per line, radians, 1/sr)
//! ```
//!
//! Both directions point away from the surface; `phi_s - phi_i = pi` is the mirror side, which is
//! the project's `phi_d = pi` ([`skinbrdf_core::angles`]). Import keeps the spectra
//! ([`CornellBrdf`]); [`CornellBrdf::to_rgb_samples`] converts them to linear sRGB
//! ([`SpectrumToRgb`]). Export writes the same layout (CRLF line ends, six decimals, 19
//! wavelengths per line, as the distributed files), so an unmodified import exports
//! byte-identically. Values stay `f64` so six-decimal numbers survive the round trip.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::DVec3;
use skinbrdf_core::{BrdfAngles, BrdfSample};

use crate::{write_atomic, Illuminant, SamplesError, SpectrumToRgb};

/// Slack on the polar-angle range check (the files print six decimals).
const ANGLE_SLACK_RAD: f64 = 1e-5;
/// Wavelengths per line in the `# wls` section of the distributed files.
const WLS_PER_LINE: usize = 19;

/// One spectral sample: the two directions (spherical, radians) and one value per band (1/sr).
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralSample {
    /// Incident polar angle.
    pub theta_i_rad: f64,
    /// Incident azimuth.
    pub phi_i_rad: f64,
    /// Scattered (exitant) polar angle.
    pub theta_s_rad: f64,
    /// Scattered azimuth.
    pub phi_s_rad: f64,
    /// BRDF per band, 1/sr.
    pub values: Vec<f64>,
}

fn dir(theta: f64, phi: f64) -> DVec3 {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    DVec3::new(st * cp, st * sp, ct)
}

impl SpectralSample {
    /// The sample's isotropic angles (project conventions).
    pub fn angles(&self) -> BrdfAngles {
        BrdfAngles::from_local(
            dir(self.theta_i_rad, self.phi_i_rad),
            dir(self.theta_s_rad, self.phi_s_rad),
        )
    }
}

/// A whole Cornell file.
#[derive(Debug, Clone, PartialEq)]
pub struct CornellBrdf {
    /// Title comment lines before `# num wls`, without the leading `#` (a leading space kept).
    pub comments: Vec<String>,
    /// Band centres, nm.
    pub wavelengths_nm: Vec<f64>,
    /// The samples.
    pub samples: Vec<SpectralSample>,
}

#[derive(PartialEq)]
enum State {
    Title,
    Count,
    Wavelengths,
    Data,
}

impl CornellBrdf {
    /// Reads and validates a `.brdf` file.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, SamplesError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| SamplesError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses `.brdf` text; `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, SamplesError> {
        let err = |line: usize, problem: String| SamplesError::Parse {
            path: PathBuf::from(path),
            line,
            problem,
        };
        let mut state = State::Title;
        let mut comments = Vec::new();
        let mut n_wls = 0usize;
        let mut wls = Vec::new();
        let mut samples = Vec::new();
        for (idx, raw) in text.lines().enumerate() {
            let line_no = idx + 1;
            let line = raw.trim_end_matches('\r');
            let trimmed = line.trim();
            if let Some(comment) = trimmed.strip_prefix('#') {
                if state == State::Wavelengths && !wls.is_empty() {
                    return Err(err(
                        line_no,
                        format!("only {} of {n_wls} wavelengths listed", wls.len()),
                    ));
                }
                if state == State::Title {
                    if comment.trim() == "num wls" {
                        state = State::Count;
                    } else {
                        comments.push(comment.to_owned());
                    }
                }
                continue;
            }
            if trimmed.is_empty() {
                continue;
            }
            match state {
                State::Title => {
                    return Err(err(
                        line_no,
                        "expected `# num wls` before the first data line".into(),
                    ));
                }
                State::Count => {
                    n_wls = trimmed
                        .parse::<usize>()
                        .ok()
                        .filter(|&n| n > 0)
                        .ok_or_else(|| {
                            err(
                                line_no,
                                format!("expected the number of wavelengths, found `{trimmed}`"),
                            )
                        })?;
                    state = State::Wavelengths;
                }
                State::Wavelengths => {
                    for tok in trimmed.split_whitespace() {
                        let wl: f64 = tok
                            .parse()
                            .ok()
                            .filter(|v: &f64| v.is_finite() && *v > 0.0)
                            .ok_or_else(|| err(line_no, format!("bad wavelength `{tok}`")))?;
                        if wls.len() == n_wls {
                            return Err(err(
                                line_no,
                                format!("more than the {n_wls} wavelengths announced"),
                            ));
                        }
                        wls.push(wl);
                    }
                    if wls.len() == n_wls {
                        state = State::Data;
                    }
                }
                State::Data => {
                    let mut vals = Vec::with_capacity(4 + n_wls);
                    for (col, tok) in trimmed.split_whitespace().enumerate() {
                        let v: f64 = tok
                            .parse()
                            .ok()
                            .filter(|v: &f64| v.is_finite())
                            .ok_or_else(|| {
                                err(
                                    line_no,
                                    format!("column {}: `{tok}` is not a finite number", col + 1),
                                )
                            })?;
                        vals.push(v);
                    }
                    if vals.len() != 4 + n_wls {
                        return Err(err(
                            line_no,
                            format!(
                                "expected {} columns (4 angles + {n_wls} bands), found {}",
                                4 + n_wls,
                                vals.len()
                            ),
                        ));
                    }
                    for (name, v) in [("theta_i", vals[0]), ("theta_s", vals[2])] {
                        if !(-ANGLE_SLACK_RAD..=std::f64::consts::FRAC_PI_2 + ANGLE_SLACK_RAD)
                            .contains(&v)
                        {
                            return Err(err(
                                line_no,
                                format!("{name} = {v} rad is outside [0, pi/2]"),
                            ));
                        }
                    }
                    samples.push(SpectralSample {
                        theta_i_rad: vals[0],
                        phi_i_rad: vals[1],
                        theta_s_rad: vals[2],
                        phi_s_rad: vals[3],
                        values: vals[4..].to_vec(),
                    });
                }
            }
        }
        let last = text.lines().count();
        match state {
            State::Title | State::Count => Err(err(last, "missing `# num wls` section".into())),
            State::Wavelengths => Err(err(
                last,
                format!("only {} of {n_wls} wavelengths listed", wls.len()),
            )),
            State::Data if samples.is_empty() => Err(err(last, "no samples".into())),
            State::Data => Ok(Self {
                comments,
                wavelengths_nm: wls,
                samples,
            }),
        }
    }

    /// The file's text in the distributed layout (CRLF line ends).
    pub fn to_text(&self) -> String {
        let mut s =
            String::with_capacity(64 + self.samples.len() * (40 + 9 * self.wavelengths_nm.len()));
        const NL: &str = "\r\n";
        for c in &self.comments {
            let _ = write!(s, "#{c}{NL}");
        }
        let _ = write!(
            s,
            "{NL}# num wls{NL}{}{NL}{NL}# wls{NL}",
            self.wavelengths_nm.len()
        );
        for chunk in self.wavelengths_nm.chunks(WLS_PER_LINE) {
            let line: Vec<String> = chunk
                .iter()
                .map(|&w| {
                    if w.fract() == 0.0 {
                        format!("{}", w as i64)
                    } else {
                        format!("{w}")
                    }
                })
                .collect();
            let _ = write!(s, "{}{NL}", line.join(" "));
        }
        let _ = write!(
            s,
            "{NL}# theta i, phi i, theta s, phi_s, spectral sample values{NL}{NL}"
        );
        for smp in &self.samples {
            let _ = write!(
                s,
                "{:.6} {:.6} {:.6} {:.6}",
                smp.theta_i_rad, smp.phi_i_rad, smp.theta_s_rad, smp.phi_s_rad
            );
            for v in &smp.values {
                let _ = write!(s, " {v:.6}");
            }
            s.push_str(NL);
        }
        s
    }

    /// Writes the file atomically.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), SamplesError> {
        let text = self.to_text();
        write_atomic(path.as_ref(), |w| w.write_all(text.as_bytes()))
    }

    /// The spectral-to-RGB converter for this file's bands.
    pub fn rgb_converter(
        &self,
        illuminant: Illuminant,
        path: &Path,
    ) -> Result<SpectrumToRgb, SamplesError> {
        SpectrumToRgb::new(&self.wavelengths_nm, illuminant, path)
    }

    /// The samples in linear sRGB (see [`crate::color`]), unit weight, no image provenance.
    pub fn to_rgb_samples(&self, conv: &SpectrumToRgb) -> Vec<BrdfSample> {
        self.samples
            .iter()
            .map(|s| {
                let rgb = conv.convert(&s.values);
                BrdfSample::from_angles(&s.angles(), rgb.map(|v| v as f32))
            })
            .collect()
    }

    /// An RGB table in the Cornell layout: three pseudo-bands at the sRGB primaries' dominant
    /// wavelengths (611, 549, 464 nm), for exporting RGB data or fitted models. Each entry is
    /// `(theta_i, phi_i, theta_s, phi_s, rgb)`.
    pub fn from_rgb(
        comments: Vec<String>,
        rows: impl IntoIterator<Item = ([f64; 4], [f64; 3])>,
    ) -> Self {
        Self {
            comments,
            wavelengths_nm: vec![611.0, 549.0, 464.0],
            samples: rows
                .into_iter()
                .map(|(a, rgb)| SpectralSample {
                    theta_i_rad: a[0],
                    phi_i_rad: a[1],
                    theta_s_rad: a[2],
                    phi_s_rad: a[3],
                    values: rgb.to_vec(),
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/cornell")
            .join(name)
    }

    #[test]
    fn real_files_import_and_export_byte_identically() {
        for name in ["garnet_red.brdf", "krylon_blue.brdf"] {
            let path = data(name);
            let b = CornellBrdf::read(&path).expect("read");
            assert_eq!(b.wavelengths_nm.len(), 31);
            assert_eq!(b.wavelengths_nm[0], 400.0);
            assert_eq!(b.wavelengths_nm[30], 700.0);
            // The data README says "1441 samples per file"; the files hold 1439 data lines each.
            assert_eq!(b.samples.len(), 1439, "{name}");
            let original = std::fs::read_to_string(&path).expect("text");
            assert_eq!(
                b.to_text(),
                original,
                "{name} did not round-trip byte-identically"
            );
            let dir = tempfile::tempdir().expect("tempdir");
            let out = dir.path().join(name);
            b.write(&out).expect("write");
            assert_eq!(CornellBrdf::read(&out).expect("reread"), b);
        }
    }

    #[test]
    fn real_files_cover_the_documented_domain_and_convert_to_rgb() {
        let path = data("garnet_red.brdf");
        let b = CornellBrdf::read(&path).expect("read");
        let conv = b.rgb_converter(Illuminant::D65, &path).expect("conv");
        let rgb = b.to_rgb_samples(&conv);
        let ti: Vec<f64> = rgb
            .iter()
            .map(|s| s.theta_i_rad.to_degrees() as f64)
            .collect();
        let lo = ti.iter().cloned().fold(f64::INFINITY, f64::min);
        let hi = ti.iter().cloned().fold(0.0, f64::max);
        assert!(
            (lo - 10.0).abs() < 0.01 && (hi - 80.0).abs() < 0.01,
            "{lo} {hi}"
        );
        // Garnet red is red: in a diffuse-looking sample the red channel dominates.
        let s = rgb[0];
        assert!(s.rho[0] > 2.0 * s.rho[2], "{:?}", s.rho);
        // Every phi_d is in [0, pi]; the brightest sample is on the mirror side.
        assert!(rgb
            .iter()
            .all(|s| (0.0..=std::f32::consts::PI + 1e-5).contains(&s.phi_d_rad)));
        let brightest = rgb
            .iter()
            .max_by(|a, b| a.rho[1].total_cmp(&b.rho[1]))
            .expect("non-empty");
        assert!(
            brightest.phi_d_rad > 3.0 && brightest.theta_h_rad < 0.05,
            "{brightest:?}"
        );
        let blue = CornellBrdf::read(data("krylon_blue.brdf")).expect("read");
        let bs = blue.to_rgb_samples(&conv)[0];
        assert!(bs.rho[2] > bs.rho[0], "{:?}", bs.rho);
    }

    #[test]
    fn malformed_input_names_file_and_line() {
        let p = Path::new("bad.brdf");
        let good = "# t\n\n# num wls\n2\n\n# wls\n400 500\n\n# data\n\n0.1 0 0.2 3.14 0.5 0.6\n";
        assert_eq!(CornellBrdf::parse(good, p).expect("good").samples.len(), 1);
        let cases = [
            (good.replace("0.5 0.6", "0.5"), 11, "expected 6 columns"),
            (good.replace("0.5 0.6", "0.5 abc"), 11, "column 6"),
            (good.replace("\n2\n", "\nx\n"), 4, "number of wavelengths"),
            (good.replace("400 500", "400"), 9, "only 1 of 2"),
            (good.replace("0.1 0 0.2", "0.1 0 2.2"), 11, "theta_s"),
            ("0.1 0.2\n".to_owned(), 1, "num wls"),
        ];
        for (text, line, needle) in cases {
            let e = CornellBrdf::parse(&text, p).expect_err(needle);
            let msg = e.to_string();
            assert!(
                matches!(e, SamplesError::Parse { line: l, .. } if l == line),
                "{msg}"
            );
            assert!(
                msg.starts_with(&format!("bad.brdf:{line}:")) && msg.contains(needle),
                "{msg}"
            );
        }
    }

    #[test]
    fn rgb_tables_round_trip() {
        let b = CornellBrdf::from_rgb(
            vec![" model".into()],
            [([0.1, 0.0, 0.2, 3.0], [0.5, 0.25, 0.125])],
        );
        let back = CornellBrdf::parse(&b.to_text(), Path::new("x")).expect("parse");
        assert_eq!(back, b);
    }
}
