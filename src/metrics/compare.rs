// STUB: to be implemented (helper "generate+metrics").
use crate::error::Result;
use crate::mesh::Mesh;

/// Differences between two meshes with the same connectivity (`vcsmooth compare`).
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Comparison {
    pub rms_distance: f64,
    pub max_distance: f64,
    /// The same, relative to the bounding-box diagonal of `a`.
    pub rms_relative: f64,
    pub max_relative: f64,
    /// Mean angle between corresponding face normals, degrees.
    pub mean_normal_angle_deg: f64,
    /// volume(b) / volume(a), area(b) / area(a).
    pub volume_ratio: f64,
    pub area_ratio: f64,
}

/// Compare `b` against `a`; an error if their vertex counts or triangles differ.
pub fn compare(a: &Mesh, b: &Mesh) -> Result<Comparison> {
    let _ = (a, b);
    todo!()
}
