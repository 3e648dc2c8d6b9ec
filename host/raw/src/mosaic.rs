//! A decoded raw file kept compact: the active area's stored values, one per photosite, with the
//! levels and phase they are read with ([`RawMosaic`]). A [`RawFrame`] in either layout, or a
//! photosite image's values row by row, are computed from it with the same arithmetic as
//! [`crate::decode_raw`], so a mosaic decoded once stands for every later decode of its file
//! (two bytes per photosite of an integer file, against 13 for a photosite frame).

use std::io::{Read, Write};

use crate::assemble::{assemble, Geometry, QuadLevels, Sensor};
use crate::bayer::BayerPhase;
use crate::frame::{RawFrame, RawLayout};
use crate::kind::FileKind;

/// The stored values of a mosaic's active area, row-major.
#[derive(Debug, Clone, PartialEq)]
pub enum MosaicSamples {
    /// Integer values (every camera's raw data).
    U16(Vec<u16>),
    /// Floating-point values (a floating-point DNG).
    F32(Vec<f32>),
}

/// Which [`MosaicSamples`] variant a mosaic's values are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SampleType {
    /// [`MosaicSamples::U16`].
    U16,
    /// [`MosaicSamples::F32`].
    F32,
}

impl SampleType {
    /// Bytes per stored value.
    pub const fn bytes(self) -> usize {
        match self {
            Self::U16 => 2,
            Self::F32 => 4,
        }
    }
}

impl MosaicSamples {
    /// The variant.
    pub const fn sample_type(&self) -> SampleType {
        match self {
            Self::U16(_) => SampleType::U16,
            Self::F32(_) => SampleType::F32,
        }
    }

    /// The number of values.
    pub fn len(&self) -> usize {
        match self {
            Self::U16(v) => v.len(),
            Self::F32(v) => v.len(),
        }
    }

    /// True when there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Writes the values little-endian, nothing else.
    pub fn write_le(&self, out: &mut impl Write) -> std::io::Result<()> {
        const CHUNK: usize = 1 << 15;
        let mut buf = Vec::with_capacity(CHUNK * 4);
        match self {
            Self::U16(v) => {
                for c in v.chunks(CHUNK) {
                    buf.clear();
                    c.iter()
                        .for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
                    out.write_all(&buf)?;
                }
            }
            Self::F32(v) => {
                for c in v.chunks(CHUNK) {
                    buf.clear();
                    c.iter()
                        .for_each(|x| buf.extend_from_slice(&x.to_le_bytes()));
                    out.write_all(&buf)?;
                }
            }
        }
        Ok(())
    }

    /// Reads exactly `count` values of `ty` written by [`MosaicSamples::write_le`]; an input
    /// that ends early is an error (`UnexpectedEof`), one with bytes left over too.
    pub fn read_le(ty: SampleType, count: usize, input: &mut impl Read) -> std::io::Result<Self> {
        const CHUNK: usize = 1 << 15;
        let mut buf = vec![0u8; CHUNK * ty.bytes()];
        let mut left = count;
        let mut out = match ty {
            SampleType::U16 => Self::U16(Vec::with_capacity(count)),
            SampleType::F32 => Self::F32(Vec::with_capacity(count)),
        };
        while left > 0 {
            let n = left.min(CHUNK);
            let bytes = &mut buf[..n * ty.bytes()];
            input.read_exact(bytes)?;
            match &mut out {
                Self::U16(v) => v.extend(
                    bytes
                        .chunks_exact(2)
                        .map(|b| u16::from_le_bytes([b[0], b[1]])),
                ),
                Self::F32(v) => v.extend(
                    bytes
                        .chunks_exact(4)
                        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                ),
            }
            left -= n;
        }
        let mut extra = [0u8; 1];
        if input.read(&mut extra)? != 0 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "more values than the mosaic has photosites",
            ));
        }
        Ok(out)
    }
}

/// A raw file's active area as stored (cropped to an even size, as both layouts are), with the
/// levels and Bayer phase a decode reads it with (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct RawMosaic {
    /// What the file is.
    pub kind: FileKind,
    /// Photosites per row (even).
    pub width_px: u32,
    /// Rows (even).
    pub height_px: u32,
    /// `width_px * height_px` stored values, row-major.
    pub samples: MosaicSamples,
    /// The Bayer phase at the top-left photosite.
    pub cfa: BayerPhase,
    /// Black level per CFA position of the quad, reading order (as used).
    pub black_levels: [f64; 4],
    /// White level (as used).
    pub white_level: f64,
    /// Bits per stored sample the file declares.
    pub bits_per_sample: u32,
    /// Full sensor width in photosites (masked areas included).
    pub sensor_width_px: u32,
    /// Full sensor height in photosites.
    pub sensor_height_px: u32,
    /// Left edge of the active area in sensor photosites.
    pub active_left_px: u32,
    /// Top edge of the active area in sensor photosites.
    pub active_top_px: u32,
}

impl RawMosaic {
    /// The frame [`crate::decode_raw`] gives for the same file in `layout`, value for value.
    pub fn frame(&self, layout: RawLayout) -> RawFrame {
        let (w, h) = (self.width_px as usize, self.height_px as usize);
        let sensor = Sensor {
            kind: self.kind,
            width: w,
            height: h,
            bits_per_sample: self.bits_per_sample as usize,
        };
        let g = Geometry {
            left: 0,
            top: 0,
            aw: w,
            ah: h,
            phase: self.cfa,
        };
        let (b, wl) = (self.black_levels, self.white_level);
        let mut f = match &self.samples {
            MosaicSamples::U16(d) => assemble(d, &sensor, &g, b, wl, layout),
            MosaicSamples::F32(d) => assemble(d, &sensor, &g, b, wl, layout),
        };
        f.sensor_width_px = self.sensor_width_px;
        f.sensor_height_px = self.sensor_height_px;
        f.active_left_px = self.active_left_px;
        f.active_top_px = self.active_top_px;
        f
    }

    /// Row `y` of the photosite image's values: each photosite's own channel, normalised as
    /// [`crate::decode_photosites`] normalises it, into `out` (`width_px` long; a shorter
    /// `out` gets the row's first values, a row past the end leaves `out` as it is).
    pub fn photosite_row(&self, y: usize, out: &mut [f32]) {
        let w = self.width_px as usize;
        if y >= self.height_px as usize {
            return;
        }
        let levels = self.levels();
        let ky = (y % 2) * 2;
        match &self.samples {
            MosaicSamples::U16(d) => row_values(&levels, &d[y * w..(y + 1) * w], ky, out),
            MosaicSamples::F32(d) => row_values(&levels, &d[y * w..(y + 1) * w], ky, out),
        }
    }

    /// The channel (0 red, 1 green, 2 blue) photosite `(x, y)` measures.
    pub const fn channel_at(&self, x: usize, y: usize) -> usize {
        self.cfa.colour_at(x, y).dng_code() as usize
    }

    fn levels(&self) -> QuadLevels {
        QuadLevels::new(self.black_levels, self.white_level, self.cfa)
    }
}

fn row_values<T: Copy + Into<f64>>(levels: &QuadLevels, row: &[T], ky: usize, out: &mut [f32]) {
    for (x, (o, &raw)) in out.iter_mut().zip(row).enumerate() {
        *o = levels.value(ky + x % 2, raw.into());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mosaic(samples: MosaicSamples) -> RawMosaic {
        RawMosaic {
            kind: FileKind::Dng,
            width_px: 4,
            height_px: 2,
            samples,
            cfa: BayerPhase::Grbg,
            black_levels: [10.0, 11.0, 12.0, 13.0],
            white_level: 1000.0,
            bits_per_sample: 10,
            sensor_width_px: 8,
            sensor_height_px: 6,
            active_left_px: 2,
            active_top_px: 1,
        }
    }

    #[test]
    fn photosite_rows_are_the_photosite_frames_values() {
        let m = mosaic(MosaicSamples::U16(vec![10, 500, 999, 1000, 13, 0, 700, 64]));
        let f = m.frame(RawLayout::Photosite);
        assert_eq!((f.sensor_width_px, f.active_left_px), (8, 2));
        let mut row = [0.0f32; 4];
        for y in 0..2 {
            m.photosite_row(y, &mut row);
            for (x, v) in row.iter().enumerate() {
                let px = f.rgb[y * 4 + x];
                assert_eq!(px[m.channel_at(x, y)].to_bits(), v.to_bits(), "({x}, {y})");
            }
        }
    }

    #[test]
    fn samples_round_trip_and_a_short_or_long_input_is_refused() {
        for s in [
            MosaicSamples::U16(vec![1, 2, 65535, 7]),
            MosaicSamples::F32(vec![0.5, -1.0, f32::NAN, 3.0]),
        ] {
            let mut bytes = Vec::new();
            s.write_le(&mut bytes).expect("write");
            let back =
                MosaicSamples::read_le(s.sample_type(), 4, &mut bytes.as_slice()).expect("read");
            let mut again = Vec::new();
            back.write_le(&mut again).expect("write");
            assert_eq!(bytes, again);
            assert!(MosaicSamples::read_le(s.sample_type(), 5, &mut bytes.as_slice()).is_err());
            assert!(MosaicSamples::read_le(s.sample_type(), 3, &mut bytes.as_slice()).is_err());
        }
    }
}
