//! One level of the hierarchy: out-of-core vertex clustering with quadric (QEM) placement.
//!
//! Why clustering and not Lindstrom–Turk edge collapse: a collapse sequence needs a global priority
//! queue and random access to a mutating mesh, which does not stream; clustering is one pass of
//! sort keys and one pass over each cluster's faces, so it runs on the memory-mapped arrays of the
//! patch engine at any size, in parallel, with a result independent of the thread count. Quadric
//! placement (each representative minimises the summed squared distances to the planes of its
//! cluster's faces) keeps the representatives on the surface, so edges and corners are not cut off
//! as with the cluster mean; the volume that remains lost is restored afterwards for the whole
//! level ([`super::transfer::restore_volume`]), which is what makes the simplification
//! volume-preserving, as Lindstrom–Turk's is by construction.
//!
//! Cells are cubes of a grid anchored at the bounding box's minimum; cluster ids follow the Morton
//! order of the cells, so a coarse level is already nearly in the engine's order.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

use crate::engine::reduce;
use crate::error::{Error, Result};
use crate::mesh::{Buf, Storage};
use crate::partition::morton3;
use crate::topology::Topology;

/// A coarse level and how the finer level maps onto it.
#[derive(Debug)]
pub struct Clustered {
    /// One representative per non-empty cell, in cell (Morton) order.
    pub positions: Buf<DVec3>,
    /// Triangles of the finer level whose corners fall into three distinct cells, renumbered,
    /// without duplicates; a pair of opposite orientations on the same three cells cancels out.
    pub triangles: Buf<[u32; 3]>,
    /// `map[v]`: the cluster of fine vertex `v`.
    pub map: Buf<u32>,
}

/// Cluster `pos` (with its `triangles` and topology) into cubes of edge `cell`.
///
/// Deterministic: keys are unique `(cell, vertex)` pairs, each cluster's quadric is summed over its
/// vertices and their faces in ascending order.
pub fn cluster(
    storage: &Storage,
    pos: &[DVec3],
    triangles: &[[u32; 3]],
    topo: &Topology,
    cell: f64,
) -> Result<Clustered> {
    let n = pos.len();
    if !(cell.is_finite() && cell > 0.0) {
        return Err(Error::parameter(
            "cell",
            format!("must be a finite length > 0, got {cell}"),
        ));
    }
    let (lo, hi) = pos
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    // At most 2^21 cells per axis (the Morton key's range): coarser cells for extreme ratios.
    let extent = if n == 0 { 0.0 } else { (hi - lo).max_element() };
    let cell = cell.max(extent / ((1u64 << 21) - 2) as f64);

    let mut keys: Buf<[u64; 2]> = storage.zeroed(n)?;
    keys.par_iter_mut().enumerate().for_each(|(v, k)| {
        let q = ((pos[v] - lo) / cell).floor().as_u64vec3();
        *k = [morton3(q.x, q.y, q.z), v as u64];
    });
    keys.par_sort_unstable();

    // Cluster ids in key order; `starts[c]..starts[c + 1]` are cluster c's entries in `keys`.
    let mut map: Buf<u32> = storage.zeroed(n)?;
    let mut clusters = 0usize;
    for (i, k) in keys.iter().enumerate() {
        if i == 0 || k[0] != keys[i - 1][0] {
            clusters += 1;
        }
        map[k[1] as usize] = (clusters - 1) as u32;
    }
    let mut starts: Buf<u32> = storage.zeroed(clusters + 1)?;
    let mut c = 0;
    for (i, k) in keys.iter().enumerate() {
        if i == 0 || k[0] != keys[i - 1][0] {
            starts[c] = i as u32;
            c += 1;
        }
    }
    starts[clusters] = n as u32;

    let mut positions: Buf<DVec3> = storage.zeroed(clusters)?;
    reduce::for_chunks_mut(&mut positions, |first, out| {
        for (k, p) in out.iter_mut().enumerate() {
            let c = first + k;
            let members = &keys[starts[c] as usize..starts[c + 1] as usize];
            *p = place(members, pos, triangles, topo, &map, c as u32);
        }
    });
    drop(keys);
    drop(starts);

    let triangles = coarse_triangles(storage, triangles, &map)?;
    Ok(Clustered {
        positions,
        triangles,
        map,
    })
}

/// Regularisation of the quadric towards the cluster mean, relative to the quadric's trace: enough
/// to pin the tangential position of a flat cluster, too little to pull a crease or corner off.
const QEM_REGULARISATION: f64 = 1e-3;

/// The representative of one cluster: the minimiser of the area-weighted plane quadric of the
/// faces around its `members`, relative to their mean (the mean alone if the faces are degenerate).
fn place(
    members: &[[u64; 2]],
    pos: &[DVec3],
    triangles: &[[u32; 3]],
    topo: &Topology,
    map: &[u32],
    c: u32,
) -> DVec3 {
    let mean = members
        .iter()
        .fold(DVec3::ZERO, |s, k| s + pos[k[1] as usize])
        / members.len() as f64;
    let (mut a, mut b) = (DMat3::ZERO, DVec3::ZERO);
    for k in members {
        let v = k[1] as u32;
        for f in topo.faces_of(v, triangles) {
            let t = triangles[f as usize];
            // Count each face once per cluster: at its first corner inside the cluster.
            let first = t.iter().position(|&u| map[u as usize] == c);
            if first.map(|i| t[i]) != Some(v) {
                continue;
            }
            let [p, q, r] = t.map(|u| pos[u as usize] - mean);
            let n = (q - p).cross(r - p);
            let len = n.length();
            if len == 0.0 {
                continue;
            }
            // Plane n·y = n·p weighted by area: (n nᵀ)/|n| is 2·area × (unit normal)(unit normal)ᵀ.
            let w = 1.0 / len;
            a += DMat3::from_cols(n * n.x * w, n * n.y * w, n * n.z * w);
            b += n * (n.dot(p) * w);
        }
    }
    let trace = a.x_axis.x + a.y_axis.y + a.z_axis.z;
    if !(trace > 0.0 && trace.is_finite()) {
        return mean;
    }
    let reg = a + DMat3::from_diagonal(DVec3::splat(QEM_REGULARISATION * trace));
    let det = reg.determinant();
    if det.abs() <= 1e-300 || det.is_nan() {
        return mean;
    }
    let y = reg.inverse() * b;
    if y.is_finite() { mean + y } else { mean }
}

/// The fine triangles mapped to clusters: degenerate ones dropped, rotated to start at their
/// smallest id, sorted; duplicates kept once and opposite-orientation pairs cancelled.
fn coarse_triangles(
    storage: &Storage,
    triangles: &[[u32; 3]],
    map: &[u32],
) -> Result<Buf<[u32; 3]>> {
    let mapped = |t: &[u32; 3]| t.map(|v| map[v as usize]);
    let distinct = |t: [u32; 3]| t[0] != t[1] && t[1] != t[2] && t[0] != t[2];
    let count = triangles.par_iter().filter(|t| distinct(mapped(t))).count();
    let mut out: Buf<[u32; 3]> = storage.zeroed(count)?;
    let mut k = 0;
    for t in triangles.iter() {
        let m = mapped(t);
        if distinct(m) {
            let first = (0..3).min_by_key(|&i| m[i]).unwrap_or(0);
            out[k] = [m[first], m[(first + 1) % 3], m[(first + 2) % 3]];
            k += 1;
        }
    }
    // Sorting by (smallest, other two sorted, orientation) groups the copies of one vertex set.
    let set = |t: &[u32; 3]| (t[0], t[1].min(t[2]), t[1].max(t[2]));
    out.par_sort_unstable_by_key(|t| (set(t), t[1] > t[2]));
    let mut kept = 0;
    let mut i = 0;
    while i < out.len() {
        let (a, b, c) = set(&out[i]);
        let mut j = i;
        let mut balance = 0i64;
        while j < out.len() && set(&out[j]) == (a, b, c) {
            balance += if out[j][1] > out[j][2] { -1 } else { 1 };
            j += 1;
        }
        if balance != 0 {
            out[kept] = if balance > 0 { [a, b, c] } else { [a, c, b] };
            kept += 1;
        }
        i = j;
    }
    out.truncate(kept);
    Ok(out)
}
