//! What a file's metadata says about its exposure ([`ExposureMeta`]), and its capture time as
//! the camera's clock stated it ([`CaptureTime`], [`LocalDateTime`]). How each field is read
//! from a file is in `meta`'s module docs.

/// A naive (zone-less) calendar date and time of day, as EXIF stores it.
#[derive(
    serde::Serialize, serde::Deserialize, Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash,
)]
pub struct LocalDateTime {
    /// Year (e.g. 2025).
    pub year: i32,
    /// Month, 1..=12.
    pub month: u8,
    /// Day of the month, 1..=31.
    pub day: u8,
    /// Hour, 0..=23.
    pub hour: u8,
    /// Minute, 0..=59.
    pub minute: u8,
    /// Second, 0..=60 (a leap second is kept as written).
    pub second: u8,
}

impl LocalDateTime {
    /// The EXIF text, `YYYY:MM:DD HH:MM:SS` (what [`LocalDateTime::parse_exif`] reads).
    pub fn exif_text(&self) -> String {
        format!(
            "{:04}:{:02}:{:02} {:02}:{:02}:{:02}",
            self.year, self.month, self.day, self.hour, self.minute, self.second
        )
    }

    /// Parses EXIF's `YYYY:MM:DD HH:MM:SS` (also accepts `-` between date fields and `T`
    /// between date and time). `Ok(None)` for the "unknown" forms (blanks, all zeros).
    pub fn parse_exif(s: &str) -> Result<Option<Self>, &'static str> {
        let s = s.trim_end_matches('\0').trim();
        if s.is_empty() || s.chars().all(|c| matches!(c, ' ' | ':' | '0' | '-')) {
            return Ok(None);
        }
        let b = s.as_bytes();
        if b.len() < 19 {
            return Err("expected `YYYY:MM:DD HH:MM:SS`");
        }
        let num = |r: std::ops::Range<usize>| -> Result<u32, &'static str> {
            let t = &s[r];
            if t.bytes().all(|c| c.is_ascii_digit()) {
                t.parse().map_err(|_| "not a number")
            } else {
                Err("expected `YYYY:MM:DD HH:MM:SS`")
            }
        };
        let sep_ok = matches!(b[4], b':' | b'-')
            && matches!(b[7], b':' | b'-')
            && matches!(b[10], b' ' | b'T')
            && b[13] == b':'
            && b[16] == b':';
        if !sep_ok {
            return Err("expected `YYYY:MM:DD HH:MM:SS`");
        }
        let (year, month, day) = (num(0..4)?, num(5..7)?, num(8..10)?);
        let (hour, minute, second) = (num(11..13)?, num(14..16)?, num(17..19)?);
        let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
        let days_in_month = match month {
            1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
            4 | 6 | 9 | 11 => 30,
            2 if leap => 29,
            2 => 28,
            _ => return Err("month out of range"),
        };
        if day == 0 || day > days_in_month || hour > 23 || minute > 59 || second > 60 {
            return Err("date or time field out of range");
        }
        // Every field was checked to fit its type above.
        Ok(Some(Self {
            year: year as i32,
            month: month as u8,
            day: day as u8,
            hour: hour as u8,
            minute: minute as u8,
            second: second as u8,
        }))
    }

    /// Seconds from 1970-01-01 00:00:00 to this date-time on the same (unspecified) clock.
    pub fn naive_seconds(&self) -> i64 {
        days_from_civil(self.year, u32::from(self.month), u32::from(self.day)) * 86_400
            + i64::from(self.hour) * 3600
            + i64::from(self.minute) * 60
            + i64::from(self.second)
    }
    /// The date-time `s` seconds after 1970-01-01 00:00:00 on the same clock: the inverse of
    /// [`Self::naive_seconds`] (proleptic Gregorian calendar, H. Hinnant's algorithm).
    pub fn from_naive_seconds(s: i64) -> Self {
        let days = s.div_euclid(86_400);
        let secs = s.rem_euclid(86_400);
        let z = days + 719_468;
        let era = z.div_euclid(146_097);
        let doe = z - era * 146_097;
        let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
        let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
        let mp = (5 * doy + 2) / 153;
        let day = (doy - (153 * mp + 2) / 5 + 1) as u8;
        let month = if mp < 10 { mp + 3 } else { mp - 9 } as u8;
        let year = (yoe + era * 400 + i64::from(month <= 2)) as i32;
        Self {
            year,
            month,
            day,
            hour: (secs / 3600) as u8,
            minute: ((secs % 3600) / 60) as u8,
            second: (secs % 60) as u8,
        }
    }
}

/// Days from 1970-01-01 to a proleptic Gregorian date (H. Hinnant's algorithm).
fn days_from_civil(y: i32, m: u32, d: u32) -> i64 {
    let y = i64::from(y) - i64::from(m <= 2);
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let m = i64::from(m);
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(d) - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// When the shutter opened, as the camera's clock stated it.
#[derive(serde::Serialize, serde::Deserialize, Debug, Clone, PartialEq, Eq)]
pub struct CaptureTime {
    /// `DateTimeOriginal`: the camera's local date and time, whole seconds.
    pub local: LocalDateTime,
    /// `SubSecTimeOriginal` as written (decimal digits of the fraction of a second: "5" is
    /// 0.5 s, "050" is 0.05 s), if present.
    pub subsec_digits: Option<String>,
    /// `OffsetTimeOriginal` as minutes east of UTC (`"+01:00"` is 60), if present.
    pub utc_offset_min: Option<i32>,
}

impl CaptureTime {
    /// The sub-second fraction in seconds (0 when the file has none).
    pub fn subsec_s(&self) -> f64 {
        match &self.subsec_digits {
            Some(d) if !d.is_empty() => {
                d.parse::<f64>().unwrap_or(0.0) / 10f64.powi(d.len() as i32)
            }
            _ => 0.0,
        }
    }

    /// Seconds since the Unix epoch (UTC) when the offset is known.
    pub fn unix_seconds(&self) -> Option<f64> {
        self.utc_offset_min
            .map(|o| (self.local.naive_seconds() - i64::from(o) * 60) as f64 + self.subsec_s())
    }

    /// Seconds since the epoch on the camera's own clock, ignoring any offset.
    pub fn naive_seconds(&self) -> f64 {
        self.local.naive_seconds() as f64 + self.subsec_s()
    }

    /// [`Self::unix_seconds`] when the offset is known, else [`Self::naive_seconds`].
    pub fn seconds(&self) -> f64 {
        self.unix_seconds().unwrap_or_else(|| self.naive_seconds())
    }
}

/// What a file's metadata says about its exposure and the camera that made it.
#[derive(serde::Serialize, serde::Deserialize, Debug, Clone, PartialEq, Default)]
pub struct ExposureMeta {
    /// `ExposureTime`, seconds.
    pub exposure_time_s: Option<f64>,
    /// `FNumber`.
    pub f_number: Option<f64>,
    /// ISO sensitivity (see `meta`'s module docs).
    pub iso: Option<u32>,
    /// `FocalLength`, millimetres.
    pub focal_length_mm: Option<f64>,
    /// `LensMake`.
    pub lens_make: Option<String>,
    /// `LensModel`.
    pub lens_model: Option<String>,
    /// `Make` as written (trimmed) in a file with a TIFF structure (DNG, CR2, NEF, ARW, ...);
    /// for other containers (CR3, CRW, MRW, RAF, X3F) the decoder's normalised camera make.
    pub camera_make: Option<String>,
    /// `Model` as written (trimmed) in a file with a TIFF structure; for other containers the
    /// decoder's normalised camera model (e.g. `EOS Digital Rebel` for a CRW whose `Model` is
    /// `Canon EOS DIGITAL REBEL`).
    pub camera_model: Option<String>,
    /// The body's serial number (see `meta`'s module docs).
    pub body_serial: Option<String>,
    /// `DateTimeOriginal` with its sub-seconds and offset.
    pub capture_time: Option<CaptureTime>,
    /// `ImageNumber` (0x9211): the shutter count or image number where the camera writes one.
    pub image_number: Option<u32>,
    /// `FocalPlaneXResolution` in pixels (of the camera's image, photosites for a raw file) per
    /// millimetre of the focal plane, converted by its unit (see `meta`'s module docs). As written:
    /// may be non-finite or not positive.
    pub focal_plane_px_per_mm_x: Option<f64>,
    /// `FocalPlaneYResolution` in pixels per millimetre, as `focal_plane_px_per_mm_x`.
    pub focal_plane_px_per_mm_y: Option<f64>,
    /// `FocalPlaneResolutionUnit` as written (2 inch, 3 cm, 4 mm, 5 um; see `meta`'s module docs).
    pub focal_plane_resolution_unit: Option<u16>,
    /// `FocalLengthIn35mmFilm` (0xA405), millimetres: the focal length giving the same field
    /// of view on a 36 x 24 mm frame.
    pub focal_length_35mm_mm: Option<f64>,
    /// A DNG's raw image in photosites, `(width, height)`, masked border included.
    pub sensor_size_px: Option<(u32, u32)>,
    /// A DNG's `DefaultCropSize`, `(width, height)` in photosites: the size of its final image.
    pub default_crop_size_px: Option<(f64, f64)>,
}

/// Parses EXIF's `±HH:MM` into minutes east of UTC; `Ok(None)` for blanks.
pub(crate) fn parse_offset(s: &str) -> Result<Option<i32>, &'static str> {
    let s = s.trim_end_matches('\0').trim();
    if s.is_empty() || s.chars().all(|c| matches!(c, ' ' | ':')) {
        return Ok(None);
    }
    let b = s.as_bytes();
    if b.len() != 6 || b[3] != b':' || !matches!(b[0], b'+' | b'-') {
        return Err("expected `+HH:MM` or `-HH:MM`");
    }
    let h: i32 = s[1..3].parse().map_err(|_| "expected `+HH:MM`")?;
    let m: i32 = s[4..6].parse().map_err(|_| "expected `+HH:MM`")?;
    if h > 14 || m > 59 {
        return Err("offset out of range");
    }
    let sign = if b[0] == b'-' { -1 } else { 1 };
    Ok(Some(sign * (h * 60 + m)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn dates_parse_and_reject() {
        let d = LocalDateTime::parse_exif("2025:03:04 05:06:07")
            .unwrap()
            .unwrap();
        assert_eq!(
            (d.year, d.month, d.day, d.hour, d.minute, d.second),
            (2025, 3, 4, 5, 6, 7)
        );
        assert_eq!(
            LocalDateTime::parse_exif("    :  :     :  :  ").unwrap(),
            None
        );
        assert_eq!(
            LocalDateTime::parse_exif("0000:00:00 00:00:00").unwrap(),
            None
        );
        assert!(LocalDateTime::parse_exif("2025:02:30 00:00:00").is_err());
        assert!(LocalDateTime::parse_exif("2025/03/04 05:06:07").is_err());
        assert!(LocalDateTime::parse_exif("yesterday").is_err());
        // 2000-03-01 is day 11017 after the epoch.
        let d = LocalDateTime::parse_exif("2000:03:01 00:00:00")
            .unwrap()
            .unwrap();
        assert_eq!(d.naive_seconds(), 11_017 * 86_400);
    }

    #[test]
    fn offsets_and_subseconds() {
        assert_eq!(parse_offset("+01:00"), Ok(Some(60)));
        assert_eq!(parse_offset("-05:30"), Ok(Some(-330)));
        assert_eq!(parse_offset("      "), Ok(None));
        assert!(parse_offset("01:00").is_err());
        let local = LocalDateTime::parse_exif("1970:01:01 01:00:00")
            .unwrap()
            .unwrap();
        let t = CaptureTime {
            local,
            subsec_digits: Some("045".into()),
            utc_offset_min: Some(60),
        };
        assert!((t.subsec_s() - 0.045).abs() < 1e-12);
        assert_eq!(t.unix_seconds(), Some(0.045));
        assert_eq!(t.naive_seconds(), 3600.045);
        let naive = CaptureTime {
            utc_offset_min: None,
            ..t
        };
        assert_eq!(naive.seconds(), 3600.045);
    }

    #[test]
    fn civil_dates_invert_naive_seconds() {
        for s in [0i64, 951_782_400, 1_795_168_800, 4_102_444_799, -86_401] {
            assert_eq!(
                LocalDateTime::from_naive_seconds(s).naive_seconds(),
                s,
                "{s}"
            );
        }
        let d = LocalDateTime::from_naive_seconds(951_782_400); // 2000-02-29
        assert_eq!((d.year, d.month, d.day), (2000, 2, 29));
    }

    proptest! {
        /// Consecutive days are 86400 s apart, across month, year and leap boundaries.
        #[test]
        fn days_are_contiguous(y in 1900i32..2200, m in 1u32..=12, d in 1u32..=28) {
            let a = days_from_civil(y, m, d);
            let b = days_from_civil(y, m, d + 1);
            prop_assert_eq!(b - a, 1);
            let next_month = if m == 12 { days_from_civil(y + 1, 1, 1) } else { days_from_civil(y, m + 1, 1) };
            let len = next_month - days_from_civil(y, m, 1);
            prop_assert!((28..=31).contains(&len));
        }
    }
}
