//! What validation found and repair did ([`MeshReport`]), what repair may do
//! ([`RepairPolicy`]) and where repaired elements came from ([`RepairMap`]): the types of
//! [`crate::validate`], below the error that carries a report.

/// How many example indices a report keeps per problem.
pub const MAX_EXAMPLES: usize = 8;

/// One kind of problem: how many, and the first few indices (triangles unless stated).
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct Problem {
    /// Number of occurrences.
    pub count: usize,
    /// The first few indices (input numbering).
    pub examples: Vec<usize>,
}

impl Problem {
    pub(crate) fn add(&mut self, index: usize) {
        self.count += 1;
        if self.examples.len() < MAX_EXAMPLES {
            self.examples.push(index);
        }
    }
}

/// What [`inspect`](crate::validate::inspect) found or [`repair`](crate::validate::repair) did.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct MeshReport {
    /// Triangles in the input.
    pub triangles_in: usize,
    /// Triangles in the output (equal to the input for [`inspect`](crate::validate::inspect)).
    pub triangles_out: usize,
    /// Vertices with NaN or infinite coordinates (examples are vertex indices).
    pub non_finite_vertices: Problem,
    /// Triangles dropped because a corner is not finite.
    pub triangles_on_non_finite: Problem,
    /// Triangles with an index out of range.
    pub index_out_of_range: Problem,
    /// Vertices merged into an identical earlier vertex (examples are vertex indices).
    pub welded_vertices: Problem,
    /// Degenerate triangles.
    pub degenerate: Problem,
    /// Duplicate triangles (examples are the later copies).
    pub duplicates: Problem,
    /// Manifold edges whose two triangles disagree on winding, as found in the input
    /// (examples are triangle indices of one side).
    pub inconsistent_edges: Problem,
    /// Triangles whose winding was reversed.
    pub flipped: Problem,
    /// Edges shared by more than two triangles (examples are triangle indices).
    pub non_manifold_edges: Problem,
    /// Components that cannot be consistently oriented.
    pub non_orientable_components: usize,
    /// Connected components (over manifold edges).
    pub components: usize,
}

impl MeshReport {
    /// One line naming every problem found, with its count and first examples.
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        let mut add = |p: &Problem, what: &str| {
            if p.count > 0 {
                let examples: Vec<String> = p.examples.iter().map(usize::to_string).collect();
                parts.push(format!("{} {what} (e.g. {})", p.count, examples.join(", ")));
            }
        };
        add(&self.non_finite_vertices, "non-finite vertices");
        add(
            &self.triangles_on_non_finite,
            "triangles on non-finite vertices",
        );
        add(
            &self.index_out_of_range,
            "triangles with an index out of range",
        );
        add(&self.degenerate, "degenerate triangles");
        add(&self.duplicates, "duplicate triangles");
        add(&self.inconsistent_edges, "edges with inconsistent winding");
        add(&self.flipped, "triangles re-wound");
        add(&self.non_manifold_edges, "non-manifold edges");
        add(&self.welded_vertices, "coincident vertices welded");
        if self.non_orientable_components > 0 {
            parts.push(format!(
                "{} non-orientable components",
                self.non_orientable_components
            ));
        }
        if parts.is_empty() {
            "no problems".to_string()
        } else {
            parts.join(", ")
        }
    }

    /// True when nothing was found that changes the mesh.
    pub fn is_clean(&self) -> bool {
        self.non_finite_vertices.count == 0
            && self.index_out_of_range.count == 0
            && self.degenerate.count == 0
            && self.duplicates.count == 0
            && self.inconsistent_edges.count == 0
    }
}

/// What to do about each problem.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RepairPolicy {
    /// Fix problems (true) or fail with [`MeshError::Defects`](crate::MeshError::Defects) on the first kind found (false).
    pub repair: bool,
    /// Weld bit-identical vertices before looking at adjacency.
    pub weld: bool,
    /// Largest fraction of the triangles a repair may lose ([`MeshReport::lost_triangles`]);
    /// more is [`MeshError::TooManyDropped`](crate::MeshError::TooManyDropped) (a scan that damaged is not the surface it claims
    /// to be).
    pub max_dropped_fraction: f64,
}

/// The default limit on the triangles a repair may drop: 1 % (a few holes of NaN vertices
/// drop well under that; a tenth of the vertices NaN drops about 30 %).
pub const MAX_DROPPED_FRACTION: f64 = 0.01;

impl RepairPolicy {
    /// Repair everything that has a safe fix, dropping at most [`MAX_DROPPED_FRACTION`] of the
    /// triangles (the default).
    pub const fn repair() -> Self {
        Self {
            repair: true,
            weld: true,
            max_dropped_fraction: MAX_DROPPED_FRACTION,
        }
    }
    /// Repair, accepting that up to `fraction` of the triangles are dropped.
    pub const fn accepting(fraction: f64) -> Self {
        Self {
            repair: true,
            weld: true,
            max_dropped_fraction: fraction,
        }
    }
    /// Refuse any defect.
    pub const fn strict() -> Self {
        Self {
            repair: false,
            weld: true,
            max_dropped_fraction: 0.0,
        }
    }
}

impl MeshReport {
    /// Triangles the repair dropped (degenerate and duplicate ones included).
    pub fn dropped_triangles(&self) -> usize {
        self.triangles_in.saturating_sub(self.triangles_out)
    }

    /// Dropped triangles that took surface with them: on a non-finite vertex or with an index
    /// out of range (a degenerate triangle has no area, a duplicate's copy stays).
    pub fn lost_triangles(&self) -> usize {
        self.triangles_on_non_finite.count + self.index_out_of_range.count
    }
}

impl Default for RepairPolicy {
    fn default() -> Self {
        Self::repair()
    }
}

/// Where each output element of [`repair_tracked`](crate::validate::repair_tracked) came from, so that per-vertex and
/// per-corner attributes (colours, texture coordinates) follow the repair.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RepairMap {
    /// Per output vertex, its input vertex.
    pub vertices: Vec<u32>,
    /// Per output triangle, its input triangle and whether its winding was flipped (corners 1
    /// and 2 swapped: output corner `k` is input corner `[0, 2, 1][k]`).
    pub triangles: Vec<(u32, bool)>,
}

impl RepairMap {
    /// The input corner (0..3) of output corner `k` of a triangle flipped or not.
    pub const fn input_corner(flipped: bool, k: usize) -> usize {
        if flipped {
            [0, 2, 1][k]
        } else {
            k
        }
    }
}
