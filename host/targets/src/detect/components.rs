//! Step 2 of the detector: the dark pixels' components of plausible size, and their outer
//! contours.
//!
//! First the 4-connected components (union-find), so that a border touching dark surroundings
//! (a shadow, a dark band, a neighbour) only diagonally through its thin white ring stays apart
//! from them; then the 8-connected unions of small 4-connected components (at most
//! [`MAX_JOIN_PX`] pixels each), so that the border of a small blurred tag whose pixels meet
//! only diagonally is whole. A union is not tried when one of its parts already decoded (the
//! orchestrator's part). The outer contour of each is traced (Moore neighbourhood tracing).

use crate::detect::types::DetectorConfig;
use glam::DVec2;

/// Largest 4-connected component (pixels) that is joined to its diagonal neighbours: the
/// black border of a tag with cells under 3 px (side under 24 px) holds at most
/// `7/16 · 24² ≈ 250` px, so this leaves ample room while keeping the large dark regions of a
/// scene (hair, shadow) out of the join.
pub const MAX_JOIN_PX: usize = 2048;

/// The dark pixels' components: 4-connected, and the 8-connected ones that join several of
/// them.
pub(crate) struct Components {
    /// Per pixel, the index of its 4-connected component in `stats` (`u32::MAX` for pixels
    /// that are not dark). Indices follow the components' first pixels in raster order.
    comp_of: Vec<u32>,
    /// Pixel count and bounding box of each 4-connected component.
    stats: Vec<CompStats>,
    /// Per 4-connected component, the first (lowest) index of the 8-connected group it is in.
    pub(crate) group_of: Vec<u32>,
    /// The 8-connected groups of more than one component.
    groups: Vec<CompStats>,
}

impl Components {
    /// Labels the dark pixels (union-find, 4-connected), then joins the small components that
    /// touch diagonally.
    pub(crate) fn new(dark: &[bool], w: usize, h: usize) -> Self {
        let mut comp_of = root_labels(dark, w, h);
        let stats = compact_labels(&mut comp_of, w, h);
        let (group_of, groups) = diagonal_groups(&comp_of, &stats, w, h);
        Self {
            comp_of,
            stats,
            group_of,
            groups,
        }
    }

    /// The components that can be a tag's border, as `(stats, index, grouped)`: the
    /// 4-connected ones first (a border touching dark surroundings only diagonally stays apart
    /// from them), then the 8-connected groups of small ones (a small blurred border whose
    /// pixels meet only diagonally), a group's index that of its first component.
    pub(crate) fn candidates(
        &self,
        w: usize,
        h: usize,
        cfg: &DetectorConfig,
    ) -> Vec<(CompStats, u32, bool)> {
        let singles = self
            .stats
            .iter()
            .enumerate()
            .filter(|(_, c)| c.plausible(w, h, cfg))
            .map(|(k, c)| (*c, k as u32, false));
        let groups = self
            .groups
            .iter()
            .filter(|c| c.plausible(w, h, cfg))
            .map(|c| (*c, self.comp_of[c.root as usize], true));
        singles.chain(groups).collect()
    }

    /// The outer contour of candidate `k` (a group when `grouped`), see [`Self::candidates`].
    pub(crate) fn contour(
        &self,
        comp: &CompStats,
        k: u32,
        grouped: bool,
        w: usize,
        h: usize,
    ) -> Vec<DVec2> {
        if grouped {
            trace_contour(|i| self.in_group(i, k), w, h, comp)
        } else {
            trace_contour(|i| self.in_component(i, k), w, h, comp)
        }
    }

    /// Whether pixel `i` belongs to the 4-connected component of index `k`.
    fn in_component(&self, i: usize, k: u32) -> bool {
        self.comp_of[i] == k
    }

    /// Whether pixel `i` belongs to the 8-connected group whose first component is `g`.
    fn in_group(&self, i: usize, g: u32) -> bool {
        let k = self.comp_of[i];
        k != u32::MAX && self.group_of[k as usize] == g
    }
}

/// Per pixel, the root pixel of its 4-connected component of dark pixels (union-find; the
/// root is the component's first pixel in raster order), `u32::MAX` for pixels that are not
/// dark.
fn root_labels(dark: &[bool], w: usize, h: usize) -> Vec<u32> {
    let mut labels: Vec<u32> = dark
        .iter()
        .enumerate()
        .map(|(i, &d)| if d { i as u32 } else { u32::MAX })
        .collect();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if labels[i] == u32::MAX {
                continue;
            }
            if x > 0 && labels[i - 1] != u32::MAX {
                union(&mut labels, i as u32, (i - 1) as u32);
            }
            if y > 0 && labels[i - w] != u32::MAX {
                union(&mut labels, i as u32, (i - w) as u32);
            }
        }
    }
    for i in 0..w * h {
        if labels[i] != u32::MAX {
            labels[i] = find(&mut labels, i as u32);
        }
    }
    labels
}

/// Turns root labels into component indices, in place, and returns each component's pixel
/// count and bounding box. A root is its component's first pixel in raster order, so the scan
/// converts it (root pixel -> component index) before any other pixel of the component reads
/// it.
fn compact_labels(labels: &mut [u32], w: usize, h: usize) -> Vec<CompStats> {
    let mut stats: Vec<CompStats> = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let r = labels[i];
            if r == u32::MAX {
                continue;
            }
            let k = if r as usize == i {
                stats.push(CompStats {
                    root: i as u32,
                    count: 0,
                    x0: x,
                    x1: x,
                    y0: y,
                    y1: y,
                });
                stats.len() - 1
            } else {
                labels[r as usize] as usize
            };
            labels[i] = k as u32;
            let e = &mut stats[k];
            e.count += 1;
            e.x0 = e.x0.min(x);
            e.x1 = e.x1.max(x);
            e.y1 = y;
        }
    }
    stats
}

/// Diagonal joins of small components (union-find over component indices): per component, the
/// first component of its 8-connected group, and the groups of more than one component.
fn diagonal_groups(
    comp_of: &[u32],
    stats: &[CompStats],
    w: usize,
    h: usize,
) -> (Vec<u32>, Vec<CompStats>) {
    let mut group_of: Vec<u32> = (0..stats.len() as u32).collect();
    // One byte per component: the join pass reads it for every dark pixel.
    let small_flag: Vec<bool> = stats.iter().map(|c| c.count <= MAX_JOIN_PX).collect();
    let small = |k: u32| small_flag[k as usize];
    let mut any = false;
    for y in 1..h {
        for x in 0..w {
            let i = y * w + x;
            let a = comp_of[i];
            if a == u32::MAX || !small(a) {
                continue;
            }
            for j in [x.checked_sub(1), (x + 1 < w).then_some(x + 1)]
                .into_iter()
                .flatten()
                .map(|xj| i - w - x + xj)
            {
                let c = comp_of[j];
                if c != u32::MAX && c != a && small(c) {
                    union(&mut group_of, a, c);
                    any = true;
                }
            }
        }
    }
    let mut groups: Vec<CompStats> = Vec::new();
    if any {
        let mut slot = vec![u32::MAX; stats.len()];
        for k in 0..stats.len() {
            let g = find(&mut group_of, k as u32) as usize;
            group_of[k] = g as u32;
            if g == k {
                continue;
            }
            if slot[g] == u32::MAX {
                slot[g] = groups.len() as u32;
                groups.push(stats[g]);
            }
            groups[slot[g] as usize].join(&stats[k]);
        }
    }
    (group_of, groups)
}

/// Pixel count and bounding box of a component.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CompStats {
    /// The first pixel in raster order (where contour tracing starts).
    root: u32,
    count: usize,
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
}

impl CompStats {
    fn join(&mut self, o: &CompStats) {
        self.count += o.count;
        self.x0 = self.x0.min(o.x0);
        self.x1 = self.x1.max(o.x1);
        self.y0 = self.y0.min(o.y0);
        self.y1 = self.y1.max(o.y1);
    }

    /// Whether the component can be a tag's black border: a fraction of the smallest tag's
    /// area (the border ring alone covers 7/16 of the square) and a bounding box that can hold a
    /// tag but not the whole image.
    fn plausible(&self, w: usize, h: usize, cfg: &DetectorConfig) -> bool {
        let min_side = cfg.min_side_px.max(4.0);
        let bw = (self.x1 - self.x0 + 1) as f64;
        let bh = (self.y1 - self.y0 + 1) as f64;
        bw.max(bh) >= min_side
            && bw.min(bh) >= 0.25 * min_side
            && self.count as f64 >= 0.3 * min_side * min_side
            && bw < w as f64
            && bh < h as f64
    }
}

fn find(p: &mut [u32], mut i: u32) -> u32 {
    let mut root = i;
    while p[root as usize] != root {
        root = p[root as usize];
    }
    while p[i as usize] != root {
        let next = p[i as usize];
        p[i as usize] = root;
        i = next;
    }
    root
}

fn union(p: &mut [u32], a: u32, b: u32) {
    let ra = find(p, a);
    let rb = find(p, b);
    if ra != rb {
        // Keep the smaller index as root: the root is then the first pixel in raster order,
        // which is where contour tracing starts.
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        p[hi as usize] = lo;
    }
}

/// Moore-neighbourhood tracing of the outer contour of the pixels for which `member` holds
/// (by pixel index), starting at their first pixel in raster order, `comp.root`.
fn trace_contour(
    member: impl Fn(usize) -> bool,
    w: usize,
    h: usize,
    comp: &CompStats,
) -> Vec<DVec2> {
    const DIRS: [(i64, i64); 8] = [
        (1, 0),
        (1, 1),
        (0, 1),
        (-1, 1),
        (-1, 0),
        (-1, -1),
        (0, -1),
        (1, -1),
    ];
    let inside = |x: i64, y: i64| -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < w
            && (y as usize) < h
            && member(y as usize * w + x as usize)
    };
    let start = (
        (comp.root as usize % w) as i64,
        (comp.root as usize / w) as i64,
    );
    let dir_of = |from: (i64, i64), to: (i64, i64)| -> usize {
        let d = (to.0 - from.0, to.1 - from.1);
        DIRS.iter().position(|&e| e == d).unwrap_or(4)
    };
    let step = |p: (i64, i64), back: (i64, i64)| -> Option<((i64, i64), (i64, i64))> {
        let db = dir_of(p, back);
        for k in 1..=8 {
            let d = (db + k) % 8;
            let q = (p.0 + DIRS[d].0, p.1 + DIRS[d].1);
            if inside(q.0, q.1) {
                let pd = (d + 7) % 8;
                return Some((q, (p.0 + DIRS[pd].0, p.1 + DIRS[pd].1)));
            }
        }
        None
    };
    let mut contour = vec![DVec2::new(start.0 as f64, start.1 as f64)];
    let Some((first, mut back)) = step(start, (start.0 - 1, start.1)) else {
        return contour;
    };
    let mut p = first;
    let limit = 4 * comp.count + 16;
    while contour.len() < limit {
        if p == start {
            // Jacob's criterion variant: stop when leaving the start the same way as at first.
            if let Some((q, _)) = step(p, back) {
                if q == first {
                    break;
                }
            }
        }
        contour.push(DVec2::new(p.0 as f64, p.1 as f64));
        let Some((q, b)) = step(p, back) else { break };
        p = q;
        back = b;
    }
    contour
}
