//! Stencil kernels: local energy minimisation (`lem`) and volume-constrained smoothing (`vcs`,
//! `vcs-triangle`) of Liu et al. 2002, on edge stencils (2 free vertices) and triangle stencils
//! (3 free vertices).
//!
//! For free vertices F, the rows are every v in F ∪ N(F). With displacements `d_f` of the free
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

use super::{Field, SweepStats, Topology};

/// What a stencil kernel does after the energy minimisation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StencilParams {
    /// Restore the stencil's volume (step 2): `vcs` and `vcs-triangle`; false gives `lem`.
    pub volume: bool,
    /// Reject a stencil whose final energy exceeds its energy before the stencil.
    pub reject_energy_increase: bool,
}

/// The result of one stencil.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    Applied,
    SkippedFixed,
    SkippedDegenerate,
    Rejected,
}

/// One row of a stencil: vertex `v`, which free vertices it is (`self_mask`) and neighbours
/// (`nbr_mask`), `1/deg v`, and its current Laplacian.
#[derive(Debug, Clone, Copy)]
struct Row {
    v: u32,
    self_mask: u8,
    nbr_mask: u8,
    inv_deg: f64,
    lap: DVec3,
}

impl Row {
    #[inline]
    fn k(&self, f: usize) -> f64 {
        if self.self_mask & (1 << f) != 0 {
            -1.0
        } else if self.nbr_mask & (1 << f) != 0 {
            self.inv_deg
        } else {
            0.0
        }
    }
}

/// Scratch buffer reused across stencils, so that no stencil allocates.
#[derive(Debug, Default)]
pub struct Workspace {
    rows: Vec<Row>,
}

/// Relative size below which a pivot of `KᵀK`, or `|n|` against the stencil's area, counts as degenerate.
const DEGENERATE: f64 = 1e-10;

/// Apply one stencil with free vertices `free` to `pos`, updating the neighbour-sum cache `sums`.
/// It reads positions of F ∪ N(F) and sums of F ∪ N(F); it writes positions of F and sums of N(F).
///
/// `triangles` is the array the topology was built from (its faces give the stencil volume).
/// Positions and sums are written only when the outcome is [`Outcome::Applied`].
pub fn apply<const N: usize, P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut P,
    sums: &mut S,
    free: [u32; N],
    params: StencilParams,
    ws: &mut Workspace,
) -> Outcome {
    if free.iter().any(|&f| topo.is_fixed(f)) {
        return Outcome::SkippedFixed;
    }

    // Rows F ∪ N(F), merged by vertex.
    // Rows F ∪ N(F): the free vertices of an edge or triangle stencil are neighbours of each
    // other, so the rows are exactly the merge of their sorted neighbour lists.
    let rows = &mut ws.rows;
    rows.clear();
    let lists: [&[u32]; N] = free.map(|f| topo.neighbors(f));
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
        let mut nbr_mask = 0u8;
        for f in 0..N {
            if lists[f].get(at[f]) == Some(&v) {
                nbr_mask |= 1 << f;
                at[f] += 1;
            }
        }
        let self_mask = free.iter().position(|&f| f == v).map_or(0, |k| 1u8 << k);
        rows.push(Row {
            v,
            self_mask,
            nbr_mask,
            inv_deg: 0.0,
            lap: DVec3::ZERO,
        });
    }
    debug_assert_eq!(
        rows.iter().filter(|r| r.self_mask != 0).count(),
        N,
        "free vertices of a stencil must be mutual neighbours"
    );

    // Normal equations (KᵀK) d = −Kᵀ L, and the energy before the stencil.
    let mut m = [[0.0f64; N]; N];
    let mut rhs = [DVec3::ZERO; N];
    let mut energy_before = 0.0;
    for r in rows.iter_mut() {
        r.inv_deg = 1.0 / topo.deg(r.v) as f64;
        r.lap = sums.get(r.v) * r.inv_deg - pos.get(r.v);
        if params.reject_energy_increase {
            energy_before += r.lap.length_squared();
        }
        let k: [f64; N] = std::array::from_fn(|f| r.k(f));
        for f in 0..N {
            if k[f] != 0.0 {
                rhs[f] -= k[f] * r.lap;
                for g in 0..N {
                    m[f][g] += k[f] * k[g];
                }
            }
        }
    }
    let Some(mut d) = solve_spd(m, rhs) else {
        return Outcome::SkippedDegenerate;
    };

    if params.volume {
        match volume_translation(topo, triangles, pos, &free, &d) {
            Some(w) => d.iter_mut().for_each(|x| *x += w),
            None => return Outcome::SkippedDegenerate,
        }
    }
    if !d.iter().all(|x| x.is_finite()) {
        return Outcome::SkippedDegenerate;
    }
    if params.reject_energy_increase {
        let energy_after: f64 = rows
            .iter()
            .map(|r| (r.lap + (0..N).fold(DVec3::ZERO, |s, f| s + r.k(f) * d[f])).length_squared())
            .sum();
        if energy_after > energy_before {
            return Outcome::Rejected;
        }
    }

    for (fi, &f) in free.iter().enumerate() {
        pos.add(f, d[fi]);
        for &u in topo.neighbors(f) {
            sums.add(u, d[fi]);
        }
    }
    Outcome::Applied
}

/// Step 2: the common translation w of the free vertices (already displaced by `d`) that restores
/// the volume of the faces touching them. `None` when the volume gradient is degenerate.
fn volume_translation<const N: usize, P: Field + ?Sized>(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &P,
    free: &[u32; N],
    d: &[DVec3; N],
) -> Option<DVec3> {
    let origin = free.iter().fold(DVec3::ZERO, |s, &f| s + pos.get(f)) / N as f64;
    // ΔV = V(P¹) − V(P⁰) and n = ∂V/∂w at P¹, both times 6 (the factor cancels in w).
    let (mut dv, mut scale) = (0.0, 0.0);
    let mut n = DVec3::ZERO;
    for (fi, &f) in free.iter().enumerate() {
        for &t in topo.faces_of(f) {
            let tri = triangles[t as usize];
            // Which corners are free; a face holding an earlier free vertex was already counted.
            let mut slot = [usize::MAX; 3];
            let mut free_corners = 0;
            let mut seen = false;
            for c in 0..3 {
                for (g, &fg) in free.iter().enumerate() {
                    if tri[c] == fg {
                        slot[c] = g;
                        free_corners += 1;
                        seen |= g < fi;
                    }
                }
            }
            if seen {
                continue;
            }
            let nt = if free_corners == 1 {
                // Most faces: only f moves, so ΔV_t = d·(p_b × p_c) and n_t = p_b × p_c.
                let c = slot.iter().position(|&g| g == fi).unwrap_or(0);
                let pb = pos.get(tri[(c + 1) % 3]) - origin;
                let pc = pos.get(tri[(c + 2) % 3]) - origin;
                let nt = pb.cross(pc);
                dv += d[fi].dot(nt);
                nt
            } else {
                let old = tri.map(|v| pos.get(v) - origin);
                let mut new = old;
                for c in 0..3 {
                    if slot[c] != usize::MAX {
                        new[c] += d[slot[c]];
                    }
                }
                dv += new[0].dot(new[1].cross(new[2])) - old[0].dot(old[1].cross(old[2]));
                let mut nt = DVec3::ZERO;
                for a in 0..3 {
                    if slot[a] != usize::MAX {
                        nt += new[(a + 1) % 3].cross(new[(a + 2) % 3]);
                    }
                }
                nt
            };
            n += nt;
            scale += nt.length_squared();
        }
    }
    // A gradient that cancels out against its faces' own (|n|² ≪ Σ|n_t|²) is degenerate.
    let nn = n.length_squared();
    if !(nn > DEGENERATE * DEGENERATE * scale) {
        return None;
    }
    Some(n * (-dv / nn))
}

/// Solve the small SPD system `m x = b` by Cholesky; `None` if a pivot is not clearly positive.
fn solve_spd<const N: usize>(m: [[f64; N]; N], b: [DVec3; N]) -> Option<[DVec3; N]> {
    let mut l = [[0.0f64; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let s = m[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if !(s > DEGENERATE * m[i][i]) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [DVec3::ZERO; N];
    for i in 0..N {
        y[i] = (b[i] - (0..i).fold(DVec3::ZERO, |s, k| s + l[i][k] * y[k])) / l[i][i];
    }
    let mut x = [DVec3::ZERO; N];
    for i in (0..N).rev() {
        x[i] = (y[i] - (i + 1..N).fold(DVec3::ZERO, |s, k| s + l[k][i] * x[k])) / l[i][i];
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
    ws: &mut Workspace,
) -> SweepStats {
    let mut stats = SweepStats::default();
    for e in edges {
        count(&mut stats, apply(topo, triangles, pos, sums, e, params, ws));
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
    ws: &mut Workspace,
) -> SweepStats {
    let mut stats = SweepStats::default();
    for t in faces {
        let free = triangles[t as usize];
        count(
            &mut stats,
            apply(topo, triangles, pos, sums, free, params, ws),
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
        let tris = vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
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
            };
            let out = apply(
                &topo,
                &tris,
                &mut pos[..],
                &mut sums[..],
                [0, 2],
                p,
                &mut Workspace::default(),
            );
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
        };
        apply(
            &topo,
            &tris,
            &mut pos[..],
            &mut sums[..],
            [0, 2],
            p,
            &mut Workspace::default(),
        );
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
        };
        let stats = sweep_triangles(
            &topo,
            &tris,
            &mut pos[..],
            &mut sums[..],
            0..8,
            p,
            &mut Workspace::default(),
        );
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
        };
        let before = pos.clone();
        let out = apply(
            &topo,
            &tris,
            &mut pos[..],
            &mut sums[..],
            [0, 1],
            p,
            &mut Workspace::default(),
        );
        assert_eq!(out, Outcome::SkippedFixed);
        assert_eq!(pos, before);

        // Coincident vertices: the volume gradient vanishes, so the stencil is degenerate, not NaN.
        let (_, tris) = bumpy_octahedron(DVec3::ZERO);
        let topo = Topology::build(6, &tris).unwrap();
        let mut pos = vec![DVec3::splat(3.0); 6];
        let mut sums = neighbor_sums(&topo, &pos);
        let out = apply(
            &topo,
            &tris,
            &mut pos[..],
            &mut sums[..],
            [0, 2],
            p,
            &mut Workspace::default(),
        );
        assert_eq!(out, Outcome::SkippedDegenerate);
        assert!(pos.iter().all(|p| *p == DVec3::splat(3.0)));
    }

    #[test]
    fn rejection_keeps_energy_from_rising() {
        let (mut pos, tris) = bumpy_octahedron(DVec3::ZERO);
        let topo = Topology::build(6, &tris).unwrap();
        let mut sums = neighbor_sums(&topo, &pos);
        let p = StencilParams {
            volume: true,
            reject_energy_increase: true,
        };
        let mut ws = Workspace::default();
        let all: Vec<u32> = (0..6).collect();
        for _ in 0..20 {
            for e in topo.edges().collect::<Vec<_>>() {
                let before = pos.clone();
                let rows: Vec<u32> = all.clone();
                let e0 = energy(&topo, &before, &rows);
                if apply(&topo, &tris, &mut pos[..], &mut sums[..], e, p, &mut ws)
                    == Outcome::Applied
                {
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
