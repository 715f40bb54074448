// STUB: to be implemented (helper "generate+metrics").
use glam::DVec3;

use crate::mesh::Mesh;
use crate::topology::Topology;

/// Everything `vcsmooth info` reports about a mesh.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct MeshInfo {
    pub vertices: usize,
    /// Triangles after fan triangulation.
    pub triangles: usize,
    /// Faces in the input file, and how many of them were polygons split into triangles.
    pub input_faces: usize,
    pub polygons_triangulated: usize,
    pub edges: usize,
    pub boundary_edges: usize,
    pub non_manifold_edges: usize,
    pub non_manifold_vertices: usize,
    pub degenerate_triangles: usize,
    pub components: usize,
    pub unreferenced_vertices: usize,
    /// Every edge has exactly two triangles.
    pub closed: bool,
    pub volume: f64,
    pub area: f64,
    pub bbox_min: [f64; 3],
    pub bbox_max: [f64; 3],
    pub bbox_diagonal: f64,
    pub mean_edge_length: f64,
    /// Mean dihedral angle between adjacent triangles, degrees (see [`roughness`]).
    pub roughness_deg: f64,
}

/// Measure `mesh` with its topology.
pub fn info(mesh: &Mesh, topo: &Topology) -> MeshInfo {
    let _ = (mesh, topo);
    todo!()
}

/// Mean length over the undirected edges (0 for none).
pub fn mean_edge_length(pos: &[DVec3], topo: &Topology) -> f64 {
    let _ = (pos, topo);
    todo!()
}

/// Mean dihedral angle, in degrees, between the normals of the two triangles of every manifold
/// interior edge (0 for a plane): the roughness measure of the tests and reports.
pub fn roughness(pos: &[DVec3], triangles: &[[u32; 3]], topo: &Topology) -> f64 {
    let _ = (pos, triangles, topo);
    todo!()
}
