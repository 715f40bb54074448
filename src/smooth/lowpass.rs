//! `vcs-lowpass` (issue #15): Taubin's λ|μ low-pass displacement as the first step of Liu et al.'s
//! 2-step approach, the volume restored exactly on vertex-ring stencils; and the automatic stop
//! rule of `--iterations auto`; see docs/quality-research.md for the definition, the evidence and
//! the numbers. Two parts:
//! - the engine's kernel ([`ring_of`], [`shares_into`], [`apply_ring`], [`sweep_rings`]), which
//!   `Method::VcsLowpass` runs patch by patch through `engine::iterate` (volume step shared with
//!   `stencil.rs`);
//! - the research prototype ([`RingStencils`], [`lowpass_iteration`]: sequential, whole mesh,
//!   its own volume arithmetic), kept as the independent reference the kernel is tested against,
//!   and [`AutoStop`], the sequential prototype of `--iterations auto`, the reference the
//!   engine's rule (`crate::engine::auto`) is tested against.
//!
//! One iteration on positions `P`:
//! 1. `D = T(P) − P`, `T` = Taubin's λ then μ umbrella step, Jacobi, fixed vertices kept.
//! 2. Every movable vertex `v` owns the stencil `F_v` = the movable vertices within graph distance
//!    [`RING_RADIUS`] of `v`; `c_u` = the number of stencils that contain `u`.
//! 3. Gauss–Seidel over `v` in index order: `p_u += D_u / c_u` for `u ∈ F_v` (step 1), then the
//!    common translation `w = n (V⁰ − V¹) / |n|²` of `F_v` that gives the faces touching `F_v`
//!    their volume back exactly (step 2, DESIGN.md). Every vertex so receives its whole Taubin
//!    displacement once per iteration, plus the volume translations of its stencils.
//!
//! The ring must be wide: step 2 removes the free vertices' *mean* normal motion; over an edge
//! (2 vertices) that is half of each vertex's denoising, over a 2-ring (~19 vertices) the noise
//! averages out and mostly the low-frequency shrink/inflation is removed.

use std::ops::Range;

use glam::DVec3;

use super::stencil::{self, Outcome};
use super::{Field, SweepStats};
use crate::topology::{Topology, TopologyParts, corners_after};

/// Graph radius of the restoring stencils (1 fails the quality target, 2 meets it).
pub const RING_RADIUS: usize = 2;

// ---------------------------------------------------------------------------------------------
// The engine's kernel (`Method::VcsLowpass`): one ring stencil at a time, over a `Field`, so the
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
    if topo.is_fixed(v) {
        return;
    }
    ring.reserve(1);
    ring.insert(v);
    let mut fixed_near = false;
    for &u in topo.neighbors(v) {
        if topo.is_fixed(u) {
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
            if topo.is_fixed(w) {
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
/// face through [`stencil::shared_face`] about the origin `p_v`, and `w` and the degenerate test
/// are [`stencil::translation`]'s, so a ring stencil restores its volume with the same arithmetic
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
                ring.all_movable || !topo.is_fixed(u)
            } else {
                ring.contains(u)
            }
        };
        let (pa, sa) = (pos.get(a) - origin, shares.get(a));
        for &t in topo.faces_of(a) {
            let (b, c) = corners_after(triangles[t as usize], a);
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
        }
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

// ---------------------------------------------------------------------------------------------
// The research prototype (sequential, whole mesh, its own volume arithmetic): kept as the
// independent reference the engine's kernel is checked against (`tests` below).

/// The ring stencils of a mesh: `members[offsets[v]..offsets[v + 1]]` is `F_v` (empty for a fixed
/// vertex), `share[u] = 1 / c_u` (0 for a vertex in no stencil).
#[derive(Debug, Clone)]
pub struct RingStencils {
    pub offsets: Vec<usize>,
    pub members: Vec<u32>,
    pub share: Vec<f64>,
}

impl RingStencils {
    /// Stencils of graph radius `radius` around every movable vertex.
    pub fn build(topo: &Topology, radius: usize) -> RingStencils {
        let n = topo.len();
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        let mut members: Vec<u32> = Vec::new();
        let mut count = vec![0u32; n];
        let mut seen = vec![u32::MAX; n];
        let mut frontier = Vec::new();
        let mut next = Vec::new();
        for v in 0..n as u32 {
            if !topo.is_fixed(v) {
                let start = members.len();
                members.push(v);
                seen[v as usize] = v;
                frontier.clear();
                frontier.push(v);
                for _ in 0..radius {
                    next.clear();
                    for &u in &frontier {
                        for &w in topo.neighbors(u) {
                            if seen[w as usize] != v && !topo.is_fixed(w) {
                                seen[w as usize] = v;
                                members.push(w);
                                next.push(w);
                            }
                        }
                    }
                    std::mem::swap(&mut frontier, &mut next);
                }
                for &u in &members[start..] {
                    count[u as usize] += 1;
                }
            }
            offsets.push(members.len());
        }
        let share = count
            .iter()
            .map(|&c| if c > 0 { 1.0 / c as f64 } else { 0.0 })
            .collect();
        RingStencils {
            offsets,
            members,
            share,
        }
    }

    /// `F_v`.
    pub fn of(&self, v: u32) -> &[u32] {
        &self.members[self.offsets[v as usize]..self.offsets[v as usize + 1]]
    }
}

/// Reusable buffers of [`lowpass_iteration`].
#[derive(Debug, Default)]
pub struct Scratch {
    d: Vec<DVec3>,
    q: Vec<DVec3>,
    vmark: Vec<u32>,
    fmark: Vec<u32>,
    faces: Vec<u32>,
}

/// Stencils applied and skipped (degenerate volume gradient) in one iteration.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    pub applied: usize,
    pub skipped_degenerate: usize,
}

fn umbrella(topo: &Topology, p: &[DVec3], v: u32) -> DVec3 {
    let ns = topo.neighbors(v);
    let mut s = DVec3::ZERO;
    for &u in ns {
        s += p[u as usize];
    }
    s / ns.len() as f64 - p[v as usize]
}

/// One λ|μ pair, Jacobi, into `out` (fixed and isolated vertices copied).
pub fn taubin_pair(
    topo: &Topology,
    p: &[DVec3],
    lambda: f64,
    mu: f64,
    tmp: &mut Vec<DVec3>,
    out: &mut Vec<DVec3>,
) {
    let n = p.len();
    let movable = |v: u32| !topo.is_fixed(v) && topo.deg(v) > 0;
    tmp.clear();
    tmp.extend((0..n as u32).map(|v| {
        if movable(v) {
            p[v as usize] + lambda * umbrella(topo, p, v)
        } else {
            p[v as usize]
        }
    }));
    out.clear();
    out.extend((0..n as u32).map(|v| {
        if movable(v) {
            tmp[v as usize] + mu * umbrella(topo, tmp, v)
        } else {
            tmp[v as usize]
        }
    }));
}

/// Volume (relative to `o`) of `faces` and its gradient for a common translation of the vertices
/// whose `vmark` equals `stamp`.
fn local_volume(
    p: &[DVec3],
    tris: &[[u32; 3]],
    faces: &[u32],
    vmark: &[u32],
    stamp: u32,
    o: DVec3,
) -> (f64, DVec3) {
    let mut vol = 0.0;
    let mut grad = DVec3::ZERO;
    for &f in faces {
        let t = tris[f as usize];
        let q = [
            p[t[0] as usize] - o,
            p[t[1] as usize] - o,
            p[t[2] as usize] - o,
        ];
        vol += q[0].dot(q[1].cross(q[2]));
        for k in 0..3 {
            if vmark[t[k] as usize] == stamp {
                grad += q[(k + 1) % 3].cross(q[(k + 2) % 3]);
            }
        }
    }
    (vol / 6.0, grad / 6.0)
}

/// One `vcs-lowpass` iteration over the whole mesh (see the module doc).
pub fn lowpass_iteration(
    topo: &Topology,
    tris: &[[u32; 3]],
    stencils: &RingStencils,
    p: &mut [DVec3],
    lambda: f64,
    mu: f64,
    s: &mut Scratch,
) -> Counts {
    let n = p.len();
    taubin_pair(topo, p, lambda, mu, &mut s.q, &mut s.d);
    for ((d, q), share) in s.d.iter_mut().zip(p.iter()).zip(&stencils.share) {
        *d = (*d - *q) * share;
    }
    s.vmark.clear();
    s.vmark.resize(n, 0);
    s.fmark.clear();
    s.fmark.resize(tris.len(), 0);
    let mut counts = Counts::default();
    for v in 0..n as u32 {
        let free = stencils.of(v);
        if free.is_empty() {
            continue;
        }
        let stamp = v + 1;
        s.faces.clear();
        for &u in free {
            s.vmark[u as usize] = stamp;
            for &f in topo.faces_of(u) {
                if s.fmark[f as usize] != stamp {
                    s.fmark[f as usize] = stamp;
                    s.faces.push(f);
                }
            }
        }
        let o = p[v as usize];
        let (v0, _) = local_volume(p, tris, &s.faces, &s.vmark, stamp, o);
        let mut scale: f64 = 0.0;
        for &u in free {
            p[u as usize] += s.d[u as usize];
            scale = scale.max((p[u as usize] - o).length_squared());
        }
        let (v1, grad) = local_volume(p, tris, &s.faces, &s.vmark, stamp, o);
        let gg = grad.length_squared();
        // |n| has the units of an area: skip a stencil whose gradient vanishes at its scale
        let usable = gg > 1e-24 * scale * scale && gg.is_finite() && v1.is_finite();
        if !usable {
            for &u in free {
                p[u as usize] -= s.d[u as usize];
            }
            counts.skipped_degenerate += 1;
            continue;
        }
        let w = grad * ((v0 - v1) / gg);
        for &u in free {
            p[u as usize] += w;
        }
        counts.applied += 1;
    }
    counts
}

/// The automatic stop of `--iterations auto`: stop when what an iteration removes along the
/// normals is no longer explained by noise (`ratio > tau`), or when the method's filter would
/// remove less than `gone` of the input noise energy per further iteration.
///
/// - `σ̂ = MAD(g) / MAD(g^ε)`, `g_v = h_v − mean_{N(v)} h`, `h_v = n_v · L(P⁰)_v`; `g^ε` the same
///   operators on i.i.d. N(0, 1) samples ε on the same connectivity.
/// - Expected: `E_k = mean (e^k − ε)² / mean ε²`, `e^k` = the method's scalar analogue applied k
///   times to ε (the caller applies it to [`AutoStop::synthetic_mut`] each iteration).
/// - Observed: `O_k = mean ((P^k − P⁰)·n)² / σ̂²`; `ratio_k = ΔO / ΔE`.
#[derive(Debug, Clone)]
pub struct AutoStop {
    p0: Vec<DVec3>,
    n0: Vec<DVec3>,
    movable: Vec<u32>,
    eps: Vec<f64>,
    syn: Vec<f64>,
    eps_energy: f64,
    sigma: f64,
    expected: f64,
    observed: f64,
    iteration: usize,
    /// Stop when more than `1 − 1/tau` of an iteration's removal is not noise (default 4/3, the
    /// research's value; the engine's is `engine::auto::DETAIL_RATIO`).
    pub tau: f64,
    /// Stop when the expected gain falls below this fraction of the noise energy (default 0.01).
    pub gone: f64,
}

/// What [`AutoStop::observe`] saw after one iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    pub iteration: usize,
    pub expected_gain: f64,
    pub ratio: f64,
    pub stop: bool,
}

fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn gaussian(state: &mut u64) -> f64 {
    let u = |s: &mut u64| ((splitmix(s) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let (a, b) = (u(state), u(state));
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let mid = x.len() / 2;
    *x.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
}

impl AutoStop {
    pub fn new(topo: &Topology, tris: &[[u32; 3]], p0: &[DVec3], seed: u64) -> AutoStop {
        let n = p0.len();
        let mut n0 = vec![DVec3::ZERO; n];
        for t in tris {
            let (a, b, c) = (p0[t[0] as usize], p0[t[1] as usize], p0[t[2] as usize]);
            let f = (b - a).cross(c - a);
            for &v in t {
                n0[v as usize] += f;
            }
        }
        let movable: Vec<u32> = (0..n as u32)
            .filter(|&v| !topo.is_fixed(v) && topo.deg(v) > 0)
            .collect();
        let mut state = seed;
        let mut eps = vec![0.0; n];
        for &v in &movable {
            eps[v as usize] = gaussian(&mut state);
        }
        for (v, x) in n0.iter_mut().enumerate() {
            *x = if topo.is_fixed(v as u32) {
                DVec3::ZERO
            } else {
                x.normalize_or_zero()
            };
        }
        let nbmean = |x: &[f64], v: u32| {
            let ns = topo.neighbors(v);
            ns.iter().map(|&u| x[u as usize]).sum::<f64>() / ns.len().max(1) as f64
        };
        let h: Vec<f64> = (0..n as u32)
            .map(|v| {
                if topo.deg(v) > 0 {
                    umbrella(topo, p0, v).dot(n0[v as usize])
                } else {
                    0.0
                }
            })
            .collect();
        let he: Vec<f64> = (0..n as u32)
            .map(|v| nbmean(&eps, v) - eps[v as usize])
            .collect();
        let mad = |x: &[f64]| {
            let mut g: Vec<f64> = movable
                .iter()
                .map(|&v| x[v as usize] - nbmean(x, v))
                .collect();
            let med = median(&mut g);
            let mut dev: Vec<f64> = g.iter().map(|y| (y - med).abs()).collect();
            median(&mut dev)
        };
        let (mh, me) = (mad(&h), mad(&he));
        let sigma = if me > 0.0 { mh / me } else { 0.0 };
        let eps_energy = movable
            .iter()
            .map(|&v| eps[v as usize].powi(2))
            .sum::<f64>()
            / movable.len().max(1) as f64;
        AutoStop {
            p0: p0.to_vec(),
            n0,
            movable,
            syn: eps.clone(),
            eps,
            eps_energy,
            sigma,
            expected: 0.0,
            observed: 0.0,
            iteration: 0,
            tau: 4.0 / 3.0,
            gone: 0.01,
        }
    }

    /// The estimated noise level along the normals (length units).
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The synthetic noise field: apply the method's scalar analogue to it once per iteration,
    /// before [`AutoStop::observe`].
    pub fn synthetic_mut(&mut self) -> &mut [f64] {
        &mut self.syn
    }

    /// Record iteration k's positions; `stop` says whether to end after it.
    pub fn observe(&mut self, p: &[DVec3]) -> Observation {
        self.iteration += 1;
        let m = self.movable.len().max(1) as f64;
        let expected = self
            .movable
            .iter()
            .map(|&v| (self.syn[v as usize] - self.eps[v as usize]).powi(2))
            .sum::<f64>()
            / m
            / self.eps_energy.max(f64::MIN_POSITIVE);
        let observed = self
            .movable
            .iter()
            .map(|&v| {
                (p[v as usize] - self.p0[v as usize])
                    .dot(self.n0[v as usize])
                    .powi(2)
            })
            .sum::<f64>()
            / m
            / (self.sigma * self.sigma).max(f64::MIN_POSITIVE);
        let gain = expected - self.expected;
        let ratio = if gain > 0.0 {
            (observed - self.observed) / gain
        } else {
            f64::INFINITY
        };
        self.expected = expected;
        self.observed = observed;
        let stop =
            self.sigma == 0.0 || (self.iteration >= 2 && ratio > self.tau) || gain < self.gone;
        Observation {
            iteration: self.iteration,
            expected_gain: gain,
            ratio,
            stop,
        }
    }
}

/// The scalar analogue of taubin and vcs-lowpass: one λ|μ pair, Jacobi, fixed vertices kept.
pub fn scalar_taubin_pair(
    topo: &Topology,
    x: &mut [f64],
    lambda: f64,
    mu: f64,
    tmp: &mut Vec<f64>,
) {
    for step in [lambda, mu] {
        tmp.clear();
        tmp.extend_from_slice(x);
        for v in 0..x.len() as u32 {
            let ns = topo.neighbors(v);
            if topo.is_fixed(v) || ns.is_empty() {
                continue;
            }
            let m = ns.iter().map(|&u| tmp[u as usize]).sum::<f64>() / ns.len() as f64;
            x[v as usize] = tmp[v as usize] + step * (m - tmp[v as usize]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{add_normal_noise, icosphere};

    fn volume(p: &[DVec3], tris: &[[u32; 3]]) -> f64 {
        tris.iter()
            .map(|t| p[t[0] as usize].dot(p[t[1] as usize].cross(p[t[2] as usize])))
            .sum::<f64>()
            / 6.0
    }

    fn rms_radius_error(p: &[DVec3]) -> f64 {
        (p.iter().map(|q| (q.length() - 1.0).powi(2)).sum::<f64>() / p.len() as f64).sqrt()
    }

    #[test]
    fn keeps_volume_and_denoises_a_sphere() {
        let mut mesh = icosphere(4);
        add_normal_noise(&mut mesh, 0.3, 7);
        let tris = mesh.triangles.to_vec();
        let mut p = mesh.positions.to_vec();
        let topo = Topology::build(p.len(), &tris).unwrap();
        let st = RingStencils::build(&topo, RING_RADIUS);
        let (v0, e0) = (volume(&p, &tris), rms_radius_error(&p));
        let mut s = Scratch::default();
        for _ in 0..10 {
            let c = lowpass_iteration(&topo, &tris, &st, &mut p, 0.5, -0.53, &mut s);
            assert_eq!(c.skipped_degenerate, 0);
        }
        assert!(((volume(&p, &tris) - v0) / v0).abs() < 1e-12);
        assert!(
            rms_radius_error(&p) < 0.5 * e0,
            "{} vs {}",
            rms_radius_error(&p),
            e0
        );
    }

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

    /// One engine-kernel iteration over the whole mesh in index order (the prototype's order).
    fn kernel_iteration(topo: &Topology, tris: &[[u32; 3]], p: &mut [DVec3]) -> SweepStats {
        let n = p.len();
        let (mut q, mut t, mut shares) = (
            vec![DVec3::ZERO; n],
            vec![DVec3::ZERO; n],
            vec![DVec3::ZERO; n],
        );
        crate::smooth::laplacian::jacobi_step(topo, p, &mut q, 0, 0.5);
        crate::smooth::laplacian::jacobi_step(topo, &q, &mut t, 0, -0.53);
        let mut counts = vec![0; n];
        counts_into(topo, &mut counts, 0);
        shares_into(topo, p, &t, &counts, &mut shares, 0);
        sweep_rings(topo, tris, p, &shares[..], 0..n as u32, None)
    }

    #[test]
    fn rings_are_symmetric_and_exclude_fixed_vertices() {
        let mut mesh = icosphere(2);
        let tris: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .copied()
            .filter(|t| !t.contains(&0))
            .collect();
        mesh.triangles = tris.clone().into();
        let topo = Topology::build(mesh.positions.len(), &tris).unwrap();
        let st = RingStencils::build(&topo, RING_RADIUS);
        let (mut a, mut b) = (Ring::default(), Ring::default());
        for v in 0..topo.len() as u32 {
            ring_of(&topo.parts(), v, &mut a, true);
            let mut want = st.of(v).to_vec();
            want.sort_unstable();
            assert_eq!(a.members, want, "vertex {v}");
            for &u in &a.members {
                assert!(!topo.is_fixed(u));
                ring_of(&topo.parts(), u, &mut b, false);
                assert!(b.contains(v));
                assert!(b.members.contains(&v));
            }
            for u in 0..topo.len() as u32 {
                assert_eq!(a.contains(u), want.contains(&u), "{u} in the ring of {v}");
            }
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

    #[test]
    fn the_engine_kernel_follows_the_prototype_and_keeps_volume() {
        // Same order of work, different rounding (the kernel sums each face's volume change
        // through the edge stencils' code, the prototype subtracts two volumes): the positions
        // agree to rounding, and both keep the volume.
        let mut mesh = icosphere(4);
        add_normal_noise(&mut mesh, 0.3, 7);
        let offset = DVec3::new(3.0, -2.0, 5.0);
        let p0: Vec<DVec3> = mesh.positions.iter().map(|p| *p + offset).collect();
        let tris = mesh.triangles.to_vec();
        let topo = Topology::build(p0.len(), &tris).unwrap();
        let st = RingStencils::build(&topo, RING_RADIUS);
        let (mut proto, mut kernel) = (p0.clone(), p0.clone());
        let mut s = Scratch::default();
        let vol = |p: &[DVec3]| crate::metrics::volume(p, &tris);
        let v0 = vol(&p0);
        for _ in 0..8 {
            lowpass_iteration(&topo, &tris, &st, &mut proto, 0.5, -0.53, &mut s);
            let stats = kernel_iteration(&topo, &tris, &mut kernel);
            assert_eq!(stats.applied as usize, topo.len());
        }
        let far = proto
            .iter()
            .zip(&kernel)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f64::max);
        assert!(far < 1e-12, "{far}");
        assert!(((vol(&kernel) - v0) / v0).abs() < 1e-12);
    }

    #[test]
    fn open_mesh_keeps_boundary_and_volume() {
        let mut mesh = icosphere(3);
        add_normal_noise(&mut mesh, 0.3, 3);
        // open a hole: drop the faces around vertex 0
        let tris: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .copied()
            .filter(|t| !t.contains(&0))
            .collect();
        let mut p = mesh.positions.to_vec();
        let topo = Topology::build(p.len(), &tris).unwrap();
        let st = RingStencils::build(&topo, RING_RADIUS);
        let before = p.clone();
        let v0 = volume(&p, &tris);
        let mut s = Scratch::default();
        for _ in 0..5 {
            lowpass_iteration(&topo, &tris, &st, &mut p, 0.5, -0.53, &mut s);
        }
        for v in 0..p.len() as u32 {
            if topo.is_fixed(v) {
                assert_eq!(p[v as usize], before[v as usize]);
            }
        }
        assert!(((volume(&p, &tris) - v0) / v0).abs() < 1e-12);
    }

    #[test]
    fn auto_stop_estimates_the_noise_and_stops() {
        let mut mesh = icosphere(5);
        let clean_edge = {
            let p = &mesh.positions;
            let t = mesh.triangles[0];
            (p[t[0] as usize] - p[t[1] as usize]).length()
        };
        add_normal_noise(&mut mesh, 0.3, 11);
        let tris = mesh.triangles.to_vec();
        let mut p = mesh.positions.to_vec();
        let topo = Topology::build(p.len(), &tris).unwrap();
        let mut auto = AutoStop::new(&topo, &tris, &p, 1);
        let rel = auto.sigma() / (0.3 * clean_edge);
        assert!((0.8..1.2).contains(&rel), "sigma estimate off by {rel}");
        let st = RingStencils::build(&topo, RING_RADIUS);
        let mut s = Scratch::default();
        let mut tmp = Vec::new();
        let mut stopped = None;
        for k in 1..=100 {
            lowpass_iteration(&topo, &tris, &st, &mut p, 0.5, -0.53, &mut s);
            scalar_taubin_pair(&topo, auto.synthetic_mut(), 0.5, -0.53, &mut tmp);
            if auto.observe(&p).stop {
                stopped = Some(k);
                break;
            }
        }
        let k = stopped.expect("stops");
        assert!((5..=30).contains(&k), "stopped after {k}");
    }
}
