//! CSV export of samples, and its reader: one header line, one sample per line, angles in
//! radians, reflectance in 1/sr, written atomically. A channel a partial sample did not
//! measure (a camera raw photosite measures one) is written `NaN`, which Rust's, numpy's and
//! pandas' number parsers read back as NaN.
//!
//! The columns are [`CSV_HEADER`]: the sample (as in the binary file) and its surface point on
//! the scan: `triangle` (the scan's triangle index, `-1` for a sample without a surface point),
//! `barycentric_1, barycentric_2` (the weights of the triangle's second and third corner) and
//! `tex_u, tex_v` (the scan's texture coordinates there), `NaN` when absent. Files written
//! before the surface point existed have the first thirteen columns only ([`CSV_HEADER_V1`]);
//! [`read_csv`] reads both, the older without a surface point.

use std::io::Write;
use std::path::{Path, PathBuf};

use skinbrdf_core::{BrdfSample, SurfacePoint};

use crate::{write_atomic, SamplesError};

/// The CSV header line (without newline).
pub const CSV_HEADER: &str = "theta_i_rad,theta_e_rad,phi_d_rad,theta_h_rad,theta_diff_rad,phi_diff_rad,rho_r,rho_g,rho_b,weight,image_index,pixel_x,pixel_y,triangle,barycentric_1,barycentric_2,tex_u,tex_v";

/// The header of files written before samples kept their surface point.
pub const CSV_HEADER_V1: &str = "theta_i_rad,theta_e_rad,phi_d_rad,theta_h_rad,theta_diff_rad,phi_diff_rad,rho_r,rho_g,rho_b,weight,image_index,pixel_x,pixel_y";

/// Largest CSV file [`read_csv`] reads (a sanity bound on untrusted input: 4 GiB is some
/// 30 million samples).
pub const MAX_CSV_BYTES: u64 = 4 << 30;

/// Writes samples as CSV to any writer.
pub fn write_csv_to(out: &mut dyn Write, samples: &[BrdfSample]) -> std::io::Result<()> {
    writeln!(out, "{CSV_HEADER}")?;
    for s in samples {
        let p = &s.surface;
        let triangle = if p.is_known() {
            i64::from(p.triangle)
        } else {
            -1
        };
        writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            s.theta_i_rad,
            s.theta_e_rad,
            s.phi_d_rad,
            s.theta_h_rad,
            s.theta_diff_rad,
            s.phi_diff_rad,
            s.rho[0],
            s.rho[1],
            s.rho[2],
            s.weight,
            s.image_index,
            s.pixel[0],
            s.pixel[1],
            triangle,
            p.barycentric[0],
            p.barycentric[1],
            p.uv[0],
            p.uv[1],
        )?;
    }
    Ok(())
}

/// Writes samples as CSV to `path`, atomically.
pub fn write_csv(path: impl AsRef<Path>, samples: &[BrdfSample]) -> Result<(), SamplesError> {
    write_atomic(path.as_ref(), |w| write_csv_to(w, samples))
}

/// Reads a sample CSV written by [`write_csv`], with the current header or the older one
/// without the surface point ([`CSV_HEADER_V1`]).
pub fn read_csv(path: impl AsRef<Path>) -> Result<Vec<BrdfSample>, SamplesError> {
    let path = path.as_ref();
    let io_err = |source| SamplesError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io_err)?;
    let len = file.metadata().map_err(io_err)?.len();
    if len > MAX_CSV_BYTES {
        return Err(SamplesError::Parse {
            path: path.to_path_buf(),
            line: 1,
            problem: format!("the file is {len} bytes, more than the {MAX_CSV_BYTES} read"),
        });
    }
    let text = std::fs::read_to_string(path).map_err(io_err)?;
    parse_csv(&text, path)
}

/// Parses sample CSV text; `path` names the file in errors.
pub fn parse_csv(text: &str, path: &Path) -> Result<Vec<BrdfSample>, SamplesError> {
    let err = |line: usize, problem: String| SamplesError::Parse {
        path: PathBuf::from(path),
        line,
        problem,
    };
    let mut lines = text.lines().enumerate();
    let header = lines
        .next()
        .map(|(_, l)| l.trim_end_matches('\r'))
        .unwrap_or_default();
    let columns = if header == CSV_HEADER {
        CSV_HEADER.split(',').count()
    } else if header == CSV_HEADER_V1 {
        CSV_HEADER_V1.split(',').count()
    } else {
        return Err(err(
            1,
            format!("the header is not a sample CSV's (expected `{CSV_HEADER}`, or the same without the surface point's five columns)"),
        ));
    };
    let mut out = Vec::new();
    for (idx, raw) in lines {
        let line = raw.trim_end_matches('\r');
        if line.is_empty() {
            continue;
        }
        out.push(parse_row(line, columns).map_err(|problem| err(idx + 1, problem))?);
    }
    Ok(out)
}

/// One data row of `columns` fields (13: without, 18: with the surface point).
fn parse_row(line: &str, columns: usize) -> Result<BrdfSample, String> {
    let fields: Vec<&str> = line.split(',').collect();
    if fields.len() != columns {
        return Err(format!("{} fields, the header has {columns}", fields.len()));
    }
    let names: Vec<&str> = CSV_HEADER.split(',').collect();
    let float = |k: usize| {
        fields[k]
            .trim()
            .parse::<f32>()
            .map_err(|_| format!("{}: `{}` is not a number", names[k], fields[k]))
    };
    let int = |k: usize, max: i64| {
        fields[k]
            .trim()
            .parse::<i64>()
            .ok()
            .filter(|v| (-1..=max).contains(v))
            .ok_or_else(|| {
                format!(
                    "{}: `{}` is not an integer in 0..={max}",
                    names[k], fields[k]
                )
            })
    };
    let u16_at = |k: usize| {
        int(k, i64::from(u16::MAX)).and_then(|v| {
            u16::try_from(v).map_err(|_| format!("{}: `{}` is negative", names[k], fields[k]))
        })
    };
    let surface = if columns > 13 {
        let triangle = match int(13, i64::from(u32::MAX))? {
            -1 => SurfacePoint::NO_TRIANGLE,
            t => t as u32,
        };
        SurfacePoint {
            triangle,
            barycentric: [float(14)?, float(15)?],
            uv: [float(16)?, float(17)?],
        }
    } else {
        SurfacePoint::NONE
    };
    Ok(BrdfSample {
        theta_i_rad: float(0)?,
        theta_e_rad: float(1)?,
        phi_d_rad: float(2)?,
        theta_h_rad: float(3)?,
        theta_diff_rad: float(4)?,
        phi_diff_rad: float(5)?,
        rho: [float(6)?, float(7)?, float(8)?],
        weight: float(9)?,
        image_index: u16_at(10)?,
        pixel: [u16_at(11)?, u16_at(12)?],
        surface,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_has_header_and_parsable_rows() {
        let s = BrdfSample {
            theta_i_rad: 0.5,
            rho: [0.25, 1.5, 3.0],
            weight: 1.0,
            ..BrdfSample::default()
        };
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("s.csv");
        write_csv(&p, &[s, s]).expect("write");
        let text = std::fs::read_to_string(&p).expect("read");
        let lines: Vec<_> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[0], CSV_HEADER);
        let cols: Vec<f64> = lines[1]
            .split(',')
            .map(|v| v.parse().expect("num"))
            .collect();
        assert_eq!(cols.len(), CSV_HEADER.split(',').count());
        assert_eq!(cols[0], 0.5);
        assert_eq!(cols[7], 1.5);
    }

    #[test]
    fn a_partial_sample_writes_nan_and_reads_back() {
        let s = BrdfSample {
            rho: [f32::NAN, 0.75, f32::NAN],
            ..BrdfSample::default()
        };
        let mut out = Vec::new();
        write_csv_to(&mut out, &[s]).expect("write");
        let text = String::from_utf8(out).expect("utf8");
        let row: Vec<f32> = text
            .lines()
            .nth(1)
            .expect("row")
            .split(',')
            .map(|v| v.parse().expect("num"))
            .collect();
        assert!(row[6].is_nan() && row[8].is_nan());
        assert_eq!(row[7], 0.75);
        // No surface point: triangle -1, the coordinates NaN.
        assert_eq!(row[13], -1.0);
        assert!(row[14..].iter().all(|v| v.is_nan()));
    }

    fn with_surface(k: u32) -> BrdfSample {
        BrdfSample {
            theta_i_rad: 0.1 * k as f32,
            theta_e_rad: 0.7,
            phi_d_rad: 3.0,
            rho: [0.2, 0.3, 0.4],
            weight: 1.0,
            image_index: 29,
            pixel: [6000, 4000],
            surface: SurfacePoint {
                triangle: 1_234_567 + k,
                barycentric: [0.1 + 0.01 * k as f32, 1.0 / 3.0],
                uv: if k == 1 {
                    [f32::NAN; 2]
                } else {
                    [0.25, 0.123_456_79]
                },
            },
            ..BrdfSample::default()
        }
    }

    #[test]
    fn round_trip_with_the_surface_point() {
        let samples = [with_surface(0), with_surface(1), BrdfSample::default()];
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("s.csv");
        write_csv(&p, &samples).expect("write");
        let back = read_csv(&p).expect("read");
        assert_eq!(back, samples);
        assert!(!back[2].surface.is_known());
        assert_eq!(back[1].surface.texture_uv(), None);
    }

    #[test]
    fn the_older_header_reads_without_a_surface_point() {
        let text = format!("{CSV_HEADER_V1}\r\n0.5,0.25,1,0,0,0,0.1,NaN,0.3,1,3,640,480\r\n");
        let back = parse_csv(&text, Path::new("old.csv")).expect("old header");
        assert_eq!(back.len(), 1);
        assert_eq!(back[0].pixel, [640, 480]);
        assert!(back[0].rho[1].is_nan());
        assert_eq!(back[0].surface, SurfacePoint::NONE);
    }

    #[test]
    fn malformed_csv_names_the_file_line_and_column() {
        let p = Path::new("bad.csv");
        let e = parse_csv("a,b,c\n", p).expect_err("header");
        assert!(e.to_string().starts_with("bad.csv:1:"), "{e}");
        // A new-format row under the old header has too many fields.
        let mut out = Vec::new();
        write_csv_to(&mut out, &[with_surface(0)]).expect("write");
        let text = String::from_utf8(out).expect("utf8");
        let row = text.lines().nth(1).expect("row");
        let e = parse_csv(&format!("{CSV_HEADER_V1}\n{row}\n"), p).expect_err("fields");
        assert!(e.to_string().contains("bad.csv:2: 18 fields"), "{e}");
        let bad = row.replacen("1234567", "-2", 1);
        let e = parse_csv(&format!("{CSV_HEADER}\n{bad}\n"), p).expect_err("triangle");
        assert!(e.to_string().contains("bad.csv:2: triangle"), "{e}");
        let bad = row.replacen("6000", "70000", 1);
        let e = parse_csv(&format!("{CSV_HEADER}\n{bad}\n"), p).expect_err("pixel");
        assert!(e.to_string().contains("pixel_x"), "{e}");
    }
}
