//! Consistent face orientation ([`Topology::orient`]): faces flipped, component by component,
//! until the two faces of every edge traverse it in opposite directions, and the vertices of the
//! edges where no choice does (a non-orientable component) fixed. Apart from the build, because
//! it changes the triangles, which the build only reads.

use glam::DVec3;

use super::Topology;
use super::build::is_degenerate;
use super::masks::{FIXED, LOOP};

/// A face's orientation as [`Topology::orient`] decides it.
const UNSEEN: u8 = 0;
const KEEP: u8 = 1;
const FLIP: u8 = 2;

impl Topology {
    /// Orient `triangles` (the array this topology was built from, or a copy the smoothing works
    /// on) consistently: flip faces (swapping their last two corners, so the first stays first)
    /// until the two faces of every edge traverse it in opposite directions. Does nothing when the
    /// build found no inconsistent edge, so a consistently oriented mesh keeps its faces as they
    /// are.
    ///
    /// Each component (faces joined through edges of exactly two faces) is walked breadth first
    /// from its first face, each face taking the orientation its neighbour asks for; then the
    /// orientation the majority of the component's faces had in the input is kept (on a tie, the
    /// one with a positive signed volume). In a non-orientable component (a Möbius strip, a Klein
    /// bottle) some edges stay inconsistent; their vertices are fixed, like those of a boundary.
    /// Counts go to
    /// [`TopologyStats::non_orientable_components`](super::TopologyStats::non_orientable_components)
    /// and [`TopologyStats::orientation_seam_edges`](super::TopologyStats::orientation_seam_edges).
    /// Calling it again on its own result changes nothing.
    ///
    /// Cost: linear in the faces (the other face of an edge is looked up among the faces of its
    /// endpoint with fewer faces), plus a byte per face and a list of one component's faces.
    pub fn orient(&mut self, triangles: &mut [[u32; 3]], positions: &[DVec3]) {
        if self.stats.inconsistent_orientation_edges == 0 {
            return;
        }
        let mut state = vec![UNSEEN; triangles.len()];
        let mut component: Vec<u32> = Vec::new();
        let mut seam: Vec<u32> = Vec::new();
        let (mut non_orientable, mut seams) = (0, 0);
        for seed in 0..triangles.len() {
            if state[seed] != UNSEEN || is_degenerate(&triangles[seed]) {
                continue;
            }
            state[seed] = KEEP;
            component.clear();
            component.push(seed as u32);
            let mut conflicts = 0;
            let mut head = 0;
            while let Some(&t) = component.get(head) {
                head += 1;
                let tri = oriented(triangles[t as usize], state[t as usize]);
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    let Some(o) = self.other_face(triangles, t, a, b) else {
                        continue;
                    };
                    // The neighbour must run b → a.
                    let want = if runs(triangles[o as usize], a, b) {
                        FLIP
                    } else {
                        KEEP
                    };
                    let have = &mut state[o as usize];
                    if *have == UNSEEN {
                        *have = want;
                        component.push(o);
                    } else if *have != want && t < o {
                        // Seen from both faces: counted from the smaller.
                        conflicts += 1;
                        seam.extend([a, b]);
                    }
                }
            }
            if conflicts > 0 {
                non_orientable += 1;
                seams += conflicts;
            }
            let flipped = component
                .iter()
                .filter(|&&t| state[t as usize] == FLIP)
                .count();
            let kept = component.len() - flipped;
            let invert = flipped > kept
                || (flipped == kept && {
                    let origin = positions[triangles[seed][0] as usize];
                    let volume: f64 = component
                        .iter()
                        .map(|&t| {
                            let [a, b, c] = oriented(triangles[t as usize], state[t as usize])
                                .map(|v| positions[v as usize] - origin);
                            a.dot(b.cross(c))
                        })
                        .sum();
                    volume < 0.0
                });
            for &t in &component {
                if (state[t as usize] == FLIP) != invert {
                    triangles[t as usize].swap(1, 2);
                }
            }
        }
        for v in seam {
            let f = &mut self.fixed[v as usize];
            self.stats.fixed_vertices += (*f == 0) as usize;
            *f = (*f | FIXED) & !LOOP;
        }
        self.stats.non_orientable_components = non_orientable;
        self.stats.orientation_seam_edges = seams;
    }

    /// The one face other than `t` with the edge `a`–`b`, if the edge has exactly two faces.
    /// Scans the faces of the endpoint with fewer, so that the edges of a vertex of high degree
    /// cost what their other endpoint costs.
    fn other_face(&self, triangles: &[[u32; 3]], t: u32, a: u32, b: u32) -> Option<u32> {
        let faces = |v: u32| self.faces_of(v, triangles).count();
        let (x, y) = if faces(a) <= faces(b) { (a, b) } else { (b, a) };
        let mut found = None;
        for f in self.faces_of(x, triangles) {
            if f != t && triangles[f as usize].contains(&y) {
                if found.is_some() {
                    return None;
                }
                found = Some(f);
            }
        }
        found
    }
}

/// `tri` as [`Topology::orient`]'s `state` says (flipped: the last two corners swapped).
#[inline]
fn oriented(tri: [u32; 3], state: u8) -> [u32; 3] {
    if state == FLIP {
        [tri[0], tri[2], tri[1]]
    } else {
        tri
    }
}

/// Whether `tri` traverses its edge from `a` to `b` (both corners).
#[inline]
fn runs(tri: [u32; 3], a: u32, b: u32) -> bool {
    (0..3).any(|k| tri[k] == a && tri[(k + 1) % 3] == b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Positions of an icosphere for `orient`'s volume tie-break.
    fn sphere() -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let m = crate::shapes::icosphere(2);
        (m.positions.to_vec(), m.triangles.to_vec())
    }

    fn oriented_volume(pos: &[DVec3], tris: &[[u32; 3]]) -> f64 {
        crate::metrics::volume(pos, tris)
    }

    #[test]
    fn one_flipped_face_is_three_inconsistent_edges_and_orient_undoes_it() {
        let (pos, mut tris) = sphere();
        let clean = tris.clone();
        tris[17].swap(0, 1);
        let mut t = Topology::build(pos.len(), &tris).unwrap();
        assert_eq!(t.stats.inconsistent_orientation_edges, 3);
        // Orientation changes neither the adjacency nor what is fixed.
        assert_eq!(t.stats.fixed_vertices, 0);
        t.orient(&mut tris, &pos);
        assert_eq!(t.stats.non_orientable_components, 0);
        assert_eq!(t.stats.fixed_vertices, 0);
        // The majority's orientation: face 17 turned back (its first corner kept first).
        assert!((0..3).any(|k| tris[17] == [clean[17][k], clean[17][(k + 1) % 3], clean[17][(k + 2) % 3]]));
        assert_eq!(&tris[..17], &clean[..17]);
        assert_eq!(&tris[18..], &clean[18..]);
    }

    #[test]
    fn alternating_flips_orient_to_positive_volume() {
        let (pos, clean) = sphere();
        let v = oriented_volume(&pos, &clean);
        // Half the faces flipped (a tie): the orientation with the positive volume wins, whichever
        // face the walk starts from; and so for the mirror image (the other half flipped).
        for parity in [0, 1] {
            let mut tris = clean.clone();
            for (k, t) in tris.iter_mut().enumerate() {
                if k % 2 == parity {
                    t.swap(1, 2);
                }
            }
            let mut t = Topology::build(pos.len(), &tris).unwrap();
            assert!(t.stats.inconsistent_orientation_edges > 100);
            t.orient(&mut tris, &pos);
            let again = Topology::build(pos.len(), &tris).unwrap();
            assert_eq!(again.stats.inconsistent_orientation_edges, 0);
            assert!((oriented_volume(&pos, &tris) - v).abs() < 1e-12 * v);
            // A second call changes nothing.
            let before = tris.clone();
            t.orient(&mut tris, &pos);
            assert_eq!(tris, before);
        }
    }

    #[test]
    fn consistent_meshes_are_left_alone_even_inside_out() {
        let (pos, mut tris) = sphere();
        tris.iter_mut().for_each(|t| t.swap(1, 2));
        let before = tris.clone();
        let mut t = Topology::build(pos.len(), &tris).unwrap();
        assert_eq!(t.stats.inconsistent_orientation_edges, 0);
        t.orient(&mut tris, &pos);
        assert_eq!(tris, before);
    }

    /// A Möbius strip of `n` quads: top vertices `0..n`, bottom `n..2n`, the last quad twisted.
    fn mobius(n: u32) -> Vec<[u32; 3]> {
        let mut tris = Vec::new();
        for k in 0..n {
            let (t0, b0) = (k, n + k);
            let (t1, b1) = if k + 1 < n {
                (k + 1, n + k + 1)
            } else {
                (n, 0)
            };
            tris.push([t0, b0, b1]);
            tris.push([t0, b1, t1]);
        }
        tris
    }

    #[test]
    fn a_mobius_strip_is_non_orientable_and_its_seam_is_fixed() {
        let n = 8;
        let mut tris = mobius(n);
        let pos: Vec<DVec3> = (0..2 * n)
            .map(|v| DVec3::new(v as f64, (v * v) as f64, 1.0))
            .collect();
        let mut t = Topology::build(2 * n as usize, &tris).unwrap();
        // The strip is consistent everywhere but across the twist.
        assert_eq!(t.stats.inconsistent_orientation_edges, 1);
        // Every vertex of the strip is on its boundary, so fixed already.
        assert_eq!(t.stats.fixed_vertices, 2 * n as usize);
        t.orient(&mut tris, &pos);
        assert_eq!(t.stats.non_orientable_components, 1);
        assert_eq!(t.stats.orientation_seam_edges, 1);
        let again = Topology::build(2 * n as usize, &tris).unwrap();
        assert_eq!(again.stats.inconsistent_orientation_edges, 1);

        // A Klein bottle (closed, nothing fixed to begin with): the seam's vertices are fixed.
        let (pos, mut tris) = klein_bottle(6, 4);
        let mut t = Topology::build(pos.len(), &tris).unwrap();
        assert_eq!(t.stats.boundary_edges, 0);
        assert_eq!(t.stats.fixed_vertices, 0);
        assert!(t.stats.inconsistent_orientation_edges > 0);
        t.orient(&mut tris, &pos);
        assert_eq!(t.stats.non_orientable_components, 1);
        let seams = t.stats.orientation_seam_edges;
        assert!(seams > 0);
        let again = Topology::build(pos.len(), &tris).unwrap();
        assert_eq!(again.stats.inconsistent_orientation_edges, seams);
        assert!(t.stats.fixed_vertices > 0 && t.stats.fixed_vertices <= 2 * seams);
        let fixed = t.fixed_mask().iter().filter(|&&f| f != 0).count();
        assert_eq!(fixed, t.stats.fixed_vertices);
    }

    /// A Klein bottle as a `u × v` grid with the rows glued straight and the columns glued with a
    /// flip; positions arbitrary but distinct.
    fn klein_bottle(u: u32, v: u32) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let id = |i: u32, j: u32| {
            let (i, j) = if i == u { (0, (v - j) % v) } else { (i, j % v) };
            i * v + j
        };
        let mut tris = Vec::new();
        for i in 0..u {
            for j in 0..v {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
        }
        let pos = (0..u * v)
            .map(|k| DVec3::new(k as f64, (k % 5) as f64, (k % 3) as f64))
            .collect();
        (pos, tris)
    }
}
