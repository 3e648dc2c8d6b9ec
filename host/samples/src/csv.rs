//! CSV export of samples: one header line, one sample per line, angles in radians,
//! reflectance in 1/sr, written atomically. A channel a partial sample did not measure (a
//! camera raw photosite measures one) is written `NaN`, which Rust's, numpy's and pandas'
//! number parsers read back as NaN.

use std::io::Write;
use std::path::Path;

use skinbrdf_core::BrdfSample;

use crate::{write_atomic, SamplesError};

/// The CSV header line (without newline).
pub const CSV_HEADER: &str = "theta_i_rad,theta_e_rad,phi_d_rad,theta_h_rad,theta_diff_rad,phi_diff_rad,rho_r,rho_g,rho_b,weight,image_index,pixel_x,pixel_y";

/// Writes samples as CSV to any writer.
pub fn write_csv_to(out: &mut dyn Write, samples: &[BrdfSample]) -> std::io::Result<()> {
    writeln!(out, "{CSV_HEADER}")?;
    for s in samples {
        writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
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
            s.pixel[1]
        )?;
    }
    Ok(())
}

/// Writes samples as CSV to `path`, atomically.
pub fn write_csv(path: impl AsRef<Path>, samples: &[BrdfSample]) -> Result<(), SamplesError> {
    write_atomic(path.as_ref(), |w| write_csv_to(w, samples))
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
    }
}
