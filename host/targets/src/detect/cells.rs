//! The tag's 10 x 10 cell grid in the tag frame (`[-1, 1]²` at the border's outer edge, the
//! white ring one cell beyond it), and the grey levels read through a quad's homography.

use crate::homography::apply_h;
use crate::image::GrayF32;
use crate::tag36h11;
use glam::{DMat3, DVec2, DVec3};

/// The tag square's corners in quad order (those of
/// [`square_to_quad`](crate::homography::square_to_quad)).
pub(crate) const SQUARE: [(f64, f64); 4] = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];

/// Mean grey value of cell (row, col) of the 10 x 10 grid: the cell centre, averaged with 3 x 3
/// points in its middle when cells are large enough (`spread` in cell units, 0 = centre only).
pub(crate) fn sample_cell(
    img: &GrayF32,
    h: &DMat3,
    row: usize,
    col: usize,
    spread: f64,
) -> Option<f64> {
    let cw = 2.0 / tag36h11::WIDTH_AT_BORDER as f64;
    let u0 = -1.0 + (col as f64 - 0.5) * cw;
    let v0 = -1.0 + (row as f64 - 0.5) * cw;
    let offs: &[f64] = if spread > 0.0 {
        &[-1.0, 0.0, 1.0]
    } else {
        &[0.0]
    };
    let mut acc = 0.0;
    let mut n = 0.0;
    for sy in offs {
        for sx in offs {
            let p = apply_h(h, DVec2::new(u0 + sx * spread * cw, v0 + sy * spread * cw));
            if !img.contains(p, 0.0) {
                continue;
            }
            acc += img.bilinear(p);
            n += 1.0;
        }
    }
    (n > 0.0).then(|| acc / n)
}

/// Least-squares plane `a + b u + c v` through `(u, v, value)`; falls back to the mean when the
/// points do not span the plane.
pub(crate) fn fit_plane(pts: &[(f64, f64, f64)]) -> Option<[f64; 3]> {
    if pts.is_empty() {
        return None;
    }
    let mean = pts.iter().map(|p| p.2).sum::<f64>() / pts.len() as f64;
    let mut ata = DMat3::ZERO;
    let mut atb = DVec3::ZERO;
    for &(u, v, z) in pts {
        let r = DVec3::new(1.0, u, v);
        ata += DMat3::from_cols(r * r.x, r * r.y, r * r.z);
        atb += r * z;
    }
    if pts.len() < 6 || ata.determinant().abs() < 1e-9 {
        return Some([mean, 0.0, 0.0]);
    }
    let s = ata.inverse() * atb;
    Some([s.x, s.y, s.z])
}

pub(crate) fn cell_uv(row: usize, col: usize) -> (f64, f64) {
    let cw = 2.0 / tag36h11::WIDTH_AT_BORDER as f64;
    (
        -1.0 + (col as f64 - 0.5) * cw,
        -1.0 + (row as f64 - 0.5) * cw,
    )
}
