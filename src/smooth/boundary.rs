//! Boundary stencils of `boundary: smooth`: the local area-constrained smoothing of boundary
//! curves that Liu et al. propose in §4, so that each hole keeps its size.
//!
//! A boundary stencil is a boundary edge `(i, j)` of two loop vertices ([`Topology::is_loop`]);
//! along their loop it reads the chain `a₂ – a – i – j – b – b₂` (a: i's other loop neighbour, b:
//! j's, a₂ and b₂ one further). Its free vertices are i and j; everything else stays where it is.
//! Interior stencils treat loop vertices as fixed, so they keep their volumes exactly, as with
//! fixed boundaries.
//!
//! - Step 1 (curve energy): with the curve umbrella `C(v) = ½ (p_prev + p_next) − p_v` on the
//!   rows a, i, j, b (a row is left out when its vertex is not on exactly two boundary edges, or is
//!   a crease vertex), minimise `E(d) = ½ Σ_v |C(v) + Σ_f k[v][f] d_f|²` over the displacements
//!   `d_i, d_j`: `k` is −1 on the diagonal and ½ towards a loop neighbour, so
//!   `KᵀK = [[5/4 + [a]/4, −1], [−1, 5/4 + [b]/4]]` (never singular) and `(KᵀK) d = −KᵀC`.
//! - Step 2 (area): the stencil's share of its loop's vector area,
//!   `A = ½ (p_a × p_i + p_i × p_j + p_j × p_b)` (the terms of `½ Σ p_k × p_{k+1}` that move),
//!   changes by exactly `ΔA = ½ (d_i × u + d_j × v + d_i × d_j)`, `u = p_j − p_a`, `v = p_b − p_i`,
//!   and a common translation w of i and j adds exactly `½ w × c`, `c = u + v + d_j − d_i` (the
//!   chord after step 1). So a translation restores the two components of ΔA across the chord
//!   and never the one along it. Which two: with n the loop's unit vector area (measured at the
//!   iteration's start, [`Loops::measure`]) and `k = n × c / |n × c|`, w (the least, ⊥ c) makes
//!   `(ΔA + ½ w × c)·n = 0` and `(ΔA + ½ w × c)·k = 0`; the gradients `½ c × n` and `½ c × k` are
//!   orthogonal, so each is one division. The residual, along `n × k`, has no component along n:
//!   the hole's size `A_loop·n` is kept exactly by every stencil, and only the loop's tilt moves.
//! - After each sweep, [`Loops::restore`] gives each loop its first `|A|` back: the tilt changes
//!   `|A|` at second order (about 1e-5 over 10 iterations on the holes of a noisy bunny), and one
//!   sequential pass of such translations along each loop, without step 1, removes it up to the
//!   square of what it removes (1e-16 of |A| on the scans).
//!
//! Why not more: the component of ΔA along the chord is the chain's twist about its chord. No
//! translation reaches it, and moving i and j apart to restore it (with a Newton solve of least
//! norm) brings the noise back: tried on the noisy scans, it kept every loop's vector area to
//! 1e-13 and made the loops 100× rougher. The same holds for the volume of the faces touching the
//! stencil: across the surface it responds to the same motion (along the surface normal) as the
//! hole's size does where the surface meets the hole edge-on (a bust's cut base), so keeping both
//! is ill-posed; tried, it also roughened the loops. Boundary stencils therefore keep the area,
//! not their faces' volume: on a noisy demosthenes, 10 `vcs` iterations move the volume about the
//! input's centroid by 3e-5 (1e-9 with `boundary: fixed`; `lem` 6e-3).
//!
//! `lem` uses the same stencils (its holes keep their size too, though its surface shrinks);
//! `vcs-lowpass` runs them in a pass of their own after its ring stencils (in the edge colouring);
//! `laplacian` and `taubin` refuse `smooth` ([`crate::Options::check`]).
//!
//! What a stencil reads and writes, for the schedule: positions of i, j, their neighbours and
//! a₂, b₂ (two loop steps from i and j, so within 2 rings of the free vertices) and the loop
//! normals (read only during the sweep); it writes the positions of i and j and the neighbour
//! sums of their neighbours (kept up to date for the edge stencils). That is an edge stencil's
//! footprint with position reads one ring wider, which the 4-ring conflict rule of
//! [`crate::schedule`] covers: reads 3 rings out of a patch against position writes 1 ring out of
//! another. So any thread count and memory budget give the same bits.

use glam::DVec3;

use super::stencil::{self, Deviation, MAX_REACH, Outcome, StencilParams};
use super::{Field, SweepStats, Topology};

/// What a boundary stencil does besides step 1.
#[derive(Debug, Clone, Copy)]
pub struct BoundaryParams<'a> {
    /// The loops with their normals, for step 2 (`vcs` and `vcs-triangle`); `None` (`lem`): step
    /// 1 only.
    pub loops: Option<&'a Loops>,
    /// Reject a stencil whose curve energy would rise.
    pub reject_energy_increase: bool,
    /// Skip a stencil that would leave a free vertex beyond this bound.
    pub deviation: Option<Deviation<'a>>,
}

/// Apply the boundary stencils of `loops` among `edges`, in the given order, Gauss–Seidel, with
/// the boundary kernel ([`apply`]). With `interior`, the other edges get their edge stencil, as
/// [`stencil::sweep_edges`] does (the edge methods' sweep); without, they are passed over (the
/// boundary part of a triangle sweep).
#[allow(clippy::too_many_arguments)]
pub fn sweep_edges<P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut P,
    sums: &mut S,
    edges: impl IntoIterator<Item = [u32; 2]>,
    params: StencilParams,
    loops: &Loops,
    interior: bool,
) -> SweepStats {
    let mut stats = SweepStats::default();
    let bp = boundary_params(params, loops);
    for e in edges {
        if is_boundary_stencil(topo, triangles, e) {
            count(&mut stats, apply(topo, triangles, pos, sums, e, bp));
        } else if interior {
            let outcome = stencil::apply(topo, triangles, pos, sums, e, params);
            stencil::count(&mut stats, outcome);
        }
    }
    stats
}

/// The boundary kernel's parameters for a sweep with `params` over `loops`.
fn boundary_params<'a>(params: StencilParams<'a>, loops: &'a Loops) -> BoundaryParams<'a> {
    BoundaryParams {
        loops: Some(loops),
        reject_energy_increase: params.reject_energy_increase,
        deviation: params.deviation,
    }
}

/// Tally a boundary stencil's outcome: as any stencil's, and in the boundary counts.
fn count(stats: &mut SweepStats, outcome: Outcome) {
    stencil::count(stats, outcome);
    match outcome {
        Outcome::Applied => stats.boundary_applied += 1,
        _ => stats.boundary_skipped += 1,
    }
}

/// Whether edge `(i, j)` is a boundary stencil: two loop vertices joined by a boundary edge.
#[inline]
pub fn is_boundary_stencil(topo: &Topology, triangles: &[[u32; 3]], [i, j]: [u32; 2]) -> bool {
    topo.is_loop(i)
        && topo.is_loop(j)
        && topo
            .loop_neighbors(triangles, i)
            .is_some_and(|n| n.contains(&j))
}

/// The neighbour of `v` along its loop other than `from`, if `v` is on exactly two boundary edges.
#[inline]
fn next_along(topo: &Topology, triangles: &[[u32; 3]], v: u32, from: u32) -> Option<u32> {
    let [x, y] = topo.loop_neighbors(triangles, v)?;
    if x == from {
        Some(y)
    } else if y == from {
        Some(x)
    } else {
        None
    }
}

/// Apply the boundary stencil of boundary edge `(i, j)` (see the module doc) to `pos`, updating
/// the neighbour-sum cache `sums`. Positions and sums are written only when the outcome is
/// [`Outcome::Applied`]. Skipped as fixed when the edge is not a boundary stencil or its loop has
/// fewer than 4 vertices (a triangular hole has no curve to smooth); skipped as degenerate when
/// step 2 does not converge or the result would move a vertex farther than `MAX_REACH` radii.
pub fn apply<P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut P,
    sums: &mut S,
    [i, j]: [u32; 2],
    params: BoundaryParams,
) -> Outcome {
    if !topo.is_loop(i) || !topo.is_loop(j) {
        return Outcome::SkippedFixed;
    }
    let (Some(a), Some(b)) = (
        next_along(topo, triangles, i, j),
        next_along(topo, triangles, j, i),
    ) else {
        return Outcome::SkippedFixed;
    };
    if a == b {
        return Outcome::SkippedFixed;
    }
    let origin = (pos.get(i) + pos.get(j)) * 0.5;
    let at = |v: u32| pos.get(v) - origin;
    let (pa, pi, pj, pb) = (at(a), at(i), at(j), at(b));

    // Step 1: rows a and b when their vertex has a second loop neighbour and is not a crease;
    // `(from, p_from)` is the row's free neighbour.
    let row = |v: u32, from: u32, p_from: DVec3| {
        if topo.is_crease(v) {
            return None;
        }
        next_along(topo, triangles, v, from).map(|far| 0.5 * (at(far) + p_from) - at(v))
    };
    let ca = row(a, i, pi);
    let cb = row(b, j, pj);
    let ci = 0.5 * (pa + pj) - pi;
    let cj = 0.5 * (pi + pb) - pj;
    let (m_ii, m_jj) = (
        1.25 + 0.25 * ca.is_some() as u8 as f64,
        1.25 + 0.25 * cb.is_some() as u8 as f64,
    );
    // −KᵀC, columns i and j of K: (a: ½, i: −1, j: ½) and (i: ½, j: −1, b: ½).
    let ri = ci - 0.5 * (ca.unwrap_or(DVec3::ZERO) + cj);
    let rj = cj - 0.5 * (ci + cb.unwrap_or(DVec3::ZERO));
    let det = m_ii * m_jj - 1.0;
    let mut d = [(m_jj * ri + rj) / det, (ri + m_ii * rj) / det];

    if let Some(loops) = params.loops {
        let Some((normal, _)) = loops.target(i) else {
            return Outcome::SkippedDegenerate;
        };
        // ΔA = ½ (d_i × u + d_j × v + d_i × d_j), u = p_j − p_a, v = p_b − p_i (exact: bilinear);
        // a common translation w adds ½ w × c, c = u + v + d_j − d_i.
        let (u, v) = (pj - pa, pb - pi);
        let change = 0.5 * (d[0].cross(u) + d[1].cross(v) + d[0].cross(d[1]));
        let c = u + v + d[1] - d[0];
        match translation(change, c, normal, 0.0) {
            Some(w) => d = [d[0] + w, d[1] + w],
            None => return Outcome::SkippedDegenerate,
        }
    }
    // The stencil's radius: its farthest vertex from the origin.
    let radius2 = [i, j]
        .iter()
        .flat_map(|&f| topo.neighbors(f))
        .fold(0.0f64, |r, &x| r.max(at(x).length_squared()));
    let reach2 = MAX_REACH * MAX_REACH * radius2;
    if !d
        .iter()
        .all(|x| x.is_finite() && x.length_squared() <= reach2)
    {
        return Outcome::SkippedDegenerate;
    }
    if let Some(bound) = params.deviation {
        let limit2 = bound.limit * bound.limit;
        let beyond = |v: u32, dv: DVec3| {
            (pos.get(v) + dv - bound.input[v as usize]).length_squared() > limit2
        };
        if beyond(i, d[0]) || beyond(j, d[1]) {
            return Outcome::DeviationLimited;
        }
    }
    if params.reject_energy_increase {
        // 2 (E(d) − E(0)) = dᵀ(KᵀK)d − 2 dᵀ(−KᵀC), exact from the normal equations.
        let change = m_ii * d[0].length_squared() + m_jj * d[1].length_squared()
            - 2.0 * d[0].dot(d[1])
            - 2.0 * (d[0].dot(ri) + d[1].dot(rj));
        if change > 0.0 {
            return Outcome::Rejected;
        }
    }
    for (f, df) in [(i, d[0]), (j, d[1])] {
        pos.add(f, df);
        for &u in topo.neighbors(f) {
            sums.add(u, df);
        }
    }
    Outcome::Applied
}

/// Step 2's translation: the least w (perpendicular to the chord `c`) for which the area change
/// `change + ½ w × c` has the component `−share` along the loop's unit `normal` n and none along
/// `k = n × c / |n × c|`. The two gradients, `½ c × n` and `½ c × k`, are orthogonal (k ⊥ n, k ⊥ c),
/// so each component is restored on its own. `None` when the chord is (nearly) along the normal
/// or not a number.
fn translation(change: DVec3, c: DVec3, normal: DVec3, share: f64) -> Option<DVec3> {
    let nc = normal.cross(c);
    let len2 = nc.length_squared();
    // Negated so that a NaN counts as degenerate.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(len2 > DEGENERATE * c.length_squared()) {
        return None;
    }
    let k = nc / len2.sqrt();
    let (g1, g2) = (0.5 * c.cross(normal), 0.5 * c.cross(k));
    let along = change.dot(normal) + share;
    Some(-along / g1.length_squared() * g1 - change.dot(k) / g2.length_squared() * g2)
}

/// Squared sine of the angle between chord and loop normal below which step 2 is degenerate.
const DEGENERATE: f64 = 1e-12;

/// The boundary loops of a mesh: its boundary edges, directed as their face runs them, grouped
/// into loops (components of the boundary edges), and each loop's unit vector area
/// `n = A / |A|`, `A = ½ Σ p_a × p_b` over its edges, measured by [`Loops::measure`].
#[derive(Debug, Clone, Default)]
pub struct Loops {
    /// Vertices on boundary edges, ascending, and the loop of each.
    vertices: Vec<u32>,
    loop_of: Vec<u32>,
    /// The edges of loop k are `edges[starts[k]..starts[k + 1]]`.
    edges: Vec<[u32; 2]>,
    starts: Vec<usize>,
    /// Per loop: its boundary stencils, and |A| at the first [`Loops::measure`] (the input's).
    stencils: Vec<u32>,
    reference: Vec<f64>,
    /// Per loop, from the last [`Loops::measure`]: the unit normal and each stencil's share of
    /// the excess `|A| − reference`; `None` for a loop of (nearly) no area.
    targets: Vec<Option<(DVec3, f64)>>,
}

/// The directed boundary edges of `triangles`: an edge a → b of a face is one when no other
/// face holds both ends (only fixed vertices can be on one). Linear in the faces.
pub fn boundary_edges(topo: &Topology, triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut directed = Vec::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a == b || !topo.is_fixed(a) || !topo.is_fixed(b) {
                continue;
            }
            let holding = topo
                .faces_of(a, triangles)
                .filter(|&f| triangles[f as usize].contains(&b))
                .take(2)
                .count();
            if holding == 1 {
                directed.push([a, b]);
            }
        }
    }
    directed
}

impl Loops {
    /// Find the boundary loops of `triangles` (the topology's, oriented). Linear in the faces.
    pub fn find(topo: &Topology, triangles: &[[u32; 3]]) -> Loops {
        Loops::from_edges(topo, triangles, boundary_edges(topo, triangles))
    }

    /// The directed boundary edges of the loops, in loop order (what [`Loops::from_edges`]
    /// takes back: a cluster plan stores them, so that no rank reads every face).
    pub fn edges(&self) -> &[[u32; 2]] {
        &self.edges
    }

    /// The loops of the directed boundary edges `directed` of `triangles` (as
    /// [`boundary_edges`] finds them, in any order). Reads the faces of boundary vertices only.
    pub fn from_edges(
        topo: &Topology,
        triangles: &[[u32; 3]],
        mut directed: Vec<[u32; 2]>,
    ) -> Loops {
        let mut vertices: Vec<u32> = directed.iter().flatten().copied().collect();
        vertices.sort_unstable();
        vertices.dedup();
        let index = |v: u32| vertices.binary_search(&v).expect("a boundary vertex");
        // Union-find over the boundary edges; a loop is numbered by its smallest vertex.
        let mut parent: Vec<usize> = (0..vertices.len()).collect();
        fn root(parent: &mut [usize], mut x: usize) -> usize {
            while parent[x] != x {
                parent[x] = parent[parent[x]];
                x = parent[x];
            }
            x
        }
        for &[a, b] in &directed {
            let (ra, rb) = (root(&mut parent, index(a)), root(&mut parent, index(b)));
            let (lo, hi) = (ra.min(rb), ra.max(rb));
            parent[hi] = lo;
        }
        let mut number = vec![u32::MAX; vertices.len()];
        let mut count = 0u32;
        let mut loop_of = vec![0u32; vertices.len()];
        for (x, l) in loop_of.iter_mut().enumerate() {
            let r = root(&mut parent, x);
            if number[r] == u32::MAX {
                number[r] = count;
                count += 1;
            }
            *l = number[r];
        }
        directed.sort_unstable_by_key(|&[a, b]| (loop_of[index(a)], a, b));
        let mut starts = vec![0usize; count as usize + 1];
        for &[a, _] in &directed {
            starts[loop_of[index(a)] as usize + 1] += 1;
        }
        for k in 0..count as usize {
            starts[k + 1] += starts[k];
        }
        let mut stencils = vec![0u32; count as usize];
        for &[a, b] in &directed {
            if is_boundary_stencil(topo, triangles, [a, b]) {
                stencils[loop_of[index(a)] as usize] += 1;
            }
        }
        Loops {
            vertices,
            loop_of,
            edges: directed,
            starts,
            stencils,
            reference: Vec::new(),
            targets: vec![None; count as usize],
        }
    }

    /// The vertices on boundary edges, ascending.
    pub fn vertices(&self) -> &[u32] {
        &self.vertices
    }

    /// Number of loops.
    pub fn len(&self) -> usize {
        self.targets.len()
    }

    /// Whether the mesh has no boundary.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }

    /// Boundary stencils over all loops.
    pub fn stencils(&self) -> u64 {
        self.stencils.iter().map(|&s| s as u64).sum()
    }

    /// Loop k's vector area `½ Σ p_a × p_b` over its directed edges, summed about its first
    /// vertex (the sum does not depend on the point for a closed loop; a near one keeps digits).
    pub fn vector_area(&self, pos: &[DVec3], k: usize) -> DVec3 {
        let edges = &self.edges[self.starts[k]..self.starts[k + 1]];
        let o = edges.first().map_or(DVec3::ZERO, |e| pos[e[0] as usize]);
        edges.iter().fold(DVec3::ZERO, |s, &[a, b]| {
            s + 0.5 * (pos[a as usize] - o).cross(pos[b as usize] - o)
        })
    }

    /// Measure every loop on `pos` (in loop and edge order, so the same bits for any thread
    /// count): its unit normal, and how much of `|A|` beyond its first measure each of its
    /// stencils is to give back. A loop whose area is below 1e-12 of its edges' squared lengths
    /// gets no target.
    pub fn measure(&mut self, pos: &[DVec3]) {
        let first = self.reference.is_empty();
        for k in 0..self.targets.len() {
            let a = self.vector_area(pos, k);
            let size: f64 = self.edges[self.starts[k]..self.starts[k + 1]]
                .iter()
                .map(|&[x, y]| pos[x as usize].distance_squared(pos[y as usize]))
                .sum();
            let len = a.length();
            if first {
                self.reference.push(len);
            }
            let ok = len * len > 1e-24 * size * size && self.stencils[k] > 0;
            let share = (len - self.reference[k]) / self.stencils[k].max(1) as f64;
            self.targets[k] = ok.then(|| (a / len, share));
        }
    }

    /// Give every loop its first measured `|A|` back: measure (see [`Loops::measure`]), then
    /// along each loop, in edge order, translate the two free vertices of each boundary stencil
    /// so that the loop's area along its normal falls by the stencil's share of the excess (the
    /// change `½ w × c` is exact and linear in w). What stays is second order in the excess,
    /// which is itself second order in the sweep's drift. A translation that would leave a vertex
    /// beyond `deviation` is left out (its share stays for the next iteration). Writes only loop
    /// vertices' positions (neighbour sums are rebuilt when the next sweep starts); sequential,
    /// so the same bits for any thread count.
    pub fn restore(
        &mut self,
        topo: &Topology,
        triangles: &[[u32; 3]],
        pos: &mut [DVec3],
        deviation: Option<Deviation>,
    ) {
        self.measure(pos);
        for k in 0..self.targets.len() {
            let Some((normal, share)) = self.targets[k] else {
                continue;
            };
            for e in self.starts[k]..self.starts[k + 1] {
                let [i, j] = self.edges[e];
                if !is_boundary_stencil(topo, triangles, [i, j]) {
                    continue;
                }
                let (Some(a), Some(b)) = (
                    next_along(topo, triangles, i, j),
                    next_along(topo, triangles, j, i),
                ) else {
                    continue;
                };
                let p = |v: u32| pos[v as usize];
                let c = (p(j) - p(a)) + (p(b) - p(i));
                let Some(w) = translation(DVec3::ZERO, c, normal, share) else {
                    continue;
                };
                if let Some(bound) = deviation {
                    let limit2 = bound.limit * bound.limit;
                    let beyond =
                        |v: u32| (p(v) + w - bound.input[v as usize]).length_squared() > limit2;
                    if beyond(i) || beyond(j) {
                        continue;
                    }
                }
                pos[i as usize] += w;
                pos[j as usize] += w;
            }
        }
    }

    /// The unit normal and the excess share of the loop through boundary vertex `v`, if it has
    /// them.
    pub fn target(&self, v: u32) -> Option<(DVec3, f64)> {
        let x = self.vertices.binary_search(&v).ok()?;
        self.targets[self.loop_of[x] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::smooth::neighbor_sums;

    #[test]
    fn the_translation_restores_the_normal_and_cross_components() {
        let (change, c) = (DVec3::new(0.3, -0.2, 0.7), DVec3::new(1.0, 0.2, -0.1));
        let n = DVec3::new(0.1, 0.3, 1.0).normalize();
        let w = translation(change, c, n, 0.05).unwrap();
        let after = change + 0.5 * w.cross(c);
        let k = n.cross(c).normalize();
        assert!((after.dot(n) + 0.05).abs() < 1e-15, "{after}");
        assert!(after.dot(k).abs() < 1e-15, "{after}");
        assert!(w.dot(c).abs() < 1e-15, "not the least: {w}");
        // A chord along the normal reaches nothing.
        assert!(translation(change, n, n, 0.0).is_none());
    }

    /// An open fan around 0 whose rim of 8 is a noisy circle: a boundary stencil keeps its loop's
    /// area along the normal, lowers the curve energy of its rows and keeps the neighbour sums.
    #[test]
    fn a_stencil_keeps_its_loop_area_along_the_normal() {
        let rim = 8u32;
        let tris: Vec<[u32; 3]> = (1..=rim).map(|k| [0, k, k % rim + 1]).collect();
        let noise = [0.1, -0.2, 0.15, 0.0, -0.1, 0.2, 0.05, -0.15];
        let mut pos = vec![DVec3::new(0.0, 0.0, 0.3)];
        for k in 0..rim as usize {
            let t = std::f64::consts::TAU * k as f64 / rim as f64;
            let r = 1.0 + noise[k];
            pos.push(DVec3::new(
                r * t.cos() + 50.0,
                r * t.sin(),
                noise[(k + 3) % 8],
            ));
        }
        let topo = Topology::build(pos.len(), &tris).unwrap();
        let mut loops = Loops::find(&topo, &tris);
        assert_eq!((loops.len(), loops.stencils()), (1, rim as u64));
        loops.measure(&pos);
        let (n, _) = loops.target(1).unwrap();
        let a0 = loops.vector_area(&pos, 0);
        let energy = |p: &[DVec3]| {
            [8u32, 1, 2, 3]
                .iter()
                .map(|&v| {
                    let [x, y] = topo.loop_neighbors(&tris, v).unwrap();
                    (0.5 * (p[x as usize] + p[y as usize]) - p[v as usize]).length_squared()
                })
                .sum::<f64>()
        };
        let mut sums = neighbor_sums(&topo, &pos);
        let params = BoundaryParams {
            loops: Some(&loops),
            reject_energy_increase: false,
            deviation: None,
        };
        let before = pos.clone();
        let out = apply(&topo, &tris, &mut pos[..], &mut sums[..], [1, 2], params);
        assert_eq!(out, Outcome::Applied);
        let a1 = loops.vector_area(&pos, 0);
        assert!((a1 - a0).dot(n).abs() < 1e-12 * a0.length(), "{a0} -> {a1}");
        assert!(energy(&pos) < energy(&before));
        assert!(pos.iter().zip(&before).filter(|(a, b)| a != b).count() == 2);
        let fresh = neighbor_sums(&topo, &pos);
        assert!(
            sums.iter()
                .zip(&fresh)
                .all(|(a, b)| (*a - *b).length() < 1e-12)
        );
        // The interior edge (0, 1) is not a boundary stencil; a loop vertex is never free.
        assert!(!is_boundary_stencil(&topo, &tris, [0, 1]));
        assert_eq!(
            apply(&topo, &tris, &mut pos[..], &mut sums[..], [0, 1], params),
            Outcome::SkippedFixed
        );
        // Restoring after the stencil gives the loop its |A| back.
        loops.restore(&topo, &tris, &mut pos, None);
        let a2 = loops.vector_area(&pos, 0);
        let (excess, left) = (a1.length() - a0.length(), a2.length() - a0.length());
        assert!(excess.abs() > 1e-5 * a0.length(), "{excess}");
        assert!(left.abs() < 1e-6 * excess.abs(), "{excess} -> {left}");
    }
}
