//! `vcs-lowpass`: Taubin's λ|μ low-pass displacement as the first step of Liu et al.'s 2-step
//! approach (§4 of the paper: any operator may be the first step, the second restores the
//! volume exactly), the volume restored block by block; see docs/quality-research.md for the
//! evidence and the numbers. This is the engine's kernel ([`sweep_blocks`]), which
//! `Method::VcsLowpass` runs patch by patch through `engine::iterate` (`vcs-guided` keeps the
//! 2-ring stencils of [`super::rings`]). The sequential whole-mesh reference it is tested against
//! is test code (`tests/oracles/lowpass.rs`).
//!
//! One iteration on positions `P`:
//! 1. `D = T(P) − P`, `T` = Taubin's λ then μ umbrella step, Jacobi, fixed vertices kept; a
//!    crease line vertex takes the steps of its line (`laplacian::jacobi_step`), so that it
//!    moves along its crease, and is movable below.
//! 2. The vertices of each patch are cut evenly into blocks of [`BLOCK`] to `2 · BLOCK − 1`
//!    consecutive ids of the plan's (Morton) order ([`blocks`]; a patch shorter than [`BLOCK`]
//!    is one block). Gauss–Seidel over the blocks, ascending: the block's movable vertices `M`
//!    move by `D` (step 1); then each `u ∈ M` moves by a common distance `s` along `e_u`, the
//!    direction of the volume gradient of `u` (its faces' `p_b × p_c`, after step 1), with `s`
//!    the root near zero of the faces' volume change, which is a cubic in `s` (step 2). The faces
//!    touching `M` so keep their volume exactly, and with them the whole mesh.
//!
//! Why blocks, and why an offset rather than a translation: step 2 removes the block's mean
//! normal motion. Over a few vertices that is much of each vertex's denoising (noise changes
//! sign from vertex to vertex); over thousands the noise averages out and what is removed is the
//! low-frequency shrink or inflation, which is what should be removed. A common translation (the
//! edge stencils' step 2) is linear in the volume but cancels on a block that wraps a thin part
//! (its two sides' gradients point apart), where it would push the block sideways; an offset
//! along each vertex's own normal pushes both sides out. Each face is visited twice per block
//! (the volume and gradients, then the cubic's higher terms), so an iteration costs a small
//! multiple of a Taubin iteration.
//!
//! What a block reads and writes (the schedule's conflict rule rests on it): it writes its own
//! vertices, which are owned by its patch, and reads the corners of their faces (one ring out);
//! the edge stencils' colouring covers that. It also reads the λ step's positions of its
//! vertices and their neighbours, an array no block writes.

use std::ops::Range;

use glam::DVec3;

use rayon::prelude::*;

use super::laplacian::{self, StepStats};
use super::method::{PatchMesh, PatchSweep};
use super::stencil::{self, Outcome};
use super::{Field, PatchField, SweepStats};
use crate::topology::{Topology, TopologyParts, corners_after};

/// Vertices per block, at least: a patch is cut evenly into blocks of consecutive vertices of
/// the plan's (Morton) order, each of `BLOCK` to `2 · BLOCK − 1` vertices unless the patch is
/// shorter ([`blocks`]).
pub const BLOCK: u32 = 4096;

/// Rounds of a block under a deviation bound: each round leaves out the members that would end
/// beyond it; a block that still has some after these is skipped.
const DEVIATION_ROUNDS: usize = 8;

/// Newton steps for the block's offset: the cubic is nearly linear (the offset is small against
/// the block), so two steps reach rounding; the rest are a margin.
const NEWTON_STEPS: usize = 4;

/// One block: its vertices, and the triangles whose smallest corner it holds when the triangles
/// are sorted by it (a run of the array).
struct Block {
    vertices: Range<u32>,
    own: Option<Range<u32>>,
}

/// A face with two or three members: its corners, and whether `b` and `c` are members (`a` is).
#[derive(Debug, Clone, Copy, Default)]
struct Shared {
    corners: [u32; 3],
    mb: bool,
    mc: bool,
}

/// A block's scratch space, reused from block to block.
#[derive(Debug, Default)]
struct Scratch {
    /// Per member: whether it moves (movable, and not left out by the deviation bound).
    free: Vec<bool>,
    /// Per member: where step 1 takes it (absolute).
    target: Vec<V4>,
    /// Per member: where it is before step 1, about the block's origin.
    here: Vec<V4>,
    /// Per member: its volume gradient after step 1, then that gradient's direction.
    dir: Vec<V4>,
    /// Per member: where step 1 puts it, about the block's origin.
    moved: Vec<V4>,
    /// Per member: its whole move (step 1 and the offset; zero for one that does not move).
    step: Vec<V4>,
    /// The faces with two or three members, corners in the order [`corners_after`] gives from
    /// the first: the only ones the cubic's higher terms need. Slots for every face of every
    /// member, filled from the front.
    shared: Vec<Shared>,
}

/// The blocks of the patch `owned`, ascending, Gauss–Seidel (each sees the latest positions):
/// [`apply_block`], step 1 taking each vertex to one Jacobi step `μ` from `half` (Taubin's λ step
/// from the iteration's positions: the pair's second step is taken here, by each block for its
/// vertices, so that it needs no array of its own). With `measure`, also how far the vertices
/// moved: each is written by its own block alone, once, so its move is measured as it is written.
#[allow(clippy::too_many_arguments)]
pub fn sweep_blocks<P: Field + ?Sized, D: Field + ?Sized>(
    mesh: PatchMesh,
    pos: &mut P,
    half: &D,
    mu: f64,
    owned: Range<u32>,
    deviation: Option<stencil::Deviation>,
    measure: bool,
) -> PatchSweep {
    let (topo, triangles) = (mesh.topo.parts(), mesh.tris);
    let mut stats = SweepStats::default();
    let mut moved = measure.then(StepStats::default);
    let mut scratch = Scratch::default();
    for vertices in blocks(owned) {
        let (lo, hi) = (vertices.start, vertices.end);
        // The faces whose smallest corner is in the block, when the triangles are sorted by it.
        let own = mesh.sorted.then(|| {
            let from = |v: u32| triangles.partition_point(|t| t[0] < v) as u32;
            from(lo)..from(hi)
        });
        let block = Block {
            vertices: lo..hi,
            own,
        };
        let outcome = apply_block(
            &topo,
            triangles,
            pos,
            (half, mu),
            block,
            deviation,
            &mut scratch,
            moved.as_mut(),
        );
        stencil::count(&mut stats, outcome);
    }
    PatchSweep {
        stencils: stats,
        moved,
    }
}

/// The λ step of the vertices `border` (ascending) from `pos` into `out`, one entry each in
/// that order: the bits [`laplacian::jacobi_step`] gives them, in parallel chunks (each entry
/// depends only on `pos`). Taken before the sweep, for the vertices whose step a patch cannot take
/// when it starts ([`patch_step`]).
pub fn border_step(topo: &Topology, pos: &[DVec3], border: &[u32], out: &mut [DVec3], lambda: f64) {
    // Chunks of a few pages of output each: enough work per task, any split the same bits.
    const CHUNK: usize = 4096;
    let parts = topo.parts();
    out.par_chunks_mut(CHUNK)
        .zip(border.par_chunks(CHUNK))
        .for_each(|(out, ids)| {
            for (o, &v) in out.iter_mut().zip(ids) {
                *o = laplacian::jacobi_at(&parts, pos, v, lambda);
            }
        });
}

/// The λ step that the blocks of the patch of `vertices` read (its vertices' and their
/// neighbours'), held by the patch: the step of a vertex whose neighbours are all in the patch
/// from `pos` as the patch starts (only the patch's blocks move its vertices, and none has run),
/// every other's from `values`, the step of the vertices `border` (ascending) that
/// [`border_step`] took before the sweep, when no patch had moved any. The same bits as the step
/// of the whole mesh from the sweep's start.
pub fn patch_step<P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    pos: &P,
    border: &[u32],
    values: &S,
    vertices: Range<u32>,
    lambda: f64,
) -> PatchField {
    let parts = topo.parts();
    let value = |k: usize| values.get(k as u32);
    let first = border.partition_point(|&b| b < vertices.start);
    let mut next = first;
    let inner = vertices
        .clone()
        .map(|v| match border.get(next) == Some(&v) {
            true => {
                next += 1;
                value(next - 1)
            }
            false => laplacian::jacobi_at(&parts, pos, v, lambda),
        })
        .collect();
    // The neighbours outside the patch: those of its border vertices (`first .. next`).
    let ring = super::neighbors_outside(topo, border[first..next].iter().copied(), &vertices);
    let outer = ring
        .iter()
        .map(|u| {
            let k = border.binary_search(u);
            value(k.expect("a neighbour in another patch is on the border"))
        })
        .collect();
    PatchField::new(vertices.start, inner, ring, outer)
}

/// The blocks of the vertex range `owned`, ascending: `⌊len / BLOCK⌋` blocks (one when the range
/// is shorter), `owned` cut evenly, block `k` starting at `len · k / count`. So every block has
/// [`BLOCK`] to `2 · BLOCK − 1` vertices unless the whole range is shorter, and a patch of a
/// multiple of [`BLOCK`] (the default patch) is cut into blocks of exactly [`BLOCK`].
///
/// Not a full run of [`BLOCK`] and a short rest: a block keeps its faces' volume exactly, so
/// what it leaves of its vertices' denoising along the normals is their mean over the block
/// (noise that averages out over thousands of vertices and not over a few). A rest of a few
/// vertices kept them near their noisy places; it sat at the end of the patch's Morton range,
/// which for the mesh's last patch is the far corner of the bounding box: often the tip of a
/// thin part, where it was the largest distance to the clean surface (docs/quality-research.md
/// §16).
pub fn blocks(owned: Range<u32>) -> impl Iterator<Item = Range<u32>> {
    let len = u64::from(owned.end.saturating_sub(owned.start));
    let count = (len / u64::from(BLOCK)).max(1);
    let at = move |k: u64| owned.start + (len * k / count) as u32;
    (0..count)
        .map(move |k| at(k)..at(k + 1))
        .filter(|b| !b.is_empty())
}

/// One block (see the module doc): its free members move to one Jacobi step `μ` from the λ step's
/// positions (`lambda_step`: those positions and `μ`; step 1: a vertex is moved only by its own
/// block, so its position is still the iteration's, and the λ step's is from it), then each by the
/// common distance `s` along its own unit volume gradient, `s` the root of the faces' volume
/// change, a cubic in `s`, found by Newton from the linear solution. Under a deviation bound the
/// members that would end beyond it are held back (they do not move) and the rest is solved
/// again: the outcome is then [`Outcome::DeviationLimited`], though the others moved. Writes
/// nothing when the outcome is a skip.
///
/// With AVX2 the same code is compiled for it: a vector's three coordinates are lanes of one
/// register, every operation lane by lane as the scalar code does it (the bits do not change).
#[allow(clippy::too_many_arguments)]
fn apply_block<P: Field + ?Sized, D: Field + ?Sized>(
    topo: &TopologyParts,
    triangles: &[[u32; 3]],
    pos: &mut P,
    lambda_step: (&D, f64),
    block: Block,
    deviation: Option<stencil::Deviation>,
    scratch: &mut Scratch,
    moves: Option<&mut StepStats>,
) -> Outcome {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (just checked).
        return unsafe {
            apply_block_avx2(
                topo,
                triangles,
                pos,
                lambda_step,
                block,
                deviation,
                scratch,
                moves,
            )
        };
    }
    apply_block_lanes(
        topo,
        triangles,
        pos,
        lambda_step,
        block,
        deviation,
        scratch,
        moves,
    )
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
unsafe fn apply_block_avx2<P: Field + ?Sized, D: Field + ?Sized>(
    topo: &TopologyParts,
    triangles: &[[u32; 3]],
    pos: &mut P,
    lambda_step: (&D, f64),
    block: Block,
    deviation: Option<stencil::Deviation>,
    scratch: &mut Scratch,
    moves: Option<&mut StepStats>,
) -> Outcome {
    apply_block_lanes(
        topo,
        triangles,
        pos,
        lambda_step,
        block,
        deviation,
        scratch,
        moves,
    )
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn apply_block_lanes<P: Field + ?Sized, D: Field + ?Sized>(
    topo: &TopologyParts,
    triangles: &[[u32; 3]],
    pos: &mut P,
    lambda_step: (&D, f64),
    block: Block,
    deviation: Option<stencil::Deviation>,
    scratch: &mut Scratch,
    mut moves: Option<&mut StepStats>,
) -> Outcome {
    let Block {
        vertices: block,
        own,
    } = block;
    let (start, len) = (block.start, block.len());
    scratch.free.clear();
    scratch
        .free
        .extend(block.clone().map(|u| topo.is_free_or_on_line(u)));
    if !scratch.free.contains(&true) {
        return Outcome::SkippedFixed;
    }
    let origin = V4::of(pos.get(start));
    // Step 1's target, the second step of the pair from the first's result (computed here
    // rather than stored: an array of the mesh's size less).
    let (half, mu) = lambda_step;
    scratch.target.clear();
    scratch.target.extend(
        block
            .clone()
            .map(|u| V4::of(laplacian::jacobi_at(topo, half, u, mu))),
    );
    let mut held_back = false;
    let slots = topo.faces_bound(block.clone());
    for _ in 0..DEVIATION_ROUNDS {
        let Scratch {
            free,
            target,
            here,
            dir,
            moved,
            step,
            shared,
        } = &mut *scratch;
        // Cut to the block's length: a member's test (`k < len`) proves its indices in bounds.
        let free = &free[..len];
        let all_free = free.iter().all(|&f| f);
        let own = own.clone().filter(|_| all_free);
        // The closures below take copies (`move`): what they read by reference the compiler
        // loaded again after every store of the passes, with each index's bounds check.
        let read: &P = pos;
        let at = move |u: u32| V4::of(read.get(u));
        // A member's index in the block's arrays (ids below the block wrap to beyond it).
        let local = move |u: u32| u.wrapping_sub(start) as usize;
        // Step 1's displacement (computed here rather than stored: one pass over memory less).
        let target = &target[..len];
        let disp = move |u: u32| target[local(u)] - at(u);
        let member = move |u: u32| {
            let k = local(u);
            k < len && (all_free || free[k])
        };
        here.clear();
        here.extend(block.clone().map(|u| at(u) - origin));
        let here = &here[..len];
        moved.clear();
        moved.extend(block.clone().zip(here).map(|(u, &h)| h + disp(u)));
        let moved = &moved[..len];
        // Where a corner is before and after step 1, about the origin.
        let before = move |u: u32, m: bool| {
            if m { here[local(u)] } else { at(u) - origin }
        };
        let after = move |u: u32, m: bool| {
            if m { moved[local(u)] } else { at(u) - origin }
        };
        // Pass 1: the volume change of step 1 and each member's gradient, every face touching a
        // member once (at its smallest member corner), in the order of the members and of each
        // member's faces (ascending).
        dir.clear();
        dir.resize(len, V4::default());
        let dir = &mut dir[..len];
        // No more faces than the topology's bound for the block: written by index into a slice, whose
        // pointer stays in a register (a push loaded the vector's pointer, length and capacity).
        if shared.len() < slots {
            shared.resize(slots, Shared::default());
        }
        let shared = &mut shared[..slots];
        let mut count = 0;
        let mut dv = 0.0;
        // A macro rather than a closure: the compiler would not inline the closure here.
        macro_rules! face {
            ($a:expr, $pa:expr, $qa:expr, $b:expr, $c:expr, $mb:expr, $mc:expr) => {{
                let (a, b, c, mb, mc): (u32, u32, u32, bool, bool) = ($a, $b, $c, $mb, $mc);
                let (pa, qa): (V4, V4) = ($pa, $qa);
                let (pb, pc) = (before(b, mb), before(c, mc));
                let (qb, qc) = (after(b, mb), after(c, mc));
                let bc = qb.cross(qc);
                dv += qa.dot(bc) - pa.dot(pb.cross(pc));
                dir[local(a)] += bc;
                if mb {
                    dir[local(b)] += qc.cross(qa);
                }
                if mc {
                    dir[local(c)] += qa.cross(qb);
                }
                if mb || mc {
                    shared[count] = Shared {
                        corners: [a, b, c],
                        mb,
                        mc,
                    };
                    count += 1;
                }
            }};
        }
        if let Some(own) = own {
            // Every member free: a face is taken at its smallest corner in the block. Those whose
            // smallest corner is in the block are `own` (sorted by first corner, which is the
            // smallest), a run per member, after its faces from below the block, which come
            // first in its ascending list: the same faces in the same order as the general walk.
            // A loop of its own: folded into the general walk (a bound and an empty run for the
            // other blocks) the sweep ran 12 % more instructions.
            let run = &triangles[own.start as usize..own.end as usize];
            let mut next = 0;
            // Every member free: a test of the range alone, which proves the index in bounds.
            let member = move |u: u32| local(u) < len;
            for a in block.clone() {
                let (pa, qa) = (here[local(a)], moved[local(a)]);
                crate::for_each_face!(topo, a, triangles, own.start, |_t, tri| {
                    let (b, c) = corners_after(tri, a);
                    let (mb, mc) = (member(b), member(c));
                    if !((mb && b < a) || (mc && c < a)) {
                        face!(a, pa, qa, b, c, mb, mc);
                    }
                });
                while let Some(&[first, b, c]) = run.get(next)
                    && first == a
                {
                    face!(a, pa, qa, b, c, member(b), member(c));
                    next += 1;
                }
            }
            debug_assert_eq!(next, run.len(), "the block's faces are a run");
        } else {
            for a in block.clone() {
                if !member(a) {
                    continue;
                }
                let (pa, qa) = (here[local(a)], moved[local(a)]);
                crate::for_each_face!(topo, a, triangles, u32::MAX, |_t, tri| {
                    let (b, c) = corners_after(tri, a);
                    let (mb, mc) = (member(b), member(c));
                    if !((mb && b < a) || (mc && c < a)) {
                        face!(a, pa, qa, b, c, mb, mc);
                    }
                });
            }
        }
        // The offset's linear coefficient is Σ |gradient|; the directions are made unit.
        let mut c1 = 0.0;
        for g in dir.iter_mut() {
            let l = g.dot(*g).sqrt();
            if l > 0.0 {
                c1 += l;
                *g = g.div(l);
            }
        }
        let dir = &*dir;
        let unit = move |u: u32, m: bool| {
            if m { dir[local(u)] } else { V4::default() }
        };
        // Pass 2: the quadratic and cubic coefficients, from the faces with two or three members.
        let (mut c2, mut c3) = (0.0, 0.0);
        for &Shared {
            corners: [a, b, c],
            mb,
            mc,
        } in &shared[..count]
        {
            let (qa, qb, qc) = (moved[local(a)], after(b, mb), after(c, mc));
            let (ea, eb, ec) = (dir[local(a)], unit(b, mb), unit(c, mc));
            let ebc = eb.cross(ec);
            c2 += ea.dot(eb.cross(qc)) + ea.dot(qb.cross(ec)) + qa.dot(ebc);
            c3 += ea.dot(ebc);
        }
        let Some(s) = offset(dv, c1, c2, c3) else {
            return Outcome::SkippedDegenerate;
        };
        step.clear();
        step.extend(block.clone().map(|u| match member(u) {
            true => disp(u) + unit(u, true).mul(s),
            false => V4::default(),
        }));
        if !scratch.step.iter().all(|d| d.vec().is_finite()) {
            return Outcome::SkippedDegenerate;
        }
        if let Some(bound) = deviation {
            let limit2 = bound.limit * bound.limit;
            let mut out = false;
            for (k, u) in block.clone().enumerate() {
                let end = pos.get(u) + scratch.step[k].vec();
                let beyond = (end - bound.input[u as usize]).length_squared();
                if scratch.free[k] && beyond > limit2 {
                    scratch.free[k] = false;
                    out = true;
                }
            }
            if out {
                held_back = true;
                if !scratch.free.contains(&true) {
                    return Outcome::DeviationLimited;
                }
                continue;
            }
        }
        for (k, u) in block.clone().enumerate() {
            if scratch.free[k] {
                let was = pos.get(u);
                let now = was + scratch.step[k].vec();
                pos.set(u, now);
                if let Some(m) = moves.as_deref_mut() {
                    let d = now.distance(was);
                    m.moved += 1;
                    m.max_displacement = m.max_displacement.max(d);
                    m.sum_displacement += d;
                }
            }
        }
        return if held_back {
            Outcome::DeviationLimited
        } else {
            Outcome::Applied
        };
    }
    Outcome::DeviationLimited
}

/// A vector as four lanes (the last zero), so that the compiler keeps it in one register: each
/// operation is `DVec3`'s, lane by lane, its sums in `DVec3`'s order (the same bits).
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(32))]
struct V4([f64; 4]);

impl V4 {
    #[inline(always)]
    fn of(p: DVec3) -> V4 {
        V4([p.x, p.y, p.z, 0.0])
    }

    #[inline(always)]
    fn vec(self) -> DVec3 {
        DVec3::new(self.0[0], self.0[1], self.0[2])
    }

    #[inline(always)]
    fn lanes(self, o: V4, f: impl Fn(f64, f64) -> f64) -> V4 {
        let (a, b) = (self.0, o.0);
        V4([f(a[0], b[0]), f(a[1], b[1]), f(a[2], b[2]), f(a[3], b[3])])
    }

    /// `self.yzx · o.zxy − o.yzx · self.zxy`: `DVec3::cross` lane by lane.
    #[inline(always)]
    fn cross(self, o: V4) -> V4 {
        let [x, y, z, w] = self.0;
        let [ox, oy, oz, ow] = o.0;
        let l = V4([y, z, x, w]).lanes(V4([oz, ox, oy, ow]), |p, q| p * q);
        let r = V4([oy, oz, ox, ow]).lanes(V4([z, x, y, w]), |p, q| p * q);
        l - r
    }

    #[inline(always)]
    fn dot(self, o: V4) -> f64 {
        let p = self.lanes(o, |p, q| p * q).0;
        p[0] + p[1] + p[2]
    }

    #[inline(always)]
    fn mul(self, s: f64) -> V4 {
        self.lanes(V4([s; 4]), |p, q| p * q)
    }

    #[inline(always)]
    fn div(self, s: f64) -> V4 {
        self.lanes(V4([s; 4]), |p, q| p / q)
    }
}

impl std::ops::Add for V4 {
    type Output = V4;
    #[inline(always)]
    fn add(self, o: V4) -> V4 {
        self.lanes(o, |p, q| p + q)
    }
}

impl std::ops::Sub for V4 {
    type Output = V4;
    #[inline(always)]
    fn sub(self, o: V4) -> V4 {
        self.lanes(o, |p, q| p - q)
    }
}

impl std::ops::AddAssign for V4 {
    #[inline(always)]
    fn add_assign(&mut self, o: V4) {
        *self = *self + o;
    }
}

/// The root `s` near zero of `dv + c1 s + c2 s² + c3 s³` (the volume change after an offset
/// `s`, times 6), by Newton from `−dv / c1`; `None` when the gradient vanishes or the steps do
/// not settle to rounding.
fn offset(dv: f64, c1: f64, c2: f64, c3: f64) -> Option<f64> {
    // Negated so that a NaN counts as degenerate.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(c1 > 0.0 && c1.is_finite() && dv.is_finite()) {
        return None;
    }
    let f = |s: f64| dv + s * (c1 + s * (c2 + s * c3));
    let mut s = -dv / c1;
    for _ in 0..NEWTON_STEPS {
        s -= f(s) / (c1 + s * (2.0 * c2 + 3.0 * s * c3));
    }
    // Settled: what is left is rounding against the terms summed.
    let size = dv.abs() + c1 * s.abs();
    (s.is_finite() && f(s).abs() <= 1e-9 * size.max(f64::MIN_POSITIVE)).then_some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The offset solves the cubic to rounding, starting from the linear solution.
    #[test]
    fn the_offset_is_the_root_near_zero() {
        for (dv, c1, c2, c3) in [
            (1e-3, 2.0, 0.5, 0.1),
            (-4.0, 3.0, -0.2, 0.01),
            (0.0, 1.0, 5.0, 5.0),
        ] {
            let s = offset(dv, c1, c2, c3).unwrap();
            let f = dv + c1 * s + c2 * s * s + c3 * s * s * s;
            assert!(
                f.abs() <= 1e-12 * (dv.abs() + c1 * s.abs()).max(1e-300),
                "{f}"
            );
            assert!(
                s.abs() <= 2.0 * dv.abs() / c1 + 1e-300,
                "the root near zero: {s}"
            );
        }
        assert_eq!(offset(1.0, 0.0, 1.0, 1.0), None);
        assert_eq!(offset(f64::NAN, 1.0, 0.0, 0.0), None);
        // No real root near zero: Newton does not settle.
        assert_eq!(offset(1.0, 1e-3, 1.0, 0.0), None);
    }

    /// A block that reads its faces as a run of the sorted triangles gives the bits of the
    /// general walk from each corner: on a noisy open sphere (its border fixed, so some blocks
    /// take the general walk either way), with and without a deviation bound.
    #[test]
    fn the_run_of_sorted_faces_gives_the_bits_of_the_general_walk() {
        use crate::topology::Topology;
        let (pos, tris) = crate::shapes::open_sorted_sphere(5, 3);
        let topo = Topology::build(pos.len(), &tris).unwrap();
        assert!((0..topo.len() as u32).any(|v| topo.is_fixed(v)));
        // A filtered field: every vertex a little way towards its neighbours' mean.
        let filtered: Vec<DVec3> = (0..pos.len())
            .map(|v| {
                let n = topo.neighbors(v as u32);
                let mean =
                    n.iter().map(|&u| pos[u as usize]).sum::<DVec3>() / n.len().max(1) as f64;
                pos[v] + 0.3 * (mean - pos[v])
            })
            .collect();
        let bound = stencil::Deviation {
            input: &pos,
            limit: 0.002,
        };
        for deviation in [None, Some(bound)] {
            let run = |sorted: bool| {
                let mut p = pos.clone();
                let mesh = PatchMesh {
                    topo: &topo,
                    tris: &tris,
                    sorted,
                    border: None,
                };
                // Two patches, their blocks not aligned to the patch's start.
                let cut = 5000;
                let mu = -0.52;
                let first =
                    sweep_blocks(mesh, &mut p[..], &filtered[..], mu, 0..cut, deviation, true);
                let second = sweep_blocks(
                    mesh,
                    &mut p[..],
                    &filtered[..],
                    mu,
                    cut..pos.len() as u32,
                    deviation,
                    true,
                );
                let st = first.then(second);
                // Each vertex's move, measured as it is written, is its distance from where it
                // was: the largest the same bits, the sum up to its order.
                let moved = st.moved.unwrap();
                let (max, sum) = p.iter().zip(&pos).fold((0.0f64, 0.0), |(m, s), (a, b)| {
                    (m.max(a.distance(*b)), s + a.distance(*b))
                });
                assert!(moved.max_displacement > 0.0);
                assert_eq!(moved.max_displacement, max);
                assert!((moved.sum_displacement - sum).abs() <= 1e-12 * sum);
                let st = st.stencils;
                (p, st.applied, st.deviation_limited)
            };
            let (fast, slow) = (run(true), run(false));
            assert!(fast.1 + fast.2 > 0);
            assert!(fast.0 != pos);
            assert_eq!(fast.0, slow.0);
            assert_eq!((fast.1, fast.2), (slow.1, slow.2));
        }
    }
}
