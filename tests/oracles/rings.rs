//! The sequential prototype of the 2-ring stencils (`vcsmooth::smooth::rings`, `vcs-guided`'s
//! second step): the stencils, and one whole-mesh iteration with its own volume arithmetic, with
//! Taubin's λ|μ pair as the first step, kept as the independent reference the kernel is tested
//! against here.

use glam::DVec3;
use vcsmooth::Topology;

/// The ring stencils of a mesh: `members[offsets[v]..offsets[v + 1]]` is `F_v` (empty for a fixed
/// vertex), `share[u] = 1 / c_u` (0 for a vertex in no stencil).
#[derive(Debug, Clone)]
pub struct RingStencils {
    pub offsets: Vec<usize>,
    pub members: Vec<u32>,
    pub share: Vec<f64>,
}

impl RingStencils {
    /// Stencils of graph radius `radius` around every movable vertex.
    pub fn build(topo: &Topology, radius: usize) -> RingStencils {
        let n = topo.len();
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        let mut members: Vec<u32> = Vec::new();
        let mut count = vec![0u32; n];
        let mut seen = vec![u32::MAX; n];
        let mut frontier = Vec::new();
        let mut next = Vec::new();
        for v in 0..n as u32 {
            if !topo.is_fixed(v) {
                let start = members.len();
                members.push(v);
                seen[v as usize] = v;
                frontier.clear();
                frontier.push(v);
                for _ in 0..radius {
                    next.clear();
                    for &u in &frontier {
                        for &w in topo.neighbors(u) {
                            if seen[w as usize] != v && !topo.is_fixed(w) {
                                seen[w as usize] = v;
                                members.push(w);
                                next.push(w);
                            }
                        }
                    }
                    std::mem::swap(&mut frontier, &mut next);
                }
                for &u in &members[start..] {
                    count[u as usize] += 1;
                }
            }
            offsets.push(members.len());
        }
        let share = count
            .iter()
            .map(|&c| if c > 0 { 1.0 / c as f64 } else { 0.0 })
            .collect();
        RingStencils {
            offsets,
            members,
            share,
        }
    }

    /// `F_v`.
    pub fn of(&self, v: u32) -> &[u32] {
        &self.members[self.offsets[v as usize]..self.offsets[v as usize + 1]]
    }
}

/// Reusable buffers of [`ring_iteration`].
#[derive(Debug, Default)]
pub struct Scratch {
    d: Vec<DVec3>,
    q: Vec<DVec3>,
    vmark: Vec<u32>,
    fmark: Vec<u32>,
    faces: Vec<u32>,
}

/// Volume (relative to `o`) of `faces` and its gradient for a common translation of the vertices
/// whose `vmark` equals `stamp`.
fn local_volume(
    p: &[DVec3],
    tris: &[[u32; 3]],
    faces: &[u32],
    vmark: &[u32],
    stamp: u32,
    o: DVec3,
) -> (f64, DVec3) {
    let mut vol = 0.0;
    let mut grad = DVec3::ZERO;
    for &f in faces {
        let t = tris[f as usize];
        let q = [
            p[t[0] as usize] - o,
            p[t[1] as usize] - o,
            p[t[2] as usize] - o,
        ];
        vol += q[0].dot(q[1].cross(q[2]));
        for k in 0..3 {
            if vmark[t[k] as usize] == stamp {
                grad += q[(k + 1) % 3].cross(q[(k + 2) % 3]);
            }
        }
    }
    (vol / 6.0, grad / 6.0)
}

/// One iteration of 2-ring stencils over the whole mesh, step 1 a Taubin λ|μ pair (see the
/// module doc).
pub fn ring_iteration(
    topo: &Topology,
    tris: &[[u32; 3]],
    stencils: &RingStencils,
    p: &mut [DVec3],
    lambda: f64,
    mu: f64,
    s: &mut Scratch,
) -> super::lowpass::Counts {
    let n = p.len();
    super::lowpass::taubin_pair(topo, p, lambda, mu, &mut s.q, &mut s.d);
    for ((d, q), share) in s.d.iter_mut().zip(p.iter()).zip(&stencils.share) {
        *d = (*d - *q) * share;
    }
    s.vmark.clear();
    s.vmark.resize(n, 0);
    s.fmark.clear();
    s.fmark.resize(tris.len(), 0);
    let mut counts = super::lowpass::Counts::default();
    for v in 0..n as u32 {
        let free = stencils.of(v);
        if free.is_empty() {
            continue;
        }
        let stamp = v + 1;
        s.faces.clear();
        for &u in free {
            s.vmark[u as usize] = stamp;
            for f in topo.faces_of(u, tris) {
                if s.fmark[f as usize] != stamp {
                    s.fmark[f as usize] = stamp;
                    s.faces.push(f);
                }
            }
        }
        let o = p[v as usize];
        let (v0, _) = local_volume(p, tris, &s.faces, &s.vmark, stamp, o);
        let mut scale: f64 = 0.0;
        for &u in free {
            p[u as usize] += s.d[u as usize];
            scale = scale.max((p[u as usize] - o).length_squared());
        }
        let (v1, grad) = local_volume(p, tris, &s.faces, &s.vmark, stamp, o);
        let gg = grad.length_squared();
        // |n| has the units of an area: skip a stencil whose gradient vanishes at its scale
        let usable = gg > 1e-24 * scale * scale && gg.is_finite() && v1.is_finite();
        if !usable {
            for &u in free {
                p[u as usize] -= s.d[u as usize];
            }
            counts.skipped_degenerate += 1;
            continue;
        }
        let w = grad * ((v0 - v1) / gg);
        for &u in free {
            p[u as usize] += w;
        }
        counts.applied += 1;
    }
    counts
}

// ---------------------------------------------------------------------------------------------
// The reference's own checks, and the kernel against it.

mod tests {
    use vcsmooth::shapes::{add_normal_noise, icosphere};
    use vcsmooth::smooth::rings::{
        COUNT_AGAIN, RING_RADIUS, Ring, counts_into, ring_of, shares_into, sweep_rings,
    };

    use vcsmooth::metrics::volume_about;

    use super::*;

    /// The triangles of `mesh` but those around vertex 0: a hole, whose rim is fixed.
    fn holed(mesh: &vcsmooth::Mesh) -> Vec<[u32; 3]> {
        mesh.triangles
            .iter()
            .copied()
            .filter(|t| !t.contains(&0))
            .collect()
    }

    #[test]
    fn rings_are_symmetric_and_exclude_fixed_vertices() {
        let mesh = icosphere(2);
        let tris = holed(&mesh);
        let topo = Topology::build(mesh.positions.len(), &tris).unwrap();
        let st = RingStencils::build(&topo, RING_RADIUS);
        let (mut a, mut b) = (Ring::default(), Ring::default());
        for v in 0..topo.len() as u32 {
            ring_of(&topo.parts(), v, &mut a, true);
            let mut want = st.of(v).to_vec();
            want.sort_unstable();
            assert_eq!(a.members, want, "vertex {v}");
            for &u in &a.members {
                assert!(!topo.is_fixed(u));
                ring_of(&topo.parts(), u, &mut b, false);
                assert!(b.contains(v));
                assert!(b.members.contains(&v));
            }
            for u in 0..topo.len() as u32 {
                assert_eq!(a.contains(u), want.contains(&u), "{u} in the ring of {v}");
            }
        }
    }

    #[test]
    fn the_kernel_follows_the_prototype_and_keeps_volume() {
        // Same order of work (the stencils of the whole mesh in index order), different rounding
        // (the kernel sums each face's volume change through the edge stencils' code, the
        // prototype subtracts two volumes): the positions agree to rounding, and both keep the
        // volume; a hole's rim stays put.
        let mut mesh = icosphere(4);
        add_normal_noise(&mut mesh, 0.3, 7);
        let offset = DVec3::new(3.0, -2.0, 5.0);
        let p0: Vec<DVec3> = mesh.positions.iter().map(|p| *p + offset).collect();
        let tris = holed(&mesh);
        let topo = Topology::build(p0.len(), &tris).unwrap();
        let st = RingStencils::build(&topo, RING_RADIUS);
        let (mut proto, mut kernel) = (p0.clone(), p0.clone());
        let mut s = Scratch::default();
        let n = p0.len();
        let mut counts = vec![0; n];
        counts_into(&topo, &mut counts, 0);
        assert!(!counts.contains(&COUNT_AGAIN));
        let (mut half, mut pair) = (Vec::new(), Vec::new());
        let mut shares = vec![DVec3::ZERO; n];
        for _ in 0..8 {
            let c = ring_iteration(&topo, &tris, &st, &mut proto, 0.5, -0.53, &mut s);
            let movable = (0..n as u32).filter(|&v| !topo.is_fixed(v)).count();
            assert_eq!(c.applied, movable);
            super::super::lowpass::taubin_pair(&topo, &kernel, 0.5, -0.53, &mut half, &mut pair);
            shares_into(&topo, &kernel, &pair, &counts, &mut shares, 0);
            let st = sweep_rings(
                &topo,
                &tris,
                kernel.as_mut_slice(),
                shares.as_slice(),
                0..n as u32,
                None,
            );
            assert_eq!(st.applied as usize, movable);
        }
        let far = proto
            .iter()
            .zip(&kernel)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f64::max);
        assert!(far < 1e-12, "{far}");
        // An open mesh: its volume about one fixed point.
        let volume = |p: &[DVec3]| volume_about(p, &tris, DVec3::ZERO);
        let v0 = volume(&p0);
        assert!(((volume(&kernel) - v0) / v0).abs() < 1e-12);
        for v in 0..n as u32 {
            if topo.is_fixed(v) {
                assert_eq!(kernel[v as usize], p0[v as usize]);
            }
        }
    }
}
