//! 2-ring stencils that restore the volume of a given displacement: `vcs-guided`'s second step
//! (the displacement is its fit to the filtered normals; `vcs-lowpass` used them for Taubin's
//! until it moved to blocks, [`super::lowpass`]). Kept for `vcs-guided` because a guided fit
//! moves an organic surface's volume locally (it flattens what it sees as noise), and a stencil
//! of two rings gives it back where it went: blocks give it back over thousands of vertices, and
//! measured on the denoising pairs that costs the organic ones 3–5 % of normal error and 13–15 %
//! of distance (docs/quality-research.md §14). The engine's kernel ([`ring_of`],
//! [`counts_into`], [`shares_into`], [`apply_ring`], [`sweep_rings`]), volume step shared with
//! `stencil.rs`; the sequential reference it is tested against is test code
//! (`tests/oracles/rings.rs`).
//!
//! One iteration on positions `P`, with `T` the first step's result:
//! 1. `D = T − P`, fixed vertices kept.
//! 2. Every movable vertex `v` owns the stencil `F_v` = the movable vertices within graph distance
//!    [`RING_RADIUS`] of `v`; `c_u` = the number of stencils that contain `u`.
//! 3. Gauss–Seidel over `v` in index order: `p_u += D_u / c_u` for `u ∈ F_v` (step 1), then the
//!    common translation `w = n (V⁰ − V¹) / |n|²` of `F_v` that gives the faces touching `F_v`
//!    their volume back exactly (step 2, DESIGN.md). Every vertex so receives its whole
//!    displacement once per iteration, plus the volume translations of its stencils.
//!
//! The ring must be wide: step 2 removes the free vertices' *mean* normal motion; over an edge
//! (2 vertices) that is half of each vertex's move, over a 2-ring (~19 vertices) the noise
//! averages out and mostly the low-frequency shrink/inflation is removed.

use std::ops::Range;

use glam::DVec3;

use super::stencil::{self, Outcome};
use super::{Field, SweepStats};
use crate::topology::{Topology, TopologyParts, corners_after};

/// Graph radius of the restoring stencils (1 fails the quality target, 2 meets it).
pub const RING_RADIUS: usize = 2;

// ---------------------------------------------------------------------------------------------
// The engine's kernel (`Method::VcsGuided`): one ring stencil at a time, over a `Field`, so the
// same code runs a whole mesh and the patches of one colour in parallel. What it reads and
// writes (the schedule's conflict rule for this method rests on it, see `crate::schedule`):
// - stencil `v` writes the positions of `F_v` (within 2 rings of `v`);
// - it reads the positions of every corner of the faces touching `F_v` (within 3 rings) and the
//   step-1 shares of `F_v`, which are computed before the sweep and only read during it.

/// A ring stencil's members: ascending, with a set beside them for membership, because a ring
/// stencil asks "is this corner free?" for every face it touches (about six per member), and the
/// 2-ring is found through its vertices' neighbour lists, which repeat most vertices. The set is
/// a table indexed by the id's distance from the stencil's centre, which holds nearly every
/// member because the plan's order keeps neighbours close, and a hash table for the others.
/// Scratch space: one per thread, reused from stencil to stencil.
#[derive(Debug, Clone)]
pub struct Ring {
    /// The members, ascending (after [`ring_of`]).
    pub members: Vec<u32>,
    /// The ids `centre − WINDOW / 2 .. centre + WINDOW / 2`: the stamp of the ring that holds
    /// them (another stamp: not a member), so clearing is one increment.
    window: Vec<u32>,
    centre: u32,
    /// Whether every vertex within two rings of the centre is movable (set by [`ring_of`]).
    all_movable: bool,
    /// Open addressing, linear probing: `stamp << 32 | vertex`, for the ids outside the window.
    slots: Vec<u64>,
    /// `32 − log2(slots.len())`: the hash keeps the product's top bits.
    shift: u32,
    stamp: u32,
}

/// The ids around a stencil's centre that [`Ring`] finds without hashing.
const WINDOW: usize = 2048;

impl Default for Ring {
    fn default() -> Ring {
        Ring {
            members: Vec::with_capacity(64),
            window: vec![0; WINDOW],
            centre: 0,
            all_movable: false,
            slots: vec![0; 128],
            shift: 32 - 7,
            stamp: 1,
        }
    }
}

impl Ring {
    /// An empty ring about `centre`.
    fn clear(&mut self, centre: u32) {
        self.members.clear();
        self.centre = centre;
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.window.fill(0);
            self.slots.fill(0);
            self.stamp = 1;
        }
    }

    /// Where `v` is in the window, if it is.
    #[inline(always)]
    fn in_window(&self, v: u32) -> Option<usize> {
        let at = v.wrapping_sub(self.centre).wrapping_add(WINDOW as u32 / 2) as usize;
        (at < WINDOW).then_some(at)
    }

    /// The slot of `v`: where it is, or the empty slot where it would go.
    #[inline(always)]
    fn slot(&self, v: u32) -> (usize, bool) {
        let mask = self.slots.len() - 1;
        // Fibonacci hashing: the top bits of the product spread consecutive ids.
        let mut at = (v.wrapping_mul(0x9E37_79B9) >> self.shift) as usize;
        let want = (self.stamp as u64) << 32 | v as u64;
        loop {
            let e = self.slots[at];
            if e == want {
                return (at, true);
            }
            if (e >> 32) as u32 != self.stamp {
                return (at, false);
            }
            at = (at + 1) & mask;
        }
    }

    /// Insert `v`; [`Ring::reserve`] must have made room for it.
    #[inline(always)]
    fn insert(&mut self, v: u32) {
        if let Some(at) = self.in_window(v) {
            if self.window[at] != self.stamp {
                self.window[at] = self.stamp;
                self.members.push(v);
            }
            return;
        }
        let (at, found) = self.slot(v);
        if !found {
            self.slots[at] = (self.stamp as u64) << 32 | v as u64;
            self.members.push(v);
        }
    }

    /// Room for `more` members beyond those held, the hash table at most half full.
    #[inline(always)]
    fn reserve(&mut self, more: usize) {
        let need = (self.members.len() + more) * 2;
        if need > self.slots.len() {
            self.grow(need);
        }
    }

    /// A hash table of at least `need` slots, the members outside the window placed again (a
    /// vertex of unusually high valence).
    #[cold]
    fn grow(&mut self, need: usize) {
        let len = need.next_power_of_two();
        self.slots = vec![0; len];
        self.shift = 32 - len.trailing_zeros();
        for k in 0..self.members.len() {
            let v = self.members[k];
            if self.in_window(v).is_none() {
                let (at, _) = self.slot(v);
                self.slots[at] = (self.stamp as u64) << 32 | v as u64;
            }
        }
    }

    /// Whether `v` is a member.
    #[inline(always)]
    pub fn contains(&self, v: u32) -> bool {
        match self.in_window(v) {
            Some(at) => self.window[at] == self.stamp,
            None => self.slot(v).1,
        }
    }
}

/// `F_v` into `ring` (cleared first): `v` and the movable vertices reachable from `v` in at most
/// [`RING_RADIUS`] steps through movable vertices, ascending; empty when `v` is fixed. The
/// relation is symmetric (a path of movable vertices reversed is one), so `u ∈ F_v ⇔ v ∈ F_u`
/// and the number of stencils holding `u` is `|F_u|`: no per-vertex count has to be stored.
/// With `sorted` false the members stay in the order found (enough for counting them).
pub fn ring_of(topo: &TopologyParts, v: u32, ring: &mut Ring, sorted: bool) {
    const { assert!(RING_RADIUS == 2, "ring_of walks exactly two rings") };
    ring.clear(v);
    if !topo.is_free_or_on_line(v) {
        return;
    }
    ring.reserve(1);
    ring.insert(v);
    let mut fixed_near = false;
    for &u in topo.neighbors(v) {
        if !topo.is_free_or_on_line(u) {
            fixed_near = true;
            continue;
        }
        let around = topo.neighbors(u);
        ring.reserve(1 + around.len());
        ring.insert(u);
        for &w in around {
            // `v` is a neighbour of each of its neighbours, and already in.
            if w == v {
                continue;
            }
            if !topo.is_free_or_on_line(w) {
                fixed_near = true;
            } else {
                ring.insert(w);
            }
        }
    }
    ring.all_movable = !fixed_near;
    if sorted {
        ring.members.sort_unstable();
    }
}

/// The sizes `|F_u|` of the vertices `first .. first + out.len()`, for [`shares_into`]: they
/// depend on the topology alone, so a run counts them once. A size above 254 is kept as
/// [`COUNT_AGAIN`] (the byte cannot hold it; such a stencil is counted again when needed).
pub fn counts_into(topo: &Topology, out: &mut [u8], first: usize) {
    let topo = topo.parts();
    let mut ring = Ring::default();
    for (k, o) in out.iter_mut().enumerate() {
        let size = ring_size(&topo, (first + k) as u32, &mut ring);
        *o = size.min(COUNT_AGAIN as usize) as u8;
    }
}

/// `|F_v|`, `ring` being scratch space.
fn ring_size(topo: &TopologyParts, v: u32, ring: &mut Ring) -> usize {
    ring_of(topo, v, ring, false);
    ring.members.len()
}

/// The size [`counts_into`] keeps for a stencil too large for its byte.
pub const COUNT_AGAIN: u8 = u8::MAX;

/// Step 1's share for the vertices `first .. first + out.len()`: `(t_u − p_u) / |F_u|`, with `t`
/// the positions after one Jacobi λ|μ pair from `pos` (so summed over the `|F_u|` stencils that
/// hold `u`, every vertex receives its whole Taubin displacement once); zero for a fixed vertex.
/// `counts` holds the sizes from [`counts_into`] for the same vertices. Each entry depends only
/// on `pos`, `taubin` and the topology, so any split of the range gives the same bits.
pub fn shares_into(
    topo: &Topology,
    pos: &[DVec3],
    taubin: &[DVec3],
    counts: &[u8],
    out: &mut [DVec3],
    first: usize,
) {
    let topo = topo.parts();
    // Only a stencil too large for its byte is counted again: the scratch space is made then.
    let mut ring: Option<Ring> = None;
    for ((k, o), &count) in out.iter_mut().enumerate().zip(counts) {
        let u = first + k;
        let count = match count {
            COUNT_AGAIN => ring_size(&topo, u as u32, ring.get_or_insert_with(Ring::default)),
            count => count as usize,
        };
        *o = if count == 0 {
            DVec3::ZERO
        } else {
            (taubin[u] - pos[u]) * (1.0 / count as f64)
        };
    }
}

/// Apply the ring stencil of `v`: every `u ∈ F_v` moves by its share `shares[u]` (step 1) plus
/// the common translation `w` that gives the faces touching `F_v` their volume back exactly
/// (step 2). The volume change and gradient are those of the edge and triangle stencils, face by
/// face through `stencil::shared_face` about the origin `p_v`, and `w` and the degenerate test
/// are `stencil::translation`'s, so a ring stencil restores its volume with the same arithmetic
/// as `vcs`. With a `deviation` bound the stencil is skipped whole when it would leave a member
/// farther than the limit from its input position (as `vcs`'s stencils are, so the volume stays
/// exact). `ring` is scratch space. Writes only when the outcome is [`Outcome::Applied`].
pub fn apply_ring<P: Field + ?Sized, D: Field + ?Sized>(
    topo: &TopologyParts,
    triangles: &[[u32; 3]],
    pos: &mut P,
    shares: &D,
    v: u32,
    deviation: Option<stencil::Deviation>,
    ring: &mut Ring,
) -> Outcome {
    ring_of(topo, v, ring, true);
    let ring = &*ring;
    if ring.members.is_empty() {
        return Outcome::SkippedFixed;
    }
    let origin = pos.get(v);
    let share = |free: bool, u: u32| if free { shares.get(u) } else { DVec3::ZERO };
    let (mut dv, mut n, mut scale) = (0.0, DVec3::ZERO, 0.0);
    // Whether the member is `v` or one of its neighbours, walked beside the ascending members:
    // then every movable neighbour of it is a member too (every neighbour, when no vertex within
    // two rings of `v` is fixed), and the set need not be asked.
    let around = topo.neighbors(v);
    let mut next = 0;
    for &a in &ring.members {
        while next < around.len() && around[next] < a {
            next += 1;
        }
        let near = a == v || around.get(next) == Some(&a);
        let free = |u: u32| {
            if near {
                ring.all_movable || topo.is_free_or_on_line(u)
            } else {
                ring.contains(u)
            }
        };
        let (pa, sa) = (pos.get(a) - origin, shares.get(a));
        crate::for_each_face!(topo, a, triangles, u32::MAX, |_t, tri| {
            let (b, c) = corners_after(tri, a);
            let (b_free, c_free) = (free(b), free(c));
            // Each face once: at its smallest free corner.
            if (b_free && b < a) || (c_free && c < a) {
                continue;
            }
            stencil::shared_face(
                pa,
                pos.get(b) - origin,
                pos.get(c) - origin,
                sa,
                share(b_free, b),
                share(c_free, c),
                b_free,
                c_free,
                &mut dv,
                &mut n,
                &mut scale,
            );
        });
    }
    let Some(w) = stencil::translation(dv, n, scale) else {
        return Outcome::SkippedDegenerate;
    };
    if !ring
        .members
        .iter()
        .all(|&u| (shares.get(u) + w).is_finite())
    {
        return Outcome::SkippedDegenerate;
    }
    if let Some(bound) = deviation {
        let limit2 = bound.limit * bound.limit;
        let beyond = |u: u32| {
            (pos.get(u) + shares.get(u) + w - bound.input[u as usize]).length_squared() > limit2
        };
        if ring.members.iter().any(|&u| beyond(u)) {
            return Outcome::DeviationLimited;
        }
    }
    for &u in &ring.members {
        pos.add(u, shares.get(u) + w);
    }
    Outcome::Applied
}

/// The ring stencils of the vertices `owned`, in ascending order, Gauss–Seidel (each sees the
/// latest positions); `shares` from [`shares_into`]; `deviation` as in [`apply_ring`].
pub fn sweep_rings<P: Field + ?Sized, D: Field + ?Sized>(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut P,
    shares: &D,
    owned: Range<u32>,
    deviation: Option<stencil::Deviation>,
) -> SweepStats {
    let topo = topo.parts();
    let mut stats = SweepStats::default();
    let mut ring = Ring::default();
    for v in owned {
        let outcome = apply_ring(&topo, triangles, pos, shares, v, deviation, &mut ring);
        stencil::count(&mut stats, outcome);
    }
    stats
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stencil too large for its byte is counted again: on a bipyramid of 300 equator vertices
    /// every 2-ring is the whole mesh (302 vertices), and its shares divide by 302.
    #[test]
    fn stencils_larger_than_a_byte_are_counted_again() {
        let k = 300u32;
        let (top, bottom) = (k, k + 1);
        let mut positions: Vec<DVec3> = (0..k)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / k as f64;
                DVec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        positions.extend([DVec3::Z, -DVec3::Z]);
        let triangles: Vec<[u32; 3]> = (0..k)
            .flat_map(|i| [[i, (i + 1) % k, top], [(i + 1) % k, i, bottom]])
            .collect();
        let topo = Topology::build(positions.len(), &triangles).unwrap();
        let n = positions.len();
        let mut counts = vec![0; n];
        counts_into(&topo, &mut counts, 0);
        assert!(counts.iter().all(|&c| c == COUNT_AGAIN));
        let taubin: Vec<DVec3> = positions.iter().map(|p| *p * 1.5).collect();
        let mut shares = vec![DVec3::ZERO; n];
        shares_into(&topo, &positions, &taubin, &counts, &mut shares, 0);
        for u in 0..n {
            assert_eq!(shares[u], (taubin[u] - positions[u]) * (1.0 / 302.0), "{u}");
        }
    }

    /// The ring's set through growth (a vertex of high valence) and many clears, with members
    /// both in its window about the centre and in its hash table.
    #[test]
    fn a_ring_grows_and_clears() {
        let mut ring = Ring::default();
        let mut before: Vec<u32> = Vec::new();
        for round in 0..300u32 {
            let centre = 5000 + round * 13;
            ring.clear(centre);
            let size = if round % 50 == 0 { 1000 } else { 20 };
            // Even k about the centre (the window), odd k far from it (the hash table).
            let members: Vec<u32> = (0..size)
                .map(|k| match k % 2 {
                    0 => centre + k - size / 2,
                    _ => k * 7919 + round + 100_000,
                })
                .collect();
            for (k, &v) in members.iter().enumerate() {
                // Room made in pieces, as `ring_of` makes it ring by ring.
                if k % 10 == 0 {
                    ring.reserve(10);
                }
                ring.insert(v);
                ring.insert(v);
            }
            assert_eq!(ring.members, members);
            assert!(members.iter().all(|&v| ring.contains(v)));
            assert!(!ring.contains(centre + size / 2 + 1), "in the window");
            assert!(!ring.contains(100_007 + round), "outside it");
            let gone = before.iter().filter(|v| !members.contains(v));
            assert!(round == 0 || gone.clone().count() > 0);
            assert!(gone.clone().all(|&v| !ring.contains(v)), "cleared");
            before = members;
        }
    }
}
