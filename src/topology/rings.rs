//! The rings of vertices around a range of them (a patch): what the schedule's conflicts and a
//! patch's own neighbour sums are found from.

use std::ops::Range;

use super::Topology;

/// The vertices outside the range `vertices` (a patch's), ring by ring (ring 1 first), up to
/// `depth` rings: a breadth-first walk, each vertex in the ring where it is first met (in no
/// particular order within it).
pub fn rings_outside(topo: &Topology, vertices: &Range<u32>, depth: usize) -> Vec<Vec<u32>> {
    let outside = |v: u32| !vertices.contains(&v);
    let mut seen = VertexSet::default();
    let mut rings: Vec<Vec<u32>> = Vec::with_capacity(depth);
    // The neighbours of a range of vertices are one run of the adjacency.
    let (offsets, vv) = topo.csr();
    let (s, e) = (vertices.start as usize, vertices.end as usize);
    let mut ring: Vec<u32> = Vec::new();
    for &u in &vv[offsets[s]..offsets[e]] {
        if outside(u) && seen.insert(u) {
            ring.push(u);
        }
    }
    while rings.len() + 1 < depth {
        let mut next = Vec::new();
        for &v in &ring {
            for &u in topo.neighbors(v) {
                if outside(u) && seen.insert(u) {
                    next.push(u);
                }
            }
        }
        rings.push(std::mem::replace(&mut ring, next));
    }
    if depth > 0 {
        rings.push(ring);
    }
    rings
}

/// A set of vertex ids (open addressing, linear probing): the rings' walk meets each vertex of
/// a ring several times.
#[derive(Default)]
struct VertexSet {
    slots: Vec<u32>,
    len: usize,
}

impl VertexSet {
    const EMPTY: u32 = u32::MAX;

    /// Adds `u`; whether it was new.
    fn insert(&mut self, u: u32) -> bool {
        if 2 * (self.len + 1) > self.slots.len() {
            let old = std::mem::replace(
                &mut self.slots,
                vec![Self::EMPTY; (4 * self.len).max(1 << 12)],
            );
            self.len = 0;
            for k in old.into_iter().filter(|&k| k != Self::EMPTY) {
                self.insert(k);
            }
        }
        let mask = self.slots.len() - 1;
        // The product's high bits: its low bits depend on the id's low bits alone.
        let shift = 64 - self.slots.len().trailing_zeros();
        let mut i = ((u as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> shift) as usize;
        loop {
            match self.slots[i] {
                k if k == u => return false,
                Self::EMPTY => {
                    self.slots[i] = u;
                    self.len += 1;
                    return true;
                }
                _ => i = (i + 1) & mask,
            }
        }
    }
}
