//! Printed sheets of the synthetic rig: several targets on one piece of paper with one layout
//! file, and the ways a real sheet differs from its layout.
//!
//! # Flattening a group of cage targets
//!
//! The reference cage ([`crate::layout::build_rig`]) puts cut-outs on a cylinder about the
//! head's axis, rows at fixed heights, one every `REFERENCE_STEP_DEG` of azimuth. With
//! `targets.reference_sheet_targets = N > 1`, every run of neighbours along a row (consecutive
//! azimuth steps, no candidate left out between them) is cut into groups of `N` (a remainder of
//! at least two makes a smaller sheet; one left over stays a cut-out), and each group is printed
//! on one flat sheet ([`flatten`]):
//!
//! * the sheet's plane passes through the mean of the group's centres; its normal `z` (out of
//!   the paper) is the normalised mean of their outward normals;
//! * the page's up `y` is the world's up (`+z`) projected into the plane, and `x = y × z` is
//!   "right" for a viewer facing the page (the sheet frame of `skinbrdf targets`' layout files);
//! * each target is projected into the plane orthogonally: its centre to the foot of its
//!   perpendicular, its up direction projected; it keeps its printed size (a square in the plane,
//!   not a foreshortened shadow);
//! * the sheet's origin is the centre of its paper: the bounding rectangle, in the plane, of its
//!   targets' papers (each [`PAPER_HALF_EXTENT`] tag half-edges wide: a sheet has no margin
//!   beyond its targets' own white paper).
//!
//! A group is printed only when the result is safe ([`print_cage`]): the flattened targets pass
//! the cage's occlusion checks (the caller's `safe`), their papers do not overlap on the page,
//! and the sheet's paper keeps [`PAPER_CLEARANCE_M`] from every other body's paper in space
//! ([`quad_distance_m`], exact for convex planar quads). Otherwise its targets stay cut-outs.
//!
//! Every cage target leans towards one azimuth (where the flash and the cameras are), so a
//! group's plane faces that way. Behind the head the rows run across that direction and their
//! neighbours flatten with their spacing nearly kept; beside the head a row runs almost along
//! it, the orthogonal projection puts neighbours nearly on top of each other, and those groups
//! stay cut-outs. So only part of the cage is printed on sheets (docs/photogrammetry.md gives
//! the default scene's count).
//!
//! # What a real sheet does that its layout does not say
//!
//! The true position of a layout point `p` (sheet frame, nominal print) is
//!
//! ```text
//! group_from_sheet · fold(k · p),    group_from_sheet = flat pose · R_x(tilt)
//! ```
//!
//! * **tilt** (`studio.sheet_tilt_deg`): the sheet is taped on crooked, turned about its own
//!   horizontal axis (`x`, through its origin) by an angle drawn uniformly in ±tilt from the
//!   scene's seed;
//! * **print scale** `k` (`studio.print_scale`): the printer scaled the page about the sheet's
//!   origin; the targets' printed sizes scale with it;
//! * **fold** (`studio.bent_sheet`): the sheet is folded about its vertical centre line
//!   (`x = 0`): a point at `x` is turned about that line by `−sign(x) · bend/2`, so both
//!   halves' outer edges come towards the viewer and lengths along the paper are kept. A target
//!   the line crosses is folded too: its true corners lie on both halves, and it is rendered
//!   as two half-tags ([`PrintPiece`]);
//! * **wrapped** (`studio.headdress_band`): the headdress is one printed band whose layout is
//!   the band unrolled flat, although on the head it is wrapped round the forehead: no pose
//!   places the layout ([`SheetShape::Wrapped`]).
//!
//! Flat sheets, tilted or scaled, are exactly their layout placed by a pose and a print scale
//! (the rig file's `group_from_sheet` and `print_scale`); folded and wrapped ones are not.

use std::collections::BTreeMap;

use glam::{DMat3, DQuat, DVec2, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinbrdf_core::Pose;
use skinbrdf_session::Target;

use crate::layout::{Layout, PAPER_HALF_EXTENT};

/// Least distance between the papers of two bodies of the cage (sheets or cut-outs), metres:
/// two papers closer than this would touch on their mounts.
pub const PAPER_CLEARANCE_M: f64 = 0.001;
/// How far behind its printed targets a sheet's paper is rendered, metres: the targets are
/// printed on it, and a tenth of a millimetre (a paper's thickness) keeps the ray tracer from
/// choosing between coplanar triangles, far below a pixel's footprint (~0.4 mm).
pub const PAPER_BACKING_OFFSET_M: f64 = 1e-4;
/// Seed salt of the sheets' tilts.
const TILT_SEED_SALT: u64 = 0x7117_5ee7;
/// Name of the headdress band's sheet (`studio.headdress_band`).
pub const HEADDRESS_BAND_NAME: &str = "headdress-band";

/// How a sheet truly lies compared with its flat layout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SheetShape {
    /// Flat: its layout, placed by its pose and print scale, gives the true corners.
    Flat,
    /// Folded about its vertical centre line (see the module docs), degrees.
    Folded {
        /// The angle between the two halves' normals.
        bend_deg: f64,
    },
    /// Wrapped round the head (the headdress band): no pose places its layout.
    Wrapped,
}

/// One printed sheet of the rig.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintedSheet {
    /// Its name (unique in the rig): `cage-<first id>`, or [`HEADDRESS_BAND_NAME`].
    pub name: String,
    /// The group it belongs to (its pose's frame).
    pub layout: Layout,
    /// The nominal layout: its targets in the sheet frame (z = 0), at their nominal printed
    /// sizes, as its layout file states them.
    pub targets: Vec<Target>,
    /// The flat sheet's pose in its group's frame, tilt included (identity for a wrapped one).
    pub group_from_sheet: Pose,
    /// Printed size over the nominal one.
    pub print_scale: f64,
    /// Its tilt about its horizontal axis, degrees (included in `group_from_sheet`).
    pub tilt_deg: f64,
    /// Flat, folded or wrapped.
    pub shape: SheetShape,
    /// Half extents of its paper (nominal), sheet frame, centred on the origin.
    pub paper_half_m: DVec2,
}

impl PrintedSheet {
    /// Whether its layout placed by a pose and a print scale is its true geometry.
    pub fn rigid(&self) -> bool {
        self.shape == SheetShape::Flat
    }

    /// The ids printed on it.
    pub fn ids(&self) -> Vec<u32> {
        self.targets.iter().map(|t| t.id).collect()
    }

    /// Where a layout point (sheet frame, nominal) truly is, group frame (see the module docs;
    /// a wrapped sheet's points are not placed by this).
    pub fn place(&self, p: DVec3) -> DVec3 {
        let scaled = p * self.print_scale;
        self.group_from_sheet.transform_point(self.fold(scaled))
    }

    /// The fold of a (scaled) sheet-frame point: turned about the sheet's y axis by
    /// `−sign(x) · bend/2` (identity for a flat sheet).
    fn fold(&self, p: DVec3) -> DVec3 {
        match self.shape {
            SheetShape::Folded { bend_deg } => fold_rotation(bend_deg, p.x) * p,
            _ => p,
        }
    }

    /// A layout target where it truly is: corners and centre placed, size scaled. A folded
    /// sheet's target states no centre (the corners' mean, as for a session's target: a
    /// folded tag has no one plane its centre would lie in with them).
    pub fn true_target(&self, t: &Target) -> Target {
        Target {
            id: t.id,
            size_m: t.size_m * self.print_scale,
            corners_m: t.corners_m.map(|c| self.place(c)),
            centre_m: self.rigid().then(|| self.place(t.centre())),
        }
    }

    /// How a layout target is printed: one flat piece, or two half-tags when the sheet's fold
    /// crosses its paper.
    pub fn pieces(&self, t: &Target) -> Vec<PrintPiece> {
        let e = PAPER_HALF_EXTENT;
        let whole = |side_x: f64, u_range: [f64; 2]| {
            let r = match self.shape {
                SheetShape::Folded { bend_deg } => fold_rotation(bend_deg, side_x),
                _ => DQuat::IDENTITY,
            };
            let put = |p: DVec3| {
                self.group_from_sheet
                    .transform_point(r * (p * self.print_scale))
            };
            PrintPiece {
                square: Target {
                    id: t.id,
                    size_m: t.size_m * self.print_scale,
                    corners_m: t.corners_m.map(put),
                    centre_m: Some(put(t.centre())),
                },
                u_range,
            }
        };
        let SheetShape::Folded { .. } = self.shape else {
            return vec![whole(0.0, [-e, e])];
        };
        // The fold line x = 0 in the tag's own coordinate u (half-edges along its x axis).
        let c = t.centre();
        let x_axis = (t.corners_m[1] - t.corners_m[0]).normalize_or_zero();
        let half = 0.5 * t.size_m;
        if x_axis.x.abs() < 1e-12 {
            return vec![whole(c.x, [-e, e])];
        }
        let u0 = -c.x / (half * x_axis.x);
        if u0 <= -e || u0 >= e {
            return vec![whole(c.x, [-e, e])];
        }
        // The side of negative u lies at x < 0 when the tag's x axis points along the sheet's.
        let (neg_side, pos_side) = if x_axis.x > 0.0 {
            (-1.0, 1.0)
        } else {
            (1.0, -1.0)
        };
        vec![whole(neg_side, [-e, u0]), whole(pos_side, [u0, e])]
    }

    /// Its paper (group frame): one quad, or one per half of a folded sheet; corners in order
    /// round the outline.
    pub fn paper_quads(&self) -> Vec<[DVec3; 4]> {
        let DVec2 { x: hx, y: hy } = self.paper_half_m;
        let quad = |x0: f64, x1: f64| {
            [
                DVec3::new(x0, hy, 0.0),
                DVec3::new(x1, hy, 0.0),
                DVec3::new(x1, -hy, 0.0),
                DVec3::new(x0, -hy, 0.0),
            ]
        };
        let halves = match self.shape {
            SheetShape::Folded { .. } => vec![quad(-hx, 0.0), quad(0.0, hx)],
            _ => vec![quad(-hx, hx)],
        };
        halves
            .into_iter()
            .map(|q| {
                // Points on the fold line (x = 0) belong to both halves; each half is folded
                // by its own side's rotation.
                let side = q[0].x + q[1].x;
                let r = match self.shape {
                    SheetShape::Folded { bend_deg } => fold_rotation(bend_deg, side),
                    _ => DQuat::IDENTITY,
                };
                q.map(|p| {
                    self.group_from_sheet
                        .transform_point(r * (p * self.print_scale))
                })
            })
            .collect()
    }

    /// The outward normal of its paper (of the flat sheet; a folded sheet's halves differ by
    /// the bend).
    pub fn normal(&self) -> DVec3 {
        self.group_from_sheet.transform_vector(DVec3::Z)
    }
}

/// The rotation of a folded sheet's half on the side of `x` (see the module docs).
fn fold_rotation(bend_deg: f64, x: f64) -> DQuat {
    let side = if x < 0.0 { -1.0 } else { 1.0 };
    DQuat::from_rotation_y(-side * 0.5 * bend_deg.to_radians())
}

/// A flat piece of a printed target: the whole tag's square in the piece's plane, of which
/// only the part between `u_range` (tag half-edges along its x axis, paper at
/// ±[`PAPER_HALF_EXTENT`]) is paper.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintPiece {
    /// The tag's square in the piece's plane (group frame).
    pub square: Target,
    /// The piece's extent along the tag's x axis, tag half-edges.
    pub u_range: [f64; 2],
}

/// How a target is printed when that is not a flat square of its own code.
#[derive(Debug, Clone, PartialEq)]
pub struct TagPrint {
    /// The tag36h11 code printed (another target's for a duplicated id).
    pub code: u32,
    /// Its flat pieces (two for a target a fold crosses).
    pub pieces: Vec<PrintPiece>,
}

impl TagPrint {
    /// A target printed flat with its own code.
    pub fn plain(t: &Target) -> Self {
        Self {
            code: t.id,
            pieces: vec![PrintPiece {
                square: *t,
                u_range: [-PAPER_HALF_EXTENT, PAPER_HALF_EXTENT],
            }],
        }
    }

    /// The same print moved by a rigid motion.
    pub fn moved(&self, by: &Pose) -> Self {
        Self {
            code: self.code,
            pieces: self
                .pieces
                .iter()
                .map(|p| PrintPiece {
                    square: move_target(&p.square, by),
                    u_range: p.u_range,
                })
                .collect(),
        }
    }
}

/// A target moved by a rigid motion.
pub fn move_target(t: &Target, by: &Pose) -> Target {
    Target {
        id: t.id,
        size_m: t.size_m,
        corners_m: t.corners_m.map(|c| by.transform_point(c)),
        centre_m: t.centre_m.map(|c| by.transform_point(c)),
    }
}

/// The paper of a cut-out target: its square widened to [`PAPER_HALF_EXTENT`] half-edges.
pub fn cutout_paper(t: &Target) -> [DVec3; 4] {
    let c = t.centre();
    t.corners_m.map(|p| c + (p - c) * PAPER_HALF_EXTENT)
}

/// Flattens targets (group frame) onto one sheet (see the module docs): the nominal layout and
/// the flat pose, before any fault. `None` when the group has no common facing direction.
pub fn flatten(name: &str, layout: Layout, members: &[&Target]) -> Option<PrintedSheet> {
    let n = members.len().max(1) as f64;
    let centre = members.iter().map(|t| t.centre()).sum::<DVec3>() / n;
    let z = members
        .iter()
        .map(|t| t.outward_normal())
        .sum::<DVec3>()
        .try_normalize()?;
    let y = (DVec3::Z - z * z.z).try_normalize()?;
    let x = y.cross(z);
    let rot = DQuat::from_mat3(&DMat3::from_cols(x, y, z));
    let plane = Pose::new(rot, centre);
    let plane_from_group = plane.inverse();
    // Each target in the plane: centre projected, up projected, printed size kept.
    let flat: Vec<(u32, f64, DVec2, DVec2)> = members
        .iter()
        .map(|t| {
            let c = plane_from_group.transform_point(t.centre());
            // The tag's up: from its bottom edge (corners 0, 1) to its top (3, 2).
            let up = plane_from_group.transform_vector(t.corners_m[3] - t.corners_m[0]);
            let up2 = DVec2::new(up.x, up.y).try_normalize().unwrap_or(DVec2::Y);
            (t.id, t.size_m, DVec2::new(c.x, c.y), up2)
        })
        .collect();
    // The paper: the bounding rectangle of the targets' papers (each tilted in the page by its
    // up direction: its corners bound it).
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for (_, size, c, up) in &flat {
        let right = DVec2::new(up.y, -up.x);
        let h = 0.5 * size * PAPER_HALF_EXTENT;
        for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = *c + right * (su * h) + *up * (sv * h);
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    let mid = 0.5 * (lo + hi);
    let targets = flat
        .iter()
        .map(|(id, size, c, up)| {
            let centre = (*c - mid).extend(0.0);
            Target::square(*id, *size, centre, DVec3::Z, up.extend(0.0))
        })
        .collect::<Option<Vec<_>>>()?;
    let origin = plane.transform_point(mid.extend(0.0));
    Some(PrintedSheet {
        name: name.to_string(),
        layout,
        targets,
        group_from_sheet: Pose::new(rot, origin),
        print_scale: 1.0,
        tilt_deg: 0.0,
        shape: SheetShape::Flat,
        paper_half_m: 0.5 * (hi - lo),
    })
}

/// A cage target with where it sits in the cage.
#[derive(Debug, Clone)]
pub struct CageTarget {
    /// The cut-out (world frame).
    pub target: Target,
    /// Its row.
    pub row: usize,
    /// Its azimuth step along the row (consecutive steps are neighbours).
    pub step: i64,
}

/// The faults a scene puts on the cage's sheets, resolved per sheet by name or by index among
/// the sheets printed so far.
#[derive(Debug, Clone, Default)]
pub struct SheetFaults {
    /// Largest tilt about a sheet's horizontal axis, degrees.
    pub tilt_deg: f64,
    /// Seed of the tilts.
    pub seed: u64,
    /// `(sheet, scale)`: the sheet printed at that scale.
    pub print_scale: Option<(crate::studio::SheetRef, f64)>,
    /// `(sheet, bend_deg)`: the sheet folded.
    pub bend: Option<(crate::studio::SheetRef, f64)>,
}

/// The cage after printing: its targets' true placements, its sheets and the targets printed
/// other than flat squares.
#[derive(Debug, Clone, Default)]
pub struct PrintedCage {
    /// Every cage target, true corners, in the input's order.
    pub targets: Vec<Target>,
    /// The sheets printed.
    pub sheets: Vec<PrintedSheet>,
    /// Targets a fold crosses, by id.
    pub prints: BTreeMap<u32, TagPrint>,
}

/// The runs of neighbours along each row, cut into groups of `n` (a remainder of at least two
/// makes a smaller group); indices into `cage`.
pub fn cage_groups(cage: &[CageTarget], n: usize) -> Vec<Vec<usize>> {
    let mut groups = Vec::new();
    if n < 2 {
        return groups;
    }
    let mut run: Vec<usize> = Vec::new();
    let flush = |run: &mut Vec<usize>, groups: &mut Vec<Vec<usize>>| {
        for chunk in run.chunks(n) {
            if chunk.len() >= 2 {
                groups.push(chunk.to_vec());
            }
        }
        run.clear();
    };
    for (i, c) in cage.iter().enumerate() {
        let continues = run
            .last()
            .is_some_and(|&j| cage[j].row == c.row && cage[j].step + 1 == c.step);
        if !continues {
            flush(&mut run, &mut groups);
        }
        run.push(i);
    }
    flush(&mut run, &mut groups);
    groups
}

/// Least distance between two bodies' papers, metres (0 when they touch or cross).
fn papers_distance_m(a: &[[DVec3; 4]], b: &[[DVec3; 4]]) -> f64 {
    a.iter()
        .flat_map(|p| b.iter().map(move |q| quad_distance_m(p, q)))
        .fold(f64::INFINITY, f64::min)
}

/// Prints the cage's targets on sheets of `n` (see the module docs). `safe` says whether a
/// target where it would truly be keeps clear of what the cage must not hide.
pub fn print_cage(
    cage: &[CageTarget],
    n: usize,
    faults: &SheetFaults,
    safe: &dyn Fn(&Target) -> bool,
) -> PrintedCage {
    let mut out = PrintedCage {
        targets: cage.iter().map(|c| c.target).collect(),
        ..PrintedCage::default()
    };
    // Bodies: members (indices into `cage`) and their papers; every target a cut-out at first.
    let mut bodies: Vec<(Vec<usize>, Vec<[DVec3; 4]>)> = cage
        .iter()
        .enumerate()
        .map(|(i, c)| (vec![i], vec![cutout_paper(&c.target)]))
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(faults.seed ^ TILT_SEED_SALT);
    for group in cage_groups(cage, n) {
        // One draw per candidate, printed or not: a sheet's tilt does not depend on whether an
        // earlier candidate was printed.
        let tilt_deg = rng.random_range(-1.0..=1.0) * faults.tilt_deg;
        let members: Vec<&Target> = group.iter().map(|&i| &cage[i].target).collect();
        let name = format!("cage-{}", members.first().map_or(0, |t| t.id));
        let Some(mut sheet) = flatten(&name, Layout::Reference, &members) else {
            continue;
        };
        let index = out.sheets.len();
        sheet.tilt_deg = tilt_deg;
        sheet.group_from_sheet = sheet.group_from_sheet
            * Pose::new(DQuat::from_rotation_x(tilt_deg.to_radians()), DVec3::ZERO);
        if let Some((which, k)) = &faults.print_scale {
            if which.names(&sheet.name, index) {
                sheet.print_scale = *k;
            }
        }
        if let Some((which, bend_deg)) = &faults.bend {
            if which.names(&sheet.name, index) {
                sheet.shape = SheetShape::Folded {
                    bend_deg: *bend_deg,
                };
            }
        }
        let truths: Vec<Target> = sheet.targets.iter().map(|t| sheet.true_target(t)).collect();
        let on_page_apart = sheet.targets.iter().enumerate().all(|(i, a)| {
            sheet.targets[i + 1..]
                .iter()
                .all(|b| quad_distance_m(&cutout_paper(a), &cutout_paper(b)) > 0.0)
        });
        let papers = sheet.paper_quads();
        let clear = bodies
            .iter()
            .filter(|(m, _)| !m.iter().any(|i| group.contains(i)))
            .all(|(_, p)| papers_distance_m(&papers, p) >= PAPER_CLEARANCE_M);
        if !(on_page_apart && clear && truths.iter().all(safe)) {
            continue;
        }
        bodies.retain(|(m, _)| !m.iter().any(|i| group.contains(i)));
        bodies.push((group.clone(), papers));
        for (&i, (t, layout_t)) in group.iter().zip(truths.into_iter().zip(&sheet.targets)) {
            if let SheetShape::Folded { .. } = sheet.shape {
                let pieces = sheet.pieces(layout_t);
                if pieces.len() > 1 {
                    out.prints.insert(t.id, TagPrint { code: t.id, pieces });
                }
            }
            out.targets[i] = t;
        }
        out.sheets.push(sheet);
    }
    out
}

/// The headdress band (`studio.headdress_band`): the headdress targets as one printed band whose
/// layout is the band unrolled flat. Each target's layout position is `(a, s)`: its arc length
/// along its row and the arc length from the band's lowest row up to its row, as the caller
/// measures them on the head; the layout is centred on its paper's bounding rectangle. The
/// band is [`SheetShape::Wrapped`]: no pose places it.
pub fn headdress_band(tags: &[(&Target, DVec2)]) -> Option<PrintedSheet> {
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for (t, p) in tags {
        let h = DVec2::splat(0.5 * t.size_m * PAPER_HALF_EXTENT);
        lo = lo.min(*p - h);
        hi = hi.max(*p + h);
    }
    let mid = 0.5 * (lo + hi);
    let targets = tags
        .iter()
        .map(|(t, p)| Target::square(t.id, t.size_m, (*p - mid).extend(0.0), DVec3::Z, DVec3::Y))
        .collect::<Option<Vec<_>>>()?;
    Some(PrintedSheet {
        name: HEADDRESS_BAND_NAME.into(),
        layout: Layout::Headdress,
        targets,
        group_from_sheet: Pose::IDENTITY,
        print_scale: 1.0,
        tilt_deg: 0.0,
        shape: SheetShape::Wrapped,
        paper_half_m: 0.5 * (hi - lo),
    })
}

// --- distances between convex planar quads -------------------------------------------------

/// Least distance between two convex planar quads in space, metres (0 when they touch or
/// cross). Exact: two disjoint convex polygons are closest edge to edge or vertex to face, and
/// two that cross have an edge of one through the other.
pub fn quad_distance_m(a: &[DVec3; 4], b: &[DVec3; 4]) -> f64 {
    fn edges(q: &[DVec3; 4]) -> impl Iterator<Item = (DVec3, DVec3)> + '_ {
        (0..4).map(move |k| (q[k], q[(k + 1) % 4]))
    }
    if edges(a).any(|(p, q)| segment_crosses_quad(p, q, b))
        || edges(b).any(|(p, q)| segment_crosses_quad(p, q, a))
    {
        return 0.0;
    }
    let mut d = f64::INFINITY;
    for (p0, p1) in edges(a) {
        for (q0, q1) in edges(b) {
            d = d.min(segment_distance_m(p0, p1, q0, q1));
        }
    }
    for p in a {
        d = d.min(point_quad_distance_m(*p, b));
    }
    for p in b {
        d = d.min(point_quad_distance_m(*p, a));
    }
    d
}

fn quad_normal(q: &[DVec3; 4]) -> DVec3 {
    (q[1] - q[0]).cross(q[3] - q[0]).normalize_or_zero()
}

/// Whether `p` (in the quad's plane) lies inside the convex quad (boundary included).
fn inside_quad(p: DVec3, q: &[DVec3; 4], n: DVec3) -> bool {
    let signs: Vec<f64> = (0..4)
        .map(|k| (q[(k + 1) % 4] - q[k]).cross(p - q[k]).dot(n))
        .collect();
    signs.iter().all(|s| *s >= -1e-15) || signs.iter().all(|s| *s <= 1e-15)
}

fn segment_crosses_quad(p0: DVec3, p1: DVec3, q: &[DVec3; 4]) -> bool {
    let n = quad_normal(q);
    let d0 = n.dot(p0 - q[0]);
    let d1 = n.dot(p1 - q[0]);
    if d0 * d1 > 0.0 || d0 == d1 {
        return false;
    }
    let x = p0 + (p1 - p0) * (d0 / (d0 - d1));
    inside_quad(x, q, n)
}

fn point_quad_distance_m(p: DVec3, q: &[DVec3; 4]) -> f64 {
    let n = quad_normal(q);
    let h = n.dot(p - q[0]);
    if inside_quad(p - n * h, q, n) {
        return h.abs();
    }
    (0..4)
        .map(|k| point_segment_distance_m(p, q[k], q[(k + 1) % 4]))
        .fold(f64::INFINITY, f64::min)
}

fn point_segment_distance_m(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let t = if ab.length_squared() > 0.0 {
        ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + ab * t)
}

/// Least distance between two segments (Ericson, *Real-Time Collision Detection*, 5.1.9).
fn segment_distance_m(p1: DVec3, q1: DVec3, p2: DVec3, q2: DVec3) -> f64 {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.length_squared();
    let e = d2.length_squared();
    let f = d2.dot(r);
    let (s, t) = if a <= 1e-30 && e <= 1e-30 {
        (0.0, 0.0)
    } else if a <= 1e-30 {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(r);
        if e <= 1e-30 {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s = if denom > 1e-30 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    (p1 + d1 * s).distance(p2 + d2 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_quad(centre: DVec3, half: f64, normal: DVec3) -> [DVec3; 4] {
        Target::square(0, 2.0 * half, centre, normal, DVec3::Z)
            .or_else(|| Target::square(0, 2.0 * half, centre, normal, DVec3::Y))
            .map(|t| t.corners_m)
            .unwrap_or([DVec3::ZERO; 4])
    }

    #[test]
    fn quad_distances_are_exact_for_simple_cases() {
        let a = square_quad(DVec3::ZERO, 0.5, DVec3::Z);
        // Parallel, 0.3 above: face to face.
        let b = square_quad(DVec3::new(0.2, 0.1, 0.3), 0.5, DVec3::Z);
        assert!((quad_distance_m(&a, &b) - 0.3).abs() < 1e-12);
        // Side by side in the plane, 0.25 apart edge to edge.
        let c = square_quad(DVec3::new(1.25, 0.0, 0.0), 0.5, DVec3::Z);
        assert!((quad_distance_m(&a, &c) - 0.25).abs() < 1e-12);
        // Overlapping in the plane.
        let d = square_quad(DVec3::new(0.5, 0.0, 0.0), 0.5, DVec3::Z);
        assert_eq!(quad_distance_m(&a, &d), 0.0);
        // Crossing at right angles.
        let e = square_quad(DVec3::ZERO, 0.5, DVec3::X);
        assert_eq!(quad_distance_m(&a, &e), 0.0);
        // Perpendicular, its edge 0.1 above the face.
        let f = square_quad(DVec3::new(0.0, 0.0, 0.6), 0.5, DVec3::X);
        assert!((quad_distance_m(&a, &f) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn a_fold_keeps_lengths_on_the_paper_and_splits_the_tag_it_crosses() {
        let t = Target::square(5, 0.03, DVec3::ZERO, DVec3::Z, DVec3::Y).expect("square");
        let sheet = PrintedSheet {
            name: "s".into(),
            layout: Layout::Reference,
            targets: vec![t],
            group_from_sheet: Pose::IDENTITY,
            print_scale: 1.0,
            tilt_deg: 0.0,
            shape: SheetShape::Folded { bend_deg: 10.0 },
            paper_half_m: DVec2::splat(0.0225),
        };
        let truth = sheet.true_target(&t);
        // Every edge keeps its length: the edge from corner 0 to corner 1 runs along the paper
        // across the fold.
        let on_fold = sheet.place(0.5 * (t.corners_m[0] + t.corners_m[1]));
        let across = truth.corners_m[0].distance(on_fold) + on_fold.distance(truth.corners_m[1]);
        assert!(
            (across - 0.03).abs() < 1e-12,
            "edge across the fold {across}"
        );
        for k in [1, 3] {
            let d = truth.corners_m[k].distance(truth.corners_m[(k + 1) % 4]);
            assert!((d - 0.03).abs() < 1e-12, "edge {k}: {d}");
        }
        // Both outer edges come towards the viewer (+z).
        assert!(truth.corners_m[0].z > 0.0 && truth.corners_m[1].z > 0.0);
        let pieces = sheet.pieces(&t);
        assert_eq!(pieces.len(), 2);
        assert!((pieces[0].u_range[1] - 0.0).abs() < 1e-12);
    }
}
