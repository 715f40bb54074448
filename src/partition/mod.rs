//! Spatial reordering and patches.
//!
//! - [`reorder`] sorts vertices along a Morton (Z-order) curve of their positions, so that a
//!   spatial patch is a contiguous range of vertex ids and a memory-mapped array is read in
//!   nearby pages; triangles are renumbered, rotated so that their smallest vertex comes first
//!   (a cyclic rotation keeps the orientation), and sorted. The permutation is kept so that the
//!   output can be written in the input's vertex order.
//! - Vertices at exactly one position are *welded* (unless asked not to): the triangles of every
//!   copy name the first of them on the curve (the smallest input id), so that a texture seam or
//!   an unmerged STL is one surface to smooth; the copies stay in the plan, unreferenced, and each
//!   takes its first's position when the output is written ([`Reordered::welded_to`]). A mesh
//!   without copies gives the plan it gave before welding existed. With a tolerance
//!   ([`Weld::Within`]), vertices closer than it are welded too (see [`Weld`]).
//! - [`patches`] cuts the reordered vertices into ranges of `patch_size` and assigns each stencil
//!   to exactly one patch, the one holding its smallest vertex: an edge stencil `(i, j)`, `i < j`,
//!   belongs to the patch of `i`; a triangle stencil to the patch of its first (smallest) vertex.
//!   So every stencil, including those crossing patches, is applied exactly once per iteration.

use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::Result;
use crate::mesh::{Buf, Storage};
use crate::meter::{Meter, Passes, STEP};
use crate::metrics;
use crate::topology::Topology;

/// Which vertices are one vertex to smooth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Weld {
    /// None: every vertex on its own.
    Off,
    /// Vertices at exactly one position (`-0` and `+0` are one value).
    Exact,
    /// Vertices within this distance (positive, finite): each vertex in input order is welded to
    /// the nearest earlier vertex within it that was not itself welded (the smallest id among
    /// equally near ones), else it stays a vertex of its own. Greedy, so a chain of vertices each
    /// just within the tolerance of the next is not pulled onto one point; deterministic, and
    /// sequential (one pass over a grid of cells of that size).
    Within(f64),
}

/// A mesh renumbered along the Morton curve.
#[derive(Debug)]
pub struct Reordered {
    /// `order[new] = old`: the input vertex at each new position.
    pub order: Buf<u32>,
    /// Positions in the new order.
    pub positions: Buf<DVec3>,
    /// Triangles in new ids, smallest vertex first, sorted ascending (sorted by first vertex only
    /// once [`Topology::orient`] has flipped some: it swaps the last two corners).
    pub triangles: Buf<[u32; 3]>,
    /// `welded_to[new]`: the vertex whose position `new` takes in the output, itself unless it is a
    /// welded copy. Empty when no vertex is (the usual case: no memory spent).
    pub welded_to: Buf<u32>,
    /// How many vertices are welded copies of another.
    pub welded: usize,
}

/// The vertex whose position `new` takes in the output, given [`Reordered::welded_to`] (empty:
/// itself).
#[inline]
pub fn source_of(welded_to: &[u32], new: usize) -> usize {
    welded_to.get(new).map_or(new, |&to| to as usize)
}

/// Move each welded copy of `positions` (plan order) to its vertex's position.
pub fn follow_welds(positions: &mut [DVec3], welded_to: &[u32]) {
    for (new, &to) in welded_to.iter().enumerate() {
        positions[new] = positions[to as usize];
    }
}

impl Reordered {
    /// The vertex whose position `new` takes in the output (see [`Reordered::welded_to`]).
    #[inline]
    pub fn source_of(&self, new: usize) -> usize {
        source_of(&self.welded_to, new)
    }

    /// The input's own order as one patch, welded like [`reorder`] if `weld` (ties between copies
    /// go to the smallest id, as on the curve).
    pub fn in_input_order(
        storage: &Storage,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        weld: Weld,
    ) -> Result<Reordered> {
        let mut order = storage.zeroed::<u32>(positions.len())?;
        order.iter_mut().zip(0..).for_each(|(o, v)| *o = v);
        let mut tris = storage.copy_of(triangles)?;
        let pairs = match weld {
            Weld::Off => Vec::new(),
            Weld::Exact => {
                let ids: Vec<u32> = (0..positions.len() as u32).collect();
                copies_sorted(ids, |v| positions[v as usize])
            }
            Weld::Within(d) => copies_within(positions, d),
        };
        let (welded_to, welded) = welded_from_pairs(storage, positions.len(), &pairs)?;
        if welded > 0 {
            tris.par_iter_mut()
                .for_each(|t| *t = t.map(|v| welded_to[v as usize]));
        }
        Ok(Reordered {
            order,
            positions: storage.copy_of(positions)?,
            triangles: tris,
            welded_to,
            welded,
        })
    }
}

/// A position's bits, with −0 read as +0 (the two are one position).
fn position_bits(p: DVec3) -> [u64; 3] {
    (p + DVec3::ZERO).to_array().map(f64::to_bits)
}

/// `(copy, first)` for each vertex of `run` (ids in a deterministic order, copies of one position
/// ordered by id) whose position, read by `at`, equals an earlier one's. Short runs compare every
/// pair; long ones (a mesh collapsed to a point) sort by position.
fn copies_in_run(run: &[u32], at: impl Fn(u32) -> DVec3) -> Vec<(u32, u32)> {
    let mut pairs = Vec::new();
    if run.len() <= 32 {
        for (k, &v) in run.iter().enumerate() {
            if let Some(&first) = run[..k].iter().find(|&&u| at(u) == at(v)) {
                pairs.push((v, first));
            }
        }
        return pairs;
    }
    copies_sorted(run.to_vec(), at)
}

/// [`copies_in_run`] by sorting `ids` by position, then id.
fn copies_sorted(mut ids: Vec<u32>, at: impl Fn(u32) -> DVec3) -> Vec<(u32, u32)> {
    let mut pairs = Vec::new();
    ids.sort_unstable_by_key(|&v| (position_bits(at(v)), v));
    let Some(&start) = ids.first() else {
        return pairs;
    };
    let mut first = start;
    for w in ids.windows(2) {
        match at(w[1]) == at(w[0]) {
            true => pairs.push((w[1], first)),
            false => first = w[1],
        }
    }
    pairs
}

/// The `(copy, first)` pairs of [`Weld::Within`] `d`, in input ids.
fn copies_within(positions: &[DVec3], d: f64) -> Vec<(u32, u32)> {
    // A vertex within `d` of another lies in its cell or a neighbouring one.
    let cell = |p: DVec3| (p / d).floor().as_i64vec3().to_array();
    let mut firsts: std::collections::HashMap<[i64; 3], Vec<u32>> = Default::default();
    let mut pairs = Vec::new();
    for (v, &p) in positions.iter().enumerate() {
        let c = cell(p);
        let mut nearest: Option<(f64, u32)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    // Saturating: cells beyond `i64` (a tolerance far below the coordinates)
                    // share the last one, and the distance decides.
                    let at = [
                        c[0].saturating_add(dx),
                        c[1].saturating_add(dy),
                        c[2].saturating_add(dz),
                    ];
                    for &u in firsts.get(&at).map_or(&[][..], Vec::as_slice) {
                        let far = positions[u as usize].distance(p);
                        let nearer = nearest.is_none_or(|(f, w)| far < f || (far == f && u < w));
                        if far <= d && nearer {
                            nearest = Some((far, u));
                        }
                    }
                }
            }
        }
        match nearest {
            Some((_, first)) => pairs.push((v as u32, first)),
            None => firsts.entry(c).or_default().push(v as u32),
        }
    }
    pairs
}

/// [`Reordered::welded_to`] and the copies' count from the `(copy, first)` pairs.
fn welded_from_pairs(
    storage: &Storage,
    n: usize,
    pairs: &[(u32, u32)],
) -> Result<(Buf<u32>, usize)> {
    if pairs.is_empty() {
        return Ok((Buf::default(), 0));
    }
    let mut to: Buf<u32> = storage.zeroed(n)?;
    to.par_iter_mut()
        .enumerate()
        .for_each(|(v, t)| *t = v as u32);
    for &(copy, first) in pairs {
        to[copy as usize] = first;
    }
    Ok((to, pairs.len()))
}

/// The `(copy, first)` pairs of the curve: copies of a position share its curve key, so each run
/// of one key (sorted by input id within) is searched alone. A chunk takes the runs that start in
/// it, so each run is searched once whatever the threads.
fn copies_on_curve(key: impl Fn(usize) -> u64 + Sync, positions: &[DVec3]) -> Vec<(u32, u32)> {
    let n = positions.len();
    let starts_run = |i: usize| i == 0 || key(i - 1) != key(i);
    (0..n.div_ceil(STEP))
        .into_par_iter()
        .flat_map_iter(|c| {
            let mut pairs = Vec::new();
            let mut i = c * STEP;
            let end = ((c + 1) * STEP).min(n);
            while i < end && !starts_run(i) {
                i += 1;
            }
            while i < end {
                let mut j = i + 1;
                while j < n && !starts_run(j) {
                    j += 1;
                }
                if j - i > 1 {
                    let run: Vec<u32> = (i as u32..j as u32).collect();
                    pairs.extend(copies_in_run(&run, |v| positions[v as usize]));
                }
                i = j;
            }
            pairs
        })
        .collect()
}

/// The input's positions as [`reorder_metered`] takes them: lent, or given, so that they go as
/// soon as the plan's copy is made (out of core, 12 B per triangle less while the triangles are
/// renumbered and sorted).
pub enum Input<'a> {
    Lent(&'a [DVec3]),
    Given(Buf<DVec3>),
}

impl std::ops::Deref for Input<'_> {
    type Target = [DVec3];

    fn deref(&self) -> &[DVec3] {
        match self {
            Input::Lent(p) => p,
            Input::Given(p) => p,
        }
    }
}

/// Reorder `positions` and `triangles` along the Morton curve (see the module doc). Deterministic:
/// ties in the curve key are broken by the input vertex id.
pub fn reorder(
    storage: &Storage,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
) -> Result<Reordered> {
    reorder_metered(
        storage,
        Input::Lent(positions),
        triangles,
        Weld::Exact,
        &Meter::default(),
    )
}

/// The passes [`reorder_metered`] counts: the curve keys, their sort, the permutation and its
/// inverse, the positions; the triangles renumbered, their sort.
pub const REORDER_PASSES: Passes = Passes {
    vertices: 4,
    triangles: 2,
};

/// [`reorder`], welding as `weld` says, counting its work into `meter` ([`REORDER_PASSES`] over
/// the mesh; the sorts count when they end). The same result.
pub fn reorder_metered(
    storage: &Storage,
    positions: Input,
    triangles: &[[u32; 3]],
    weld: Weld,
    meter: &Meter,
) -> Result<Reordered> {
    reorder_counted(storage, positions, triangles, weld, false, meter).map(|(r, _)| r)
}

/// [`reorder_metered`], and with `components` the reordered mesh's connected components
/// ([`metrics::components`]), counted as the sort holds each bucket of triangles in cache rather
/// than in a pass of their own over the plan's triangles afterwards.
pub fn reorder_counted(
    storage: &Storage,
    positions: Input,
    triangles: &[[u32; 3]],
    weld: Weld,
    components: bool,
    meter: &Meter,
) -> Result<(Reordered, Option<usize>)> {
    let n = positions.len();
    // Minima and maxima do not depend on the order they are taken in.
    let (lo, hi) = positions
        .par_iter()
        .fold(
            || (DVec3::INFINITY, DVec3::NEG_INFINITY),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        )
        .reduce(
            || (DVec3::INFINITY, DVec3::NEG_INFINITY),
            |(lo, hi), (l, h)| (lo.min(l), hi.max(h)),
        );
    let extent = (hi - lo).max_element();
    let scale = if extent > 0.0 {
        ((1u64 << 21) - 1) as f64 / extent
    } else {
        0.0
    };

    let curve = move |p: DVec3| {
        let q = ((p - lo) * scale).as_u64vec3();
        morton3(q.x, q.y, q.z)
    };

    // Element-wise passes, cut into chunks only to count them: each item is computed as in one pass.
    let mut keys: Buf<[u64; 2]> = storage.zeroed(n)?;
    keys.par_chunks_mut(STEP).enumerate().for_each(|(c, keys)| {
        for (k, key) in keys.iter_mut().enumerate() {
            let v = c * STEP + k;
            *key = [curve(positions[v]), v as u64];
        }
        meter.add(keys.len() as u64);
    });
    keys.par_sort_unstable();
    meter.add(n as u64);

    let mut order: Buf<u32> = storage.zeroed(n)?;
    order
        .par_iter_mut()
        .zip(keys.par_iter())
        .for_each(|(o, k)| *o = k[1] as u32);
    // The keys go before the positions are copied (8 B per vertex less at the phase's peak): the
    // welding finds equal keys again from the copied positions.
    drop(keys);
    let mut rank: Buf<u32> = storage.zeroed(n)?;
    scatter(&mut rank, &order, |new| new as u32);
    meter.add(n as u64);

    let mut new_pos: Buf<DVec3> = storage.zeroed(n)?;
    new_pos
        .par_chunks_mut(STEP)
        .zip(order.par_chunks(STEP))
        .for_each(|(p, old)| {
            for (p, &old) in p.iter_mut().zip(old) {
                *p = positions[old as usize];
            }
            meter.add(p.len() as u64);
        });

    let pairs = match weld {
        Weld::Off => Vec::new(),
        Weld::Exact => copies_on_curve(|i| curve(new_pos[i]), &new_pos),
        Weld::Within(d) => copies_within(&positions, d)
            .into_iter()
            .map(|(copy, first)| (rank[copy as usize], rank[first as usize]))
            .collect(),
    };
    drop(positions);
    let (welded_to, welded) = welded_from_pairs(storage, n, &pairs)?;
    if welded > 0 {
        rank.par_iter_mut()
            .for_each(|r| *r = welded_to[*r as usize]);
    }

    // Renumbered, smallest vertex first, and sorted by a bucket sort on that vertex.
    let renumbered = |t: usize| {
        let r = triangles[t].map(|v| rank[v as usize]);
        let first = (0..3).min_by_key(|&k| r[k]).unwrap_or(0);
        [r[first], r[(first + 1) % 3], r[(first + 2) % 3]]
    };
    let mut tris: Buf<[u32; 3]> = storage.zeroed(triangles.len())?;
    let shift = first_corner_shift(n);
    let sort = |tris: &mut Buf<[u32; 3]>, join: &(dyn Fn(&[[u32; 3]]) + Sync)| {
        sort_by_buckets(
            triangles.len(),
            renumbered,
            |t| (t[0] >> shift) as usize,
            |bucket| {
                sort_by_first(bucket, shift);
                join(bucket);
            },
            tris,
            meter,
        )
    };
    let count = match components {
        true => Some(metrics::components_joining(n, storage, |join| sort(&mut tris, join))?.0),
        false => {
            sort(&mut tris, &|_| ());
            None
        }
    };
    meter.add(triangles.len() as u64);
    let reordered = Reordered {
        order,
        positions: new_pos,
        triangles: tris,
        welded_to,
        welded,
    };
    Ok((reordered, count))
}

/// Buckets of [`sort_by_buckets`]: few enough that every chunk of items keeps a count for each
/// and that the streams it writes stay in cache.
const BUCKETS: usize = 1 << 11;

/// Most chunks [`sort_by_buckets`] cuts its items into.
const CHUNKS: usize = 256;

/// `out` = the items `item(0..count)` in ascending order: a counting sort into [`BUCKETS`] by
/// `bucket(item)` (not decreasing with the item), stable, each bucket then sorted in cache by
/// `sort`.
/// Chunks of at least [`STEP`] items count their buckets, so each chunk knows where its items of each
/// bucket go: the placement does not depend on the threads. `meter` counts the items placed.
fn sort_by_buckets<T: Copy + Ord + Send + Sync>(
    count: usize,
    item: impl Fn(usize) -> T + Sync,
    bucket: impl Fn(&T) -> usize + Sync,
    sort: impl Fn(&mut [T]) + Sync,
    out: &mut [T],
    meter: &Meter,
) {
    assert_eq!(out.len(), count);
    // At most CHUNKS chunks, so that their counts stay small on the largest meshes.
    let step = count.div_ceil(CHUNKS).max(STEP);
    let range = |c: usize| c * step..((c + 1) * step).min(count);
    let mut counts: Vec<Vec<usize>> = (0..count.div_ceil(step))
        .into_par_iter()
        .map(|c| {
            let mut n = vec![0usize; BUCKETS];
            for i in range(c) {
                n[bucket(&item(i))] += 1;
            }
            n
        })
        .collect();
    // Counts into where each chunk's items of each bucket start, bucket by bucket.
    let mut ends = vec![0usize; BUCKETS];
    let mut at = 0;
    for (b, end) in ends.iter_mut().enumerate() {
        for n in counts.iter_mut() {
            let k = n[b];
            n[b] = at;
            at += k;
        }
        *end = at;
    }
    let slots = Slots(out.as_mut_ptr());
    counts
        .into_par_iter()
        .enumerate()
        .for_each(|(c, mut next)| {
            let items = range(c);
            let placed = items.len() as u64;
            for i in items {
                let x = item(i);
                let slot = &mut next[bucket(&x)];
                // SAFETY: the chunks' slots of a bucket are disjoint ranges of `0..count`, and each
                // is handed out once.
                unsafe { slots.write(*slot, x) };
                *slot += 1;
            }
            meter.add(placed);
        });
    let lens: Vec<usize> = (0..BUCKETS)
        .map(|b| ends[b] - b.checked_sub(1).map_or(0, |p| ends[p]))
        .collect();
    crate::topology::split_lens(out, &lens)
        .into_par_iter()
        .for_each(&sort);
}

/// The smallest shift of a vertex id below `n` that gives one of the [`BUCKETS`].
fn first_corner_shift(n: usize) -> u32 {
    usize::BITS - (n >> BUCKETS.trailing_zeros()).leading_zeros()
}

/// Sorts `tris`, whose first corners agree above their low `bits` bits: a counting sort by the
/// first corner, then each run of one first corner (a vertex's few triangles) by the others.
fn sort_by_first(tris: &mut [[u32; 3]], bits: u32) {
    if tris.len() < 2 {
        return;
    }
    let low = |t: &[u32; 3]| (t[0] & ((1u32 << bits) - 1)) as usize;
    let mut starts = vec![0usize; (1 << bits) + 1];
    for t in tris.iter() {
        starts[low(t) + 1] += 1;
    }
    for k in 1..starts.len() {
        starts[k] += starts[k - 1];
    }
    let copy = tris.to_vec();
    let mut next = starts.clone();
    for t in copy {
        let slot = &mut next[low(&t)];
        tris[*slot] = t;
        *slot += 1;
    }
    for run in starts.windows(2) {
        let run = &mut tris[run[0]..run[1]];
        if run.len() > 1 {
            run.sort_unstable();
        }
    }
}

/// The items of [`sort_by_buckets`]'s output, written from several threads at distinct slots.
struct Slots<T>(*mut T);

// SAFETY: the pointer is only used to write distinct slots (see `sort_by_buckets`).
unsafe impl<T: Send> Sync for Slots<T> {}

impl<T> Slots<T> {
    /// SAFETY: `slot` is in bounds and no other thread reads or writes it meanwhile.
    unsafe fn write(&self, slot: usize, x: T) {
        unsafe { self.0.add(slot).write(x) }
    }
}

/// `out[index[k]] = value(k)` for every `k`, on the current pool; `index` must be a permutation
/// of `0..out.len()` (a slot that no index names keeps its value). Each of a few ranges of `out`
/// scans all of `index` for the slots in it: a sequential read of 4 bytes per item per range, far
/// cheaper than the scattered writes it shares out, and no unsafe code. The ranges are at most
/// `SCATTER_RANGES`, so that the reading does not grow with the thread count of a large node.
pub fn scatter<T: Send>(out: &mut [T], index: &[u32], value: impl Fn(usize) -> T + Sync) {
    scatter_metered(out, index, value, &Meter::default());
}

/// [`scatter`], counting into `meter` the slots of `out` written (all of them when `index` is a
/// permutation), once per [`STEP`] of `index` that each range scans.
pub fn scatter_metered<T: Send>(
    out: &mut [T],
    index: &[u32],
    value: impl Fn(usize) -> T + Sync,
    meter: &Meter,
) {
    let ranges = rayon::current_num_threads().clamp(1, SCATTER_RANGES);
    let part = out.len().div_ceil(ranges).max(1);
    out.par_chunks_mut(part).enumerate().for_each(|(c, out)| {
        let lo = c * part;
        for (s, step) in index.chunks(STEP).enumerate() {
            let mut written = 0;
            for (k, &i) in step.iter().enumerate() {
                if let Some(slot) = (i as usize).checked_sub(lo).and_then(|i| out.get_mut(i)) {
                    *slot = value(s * STEP + k);
                    written += 1;
                }
            }
            meter.add(written);
        }
    });
}

/// Most ranges [`scatter`] shares out: each reads the whole index.
const SCATTER_RANGES: usize = 8;

/// Interleave the low 21 bits of x, y, z into a 63-bit Morton key.
pub(crate) fn morton3(x: u64, y: u64, z: u64) -> u64 {
    fn spread(mut v: u64) -> u64 {
        v &= 0x1f_ffff;
        v = (v | v << 32) & 0x1f_0000_0000_ffff;
        v = (v | v << 16) & 0x1f_0000_ff00_00ff;
        v = (v | v << 8) & 0x100f_00f0_0f00_f00f;
        v = (v | v << 4) & 0x10c3_0c30_c30c_30c3;
        v = (v | v << 2) & 0x1249_2492_4924_9249;
        v
    }
    spread(x) | spread(y) << 1 | spread(z) << 2
}

/// One patch: a contiguous range of (reordered) vertices and the stencils it owns.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Patch {
    /// Owned vertices; the patch owns the edge stencils `(i, j)`, `i < j`, with `i` in this range.
    pub vertices: Range<u32>,
    /// Owned triangle stencils: indices into the sorted triangles whose first vertex is owned.
    pub triangles: Range<u32>,
}

impl Patch {
    /// The owned edge stencils, in ascending `(i, j)` order.
    pub fn edges<'a>(&self, topo: &'a Topology) -> impl Iterator<Item = [u32; 2]> + 'a {
        topo.edges_from(self.vertices.clone())
    }
}

impl Patch {
    /// Owned edge stencils whose second vertex lies in another patch (stencils crossing the seam).
    pub fn crossing_edges(&self, topo: &Topology) -> u64 {
        // An owned edge `(i, j)`, `i < j`, leaves the contiguous range only past its end, and
        // neighbours ascend: the crossing ones are a suffix of each list.
        let end = self.vertices.end;
        self.vertices
            .clone()
            .map(|i| {
                let nbrs = topo.neighbors(i);
                (nbrs.len() - nbrs.partition_point(|&j| j < end)) as u64
            })
            .sum()
    }
}

/// Cut `n_vertices` reordered vertices into patches of `patch_size` (the last may be smaller).
/// `triangles` must be sorted with their smallest vertex first, as [`reorder`] leaves them.
pub fn patches(n_vertices: usize, triangles: &[[u32; 3]], patch_size: usize) -> Vec<Patch> {
    let size = patch_size.max(1);
    let first_triangle = |v: usize| triangles.partition_point(|t| (t[0] as usize) < v) as u32;
    (0..n_vertices.div_ceil(size))
        .map(|p| {
            let (lo, hi) = (p * size, ((p + 1) * size).min(n_vertices));
            Patch {
                vertices: lo as u32..hi as u32,
                triangles: first_triangle(lo)..first_triangle(hi),
            }
        })
        .collect()
}

/// The patches' border: the vertices with a neighbour in another patch, ascending, those whose
/// shares a patch cannot take from the positions at its start (`smooth::method::PatchMesh::border`;
/// not the seam, `engine::seam`, whose vertices have a neighbour in an earlier patch). `patches`
/// are the ranges [`patches`] cut, ascending; the list is in `storage` (out of core; 5 % of the
/// vertices of a 1.3M-triangle sphere at the default patch size, 11 % at 4096).
pub fn patch_border(topo: &Topology, patches: &[Patch], storage: &Storage) -> Result<Buf<u32>> {
    select_vertices(
        patches,
        |_| true,
        storage,
        |p, v| topo.neighbors(v).iter().any(|u| !p.vertices.contains(u)),
    )
}

/// The vertices `keep` selects of each patch that `runs`, patch after patch, ascending, in
/// `storage`: counted, then written, in parallel over the patches.
pub fn select_vertices(
    patches: &[Patch],
    runs: impl Fn(usize) -> bool + Sync,
    storage: &Storage,
    keep: impl Fn(&Patch, u32) -> bool + Sync,
) -> Result<Buf<u32>> {
    let kept = |k: usize| {
        let p = &patches[k];
        let vertices = if runs(k) { p.vertices.clone() } else { 0..0 };
        vertices.filter(|&v| keep(p, v))
    };
    let counts: Vec<usize> = (0..patches.len())
        .into_par_iter()
        .map(|k| kept(k).count())
        .collect();
    let mut out: Buf<u32> = storage.zeroed(counts.iter().sum())?;
    crate::topology::split_lens(&mut out, &counts)
        .into_par_iter()
        .enumerate()
        .for_each(|(k, dst)| {
            let mut vertices = kept(k);
            dst.fill_with(|| vertices.next().expect("counted"));
        });
    Ok(out)
}

#[cfg(test)]
mod tests {
    #[test]
    fn given_positions_go_once_the_plan_has_its_copy() {
        // The input's positions given to the reorder (24 B per vertex in scratch) are let go
        // before the triangles are renumbered beside the copy, and the curve keys before the
        // copy is made; lent ones give the same plan.
        let sphere = crate::shapes::icosphere(5);
        let (n, m) = (sphere.positions.len() as u64, sphere.triangles.len() as u64);
        let dir = tempfile::tempdir().unwrap();
        let storage = Storage::scratch(dir.path()).unwrap();
        let given = storage.copy_of(&sphere.positions).unwrap();
        let meter = Meter::default();
        let r = reorder_metered(
            &storage,
            Input::Given(given),
            &sphere.triangles,
            Weld::Exact,
            &meter,
        )
        .unwrap();
        // The copy and the permutation (28 B per vertex), its inverse (4), then the triangles.
        let peak = (56 * n).max(32 * n + 12 * m);
        assert!(
            storage.peak_mapped_bytes() <= peak,
            "{} > {peak}",
            storage.peak_mapped_bytes()
        );
        assert_eq!(storage.held_bytes(), 28 * n + 12 * m);
        let lent = reorder(&Storage::heap(), &sphere.positions, &sphere.triangles).unwrap();
        assert_eq!(r.positions, lent.positions);
        assert_eq!(r.triangles, lent.triangles);
        assert_eq!(r.order, lent.order);
    }

    use super::*;

    /// Components counted as the reorder sorts the triangles: the count of a plain search, the
    /// same plan as without the count, for any thread count, on the heap and in scratch files.
    #[test]
    fn the_reorder_counts_the_components_it_sorts() {
        // 12 spheres of 162 vertices, apart; spheres 0–1 and 4–5 joined by a face; a degenerate
        // face that would join 7 and 8 if it counted; an unreferenced vertex.
        let s = crate::shapes::icosphere(2);
        let n = s.positions.len() as u32;
        let mut pos: Vec<DVec3> = (0..12)
            .flat_map(|c| {
                let at = DVec3::new(3.0 * (c % 4) as f64, 3.0 * (c / 4) as f64, 0.0);
                s.positions.iter().map(move |p| *p + at)
            })
            .collect();
        pos.push(DVec3::new(-5.0, 0.0, 0.0));
        let mut tris: Vec<[u32; 3]> = (0..12)
            .flat_map(|c| s.triangles.iter().map(move |t| t.map(|v| v + c * n)))
            .collect();
        tris.push([0, 1, n]);
        tris.push([4 * n, 4 * n + 1, 5 * n]);
        tris.push([7 * n, 7 * n, 8 * n]);
        let plain = reorder(&Storage::heap(), &pos, &tris).unwrap();
        let dir = tempfile::tempdir().unwrap();
        for threads in [1, 2, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for storage in [Storage::heap(), Storage::scratch(dir.path()).unwrap()] {
                let (r, count) = pool
                    .install(|| {
                        reorder_counted(
                            &storage,
                            Input::Lent(&pos),
                            &tris,
                            Weld::Exact,
                            true,
                            &Meter::default(),
                        )
                    })
                    .unwrap();
                let searched = metrics::components(
                    pos.len(),
                    &r.triangles,
                    &Storage::heap(),
                    &Meter::default(),
                )
                .unwrap();
                assert_eq!(count, Some(10), "{threads} threads");
                assert_eq!(searched, 10);
                assert_eq!(r.triangles, plain.triangles);
                assert_eq!(r.positions, plain.positions);
            }
        }
    }

    #[test]
    fn morton_interleaves_bits() {
        assert_eq!(morton3(1, 0, 0), 1);
        assert_eq!(morton3(0, 1, 0), 2);
        assert_eq!(morton3(0, 0, 1), 4);
        assert_eq!(morton3(3, 0, 0), 0b1001);
        assert_eq!(morton3(0x1f_ffff, 0x1f_ffff, 0x1f_ffff), (1u64 << 63) - 1);
    }

    #[test]
    fn reorder_is_a_permutation_that_keeps_triangles_and_orientation() {
        let pos: Vec<DVec3> = (0..6)
            .map(|k| DVec3::new((5 - k) as f64, (k % 2) as f64, 0.0))
            .collect();
        let tris = vec![[0, 1, 2], [2, 1, 3], [3, 4, 5], [5, 4, 0]];
        let r = reorder(&Storage::heap(), &pos, &tris).unwrap();
        let mut seen = r.order.to_vec();
        seen.sort();
        assert_eq!(seen, (0..6).collect::<Vec<u32>>());
        for (new, &old) in r.order.iter().enumerate() {
            assert_eq!(r.positions[new], pos[old as usize]);
        }
        // Each reordered triangle maps back to an input triangle up to a cyclic rotation.
        let back = |t: &[u32; 3]| t.map(|v| r.order[v as usize]);
        for t in r.triangles.iter() {
            let b = back(t);
            assert!(t[0] < t[1] && t[0] < t[2]);
            assert!(
                tris.iter()
                    .any(|o| (0..3).any(|k| [o[k], o[(k + 1) % 3], o[(k + 2) % 3]] == b))
            );
        }
        assert!(r.triangles.windows(2).all(|w| w[0] <= w[1]));
    }

    /// Copies (−0 and +0 one position; a run of many on one curve key) are welded to the first by
    /// input id on the curve and in the input order alike; a mesh without copies spends nothing.
    #[test]
    fn copies_are_welded_to_their_first() {
        let mut pos: Vec<DVec3> = (0..40).map(|k| DVec3::new(k as f64, 0.0, 1.0)).collect();
        pos.extend((0..50).map(|_| DVec3::new(3.0, 1.0, 1.0)));
        pos[7] = DVec3::new(3.0, 1.0, 1.0);
        pos[2] = DVec3::new(0.0, -0.0, 1.0);
        pos[0] = DVec3::new(0.0, 0.0, 1.0);
        let tris: Vec<[u32; 3]> = (0..88).map(|k| [k, k + 1, k + 2]).collect();
        let first = |v: usize| match v {
            2 => 0,
            40.. => 7,
            v => v,
        };
        for whole in [false, true] {
            let r = match whole {
                false => reorder(&Storage::heap(), &pos, &tris).unwrap(),
                true => {
                    Reordered::in_input_order(&Storage::heap(), &pos, &tris, Weld::Exact).unwrap()
                }
            };
            assert_eq!(r.welded, 51);
            let rank: std::collections::HashMap<u32, usize> = r
                .order
                .iter()
                .enumerate()
                .map(|(new, &old)| (old, new))
                .collect();
            for (new, &old) in r.order.iter().enumerate() {
                let want = rank[&(first(old as usize) as u32)];
                assert_eq!(r.source_of(new), want, "{old} (whole: {whole})");
            }
            // No triangle names a copy.
            assert!(
                r.triangles
                    .iter()
                    .flatten()
                    .all(|&v| r.source_of(v as usize) == v as usize)
            );
            let unwelded = reorder_metered(
                &Storage::heap(),
                Input::Lent(&pos),
                &tris,
                Weld::Off,
                &Meter::default(),
            )
            .unwrap();
            assert_eq!((unwelded.welded, unwelded.welded_to.len()), (0, 0));
        }
        let distinct: Vec<DVec3> = (0..9).map(|k| DVec3::splat(k as f64)).collect();
        let r = reorder(&Storage::heap(), &distinct, &[[0, 1, 2]]).unwrap();
        assert_eq!((r.welded, r.welded_to.len()), (0, 0));
    }

    /// Within a tolerance: each vertex joins the nearest earlier unjoined one (ties to the
    /// smallest id), a chain is not pulled together, and the curve gives the welds that the
    /// input order gives.
    #[test]
    fn vertices_within_a_tolerance_are_welded_greedily_in_input_order() {
        let p = |x: f64| DVec3::new(x, 0.5, -0.25);
        // 0 and 1 weld (0.6 apart); 2 is 0.6 from 1 but 1.2 from 0: its own; 3 is as near to
        // 0 as to 2 (0.6): the smaller id; 4 is nearer to 2 than to 0.
        let pos = vec![p(0.0), p(0.6), p(1.2), p(0.6), p(1.0), p(10.0)];
        assert_eq!(copies_within(&pos, 1.0), vec![(1, 0), (3, 0), (4, 2)]);
        let tris = vec![[0, 2, 5], [1, 4, 5], [3, 2, 5]];
        let r =
            Reordered::in_input_order(&Storage::heap(), &pos, &tris, Weld::Within(1.0)).unwrap();
        assert_eq!(r.welded, 3);
        assert_eq!(r.triangles[..], [[0, 2, 5], [0, 2, 5], [0, 2, 5]]);
        let curve = reorder_metered(
            &Storage::heap(),
            Input::Lent(&pos),
            &tris,
            Weld::Within(1.0),
            &Meter::default(),
        )
        .unwrap();
        assert_eq!(curve.welded, 3);
        for new in 0..pos.len() {
            let old = curve.order[new] as usize;
            let to = curve.order[curve.source_of(new)] as usize;
            assert_eq!(to, r.source_of(old), "vertex {old}");
        }
        // Exactly equal positions weld at any tolerance; none is welded with none.
        assert_eq!(copies_within(&[p(0.0), p(0.0)], 1e-300), vec![(1, 0)]);
        let none = Reordered::in_input_order(&Storage::heap(), &pos, &tris, Weld::Off).unwrap();
        assert_eq!((none.welded, none.welded_to.len()), (0, 0));
    }

    #[test]
    fn patches_cover_vertices_and_triangles_once() {
        let tris: Vec<[u32; 3]> = vec![[0, 1, 2], [0, 2, 3], [1, 4, 2], [3, 5, 6], [4, 5, 6]];
        let ps = patches(7, &tris, 3);
        assert_eq!(ps.len(), 3);
        assert_eq!(ps[0].vertices, 0..3);
        assert_eq!(ps[2].vertices, 6..7);
        assert_eq!(
            ps.iter().map(|p| p.triangles.len()).sum::<usize>(),
            tris.len()
        );
        assert_eq!(ps[0].triangles, 0..3);
        assert_eq!(ps[1].triangles, 3..5);
    }

    #[test]
    fn scatter_places_every_item_for_any_thread_count() {
        let n = 10_007;
        let index = crate::shapes::permutation(n, 0x1234_5679);
        let mut want = vec![0u64; n];
        for (k, &i) in index.iter().enumerate() {
            want[i as usize] = k as u64 * 3;
        }
        for threads in [1, 3, 16] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut out = vec![0u64; n];
            pool.install(|| scatter(&mut out, &index, |k| k as u64 * 3));
            assert_eq!(out, want, "{threads} threads");
        }
    }

    /// The triangles' bucket sort gives what a plain sort gives (duplicates, runs of one first
    /// corner, empty buckets, more than one chunk), for any thread count and vertex count.
    #[test]
    fn bucket_sort_equals_a_plain_sort() {
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move |m: u32| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % m as u64) as u32
        };
        for n in [1u32, 5, 2048, 4099, 1 << 16, 3_000_017] {
            let count = 3 * STEP + 7;
            let tris: Vec<[u32; 3]> = (0..count)
                .map(|_| {
                    // Some vertices far more often than others, and repeated triangles.
                    let a = if next(4) == 0 {
                        next(n.min(3))
                    } else {
                        next(n)
                    };
                    [a, next(n), next(n)]
                })
                .collect();
            let mut want = tris.clone();
            want.sort_unstable();
            let shift = first_corner_shift(n as usize);
            for threads in [1, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut out = vec![[0; 3]; count];
                pool.install(|| {
                    sort_by_buckets(
                        count,
                        |t| tris[t],
                        |t| (t[0] >> shift) as usize,
                        |b| sort_by_first(b, shift),
                        &mut out,
                        &Meter::default(),
                    )
                });
                assert_eq!(out, want, "{n} vertices, {threads} threads");
            }
        }
    }
}
