//! `vcsmooth compare`: how far a mesh moved from another with the same connectivity.

use glam::DVec3;

use super::info::{angle_deg, bounding_box};
use crate::error::{Error, Result};
use crate::mesh::Mesh;

/// Differences between two meshes with the same connectivity (`vcsmooth compare`).
///
/// Every number is finite and none is −0 (the struct goes to JSON as is). A quantity that is not
/// defined for the meshes given (a ratio whose denominator is 0, a mean over nothing) is `None`,
/// `null` in JSON: never a made-up 0 or 1.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Comparison {
    /// Root mean square and largest distance between corresponding vertices (0 for no vertices:
    /// nothing moved).
    pub rms_distance: f64,
    pub max_distance: f64,
    /// The same, relative to the bounding-box diagonal of `a`; `None` when that diagonal is 0.
    pub rms_relative: Option<f64>,
    pub max_relative: Option<f64>,
    /// Mean angle between corresponding face normals, degrees, over the triangles that have a
    /// normal (non-zero area) in both meshes; `None` when none has.
    pub mean_normal_angle_deg: Option<f64>,
    /// volume(b) / volume(a), area(b) / area(a); `None` when the denominator is 0 (or the quotient
    /// is not finite).
    pub volume_ratio: Option<f64>,
    pub area_ratio: Option<f64>,
    /// The bounding-box diagonal of `a` that the relative distances divide by.
    pub bbox_diagonal: f64,
    /// Signed volumes of `a` and `b`, both about `a`'s centroid ([`crate::metrics::volume_about`]),
    /// and their areas ([`crate::metrics::area`]).
    pub volume_a: f64,
    pub volume_b: f64,
    pub area_a: f64,
    pub area_b: f64,
}

/// Compare `b` against `a`; an error if their vertex counts or triangles differ.
///
/// The error is [`Error::Topology`] naming the first difference (the caller adds the file names).
pub fn compare(a: &Mesh, b: &Mesh) -> Result<Comparison> {
    same_connectivity(a, b)?;
    compare_same(a, b)
}

/// Whether `b` has `a`'s vertex count and triangles, their indices in range: `Ok`, or
/// [`Error::Topology`] naming the first difference (the caller adds the file names).
pub fn same_connectivity(a: &Mesh, b: &Mesh) -> Result<()> {
    let (na, nb) = (a.positions.len(), b.positions.len());
    if na != nb {
        return Err(Error::topology(format!(
            "the meshes differ in connectivity: {na} vertices against {nb}"
        )));
    }
    let (ta, tb) = (&a.triangles, &b.triangles);
    if ta.len() != tb.len() {
        return Err(Error::topology(format!(
            "the meshes differ in connectivity: {} triangles against {}",
            ta.len(),
            tb.len()
        )));
    }
    if let Some(k) = ta.iter().zip(tb).position(|(x, y)| x != y) {
        return Err(Error::topology(format!(
            "the meshes differ in connectivity: triangle {k} is {:?} against {:?}",
            ta[k], tb[k]
        )));
    }
    if let Some(k) = ta.iter().position(|t| t.iter().any(|&v| v as usize >= na)) {
        return Err(Error::topology(format!(
            "triangle {k} indexes a vertex out of range (0..{na})"
        )));
    }
    Ok(())
}

/// [`compare`] of meshes that [`same_connectivity`] accepted.
fn compare_same(a: &Mesh, b: &Mesh) -> Result<Comparison> {
    let na = a.positions.len();
    let ta = &a.triangles;
    let (mut sum_sq, mut max) = (0.0f64, 0.0f64);
    for (p, q) in a.positions.iter().zip(&b.positions) {
        let d = p.distance(*q);
        sum_sq += d * d;
        max = max.max(d);
    }
    let rms = if na == 0 {
        0.0
    } else {
        (sum_sq / na as f64).sqrt()
    };
    let (lo, hi) = bounding_box(&a.positions);
    let diagonal = (hi - lo).length();
    let relative = |d: f64| ratio(d, diagonal);

    let normal = |pos: &[DVec3], t: &[u32; 3]| {
        let [p, q, r] = t.map(|v| pos[v as usize]);
        let n = (q - p).cross(r - p);
        (n.length_squared() > 0.0 && n.is_finite()).then_some(n)
    };
    let (mut angle_sum, mut faces) = (0.0, 0usize);
    for t in ta {
        if let (Some(n1), Some(n2)) = (normal(&a.positions, t), normal(&b.positions, t)) {
            angle_sum += angle_deg(n1, n2);
            faces += 1;
        }
    }

    // Both about A's centroid: an open mesh's volume depends on the point.
    let origin = super::centroid(&a.positions);
    let (volume_a, volume_b) = (
        super::volume_about(&a.positions, ta, origin),
        super::volume_about(&b.positions, ta, origin),
    );
    let (area_a, area_b) = (super::area(&a.positions, ta), super::area(&b.positions, ta));
    Ok(Comparison {
        rms_distance: rms,
        max_distance: max,
        rms_relative: relative(rms),
        max_relative: relative(max),
        mean_normal_angle_deg: ratio(angle_sum, faces as f64),
        volume_ratio: ratio(volume_b, volume_a),
        area_ratio: ratio(area_b, area_a),
        bbox_diagonal: diagonal,
        // `+ 0.0` turns the −0 of an empty sum into 0.
        volume_a: volume_a + 0.0,
        volume_b: volume_b + 0.0,
        area_a: area_a + 0.0,
        area_b: area_b + 0.0,
    })
}

/// [`compare`] of meshes that need not share vertices, given the distances of `a`'s vertices to
/// `b`'s surface (their RMS and largest, from [`super::deviation`]): the distances are those, the
/// volumes and areas each mesh's own (both volumes about `a`'s centroid), the normal angle
/// undefined (`None`: no faces correspond).
pub fn compare_surfaces(a: &Mesh, b: &Mesh, rms: f64, max: f64) -> Comparison {
    let (lo, hi) = bounding_box(&a.positions);
    let diagonal = (hi - lo).length();
    let origin = super::centroid(&a.positions);
    let (volume_a, volume_b) = (
        super::volume_about(&a.positions, &a.triangles, origin),
        super::volume_about(&b.positions, &b.triangles, origin),
    );
    let (area_a, area_b) = (
        super::area(&a.positions, &a.triangles),
        super::area(&b.positions, &b.triangles),
    );
    Comparison {
        rms_distance: rms + 0.0,
        max_distance: max + 0.0,
        rms_relative: ratio(rms, diagonal),
        max_relative: ratio(max, diagonal),
        mean_normal_angle_deg: None,
        volume_ratio: ratio(volume_b, volume_a),
        area_ratio: ratio(area_b, area_a),
        bbox_diagonal: diagonal,
        volume_a: volume_a + 0.0,
        volume_b: volume_b + 0.0,
        area_a: area_a + 0.0,
        area_b: area_b + 0.0,
    }
}

/// The distance each vertex moved from `a` to `b` (the same vertices, in the same order), into
/// `out`: the value the pictures of a run or a comparison colour each vertex by. A field of signed
/// deviations along the input's normals may take its place.
pub fn displacement_lengths(a: &[DVec3], b: &[DVec3], out: &mut [f32]) {
    for ((p, q), d) in a.iter().zip(b).zip(out) {
        *d = p.distance(*q) as f32;
    }
}

/// `num / den` when it is a finite number (`None` for a zero denominator), never −0.
fn ratio(num: f64, den: f64) -> Option<f64> {
    let r = num / den;
    (den != 0.0 && r.is_finite()).then_some(r + 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{add_normal_noise, icosphere, torus};

    #[test]
    fn a_mesh_against_itself() {
        let a = torus(1);
        let c = compare(&a, &a).unwrap();
        assert_eq!((c.rms_distance, c.max_distance), (0.0, 0.0));
        assert_eq!((c.rms_relative, c.max_relative), (Some(0.0), Some(0.0)));
        assert_eq!(c.mean_normal_angle_deg, Some(0.0));
        assert_eq!((c.volume_ratio, c.area_ratio), (Some(1.0), Some(1.0)));
    }

    #[test]
    fn translated_copy() {
        let a = icosphere(2);
        let shift = DVec3::new(0.3, -0.4, 1.2); // length 1.3
        let mut b = a.clone();
        b.positions.iter_mut().for_each(|p| *p += shift);
        let c = compare(&a, &b).unwrap();
        assert!((c.rms_distance - 1.3).abs() < 1e-12, "{}", c.rms_distance);
        assert!((c.max_distance - 1.3).abs() < 1e-12);
        assert!((c.rms_relative.unwrap() - 1.3 / 12f64.sqrt()).abs() < 1e-12);
        let angle = c.mean_normal_angle_deg.unwrap();
        assert!(angle < 1e-5, "{angle}");
        assert!((c.volume_ratio.unwrap() - 1.0).abs() < 1e-12);
        assert!((c.area_ratio.unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn scaled_and_noisy_copies() {
        let a = icosphere(2);
        let mut b = a.clone();
        b.positions.iter_mut().for_each(|p| *p *= 2.0);
        let c = compare(&a, &b).unwrap();
        assert!((c.volume_ratio.unwrap() - 8.0).abs() < 1e-12);
        assert!((c.area_ratio.unwrap() - 4.0).abs() < 1e-12);
        assert!((c.max_distance - 1.0).abs() < 1e-12);

        let mut n = a.clone();
        add_normal_noise(&mut n, 0.3, 5);
        let c = compare(&a, &n).unwrap();
        assert!(c.rms_distance > 0.0 && c.max_distance >= c.rms_distance);
        assert!(c.mean_normal_angle_deg > Some(1.0));
    }

    #[test]
    fn different_connectivity_is_an_error() {
        let a = icosphere(1);
        let b = icosphere(2);
        let e = compare(&a, &b).unwrap_err();
        assert!(matches!(e, Error::Topology { path: None, .. }));
        assert!(e.to_string().contains("vertices"), "{e}");

        let mut c = a.clone();
        c.triangles.swap(3, 4);
        let e = compare(&a, &c).unwrap_err();
        assert!(e.to_string().contains("triangle 3"), "{e}");

        let mut d = a.clone();
        d.triangles.heap_mut().pop();
        assert!(
            compare(&a, &d)
                .unwrap_err()
                .to_string()
                .contains("triangles")
        );
    }

    #[test]
    fn undefined_quantities_are_none() {
        assert_eq!(ratio(0.0, 0.0), None);
        assert_eq!(ratio(1.0, 0.0), None);
        assert_eq!(ratio(1.0, -0.0), None);
        assert_eq!(ratio(3.0, 2.0), Some(1.5));
        assert!(ratio(-0.0, 2.0).unwrap().is_sign_positive());
        // A flat mesh (zero volume) against itself: the volume ratio is undefined, the area's not.
        let flat = Mesh::new(vec![DVec3::ZERO, DVec3::X, DVec3::Y], vec![[0, 1, 2]]);
        let c = compare(&flat, &flat).unwrap();
        assert_eq!((c.volume_ratio, c.area_ratio), (None, Some(1.0)));
        assert!(c.volume_a.is_sign_positive() && c.volume_b.is_sign_positive());
        // All vertices at one point: no diagonal, no normal.
        let point = Mesh::new(vec![DVec3::ONE; 3], vec![[0, 1, 2]]);
        let c = compare(&point, &point).unwrap();
        assert_eq!((c.rms_relative, c.mean_normal_angle_deg), (None, None));
        let empty = Mesh::default();
        let c = compare(&empty, &empty).unwrap();
        assert_eq!(
            (c.rms_distance, c.volume_ratio, c.area_ratio),
            (0.0, None, None)
        );
        let json = serde_json::to_string(&c).unwrap();
        assert!(json.contains("\"volume_ratio\":null"), "{json}");
        assert!(!json.contains("-0"), "{json}");
    }
}
