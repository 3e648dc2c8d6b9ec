//! A run's decoded raw files, so that each is decoded once per run ([`DecodeCache`]).
//!
//! The first load of a camera raw file decodes it ([`skinbrdf_raw::decode_mosaic`]) and writes
//! its compact mosaic (the active area's stored values: two bytes per photosite of an integer
//! file) to a file of the cache's directory; every later load of the same file with the same
//! level overrides reads that file back instead of decoding again, and computes the image (or
//! the geometry grey, or the input check's statistics) from it with the decoder's own
//! arithmetic, so the values are identical. An entry stands for the file it came from only while
//! that file keeps its length and modification time; otherwise the file is decoded again. A
//! cached file that cannot be read back is decoded again too; a cache that cannot be written
//! is a cache that holds nothing (loads decode as without one).
//!
//! The cache holds the mosaics on disk, not in memory (a 24 MP file's mosaic is 48 MB).
//! Its files are named like the project's temporary files (`.NAME.PID.tmp`), so a run that dies
//! leaves them to the next run's clean-up; the cache removes its files and the directories it
//! made when it is dropped.

use std::collections::HashMap;
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::SystemTime;

use skinbrdf_raw::{MosaicSamples, RawError, RawMosaic, RawOptions};

/// A file's identity as the cache checks it: its length and modification time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Fingerprint {
    len: u64,
    modified: Option<SystemTime>,
}

impl Fingerprint {
    fn of(path: &Path) -> Option<Self> {
        let m = std::fs::metadata(path).ok()?;
        Some(Self {
            len: m.len(),
            modified: m.modified().ok(),
        })
    }
}

/// What the cache keys an entry by: the file and the level overrides it was decoded with.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Key {
    path: PathBuf,
    levels_bits: Option<[u64; 4]>,
    white_bits: Option<u64>,
}

impl Key {
    fn new(path: &Path, opts: &RawOptions) -> Self {
        Self {
            path: path.to_path_buf(),
            levels_bits: opts.black_levels.map(|b| b.map(f64::to_bits)),
            white_bits: opts.white_level.map(f64::to_bits),
        }
    }
}

/// One cached mosaic: where its values are, and everything else about it.
#[derive(Debug)]
struct Entry {
    file: PathBuf,
    source: Fingerprint,
    /// The mosaic with its values left out (an empty vector of their type).
    shape: RawMosaic,
}

/// A run's decoded raw files (see the module docs).
#[derive(Debug)]
pub struct DecodeCache {
    dir: PathBuf,
    /// The directories the cache made (deepest last), removed when it is dropped if empty.
    made: Mutex<Vec<PathBuf>>,
    entries: Mutex<HashMap<Key, Entry>>,
    next: std::sync::atomic::AtomicUsize,
}

impl DecodeCache {
    /// A cache writing its files into `dir` (made when the first file is written).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            made: Mutex::new(Vec::new()),
            entries: Mutex::new(HashMap::new()),
            next: std::sync::atomic::AtomicUsize::new(0),
        }
    }

    /// The directory the cache writes into.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The number of mosaics the cache holds.
    pub fn len(&self) -> usize {
        self.entries.lock().map_or(0, |e| e.len())
    }

    /// True when the cache holds no mosaic.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The mosaic of the raw file at `path` decoded with `opts`: read back from the cache when
    /// it holds the file as it is now, else decoded (and kept).
    pub fn mosaic(&self, path: &Path, opts: &RawOptions) -> Result<RawMosaic, RawError> {
        let key = Key::new(path, opts);
        let now = Fingerprint::of(path);
        if let Some(m) = now.and_then(|fp| self.read_back(&key, fp)) {
            return Ok(m);
        }
        let m = skinbrdf_raw::decode_mosaic(path, opts)?;
        if let Some(fp) = now {
            self.keep(key, fp, &m);
        }
        Ok(m)
    }

    fn read_back(&self, key: &Key, now: Fingerprint) -> Option<RawMosaic> {
        let (file, shape) = {
            let entries = self.entries.lock().ok()?;
            let e = entries.get(key).filter(|e| e.source == now)?;
            (e.file.clone(), e.shape.clone())
        };
        let count = (shape.width_px as usize).checked_mul(shape.height_px as usize)?;
        let mut input = BufReader::new(std::fs::File::open(&file).ok()?);
        let samples =
            MosaicSamples::read_le(shape.samples.sample_type(), count, &mut input).ok()?;
        Some(RawMosaic { samples, ..shape })
    }

    /// Writes `m` to a file of the cache and records it; a failure leaves it out.
    fn keep(&self, key: Key, source: Fingerprint, m: &RawMosaic) {
        if self.make_dir().is_err() {
            return;
        }
        let n = self.next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let file = self
            .dir
            .join(format!(".mosaic-{n:05}.{}.tmp", std::process::id()));
        let written = std::fs::File::create(&file).and_then(|f| {
            let mut w = BufWriter::with_capacity(1 << 20, f);
            m.samples.write_le(&mut w)?;
            w.flush()
        });
        if written.is_err() {
            let _ = std::fs::remove_file(&file);
            return;
        }
        let shape = RawMosaic {
            kind: m.kind,
            width_px: m.width_px,
            height_px: m.height_px,
            samples: match m.samples {
                MosaicSamples::U16(_) => MosaicSamples::U16(Vec::new()),
                MosaicSamples::F32(_) => MosaicSamples::F32(Vec::new()),
            },
            cfa: m.cfa,
            black_levels: m.black_levels,
            white_level: m.white_level,
            bits_per_sample: m.bits_per_sample,
            sensor_width_px: m.sensor_width_px,
            sensor_height_px: m.sensor_height_px,
            active_left_px: m.active_left_px,
            active_top_px: m.active_top_px,
        };
        let old = self.entries.lock().ok().and_then(|mut e| {
            e.insert(
                key,
                Entry {
                    file: file.clone(),
                    source,
                    shape,
                },
            )
        });
        if let Some(old) = old {
            let _ = std::fs::remove_file(old.file);
        }
    }

    /// Makes the cache's directory and records the ones it made.
    fn make_dir(&self) -> std::io::Result<()> {
        if self.dir.is_dir() {
            return Ok(());
        }
        let mut missing: Vec<PathBuf> = self
            .dir
            .ancestors()
            .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
            .map(Path::to_path_buf)
            .collect();
        std::fs::create_dir_all(&self.dir)?;
        missing.reverse();
        if let Ok(mut made) = self.made.lock() {
            made.extend(missing);
        }
        Ok(())
    }
}

impl Drop for DecodeCache {
    fn drop(&mut self) {
        if let Ok(entries) = self.entries.get_mut() {
            for (_, e) in entries.drain() {
                let _ = std::fs::remove_file(e.file);
            }
        }
        if let Ok(made) = self.made.get_mut() {
            for d in made.iter().rev() {
                let _ = std::fs::remove_dir(d);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbrdf_raw::dng::{write_dng, DngImage};
    use skinbrdf_raw::{BayerPhase, RawLayout};

    fn dng(dir: &Path, name: &str, value: u16) -> PathBuf {
        let (w, h) = (24u32, 16u32);
        let data = (0..w * h).map(|i| value + (i % 97) as u16).collect();
        let p = dir.join(name);
        write_dng(&p, &DngImage::new(w, h, BayerPhase::Rggb, 16, data)).expect("write");
        p
    }

    #[test]
    fn a_file_is_decoded_once_and_read_back_identical_until_it_changes() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dng(dir.path(), "a.dng", 1000);
        let cache_dir = dir.path().join("out").join("decoded");
        let cache = DecodeCache::new(&cache_dir);
        let opts = RawOptions::default();
        let first = cache.mosaic(&p, &opts).expect("decode");
        assert_eq!(cache.len(), 1);
        let again = cache.mosaic(&p, &opts).expect("read back");
        assert_eq!(first, again);
        let direct = skinbrdf_raw::decode_raw(&p, &opts, RawLayout::Photosite).expect("decode");
        let from_cache = again.frame(RawLayout::Photosite);
        assert_eq!(
            format!("{:?}", direct.rgb),
            format!("{:?}", from_cache.rgb),
            "NaN-aware: the same bits"
        );
        assert_eq!(direct.saturated, from_cache.saturated);
        // Other levels are another entry.
        let other = RawOptions {
            black_levels: Some([10.0; 4]),
            white_level: Some(60000.0),
        };
        cache.mosaic(&p, &other).expect("decode");
        assert_eq!(cache.len(), 2);
        // A changed file is decoded again.
        std::thread::sleep(std::time::Duration::from_millis(20));
        let _ = dng(dir.path(), "a.dng", 2000);
        let changed = cache.mosaic(&p, &opts).expect("decode");
        assert_ne!(changed, first);
        assert_eq!(cache.len(), 2);
        drop(cache);
        assert!(
            !dir.path().join("out").exists(),
            "the cache removes its files and the directories it made"
        );
    }
}
