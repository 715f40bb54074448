//! The fixed-vertex mask's bits, and what sets them after the build: pins from the caller and
//! crease edges measured on the positions and on a face-normal field the caller gives. Loop
//! vertices (boundary vertices that boundary smoothing may move along their loop) are marked by
//! the build; any other reason to fix one clears its mark.

use glam::DVec3;
use rayon::prelude::*;

use super::{CHUNK, Topology};

/// Bits of the fixed-vertex mask: any non-zero entry is a fixed vertex; [`CREASE`] also marks it
/// as a crease vertex ([`Topology::crease`]), whose row the stencil energy leaves out; [`LOOP`]
/// as a loop vertex (see the [module doc](super)), which any other reason to fix it clears.
pub(super) const FIXED: u8 = 1;
pub(super) const CREASE: u8 = 2;
pub(super) const LOOP: u8 = 4;

/// Crease edges a vertex needs to be a crease vertex ([`Topology::crease`]). Two: a crease
/// vertex is on a crease line (or a corner where lines meet); a lone crease edge, or the last
/// edge of a line that fades out, does not fix its vertices. On noisy input many falsely
/// detected edges are lone ones (Fandisk 0.7 at 40° with 3 filter iterations: 1,437 crease
/// vertices with one edge, 1,033 with two, 700 true ones); on a clean mesh only the open ends
/// of crease lines are dropped (clean Fandisk: 2 of 700).
pub const MIN_CREASE_EDGES: u32 = 2;

impl Topology {
    /// Whether `v` is a loop vertex: fixed only because it is a regular boundary vertex (see the
    /// [module doc](super)), so boundary smoothing may move it along its loop.
    #[inline]
    pub fn is_loop(&self, v: u32) -> bool {
        self.fixed[v as usize] == FIXED | LOOP
    }

    /// The two neighbours of `v` along its boundary loop (the other ends of its two boundary
    /// edges, ascending), when `v` is on exactly two boundary edges; `None` otherwise.
    /// `triangles` is the array the topology was built from; any orientation. Costs O(d²) in
    /// the number d of faces of `v` (about 4 on a boundary).
    pub fn loop_neighbors(&self, triangles: &[[u32; 3]], v: u32) -> Option<[u32; 2]> {
        let faces = self.faces_of(v);
        // A neighbour is across a boundary edge when exactly one face of v holds it.
        let mut found = [0u32; 2];
        let mut count = 0;
        for &u in self.neighbors(v) {
            let holding = faces
                .iter()
                .filter(|&&t| triangles[t as usize].contains(&u))
                .take(2)
                .count();
            if holding == 1 {
                if count == 2 {
                    return None;
                }
                found[count] = u;
                count += 1;
            }
        }
        (count == 2).then_some(found)
    }

    /// Fix the vertices for which `pinned(v)` holds (this topology's ids), whatever their
    /// topology: no method moves them, and a stencil containing one is skipped like one with a
    /// boundary vertex, so stencil volumes stay exact. Counts them in
    /// [`TopologyStats::pinned_vertices`](super::TopologyStats::pinned_vertices) and those not
    /// fixed before in `fixed_vertices`. Parallel over vertices; the result does not depend on the
    /// number of threads.
    pub fn pin(&mut self, pinned: impl Fn(u32) -> bool + Sync) {
        let (pins, newly) = self.fix_where(pinned);
        self.stats.pinned_vertices += pins;
        self.stats.fixed_vertices += newly;
    }

    /// Fix the crease vertices: those on at least `MIN_CREASE_EDGES` crease edges, edges of two
    /// triangles whose normals differ by more than `angle_deg` degrees (0° where the surface is
    /// flat, 90° on a cube's edge) both on `positions` and in `normals` (unit normals, one per
    /// triangle in this topology's triangle order, each in its triangle's own vertex order).
    /// The engine passes filtered normals (`Plan::crease`): the filtered field tells where the
    /// edges are on noisy input, the positions keep the filter's own artefacts (facets on a
    /// curved part) from making creases, so on clean input the creases are those of the
    /// positions, or a few fewer. The angle does not depend on the faces' orientation. Counts the
    /// edges in [`TopologyStats::crease_edges`](super::TopologyStats::crease_edges), the crease
    /// vertices in `crease_vertices` and those not fixed before in `fixed_vertices`. Corners
    /// where creases meet are crease vertices too. Parallel over vertices; the result does not
    /// depend on the number of threads.
    pub fn crease(
        &mut self,
        triangles: &[[u32; 3]],
        positions: &[DVec3],
        normals: &[DVec3],
        angle_deg: f64,
    ) {
        let cos_limit = angle_deg.to_radians().cos();
        let n = self.len();
        // Crease edges at each vertex; a vertex's edges to higher ids count the edges once.
        let counts: Vec<(u32, u32)> = (0..n as u32)
            .into_par_iter()
            .with_min_len(CHUNK)
            .map(|v| {
                let (mut all, mut above) = (0u32, 0u32);
                for &u in self.neighbors(v) {
                    if self.is_crease_edge(triangles, positions, normals, v, u, cos_limit) {
                        all += 1;
                        above += (u > v) as u32;
                    }
                }
                (all, above)
            })
            .collect();
        let edges: usize = counts.iter().map(|c| c.1 as usize).sum();
        let (vertices, newly) =
            self.fix_where_as(CREASE, |v| counts[v as usize].0 >= MIN_CREASE_EDGES);
        self.stats.crease_edges += edges;
        self.stats.crease_vertices += vertices;
        self.stats.fixed_vertices += newly;
    }

    /// Whether edge `(v, u)` has exactly two triangles whose normals (each taken in the direction
    /// the edge is traversed, so that orientation does not matter) make an angle whose cosine is
    /// below `cos_limit`, both in `normals` and on `positions`. A triangle of zero area (or a
    /// zero normal) makes no crease.
    fn is_crease_edge(
        &self,
        triangles: &[[u32; 3]],
        positions: &[DVec3],
        normals: &[DVec3],
        v: u32,
        u: u32,
        cos_limit: f64,
    ) -> bool {
        let mut ends = [DVec3::ZERO; 2];
        let mut raw = [DVec3::ZERO; 2];
        let mut found = 0;
        for &f in self.faces_of(v) {
            let t = triangles[f as usize];
            let Some(k) = t.iter().position(|&x| x == v) else {
                continue;
            };
            let (next, prev) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let sign = if next == u {
                1.0
            } else if prev == u {
                -1.0
            } else {
                continue;
            };
            if found == 2 {
                return false;
            }
            ends[found] = sign * normals[f as usize];
            let [a, b, c] = t.map(|x| positions[x as usize]);
            raw[found] = sign * (b - a).cross(c - a);
            found += 1;
        }
        if found != 2 {
            return false;
        }
        // Opposite traversals (a consistent pair) give opposite signs: flip one back.
        let sharp = |[n0, n1]: [DVec3; 2]| {
            let (l0, l1) = (n0.length(), n1.length());
            l0 > 0.0 && l1 > 0.0 && n0.dot(-n1) / (l0 * l1) < cos_limit
        };
        sharp(ends) && sharp(raw)
    }

    /// Whether `v` is a crease vertex ([`Topology::crease`]; such a vertex is also fixed).
    #[inline]
    pub fn is_crease(&self, v: u32) -> bool {
        self.fixed[v as usize] & CREASE != 0
    }

    /// Fix the vertices for which `fixed(v)` holds; returns how many did and how many of them
    /// were not fixed before.
    fn fix_where(&mut self, fixed: impl Fn(u32) -> bool + Sync) -> (usize, usize) {
        self.fix_where_as(FIXED, fixed)
    }

    /// [`Topology::fix_where`], marking the vertices with `mark` (a fixed mark, [`FIXED`] or
    /// [`FIXED`] | [`CREASE`]).
    fn fix_where_as(&mut self, mark: u8, fixed: impl Fn(u32) -> bool + Sync) -> (usize, usize) {
        let mark = mark | FIXED;
        self.fixed
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                let (mut all, mut newly) = (0, 0);
                for (k, f) in chunk.iter_mut().enumerate() {
                    if fixed((c * CHUNK + k) as u32) {
                        all += 1;
                        newly += (*f == 0) as usize;
                        *f = (*f | mark) & !LOOP;
                    }
                }
                (all, newly)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rim_vertices_are_loop_vertices_until_pinned() {
        let tris: Vec<[u32; 3]> = (1..=5).map(|k| [0, k, k % 5 + 1]).collect();
        let mut t = Topology::build(6, &tris).unwrap();
        assert!(!t.is_loop(0) && (1..=5).all(|v| t.is_loop(v)));
        assert_eq!(t.loop_neighbors(&tris, 1), Some([2, 5]));
        assert_eq!(t.loop_neighbors(&tris, 0), None);
        t.pin(|v| v == 3);
        assert!(t.is_fixed(3) && !t.is_loop(3) && t.is_loop(2));
        // A vertex on four boundary edges (two fans touching at 0) is no loop vertex.
        let mut tris = tris;
        tris.extend([[0, 6, 7], [0, 7, 8]]);
        let t = Topology::build(9, &tris).unwrap();
        assert!(t.is_fixed(0) && !t.is_loop(0) && t.is_loop(7));
    }
}
