//! The fixed-vertex mask's bits, and what sets them after the build: pins from the caller and
//! crease edges measured on the positions and on a face-normal field the caller gives. Loop
//! vertices (boundary vertices that boundary smoothing may move along their loop) are marked by
//! the build; any other reason to fix one clears its mark.

use glam::DVec3;
use rayon::prelude::*;

use super::{CHUNK, Topology};
use crate::error::Result;
use crate::mesh::{Buf, Storage};

/// Bits of the fixed-vertex mask: any non-zero entry is a fixed vertex; [`CREASE`] also marks it
/// as a crease vertex ([`Topology::crease`]), whose row the stencil energy leaves out, and
/// [`LINE`] as one on a crease line; [`LOOP`] as a loop vertex (see the [module doc](super)),
/// which any other reason to fix it clears.
pub(super) const FIXED: u8 = 1;
pub(super) const CREASE: u8 = 2;
pub(super) const LOOP: u8 = 4;
/// With [`CREASE`]: a crease line vertex ([`Topology::line_neighbors`]), fixed for the methods
/// that do not smooth creases.
pub(super) const LINE: u8 = 8;

/// Crease edges a vertex needs to be a crease vertex ([`Topology::crease`]). Two: a crease
/// vertex is on a crease line (or a corner where lines meet); a lone crease edge, or the last
/// edge of a line that fades out, does not fix its vertices. On noisy input many falsely
/// detected edges are lone ones (Fandisk 0.7 at 40° with 3 filter iterations: 1,437 crease
/// vertices with one edge, 1,033 with two, 700 true ones); on a clean mesh only the open ends
/// of crease lines are dropped (clean Fandisk: 2 of 700).
pub const MIN_CREASE_EDGES: u32 = 2;

/// A crease edge runs along the crease of its faces' filtered normals: the cosine of its angle
/// to their cross product is above this (26°). On noisy input the edges beside a crease or
/// across it are sharp too; without this test, at 40° a third of Fandisk 0.7's crease line
/// vertices had a crease neighbour off the crease, which pulled them off it.
const CREASE_ALIGNMENT: f64 = 0.9;

/// A line vertex's two crease edges go on nearly straight through it: the cosine of the angle
/// between them is below minus this (the angle above 143°), on the input positions.
/// Chosen with [`CREASE_ALIGNMENT`] on the machined denoising pairs (tools/denoise_table.py;
/// CHANGELOG, results version 8).
const LINE_STRAIGHTNESS: f64 = 0.8;

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

    /// Mark the crease vertices: those on at least `MIN_CREASE_EDGES` crease edges, edges of two
    /// triangles whose normals differ by more than `angle_deg` degrees (0° where the surface is
    /// flat, 90° on a cube's edge) both on `positions` and in `normals` (unit normals, one per
    /// triangle in this topology's triangle order, each in its triangle's own vertex order).
    /// The engine passes filtered normals (`Plan::crease`): the filtered field tells where the
    /// edges are on noisy input, the positions keep the filter's own artefacts (facets on a
    /// curved part) from making creases, so on clean input the creases are those of the
    /// positions, or a few fewer. The angle does not depend on the faces' orientation.
    ///
    /// A vertex on exactly two crease edges is a crease line vertex: its two crease neighbours
    /// are kept (in an array from `storage`, two bytes per vertex; see
    /// [`Topology::line_neighbors`]), so that the methods that smooth creases move it along its
    /// line; every other method keeps it fixed. A corner, where three or more crease edges meet,
    /// and a line vertex whose crease neighbours are not among its first 255, are fixed. Counts
    /// the edges in [`TopologyStats::crease_edges`](super::TopologyStats::crease_edges), the
    /// crease vertices (line vertices and corners) in `crease_vertices` and those not fixed
    /// before in `fixed_vertices` (a line vertex cannot move freely). Parallel over vertices;
    /// the result does not depend on the number of threads.
    pub fn crease(
        &mut self,
        storage: &Storage,
        triangles: &[[u32; 3]],
        positions: &[DVec3],
        normals: &[DVec3],
        angle_deg: f64,
    ) -> Result<()> {
        let cos_limit = angle_deg.to_radians().cos();
        let n = self.len();
        let mut lines: Buf<u8> = storage.zeroed(2 * n)?;
        // Per vertex: its crease edges to higher ids (which count each edge once), and its mark:
        // none, a corner's, or a line vertex's. A line vertex was free, its two crease edges go
        // on nearly straight through it, and their places in its neighbour list (kept in
        // `lines`) fit a byte.
        let marks: Vec<(u32, u8)> = lines
            .par_chunks_mut(2 * CHUNK)
            .enumerate()
            .flat_map_iter(|(c, places)| {
                let first = (c * CHUNK) as u32;
                places.chunks_exact_mut(2).zip(first..).map(|(place, v)| {
                    let nbrs = self.neighbors(v);
                    let (mut all, mut above) = (0u32, 0u32);
                    for (k, &u) in nbrs.iter().enumerate() {
                        if self.is_crease_edge(triangles, positions, normals, v, u, cos_limit) {
                            if let Some(p) = place.get_mut(all as usize) {
                                *p = k.min(u8::MAX as usize) as u8;
                            }
                            all += 1;
                            above += (u > v) as u32;
                        }
                    }
                    let mark = if all < MIN_CREASE_EDGES {
                        0
                    } else if all > 2 || self.is_fixed(v) || place.contains(&u8::MAX) {
                        CREASE
                    } else {
                        let p = positions[v as usize];
                        let [a, b] =
                            [place[0], place[1]].map(|k| positions[nbrs[k as usize] as usize] - p);
                        // Two crease edges that turn at the vertex: on noisy input, a zigzag
                        // through the noise; the vertex is smoothed as any other.
                        let straight = a.dot(b) < -LINE_STRAIGHTNESS * a.length() * b.length();
                        if straight { CREASE | LINE } else { 0 }
                    };
                    (above, mark)
                })
            })
            .collect();
        let edges: usize = marks.iter().map(|m| m.0 as usize).sum();
        let (vertices, newly) = self.fix_where_as(CREASE, |v| marks[v as usize].1 == CREASE);
        let (on_lines, newly_on_lines) =
            self.fix_where_as(CREASE | LINE, |v| marks[v as usize].1 == CREASE | LINE);
        self.lines = lines;
        self.stats.crease_edges += edges;
        self.stats.crease_vertices += vertices + on_lines;
        self.stats.fixed_vertices += newly + newly_on_lines;
        Ok(())
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
        // Along the crease its filtered normals make: a noisy mesh's edges across a crease, or
        // beside it, are sharp too.
        let e = positions[u as usize] - positions[v as usize];
        let along = ends[0].cross(ends[1]);
        let aligned = e.dot(along).abs() > CREASE_ALIGNMENT * e.length() * along.length();
        sharp(ends) && sharp(raw) && aligned
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

    /// A strip of `w + 1` columns folded at 90° along row 2 (the x axis): rows 0–2 in the plane
    /// z = 0, rows 2–4 in the plane y = 0; vertex `row · (w + 1) + x` at column x.
    fn fold(w: u32) -> (Vec<[u32; 3]>, Vec<DVec3>) {
        let mut pos = Vec::new();
        for &(y, z) in &[(2.0, 0.0), (1.0, 0.0), (0.0, 0.0), (0.0, -1.0), (0.0, -2.0)] {
            pos.extend((0..=w).map(|x| DVec3::new(x as f64, y, z)));
        }
        let mut tris = Vec::new();
        for row in 0..4 {
            for col in 0..w {
                let a = row * (w + 1) + col;
                tris.extend([[a, a + w + 1, a + 1], [a + 1, a + w + 1, a + w + 2]]);
            }
        }
        (tris, pos)
    }

    #[test]
    fn crease_line_vertices_move_along_their_line() {
        use crate::smooth::laplacian::jacobi_step;
        let (tris, mut pos) = fold(4);
        let mut t = Topology::build(pos.len(), &tris).unwrap();
        let normals: Vec<DVec3> = tris
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| pos[v as usize]);
                (b - a).cross(c - a).normalize()
            })
            .collect();
        t.crease(&Storage::heap(), &tris, &pos, &normals, 40.0)
            .unwrap();
        // Row 2 is vertices 10–14; its ends are on the boundary, fixed and no line vertices.
        assert_eq!(t.stats.crease_edges, 4);
        assert_eq!(t.stats.crease_vertices, 3);
        for v in 0..pos.len() as u32 {
            let line = (11..=13).contains(&v).then(|| [v - 1, v + 1]);
            assert_eq!(t.line_neighbors(v), line, "vertex {v}");
            assert_eq!(t.is_crease(v), line.is_some(), "vertex {v}");
            // Fixed for the methods that do not smooth creases.
            assert!(line.is_none() || t.is_fixed(v), "vertex {v}");
        }
        // Moved off the crease, a line vertex goes back to its crease neighbours' midpoint, not
        // towards its ring's (inside the fold); a free vertex goes to its ring's.
        pos[12] += DVec3::new(0.25, 0.5, -0.5);
        pos[7] += DVec3::new(0.0, 0.0, 0.5);
        let mut out = vec![DVec3::ZERO; pos.len()];
        jacobi_step(&t, &pos, &mut out, 0, 1.0);
        assert_eq!(out[12], DVec3::new(2.0, 0.0, 0.0));
        let ring = t
            .neighbors(7)
            .iter()
            .map(|&u| pos[u as usize])
            .sum::<DVec3>();
        assert!(out[7].distance(ring / t.deg(7) as f64) < 1e-12);
        assert_eq!(out[10], pos[10], "a boundary vertex stays");
    }

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
