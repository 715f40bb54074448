//! Measurement for issue #34 (not part of the tool): how fast the `vcs` edge stencil could run
//! with each vertex's neighbours kept in fan order, against the kernel (`stencil::sweep_edges`),
//! before that result change is made.
//!
//! usage: stencil_floor MESH [ITERATIONS] [REPEATS]   (default 3 and 5; one thread)
//!
//! The mesh (closed and manifold, with no creases) is taken in the plan's order. Both kernels
//! sweep every edge `(i < j)` ascending, Gauss–Seidel, `ITERATIONS` times from the same
//! positions; the medians of `REPEATS` such runs are printed as edge stencils per second.
//!
//! The fan kernel solves the same stencil (the normal equations of Liu et al.'s energy, then the
//! translation that restores the faces' volume) in another order of summation, so its output
//! differs from the kernel's in the last bits and is checked for that only: the volume kept,
//! the positions within a small distance of the kernel's. What it saves:
//! - the rows: each free vertex's ring read straight (the two common neighbours are next to the
//!   other free vertex in it), no merge of two sorted lists;
//! - the volume: a face is two consecutive ring entries, no triangle looked up, and each ring
//!   position is loaded once for its row and its faces.
use std::time::Instant;

use glam::DVec3;
use vcsmooth::engine::plan::{Layout, Plan};
use vcsmooth::mesh::Storage;
use vcsmooth::smooth::neighbor_sums;
use vcsmooth::smooth::stencil::{self, StencilParams, shared_face};
use vcsmooth::topology::{Topology, corners_after};

fn median(mut seconds: Vec<f64>) -> f64 {
    seconds.sort_by(f64::total_cmp);
    seconds[seconds.len() / 2]
}

/// Every vertex's neighbours in the order of its faces (each face `(v, r[t], r[t + 1])` in its
/// own orientation), starting at the smallest; `None` when some vertex's faces do not close
/// into one fan.
fn fans(topo: &Topology, tris: &[[u32; 3]]) -> Option<(Vec<usize>, Vec<u32>)> {
    let (offsets, _) = topo.csr();
    let mut ring = vec![0u32; offsets[topo.len()]];
    let mut next: Vec<(u32, u32)> = Vec::new();
    for v in 0..topo.len() as u32 {
        next.clear();
        next.extend(
            topo.faces_of(v, tris)
                .map(|t| corners_after(tris[t as usize], v)),
        );
        let out = &mut ring[offsets[v as usize]..offsets[v as usize + 1]];
        if next.len() != out.len() {
            return None;
        }
        let mut at = *topo.neighbors(v).first()?;
        for slot in out.iter_mut() {
            *slot = at;
            at = next.iter().find(|&&(b, _)| b == at)?.1;
        }
        if at != out[0] {
            return None;
        }
    }
    Some((offsets.to_vec(), ring))
}

/// One `vcs` edge stencil on fan-ordered rings; false when skipped as degenerate.
// The tests are negated so that a NaN counts as degenerate, as in the kernel.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
#[inline(never)]
fn fan_stencil(
    offsets: &[usize],
    ring: &[u32],
    pos: &mut [DVec3],
    sums: &mut [DVec3],
    f: u32,
    g: u32,
) -> bool {
    let rf = &ring[offsets[f as usize]..offsets[f as usize + 1]];
    let rg = &ring[offsets[g as usize]..offsets[g as usize + 1]];
    let (kf, kg) = (rf.len(), rg.len());
    if kf > 32 || kg > 32 {
        return false;
    }
    let (Some(j), Some(i)) = (
        rf.iter().position(|&u| u == g),
        rg.iter().position(|&u| u == f),
    ) else {
        return false;
    };
    // Faces (f, g, c1) and (f, c2, g): c1 follows g in f's ring and precedes f in g's.
    let (jn, jp) = ((j + 1) % kf, (j + kf - 1) % kf);
    let (ip, in_) = ((i + kg - 1) % kg, (i + 1) % kg);
    let (pf, pg) = (pos[f as usize], pos[g as usize]);
    let origin = (pf + pg) * 0.5;
    const INV: [f64; 16] = {
        let mut t = [0.0; 16];
        let mut d = 1;
        while d < 16 {
            t[d] = 1.0 / d as f64;
            d += 1;
        }
        t
    };
    let inv = |u: u32| {
        let d = offsets[u as usize + 1] - offsets[u as usize];
        if d < 16 { INV[d] } else { 1.0 / d as f64 }
    };
    let (mut sq, mut cross, mut weighted) = ([0.0f64; 2], 0.0, [DVec3::ZERO; 2]);
    let mut rel_f = [DVec3::ZERO; 33];
    let mut rel_g = [DVec3::ZERO; 33];
    for (t, &u) in rf.iter().enumerate() {
        let (w, p) = (inv(u), pos[u as usize]);
        rel_f[t] = p - origin;
        let lap = sums[u as usize] * w - p;
        weighted[0] += w * lap;
        sq[0] += w * w;
        if t == jn || t == jp {
            weighted[1] += w * lap;
            sq[1] += w * w;
            cross += w * w;
        }
    }
    for (t, &u) in rg.iter().enumerate() {
        let p = pos[u as usize];
        rel_g[t] = p - origin;
        if t == ip || t == in_ {
            continue;
        }
        let w = inv(u);
        let lap = sums[u as usize] * w - p;
        weighted[1] += w * lap;
        sq[1] += w * w;
    }
    let (wf, wg) = (1.0 / kf as f64, 1.0 / kg as f64);
    let lap = [sums[f as usize] * wf - pf, sums[g as usize] * wg - pg];
    let (a, o, c) = (1.0 + sq[0], cross - wf - wg, 1.0 + sq[1]);
    let det = a * c - o * o;
    if !(a > 0.0 && det > 1e-10 * a * c) {
        return false;
    }
    let (b0, b1) = (lap[0] - weighted[0], lap[1] - weighted[1]);
    let mut d = [(c * b0 - o * b1) / det, (a * b1 - o * b0) / det];
    // The volume: f's faces but the two shared, g's likewise, then the shared two.
    (rel_f[kf], rel_g[kg]) = (rel_f[0], rel_g[0]);
    let (mut dv, mut n, mut scale) = (0.0, DVec3::ZERO, 0.0);
    let mut singles = |rel: &[DVec3], k: usize, skip: [usize; 2]| {
        let mut s = DVec3::ZERO;
        for t in 0..k {
            if t == skip[0] || t == skip[1] {
                continue;
            }
            let nt = rel[t].cross(rel[t + 1]);
            s += nt;
            scale += nt.length_squared();
        }
        s
    };
    // In f's ring the faces holding g start at jp (f, c2, g) and at j (f, g, c1).
    let sf = singles(&rel_f, kf, [jp, j]);
    // In g's ring: (g, c1, f) starts at ip, (g, f, c2) at i.
    let sg = singles(&rel_g, kg, [ip, i]);
    dv += d[0].dot(sf) + d[1].dot(sg);
    n += sf + sg;
    let (p, q1, q2) = (pf - origin, pg - origin, rel_f[jn]);
    let z = DVec3::ZERO;
    let acc = (&mut dv, &mut n, &mut scale);
    shared_face(p, q1, q2, d[0], d[1], z, true, false, acc.0, acc.1, acc.2);
    shared_face(
        p, rel_f[jp], q1, d[0], z, d[1], false, true, acc.0, acc.1, acc.2,
    );
    let nn = n.length_squared();
    if !(nn > 1e-20 * scale) {
        return false;
    }
    let w = n * (-dv / nn);
    d[0] += w;
    d[1] += w;
    let near2 = (pf - origin)
        .length_squared()
        .max((pg - origin).length_squared());
    let reach2 = 256.0 * near2;
    if !(d[0].length_squared() <= reach2 && d[1].length_squared() <= reach2) {
        return false;
    }
    pos[f as usize] += d[0];
    pos[g as usize] += d[1];
    for &u in rf {
        sums[u as usize] += d[0];
    }
    for &u in rg {
        sums[u as usize] += d[1];
    }
    true
}

fn volume(pos: &[DVec3], tris: &[[u32; 3]]) -> f64 {
    let o = pos[0];
    tris.iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| pos[v as usize] - o);
            a.dot(b.cross(c))
        })
        .sum::<f64>()
        / 6.0
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .expect("usage: stencil_floor MESH [ITERATIONS] [REPEATS]");
    let iterations: usize = args.next().map_or(3, |r| r.parse().expect("ITERATIONS"));
    let repeats: usize = args.next().map_or(5, |r| r.parse().expect("REPEATS"));
    let mesh = vcsmooth::io::read_mesh(std::path::Path::new(&path)).expect("a mesh");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    pool.install(|| {
        let plan = Plan::new(&Storage::heap(), &mesh.positions, &mesh.triangles, Layout::Patches(4096))
            .expect("a plan");
        let (pos0, tris, topo) = (
            &plan.reordered.positions[..],
            &plan.reordered.triangles[..],
            &plan.topology,
        );
        assert!((0..topo.len() as u32).all(|v| !topo.is_fixed(v)), "a closed manifold mesh");
        let (offsets, ring) = fans(topo, tris).expect("every vertex one closed fan");
        let edges: Vec<[u32; 2]> = topo.edges().collect();
        let params = StencilParams {
            volume: true,
            reject_energy_increase: false,
            deviation: None,
        };
        let kernel = || {
            let (mut pos, mut sums) = (pos0.to_vec(), neighbor_sums(topo, pos0));
            let clock = Instant::now();
            let mut applied = 0;
            for _ in 0..iterations {
                let st = stencil::sweep_edges(topo, tris, &mut pos[..], &mut sums[..], edges.iter().copied(), params);
                applied += st.applied;
            }
            (clock.elapsed().as_secs_f64(), pos, applied)
        };
        let fan = || {
            let (mut pos, mut sums) = (pos0.to_vec(), neighbor_sums(topo, pos0));
            let clock = Instant::now();
            let mut applied = 0;
            for _ in 0..iterations {
                for &[f, g] in &edges {
                    applied += fan_stencil(&offsets, &ring, &mut pos, &mut sums, f, g) as u64;
                }
            }
            (clock.elapsed().as_secs_f64(), pos, applied)
        };
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let (mut last_a, mut last_b) = (None, None);
        for _ in 0..repeats {
            let (s, p, n) = kernel();
            a.push(s);
            last_a = Some((p, n));
            let (s, p, n) = fan();
            b.push(s);
            last_b = Some((p, n));
        }
        let ((pa, na), (pb, nb)) = (last_a.unwrap(), last_b.unwrap());
        let stencils = (edges.len() * iterations) as f64;
        let (ta, tb) = (median(a), median(b));
        let v0 = volume(pos0, tris);
        let mean_edge = edges.iter().map(|&[i, j]| pos0[i as usize].distance(pos0[j as usize])).sum::<f64>()
            / edges.len() as f64;
        let apart = pa.iter().zip(&pb).map(|(x, y)| x.distance(*y)).fold(0.0, f64::max);
        let moved = pa.iter().zip(pos0).map(|(x, y)| x.distance(*y)).fold(0.0, f64::max);
        println!("{} edges, {iterations} iterations, medians of {repeats}, one thread", edges.len());
        println!("kernel: {ta:.3} s, {:.2} M stencils/s, {na} applied, |dV|/V {:.1e}", stencils / ta / 1e6, ((volume(&pa, tris) - v0) / v0).abs());
        println!("fan:    {tb:.3} s, {:.2} M stencils/s, {nb} applied, |dV|/V {:.1e}", stencils / tb / 1e6, ((volume(&pb, tris) - v0) / v0).abs());
        println!("fan / kernel: {:.2}x; largest distance between the two results {:.1e} mean edges (largest move {:.1e})", ta / tb, apart / mean_edge, moved / mean_edge);
    });
}
