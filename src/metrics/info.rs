//! `vcsmooth info`: counts, topology, volume, area, bounding box, edge length and roughness of a mesh.

use std::ops::Range;
use std::sync::atomic::Ordering::{AcqRel, Acquire, Relaxed};
use std::sync::atomic::{AtomicBool, AtomicU32};

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::mesh::{Mesh, Storage};
use crate::meter::Meter;
use crate::topology::{Lanes, Topology, corners_after, is_degenerate};

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
    /// Vertices that no method moves freely (boundary, non-manifold, degenerate, unreferenced,
    /// hubs, orientation seams, pins, crease vertices: see `crease_vertices`).
    #[serde(default)]
    pub fixed_vertices: usize,
    /// Vertices pinned by the run (`pins` of [`crate::EngineSettings`]); included in
    /// `fixed_vertices`.
    #[serde(default)]
    pub pinned_vertices: usize,
    /// Crease edges of the run (`crease_angle` of [`crate::Options`]) between two crease
    /// vertices: edges whose faces' normals differ by more than the angle on a denoised copy of
    /// the input, along lines that are that sharp on the input too.
    #[serde(default)]
    pub crease_edges: usize,
    /// Vertices on two or more crease edges, included in `fixed_vertices`: a corner (three or
    /// more) never moves; a vertex on a crease line moves only along it with `laplacian`, `taubin`
    /// and `vcs-lowpass`, as any vertex with `vcs-guided`, and not at all with the others.
    #[serde(default)]
    pub crease_vertices: usize,
    /// Connected components of the (non-degenerate) triangles, through shared vertices;
    /// unreferenced vertices are not components.
    pub components: usize,
    /// Vertices of no triangle (welded copies not included).
    pub unreferenced_vertices: usize,
    /// Vertices at exactly the position of another (texture seams, unmerged corners), welded to
    /// it for smoothing: they move with it (see [`crate::partition`]); 0 with `weld` off.
    #[serde(default)]
    pub welded_vertices: usize,
    /// Every edge has exactly two triangles (no boundary, no non-manifold edge), and there is at
    /// least one triangle.
    pub closed: bool,
    /// Signed volume ([`crate::metrics::volume`]): positive for an outward-oriented closed mesh
    /// (of the consistently oriented faces, see `inconsistent_orientation_edges`). Measured
    /// about `volume_origin`, which matters on an open mesh only.
    pub volume: f64,
    /// The point the volume is measured about: the input's centroid (all vertices), for the
    /// output too, so that an open mesh's input and output volumes compare.
    #[serde(default)]
    pub volume_origin: [f64; 3],
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
pub fn info(mesh: &Mesh, topo: &Topology) -> Result<MeshInfo> {
    if topo.stats.inconsistent_orientation_edges == 0 {
        return info_of(&mesh.positions, &mesh.triangles, &mesh.source, topo);
    }
    let (mut topo, mut triangles) = (topo.clone(), mesh.triangles.to_vec());
    topo.orient(&mut triangles, &mesh.positions);
    info_of(&mesh.positions, &triangles, &mesh.source, &topo)
}

impl MeshInfo {
    /// Count `welded` copies (vertices of no triangle once welded, so counted by the topology as
    /// unreferenced and fixed) as welded instead.
    pub fn count_welded(&mut self, welded: usize) {
        self.welded_vertices = welded;
        self.unreferenced_vertices -= welded;
        self.fixed_vertices -= welded;
    }
}

/// [`info`] from the parts of a mesh (e.g. the reordered arrays of the patch engine; every count
/// is independent of the vertex and triangle order). The triangles are measured as they are:
/// oriented already when they come from a plan. The sums run over the vertices in order
/// ([`vertex_sums`]); the engine measures its plans over chunks in parallel instead
/// (`engine::reduce::geometry`).
pub fn info_of(
    pos: &[DVec3],
    triangles: &[[u32; 3]],
    source: &crate::mesh::Source,
    topo: &Topology,
) -> Result<MeshInfo> {
    let components = components(pos.len(), triangles, &Storage::heap(), &Meter::default())?;
    let mut info = connectivity(pos.len(), triangles.len(), source, topo, components);
    info.set_geometry(geometry(pos, triangles, topo));
    Ok(info)
}

/// The counts of [`MeshInfo`] (everything but the [`Geometry`], left at zero) of a mesh of
/// `vertices` and `triangles` with the topology `topo` and `components` ([`components`]). They
/// do not depend on the positions: a run counts its input once and gives its output the same
/// counts.
pub fn connectivity(
    vertices: usize,
    triangles: usize,
    source: &crate::mesh::Source,
    topo: &Topology,
    components: usize,
) -> MeshInfo {
    debug_assert_eq!(
        topo.len(),
        vertices,
        "topology built for another vertex count"
    );
    let s = &topo.stats;
    MeshInfo {
        vertices,
        triangles,
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
        crease_edges: s.crease_edges,
        crease_vertices: s.crease_vertices,
        components,
        unreferenced_vertices: s.unreferenced_vertices,
        closed: s.boundary_edges == 0 && s.non_manifold_edges == 0 && triangles > 0,
        ..MeshInfo::default()
    }
}

/// What [`MeshInfo`] reports of the positions, as sums and extremes so that parts of a mesh can
/// be measured apart and combined.
#[derive(Debug, Clone, Copy)]
pub struct Geometry {
    /// Signed volume about `origin` ([`crate::metrics::volume_about`]) and area.
    pub volume: f64,
    pub origin: DVec3,
    pub area: f64,
    /// Smallest and largest coordinates, see [`extent`].
    pub extent: (DVec3, DVec3),
    pub edges: EdgeSums,
}

/// [`Geometry`] of a whole mesh, summed in the order of [`vertex_sums`] over all its vertices.
pub fn geometry(pos: &[DVec3], triangles: &[[u32; 3]], topo: &Topology) -> Geometry {
    let origin = super::centroid(pos);
    vertex_sums(pos, triangles, topo, 0..topo.len() as u32, origin).geometry(origin)
}

impl MeshInfo {
    /// Set the figures that depend on the positions (volume, area, bounding box, mean edge length,
    /// roughness) from `g`; the counts stay.
    pub fn set_geometry(&mut self, g: Geometry) {
        let (lo, hi) = bounding(g.extent);
        self.volume = g.volume;
        self.volume_origin = g.origin.to_array();
        self.area = g.area;
        self.bbox_min = lo.to_array();
        self.bbox_max = hi.to_array();
        self.bbox_diagonal = (hi - lo).length();
        self.mean_edge_length = mean(g.edges.length);
        self.roughness_deg = mean(g.edges.angle);
    }
}

/// `sum / count`, 0 for no items.
fn mean((sum, count): (f64, usize)) -> f64 {
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// Smallest and largest coordinates over `pos`, NaN coordinates ignored: `(+∞, −∞)` on an axis
/// with none. Combine the extents of parts with [`extent_union`].
pub fn extent(pos: &[DVec3]) -> (DVec3, DVec3) {
    let none = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    pos.iter().fold(none, |e, &p| extent_union(e, (p, p)))
}

/// The extent of two parts together.
pub fn extent_union((lo, hi): (DVec3, DVec3), (l, h): (DVec3, DVec3)) -> (DVec3, DVec3) {
    // f64::min / max ignore NaN (DVec3::min would not).
    (
        DVec3::new(lo.x.min(l.x), lo.y.min(l.y), lo.z.min(l.z)),
        DVec3::new(hi.x.max(h.x), hi.y.max(h.y), hi.z.max(h.z)),
    )
}

/// Smallest and largest coordinates over `pos` (NaN coordinates ignored); zeros for none.
pub(crate) fn bounding_box(pos: &[DVec3]) -> (DVec3, DVec3) {
    bounding(extent(pos))
}

/// An extent as a bounding box: zeros rather than ±∞ on an axis without coordinates (an empty
/// mesh, or only NaN).
fn bounding((lo, hi): (DVec3, DVec3)) -> (DVec3, DVec3) {
    let fix = |lo: f64, hi: f64| if lo <= hi { (lo, hi) } else { (0.0, 0.0) };
    let (x, y, z) = (fix(lo.x, hi.x), fix(lo.y, hi.y), fix(lo.z, hi.z));
    (DVec3::new(x.0, y.0, z.0), DVec3::new(x.1, y.1, z.1))
}

/// Connected components of the `n` vertices joined by `triangles`, counting only vertices with a
/// neighbour (a corner of a face with three distinct corners; degenerate faces join nothing, as
/// in the topology): a union–find over the faces, in parallel on the current pool (a count, the
/// same for any order of the unions). It needs no adjacency, so a run counts it before building
/// one. Its forest, one entry per vertex, is a working array of `storage`
/// ([`Storage::working`]: a scratch file for a mesh larger than the memory budget, else memory
/// given back when the count is done). `meter` counts the faces. Fails, as the topology's build
/// does, when a triangle indexes a vertex `>= n` or `n` exceeds the 32-bit ids.
pub fn components(
    n: usize,
    triangles: &[[u32; 3]],
    storage: &Storage,
    meter: &Meter,
) -> Result<usize> {
    // Faces per work item: enough to make scheduling negligible.
    const GRAIN: usize = 1 << 14;
    components_joining(n, storage, |join| {
        triangles.par_chunks(GRAIN).for_each(|chunk| {
            join(chunk);
            meter.add(chunk.len() as u64);
        })
    })
    .map(|(count, ())| count)
}

/// [`components`] of the faces that `work` hands to `join`, from any thread, in any order and
/// pieces (each face once, or more: a face joined again changes nothing): so that a pass that
/// holds the faces anyway (the reorder's sort) counts them where they are. Returns the count
/// and what `work` returns.
pub fn components_joining<R>(
    n: usize,
    storage: &Storage,
    work: impl FnOnce(&(dyn Fn(&[[u32; 3]]) + Sync)) -> R,
) -> Result<(usize, R)> {
    if n > u32::MAX as usize {
        return Err(Error::topology(format!(
            "{n} vertices exceed the 2^32 limit"
        )));
    }
    // Vertices per work item: enough to make scheduling negligible.
    const GRAIN: usize = 1 << 14;
    // A vertex no face has joined yet: its own root once one does.
    const UNSEEN: u32 = u32::MAX;
    let mut forest = storage.working::<u32>(n)?;
    forest.par_chunks_mut(GRAIN).for_each(|c| c.fill(UNSEEN));
    // SAFETY: `AtomicU32` has the size, alignment and bit validity of `u32`, and the exclusive
    // borrow of `forest` keeps every other access out while this view lives.
    let parent: &[AtomicU32] =
        unsafe { std::slice::from_raw_parts(forest.as_mut_ptr().cast::<AtomicU32>(), n) };
    // parent[v] ≤ v for every vertex seen: a root is linked under a smaller root, so no cycle can
    // form whatever the interleaving; a stale read only makes a find or a link retry, and
    // rayon's join orders the passes. A find starts at a vertex its face has seen and follows
    // links to vertices seen; the links are published with Release and read with Acquire, so
    // that a thread that reads a link also sees its target marked seen (never UNSEEN).
    let find = |mut v: u32| loop {
        let p = parent[v as usize].load(Acquire);
        if p == v {
            return v;
        }
        let g = parent[p as usize].load(Acquire);
        if g == p {
            return p;
        }
        // Path halving: point v at its grandparent (a no-op if another thread moved it already).
        let _ = parent[v as usize].compare_exchange(p, g, AcqRel, Acquire);
        v = g;
    };
    let link = |a: u32, b: u32| {
        let (mut a, mut b) = (find(a), find(b));
        while a != b {
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            if parent[hi as usize]
                .compare_exchange(hi, lo, AcqRel, Acquire)
                .is_ok()
            {
                return;
            }
            (a, b) = (find(a), find(b));
        }
    };
    let out_of_range = AtomicBool::new(false);
    let join = |faces: &[[u32; 3]]| {
        for t in faces {
            if t.iter().any(|&v| v as usize >= n) {
                out_of_range.store(true, Relaxed);
                continue;
            }
            if is_degenerate(t) {
                continue;
            }
            for &v in t {
                let _ = parent[v as usize].compare_exchange(UNSEEN, v, AcqRel, Acquire);
            }
            link(t[0], t[1]);
            link(t[0], t[2]);
        }
    };
    let worked = work(&join);
    if out_of_range.into_inner() {
        return Err(Error::topology(format!(
            "a triangle indexes a vertex out of range (0..{n})"
        )));
    }
    let count = (0..n as u32)
        .into_par_iter()
        .with_min_len(GRAIN)
        .filter(|&v| parent[v as usize].load(Relaxed) == v)
        .count();
    Ok((count, worked))
}

/// Mean length over the undirected edges (0 for none), summed in ascending `(i, j)` order.
pub fn mean_edge_length(pos: &[DVec3], topo: &Topology) -> f64 {
    let (sum, count) = topo.edges().fold((0.0, 0usize), |(s, c), [i, j]| {
        (s + pos[i as usize].distance(pos[j as usize]), c + 1)
    });
    mean((sum, count))
}

/// Mean dihedral angle, in degrees, between the normals of the two triangles of every manifold
/// interior edge (0 for a plane): the roughness measure of the tests and reports. Summed in
/// ascending `(i, j)` order.
///
/// Edges with one or three or more triangles are skipped, and so are edges next to a zero-area
/// triangle (no normal). The angle is `atan2(|n₁ × n₂|, n₁ · n₂)`, accurate near 0°. 0 when no edge
/// counts.
pub fn roughness(pos: &[DVec3], triangles: &[[u32; 3]], topo: &Topology) -> f64 {
    let all = 0..topo.len() as u32;
    mean(
        vertex_sums(pos, triangles, topo, all, DVec3::ZERO)
            .edges
            .angle,
    )
}

/// Sums over some edges: of their lengths, and of the dihedral angles that [`roughness`] counts,
/// each with its number of terms.
#[derive(Debug, Clone, Copy, Default)]
pub struct EdgeSums {
    pub length: (f64, usize),
    pub angle: (f64, usize),
}

/// The sums of two sets of edges together (`self`'s terms first).
impl std::ops::Add for EdgeSums {
    type Output = EdgeSums;

    fn add(self, o: EdgeSums) -> EdgeSums {
        let add = |(s, n): (f64, usize), (t, m): (f64, usize)| (s + t, n + m);
        EdgeSums {
            length: add(self.length, o.length),
            angle: add(self.angle, o.angle),
        }
    }
}

/// What [`Geometry`] sums over some vertices, so that parts of a mesh can be measured apart and
/// combined (with `+`, in order) and then divided once.
#[derive(Debug, Clone, Copy)]
pub struct VertexSums {
    /// `Σ det(p_a − o, p_b − o, p_c − o)` ([`super::determinant`]) and `Σ |(p_b − p_a) × (p_c − p_a)|`
    /// over the (non-degenerate) faces whose smallest corner is one of the vertices: six times
    /// their volume about `o`, twice their area. A degenerate face has no area and (to rounding)
    /// no volume, and no part in the adjacency: it is left out.
    pub determinants: f64,
    pub doubled_area: f64,
    /// Smallest and largest coordinates of the vertices ([`extent`]).
    pub extent: (DVec3, DVec3),
    /// The edges whose smaller end is one of the vertices.
    pub edges: EdgeSums,
}

impl Default for VertexSums {
    fn default() -> VertexSums {
        VertexSums {
            determinants: -0.0,
            doubled_area: -0.0,
            extent: extent(&[]),
            edges: EdgeSums::default(),
        }
    }
}

/// The sums of two sets of vertices together (`self`'s terms first).
impl std::ops::Add for VertexSums {
    type Output = VertexSums;

    fn add(self, o: VertexSums) -> VertexSums {
        VertexSums {
            determinants: self.determinants + o.determinants,
            doubled_area: self.doubled_area + o.doubled_area,
            extent: extent_union(self.extent, o.extent),
            edges: self.edges + o.edges,
        }
    }
}

impl VertexSums {
    /// The [`Geometry`] of the sums of a whole mesh, taken about `origin`.
    pub fn geometry(self, origin: DVec3) -> Geometry {
        Geometry {
            volume: self.determinants / 6.0,
            origin,
            area: self.doubled_area / 2.0,
            extent: self.extent,
            edges: self.edges,
        }
    }
}

/// Positions by vertex id, as the vertex pass ([`vertex_sums`]) reads them: a slice, or one
/// read as a file stores it ([`AsF32`]).
pub trait Positions: Sync {
    fn at(&self, v: u32) -> DVec3;
}

impl Positions for [DVec3] {
    #[inline(always)]
    fn at(&self, v: u32) -> DVec3 {
        self[v as usize]
    }
}

/// Positions read rounded to `f32`, as a binary `float` file stores them: an output measured as
/// written without rounding the array itself.
pub struct AsF32<'a>(pub &'a [DVec3]);

impl Positions for AsF32<'_> {
    #[inline(always)]
    fn at(&self, v: u32) -> DVec3 {
        let p = self.0[v as usize];
        DVec3::new(
            f64::from(p.x as f32),
            f64::from(p.y as f32),
            f64::from(p.z as f32),
        )
    }
}

/// [`VertexSums`] of `vertices` (determinants about `origin`), in ascending order: one walk over
/// the vertices and their faces for every figure.
///
/// At each vertex `i` the faces' normals are computed once (at a vertex of at most [`LANES`]
/// faces all of them, without a branch; else those holding a corner above `i`), and each edge
/// `(i, j)` above `i` takes the normals of the faces holding `j`, so an edge's faces need no
/// search of the mesh. At its smallest corner the same normal gives a face's area, and its
/// determinant as `(p_a − o) · n` (the same in exact arithmetic).
pub fn vertex_sums<P: Positions + ?Sized>(
    pos: &P,
    triangles: &[[u32; 3]],
    topo: &Topology,
    vertices: Range<u32>,
    origin: DVec3,
) -> VertexSums {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (just checked).
        return unsafe { vertex_sums_avx2(pos, triangles, topo, vertices, origin) };
    }
    vertex_sums_lanes(pos, triangles, topo, vertices, origin)
}

/// [`vertex_sums`] compiled for AVX2: the lanes of a vertex's faces compared in one instruction,
/// four angles' arithmetic in another. The same operations, so the same bits (no fused
/// multiply-add: Rust does not contract a product and a sum).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn vertex_sums_avx2<P: Positions + ?Sized>(
    pos: &P,
    triangles: &[[u32; 3]],
    topo: &Topology,
    vertices: Range<u32>,
    origin: DVec3,
) -> VertexSums {
    vertex_sums_lanes(pos, triangles, topo, vertices, origin)
}

#[inline(always)]
fn vertex_sums_lanes<P: Positions + ?Sized>(
    pos: &P,
    triangles: &[[u32; 3]],
    topo: &Topology,
    vertices: Range<u32>,
    origin: DVec3,
) -> VertexSums {
    // Plain slices: the topology's own accessors ask at every call where an array lives.
    let parts = topo.parts();
    let mut all = VertexSums::default();
    let mut wide: Vec<EdgeFaces> = Vec::new();
    let mut angles = Angles::default();
    for i in vertices {
        let p = pos.at(i);
        all.extent = extent_union(all.extent, (p, p));
        let above = parts.neighbors(i);
        let above = &above[above.partition_point(|&j| j <= i)..];
        if above.is_empty() {
            continue;
        }
        for &j in above {
            all.edges.length.0 += p.distance(pos.at(j));
            all.edges.length.1 += 1;
        }
        // The faces into lanes, and the wide walk for a vertex with more.
        let (mut lanes, mut count) = ([0u32; LANES], 0);
        crate::for_each_face!(parts, i, triangles, u32::MAX, |t, _tri| {
            if let Some(lane) = lanes.get_mut(count) {
                *lane = t;
            }
            count += 1;
        });
        if count <= LANES {
            narrow_vertex(
                pos,
                triangles,
                &lanes[..count],
                i,
                above,
                origin,
                &mut all,
                &mut angles,
            );
        } else {
            wide.resize(above.len(), EdgeFaces::default());
            let slot = |v: u32| above.binary_search(&v).ok();
            let faces = parts.faces_of(i, triangles);
            add_faces(pos, triangles, faces, i, origin, &mut wide, slot, &mut all);
            for e in &wide {
                if e.count == 2 {
                    angles.push(e.normals, &mut all.edges);
                }
            }
        }
    }
    angles.add_to(&mut all.edges);
    all
}

/// Faces of a vertex that [`vertex_sums`] holds in the lanes of a [`Lanes`] and searches all at
/// once for an edge's (more: [`add_faces`]); surface meshes have 6 faces to a vertex.
const LANES: usize = 8;

/// [`vertex_sums`] at a vertex `i` with at most [`LANES`] faces: their corners after `i` and
/// their normals in lanes, and each edge `(i, j)` of `above` takes the faces whose lanes hold `j`
/// (compared all at once: no search, no branch to mispredict but the count's).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn narrow_vertex<P: Positions + ?Sized>(
    pos: &P,
    triangles: &[[u32; 3]],
    faces: &[u32],
    i: u32,
    above: &[u32],
    origin: DVec3,
    all: &mut VertexSums,
    angles: &mut Angles,
) {
    // No neighbour is u32::MAX: it marks the lanes past the faces.
    let (mut b, mut c) = ([u32::MAX; LANES], [u32::MAX; LANES]);
    let mut normals = [DVec3::ZERO; LANES];
    for (k, &t) in faces.iter().enumerate() {
        let tri = triangles[t as usize];
        (b[k], c[k]) = corners_after(tri, i);
        normals[k] = face_normal(pos, tri, origin, (b[k] > i) & (c[k] > i), all);
    }
    let (b, c) = (Lanes::new(&b), Lanes::new(&c));
    for &j in above {
        // A face of `i` holds `j` as one corner after `i` or the other.
        let holds = b.equal(j) | c.equal(j);
        if holds.count_ones() == 2 {
            let first = holds.trailing_zeros() as usize;
            let second = (holds & (holds - 1)).trailing_zeros() as usize;
            angles.push([normals[first], normals[second]], &mut all.edges);
        }
    }
}

/// The faces of `i` into `edges` (the edges `(i, j)` above `i`, at the slots `slot(j)` gives)
/// and, where `i` is a face's smallest corner, its determinant and area into `all`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn add_faces<P: Positions + ?Sized>(
    pos: &P,
    triangles: &[[u32; 3]],
    faces: impl Iterator<Item = u32>,
    i: u32,
    origin: DVec3,
    edges: &mut [EdgeFaces],
    slot: impl Fn(u32) -> Option<usize>,
    all: &mut VertexSums,
) {
    // Only the counts: a normal is read only where they say it was written.
    edges.iter_mut().for_each(|e| e.count = 0);
    for t in faces {
        let tri = triangles[t as usize];
        // Every corner of a face of `i` is a neighbour of `i`; those above it own the edges.
        let (b, c) = corners_after(tri, i);
        let (b_above, c_above) = (b > i, c > i);
        if !(b_above | c_above) {
            continue;
        }
        let n = face_normal(pos, tri, origin, b_above & c_above, all);
        for (v, is_above) in [(b, b_above), (c, c_above)] {
            if is_above && let Some(k) = slot(v) {
                edges[k].add(n);
            }
        }
    }
}

/// The normal `(p_b − p_a) × (p_c − p_a)` of `tri`; where the vertex at hand is its smallest
/// corner (`smallest`: the one place a face is counted), its determinant `(p_a − o) · n` and area
/// added to `all`.
#[inline(always)]
fn face_normal<P: Positions + ?Sized>(
    pos: &P,
    tri: [u32; 3],
    origin: DVec3,
    smallest: bool,
    all: &mut VertexSums,
) -> DVec3 {
    let [pa, pb, pc] = tri.map(|v| pos.at(v));
    let n = (pb - pa).cross(pc - pa);
    if smallest {
        all.determinants += (pa - origin).dot(n);
        all.doubled_area += n.length();
    }
    n
}

/// Whether a face normal gives an angle: non-zero and finite (`0 · x` is `±0` for a finite `x`
/// and NaN otherwise, a test without branches).
#[inline(always)]
fn usable([x, y, z]: [f64; 3]) -> bool {
    x * x + y * y + z * z > 0.0 && x * 0.0 + y * 0.0 + z * 0.0 == 0.0
}

/// Dihedral angles waiting in [`vertex_sums`]: taken in batches, the arithmetic of the angles
/// (the pass's longest chains of dependent instructions) runs in vector lanes without the walk
/// between them; the sum is the same, in the same order.
const ANGLE_BATCH: usize = 64;

/// The normal pairs of the dihedral angles waiting in [`vertex_sums`], coordinate by coordinate
/// (`[a.x, a.y, a.z, b.x, b.y, b.z]`), so that the batch's arithmetic fills vector lanes.
struct Angles {
    normals: [[f64; ANGLE_BATCH]; 6],
    len: usize,
}

impl Default for Angles {
    fn default() -> Angles {
        Angles {
            normals: [[0.0; ANGLE_BATCH]; 6],
            len: 0,
        }
    }
}

impl Angles {
    /// Queue the angle between `a` and `b` (counted if both are usable, see [`usable`]); a full
    /// batch is added to `sums` first. Inlined with the batch's arithmetic into the walk, so that
    /// it is compiled for the walk's instructions.
    #[inline(always)]
    fn push(&mut self, [a, b]: [DVec3; 2], sums: &mut EdgeSums) {
        if self.len == ANGLE_BATCH {
            self.add_to(sums);
        }
        let k = self.len;
        for (c, x) in [a.x, a.y, a.z, b.x, b.y, b.z].into_iter().enumerate() {
            self.normals[c][k] = x;
        }
        self.len += 1;
    }

    /// Add the waiting angles, in order, to `sums`.
    #[inline(always)]
    fn add_to(&mut self, sums: &mut EdgeSums) {
        // The arithmetic first for the whole batch (the unused tail too: no branch, and a value
        // that is never read), in vector lanes; then the sum of the angles between
        // usable normals (see [`usable`]), with the library where it must take over. The
        // arguments are [`angle_arguments`]'s, bit for bit.
        let [ax, ay, az, bx, by, bz] = &self.normals;
        let mut args = [(0.0, 0.0); ANGLE_BATCH];
        let mut fast = [0.0; ANGLE_BATCH];
        // 0: not counted, 1: the fast arithmetic's, 2: the library's.
        let mut how = [0u8; ANGLE_BATCH];
        for k in 0..ANGLE_BATCH {
            let (cx, cy, cz) = (
                ay[k] * bz[k] - by[k] * az[k],
                az[k] * bx[k] - bz[k] * ax[k],
                ax[k] * by[k] - bx[k] * ay[k],
            );
            let y = (cx * cx + cy * cy + cz * cz).sqrt();
            let x = ax[k] * bx[k] + ay[k] * by[k] + az[k] * bz[k];
            args[k] = (y, x);
            fast[k] = fast_arithmetic((y, x));
            let counted = usable([ax[k], ay[k], az[k]]) & usable([bx[k], by[k], bz[k]]);
            how[k] = counted as u8 * (2 - fast_covers((y, x)) as u8);
        }
        for k in 0..self.len {
            sums.angle.0 += match how[k] {
                0 => continue,
                1 => fast[k],
                _ => degrees_of(args[k]),
            };
            sums.angle.1 += 1;
        }
        self.len = 0;
    }
}

/// The faces of one edge as [`vertex_sums`] finds them at a vertex with many faces: how many,
/// and the first two's normals.
#[derive(Clone, Copy, Default)]
struct EdgeFaces {
    normals: [DVec3; 2],
    count: u32,
}

impl EdgeFaces {
    #[inline]
    fn add(&mut self, n: DVec3) {
        if let Some(slot) = self.normals.get_mut(self.count as usize) {
            *slot = n;
        }
        self.count += 1;
    }
}

/// The angle between two non-zero vectors, in degrees.
pub(crate) fn angle_deg(a: DVec3, b: DVec3) -> f64 {
    degrees_of(angle_arguments(a, b))
}

/// The two arguments of [`angle_deg`]'s arctangent, `(|a × b|, a · b)`: accurate near 0° and 180°.
fn angle_arguments(a: DVec3, b: DVec3) -> (f64, f64) {
    (a.cross(b).length(), a.dot(b))
}

/// The angle of [`angle_arguments`], in degrees.
fn degrees_of((y, x): (f64, f64)) -> f64 {
    y.atan2(x).to_degrees()
}

/// Whether [`fast_arithmetic`] gives the angle of `(y, x)`: `y ≥ +0`, neither argument NaN or
/// infinite, not both zero (and `y + |x|` finite: the library takes the few pairs near the
/// largest double too).
#[inline]
fn fast_covers((y, x): (f64, f64)) -> bool {
    let s = y + x.abs();
    !y.is_sign_negative() && s > 0.0 && s < f64::INFINITY
}

/// [`degrees_of`] within a few units in the last place (relative error below 1e-15, see the
/// tests), for the roughness's millions of angles: the library's `atan2` was most of its pass.
/// Cephes' arctangent (S. L. Moshier): the angle of `(y, x)` folded into `[0°, 45°]` and reduced
/// to `−0.21 < u ≤ 0.66`, where a degree-4/5 rational function is exact to double precision; the
/// reduction is exact but for one rounding of `u`. Without a branch (selects), for the arguments
/// that [`fast_covers`]; anything for others (zeros, infinities, NaN and negative `y`, never from
/// [`angle_arguments`] with usable normals, go to the library).
// The coefficients as Cephes publishes them (more digits than an f64 holds).
#[allow(clippy::excessive_precision)]
#[inline]
fn fast_arithmetic((y, x): (f64, f64)) -> f64 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    const P: [f64; 5] = [
        -8.750608600031904122785e-1,
        -1.615753718733365076637e1,
        -7.500855792314704667340e1,
        -1.228866684490136173410e2,
        -6.485021904942025371773e1,
    ];
    const Q: [f64; 5] = [
        2.485846490142306297962e1,
        1.650270098316988542046e2,
        4.328810604912902668951e2,
        4.853903996359136964868e2,
        1.945506571482613964425e2,
    ];
    // π/2 − FRAC_PI_2: what the constants lack, added after the subtractions.
    const MOREBITS: f64 = 6.123233995736765886130e-17;
    let ax = x.abs();
    let steep = y > ax;
    let (lo, hi) = if steep { (ax, y) } else { (y, ax) };
    // atan(lo/hi) = π/4 + atan((lo − hi)/(lo + hi)) above lo/hi = 0.66.
    let big = lo > 0.66 * hi;
    let (num, den) = if big { (lo - hi, lo + hi) } else { (lo, hi) };
    let u = num / den;
    let z = u * u;
    let p = (((P[0] * z + P[1]) * z + P[2]) * z + P[3]) * z + P[4];
    let q = ((((z + Q[0]) * z + Q[1]) * z + Q[2]) * z + Q[3]) * z + Q[4];
    let r = u + u * (z * p / q);
    let r = if big {
        FRAC_PI_4 + (r + 0.5 * MOREBITS)
    } else {
        r
    };
    let r = if steep { (FRAC_PI_2 - r) + MOREBITS } else { r };
    let r = if x < 0.0 {
        (PI - r) + 2.0 * MOREBITS
    } else {
        r
    };
    r.to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{add_normal_noise, icosphere};

    /// One angle as [`vertex_sums`] takes it: [`fast_arithmetic`] where it covers, else the
    /// library.
    fn degrees_of_fast(args: (f64, f64)) -> f64 {
        match fast_covers(args) {
            true => fast_arithmetic(args),
            false => degrees_of(args),
        }
    }

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
    fn the_component_forest_goes_where_the_storage_puts_it() {
        // Two spheres apart: two components, counted the same from a scratch file.
        let a = icosphere(3);
        let mut tris = a.triangles.to_vec();
        let n = a.positions.len() as u32;
        tris.extend(a.triangles.iter().map(|t| t.map(|v| v + n)));
        let count = |storage: &Storage| {
            components(2 * n as usize, &tris, storage, &Meter::default()).unwrap()
        };
        let heap = count(&Storage::heap());
        let dir = tempfile::tempdir().unwrap();
        let scratch = Storage::scratch(dir.path()).unwrap();
        let mapped = count(&scratch);
        assert_eq!((heap, mapped), (2, 2));
        assert_eq!(
            scratch.mapped_bytes(),
            4 * 2 * n as u64,
            "one u32 per vertex, mapped"
        );
    }

    #[test]
    fn a_face_out_of_range_is_an_error_not_a_panic() {
        let count = components(
            3,
            &[[0, 1, 2], [0, 1, 5]],
            &Storage::heap(),
            &Meter::default(),
        );
        assert!(count.is_err());
    }

    #[test]
    fn components_are_counted_the_same_for_any_thread_count() {
        // 60 spheres whose vertex ids are shuffled together (so that every chunk holds pieces of
        // many), every third joined to the next by a triangle, and a few unreferenced vertices:
        // the union-find over the faces against a search over the topology, on 1, 2 and 4
        // threads.
        let s = icosphere(3);
        let (n, k) = (s.positions.len() as u32, 60u32);
        let total = n * k + 5;
        let perm = crate::shapes::permutation(total as usize, 7);
        let id = |v: u32| perm[v as usize];
        let mut tris: Vec<[u32; 3]> = (0..k)
            .flat_map(|c| s.triangles.iter().map(move |t| t.map(|v| v + c * n)))
            .collect();
        tris.extend(
            (0..k - 1)
                .step_by(3)
                .map(|c| [c * n, c * n + 1, (c + 1) * n]),
        );
        // Degenerate faces join nothing: not two spheres, not two unreferenced vertices.
        tris.push([n, n, 2 * n]);
        tris.push([n * k, n * k + 1, n * k]);
        let tris: Vec<[u32; 3]> = tris.iter().map(|t| t.map(id)).collect();
        let t = Topology::build(total as usize, &tris).unwrap();
        let mut seen = vec![false; total as usize];
        let mut expected = 0;
        for start in 0..total {
            if seen[start as usize] || t.deg(start) == 0 {
                continue;
            }
            expected += 1;
            let mut stack = vec![start];
            seen[start as usize] = true;
            while let Some(v) = stack.pop() {
                for &u in t.neighbors(v) {
                    if !std::mem::replace(&mut seen[u as usize], true) {
                        stack.push(u);
                    }
                }
            }
        }
        assert_eq!(expected, 60 - 20);
        for threads in [1, 2, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let counted = pool.install(|| {
                components(total as usize, &tris, &Storage::heap(), &Meter::default()).unwrap()
            });
            assert_eq!(counted, expected, "{threads} threads");
        }
    }

    #[test]
    fn open_fan_has_boundary_and_one_component() {
        // Centre 0, rim 1..=5, four triangles not closing the fan: spokes 0-1 and 0-5 and the
        // four rim edges are boundary.
        let pos = (0..6)
            .map(|k| DVec3::new(k as f64, (k * k) as f64, 0.0))
            .collect();
        let m = Mesh::new(pos, (1..=4).map(|k| [0, k, k + 1]).collect());
        let i = info(&m, &topo(&m)).unwrap();
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
        let i = info(&m, &topo(&m)).unwrap();
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
        let i = info(&m, &topo(&m)).unwrap();
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
        let i = info(&m, &t).unwrap();
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
        // Only edge 0-1 counts.
        let angles = |range| {
            let s = vertex_sums(&m.positions[..], &m.triangles, &t, range, DVec3::ZERO);
            s.edges.angle.1
        };
        assert_eq!(angles(0..1), 1);
        assert_eq!(angles(1..5), 0);
    }

    /// [`vertex_sums`] against the plain definition: each vertex `i` in ascending order, its
    /// faces whose smallest corner it is (volume and area), each edge `(i, j)`, `i < j`, ascending;
    /// its faces looked for among all faces of `i`; an angle when there are exactly two, both with
    /// a usable normal. Bit for bit (with the same arctangent, the library's held to it apart, and
    /// the determinant as `(p_a − o) · n`; `tests/engine.rs` holds both to the plain formulas),
    /// on a mesh with every special case: a hub above the small-degree search, a non-manifold
    /// fin, a boundary, a zero-area face, a degenerate face, flipped faces.
    #[test]
    fn vertex_sums_match_the_definition_bit_for_bit() {
        let mut m = icosphere(3);
        add_normal_noise(&mut m, 0.2, 7);
        // A hole (a boundary) and a duplicate face (non-manifold edges).
        m.triangles[0] = m.triangles[1];
        let n = m.positions.len() as u32;
        // A hub: a fan of 40 faces around vertex 0 over other vertices of the sphere, so that
        // it has more than 16 neighbours above it.
        let ring: Vec<u32> = (100..141).map(|k| 3 * k + k % 5).collect();
        for w in ring.windows(2) {
            m.triangles.push([0, w[0], w[1]]);
        }
        // A fin on an edge (non-manifold), a zero-area face, flipped faces.
        m.positions.push(DVec3::new(2.0, 2.0, 2.0));
        let [a, b, _] = m.triangles[5];
        m.triangles.push([a, b, n]);
        m.positions.push(m.positions[0]);
        m.triangles.push([0, 1, n + 1]);
        for t in m.triangles.iter_mut().step_by(17) {
            t.swap(0, 1);
        }
        m.triangles.push([3, 7, 3]);
        let t = topo(&m);
        let pos: &[DVec3] = &m.positions;
        let origin = DVec3::new(0.1, -0.2, 0.3);
        let definition = |vertices: Range<u32>| {
            let mut expected = VertexSums::default();
            let normal = |tri: [u32; 3]| {
                let [a, b, c] = tri.map(|v| pos[v as usize]);
                (b - a).cross(c - a)
            };
            for i in vertices {
                let p = pos[i as usize];
                expected.extent = extent_union(expected.extent, (p, p));
                for f in t.faces_of(i, &m.triangles) {
                    let tri = m.triangles[f as usize];
                    if tri.iter().all(|&v| v >= i) {
                        let a = pos[tri[0] as usize] - origin;
                        expected.determinants += a.dot(normal(tri));
                        expected.doubled_area += normal(tri).length();
                    }
                }
                for &j in t.neighbors(i).iter().filter(|&&j| j > i) {
                    let e = &mut expected.edges;
                    e.length.0 += p.distance(pos[j as usize]);
                    e.length.1 += 1;
                    let normals: Vec<DVec3> = t
                        .faces_of(i, &m.triangles)
                        .map(|f| m.triangles[f as usize])
                        .filter(|tri| tri.contains(&j))
                        .map(normal)
                        .collect();
                    let usable = |n: &DVec3| n.length_squared() > 0.0 && n.is_finite();
                    if normals.len() == 2 && normals.iter().all(usable) {
                        let args = angle_arguments(normals[0], normals[1]);
                        e.angle.0 += degrees_of_fast(args);
                        e.angle.1 += 1;
                    }
                }
            }
            expected
        };
        assert!(t.neighbors(0).len() > 17, "the hub takes the binary search");
        assert!(t.stats.non_manifold_edges > 0 && t.stats.boundary_edges > 0);
        assert!(t.stats.degenerate_triangles > 0);
        let bits = |s: VertexSums| {
            let e = s.edges;
            let (lo, hi) = s.extent;
            [
                s.determinants.to_bits(),
                s.doubled_area.to_bits(),
                e.length.0.to_bits(),
                e.length.1 as u64,
                e.angle.0.to_bits(),
                e.angle.1 as u64,
            ]
            .into_iter()
            .chain([lo, hi].iter().flat_map(|v| v.to_array().map(f64::to_bits)))
            .collect::<Vec<u64>>()
        };
        let n = t.len() as u32;
        // Vertex by vertex too, so that an angle given to another edge of its vertex is caught.
        for range in (0..n).map(|i| i..i + 1).chain(std::iter::once(0..n)) {
            let (got, expected) = (
                vertex_sums(pos, &m.triangles, &t, range.clone(), origin),
                definition(range.clone()),
            );
            assert_eq!(bits(got), bits(expected), "vertices {range:?}");
        }
        // Read as `f32`, the bits of the positions rounded first.
        let rounded: Vec<DVec3> = pos.iter().map(|p| p.as_vec3().as_dvec3()).collect();
        assert!(rounded.iter().zip(pos.iter()).any(|(a, b)| a != b));
        let (got, expected) = (
            vertex_sums(&AsF32(pos), &m.triangles, &t, 0..n, origin),
            vertex_sums(&rounded[..], &m.triangles, &t, 0..n, origin),
        );
        assert_eq!(bits(got), bits(expected), "read as f32");
    }

    /// The arctangent of the roughness against the library's: within 1e-15 relative over the
    /// whole half-turn (tiny angles, both folds of the reduction, near 90° and 180°, scales far
    /// from 1), and the library's own answers where it hands over.
    #[test]
    fn the_fast_arctangent_follows_the_library() {
        let mut next = crate::shapes::uniform(11);
        let mut angles: Vec<f64> = (0..200_000)
            .map(|_| next() * std::f64::consts::PI)
            .collect();
        angles.extend((0..2000).map(|k| 10f64.powf(-(k as f64) / 100.0)));
        angles.extend((0..2000).map(|k| std::f64::consts::PI - 10f64.powf(-(k as f64) / 150.0)));
        for k in 0..4000 {
            // Around the folds: 45°, 90°, 135°, and the reduction's switch at atan(0.66).
            let at = [0.25, 0.5, 0.75][k % 3] * std::f64::consts::PI;
            angles.push(at + (next() - 0.5) * 1e-6);
            angles.push(0.66f64.atan() + (next() - 0.5) * 1e-9);
        }
        for (k, a) in angles.into_iter().enumerate() {
            let scale = 10f64.powi((k % 41) as i32 - 20);
            let (y, x) = (a.sin() * scale, a.cos() * scale);
            let (fast, library) = (degrees_of_fast((y, x)), degrees_of((y, x)));
            assert!(
                (fast - library).abs() <= 1e-15 * library.abs(),
                "angle {a}: {fast} against {library}"
            );
        }
        for args in [
            (0.0, 1.0),
            (0.0, -1.0),
            (1.0, 0.0),
            (1.0, -0.0),
            (-0.0, -1.0),
            (0.0, 0.0),
            (f64::INFINITY, 1.0),
            (1.0, f64::NEG_INFINITY),
            (f64::INFINITY, f64::INFINITY),
            (f64::NAN, 1.0),
            (1.0, f64::NAN),
            (-1.0, -1.0),
        ] {
            let (fast, library) = (degrees_of_fast(args), degrees_of(args));
            assert!(
                fast.to_bits() == library.to_bits() || (fast - library).abs() <= 1e-15 * library,
                "{args:?}: {fast} against {library}"
            );
        }
    }
}
