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

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::mesh::{Buf, Storage};
use crate::meter::{Meter, Passes};

/// CSR adjacency and fixed-vertex mask of a triangle mesh.
#[derive(Debug, Clone, Default)]
pub struct Topology {
    vv_offsets: Buf<usize>,
    vv: Buf<u32>,
    vf_offsets: Buf<usize>,
    vf: Buf<u32>,
    fixed: Buf<u8>,
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
    /// One byte per vertex, 1 = fixed.
    pub fixed: &'a [u8],
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
}

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
    /// Vertices that no method moves (see the module doc).
    pub fixed_vertices: usize,
    /// Edges of two triangles that both traverse it in the same direction: the input's faces are
    /// not consistently oriented there (counted on the faces as built, before [`Topology::orient`]).
    #[serde(default)]
    pub inconsistent_orientation_edges: usize,
    /// Components (through edges of two triangles) that no choice of face orientations makes
    /// consistent, such as a Möbius strip; found by [`Topology::orient`].
    #[serde(default)]
    pub non_orientable_components: usize,
    /// Edges left inconsistent by [`Topology::orient`] in non-orientable components; their vertices
    /// are fixed.
    #[serde(default)]
    pub orientation_seam_edges: usize,
    /// Vertices with more than [`MAX_FREE_DEGREE`] neighbours (fixed).
    #[serde(default)]
    pub high_degree_vertices: usize,
    /// Vertices pinned by the caller ([`Topology::pin`]): fixed whatever their topology, and
    /// counted in `fixed_vertices`.
    #[serde(default)]
    pub pinned_vertices: usize,
    /// Edges of two triangles whose normals differ by more than the run's crease angle
    /// ([`Topology::crease`]); 0 when no crease angle is given.
    #[serde(default)]
    pub crease_edges: usize,
    /// Vertices on a crease edge: fixed, and counted in `fixed_vertices`.
    #[serde(default)]
    pub crease_vertices: usize,
}

impl TopologyStats {
    /// Count vertex `v`'s analysis `a`, and set its entry `fix` of the fixed mask (which
    /// degenerate triangles at `v` may have set before: then it is not a loop vertex).
    fn count(&mut self, a: &VertexAnalysis, fix: &mut u8) {
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

    fn add(mut self, o: TopologyStats) -> TopologyStats {
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

/// Bits of the fixed-vertex mask: any non-zero entry is a fixed vertex; [`CREASE`] also marks it
/// as a crease vertex ([`Topology::crease`]), whose row the stencil energy leaves out; [`LOOP`]
/// as a loop vertex (see the module doc), which any other reason to fix it clears.
const FIXED: u8 = 1;
const CREASE: u8 = 2;
const LOOP: u8 = 4;

/// Pass 2 of the build, for a mesh whose vertices do not all have as many neighbours as faces:
/// the neighbour lists laid out by `vv_offsets`, each chunk of vertices into its own slice.
fn pass_2(
    storage: &Storage,
    vv_offsets: &[usize],
    vf_offsets: &[usize],
    vf: &[u32],
    triangles: &[[u32; 3]],
    meter: &Meter,
) -> Result<Buf<u32>> {
    let n_vertices = vv_offsets.len() - 1;
    let chunks = n_vertices.div_ceil(CHUNK);
    let mut vv: Buf<u32> = storage.zeroed(vv_offsets[n_vertices])?;
    let chunk_lens: Vec<usize> = (0..chunks)
        .map(|c| {
            let (lo, hi) = (c * CHUNK, ((c + 1) * CHUNK).min(n_vertices));
            vv_offsets[hi] - vv_offsets[lo]
        })
        .collect();
    split_lens(&mut vv, &chunk_lens)
        .into_par_iter()
        .enumerate()
        .for_each_init(VertexScratch::default, |scratch, (c, out)| {
            let range = c * CHUNK..((c + 1) * CHUNK).min(n_vertices);
            let range_len = range.len() as u64;
            let mut at = 0;
            for v in range {
                let faces = &vf[vf_offsets[v]..vf_offsets[v + 1]];
                let deg = vv_offsets[v + 1] - vv_offsets[v];
                write_neighbors(v as u32, faces, triangles, scratch, &mut out[at..at + deg]);
                at += deg;
            }
            meter.add(range_len);
        });
    Ok(vv)
}

/// Reusable per-thread buffers of the per-vertex analysis.
#[derive(Default)]
struct VertexScratch {
    /// Pass 1: `u << 1 | direction` for each corner u of a face at v (0: the face runs v → u,
    /// 1: u → v); pass 2: the corners alone.
    keys: Vec<u64>,
    corners: Vec<u32>,
    parent: Vec<usize>,
}

/// Reusable per-thread buffers of a chunk of vertices in pass 1: a copy of its region of the
/// vertex → face array while that is sorted by vertex, and the link edge `(b[i], c[i])` of
/// each entry of the sorted region (its face runs v → b → c), so that the analysis reads no
/// triangle again.
#[derive(Default)]
struct ChunkScratch {
    faces: Vec<u32>,
    b: Vec<u32>,
    c: Vec<u32>,
}

impl Topology {
    /// Build the adjacency of `n_vertices` vertices and `triangles`, on the heap.
    ///
    /// Fails only if a triangle indexes a vertex `>= n_vertices` (readers reject those first).
    pub fn build(n_vertices: usize, triangles: &[[u32; 3]]) -> Result<Topology> {
        Topology::build_in(&Storage::heap(), n_vertices, triangles)
    }

    /// Build as [`Topology::build`], placing the arrays as `storage` says. Parallel over vertices
    /// on the current rayon pool; the result does not depend on the number of threads.
    pub fn build_in(
        storage: &Storage,
        n_vertices: usize,
        triangles: &[[u32; 3]],
    ) -> Result<Topology> {
        Topology::build_metered(storage, n_vertices, triangles, &Meter::default())
    }

    /// The passes [`Topology::build_metered`] counts: the corners counted and their faces placed
    /// (triangles), the vertices analysed and their neighbours listed (vertices).
    pub const BUILD_PASSES: Passes = Passes {
        vertices: 2,
        triangles: 2,
    };

    /// [`Topology::build_in`], counting its work into `meter` ([`Topology::BUILD_PASSES`] over
    /// the mesh, once per block of triangles or chunk of vertices). The same topology.
    pub fn build_metered(
        storage: &Storage,
        n_vertices: usize,
        triangles: &[[u32; 3]],
        meter: &Meter,
    ) -> Result<Topology> {
        if n_vertices > u32::MAX as usize || triangles.len() > u32::MAX as usize {
            return Err(Error::topology(format!(
                "{n_vertices} vertices / {} triangles exceed the 2^32 limit",
                triangles.len()
            )));
        }
        let mut stats = TopologyStats {
            vertices: n_vertices,
            triangles: triangles.len(),
            ..Default::default()
        };
        let mut fixed: Buf<u8> = storage.zeroed(n_vertices)?;

        // Vertex → face CSR, a counting sort in parallel: each block of triangles counts its
        // corners per chunk of vertices, then scatters its triangle ids into the chunks' regions
        // (block after block, so each region holds its triangles ascending); each chunk then sorts
        // its region by vertex, stably, and analyses its vertices (pass 1).
        let chunks = n_vertices.div_ceil(CHUNK);
        let block_len = triangles.len().div_ceil(BLOCKS).max(1);
        let counted: Vec<BlockCount> = triangles
            .par_chunks(block_len)
            .enumerate()
            .map(|(b, block)| {
                let count = count_block(b * block_len, block, n_vertices, chunks);
                meter.add(block.len() as u64);
                count
            })
            .collect();
        if let Some(t) = counted.iter().find_map(|c| c.out_of_range) {
            return Err(Error::topology(format!(
                "triangle {t} indexes a vertex out of range (0..{n_vertices})"
            )));
        }
        for &t in counted.iter().flat_map(|c| &c.degenerate) {
            stats.degenerate_triangles += 1;
            for &v in &triangles[t as usize] {
                fixed[v as usize] = 1;
            }
        }
        // Where each chunk's region starts in `vf`.
        let mut region_start = Vec::with_capacity(chunks + 1);
        let mut total = 0usize;
        for c in 0..chunks {
            region_start.push(total);
            total += counted
                .iter()
                .map(|b| b.per_chunk[c] as usize)
                .sum::<usize>();
        }
        region_start.push(total);
        let mut vf: Buf<u32> = storage.zeroed(total)?;
        // Each block's piece of each chunk's region, in chunk order.
        let mut pieces: Vec<Vec<&mut [u32]>> = (0..counted.len())
            .map(|_| Vec::with_capacity(chunks))
            .collect();
        let mut rest: &mut [u32] = &mut vf;
        for c in 0..chunks {
            for (b, count) in counted.iter().enumerate() {
                let (piece, tail) =
                    std::mem::take(&mut rest).split_at_mut(count.per_chunk[c] as usize);
                pieces[b].push(piece);
                rest = tail;
            }
        }
        pieces
            .into_par_iter()
            .zip(triangles.par_chunks(block_len))
            .enumerate()
            .for_each(|(b, (mut pieces, block))| {
                for (k, tri) in block.iter().enumerate() {
                    if is_degenerate(tri) {
                        continue;
                    }
                    let t = (b * block_len + k) as u32;
                    let c = tri[0] as usize / CHUNK;
                    if tri.iter().all(|&v| v as usize / CHUNK == c) {
                        // Nearly every face: its three places taken at once, rather than each
                        // waiting for the piece to be shortened by the one before.
                        let (head, tail) = std::mem::take(&mut pieces[c]).split_at_mut(3);
                        head.fill(t);
                        pieces[c] = tail;
                        continue;
                    }
                    for &v in tri {
                        let piece = &mut pieces[v as usize / CHUNK];
                        let (head, tail) =
                            std::mem::take(piece).split_first_mut().expect("counted");
                        *head = t;
                        *piece = tail;
                    }
                }
                meter.add(block.len() as u64);
            });

        // Pass 1, chunk by chunk: sort the region by vertex into `vf` and its offsets, then per
        // vertex the number of distinct neighbours, edge counts and the fixed flag. The
        // neighbours go to `vv` laid out as `vf`, which is their final place when every vertex
        // has as many neighbours as faces (a closed manifold: no pass 2 then).
        let mut vf_offsets: Buf<usize> = storage.zeroed(n_vertices + 1)?;
        let mut vv_offsets: Buf<usize> = storage.zeroed(n_vertices + 1)?;
        let mut vv: Buf<u32> = storage.zeroed(total)?;
        let region_lens: Vec<usize> = region_start.windows(2).map(|w| w[1] - w[0]).collect();
        // Each chunk's stats, vertices with more or fewer neighbours than faces, and neighbours.
        let found: Vec<(TopologyStats, usize, usize)> = split_lens(&mut vf, &region_lens)
            .into_par_iter()
            .zip(split_lens(&mut vv, &region_lens))
            .zip(vf_offsets[1..].par_chunks_mut(CHUNK))
            .zip(vv_offsets[1..].par_chunks_mut(CHUNK))
            .zip(fixed.par_chunks_mut(CHUNK))
            .enumerate()
            .map_init(
                <(ChunkScratch, VertexScratch)>::default,
                |(link, scratch), (c, ((((region, nbrs), ends), degs), fixed))| {
                    let lo = (c * CHUNK) as u32;
                    sort_region(lo, region, region_start[c], ends, triangles, link);
                    let mut st = TopologyStats::default();
                    let mut misfits = 0;
                    let mut start = 0;
                    // The offsets in `vv` as if every vertex before had as many neighbours as
                    // faces, as in a closed manifold; those of a mesh with misfits are shifted
                    // below. So the offsets are summed here, in parallel, not in a sequential
                    // pass after.
                    let mut placed = region_start[c];
                    for (k, (deg, fix)) in degs.iter_mut().zip(fixed.iter_mut()).enumerate() {
                        let end = ends[k] - region_start[c];
                        let (b, c) = (&link.b[start..end], &link.c[start..end]);
                        let a = analyse_vertex(lo + k as u32, b, c, scratch, &mut nbrs[start..]);
                        start = end;
                        placed += a.degree;
                        *deg = placed;
                        misfits += (a.degree != b.len()) as usize;
                        st.count(&a, fix);
                    }
                    meter.add(degs.len() as u64);
                    (st, misfits, placed - region_start[c])
                },
            )
            .collect();
        let mut misfits = 0;
        for &(st, m, _) in &found {
            stats = stats.add(st);
            misfits += m;
        }
        if misfits > 0 {
            // Shift each chunk's offsets by how much its neighbours' place in `vv` differs from
            // its faces' in `vf` (the sums over the chunks before it).
            let mut placed = 0usize;
            let shifts: Vec<usize> = (found.iter().zip(&region_start))
                .map(|(&(_, _, n), &start)| {
                    let shift = placed.wrapping_sub(start);
                    placed += n;
                    shift
                })
                .collect();
            vv_offsets[1..]
                .par_chunks_mut(CHUNK)
                .zip(shifts)
                .filter(|(_, shift)| *shift != 0)
                .for_each(|(offsets, shift)| {
                    offsets.iter_mut().for_each(|o| *o = o.wrapping_add(shift));
                });
        }
        if misfits == 0 {
            // The skipped pass 2, for the meter.
            meter.add(n_vertices as u64);
        } else {
            // Pass 1's array goes before pass 2's is made, so the two are never held at once.
            drop(std::mem::take(&mut vv));
            vv = pass_2(storage, &vv_offsets, &vf_offsets, &vf, triangles, meter)?;
        }
        Ok(Topology {
            vv_offsets,
            vv,
            vf_offsets,
            vf,
            fixed,
            stats,
        })
    }

    /// The arrays: for storing a plan on disk, and for kernels (see [`TopologyParts`]).
    pub fn parts(&self) -> TopologyParts<'_> {
        TopologyParts {
            vv_offsets: &self.vv_offsets,
            vv: &self.vv,
            vf_offsets: &self.vf_offsets,
            vf: &self.vf,
            fixed: &self.fixed,
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
        stats: TopologyStats,
    ) -> std::result::Result<Topology, String> {
        let n = fixed.len();
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
        ok(&self.vv_offsets, self.vv.len())
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
        &self.vv[self.vv_offsets[v]..self.vv_offsets[v + 1]]
    }

    /// The vertex→vertex CSR arrays: the neighbours of `v` are `vv[offsets[v]..offsets[v + 1]]`.
    /// Every id in `vv` is below [`Topology::len`].
    #[inline]
    pub fn csr(&self) -> (&[usize], &[u32]) {
        (&self.vv_offsets, &self.vv)
    }

    /// Number of neighbours of `v`.
    #[inline]
    pub fn deg(&self, v: u32) -> usize {
        let v = v as usize;
        self.vv_offsets[v + 1] - self.vv_offsets[v]
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

    /// Whether `v` is a loop vertex: fixed only because it is a regular boundary vertex (see the
    /// module doc), so boundary smoothing may move it along its loop.
    #[inline]
    pub fn is_loop(&self, v: u32) -> bool {
        self.fixed[v as usize] == FIXED | LOOP
    }

    /// The two neighbours of `v` along its boundary loop (the other ends of its two boundary
    /// edges, ascending), when `v` is on exactly two boundary edges; `None` otherwise.
    /// `triangles` is the array the topology was built from; any orientation. Costs O(d²) in
    /// the number d of faces of `v` (about 4 on a boundary).
    pub fn loop_neighbors(&self, triangles: &[[u32; 3]], v: u32) -> Option<[u32; 2]> {
        let faces = self.faces_of(v);
        // A neighbour is across a boundary edge when exactly one face of v holds it.
        let mut found = [0u32; 2];
        let mut count = 0;
        for &u in self.neighbors(v) {
            let holding = faces
                .iter()
                .filter(|&&t| triangles[t as usize].contains(&u))
                .take(2)
                .count();
            if holding == 1 {
                if count == 2 {
                    return None;
                }
                found[count] = u;
                count += 1;
            }
        }
        (count == 2).then_some(found)
    }

    /// The fixed-vertex mask, one entry per vertex (non-zero = fixed; bit 2 also marks a crease
    /// vertex, bit 3 a loop vertex).
    pub fn fixed_mask(&self) -> &[u8] {
        &self.fixed
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
        if let Some(a) = self.vv.advisor() {
            a.will_need(self.vv_offsets[lo]..self.vv_offsets[hi]);
        }
        if let Some(a) = self.vf.advisor() {
            a.will_need(self.vf_offsets[lo]..self.vf_offsets[hi]);
        }
    }

    /// Fix the vertices for which `pinned(v)` holds (this topology's ids), whatever their
    /// topology: no method moves them, and a stencil containing one is skipped like one with a
    /// boundary vertex, so stencil volumes stay exact. Counts them in
    /// [`TopologyStats::pinned_vertices`] and those not fixed before in `fixed_vertices`.
    /// Parallel over vertices; the result does not depend on the number of threads.
    pub fn pin(&mut self, pinned: impl Fn(u32) -> bool + Sync) {
        let (pins, newly) = self.fix_where(pinned);
        self.stats.pinned_vertices += pins;
        self.stats.fixed_vertices += newly;
    }

    /// Fix the vertices on crease edges: edges of two triangles whose normals, measured on
    /// `positions` (this topology's ids), differ by more than `angle_deg` degrees (0° where the
    /// surface is flat, 90° on a cube's edge). The angle does not depend on the faces'
    /// orientation. Counts the edges in [`TopologyStats::crease_edges`], their vertices in
    /// `crease_vertices` and those not fixed before in `fixed_vertices`. Corners where creases
    /// meet are crease vertices too. Parallel over vertices; the result does not depend on the
    /// number of threads.
    pub fn crease(&mut self, triangles: &[[u32; 3]], positions: &[DVec3], angle_deg: f64) {
        let cos_limit = angle_deg.to_radians().cos();
        let n = self.len();
        // Crease edges at each vertex; a vertex's edges to higher ids count the edges once.
        let counts: Vec<(u32, u32)> = (0..n as u32)
            .into_par_iter()
            .with_min_len(CHUNK)
            .map(|v| {
                let (mut all, mut above) = (0u32, 0u32);
                for &u in self.neighbors(v) {
                    if self.is_crease_edge(triangles, positions, v, u, cos_limit) {
                        all += 1;
                        above += (u > v) as u32;
                    }
                }
                (all, above)
            })
            .collect();
        let edges: usize = counts.iter().map(|c| c.1 as usize).sum();
        let (vertices, newly) = self.fix_where_as(CREASE, |v| counts[v as usize].0 > 0);
        self.stats.crease_edges += edges;
        self.stats.crease_vertices += vertices;
        self.stats.fixed_vertices += newly;
    }

    /// Whether edge `(v, u)` has exactly two triangles whose normals (each taken in the direction
    /// the edge is traversed, so that orientation does not matter) make an angle whose cosine is
    /// below `cos_limit`. A triangle of zero area makes no crease.
    fn is_crease_edge(
        &self,
        triangles: &[[u32; 3]],
        positions: &[DVec3],
        v: u32,
        u: u32,
        cos_limit: f64,
    ) -> bool {
        let mut normals = [DVec3::ZERO; 2];
        let mut found = 0;
        for &f in self.faces_of(v) {
            let t = triangles[f as usize];
            let Some(k) = t.iter().position(|&x| x == v) else {
                continue;
            };
            let (next, prev) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let sign = if next == u {
                1.0
            } else if prev == u {
                -1.0
            } else {
                continue;
            };
            if found == 2 {
                return false;
            }
            let [a, b, c] = t.map(|x| positions[x as usize]);
            normals[found] = sign * (b - a).cross(c - a);
            found += 1;
        }
        if found != 2 {
            return false;
        }
        // Opposite traversals (a consistent pair) give opposite signs: flip one back.
        let (n0, n1) = (normals[0], -normals[1]);
        let (l0, l1) = (n0.length(), n1.length());
        if l0 == 0.0 || l1 == 0.0 {
            return false;
        }
        n0.dot(n1) / (l0 * l1) < cos_limit
    }

    /// Whether `v` is a crease vertex ([`Topology::crease`]; such a vertex is also fixed).
    #[inline]
    pub fn is_crease(&self, v: u32) -> bool {
        self.fixed[v as usize] & CREASE != 0
    }

    /// Fix the vertices for which `fixed(v)` holds; returns how many did and how many of them
    /// were not fixed before.
    fn fix_where(&mut self, fixed: impl Fn(u32) -> bool + Sync) -> (usize, usize) {
        self.fix_where_as(FIXED, fixed)
    }

    /// [`Topology::fix_where`], marking the vertices with `mark` (a fixed mark, [`FIXED`] or
    /// [`FIXED`] | [`CREASE`]).
    fn fix_where_as(&mut self, mark: u8, fixed: impl Fn(u32) -> bool + Sync) -> (usize, usize) {
        let mark = mark | FIXED;
        self.fixed
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                let (mut all, mut newly) = (0, 0);
                for (k, f) in chunk.iter_mut().enumerate() {
                    if fixed((c * CHUNK + k) as u32) {
                        all += 1;
                        newly += (*f == 0) as usize;
                        *f = (*f | mark) & !LOOP;
                    }
                }
                (all, newly)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    }

    /// Bytes held by the adjacency arrays (for memory reports).
    pub fn heap_bytes(&self) -> usize {
        (self.vv_offsets.len() + self.vf_offsets.len()) * std::mem::size_of::<usize>()
            + (self.vv.len() + self.vf.len()) * 4
            + self.fixed.len()
    }
}

/// A face's orientation as [`Topology::orient`] decides it.
const UNSEEN: u8 = 0;
const KEEP: u8 = 1;
const FLIP: u8 = 2;

impl Topology {
    /// Orient `triangles` (the array this topology was built from, or a copy the smoothing works
    /// on) consistently: flip faces (swapping their last two corners, so the first stays first)
    /// until the two faces of every edge traverse it in opposite directions. Does nothing when the
    /// build found no inconsistent edge, so a consistently oriented mesh keeps its faces as they
    /// are.
    ///
    /// Each component (faces joined through edges of exactly two faces) is walked breadth first
    /// from its first face, each face taking the orientation its neighbour asks for; then the
    /// orientation the majority of the component's faces had in the input is kept (on a tie, the
    /// one with a positive signed volume). In a non-orientable component (a Möbius strip, a Klein
    /// bottle) some edges stay inconsistent; their vertices are fixed, like those of a boundary.
    /// Counts go to [`TopologyStats::non_orientable_components`] and
    /// [`TopologyStats::orientation_seam_edges`]. Calling it again on its own result changes
    /// nothing.
    ///
    /// Cost: linear in the faces (the other face of an edge is looked up among the faces of its
    /// endpoint with fewer faces), plus a byte per face and a list of one component's faces.
    pub fn orient(&mut self, triangles: &mut [[u32; 3]], positions: &[DVec3]) {
        if self.stats.inconsistent_orientation_edges == 0 {
            return;
        }
        let mut state = vec![UNSEEN; triangles.len()];
        let mut component: Vec<u32> = Vec::new();
        let mut seam: Vec<u32> = Vec::new();
        let (mut non_orientable, mut seams) = (0, 0);
        for seed in 0..triangles.len() {
            if state[seed] != UNSEEN || is_degenerate(&triangles[seed]) {
                continue;
            }
            state[seed] = KEEP;
            component.clear();
            component.push(seed as u32);
            let mut conflicts = 0;
            let mut head = 0;
            while let Some(&t) = component.get(head) {
                head += 1;
                let tri = oriented(triangles[t as usize], state[t as usize]);
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    let Some(o) = self.other_face(triangles, t, a, b) else {
                        continue;
                    };
                    // The neighbour must run b → a.
                    let want = if runs(triangles[o as usize], a, b) {
                        FLIP
                    } else {
                        KEEP
                    };
                    let have = &mut state[o as usize];
                    if *have == UNSEEN {
                        *have = want;
                        component.push(o);
                    } else if *have != want && t < o {
                        // Seen from both faces: counted from the smaller.
                        conflicts += 1;
                        seam.extend([a, b]);
                    }
                }
            }
            if conflicts > 0 {
                non_orientable += 1;
                seams += conflicts;
            }
            let flipped = component
                .iter()
                .filter(|&&t| state[t as usize] == FLIP)
                .count();
            let kept = component.len() - flipped;
            let invert = flipped > kept
                || (flipped == kept && {
                    let origin = positions[triangles[seed][0] as usize];
                    let volume: f64 = component
                        .iter()
                        .map(|&t| {
                            let [a, b, c] = oriented(triangles[t as usize], state[t as usize])
                                .map(|v| positions[v as usize] - origin);
                            a.dot(b.cross(c))
                        })
                        .sum();
                    volume < 0.0
                });
            for &t in &component {
                if (state[t as usize] == FLIP) != invert {
                    triangles[t as usize].swap(1, 2);
                }
            }
        }
        for v in seam {
            let f = &mut self.fixed[v as usize];
            self.stats.fixed_vertices += (*f == 0) as usize;
            *f = (*f | FIXED) & !LOOP;
        }
        self.stats.non_orientable_components = non_orientable;
        self.stats.orientation_seam_edges = seams;
    }

    /// The one face other than `t` with the edge `a`–`b`, if the edge has exactly two faces.
    /// Scans the faces of the endpoint with fewer, so that the edges of a vertex of high degree
    /// cost what their other endpoint costs.
    fn other_face(&self, triangles: &[[u32; 3]], t: u32, a: u32, b: u32) -> Option<u32> {
        let (x, y) = if self.faces_of(a).len() <= self.faces_of(b).len() {
            (a, b)
        } else {
            (b, a)
        };
        let mut found = None;
        for &f in self.faces_of(x) {
            if f != t && triangles[f as usize].contains(&y) {
                if found.is_some() {
                    return None;
                }
                found = Some(f);
            }
        }
        found
    }
}

/// `tri` as [`Topology::orient`]'s `state` says (flipped: the last two corners swapped).
#[inline]
fn oriented(tri: [u32; 3], state: u8) -> [u32; 3] {
    if state == FLIP {
        [tri[0], tri[2], tri[1]]
    } else {
        tri
    }
}

/// Whether `tri` traverses its edge from `a` to `b` (both corners).
#[inline]
fn runs(tri: [u32; 3], a: u32, b: u32) -> bool {
    (0..3).any(|k| tri[k] == a && tri[(k + 1) % 3] == b)
}

/// What the build learns about one vertex from its faces.
#[derive(Debug, PartialEq, Eq)]
struct VertexAnalysis {
    degree: usize,
    /// Edges to higher-numbered neighbours (each undirected edge counted once), by kind.
    edges: usize,
    boundary_edges: usize,
    non_manifold_edges: usize,
    /// Edges of two faces that run the same way (to higher-numbered neighbours).
    inconsistent_edges: usize,
    non_manifold_vertex: bool,
    fixed: bool,
    /// On exactly two boundary edges, manifold, link one path, degree at most
    /// [`MAX_FREE_DEGREE`]: fixed only as a boundary vertex.
    loop_vertex: bool,
}

/// Blocks of triangles the vertex → face build counts and scatters in parallel (a work size
/// only, like [`CHUNK`]).
const BLOCKS: usize = 64;

/// What one block of triangles holds for the vertex → face build.
struct BlockCount {
    /// Corners of the block's (non-degenerate) triangles in each chunk of [`CHUNK`] vertices.
    per_chunk: Vec<u32>,
    /// The block's degenerate triangles (a repeated corner), ascending.
    degenerate: Vec<u32>,
    /// The block's first triangle with a corner out of range.
    out_of_range: Option<usize>,
}

/// `data` cut into consecutive slices of `lens` (which sum to at most its length).
pub(crate) fn split_lens<'a, T>(mut data: &'a mut [T], lens: &[usize]) -> Vec<&'a mut [T]> {
    lens.iter()
        .map(|&n| {
            let (head, tail) = std::mem::take(&mut data).split_at_mut(n);
            data = tail;
            head
        })
        .collect()
}

/// Count the corners of `block` (triangles `first..`) per chunk of vertices.
fn count_block(first: usize, block: &[[u32; 3]], n_vertices: usize, chunks: usize) -> BlockCount {
    let mut count = BlockCount {
        per_chunk: Vec::new(),
        degenerate: Vec::new(),
        out_of_range: None,
    };
    // A count per corner of the triangle: the corners of a face are nearly always in one chunk,
    // and one counter would make each of their increments wait for the one before.
    let mut corners = vec![[0u32; 3]; chunks];
    for (k, tri) in block.iter().enumerate() {
        if tri.iter().any(|&v| v as usize >= n_vertices) {
            count.out_of_range = Some(first + k);
            break;
        }
        if is_degenerate(tri) {
            count.degenerate.push((first + k) as u32);
            continue;
        }
        for (j, &v) in tri.iter().enumerate() {
            corners[v as usize / CHUNK][j] += 1;
        }
    }
    count.per_chunk = corners.iter().map(|c| c.iter().sum()).collect();
    count
}

/// Sort the region of `vf` of the chunk of vertices from `lo`, which holds the ids of the faces
/// at its vertices ascending (a face once per corner in the chunk, in a row), by vertex, keeping
/// each vertex's faces ascending, and the link edge of each sorted entry into `s.b`, `s.c`;
/// `ends[k]` gets where vertex `lo + k`'s faces end in `vf` (the region starts at `start`).
fn sort_region(
    lo: u32,
    region: &mut [u32],
    start: usize,
    ends: &mut [usize],
    triangles: &[[u32; 3]],
    s: &mut ChunkScratch,
) {
    let n = ends.len() as u32;
    s.faces.clear();
    s.faces.extend_from_slice(region);
    // A counting sort in two sweeps over the region's faces, each taken once for all its
    // corners in the chunk; the second reads the triangles again rather than keep each
    // entry's vertex from the first.
    ends.fill(0);
    let mut i = 0;
    while let Some(&t) = region.get(i) {
        let k = triangles[t as usize].map(|u| u.wrapping_sub(lo));
        if k.iter().all(|&k| k < n) {
            // The common case, a face inside the chunk, without a branch per corner.
            for k in k {
                ends[k as usize] += 1;
            }
            i += 3;
            continue;
        }
        for k in k {
            if k < n {
                ends[k as usize] += 1;
                i += 1;
            }
        }
    }
    // `ends` as starts within the region, then advanced past each placed face to the ends.
    let mut at = 0;
    for e in ends.iter_mut() {
        let n = *e;
        *e = at;
        at += n;
    }
    s.b.resize(region.len(), 0);
    s.c.resize(region.len(), 0);
    // Slices apart from `s`, so that the compiler need not reload where they are after each
    // store.
    let (faces, b, c) = (&s.faces[..], &mut s.b[..], &mut s.c[..]);
    let mut i = 0;
    while let Some(&t) = faces.get(i) {
        let [x, y, z] = triangles[t as usize];
        let inside = [x, y, z].map(|u| u.wrapping_sub(lo) < n);
        for ((u, v, w), inside) in [(x, y, z), (y, z, x), (z, x, y)].into_iter().zip(inside) {
            if inside {
                let e = &mut ends[(u - lo) as usize];
                region[*e] = t;
                b[*e] = v;
                c[*e] = w;
                *e += 1;
                i += 1;
            }
        }
    }
    ends.iter_mut().for_each(|e| *e += start);
}

/// Most faces of a vertex that [`closed_fan`] tries: its walk costs up to d², the general
/// analysis d log d. Surface meshes have degrees near 6.
const FAN_LIMIT: usize = 16;

/// The link edges `(b[i], c[i])` of the faces of `v` (each face runs v → b → c) when they form
/// one consistently oriented cycle through distinct neighbours: the interior vertex of a
/// manifold, which is nearly every vertex of a scan. Then the b's are exactly the neighbours,
/// each shared by two faces that traverse their edge in opposite directions, and the link is
/// connected; so [`analyse_vertex`] can skip its sort and union-find.
/// Returns the number of neighbours above `v` (its edges, each counted at its lower end) and
/// writes the neighbours into the first d entries of `out` (it may write up to 8); `None` for
/// anything else (or more than [`FAN_LIMIT`] faces), which the general path handles.
#[inline]
fn closed_fan(v: u32, b: &[u32], c: &[u32], out: &mut [u32]) -> Option<usize> {
    let d = b.len();
    if d < 3 {
        None
    } else if d <= 8 {
        let mut keys = padded(b);
        let lanes = Lanes::new(&keys);
        // No hit is lane 8, past the faces.
        let above = fan_walk(v, c, |u| {
            (lanes.equal(u) | 1 << 8).trailing_zeros() as usize
        })?;
        // Most vertices have 6 faces or fewer: their lanes past 6 are padding, in place.
        if d <= 6 {
            sort6(&mut keys);
        } else {
            sort8(&mut keys);
        }
        // All 8 lanes when there is room: a copy of fixed length, not a call to copy d.
        match out.get_mut(..8) {
            Some(lanes) => lanes.copy_from_slice(&keys),
            None => copy_rare(&keys[..d], out),
        }
        Some(above)
    } else if d <= FAN_LIMIT {
        let above = fan_walk(v, c, |u| {
            b.iter().position(|&x| x == u).unwrap_or(FAN_LIMIT)
        })?;
        sort_small(b, &mut out[..d]);
        Some(above)
    } else {
        None
    }
}

/// `x` into the first entries of `out`: out of line, so that the compiler does not merge it with
/// the fixed-length copy of its caller into one call of variable length.
#[cold]
#[inline(never)]
fn copy_rare(x: &[u32], out: &mut [u32]) {
    out[..x.len()].copy_from_slice(x);
}

/// [`closed_fan`]'s test, with `first(u)` the first face whose b is u (at least d if none).
///
/// Walk d steps from face 0: the face after face i is the first whose b is i's c. Seeing every
/// face and ending at face 0 visits each once, each as the first face with its b: so the b's are
/// distinct and the c's are the b's permuted, which also makes the c's met on the way the
/// neighbours. The face after each face is looked up first, for all faces, into 4 bits each of
/// `next`: the lookups do not wait for one another, and the walk is a shift per step.
#[inline(always)]
fn fan_walk(v: u32, c: &[u32], first: impl Fn(u32) -> usize) -> Option<usize> {
    let (mut next, mut found, mut above) = (0u64, true, 0);
    for (i, &u) in c.iter().enumerate() {
        above += (u > v) as usize;
        let after = first(u);
        found &= after < c.len();
        next |= (after as u64 & 15) << (4 * i);
    }
    let (mut at, mut seen) = (0, 0u32);
    for _ in 0..c.len() {
        at = (next >> (4 * at)) as usize & 15;
        seen |= 1 << at;
    }
    (found && at == 0 && seen == (1 << c.len()) - 1).then_some(above)
}

/// `x` (at most 8 ids) in the first lanes of 8, the rest `u32::MAX`: an id no vertex has (ids
/// are below it, so it matches no corner) and that sorts last.
#[inline(always)]
fn padded(x: &[u32]) -> [u32; 8] {
    std::array::from_fn(|k| x.get(k).copied().unwrap_or(u32::MAX))
}

/// 8 ids, to find which of them equal a given one all at once: a search stopping at the match
/// mispredicts its exit at nearly every face (most of [`fan_walk`]'s time, before).
#[cfg(target_arch = "x86_64")]
struct Lanes(std::arch::x86_64::__m128i, std::arch::x86_64::__m128i);

#[cfg(target_arch = "x86_64")]
impl Lanes {
    #[inline(always)]
    fn new(x: &[u32; 8]) -> Lanes {
        use std::arch::x86_64::*;
        let x = x.map(|x| x as i32);
        // SAFETY: SSE2 is part of the x86_64 baseline. Set from the ids rather than loaded from
        // `x`, which its stores have only just written (a wide load of narrow stores stalls).
        unsafe {
            Lanes(
                _mm_set_epi32(x[3], x[2], x[1], x[0]),
                _mm_set_epi32(x[7], x[6], x[5], x[4]),
            )
        }
    }

    /// The lanes equal to `u`, as the bits of a mask.
    #[inline(always)]
    fn equal(&self, u: u32) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let u = _mm_set1_epi32(u as i32);
            let words = _mm_packs_epi32(_mm_cmpeq_epi32(self.0, u), _mm_cmpeq_epi32(self.1, u));
            _mm_movemask_epi8(_mm_packs_epi16(words, words)) as u32 & 0xff
        }
    }
}

/// [`Lanes`] without x86_64's vector instructions.
#[cfg(not(target_arch = "x86_64"))]
struct Lanes([u32; 8]);

#[cfg(not(target_arch = "x86_64"))]
impl Lanes {
    fn new(x: &[u32; 8]) -> Lanes {
        Lanes(*x)
    }

    fn equal(&self, u: u32) -> u32 {
        self.0
            .iter()
            .rev()
            .fold(0, |m, &x| m << 1 | (x == u) as u32)
    }
}

/// Classify vertex `v` from the link edges `(b[i], c[i])` of its (non-degenerate) faces; when
/// it has as many neighbours as faces, write them into the first of `out`, ascending. `out` is
/// the rest of its chunk's array, where the entries past v's are written later if at all: it
/// may change up to 8 (see [`closed_fan`]). O(d log d) in the degree d.
fn analyse_vertex(
    v: u32,
    b: &[u32],
    c: &[u32],
    s: &mut VertexScratch,
    out: &mut [u32],
) -> VertexAnalysis {
    if let Some(edges) = closed_fan(v, b, c, out) {
        return VertexAnalysis {
            degree: b.len(),
            edges,
            boundary_edges: 0,
            non_manifold_edges: 0,
            inconsistent_edges: 0,
            non_manifold_vertex: false,
            fixed: false,
            loop_vertex: false,
        };
    }
    let a = analyse_general(v, b, c, s);
    if a.degree == b.len() {
        out[..a.degree].copy_from_slice(&s.corners);
    }
    a
}

/// [`analyse_vertex`] for any vertex, without the shortcut.
fn analyse_general(v: u32, b: &[u32], c: &[u32], s: &mut VertexScratch) -> VertexAnalysis {
    s.keys.clear();
    s.corners.clear();
    for (&b, &c) in b.iter().zip(c) {
        // The face runs v → b → c → v.
        s.keys.push((b as u64) << 1);
        s.keys.push((c as u64) << 1 | 1);
    }
    s.keys.sort_unstable();
    let mut a = VertexAnalysis {
        degree: 0,
        edges: 0,
        boundary_edges: 0,
        non_manifold_edges: 0,
        inconsistent_edges: 0,
        non_manifold_vertex: false,
        fixed: false,
        loop_vertex: false,
    };
    let mut ends = 0; // neighbours met once: ends of a path-shaped link
    let mut manifold = true;
    let mut i = 0;
    while i < s.keys.len() {
        let u = (s.keys[i] >> 1) as u32;
        let (mut count, mut outgoing) = (0, 0);
        while i < s.keys.len() && (s.keys[i] >> 1) as u32 == u {
            count += 1;
            outgoing += (s.keys[i] & 1 == 0) as usize;
            i += 1;
        }
        s.corners.push(u);
        match count {
            1 => ends += 1,
            2 => {}
            _ => manifold = false,
        }
        if u > v {
            a.edges += 1;
            match count {
                1 => a.boundary_edges += 1,
                2 => a.inconsistent_edges += (outgoing != 1) as usize,
                _ => a.non_manifold_edges += 1,
            }
        }
    }
    a.degree = s.corners.len();
    let nbrs = &s.corners[..];
    if nbrs.is_empty() {
        a.fixed = true; // unreferenced
    } else if ends > 0 || !manifold {
        // Boundary or non-manifold edge at v.
        a.fixed = true;
        a.non_manifold_vertex =
            manifold && (ends != 2 || !link_connected(nbrs, b, c, &mut s.parent));
        a.loop_vertex = manifold && !a.non_manifold_vertex && a.degree <= MAX_FREE_DEGREE;
    } else if !link_connected(nbrs, b, c, &mut s.parent) {
        a.fixed = true;
        a.non_manifold_vertex = true;
    }
    a.fixed |= a.degree > MAX_FREE_DEGREE;
    a
}

/// The sorted distinct neighbours of `v` into `out` (of the length pass 1 found): the list
/// [`analyse_vertex`] writes, without the link analysis pass 1 already made (that analysis, the
/// union-find over the link, was a third of the build's instructions when pass 2 repeated it).
fn write_neighbors(
    v: u32,
    faces: &[u32],
    triangles: &[[u32; 3]],
    s: &mut VertexScratch,
    out: &mut [u32],
) {
    if out.len() == faces.len() && faces.len() <= FAN_LIMIT {
        // The interior vertex of a manifold (see `closed_fan`): its faces' b corners are distinct
        // and as many as its neighbours, so they are the neighbours.
        let mut b = [0; FAN_LIMIT];
        for (x, &t) in b.iter_mut().zip(faces) {
            *x = corner_after(&triangles[t as usize], v);
        }
        sort_small(&b[..faces.len()], out);
        if out.windows(2).all(|w| w[0] < w[1]) {
            return;
        }
    }
    s.corners.clear();
    for &t in faces {
        let (b, c) = corners_after(triangles[t as usize], v);
        s.corners.push(b);
        s.corners.push(c);
    }
    s.corners.sort_unstable();
    s.corners.dedup();
    out.copy_from_slice(&s.corners);
}

fn is_degenerate(t: &[u32; 3]) -> bool {
    t[0] == t[1] || t[1] == t[2] || t[0] == t[2]
}

/// The corner after `v` in triangle `t` (which has `v` once), without a branch to mispredict.
#[inline]
fn corner_after(t: &[u32; 3], v: u32) -> u32 {
    let k = (t[1] == v) as usize + 2 * (t[2] == v) as usize;
    t[[1, 2, 0][k]]
}

/// `x` into `out` (of the same length), ascending. Up to 8 entries (a vertex's neighbours, as a
/// rule) through a sorting network: its comparisons, branch-free, cost less than the
/// mispredicted branches of an insertion sort on ids that come in no useful order.
#[inline]
fn sort_small(x: &[u32], out: &mut [u32]) {
    if x.len() > 8 {
        out.copy_from_slice(x);
        insertion_sort(out);
        return;
    }
    let mut a = padded(x);
    sort8(&mut a);
    out.copy_from_slice(&a[..x.len()]);
}

/// Sort 8 entries through a sorting network: the fewest comparators (19), branch-free.
#[inline]
fn sort8(a: &mut [u32; 8]) {
    let mut exchange = |i: usize, j: usize| (a[i], a[j]) = (a[i].min(a[j]), a[i].max(a[j]));
    exchange(0, 2);
    exchange(1, 3);
    exchange(4, 6);
    exchange(5, 7);
    exchange(0, 4);
    exchange(1, 5);
    exchange(2, 6);
    exchange(3, 7);
    exchange(0, 1);
    exchange(2, 3);
    exchange(4, 5);
    exchange(6, 7);
    exchange(2, 4);
    exchange(3, 5);
    exchange(1, 4);
    exchange(3, 6);
    exchange(1, 2);
    exchange(3, 4);
    exchange(5, 6);
}

/// Sort the first 6 of 8 entries through a sorting network: the fewest comparators (12).
#[inline]
fn sort6(a: &mut [u32; 8]) {
    let mut exchange = |i: usize, j: usize| (a[i], a[j]) = (a[i].min(a[j]), a[i].max(a[j]));
    exchange(0, 5);
    exchange(1, 3);
    exchange(2, 4);
    exchange(1, 2);
    exchange(3, 4);
    exchange(0, 3);
    exchange(2, 5);
    exchange(0, 1);
    exchange(2, 3);
    exchange(4, 5);
    exchange(1, 2);
    exchange(3, 4);
}

/// Sort a short slice ascending.
#[inline]
fn insertion_sort(x: &mut [u32]) {
    for i in 1..x.len() {
        let y = x[i];
        let mut j = i;
        while j > 0 && x[j - 1] > y {
            x[j] = x[j - 1];
            j -= 1;
        }
        x[j] = y;
    }
}

/// The two other corners of triangle `t` after `v`, in the triangle's cyclic order (`v` must be
/// a corner): the edge opposite `v`, oriented as the face runs.
#[inline]
pub fn corners_after(t: [u32; 3], v: u32) -> (u32, u32) {
    if t[0] == v {
        (t[1], t[2])
    } else if t[1] == v {
        (t[2], t[0])
    } else {
        (t[0], t[1])
    }
}

/// Whether the link edges of a vertex connect all its neighbours (one component).
fn link_connected(nbrs: &[u32], b: &[u32], c: &[u32], parent: &mut Vec<usize>) -> bool {
    parent.clear();
    parent.extend(0..nbrs.len());
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let mut components = nbrs.len();
    for (&b, &c) in b.iter().zip(c) {
        // Neighbours are sorted, so local ids come from a binary search.
        let (Ok(lb), Ok(lc)) = (nbrs.binary_search(&b), nbrs.binary_search(&c)) else {
            return false;
        };
        let (rb, rc) = (find(parent, lb), find(parent, lc));
        if rb != rc {
            parent[rb] = rc;
            components -= 1;
        }
    }
    components == 1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Octahedron: closed, 6 vertices of degree 4.
    fn octahedron() -> Vec<[u32; 3]> {
        crate::shapes::octahedron().triangles.to_vec()
    }

    #[test]
    fn the_sorting_networks_sort_every_input() {
        // A comparator network sorts every input if it sorts every input of zeros and ones.
        for bits in 0u32..256 {
            let mut a: [u32; 8] = std::array::from_fn(|k| bits >> k & 1);
            sort8(&mut a);
            assert!(a.is_sorted(), "sort8 {bits:08b}");
            let mut a: [u32; 8] = std::array::from_fn(|k| if k < 6 { bits >> k & 1 } else { 9 });
            sort6(&mut a);
            assert!(a.is_sorted(), "sort6 {bits:06b}");
        }
    }

    #[test]
    fn closed_octahedron_has_no_fixed_vertex() {
        let t = Topology::build(6, &octahedron()).unwrap();
        assert_eq!(t.stats.edges, 12);
        assert_eq!(t.stats.boundary_edges, 0);
        assert_eq!(t.stats.fixed_vertices, 0);
        assert!((0..6).all(|v| t.deg(v) == 4 && t.faces_of(v).len() == 4));
        assert_eq!(t.edges().count(), 12);
        assert!(t.edges().all(|[i, j]| i < j));
    }

    #[test]
    fn open_fan_fixes_its_rim_only() {
        // Centre 0 with rim 1..=5 closed around it: the rim is boundary, the centre is interior.
        let tris: Vec<[u32; 3]> = (1..=5).map(|k| [0, k, k % 5 + 1]).collect();
        let t = Topology::build(6, &tris).unwrap();
        assert!(!t.is_fixed(0));
        assert!((1..=5).all(|v| t.is_fixed(v)));
        assert_eq!(t.stats.boundary_edges, 5);
    }

    #[test]
    fn rim_vertices_are_loop_vertices_until_pinned() {
        let tris: Vec<[u32; 3]> = (1..=5).map(|k| [0, k, k % 5 + 1]).collect();
        let mut t = Topology::build(6, &tris).unwrap();
        assert!(!t.is_loop(0) && (1..=5).all(|v| t.is_loop(v)));
        assert_eq!(t.loop_neighbors(&tris, 1), Some([2, 5]));
        assert_eq!(t.loop_neighbors(&tris, 0), None);
        t.pin(|v| v == 3);
        assert!(t.is_fixed(3) && !t.is_loop(3) && t.is_loop(2));
        // A vertex on four boundary edges (two fans touching at 0) is no loop vertex.
        let mut tris = tris;
        tris.extend([[0, 6, 7], [0, 7, 8]]);
        let t = Topology::build(9, &tris).unwrap();
        assert!(t.is_fixed(0) && !t.is_loop(0) && t.is_loop(7));
    }

    #[test]
    fn non_manifold_edge_and_vertex_are_fixed() {
        // Three triangles on edge (0,1).
        let t = Topology::build(5, &[[0, 1, 2], [1, 0, 3], [0, 1, 4]]).unwrap();
        assert_eq!(t.stats.non_manifold_edges, 1);
        assert!(t.is_fixed(0) && t.is_fixed(1));

        // Two closed octahedra sharing vertex 0 (a bow-tie of two closed fans): 0 is non-manifold.
        let mut tris = octahedron();
        let shift = |v: u32| if v == 0 { 0 } else { v + 5 };
        tris.extend(octahedron().iter().map(|t| t.map(shift)));
        let t = Topology::build(11, &tris).unwrap();
        assert_eq!(t.stats.non_manifold_vertices, 1);
        assert!(t.is_fixed(0));
        assert_eq!(t.stats.fixed_vertices, 1);
    }

    #[test]
    fn degenerate_and_unreferenced_vertices_are_fixed_and_counted() {
        let mut tris = octahedron();
        tris.push([0, 0, 1]);
        let t = Topology::build(7, &tris).unwrap();
        assert_eq!(t.stats.degenerate_triangles, 1);
        assert_eq!(t.stats.unreferenced_vertices, 1);
        assert!(t.is_fixed(0) && t.is_fixed(1) && t.is_fixed(6) && !t.is_fixed(2));
    }

    #[test]
    fn out_of_range_index_is_an_error() {
        assert!(Topology::build(3, &[[0, 1, 3]]).is_err());
    }

    /// Positions of an icosphere for `orient`'s volume tie-break.
    fn sphere() -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let m = crate::shapes::icosphere(2);
        (m.positions.to_vec(), m.triangles.to_vec())
    }

    fn oriented_volume(pos: &[DVec3], tris: &[[u32; 3]]) -> f64 {
        crate::metrics::volume(pos, tris)
    }

    #[test]
    fn one_flipped_face_is_three_inconsistent_edges_and_orient_undoes_it() {
        let (pos, mut tris) = sphere();
        let clean = tris.clone();
        tris[17].swap(0, 1);
        let mut t = Topology::build(pos.len(), &tris).unwrap();
        assert_eq!(t.stats.inconsistent_orientation_edges, 3);
        // Orientation changes neither the adjacency nor what is fixed.
        assert_eq!(t.stats.fixed_vertices, 0);
        t.orient(&mut tris, &pos);
        assert_eq!(t.stats.non_orientable_components, 0);
        assert_eq!(t.stats.fixed_vertices, 0);
        // The majority's orientation: face 17 turned back (its first corner kept first).
        assert!((0..3).any(|k| tris[17] == [clean[17][k], clean[17][(k + 1) % 3], clean[17][(k + 2) % 3]]));
        assert_eq!(&tris[..17], &clean[..17]);
        assert_eq!(&tris[18..], &clean[18..]);
    }

    #[test]
    fn alternating_flips_orient_to_positive_volume() {
        let (pos, clean) = sphere();
        let v = oriented_volume(&pos, &clean);
        // Half the faces flipped (a tie): the orientation with the positive volume wins, whichever
        // face the walk starts from; and so for the mirror image (the other half flipped).
        for parity in [0, 1] {
            let mut tris = clean.clone();
            for (k, t) in tris.iter_mut().enumerate() {
                if k % 2 == parity {
                    t.swap(1, 2);
                }
            }
            let mut t = Topology::build(pos.len(), &tris).unwrap();
            assert!(t.stats.inconsistent_orientation_edges > 100);
            t.orient(&mut tris, &pos);
            let again = Topology::build(pos.len(), &tris).unwrap();
            assert_eq!(again.stats.inconsistent_orientation_edges, 0);
            assert!((oriented_volume(&pos, &tris) - v).abs() < 1e-12 * v);
            // A second call changes nothing.
            let before = tris.clone();
            t.orient(&mut tris, &pos);
            assert_eq!(tris, before);
        }
    }

    #[test]
    fn consistent_meshes_are_left_alone_even_inside_out() {
        let (pos, mut tris) = sphere();
        tris.iter_mut().for_each(|t| t.swap(1, 2));
        let before = tris.clone();
        let mut t = Topology::build(pos.len(), &tris).unwrap();
        assert_eq!(t.stats.inconsistent_orientation_edges, 0);
        t.orient(&mut tris, &pos);
        assert_eq!(tris, before);
    }

    /// A Möbius strip of `n` quads: top vertices `0..n`, bottom `n..2n`, the last quad twisted.
    fn mobius(n: u32) -> Vec<[u32; 3]> {
        let mut tris = Vec::new();
        for k in 0..n {
            let (t0, b0) = (k, n + k);
            let (t1, b1) = if k + 1 < n {
                (k + 1, n + k + 1)
            } else {
                (n, 0)
            };
            tris.push([t0, b0, b1]);
            tris.push([t0, b1, t1]);
        }
        tris
    }

    #[test]
    fn a_mobius_strip_is_non_orientable_and_its_seam_is_fixed() {
        let n = 8;
        let mut tris = mobius(n);
        let pos: Vec<DVec3> = (0..2 * n)
            .map(|v| DVec3::new(v as f64, (v * v) as f64, 1.0))
            .collect();
        let mut t = Topology::build(2 * n as usize, &tris).unwrap();
        // The strip is consistent everywhere but across the twist.
        assert_eq!(t.stats.inconsistent_orientation_edges, 1);
        // Every vertex of the strip is on its boundary, so fixed already.
        assert_eq!(t.stats.fixed_vertices, 2 * n as usize);
        t.orient(&mut tris, &pos);
        assert_eq!(t.stats.non_orientable_components, 1);
        assert_eq!(t.stats.orientation_seam_edges, 1);
        let again = Topology::build(2 * n as usize, &tris).unwrap();
        assert_eq!(again.stats.inconsistent_orientation_edges, 1);

        // A Klein bottle (closed, nothing fixed to begin with): the seam's vertices are fixed.
        let (pos, mut tris) = klein_bottle(6, 4);
        let mut t = Topology::build(pos.len(), &tris).unwrap();
        assert_eq!(t.stats.boundary_edges, 0);
        assert_eq!(t.stats.fixed_vertices, 0);
        assert!(t.stats.inconsistent_orientation_edges > 0);
        t.orient(&mut tris, &pos);
        assert_eq!(t.stats.non_orientable_components, 1);
        let seams = t.stats.orientation_seam_edges;
        assert!(seams > 0);
        let again = Topology::build(pos.len(), &tris).unwrap();
        assert_eq!(again.stats.inconsistent_orientation_edges, seams);
        assert!(t.stats.fixed_vertices > 0 && t.stats.fixed_vertices <= 2 * seams);
        let fixed = t.fixed_mask().iter().filter(|&&f| f != 0).count();
        assert_eq!(fixed, t.stats.fixed_vertices);
    }

    /// A Klein bottle as a `u × v` grid with the rows glued straight and the columns glued with a
    /// flip; positions arbitrary but distinct.
    fn klein_bottle(u: u32, v: u32) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let id = |i: u32, j: u32| {
            let (i, j) = if i == u { (0, (v - j) % v) } else { (i, j % v) };
            i * v + j
        };
        let mut tris = Vec::new();
        for i in 0..u {
            for j in 0..v {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
        }
        let pos = (0..u * v)
            .map(|k| DVec3::new(k as f64, (k % 5) as f64, (k % 3) as f64))
            .collect();
        (pos, tris)
    }

    #[test]
    fn hubs_above_the_degree_limit_are_fixed_and_counted() {
        // A closed bipyramid: two apexes over a rim of `d` vertices.
        for (d, hub_fixed) in [(MAX_FREE_DEGREE, false), (MAX_FREE_DEGREE + 1, true)] {
            let d = d as u32;
            let mut tris = Vec::new();
            for k in 0..d {
                tris.push([d, k, (k + 1) % d]);
                tris.push([d + 1, (k + 1) % d, k]);
            }
            let t = Topology::build(d as usize + 2, &tris).unwrap();
            assert_eq!(t.stats.boundary_edges, 0);
            assert_eq!(t.is_fixed(d), hub_fixed);
            assert_eq!(t.stats.high_degree_vertices, 2 * hub_fixed as usize);
            assert_eq!(t.stats.fixed_vertices, 2 * hub_fixed as usize);
            assert!(!t.is_fixed(0));
        }
    }

    #[test]
    fn the_closed_fan_shortcut_agrees_with_the_general_analysis() {
        // Fans around vertex 0 over rims 1..=d: closed, open, with a face flipped, with a rim
        // vertex repeated (two cycles through 0, a pinch), and a double cover of the rim.
        let ring = |d: u32| -> Vec<[u32; 3]> { (1..=d).map(|k| [0, k, k % d + 1]).collect() };
        let mut cases: Vec<Vec<[u32; 3]>> = Vec::new();
        let limit = FAN_LIMIT as u32;
        for d in [3, 4, 6, limit, limit + 1] {
            cases.push(ring(d));
            let mut open = ring(d);
            open.pop();
            cases.push(open);
            let mut flipped = ring(d);
            flipped[1].swap(1, 2);
            cases.push(flipped);
            let mut twice = ring(d);
            twice.extend(ring(d));
            cases.push(twice);
        }
        // Two triangles fans sharing vertex 0 (a pinch): 0-1-2-3 and 0-4-5-6.
        cases.push(vec![
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 1],
            [0, 4, 5],
            [0, 5, 6],
            [0, 6, 4],
        ]);
        // Two cycles through the same rim vertex 1: 1-2-3 and 1-4-5.
        cases.push(vec![
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 1],
            [0, 1, 4],
            [0, 4, 5],
            [0, 5, 1],
        ]);
        let mut s = VertexScratch::default();
        let mut shortcuts = 0;
        for tris in &cases {
            let n = tris.iter().flatten().max().unwrap() + 1;
            let topo = Topology::build(n as usize, tris).unwrap();
            for v in 0..n {
                let faces = topo.faces_of(v);
                let (b, c): (Vec<u32>, Vec<u32>) = faces
                    .iter()
                    .map(|&t| corners_after(tris[t as usize], v))
                    .unzip();
                // With room past the vertex's entries, as in the build.
                let mut out = vec![0; faces.len() + 8];
                let a = analyse_vertex(v, &b, &c, &mut s, &mut out);
                if closed_fan(v, &b, &c, &mut out.clone()).is_some() {
                    shortcuts += 1;
                    assert_eq!(a, analyse_general(v, &b, &c, &mut s), "{tris:?} at {v}");
                }
                if a.degree == faces.len() {
                    assert_eq!(out[..a.degree], *topo.neighbors(v), "{tris:?} at {v}");
                }
                let mut want: Vec<u32> = faces
                    .iter()
                    .flat_map(|&t| tris[t as usize])
                    .filter(|&u| u != v)
                    .collect();
                want.sort_unstable();
                want.dedup();
                assert_eq!(topo.neighbors(v), &want[..], "{tris:?} at {v}");
            }
        }
        // The closed rings' centres (d <= FAN_LIMIT) take the shortcut; nothing else here.
        assert_eq!(shortcuts, 4);
    }

    #[test]
    fn the_parallel_build_gives_the_plain_adjacency_for_any_thread_count() {
        // Over several chunks and blocks, in a shuffled vertex order (faces of a vertex scattered
        // over the blocks), with degenerate triangles and unreferenced vertices; closed (the
        // neighbours placed in pass 1) and with holes (placed by pass 2).
        let mesh = crate::shapes::icosphere(6);
        let n = mesh.positions.len() + 5;
        let perm = crate::shapes::permutation(n, 0x2545_f491_4f6c_dd1du64);
        let mut closed: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| perm[v as usize]))
            .collect();
        for k in [0, 17, 5000, 40_000] {
            closed.insert(k, [perm[k], perm[k], perm[k + 1]]);
        }
        let mut open = closed.clone();
        for k in [70_000, 30_000, 30_001, 9] {
            open.remove(k);
        }
        for tris in [closed, open] {
            assert!(n > 4 * CHUNK && tris.len() > 4 * BLOCKS);
            let mut faces_of: Vec<Vec<u32>> = vec![Vec::new(); n];
            let mut nbrs: Vec<Vec<u32>> = vec![Vec::new(); n];
            for (t, tri) in tris.iter().enumerate() {
                if is_degenerate(tri) {
                    continue;
                }
                for &v in tri {
                    faces_of[v as usize].push(t as u32);
                    nbrs[v as usize].extend(tri.iter().filter(|&&u| u != v));
                }
            }
            nbrs.iter_mut().for_each(|l| {
                l.sort_unstable();
                l.dedup();
            });
            let mut first = None;
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let topo = pool.install(|| Topology::build(n, &tris)).unwrap();
                for v in 0..n as u32 {
                    assert_eq!(topo.faces_of(v), &faces_of[v as usize][..], "faces of {v}");
                    assert_eq!(
                        topo.neighbors(v),
                        &nbrs[v as usize][..],
                        "neighbours of {v}"
                    );
                }
                assert_eq!(topo.stats.degenerate_triangles, 4);
                assert_eq!(topo.stats.unreferenced_vertices, 5);
                let fixed = topo.fixed_mask().to_vec();
                match &first {
                    None => first = Some((topo.stats, fixed)),
                    Some((stats, mask)) => assert!(*stats == topo.stats && *mask == fixed),
                }
            }
            let (stats, _) = first.unwrap();
            assert_eq!(
                stats.boundary_edges > 0,
                tris.len() < mesh.triangles.len() + 4
            );
        }
    }

    /// The arrays and stats of a topology, to compare whole.
    type Whole = (
        Vec<usize>,
        Vec<u32>,
        Vec<usize>,
        Vec<u32>,
        Vec<u8>,
        TopologyStats,
    );

    fn whole(t: &Topology) -> Whole {
        let p = t.parts();
        (
            p.vv_offsets.to_vec(),
            p.vv.to_vec(),
            p.vf_offsets.to_vec(),
            p.vf.to_vec(),
            p.fixed.to_vec(),
            t.stats,
        )
    }

    /// The topology vertex by vertex, without the build's chunks, counting sorts, closed-fan
    /// shortcut, 8-wide writes, offsets summed in chunks or pass 2: each vertex's faces from one
    /// scan of the triangles, and its neighbours and flags from the general analysis.
    fn reference(n: usize, tris: &[[u32; 3]]) -> Whole {
        let mut stats = TopologyStats {
            vertices: n,
            triangles: tris.len(),
            ..Default::default()
        };
        let mut faces_of = vec![Vec::new(); n];
        let mut fixed = vec![0u8; n];
        for (t, tri) in tris.iter().enumerate() {
            if is_degenerate(tri) {
                stats.degenerate_triangles += 1;
                tri.iter().for_each(|&v| fixed[v as usize] = FIXED);
                continue;
            }
            tri.iter()
                .for_each(|&v| faces_of[v as usize].push(t as u32));
        }
        let (mut vv_offsets, mut vv, mut vf_offsets, mut vf) = (vec![0], vec![], vec![0], vec![]);
        let mut s = VertexScratch::default();
        for v in 0..n {
            let (b, c): (Vec<u32>, Vec<u32>) = faces_of[v]
                .iter()
                .map(|&t| corners_after(tris[t as usize], v as u32))
                .unzip();
            let a = analyse_general(v as u32, &b, &c, &mut s);
            vf.extend(&faces_of[v]);
            vf_offsets.push(vf.len());
            vv.extend(&s.corners);
            vv_offsets.push(vv.len());
            stats.count(&a, &mut fixed[v]);
        }
        (vv_offsets, vv, vf_offsets, vf, fixed, stats)
    }

    #[test]
    fn the_build_equals_a_vertex_by_vertex_reference_on_varied_meshes() {
        let mut cases: Vec<(&str, usize, Vec<[u32; 3]>)> = Vec::new();
        let sphere = crate::shapes::icosphere(6);
        let n = sphere.positions.len();
        let perm = crate::shapes::permutation(n, 7);
        let shuffled: Vec<[u32; 3]> = sphere
            .triangles
            .iter()
            .map(|t| t.map(|v| perm[v as usize]))
            .collect();
        cases.push(("sphere", n, sphere.triangles.to_vec()));
        cases.push(("shuffled sphere", n, shuffled.clone()));
        // Holes (so pass 2 and shifted offsets), flipped faces, degenerate faces, a duplicated
        // face and a fin (non-manifold edges), unreferenced vertices.
        let mut rough = shuffled.clone();
        for k in (0..rough.len()).step_by(997) {
            rough[k].swap(1, 2);
        }
        for k in [80_000, 50_000, 50_001, 12_345, 3] {
            rough.remove(k);
        }
        rough.insert(17, [perm[5], perm[5], perm[9]]);
        rough.insert(40_000, [perm[1], perm[2], perm[1]]);
        rough.push(rough[1000]);
        let [a, b, _] = rough[2000];
        rough.push([a, b, n as u32]);
        cases.push(("rough sphere", n + 3, rough));
        // Two spheres sharing one vertex (a pinch, two closed fans at it), one of them
        // inside out.
        let mut pinched = shuffled.clone();
        let other = |v: u32| if v == perm[0] { perm[0] } else { v + n as u32 };
        pinched.extend(
            shuffled
                .iter()
                .map(|t| [other(t[0]), other(t[2]), other(t[1])]),
        );
        cases.push(("pinched spheres", 2 * n, pinched));
        // Closed bipyramids whose apexes have 3 to 20 faces: every path of the closed-fan test
        // (up to 6, 8 and 16 faces) and the general analysis beyond, each also with a face
        // flipped and with a face gone.
        let mut cones = Vec::new();
        let mut base = 0;
        for d in 3..=20u32 {
            for variant in 0..3 {
                let (apex, other_apex) = (base + d, base + d + 1);
                let mut fan = Vec::new();
                for k in 0..d {
                    fan.push([apex, base + k, base + (k + 1) % d]);
                    fan.push([other_apex, base + (k + 1) % d, base + k]);
                }
                match variant {
                    1 => fan[2].swap(1, 2),
                    2 => drop(fan.remove(2)),
                    _ => {}
                }
                cones.extend(fan);
                base += d + 2;
            }
        }
        cases.push(("bipyramids", base as usize, cones));
        let bunny =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/stanford-bunny.ply");
        let scan = crate::io::read_mesh(&bunny).unwrap();
        let n = scan.positions.len();
        let perm = crate::shapes::permutation(n, 11);
        let tris: Vec<[u32; 3]> = scan.triangles.to_vec();
        cases.push(("scan", n, tris.clone()));
        let shuffled = tris.iter().map(|t| t.map(|v| perm[v as usize])).collect();
        cases.push(("shuffled scan", n, shuffled));

        for (name, n, tris) in &cases {
            let want = reference(*n, tris);
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let topo = pool.install(|| Topology::build(*n, tris)).unwrap();
                assert!(whole(&topo) == want, "{name} on {threads} threads");
            }
        }
    }
}
