//! Which patches may run at the same time, and in what order.
//!
//! A stencil with free vertices F reads positions and neighbour sums of F ∪ N(F) (and, for the
//! Laplacians, their neighbours' positions through the sums), and writes positions of F and sums of
//! N(F). Two stencils whose free vertices are 3 or more rings apart therefore touch disjoint data.
//! A patch's free vertices lie within one ring of its owned range, so two patches whose owned
//! ranges are more than 4 rings apart never conflict; closer ones are joined in the conflict graph.
//! A patch takes the neighbour sums it reads afresh from the positions when it starts
//! ([`crate::smooth::rebuild_patch_sums`]: its vertices and two rings around them, reading
//! positions three rings out), which the same 4 rings keep apart from any other patch of its
//! colour (3 + 1 < 5).
//!
//! **The order of work streams through the mesh.** The patches, in Morton order, are cut into
//! [`LANES`] lanes of `n = ⌈patches / LANES⌉` consecutive patches; step `s` (0 ≤ s < n) takes the
//! `s`-th patch of every lane: patches `s, s + n, s + 2n, …`. The steps run one after another;
//! inside a step its patches are coloured on their own conflict graph with DSatur (petgraph), the
//! colours run one after another in ascending colour number, and the patches of one colour run in
//! parallel. Because they touch disjoint data, the result equals running them one by one in the
//! order (step, colour, patch), whatever the thread count. Each step moves every lane on by one
//! patch, so an iteration passes over the scratch of each lane once, in Morton order, with the
//! step's pages (and its neighbours', which the next step reads) the only ones in use: that is what
//! keeps a mesh past the page cache from reading its scratch again for every colour. A mesh of at
//! most [`LANES`] patches is one step, coloured whole. The cluster's ranks own contiguous blocks of
//! patches, so every rank has patches in every step.
//!
//! The boundary stencils of `boundary: smooth` ([`crate::smooth::boundary`]) write what an edge
//! stencil writes and read positions one ring further (two steps along their loop, within 2 rings
//! of their free vertices, so within 3 of the patch): against another patch's position writes (1
//! ring out) that is the same 4 rings, so they share the edge colouring.
//!
//! `vcs-guided` has wider stencils and gets its own colouring ([`Schedule::ring_colours`], in the
//! same steps): the stencil of an owned vertex v writes the positions of its 2-ring `F_v` and reads
//! the corners of the faces touching `F_v`, i.e. the 3-ring of v (its step-1 shares are computed
//! before the sweep and only read; it keeps no neighbour sums). A patch therefore writes within 2
//! rings of its owned range and reads within 3 (halo 3), and two patches can only meet when their
//! owned ranges are at most 2 + 3 = 5 rings apart: the same rule with 5 conflict rings instead of
//! 4. Both colourings come from one breadth-first walk of 5 rings per patch.

use petgraph::graph::UnGraph;
use rayon::prelude::*;

use crate::error::Result;
use crate::mesh::storage::Advisor;
use crate::mesh::{Buf, Storage};
use crate::meter::Meter;
use crate::partition::Patch;
use crate::topology::{Topology, rings_outside};

/// Rings around a patch's owned range within which another patch's owned vertices conflict.
const CONFLICT_RINGS: usize = 4;
/// Rings of halo a patch reads outside its owned range (F ∪ N(F) with F one ring out).
const HALO_RINGS: usize = 2;
/// The same two for the 2-ring stencils of `vcs-guided` (see the module doc).
const RING_CONFLICT_RINGS: usize = 5;
const RING_HALO_RINGS: usize = 3;
/// Lanes of the streaming order (see the module doc): the patches of one step. Part of the
/// results: another count is another order of work.
pub const LANES: usize = 128;

/// The colouring of the patches.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Schedule {
    /// Patch indices of each colour, ascending; the colours of every step, steps and colours in
    /// execution order (edge and triangle stencils).
    pub colours: Vec<Vec<u32>>,
    /// Per patch: vertices outside its owned range that its stencils read.
    pub halo: Vec<u32>,
    /// The colouring for the 2-ring stencils of `vcs-guided`, in the same form.
    pub ring_colours: Vec<Vec<u32>>,
    /// Per patch: vertices outside its owned range that its 2-ring stencils read (3 rings).
    pub ring_halo: Vec<u32>,
}

impl Schedule {
    /// One patch in one colour (a plan that does not cut the mesh).
    pub fn single() -> Schedule {
        Schedule {
            colours: vec![vec![0]],
            halo: vec![0],
            ring_colours: vec![vec![0]],
            ring_halo: vec![0],
        }
    }
}

/// Patches near each patch (higher indices only) and its halo, for one conflict radius.
struct Near {
    others: Vec<u32>,
    halo: u32,
}

/// Colour the conflict graph of `patches` on `topo` (runs on the current rayon pool; the result
/// does not depend on the thread count).
pub fn schedule(topo: &Topology, patches: &[Patch]) -> Schedule {
    schedule_metered(topo, patches, &Meter::default())
}

/// Patches [`schedule_metered`] counts per patch: its neighbourhood, then each of the two
/// colourings (counted whole when it ends).
pub const SCHEDULE_PASSES: u64 = 3;

/// [`schedule`], counting its work into `meter` ([`SCHEDULE_PASSES`] per patch). The same
/// schedule.
pub fn schedule_metered(topo: &Topology, patches: &[Patch], meter: &Meter) -> Schedule {
    let patch_size = patches.first().map_or(1, |p| p.vertices.len().max(1)) as u32;
    let owner = |v: u32| v / patch_size;
    let near: Vec<[Near; 2]> = patches
        .par_iter()
        .enumerate()
        .map(|(a, p)| {
            let rings = rings_outside(topo, &p.vertices, RING_CONFLICT_RINGS);
            let within = |conflict: usize, halo: usize| {
                let halo = rings.iter().take(halo).map(|r| r.len() as u32).sum();
                // A patch has a handful of near patches: gathered as found, so that what each
                // patch keeps is that handful, not one entry per vertex of its rings.
                let mut others: Vec<u32> = Vec::new();
                for &v in rings.iter().take(conflict).flatten() {
                    let b = owner(v);
                    if b as usize > a && !others.contains(&b) {
                        others.push(b);
                    }
                }
                others.sort_unstable();
                Near { others, halo }
            };
            let near = [
                within(CONFLICT_RINGS, HALO_RINGS),
                within(RING_CONFLICT_RINGS, RING_HALO_RINGS),
            ];
            meter.add(1);
            near
        })
        .collect();
    let steps = steps(patches.len());
    let (colours, halo) = colour(near.iter().map(|n| &n[0]), steps);
    meter.add(patches.len() as u64);
    let (ring_colours, ring_halo) = colour(near.iter().map(|n| &n[1]), steps);
    meter.add(patches.len() as u64);
    Schedule {
        colours,
        halo,
        ring_colours,
        ring_halo,
    }
}

/// Steps of the streaming order of `patches` patches: the length of a lane (see the module doc).
pub fn steps(patches: usize) -> usize {
    patches.div_ceil(LANES).max(1)
}

/// The colours of the patches given by each one's near patches, step by step (`steps` of them:
/// patch `p` is in step `p % steps`), each step's conflict graph coloured with DSatur; and the
/// halos.
fn colour<'a>(near: impl Iterator<Item = &'a Near>, steps: usize) -> (Vec<Vec<u32>>, Vec<u32>) {
    let near: Vec<&Near> = near.collect();
    let mut colours = Vec::new();
    for step in 0..steps {
        let members: Vec<u32> = (step..near.len())
            .step_by(steps)
            .map(|p| p as u32)
            .collect();
        let mut graph = UnGraph::<(), ()>::with_capacity(members.len(), 0);
        let nodes: Vec<_> = members.iter().map(|_| graph.add_node(())).collect();
        let node_of = |p: u32| nodes[(p as usize - step) / steps];
        for &a in &members {
            for &b in &near[a as usize].others {
                if b as usize % steps == step {
                    graph.add_edge(node_of(a), node_of(b), ());
                }
            }
        }
        let (colouring, count) = petgraph::algo::dsatur_coloring(&graph);
        let mut mine = vec![Vec::new(); count];
        for (&p, node) in members.iter().zip(&nodes) {
            mine[colouring[node]].push(p);
        }
        colours.extend(mine.into_iter().filter(|c| !c.is_empty()));
    }
    (colours, near.iter().map(|n| n.halo).collect())
}

/// Each patch's rings: the vertices outside it within [`RING_HALO_RINGS`] of it, ascending, the
/// patches' one after another in an array of the plan's storage. What a patch's sweep reads of
/// other patches' arrays (3 rings for every method's stencils: see the module doc), scattered over
/// them: out of core the read-ahead asks for their pages with the patch's own ranges.
pub struct PatchRings {
    starts: Vec<usize>,
    vertices: Buf<u32>,
}

impl PatchRings {
    /// The rings of `patches`, whose sizes `schedule` counted (its `ring_halo`).
    pub fn of(
        topo: &Topology,
        patches: &[Patch],
        schedule: &Schedule,
        storage: &Storage,
    ) -> Result<PatchRings> {
        let sizes: Vec<usize> = (0..patches.len())
            .map(|p| schedule.ring_halo.get(p).copied().unwrap_or(0) as usize)
            .collect();
        let starts: Vec<usize> = std::iter::once(0)
            .chain(sizes.iter().scan(0, |end, &size| {
                *end += size;
                Some(*end)
            }))
            .collect();
        let mut vertices: Buf<u32> = storage.zeroed(starts[patches.len()])?;
        let slices = crate::topology::split_lens(&mut vertices, &sizes);
        patches.par_iter().zip(slices).for_each(|(patch, out)| {
            let mut rings = rings_outside(topo, &patch.vertices, RING_HALO_RINGS).concat();
            rings.sort_unstable();
            // The schedule counted these rings; another count (a schedule not of this
            // topology) leaves the patch without them: they are only advice.
            if rings.len() == out.len() {
                out.copy_from_slice(&rings);
            }
        });
        Ok(PatchRings { starts, vertices })
    }

    /// The rings of patch `p`, ascending.
    pub fn of_patch(&self, p: usize) -> &[u32] {
        &self.vertices[self.starts[p]..self.starts[p + 1]]
    }
}

/// The bounded read-ahead pipeline of out-of-core runs: while the patches of one colour are
/// smoothed, a prefetch thread receives the patches of the colours after it (about one step of
/// the streaming order) over a bounded channel and asks the kernel to read their pages ahead
/// (positions, neighbour sums, adjacency, triangles), and those of their rings. It only gives
/// advice, so it never changes a result; when the queue is full, hints are dropped rather than
/// stalling the sweep. On the heap there is nothing to prefetch and no thread is started.
pub struct Prefetch {
    tx: Option<crossbeam_channel::Sender<u32>>,
}

impl Prefetch {
    /// A prefetch that does nothing (in-core runs).
    pub fn none() -> Prefetch {
        Prefetch { tx: None }
    }

    /// Hint that patch `p`'s vertices, triangles and rings will be needed soon.
    pub fn hint(&self, p: u32) {
        if let Some(tx) = &self.tx {
            let _ = tx.try_send(p);
        }
    }
}

/// Hints the queue of [`with_prefetch`] holds: two steps' patches.
pub const PREFETCH_QUEUE: usize = 2 * LANES;

/// What the read-ahead of [`with_prefetch`] advises.
pub struct ReadAhead<'a> {
    pub topo: &'a Topology,
    pub patches: &'a [Patch],
    /// The patches' rings, whose pages are asked for with the patch's own.
    pub rings: Option<&'a PatchRings>,
    /// Per-vertex arrays (positions and sums of a mapped run).
    pub vertices: Vec<Advisor>,
    /// The triangles.
    pub triangles: Option<Advisor>,
}

/// Run `f` with a prefetch pipeline for `ahead`; without per-vertex advisors, `f` gets
/// [`Prefetch::none`].
pub fn with_prefetch<R>(ahead: ReadAhead, f: impl FnOnce(&Prefetch) -> R) -> R {
    if ahead.vertices.is_empty() {
        return f(&Prefetch::none());
    }
    let (tx, rx) = crossbeam_channel::bounded::<u32>(PREFETCH_QUEUE);
    std::thread::scope(|scope| {
        scope.spawn(move || {
            for p in rx {
                let patch = &ahead.patches[p as usize];
                let v = &patch.vertices;
                ahead.topo.will_need(v.clone());
                for a in &ahead.vertices {
                    a.will_need(v.start as usize..v.end as usize);
                }
                if let Some(a) = &ahead.triangles {
                    let t = &patch.triangles;
                    a.will_need(t.start as usize..t.end as usize);
                }
                if let Some(rings) = ahead.rings {
                    let ring = rings.of_patch(p as usize);
                    for a in &ahead.vertices {
                        a.will_need_each(ring.iter().map(|&v| v as usize..v as usize + 1));
                    }
                    ahead
                        .topo
                        .will_need_scattered(ring, ahead.triangles.as_ref());
                }
            }
        });
        let prefetch = Prefetch { tx: Some(tx) };
        let result = f(&prefetch);
        drop(prefetch); // closes the channel, so the prefetch thread ends
        result
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::partition;

    /// A strip of 2 × n vertices (triangulated ladder), so ring distance is easy to reason about.
    fn ladder(n: u32) -> Vec<[u32; 3]> {
        (0..n - 1)
            .flat_map(|k| {
                [
                    [2 * k, 2 * k + 1, 2 * k + 2],
                    [2 * k + 1, 2 * k + 3, 2 * k + 2],
                ]
            })
            .collect()
    }

    /// Each ring holds exactly the vertices at that graph distance from the patch (a plain
    /// breadth-first search of distances over the whole mesh), on a sphere whose Morton patches
    /// have ragged borders, and on the patch of the whole mesh (no ring).
    /// An icosphere's triangles smallest corner first and sorted, as the plan orders them, its
    /// vertex count and topology.
    fn sorted_sphere() -> (Vec<[u32; 3]>, usize, Topology) {
        let m = crate::shapes::icosphere(4);
        let mut tris = m.triangles.to_vec();
        tris.iter_mut().for_each(|t| t.sort_unstable());
        tris.sort_unstable();
        let n = m.positions.len();
        let topo = Topology::build(n, &tris).unwrap();
        (tris, n, topo)
    }

    #[test]
    fn rings_are_the_vertices_at_each_distance_from_the_patch() {
        let (tris, n, topo) = sorted_sphere();
        let mut ps = partition::patches(n, &tris, 97);
        ps.push(Patch {
            vertices: 0..n as u32,
            triangles: 0..tris.len() as u32,
        });
        for p in &ps {
            let mut dist = vec![usize::MAX; n];
            let mut front: Vec<u32> = p.vertices.clone().collect();
            front.iter().for_each(|&v| dist[v as usize] = 0);
            for d in 1..=RING_CONFLICT_RINGS {
                let mut next = Vec::new();
                for &v in &front {
                    for &u in topo.neighbors(v) {
                        if dist[u as usize] == usize::MAX {
                            dist[u as usize] = d;
                            next.push(u);
                        }
                    }
                }
                front = next;
            }
            let rings = rings_outside(&topo, &p.vertices, RING_CONFLICT_RINGS);
            assert_eq!(rings.len(), RING_CONFLICT_RINGS);
            for (k, ring) in rings.iter().enumerate() {
                let want: Vec<u32> = (0..n as u32)
                    .filter(|&v| dist[v as usize] == k + 1)
                    .collect();
                let mut ring = ring.clone();
                ring.sort_unstable();
                assert_eq!(ring, want, "patch {:?}, ring {}", p.vertices, k + 1);
            }
            let crossing = p
                .edges(&topo)
                .filter(|[_, j]| !p.vertices.contains(j))
                .count() as u64;
            assert_eq!(p.crossing_edges(&topo), crossing);
        }
        assert!(ps.len() > 20 && ps.iter().any(|p| p.crossing_edges(&topo) > 0));
    }

    /// Each patch's stored rings are its 3 rings ascending, on the heap and in scratch, and a
    /// schedule of another mesh leaves a patch without rings rather than with wrong ones.
    #[test]
    fn patch_rings_hold_each_patchs_three_rings_ascending() {
        let (tris, n, topo) = sorted_sphere();
        let ps = partition::patches(n, &tris, 97);
        let sched = schedule(&topo, &ps);
        let dir = tempfile::tempdir().unwrap();
        for storage in [Storage::heap(), Storage::scratch(dir.path()).unwrap()] {
            let rings = PatchRings::of(&topo, &ps, &sched, &storage).unwrap();
            let mut total = 0;
            for (p, patch) in ps.iter().enumerate() {
                let mut want = rings_outside(&topo, &patch.vertices, 3).concat();
                want.sort_unstable();
                assert!(!want.is_empty() && want.iter().all(|v| !patch.vertices.contains(v)));
                assert_eq!(rings.of_patch(p), want, "patch {p}");
                total += want.len();
            }
            assert_eq!(rings.vertices.len(), total);
        }
        let mut wrong = sched.clone();
        wrong.ring_halo[0] += 1;
        let rings = PatchRings::of(&topo, &ps, &wrong, &Storage::heap()).unwrap();
        assert!(rings.of_patch(0).iter().all(|&v| v == 0));
        let mut want = rings_outside(&topo, &ps[1].vertices, 3).concat();
        want.sort_unstable();
        assert_eq!(rings.of_patch(1), want);
    }

    #[test]
    fn neighbouring_patches_get_different_colours_distant_ones_may_share() {
        let tris = ladder(100);
        let topo = Topology::build(200, &tris).unwrap();
        let ps = partition::patches(200, &tris, 20);
        let s = schedule(&topo, &ps);
        let colour_of = |p: u32| s.colours.iter().position(|c| c.contains(&p)).unwrap();
        for p in 0..ps.len() as u32 - 1 {
            assert_ne!(colour_of(p), colour_of(p + 1));
        }
        assert!(
            s.colours.len() < ps.len(),
            "distant patches should share colours"
        );
        assert_eq!(s.colours.iter().map(Vec::len).sum::<usize>(), ps.len());
        // Each patch's halo: 2 rings on each side of a ladder, 2 vertices per ring.
        assert_eq!(s.halo[3], 8);
        assert_eq!(s.halo[0], 4);
        // The 2-ring stencils read 3 rings.
        assert_eq!(s.ring_halo[3], 12);
        assert_eq!(s.ring_halo[0], 6);
    }

    #[test]
    fn patches_of_one_ring_colour_are_more_than_5_rings_apart() {
        // Patches of 4 vertices (2 rungs) on a ladder: ring distance between rungs is their
        // index difference, so the owned ranges of patches p and q are 2|p − q| − 1 rings apart.
        let tris = ladder(120);
        let topo = Topology::build(240, &tris).unwrap();
        let ps = partition::patches(240, &tris, 4);
        let s = schedule(&topo, &ps);
        let ring_colour = |p: u32| s.ring_colours.iter().position(|c| c.contains(&p)).unwrap();
        let edge_colour = |p: u32| s.colours.iter().position(|c| c.contains(&p)).unwrap();
        for p in 0..ps.len() as u32 {
            for q in p + 1..(p + 4).min(ps.len() as u32) {
                // 1, 3 and 5 rings apart: conflicts for the ring stencils.
                assert_ne!(ring_colour(p), ring_colour(q), "{p} {q}");
            }
            for q in p + 1..(p + 3).min(ps.len() as u32) {
                assert_ne!(edge_colour(p), edge_colour(q), "{p} {q}");
            }
        }
        // 3 vertices apart is 5 rings: conflicts for ring stencils only; the colourings differ.
        assert!(s.ring_colours.len() > s.colours.len());
        assert_eq!(s.ring_colours.iter().map(Vec::len).sum::<usize>(), ps.len());
    }

    /// More patches than lanes: three steps, step `s` the patches `p ≡ s (mod 3)`, every colour
    /// of a step before the next step's. Patches of 4 vertices on a ladder are 2|p − q| − 1 rings
    /// apart, so within a step (3 apart, 5 rings) the edge stencils do not conflict and each step
    /// is one colour, where the 2-ring stencils (conflict within 5 rings) need two.
    #[test]
    fn a_mesh_of_more_patches_than_lanes_runs_lane_by_lane() {
        let patches = 3 * LANES;
        let n = 4 * patches as u32 / 2;
        let tris = ladder(n);
        let topo = Topology::build(2 * n as usize, &tris).unwrap();
        let ps = partition::patches(2 * n as usize, &tris, 4);
        assert_eq!(ps.len(), patches);
        let s = schedule(&topo, &ps);
        assert_eq!(steps(ps.len()), 3);
        let lane_step = |p: u32| p as usize % 3;
        let expect: Vec<Vec<u32>> = (0..3)
            .map(|step| {
                (0..patches as u32)
                    .filter(|&p| lane_step(p) == step)
                    .collect()
            })
            .collect();
        assert_eq!(s.colours, expect);
        assert_eq!(s.ring_colours.len(), 6);
        for (k, colour) in s.ring_colours.iter().enumerate() {
            assert!(colour.iter().all(|&p| lane_step(p) == k / 2), "{k}");
            assert!(colour.windows(2).all(|w| w[1] - w[0] >= 6), "{k}");
        }
        assert_eq!(s.ring_colours.iter().map(Vec::len).sum::<usize>(), patches);
        // One patch more than a step holds is two steps.
        assert_eq!(steps(LANES), 1);
        assert_eq!(steps(LANES + 1), 2);
    }
}
