//! Several Jacobi steps per pass over memory, tile by tile (temporal blocking), for `laplacian`
//! and `taubin`.
//!
//! A Jacobi step on a mesh larger than the caches streams the positions and the adjacency through
//! memory once; ten steps stream them ten times, and that traffic, not arithmetic, is what a plain
//! step waits for. Here the (Morton-ordered) vertices are cut into tiles of [`TILE`] consecutive
//! vertices. A round of `k ≤ depth` steps gathers, for each tile, the positions of its own vertices
//! and of the `k` rings of vertices around them into a small local array, runs the `k` steps there
//! (step `s` on the tile and its `k − 1 − s` inner rings, the values the next step still reads) and
//! writes the tile's own vertices back: the mesh passes through memory once per round, the steps
//! run in cache. The rings are computed redundantly by neighbouring tiles; that costs arithmetic,
//! which is cheap next to the traffic saved.
//!
//! A tile's own vertices keep their order, so an *interior* one (all neighbours own) reads its
//! neighbour list straight from the [`Topology`], its ids shifted by the tile's first vertex. The
//! others — own vertices on the tile's edge and the ring vertices — get a local row: the same
//! neighbour list, in the same order, in 16-bit local ids. The kernel does the same floating-point
//! operations in the same order as [`crate::smooth::laplacian::jacobi_step`], so the result is
//! bit-identical to `k` plain steps for any tile size, depth and thread count. Positions are held
//! locally as four lanes (x, y, z, 0), so that a neighbour is added with whole-vector instructions;
//! each lane sees the operations of the scalar kernel.
//!
//! The plan (local rows, ring vertices to gather) is about 6 bytes per vertex on a Morton-ordered
//! surface (5.8 on a 2.6M-vertex sphere with the defaults). The first round builds it, tile by
//! tile in the thread that then runs the tile (one breadth-first pass, its adjacency still in
//! cache for the steps); it lives on the heap, so the engine uses it only when the mesh is in
//! memory. The engine runs the tiles of a round in parallel; this module runs no threads.

use std::cell::RefCell;
use std::ops::Range;
use std::sync::OnceLock;

use glam::DVec3;

use crate::smooth::INV_DEGREE;
use crate::smooth::laplacian::StepStats;
use crate::topology::Topology;

/// Own vertices per tile. With [`DEPTH`] rings a tile of a Morton-ordered surface holds ~1.3× as
/// many vertices (1.29 on a 2.6M-vertex sphere): 2.7 MiB of local positions, in the second- and
/// third-level caches. Tiles of 16,384 fit the second level better but recompute 1.43× the
/// vertices; on the 2-core machine measured both ran at the same speed within noise, 8,192 was
/// slower (overhead 1.61).
pub const TILE: usize = 32768;

/// Most steps per round. Deeper rounds pass over memory less often but recompute more ring
/// vertices and take longer to plan; taubin's iterations are two steps, so an even depth keeps its
/// rounds whole. Depths 4 to 10 ran 10 taubin iterations on 5.2M triangles within noise of each
/// other (the fastest runs all 0.20–0.21 s); 8 keeps the plan small.
pub const DEPTH: usize = 8;

/// Local indices are 16-bit: a tile and its rings may hold at most this many vertices.
const MAX_LOCAL: usize = 1 << 16;

/// The rounds' schedule for one topology: per tile, its rings and local adjacency.
#[derive(Debug, Clone)]
pub struct TilePlan<'t> {
    topo: &'t Topology,
    tile: usize,
    depth: usize,
    /// Each tile's rings and rows, built by the first round that runs it (`None`: it cannot be
    /// planned, see [`TilePlan::new`]).
    tiles: Vec<OnceLock<Option<Tile>>>,
}

#[derive(Debug, Clone, Default)]
struct Tile {
    /// The first own vertex (the tile owns `start .. start + ring_end[0]`).
    start: usize,
    /// Local vertex count after ring `r` (`r = 0`: the own vertices), `depth + 1` entries.
    ring_end: Vec<u32>,
    /// Global ids of the ring vertices, ring by ring, each in order of discovery: local id
    /// `ring_end[0] + j` is vertex `gather[j]`.
    gather: Vec<u32>,
    /// One entry per row `0 .. ring_end[depth - 1]`: [`INTERIOR`] for an own vertex whose
    /// neighbours are all own (read from the topology, local id = global id − `start`), else the
    /// length of its row in `nbrs` (0: a fixed vertex, copied unchanged).
    kinds: Vec<u8>,
    /// Local adjacency of the rows that are not interior, row after row.
    nbrs: Vec<u16>,
    /// Ring 1 as (global id, local id), ascending: where a measuring round finds the corners of
    /// the tile's triangles that are not its own.
    ring1: Vec<(u32, u32)>,
}

/// The kind of a row that reads its neighbours from the topology.
const INTERIOR: u8 = u8::MAX;

/// A position as four lanes, so that a neighbour is added with vector instructions.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(32))]
struct P4([f64; 4]);

impl P4 {
    #[inline(always)]
    fn of(p: DVec3) -> P4 {
        P4([p.x, p.y, p.z, 0.0])
    }

    #[inline(always)]
    fn vec(self) -> DVec3 {
        DVec3::new(self.0[0], self.0[1], self.0[2])
    }
}

impl<'t> TilePlan<'t> {
    /// The plan with the default tile size and depth. Tiles are planned by the first round that
    /// runs them (in the thread that runs them, while their adjacency is in cache), so that round
    /// pays for the plan. A tile cannot be planned when it and its rings exceed the 16-bit local
    /// ids (a vertex order without locality), or a vertex that is not fixed has 255 or more
    /// neighbours or none: [`TilePlan::run_tile`] then returns `None`, and callers run plain
    /// steps, which give the same result.
    pub fn new(topo: &'t Topology) -> TilePlan<'t> {
        TilePlan::lazy(topo, TILE, DEPTH)
    }

    /// A plan for tiles of `tile` own vertices (1 ..= 65,536) and rounds of at most `depth` steps
    /// (≥ 1), its tiles planned as rounds reach them.
    pub fn lazy(topo: &'t Topology, tile: usize, depth: usize) -> TilePlan<'t> {
        assert!((1..=MAX_LOCAL).contains(&tile) && depth >= 1);
        TilePlan {
            topo,
            tile,
            depth,
            tiles: (0..topo.len().div_ceil(tile))
                .map(|_| OnceLock::new())
                .collect(),
        }
    }

    /// Tile `t`, planned if it was not yet.
    fn tile(&self, t: usize) -> Option<&Tile> {
        let own = t * self.tile..((t + 1) * self.tile).min(self.topo.len());
        self.tiles[t]
            .get_or_init(|| {
                RING_IDS.with_borrow_mut(|ids| build_tile(self.topo, own, self.depth, ids))
            })
            .as_ref()
    }

    /// The planned tiles.
    fn planned(&self) -> impl Iterator<Item = &Tile> {
        self.tiles.iter().filter_map(|t| t.get()?.as_ref())
    }

    /// Most steps one round can run.
    pub fn depth(&self) -> usize {
        self.depth
    }

    /// Local vertices over own vertices, summed over the tiles (for tests and tuning).
    pub fn overhead(&self) -> f64 {
        let local: usize = self
            .planned()
            .map(|t| t.ring_end[self.depth] as usize)
            .sum();
        local as f64 / self.topo.len().max(1) as f64
    }

    /// Bytes the plan holds.
    pub fn bytes(&self) -> usize {
        self.planned()
            .map(|t| {
                4 * (t.ring_end.len() + t.gather.len() + 2 * t.ring1.len())
                    + t.kinds.len()
                    + 2 * t.nbrs.len()
            })
            .sum()
    }
}

/// Rings and local adjacency of the tile owning `own`, in one breadth-first pass: expanding the
/// vertices of ring `r − 1` (in local order) discovers ring `r` (local ids in order of discovery)
/// and writes their rows at the same time.
#[inline(never)]
fn build_tile(topo: &Topology, own: Range<usize>, depth: usize, ids: &mut RingIds) -> Option<Tile> {
    let (offsets, vv) = topo.csr();
    let fixed = topo.fixed_mask();
    let nbrs_of = |v: usize| &vv[offsets[v]..offsets[v + 1]];
    let is_own = |u: u32| (u as usize).wrapping_sub(own.start) < own.len();
    ids.clear();
    let mut kinds: Vec<u8> = Vec::with_capacity(own.len() * 5 / 4);
    let mut nbrs: Vec<u16> = Vec::new();
    let mut gather: Vec<u32> = Vec::new();
    let mut ring_end = vec![own.len() as u32];
    // The row of `v`, its neighbours outside the tile joining the next ring. `None`: the tile
    // does not fit 16-bit ids, or the row cannot be expressed (see below).
    let mut row = |v: usize, gather: &mut Vec<u32>| -> Option<u8> {
        let line;
        let nb = if fixed[v] == 0 {
            nbrs_of(v)
        } else {
            if is_own(v as u32) {
                // Every neighbour of an own vertex is in ring 1, so that a measuring round finds
                // the corners of the tile's triangles there; a fixed vertex's row does not
                // discover them all.
                for &u in nbrs_of(v) {
                    if !is_own(u) {
                        let next = own.len() + gather.len();
                        if ids.get_or_insert(u, next as u32) as usize == next {
                            gather.push(u);
                        }
                    }
                }
            }
            match topo.line_neighbors(v as u32) {
                // A crease line vertex: a row of its two crease neighbours, whose mean is
                // `jacobi_step`'s (a sum from zero, times 1/2).
                Some(pair) => {
                    line = pair;
                    &line[..]
                }
                // Copied unchanged: its neighbours are not needed.
                None => return Some(0),
            }
        };
        if nb.is_empty() || nb.len() >= INTERIOR as usize {
            // No neighbour: `jacobi_step` would move it (towards the origin), which an empty row
            // cannot say; 255 or more: the length does not fit the kind byte. Both are left to
            // plain steps.
            return None;
        }
        for &u in nb {
            let l = if is_own(u) {
                u as usize - own.start
            } else {
                let next = own.len() + gather.len();
                let l = ids.get_or_insert(u, next as u32) as usize;
                if l == next {
                    gather.push(u);
                }
                l
            };
            if l >= MAX_LOCAL {
                return None;
            }
            nbrs.push(l as u16);
        }
        Some(nb.len() as u8)
    };
    // Own vertices: interior (every neighbour own: read from the topology, no row here), fixed,
    // or on the edge of the tile (their rows discover ring 1).
    for v in own.clone() {
        let nb = nbrs_of(v);
        let interior = fixed[v] == 0 && !nb.is_empty() && nb.iter().all(|&u| is_own(u));
        kinds.push(if interior {
            INTERIOR
        } else {
            row(v, &mut gather)?
        });
    }
    ring_end.push((own.len() + gather.len()) as u32);
    // Rings 1 .. depth − 1 get rows, which discover the next ring.
    for r in 1..depth {
        let ring = ring_end[r - 1] as usize - own.len()..ring_end[r] as usize - own.len();
        for j in ring {
            // The ring's rows are scattered over the topology's arrays: ask for them ahead.
            if let Some(&v) = gather.get(j + 16) {
                prefetch(&offsets[v as usize]);
            }
            if let Some(&v) = gather.get(j + 8) {
                prefetch(&vv[offsets[v as usize]..]);
            }
            let kind = row(gather[j] as usize, &mut gather)?;
            kinds.push(kind);
        }
        ring_end.push((own.len() + gather.len()) as u32);
    }
    // What the kernel's unchecked reads rely on: a row of ring `r` reads only rings up to `r + 1`,
    // which the step that computes the row has gathered or computed. True by construction (an id
    // is given as the next ring's next vertex); checked, since memory safety rests on it.
    let mut at = 0;
    for (i, &kind) in kinds.iter().enumerate() {
        if kind != INTERIOR {
            let ring = ring_end.partition_point(|&e| e as usize <= i);
            let row = &nbrs[at..at + kind as usize];
            assert!(row.iter().all(|&l| (l as u32) < ring_end[ring + 1]));
            at += kind as usize;
        }
    }
    let mut ring1: Vec<(u32, u32)> = gather[..ring_end[1] as usize - own.len()]
        .iter()
        .zip(own.len() as u32..)
        .map(|(&g, l)| (g, l))
        .collect();
    ring1.sort_unstable();
    Some(Tile {
        start: own.start,
        ring_end,
        gather,
        kinds,
        nbrs,
        ring1,
    })
}

/// Hint the CPU to bring the cache line at `p` closer (no effect on results).
#[inline(always)]
fn prefetch<T: ?Sized>(p: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch only hints the cache; `p` is a valid reference anyway.
    unsafe {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        _mm_prefetch::<_MM_HINT_T0>((p as *const T).cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Global id → local id of one tile's ring vertices (open addressing, linear probing); reused
/// from tile to tile by each thread.
#[derive(Default)]
struct RingIds {
    keys: Vec<u32>,
    values: Vec<u32>,
    len: usize,
}

impl RingIds {
    const EMPTY: u32 = u32::MAX;

    fn clear(&mut self) {
        if self.keys.is_empty() {
            self.keys = vec![Self::EMPTY; 1 << 12];
            self.values = vec![0; 1 << 12];
        } else {
            self.keys.fill(Self::EMPTY);
        }
        self.len = 0;
    }

    /// The slot of `u`, or the empty slot where it would go.
    fn slot(&self, u: u32) -> usize {
        let mask = self.keys.len() - 1;
        let mut i = (u.wrapping_mul(0x9e37_79b1) as usize) & mask;
        while self.keys[i] != u && self.keys[i] != Self::EMPTY {
            i = (i + 1) & mask;
        }
        i
    }

    /// The value of `u`; if absent, `u` is added with `value`, which is returned.
    fn get_or_insert(&mut self, u: u32, value: u32) -> u32 {
        let i = self.slot(u);
        if self.keys[i] == u {
            return self.values[i];
        }
        self.keys[i] = u;
        self.values[i] = value;
        self.len += 1;
        if 2 * self.len > self.keys.len() {
            let old: Vec<(u32, u32)> = self
                .keys
                .iter()
                .zip(&self.values)
                .filter(|(k, _)| **k != Self::EMPTY)
                .map(|(&k, &v)| (k, v))
                .collect();
            self.keys = vec![Self::EMPTY; 2 * self.keys.len()];
            self.values = vec![0; self.keys.len()];
            for (k, v) in old {
                let i = self.slot(k);
                self.keys[i] = k;
                self.values[i] = v;
            }
        }
        value
    }
}

/// Per-thread local arrays, kept between tiles and rounds.
#[derive(Default)]
struct Local {
    a: Vec<P4>,
    b: Vec<P4>,
    before: Vec<P4>,
}

thread_local! {
    static LOCAL: RefCell<Local> = RefCell::new(Local::default());
    static RING_IDS: RefCell<RingIds> = RefCell::new(RingIds::default());
}

impl TilePlan<'_> {
    /// Vertices per tile: tile `t` owns vertices `t · tile_size ..` (the last tile may be shorter).
    pub fn tile_size(&self) -> usize {
        self.tile
    }

    /// One round on tile `t`: `factors.len()` Jacobi steps `p ← p + f L(p)` (one factor per step,
    /// at most [`TilePlan::depth`]) from `src` into `out`, the tile's own vertices of the result
    /// (`out.len()` = the tile's length). Plans the tile first if no round has yet. With a
    /// [`Measure`] also measures the iterations it names, one [`Measured`] each, in order. The
    /// positions are bit-identical to the steps run one by one with
    /// [`crate::smooth::laplacian::jacobi_step`]. `None` when the tile cannot be planned (see
    /// [`TilePlan::new`]): then `out` is untouched.
    ///
    /// # Panics
    /// If `src` does not have one entry per vertex, or there are more factors than the depth (one
    /// less when the volume is measured).
    pub fn run_tile(
        &self,
        t: usize,
        src: &[DVec3],
        out: &mut [DVec3],
        factors: &[f64],
        measure: Option<Measure>,
    ) -> Option<Vec<Measured>> {
        assert!(src.len() == self.topo.len());
        let extra = measure.is_some_and(|m| m.volume.is_some()) as usize;
        assert!(!factors.is_empty() && factors.len() + extra <= self.depth);
        assert!(measure.is_none_or(|m| m.per > 0 && m.block > 0));
        let tile = self.tile(t)?;
        Some(
            LOCAL.with_borrow_mut(|local| {
                run_tile(self.topo, tile, src, out, factors, measure, local)
            }),
        )
    }
}

/// What a round measures: each iteration (`per` steps) whose bit is set in `iterations` (bit `j`
/// for steps `j · per .. (j + 1) · per` of the round), from its start to its end.
#[derive(Debug, Clone, Copy)]
pub struct Measure<'m> {
    pub per: usize,
    pub iterations: u64,
    /// How far each own vertex moved, summed per block of `block` vertices (blocks start at
    /// multiples of `block`, so that folding them in order gives the same sums as plain steps
    /// measured over chunks of that size).
    pub block: usize,
    /// The triangles, sorted by their first corner (their smallest), and an origin: then also the
    /// sums of the determinants about the origin and of the doubled areas of the tile's
    /// triangles (those whose first corner it owns), in their order. The round then keeps ring
    /// 1 exact to its end, so it runs at most `depth − 1` steps.
    pub volume: Option<(&'m [[u32; 3]], DVec3)>,
}

/// What a round measured of one iteration on one tile.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    /// Per block of the own vertices; `moved` counts those that are not fixed.
    pub blocks: Vec<StepStats>,
    /// `(Σ det, Σ doubled area)` over the tile's triangles, with [`Measure::volume`].
    pub sums: Option<(f64, f64)>,
}

fn run_tile(
    topo: &Topology,
    tile: &Tile,
    src: &[DVec3],
    out: &mut [DVec3],
    factors: &[f64],
    measure: Option<Measure>,
    local: &mut Local,
) -> Vec<Measured> {
    let k = factors.len();
    let own = tile.ring_end[0] as usize;
    // Measuring the volume keeps ring 1 exact through the last step: one ring more each step.
    let extra = measure.is_some_and(|m| m.volume.is_some()) as usize;
    let len = tile.ring_end[k + extra] as usize;
    let Local { a, b, before } = local;
    if a.len() < len {
        a.resize(len, P4::default());
        b.resize(len, P4::default());
    }
    for (l, p) in a.iter_mut().zip(&src[tile.start..tile.start + own]) {
        *l = P4::of(*p);
    }
    let gather = &tile.gather[..len - own];
    for (j, (l, &g)) in a[own..len].iter_mut().zip(gather).enumerate() {
        if let Some(&ahead) = gather.get(j + 8) {
            prefetch(&src[ahead as usize]);
        }
        *l = P4::of(src[g as usize]);
    }
    let (offsets, vv) = topo.csr();
    let interior = Interior {
        offsets: &offsets[tile.start..tile.start + own + 1],
        vv,
        start: tile.start,
    };
    let mut measured = Vec::new();
    let per = measure.map_or(1, |m| m.per);
    // Whether iteration `j` of the round is measured.
    let named = |j: usize| measure.is_some_and(|m| j < 64 && m.iterations >> j & 1 == 1);
    for (s, &f) in factors.iter().enumerate() {
        if s % per == 0 && named(s / per) {
            before.clear();
            before.extend_from_slice(&a[..own]);
        }
        // Step `s` updates the rows the following steps still read: the own vertices and the
        // rings inside ring `k − s` (one more when measuring the volume).
        let rows = tile.ring_end[k - 1 - s + extra] as usize;
        let reach = tile.ring_end[k - s + extra] as usize;
        relax(
            &interior,
            &tile.kinds[..rows],
            &tile.nbrs,
            &a[..reach],
            &mut b[..rows],
            f,
        );
        std::mem::swap(a, b);
        if let Some(m) = measure
            && s % per == per - 1
            && named(s / per)
        {
            measured.push(Measured {
                blocks: moves(tile, &a[..own], before, m.block),
                sums: m.volume.map(|(tris, origin)| sums(tile, a, tris, origin)),
            });
        }
    }
    for (o, l) in out.iter_mut().zip(&a[..own]) {
        *o = l.vec();
    }
    measured
}

/// How far each own vertex moved from `before` to `now`, per block of `block` vertices.
fn moves(tile: &Tile, now: &[P4], before: &[P4], block: usize) -> Vec<StepStats> {
    let mut blocks = Vec::new();
    let mut i = 0;
    while i < now.len() {
        let end = now.len().min(i + block - (tile.start + i) % block);
        let mut st = StepStats::default();
        for j in i..end {
            let d = now[j].vec().distance(before[j].vec());
            st.moved += (tile.kinds[j] != 0) as u64;
            st.max_displacement = st.max_displacement.max(d);
            st.sum_displacement += d;
        }
        blocks.push(st);
        i = end;
    }
    blocks
}

/// `(Σ det(a − o, b − o, c − o), Σ |(b − a) × (c − a)|)` over the triangles whose first corner the
/// tile owns (a run of `tris`, sorted by it), in their order, from the local positions `at` (own
/// and ring 1), with [`crate::metrics::determinant_and_area_by`]'s arithmetic.
fn sums(tile: &Tile, at: &[P4], tris: &[[u32; 3]], o: DVec3) -> (f64, f64) {
    let own = tile.ring_end[0] as usize;
    let first = |v: usize| tris.partition_point(|t| (t[0] as usize) < v);
    let run = &tris[first(tile.start)..first(tile.start + own)];
    let (start, ring1) = (tile.start, &tile.ring1[..]);
    let corner = move |v: u32| -> DVec3 {
        let l = (v as usize).wrapping_sub(start);
        if l < own {
            return at[l].vec();
        }
        // A triangle's corners are neighbours, so a corner that is not own is in ring 1.
        match ring1.binary_search_by_key(&v, |&(g, _)| g) {
            Ok(k) => at[ring1[k].1 as usize].vec(),
            Err(_) => DVec3::NAN,
        }
    };
    crate::metrics::determinant_and_area_by(run, corner, o)
}

/// Where the interior rows of a tile find their neighbours: the topology's adjacency of the own
/// vertices `start ..`, whose ids minus `start` are local ids.
struct Interior<'a> {
    offsets: &'a [usize],
    vv: &'a [u32],
    start: usize,
}

/// One step over the rows `0 .. kinds.len()` of a tile (its own vertices and inner rings, up to
/// ring `r`), reading `src` (the local vertices up to ring `r + 1`) and writing `dst`. The same
/// operations, in the same order, as the scalar kernel (a sum from zero in adjacency order, then
/// `p + f (sum / deg − p)`), lane by lane. With AVX a neighbour is one 4-lane add.
fn relax(inner: &Interior, kinds: &[u8], nbrs: &[u16], src: &[P4], dst: &mut [P4], f: f64) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (just checked).
        return unsafe { relax_avx(inner, kinds, nbrs, src, dst, f) };
    }
    relax_lanes(inner, kinds, nbrs, src, dst, f)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn relax_avx(
    inner: &Interior,
    kinds: &[u8],
    nbrs: &[u16],
    src: &[P4],
    dst: &mut [P4],
    f: f64,
) {
    relax_lanes(inner, kinds, nbrs, src, dst, f)
}

#[inline(always)]
fn relax_lanes(inner: &Interior, kinds: &[u8], nbrs: &[u16], src: &[P4], dst: &mut [P4], f: f64) {
    // Every step computes at least the own vertices, and `src` holds the rows and the next ring.
    let own = inner.offsets.len() - 1;
    assert!(kinds.len() == dst.len() && src.len() >= dst.len() && dst.len() >= own);
    let mut nbrs = nbrs;
    let (dst_own, dst_rings) = dst.split_at_mut(own);
    let (kinds_own, kinds_rings) = kinds.split_at(own);
    let rows = dst_own.iter_mut().zip(kinds_own).zip(&src[..own]);
    // The own vertices' positions indexed by global id: `own_base + u` is `src[u − start]` for
    // an own vertex `u` (one address computation less per neighbour than the subtraction).
    let own_base = src.as_ptr().wrapping_sub(inner.start);
    for (((out, &kind), p), w) in rows.zip(inner.offsets.windows(2)) {
        *out = if kind == INTERIOR {
            let row = &inner.vv[w[0]..w[1]];
            // SAFETY: `build_tile` marks a row interior only when every neighbour is an own
            // vertex, so `start ≤ u < start + own` and `own_base + u` is `src[u − start]`, in
            // bounds (`own ≤ src.len()`, asserted above) and derived from `src`.
            let sum = row_sum(row, |u| unsafe { *own_base.wrapping_add(u as usize) });
            let d = row.len();
            let inv = if d < INV_DEGREE.len() {
                INV_DEGREE[d]
            } else {
                1.0 / d as f64
            };
            relaxed(*p, sum, inv, f)
        } else {
            local_row(kind, &mut nbrs, src, *p, f)
        };
    }
    for ((out, &kind), p) in dst_rings.iter_mut().zip(kinds_rings).zip(&src[own..]) {
        *out = local_row(kind, &mut nbrs, src, *p, f);
    }
}

/// A row of `kind` local neighbours taken from the front of `nbrs` (0: a fixed vertex).
#[inline(always)]
fn local_row(kind: u8, nbrs: &mut &[u16], src: &[P4], p: P4, f: f64) -> P4 {
    if kind == 0 {
        return p;
    }
    let (row, rest) = nbrs.split_at(kind as usize);
    *nbrs = rest;
    // SAFETY: `build_tile` checked that a row of ring `r` names only local vertices of rings up
    // to `r + 1`, which is what `src` holds (`run_tile` passes `a[..ring_end[r + 1]]` with the
    // rows up to ring `r`).
    let sum = row_sum(row, |u| unsafe { *src.get_unchecked(u as usize) });
    relaxed(p, sum, INV_DEGREE[kind as usize], f)
}

/// The sum of the positions of a row, from zero, in the row's order. Degrees 5 to 7 (most vertices
/// of a surface) are unrolled: no loop branch, and the same additions in the same order.
#[inline(always)]
fn row_sum<T: Copy>(row: &[T], get: impl Fn(T) -> P4) -> [f64; 4] {
    #[inline(always)]
    fn unrolled<const K: usize, T: Copy>(row: &[T], get: &impl Fn(T) -> P4) -> [f64; 4] {
        let mut sum = [0.0f64; 4];
        if let Ok(row) = <&[T; K]>::try_from(row) {
            for &u in row {
                add(&mut sum, &get(u));
            }
        }
        sum
    }
    match row.len() {
        5 => unrolled::<5, T>(row, &get),
        6 => unrolled::<6, T>(row, &get),
        7 => unrolled::<7, T>(row, &get),
        _ => {
            let mut sum = [0.0f64; 4];
            for &u in row {
                add(&mut sum, &get(u));
            }
            sum
        }
    }
}

#[inline(always)]
fn add(sum: &mut [f64; 4], q: &P4) {
    for (s, x) in sum.iter_mut().zip(q.0) {
        *s += x;
    }
}

/// `p + f (sum · inv − p)`, lane by lane: the scalar kernel's expression.
#[inline(always)]
fn relaxed(p: P4, sum: [f64; 4], inv: f64, f: f64) -> P4 {
    let mut r = [0.0f64; 4];
    for l in 0..4 {
        r[l] = p.0[l] + f * (sum[l] * inv - p.0[l]);
    }
    P4(r)
}
