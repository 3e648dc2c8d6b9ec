//! Step 1 of the detector: the adaptive threshold, as the reference library's.
//!
//! The image is cut into tiles of [`DetectorConfig::tile_px`]; each pixel is compared with the
//! mid-level of the minimum and maximum over the 3 x 3 neighbouring tiles. Pixels whose
//! neighbourhood contrast is below [`DetectorConfig::min_contrast`] (relative to the image's
//! range) are left unclassified, so flat regions and uneven flash lighting do not produce
//! spurious components.

use crate::detect::types::DetectorConfig;
use crate::image::GrayF32;

/// Dark pixels of the adaptive threshold (step 1 of the method).
pub(crate) fn threshold(img: &GrayF32, cfg: &DetectorConfig) -> Vec<bool> {
    let (w, h) = (img.width, img.height);
    let ts = cfg.tile_px.max(2);
    let (tw, th) = (w.div_ceil(ts), h.div_ceil(ts));
    let mut tmin = vec![f32::INFINITY; tw * th];
    let mut tmax = vec![f32::NEG_INFINITY; tw * th];
    let (mut gmin, mut gmax) = (f32::INFINITY, f32::NEG_INFINITY);
    for y in 0..h {
        let row = &img.data[y * w..(y + 1) * w];
        let ty = y / ts;
        for (x, &v) in row.iter().enumerate() {
            let t = ty * tw + x / ts;
            tmin[t] = tmin[t].min(v);
            tmax[t] = tmax[t].max(v);
        }
    }
    for (&a, &b) in tmin.iter().zip(&tmax) {
        gmin = gmin.min(a);
        gmax = gmax.max(b);
    }
    let min_diff = cfg.min_contrast * (gmax - gmin).max(1e-12);
    // 3x3 tile dilation of min and max.
    let mut nmin = vec![0f32; tw * th];
    let mut nmax = vec![0f32; tw * th];
    for ty in 0..th {
        for tx in 0..tw {
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (x, y) = (tx as i64 + dx, ty as i64 + dy);
                    if x < 0 || y < 0 || x >= tw as i64 || y >= th as i64 {
                        continue;
                    }
                    let t = y as usize * tw + x as usize;
                    lo = lo.min(tmin[t]);
                    hi = hi.max(tmax[t]);
                }
            }
            nmin[ty * tw + tx] = lo;
            nmax[ty * tw + tx] = hi;
        }
    }
    let mut dark = vec![false; w * h];
    for y in 0..h {
        let ty = y / ts;
        for x in 0..w {
            let t = ty * tw + x / ts;
            let (lo, hi) = (nmin[t], nmax[t]);
            if hi - lo < min_diff {
                continue;
            }
            dark[y * w + x] = img.data[y * w + x] <= 0.5 * (lo + hi);
        }
    }
    dark
}
