//! Taubin's λ|μ pair as one cache-blocked pass over the mesh.
//!
//! Done as two full Jacobi steps, an iteration of `taubin` streams the positions, the adjacency and
//! the intermediate positions through memory twice; on a mesh larger than the caches the second
//! step runs at about half the speed it reaches in cache. Here the vertices are cut into blocks of
//! [`BLOCK`] consecutive (Morton-ordered) vertices and the μ step of a block runs as soon as the λ
//! step has produced every intermediate position it reads, while those and the block's adjacency
//! are still in cache.
//!
//! The pair goes `a` → `b` (λ) → `c` (μ) through three buffers, so that no λ step ever reads a
//! position a μ step has already replaced. The blocks are split into one contiguous band per
//! thread; a band runs its λ steps in order, and after the λ step of block `k` the μ steps of the
//! blocks whose neighbours all lie in the band and in blocks `≤ k` (its *ready list*). A block
//! with a neighbour in another band is *deferred*: its μ step runs after every λ step, in a second
//! parallel pass. Every output is a pure function of `a`, so the result is bit-identical to two
//! [`crate::smooth::laplacian::jacobi_step`]s, for any number of bands or threads; the statistics
//! are summed per block in block order, so they do not depend on the thread count either.

use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;

use crate::smooth::laplacian::{self, Previous, StepStats};
use crate::topology::Topology;

/// Vertices per block. In Morton order half the blocks of a large mesh have a neighbour 15 or more
/// blocks of 4096 vertices ahead, so a block's μ step waits for many λ steps; smaller blocks keep
/// less waiting data (callgrind's cache simulation, 10 taubin iterations of a 327,680-triangle
/// sphere with a 2 MiB last-level cache: 2.06M last-level read misses in the μ steps with blocks
/// of 4096 vertices, 1.28M with 1024; the unfused μ step had 1.46M plus 1.23M for the separate
/// displacement pass).
pub const BLOCK: usize = 1024;

/// The schedule of a fused pair for one topology and one band count.
#[derive(Debug, Clone)]
pub struct PairPlan {
    vertices: usize,
    bands: Vec<Band>,
    /// One flag per block: its μ step runs in the second pass.
    deferred: Vec<bool>,
}

#[derive(Debug, Clone)]
struct Band {
    blocks: Range<usize>,
    /// The ready list of the band's `k`-th block is `ready[ready_at[k]..ready_at[k + 1]]`.
    ready_at: Vec<u32>,
    ready: Vec<u32>,
}

impl PairPlan {
    /// Plan the fused pair on `topo` for `bands` bands (≥ 1; usually the number of threads).
    pub fn new(topo: &Topology, bands: usize) -> PairPlan {
        let n = topo.len();
        let blocks = n.div_ceil(BLOCK);
        let (offsets, vv) = topo.csr();
        // The lowest and highest block that each block's vertices and their neighbours fall in.
        let reach: Vec<(usize, usize)> = (0..blocks)
            .into_par_iter()
            .map(|b| {
                let (lo, hi) = (b * BLOCK, ((b + 1) * BLOCK).min(n));
                let nbrs = &vv[offsets[lo]..offsets[hi]];
                let (min, max) = nbrs.iter().fold((lo, hi - 1), |(a, z), &u| {
                    (a.min(u as usize), z.max(u as usize))
                });
                (min / BLOCK, max / BLOCK)
            })
            .collect();
        let count = bands.clamp(1, blocks.max(1));
        let mut deferred = vec![false; blocks];
        let bands = (0..count)
            .map(|k| {
                let range = k * blocks / count..(k + 1) * blocks / count;
                // Counting sort of the band's local blocks by the block after whose λ step they
                // are ready (block order within a list, so a list runs in ascending order).
                let mut ready_at = vec![0u32; range.len() + 1];
                let mut local = Vec::with_capacity(range.len());
                for i in range.clone() {
                    let (lo, hi) = reach[i];
                    if lo >= range.start && hi < range.end {
                        let at = hi.max(i) - range.start;
                        ready_at[at + 1] += 1;
                        local.push((at, i as u32));
                    } else {
                        deferred[i] = true;
                    }
                }
                for k in 0..range.len() {
                    ready_at[k + 1] += ready_at[k];
                }
                let mut cursor = ready_at.clone();
                let mut ready = vec![0u32; local.len()];
                for (at, i) in local {
                    ready[cursor[at] as usize] = i;
                    cursor[at] += 1;
                }
                Band {
                    blocks: range,
                    ready_at,
                    ready,
                }
            })
            .collect();
        PairPlan {
            vertices: n,
            bands,
            deferred,
        }
    }

    /// Blocks whose μ step waits for the second pass (for tests and tuning).
    pub fn deferred_blocks(&self) -> usize {
        self.deferred.iter().filter(|&&d| d).count()
    }

    fn block(&self, b: usize) -> Range<usize> {
        b * BLOCK..((b + 1) * BLOCK).min(self.vertices)
    }
}

/// One λ|μ pair: `b = a + λ L(a)`, then `c = b + μ L(b)`, on the current rayon pool. Returns the
/// vertices moved by the two steps together, and how far each vertex moved from `a` to `c`.
///
/// # Panics
/// If the slices do not all have `topo.len()` entries, or the plan was made for another topology.
pub fn pair(
    plan: &PairPlan,
    topo: &Topology,
    a: &[DVec3],
    b: &mut [DVec3],
    c: &mut [DVec3],
    lambda: f64,
    mu: f64,
) -> (u64, StepStats) {
    let n = topo.len();
    assert!(a.len() == n && b.len() == n && c.len() == n && plan.vertices == n);
    let mut per_block = vec![StepStats::default(); plan.deferred.len()];

    // First pass: the bands in parallel, each on its own part of `b` and `c`.
    let mut work = Vec::with_capacity(plan.bands.len());
    let (mut b_rest, mut c_rest) = (&mut *b, &mut *c);
    for band in &plan.bands {
        let len = band.blocks.len() * BLOCK;
        let len = len.min(b_rest.len());
        let (bb, bt) = b_rest.split_at_mut(len);
        let (cb, ct) = c_rest.split_at_mut(len);
        (b_rest, c_rest) = (bt, ct);
        work.push((band, bb, cb));
    }
    let first: Vec<(u64, Vec<(u32, StepStats)>)> = work
        .into_par_iter()
        .map(|(band, bb, cb)| {
            let base = band.blocks.start * BLOCK;
            let mut moved = 0;
            let mut done = Vec::with_capacity(band.ready.len());
            for (k, blk) in band.blocks.clone().enumerate() {
                let r = plan.block(blk);
                let out = &mut bb[r.start - base..r.end - base];
                moved += laplacian::jacobi_step(topo, a, out, r.start, lambda);
                let ready = &band.ready[band.ready_at[k] as usize..band.ready_at[k + 1] as usize];
                for &i in ready {
                    let r = plan.block(i as usize);
                    let out = &mut cb[r.start - base..r.end - base];
                    let old = Previous::Slice(&a[r.clone()]);
                    let st = laplacian::jacobi_step_window(topo, bb, base, out, r.start, mu, old);
                    done.push((i, st));
                }
            }
            (moved, done)
        })
        .collect();

    // Second pass: the deferred μ steps, every λ step being done.
    let b: &[DVec3] = b;
    let second: Vec<(usize, StepStats)> = c
        .par_chunks_mut(BLOCK)
        .enumerate()
        .filter(|(i, _)| plan.deferred[*i])
        .map(|(i, out)| {
            let r = plan.block(i);
            let old = Previous::Slice(&a[r.clone()]);
            (
                i,
                laplacian::jacobi_step_measured(topo, b, out, r.start, mu, old),
            )
        })
        .collect();

    let mut moved = 0;
    for (m, done) in first {
        moved += m;
        for (i, st) in done {
            per_block[i as usize] = st;
        }
    }
    for (i, st) in second {
        per_block[i] = st;
    }
    let total = per_block
        .into_iter()
        .fold(StepStats::default(), StepStats::then);
    (moved + total.moved, total)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate;

    #[test]
    fn fused_pair_equals_two_plain_steps_for_any_band_count() {
        // Big enough for several blocks, with a random vertex order so that blocks reach far.
        let mut mesh = generate::icosphere(5);
        generate::add_normal_noise(&mut mesh, 0.3, 4);
        let n = mesh.positions.len();
        let perm: Vec<u32> = {
            let mut p: Vec<u32> = (0..n as u32).collect();
            let mut x = 0x9e37_79b9_7f4a_7c15u64;
            for i in (1..n).rev() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                p.swap(i, (x % (i as u64 + 1)) as usize);
            }
            p
        };
        let mut pos = vec![DVec3::ZERO; n];
        for (old, &new) in perm.iter().enumerate() {
            pos[new as usize] = mesh.positions[old];
        }
        let mut tris: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| perm[v as usize]))
            .collect();
        // An open hole, so that some vertices are fixed.
        tris.truncate(tris.len() - 3);
        let topo = Topology::build(n, &tris).unwrap();
        assert!(topo.stats.fixed_vertices > 0 && n > 2 * BLOCK);

        let (lambda, mu) = (0.5, -0.53);
        let mut mid = vec![DVec3::ZERO; n];
        let mut want = vec![DVec3::ZERO; n];
        let m1 = laplacian::jacobi_step(&topo, &pos, &mut mid, 0, lambda);
        let st =
            laplacian::jacobi_step_measured(&topo, &mid, &mut want, 0, mu, Previous::Slice(&pos));
        let mut reference = None;
        for bands in [1, 2, 3, 7] {
            let plan = PairPlan::new(&topo, bands);
            if bands > 1 {
                assert!(plan.deferred_blocks() > 0);
            }
            let (mut b, mut c) = (vec![DVec3::ZERO; n], vec![DVec3::ZERO; n]);
            let (moved, fs) = pair(&plan, &topo, &pos, &mut b, &mut c, lambda, mu);
            assert_eq!(b, mid, "{bands} bands");
            assert_eq!(c, want, "{bands} bands");
            assert_eq!(moved, m1 + st.moved);
            assert_eq!(fs.max_displacement, st.max_displacement);
            assert!(
                (fs.sum_displacement - st.sum_displacement).abs() <= 1e-12 * st.sum_displacement
            );
            // The statistics do not depend on the band count.
            assert_eq!(*reference.get_or_insert(fs), fs);
        }
    }
}
