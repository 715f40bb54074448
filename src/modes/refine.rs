//! Adaptive subdivision and the paper's refine-and-smooth workflow (Liu et al. 2002, §4 and
//! Figs. 5–7): refine a coarse mesh until no edge is longer than δ, smooth it with `vcs`, repeat.
//!
//! - [`subdivide`] splits triangles until every edge is at most `max_edge` (δ). New vertices are
//!   edge midpoints, so they lie on the input's triangles and the volume of a closed mesh does not
//!   change (up to rounding); a closed manifold stays closed and manifold, orientation is kept,
//!   and an open mesh keeps its boundary (its boundary edges are split, never moved).
//! - [`refine`] alternates [`subdivide`] and whole-mesh smoothing ([`crate::engine::smooth_in_order`])
//!   for a number of rounds, recording volume, counts and edge lengths per round.
//!
//! # Scheme: conforming longest-edge bisection (Rivara)
//!
//! The paper splits each long edge uniformly into `ceil(len/δ)` pieces, scatters points inside the
//! faces and triangulates them, without saying how. We use Rivara's conforming longest-edge
//! bisection, which reaches the same guarantee (every edge ≤ δ, new points on the input surface)
//! with a triangulation that is valid by construction:
//!
//! 1. Mark every edge longer than δ.
//! 2. Closure: a triangle with a marked edge also marks its own longest edge (ties broken by the
//!    lower `(min id, max id)` key, so the choice is deterministic), until nothing changes.
//! 3. Every marked edge gets its midpoint (one new vertex per undirected edge, shared by all its
//!    triangles, so neighbours agree and no crack opens).
//! 4. A triangle with one or two marked edges is bisected on its longest edge (midpoint to the
//!    opposite corner), and the half that holds the other marked edge, if any, again on that edge:
//!    2 or 3 triangles. A triangle with three marked edges gets the regular split into four
//!    triangles similar to it (corner triangles + middle one), as uniform subdivision would. All
//!    children keep the parent's orientation.
//!
//! Passes repeat until no edge is longer than δ. Longest-edge bisection keeps the smallest angle
//! at least half the input's (Rosenberg–Stenger), and the regular split keeps the angles, so the
//! triangles stay well shaped and lengths halve every pass or two. Where every edge is long the
//! result is the uniform midpoint subdivision. Why not the paper's uniform `k`-split with a per-face point lattice:
//! stitching lattices of different densities to edges split into different numbers of pieces
//! needs a constrained triangulation per face whose validity and edge bound are much harder to
//! guarantee. The price: pieces are halves, so an edge of length just over `2^j·δ` ends in `2^(j+1)`
//! pieces where the paper's `ceil(len/δ)` could be up to about half that, and a bisected triangle's
//! new median can need one more pass.
//!
//! A triangle with no edge longer than δ is left as it is unless a neighbour's bisection splits
//! a shared edge (conformity). Vertex ids `0..n` keep their positions; new vertices are appended.
//! Degenerate triangles (a repeated index) are split like any other and stay degenerate.

use glam::DVec3;
use rayon::prelude::*;

use crate::engine::{self, Observer};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::metrics;
use crate::smooth::Options;

/// Largest number of triangles [`subdivide`] creates (2^31); a δ that needs more is refused.
pub const MAX_TRIANGLES: u64 = 1 << 31;

/// Bisection passes after which [`subdivide`] gives up. Not reached in practice: every pass or
/// two halves the longest edge, and the triangle limit caps the ratio of length to δ near 2^31.
const MAX_PASSES: usize = 200;

/// What [`subdivide`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct SubdivideStats {
    pub vertices_before: usize,
    pub triangles_before: usize,
    pub vertices_after: usize,
    pub triangles_after: usize,
    /// Longest edge of the input and of the output.
    pub max_edge_before: f64,
    pub max_edge_after: f64,
    /// Bisection passes made (0: nothing to split).
    pub passes: usize,
}

/// Check that `max_edge` is a usable δ: finite and positive.
pub fn check_max_edge(max_edge: f64) -> Result<()> {
    if max_edge.is_finite() && max_edge > 0.0 {
        Ok(())
    } else {
        Err(Error::parameter(
            "max_edge",
            format!("must be a finite length > 0, got {max_edge}"),
        ))
    }
}

/// A lower bound on the triangles [`subdivide`] makes from `mesh` for `max_edge`: a triangle
/// whose edges are all ≤ δ has area ≤ (√3/4)·δ², and an edge of length `l` ends up in at least
/// `ceil(l/δ)` pieces. Cheap (no allocation); used to refuse a δ beyond [`MAX_TRIANGLES`] up front.
pub fn triangles_at_least(mesh: &Mesh, max_edge: f64) -> f64 {
    let pos = &mesh.positions;
    let cell = 3f64.sqrt() / 4.0 * max_edge * max_edge;
    mesh.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| pos.get(v as usize).copied().unwrap_or_default());
            let by_area = 0.5 * (b - a).cross(c - a).length() / cell;
            let longest = (b - a).length().max((c - b).length()).max((a - c).length());
            by_area.max(longest / max_edge).max(1.0)
        })
        .sum()
}

/// The triangles [`subdivide`] makes from `mesh` for `max_edge`, estimated from above: what
/// memory checks size the output by. Bisection halves, so an edge of length `l > δ` ends in
/// `p(l) = 2^ceil(log2(l/δ))` pieces (not the paper's `ceil(l/δ)`), and a triangle whose two
/// longest edges end in `p₁ ≥ p₂` pieces becomes about `p₁·p₂` triangles (`p²` under the regular
/// split, fewer where only the longest edge is long). Not a proven bound (a neighbour's closure
/// can split an edge once more), but on the test scans and noisy spheres, tori and icosahedra at
/// δ from their longest edge down to 1/300 of it, it was never below the count made and at most
/// 29 % above it ([`triangles_at_least`] was up to 3× below); only a δ that divides edges into
/// halves of exactly δ, where rounding splits some of them once more, gave a few % more. Cheap
/// (no allocation).
pub fn estimate_triangles(mesh: &Mesh, max_edge: f64) -> f64 {
    let pos = &mesh.positions;
    let pieces = |l: f64| {
        if l > max_edge {
            (l / max_edge).log2().ceil().exp2()
        } else {
            1.0
        }
    };
    mesh.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| pos.get(v as usize).copied().unwrap_or_default());
            let mut p = [(b - a).length(), (c - b).length(), (a - c).length()].map(pieces);
            p.sort_by(|x, y| y.total_cmp(x));
            p[0] * p[1]
        })
        .sum()
}

/// Subdivide `mesh` in place until every edge is at most `max_edge` (see the module doc for the
/// scheme and its guarantees). The positions move to the heap; the source layout follows the split
/// where it can ([`crate::mesh::FileLayout::subdivided`]: a PLY's vertex properties are
/// interpolated at the new vertices, its face properties copied to the child faces) and is
/// dropped otherwise, keeping the format and the coordinate precision.
///
/// Errors: `max_edge` not finite and positive; triangles indexing vertices out of range; a δ
/// that would create more than [`MAX_TRIANGLES`] triangles (checked before allocating).
pub fn subdivide(mesh: &mut Mesh, max_edge: f64) -> Result<SubdivideStats> {
    check_max_edge(max_edge)?;
    let n = mesh.positions.len();
    if let Some((t, _)) = mesh
        .triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.iter().any(|&v| v as usize >= n))
    {
        return Err(Error::topology(format!(
            "triangle {t} indexes a vertex out of range (0..{n})"
        )));
    }
    let estimate = triangles_at_least(mesh, max_edge);
    if estimate > MAX_TRIANGLES as f64 {
        return Err(too_many(estimate, max_edge));
    }
    let mut stats = SubdivideStats {
        vertices_before: n,
        triangles_before: mesh.triangles.len(),
        max_edge_before: max_edge_of(&mesh.positions, &mesh.triangles),
        ..Default::default()
    };
    let limit2 = max_edge * max_edge;
    if stats.max_edge_before * stats.max_edge_before > limit2 {
        let mut pos: Vec<DVec3> = mesh.positions.to_vec();
        let mut tris: Vec<[u32; 3]> = mesh.triangles.to_vec();
        // What the source layout needs to follow the split: each new vertex's edge, each
        // triangle's input face (a polygon's fan triangles share their polygon).
        let mut lineage = mesh.source.layout.as_ref().map(|_| Lineage {
            parents: Vec::new(),
            face_of: match &mesh.source.face_sizes {
                Some(sizes) => sizes
                    .iter()
                    .enumerate()
                    .flat_map(|(f, &k)| {
                        std::iter::repeat_n(f as u32, (k as usize).saturating_sub(2))
                    })
                    .collect(),
                None => (0..tris.len() as u32).collect(),
            },
        });
        lineage.take_if(|l| l.face_of.len() != tris.len());
        loop {
            if stats.passes >= MAX_PASSES {
                return Err(Error::topology(format!(
                    "subdivision did not bring every edge down to {max_edge} after {MAX_PASSES} passes"
                )));
            }
            if !bisect_pass(&mut pos, &mut tris, limit2, max_edge, lineage.as_mut())? {
                break;
            }
            stats.passes += 1;
        }
        let source = std::mem::take(&mut mesh.source);
        let layout = source
            .layout
            .zip(lineage)
            .and_then(|(l, t)| l.subdivided(&t.parents, &tris, &t.face_of));
        *mesh = Mesh::new(pos, tris);
        mesh.source.layout = layout;
        mesh.source.format = source.format;
        mesh.source.precision = source.precision;
        mesh.source.input_faces = mesh.triangles.len();
    }
    stats.vertices_after = mesh.positions.len();
    stats.triangles_after = mesh.triangles.len();
    stats.max_edge_after = max_edge_of(&mesh.positions, &mesh.triangles);
    Ok(stats)
}

fn too_many(triangles: f64, max_edge: f64) -> Error {
    Error::parameter(
        "max_edge",
        format!(
            "{max_edge} would create at least {triangles:.3e} triangles, more than the limit of \
             2^31; choose a larger one"
        ),
    )
}

/// Longest edge of `triangles` (0 for none).
pub fn max_edge_of(pos: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .par_iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| pos[v as usize]);
            (b - a)
                .length_squared()
                .max((c - b).length_squared())
                .max((a - c).length_squared())
        })
        .reduce(|| 0.0, f64::max)
        .sqrt()
}

/// Canonical key of the undirected edge `{u, v}`.
#[inline]
fn key(u: u32, v: u32) -> u64 {
    let (a, b) = if u < v { (u, v) } else { (v, u) };
    ((a as u64) << 32) | b as u64
}

/// Where the vertices and triangles of a subdivision came from, for the source layout
/// ([`crate::mesh::FileLayout::subdivided`]).
struct Lineage {
    /// The edge endpoints of each new vertex, in order of creation.
    parents: Vec<[u32; 2]>,
    /// The input face of each current triangle.
    face_of: Vec<u32>,
}

/// One conforming bisection pass. Returns false (and changes nothing) when no edge is longer
/// than δ (`limit2` = δ²). With `lineage`, records the new vertices' edges and the triangles'
/// input faces.
fn bisect_pass(
    pos: &mut Vec<DVec3>,
    tris: &mut Vec<[u32; 3]>,
    limit2: f64,
    max_edge: f64,
    mut lineage: Option<&mut Lineage>,
) -> Result<bool> {
    // Half-edges (key, 3·face + corner) sorted by key: undirected edges are the runs of equal keys.
    let mut half: Vec<(u64, u32)> = Vec::with_capacity(3 * tris.len());
    half.extend(
        tris.iter().enumerate().flat_map(|(f, t)| {
            (0..3).map(move |c| (key(t[c], t[(c + 1) % 3]), (3 * f + c) as u32))
        }),
    );
    half.par_sort_unstable();
    let mut edge_of = vec![0u32; half.len()]; // half-edge → edge id
    let mut start: Vec<usize> = Vec::new(); // edge id → first index in `half`
    for (i, &(k, h)) in half.iter().enumerate() {
        if i == 0 || half[i - 1].0 != k {
            start.push(i);
        }
        edge_of[h as usize] = (start.len() - 1) as u32;
    }
    let n_edges = start.len();
    start.push(half.len());
    let len2: Vec<f64> = (0..n_edges)
        .into_par_iter()
        .map(|e| {
            let k = half[start[e]].0;
            let (a, b) = ((k >> 32) as usize, (k & 0xffff_ffff) as usize);
            (pos[a] - pos[b]).length_squared()
        })
        .collect();
    let mut marked: Vec<bool> = len2.iter().map(|&l| l > limit2).collect();
    if !marked.iter().any(|&m| m) {
        return Ok(false);
    }
    // Each face's longest edge, as a corner index (edge from corner c to c + 1).
    let longest: Vec<u8> = (0..tris.len())
        .into_par_iter()
        .map(|f| {
            let score = |c: usize| {
                let e = edge_of[3 * f + c] as usize;
                (len2[e], std::cmp::Reverse(half[start[e]].0))
            };
            let mut best = 0;
            for c in 1..3 {
                if score(c) > score(best) {
                    best = c;
                }
            }
            best as u8
        })
        .collect();
    // Closure: a face with a marked edge marks its longest edge.
    let face_marked =
        |f: usize, marked: &[bool]| (0..3).any(|c| marked[edge_of[3 * f + c] as usize]);
    let mut work: Vec<usize> = (0..tris.len())
        .filter(|&f| face_marked(f, &marked))
        .collect();
    while let Some(f) = work.pop() {
        let e = edge_of[3 * f + longest[f] as usize] as usize;
        if !marked[e] {
            marked[e] = true;
            work.extend(
                half[start[e]..start[e + 1]]
                    .iter()
                    .map(|&(_, h)| h as usize / 3),
            );
        }
    }
    // Count before allocating.
    let new_vertices = marked.iter().filter(|&&m| m).count();
    let new_triangles: u64 = (0..tris.len())
        .map(|f| {
            1 + (0..3)
                .filter(|&c| marked[edge_of[3 * f + c] as usize])
                .count() as u64
        })
        .sum();
    if new_triangles > MAX_TRIANGLES {
        return Err(too_many(new_triangles as f64, max_edge));
    }
    if pos.len() + new_vertices > u32::MAX as usize {
        return Err(Error::parameter(
            "max_edge",
            format!("{max_edge} would create more than 2^32 vertices; choose a larger one"),
        ));
    }
    // Midpoints, one per marked edge, in ascending edge-key order.
    let mut mid = vec![u32::MAX; n_edges];
    pos.reserve_exact(new_vertices);
    for e in 0..n_edges {
        if marked[e] {
            let k = half[start[e]].0;
            let (a, b) = ((k >> 32) as usize, (k & 0xffff_ffff) as usize);
            mid[e] = pos.len() as u32;
            pos.push(0.5 * (pos[a] + pos[b]));
            if let Some(l) = lineage.as_deref_mut() {
                l.parents.push([a as u32, b as u32]);
            }
        }
    }
    let mut out: Vec<[u32; 3]> = Vec::with_capacity(new_triangles as usize);
    for (f, t) in tris.iter().enumerate() {
        let l = longest[f] as usize;
        let m_of = |c: usize| mid[edge_of[3 * f + (c % 3)] as usize];
        let m = m_of(l);
        if m == u32::MAX {
            out.push(*t);
            continue;
        }
        // Rotate so that the longest edge is (a, b), opposite corner c.
        let (a, b, c) = (t[l], t[(l + 1) % 3], t[(l + 2) % 3]);
        let (m_bc, m_ca) = (m_of(l + 1), m_of(l + 2));
        if m_bc != u32::MAX && m_ca != u32::MAX {
            // All three marked: the regular split into four triangles similar to the parent.
            out.extend([[a, m, m_ca], [m, b, m_bc], [m_ca, m_bc, c], [m, m_bc, m_ca]]);
            continue;
        }
        // Half (a, m, c): split on edge (c, a) at m_ca.
        if m_ca == u32::MAX {
            out.push([a, m, c]);
        } else {
            out.push([a, m, m_ca]);
            out.push([m, c, m_ca]);
        }
        // Half (m, b, c): split on edge (b, c) at m_bc.
        if m_bc == u32::MAX {
            out.push([m, b, c]);
        } else {
            out.push([m, b, m_bc]);
            out.push([m, m_bc, c]);
        }
    }
    debug_assert_eq!(out.len() as u64, new_triangles);
    if let Some(l) = lineage {
        // Children follow their parent in `out`: 1 + (marked edges) of them each.
        let mut face_of = Vec::with_capacity(out.len());
        for (f, &input) in l.face_of.iter().enumerate() {
            let children = 1
                + (0..3)
                    .filter(|&c| marked[edge_of[3 * f + c] as usize])
                    .count();
            face_of.extend(std::iter::repeat_n(input, children));
        }
        l.face_of = face_of;
    }
    *tris = out;
    Ok(true)
}

/// Options of [`refine`]: δ, the number of rounds and the smoothing of each round.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RefineOptions {
    /// δ: the longest edge [`subdivide`] leaves.
    pub max_edge: f64,
    /// Rounds of subdivide-then-smooth (the paper's Figs. 5–7 show 2).
    pub rounds: usize,
    /// Smoothing after each subdivision; default `vcs` with 5 iterations, as in the figures.
    pub smoothing: Options,
}

impl Default for RefineOptions {
    fn default() -> Self {
        RefineOptions {
            max_edge: 1.0,
            rounds: 2,
            smoothing: Options {
                method: crate::Method::REFINE,
                iterations: 5,
                ..Options::default()
            },
        }
    }
}

/// One round of [`refine`].
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct RoundRecord {
    /// 1-based round number.
    pub round: usize,
    pub subdivision: SubdivideStats,
    /// Signed volume before the subdivision, after it, and after the smoothing, all about the
    /// input's centroid.
    pub volume_before: f64,
    pub volume_subdivided: f64,
    pub volume_smoothed: f64,
    /// Longest edge after the smoothing (it can exceed δ again: the next round splits it).
    pub max_edge_smoothed: f64,
}

/// The paper's refine-and-smooth workflow: `rounds` times, [`subdivide`] to `max_edge`, then
/// smooth with `opts.smoothing` on `threads` threads (`None`: all cores). Returns one record per
/// round. With `vcs` on a closed mesh the volume moves only by rounding (≤ 1e-9 relative per round).
pub fn refine(
    mesh: &mut Mesh,
    opts: &RefineOptions,
    threads: Option<usize>,
    observer: &mut dyn Observer,
) -> Result<Vec<RoundRecord>> {
    refine_checked(mesh, opts, threads, observer, &mut |_, _| Ok(()))
}

/// [`refine`] that calls `check(round, mesh)` before each round's subdivision and stops with its
/// error: how a caller refuses a round whose output (see [`estimate_triangles`]) would not fit
/// its memory, before the round allocates anything.
pub fn refine_checked(
    mesh: &mut Mesh,
    opts: &RefineOptions,
    threads: Option<usize>,
    observer: &mut dyn Observer,
    check: &mut dyn FnMut(usize, &Mesh) -> Result<()>,
) -> Result<Vec<RoundRecord>> {
    check_max_edge(opts.max_edge)?;
    // Grown round by round: `rounds` comes from the caller and may be anything.
    let mut records = Vec::new();
    // Every volume about the input's centroid: an open mesh's depends on the point, and
    // subdivision moves the centroid of the vertices.
    let origin = metrics::centroid(&mesh.positions);
    let volume = |m: &Mesh| metrics::volume_about(&m.positions, &m.triangles, origin);
    for round in 1..=opts.rounds {
        check(round, mesh)?;
        let volume_before = volume(mesh);
        let subdivision = subdivide(mesh, opts.max_edge)?;
        let volume_subdivided = volume(mesh);
        let settings = engine::EngineSettings {
            threads,
            ..Default::default()
        };
        engine::smooth_in_order(mesh, &opts.smoothing, &settings, observer)?;
        records.push(RoundRecord {
            round,
            subdivision,
            volume_before,
            volume_subdivided,
            volume_smoothed: volume(mesh),
            max_edge_smoothed: max_edge_of(&mesh.positions, &mesh.triangles),
        });
    }
    Ok(records)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes;
    use crate::topology::Topology;

    fn edges_ok(mesh: &Mesh, delta: f64) {
        let max = max_edge_of(&mesh.positions, &mesh.triangles);
        assert!(max <= delta * (1.0 + 1e-12), "max edge {max} > {delta}");
    }

    #[test]
    fn single_triangle_open_boundary_kept() {
        let mut m = Mesh::new(
            vec![DVec3::ZERO, DVec3::X * 3.0, DVec3::Y * 2.0],
            vec![[0, 1, 2]],
        );
        let s = subdivide(&mut m, 0.5).unwrap();
        edges_ok(&m, 0.5);
        assert_eq!(s.triangles_after, m.triangles.len());
        // Area and orientation kept: every child has a positive z normal.
        let area = metrics::area(&m.positions, &m.triangles);
        assert!((area - 3.0).abs() < 1e-12, "{area}");
        for t in m.triangles.iter() {
            let [a, b, c] = t.map(|v| m.positions[v as usize]);
            assert!((b - a).cross(c - a).z > 0.0);
        }
        let topo = Topology::build(m.positions.len(), &m.triangles).unwrap();
        assert_eq!(topo.stats.non_manifold_edges, 0);
        assert!(topo.stats.boundary_edges > 3);
    }

    #[test]
    fn nothing_to_do_keeps_mesh_and_source() {
        let mut m = shapes::icosphere(1);
        let before = m.triangles.to_vec();
        let s = subdivide(&mut m, 10.0).unwrap();
        assert_eq!(s.passes, 0);
        assert_eq!(&m.triangles[..], &before[..]);
        assert_eq!(s.triangles_before, s.triangles_after);
    }

    #[test]
    fn bad_delta_and_huge_estimate_refused() {
        let mut m = shapes::icosphere(0);
        for d in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(subdivide(&mut m, d).is_err());
        }
        let e = subdivide(&mut m, 1e-6).unwrap_err().to_string();
        assert!(e.contains("2^31"), "{e}");
        assert_eq!(m.triangles.len(), 20);
    }

    #[test]
    fn degenerate_triangle_does_not_hang() {
        let mut m = Mesh::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::X * 2.0],
            vec![[0, 1, 2], [0, 0, 2]],
        );
        subdivide(&mut m, 0.3).unwrap();
        edges_ok(&m, 0.3);
    }
}
