//! Measurements of a mesh: volume, area and the per-run statistics that reports and tests use;
//! how far one mesh deviates from another ([`deviation`], with [`surface`] for meshes that do
//! not share vertices).
//!
//! Orientation convention: outward-facing triangles (counter-clockwise seen from outside) give a
//! positive volume; an inward-oriented closed mesh has a negative one.

use glam::DVec3;

/// Signed volume `(1/6) Σ det(p_a, p_b, p_c)` by the divergence theorem, summed in f64 relative to
/// the centroid of the positions (which keeps the determinants well conditioned far from the origin).
///
/// For an open mesh the result depends on the reference point: use [`volume_about`] with one fixed
/// point to follow the volume of an open mesh through a run.
pub fn volume(pos: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    volume_about(pos, triangles, centroid(pos))
}

/// Signed volume of the cone from `origin` over the triangles (for a closed mesh, its volume).
pub fn volume_about(pos: &[DVec3], triangles: &[[u32; 3]], origin: DVec3) -> f64 {
    determinant_sum(pos, triangles, origin) / 6.0
}

/// Total surface area.
pub fn area(pos: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    doubled_area_sum(pos, triangles) / 2.0
}

/// `x` as a percentage of `reference`; NaN (undefined: `null` in JSON, `undefined` in tables)
/// for NaN, and for a reference of 0 or not finite (the volume of a flat or open sheet), which
/// no ratio is against.
pub fn percent(x: f64, reference: f64) -> f64 {
    if x.is_nan() || reference == 0.0 || !reference.is_finite() {
        f64::NAN
    } else {
        100.0 * x / reference
    }
}

/// Mean of the positions (zero for none).
pub fn centroid(pos: &[DVec3]) -> DVec3 {
    if pos.is_empty() {
        return DVec3::ZERO;
    }
    position_sum(pos) / pos.len() as f64
}

/// Six times the signed volume of the tetrahedron `(o, a, b, c)`, given `a − o, b − o, c − o`.
#[inline(always)]
pub fn determinant(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    a.dot(b.cross(c))
}

/// Twice the area of the triangle `(a, b, c)`.
#[inline(always)]
pub fn doubled_area(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    (b - a).cross(c - a).length()
}

/// `Σ det(p_a − o, p_b − o, p_c − o)` over the triangles, in order: six times their signed volume
/// about `o` ([`crate::engine::reduce`] adds these sums up over chunks in parallel).
pub fn determinant_sum(pos: &[DVec3], triangles: &[[u32; 3]], origin: DVec3) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| pos[v as usize] - origin);
            determinant(a, b, c)
        })
        .sum::<f64>()
}

/// `Σ |(p_b − p_a) × (p_c − p_a)|` over the triangles, in order: twice their area.
pub fn doubled_area_sum(pos: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| pos[v as usize]);
            doubled_area(a, b, c)
        })
        .sum::<f64>()
}

/// [`determinant_sum`] and [`doubled_area_sum`] in one pass over the triangles.
pub fn determinant_and_area_sums(
    pos: &[DVec3],
    triangles: &[[u32; 3]],
    origin: DVec3,
) -> (f64, f64) {
    triangles.iter().fold((-0.0, -0.0), |(v, s), t| {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        (
            v + determinant(a - origin, b - origin, c - origin),
            s + doubled_area(a, b, c),
        )
    })
}

/// Sum of the positions, in order.
pub fn position_sum(pos: &[DVec3]) -> DVec3 {
    pos.iter().fold(DVec3::ZERO, |s, p| s + *p)
}

mod compare;
pub mod deviation;
mod info;
pub mod surface;
pub use compare::{Comparison, compare, compare_surfaces, displacement_lengths, same_connectivity};
pub use deviation::{DeviationStats, signed_deviations};
pub use info::{
    EdgeSums, Geometry, MeshInfo, VertexSums, connectivity, extent, extent_union, geometry, info,
    info_of, mean_edge_length, roughness, vertex_sums,
};
