//! `vcsmooth compare`: how far a mesh moved from another with the same connectivity.

use glam::DVec3;

use super::info::{angle_deg, bounding_box};
use crate::error::{Error, Result};
use crate::mesh::Mesh;

/// Differences between two meshes with the same connectivity (`vcsmooth compare`).
///
/// Every field is finite (the struct goes to JSON as is).
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Comparison {
    /// Root mean square and largest distance between corresponding vertices (0 for no vertices).
    pub rms_distance: f64,
    pub max_distance: f64,
    /// The same, relative to the bounding-box diagonal of `a` (0 when that diagonal is 0).
    pub rms_relative: f64,
    pub max_relative: f64,
    /// Mean angle between corresponding face normals, degrees, over the triangles that have a
    /// normal (non-zero area) in both meshes; 0 when none has.
    pub mean_normal_angle_deg: f64,
    /// volume(b) / volume(a), area(b) / area(a). When the denominator is 0 (or the quotient is not
    /// finite) the ratio is 1 if the numerator is 0 too, else 0.
    pub volume_ratio: f64,
    pub area_ratio: f64,
    /// The bounding-box diagonal of `a` that the relative distances divide by.
    pub bbox_diagonal: f64,
    /// Signed volumes and areas of `a` and `b` ([`crate::metrics::volume`], [`crate::metrics::area`]).
    pub volume_a: f64,
    pub volume_b: f64,
    pub area_a: f64,
    pub area_b: f64,
}

/// Compare `b` against `a`; an error if their vertex counts or triangles differ.
///
/// The error is [`Error::Topology`] naming the first difference (the caller adds the file names).
pub fn compare(a: &Mesh, b: &Mesh) -> Result<Comparison> {
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
    let relative = |d: f64| if diagonal > 0.0 { d / diagonal } else { 0.0 };

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

    let (volume_a, volume_b) = (
        super::volume(&a.positions, ta),
        super::volume(&b.positions, ta),
    );
    let (area_a, area_b) = (super::area(&a.positions, ta), super::area(&b.positions, ta));
    Ok(Comparison {
        rms_distance: rms,
        max_distance: max,
        rms_relative: relative(rms),
        max_relative: relative(max),
        mean_normal_angle_deg: if faces == 0 {
            0.0
        } else {
            angle_sum / faces as f64
        },
        volume_ratio: ratio(volume_b, volume_a),
        area_ratio: ratio(area_b, area_a),
        bbox_diagonal: diagonal,
        volume_a,
        volume_b,
        area_a,
        area_b,
    })
}

/// `num / den`, always finite: 1 for 0/0, 0 for any other quotient that is not finite.
fn ratio(num: f64, den: f64) -> f64 {
    let r = num / den;
    if r.is_finite() {
        r
    } else if num == 0.0 && den == 0.0 {
        1.0
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{add_normal_noise, icosphere, torus};

    #[test]
    fn a_mesh_against_itself() {
        let a = torus(1);
        let c = compare(&a, &a).unwrap();
        assert_eq!(
            (
                c.rms_distance,
                c.max_distance,
                c.rms_relative,
                c.max_relative
            ),
            (0.0, 0.0, 0.0, 0.0)
        );
        assert_eq!(c.mean_normal_angle_deg, 0.0);
        assert_eq!((c.volume_ratio, c.area_ratio), (1.0, 1.0));
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
        assert!((c.rms_relative - 1.3 / 12f64.sqrt()).abs() < 1e-12);
        assert!(
            c.mean_normal_angle_deg < 1e-5,
            "{}",
            c.mean_normal_angle_deg
        );
        assert!((c.volume_ratio - 1.0).abs() < 1e-12);
        assert!((c.area_ratio - 1.0).abs() < 1e-12);
    }

    #[test]
    fn scaled_and_noisy_copies() {
        let a = icosphere(2);
        let mut b = a.clone();
        b.positions.iter_mut().for_each(|p| *p *= 2.0);
        let c = compare(&a, &b).unwrap();
        assert!((c.volume_ratio - 8.0).abs() < 1e-12);
        assert!((c.area_ratio - 4.0).abs() < 1e-12);
        assert!((c.max_distance - 1.0).abs() < 1e-12);

        let mut n = a.clone();
        add_normal_noise(&mut n, 0.3, 5);
        let c = compare(&a, &n).unwrap();
        assert!(c.rms_distance > 0.0 && c.max_distance >= c.rms_distance);
        assert!(c.mean_normal_angle_deg > 1.0);
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
    fn ratios_stay_finite() {
        assert_eq!(ratio(0.0, 0.0), 1.0);
        assert_eq!(ratio(1.0, 0.0), 0.0);
        assert_eq!(ratio(3.0, 2.0), 1.5);
        // A flat mesh (zero volume) against itself and against a bent copy.
        let flat = Mesh::new(vec![DVec3::ZERO, DVec3::X, DVec3::Y], vec![[0, 1, 2]]);
        let c = compare(&flat, &flat).unwrap();
        assert_eq!(c.volume_ratio, 1.0);
        let empty = Mesh::default();
        let c = compare(&empty, &empty).unwrap();
        assert_eq!(
            (c.rms_distance, c.volume_ratio, c.area_ratio),
            (0.0, 1.0, 1.0)
        );
    }
}
