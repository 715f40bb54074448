//! What the build and the passes after it count about a mesh ([`TopologyStats`]), for `info` and
//! the reports; and how one vertex's analysis is counted into them and into the fixed mask, in
//! the one method that the build and its test's vertex-by-vertex reference share.

use super::MAX_FREE_DEGREE;
use super::fans::VertexAnalysis;
use super::masks::{FIXED, LOOP};

/// What the topology build counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TopologyStats {
    pub vertices: usize,
    pub triangles: usize,
    /// Undirected edges of non-degenerate triangles.
    pub edges: usize,
    pub boundary_edges: usize,
    pub non_manifold_edges: usize,
    /// Vertices whose link is neither one cycle nor one path (e.g. two cones touching at a tip).
    pub non_manifold_vertices: usize,
    /// Triangles with a repeated vertex index.
    pub degenerate_triangles: usize,
    /// Vertices used by no triangle.
    pub unreferenced_vertices: usize,
    /// Vertices that no method moves (see the [module doc](super)).
    pub fixed_vertices: usize,
    /// Edges of two triangles that both traverse it in the same direction: the input's faces are
    /// not consistently oriented there (counted on the faces as built, before
    /// [`Topology::orient`](super::Topology::orient)).
    #[serde(default)]
    pub inconsistent_orientation_edges: usize,
    /// Components (through edges of two triangles) that no choice of face orientations makes
    /// consistent, such as a Möbius strip; found by [`Topology::orient`](super::Topology::orient).
    #[serde(default)]
    pub non_orientable_components: usize,
    /// Edges left inconsistent by [`Topology::orient`](super::Topology::orient) in
    /// non-orientable components; their vertices are fixed.
    #[serde(default)]
    pub orientation_seam_edges: usize,
    /// Vertices with more than [`MAX_FREE_DEGREE`] neighbours (fixed).
    #[serde(default)]
    pub high_degree_vertices: usize,
    /// Vertices pinned by the caller ([`Topology::pin`](super::Topology::pin)): fixed whatever
    /// their topology, and counted in `fixed_vertices`.
    #[serde(default)]
    pub pinned_vertices: usize,
    /// Crease edges between two crease vertices, edges of two triangles whose normals differ by
    /// more than the run's crease angle ([`Topology::crease`](super::Topology::crease)); 0 when
    /// no crease angle is given.
    #[serde(default)]
    pub crease_edges: usize,
    /// Vertices on a crease edge: fixed, and counted in `fixed_vertices`.
    #[serde(default)]
    pub crease_vertices: usize,
}

impl TopologyStats {
    /// Count vertex `v`'s analysis `a`, and set its entry `fix` of the fixed mask (which
    /// degenerate triangles at `v` may have set before: then it is not a loop vertex).
    pub(super) fn count(&mut self, a: &VertexAnalysis, fix: &mut u8) {
        self.edges += a.edges;
        self.boundary_edges += a.boundary_edges;
        self.non_manifold_edges += a.non_manifold_edges;
        self.non_manifold_vertices += a.non_manifold_vertex as usize;
        self.inconsistent_orientation_edges += a.inconsistent_edges;
        self.high_degree_vertices += (a.degree > MAX_FREE_DEGREE) as usize;
        self.unreferenced_vertices += (a.degree == 0) as usize;
        if a.fixed {
            *fix = if a.loop_vertex && *fix == 0 {
                FIXED | LOOP
            } else {
                FIXED
            };
        }
        self.fixed_vertices += (*fix != 0) as usize;
    }

    pub(super) fn add(mut self, o: TopologyStats) -> TopologyStats {
        self.edges += o.edges;
        self.boundary_edges += o.boundary_edges;
        self.non_manifold_edges += o.non_manifold_edges;
        self.non_manifold_vertices += o.non_manifold_vertices;
        self.unreferenced_vertices += o.unreferenced_vertices;
        self.fixed_vertices += o.fixed_vertices;
        self.inconsistent_orientation_edges += o.inconsistent_orientation_edges;
        self.high_degree_vertices += o.high_degree_vertices;
        self
    }
}
