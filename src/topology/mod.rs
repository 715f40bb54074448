//! Immutable connectivity: CSR vertex→vertex and vertex→face adjacency, the fixed-vertex mask, and
//! counts of what is unusual about the mesh.
//!
//! Conventions:
//! - `neighbors(v)` is sorted ascending and has no duplicates; `deg(v)` is its length.
//! - `faces_of(v)` lists the triangles (indices into the triangle array) that use `v`, ascending.
//! - A vertex is **fixed** (never moved by any method) when it is on the boundary (an edge used by one
//!   triangle), on a non-manifold edge (used by three or more), is a non-manifold vertex (its link is
//!   not one cycle or one path), belongs to a degenerate triangle (a repeated index), is
//!   unreferenced, or has more than [`MAX_FREE_DEGREE`] neighbours (a hub: see there). Degenerate
//!   triangles take no part in the adjacency.
//! - A **loop vertex** ([`Topology::is_loop`]) is a boundary vertex fixed for that reason alone: a
//!   manifold vertex whose link is one path, so that exactly two of its edges are boundary edges
//!   (its neighbours along its boundary loop, [`Topology::loop_neighbors`]). It stays fixed for
//!   every stencil and Jacobi step; only the boundary stencils of `boundary: smooth`
//!   ([`crate::smooth::boundary`]) move it, along its loop. Pinning it, a crease or an
//!   orientation seam through it makes it an ordinary fixed vertex.
//! - Orientation: an edge of two triangles is consistent when they traverse it in opposite
//!   directions. The build counts the inconsistent ones; [`Topology::orient`] flips faces of a
//!   copy of the triangles until every component that can be is consistent, and fixes the
//!   vertices of the edges where that is impossible (non-orientable components). Adjacency and
//!   the rest of the mask do not depend on orientation.
//!
//! The same structure describes a whole mesh or one patch with its halo (local ids); kernels only
//! ever see a `Topology` and a position slice.
//!
//! Files by job: `build` (the parallel CSR build), `fans` (one vertex classified from the faces
//! around it), `stats` (the counts), `masks` (the mask's bits, pins and creases), `orient` (face
//! orientation).

mod build;
mod fans;
mod masks;
mod orient;
mod rings;
mod stats;

pub(crate) use build::{is_degenerate, split_lens};
pub(crate) use fans::Lanes;
pub use fans::corners_after;
pub use rings::rings_outside;
pub use stats::TopologyStats;

use crate::mesh::Buf;

/// CSR adjacency and fixed-vertex mask of a triangle mesh.
#[derive(Debug, Clone, Default)]
pub struct Topology {
    /// Empty when it would equal `vf_offsets` (every vertex has as many neighbours as faces: a
    /// closed manifold), which then serve both lists: 8 bytes per vertex less.
    vv_offsets: Buf<usize>,
    vv: Buf<u32>,
    vf_offsets: Buf<usize>,
    vf: Buf<u32>,
    fixed: Buf<u8>,
    /// Two bytes per vertex when creases were detected (empty otherwise): for a crease line
    /// vertex ([`Topology::line_neighbors`]), the places of its two crease neighbours in its
    /// neighbour list.
    lines: Buf<u8>,
    /// Counts found while building, for `info` and reports.
    pub stats: TopologyStats,
}

/// The arrays of a [`Topology`], as [`Topology::parts`] lends them and
/// [`Topology::from_parts`] takes them back.
pub struct TopologyParts<'a> {
    /// Vertex → vertex CSR offsets (`len + 1`) and neighbour indices.
    pub vv_offsets: &'a [usize],
    pub vv: &'a [u32],
    /// Vertex → face CSR offsets (`len + 1`) and triangle indices.
    pub vf_offsets: &'a [usize],
    pub vf: &'a [u32],
    /// One byte per vertex, non-zero = fixed (see [`Topology::fixed_mask`]).
    pub fixed: &'a [u8],
    /// Empty, or two bytes per vertex: the crease line vertices' crease neighbours, as places in
    /// their neighbour lists ([`Topology::line_neighbors`]).
    pub lines: &'a [u8],
}

/// The accessors of [`Topology`] on the plain slices: a kernel takes the parts once per sweep,
/// because the topology's own accessors ask at every call whether an array is on the heap or
/// mapped.
impl<'a> TopologyParts<'a> {
    #[inline(always)]
    pub fn neighbors(&self, v: u32) -> &'a [u32] {
        let (offsets, v) = (self.vv_offsets, v as usize);
        &self.vv[offsets[v]..offsets[v + 1]]
    }

    #[inline(always)]
    pub fn deg(&self, v: u32) -> usize {
        let (offsets, v) = (self.vv_offsets, v as usize);
        offsets[v + 1] - offsets[v]
    }

    #[inline(always)]
    pub fn faces_of(&self, v: u32) -> &'a [u32] {
        let (offsets, v) = (self.vf_offsets, v as usize);
        &self.vf[offsets[v]..offsets[v + 1]]
    }

    #[inline(always)]
    pub fn is_fixed(&self, v: u32) -> bool {
        self.fixed[v as usize] != 0
    }

    /// Whether a method that smooths creases moves `v`: it is free, or a crease line vertex.
    #[inline(always)]
    pub fn is_free_or_on_line(&self, v: u32) -> bool {
        !self.is_fixed(v) || self.line_neighbors(v).is_some()
    }

    /// [`Topology::line_neighbors`].
    #[inline(always)]
    pub fn line_neighbors(&self, v: u32) -> Option<[u32; 2]> {
        line_neighbors(self.fixed, self.lines, self.neighbors(v), v)
    }
}

/// The crease neighbours of `v` if its mask entry marks a crease line vertex, from its places in
/// `neighbors` (`v`'s list); `None` also for places out of range (a damaged stored plan).
#[inline(always)]
fn line_neighbors(fixed: &[u8], lines: &[u8], neighbors: &[u32], v: u32) -> Option<[u32; 2]> {
    if fixed[v as usize] & masks::LINE == 0 {
        return None;
    }
    let at = lines.get(2 * v as usize..2 * v as usize + 2)?;
    Some([
        *neighbors.get(at[0] as usize)?,
        *neighbors.get(at[1] as usize)?,
    ])
}

/// Most neighbours a vertex may have and still move. A stencil with a free vertex of degree d
/// costs O(d) (its rows and faces), and the vertex is free in d stencils, so one iteration costs
/// O(d²) per vertex: a hole filled by a fan around one vertex, or a cone capped by one, would make
/// a single vertex take minutes. Above this degree the vertex is fixed (for every method, so that
/// all methods agree on what moves), which keeps an iteration within about this factor of a mesh's
/// edge count. Surface meshes have degrees near 6; the degree of a fan vertex of a filled hole is
/// the hole's rim length.
pub const MAX_FREE_DEGREE: usize = 1024;

/// Vertices per parallel work item of the build (a work size only: every chunk's result is
/// placed by vertex id, so the topology does not depend on it).
const CHUNK: usize = 1 << 13;

impl Topology {
    /// The arrays: for storing a plan on disk, and for kernels (see [`TopologyParts`]).
    pub fn parts(&self) -> TopologyParts<'_> {
        TopologyParts {
            vv_offsets: self.vv_offsets(),
            vv: &self.vv,
            vf_offsets: &self.vf_offsets,
            vf: &self.vf,
            fixed: &self.fixed,
            lines: &self.lines,
        }
    }

    /// A topology from arrays written by [`Topology::parts`] (e.g. mapped from a plan on disk).
    /// Checks the shapes only, in O(1), so that a rank mapping a huge plan touches no page it does
    /// not need; whoever uses the entries of a vertex checks them first with
    /// [`Topology::check_vertex`].
    pub fn from_parts(
        vv_offsets: Buf<usize>,
        vv: Buf<u32>,
        vf_offsets: Buf<usize>,
        vf: Buf<u32>,
        fixed: Buf<u8>,
        lines: Buf<u8>,
        stats: TopologyStats,
    ) -> std::result::Result<Topology, String> {
        let n = fixed.len();
        if !(lines.is_empty() || lines.len() == 2 * n) {
            return Err("crease line array has the wrong size".into());
        }
        let shape_ok = |offsets: &[usize], data: usize| {
            offsets.len() == n + 1 && offsets.first() == Some(&0) && offsets.last() == Some(&data)
        };
        if n != stats.vertices
            || !shape_ok(&vv_offsets, vv.len())
            || !shape_ok(&vf_offsets, vf.len())
        {
            return Err("adjacency arrays have inconsistent sizes".into());
        }
        Ok(Topology {
            vv_offsets,
            vv,
            vf_offsets,
            vf,
            fixed,
            lines,
            stats,
        })
    }

    /// Whether the stored adjacency of `v` is well formed: offsets in order and within the arrays,
    /// neighbours and faces in range (for topologies from [`Topology::from_parts`]).
    pub fn check_vertex(&self, v: u32) -> bool {
        let v = v as usize;
        let n = self.len();
        let ok = |offsets: &[usize], len: usize| {
            v < n && offsets[v] <= offsets[v + 1] && offsets[v + 1] <= len
        };
        ok(self.vv_offsets(), self.vv.len())
            && ok(&self.vf_offsets, self.vf.len())
            && self.neighbors(v as u32).iter().all(|&u| (u as usize) < n)
            && self
                .faces_of(v as u32)
                .iter()
                .all(|&t| (t as usize) < self.stats.triangles)
    }

    /// Number of vertices.
    #[inline]
    pub fn len(&self) -> usize {
        self.fixed.len()
    }

    /// True when there are no vertices.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.fixed.is_empty()
    }

    /// Neighbours of `v`, ascending.
    #[inline]
    pub fn neighbors(&self, v: u32) -> &[u32] {
        let v = v as usize;
        let offsets = self.vv_offsets();
        &self.vv[offsets[v]..offsets[v + 1]]
    }

    /// The vertex → vertex offsets, `vf_offsets` when they are the same.
    #[inline]
    fn vv_offsets(&self) -> &[usize] {
        match self.vv_offsets.is_empty() {
            true => &self.vf_offsets,
            false => &self.vv_offsets,
        }
    }

    /// The vertex→vertex CSR arrays: the neighbours of `v` are `vv[offsets[v]..offsets[v + 1]]`.
    /// Every id in `vv` is below [`Topology::len`].
    #[inline]
    pub fn csr(&self) -> (&[usize], &[u32]) {
        (self.vv_offsets(), &self.vv)
    }

    /// Number of neighbours of `v`.
    #[inline]
    pub fn deg(&self, v: u32) -> usize {
        let v = v as usize;
        let offsets = self.vv_offsets();
        offsets[v + 1] - offsets[v]
    }

    /// Triangles using `v` (indices into the triangle array the topology was built from), ascending.
    #[inline]
    pub fn faces_of(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vf[self.vf_offsets[v]..self.vf_offsets[v + 1]]
    }

    /// Whether `v` is fixed (see the module doc).
    #[inline]
    pub fn is_fixed(&self, v: u32) -> bool {
        self.fixed[v as usize] != 0
    }

    /// The fixed-vertex mask, one entry per vertex (non-zero = fixed; bit 2 also marks a crease
    /// vertex, bit 3 a loop vertex, bit 4 a crease line vertex).
    pub fn fixed_mask(&self) -> &[u8] {
        &self.fixed
    }

    /// The two crease neighbours of `v` when it is a crease line vertex (on exactly two crease
    /// edges, see [`Topology::crease`]), ascending: the methods that smooth creases move it as a
    /// point of that line; every other method keeps it fixed, as it keeps a corner. `None` for
    /// any other vertex.
    #[inline]
    pub fn line_neighbors(&self, v: u32) -> Option<[u32; 2]> {
        line_neighbors(&self.fixed, &self.lines, self.neighbors(v), v)
    }

    /// Every undirected edge once, as `(i, j)` with `i < j`, in ascending `(i, j)` order: the edge
    /// stencil order of the stencil methods.
    pub fn edges(&self) -> impl Iterator<Item = [u32; 2]> + '_ {
        self.edges_from(0..self.len() as u32)
    }

    /// The edges `(i, j)`, `i < j`, whose smaller vertex `i` is in `vertices`, in ascending order
    /// (the edge stencils a patch owns).
    pub fn edges_from(
        &self,
        vertices: std::ops::Range<u32>,
    ) -> impl Iterator<Item = [u32; 2]> + '_ {
        vertices.flat_map(move |i| {
            let nbrs = self.neighbors(i);
            let first_above = nbrs.partition_point(|&j| j <= i);
            nbrs[first_above..].iter().map(move |&j| [i, j])
        })
    }

    /// Ask the kernel to read ahead the adjacency of `vertices` when the arrays are memory-mapped
    /// (a hint for the prefetch pipeline; no data is touched).
    pub fn will_need(&self, vertices: std::ops::Range<u32>) {
        let (lo, hi) = (
            vertices.start as usize,
            (vertices.end as usize).min(self.len()),
        );
        if lo >= hi {
            return;
        }
        for offsets in [&self.vv_offsets, &self.vf_offsets] {
            if let Some(a) = offsets.advisor() {
                a.will_need(lo..hi + 1);
            }
        }
        if let Some(a) = self.fixed.advisor() {
            a.will_need(lo..hi);
        }
        if let Some(a) = self.lines.advisor() {
            a.will_need(2 * lo..2 * hi);
        }
        if let Some(a) = self.vv.advisor() {
            a.will_need(self.vv_offsets()[lo]..self.vv_offsets()[hi]);
        }
        if let Some(a) = self.vf.advisor() {
            a.will_need(self.vf_offsets[lo]..self.vf_offsets[hi]);
        }
    }

    /// Bytes held by the adjacency arrays (for memory reports).
    pub fn heap_bytes(&self) -> usize {
        (self.vv_offsets.len() + self.vf_offsets.len()) * std::mem::size_of::<usize>()
            + (self.vv.len() + self.vf.len()) * 4
            + self.fixed.len()
            + self.lines.len()
    }
}
