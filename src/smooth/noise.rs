//! Per-vertex quantities of the automatic stop (`--iterations auto`, [`crate::engine::auto`]):
//! the noise estimate's operators, a reproducible white-noise sample, and the scalar analogue of
//! the Jacobi methods. Pure functions over a vertex range `first .. first + out.len()`, each
//! entry depending only on its inputs, so any split into ranges gives the same bits.
//!
//! "Movable" is "not fixed" ([`Topology::is_fixed`]: unreferenced vertices are fixed too). The
//! definitions are those of docs/quality-research.md §5:
//! - `n_v`: the unit area-weighted normal of the input, zero on fixed vertices;
//! - `h_v = n_v · L(P⁰)_v`, the normal component of the umbrella Laplacian;
//! - `g_v = h_v − mean_{u∈N(v)} h_u`, its second difference (the smooth curvature cancels);
//! - `ε_v ~ N(0, 1)`, i.i.d. on the movable vertices, 0 on fixed ones.

use glam::DVec3;

use super::inv_deg;
use crate::topology::Topology;

/// The unit area-weighted normals of the vertices (zero for a fixed vertex, and for one whose
/// faces' normals cancel).
pub fn unit_normals_into(
    topo: &Topology,
    tris: &[[u32; 3]],
    pos: &[DVec3],
    out: &mut [DVec3],
    first: usize,
) {
    for (k, o) in out.iter_mut().enumerate() {
        let v = (first + k) as u32;
        *o = if topo.is_fixed(v) {
            DVec3::ZERO
        } else {
            let sum = topo.faces_of(v, tris).fold(DVec3::ZERO, |s, t| {
                let [a, b, c] = tris[t as usize].map(|i| pos[i as usize]);
                s + (b - a).cross(c - a)
            });
            sum.normalize_or_zero()
        };
    }
}

/// `h_v = n_v · L(p)_v` (0 for a vertex without neighbours).
pub fn normal_laplacian_into(
    topo: &Topology,
    pos: &[DVec3],
    normals: &[DVec3],
    out: &mut [f64],
    first: usize,
) {
    for (k, o) in out.iter_mut().enumerate() {
        let v = first + k;
        let ns = topo.neighbors(v as u32);
        *o = if ns.is_empty() {
            0.0
        } else {
            let sum = super::neighbor_sum(topo, pos, v as u32);
            (sum * inv_deg(ns.len()) - pos[v]).dot(normals[v])
        };
    }
}

/// The scalar umbrella `mean_{u∈N(v)} x_u − x_v` of every vertex (0 without neighbours).
pub fn scalar_laplacian_into(topo: &Topology, x: &[f64], out: &mut [f64], first: usize) {
    for (k, o) in out.iter_mut().enumerate() {
        let v = first + k;
        *o = neighbour_mean(topo, x, v as u32) - x[v];
    }
}

/// `x_v − mean_{u∈N(v)} x_u` on movable vertices, NaN on fixed ones (which a median then skips).
pub fn second_difference_into(topo: &Topology, x: &[f64], out: &mut [f64], first: usize) {
    for (k, o) in out.iter_mut().enumerate() {
        let v = (first + k) as u32;
        *o = if topo.is_fixed(v) {
            f64::NAN
        } else {
            x[v as usize] - neighbour_mean(topo, x, v)
        };
    }
}

/// One Jacobi umbrella step `x_v + factor · (mean_{N(v)} x − x_v)` on movable vertices; fixed
/// vertices keep their value. The scalar analogue of one step of `laplacian` and `taubin`.
pub fn scalar_step_into(topo: &Topology, x: &[f64], out: &mut [f64], first: usize, factor: f64) {
    for (k, o) in out.iter_mut().enumerate() {
        let v = (first + k) as u32;
        let xv = x[v as usize];
        *o = if topo.is_fixed(v) {
            xv
        } else {
            xv + factor * (neighbour_mean(topo, x, v) - xv)
        };
    }
}

/// `ε_v`: a standard normal sample for a movable vertex `v`, 0 for a fixed one. A function of
/// `seed` and `v` alone (outputs `2v + 1` and `2v + 2` of the SplitMix64 stream from `seed`,
/// through Box–Muller), so the sample is recomputed rather than stored.
pub fn white_noise_into(topo: &Topology, seed: u64, out: &mut [f64], first: usize) {
    for (k, o) in out.iter_mut().enumerate() {
        *o = epsilon(topo, seed, first + k);
    }
}

/// `ε_v` of [`white_noise_into`] for any vertex `v`.
#[inline]
pub fn epsilon(topo: &Topology, seed: u64, v: usize) -> f64 {
    match topo.is_fixed(v as u32) {
        true => 0.0,
        false => gaussian(seed, v as u64),
    }
}

/// `ε_v` of [`white_noise_into`] for a movable vertex.
pub fn gaussian(seed: u64, v: u64) -> f64 {
    const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;
    let uniform = |k: u64| {
        let mut z = seed.wrapping_add(k.wrapping_mul(GOLDEN));
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        // In (0, 1): never 0, whose logarithm Box–Muller cannot take.
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let (a, b) = (uniform(2 * v + 1), uniform(2 * v + 2));
    (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
}

fn neighbour_mean(topo: &Topology, x: &[f64], v: u32) -> f64 {
    let ns = topo.neighbors(v);
    if ns.is_empty() {
        return 0.0;
    }
    ns.iter().map(|&u| x[u as usize]).sum::<f64>() * inv_deg(ns.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::icosphere;

    #[test]
    fn the_sample_is_standard_normal_and_repeats() {
        let n = 200_000u64;
        let xs: Vec<f64> = (0..n).map(|v| gaussian(1, v)).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.01,
            "{mean} {var}"
        );
        // Neighbouring vertices are not correlated (their draws do not share stream outputs).
        let lag = xs.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / n as f64;
        assert!(lag.abs() < 0.01, "{lag}");
        assert_eq!(gaussian(1, 17), xs[17]);
        assert_ne!(gaussian(2, 17), xs[17]);
    }

    #[test]
    fn a_sphere_has_outward_normals_and_constant_normal_laplacian() {
        let mesh = icosphere(3);
        let topo = Topology::build(mesh.positions.len(), &mesh.triangles).unwrap();
        let n = topo.len();
        let mut normals = vec![DVec3::ZERO; n];
        unit_normals_into(&topo, &mesh.triangles, &mesh.positions, &mut normals, 0);
        for (p, q) in mesh.positions.iter().zip(&normals) {
            assert!(p.normalize().dot(*q) > 0.999);
        }
        let mut h = vec![0.0; n];
        normal_laplacian_into(&topo, &mesh.positions, &normals, &mut h, 0);
        // Curvature only: inward, about the same everywhere, so its second difference is small.
        assert!(h.iter().all(|&x| x < 0.0));
        let mut g = vec![0.0; n];
        second_difference_into(&topo, &h, &mut g, 0);
        let (gmax, hmin) = (
            g.iter().fold(0.0f64, |m, x| m.max(x.abs())),
            h.iter().fold(f64::MAX, |m, x| m.min(x.abs())),
        );
        assert!(gmax < 0.2 * hmin, "{gmax} {hmin}");
    }

    #[test]
    fn the_scalar_step_smooths_and_keeps_fixed_values() {
        let mesh = icosphere(2);
        let tris: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .copied()
            .filter(|t| !t.contains(&0))
            .collect();
        let topo = Topology::build(mesh.positions.len(), &tris).unwrap();
        let n = topo.len();
        let mut eps = vec![0.0; n];
        white_noise_into(&topo, 1, &mut eps, 0);
        let mut out = vec![0.0; n];
        scalar_step_into(&topo, &eps, &mut out, 0, 0.5);
        let energy = |x: &[f64]| x.iter().map(|y| y * y).sum::<f64>();
        assert!(energy(&out) < 0.7 * energy(&eps));
        for v in 0..n as u32 {
            if topo.is_fixed(v) {
                assert_eq!(eps[v as usize], 0.0);
                assert_eq!(out[v as usize], 0.0);
            }
        }
        // Split into ranges, the same bits.
        let mut split = vec![0.0; n];
        let (a, b) = split.split_at_mut(7);
        scalar_step_into(&topo, &eps, a, 0, 0.5);
        scalar_step_into(&topo, &eps, b, 7, 0.5);
        assert_eq!(split, out);
    }
}
