//! Measurements of a mesh: volume, area and the per-run statistics that reports and tests use.
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
    let c = origin;
    triangles
        .iter()
        .map(|t| {
            let [a, b, d] = t.map(|v| pos[v as usize] - c);
            a.dot(b.cross(d))
        })
        .sum::<f64>()
        / 6.0
}

/// Total surface area.
pub fn area(pos: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    triangles
        .iter()
        .map(|t| {
            let [a, b, d] = t.map(|v| pos[v as usize]);
            (b - a).cross(d - a).length()
        })
        .sum::<f64>()
        / 2.0
}

/// Mean of the positions (zero for none).
pub fn centroid(pos: &[DVec3]) -> DVec3 {
    if pos.is_empty() {
        return DVec3::ZERO;
    }
    pos.iter().fold(DVec3::ZERO, |s, p| s + *p) / pos.len() as f64
}

mod compare;
mod info;
pub use compare::{Comparison, compare};
pub use info::{MeshInfo, info, info_of, mean_edge_length, roughness};
