//! The sequential prototype of `vcs-lowpass` (one whole-mesh iteration, its blocks with their
//! own volume arithmetic) and of `--iterations auto` ([`AutoStop`], the rule for filters),
//! kept as the independent references that the kernel (`vcsmooth::smooth::lowpass`) and the
//! engine's rule (`vcsmooth::engine::auto`) are tested against: here, in `engine` and in `auto`.
//! The method is defined in the kernel's module doc and in docs/quality-research.md.

use glam::DVec3;
use vcsmooth::Topology;

/// Reusable buffers of [`lowpass_iteration`].
#[derive(Debug, Default)]
pub struct Scratch {
    d: Vec<DVec3>,
    q: Vec<DVec3>,
    fmark: Vec<u32>,
    faces: Vec<u32>,
}

/// Blocks applied and skipped (degenerate volume gradient) in one iteration.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    pub applied: usize,
    pub skipped_degenerate: usize,
}

fn umbrella(topo: &Topology, p: &[DVec3], v: u32) -> DVec3 {
    let ns = topo.neighbors(v);
    let mut s = DVec3::ZERO;
    for &u in ns {
        s += p[u as usize];
    }
    s / ns.len() as f64 - p[v as usize]
}

/// One λ|μ pair, Jacobi, into `out` (fixed and isolated vertices copied).
pub fn taubin_pair(
    topo: &Topology,
    p: &[DVec3],
    lambda: f64,
    mu: f64,
    tmp: &mut Vec<DVec3>,
    out: &mut Vec<DVec3>,
) {
    let n = p.len();
    let movable = |v: u32| !topo.is_fixed(v) && topo.deg(v) > 0;
    tmp.clear();
    tmp.extend((0..n as u32).map(|v| {
        if movable(v) {
            p[v as usize] + lambda * umbrella(topo, p, v)
        } else {
            p[v as usize]
        }
    }));
    out.clear();
    out.extend((0..n as u32).map(|v| {
        if movable(v) {
            tmp[v as usize] + mu * umbrella(topo, tmp, v)
        } else {
            tmp[v as usize]
        }
    }));
}

/// Six times the volume (relative to `o`) of `faces` with the vertices of `moved` displaced by
/// `s` along their `dir`.
fn offset_volume(
    p: &[DVec3],
    tris: &[[u32; 3]],
    faces: &[u32],
    moved: &dyn Fn(u32) -> Option<DVec3>,
    s: f64,
    o: DVec3,
) -> f64 {
    faces
        .iter()
        .map(|&f| {
            let q =
                tris[f as usize].map(|v| p[v as usize] - o + moved(v).unwrap_or(DVec3::ZERO) * s);
            q[0].dot(q[1].cross(q[2]))
        })
        .sum()
}

/// One `vcs-lowpass` iteration over the whole mesh, as one patch cut evenly into blocks of at
/// least `block` consecutive vertices (see the kernel's module doc): each block's movable vertices take their
/// whole Taubin displacement, then the common offset along their unit volume gradients that
/// gives the block's faces their volume back, found here by the secant method on the volume
/// itself (the kernel solves the cubic's coefficients).
#[allow(clippy::needless_range_loop)] // The blocks are ranges of ids: plainest as such.
pub fn lowpass_iteration(
    topo: &Topology,
    tris: &[[u32; 3]],
    p: &mut [DVec3],
    lambda: f64,
    mu: f64,
    block: usize,
    s: &mut Scratch,
) -> Counts {
    let n = p.len();
    taubin_pair(topo, p, lambda, mu, &mut s.q, &mut s.d);
    for (v, (d, q)) in s.d.iter_mut().zip(p.iter()).enumerate() {
        *d = if topo.is_fixed(v as u32) {
            DVec3::ZERO
        } else {
            *d - *q
        };
    }
    s.fmark.clear();
    s.fmark.resize(tris.len(), u32::MAX);
    let mut counts = Counts::default();
    // ⌊n / block⌋ blocks (one if fewer), the ids cut evenly.
    let count = (n / block).max(1);
    for k in 0..count {
        let (lo, hi) = (n * k / count, n * (k + 1) / count);
        let free = |u: u32| (lo..hi).contains(&(u as usize)) && !topo.is_fixed(u);
        if !(lo..hi).any(|u| free(u as u32)) {
            continue;
        }
        s.faces.clear();
        for u in lo..hi {
            if free(u as u32) {
                for f in topo.faces_of(u as u32, tris) {
                    if s.fmark[f as usize] != k as u32 {
                        s.fmark[f as usize] = k as u32;
                        s.faces.push(f);
                    }
                }
            }
        }
        let o = p[lo];
        let none = |_: u32| None;
        let v0 = offset_volume(p, tris, &s.faces, &none, 0.0, o);
        for u in lo..hi {
            if free(u as u32) {
                p[u] += s.d[u];
            }
        }
        // Each free vertex's unit volume gradient after step 1.
        let dir: Vec<DVec3> = (lo..hi)
            .map(|u| {
                let mut g = DVec3::ZERO;
                if free(u as u32) {
                    for f in topo.faces_of(u as u32, tris) {
                        let t = tris[f as usize];
                        let k = t.iter().position(|&x| x as usize == u).unwrap();
                        let (b, c) = (t[(k + 1) % 3] as usize, t[(k + 2) % 3] as usize);
                        g += (p[b] - o).cross(p[c] - o);
                    }
                }
                g.normalize_or_zero()
            })
            .collect();
        let moved = |u: u32| free(u).then(|| dir[u as usize - lo]);
        let f = |x: f64| offset_volume(p, tris, &s.faces, &moved, x, o) - v0;
        let (mut a, mut b) = (0.0, 1e-6 * (p[lo] - p[hi - 1]).length().max(1e-300));
        let (mut fa, mut fb) = (f(a), f(b));
        for _ in 0..50 {
            if fb == fa {
                break;
            }
            let c = b - fb * (b - a) / (fb - fa);
            (a, fa) = (b, fb);
            b = c;
            fb = f(b);
        }
        if !b.is_finite() || !fb.is_finite() {
            for u in lo..hi {
                if free(u as u32) {
                    p[u] -= s.d[u];
                }
            }
            counts.skipped_degenerate += 1;
            continue;
        }
        for u in lo..hi {
            if free(u as u32) {
                p[u] += dir[u - lo] * b;
            }
        }
        counts.applied += 1;
    }
    counts
}

/// The automatic stop of `--iterations auto`: stop when what an iteration removes along the
/// normals is no longer explained by noise (`ratio > tau`), or when the method's filter would
/// remove less than `gone` of the input noise energy per further iteration.
///
/// - `σ̂ = MAD(g) / MAD(g^ε)`, `g_v = h_v − mean_{N(v)} h`, `h_v = n_v · L(P⁰)_v`; `g^ε` the same
///   operators on i.i.d. N(0, 1) samples ε on the same connectivity.
/// - Expected: `E_k = mean (e^k − ε)² / mean ε²`, `e^k` = the method's scalar analogue applied k
///   times to ε (the caller applies it to [`AutoStop::synthetic_mut`] each iteration).
/// - Observed: `O_k = mean ((P^k − P⁰)·n)² / σ̂²`; `ratio_k = ΔO / ΔE`.
#[derive(Debug, Clone)]
pub struct AutoStop {
    p0: Vec<DVec3>,
    n0: Vec<DVec3>,
    movable: Vec<u32>,
    eps: Vec<f64>,
    syn: Vec<f64>,
    eps_energy: f64,
    sigma: f64,
    expected: f64,
    observed: f64,
    iteration: usize,
    /// Stop when more than `1 − 1/tau` of an iteration's removal is not noise (default 4/3, the
    /// research's value; the engine's is `engine::auto::DETAIL_RATIO`).
    pub tau: f64,
    /// Stop when the expected gain falls below this fraction of the noise energy (default 0.01).
    pub gone: f64,
}

/// What [`AutoStop::observe`] saw after one iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    pub iteration: usize,
    pub expected_gain: f64,
    pub ratio: f64,
    pub stop: bool,
}

fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn gaussian(state: &mut u64) -> f64 {
    let u = |s: &mut u64| ((splitmix(s) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let (a, b) = (u(state), u(state));
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let mid = x.len() / 2;
    *x.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
}

impl AutoStop {
    pub fn new(topo: &Topology, tris: &[[u32; 3]], p0: &[DVec3], seed: u64) -> AutoStop {
        let n = p0.len();
        let mut n0 = vec![DVec3::ZERO; n];
        for t in tris {
            let (a, b, c) = (p0[t[0] as usize], p0[t[1] as usize], p0[t[2] as usize]);
            let f = (b - a).cross(c - a);
            for &v in t {
                n0[v as usize] += f;
            }
        }
        let movable: Vec<u32> = (0..n as u32)
            .filter(|&v| !topo.is_fixed(v) && topo.deg(v) > 0)
            .collect();
        let mut state = seed;
        let mut eps = vec![0.0; n];
        for &v in &movable {
            eps[v as usize] = gaussian(&mut state);
        }
        for (v, x) in n0.iter_mut().enumerate() {
            *x = if topo.is_fixed(v as u32) {
                DVec3::ZERO
            } else {
                x.normalize_or_zero()
            };
        }
        let nbmean = |x: &[f64], v: u32| {
            let ns = topo.neighbors(v);
            ns.iter().map(|&u| x[u as usize]).sum::<f64>() / ns.len().max(1) as f64
        };
        let h: Vec<f64> = (0..n as u32)
            .map(|v| {
                if topo.deg(v) > 0 {
                    umbrella(topo, p0, v).dot(n0[v as usize])
                } else {
                    0.0
                }
            })
            .collect();
        let he: Vec<f64> = (0..n as u32)
            .map(|v| nbmean(&eps, v) - eps[v as usize])
            .collect();
        let mad = |x: &[f64]| {
            let mut g: Vec<f64> = movable
                .iter()
                .map(|&v| x[v as usize] - nbmean(x, v))
                .collect();
            let med = median(&mut g);
            let mut dev: Vec<f64> = g.iter().map(|y| (y - med).abs()).collect();
            median(&mut dev)
        };
        let (mh, me) = (mad(&h), mad(&he));
        let sigma = if me > 0.0 { mh / me } else { 0.0 };
        let eps_energy = movable
            .iter()
            .map(|&v| eps[v as usize].powi(2))
            .sum::<f64>()
            / movable.len().max(1) as f64;
        AutoStop {
            p0: p0.to_vec(),
            n0,
            movable,
            syn: eps.clone(),
            eps,
            eps_energy,
            sigma,
            expected: 0.0,
            observed: 0.0,
            iteration: 0,
            tau: 4.0 / 3.0,
            gone: 0.01,
        }
    }

    /// The estimated noise level along the normals (length units).
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The synthetic noise field: apply the method's scalar analogue to it once per iteration,
    /// before [`AutoStop::observe`].
    pub fn synthetic_mut(&mut self) -> &mut [f64] {
        &mut self.syn
    }

    /// Record iteration k's positions; `stop` says whether to end after it.
    pub fn observe(&mut self, p: &[DVec3]) -> Observation {
        self.iteration += 1;
        let m = self.movable.len().max(1) as f64;
        let expected = self
            .movable
            .iter()
            .map(|&v| (self.syn[v as usize] - self.eps[v as usize]).powi(2))
            .sum::<f64>()
            / m
            / self.eps_energy.max(f64::MIN_POSITIVE);
        let observed = self
            .movable
            .iter()
            .map(|&v| {
                (p[v as usize] - self.p0[v as usize])
                    .dot(self.n0[v as usize])
                    .powi(2)
            })
            .sum::<f64>()
            / m
            / (self.sigma * self.sigma).max(f64::MIN_POSITIVE);
        let gain = expected - self.expected;
        let ratio = if gain > 0.0 {
            (observed - self.observed) / gain
        } else {
            f64::INFINITY
        };
        self.expected = expected;
        self.observed = observed;
        let stop =
            self.sigma == 0.0 || (self.iteration >= 2 && ratio > self.tau) || gain < self.gone;
        Observation {
            iteration: self.iteration,
            expected_gain: gain,
            ratio,
            stop,
        }
    }
}

/// The scalar analogue of taubin and vcs-lowpass: one λ|μ pair, Jacobi, fixed vertices kept.
pub fn scalar_taubin_pair(
    topo: &Topology,
    x: &mut [f64],
    lambda: f64,
    mu: f64,
    tmp: &mut Vec<f64>,
) {
    for step in [lambda, mu] {
        tmp.clear();
        tmp.extend_from_slice(x);
        for v in 0..x.len() as u32 {
            let ns = topo.neighbors(v);
            if topo.is_fixed(v) || ns.is_empty() {
                continue;
            }
            let m = ns.iter().map(|&u| tmp[u as usize]).sum::<f64>() / ns.len() as f64;
            x[v as usize] = tmp[v as usize] + step * (m - tmp[v as usize]);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The references' own checks, and the kernel against them.

mod tests {
    use vcsmooth::engine::{self, EngineSettings, Quiet};
    use vcsmooth::shapes::{add_normal_noise, icosphere};
    use vcsmooth::smooth::lowpass::BLOCK;
    use vcsmooth::{Method, Options, metrics};

    use super::*;

    fn volume(p: &[DVec3], tris: &[[u32; 3]]) -> f64 {
        tris.iter()
            .map(|t| p[t[0] as usize].dot(p[t[1] as usize].cross(p[t[2] as usize])))
            .sum::<f64>()
            / 6.0
    }

    fn rms_radius_error(p: &[DVec3]) -> f64 {
        (p.iter().map(|q| (q.length() - 1.0).powi(2)).sum::<f64>() / p.len() as f64).sqrt()
    }

    #[test]
    fn keeps_volume_and_denoises_a_sphere() {
        let mut mesh = icosphere(4);
        add_normal_noise(&mut mesh, 0.3, 7);
        let tris = mesh.triangles.to_vec();
        let mut p = mesh.positions.to_vec();
        let topo = Topology::build(p.len(), &tris).unwrap();
        let (v0, e0) = (volume(&p, &tris), rms_radius_error(&p));
        let mut s = Scratch::default();
        for _ in 0..10 {
            // Blocks of 300 or more: eight of 320 or 321, most of their faces shared with another.
            let c = lowpass_iteration(&topo, &tris, &mut p, 0.5, -0.53, 300, &mut s);
            assert_eq!((c.applied, c.skipped_degenerate), (8, 0));
        }
        assert!(((volume(&p, &tris) - v0) / v0).abs() < 1e-12);
        assert!(
            rms_radius_error(&p) < 0.5 * e0,
            "{} vs {}",
            rms_radius_error(&p),
            e0
        );
    }

    #[test]
    fn the_engine_kernel_follows_the_prototype_and_keeps_volume() {
        // Same order of work (the engine in the input's own order: one patch, its blocks in
        // index order), different arithmetic (the kernel solves the cubic's coefficients, the
        // prototype the volume itself by the secant method): the positions agree to rounding,
        // and both keep the volume. 10,242 vertices: two blocks of 5,121.
        let mut mesh = icosphere(5);
        add_normal_noise(&mut mesh, 0.3, 7);
        let offset = DVec3::new(3.0, -2.0, 5.0);
        let p0: Vec<DVec3> = mesh.positions.iter().map(|p| *p + offset).collect();
        mesh.positions = p0.clone().into();
        let tris = mesh.triangles.to_vec();
        let topo = Topology::build(p0.len(), &tris).unwrap();
        let iterations = 8;
        let blocks = topo.len() / BLOCK as usize;
        assert_eq!(blocks, 2);
        let mut proto = p0.clone();
        let mut s = Scratch::default();
        for _ in 0..iterations {
            let mu = Method::VcsLowpass.unit().default_mu();
            let c = lowpass_iteration(&topo, &tris, &mut proto, 0.5, mu, BLOCK as usize, &mut s);
            assert_eq!(c.applied, blocks);
        }
        let opts = Options {
            method: Method::VcsLowpass,
            iterations,
            ..Options::default()
        };
        let report =
            engine::smooth_in_order(&mut mesh, &opts, &EngineSettings::default(), &mut Quiet)
                .unwrap();
        assert_eq!(report.records.len(), iterations);
        for r in &report.records {
            assert_eq!(r.stencils.applied as usize, blocks, "{}", r.iteration);
        }
        let kernel = mesh.positions.to_vec();
        let far = proto
            .iter()
            .zip(&kernel)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f64::max);
        assert!(far < 1e-12, "{far}");
        let vol = |p: &[DVec3]| metrics::volume(p, &tris);
        let v0 = vol(&p0);
        assert!(((vol(&kernel) - v0) / v0).abs() < 1e-12);
    }

    #[test]
    fn open_mesh_keeps_boundary_and_volume() {
        let mut mesh = icosphere(3);
        add_normal_noise(&mut mesh, 0.3, 3);
        // open a hole: drop the faces around vertex 0
        let tris: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .copied()
            .filter(|t| !t.contains(&0))
            .collect();
        let mut p = mesh.positions.to_vec();
        let topo = Topology::build(p.len(), &tris).unwrap();
        let before = p.clone();
        let v0 = volume(&p, &tris);
        let mut s = Scratch::default();
        for _ in 0..5 {
            lowpass_iteration(&topo, &tris, &mut p, 0.5, -0.53, 100, &mut s);
        }
        for v in 0..p.len() as u32 {
            if topo.is_fixed(v) {
                assert_eq!(p[v as usize], before[v as usize]);
            }
        }
        assert!(((volume(&p, &tris) - v0) / v0).abs() < 1e-12);
    }

    #[test]
    fn auto_stop_estimates_the_noise_and_stops() {
        let mut mesh = icosphere(5);
        let clean_edge = {
            let p = &mesh.positions;
            let t = mesh.triangles[0];
            (p[t[0] as usize] - p[t[1] as usize]).length()
        };
        add_normal_noise(&mut mesh, 0.3, 11);
        let tris = mesh.triangles.to_vec();
        let mut p = mesh.positions.to_vec();
        let topo = Topology::build(p.len(), &tris).unwrap();
        let mut auto = AutoStop::new(&topo, &tris, &p, 1);
        let rel = auto.sigma() / (0.3 * clean_edge);
        assert!((0.8..1.2).contains(&rel), "sigma estimate off by {rel}");
        let mut s = Scratch::default();
        let mut tmp = Vec::new();
        let mut stopped = None;
        for k in 1..=100 {
            lowpass_iteration(&topo, &tris, &mut p, 0.5, -0.53, BLOCK as usize, &mut s);
            scalar_taubin_pair(&topo, auto.synthetic_mut(), 0.5, -0.53, &mut tmp);
            if auto.observe(&p).stop {
                stopped = Some(k);
                break;
            }
        }
        let k = stopped.expect("stops");
        assert!((5..=30).contains(&k), "stopped after {k}");
    }
}
