//! Immutable connectivity: CSR vertex→vertex and vertex→face adjacency, the fixed-vertex mask, and
//! counts of what is unusual about the mesh.
//!
//! Conventions:
//! - `neighbors(v)` is sorted ascending and has no duplicates; `deg(v)` is its length.
//! - `faces_of(v, triangles)` gives the triangles (indices into the triangle array) that use `v`,
//!   ascending, degenerate ones excepted. A topology lists them per vertex, or, once
//!   [`Topology::faces_by_runs`] found the triangles sorted by their first corner and that corner
//!   their smallest (the plan's layout), finds them in the triangle array itself: the faces whose
//!   smallest corner is `u` are one run of it, so `v`'s faces are those of its lower neighbours'
//!   runs that use `v`, then its own run. That keeps 10 to 14 B per triangle less (closed or
//!   open), and the same order.
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

use rayon::prelude::*;

use crate::error::Result;
use crate::mesh::storage::Advisor;
use crate::mesh::{Buf, Storage};

/// CSR adjacency and fixed-vertex mask of a triangle mesh.
#[derive(Debug, Clone, Default)]
pub struct Topology {
    /// Empty when it would equal the face lists' offsets (every vertex has as many neighbours as
    /// faces: a closed manifold), which then serve both lists: 8 bytes per vertex less.
    vv_offsets: Buf<usize>,
    vv: Buf<u32>,
    faces: FaceIndex,
    fixed: Buf<u8>,
    /// Two bytes per vertex when creases were detected (empty otherwise): for a crease line
    /// vertex ([`Topology::line_neighbors`]), the places of its two crease neighbours in its
    /// neighbour list.
    lines: Buf<u8>,
    /// Counts found while building, for `info` and reports.
    pub stats: TopologyStats,
}

/// How a [`Topology`] finds the faces of a vertex.
#[derive(Debug, Clone)]
pub enum FaceIndex {
    /// Vertex → face CSR: offsets (`len + 1`) and triangle indices, each vertex's ascending.
    Lists {
        offsets: Buf<usize>,
        faces: Buf<u32>,
    },
    /// For triangles sorted by their first corner, which is their smallest: the faces whose
    /// smallest corner is `u` are `starts[u]..starts[u + 1]` (`len + 1` entries).
    Runs { starts: Buf<u32> },
}

impl Default for FaceIndex {
    fn default() -> Self {
        FaceIndex::Lists {
            offsets: Buf::default(),
            faces: Buf::default(),
        }
    }
}

/// A [`FaceIndex`]'s arrays, lent.
#[derive(Debug, Clone, Copy)]
pub enum FaceParts<'a> {
    Lists {
        offsets: &'a [usize],
        faces: &'a [u32],
    },
    Runs {
        starts: &'a [u32],
    },
}

impl FaceIndex {
    fn parts(&self) -> FaceParts<'_> {
        match self {
            FaceIndex::Lists { offsets, faces } => FaceParts::Lists { offsets, faces },
            FaceIndex::Runs { starts } => FaceParts::Runs { starts },
        }
    }
}

impl<'a> FaceParts<'a> {
    /// The faces of `v`, whose neighbours `neighbors` gives (ascending), in `triangles` (those
    /// the index was built for), ascending.
    #[inline(always)]
    fn of(
        self,
        v: u32,
        neighbors: impl FnOnce() -> &'a [u32],
        triangles: &'a [[u32; 3]],
    ) -> FacesOf<'a> {
        match self {
            FaceParts::Lists { offsets, faces } => {
                let v = v as usize;
                FacesOf::Listed(faces[offsets[v]..offsets[v + 1]].iter())
            }
            FaceParts::Runs { starts } => FacesOf::Found(RunWalk {
                triangles,
                starts,
                v,
                lower: neighbors().iter(),
                at: 0,
                end: 0,
                own: false,
            }),
        }
    }
}

/// The faces of a vertex ([`Topology::faces_of`]), ascending.
#[derive(Debug, Clone)]
pub enum FacesOf<'a> {
    Listed(std::slice::Iter<'a, u32>),
    Found(RunWalk<'a>),
}

impl Iterator for FacesOf<'_> {
    type Item = u32;

    #[inline(always)]
    fn next(&mut self) -> Option<u32> {
        match self {
            FacesOf::Listed(faces) => faces.next().copied(),
            FacesOf::Found(walk) => walk.next(),
        }
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        match self {
            FacesOf::Listed(faces) => faces.size_hint(),
            FacesOf::Found(_) => (0, None),
        }
    }

    fn count(self) -> usize {
        match self {
            FacesOf::Listed(faces) => faces.len(),
            FacesOf::Found(walk) => walk.count(),
        }
    }
}

/// The faces of `v` found in the runs of the triangle array ([`FaceIndex::Runs`]): those of each
/// lower neighbour's run that use `v`, in the neighbours' order, then `v`'s own run. Runs of
/// larger vertices lie further on, so the faces come ascending, as a list holds them.
#[derive(Debug, Clone)]
pub struct RunWalk<'a> {
    triangles: &'a [[u32; 3]],
    starts: &'a [u32],
    v: u32,
    /// `v`'s neighbours not yet walked; the walk stops taking them at the first above `v`.
    lower: std::slice::Iter<'a, u32>,
    /// The rest of the run being walked.
    at: u32,
    end: u32,
    /// Whether that run is `v`'s own (the last).
    own: bool,
}

impl Iterator for RunWalk<'_> {
    type Item = u32;

    #[inline(always)]
    fn next(&mut self) -> Option<u32> {
        loop {
            if self.at < self.end {
                let t = self.at;
                self.at += 1;
                let tri = self.triangles[t as usize];
                // A lower neighbour's face is `v`'s when `v` is one of its other corners; every
                // face of the own run starts with `v`. Degenerate faces belong to no vertex.
                let uses = self.own | (tri[1] == self.v) | (tri[2] == self.v);
                if uses && !build::is_degenerate(&tri) {
                    return Some(t);
                }
                continue;
            }
            let u = match self.lower.next() {
                Some(&u) if u < self.v => u,
                _ if !self.own => {
                    self.own = true;
                    self.lower = [].iter();
                    self.v
                }
                _ => return None,
            };
            self.at = self.starts[u as usize];
            self.end = self.starts[u as usize + 1];
        }
    }
}

/// Candidate faces (those of a vertex's lower neighbours' runs and of its own) that
/// [`for_each_face!`] gathers at once.
#[doc(hidden)]
pub const GATHERED: usize = 24;

/// `for_each_face!(parts, v, triangles, end, |t, tri| { … })` runs the block for each face `t`
/// of `v` below the triangle `end` (`u32::MAX`: all of them), `tri` its corners, in
/// [`Topology::faces_of`]'s order; `continue` goes to the next face. `parts` is a
/// [`TopologyParts`]. A macro for the kernels' inner loops: written out in place, the block is
/// compiled with its caller (a closure was not inlined into a kernel compiled for AVX2) and the
/// walk of a list is the plain loop over it.
#[macro_export]
macro_rules! for_each_face {
    ($parts:expr, $v:expr, $triangles:expr, $end:expr, |$t:ident, $tri:ident| $body:block) => {{
        let parts: &$crate::topology::TopologyParts = &$parts;
        let (v, triangles, end): (u32, &[[u32; 3]], u32) = ($v, $triangles, $end);
        match parts.faces {
            $crate::topology::FaceParts::Lists { offsets, faces } => {
                for &$t in &faces[offsets[v as usize]..offsets[v as usize + 1]] {
                    if $t >= end {
                        break;
                    }
                    let $tri = triangles[$t as usize];
                    $body
                }
            }
            $crate::topology::FaceParts::Runs { starts } => {
                let neighbors = parts.neighbors(v);
                let lower = &neighbors[..neighbors.partition_point(|&u| u < v)];
                // The faces gathered first without a branch per face (each candidate written,
                // and kept by advancing the count when it is `v`'s), then walked as a list; a
                // vertex with more candidates than the buffer holds is walked in the runs.
                let mut gathered = [0u32; $crate::topology::GATHERED];
                let mut count = 0usize;
                let mut fits = true;
                for u in lower.iter().copied().chain(::core::iter::once(v)) {
                    let (first, last) = (starts[u as usize], starts[u as usize + 1].min(end));
                    if first >= end {
                        break;
                    }
                    if count + (last - first) as usize > $crate::topology::GATHERED {
                        fits = false;
                        break;
                    }
                    let own = u == v;
                    for t in first..last {
                        let c = triangles[t as usize];
                        gathered[count] = t;
                        let uses = own | (c[1] == v) | (c[2] == v);
                        count += (uses & !$crate::topology::is_degenerate(&c)) as usize;
                    }
                }
                if fits {
                    for &$t in &gathered[..count] {
                        let $tri = triangles[$t as usize];
                        $body
                    }
                } else {
                    for u in lower.iter().copied().chain(::core::iter::once(v)) {
                        let (first, last) = (starts[u as usize], starts[u as usize + 1]);
                        if first >= end {
                            break;
                        }
                        // A lower neighbour's face is `v`'s when `v` is one of its other
                        // corners; every face of the own run starts with `v`. Degenerate faces
                        // are no vertex's.
                        let own = u == v;
                        for $t in first..last.min(end) {
                            let $tri = triangles[$t as usize];
                            let uses = own | ($tri[1] == v) | ($tri[2] == v);
                            if !uses || $crate::topology::is_degenerate(&$tri) {
                                continue;
                            }
                            $body
                        }
                    }
                }
            }
        }
    }};
}

/// The arrays of a [`Topology`], as [`Topology::parts`] lends them and
/// [`Topology::from_parts`] takes them back.
pub struct TopologyParts<'a> {
    /// Vertex → vertex CSR offsets (`len + 1`) and neighbour indices.
    pub vv_offsets: &'a [usize],
    pub vv: &'a [u32],
    /// Where the faces of each vertex are.
    pub faces: FaceParts<'a>,
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

    /// [`Topology::faces_of`].
    #[inline(always)]
    pub fn faces_of(&self, v: u32, triangles: &'a [[u32; 3]]) -> FacesOf<'a> {
        self.faces.of(v, || self.neighbors(v), triangles)
    }

    /// [`Topology::faces_bound`].
    #[inline]
    pub fn faces_bound(&self, vertices: std::ops::Range<u32>) -> usize {
        faces_bound(self.faces, self.vv_offsets, self.vv, vertices)
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

/// Most faces a vertex may have for [`Topology::faces_by_runs`] to find faces in runs.
pub const MAX_RUN: usize = 64;

/// Vertices per parallel work item of the build (a work size only: every chunk's result is
/// placed by vertex id, so the topology does not depend on it).
const CHUNK: usize = 1 << 13;

impl Topology {
    /// The arrays: for storing a plan on disk, and for kernels (see [`TopologyParts`]).
    pub fn parts(&self) -> TopologyParts<'_> {
        TopologyParts {
            vv_offsets: self.vv_offsets(),
            vv: &self.vv,
            faces: self.faces.parts(),
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
        faces: FaceIndex,
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
        let faces_ok = match &faces {
            FaceIndex::Lists { offsets, faces } => shape_ok(offsets, faces.len()),
            FaceIndex::Runs { starts } => {
                starts.len() == n + 1
                    && starts.first() == Some(&0)
                    && starts.last().map(|&t| t as usize) == Some(stats.triangles)
            }
        };
        if n != stats.vertices || !shape_ok(&vv_offsets, vv.len()) || !faces_ok {
            return Err("adjacency arrays have inconsistent sizes".into());
        }
        Ok(Topology {
            vv_offsets,
            vv,
            faces,
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
        let t = self.stats.triangles;
        ok(self.vv_offsets(), self.vv.len())
            && self.neighbors(v as u32).iter().all(|&u| (u as usize) < n)
            && match &self.faces {
                FaceIndex::Lists { offsets, faces } => {
                    ok(offsets, faces.len())
                        && faces[offsets[v]..offsets[v + 1]]
                            .iter()
                            .all(|&f| (f as usize) < t)
                }
                // The runs of the vertex and of its lower neighbours, which its walk reads: the
                // neighbours ascending, so that those below the vertex are the walk's.
                FaceIndex::Runs { starts } => {
                    let neighbors = self.neighbors(v as u32);
                    neighbors.windows(2).all(|w| w[0] < w[1])
                        && neighbors
                            .iter()
                            .map(|&u| u as usize)
                            .filter(|&u| u < v)
                            .chain([v])
                            .all(|u| starts[u] <= starts[u + 1] && starts[u + 1] as usize <= t)
                }
            }
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

    /// The vertex → vertex offsets, the face lists' when they are the same.
    #[inline]
    fn vv_offsets(&self) -> &[usize] {
        match (&self.faces, self.vv_offsets.is_empty()) {
            (FaceIndex::Lists { offsets, .. }, true) => offsets,
            _ => &self.vv_offsets,
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

    /// Triangles using `v` (indices into `triangles`, the array the topology was built from:
    /// its runs are read when the faces are not listed), ascending; degenerate ones excepted.
    #[inline]
    pub fn faces_of<'a>(&'a self, v: u32, triangles: &'a [[u32; 3]]) -> FacesOf<'a> {
        self.faces.parts().of(v, || self.neighbors(v), triangles)
    }

    /// At least the number of faces that use some of `vertices` (to size a buffer of them): for
    /// listed faces the lists' lengths together; for runs, the vertices' own runs and the runs
    /// of their neighbours below them all, each run once.
    pub fn faces_bound(&self, vertices: std::ops::Range<u32>) -> usize {
        faces_bound(self.faces.parts(), self.vv_offsets(), &self.vv, vertices)
    }

    /// Find the faces of each vertex in the runs of `triangles` ([`FaceIndex::Runs`]) rather than
    /// in lists, when they are sorted by their first corner and that corner is their smallest
    /// (and this topology was built from them): 12 B per triangle less, and 4 more for a mesh
    /// whose neighbour lists kept their own offsets. The same faces in the same order. Returns
    /// whether it did; the lists stay otherwise.
    pub fn faces_by_runs(&mut self, storage: &Storage, triangles: &[[u32; 3]]) -> Result<bool> {
        if matches!(self.faces, FaceIndex::Runs { .. }) {
            return Ok(true);
        }
        if triangles.len() != self.stats.triangles || !build::sorted_by_first(triangles) {
            return Ok(false);
        }
        // A vertex's neighbours each walk its run: a hub whose run is long (a hole filled by a
        // fan) would cost its d neighbours d faces each, where the lists cost them their own.
        // A run is no longer than its vertex's list, so such a mesh keeps the lists.
        if let FaceIndex::Lists { offsets, .. } = &self.faces
            && offsets.par_windows(2).any(|w| w[1] - w[0] > MAX_RUN)
        {
            return Ok(false);
        }
        // The lists go before the runs' starts are made, so that they are never held together.
        let lists = std::mem::replace(
            &mut self.faces,
            FaceIndex::Runs {
                starts: Buf::default(),
            },
        );
        if let FaceIndex::Lists { offsets, faces } = lists {
            drop(faces);
            if self.vv_offsets.is_empty() {
                self.vv_offsets = offsets;
            }
        }
        self.faces = FaceIndex::Runs {
            starts: build::run_starts(storage, self.len(), triangles)?,
        };
        Ok(true)
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
        let face_offsets = match &self.faces {
            FaceIndex::Lists { offsets, .. } => offsets,
            FaceIndex::Runs { .. } => &Buf::default(),
        };
        for offsets in [&self.vv_offsets, face_offsets] {
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
        match &self.faces {
            FaceIndex::Lists { offsets, faces } => {
                if let Some(a) = faces.advisor() {
                    a.will_need(offsets[lo]..offsets[hi]);
                }
            }
            // The runs of the range's vertices; the lower neighbours' lie mostly among them.
            FaceIndex::Runs { starts } => {
                if let Some(a) = starts.advisor() {
                    a.will_need(lo..hi + 1);
                }
            }
        }
    }

    /// [`Topology::will_need`] for scattered `vertices` (ascending; a patch's rings), and, given
    /// the triangles' advisor, their faces' runs: each page asked for once.
    pub fn will_need_scattered(&self, vertices: &[u32], triangles: Option<&Advisor>) {
        let each = |a: Option<Advisor>, per: usize, extra: usize| {
            if let Some(a) = a {
                let at = |v: u32| v as usize * per;
                a.will_need_each(vertices.iter().map(|&v| at(v)..at(v) + per + extra));
            }
        };
        let face_offsets = match &self.faces {
            FaceIndex::Lists { offsets, .. } => offsets.advisor(),
            FaceIndex::Runs { starts } => starts.advisor(),
        };
        each(self.vv_offsets.advisor(), 1, 1);
        each(face_offsets, 1, 1);
        each(self.fixed.advisor(), 1, 0);
        each(self.lines.advisor(), 2, 0);
        // Each vertex's span of a CSR array, from its offsets: read here, so asked for above
        // first, so that their reads are under way together.
        let spans = |a: Option<&Advisor>, start: &dyn Fn(usize) -> usize| {
            if let Some(a) = a {
                a.will_need_each(
                    vertices
                        .iter()
                        .map(|&v| start(v as usize)..start(v as usize + 1)),
                );
            }
        };
        let offsets = self.vv_offsets();
        spans(self.vv.advisor().as_ref(), &|v| offsets[v]);
        match &self.faces {
            FaceIndex::Lists { offsets, faces } => spans(faces.advisor().as_ref(), &|v| offsets[v]),
            FaceIndex::Runs { starts } => spans(triangles, &|v| starts[v] as usize),
        }
    }

    /// [`crate::mesh::storage::read_at_random`] for every array of the topology.
    pub fn read_at_random(&self, random: bool) {
        use crate::mesh::storage::read_at_random;
        read_at_random(&self.vv_offsets, random);
        read_at_random(&self.vv, random);
        match &self.faces {
            FaceIndex::Lists { offsets, faces } => {
                read_at_random(offsets, random);
                read_at_random(faces, random);
            }
            FaceIndex::Runs { starts } => {
                read_at_random(starts, random);
            }
        }
        read_at_random(&self.fixed, random);
        read_at_random(&self.lines, random);
    }

    /// Bytes held by the adjacency arrays (for memory reports).
    pub fn heap_bytes(&self) -> usize {
        let faces = match &self.faces {
            FaceIndex::Lists { offsets, faces } => offsets.len() * 8 + faces.len() * 4,
            FaceIndex::Runs { starts } => starts.len() * 4,
        };
        self.vv_offsets.len() * std::mem::size_of::<usize>()
            + self.vv.len() * 4
            + faces
            + self.fixed.len()
            + self.lines.len()
    }
}

/// [`Topology::faces_bound`] on the arrays.
fn faces_bound(
    faces: FaceParts,
    vv_offsets: &[usize],
    vv: &[u32],
    vertices: std::ops::Range<u32>,
) -> usize {
    let (lo, hi) = (vertices.start as usize, vertices.end as usize);
    if lo >= hi {
        return 0;
    }
    match faces {
        FaceParts::Lists { offsets, .. } => offsets[hi] - offsets[lo],
        FaceParts::Runs { starts } => {
            // The vertices' own runs, and the runs of their neighbours below them all, each once.
            let mut below: Vec<u32> = vv[vv_offsets[lo]..vv_offsets[hi]]
                .iter()
                .copied()
                .filter(|&u| (u as usize) < lo)
                .collect();
            below.sort_unstable();
            below.dedup();
            let run = |u: u32| (starts[u as usize + 1] - starts[u as usize]) as usize;
            (starts[hi] - starts[lo]) as usize + below.into_iter().map(run).sum::<usize>()
        }
    }
}
