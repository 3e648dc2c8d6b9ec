//! Mesh validation and safe repair of what scanners produce.
//!
//! [`inspect`] counts problems without changing anything; [`repair`] fixes those that have a
//! safe fix and reports every change with counts and examples (input triangle indices):
//!
//! * **non-finite vertices** (NaN/∞): every triangle using one is dropped, then the vertex;
//! * **out-of-range indices**: the triangle is dropped;
//! * **coincident vertices** (bit-identical positions, as scanners emit at patch seams): welded,
//!   so adjacency (and winding repair) sees through the seam;
//! * **degenerate triangles**: repeated corners, or height below [`DEGENERATE_REL_HEIGHT`] of the
//!   longest edge (no usable normal, and a ray cannot hit them reliably): dropped;
//! * **duplicate triangles** (same three vertices in any order): all but the first dropped;
//! * **inconsistent winding**: two triangles traversing their shared edge in the same direction.
//!   Each connected component (across manifold edges) is re-oriented by a breadth-first walk,
//!   and the component keeps the orientation of the larger part (by area) of its input
//!   triangles, so a scan that is mostly right stays right. Edges shared by more than two
//!   triangles (non-manifold) are reported and not walked across; a component that cannot be
//!   oriented (Möbius-like) is reported.
//!
//! [`RepairPolicy::strict`] turns any of these into an error instead of a fix.

use std::collections::{HashMap, VecDeque};

use glam::Vec3;
use skinbrdf_core::TriMesh;

use crate::error::MeshError;
pub use crate::report::{
    MeshReport, Problem, RepairMap, RepairPolicy, MAX_DROPPED_FRACTION, MAX_EXAMPLES,
};

/// A triangle is degenerate when its height is below this fraction of its longest edge
/// (needles and caps): f32 cross products are accurate to ~1e-7 relative, so below 1e-5 the
/// normal's direction is noise.
pub const DEGENERATE_REL_HEIGHT: f32 = 1e-5;

fn is_degenerate(a: Vec3, b: Vec3, c: Vec3) -> bool {
    let area2 = (b - a).cross(c - a).length();
    let longest = (b - a)
        .length_squared()
        .max((c - b).length_squared())
        .max((a - c).length_squared());
    // height = area2 / longest_edge; degenerate when height < rel * longest_edge.
    area2.is_nan() || area2 <= DEGENERATE_REL_HEIGHT * longest || longest == 0.0
}

/// Counts the problems of a mesh without changing it.
pub fn inspect(mesh: &TriMesh) -> MeshReport {
    let (_, mut report, _) = repair_impl(mesh, true);
    report.triangles_out = mesh.indices.len();
    report.flipped = Problem::default();
    report
}

/// Repairs a mesh according to `policy`; `source` names it in errors.
pub fn repair(
    mesh: &TriMesh,
    policy: RepairPolicy,
    source: &str,
) -> Result<(TriMesh, MeshReport), MeshError> {
    repair_tracked(mesh, policy, source).map(|(m, r, _)| (m, r))
}

/// [`repair`], also returning where each output vertex and triangle came from.
pub fn repair_tracked(
    mesh: &TriMesh,
    policy: RepairPolicy,
    source: &str,
) -> Result<(TriMesh, MeshReport, RepairMap), MeshError> {
    let (out, report, map) = repair_impl(mesh, policy.weld);
    if !policy.repair && !report.is_clean() {
        return Err(MeshError::Defects {
            source_name: source.to_string(),
            report: Box::new(report),
        });
    }
    if out.indices.is_empty() {
        return Err(MeshError::Empty {
            source_name: source.to_string(),
            triangles_in: report.triangles_in,
        });
    }
    let dropped = report.lost_triangles();
    if dropped as f64 > policy.max_dropped_fraction * report.triangles_in as f64 {
        return Err(MeshError::TooManyDropped {
            source_name: source.to_string(),
            max_fraction: policy.max_dropped_fraction,
            report: Box::new(report),
        });
    }
    Ok((out, report, map))
}

fn repair_impl(mesh: &TriMesh, weld: bool) -> (TriMesh, MeshReport, RepairMap) {
    let mut r = MeshReport {
        triangles_in: mesh.indices.len(),
        ..Default::default()
    };
    let finite: Vec<bool> = mesh.positions.iter().map(|p| p.is_finite()).collect();
    for (i, f) in finite.iter().enumerate() {
        if !f {
            r.non_finite_vertices.add(i);
        }
    }
    let rep = weld_map(mesh, &finite, weld, &mut r);
    let kept = filter_triangles(mesh, &finite, &rep, &mut r);
    let adj = adjacency(&kept, &mut r);
    let flip = orient(mesh, &kept, &adj, &mut r);
    let (out, map) = assemble(mesh, &kept, &flip, &mut r);
    (out, r, map)
}

/// Per vertex, its representative: itself, or the first earlier vertex at the bit-identical
/// position when welding.
fn weld_map(mesh: &TriMesh, finite: &[bool], weld: bool, r: &mut MeshReport) -> Vec<u32> {
    let nv = mesh.positions.len();
    let mut rep: Vec<u32> = (0..nv as u32).collect();
    if weld {
        let mut seen: HashMap<[u32; 3], u32> = HashMap::with_capacity(nv);
        for (i, p) in mesh.positions.iter().enumerate() {
            if !finite[i] {
                continue;
            }
            // +0.0 so that -0.0 and 0.0 weld.
            let key = [
                (p.x + 0.0).to_bits(),
                (p.y + 0.0).to_bits(),
                (p.z + 0.0).to_bits(),
            ];
            let first = *seen.entry(key).or_insert(i as u32);
            if first != i as u32 {
                rep[i] = first;
                r.welded_vertices.add(i);
            }
        }
    }
    rep
}

/// The triangles kept (input index, corners as representatives): in range, on finite
/// vertices, not degenerate, not a duplicate.
fn filter_triangles(
    mesh: &TriMesh,
    finite: &[bool],
    rep: &[u32],
    r: &mut MeshReport,
) -> Vec<(usize, [u32; 3])> {
    let nv = mesh.positions.len();
    let mut kept: Vec<(usize, [u32; 3])> = Vec::with_capacity(mesh.indices.len());
    let mut dup: HashMap<[u32; 3], usize> = HashMap::with_capacity(mesh.indices.len());
    for (t, tri) in mesh.indices.iter().enumerate() {
        if tri.iter().any(|&v| v as usize >= nv) {
            r.index_out_of_range.add(t);
            continue;
        }
        if tri.iter().any(|&v| !finite[v as usize]) {
            r.triangles_on_non_finite.add(t);
            continue;
        }
        let w = tri.map(|v| rep[v as usize]);
        let [a, b, c] = w.map(|v| mesh.positions[v as usize]);
        if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] || is_degenerate(a, b, c) {
            r.degenerate.add(t);
            continue;
        }
        let mut key = w;
        key.sort_unstable();
        if dup.insert(key, t).is_some() {
            r.duplicates.add(t);
            continue;
        }
        kept.push((t, w));
    }
    kept
}

/// Per kept triangle, its neighbours across manifold edges and whether the two traverse the
/// shared edge in the same direction (inconsistent winding); non-manifold edges are reported.
fn adjacency(kept: &[(usize, [u32; 3])], r: &mut MeshReport) -> Vec<Vec<(usize, bool)>> {
    let mut edges: HashMap<(u32, u32), Vec<(usize, bool)>> = HashMap::with_capacity(kept.len() * 2);
    for (k, (_, w)) in kept.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (w[e], w[(e + 1) % 3]);
            let forward = a < b;
            edges
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push((k, forward));
        }
    }
    let mut adj: Vec<Vec<(usize, bool)>> = vec![Vec::new(); kept.len()];
    for list in edges.values() {
        match list.as_slice() {
            [(k1, f1), (k2, f2)] => {
                // Consistent when they traverse the edge in opposite directions.
                let same_dir = f1 == f2;
                if same_dir {
                    r.inconsistent_edges.add(kept[*k1].0);
                }
                adj[*k1].push((*k2, same_dir));
                adj[*k2].push((*k1, same_dir));
            }
            [_] => {}
            many => r.non_manifold_edges.add(kept[many[0].0].0),
        }
    }
    adj
}

/// Per kept triangle, whether to flip it: each component oriented by a breadth-first walk
/// (`flip[k2] = flip[k1] XOR same_dir`), keeping the orientation of its larger area.
fn orient(
    mesh: &TriMesh,
    kept: &[(usize, [u32; 3])],
    adj: &[Vec<(usize, bool)>],
    r: &mut MeshReport,
) -> Vec<Option<bool>> {
    let mut flip: Vec<Option<bool>> = vec![None; kept.len()];
    let area = |k: usize| {
        let [a, b, c] = kept[k].1.map(|v| mesh.positions[v as usize]);
        (b - a).cross(c - a).length() as f64
    };
    let mut queue = VecDeque::new();
    for start in 0..kept.len() {
        if flip[start].is_some() {
            continue;
        }
        r.components += 1;
        flip[start] = Some(false);
        queue.push_back(start);
        let mut members = vec![start];
        let mut orientable = true;
        while let Some(k) = queue.pop_front() {
            let fk = flip[k].unwrap_or(false);
            for &(n, same_dir) in &adj[k] {
                let want = fk ^ same_dir;
                match flip[n] {
                    None => {
                        flip[n] = Some(want);
                        members.push(n);
                        queue.push_back(n);
                    }
                    Some(f) if f != want => orientable = false,
                    Some(_) => {}
                }
            }
        }
        if !orientable {
            r.non_orientable_components += 1;
        }
        let flipped_area: f64 = members
            .iter()
            .filter(|&&k| flip[k] == Some(true))
            .map(|&k| area(k))
            .sum();
        let total: f64 = members.iter().map(|&k| area(k)).sum();
        if flipped_area > 0.5 * total {
            for &k in &members {
                flip[k] = flip[k].map(|f| !f);
            }
        }
    }
    flip
}

/// The repaired mesh: kept triangles (flipped where oriented so), unreferenced vertices
/// dropped (keeping their order), and where each came from.
fn assemble(
    mesh: &TriMesh,
    kept: &[(usize, [u32; 3])],
    flip: &[Option<bool>],
    r: &mut MeshReport,
) -> (TriMesh, RepairMap) {
    let nv = mesh.positions.len();
    let mut used = vec![false; nv];
    for (_, w) in kept {
        for &v in w {
            used[v as usize] = true;
        }
    }
    let mut remap: Vec<u32> = vec![u32::MAX; nv];
    let mut out = TriMesh::default();
    let mut map = RepairMap::default();
    let mut normals_out = Vec::new();
    let normals = mesh.normals.as_ref().filter(|n| n.len() == nv);
    for v in (0..nv).filter(|&v| used[v]) {
        remap[v] = out.positions.len() as u32;
        map.vertices.push(v as u32);
        out.positions.push(mesh.positions[v]);
        if let Some(n) = normals {
            normals_out.push(n[v]);
        }
    }
    for (k, (t, w)) in kept.iter().enumerate() {
        let mut w = *w;
        let flipped = flip[k] == Some(true);
        if flipped {
            w.swap(1, 2);
            r.flipped.add(*t);
        }
        out.indices.push(w.map(|v| remap[v as usize]));
        map.triangles.push((*t as u32, flipped));
    }
    if normals.is_some() {
        out.normals = Some(normals_out);
    }
    r.triangles_out = out.indices.len();
    (out, map)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3x3-vertex grid of 8 triangles, consistently wound (+z).
    fn grid() -> TriMesh {
        let mut positions = Vec::new();
        for y in 0..3 {
            for x in 0..3 {
                positions.push(Vec3::new(x as f32 * 0.01, y as f32 * 0.01, 0.0));
            }
        }
        let mut indices = Vec::new();
        for y in 0..2u32 {
            for x in 0..2u32 {
                let i = y * 3 + x;
                indices.push([i, i + 1, i + 4]);
                indices.push([i, i + 4, i + 3]);
            }
        }
        TriMesh {
            positions,
            indices,
            normals: None,
        }
    }

    #[test]
    fn clean_mesh_is_untouched() {
        let m = grid();
        let (out, r) = repair(&m, RepairPolicy::repair(), "grid").unwrap();
        assert!(r.is_clean(), "{r:?}");
        assert_eq!(out, m);
        assert_eq!(r.components, 1);
    }

    #[test]
    fn nan_vertex_drops_its_triangles() {
        let mut m = grid();
        m.positions[4] = Vec3::new(f32::NAN, 0.0, 0.0);
        // Dropping 6 of 8 triangles is beyond the default limit: an error naming the count ...
        let e = repair(&m, RepairPolicy::repair(), "scan.ply").unwrap_err();
        assert!(
            matches!(
                &e,
                MeshError::TooManyDropped { report, .. }
                    if report.lost_triangles() == 6 && report.triangles_in == 8
            ),
            "{e}"
        );
        assert!(e.to_string().contains("scan.ply"), "{e}");
        // ... unless the caller accepts it.
        let (out, r) = repair(&m, RepairPolicy::accepting(1.0), "grid").unwrap();
        assert_eq!(r.non_finite_vertices.count, 1);
        assert_eq!(r.non_finite_vertices.examples, vec![4]);
        // Vertex 4 is the centre: every triangle of the grid uses it but two? count them.
        let using = m.indices.iter().filter(|t| t.contains(&4)).count();
        assert_eq!(r.triangles_on_non_finite.count, using);
        assert_eq!(out.indices.len(), 8 - using);
        assert!(out.positions.iter().all(|p| p.is_finite()));
        assert!(out.validate().is_empty());
        let e = repair(&m, RepairPolicy::strict(), "scan.ply").unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("scan.ply") && msg.contains("1 non-finite vertices"),
            "{msg}"
        );
    }

    #[test]
    fn degenerate_and_duplicates_are_dropped_with_examples() {
        let mut m = grid();
        m.indices.push([0, 0, 1]); // repeated corner: 8
        m.indices.push([0, 1, 2]); // collinear: 9
        m.indices.push([4, 1, 0]); // duplicate of triangle 0 ([0,1,4]) reordered: 10
        let (out, r) = repair(&m, RepairPolicy::repair(), "grid").unwrap();
        assert_eq!(r.degenerate.examples, vec![8, 9]);
        assert_eq!(r.duplicates.examples, vec![10]);
        assert_eq!(out.indices.len(), 8);
        let e = repair(&m, RepairPolicy::strict(), "g")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("2 degenerate") && e.contains("1 duplicate"),
            "{e}"
        );
    }

    #[test]
    fn inconsistent_winding_is_fixed_towards_the_majority() {
        let mut m = grid();
        m.indices[3].swap(1, 2);
        m.indices[6].swap(1, 2);
        let r0 = inspect(&m);
        assert!(r0.inconsistent_edges.count >= 2, "{r0:?}");
        let (out, r) = repair(&m, RepairPolicy::repair(), "grid").unwrap();
        let mut flipped = r.flipped.examples.clone();
        flipped.sort();
        assert_eq!(flipped, vec![3, 6]);
        for t in 0..out.indices.len() {
            assert!(
                out.face_normal_area2(t).z > 0.0,
                "triangle {t} still flipped"
            );
        }
        assert_eq!(inspect(&out).inconsistent_edges.count, 0);
    }

    #[test]
    fn welding_joins_seams_and_out_of_range_is_dropped() {
        let mut m = grid();
        // Duplicate vertex 4 at the end and use it in two triangles: a seam.
        m.positions.push(m.positions[4]);
        for t in m.indices.iter_mut().take(2) {
            for v in t.iter_mut() {
                if *v == 4 {
                    *v = 9;
                }
            }
        }
        m.indices.push([0, 1, 77]);
        // One triangle of nine lost is beyond the default 1 %: accepted here.
        let (out, r) = repair(&m, RepairPolicy::accepting(0.2), "grid").unwrap();
        assert_eq!(r.welded_vertices.examples, vec![9]);
        assert_eq!(r.index_out_of_range.examples, vec![8]);
        assert_eq!(out.positions.len(), 9);
        assert_eq!(r.components, 1);
    }
}
