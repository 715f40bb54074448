//! One vertex from its fan: the link edges of its faces (each face runs v → b → c) classified as
//! one closed cycle, one path or neither, which gives the vertex's edge counts, whether it is
//! fixed, and its neighbours sorted. This is the inner loop of the build, so the common case, the
//! closed fan of a manifold's interior vertex, takes a shortcut (lanes compared at once, sorting
//! networks) that a test holds to the general analysis.

use super::MAX_FREE_DEGREE;

/// What the build learns about one vertex from its faces.
#[derive(Debug, PartialEq, Eq)]
pub(super) struct VertexAnalysis {
    pub(super) degree: usize,
    /// Edges to higher-numbered neighbours (each undirected edge counted once), by kind.
    pub(super) edges: usize,
    pub(super) boundary_edges: usize,
    pub(super) non_manifold_edges: usize,
    /// Edges of two faces that run the same way (to higher-numbered neighbours).
    pub(super) inconsistent_edges: usize,
    pub(super) non_manifold_vertex: bool,
    pub(super) fixed: bool,
    /// On exactly two boundary edges, manifold, link one path, degree at most
    /// [`MAX_FREE_DEGREE`]: fixed only as a boundary vertex.
    pub(super) loop_vertex: bool,
}

/// Reusable per-thread buffers of the per-vertex analysis.
#[derive(Default)]
pub(super) struct VertexScratch {
    /// Pass 1: `u << 1 | direction` for each corner u of a face at v (0: the face runs v → u,
    /// 1: u → v); pass 2: the corners alone.
    keys: Vec<u64>,
    pub(super) corners: Vec<u32>,
    parent: Vec<usize>,
}

/// Most faces of a vertex that [`closed_fan`] tries: its walk costs up to d², the general
/// analysis d log d. Surface meshes have degrees near 6.
const FAN_LIMIT: usize = 16;

/// The link edges `(b[i], c[i])` of the faces of `v` (each face runs v → b → c) when they form
/// one consistently oriented cycle through distinct neighbours: the interior vertex of a
/// manifold, which is nearly every vertex of a scan. Then the b's are exactly the neighbours,
/// each shared by two faces that traverse their edge in opposite directions, and the link is
/// connected; so [`analyse_vertex`] can skip its sort and union-find.
/// Returns the number of neighbours above `v` (its edges, each counted at its lower end) and
/// writes the neighbours into the first d entries of `out` (it may write up to 8); `None` for
/// anything else (or more than [`FAN_LIMIT`] faces), which the general path handles.
#[inline]
fn closed_fan(v: u32, b: &[u32], c: &[u32], out: &mut [u32]) -> Option<usize> {
    let d = b.len();
    if d < 3 {
        None
    } else if d <= 8 {
        let mut keys = padded(b);
        let lanes = Lanes::new(&keys);
        // No hit is lane 8, past the faces.
        let above = fan_walk(v, c, |u| {
            (lanes.equal(u) | 1 << 8).trailing_zeros() as usize
        })?;
        // Most vertices have 6 faces or fewer: their lanes past 6 are padding, in place.
        if d <= 6 {
            sort6(&mut keys);
        } else {
            sort8(&mut keys);
        }
        // All 8 lanes when there is room: a copy of fixed length, not a call to copy d.
        match out.get_mut(..8) {
            Some(lanes) => lanes.copy_from_slice(&keys),
            None => copy_rare(&keys[..d], out),
        }
        Some(above)
    } else if d <= FAN_LIMIT {
        let above = fan_walk(v, c, |u| {
            b.iter().position(|&x| x == u).unwrap_or(FAN_LIMIT)
        })?;
        sort_small(b, &mut out[..d]);
        Some(above)
    } else {
        None
    }
}

/// `x` into the first entries of `out`: out of line, so that the compiler does not merge it with
/// the fixed-length copy of its caller into one call of variable length.
#[cold]
#[inline(never)]
fn copy_rare(x: &[u32], out: &mut [u32]) {
    out[..x.len()].copy_from_slice(x);
}

/// [`closed_fan`]'s test, with `first(u)` the first face whose b is u (at least d if none).
///
/// Walk d steps from face 0: the face after face i is the first whose b is i's c. Seeing every
/// face and ending at face 0 visits each once, each as the first face with its b: so the b's are
/// distinct and the c's are the b's permuted, which also makes the c's met on the way the
/// neighbours. The face after each face is looked up first, for all faces, into 4 bits each of
/// `next`: the lookups do not wait for one another, and the walk is a shift per step.
#[inline(always)]
fn fan_walk(v: u32, c: &[u32], first: impl Fn(u32) -> usize) -> Option<usize> {
    let (mut next, mut found, mut above) = (0u64, true, 0);
    for (i, &u) in c.iter().enumerate() {
        above += (u > v) as usize;
        let after = first(u);
        found &= after < c.len();
        next |= (after as u64 & 15) << (4 * i);
    }
    let (mut at, mut seen) = (0, 0u32);
    for _ in 0..c.len() {
        at = (next >> (4 * at)) as usize & 15;
        seen |= 1 << at;
    }
    (found && at == 0 && seen == (1 << c.len()) - 1).then_some(above)
}

/// `x` (at most 8 ids) in the first lanes of 8, the rest `u32::MAX`: an id no vertex has (ids
/// are below it, so it matches no corner) and that sorts last.
#[inline(always)]
fn padded(x: &[u32]) -> [u32; 8] {
    std::array::from_fn(|k| x.get(k).copied().unwrap_or(u32::MAX))
}

/// 8 ids, to find which of them equal a given one all at once: a search stopping at the match
/// mispredicts its exit at nearly every face (most of [`fan_walk`]'s time, before).
#[cfg(target_arch = "x86_64")]
pub(crate) struct Lanes(std::arch::x86_64::__m128i, std::arch::x86_64::__m128i);

#[cfg(target_arch = "x86_64")]
impl Lanes {
    #[inline(always)]
    pub(crate) fn new(x: &[u32; 8]) -> Lanes {
        use std::arch::x86_64::*;
        let x = x.map(|x| x as i32);
        // SAFETY: SSE2 is part of the x86_64 baseline. Set from the ids rather than loaded from
        // `x`, which its stores have only just written (a wide load of narrow stores stalls).
        unsafe {
            Lanes(
                _mm_set_epi32(x[3], x[2], x[1], x[0]),
                _mm_set_epi32(x[7], x[6], x[5], x[4]),
            )
        }
    }

    /// The lanes equal to `u`, as the bits of a mask.
    #[inline(always)]
    pub(crate) fn equal(&self, u: u32) -> u32 {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of the x86_64 baseline.
        unsafe {
            let u = _mm_set1_epi32(u as i32);
            let words = _mm_packs_epi32(_mm_cmpeq_epi32(self.0, u), _mm_cmpeq_epi32(self.1, u));
            _mm_movemask_epi8(_mm_packs_epi16(words, words)) as u32 & 0xff
        }
    }
}

/// [`Lanes`] without x86_64's vector instructions.
#[cfg(not(target_arch = "x86_64"))]
pub(crate) struct Lanes([u32; 8]);

#[cfg(not(target_arch = "x86_64"))]
impl Lanes {
    pub(crate) fn new(x: &[u32; 8]) -> Lanes {
        Lanes(*x)
    }

    pub(crate) fn equal(&self, u: u32) -> u32 {
        self.0
            .iter()
            .rev()
            .fold(0, |m, &x| m << 1 | (x == u) as u32)
    }
}

/// Classify vertex `v` from the link edges `(b[i], c[i])` of its (non-degenerate) faces; when
/// it has as many neighbours as faces, write them into the first of `out`, ascending. `out` is
/// the rest of its chunk's array, where the entries past v's are written later if at all: it
/// may change up to 8 (see [`closed_fan`]). O(d log d) in the degree d.
pub(super) fn analyse_vertex(
    v: u32,
    b: &[u32],
    c: &[u32],
    s: &mut VertexScratch,
    out: &mut [u32],
) -> VertexAnalysis {
    if let Some(edges) = closed_fan(v, b, c, out) {
        return VertexAnalysis {
            degree: b.len(),
            edges,
            boundary_edges: 0,
            non_manifold_edges: 0,
            inconsistent_edges: 0,
            non_manifold_vertex: false,
            fixed: false,
            loop_vertex: false,
        };
    }
    let a = analyse_general(v, b, c, s);
    if a.degree == b.len() {
        out[..a.degree].copy_from_slice(&s.corners);
    }
    a
}

/// [`analyse_vertex`] for any vertex, without the shortcut.
pub(super) fn analyse_general(
    v: u32,
    b: &[u32],
    c: &[u32],
    s: &mut VertexScratch,
) -> VertexAnalysis {
    s.keys.clear();
    s.corners.clear();
    for (&b, &c) in b.iter().zip(c) {
        // The face runs v → b → c → v.
        s.keys.push((b as u64) << 1);
        s.keys.push((c as u64) << 1 | 1);
    }
    s.keys.sort_unstable();
    let mut a = VertexAnalysis {
        degree: 0,
        edges: 0,
        boundary_edges: 0,
        non_manifold_edges: 0,
        inconsistent_edges: 0,
        non_manifold_vertex: false,
        fixed: false,
        loop_vertex: false,
    };
    let mut ends = 0; // neighbours met once: ends of a path-shaped link
    let mut manifold = true;
    let mut i = 0;
    while i < s.keys.len() {
        let u = (s.keys[i] >> 1) as u32;
        let (mut count, mut outgoing) = (0, 0);
        while i < s.keys.len() && (s.keys[i] >> 1) as u32 == u {
            count += 1;
            outgoing += (s.keys[i] & 1 == 0) as usize;
            i += 1;
        }
        s.corners.push(u);
        match count {
            1 => ends += 1,
            2 => {}
            _ => manifold = false,
        }
        if u > v {
            a.edges += 1;
            match count {
                1 => a.boundary_edges += 1,
                2 => a.inconsistent_edges += (outgoing != 1) as usize,
                _ => a.non_manifold_edges += 1,
            }
        }
    }
    a.degree = s.corners.len();
    let nbrs = &s.corners[..];
    if nbrs.is_empty() {
        a.fixed = true; // unreferenced
    } else if ends > 0 || !manifold {
        // Boundary or non-manifold edge at v.
        a.fixed = true;
        a.non_manifold_vertex =
            manifold && (ends != 2 || !link_connected(nbrs, b, c, &mut s.parent));
        a.loop_vertex = manifold && !a.non_manifold_vertex && a.degree <= MAX_FREE_DEGREE;
    } else if !link_connected(nbrs, b, c, &mut s.parent) {
        a.fixed = true;
        a.non_manifold_vertex = true;
    }
    a.fixed |= a.degree > MAX_FREE_DEGREE;
    a
}

/// The sorted distinct neighbours of `v` into `out` (of the length pass 1 found): the list
/// [`analyse_vertex`] writes, without the link analysis pass 1 already made (that analysis, the
/// union-find over the link, was a third of the build's instructions when pass 2 repeated it).
pub(super) fn write_neighbors(
    v: u32,
    faces: &[u32],
    triangles: &[[u32; 3]],
    s: &mut VertexScratch,
    out: &mut [u32],
) {
    if out.len() == faces.len() && faces.len() <= FAN_LIMIT {
        // The interior vertex of a manifold (see `closed_fan`): its faces' b corners are distinct
        // and as many as its neighbours, so they are the neighbours.
        let mut b = [0; FAN_LIMIT];
        for (x, &t) in b.iter_mut().zip(faces) {
            *x = corner_after(&triangles[t as usize], v);
        }
        sort_small(&b[..faces.len()], out);
        if out.windows(2).all(|w| w[0] < w[1]) {
            return;
        }
    }
    s.corners.clear();
    for &t in faces {
        let (b, c) = corners_after(triangles[t as usize], v);
        s.corners.push(b);
        s.corners.push(c);
    }
    s.corners.sort_unstable();
    s.corners.dedup();
    out.copy_from_slice(&s.corners);
}

/// The corner after `v` in triangle `t` (which has `v` once), without a branch to mispredict.
#[inline]
fn corner_after(t: &[u32; 3], v: u32) -> u32 {
    let k = (t[1] == v) as usize + 2 * (t[2] == v) as usize;
    t[[1, 2, 0][k]]
}

/// `x` into `out` (of the same length), ascending. Up to 8 entries (a vertex's neighbours, as a
/// rule) through a sorting network: its comparisons, branch-free, cost less than the
/// mispredicted branches of an insertion sort on ids that come in no useful order.
#[inline]
fn sort_small(x: &[u32], out: &mut [u32]) {
    if x.len() > 8 {
        out.copy_from_slice(x);
        insertion_sort(out);
        return;
    }
    let mut a = padded(x);
    sort8(&mut a);
    out.copy_from_slice(&a[..x.len()]);
}

/// Sort 8 entries through a sorting network: the fewest comparators (19), branch-free.
#[inline]
fn sort8(a: &mut [u32; 8]) {
    let mut exchange = |i: usize, j: usize| (a[i], a[j]) = (a[i].min(a[j]), a[i].max(a[j]));
    exchange(0, 2);
    exchange(1, 3);
    exchange(4, 6);
    exchange(5, 7);
    exchange(0, 4);
    exchange(1, 5);
    exchange(2, 6);
    exchange(3, 7);
    exchange(0, 1);
    exchange(2, 3);
    exchange(4, 5);
    exchange(6, 7);
    exchange(2, 4);
    exchange(3, 5);
    exchange(1, 4);
    exchange(3, 6);
    exchange(1, 2);
    exchange(3, 4);
    exchange(5, 6);
}

/// Sort the first 6 of 8 entries through a sorting network: the fewest comparators (12).
#[inline]
fn sort6(a: &mut [u32; 8]) {
    let mut exchange = |i: usize, j: usize| (a[i], a[j]) = (a[i].min(a[j]), a[i].max(a[j]));
    exchange(0, 5);
    exchange(1, 3);
    exchange(2, 4);
    exchange(1, 2);
    exchange(3, 4);
    exchange(0, 3);
    exchange(2, 5);
    exchange(0, 1);
    exchange(2, 3);
    exchange(4, 5);
    exchange(1, 2);
    exchange(3, 4);
}

/// Sort a short slice ascending.
#[inline]
fn insertion_sort(x: &mut [u32]) {
    for i in 1..x.len() {
        let y = x[i];
        let mut j = i;
        while j > 0 && x[j - 1] > y {
            x[j] = x[j - 1];
            j -= 1;
        }
        x[j] = y;
    }
}

/// The two other corners of triangle `t` after `v`, in the triangle's cyclic order (`v` must be
/// a corner): the edge opposite `v`, oriented as the face runs.
#[inline]
pub fn corners_after(t: [u32; 3], v: u32) -> (u32, u32) {
    if t[0] == v {
        (t[1], t[2])
    } else if t[1] == v {
        (t[2], t[0])
    } else {
        (t[0], t[1])
    }
}

/// Whether the link edges of a vertex connect all its neighbours (one component).
fn link_connected(nbrs: &[u32], b: &[u32], c: &[u32], parent: &mut Vec<usize>) -> bool {
    parent.clear();
    parent.extend(0..nbrs.len());
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let mut components = nbrs.len();
    for (&b, &c) in b.iter().zip(c) {
        // Neighbours are sorted, so local ids come from a binary search.
        let (Ok(lb), Ok(lc)) = (nbrs.binary_search(&b), nbrs.binary_search(&c)) else {
            return false;
        };
        let (rb, rc) = (find(parent, lb), find(parent, lc));
        if rb != rc {
            parent[rb] = rc;
            components -= 1;
        }
    }
    components == 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::topology::Topology;

    #[test]
    fn the_sorting_networks_sort_every_input() {
        // A comparator network sorts every input if it sorts every input of zeros and ones.
        for bits in 0u32..256 {
            let mut a: [u32; 8] = std::array::from_fn(|k| bits >> k & 1);
            sort8(&mut a);
            assert!(a.is_sorted(), "sort8 {bits:08b}");
            let mut a: [u32; 8] = std::array::from_fn(|k| if k < 6 { bits >> k & 1 } else { 9 });
            sort6(&mut a);
            assert!(a.is_sorted(), "sort6 {bits:06b}");
        }
    }

    #[test]
    fn the_closed_fan_shortcut_agrees_with_the_general_analysis() {
        // Fans around vertex 0 over rims 1..=d: closed, open, with a face flipped, with a rim
        // vertex repeated (two cycles through 0, a pinch), and a double cover of the rim.
        let ring = |d: u32| -> Vec<[u32; 3]> { (1..=d).map(|k| [0, k, k % d + 1]).collect() };
        let mut cases: Vec<Vec<[u32; 3]>> = Vec::new();
        let limit = FAN_LIMIT as u32;
        for d in [3, 4, 6, limit, limit + 1] {
            cases.push(ring(d));
            let mut open = ring(d);
            open.pop();
            cases.push(open);
            let mut flipped = ring(d);
            flipped[1].swap(1, 2);
            cases.push(flipped);
            let mut twice = ring(d);
            twice.extend(ring(d));
            cases.push(twice);
        }
        // Two triangles fans sharing vertex 0 (a pinch): 0-1-2-3 and 0-4-5-6.
        cases.push(vec![
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 1],
            [0, 4, 5],
            [0, 5, 6],
            [0, 6, 4],
        ]);
        // Two cycles through the same rim vertex 1: 1-2-3 and 1-4-5.
        cases.push(vec![
            [0, 1, 2],
            [0, 2, 3],
            [0, 3, 1],
            [0, 1, 4],
            [0, 4, 5],
            [0, 5, 1],
        ]);
        let mut s = VertexScratch::default();
        let mut shortcuts = 0;
        for tris in &cases {
            let n = tris.iter().flatten().max().unwrap() + 1;
            let topo = Topology::build(n as usize, tris).unwrap();
            for v in 0..n {
                let faces: Vec<u32> = topo.faces_of(v, tris).collect();
                let (b, c): (Vec<u32>, Vec<u32>) = faces
                    .iter()
                    .map(|&t| corners_after(tris[t as usize], v))
                    .unzip();
                // With room past the vertex's entries, as in the build.
                let mut out = vec![0; faces.len() + 8];
                let a = analyse_vertex(v, &b, &c, &mut s, &mut out);
                if closed_fan(v, &b, &c, &mut out.clone()).is_some() {
                    shortcuts += 1;
                    assert_eq!(a, analyse_general(v, &b, &c, &mut s), "{tris:?} at {v}");
                }
                if a.degree == faces.len() {
                    assert_eq!(out[..a.degree], *topo.neighbors(v), "{tris:?} at {v}");
                }
                let mut want: Vec<u32> = faces
                    .iter()
                    .flat_map(|&t| tris[t as usize])
                    .filter(|&u| u != v)
                    .collect();
                want.sort_unstable();
                want.dedup();
                assert_eq!(topo.neighbors(v), &want[..], "{tris:?} at {v}");
            }
        }
        // The closed rings' centres (d <= FAN_LIMIT) take the shortcut; nothing else here.
        assert_eq!(shortcuts, 4);
    }
}
