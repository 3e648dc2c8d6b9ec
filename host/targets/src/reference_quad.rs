//! The AprilTag reference library's quad stage (AprilTag 3, `quad_decimate = 1`,
//! `quad_sigma = 0`, `refine_edges = 0`), reimplemented so that its corners can be reported
//! next to ours ([`crate::CornerModel::BinaryBoundary`]).
//!
//! Why it exists: the reference library's published detections (for instance the `.txt` files
//! shipped with its test photos) are this stage's corners. Reproducing them lets a user compare a
//! session with a run of that library like for like, and lets the tests check the rest of our
//! detector (IDs, which tags are found) against it without the estimator's differences. It is
//! *not* the accurate estimate: the default edge refinement is (docs/benchmarks-poses.md).
//!
//! # Method (each step as the library does it, in integer grey levels)
//!
//! 1. **Threshold.** Grey levels `0..=255`; 4 x 4 px tiles (the partial ones at the right and
//!    bottom borders take the last full tile's statistics); per tile the minimum and maximum,
//!    each dilated over the 3 x 3 neighbouring tiles; a tile whose `max - min` is below
//!    [`MIN_WHITE_BLACK_DIFF`] is unclassified (127), otherwise each pixel is light (255) when
//!    above `min + (max - min) / 2` (integer division) and dark (0) otherwise.
//! 2. **Components.** Union-find over equal classified pixels: dark pixels 4-connected, light
//!    pixels 8-connected (so a dark border touching a dark background only diagonally stays
//!    apart from it); the first and last columns are only reached as neighbours.
//! 3. **Boundary clusters.** For every dark/light pair of 4- or diagonal neighbours whose
//!    components both have at least [`MIN_COMPONENT_PX`] pixels, the point half-way between the
//!    two pixels joins the cluster of that (dark component, light component) pair, with the
//!    direction towards the light pixel.
//! 4. **Quad fit per cluster.** The points are ordered by angle about the (slightly jittered)
//!    centre of their bounding box, duplicates removed, and each gets the weight
//!    `|grey gradient| + 1` (central differences at the pixel holding it). The four corners are
//!    the combination of four of the (at most [`MAX_MAXIMA`]) maxima of the smoothed local
//!    line-fit error that minimises the total error of the four weighted total-least-squares
//!    lines between them; lines with a mean squared error over [`MAX_LINE_FIT_MSE`], adjacent
//!    lines within 10° of parallel, quads smaller than the tag's 8 px border square, or not
//!    turning the right way, are rejected. Corners are the intersections of adjacent lines.
//!
//! The library puts pixel centres at half-integers; the corners returned here are in the
//! project's convention (integer = pixel centre), i.e. the library's minus 0.5 px.

use crate::image::GrayF32;
use glam::DVec2;
use std::collections::HashMap;

/// Threshold tile size, pixels (the library's `tilesz`).
pub const TILE_PX: usize = 4;
/// Smallest `max - min` of a tile neighbourhood that is thresholded, grey levels
/// (`qtp.min_white_black_diff`).
pub const MIN_WHITE_BLACK_DIFF: i32 = 5;
/// Smallest component whose boundary points are clustered, pixels.
pub const MIN_COMPONENT_PX: u32 = 25;
/// Fewest distinct boundary points a quad is fitted to.
pub const MIN_CLUSTER_POINTS: usize = 24;
/// Most maxima of the line-fit error tried as corners (`qtp.max_nmaxima`).
pub const MAX_MAXIMA: usize = 10;
/// Largest mean squared error of a side's line fit, px² in half-pixel units
/// (`qtp.max_line_fit_mse`).
pub const MAX_LINE_FIT_MSE: f64 = 10.0;
/// Cosine of the smallest angle between adjacent sides, 10° (`qtp.cos_critical_rad`).
pub const COS_CRITICAL: f64 = 0.984_807_753_012_208;
/// tag36h11's black-border width in cells (`width_at_border`), the smallest quad accepted.
pub const TAG_WIDTH_AT_BORDER: i32 = 8;

const UNCLASSIFIED: u8 = 127;

/// Every quad the library's quad stage finds in `img`, corners in the project's pixel
/// convention, in the library's order (before decoding rotates them).
pub fn reference_quads(img: &GrayF32) -> Vec<[DVec2; 4]> {
    let (w, h) = (img.width, img.height);
    if w < 2 * TILE_PX || h < 2 * TILE_PX {
        return Vec::new();
    }
    let grey: Vec<u8> = img
        .data
        .iter()
        .map(|&v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
        .collect();
    let thr = threshold(&grey, w, h);
    let mut uf = components(&thr, w, h);
    let clusters = boundary_clusters(&thr, w, h, &mut uf);
    let max_points = 3 * (2 * w + 2 * h);
    // In a fixed order (the map's is arbitrary); each cluster is handed to its fit by value.
    let mut clusters: Vec<((u32, u32), Vec<Pt>)> = clusters.into_iter().collect();
    clusters.sort_unstable_by_key(|(k, _)| *k);
    clusters
        .into_iter()
        .filter_map(|(_, pts)| {
            if pts.len() > max_points {
                return None;
            }
            let q = fit_quad(pts, &grey, w, h)?;
            Some(q.map(|p| p - DVec2::splat(0.5)))
        })
        .collect()
}

fn threshold(grey: &[u8], w: usize, h: usize) -> Vec<u8> {
    let (tw, th) = (w / TILE_PX, h / TILE_PX);
    let mut tmin = vec![255u8; tw * th];
    let mut tmax = vec![0u8; tw * th];
    for ty in 0..th {
        for tx in 0..tw {
            let (mut lo, mut hi) = (255u8, 0u8);
            for dy in 0..TILE_PX {
                let row = (ty * TILE_PX + dy) * w + tx * TILE_PX;
                for &v in &grey[row..row + TILE_PX] {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
            tmin[ty * tw + tx] = lo;
            tmax[ty * tw + tx] = hi;
        }
    }
    let mut nmin = vec![255u8; tw * th];
    let mut nmax = vec![0u8; tw * th];
    for ty in 0..th {
        for tx in 0..tw {
            let (mut lo, mut hi) = (255u8, 0u8);
            for y in ty.saturating_sub(1)..(ty + 2).min(th) {
                for x in tx.saturating_sub(1)..(tx + 2).min(tw) {
                    lo = lo.min(tmin[y * tw + x]);
                    hi = hi.max(tmax[y * tw + x]);
                }
            }
            nmin[ty * tw + tx] = lo;
            nmax[ty * tw + tx] = hi;
        }
    }
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        let ty = (y / TILE_PX).min(th - 1);
        let full_row = y < th * TILE_PX;
        for x in 0..w {
            let tx = (x / TILE_PX).min(tw - 1);
            let (lo, hi) = (i32::from(nmin[ty * tw + tx]), i32::from(nmax[ty * tw + tx]));
            // The contrast floor applies to full tiles only; the partial border tiles are
            // always thresholded.
            let full = full_row && x < tw * TILE_PX;
            out[y * w + x] = if full && hi - lo < MIN_WHITE_BLACK_DIFF {
                UNCLASSIFIED
            } else if i32::from(grey[y * w + x]) > lo + (hi - lo) / 2 {
                255
            } else {
                0
            };
        }
    }
    out
}

/// Union-find with set sizes.
struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }

    fn find(&mut self, mut i: u32) -> u32 {
        while self.parent[i as usize] != i {
            let p = self.parent[i as usize];
            self.parent[i as usize] = self.parent[p as usize];
            i = p;
        }
        i
    }

    fn union(&mut self, a: usize, b: usize) {
        let (mut ra, mut rb) = (self.find(a as u32), self.find(b as u32));
        if ra == rb {
            return;
        }
        if self.size[ra as usize] < self.size[rb as usize] {
            std::mem::swap(&mut ra, &mut rb);
        }
        self.parent[rb as usize] = ra;
        self.size[ra as usize] += self.size[rb as usize];
    }
}

fn components(t: &[u8], w: usize, h: usize) -> UnionFind {
    let mut uf = UnionFind::new(w * h);
    for y in 0..h {
        for x in 1..w - 1 {
            let i = y * w + x;
            let v = t[i];
            if v == UNCLASSIFIED {
                continue;
            }
            let mut link = |j: usize| {
                if t[j] == v {
                    uf.union(i, j);
                }
            };
            link(i - 1);
            if y > 0 {
                link(i - w);
                if v == 255 {
                    link(i - w - 1);
                    link(i - w + 1);
                }
            }
        }
    }
    uf
}

/// A boundary point in half-pixel units (the library's fixed point), with the direction
/// towards the light pixel.
#[derive(Debug, Clone, Copy)]
struct Pt {
    x: u16,
    y: u16,
    gx: i16,
    gy: i16,
    slope: f32,
}

fn boundary_clusters(
    t: &[u8],
    w: usize,
    h: usize,
    uf: &mut UnionFind,
) -> HashMap<(u32, u32), Vec<Pt>> {
    let mut clusters: HashMap<(u32, u32), Vec<Pt>> = HashMap::new();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let v0 = t[y * w + x];
            if v0 == UNCLASSIFIED {
                continue;
            }
            let rep0 = uf.find((y * w + x) as u32);
            if uf.size[rep0 as usize] < MIN_COMPONENT_PX {
                continue;
            }
            for (dx, dy) in [(1i64, 0i64), (0, 1), (-1, 1), (1, 1)] {
                let j = (y as i64 + dy) as usize * w + (x as i64 + dx) as usize;
                let v1 = t[j];
                if i32::from(v0) + i32::from(v1) != 255 {
                    continue;
                }
                let rep1 = uf.find(j as u32);
                if uf.size[rep1 as usize] < MIN_COMPONENT_PX {
                    continue;
                }
                let g = (i32::from(v1) - i32::from(v0)) as i16;
                clusters
                    .entry((rep0.min(rep1), rep0.max(rep1)))
                    .or_default()
                    .push(Pt {
                        x: (2 * x as i64 + dx) as u16,
                        y: (2 * y as i64 + dy) as u16,
                        gx: dx as i16 * g,
                        gy: dy as i16 * g,
                        slope: 0.0,
                    });
            }
        }
    }
    clusters
}

/// Cumulative weighted moments of the ordered points: entry `j` covers points `0..=j`.
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    mx: f64,
    my: f64,
    mxx: f64,
    myy: f64,
    mxy: f64,
    w: f64,
}

impl Moments {
    fn add(self, o: Self) -> Self {
        Self {
            mx: self.mx + o.mx,
            my: self.my + o.my,
            mxx: self.mxx + o.mxx,
            myy: self.myy + o.myy,
            mxy: self.mxy + o.mxy,
            w: self.w + o.w,
        }
    }
    fn sub(self, o: Self) -> Self {
        Self {
            mx: self.mx - o.mx,
            my: self.my - o.my,
            mxx: self.mxx - o.mxx,
            myy: self.myy - o.myy,
            mxy: self.mxy - o.mxy,
            w: self.w - o.w,
        }
    }
}

fn cumulative_moments(pts: &[Pt], grey: &[u8], w: usize, h: usize) -> Vec<Moments> {
    let mut acc = Moments::default();
    pts.iter()
        .map(|p| {
            let x = f64::from(p.x) * 0.5 + 0.5;
            let y = f64::from(p.y) * 0.5 + 0.5;
            let (ix, iy) = (x as usize, y as usize);
            let mut wt = 1.0;
            if ix > 0 && ix + 1 < w && iy > 0 && iy + 1 < h {
                let at = |xx: usize, yy: usize| i32::from(grey[yy * w + xx]);
                let gx = at(ix + 1, iy) - at(ix - 1, iy);
                let gy = at(ix, iy + 1) - at(ix, iy - 1);
                wt = f64::from(gx * gx + gy * gy).sqrt() + 1.0;
            }
            acc = acc.add(Moments {
                mx: wt * x,
                my: wt * y,
                mxx: wt * x * x,
                myy: wt * y * y,
                mxy: wt * x * y,
                w: wt,
            });
            acc
        })
        .collect()
}

/// A fitted line: a point on it, its unit normal, the sum and the mean of the squared errors.
struct LineFit {
    point: DVec2,
    normal: DVec2,
    err: f64,
    mse: f64,
}

/// Weighted total-least-squares line through the points `i0..=i1` (wrapping when `i1 < i0`).
/// As the library, the square roots of the eigen decomposition are taken in single precision
/// and the summed error is `N` times the smallest eigenvalue.
fn fit_line(m: &[Moments], i0: usize, i1: usize) -> LineFit {
    let sz = m.len();
    let (s, n) = if i0 < i1 {
        let s = if i0 > 0 { m[i1].sub(m[i0 - 1]) } else { m[i1] };
        (s, i1 - i0 + 1)
    } else {
        let before = if i0 > 0 {
            m[i0 - 1]
        } else {
            Moments::default()
        };
        (m[sz - 1].sub(before).add(m[i1]), sz - i0 + i1 + 1)
    };
    let ex = s.mx / s.w;
    let ey = s.my / s.w;
    let cxx = s.mxx / s.w - ex * ex;
    let cxy = s.mxy / s.w - ex * ey;
    let cyy = s.myy / s.w - ey * ey;
    let root = f64::from((((cxx - cyy) * (cxx - cyy) + 4.0 * cxy * cxy) as f32).sqrt());
    let eig_small = 0.5 * (cxx + cyy - root);
    let eig = 0.5 * (cxx + cyy + root);
    let (nx1, ny1) = (cxx - eig, cxy);
    let (nx2, ny2) = (cxy, cyy - eig);
    let (m1, m2) = (nx1 * nx1 + ny1 * ny1, nx2 * nx2 + ny2 * ny2);
    let (nx, ny, mm) = if m1 > m2 {
        (nx1, ny1, m1)
    } else {
        (nx2, ny2, m2)
    };
    let len = f64::from((mm as f32).sqrt());
    LineFit {
        point: DVec2::new(ex, ey),
        normal: DVec2::new(nx / len, ny / len),
        err: n as f64 * eig_small,
        mse: eig_small,
    }
}

/// The four point indices where the sides meet (the library's `quad_segment_maxima`).
fn segment_maxima(m: &[Moments]) -> Option<[usize; 4]> {
    let sz = m.len();
    let ksz = (sz / 12).min(20);
    if ksz < 2 {
        return None;
    }
    let raw: Vec<f64> = (0..sz)
        .map(|i| fit_line(m, (i + sz - ksz) % sz, (i + ksz) % sz).err)
        .collect();
    // Low-pass filter, sigma 1 point, cut off at 0.05: 7 taps (single-precision weights).
    const TAPS: usize = 7;
    let f: [f64; TAPS] = std::array::from_fn(|i| {
        let j = i as f64 - (TAPS / 2) as f64;
        f64::from((-j * j / 2.0).exp() as f32)
    });
    let errs: Vec<f64> = (0..sz)
        .map(|iy| {
            (0..TAPS)
                .map(|i| raw[(iy + i + sz - TAPS / 2) % sz] * f[i])
                .sum()
        })
        .collect();
    let mut maxima: Vec<usize> = (0..sz)
        .filter(|&i| errs[i] > errs[(i + 1) % sz] && errs[i] > errs[(i + sz - 1) % sz])
        .collect();
    if maxima.len() < 4 {
        return None;
    }
    if maxima.len() > MAX_MAXIMA {
        let mut sorted: Vec<f64> = maxima.iter().map(|&i| errs[i]).collect();
        sorted.sort_by(|a, b| b.total_cmp(a));
        let cut = sorted[MAX_MAXIMA];
        maxima.retain(|&i| errs[i] > cut);
    }
    let nm = maxima.len();
    let mut best: Option<(f64, [usize; 4])> = None;
    for m0 in 0..nm.saturating_sub(3) {
        let i0 = maxima[m0];
        for m1 in m0 + 1..nm - 2 {
            let i1 = maxima[m1];
            let l01 = fit_line(m, i0, i1);
            if l01.mse > MAX_LINE_FIT_MSE {
                continue;
            }
            for m2 in m1 + 1..nm - 1 {
                let i2 = maxima[m2];
                let l12 = fit_line(m, i1, i2);
                if l12.mse > MAX_LINE_FIT_MSE || l01.normal.dot(l12.normal).abs() > COS_CRITICAL {
                    continue;
                }
                for &i3 in &maxima[m2 + 1..nm] {
                    let l23 = fit_line(m, i2, i3);
                    if l23.mse > MAX_LINE_FIT_MSE {
                        continue;
                    }
                    let l30 = fit_line(m, i3, i0);
                    if l30.mse > MAX_LINE_FIT_MSE {
                        continue;
                    }
                    let err = l01.err + l12.err + l23.err + l30.err;
                    if best.is_none_or(|(b, _)| err < b) {
                        best = Some((err, [i0, i1, i2, i3]));
                    }
                }
            }
        }
    }
    let (err, idx) = best?;
    (err / (sz as f64) < MAX_LINE_FIT_MSE).then_some(idx)
}

/// The library's `fit_quad` for tag36h11 (black border inside a white one), corners in its own
/// pixel convention.
fn fit_quad(mut pts: Vec<Pt>, grey: &[u8], w: usize, h: usize) -> Option<[DVec2; 4]> {
    if pts.len() < MIN_CLUSTER_POINTS {
        return None;
    }
    let (mut xmin, mut xmax, mut ymin, mut ymax) = (pts[0].x, pts[0].x, pts[0].y, pts[0].y);
    for p in &pts[1..] {
        xmin = xmin.min(p.x);
        xmax = xmax.max(p.x);
        ymin = ymin.min(p.y);
        ymax = ymax.max(p.y);
    }
    if (i32::from(xmax) - i32::from(xmin)) * (i32::from(ymax) - i32::from(ymin))
        < TAG_WIDTH_AT_BORDER
    {
        return None;
    }
    // The library jitters the centre a little so that points get more distinct angles.
    let cx = ((f64::from(xmin) + f64::from(xmax)) * 0.5 + 0.05118) as f32;
    let cy = ((f64::from(ymin) + f64::from(ymax)) * 0.5 - 0.028581) as f32;
    let mut dot = 0f32;
    // Monotone pseudo-angle: a quadrant offset plus a slope within the quadrant.
    const QUADRANTS: [[f32; 2]; 2] = [[-131_072.0, 0.0], [262_144.0, 131_072.0]];
    for p in &mut pts {
        let (mut dx, mut dy) = (f32::from(p.x) - cx, f32::from(p.y) - cy);
        dot += dx * f32::from(p.gx) + dy * f32::from(p.gy);
        let quadrant = QUADRANTS[usize::from(dy > 0.0)][usize::from(dx > 0.0)];
        if dy < 0.0 {
            dy = -dy;
            dx = -dx;
        }
        if dx < 0.0 {
            (dx, dy) = (dy, -dx);
        }
        p.slope = quadrant + dy / dx;
    }
    // The black border must be inside the white one (gradients pointing outward).
    if dot < 0.0 {
        return None;
    }
    pts.sort_by(|a, b| a.slope.total_cmp(&b.slope));
    pts.dedup_by(|p, last| p.x == last.x && p.y == last.y);
    if pts.len() < MIN_CLUSTER_POINTS {
        return None;
    }
    let m = cumulative_moments(&pts, grey, w, h);
    let idx = segment_maxima(&m)?;
    let mut lines = Vec::with_capacity(4);
    for i in 0..4 {
        let l = fit_line(&m, idx[i], idx[(i + 1) % 4]);
        if l.mse > MAX_LINE_FIT_MSE {
            return None;
        }
        lines.push(l);
    }
    let mut q = [DVec2::ZERO; 4];
    for i in 0..4 {
        let (a, b) = (&lines[i], &lines[(i + 1) % 4]);
        // a.point + l0 * perp(a) = b.point + l1 * perp(b), perp(n) = (n.y, -n.x).
        let (a00, a01) = (a.normal.y, -b.normal.y);
        let (a10, a11) = (-a.normal.x, b.normal.x);
        let (b0, b1) = (b.point.x - a.point.x, b.point.y - a.point.y);
        let det = a00 * a11 - a10 * a01;
        if det.abs() < 0.001 {
            return None;
        }
        let l0 = (a11 * b0 - a01 * b1) / det;
        q[i] = DVec2::new(a.point.x + l0 * a00, a.point.y + l0 * a10);
    }
    // Too small: the two triangles' areas (Heron) under the tag's border width squared.
    let tri = |p: DVec2, r: DVec2, s: DVec2| {
        let (la, lb, lc) = (p.distance(r), r.distance(s), s.distance(p));
        let hp = 0.5 * (la + lb + lc);
        (hp * (hp - la) * (hp - lb) * (hp - lc)).sqrt()
    };
    let area = tri(q[0], q[1], q[2]) + tri(q[2], q[3], q[0]);
    // (A NaN area, from a degenerate quad, is rejected too.)
    if area.is_nan() || area < f64::from(TAG_WIDTH_AT_BORDER * TAG_WIDTH_AT_BORDER) {
        return None;
    }
    for i in 0..4 {
        let d1 = q[(i + 1) % 4] - q[i];
        let d2 = q[(i + 2) % 4] - q[(i + 1) % 4];
        let cos = d1.dot(d2) / (d1.length_squared() * d2.length_squared()).sqrt();
        if cos.abs() > COS_CRITICAL || d1.x * d2.y < d1.y * d2.x {
            return None;
        }
    }
    Some(q)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::homography::square_to_quad;
    use crate::render::paint_tag;

    #[test]
    fn a_sharp_axis_aligned_tag_gives_its_pixel_boundary() {
        // A 40 px tag with its border on pixel edges: the boundary points lie exactly on the
        // pixel edges. The segments share their end points (the error maxima), which may be a
        // point of the neighbouring side a pixel off the line, so the corners are the square's
        // to a few hundredths of a pixel, not exactly.
        let (w, h) = (120, 100);
        let mut img = GrayF32::new(w, h, vec![1.0; w * h]).expect("image");
        let corners = [
            DVec2::new(39.5, 69.5),
            DVec2::new(79.5, 69.5),
            DVec2::new(79.5, 29.5),
            DVec2::new(39.5, 29.5),
        ];
        let h_img = square_to_quad(&corners).expect("homography");
        assert!(paint_tag(&mut img, &h_img, 7, 0.0, 1.0, 4));
        let quads = reference_quads(&img);
        let outer = quads
            .iter()
            .find(|q| {
                corners
                    .iter()
                    .all(|c| q.iter().any(|p| p.distance(*c) < 0.05))
            })
            .unwrap_or_else(|| panic!("outer quad not found in {quads:?}"));
        for c in corners {
            let d = outer.iter().map(|p| p.distance(c)).fold(f64::MAX, f64::min);
            assert!(d < 0.05, "{c}: {d}");
        }
    }

    #[test]
    fn flat_images_and_tiny_images_give_no_quads() {
        let flat = GrayF32::new(64, 64, vec![0.5; 64 * 64]).expect("image");
        assert!(reference_quads(&flat).is_empty());
        let tiny = GrayF32::new(5, 5, vec![0.0; 25]).expect("image");
        assert!(reference_quads(&tiny).is_empty());
    }
}
