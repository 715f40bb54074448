//! Generated test meshes: closed icospheres and tori, with seeded Gaussian noise along vertex normals.
// STUB: to be implemented (helper "generate+metrics").

use crate::mesh::Mesh;

/// Unit icosphere centred at the origin, outward-oriented: `10·4^k + 2` vertices, `20·4^k` triangles
/// (k = 2 gives the paper's 162-vertex sphere).
pub fn icosphere(subdivisions: u32) -> Mesh {
    let _ = subdivisions;
    todo!()
}

/// Closed torus around the z axis (major radius 1, minor radius 0.4), outward-oriented, a regular
/// grid whose resolution doubles with each subdivision level.
pub fn torus(subdivisions: u32) -> Mesh {
    let _ = subdivisions;
    todo!()
}

/// Displace every vertex along its (area-weighted) normal by Gaussian noise of standard deviation
/// `sigma` × the mean edge length; deterministic for a seed.
pub fn add_normal_noise(mesh: &mut Mesh, sigma: f64, seed: u64) {
    let _ = (mesh, sigma, seed);
    todo!()
}
