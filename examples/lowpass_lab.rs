//! Research lab for issue #15 (not part of the tool): sequential, single-threaded prototypes of
//! denoising variants, writing the f64 positions after every iteration for tools/quality_lab.py.
//!
//! usage: lowpass_lab IN OUTPREFIX METHOD ITERS [key=value ...]
//!   METHOD: taubin      Jacobi λ|μ (as the tool's taubin)
//!           lp          edge stencils, Gauss–Seidel; step 1 = λ|μ moves of the 2 free vertices
//!                       (scaled by s), step 2 = the exact volume translation (DESIGN.md)
//!           lpv         per-vertex-normalised: like lp, but each free vertex's λ|μ step is divided
//!                       by the number of eligible stencils containing it (≈ one λ|μ per iteration)
//!   keys: lambda=0.5 mu=-0.53 s=1.0
//!   lpr (vertex + r-ring stencils, docs/quality-research.md §4) also: r=1, fuji=1, proj=1, and
//!   the feature-aware step-1 variants of §11.2: bil=c (bilateral umbrella weights, scale c·σ̂),
//!   nf=K [sr=σ_r nv=1] (normal filtering then vertex update instead of λ|μ), cot=1 (cotangent
//!   weights)
//! Output: OUTPREFIX.K.bin (n×3 little-endian f64) for K = 1..=ITERS; per-iteration JSON lines on
//! stdout (volume, mean/max displacement, roughness).
// The lab's tests are written NaN-aware (`!(x > t)` is true for NaN) and index by vertex, as the
// formulas do.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]
use glam::DVec3;
use std::collections::HashMap;
use std::io::Write;

struct Topo {
    nb_off: Vec<usize>,
    nb: Vec<u32>,
    vf_off: Vec<usize>,
    vf: Vec<u32>,
    fixed: Vec<bool>,
    edges: Vec<(u32, u32)>,
}

fn topo(n: usize, tris: &[[u32; 3]]) -> Topo {
    let mut ecount: HashMap<(u32, u32), u32> = HashMap::new();
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *ecount.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut fixed = vec![false; n];
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut edges = Vec::new();
    for (&(a, b), &c) in &ecount {
        if c != 2 {
            fixed[a as usize] = true;
            fixed[b as usize] = true;
        }
        adj[a as usize].push(b);
        adj[b as usize].push(a);
        edges.push((a, b));
    }
    edges.sort_unstable();
    let mut vfs: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (i, t) in tris.iter().enumerate() {
        for &v in t {
            vfs[v as usize].push(i as u32);
        }
    }
    let (mut nb_off, mut nb, mut vf_off, mut vf) = (vec![0], vec![], vec![0], vec![]);
    for v in 0..n {
        adj[v].sort_unstable();
        nb.extend_from_slice(&adj[v]);
        nb_off.push(nb.len());
        vf.extend_from_slice(&vfs[v]);
        vf_off.push(vf.len());
        if adj[v].is_empty() {
            fixed[v] = true;
        }
    }
    Topo {
        nb_off,
        nb,
        vf_off,
        vf,
        fixed,
        edges,
    }
}

fn lap(p: &[DVec3], t: &Topo, v: usize) -> DVec3 {
    let ns = &t.nb[t.nb_off[v]..t.nb_off[v + 1]];
    let mut s = DVec3::ZERO;
    for &u in ns {
        s += p[u as usize];
    }
    s / ns.len() as f64 - p[v]
}

/// Normalised cotangent Laplacian (weights (cot α + cot β)/2 clamped at 0, divided by their sum);
/// the umbrella where the weights vanish.
fn lap_cot(p: &[DVec3], tris: &[[u32; 3]], t: &Topo, v: usize) -> DVec3 {
    let mut ws: Vec<(usize, f64)> = Vec::new();
    let mut add = |u: usize, w: f64| match ws.iter_mut().find(|x| x.0 == u) {
        Some(x) => x.1 += w,
        None => ws.push((u, w)),
    };
    let cotan = |at: DVec3, x: DVec3, y: DVec3| {
        let (a, b) = (x - at, y - at);
        let c = a.cross(b).length();
        if c > 0.0 { a.dot(b) / c } else { 0.0 }
    };
    for &f in &t.vf[t.vf_off[v]..t.vf_off[v + 1]] {
        let tr = tris[f as usize];
        let k = tr.iter().position(|&x| x as usize == v).unwrap();
        let (a, b) = (tr[(k + 1) % 3] as usize, tr[(k + 2) % 3] as usize);
        add(a, 0.5 * cotan(p[b], p[v], p[a]));
        add(b, 0.5 * cotan(p[a], p[v], p[b]));
    }
    let (mut s, mut wsum) = (DVec3::ZERO, 0.0);
    for &(u, w) in &ws {
        let w = w.max(0.0);
        s += (p[u] - p[v]) * w;
        wsum += w;
    }
    if wsum > 0.0 { s / wsum } else { lap(p, t, v) }
}

/// Scale-dependent umbrella (Fujiwara): neighbours weighted by 1 / edge length.
fn lap_fuji(p: &[DVec3], t: &Topo, v: usize) -> DVec3 {
    let (mut s, mut w) = (DVec3::ZERO, 0.0);
    for &u in &t.nb[t.nb_off[v]..t.nb_off[v + 1]] {
        let e = p[u as usize] - p[v];
        let wi = 1.0 / e.length().max(1e-300);
        s += e * wi;
        w += wi;
    }
    s / w
}

fn volume(p: &[DVec3], tris: &[[u32; 3]]) -> f64 {
    tris.iter()
        .map(|t| p[t[0] as usize].dot(p[t[1] as usize].cross(p[t[2] as usize])))
        .sum::<f64>()
        / 6.0
}

/// Faces touching the free set, each once.
fn stencil_faces(t: &Topo, free: &[usize], out: &mut Vec<u32>) {
    out.clear();
    for &f in free {
        out.extend_from_slice(&t.vf[t.vf_off[f]..t.vf_off[f + 1]]);
    }
    out.sort_unstable();
    out.dedup();
}

/// Local volume (relative to origin o) and its gradient n for a common translation of `free`.
fn local_vol(
    p: &[DVec3],
    tris: &[[u32; 3]],
    faces: &[u32],
    free: &[usize],
    o: DVec3,
) -> (f64, DVec3) {
    local_vol_by(p, tris, faces, |v| free.contains(&v), o)
}

fn local_vol_by(
    p: &[DVec3],
    tris: &[[u32; 3]],
    faces: &[u32],
    is_free: impl Fn(usize) -> bool,
    o: DVec3,
) -> (f64, DVec3) {
    // A weight of 1 multiplies exactly: the same sums as without one.
    let weight = |v: usize| if is_free(v) { 1.0 } else { 0.0 };
    local_vol_weighted(p, tris, faces, weight, o)
}

/// Volume (relative to `o`) of `faces` and its gradient for the translation field `weight(u) · t`
/// (weight 0: not free).
fn local_vol_weighted(
    p: &[DVec3],
    tris: &[[u32; 3]],
    faces: &[u32],
    weight: impl Fn(usize) -> f64,
    o: DVec3,
) -> (f64, DVec3) {
    let mut v = 0.0;
    let mut n = DVec3::ZERO;
    for &f in faces {
        let tr = tris[f as usize];
        let q = [
            p[tr[0] as usize] - o,
            p[tr[1] as usize] - o,
            p[tr[2] as usize] - o,
        ];
        v += q[0].dot(q[1].cross(q[2]));
        for k in 0..3 {
            let w = weight(tr[k] as usize);
            if w != 0.0 {
                n += q[(k + 1) % 3].cross(q[(k + 2) % 3]) * w;
            }
        }
    }
    (v / 6.0, n / 6.0)
}

fn vertex_normals(p: &[DVec3], tris: &[[u32; 3]], t: &Topo) -> Vec<DVec3> {
    let mut nrm = vec![DVec3::ZERO; p.len()];
    for tr in tris {
        let (a, b, c) = (p[tr[0] as usize], p[tr[1] as usize], p[tr[2] as usize]);
        let f = (b - a).cross(c - a);
        for &v in tr {
            nrm[v as usize] += f;
        }
    }
    for (v, x) in nrm.iter_mut().enumerate() {
        *x = if t.fixed[v] {
            DVec3::ZERO
        } else {
            x.normalize_or_zero()
        };
    }
    nrm
}

/// Standard normal deviate (xorshift64* + Box–Muller), deterministic.
fn gauss(s: &mut u64) -> f64 {
    let mut u = || {
        *s ^= *s >> 12;
        *s ^= *s << 25;
        *s ^= *s >> 27;
        ((s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let (a, b) = (u(), u());
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

/// Noise level along the normals: MAD of the second difference of h = n·L(p), divided by the MAD
/// of the same operator applied to unit white noise on the same connectivity.
fn noise_sigma(p: &[DVec3], nrm: &[DVec3], t: &Topo, eps: &[f64], movable: &[usize]) -> f64 {
    let n = p.len();
    let nbmean = |x: &[f64], v: usize| {
        let ns = &t.nb[t.nb_off[v]..t.nb_off[v + 1]];
        ns.iter().map(|&u| x[u as usize]).sum::<f64>() / ns.len().max(1) as f64
    };
    let h: Vec<f64> = (0..n)
        .map(|v| {
            if t.nb_off[v + 1] > t.nb_off[v] {
                lap(p, t, v).dot(nrm[v])
            } else {
                0.0
            }
        })
        .collect();
    let he: Vec<f64> = (0..n).map(|v| nbmean(eps, v) - eps[v]).collect();
    let mad = |x: &[f64]| {
        let mut g: Vec<f64> = movable.iter().map(|&v| x[v] - nbmean(x, v)).collect();
        let mid = g.len() / 2;
        let med = *g.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
        let mut dev: Vec<f64> = g.iter().map(|x| (x - med).abs()).collect();
        *dev.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
    };
    mad(&h) / mad(&he)
}

/// Liu et al.'s step 1 on the edge stencil `free`: minimise Σ_rows |L(v)|² over the two free
/// positions (2×2 normal equations, per coordinate). false if singular.
fn stencil_min(p: &mut [DVec3], t: &Topo, free: [usize; 2], rows: &mut Vec<usize>) -> bool {
    rows.clear();
    for &f in &free {
        rows.push(f);
        rows.extend(
            t.nb[t.nb_off[f]..t.nb_off[f + 1]]
                .iter()
                .map(|&u| u as usize),
        );
    }
    rows.sort_unstable();
    rows.dedup();
    let (mut a00, mut a01, mut a11) = (0.0, 0.0, 0.0);
    let (mut b0, mut b1) = (DVec3::ZERO, DVec3::ZERO);
    for &v in rows.iter() {
        let ns = &t.nb[t.nb_off[v]..t.nb_off[v + 1]];
        let inv = 1.0 / ns.len() as f64;
        let coef = |f: usize| {
            if v == f {
                -1.0
            } else if ns.contains(&(f as u32)) {
                inv
            } else {
                0.0
            }
        };
        let (k0, k1) = (coef(free[0]), coef(free[1]));
        let l = lap(p, t, v);
        let q = p[free[0]] * k0 + p[free[1]] * k1 - l;
        a00 += k0 * k0;
        a01 += k0 * k1;
        a11 += k1 * k1;
        b0 += q * k0;
        b1 += q * k1;
    }
    let det = a00 * a11 - a01 * a01;
    if !(det > 1e-12 * (a00 * a11).max(1e-300)) {
        return false;
    }
    p[free[0]] = (b0 * a11 - b1 * a01) / det;
    p[free[1]] = (b1 * a00 - b0 * a01) / det;
    true
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 5 {
        eprintln!("usage: lowpass_lab IN OUTPREFIX METHOD ITERS [key=value ...]");
        std::process::exit(2);
    }
    let mesh = vcsmooth::io::read_mesh(std::path::Path::new(&a[1])).expect("read");
    let (prefix, method) = (&a[2], a[3].as_str());
    let auto = a[4] == "auto";
    let iters = if auto {
        100
    } else {
        a[4].parse::<usize>().unwrap()
    };
    let mut kv: HashMap<String, f64> = HashMap::new();
    for s in &a[5..] {
        let (k, v) = s.split_once('=').expect("key=value");
        kv.insert(k.to_string(), v.parse().unwrap());
    }
    let g = |k: &str, d: f64| *kv.get(k).unwrap_or(&d);
    let (lambda, mu, s) = (g("lambda", 0.5), g("mu", -0.53), g("s", 1.0));
    let tris: Vec<[u32; 3]> = mesh.triangles.to_vec();
    let mut p: Vec<DVec3> = mesh.positions.to_vec();
    let n = p.len();
    let t = topo(n, &tris);
    // eligible stencils and each vertex's count of them
    let elig: Vec<(u32, u32)> = t
        .edges
        .iter()
        .copied()
        .filter(|&(i, j)| !t.fixed[i as usize] && !t.fixed[j as usize])
        .collect();
    let mut cnt = vec![0u32; n];
    for &(i, j) in &elig {
        cnt[i as usize] += 1;
        cnt[j as usize] += 1;
    }
    let v0 = volume(&p, &tris);
    // --- automatic stopping (noise-explained removal), see docs/quality-research.md
    let p0 = p.clone();
    let nrm0 = vertex_normals(&p0, &tris, &t);
    let movable: Vec<usize> = (0..n).filter(|&v| !t.fixed[v]).collect();
    let mut rng = 0x9E37_79B9_7F4A_7C15u64;
    let mut eps = vec![0.0; n];
    for &v in &movable {
        eps[v] = gauss(&mut rng);
    }
    let sigma = noise_sigma(&p0, &nrm0, &t, &eps, &movable);
    let e0: f64 =
        movable.iter().map(|&v| eps[v] * eps[v]).sum::<f64>() / movable.len().max(1) as f64;
    let mut syn = eps.clone();
    let (mut exp_prev, mut obs_prev) = (0.0f64, 0.0f64);
    let tau = g("tau", 4.0 / 3.0);
    let eps_gone = g("gone", 0.01);
    eprintln!("sigma_hat {sigma:e}");
    let mut faces = Vec::new();
    let mut skipped = 0usize;
    let mut rings: Vec<Vec<usize>> = Vec::new();
    let mut rcnt = vec![0u32; n];
    let mut stamp = vec![0u32; n];
    let mut ringd: Vec<Vec<u8>> = Vec::new();
    let mut weight = vec![0.0f64; n];
    let mut rows: Vec<usize> = Vec::new();
    for it in 1..=iters {
        let before = p.clone();
        match method {
            "taubin" => {
                for step in [lambda, mu] {
                    let old = p.clone();
                    for v in 0..n {
                        if !t.fixed[v] {
                            p[v] = old[v] + step * s * lap(&old, &t, v);
                        }
                    }
                }
            }
            "lp" | "lpv" => {
                for &(i, j) in &elig {
                    let free = [i as usize, j as usize];
                    stencil_faces(&t, &free, &mut faces);
                    let o = (p[free[0]] + p[free[1]]) * 0.5;
                    let (vol0, _) = local_vol(&p, &tris, &faces, &free, o);
                    let keep = [p[free[0]], p[free[1]]];
                    for step in [lambda, mu] {
                        for &f in &free {
                            let w = if method == "lpv" {
                                s / cnt[f] as f64
                            } else {
                                s
                            };
                            let d = lap(&p, &t, f);
                            p[f] += step * w * d;
                        }
                    }
                    let (vol1, nv) = local_vol(&p, &tris, &faces, &free, o);
                    let nn = nv.length_squared();
                    let scale = (keep[0] - keep[1]).length_squared().max(1e-300);
                    if !(nn > 1e-24 * scale * scale) || !nn.is_finite() {
                        p[free[0]] = keep[0];
                        p[free[1]] = keep[1];
                        skipped += 1;
                        continue;
                    }
                    let w = nv * ((vol0 - vol1) / nn);
                    p[free[0]] += w;
                    p[free[1]] += w;
                }
            }
            "lps" => {
                // global Jacobi λ|μ displacement, handed out to the edge stencils (each of a vertex's
                // stencils applies 1/cnt of it in step 1), each stencil's volume then restored (step 2)
                let mut q = p.clone();
                for step in [lambda, mu] {
                    let old = q.clone();
                    for v in 0..n {
                        if !t.fixed[v] {
                            q[v] = old[v] + step * s * lap(&old, &t, v);
                        }
                    }
                }
                let d: Vec<DVec3> = (0..n)
                    .map(|v| {
                        if cnt[v] > 0 {
                            (q[v] - p[v]) / cnt[v] as f64
                        } else {
                            DVec3::ZERO
                        }
                    })
                    .collect();
                for &(i, j) in &elig {
                    let free = [i as usize, j as usize];
                    stencil_faces(&t, &free, &mut faces);
                    let o = (p[free[0]] + p[free[1]]) * 0.5;
                    let (vol0, _) = local_vol(&p, &tris, &faces, &free, o);
                    p[free[0]] += d[free[0]];
                    p[free[1]] += d[free[1]];
                    let (vol1, nv) = local_vol(&p, &tris, &faces, &free, o);
                    let nn = nv.length_squared();
                    if !(nn > 0.0) || !nn.is_finite() {
                        skipped += 1;
                        continue;
                    }
                    let w = nv * ((vol0 - vol1) / nn);
                    p[free[0]] += w;
                    p[free[1]] += w;
                }
            }
            "lpr" => {
                // global Jacobi λ|μ displacement; stencils = each free vertex with its r-ring (fixed
                // vertices left out); step 1 applies 1/cnt of each member's displacement, step 2 the
                // exact common translation of the stencil that restores its volume
                let r = g("r", 1.0) as usize;
                let mut q = p.clone();
                let fuji = g("fuji", 0.0) != 0.0;
                // bil=c: bilateral umbrella weights exp(-h²/(2 (c σ̂)²)), h = n_v · (p_u − p_v)
                // with the vertex normals of the iteration's start (feature-aware step 1)
                let bil = g("bil", 0.0);
                // cot=1: normalised cotangent weights (clamped at 0) instead of the umbrella
                let cot = g("cot", 0.0) != 0.0;
                let nb = if bil > 0.0 {
                    vertex_normals(&p, &tris, &t)
                } else {
                    Vec::new()
                };
                for step in [lambda, mu] {
                    let old = q.clone();
                    for v in 0..n {
                        if !t.fixed[v] {
                            let l = if fuji {
                                lap_fuji(&old, &t, v)
                            } else if cot {
                                lap_cot(&old, &tris, &t, v)
                            } else if bil > 0.0 {
                                let s2 = 2.0 * (bil * sigma).powi(2);
                                let (mut acc, mut wsum) = (DVec3::ZERO, 0.0);
                                for &u in &t.nb[t.nb_off[v]..t.nb_off[v + 1]] {
                                    let d = old[u as usize] - old[v];
                                    let h = nb[v].dot(d);
                                    let w = (-h * h / s2).exp();
                                    acc += d * w;
                                    wsum += w;
                                }
                                if wsum > 0.0 { acc / wsum } else { DVec3::ZERO }
                            } else {
                                lap(&old, &t, v)
                            };
                            q[v] = old[v] + step * s * l;
                        }
                    }
                }
                // nf=K: step 1 = normal filtering instead of λ|μ (Sun et al. 2007 / Zheng et al.
                // 2011): K passes of area-weighted averaging of the face normals over the faces
                // sharing a vertex (sr=σ_r > 0: bilateral range weight exp(-|n_f − n_g|²/2σ_r²)),
                // then nv=N vertex updates p_v += mean_{f∋v} m_f (m_f · (c_f − p_v))
                let kn = g("nf", 0.0) as usize;
                if kn > 0 {
                    let sr = g("sr", 0.0);
                    let nvu = g("nv", 1.0) as usize;
                    let nfc = tris.len();
                    let mut fm = vec![DVec3::ZERO; nfc];
                    let mut fa = vec![0.0; nfc];
                    for (i, tr) in tris.iter().enumerate() {
                        let (a, b, c) = (p[tr[0] as usize], p[tr[1] as usize], p[tr[2] as usize]);
                        let cr = (b - a).cross(c - a);
                        fa[i] = 0.5 * cr.length();
                        fm[i] = cr.normalize_or_zero();
                    }
                    for _ in 0..kn {
                        let old = fm.clone();
                        for (i, tr) in tris.iter().enumerate() {
                            let mut acc = DVec3::ZERO;
                            for &v in tr {
                                for &gf in &t.vf[t.vf_off[v as usize]..t.vf_off[v as usize + 1]] {
                                    let gf = gf as usize;
                                    let mut w = fa[gf];
                                    if sr > 0.0 {
                                        w *= (-(old[i] - old[gf]).length_squared()
                                            / (2.0 * sr * sr))
                                            .exp();
                                    }
                                    acc += old[gf] * w;
                                }
                            }
                            fm[i] = acc.normalize_or_zero();
                        }
                    }
                    q = p.clone();
                    for _ in 0..nvu {
                        let old = q.clone();
                        for v in 0..n {
                            if t.fixed[v] {
                                continue;
                            }
                            let fs = &t.vf[t.vf_off[v]..t.vf_off[v + 1]];
                            let mut acc = DVec3::ZERO;
                            for &f in fs {
                                let tr = tris[f as usize];
                                let c = (old[tr[0] as usize]
                                    + old[tr[1] as usize]
                                    + old[tr[2] as usize])
                                    / 3.0;
                                let m = fm[f as usize];
                                acc += m * m.dot(c - old[v]);
                            }
                            q[v] = old[v] + s * acc / fs.len() as f64;
                        }
                    }
                }
                if g("proj", 0.0) != 0.0 {
                    let nr = vertex_normals(&p, &tris, &t);
                    for v in 0..n {
                        let dv = q[v] - p[v];
                        q[v] = p[v] + nr[v] * dv.dot(nr[v]);
                    }
                }
                if rings.is_empty() {
                    for v in 0..n {
                        let mut set = vec![];
                        let mut dist = vec![];
                        if !t.fixed[v] {
                            set.push(v);
                            dist.push(0u8);
                            let mut frontier = vec![v];
                            for d in 0..r {
                                let mut next = vec![];
                                for &u in &frontier {
                                    for &w in &t.nb[t.nb_off[u]..t.nb_off[u + 1]] {
                                        let w = w as usize;
                                        if !t.fixed[w] && !set.contains(&w) {
                                            set.push(w);
                                            dist.push(d as u8 + 1);
                                            next.push(w);
                                        }
                                    }
                                }
                                frontier = next;
                            }
                        }
                        for &u in &set {
                            rcnt[u] += 1;
                        }
                        rings.push(set);
                        ringd.push(dist);
                    }
                }
                // w1=, w2=, w3=: the step-2 translation tapered by graph distance from the stencil's
                // centre (weight 1 at the centre); all displacements stay parallel, so the volume
                // is still linear in the step and restored exactly
                let taper = [1.0, g("w1", 1.0), g("w2", 1.0), g("w3", 1.0)];
                let d: Vec<DVec3> = (0..n)
                    .map(|v| {
                        if rcnt[v] > 0 {
                            (q[v] - p[v]) / rcnt[v] as f64
                        } else {
                            DVec3::ZERO
                        }
                    })
                    .collect();
                for v in 0..n {
                    let free = &rings[v];
                    if free.is_empty() {
                        continue;
                    }
                    stencil_faces(&t, free, &mut faces);
                    for (&u, &du) in free.iter().zip(&ringd[v]) {
                        stamp[u] = v as u32 + 1;
                        weight[u] = taper[du as usize];
                    }
                    let o = p[v];
                    let mark = |u: usize| stamp[u] == v as u32 + 1;
                    let wt = |u: usize| if mark(u) { weight[u] } else { 0.0 };
                    let (vol0, _) = local_vol_by(&p, &tris, &faces, mark, o);
                    for &u in free {
                        p[u] += d[u];
                    }
                    let (vol1, nv) = local_vol_weighted(&p, &tris, &faces, wt, o);
                    let nn = nv.length_squared();
                    if !(nn > 0.0) || !nn.is_finite() {
                        skipped += 1;
                        continue;
                    }
                    let w = nv * ((vol0 - vol1) / nn);
                    for &u in free {
                        p[u] += w * weight[u];
                    }
                }
            }
            "vcs" | "lem" => {
                for &(i, j) in &elig {
                    let free = [i as usize, j as usize];
                    stencil_faces(&t, &free, &mut faces);
                    let o = (p[free[0]] + p[free[1]]) * 0.5;
                    let (vol0, _) = local_vol(&p, &tris, &faces, &free, o);
                    let keep = [p[free[0]], p[free[1]]];
                    if !stencil_min(&mut p, &t, free, &mut rows) {
                        skipped += 1;
                        continue;
                    }
                    if method == "lem" {
                        continue;
                    }
                    let (vol1, nv) = local_vol(&p, &tris, &faces, &free, o);
                    let nn = nv.length_squared();
                    if !(nn > 0.0) || !nn.is_finite() {
                        p[free[0]] = keep[0];
                        p[free[1]] = keep[1];
                        skipped += 1;
                        continue;
                    }
                    let w = nv * ((vol0 - vol1) / nn);
                    p[free[0]] += w;
                    p[free[1]] += w;
                }
            }
            "glob" => {
                // reference only: Jacobi λ|μ, then one uniform offset along the vertex normals that
                // restores the global volume (secant iterations)
                for step in [lambda, mu] {
                    let old = p.clone();
                    for v in 0..n {
                        if !t.fixed[v] {
                            p[v] = old[v] + step * s * lap(&old, &t, v);
                        }
                    }
                }
                let mut nrm = vec![DVec3::ZERO; n];
                for tr in &tris {
                    let (a, b, c) = (p[tr[0] as usize], p[tr[1] as usize], p[tr[2] as usize]);
                    let fnrm = (b - a).cross(c - a);
                    for &v in tr {
                        nrm[v as usize] += fnrm;
                    }
                }
                for v in 0..n {
                    nrm[v] = if t.fixed[v] {
                        DVec3::ZERO
                    } else {
                        nrm[v].normalize_or_zero()
                    };
                }
                let base = p.clone();
                let f = |x: f64, p: &mut Vec<DVec3>| {
                    for v in 0..n {
                        p[v] = base[v] + nrm[v] * x;
                    }
                    volume(p, &tris) - v0
                };
                let (mut x0, mut x1) = (0.0, 1e-3 * (base[0] - base[1]).length().max(1e-12));
                let (mut f0, mut f1) = (f(x0, &mut p), f(x1, &mut p));
                for _ in 0..30 {
                    if f1 == f0 {
                        break;
                    }
                    let x2 = x1 - f1 * (x1 - x0) / (f1 - f0);
                    x0 = x1;
                    f0 = f1;
                    x1 = x2;
                    f1 = f(x1, &mut p);
                    if (f1 / v0).abs() < 1e-15 {
                        break;
                    }
                }
            }
            _ => panic!("unknown method {method}"),
        }
        let mut sum = 0.0;
        let mut mx: f64 = 0.0;
        let mut moved = 0usize;
        for v in 0..n {
            if !t.fixed[v] {
                let d = (p[v] - before[v]).length();
                sum += d;
                mx = mx.max(d);
                moved += 1;
            }
        }
        let vol = volume(&p, &tris);
        // expected: the method's scalar analogue on the synthetic white noise
        if method == "vcs" || method == "lem" {
            let mut sv: Vec<DVec3> = syn.iter().map(|&x| DVec3::new(x, 0.0, 0.0)).collect();
            for &(i, j) in &elig {
                let (a, b) = (sv[i as usize].x, sv[j as usize].x);
                if stencil_min(&mut sv, &t, [i as usize, j as usize], &mut rows) && method == "vcs"
                {
                    // scalar step 2 (linearised volume, equal vertex weights): remove the mean change
                    let m = 0.5 * ((sv[i as usize].x - a) + (sv[j as usize].x - b));
                    sv[i as usize].x -= m;
                    sv[j as usize].x -= m;
                }
            }
            for v in 0..n {
                syn[v] = sv[v].x;
            }
        } else {
            for step in [lambda, mu] {
                let old = syn.clone();
                for &v in &movable {
                    let ns = &t.nb[t.nb_off[v]..t.nb_off[v + 1]];
                    let m = ns.iter().map(|&u| old[u as usize]).sum::<f64>() / ns.len() as f64;
                    syn[v] = old[v] + step * s * (m - old[v]);
                }
            }
        }
        let exp_k = movable
            .iter()
            .map(|&v| (syn[v] - eps[v]).powi(2))
            .sum::<f64>()
            / movable.len().max(1) as f64
            / e0;
        let obs_k = movable
            .iter()
            .map(|&v| ((p[v] - p0[v]).dot(nrm0[v])).powi(2))
            .sum::<f64>()
            / movable.len().max(1) as f64
            / (sigma * sigma);
        let (dexp, dobs) = (exp_k - exp_prev, obs_k - obs_prev);
        let ratio = if dexp > 0.0 {
            dobs / dexp
        } else {
            f64::INFINITY
        };
        let ratio_s = if ratio.is_finite() {
            format!("{ratio:e}")
        } else {
            "null".to_string()
        };
        // stencil methods (vcs, lem): their scalar analogue stalls after 1–2 iterations, so the
        // "noise gone" test is on the displacement instead: mean move < 5 % of the noise level
        let stop = auto
            && if method == "vcs" || method == "lem" {
                (sum / moved.max(1) as f64) < g("dgone", 0.05) * sigma
            } else {
                (it >= 2 && ratio > tau) || dexp < eps_gone
            };
        exp_prev = exp_k;
        obs_prev = obs_k;
        println!(
            "{{\"iteration\":{it},\"dvol\":{:e},\"mean_displacement\":{:e},\"max_displacement\":{:e},\"skipped\":{skipped},\"exp\":{exp_k:e},\"obs\":{obs_k:e},\"ratio\":{ratio_s},\"stop\":{stop}}}",
            vol / v0 - 1.0,
            sum / moved.max(1) as f64,
            mx
        );
        let mut buf = Vec::with_capacity(n * 24);
        for q in &p {
            for c in [q.x, q.y, q.z] {
                buf.extend_from_slice(&c.to_le_bytes());
            }
        }
        std::fs::File::create(format!("{prefix}.{it}.bin"))
            .unwrap()
            .write_all(&buf)
            .unwrap();
        if stop {
            break;
        }
    }
}
