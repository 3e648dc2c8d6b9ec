//! Painting tags into images (anti-aliased by supersampling), for tests, benchmarks and the
//! synthetic generator.

use crate::homography::apply_h;
use crate::image::GrayF32;
use crate::tag36h11;
use glam::{DMat3, DVec2};

/// Cell of the 10 x 10 grid at tag-frame point `uv` (`None` outside the tag including its white
/// ring, which spans `[-1.25, 1.25]`).
pub fn tag_value_at(bits: &[[bool; 10]; 10], uv: DVec2) -> Option<bool> {
    let cw = 2.0 / tag36h11::WIDTH_AT_BORDER as f64;
    let col = ((uv.x + 1.0) / cw + 1.0).floor();
    let row = ((uv.y + 1.0) / cw + 1.0).floor();
    if !(0.0..10.0).contains(&col) || !(0.0..10.0).contains(&row) {
        return None;
    }
    Some(bits[row as usize][col as usize])
}

/// Paints tag `id` through `image_from_tag` (a homography from the tag frame to pixels), with
/// `black`/`white` grey levels and `ss x ss` supersampling per pixel (pixel-centre convention:
/// pixel `(i, j)` covers `[i - 0.5, i + 0.5] x [j - 0.5, j + 0.5]`). Returns `false` for an
/// unknown ID or a singular homography.
pub fn paint_tag(
    img: &mut GrayF32,
    image_from_tag: &DMat3,
    id: usize,
    black: f32,
    white: f32,
    ss: usize,
) -> bool {
    let Some(bits) = tag36h11::tag_bits(id) else {
        return false;
    };
    if image_from_tag.determinant().abs() < 1e-15 {
        return false;
    }
    let tag_from_image = image_from_tag.inverse();
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for c in [(-1.25, -1.25), (1.25, -1.25), (1.25, 1.25), (-1.25, 1.25)] {
        let p = apply_h(image_from_tag, DVec2::new(c.0, c.1));
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let x0 = (lo.x.floor() as isize - 1).max(0);
    let y0 = (lo.y.floor() as isize - 1).max(0);
    let x1 = (hi.x.ceil() as isize + 1).min(img.width as isize - 1);
    let y1 = (hi.y.ceil() as isize + 1).min(img.height as isize - 1);
    let ss = ss.max(1);
    for y in y0..=y1 {
        for x in x0..=x1 {
            let mut acc = 0.0f64;
            let mut inside = 0usize;
            for sy in 0..ss {
                for sx in 0..ss {
                    let p = DVec2::new(
                        x as f64 - 0.5 + (sx as f64 + 0.5) / ss as f64,
                        y as f64 - 0.5 + (sy as f64 + 0.5) / ss as f64,
                    );
                    if let Some(w) = tag_value_at(&bits, apply_h(&tag_from_image, p)) {
                        inside += 1;
                        acc += if w { white as f64 } else { black as f64 };
                    }
                }
            }
            if inside > 0 {
                let i = y as usize * img.width + x as usize;
                let bg = img.data[i] as f64;
                let n = (ss * ss) as f64;
                img.data[i] = ((acc + bg * (n - inside as f64)) / n) as f32;
            }
        }
    }
    true
}
