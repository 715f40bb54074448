//! `hc`: the HC Laplacian of Vollmer, Mencl and Müller (1999), "Improved Laplacian smoothing of
//! noisy surface meshes". Each iteration is an umbrella average followed by a push back towards
//! where the vertex was and where it started, which cancels most of the Laplacian's shrinking
//! without a volume constraint.
//!
//! With `o` the input positions, `q` the positions at the iteration's start and `p_v` the average
//! of `q` over the neighbours of `v`:
//!
//! ```text
//! b_v  = p_v − (α o_v + (1 − α) q_v)                  pass 0, into the auxiliary field
//! q'_v = p_v − (β b_v + (1 − β) avg_{u∈N(v)} b_u)     pass 1, into the new positions
//! ```
//!
//! α weighs the pull towards the input (0: none), β the share of the vertex's own difference in
//! its push back. Both passes are Jacobi, so any split of the vertices gives the same bits. A fixed
//! vertex, or one without neighbours, does not move and has `b = 0` (its `p` is its `q`, which is
//! its `o`), so it pushes none of its neighbours.

use glam::DVec3;

use super::laplacian::{StepStats, clamp_to_ball};
use super::method::{Control, Needs, PassFields, Schedule, Settle, Smoother, StopRule};
use super::{Options, Topology, inv_deg, neighbor_sum};

/// α, the weight of the input position in `b`: the value the paper's figures and trimesh's
/// `filter_humphrey` use.
pub const ALPHA: f64 = 0.1;
/// β, the weight of a vertex's own `b` against its neighbours' average, as above.
pub const BETA: f64 = 0.5;

/// The average of `field` over the neighbours of `v`, or `None` for a vertex without any.
#[inline]
fn average(topo: &Topology, field: &[DVec3], v: u32) -> Option<DVec3> {
    let nbrs = topo.neighbors(v);
    if nbrs.is_empty() {
        return None;
    }
    Some(neighbor_sum(topo, field, v) * inv_deg(nbrs.len()))
}

/// Pass 0 for the vertices `first .. first + out.len()`: `b` from the positions `pos` and the
/// input `input` (indexed like `pos`).
pub fn differences(
    topo: &Topology,
    pos: &[DVec3],
    input: &[DVec3],
    out: &mut [DVec3],
    first: usize,
) {
    let fixed = &topo.fixed_mask()[first..first + out.len()];
    for (k, b) in out.iter_mut().enumerate() {
        let v = first + k;
        *b = match average(topo, pos, v as u32) {
            Some(p) if fixed[k] == 0 => p - (ALPHA * input[v] + (1.0 - ALPHA) * pos[v]),
            _ => DVec3::ZERO,
        };
    }
}

/// Pass 1 for the vertices `first .. first + out.len()`: the new positions from `pos` and the
/// differences `b` of pass 0 (`p_v` is averaged again, with the same bits, rather than kept from
/// pass 0 in a third vector per vertex); with `limit`, each ends within that distance of its `input`
/// position. Returns how far the vertices moved from `pos`.
pub fn corrected(
    topo: &Topology,
    pos: &[DVec3],
    b: &[DVec3],
    (input, limit): (&[DVec3], Option<f64>),
    out: &mut [DVec3],
    first: usize,
) -> StepStats {
    let fixed = &topo.fixed_mask()[first..first + out.len()];
    let mut st = StepStats::default();
    for (k, new) in out.iter_mut().enumerate() {
        let v = first + k;
        let q = pos[v];
        let p = match average(topo, pos, v as u32) {
            Some(p) if fixed[k] == 0 => p,
            _ => {
                *new = q;
                continue;
            }
        };
        st.moved += 1;
        let spread = average(topo, b, v as u32).unwrap_or(DVec3::ZERO);
        let mut next = p - (BETA * b[v] + (1.0 - BETA) * spread);
        if let Some(limit) = limit {
            next = clamp_to_ball(next, input[v], limit);
        }
        let d = next.distance(q);
        st.max_displacement = st.max_displacement.max(d);
        st.sum_displacement += d;
        *new = next;
    }
    st
}

/// The `hc` method (see the module doc).
pub struct Hc;

impl Smoother for Hc {
    fn name(&self) -> &'static str {
        "hc"
    }
    fn help(&self) -> &'static str {
        "HC Laplacian: an average pushed back towards the input (Vollmer et al. 1999; shrinks little)"
    }
    fn schedule(&self, _: &Options) -> Schedule {
        Schedule::TwoPass
    }
    fn keeps_volume(&self) -> bool {
        false
    }
    fn needs(&self) -> Needs {
        Needs {
            input: true,
            aux: true,
            ..Needs::default()
        }
    }
    fn stop_rule(&self, _: &Options) -> StopRule {
        StopRule::Settle(Settle::SLOW)
    }
    fn accepts(&self, _: Control) -> bool {
        false
    }
    fn pass(
        &self,
        k: usize,
        topo: &Topology,
        _: &Options,
        fields: PassFields,
        first: usize,
        out: &mut [DVec3],
    ) -> StepStats {
        match k {
            0 => {
                differences(topo, fields.pos, fields.input, out, first);
                StepStats::default()
            }
            _ => corrected(
                topo,
                fields.pos,
                fields.aux,
                (fields.input, fields.limit),
                out,
                first,
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::icosphere;
    use crate::smooth::laplacian::jacobi_step;

    fn iterate(topo: &Topology, input: &[DVec3], times: usize) -> Vec<DVec3> {
        let mut pos = input.to_vec();
        let mut b = vec![DVec3::ZERO; pos.len()];
        let mut next = pos.clone();
        for _ in 0..times {
            differences(topo, &pos, input, &mut b, 0);
            corrected(topo, &pos, &b, (input, None), &mut next, 0);
            std::mem::swap(&mut pos, &mut next);
        }
        pos
    }

    /// A bumpy sphere: every vertex pushed in or out along its radius by a fixed pattern.
    fn bumpy() -> (Topology, Vec<DVec3>) {
        let mesh = icosphere(3);
        let topo = Topology::build(mesh.positions.len(), &mesh.triangles).unwrap();
        let pos = mesh
            .positions
            .iter()
            .enumerate()
            .map(|(i, p)| *p * (1.0 + 0.05 * ((i * 7919 % 13) as f64 / 6.0 - 1.0)))
            .collect();
        (topo, pos)
    }

    fn mean_radius(pos: &[DVec3]) -> f64 {
        pos.iter().map(|p| p.length()).sum::<f64>() / pos.len() as f64
    }

    #[test]
    fn a_mesh_at_rest_on_its_input_does_not_move() {
        let tris: Vec<[u32; 3]> = (1..=6).map(|k| [0, k, k % 6 + 1]).collect();
        let topo = Topology::build(7, &tris).unwrap();
        let pos = vec![DVec3::new(1.5, -2.0, 3.25); 7];
        assert_eq!(iterate(&topo, &pos, 3), pos);
    }

    #[test]
    fn it_smooths_the_bumps_and_shrinks_far_less_than_the_laplacian() {
        let (topo, input) = bumpy();
        let roughness = |pos: &[DVec3]| {
            (0..pos.len() as u32)
                .map(|v| crate::smooth::laplacian::umbrella(&topo, pos, v).length())
                .sum::<f64>()
        };
        let hc = iterate(&topo, &input, 10);
        let mut lap = input.clone();
        let mut next = input.clone();
        for _ in 0..10 {
            jacobi_step(&topo, &lap, &mut next, 0, 1.0);
            std::mem::swap(&mut lap, &mut next);
        }
        assert!(roughness(&hc) < 0.5 * roughness(&input));
        let r0 = mean_radius(&input);
        let (shrink_hc, shrink_lap) = (r0 - mean_radius(&hc), r0 - mean_radius(&lap));
        assert!(shrink_lap > 0.0);
        assert!(
            shrink_hc.abs() < 0.25 * shrink_lap,
            "{shrink_hc} vs {shrink_lap}"
        );
    }

    #[test]
    fn any_split_of_the_vertices_gives_the_same_bits() {
        let (topo, input) = bumpy();
        let whole = iterate(&topo, &input, 2);
        let n = input.len();
        let (mut pos, mut b, mut next) = (input.clone(), vec![DVec3::ZERO; n], input.clone());
        for _ in 0..2 {
            for (at, chunk) in b.chunks_mut(37).enumerate() {
                differences(&topo, &pos, &input, chunk, at * 37);
            }
            for (at, chunk) in next.chunks_mut(53).enumerate() {
                corrected(&topo, &pos, &b, (&input, None), chunk, at * 53);
            }
            std::mem::swap(&mut pos, &mut next);
        }
        assert_eq!(pos, whole);
    }

    #[test]
    fn the_deviation_bound_holds() {
        let (topo, input) = bumpy();
        let n = input.len();
        let (mut pos, mut b, mut next) = (input.clone(), vec![DVec3::ZERO; n], input.clone());
        for _ in 0..20 {
            differences(&topo, &pos, &input, &mut b, 0);
            corrected(&topo, &pos, &b, (&input, Some(1e-3)), &mut next, 0);
            std::mem::swap(&mut pos, &mut next);
        }
        let worst = pos
            .iter()
            .zip(&input)
            .map(|(p, o)| p.distance(*o))
            .fold(0.0, f64::max);
        assert!(worst <= 1e-3 * (1.0 + 1e-12), "{worst}");
        assert!(worst > 0.5e-3);
    }
}
