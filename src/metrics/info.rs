//! `vcsmooth info`: counts, topology, volume, area, bounding box, edge length and roughness of a mesh.

use glam::DVec3;

use crate::mesh::Mesh;
use crate::topology::Topology;

/// Everything `vcsmooth info` reports about a mesh.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
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
    /// Edges whose two triangles traverse them in the same direction: the faces are not
    /// consistently oriented (see [`crate::topology`]). Volume, area and roughness are measured,
    /// and meshes smoothed, with the faces oriented consistently; files keep them as they came.
    #[serde(default)]
    pub inconsistent_orientation_edges: usize,
    /// Components that cannot be oriented consistently (a Möbius strip, a Klein bottle).
    #[serde(default)]
    pub non_orientable_components: usize,
    /// Edges that stay inconsistent in those components; their vertices are fixed.
    #[serde(default)]
    pub orientation_seam_edges: usize,
    /// Vertices with more neighbours than [`crate::topology::MAX_FREE_DEGREE`]; they are fixed.
    #[serde(default)]
    pub high_degree_vertices: usize,
    /// Vertices that no method moves (boundary, non-manifold, degenerate, unreferenced, hubs,
    /// orientation seams).
    #[serde(default)]
    pub fixed_vertices: usize,
    /// Vertices pinned by the run (`pins` of [`crate::EngineSettings`]); included in
    /// `fixed_vertices`.
    #[serde(default)]
    pub pinned_vertices: usize,
    /// Connected components of the (non-degenerate) triangles, through shared vertices;
    /// unreferenced vertices are not components.
    pub components: usize,
    pub unreferenced_vertices: usize,
    /// Every edge has exactly two triangles (no boundary, no non-manifold edge), and there is at
    /// least one triangle.
    pub closed: bool,
    /// Signed volume ([`crate::metrics::volume`]): positive for an outward-oriented closed mesh
    /// (of the consistently oriented faces, see `inconsistent_orientation_edges`).
    pub volume: f64,
    pub area: f64,
    /// Bounding box of all vertices (unreferenced ones included); zeros for an empty mesh.
    pub bbox_min: [f64; 3],
    pub bbox_max: [f64; 3],
    pub bbox_diagonal: f64,
    pub mean_edge_length: f64,
    /// Mean dihedral angle between adjacent triangles, degrees (see [`roughness`]).
    pub roughness_deg: f64,
}

/// Measure `mesh` with its topology (`topo` built from `mesh.triangles` over `mesh.positions`).
/// Faces that are not consistently oriented are measured as the smoothing sees them: oriented
/// ([`Topology::orient`]) in a copy.
pub fn info(mesh: &Mesh, topo: &Topology) -> MeshInfo {
    if topo.stats.inconsistent_orientation_edges == 0 {
        return info_of(&mesh.positions, &mesh.triangles, &mesh.source, topo);
    }
    let (mut topo, mut triangles) = (topo.clone(), mesh.triangles.to_vec());
    topo.orient(&mut triangles, &mesh.positions);
    info_of(&mesh.positions, &triangles, &mesh.source, &topo)
}

/// [`info`] from the parts of a mesh (e.g. the reordered arrays of the patch engine; every figure
/// is independent of the vertex and triangle order). The triangles are measured as they are:
/// oriented already when they come from a plan.
pub fn info_of(
    pos: &[DVec3],
    triangles: &[[u32; 3]],
    source: &crate::mesh::Source,
    topo: &Topology,
) -> MeshInfo {
    debug_assert_eq!(
        topo.len(),
        pos.len(),
        "topology built for another vertex count"
    );
    let s = &topo.stats;
    let (lo, hi) = bounding_box(pos);
    MeshInfo {
        vertices: pos.len(),
        triangles: triangles.len(),
        input_faces: source.input_faces,
        polygons_triangulated: source.polygons_triangulated,
        edges: s.edges,
        boundary_edges: s.boundary_edges,
        non_manifold_edges: s.non_manifold_edges,
        non_manifold_vertices: s.non_manifold_vertices,
        degenerate_triangles: s.degenerate_triangles,
        inconsistent_orientation_edges: s.inconsistent_orientation_edges,
        non_orientable_components: s.non_orientable_components,
        orientation_seam_edges: s.orientation_seam_edges,
        high_degree_vertices: s.high_degree_vertices,
        fixed_vertices: s.fixed_vertices,
        pinned_vertices: s.pinned_vertices,
        components: components(topo),
        unreferenced_vertices: s.unreferenced_vertices,
        closed: s.boundary_edges == 0 && s.non_manifold_edges == 0 && !triangles.is_empty(),
        volume: super::volume(pos, triangles),
        area: super::area(pos, triangles),
        bbox_min: lo.to_array(),
        bbox_max: hi.to_array(),
        bbox_diagonal: (hi - lo).length(),
        mean_edge_length: mean_edge_length(pos, topo),
        roughness_deg: roughness(pos, triangles, topo),
    }
}

/// Smallest and largest coordinates over `pos` (NaN coordinates ignored); zeros for none.
pub(crate) fn bounding_box(pos: &[DVec3]) -> (DVec3, DVec3) {
    let (lo, hi) = pos.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        // f64::min / max ignore NaN (DVec3::min would not).
        |(lo, hi), p| {
            let l = DVec3::new(lo.x.min(p.x), lo.y.min(p.y), lo.z.min(p.z));
            let h = DVec3::new(hi.x.max(p.x), hi.y.max(p.y), hi.z.max(p.z));
            (l, h)
        },
    );
    // Empty input, or an axis with only NaN: report zeros rather than ±inf.
    let fix = |lo: f64, hi: f64| if lo <= hi { (lo, hi) } else { (0.0, 0.0) };
    let (x, y, z) = (fix(lo.x, hi.x), fix(lo.y, hi.y), fix(lo.z, hi.z));
    (DVec3::new(x.0, y.0, z.0), DVec3::new(x.1, y.1, z.1))
}

/// Connected components over the adjacency, counting only vertices with a neighbour.
fn components(topo: &Topology) -> usize {
    // A bit per vertex and a breadth-first frontier (on a surface it holds about √n vertices,
    // where a depth-first stack can grow to n): the count stays cheap in memory for huge meshes.
    let n = topo.len();
    let mut seen = vec![0u64; n.div_ceil(64)];
    let mut mark = |v: u32| {
        let (w, b) = (v as usize / 64, 1u64 << (v % 64));
        let new = seen[w] & b == 0;
        seen[w] |= b;
        new
    };
    let mut frontier = std::collections::VecDeque::new();
    let mut count = 0;
    for start in 0..n as u32 {
        if topo.deg(start) == 0 || !mark(start) {
            continue;
        }
        count += 1;
        frontier.push_back(start);
        while let Some(v) = frontier.pop_front() {
            for &u in topo.neighbors(v) {
                if mark(u) {
                    frontier.push_back(u);
                }
            }
        }
    }
    count
}

/// Mean length over the undirected edges (0 for none).
pub fn mean_edge_length(pos: &[DVec3], topo: &Topology) -> f64 {
    let (sum, count) = topo.edges().fold((0.0, 0usize), |(s, c), [i, j]| {
        (s + pos[i as usize].distance(pos[j as usize]), c + 1)
    });
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// Mean dihedral angle, in degrees, between the normals of the two triangles of every manifold
/// interior edge (0 for a plane): the roughness measure of the tests and reports.
///
/// Edges with one or three or more triangles are skipped, and so are edges next to a zero-area
/// triangle (no normal). The angle is `atan2(|n₁ × n₂|, n₁ · n₂)`, accurate near 0°. 0 when no edge
/// counts.
pub fn roughness(pos: &[DVec3], triangles: &[[u32; 3]], topo: &Topology) -> f64 {
    let normal = |t: u32| {
        let [a, b, c] = triangles[t as usize].map(|v| pos[v as usize]);
        let n = (b - a).cross(c - a);
        (n.length_squared() > 0.0 && n.is_finite()).then_some(n)
    };
    let mut sum = 0.0;
    let mut count = 0usize;
    for [i, j] in topo.edges() {
        let Some([f, g]) = two_faces(topo, triangles, i, j) else {
            continue;
        };
        if let (Some(n1), Some(n2)) = (normal(f), normal(g)) {
            sum += angle_deg(n1, n2);
            count += 1;
        }
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// The angle between two non-zero vectors, in degrees.
pub(crate) fn angle_deg(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b)).to_degrees()
}

/// The faces of edge `i`–`j`, if there are exactly two: found among the faces of the endpoint with
/// fewer, so that the edges of a vertex of degree d cost O(d) together, not O(d²).
fn two_faces(topo: &Topology, triangles: &[[u32; 3]], i: u32, j: u32) -> Option<[u32; 2]> {
    let (x, y) = if topo.faces_of(i).len() <= topo.faces_of(j).len() {
        (i, j)
    } else {
        (j, i)
    };
    let mut found = [0u32; 2];
    let mut n = 0;
    for &t in topo.faces_of(x) {
        if triangles[t as usize].contains(&y) {
            if n == 2 {
                return None;
            }
            found[n] = t;
            n += 1;
        }
    }
    (n == 2).then_some(found)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{add_normal_noise, icosphere};

    fn topo(m: &Mesh) -> Topology {
        Topology::build(m.positions.len(), &m.triangles).unwrap()
    }

    /// A flat `n × n` grid of unit squares in the z = 0 plane, split into triangles.
    fn grid(n: u32) -> Mesh {
        let mut pos = Vec::new();
        for y in 0..=n {
            for x in 0..=n {
                pos.push(DVec3::new(x as f64, y as f64, 0.0));
            }
        }
        let id = |x: u32, y: u32| y * (n + 1) + x;
        let mut tris = Vec::new();
        for y in 0..n {
            for x in 0..n {
                tris.push([id(x, y), id(x + 1, y), id(x + 1, y + 1)]);
                tris.push([id(x, y), id(x + 1, y + 1), id(x, y + 1)]);
            }
        }
        Mesh::new(pos, tris)
    }

    #[test]
    fn open_fan_has_boundary_and_one_component() {
        // Centre 0, rim 1..=5, four triangles not closing the fan: spokes 0-1 and 0-5 and the
        // four rim edges are boundary.
        let pos = (0..6)
            .map(|k| DVec3::new(k as f64, (k * k) as f64, 0.0))
            .collect();
        let m = Mesh::new(pos, (1..=4).map(|k| [0, k, k + 1]).collect());
        let i = info(&m, &topo(&m));
        assert_eq!(i.vertices, 6);
        assert_eq!(i.triangles, 4);
        assert_eq!(i.edges, 9);
        assert_eq!(i.boundary_edges, 6);
        assert_eq!(i.non_manifold_edges, 0);
        assert_eq!(i.components, 1);
        assert!(!i.closed);
        assert_eq!(i.bbox_min, [0.0, 0.0, 0.0]);
        assert_eq!(i.bbox_max, [5.0, 25.0, 0.0]);
    }

    #[test]
    fn two_disjoint_spheres_and_an_unreferenced_vertex() {
        let a = icosphere(1);
        let n = a.positions.len() as u32;
        let mut pos = a.positions.to_vec();
        pos.extend(a.positions.iter().map(|p| *p + DVec3::new(3.0, 0.0, 0.0)));
        pos.push(DVec3::new(-7.0, 0.0, 0.0));
        let mut tris = a.triangles.to_vec();
        tris.extend(a.triangles.iter().map(|t| t.map(|v| v + n)));
        let m = Mesh::new(pos, tris);
        let i = info(&m, &topo(&m));
        assert_eq!(i.components, 2);
        assert_eq!(i.unreferenced_vertices, 1);
        assert!(i.closed);
        let one = crate::metrics::volume(&a.positions, &a.triangles);
        assert!((i.volume - 2.0 * one).abs() < 1e-12);
        assert_eq!(i.bbox_min[0], -7.0);
        assert!((i.bbox_max[0] - 4.0).abs() < 1e-12);
    }

    #[test]
    fn empty_mesh_is_all_zeros() {
        let m = Mesh::default();
        let i = info(&m, &topo(&m));
        assert_eq!(i.components, 0);
        assert!(!i.closed);
        assert_eq!(
            (i.bbox_min, i.bbox_max, i.bbox_diagonal),
            ([0.0; 3], [0.0; 3], 0.0)
        );
        assert_eq!(
            (i.mean_edge_length, i.roughness_deg, i.volume, i.area),
            (0.0, 0.0, 0.0, 0.0)
        );
    }

    #[test]
    fn sphere_info() {
        let m = icosphere(2);
        let t = topo(&m);
        let i = info(&m, &t);
        assert!(i.closed);
        assert_eq!(
            (i.vertices, i.triangles, i.edges, i.input_faces),
            (162, 320, 480, 320)
        );
        assert!((i.bbox_diagonal - 12f64.sqrt()).abs() < 1e-12);
        // Edges of the 162-vertex sphere are about 0.3 long; dihedral angles about 10 degrees.
        assert!(
            i.mean_edge_length > 0.25 && i.mean_edge_length < 0.35,
            "{}",
            i.mean_edge_length
        );
        assert!(
            i.roughness_deg > 5.0 && i.roughness_deg < 20.0,
            "{}",
            i.roughness_deg
        );
    }

    #[test]
    fn grid_edge_length_and_zero_roughness() {
        let m = grid(4);
        let t = topo(&m);
        // 40 unit edges and 16 diagonals.
        let expected = (40.0 + 16.0 * 2f64.sqrt()) / 56.0;
        assert!((mean_edge_length(&m.positions, &t) - expected).abs() < 1e-12);
        assert_eq!(roughness(&m.positions, &m.triangles, &t), 0.0);
    }

    #[test]
    fn noise_makes_a_sphere_rougher() {
        let clean = icosphere(2);
        let mut noisy = clean.clone();
        add_normal_noise(&mut noisy, 0.3, 1);
        let t = topo(&clean);
        let r_clean = roughness(&clean.positions, &clean.triangles, &t);
        let r_noisy = roughness(&noisy.positions, &noisy.triangles, &t);
        assert!(
            r_noisy > r_clean * 1.2,
            "noisy {r_noisy} vs clean {r_clean}"
        );
    }

    #[test]
    fn roughness_skips_zero_area_and_non_manifold_edges() {
        // A right-angle fold (90 degrees) plus a zero-area triangle on a third edge.
        let pos = vec![
            DVec3::ZERO,
            DVec3::X,
            DVec3::Y,
            DVec3::Z,
            DVec3::new(2.0, -1.0, 0.0), // collinear with 1 and 2
        ];
        let tris = vec![[0, 1, 2], [1, 0, 3], [1, 2, 4]];
        let m = Mesh::new(pos, tris);
        let t = topo(&m);
        // Edge 0-1: 90 degrees; edge 1-2 borders the zero-area triangle: skipped.
        assert!((roughness(&m.positions, &m.triangles, &t) - 90.0).abs() < 1e-12);
        assert_eq!(two_faces(&t, &m.triangles, 0, 1), Some([0, 1]));
        assert_eq!(two_faces(&t, &m.triangles, 1, 2), Some([0, 2]));
        assert_eq!(two_faces(&t, &m.triangles, 0, 3), None);
    }
}
