//! Umbrella Laplacian and its Jacobi (forward Euler) step, the kernel of `laplacian` and `taubin`.

use glam::DVec3;

use super::{Field, Topology, inv_deg, neighbor_sum};
use crate::topology::TopologyParts;

/// Umbrella Laplacian `L(v) = (1/deg v) Σ_{u∈N(v)} p_u − p_v`; zero for an isolated vertex.
#[inline]
pub fn umbrella(topo: &Topology, pos: &[DVec3], v: u32) -> DVec3 {
    let nbrs = topo.neighbors(v);
    if nbrs.is_empty() {
        return DVec3::ZERO;
    }
    neighbor_sum(topo, pos, v) * inv_deg(nbrs.len()) - pos[v as usize]
}

/// One Jacobi step `p' = p + λ L(p)` for the vertices `first .. first + dst.len()`, reading only `src`.
///
/// Fixed vertices are copied unchanged, but for crease line vertices
/// ([`Topology::line_neighbors`]), whose umbrella is that of their line: the mean of their two
/// crease neighbours. Each output depends only on `src`, so any split of the vertex
/// range over threads gives bit-identical results. Returns the number of vertices moved.
pub fn jacobi_step(
    topo: &Topology,
    src: &[DVec3],
    dst: &mut [DVec3],
    first: usize,
    lambda: f64,
) -> u64 {
    step::<NO_MEASURE, false>(topo, src, dst, first, lambda, (&[], 0.0)).moved
}

/// What a measured Jacobi step did over its vertex range.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepStats {
    /// Vertices moved (not fixed).
    pub moved: u64,
    /// Largest distance a vertex of the range moved.
    pub max_displacement: f64,
    /// Sum of the distances the vertices of the range moved (fixed ones count 0).
    pub sum_displacement: f64,
}

impl StepStats {
    /// Combine with the statistics of the following range (sums in range order, so a fixed split
    /// into ranges gives the same result for any number of threads).
    pub fn then(self, o: StepStats) -> StepStats {
        StepStats {
            moved: self.moved + o.moved,
            max_displacement: self.max_displacement.max(o.max_displacement),
            sum_displacement: self.sum_displacement + o.sum_displacement,
        }
    }
}

/// Where a measured step finds each vertex's previous position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Previous {
    /// In `src` (a step between two buffers: `p' = p + λ L(p)` moved `p` by `|p' − p|`).
    Src,
    /// In `dst`, about to be overwritten (the second step of a λ|μ pair that goes back into the
    /// buffer the pair started from: the pair moved the vertex by `|p'' − p|`).
    Dst,
}

/// [`jacobi_step`] that also measures how far each vertex moved from its previous position (see
/// [`Previous`]), in the same pass. The positions written are bit-identical to [`jacobi_step`]'s.
pub fn jacobi_step_measured(
    topo: &Topology,
    src: &[DVec3],
    dst: &mut [DVec3],
    first: usize,
    lambda: f64,
    previous: Previous,
) -> StepStats {
    match previous {
        Previous::Src => step::<FROM_SRC, false>(topo, src, dst, first, lambda, (&[], 0.0)),
        Previous::Dst => step::<FROM_DST, false>(topo, src, dst, first, lambda, (&[], 0.0)),
    }
}

/// [`jacobi_step_measured`] that then moves each new position back onto the ball of radius
/// `limit` around its `input` position (indexed like `src`) when it ends outside: the
/// `max_deviation` bound of `laplacian` and `taubin`. The volume is not kept (it never is by
/// these methods); the displacement is measured on the clamped positions.
#[allow(clippy::too_many_arguments)]
pub fn jacobi_step_clamped(
    topo: &Topology,
    src: &[DVec3],
    dst: &mut [DVec3],
    first: usize,
    lambda: f64,
    previous: Previous,
    input: &[DVec3],
    limit: f64,
) -> StepStats {
    assert!(input.len() >= first + dst.len());
    let bound = (input, limit);
    match previous {
        Previous::Src => step::<FROM_SRC, true>(topo, src, dst, first, lambda, bound),
        Previous::Dst => step::<FROM_DST, true>(topo, src, dst, first, lambda, bound),
    }
}

/// `p` moved back onto the ball of radius `limit` around `origin` when it lies outside: the
/// `max_deviation` bound of the Jacobi methods.
#[inline]
pub fn clamp_to_ball(p: DVec3, origin: DVec3, limit: f64) -> DVec3 {
    let off = p - origin;
    let length = off.length();
    if length > limit {
        origin + off * (limit / length)
    } else {
        p
    }
}

const NO_MEASURE: u8 = 0;
/// Measure against the vertex's position in `src`.
const FROM_SRC: u8 = 1;
/// Measure against the value of `dst` being overwritten.
const FROM_DST: u8 = 2;

/// The Jacobi kernel ([`step_of`]), compiled for AVX2 too and chosen at run time: the same
/// operations (Rust fuses no product and sum), so the same bits.
#[inline(always)]
fn step<const MEASURE: u8, const CLAMP: bool>(
    topo: &Topology,
    src: &[DVec3],
    dst: &mut [DVec3],
    first: usize,
    lambda: f64,
    bound: (&[DVec3], f64),
) -> StepStats {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (just checked).
        return unsafe { step_avx2::<MEASURE, CLAMP>(topo, src, dst, first, lambda, bound) };
    }
    step_of::<MEASURE, CLAMP>(topo, src, dst, first, lambda, bound)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn step_avx2<const MEASURE: u8, const CLAMP: bool>(
    topo: &Topology,
    src: &[DVec3],
    dst: &mut [DVec3],
    first: usize,
    lambda: f64,
    bound: (&[DVec3], f64),
) -> StepStats {
    step_of::<MEASURE, CLAMP>(topo, src, dst, first, lambda, bound)
}

/// The sum of the positions (`get`) of `nbrs`, from zero, in their order. Degrees 5 to 7 (most
/// vertices of a surface) are unrolled (a row of a known length): no loop branch, the same
/// additions in the same order.
#[inline(always)]
fn neighbour_sum(get: impl Fn(u32) -> DVec3, nbrs: &[u32]) -> DVec3 {
    #[inline(always)]
    fn sum<'a>(get: impl Fn(u32) -> DVec3, row: impl IntoIterator<Item = &'a u32>) -> DVec3 {
        let mut sum = DVec3::ZERO;
        for &u in row {
            sum += get(u);
        }
        sum
    }
    match nbrs.len() {
        5 => sum(get, <&[u32; 5]>::try_from(nbrs).unwrap_or(&[0; 5])),
        6 => sum(get, <&[u32; 6]>::try_from(nbrs).unwrap_or(&[0; 6])),
        7 => sum(get, <&[u32; 7]>::try_from(nbrs).unwrap_or(&[0; 7])),
        _ => sum(get, nbrs),
    }
}

/// One Jacobi step `p + λ L(p)` at vertex `v`, at `p` in the step's source (read through `get`),
/// `free` when it is not fixed, `nbrs` its neighbours: `None` for a fixed vertex that stays. A
/// crease line vertex steps along its line: the umbrella of its two crease neighbours (a lookup
/// only fixed vertices make).
#[inline(always)]
fn stepped(
    topo: &TopologyParts,
    get: impl Fn(u32) -> DVec3,
    v: u32,
    p: DVec3,
    free: bool,
    nbrs: &[u32],
    lambda: f64,
) -> Option<DVec3> {
    if free {
        let sum = neighbour_sum(&get, nbrs);
        Some(p + lambda * (sum * inv_deg(nbrs.len()) - p))
    } else {
        topo.line_neighbors(v)
            .map(|[a, b]| p + lambda * ((get(a) + get(b)) * 0.5 - p))
    }
}

/// Vertex `v` after one Jacobi step from `src`: the bits [`jacobi_step`] writes for it.
#[inline(always)]
pub fn jacobi_at<F: Field + ?Sized>(topo: &TopologyParts, src: &F, v: u32, lambda: f64) -> DVec3 {
    let p = src.get(v);
    let free = topo.fixed[v as usize] == 0;
    stepped(topo, |u| src.get(u), v, p, free, topo.neighbors(v), lambda).unwrap_or(p)
}

/// The Jacobi kernel. The CSR arrays are walked directly (one offset load per vertex, the
/// neighbour slice cut from a running position) and neighbour positions are gathered without a
/// bounds check per neighbour: this loop is the time of `laplacian` and `taubin` when they run
/// plain steps (out of core, and in the cluster engine), and of `vcs-lowpass`'s λ|μ pair.
#[inline(always)]
fn step_of<const MEASURE: u8, const CLAMP: bool>(
    topo: &Topology,
    src: &[DVec3],
    dst: &mut [DVec3],
    first: usize,
    lambda: f64,
    (input, limit): (&[DVec3], f64),
) -> StepStats {
    let n = dst.len();
    let parts = topo.parts();
    let (offsets, vv) = (parts.vv_offsets, parts.vv);
    // The unchecked gather below relies on this: every id in `vv` is below `topo.len()` (the
    // topology's invariant, checked when it is built), so it is below `src.len()`.
    assert!(src.len() >= topo.len());
    // SAFETY: `u < topo.len() <= src.len()` (asserted above) for every neighbour and crease
    // neighbour `u` of the topology.
    let get = |u: u32| unsafe { *src.get_unchecked(u as usize) };
    // The mask, offsets and old positions of the range as slices: one bounds check for the range
    // instead of one per vertex.
    let fixed = &topo.fixed_mask()[first..first + n];
    let own = &src[first..first + n];
    let offsets = &offsets[first..first + n + 1];
    let mut st = StepStats::default();
    for k in 0..n {
        let p = own[k];
        let nbrs = &vv[offsets[k]..offsets[k + 1]];
        let v = (first + k) as u32;
        let new = match stepped(&parts, get, v, p, fixed[k] == 0, nbrs, lambda) {
            Some(new) => {
                st.moved += 1;
                if CLAMP {
                    clamp_to_ball(new, input[first + k], limit)
                } else {
                    new
                }
            }
            None => p,
        };
        if MEASURE != NO_MEASURE {
            let before = if MEASURE == FROM_SRC { p } else { dst[k] };
            let d = new.distance(before);
            st.max_displacement = st.max_displacement.max(d);
            st.sum_displacement += d;
        }
        dst[k] = new;
    }
    st
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

    /// The step of one vertex, as the default method's blocks take it, is the whole step's, bit
    /// for bit: at free vertices of every degree and at the fixed ones of an open border.
    #[test]
    fn jacobi_at_is_the_step_of_each_vertex() {
        let (pos, tris) = crate::shapes::open_sorted_sphere(4, 5);
        let topo = Topology::build(pos.len(), &tris).unwrap();
        assert!((0..topo.len() as u32).any(|v| topo.is_fixed(v)));
        let parts = topo.parts();
        for lambda in [0.5, -0.52] {
            let mut out = vec![DVec3::ZERO; pos.len()];
            jacobi_step(&topo, &pos, &mut out, 0, lambda);
            assert!(out != pos);
            for (v, &want) in out.iter().enumerate() {
                assert_eq!(
                    jacobi_at(&parts, &pos[..], v as u32, lambda),
                    want,
                    "vertex {v}"
                );
            }
        }
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
