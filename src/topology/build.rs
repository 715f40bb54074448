//! The CSR build: a mesh's triangles into the vertex → face and vertex → vertex arrays, the fixed
//! mask and the counts, in parallel over blocks of triangles and chunks of vertices. Each chunk's
//! result is placed by vertex id, so the topology does not depend on the number of threads; the
//! tests hold it to a plain vertex-by-vertex reference.

use rayon::prelude::*;

use super::fans::{VertexScratch, analyse_vertex, write_neighbors};
use super::{CHUNK, FaceIndex, Topology, TopologyStats};
use crate::error::{Error, Result};
use crate::mesh::{Buf, Storage};
use crate::meter::{Meter, Passes};

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
        let built = Topology::build_faces(storage, n_vertices, triangles, meter, false)?;
        Ok(built.expect("a build that lists its faces is never given up"))
    }

    /// [`Topology::build_metered`] for triangles in the plan's layout (sorted by their first
    /// corner, which is their smallest), giving a topology that finds its faces in their runs
    /// ([`Topology::faces_by_runs`]) without ever holding the vertex → face list: each chunk of
    /// vertices gathers its faces on the heap from its own runs and the faces that cross into it
    /// from below. The same topology as a build and `faces_by_runs`. Triangles in another layout,
    /// or a vertex of more than [`super::MAX_RUN`] faces, get the listed build.
    pub fn build_runs_metered(
        storage: &Storage,
        n_vertices: usize,
        triangles: &[[u32; 3]],
        meter: &Meter,
    ) -> Result<Topology> {
        if sorted_by_first(triangles)
            && let Some(built) = Topology::build_faces(storage, n_vertices, triangles, meter, true)?
        {
            return Ok(built);
        }
        Topology::build_metered(storage, n_vertices, triangles, &Meter::default())
    }

    /// The build: the faces listed, or (`gather`) gathered per chunk from the runs of sorted
    /// triangles; `None` when gathering finds a vertex of more than [`super::MAX_RUN`] faces.
    fn build_faces(
        storage: &Storage,
        n_vertices: usize,
        triangles: &[[u32; 3]],
        meter: &Meter,
        gather: bool,
    ) -> Result<Option<Topology>> {
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
                let count = count_block(b * block_len, block, n_vertices, chunks, gather);
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
        // Gathering, only the corners that cross into a chunk from a face whose smallest corner
        // is in a lower one are placed (each chunk's own runs hold the rest).
        let placed = |count: &BlockCount, c: usize| match gather {
            true => count.crossing[c] as usize,
            false => count.per_chunk[c] as usize,
        };
        let mut cross_start = Vec::with_capacity(chunks + 1);
        let mut placed_total = 0usize;
        for c in 0..chunks {
            cross_start.push(placed_total);
            placed_total += counted.iter().map(|b| placed(b, c)).sum::<usize>();
        }
        cross_start.push(placed_total);
        let mut vf: Buf<u32> = storage.zeroed(placed_total)?;
        // Each block's piece of each chunk's region, in chunk order.
        let mut pieces: Vec<Vec<&mut [u32]>> = (0..counted.len())
            .map(|_| Vec::with_capacity(chunks))
            .collect();
        let mut rest: &mut [u32] = &mut vf;
        for c in 0..chunks {
            for (b, count) in counted.iter().enumerate() {
                let (piece, tail) = std::mem::take(&mut rest).split_at_mut(placed(count, c));
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
                        if gather {
                            continue;
                        }
                        // Nearly every face: its three places taken at once, rather than each
                        // waiting for the piece to be shortened by the one before.
                        let (head, tail) = std::mem::take(&mut pieces[c]).split_at_mut(3);
                        head.fill(t);
                        pieces[c] = tail;
                        continue;
                    }
                    for &v in tri {
                        if gather && v as usize / CHUNK == c {
                            continue;
                        }
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
        // has as many neighbours as faces (a closed manifold: no pass 2 then). A vertex's
        // neighbours less its faces go to `misfit`, a byte each (the neighbours' offsets would
        // be 8, and are needed only where some vertex differs).
        let mut vf_offsets: Buf<usize> = storage.zeroed(n_vertices + 1)?;
        let mut misfit: Buf<u8> = storage.zeroed(n_vertices)?;
        let mut vv: Buf<u32> = storage.zeroed(total)?;
        let region_lens: Vec<usize> = region_start.windows(2).map(|w| w[1] - w[0]).collect();
        let gathered = gather.then(|| Gathered {
            cross_start: cross_start.clone(),
            own: (0..=chunks)
                .map(|c| triangles.partition_point(|t| (t[0] as usize) < c * CHUNK))
                .collect(),
        });
        let (regions, cross): (Vec<Option<&mut [u32]>>, &[u32]) = match gather {
            true => ((0..chunks).map(|_| None).collect(), &vf[..]),
            false => (
                split_lens(&mut vf, &region_lens)
                    .into_iter()
                    .map(Some)
                    .collect(),
                &[],
            ),
        };
        let chunk_faces = gathered.as_ref();
        let found: Vec<Found> = regions
            .into_par_iter()
            .zip(split_lens(&mut vv, &region_lens))
            .zip(vf_offsets[1..].par_chunks_mut(CHUNK))
            .zip(misfit.par_chunks_mut(CHUNK))
            .zip(fixed.par_chunks_mut(CHUNK))
            .enumerate()
            .map_init(
                <(ChunkScratch, VertexScratch, Vec<u32>)>::default,
                |(link, scratch, own), (c, ((((region, nbrs), ends), misfit), fixed))| {
                    let lo = (c * CHUNK) as u32;
                    let region = match (region, chunk_faces) {
                        (Some(region), _) => region,
                        (None, Some(g)) => g.region(c, cross, triangles, own),
                        (None, None) => unreachable!("a region listed or gathered"),
                    };
                    debug_assert_eq!(region.len(), region_lens[c]);
                    sort_region(lo, region, region_start[c], ends, triangles, link);
                    let mut found = Found::default();
                    let mut start = 0;
                    for (k, (m, fix)) in misfit.iter_mut().zip(fixed.iter_mut()).enumerate() {
                        let end = ends[k] - region_start[c];
                        let (b, c) = (&link.b[start..end], &link.c[start..end]);
                        let a = analyse_vertex(lo + k as u32, b, c, scratch, &mut nbrs[start..]);
                        start = end;
                        found.neighbours += a.degree;
                        if a.degree != b.len() {
                            found.misfits += 1;
                            *m = match i8::try_from(a.degree as isize - b.len() as isize) {
                                Ok(d) if d != ESCAPE => d as u8,
                                _ => {
                                    found.escaped.push((k, a.degree));
                                    ESCAPE as u8
                                }
                            };
                        }
                        found.stats.count(&a, fix);
                        found.most_faces = found.most_faces.max(b.len());
                    }
                    meter.add(misfit.len() as u64);
                    found
                },
            )
            .collect();
        let mut misfits = 0;
        for f in &found {
            stats = stats.add(f.stats);
            misfits += f.misfits;
        }
        if gather && found.iter().any(|f| f.most_faces > super::MAX_RUN) {
            return Ok(None);
        }
        let mut vv_offsets = Buf::default();
        if misfits == 0 {
            // The skipped pass 2, for the meter. The neighbours' offsets are then the faces'
            // (`Topology::vv_offsets`).
            meter.add(n_vertices as u64);
        } else {
            // Pass 1's neighbours go before the offsets and pass 2's are made, so that they are
            // never held together.
            drop(std::mem::take(&mut vv));
            vv_offsets = neighbour_offsets(storage, &vf_offsets, &misfit, &found)?;
            drop(std::mem::take(&mut misfit));
            let source = match &gathered {
                // The faces' offsets go before the neighbours are placed (each chunk finds its
                // vertices' faces again).
                Some(g) => {
                    drop(std::mem::take(&mut vf_offsets));
                    Source::Gathered { g, cross: &vf }
                }
                None => Source::Listed {
                    offsets: &vf_offsets,
                    faces: &vf,
                },
            };
            vv = pass_2(storage, &vv_offsets, source, triangles, meter)?;
        }
        let faces = match gathered {
            Some(_) => {
                drop(vf);
                if vv_offsets.is_empty() {
                    vv_offsets = vf_offsets;
                } else {
                    drop(vf_offsets);
                }
                FaceIndex::Runs {
                    starts: run_starts(storage, n_vertices, triangles)?,
                }
            }
            None => FaceIndex::Lists {
                offsets: vf_offsets,
                faces: vf,
            },
        };
        Ok(Some(Topology {
            vv_offsets,
            vv,
            faces,
            fixed,
            lines: Buf::default(),
            stats,
        }))
    }
}

/// The `misfit` byte of a vertex whose neighbours less faces is not an `i8`, or is this one: its
/// degree is in [`Found::escaped`].
const ESCAPE: i8 = i8::MIN;

/// What pass 1 found in one chunk of vertices.
#[derive(Default)]
struct Found {
    stats: TopologyStats,
    /// Vertices with more or fewer neighbours than faces.
    misfits: usize,
    /// Neighbours of all the chunk's vertices.
    neighbours: usize,
    /// `(k, degree)` of the chunk's vertices whose neighbours less faces is not an `i8` other
    /// than [`ESCAPE`], ascending (hubs and badly broken fans: rare).
    escaped: Vec<(usize, usize)>,
    /// The most faces of one of the chunk's vertices.
    most_faces: usize,
}

/// The vertex → vertex offsets, from the faces' and pass 1's `misfit` bytes (a vertex's
/// neighbours less its faces, or [`ESCAPE`]), each chunk after the neighbours of those before.
fn neighbour_offsets(
    storage: &Storage,
    vf_offsets: &[usize],
    misfit: &[u8],
    found: &[Found],
) -> Result<Buf<usize>> {
    let mut offsets: Buf<usize> = storage.zeroed(vf_offsets.len())?;
    let mut placed = 0;
    let bases: Vec<usize> = found
        .iter()
        .map(|f| {
            let base = placed;
            placed += f.neighbours;
            base
        })
        .collect();
    offsets[1..]
        .par_chunks_mut(CHUNK)
        .zip(misfit.par_chunks(CHUNK))
        .zip(found.par_iter().zip(bases))
        .enumerate()
        .for_each(|(c, ((out, misfit), (found, base)))| {
            let mut at = base;
            let mut escaped = found.escaped.iter();
            for (k, (o, &m)) in out.iter_mut().zip(misfit).enumerate() {
                let v = c * CHUNK + k;
                at += match m as i8 {
                    ESCAPE => {
                        let &(at_k, degree) = escaped.next().expect("an escaped vertex");
                        debug_assert_eq!(at_k, k, "escaped vertices in order");
                        degree
                    }
                    d => (vf_offsets[v + 1] - vf_offsets[v]).wrapping_add_signed(d as isize),
                };
                *o = at;
            }
        });
    Ok(offsets)
}

/// Where pass 2 finds each vertex's faces.
enum Source<'a> {
    Listed {
        offsets: &'a [usize],
        faces: &'a [u32],
    },
    Gathered {
        g: &'a Gathered,
        cross: &'a [u32],
    },
}

/// Pass 2 of the build, for a mesh whose vertices do not all have as many neighbours as faces:
/// the neighbour lists laid out by `vv_offsets`, each chunk of vertices into its own slice.
fn pass_2(
    storage: &Storage,
    vv_offsets: &[usize],
    source: Source,
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
        .for_each_init(
            <(VertexScratch, Vec<u32>, Vec<usize>, ChunkScratch)>::default,
            |(scratch, buffer, ends, link), (c, out)| {
                let range = c * CHUNK..((c + 1) * CHUNK).min(n_vertices);
                let range_len = range.len() as u64;
                let all: &[u32] = match &source {
                    Source::Listed { faces, .. } => faces,
                    Source::Gathered { g, cross } => {
                        let region = g.region(c, cross, triangles, buffer);
                        ends.clear();
                        ends.resize(range.len(), 0);
                        sort_region(c as u32 * CHUNK as u32, region, 0, ends, triangles, link);
                        buffer
                    }
                };
                let mut at = 0;
                for v in range {
                    let faces = match &source {
                        Source::Listed { offsets, .. } => &all[offsets[v]..offsets[v + 1]],
                        Source::Gathered { .. } => {
                            let k = v - c * CHUNK;
                            &all[k.checked_sub(1).map_or(0, |j| ends[j])..ends[k]]
                        }
                    };
                    let deg = vv_offsets[v + 1] - vv_offsets[v];
                    write_neighbors(v as u32, faces, triangles, scratch, &mut out[at..at + deg]);
                    at += deg;
                }
                meter.add(range_len);
            },
        );
    Ok(vv)
}

/// Each chunk's faces gathered for a build from sorted triangles: the faces crossing into it
/// from a face whose smallest corner is in a lower chunk (placed by the build's scatter, each
/// chunk's at `cross_start[c]`), then its own runs (`own[c]..own[c + 1]`), a face once per corner
/// in the chunk. Ascending, in a row per face: the chunk's region of the vertex → face array.
struct Gathered {
    cross_start: Vec<usize>,
    own: Vec<usize>,
}

impl Gathered {
    fn region<'b>(
        &self,
        c: usize,
        cross: &[u32],
        triangles: &[[u32; 3]],
        out: &'b mut Vec<u32>,
    ) -> &'b mut [u32] {
        out.clear();
        out.extend_from_slice(&cross[self.cross_start[c]..self.cross_start[c + 1]]);
        for (t, tri) in (self.own[c]..self.own[c + 1]).zip(&triangles[self.own[c]..self.own[c + 1]])
        {
            if is_degenerate(tri) {
                continue;
            }
            for &v in tri {
                if v as usize / CHUNK == c {
                    out.push(t as u32);
                }
            }
        }
        out
    }
}

/// Blocks of triangles the vertex → face build counts and scatters in parallel (a work size
/// only, like [`CHUNK`]).
const BLOCKS: usize = 64;

/// What one block of triangles holds for the vertex → face build.
struct BlockCount {
    /// Corners of the block's (non-degenerate) triangles in each chunk of [`CHUNK`] vertices.
    per_chunk: Vec<u32>,
    /// Of those, when gathering, the corners in another chunk than the face's first corner.
    crossing: Vec<u32>,
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
fn count_block(
    first: usize,
    block: &[[u32; 3]],
    n_vertices: usize,
    chunks: usize,
    gather: bool,
) -> BlockCount {
    let mut count = BlockCount {
        per_chunk: Vec::new(),
        crossing: vec![0; if gather { chunks } else { 0 }],
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
        if gather {
            let c = tri[0] as usize / CHUNK;
            for &v in &tri[1..] {
                if v as usize / CHUNK != c {
                    count.crossing[v as usize / CHUNK] += 1;
                }
            }
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

/// Whether a face repeats a corner: it joins no vertices, in the topology (whose corners are
/// fixed and counted) and in [`crate::metrics::components`] alike.
pub(crate) fn is_degenerate(t: &[u32; 3]) -> bool {
    t[0] == t[1] || t[1] == t[2] || t[0] == t[2]
}

/// Whether every triangle's first corner is its smallest and the triangles are sorted by it
/// (the layout [`FaceIndex::Runs`] reads).
pub(super) fn sorted_by_first(triangles: &[[u32; 3]]) -> bool {
    let first = |t: &[u32; 3]| t[0] <= t[1] && t[0] <= t[2];
    triangles.par_iter().all(first)
        && triangles
            .par_windows(2)
            .with_min_len(1 << 14)
            .all(|w| w[0][0] <= w[1][0])
}

/// Where each vertex's run of `triangles` (sorted by first corner, [`sorted_by_first`]) starts,
/// and the end: `n_vertices + 1` entries.
pub(super) fn run_starts(
    storage: &Storage,
    n_vertices: usize,
    triangles: &[[u32; 3]],
) -> Result<Buf<u32>> {
    let mut starts: Buf<u32> = storage.zeroed(n_vertices + 1)?;
    // Each chunk of vertices finds its first run by a search, then walks its triangles.
    starts
        .par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, out)| {
            let lo = (c * CHUNK) as u32;
            let mut t = triangles.partition_point(|tri| tri[0] < lo);
            for (k, s) in out.iter_mut().enumerate() {
                let v = lo + k as u32;
                while t < triangles.len() && triangles[t][0] < v {
                    t += 1;
                }
                *s = t as u32;
            }
        });
    Ok(starts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::topology::corners_after;
    use crate::topology::fans::analyse_general;
    use crate::topology::masks::FIXED;
    use crate::topology::{FaceParts, MAX_FREE_DEGREE};

    /// Octahedron: closed, 6 vertices of degree 4.
    fn octahedron() -> Vec<[u32; 3]> {
        crate::shapes::octahedron().triangles.to_vec()
    }

    #[test]
    fn closed_octahedron_has_no_fixed_vertex() {
        let t = Topology::build(6, &octahedron()).unwrap();
        assert_eq!(t.stats.edges, 12);
        assert_eq!(t.stats.boundary_edges, 0);
        assert_eq!(t.stats.fixed_vertices, 0);
        let tris = octahedron();
        assert!((0..6).all(|v| t.deg(v) == 4 && t.faces_of(v, &tris).count() == 4));
        assert_eq!(t.edges().count(), 12);
        assert!(t.edges().all(|[i, j]| i < j));
        // As many neighbours as faces everywhere: one offsets array serves both lists.
        assert!(t.vv_offsets.is_empty());
        assert_eq!(t.heap_bytes(), 7 * 8 + 2 * 24 * 4 + 6);
    }

    #[test]
    fn open_fan_fixes_its_rim_only() {
        // Centre 0 with rim 1..=5 closed around it: the rim is boundary, the centre is interior.
        let tris: Vec<[u32; 3]> = (1..=5).map(|k| [0, k, k % 5 + 1]).collect();
        let t = Topology::build(6, &tris).unwrap();
        assert!(!t.is_fixed(0));
        assert!((1..=5).all(|v| t.is_fixed(v)));
        assert_eq!(t.stats.boundary_edges, 5);
        // The rim has a neighbour more than faces: the offsets differ, both are kept.
        assert_eq!(t.parts().vv_offsets, [0, 5, 8, 11, 14, 17, 20]);
        assert_eq!(whole(&t).2, [0, 5, 7, 9, 11, 13, 15]);
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
                    assert!(
                        topo.faces_of(v, &tris)
                            .eq(faces_of[v as usize].iter().copied())
                    );
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
        let FaceParts::Lists { offsets, faces } = p.faces else {
            panic!("a build lists the faces")
        };
        (
            p.vv_offsets.to_vec(),
            p.vv.to_vec(),
            offsets.to_vec(),
            faces.to_vec(),
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
        // Holes (so pass 2 and summed offsets), flipped faces, degenerate faces, a duplicated
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
        // Vertices whose neighbours less faces do not fit a byte, or are the escape value: a hub
        // of 300 separate faces (600 neighbours), one face repeated 300 times (2 neighbours, and
        // so for its other two corners) and one repeated 130 times (-128), in several chunks,
        // with a boundary vertex of a small misfit between them.
        let hub = CHUNK as u32 + 5;
        let mut escapes: Vec<[u32; 3]> = (0..300).map(|k| [hub, 2 * k, 2 * k + 1]).collect();
        let repeated = 3 * CHUNK as u32 + 1;
        escapes.extend((0..300).map(|_| [repeated, 700, 701]));
        escapes.extend((0..130).map(|_| [repeated + 2, 704, 705]));
        escapes.push([2 * CHUNK as u32, 702, 703]);
        cases.push(("escapes", 3 * CHUNK + 7, escapes));
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

    #[test]
    fn the_build_from_runs_is_the_build_with_its_faces_in_runs() {
        // The reference cases in the plan's layout (with and without a vertex over MAX_RUN,
        // which falls back to the lists), on several thread counts: the same neighbours, mask,
        // counts and faces as a listed build turned to runs.
        let sphere = crate::shapes::icosphere(6);
        let bunny =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/stanford-bunny.ply");
        let scan = crate::io::read_mesh(&bunny).unwrap();
        let mut open = sphere.triangles.to_vec();
        open.truncate(open.len() - 300);
        open.extend([[5, 5, 9], [7, 7, 7], [3, 11, 4], [3, 11, 4], [3, 11, 20]]);
        let hub = 2 * CHUNK as u32 + 3;
        let mut hubbed = open.clone();
        hubbed.extend((0..200).map(|k| [hub, 10 * k, 10 * k + 1]));
        let cases = [
            ("closed", sphere.positions.len(), sphere.triangles.to_vec()),
            ("open", sphere.positions.len(), open),
            ("hub", sphere.positions.len(), hubbed),
            ("scan", scan.positions.len(), scan.triangles.to_vec()),
        ];
        for (name, n, tris) in cases {
            let sorted = plan_layout(&tris);
            let mut want = Topology::build(n, &sorted).unwrap();
            let runs = want.faces_by_runs(&Storage::heap(), &sorted).unwrap();
            assert_eq!(runs, name != "hub", "{name}");
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let got = pool
                    .install(|| {
                        Topology::build_runs_metered(
                            &Storage::heap(),
                            n,
                            &sorted,
                            &Meter::default(),
                        )
                    })
                    .unwrap();
                let (w, g) = (want.parts(), got.parts());
                assert_eq!(g.vv_offsets, w.vv_offsets, "{name}");
                assert_eq!(g.vv, w.vv, "{name}");
                assert_eq!(g.fixed, w.fixed, "{name}");
                assert!(got.stats == want.stats, "{name}");
                match (g.faces, w.faces) {
                    (FaceParts::Runs { starts: a }, FaceParts::Runs { starts: b }) => {
                        assert_eq!(a, b)
                    }
                    (
                        FaceParts::Lists {
                            offsets: a,
                            faces: b,
                        },
                        FaceParts::Lists {
                            offsets: c,
                            faces: d,
                        },
                    ) => {
                        assert!(a == c && b == d, "{name}")
                    }
                    _ => panic!("{name}: runs against lists"),
                }
            }
        }
        // Triangles in another layout get the listed build.
        let got = Topology::build_runs_metered(
            &Storage::heap(),
            scan.positions.len(),
            &scan.triangles,
            &Meter::default(),
        )
        .unwrap();
        assert!(matches!(got.parts().faces, FaceParts::Lists { .. }));
    }

    /// `tris` as a plan lays them out: each rotated to start at its smallest corner (which keeps
    /// its orientation), then sorted by that corner, stably.
    fn plan_layout(tris: &[[u32; 3]]) -> Vec<[u32; 3]> {
        let mut out: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| {
                let k = (0..3).min_by_key(|&k| t[k]).unwrap();
                [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
            })
            .collect();
        out.sort_by_key(|t| t[0]);
        out
    }

    #[test]
    fn faces_found_in_runs_are_the_listed_faces_in_their_order() {
        // Closed and open, degenerate faces (one repeated corner, and three), faces repeated, a
        // non-manifold edge, an unreferenced vertex, a hub and vertices in several chunks.
        let sphere = crate::shapes::icosphere(5);
        let n = sphere.positions.len();
        let perm = crate::shapes::permutation(n + 1, 3);
        let mut tris: Vec<[u32; 3]> = sphere
            .triangles
            .iter()
            .map(|t| t.map(|v| perm[v as usize]))
            .collect();
        let closed = tris.clone();
        tris.truncate(tris.len() - 40);
        tris.extend([[5, 5, 9], [7, 7, 7], [3, 11, 4], [3, 11, 4], [3, 11, 20]]);
        // A vertex of 50 more faces: its lower neighbours' runs hold more candidates than the
        // walk gathers at once.
        let hub = n as u32 / 2;
        tris.extend((0..50).map(|k| [hub, k, k + 1]));
        let mut cases = vec![("closed", closed), ("open and damaged", tris.clone())];
        let bunny =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/stanford-bunny.ply");
        cases.push((
            "scan",
            crate::io::read_mesh(&bunny).unwrap().triangles.to_vec(),
        ));
        for (name, tris) in cases {
            let n = 1 + tris.iter().flatten().copied().max().unwrap() as usize + 1;
            let listed = Topology::build(n, &tris).unwrap();
            let mut unsorted = listed.clone();
            assert!(!unsorted.faces_by_runs(&Storage::heap(), &tris).unwrap());
            let sorted = plan_layout(&tris);
            let listed = Topology::build(n, &sorted).unwrap();
            let mut runs = listed.clone();
            assert!(
                runs.faces_by_runs(&Storage::heap(), &sorted).unwrap(),
                "{name}"
            );
            assert!(matches!(runs.parts().faces, FaceParts::Runs { .. }));
            let walked = |topo: &Topology, v: u32, end: u32| {
                let mut out = Vec::new();
                crate::for_each_face!(topo.parts(), v, &sorted, end, |t, tri| {
                    assert_eq!(tri, sorted[t as usize]);
                    out.push(t);
                });
                out
            };
            for v in 0..n as u32 {
                let want: Vec<u32> = listed.faces_of(v, &sorted).collect();
                let got: Vec<u32> = runs.faces_of(v, &sorted).collect();
                assert_eq!(got, want, "{name}: faces of {v}");
                assert_eq!(walked(&runs, v, u32::MAX), want, "{name}: {v} walked");
                assert_eq!(walked(&listed, v, u32::MAX), want, "{name}: {v} listed");
                // Below a run's start: the faces whose smallest corner is below its vertex.
                for w in [v / 2, v.saturating_sub(3), v, v + 1] {
                    let end = sorted.partition_point(|t| t[0] < w) as u32;
                    let below: Vec<u32> = want.iter().copied().filter(|&t| t < end).collect();
                    assert_eq!(walked(&runs, v, end), below, "{name}: {v} below {w}");
                    assert_eq!(walked(&listed, v, end), below);
                }
                assert_eq!(runs.neighbors(v), listed.neighbors(v));
                assert!(runs.check_vertex(v));
            }
            // The bound holds every face of a range of vertices once.
            for lo in (0..n as u32).step_by(97) {
                let range = lo..(lo + 150).min(n as u32);
                let mut faces: Vec<u32> = range
                    .clone()
                    .flat_map(|v| listed.faces_of(v, &sorted))
                    .collect();
                faces.sort_unstable();
                faces.dedup();
                let bound = runs.faces_bound(range.clone());
                assert!(bound >= faces.len(), "{name} {range:?}");
                assert!(listed.faces_bound(range) >= faces.len());
            }
            // The lists and their offsets are gone; the neighbours keep offsets of their own.
            let t = sorted.len() - listed.stats.degenerate_triangles;
            let saved = listed.heap_bytes() - runs.heap_bytes();
            let own_offsets = match listed.vv_offsets.is_empty() {
                true => 0,
                false => 8 * (n + 1),
            };
            assert_eq!(saved + 4 * (n + 1), 12 * t + own_offsets, "{name}");
        }
        // The bound counts a lower neighbour's run once, however many vertices it is next to:
        // the rim of a fan around vertex 0 is next to it alone, whose run is the fan.
        let fan: Vec<[u32; 3]> = (1..=10).map(|k| [0, k, k % 10 + 1]).collect();
        let mut topo = Topology::build(11, &fan).unwrap();
        assert!(topo.faces_by_runs(&Storage::heap(), &fan).unwrap());
        assert_eq!(topo.faces_bound(1..11), 10);
        // A vertex of more faces than a run may hold keeps the lists.
        let hub = 5;
        tris.extend((0..super::super::MAX_RUN as u32).map(|k| [hub, 100 + k, 101 + k]));
        let sorted = plan_layout(&tris);
        let n = 1 + sorted.iter().flatten().copied().max().unwrap() as usize;
        let mut topo = Topology::build(n, &sorted).unwrap();
        assert!(!topo.faces_by_runs(&Storage::heap(), &sorted).unwrap());
        assert!(matches!(topo.parts().faces, FaceParts::Lists { .. }));
    }
}
