//! Camera and exposure metadata as LibRaw reads it, with the make, model and capture time as
//! written where LibRaw met them in TIFF/EXIF directories.

use crate::exif::{ExifTags, TAG_DATE_TIME_ORIGINAL, TAG_MAKE, TAG_MODEL};
use crate::handle::State;

/// Seconds per day, for the timestamp's calendar date.
const SECONDS_PER_DAY: i64 = 86_400;

/// A file's camera and exposure metadata. Values LibRaw leaves at zero are `None`.
#[derive(Debug, Clone, PartialEq)]
pub struct Metadata {
    /// The make as LibRaw normalises it.
    pub make: String,
    /// The model as LibRaw normalises it.
    pub model: String,
    /// The TIFF Make tag as written.
    pub make_as_written: Option<String>,
    /// The TIFF Model tag as written.
    pub model_as_written: Option<String>,
    pub exposure_time_s: Option<f64>,
    pub f_number: Option<f64>,
    pub iso: Option<f64>,
    pub focal_length_mm: Option<f64>,
    /// `YYYY:MM:DD HH:MM:SS`: DateTimeOriginal as written, else LibRaw's timestamp in UTC.
    pub capture_time: Option<String>,
}

/// A positive finite value, else `None`.
fn positive(v: f32) -> Option<f64> {
    let v = f64::from(v);
    (v.is_finite() && v > 0.0).then_some(v)
}

impl Metadata {
    pub(crate) fn from_state(s: &State, exif: &ExifTags, bytes: &[u8]) -> Self {
        let capture_time = exif
            .ascii(bytes, TAG_DATE_TIME_ORIGINAL)
            .or_else(|| (s.timestamp_s > 0).then(|| utc_text(s.timestamp_s)));
        Metadata {
            make: s.make.clone(),
            model: s.model.clone(),
            make_as_written: exif.ascii(bytes, TAG_MAKE),
            model_as_written: exif.ascii(bytes, TAG_MODEL),
            exposure_time_s: positive(s.shutter_s),
            f_number: positive(s.aperture),
            iso: positive(s.iso_speed),
            focal_length_mm: positive(s.focal_len_mm),
            capture_time,
        }
    }
}

/// `seconds` since 1970 as `YYYY:MM:DD HH:MM:SS` in UTC (proleptic Gregorian calendar).
pub(crate) fn utc_text(seconds: i64) -> String {
    let days = seconds.div_euclid(SECONDS_PER_DAY);
    let secs = seconds.rem_euclid(SECONDS_PER_DAY);
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}:{m:02}:{d:02} {:02}:{:02}:{:02}",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

/// The calendar date of day `z` since 1970-01-01 (H. Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, i64, i64) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_read_as_utc_calendar_time() {
        assert_eq!(utc_text(0), "1970:01:01 00:00:00");
        assert_eq!(utc_text(951_782_400), "2000:02:29 00:00:00");
        assert_eq!(utc_text(1_068_485_966), "2003:11:10 17:39:26");
    }
}
