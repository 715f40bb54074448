//! Stencil kernels: local energy minimisation (`lem`) and volume-constrained smoothing (`vcs`,
//! `vcs-triangle`) of Liu et al. 2002, on edge stencils (2 free vertices) and triangle stencils
//! (3 free vertices).
//!
//! For free vertices F, the rows are every v in F ∪ N(F) except crease vertices
//! ([`Topology::crease`]: fixed, and their Laplacian across the crease is a feature to keep). With displacements `d_f` of the free
//! vertices, the row's Laplacian becomes `L(v) + Σ_f k[v][f] d_f`, where `k[v][f]` is −1 if v = f,
//! `1/deg v` if f ∈ N(v), else 0. The stencil energy is `E(d) = ½ Σ_v |L(v) + Σ_f k[v][f] d_f|²`
//! (the paper's `½‖KP − Q‖²` written in displacements, which makes it translation-invariant).
//!
//! - Step 1 (`lem`): minimise E: `(KᵀK) d = −Kᵀ L`, an |F|×|F| SPD system with three right-hand sides.
//! - Step 2 (`vcs`): translate all free vertices by one vector w so that the volume of the faces that
//!   touch F, `V = (1/6) Σ_t det(p_a, p_b, p_c)` in each face's own order, returns to its value
//!   before the stencil. V is exactly linear in a common translation: `V(P¹ + w) = V(P¹) + n·w` with
//!   `n = (1/6) Σ_t Σ_{free corner a of t} p_b × p_c` at P¹, so `w = n (V⁰ − V¹) / |n|²`.
//!
//! All arithmetic is f64 relative to the free vertices' centroid, so the determinants stay well
//! conditioned far from the origin. The Laplacians come from a neighbour-sum cache (see
//! [`super::neighbor_sums`]) that each applied stencil updates, so a stencil costs O(|F ∪ N(F)|).

use glam::DVec3;

use super::{Field, SweepStats, Topology, inv_deg};
use crate::topology::{TopologyParts, corners_after};

/// What a stencil kernel does after the energy minimisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StencilParams<'a> {
    /// Restore the stencil's volume (step 2): `vcs` and `vcs-triangle`; false gives `lem`.
    pub volume: bool,
    /// Reject a stencil whose final energy exceeds its energy before the stencil.
    pub reject_energy_increase: bool,
    /// Skip a stencil whose result would move a free vertex too far from its input position.
    pub deviation: Option<Deviation<'a>>,
}

/// A bound on how far a vertex may end from its input position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deviation<'a> {
    /// The input positions, indexed like the positions the kernel smooths (only the free
    /// vertices' entries are read).
    pub input: &'a [DVec3],
    /// The largest distance allowed (> 0).
    pub limit: f64,
}

/// The result of one stencil.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    Applied,
    SkippedFixed,
    SkippedDegenerate,
    Rejected,
    /// Skipped because a free vertex would have ended beyond the [`Deviation`] limit.
    DeviationLimited,
}

/// Relative size below which a pivot of `KᵀK`, or `|n|` against the stencil's area, counts as degenerate.
const DEGENERATE: f64 = 1e-10;

/// Farthest a stencil may move a free vertex, in radii of the stencil (the largest distance from
/// the free vertices' centroid to a vertex of F ∪ N(F), before the stencil). The minimiser of the
/// stencil energy stays within about one radius, and the volume step only restores what that step
/// changed; a result beyond this bound comes from a stencil whose solve or volume gradient is
/// nearly singular without being caught by the relative tests, and is skipped as degenerate.
/// Measured over 10 iterations of `lem`, `vcs` and `vcs-triangle`: at most 0.7 radii on the scans
/// of `tests/data`, at most 4 on spheres and tori with noise of 3 mean edge lengths.
pub(crate) const MAX_REACH: f64 = 16.0;

/// Apply one stencil with free vertices `free` to `pos`, updating the neighbour-sum cache `sums`.
/// It reads positions of F ∪ N(F) and sums of F ∪ N(F); it writes positions of F and sums of N(F).
/// A stencil is skipped as degenerate when its system or volume gradient is nearly singular, or
/// when its result would move a free vertex farther than `MAX_REACH` times the stencil's radius;
/// with a [`Deviation`] bound, it is skipped when its result (after the volume step) would leave
/// a free vertex farther than the limit from its input position, so every applied stencil keeps
/// its volume exactly.
///
/// `triangles` is the array the topology was built from (its faces give the stencil volume).
/// Positions and sums are written only when the outcome is [`Outcome::Applied`]. The free vertices
/// must be mutual neighbours (an edge or a face of the mesh); a stencil whose are not is skipped
/// as degenerate.
///
/// How the normal equations are assembled: with `w_v = 1/deg v` and `k[v][f] = −[v = f] + w_v [v ∈ N(f)]`,
/// and the free vertices mutual neighbours,
/// - `(KᵀK)[f][f] = 1 + Σ_{v∈N(f)} w_v²`,
/// - `(KᵀK)[f][g] = Σ_{v∈N(f)∩N(g)} w_v² − w_f − w_g` for f ≠ g,
/// - `(−KᵀL)[f] = L(f) − Σ_{v∈N(f)} w_v L(v)`,
///
/// so one merge of the sorted neighbour lists, computing each row's Laplacian once, gives the
/// whole system without materialising K.
pub fn apply<const N: usize, P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut P,
    sums: &mut S,
    free: [u32; N],
    params: StencilParams,
) -> Outcome {
    apply_in(topo, &topo.parts(), triangles, pos, sums, free, params)
}

/// [`apply`] with the topology's arrays already taken.
fn apply_in<const N: usize, P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    adj: &TopologyParts,
    triangles: &[[u32; 3]],
    pos: &mut P,
    sums: &mut S,
    free: [u32; N],
    params: StencilParams,
) -> Outcome {
    const { assert!(N >= 1 && N <= 8, "masks are u8") };
    if free.iter().any(|&f| adj.is_fixed(f)) {
        return Outcome::SkippedFixed;
    }

    // Rows F ∪ N(F) = the merge of the free vertices' sorted neighbour lists (each free vertex is
    // in the others' lists); `mask` says which lists hold the row.
    let mut lists: [&[u32]; N] = [&[]; N];
    for (l, &f) in lists.iter_mut().zip(&free) {
        *l = adj.neighbors(f);
    }
    let centre = free.iter().fold(DVec3::ZERO, |s, &f| s + pos.get(f)) * (1.0 / N as f64);
    let mut sq = [0.0f64; N]; // Σ_{v∈N(f)} w_v²
    let mut cross = [[0.0f64; N]; N]; // Σ_{v∈N(f)∩N(g)} w_v², f < g
    let mut weighted = [DVec3::ZERO; N]; // Σ_{v∈N(f)} w_v L(v)
    let mut lap_free = [DVec3::ZERO; N]; // L(f)
    let mut free_mask = [0u8; N]; // which lists hold free vertex f: all but f's own when adjacent
    // Crease vertices' rows stay out of the energy: their Laplacian across the crease is the
    // feature, not noise, and minimising it would pull their free neighbours off the faces.
    let creases = topo.stats.crease_vertices > 0;
    // Inlined at each of the merge's call sites, where the mask is a constant for edge stencils.
    merge_rows(
        lists,
        #[inline(always)]
        |v, mask| {
            if creases && topo.is_crease(v) {
                // Never a free vertex (those are not fixed), so only a row is left out.
                return;
            }
            let w = inv_deg(adj.deg(v));
            let p = pos.get(v);
            let lap = sums.get(v) * w - p;
            for f in 0..N {
                if mask & (1 << f) != 0 {
                    weighted[f] += w * lap;
                    sq[f] += w * w;
                    for (g, c) in cross[f].iter_mut().enumerate().skip(f + 1) {
                        if mask & (1 << g) != 0 {
                            *c += w * w;
                        }
                    }
                } else if v == free[f] {
                    free_mask[f] = mask;
                }
            }
        },
    );
    let all = (((1u16 << N) - 1) & 0xff) as u8;
    if (0..N).any(|f| free_mask[f] != all & !(1 << f)) {
        debug_assert!(
            false,
            "free vertices of a stencil must be mutual neighbours"
        );
        return Outcome::SkippedDegenerate;
    }

    // Normal equations (KᵀK) d = −Kᵀ L. A free vertex's Laplacian is taken here rather than at
    // its row, the same arithmetic, so that the rows need not carry it.
    let mut w_free = [0.0f64; N];
    for (w, l) in w_free.iter_mut().zip(&lists) {
        *w = inv_deg(l.len());
    }
    for f in 0..N {
        lap_free[f] = sums.get(free[f]) * w_free[f] - pos.get(free[f]);
    }
    let mut m = [[0.0f64; N]; N];
    for f in 0..N {
        m[f][f] = 1.0 + sq[f];
        for g in f + 1..N {
            let x = cross[f][g] - w_free[f] - w_free[g];
            m[f][g] = x;
            m[g][f] = x;
        }
    }
    let mut rhs = [DVec3::ZERO; N];
    for f in 0..N {
        rhs[f] = lap_free[f] - weighted[f];
    }
    let Some(mut d) = solve_spd(m, rhs) else {
        return Outcome::SkippedDegenerate;
    };

    if params.volume {
        match volume_translation(adj, triangles, pos, &free, centre, &d) {
            Some(w) => d.iter_mut().for_each(|x| *x += w),
            None => return Outcome::SkippedDegenerate,
        }
    }
    // The squared radius of the stencil about `centre` is the largest over its rows; the free
    // vertices are rows, so theirs bounds it from below, and a step within reach of that bound
    // is within reach of the radius, which then need not be measured (the same decision).
    let distance2 = |v: u32| (pos.get(v) - centre).length_squared();
    let near2 = free.iter().fold(0.0f64, |r, &f| r.max(distance2(f)));
    if !within_reach(&d, near2) {
        let radius2 = lists
            .iter()
            .flat_map(|l| l.iter())
            .fold(0.0f64, |r, &v| r.max(distance2(v)));
        if !within_reach(&d, radius2) {
            return Outcome::SkippedDegenerate;
        }
    }
    if let Some(bound) = params.deviation {
        // The whole stencil or nothing: a step scaled back would need its volume step again.
        let limit2 = bound.limit * bound.limit;
        let beyond = |fi: usize, f: u32| {
            (pos.get(f) + d[fi] - bound.input[f as usize]).length_squared() > limit2
        };
        if free.iter().enumerate().any(|(fi, &f)| beyond(fi, f)) {
            return Outcome::DeviationLimited;
        }
    }
    if params.reject_energy_increase {
        // 2 (E(d) − E(0)) = dᵀ(KᵀK)d + 2 dᵀKᵀL = Σ_fg m_fg d_f·d_g − 2 Σ_f d_f·rhs_f: the exact
        // energy change from the normal equations, so no row needs to be revisited (and the
        // difference is not lost in the cancellation of two large energies).
        let mut change = 0.0;
        for f in 0..N {
            change -= 2.0 * d[f].dot(rhs[f]);
            for g in 0..N {
                change += m[f][g] * d[f].dot(d[g]);
            }
        }
        if change > 0.0 {
            return Outcome::Rejected;
        }
    }

    for (fi, &f) in free.iter().enumerate() {
        pos.add(f, d[fi]);
        for &u in lists[fi] {
            sums.add(u, d[fi]);
        }
    }
    Outcome::Applied
}

/// Whether every displacement is finite and at most [`MAX_REACH`] times the stencil's radius
/// (`radius2` is its square): the last line of defence against a nearly singular stencil.
#[inline]
fn within_reach<const N: usize>(d: &[DVec3; N], radius2: f64) -> bool {
    let reach2 = MAX_REACH * MAX_REACH * radius2;
    // Within a finite reach, the squared length is finite and not NaN, so every component is
    // finite: only an infinite reach needs the components tested.
    d.iter()
        .all(|x| x.length_squared() <= reach2 && (reach2 < f64::INFINITY || x.is_finite()))
}

/// Call `row(v, mask)` for every vertex v of the union of the ascending lists, in ascending order,
/// with bit f of `mask` set when `lists[f]` holds v.
#[inline(always)]
fn merge_rows<const N: usize>(lists: [&[u32]; N], mut row: impl FnMut(u32, u8)) {
    if N == 2 {
        // Edge stencils: a plain two-way merge. Each branch passes a constant mask, so after
        // inlining every branch accumulates into only the lists that hold its row.
        let (la, lb) = (lists[0], lists[1]);
        let (mut i, mut j) = (0, 0);
        while let (Some(&x), Some(&y)) = (la.get(i), lb.get(j)) {
            if x < y {
                row(x, 1);
                i += 1;
            } else if y < x {
                row(y, 2);
                j += 1;
            } else {
                row(x, 3);
                i += 1;
                j += 1;
            }
        }
        la[i..].iter().for_each(|&x| row(x, 1));
        lb[j..].iter().for_each(|&y| row(y, 2));
        return;
    }
    let mut at = [0usize; N];
    loop {
        let mut v = u32::MAX;
        for f in 0..N {
            if let Some(&u) = lists[f].get(at[f]) {
                v = v.min(u);
            }
        }
        if v == u32::MAX {
            break;
        }
        let mut mask = 0u8;
        for f in 0..N {
            let hit = lists[f].get(at[f]) == Some(&v);
            mask |= (hit as u8) << f;
            at[f] += hit as usize;
        }
        row(v, mask);
    }
}

/// Step 2: the common translation w of the free vertices (`pos`, to be displaced by `d`) that
/// restores the volume of the faces touching them, computed about `origin` (the free vertices'
/// centroid). `None` when the volume gradient is degenerate: `|n|²` tiny against `Σ|n_t|²`, each
/// face's gradient taken before the stencil, so that a step that collapses the stencil's faces
/// (a triangle stencil on a closed tetrahedron shrinks it to a point) cannot shrink the yardstick
/// along with the gradient it measures.
fn volume_translation<const N: usize, P: Field + ?Sized>(
    adj: &TopologyParts,
    triangles: &[[u32; 3]],
    pos: &P,
    free: &[u32; N],
    origin: DVec3,
    d: &[DVec3; N],
) -> Option<DVec3> {
    // ΔV = V(P¹) − V(P⁰) and n = ∂V/∂w at P¹, both times 6 (the factor cancels in w).
    let (mut dv, mut scale) = (0.0, 0.0);
    let mut n = DVec3::ZERO;
    if N == 2 {
        // Edge stencils, the common case, with the same arithmetic in the same order as below:
        // a face's other free corner can only be the edge's other end.
        for fi in 0..2 {
            let (f, g) = (free[fi], free[1 - fi]);
            let mut single = DVec3::ZERO;
            crate::for_each_face!(adj, f, triangles, u32::MAX, |_t, tri| {
                let (b, c) = corners_after(tri, f);
                let (b_free, c_free) = (b == g, c == g);
                if !(b_free | c_free) {
                    let nt = (pos.get(b) - origin).cross(pos.get(c) - origin);
                    single += nt;
                    scale += nt.length_squared();
                    continue;
                }
                if fi == 1 {
                    continue;
                }
                let (p, q, r) = (
                    pos.get(f) - origin,
                    pos.get(b) - origin,
                    pos.get(c) - origin,
                );
                // One call per case, so that each is compiled for its own free corners.
                let (z, acc) = (DVec3::ZERO, (&mut dv, &mut n, &mut scale));
                match (b_free, c_free) {
                    (true, false) => {
                        shared_face(p, q, r, d[0], d[1], z, true, false, acc.0, acc.1, acc.2)
                    }
                    (false, true) => {
                        shared_face(p, q, r, d[0], z, d[1], false, true, acc.0, acc.1, acc.2)
                    }
                    _ => shared_face(p, q, r, d[0], d[1], d[1], true, true, acc.0, acc.1, acc.2),
                }
            });
            dv += d[fi].dot(single);
            n += single;
        }
        return translation(dv, n, scale);
    }
    for (fi, &f) in free.iter().enumerate() {
        // Faces where f is the only free corner (most of them): n_t = p_b × p_c does not depend
        // on f, and ΔV_t = d_f · n_t, so their n_t are summed first and dotted with d_f once.
        let mut single = DVec3::ZERO;
        crate::for_each_face!(adj, f, triangles, u32::MAX, |_t, tri| {
            let (b, c) = corners_after(tri, f);
            // Which other free vertices are corners of this face.
            let mut others = 0u8;
            for (g, &fg) in free.iter().enumerate() {
                others |= (((b == fg) | (c == fg)) as u8) << g;
            }
            if others == 0 {
                let nt = (pos.get(b) - origin).cross(pos.get(c) - origin);
                single += nt;
                scale += nt.length_squared();
                continue;
            }
            // A face holding an earlier free vertex was already counted with it.
            if others & ((1u8 << fi) - 1) != 0 {
                continue;
            }
            // Faces with several free corners (2 per edge stencil, 4 per triangle stencil), in the
            // face's cyclic order (f, b, c): P, Q, R after step 1, p, q, r before.
            let (mut db, mut dc) = (DVec3::ZERO, DVec3::ZERO);
            let (mut b_free, mut c_free) = (false, false);
            for (g, &fg) in free.iter().enumerate() {
                if b == fg {
                    db = d[g];
                    b_free = true;
                }
                if c == fg {
                    dc = d[g];
                    c_free = true;
                }
            }
            let (p, q, r) = (
                pos.get(f) - origin,
                pos.get(b) - origin,
                pos.get(c) - origin,
            );
            shared_face(
                p, q, r, d[fi], db, dc, b_free, c_free, &mut dv, &mut n, &mut scale,
            );
        });
        dv += d[fi].dot(single);
        n += single;
    }
    translation(dv, n, scale)
}

/// A face with several free corners, in its cyclic order (f, b, c): `p, q, r` before the step,
/// displaced by `df, db, dc` (zero for a corner that is not free). Adds its volume change to `dv`,
/// its gradient (p_b × p_c over its free corners a, after the step) to `n`, and that gradient's
/// size before the step, the face's share of the yardstick, to `scale`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn shared_face(
    p: DVec3,
    q: DVec3,
    r: DVec3,
    df: DVec3,
    db: DVec3,
    dc: DVec3,
    b_free: bool,
    c_free: bool,
    dv: &mut f64,
    n: &mut DVec3,
    scale: &mut f64,
) {
    let (bp, bq, br) = (p + df, q + db, r + dc);
    let qr = bq.cross(br);
    let qr0 = q.cross(r);
    *dv += bp.dot(qr) - p.dot(qr0);
    let (mut nt, mut nt0) = (qr, qr0);
    if b_free {
        nt += br.cross(bp);
        nt0 += r.cross(p);
    }
    if c_free {
        nt += bp.cross(bq);
        nt0 += p.cross(q);
    }
    *n += nt;
    *scale += nt0.length_squared();
}

/// The translation `w = −n ΔV / |n|²`, or `None` when the gradient is degenerate: it cancels out
/// against its faces' own (|n|² ≪ Σ|n_t|²).
#[inline]
pub(crate) fn translation(dv: f64, n: DVec3, scale: f64) -> Option<DVec3> {
    let nn = n.length_squared();
    // Negated so that a NaN counts as degenerate.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(nn > DEGENERATE * DEGENERATE * scale) {
        return None;
    }
    Some(n * (-dv / nn))
}

/// Solve the small SPD system `m x = b` by Cholesky; `None` if a pivot is not clearly positive.
///
/// For N = 2 the same test (pivots `m00` and `det/m00`, each against its diagonal entry) and
/// Cramer's rule, one division instead of two square roots and four divisions.
// The pivot tests are negated so that a NaN counts as degenerate.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn solve_spd<const N: usize>(m: [[f64; N]; N], b: [DVec3; N]) -> Option<[DVec3; N]> {
    if N == 2 {
        let (a, o, c) = (m[0][0], m[0][1], m[1][1]);
        let det = a * c - o * o;
        if !(a > 0.0 && det > DEGENERATE * a * c) {
            return None;
        }
        let inv = 1.0 / det;
        let mut x = [DVec3::ZERO; N];
        x[0] = (c * b[0] - o * b[1]) * inv;
        x[1] = (a * b[1] - o * b[0]) * inv;
        return Some(x);
    }
    let mut l = [[0.0f64; N]; N];
    let mut inv_diag = [0.0f64; N];
    for i in 0..N {
        for j in 0..=i {
            let s = m[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if !(s > DEGENERATE * m[i][i]) {
                    return None;
                }
                l[i][i] = s.sqrt();
                inv_diag[i] = 1.0 / l[i][i];
            } else {
                l[i][j] = s * inv_diag[j];
            }
        }
    }
    let mut y = [DVec3::ZERO; N];
    for i in 0..N {
        y[i] = (b[i] - (0..i).fold(DVec3::ZERO, |s, k| s + l[i][k] * y[k])) * inv_diag[i];
    }
    let mut x = [DVec3::ZERO; N];
    for i in (0..N).rev() {
        x[i] = (y[i] - (i + 1..N).fold(DVec3::ZERO, |s, k| s + l[k][i] * x[k])) * inv_diag[i];
    }
    Some(x)
}

/// Tally an outcome into sweep statistics.
#[inline]
pub fn count(stats: &mut SweepStats, outcome: Outcome) {
    match outcome {
        Outcome::Applied => stats.applied += 1,
        Outcome::SkippedFixed => stats.skipped_fixed += 1,
        Outcome::SkippedDegenerate => stats.skipped_degenerate += 1,
        Outcome::Rejected => stats.rejected += 1,
        Outcome::DeviationLimited => stats.deviation_limited += 1,
    }
}

/// Apply the edge stencils `edges`, in the given order, Gauss–Seidel (each sees the latest positions).
pub fn sweep_edges<P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut P,
    sums: &mut S,
    edges: impl IntoIterator<Item = [u32; 2]>,
    params: StencilParams,
) -> SweepStats {
    let (adj, mut stats) = (topo.parts(), SweepStats::default());
    for e in edges {
        count(
            &mut stats,
            apply_in(topo, &adj, triangles, pos, sums, e, params),
        );
    }
    stats
}

/// Apply the triangle stencils (indices into `triangles`), in the given order, Gauss–Seidel.
/// A triangle with a repeated index has fixed vertices and is counted as skipped.
pub fn sweep_triangles<P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut P,
    sums: &mut S,
    faces: impl IntoIterator<Item = u32>,
    params: StencilParams,
) -> SweepStats {
    let (adj, mut stats) = (topo.parts(), SweepStats::default());
    for t in faces {
        let free = triangles[t as usize];
        count(
            &mut stats,
            apply_in(topo, &adj, triangles, pos, sums, free, params),
        );
    }
    stats
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::smooth::neighbor_sums;

    /// A bumpy closed octahedron far from the origin.
    fn bumpy_octahedron(offset: DVec3) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let pos = vec![
            DVec3::new(1.3, 0.1, 0.0),
            DVec3::new(-0.8, 0.0, 0.2),
            DVec3::new(0.0, 1.1, -0.1),
            DVec3::new(0.1, -0.9, 0.0),
            DVec3::new(0.0, 0.2, 1.4),
            DVec3::new(-0.1, 0.0, -0.7),
        ];
        let tris = crate::shapes::octahedron().triangles.to_vec();
        (pos.into_iter().map(|p| p + offset).collect(), tris)
    }

    /// Measured relative to the centroid: summed about the far-away origin, the test itself would
    /// lose the digits it checks.
    fn volume(pos: &[DVec3], tris: &[[u32; 3]]) -> f64 {
        crate::metrics::volume(pos, tris)
    }

    fn energy(topo: &Topology, pos: &[DVec3], rows: &[u32]) -> f64 {
        rows.iter()
            .map(|&v| crate::smooth::laplacian::umbrella(topo, pos, v).length_squared())
            .sum::<f64>()
    }

    #[test]
    fn edge_stencil_restores_volume_far_from_origin() {
        for offset in [DVec3::ZERO, DVec3::new(1e4, -2e4, 3e4)] {
            let (mut pos, tris) = bumpy_octahedron(offset);
            let topo = Topology::build(6, &tris).unwrap();
            let mut sums = neighbor_sums(&topo, &pos);
            let before = volume(&pos, &tris);
            let p = StencilParams {
                volume: true,
                reject_energy_increase: false,
                deviation: None,
            };
            let out = apply(&topo, &tris, &mut pos[..], &mut sums[..], [0, 2], p);
            assert_eq!(out, Outcome::Applied);
            let rel = ((volume(&pos, &tris) - before) / before).abs();
            assert!(rel < 1e-9, "offset {offset}: relative volume change {rel}");
            let fresh = neighbor_sums(&topo, &pos);
            for (a, b) in sums.iter().zip(&fresh) {
                assert!((*a - *b).length() < 1e-9 * (1.0 + offset.length()));
            }
        }
    }

    #[test]
    fn lem_step_lowers_stencil_energy_and_is_its_minimum() {
        let (pos0, tris) = bumpy_octahedron(DVec3::ZERO);
        let topo = Topology::build(6, &tris).unwrap();
        let rows: Vec<u32> = (0..6).collect(); // every vertex is in F ∪ N(F) of edge (0, 2)
        let mut pos = pos0.clone();
        let mut sums = neighbor_sums(&topo, &pos);
        let p = StencilParams {
            volume: false,
            reject_energy_increase: false,
            deviation: None,
        };
        apply(&topo, &tris, &mut pos[..], &mut sums[..], [0, 2], p);
        let e1 = energy(&topo, &pos, &rows);
        assert!(e1 < energy(&topo, &pos0, &rows));
        // Any small perturbation of a free vertex raises the energy: the solve found the minimum.
        for dir in [DVec3::X, DVec3::Y, DVec3::Z, DVec3::NEG_X] {
            for f in [0usize, 2] {
                let mut q = pos.clone();
                q[f] += 1e-4 * dir;
                assert!(energy(&topo, &q, &rows) > e1);
            }
        }
    }

    #[test]
    fn triangle_stencil_restores_volume() {
        let (mut pos, tris) = bumpy_octahedron(DVec3::new(-50.0, 7.0, 3.0));
        let topo = Topology::build(6, &tris).unwrap();
        let mut sums = neighbor_sums(&topo, &pos);
        let before = volume(&pos, &tris);
        let p = StencilParams {
            volume: true,
            reject_energy_increase: false,
            deviation: None,
        };
        let stats = sweep_triangles(&topo, &tris, &mut pos[..], &mut sums[..], 0..8, p);
        assert_eq!(stats.applied, 8);
        assert!(((volume(&pos, &tris) - before) / before).abs() < 1e-9);
    }

    #[test]
    fn fixed_and_degenerate_stencils_are_skipped_untouched() {
        // Open fan: rim vertices are fixed, so edge (0, 1) is skipped.
        let tris: Vec<[u32; 3]> = (1..=5).map(|k| [0, k, k % 5 + 1]).collect();
        let topo = Topology::build(6, &tris).unwrap();
        let mut pos: Vec<DVec3> = (0..6).map(|k| DVec3::new(k as f64, 0.0, 0.0)).collect();
        let mut sums = neighbor_sums(&topo, &pos);
        let p = StencilParams {
            volume: true,
            reject_energy_increase: false,
            deviation: None,
        };
        let before = pos.clone();
        let out = apply(&topo, &tris, &mut pos[..], &mut sums[..], [0, 1], p);
        assert_eq!(out, Outcome::SkippedFixed);
        assert_eq!(pos, before);

        // Coincident vertices: the volume gradient vanishes, so the stencil is degenerate, not NaN.
        let (_, tris) = bumpy_octahedron(DVec3::ZERO);
        let topo = Topology::build(6, &tris).unwrap();
        let mut pos = vec![DVec3::splat(3.0); 6];
        let mut sums = neighbor_sums(&topo, &pos);
        let out = apply(&topo, &tris, &mut pos[..], &mut sums[..], [0, 2], p);
        assert_eq!(out, Outcome::SkippedDegenerate);
        assert!(pos.iter().all(|p| *p == DVec3::splat(3.0)));
    }

    #[test]
    fn a_closed_tetrahedron_is_degenerate_for_every_stencil() {
        // A triangle stencil's energy minimum collapses its triangle onto the fourth vertex, where
        // no translation restores the volume (the gradient vanishes with the faces); an edge
        // stencil cannot restore it either. Skipped, not sent to infinity.
        let tris = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let topo = Topology::build(4, &tris).unwrap();
        for offset in [DVec3::ZERO, DVec3::new(300.0, -20.0, 7.0)] {
            let pos0: Vec<DVec3> = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z]
                .iter()
                .map(|p| *p * 0.01 + offset)
                .collect();
            let p = StencilParams {
                volume: true,
                reject_energy_increase: false,
                deviation: None,
            };
            let mut pos = pos0.clone();
            let mut sums = neighbor_sums(&topo, &pos);
            let st = sweep_triangles(&topo, &tris, &mut pos[..], &mut sums[..], 0..4, p);
            assert_eq!((st.applied, st.skipped_degenerate), (0, 4), "{offset}");
            let st = sweep_edges(&topo, &tris, &mut pos[..], &mut sums[..], topo.edges(), p);
            assert_eq!((st.applied, st.skipped_degenerate), (0, 6), "{offset}");
            assert_eq!(pos, pos0);
        }
    }

    #[test]
    fn displacements_beyond_reach_or_not_finite_are_refused() {
        let r2 = 4.0; // radius 2
        let near = [DVec3::new(0.0, 2.0 * MAX_REACH, 0.0), DVec3::ZERO];
        assert!(within_reach(&near, r2));
        let far = [DVec3::ZERO, DVec3::new(0.0, 2.0 * MAX_REACH * 1.001, 0.0)];
        assert!(!within_reach(&far, r2));
        assert!(!within_reach(&[DVec3::new(f64::NAN, 0.0, 0.0)], r2));
        assert!(!within_reach(
            &[DVec3::new(f64::INFINITY, 0.0, 0.0)],
            f64::INFINITY
        ));
        // A stencil of coincident vertices may not move at all.
        assert!(within_reach(&[DVec3::ZERO], 0.0));
        assert!(!within_reach(&[DVec3::splat(1e-100)], 0.0));
    }

    #[test]
    fn rejection_keeps_energy_from_rising() {
        let (mut pos, tris) = bumpy_octahedron(DVec3::ZERO);
        let topo = Topology::build(6, &tris).unwrap();
        let mut sums = neighbor_sums(&topo, &pos);
        let p = StencilParams {
            volume: true,
            reject_energy_increase: true,
            deviation: None,
        };
        let all: Vec<u32> = (0..6).collect();
        for _ in 0..20 {
            for e in topo.edges().collect::<Vec<_>>() {
                let before = pos.clone();
                let rows: Vec<u32> = all.clone();
                let e0 = energy(&topo, &before, &rows);
                if apply(&topo, &tris, &mut pos[..], &mut sums[..], e, p) == Outcome::Applied {
                    assert!(energy(&topo, &pos, &rows) <= e0 * (1.0 + 1e-12));
                }
            }
        }
    }

    #[test]
    fn cholesky_solves_small_systems() {
        let m = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        let x = [
            DVec3::new(1.0, -2.0, 0.5),
            DVec3::new(0.0, 1.0, 3.0),
            DVec3::new(2.0, 2.0, -1.0),
        ];
        let b: [DVec3; 3] =
            std::array::from_fn(|i| (0..3).fold(DVec3::ZERO, |s, j| s + m[i][j] * x[j]));
        let got = solve_spd(m, b).unwrap();
        for i in 0..3 {
            assert!((got[i] - x[i]).length() < 1e-12);
        }
        assert!(solve_spd([[1.0, 1.0], [1.0, 1.0]], [DVec3::ONE; 2]).is_none());
    }
}
