//! The nearest point of a triangle mesh to a query point, through a bounding-volume hierarchy:
//! `compare`'s distance between meshes that do not share vertices.
//!
//! The tree is built once over the triangles (median split of the centroids along the longest
//! axis of their box, down to leaves of at most `LEAF` triangles); a query descends nearer
//! child first and prunes a box farther than the best distance found so far. Building and
//! querying are deterministic: the nearest point found is the same on every run, and of several
//! triangles at the same distance the one found first in that fixed order wins.

use glam::DVec3;

/// Triangles per leaf.
const LEAF: usize = 4;

/// An axis-aligned box.
#[derive(Debug, Clone, Copy)]
struct Aabb {
    lo: DVec3,
    hi: DVec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        lo: DVec3::splat(f64::INFINITY),
        hi: DVec3::splat(f64::NEG_INFINITY),
    };

    fn grow(self, p: DVec3) -> Aabb {
        Aabb {
            lo: self.lo.min(p),
            hi: self.hi.max(p),
        }
    }

    fn union(self, o: Aabb) -> Aabb {
        Aabb {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }

    /// Squared distance from `p` to the box (0 inside).
    fn distance_sq(&self, p: DVec3) -> f64 {
        let d = (self.lo - p).max(p - self.hi).max(DVec3::ZERO);
        d.length_squared()
    }
}

/// A node: a box and either two children or a run of `order`.
#[derive(Debug, Clone, Copy)]
struct Node {
    bounds: Aabb,
    /// Leaf: the first of `count` entries of `order`; inner: the index of the first child (the
    /// second follows it).
    first: u32,
    count: u32,
}

/// A triangle mesh prepared for nearest-point queries.
pub struct Surface<'a> {
    positions: &'a [DVec3],
    triangles: &'a [[u32; 3]],
    nodes: Vec<Node>,
    /// Triangle ids in leaf order.
    order: Vec<u32>,
}

/// The nearest point of a [`Surface`] to a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nearest {
    pub point: DVec3,
    pub distance: f64,
    /// The triangle it lies on.
    pub triangle: u32,
}

impl<'a> Surface<'a> {
    /// The hierarchy over `triangles` (indices into `positions`, checked by the caller).
    pub fn new(positions: &'a [DVec3], triangles: &'a [[u32; 3]]) -> Surface<'a> {
        let boxes: Vec<Aabb> = triangles
            .iter()
            .map(|t| {
                t.iter()
                    .fold(Aabb::EMPTY, |b, &v| b.grow(positions[v as usize]))
            })
            .collect();
        let centres: Vec<DVec3> = boxes.iter().map(|b| (b.lo + b.hi) * 0.5).collect();
        let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * triangles.len() / LEAF + 1);
        if !triangles.is_empty() {
            nodes.push(Node {
                bounds: Aabb::EMPTY,
                first: 0,
                count: 0,
            });
            // (node, range of `order`), split breadth-first so that children are adjacent.
            let mut pending = vec![(0usize, 0usize, order.len())];
            while let Some((node, start, end)) = pending.pop() {
                let ids = &mut order[start..end];
                let bounds = ids
                    .iter()
                    .fold(Aabb::EMPTY, |b, &t| b.union(boxes[t as usize]));
                if ids.len() <= LEAF {
                    nodes[node] = Node {
                        bounds,
                        first: start as u32,
                        count: ids.len() as u32,
                    };
                    continue;
                }
                let spread = ids
                    .iter()
                    .fold(Aabb::EMPTY, |b, &t| b.grow(centres[t as usize]));
                let extent = spread.hi - spread.lo;
                let axis = if extent.x >= extent.y && extent.x >= extent.z {
                    0
                } else if extent.y >= extent.z {
                    1
                } else {
                    2
                };
                let mid = ids.len() / 2;
                // Ties broken by the id, so that the split does not depend on the sort.
                ids.select_nth_unstable_by(mid, |&a, &b| {
                    centres[a as usize][axis]
                        .total_cmp(&centres[b as usize][axis])
                        .then(a.cmp(&b))
                });
                let child = nodes.len();
                nodes.push(Node {
                    bounds: Aabb::EMPTY,
                    first: 0,
                    count: 0,
                });
                nodes.push(nodes[child]);
                nodes[node] = Node {
                    bounds,
                    first: child as u32,
                    count: 0,
                };
                pending.push((child + 1, start + mid, end));
                pending.push((child, start, start + mid));
            }
        }
        Surface {
            positions,
            triangles,
            nodes,
            order,
        }
    }

    /// The nearest point of the surface to `p`; `None` without triangles.
    pub fn nearest(&self, p: DVec3) -> Option<Nearest> {
        let root = self.nodes.first()?;
        let mut best = Nearest {
            point: p,
            distance: f64::INFINITY,
            triangle: 0,
        };
        let mut best_sq = f64::INFINITY;
        let mut stack = vec![(0usize, root.bounds.distance_sq(p))];
        while let Some((n, d_sq)) = stack.pop() {
            if d_sq > best_sq {
                continue;
            }
            let node = self.nodes[n];
            if node.count > 0 {
                let run = node.first as usize..(node.first + node.count) as usize;
                for &t in &self.order[run] {
                    let [a, b, c] = self.triangles[t as usize].map(|v| self.positions[v as usize]);
                    let q = closest_on_triangle(p, a, b, c);
                    let e = (q - p).length_squared();
                    if e < best_sq || (e == best_sq && t < best.triangle) {
                        best_sq = e;
                        best = Nearest {
                            point: q,
                            distance: 0.0,
                            triangle: t,
                        };
                    }
                }
                continue;
            }
            let (l, r) = (node.first as usize, node.first as usize + 1);
            let (dl, dr) = (
                self.nodes[l].bounds.distance_sq(p),
                self.nodes[r].bounds.distance_sq(p),
            );
            // The nearer child is popped first.
            if dl <= dr {
                stack.push((r, dr));
                stack.push((l, dl));
            } else {
                stack.push((l, dl));
                stack.push((r, dr));
            }
        }
        best.distance = best_sq.sqrt();
        Some(best)
    }
}

/// The point of triangle `(a, b, c)` nearest to `p` (by its barycentric region; a degenerate
/// triangle gives the nearest point of its edges).
pub fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let sum = va + vb + vc;
    if sum.abs() <= f64::MIN_POSITIVE || !sum.is_finite() {
        // Degenerate: the nearest of the three edges.
        return [(a, b), (b, c), (c, a)]
            .map(|(u, v)| closest_on_segment(p, u, v))
            .into_iter()
            .min_by(|x, y| {
                (*x - p)
                    .length_squared()
                    .total_cmp(&(*y - p).length_squared())
            })
            .unwrap_or(a);
    }
    let (v, w) = (vb / sum, vc / sum);
    a + ab * v + ac * w
}

fn closest_on_segment(p: DVec3, u: DVec3, v: DVec3) -> DVec3 {
    let e = v - u;
    let len = e.length_squared();
    if len == 0.0 {
        return u;
    }
    u + e * ((p - u).dot(e) / len).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::icosphere;

    fn brute(pos: &[DVec3], tris: &[[u32; 3]], p: DVec3) -> f64 {
        tris.iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| pos[v as usize]);
                closest_on_triangle(p, a, b, c).distance(p)
            })
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn nearest_matches_brute_force() {
        let m = icosphere(3);
        let s = Surface::new(&m.positions, &m.triangles);
        let mut uniform = crate::shapes::uniform(7);
        let mut next = || uniform() * 4.0 - 2.0;
        for _ in 0..200 {
            let p = DVec3::new(next(), next(), next());
            let n = s.nearest(p).unwrap();
            assert_eq!(n.distance, brute(&m.positions, &m.triangles, p));
            assert!((n.point.distance(p) - n.distance).abs() < 1e-12);
        }
    }

    #[test]
    fn regions_of_a_triangle() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        let at = |x, y, z| closest_on_triangle(DVec3::new(x, y, z), a, b, c);
        assert!(at(0.2, 0.2, 3.0).distance(DVec3::new(0.2, 0.2, 0.0)) < 1e-15);
        assert_eq!(at(-1.0, -1.0, 0.0), a);
        assert_eq!(at(2.0, -0.5, 0.0), b);
        assert_eq!(at(0.5, -1.0, 1.0), DVec3::new(0.5, 0.0, 0.0));
        assert_eq!(at(1.0, 1.0, 0.0), DVec3::new(0.5, 0.5, 0.0));
        // Degenerate: a segment.
        let q = closest_on_triangle(DVec3::new(0.5, 1.0, 0.0), a, b, b);
        assert_eq!(q, DVec3::new(0.5, 0.0, 0.0));
        assert!(Surface::new(&[], &[]).nearest(DVec3::ZERO).is_none());
    }
}
