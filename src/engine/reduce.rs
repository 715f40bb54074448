//! Deterministic parallel work over arrays: fixed-size chunks of [`CHUNK`] items, mapped on the
//! current rayon pool, their results combined in chunk order. The chunking, not the thread count,
//! decides every rounding, so each result is bit-identical for any number of threads. Every
//! parallel sum of the engine (its statistics included), the multiresolution mode and the cluster
//! engine goes through here.

use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;

use crate::metrics;
use crate::smooth::laplacian::StepStats;
use crate::topology::Topology;

/// Items per work unit.
pub const CHUNK: usize = 1 << 14;

/// `f(first, chunk)` on each chunk of `items` (`first`: the index of the chunk's first item).
pub fn for_chunks_mut<T: Send>(items: &mut [T], f: impl Fn(usize, &mut [T]) + Sync) {
    items
        .par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, chunk)| f(c * CHUNK, chunk));
}

/// `map(first, chunk)` on each chunk of `items`, folded in chunk order from `init`.
pub fn map_fold<T: Sync, R: Send>(
    items: &[T],
    map: impl Fn(usize, &[T]) -> R + Sync,
    init: R,
    fold: impl Fn(R, R) -> R,
) -> R {
    let parts: Vec<R> = items
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| map(c * CHUNK, chunk))
        .collect();
    parts.into_iter().fold(init, fold)
}

/// `map(first, chunk)` on each chunk of `out`, writing it, and the results folded in chunk order.
pub fn map_fold_mut<T: Send, R: Send>(
    out: &mut [T],
    map: impl Fn(usize, &mut [T]) -> R + Sync,
    init: R,
    fold: impl Fn(R, R) -> R,
) -> R {
    let parts: Vec<R> = out
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, chunk)| map(c * CHUNK, chunk))
        .collect();
    parts.into_iter().fold(init, fold)
}

/// Signed volume about `origin` and area of `tris` ([`metrics::volume_about`], [`metrics::area`]).
pub fn volume_area(pos: &[DVec3], tris: &[[u32; 3]], origin: DVec3) -> (f64, f64) {
    let (v, a) = map_fold(
        tris,
        |_, chunk| metrics::determinant_and_area_sums(pos, chunk, origin),
        (-0.0, -0.0),
        |(v, a), (pv, pa)| (v + pv, a + pa),
    );
    (v / 6.0, a / 2.0)
}

/// [`metrics::geometry`] over chunks: volume and area over chunks of triangles, about the
/// centroid summed over chunks of vertices; the extent, and the edges by their smaller vertex
/// (in ascending `(i, j)` order within a chunk), over chunks of vertices.
pub fn geometry(pos: &[DVec3], tris: &[[u32; 3]], topo: &Topology) -> metrics::Geometry {
    let (volume, area) = volume_area(pos, tris, centroid(pos));
    let extent = map_fold(
        pos,
        |_, chunk| metrics::extent(chunk),
        metrics::extent(&[]),
        metrics::extent_union,
    );
    let edges = map_fold(
        pos,
        |first, chunk| {
            let vertices = first as u32..(first + chunk.len()) as u32;
            metrics::edge_sums(pos, tris, topo, vertices)
        },
        metrics::EdgeSums::default(),
        |a, b| a + b,
    );
    metrics::Geometry {
        volume,
        area,
        extent,
        edges,
    }
}

/// Signed volume about `origin` ([`metrics::volume_about`]).
pub fn volume(pos: &[DVec3], tris: &[[u32; 3]], origin: DVec3) -> f64 {
    map_fold(
        tris,
        |_, chunk| metrics::determinant_sum(pos, chunk, origin),
        -0.0,
        |s, x| s + x,
    ) / 6.0
}

/// Mean position (zero for none), [`metrics::centroid`] summed over chunks.
pub fn centroid(pos: &[DVec3]) -> DVec3 {
    if pos.is_empty() {
        return DVec3::ZERO;
    }
    position_sum(pos) / pos.len() as f64
}

/// Sum of the positions (ranks add theirs before dividing by the count).
pub fn position_sum(pos: &[DVec3]) -> DVec3 {
    map_fold(
        pos,
        |_, chunk| metrics::position_sum(chunk),
        DVec3::ZERO,
        |s, p| s + p,
    )
}

/// Largest and summed distance between `a` and `b`, vertex by vertex.
pub fn displacement(a: &[DVec3], b: &[DVec3]) -> StepStats {
    let (max, sum) = map_fold(
        a,
        |first, x| {
            let y = &b[first..first + x.len()];
            x.iter().zip(y).fold((0.0f64, 0.0), |(m, s), (p, q)| {
                let d = p.distance(*q);
                (m.max(d), s + d)
            })
        },
        (0.0f64, 0.0),
        |(m, s), (pm, ps)| (m.max(pm), s + ps),
    );
    StepStats {
        moved: 0,
        max_displacement: max,
        sum_displacement: sum,
    }
}

/// Neighbour sums `S(v) = Σ_{u∈N(v)} p_u` of the vertices `range`, into `sums[range]`.
pub fn neighbor_sums(topo: &Topology, pos: &[DVec3], sums: &mut [DVec3], range: Range<usize>) {
    let first = range.start;
    for_chunks_mut(&mut sums[range], |at, out| {
        crate::smooth::neighbor_sums_into(topo, pos, out, first + at)
    });
}
