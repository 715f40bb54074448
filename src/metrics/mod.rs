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

/// [`determinant_sum`] and [`doubled_area_sum`] in one pass over the triangles, each summed in
/// order (the same bits as the two folds): what every iteration's record measures.
pub fn determinant_and_area_sums(
    pos: &[DVec3],
    triangles: &[[u32; 3]],
    origin: DVec3,
) -> (f64, f64) {
    determinant_and_area_by(triangles, |v| pos[v as usize], origin)
}

/// [`determinant_and_area_sums`] with each corner's position from `corner`: for positions held
/// elsewhere than in one array by vertex id (a tile's local copy, [`crate::smooth::tiled`]).
#[inline(always)]
pub(crate) fn determinant_and_area_by(
    triangles: &[[u32; 3]],
    corner: impl Fn(u32) -> DVec3,
    origin: DVec3,
) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (just checked).
        return unsafe { determinant_and_area_avx2(triangles, corner, origin) };
    }
    determinant_and_area_batches(triangles, corner, origin)
}

/// [`determinant_and_area_by`] compiled for AVX2: four triangles' arithmetic to an instruction.
/// The same operations, so the same bits (Rust does not fuse a product and a sum).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn determinant_and_area_avx2(
    triangles: &[[u32; 3]],
    corner: impl Fn(u32) -> DVec3,
    origin: DVec3,
) -> (f64, f64) {
    determinant_and_area_batches(triangles, corner, origin)
}

/// Triangles whose terms [`determinant_and_area_batches`] computes at once.
const TERM_BATCH: usize = 32;

/// The sums of [`determinant_and_area_sums`]: the corners of a batch of triangles gathered
/// coordinate by coordinate, their terms computed for the whole batch (in vector lanes), then
/// added in order. Each term is [`determinant`]'s and [`doubled_area`]'s, operation for operation.
#[inline(always)]
fn determinant_and_area_batches(
    triangles: &[[u32; 3]],
    corner: impl Fn(u32) -> DVec3,
    o: DVec3,
) -> (f64, f64) {
    let (mut volume, mut area) = (-0.0, -0.0);
    // x, y, z of the first, second and third corners, and the terms: set once (a short last
    // batch leaves stale lanes, computed and not added).
    let mut at = [[0.0f64; TERM_BATCH]; 9];
    let mut dets = [0.0f64; TERM_BATCH];
    let mut areas = [0.0f64; TERM_BATCH];
    for batch in triangles.chunks(TERM_BATCH) {
        for (k, t) in batch.iter().enumerate() {
            // Below the batch length already: said so, the stores need no check.
            let k = k % TERM_BATCH;
            let [a, b, c] = t.map(&corner);
            for (row, x) in at
                .iter_mut()
                .zip([a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z])
            {
                row[k] = x;
            }
        }
        let [ax, ay, az, bx, by, bz, cx, cy, cz] = &at;
        for k in 0..TERM_BATCH {
            // determinant(a − o, b − o, c − o) = (a − o) · ((b − o) × (c − o)).
            let (ax_, ay_, az_) = (ax[k] - o.x, ay[k] - o.y, az[k] - o.z);
            let (bx_, by_, bz_) = (bx[k] - o.x, by[k] - o.y, bz[k] - o.z);
            let (cx_, cy_, cz_) = (cx[k] - o.x, cy[k] - o.y, cz[k] - o.z);
            let (x, y, z) = (
                by_ * cz_ - cy_ * bz_,
                bz_ * cx_ - cz_ * bx_,
                bx_ * cy_ - cx_ * by_,
            );
            dets[k] = ax_ * x + ay_ * y + az_ * z;
            // doubled_area(a, b, c) = |(b − a) × (c − a)|.
            let (ux, uy, uz) = (bx[k] - ax[k], by[k] - ay[k], bz[k] - az[k]);
            let (wx, wy, wz) = (cx[k] - ax[k], cy[k] - ay[k], cz[k] - az[k]);
            let (nx, ny, nz) = (uy * wz - wy * uz, uz * wx - wz * ux, ux * wy - wx * uy);
            areas[k] = (nx * nx + ny * ny + nz * nz).sqrt();
        }
        for (d, a) in dets.iter().zip(&areas).take(batch.len()) {
            volume += d;
            area += a;
        }
    }
    (volume, area)
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
    AsF32, EdgeSums, Geometry, MeshInfo, Positions, VertexSums, components, components_joining,
    connectivity, extent, extent_union, geometry, info, info_of, mean_edge_length, roughness,
    vertex_sums,
};

#[cfg(test)]
mod tests {
    use super::*;

    /// The batched sums against the plain folds of [`determinant`] and [`doubled_area`], bit for
    /// bit, at every batch boundary and on NaN, infinite and zero-area triangles.
    #[test]
    fn determinant_and_area_sums_are_the_plain_folds() {
        let mut next = crate::shapes::uniform(5);
        let mut pos: Vec<DVec3> = (0..200)
            .map(|_| DVec3::new(next() * 3.0 - 1.0, next() * 1e3, next() - 0.5))
            .collect();
        // Only the last triangles reach these: the sums before them stay finite.
        pos.push(DVec3::new(f64::INFINITY, 0.0, 1.0));
        pos.push(DVec3::new(f64::NAN, 0.0, 1.0));
        let tris: Vec<[u32; 3]> = (0..300u32)
            .map(|k| [k % 200, (k * 7 + 1) % 200, (k * 13 + 5) % 200])
            .chain([[1, 1, 2], [3, 4, 200], [5, 201, 6]])
            .collect();
        let origin = DVec3::new(0.25, 400.0, -0.125);
        for len in [0, 1, 31, 32, 33, 64, 65, 300, 301, 302, 303] {
            let t = &tris[..len];
            let plain = t.iter().fold((-0.0f64, -0.0f64), |(v, s), t| {
                let [a, b, c] = t.map(|v| pos[v as usize]);
                (
                    v + determinant(a - origin, b - origin, c - origin),
                    s + doubled_area(a, b, c),
                )
            });
            let got = determinant_and_area_sums(&pos, t, origin);
            assert_eq!(got.0.is_finite(), len <= 301, "{len} triangles");
            let bits = |(v, s): (f64, f64)| (v.to_bits(), s.to_bits());
            assert_eq!(bits(got), bits(plain), "{len} triangles");
            let lanes = determinant_and_area_batches(t, |v| pos[v as usize], origin);
            assert_eq!(bits(lanes), bits(plain), "{len} triangles, without AVX2");
        }
    }
}
