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
/// between them is below minus this (the angle above 143°), on the fitted positions.
/// Chosen with [`CREASE_ALIGNMENT`] on the machined denoising pairs (tools/denoise_table.py;
/// CHANGELOG, results version 8).
const LINE_STRAIGHTNESS: f64 = 0.8;

/// The (unnormalised) normal of triangle `f` on `positions`.
fn face_normal(triangles: &[[u32; 3]], positions: &[DVec3], f: u32) -> DVec3 {
    let [a, b, c] = triangles[f as usize].map(|x| positions[x as usize]);
    (b - a).cross(c - a)
}

/// The cosine of the angle between the normals of an edge's two triangles, each taken in the
/// direction it traverses the edge: opposite traversals (a consistent pair) give opposite
/// signs, so one is flipped back. 1 (flat) when either is zero.
fn cosine([n0, n1]: [DVec3; 2]) -> f64 {
    let (l0, l1) = (n0.length(), n1.length());
    if l0 > 0.0 && l1 > 0.0 {
        n0.dot(-n1) / (l0 * l1)
    } else {
        1.0
    }
}

/// The neighbour places a crease-edge mask holds (its set bits), ascending.
fn places(mask: u64) -> impl Iterator<Item = usize> {
    let mut rest = mask;
    std::iter::from_fn(move || {
        (rest != 0).then(|| {
            let k = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            k
        })
    })
}

/// The lowest and highest places of a mask of two or more crease edges: a line vertex's two.
fn line_places(mask: u64) -> [usize; 2] {
    [mask.trailing_zeros(), 63 - mask.leading_zeros()].map(|k| k as usize)
}

/// Passes that drop the ends of crease lines, then give them back ([`Topology::crease`], step
/// 2): the noise a filter leaves makes short lines. Chosen on the machined denoising pairs
/// (tools/denoise_table.py; docs/quality-research.md §19): 6 or 7 passes lose Fandisk 0.7's
/// gain, 5 keep it.
const SHORT_LINE_PASSES: usize = 5;

/// The largest angle between a face's input normal and its filtered one around a vertex whose
/// input is clean ([`Topology::crease`], step 2).
const CLEAN_ANGLE: f64 = 10.0;

/// How far along its lines ([`Topology::crease`], step 3) the input's angle is measured around
/// a crease vertex, in edges: the line of about `2 · LINE_REACH + 1` vertices it is the middle of.
const LINE_REACH: usize = 5;

/// The most crease vertices step 3 of [`Topology::crease`] reaches around one: a line's 11
/// are far below it; a web of crease edges (a coarse tessellation whose every edge is sharp)
/// would otherwise cost the square of its size per vertex.
const LINE_REACHED: usize = 64;

/// Flags of a vertex in [`Topology::crease`]: its input is clean; it is on a crease edge
/// beyond its 64th neighbour (never dropped: there is no bit for that edge).
const CLEAN: u8 = 1;
const MANY: u8 = 2;

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
        // A neighbour is across a boundary edge when exactly one face of v holds it.
        let mut found = [0u32; 2];
        let mut count = 0;
        for &u in self.neighbors(v) {
            let holding = self
                .faces_of(v, triangles)
                .filter(|&t| triangles[t as usize].contains(&u))
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

    /// Mark the crease vertices, in three steps:
    ///
    /// 1. A crease edge is an edge of two triangles whose normals differ by more than
    ///    `angle_deg` degrees (0° where the surface is flat, 90° on a cube's edge) both in
    ///    `normals` (unit normals, one per triangle in this topology's triangle order, each in
    ///    its triangle's own vertex order) and on `fitted`, and which runs along the crease the
    ///    two normals make. A vertex on at least [`MIN_CREASE_EDGES`] of them is a crease vertex:
    ///    a line vertex when it is on two that go on nearly straight through it, a corner when
    ///    on more (or when it was fixed before). The engine passes filtered normals and positions
    ///    fitted to them (`Plan::crease`), on which the edges of a noisy part are as plain as
    ///    on a clean one.
    /// 2. Short lines go where the input is noisy: [`SHORT_LINE_PASSES`] passes drop the
    ///    crease vertices with fewer than two crease neighbours left (the ends of every line,
    ///    one vertex a pass), then as many passes give back to the vertices that survived their
    ///    dropped crease neighbours. What noise makes are short lines and lone edges; a line of
    ///    at most `2 · SHORT_LINE_PASSES` crease vertices is gone, one longer is whole again (a
    ///    closed loop stays, and so does a spur of a long line, grown back from it).
    ///    A vertex whose faces' normals on `input` are all within [`CLEAN_ANGLE`] of the filtered
    ///    ones (faces of zero area aside) is on clean surface and never dropped: there the
    ///    crease edges found are the input's own, and a short one is a real edge.
    /// 3. A line must be sharp on the input too: a crease vertex stays when the median angle
    ///    between the `input` normals across the crease edges that reach the crease vertices
    ///    within [`LINE_REACH`] edges of it along its lines is above `angle_deg`. A filter makes
    ///    facets on a curved part, and the fitted positions make them edges; the input there is
    ///    smooth. A vertex on a crease edge beyond its 64th neighbour skips steps 2 and 3.
    ///
    /// A line vertex's two crease neighbours are kept (in an array from `storage`, two bytes
    /// per vertex; see [`Topology::line_neighbors`]), so that the methods that smooth creases
    /// move it along its line; every other method keeps it fixed. A corner, and a vertex on two
    /// crease edges one of which is not among its first 64 neighbours, are fixed. Counts the
    /// crease edges between the crease vertices kept in
    /// [`TopologyStats::crease_edges`](super::TopologyStats::crease_edges) (but those beyond
    /// the 64th neighbour of their lower end), those vertices
    /// (line vertices and corners) in `crease_vertices` and those not fixed
    /// before in `fixed_vertices` (a line vertex cannot move freely). Every pass is a Jacobi
    /// pass, parallel over vertices: the result does not depend on the number of threads.
    pub fn crease(
        &mut self,
        storage: &Storage,
        triangles: &[[u32; 3]],
        input: &[DVec3],
        fitted: &[DVec3],
        normals: &[DVec3],
        angle_deg: f64,
    ) -> Result<()> {
        let cos_limit = angle_deg.to_radians().cos();
        let n = self.len();
        // Per vertex: which of its first 64 neighbours are across a crease edge (bit k for
        // neighbour k); its flags; its mark on all its crease edges.
        let mut edges: Buf<u64> = storage.zeroed(n)?;
        let mut flags: Buf<u8> = storage.zeroed(n)?;
        let mut base: Buf<u8> = storage.zeroed(n)?;
        edges
            .par_chunks_mut(CHUNK)
            .zip(flags.par_chunks_mut(CHUNK))
            .zip(base.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((edges, flags), base))| {
                let first = (c * CHUNK) as u32;
                for (k, v) in (first..).take(edges.len()).enumerate() {
                    let (mut mask, mut all) = (0u64, 0u32);
                    for (place, &u) in self.neighbors(v).iter().enumerate() {
                        if self.is_crease_edge(triangles, fitted, normals, v, u, cos_limit) {
                            if place < 64 {
                                mask |= 1 << place;
                            }
                            all += 1;
                        }
                    }
                    let many = all > mask.count_ones();
                    let clean = self.is_clean(triangles, input, normals, v);
                    edges[k] = mask;
                    flags[k] = if many { MANY } else { 0 } | if clean { CLEAN } else { 0 };
                    base[k] = if many && all >= MIN_CREASE_EDGES {
                        CREASE
                    } else {
                        self.crease_mark(fitted, v, mask)
                    };
                }
            });
        // Step 2: the ends of lines off, one vertex a pass, where the input is not clean...
        let mut state: Buf<u8> = storage.zeroed(n)?;
        state.copy_from_slice(&base);
        let mut next: Buf<u8> = storage.zeroed(n)?;
        for _ in 0..SHORT_LINE_PASSES {
            let (from, flags, edges) = (&state[..], &flags[..], &edges[..]);
            self.vertex_pass_u8(
                &mut next,
                || (),
                |_, v| {
                    let m = from[v as usize];
                    if m == 0 || flags[v as usize] != 0 {
                        return m;
                    }
                    let live = self.live_edges(edges[v as usize], v, from);
                    self.crease_mark(fitted, v, live)
                },
            );
            std::mem::swap(&mut state, &mut next);
        }
        // ... then back along the lines that kept a vertex.
        for _ in 0..SHORT_LINE_PASSES {
            let (from, base, edges) = (&state[..], &base[..], &edges[..]);
            self.vertex_pass_u8(
                &mut next,
                || (),
                |_, v| {
                    let b = base[v as usize];
                    let kept =
                        from[v as usize] != 0 || self.live_edges(edges[v as usize], v, from) != 0;
                    if b != 0 && kept { b } else { 0 }
                },
            );
            std::mem::swap(&mut state, &mut next);
        }
        // Step 3: sharp on the input along the line.
        {
            let (from, flags, edges) = (&state[..], &flags[..], &edges[..]);
            let buffers = || (Vec::new(), Vec::new());
            self.vertex_pass_u8(&mut next, buffers, |buffers, v| {
                let m = from[v as usize];
                let sharp = m != 0
                    && (flags[v as usize] & MANY != 0
                        || self
                            .line_is_sharp(triangles, input, edges, from, v, cos_limit, buffers));
                if sharp { m } else { 0 }
            });
        }
        let marks = next;
        drop(state);
        // A line vertex's two places, and the edges of the creases kept, each once.
        let mut lines: Buf<u8> = storage.zeroed(2 * n)?;
        let counted: usize = lines
            .par_chunks_mut(2 * CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                let first = (c * CHUNK) as u32;
                let mut counted = 0;
                for (place, v) in chunk.chunks_exact_mut(2).zip(first..) {
                    let (mark, mask) = (marks[v as usize], edges[v as usize]);
                    if mark == CREASE | LINE {
                        place.copy_from_slice(&line_places(mask).map(|k| k as u8));
                    }
                    if mark != 0 {
                        let nbrs = self.neighbors(v);
                        let live = places(self.live_edges(mask, v, &marks));
                        counted += live.filter(|&k| nbrs[k] > v).count();
                    }
                }
                counted
            })
            .sum();
        let (vertices, newly) = self.fix_where_as(CREASE, |v| marks[v as usize] == CREASE);
        let (on_lines, newly_on_lines) =
            self.fix_where_as(CREASE | LINE, |v| marks[v as usize] == CREASE | LINE);
        self.lines = lines;
        self.stats.crease_edges += counted;
        self.stats.crease_vertices += vertices + on_lines;
        self.stats.fixed_vertices += newly + newly_on_lines;
        Ok(())
    }

    /// The mark of `v` with the crease edges `mask` (bits by neighbour place): none, a corner's
    /// ([`CREASE`]), or a line vertex's ([`CREASE`] | [`LINE`]). A line vertex was free and its
    /// two crease edges go on nearly straight through it on `positions`.
    fn crease_mark(&self, positions: &[DVec3], v: u32, mask: u64) -> u8 {
        let count = mask.count_ones();
        if count < MIN_CREASE_EDGES {
            0
        } else if count > 2 || self.is_fixed(v) {
            CREASE
        } else {
            let nbrs = self.neighbors(v);
            let p = positions[v as usize];
            let [a, b] = line_places(mask).map(|k| positions[nbrs[k] as usize] - p);
            // Two crease edges that turn at the vertex: on noisy input, a zigzag through the
            // noise; the vertex is smoothed as any other.
            let straight = a.dot(b) < -LINE_STRAIGHTNESS * a.length() * b.length();
            if straight { CREASE | LINE } else { 0 }
        }
    }

    /// The crease edges of `v` among `mask` whose other end is still marked in `marks`.
    fn live_edges(&self, mask: u64, v: u32, marks: &[u8]) -> u64 {
        let nbrs = self.neighbors(v);
        places(mask)
            .filter(|&k| marks[nbrs[k] as usize] != 0)
            .fold(0, |live, k| live | 1 << k)
    }

    /// Whether the faces of `v` have their `positions` normals within [`CLEAN_ANGLE`] of
    /// `normals` (a face with a zero normal in either is left out): the input is clean around
    /// `v`.
    fn is_clean(
        &self,
        triangles: &[[u32; 3]],
        positions: &[DVec3],
        normals: &[DVec3],
        v: u32,
    ) -> bool {
        let cos_clean = CLEAN_ANGLE.to_radians().cos();
        self.faces_of(v, triangles).all(|f| {
            let (raw, filtered) = (face_normal(triangles, positions, f), normals[f as usize]);
            // A face of zero area has no normal to compare: a sliver of a clean CAD mesh.
            let (l0, l1) = (raw.length(), filtered.length());
            !(l0 > 0.0 && l1 > 0.0) || raw.dot(filtered) > cos_clean * l0 * l1
        })
    }

    /// Step 3 of [`Topology::crease`] for the marked vertex `v`: the crease edges by which a
    /// breadth-first walk from `v` along crease edges between marked vertices first reaches
    /// each vertex within [`LINE_REACH`] edges (at most [`LINE_REACHED`] of them), and whether
    /// the median of their angles on `positions` is above the angle of `cos_limit`. `seen` and
    /// `cosines` are the caller's buffers, reused from vertex to vertex.
    #[allow(clippy::too_many_arguments)]
    fn line_is_sharp(
        &self,
        triangles: &[[u32; 3]],
        positions: &[DVec3],
        edges: &[u64],
        marks: &[u8],
        v: u32,
        cos_limit: f64,
        (seen, cosines): &mut (Vec<u32>, Vec<f64>),
    ) -> bool {
        seen.clear();
        seen.push(v);
        cosines.clear();
        let mut front = 0;
        for _ in 0..LINE_REACH {
            let end = seen.len();
            for i in front..end {
                let w = seen[i];
                let nbrs = self.neighbors(w);
                for k in places(self.live_edges(edges[w as usize], w, marks)) {
                    let u = nbrs[k];
                    if seen.len() < LINE_REACHED && !seen.contains(&u) {
                        seen.push(u);
                        cosines.push(self.edge_cosine(triangles, positions, w, u));
                    }
                }
            }
            front = end;
        }
        if cosines.is_empty() {
            return false;
        }
        // Descending cosines are ascending angles: the upper median angle.
        cosines.sort_by(|a, b| b.total_cmp(a));
        cosines[cosines.len() / 2] < cos_limit
    }

    /// The cosine of the angle between the normals on `positions` of the two triangles of edge
    /// `(v, u)`, whatever their orientation; 1 (flat) unless the edge has exactly two triangles
    /// of non-zero area.
    fn edge_cosine(&self, triangles: &[[u32; 3]], positions: &[DVec3], v: u32, u: u32) -> f64 {
        self.edge_faces(triangles, v, u).map_or(1.0, |faces| {
            cosine(faces.map(|(f, sign)| sign * face_normal(triangles, positions, f)))
        })
    }

    /// `f(state, v)` for every vertex into `out`, parallel in fixed chunks, each with a `state`
    /// from `init` (buffers reused from vertex to vertex).
    fn vertex_pass_u8<S>(
        &self,
        out: &mut [u8],
        init: impl Fn() -> S + Sync,
        f: impl Fn(&mut S, u32) -> u8 + Sync,
    ) {
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
            let mut state = init();
            let first = (c * CHUNK) as u32;
            for (o, v) in out.iter_mut().zip(first..) {
                *o = f(&mut state, v);
            }
        });
    }

    /// The two triangles of edge `(v, u)`, each with the sign that turns its normal into the
    /// one taken in the direction it traverses the edge (so that orientation does not matter);
    /// `None` unless the edge has exactly two.
    fn edge_faces(&self, triangles: &[[u32; 3]], v: u32, u: u32) -> Option<[(u32, f64); 2]> {
        let mut found = [(0, 0.0); 2];
        let mut count = 0;
        for f in self.faces_of(v, triangles) {
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
            if count == 2 {
                return None;
            }
            found[count] = (f, sign);
            count += 1;
        }
        (count == 2).then_some(found)
    }

    /// Whether edge `(v, u)` has exactly two triangles whose normals make an angle whose cosine
    /// is below `cos_limit`, both in `normals` and on `positions`, and runs along the crease
    /// their `normals` make. A triangle of zero area (or a zero normal) makes no crease.
    fn is_crease_edge(
        &self,
        triangles: &[[u32; 3]],
        positions: &[DVec3],
        normals: &[DVec3],
        v: u32,
        u: u32,
        cos_limit: f64,
    ) -> bool {
        let Some(faces) = self.edge_faces(triangles, v, u) else {
            return false;
        };
        let ends = faces.map(|(f, sign)| sign * normals[f as usize]);
        let raw = faces.map(|(f, sign)| sign * face_normal(triangles, positions, f));
        // Along the crease its filtered normals make: a noisy mesh's edges across a crease, or
        // beside it, are sharp too.
        let e = positions[u as usize] - positions[v as usize];
        let along = ends[0].cross(ends[1]);
        let aligned = e.dot(along).abs() > CREASE_ALIGNMENT * e.length() * along.length();
        cosine(ends) < cos_limit && cosine(raw) < cos_limit && aligned
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
        t.crease(&Storage::heap(), &tris, &pos, &pos, &normals, 40.0)
            .unwrap();
        // Row 2 is vertices 10–14; its ends are on the boundary, fixed and no line vertices (nor
        // their edges crease edges between crease vertices).
        assert_eq!(t.stats.crease_edges, 2);
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

    /// [`fold`] with its lower half turned `turn` degrees from the upper one's plane (0: flat,
    /// 90: [`fold`]'s), and the unit normals of its triangles.
    fn fold_at(w: u32, turn: f64) -> (Vec<DVec3>, Vec<DVec3>) {
        let (tris, mut pos) = fold(w);
        let (sin, cos) = turn.to_radians().sin_cos();
        for (v, p) in pos.iter_mut().enumerate().skip(3 * (w as usize + 1)) {
            let d = (v / (w as usize + 1) - 2) as f64;
            *p = DVec3::new(p.x, -d * cos, -d * sin);
        }
        let normals = (0..tris.len() as u32)
            .map(|f| face_normal(&tris, &pos, f).normalize())
            .collect();
        (pos, normals)
    }

    /// The crease vertices [`Topology::crease`] finds at 40° on a fold of `w` columns whose input
    /// is turned `input` degrees and whose fitted copy (and its normals) `fitted` degrees.
    fn creases_of_fold(w: u32, input: f64, fitted: f64) -> Vec<u32> {
        let (tris, _) = fold(w);
        let (input, _) = fold_at(w, input);
        let (fitted, normals) = fold_at(w, fitted);
        let mut t = Topology::build(input.len(), &tris).unwrap();
        t.crease(&Storage::heap(), &tris, &input, &fitted, &normals, 40.0)
            .unwrap();
        let found: Vec<u32> = (0..input.len() as u32)
            .filter(|&v| t.is_crease(v))
            .collect();
        assert_eq!(t.stats.crease_vertices, found.len());
        assert_eq!(t.stats.crease_edges, found.len().saturating_sub(1));
        found
    }

    #[test]
    fn noise_makes_no_short_lines_and_smooth_input_no_lines() {
        // The interior vertices of row 2, the fold's line.
        let line = |w: u32| (2 * (w + 1) + 1..3 * (w + 1) - 1).collect::<Vec<u32>>();
        // Clean input (the fitted copy is the input): every line stays, however short.
        assert_eq!(creases_of_fold(6, 90.0, 90.0), line(6));
        assert_eq!(creases_of_fold(30, 90.0, 90.0), line(30));
        // The input 25° off the filtered normals on one side (not clean): a line of at most
        // 2 · SHORT_LINE_PASSES = 10 vertices is noise, a longer one stays whole.
        assert!(creases_of_fold(6, 90.0, 115.0).is_empty());
        assert!(creases_of_fold(11, 90.0, 115.0).is_empty());
        assert_eq!(creases_of_fold(12, 90.0, 115.0), line(12));
        assert_eq!(creases_of_fold(30, 90.0, 115.0), line(30));
        // The edge test reads the fitted copy: a crease of the input alone is none.
        assert!(creases_of_fold(30, 45.0, 35.0).is_empty());
        // A fold of the fitted copy where the input is flat: no crease.
        assert!(creases_of_fold(30, 0.0, 90.0).is_empty());
        // Nor where the input's angle is below the crease angle.
        assert!(creases_of_fold(30, 30.0, 90.0).is_empty());
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
