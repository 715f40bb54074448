//! Umbrella Laplacian and its Jacobi (forward Euler) step, the kernel of `laplacian` and `taubin`.

use glam::DVec3;

use super::{Topology, inv_deg};

/// Umbrella Laplacian `L(v) = (1/deg v) Σ_{u∈N(v)} p_u − p_v`; zero for an isolated vertex.
#[inline]
pub fn umbrella(topo: &Topology, pos: &[DVec3], v: u32) -> DVec3 {
    let nbrs = topo.neighbors(v);
    if nbrs.is_empty() {
        return DVec3::ZERO;
    }
    let sum = nbrs.iter().fold(DVec3::ZERO, |s, &u| s + pos[u as usize]);
    sum * inv_deg(nbrs.len()) - pos[v as usize]
}

/// One Jacobi step `p' = p + λ L(p)` for the vertices `first .. first + dst.len()`, reading only `src`.
///
/// Fixed vertices are copied unchanged. Each output depends only on `src`, so any split of the vertex
/// range over threads gives bit-identical results. Returns the number of vertices moved.
pub fn jacobi_step(
    topo: &Topology,
    src: &[DVec3],
    dst: &mut [DVec3],
    first: usize,
    lambda: f64,
) -> u64 {
    // The mask and the old positions of the range as slices: one bounds check for the range
    // instead of one per vertex.
    let fixed = &topo.fixed_mask()[first..first + dst.len()];
    let own = &src[first..first + dst.len()];
    let mut moved = 0;
    for (k, ((out, &fix), &p)) in dst.iter_mut().zip(fixed).zip(own).enumerate() {
        *out = if fix != 0 {
            p
        } else {
            moved += 1;
            let nbrs = topo.neighbors((first + k) as u32);
            let sum = nbrs.iter().fold(DVec3::ZERO, |s, &u| s + src[u as usize]);
            p + lambda * (sum * inv_deg(nbrs.len()) - p)
        };
    }
    moved
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laplacian_of_constant_field_is_zero_and_step_is_identity() {
        let tris: Vec<[u32; 3]> = (1..=6).map(|k| [0, k, k % 6 + 1]).collect();
        let topo = Topology::build(7, &tris).unwrap();
        let pos = vec![DVec3::new(1.5, -2.0, 3.25); 7];
        for v in 0..7 {
            assert_eq!(umbrella(&topo, &pos, v), DVec3::ZERO);
        }
        let mut out = vec![DVec3::ZERO; 7];
        jacobi_step(&topo, &pos, &mut out, 0, 0.5);
        assert_eq!(out, pos);
    }

    #[test]
    fn step_moves_centre_towards_rim_average_and_keeps_rim() {
        let tris: Vec<[u32; 3]> = (1..=4).map(|k| [0, k, k % 4 + 1]).collect();
        let topo = Topology::build(5, &tris).unwrap();
        let mut pos = vec![
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::X,
            DVec3::Y,
            DVec3::NEG_X,
            DVec3::NEG_Y,
        ];
        let mut out = vec![DVec3::ZERO; 5];
        assert_eq!(jacobi_step(&topo, &pos, &mut out, 0, 0.5), 1);
        assert_eq!(out[0], DVec3::new(0.0, 0.0, 0.5));
        pos[0] = out[0];
        assert_eq!(out, pos);
    }
}
