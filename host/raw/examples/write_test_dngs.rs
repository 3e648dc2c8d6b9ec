//! Writes a set of test DNGs for the LibRaw peer check (`scripts/peers/dng_rawpy_check.py`).
//!
//! ```text
//! cargo run --release -p skinbrdf-raw --example write_test_dngs -- DIR [--big]
//! ```
//!
//! For every Bayer phase and bit depth (12, 14, 16) a small sensor with its active area at an
//! even and at an odd offset, per-position black levels and a white level below full scale; with `--big` also a
//! 6000x4000 14-bit sensor (the benchmark file). Beside each `NAME.dng` it writes `NAME.u16`
//! (the photosites, little-endian, row-major, full sensor) and lists every file with its
//! expected layout and levels in `DIR/manifest.json`.

use std::fmt::Write as _;
use std::path::PathBuf;

use skinbrdf_raw::dng::{write_dng, DngImage};
use skinbrdf_raw::{BayerPhase, CaptureTime, LocalDateTime};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().ok_or("usage: write_test_dngs DIR [--big]")?);
    let big = args.any(|a| a == "--big");
    std::fs::create_dir_all(&dir)?;
    let mut cases: Vec<(String, u32, u32, BayerPhase, u32, [u32; 4])> = Vec::new();
    for phase in BayerPhase::ALL {
        for bits in [12u32, 14, 16] {
            // Width a multiple of 4 so every depth packs whole bytes; the active area at an
            // even offset (4, 2) and at an odd one (3, 1).
            for (tag, area) in [("even", [2, 4, 40, 62]), ("odd", [1, 3, 41, 63])] {
                cases.push((
                    format!("{}_{bits}_{tag}", phase.name().to_ascii_lowercase()),
                    64,
                    42,
                    phase,
                    bits,
                    area,
                ));
            }
        }
    }
    if big {
        cases.push((
            "big_6000x4000_14".into(),
            6000,
            4000,
            BayerPhase::Rggb,
            14,
            [0, 0, 4000, 6000],
        ));
    }
    let mut manifest = String::from("[\n");
    for (k, (name, w, h, phase, bits, area)) in cases.iter().enumerate() {
        let max = (1u32 << bits) - 1;
        let white = max - 3;
        let base = (max / 64) as u16;
        let black = [base, base + 3, base + 5, base + 8];
        // A deterministic pattern spanning below black to above white.
        let mut s = 0x9E37_79B9_7F4A_7C15u64 ^ (k as u64);
        let data: Vec<u16> = (0..w * h)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s % u64::from(max + 1)) as u16
            })
            .collect();
        let mut img = DngImage::new(*w, *h, *phase, *bits, data);
        img.active_area = Some(*area);
        img.black_levels = black;
        img.white_level = white as u16;
        img.make = "Skinbrdf".into();
        img.model = "Peer Check".into();
        img.exposure_time_s = Some(1.0 / 125.0);
        img.f_number = Some(8.0);
        img.iso = Some(100);
        img.capture_time = Some(CaptureTime {
            local: LocalDateTime {
                year: 2025,
                month: 6,
                day: 1,
                hour: 12,
                minute: 0,
                second: k as u8 % 60,
            },
            subsec_digits: Some("25".into()),
            utc_offset_min: Some(60),
        });
        img.image_number = Some(k as u32 + 1);
        write_dng(&dir.join(format!("{name}.dng")), &img)?;
        let bytes: Vec<u8> = img.data.iter().flat_map(|v| v.to_le_bytes()).collect();
        skinbrdf_core::fsio::write_atomic(&dir.join(format!("{name}.u16")), &bytes)?;
        let sep = if k + 1 == cases.len() { "" } else { "," };
        writeln!(
            manifest,
            "  {{\"name\": \"{name}\", \"width\": {w}, \"height\": {h}, \"pattern\": \"{}\", \"bits\": {bits}, \
             \"active_area\": [{}, {}, {}, {}], \"black_levels\": [{}, {}, {}, {}], \"white_level\": {white}}}{sep}",
            phase.name(),
            area[0], area[1], area[2], area[3],
            black[0], black[1], black[2], black[3],
        )?;
        eprintln!("wrote {}", dir.join(format!("{name}.dng")).display());
    }
    manifest.push_str("]\n");
    skinbrdf_core::fsio::write_atomic(&dir.join("manifest.json"), manifest.as_bytes())?;
    println!("{}", dir.join("manifest.json").display());
    Ok(())
}
