//! Pure shapes: the meshes `vcsmooth generate`, `demo`, `bench` and the tests start from. No
//! files here: writing them is [`crate::io`]'s (see [`crate::io::write_mesh`] and, for the
//! streamed [`Subdivision`], [`crate::io::write_ply_streamed`]).
//!
//! - [`octahedron`]: the unit octahedron, 8 triangles.
//! - [`icosphere`]: the unit sphere (radius 1, centred at the origin), `20·4^k` triangles.
//! - [`torus`]: around the z axis, major radius 1, minor radius 0.4, `256·4^k` triangles.
//! - [`add_normal_noise`]: seeded Gaussian noise along the vertex normals, σ × the mean edge length.
//! - [`Subdivision`]: a base mesh split flat into `4^L` triangles per triangle, produced one
//!   vertex and one triangle at a time (for outputs larger than memory), or in memory
//!   ([`Subdivision::to_mesh`]).
//!
//! Orientation: faces are counter-clockwise seen from outside, so the right-hand normal
//! `(b − a) × (c − a)` points outward and a closed shape has positive signed volume
//! ([`crate::metrics::volume`]). Lengths are in the shapes' own units (the sphere's radius is 1).
//!
//! [`icosphere`] and [`torus`] return closed, outward-oriented manifold meshes without duplicate
//! vertices, with `source.input_faces` set to their triangle count and no other source layout
//! (they are written as a plain `x y z` + triangle list). The noise uses its own tiny seeded
//! generator (splitmix64 + Box–Muller), so a seed gives the same mesh on every run and platform.

use std::collections::HashMap;

use glam::DVec3;

use crate::mesh::Mesh;
use crate::metrics::mean_edge_length;
use crate::topology::Topology;

/// The unit octahedron: vertices `±x, ±y, ±z` (in that order: `+x, −x, +y, −y, +z, −z`), 8
/// outward triangles, every vertex of degree 4. The smallest closed mesh on which every stencil
/// has a full 1-ring: the tests' fixture.
pub fn octahedron() -> Mesh {
    let positions = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ]
    .map(DVec3::from_array)
    .to_vec();
    let triangles = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    let mut mesh = Mesh::new(positions, triangles);
    mesh.source.input_faces = mesh.triangles.len();
    mesh
}

/// Largest subdivision level [`icosphere`] accepts: `20·4^12` ≈ 335 M triangles, the last level
/// whose vertex and triangle counts fit the crate's 32-bit indices with room to spare.
pub const ICOSPHERE_MAX_SUBDIVISIONS: u32 = 12;

/// Largest subdivision level [`torus`] accepts: `256·4^10` ≈ 268 M triangles.
pub const TORUS_MAX_SUBDIVISIONS: u32 = 10;

/// Unit icosphere centred at the origin, outward-oriented: `10·4^k + 2` vertices, `20·4^k` triangles
/// (k = 2 gives the paper's 162-vertex sphere).
///
/// Built from the regular icosahedron by `k` rounds of midpoint subdivision (every triangle split
/// into four, new vertices pushed onto the sphere), so every vertex is at radius 1 up to rounding.
/// Vertex order: the 12 icosahedron corners, then each level's edge midpoints in ascending
/// `(lower id, higher id)` order of their edge.
///
/// # Panics
/// If `subdivisions > ICOSPHERE_MAX_SUBDIVISIONS`.
pub fn icosphere(subdivisions: u32) -> Mesh {
    assert!(
        subdivisions <= ICOSPHERE_MAX_SUBDIVISIONS,
        "icosphere: {subdivisions} subdivisions exceed the maximum of {ICOSPHERE_MAX_SUBDIVISIONS}"
    );
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let corners = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut positions: Vec<DVec3> = corners
        .iter()
        .map(|&c| DVec3::from_array(c).normalize())
        .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        triangles = subdivide_on_sphere(&mut positions, &triangles);
    }
    generated(positions, triangles)
}

/// One round of midpoint subdivision of a closed, consistently oriented mesh whose vertices lie
/// on the unit sphere: appends one vertex per edge (projected onto the sphere) to `positions` and
/// returns the four children of every triangle, in the parent's order and orientation.
///
/// Edge ids come from a CSR of the half-edges `a → b` with `a < b`: in a closed oriented manifold
/// every undirected edge is exactly one such half-edge, so no hash map is needed.
fn subdivide_on_sphere(positions: &mut Vec<DVec3>, triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let n = positions.len();
    let mut offsets = vec![0usize; n + 1];
    for t in triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            if a < b {
                offsets[a as usize + 1] += 1;
            }
        }
    }
    for v in 0..n {
        offsets[v + 1] += offsets[v];
    }
    let mut upper = vec![0u32; offsets[n]];
    let mut cursor = offsets.clone();
    for t in triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            if a < b {
                upper[cursor[a as usize]] = b;
                cursor[a as usize] += 1;
            }
        }
    }
    drop(cursor);
    for v in 0..n {
        upper[offsets[v]..offsets[v + 1]].sort_unstable();
    }

    positions.reserve(upper.len());
    for a in 0..n {
        for &b in &upper[offsets[a]..offsets[a + 1]] {
            let m = (positions[a] + positions[b as usize]).normalize();
            positions.push(m);
        }
    }

    let midpoint = |a: u32, b: u32| -> u32 {
        let (lo, hi) = if a < b {
            (a as usize, b)
        } else {
            (b as usize, a)
        };
        let row = &upper[offsets[lo]..offsets[lo + 1]];
        let k = row.binary_search(&hi).expect(
            "icosphere subdivision: every edge of a closed oriented mesh has an a<b half-edge",
        );
        (n + offsets[lo] + k) as u32
    };
    let mut out = Vec::with_capacity(triangles.len() * 4);
    for &[a, b, c] in triangles {
        let (ab, bc, ca) = (midpoint(a, b), midpoint(b, c), midpoint(c, a));
        out.push([a, ab, ca]);
        out.push([b, bc, ab]);
        out.push([c, ca, bc]);
        out.push([ab, bc, ca]);
    }
    out
}

/// Closed torus around the z axis (major radius 1, minor radius 0.4), outward-oriented, a regular
/// grid whose resolution doubles with each subdivision level.
///
/// The grid has `16·2^k` vertices around the z axis and `8·2^k` around the tube: `128·4^k`
/// vertices and `256·4^k` triangles. Vertex `i·(8·2^k) + j` sits at angle `2πi/(16·2^k)` around
/// z and `2πj/(8·2^k)` around the tube (angle 0 on the outer equator).
///
/// # Panics
/// If `subdivisions > TORUS_MAX_SUBDIVISIONS`.
pub fn torus(subdivisions: u32) -> Mesh {
    assert!(
        subdivisions <= TORUS_MAX_SUBDIVISIONS,
        "torus: {subdivisions} subdivisions exceed the maximum of {TORUS_MAX_SUBDIVISIONS}"
    );
    const MAJOR: f64 = 1.0;
    const MINOR: f64 = 0.4;
    let nu = 16u32 << subdivisions; // around the z axis
    let nv = 8u32 << subdivisions; // around the tube
    let tau = std::f64::consts::TAU;
    let mut positions = Vec::with_capacity(nu as usize * nv as usize);
    for i in 0..nu {
        let (st, ct) = (tau * i as f64 / nu as f64).sin_cos();
        for j in 0..nv {
            let (sp, cp) = (tau * j as f64 / nv as f64).sin_cos();
            let rho = MAJOR + MINOR * cp;
            positions.push(DVec3::new(rho * ct, rho * st, MINOR * sp));
        }
    }
    let id = |i: u32, j: u32| (i % nu) * nv + (j % nv);
    let mut triangles = Vec::with_capacity(2 * positions.len());
    for i in 0..nu {
        for j in 0..nv {
            // (∂/∂θ) × (∂/∂φ) points out of the tube, so (θ, φ) counter-clockwise is outward.
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    generated(positions, triangles)
}

/// A generated mesh: no source layout except the face count.
fn generated(positions: Vec<DVec3>, triangles: Vec<[u32; 3]>) -> Mesh {
    let mut mesh = Mesh::new(positions, triangles);
    mesh.source.input_faces = mesh.triangles.len();
    mesh
}

/// A random permutation of `0..n` (a xorshift Fisher–Yates, deterministic per seed): for tests
/// that renumber a mesh's vertices so that its neighbourhoods are scattered.
#[cfg(test)]
pub(crate) fn permutation(n: usize, seed: u64) -> Vec<u32> {
    let mut perm: Vec<u32> = (0..n as u32).collect();
    let mut x = seed | 1;
    for i in (1..n).rev() {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        perm.swap(i, (x % (i as u64 + 1)) as usize);
    }
    perm
}

/// A noisy icosphere of `level` (noise 0.3, `seed`) opened by dropping the faces around vertex 0,
/// its triangles turned to put their smallest corner first and sorted by it (the plan's layout):
/// its positions and triangles, for kernel tests with a border.
#[cfg(test)]
pub(crate) fn open_sorted_sphere(level: u32, seed: u64) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let mut mesh = icosphere(level);
    add_normal_noise(&mut mesh, 0.3, seed);
    let mut tris: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .filter(|t| !t.contains(&0))
        .map(|&[a, b, c]| match a.min(b).min(c) {
            m if m == a => [a, b, c],
            m if m == b => [b, c, a],
            _ => [c, a, b],
        })
        .collect();
    tris.sort_by_key(|t| t[0]);
    (mesh.positions.to_vec(), tris)
}

/// Numbers in [0, 1) from a 64-bit linear congruential generator (Knuth's MMIX constants, the
/// top 53 bits), deterministic per seed: for tests that want many values and no dependency.
#[cfg(test)]
pub(crate) fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Displace every vertex along its (area-weighted) normal by Gaussian noise of standard deviation
/// `sigma` × the mean edge length; deterministic for a seed.
///
/// - Normals: the sum of the (unnormalised, i.e. area-weighted) normals of a vertex's triangles,
///   normalised; a vertex whose sum is zero or not finite (unreferenced, or cancelling) keeps its
///   position, so no NaN is ever produced.
/// - One N(0, 1) sample is drawn per vertex in vertex order (also for vertices that do not move),
///   from splitmix64(`seed`) through Box–Muller; the same seed gives a bit-identical mesh.
/// - `sigma == 0` (or a non-finite `sigma`, or a mesh whose triangles index vertices out of range)
///   leaves the positions bit-identical.
pub fn add_normal_noise(mesh: &mut Mesh, sigma: f64, seed: u64) {
    if sigma == 0.0 || !sigma.is_finite() || mesh.positions.is_empty() {
        return;
    }
    let Ok(topo) = Topology::build(mesh.positions.len(), &mesh.triangles) else {
        return;
    };
    let scale = sigma * mean_edge_length(&mesh.positions, &topo);
    if scale == 0.0 || !scale.is_finite() {
        return;
    }

    let pos = &mut mesh.positions;
    let mut normals = vec![DVec3::ZERO; pos.len()];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        let n = (b - a).cross(c - a); // |n| = 2 × area
        for &v in t {
            normals[v as usize] += n;
        }
    }
    let mut rng = Gaussian::new(seed);
    for (p, n) in pos.iter_mut().zip(&normals) {
        let z = rng.sample();
        if let Some(n) = n.try_normalize() {
            let moved = *p + n * (scale * z);
            if moved.is_finite() {
                *p = moved;
            }
        }
    }
}

/// Largest level [`Subdivision`] accepts: every base triangle becomes `4^15` ≈ 1.1·10⁹ triangles.
pub const SUBDIVIDE_MAX_LEVELS: u32 = 15;

/// Flat subdivision of a base mesh, every triangle split into `s²` (s = 2^`levels`), produced one
/// vertex and one triangle at a time, so that a writer can stream meshes of hundreds of millions
/// of triangles from a real scan: memory is the base mesh and its edge table, never the output.
///
/// - New vertices lie on the base triangles (a flat lattice: `A + i/s (B − A) + j/s (C − A)` in
///   triangle `(A, B, C)`), shared along base edges, so a closed manifold base gives a closed
///   manifold output with the same orientation, and without noise the same volume.
/// - Vertex ids: the base vertices, then `s − 1` per base edge (edges in ascending `(i, j)` order,
///   points numbered from the lower end), then the interior lattice points of each base triangle
///   (row `j = 1..s`, then `i = 1..s−j`). [`Subdivision::for_each_vertex`] gives them in id order.
/// - Triangles: the `s²` children of each base triangle in turn, in the parent's orientation.
/// - Noise (`sigma > 0`): each vertex moves along its normal (the area-weighted base vertex
///   normal, the sum of the edge's face normals, or the face normal) by Gaussian noise of standard
///   deviation `sigma` × (base mean edge length / s), drawn from a hash of the seed and the vertex
///   id, so a vertex's position does not depend on the order it is produced in.
/// - Degenerate base triangles (a repeated index) are dropped.
pub struct Subdivision<'a> {
    positions: &'a [DVec3],
    /// The base triangles that are not degenerate.
    faces: Vec<[u32; 3]>,
    /// Undirected base edges `[lo, hi]`, ascending, and each one's index.
    edges: Vec<[u32; 2]>,
    edge_id: HashMap<(u32, u32), u64>,
    /// Area-weighted normals of the noise: per face, per base vertex, per edge.
    face_normals: Vec<DVec3>,
    vertex_normals: Vec<DVec3>,
    edge_normals: Vec<DVec3>,
    /// Pieces per base edge, `2^levels`.
    s: u64,
    /// Standard deviation of the noise (0: none).
    scale: f64,
    seed: u64,
    vertices: u64,
    triangles: u64,
}

impl<'a> Subdivision<'a> {
    /// Prepares the subdivision of `base` into `4^levels` triangles per base triangle.
    ///
    /// # Errors
    /// [`crate::Error::Parameter`] (`subdivision_levels`) when `levels > SUBDIVIDE_MAX_LEVELS`,
    /// [`crate::Error::Topology`] when the output's vertex or triangle count does not fit 32-bit
    /// indices; the topology's error when `base` has none.
    pub fn new(base: &'a Mesh, levels: u32, sigma: f64, seed: u64) -> crate::Result<Self> {
        if levels > SUBDIVIDE_MAX_LEVELS {
            return Err(crate::Error::parameter(
                "subdivision_levels",
                format!("must be at most {SUBDIVIDE_MAX_LEVELS}, got {levels}"),
            ));
        }
        let s = 1u64 << levels;
        let topo = Topology::build(base.positions.len(), &base.triangles)?;
        let pos: &[DVec3] = &base.positions;
        let faces: Vec<[u32; 3]> = base
            .triangles
            .iter()
            .copied()
            .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .collect();
        let edges: Vec<[u32; 2]> = topo.edges().collect();
        let edge_id: HashMap<(u32, u32), u64> = edges
            .iter()
            .enumerate()
            .map(|(e, &[a, b])| ((a, b), e as u64))
            .collect();
        let per_edge = s - 1;
        let per_face = (s - 1) * s.saturating_sub(2) / 2;
        let vertices =
            pos.len() as u64 + edges.len() as u64 * per_edge + faces.len() as u64 * per_face;
        let triangles = faces.len() as u64 * s * s;
        if vertices > u32::MAX as u64 || triangles > u32::MAX as u64 {
            return Err(crate::Error::topology(format!(
                "{levels} subdivision levels make {vertices} vertices and {triangles} triangles, beyond 32-bit indices"
            )));
        }

        let face_normals: Vec<DVec3> = faces
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| pos[v as usize]);
                (b - a).cross(c - a)
            })
            .collect();
        let mut vertex_normals = vec![DVec3::ZERO; pos.len()];
        let mut edge_normals = vec![DVec3::ZERO; edges.len()];
        for (t, n) in faces.iter().zip(&face_normals) {
            for k in 0..3 {
                vertex_normals[t[k] as usize] += *n;
                let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                edge_normals[edge_id[&(a, b)] as usize] += *n;
            }
        }
        let scale = sigma * mean_edge_length(pos, &topo) / s as f64;
        Ok(Subdivision {
            positions: pos,
            faces,
            edges,
            edge_id,
            face_normals,
            vertex_normals,
            edge_normals,
            s,
            scale,
            seed,
            vertices,
            triangles,
        })
    }

    /// Vertices of the output.
    pub fn vertices(&self) -> u64 {
        self.vertices
    }

    /// Triangles of the output: `s²` × [`Subdivision::base_triangles`].
    pub fn triangles(&self) -> u64 {
        self.triangles
    }

    /// The base triangles that are subdivided (the non-degenerate ones).
    pub fn base_triangles(&self) -> usize {
        self.faces.len()
    }

    /// Pieces every base edge is split into, `s = 2^levels`.
    pub fn pieces(&self) -> u64 {
        self.s
    }

    /// Calls `f` with every output vertex position, in id order; stops at the first error.
    pub fn for_each_vertex<E>(
        &self,
        mut f: impl FnMut(DVec3) -> std::result::Result<(), E>,
    ) -> std::result::Result<(), E> {
        let (pos, s) = (self.positions, self.s);
        let nv = pos.len() as u64;
        for (v, p) in pos.iter().enumerate() {
            f(self.noisy(v as u64, *p, self.vertex_normals[v]))?;
        }
        for (e, &[a, b]) in self.edges.iter().enumerate() {
            let (pa, pb) = (pos[a as usize], pos[b as usize]);
            for k in 1..s {
                let id = nv + e as u64 * (s - 1) + (k - 1);
                f(self.noisy(
                    id,
                    pa + (pb - pa) * (k as f64 / s as f64),
                    self.edge_normals[e],
                ))?;
            }
        }
        for (t, tri) in self.faces.iter().enumerate() {
            let [a, b, c] = tri.map(|v| pos[v as usize]);
            for j in 1..s {
                for i in 1..s - j {
                    let p = a + (b - a) * (i as f64 / s as f64) + (c - a) * (j as f64 / s as f64);
                    f(self.noisy(self.id(t, i, j), p, self.face_normals[t]))?;
                }
            }
        }
        Ok(())
    }

    /// Calls `f` with every output triangle, in order; stops at the first error.
    pub fn for_each_triangle<E>(
        &self,
        mut f: impl FnMut([u32; 3]) -> std::result::Result<(), E>,
    ) -> std::result::Result<(), E> {
        let s = self.s;
        // Ids fit u32: `new` checked the vertex count.
        let tri = |q: [u64; 3]| q.map(|v| v as u32);
        for t in 0..self.faces.len() {
            for j in 0..s {
                for i in 0..s - j {
                    f(tri([
                        self.id(t, i, j),
                        self.id(t, i + 1, j),
                        self.id(t, i, j + 1),
                    ]))?;
                    if i + j + 1 < s {
                        f(tri([
                            self.id(t, i + 1, j),
                            self.id(t, i + 1, j + 1),
                            self.id(t, i, j + 1),
                        ]))?;
                    }
                }
            }
        }
        Ok(())
    }

    /// The whole output in memory, as a generated mesh (`source.input_faces` = its triangles).
    pub fn to_mesh(&self) -> Mesh {
        let mut positions = Vec::with_capacity(self.vertices as usize);
        let mut triangles = Vec::with_capacity(self.triangles as usize);
        let _ = self.for_each_vertex(|p| {
            positions.push(p);
            Ok::<_, std::convert::Infallible>(())
        });
        let _ = self.for_each_triangle(|t| {
            triangles.push(t);
            Ok::<_, std::convert::Infallible>(())
        });
        generated(positions, triangles)
    }

    /// `p` moved along `n` by the noise of vertex `id` (unmoved without noise, normal or a finite
    /// result).
    fn noisy(&self, id: u64, p: DVec3, n: DVec3) -> DVec3 {
        if self.scale == 0.0 || !self.scale.is_finite() {
            return p;
        }
        match n.try_normalize() {
            Some(n) => {
                let z = Gaussian::new(self.seed ^ id.wrapping_mul(0xD1B5_4A32_D192_ED03)).sample();
                let moved = p + n * (self.scale * z);
                if moved.is_finite() { moved } else { p }
            }
            None => p,
        }
    }

    /// Id of the point `k` pieces from base vertex `u` towards `v` on their edge (0 < k < s).
    fn edge_point(&self, u: u32, v: u32, k: u64) -> u64 {
        let (lo, hi, k) = if u < v { (u, v, k) } else { (v, u, self.s - k) };
        self.positions.len() as u64 + self.edge_id[&(lo, hi)] * (self.s - 1) + (k - 1)
    }

    /// Id of lattice point `(i, j)` of base face `t = (A, B, C)`: `A + i/s (B − A) + j/s (C − A)`.
    fn id(&self, t: usize, i: u64, j: u64) -> u64 {
        let s = self.s;
        let [a, b, c] = self.faces[t];
        match (i, j) {
            (0, 0) => a as u64,
            _ if i == s => b as u64,
            _ if j == s => c as u64,
            (_, 0) => self.edge_point(a, b, i),
            (0, _) => self.edge_point(a, c, j),
            _ if i + j == s => self.edge_point(b, c, j),
            _ => {
                let per_face = (s - 1) * s.saturating_sub(2) / 2;
                let interior = self.positions.len() as u64 + self.edges.len() as u64 * (s - 1);
                let row = (j - 1) * (s - 1) - (j - 1) * j / 2;
                interior + t as u64 * per_face + row + (i - 1)
            }
        }
    }
}

/// Standard normal samples from splitmix64 through the Box–Muller transform (both outputs used).
struct Gaussian {
    state: u64,
    spare: Option<f64>,
}

impl Gaussian {
    fn new(seed: u64) -> Self {
        Gaussian {
            state: seed,
            spare: None,
        }
    }

    /// splitmix64 (Steele, Lea, Flood 2014).
    fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1]: never 0, so its logarithm is finite.
    fn uniform_open0(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    fn sample(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        let r = (-2.0 * self.uniform_open0().ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * self.uniform_open0()).sin_cos();
        self.spare = Some(r * s);
        r * c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::{info, volume};
    use std::f64::consts::PI;

    #[test]
    fn subdivision_is_closed_keeps_the_surface_and_counts() {
        let base = icosphere(1);
        let sub = Subdivision::new(&base, 2, 0.0, 1).unwrap();
        assert_eq!((sub.pieces(), sub.base_triangles()), (4, 80));
        assert_eq!(sub.triangles(), 80 * 16);
        let m = sub.to_mesh();
        assert_eq!(m.positions.len() as u64, sub.vertices());
        assert_eq!(m.triangles.len() as u64, sub.triangles());
        let i = info(&m, &topo(&m)).unwrap();
        assert!(i.closed && i.components == 1 && i.non_manifold_vertices == 0);
        assert_eq!(i.vertices as i64 - i.edges as i64 + i.triangles as i64, 2);
        // The base vertices come first and unmoved; every new vertex lies on the base surface.
        assert_eq!(bits(&m)[..base.positions.len()], bits(&base)[..]);
        // Flat subdivision: the same volume as the base, same orientation.
        let (v0, v1) = (
            volume(&base.positions, &base.triangles),
            volume(&m.positions, &m.triangles),
        );
        assert!(v1 > 0.0 && ((v1 - v0) / v0).abs() < 1e-12, "{v0} vs {v1}");
        // Noise moves vertices, deterministically, and the same whatever the order of production.
        let noisy = Subdivision::new(&base, 2, 0.3, 9).unwrap().to_mesh();
        let again = Subdivision::new(&base, 2, 0.3, 9).unwrap().to_mesh();
        assert_eq!(bits(&noisy), bits(&again));
        assert_ne!(bits(&noisy), bits(&m));
        assert_eq!(noisy.triangles, m.triangles);
    }

    #[test]
    fn subdivision_level_zero_is_the_base_and_limits_are_refused() {
        let base = torus(0);
        let m = Subdivision::new(&base, 0, 0.0, 1).unwrap().to_mesh();
        assert_eq!(bits(&m), bits(&base));
        assert_eq!(m.triangles, base.triangles);
        let e = Subdivision::new(&base, SUBDIVIDE_MAX_LEVELS + 1, 0.0, 1)
            .err()
            .unwrap();
        assert!(e.to_string().contains("at most 15"), "{e}");
        let e = Subdivision::new(&base, 15, 0.0, 1).err().unwrap();
        assert!(e.to_string().contains("beyond 32-bit indices"), "{e}");
    }

    #[test]
    fn subdivision_drops_degenerate_base_triangles() {
        let base = Mesh::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::Y],
            vec![[0, 1, 2], [0, 0, 1]],
        );
        let sub = Subdivision::new(&base, 1, 0.0, 1).unwrap();
        assert_eq!(
            (sub.base_triangles(), sub.triangles(), sub.vertices()),
            (1, 4, 6)
        );
        let m = sub.to_mesh();
        for t in m.triangles.iter() {
            let [a, b, c] = t.map(|v| m.positions[v as usize]);
            assert!((b - a).cross(c - a).z > 0.0, "orientation kept");
        }
    }

    fn topo(m: &Mesh) -> Topology {
        Topology::build(m.positions.len(), &m.triangles).unwrap()
    }

    fn bits(m: &Mesh) -> Vec<[u64; 3]> {
        m.positions
            .iter()
            .map(|p| p.to_array().map(f64::to_bits))
            .collect()
    }

    #[test]
    fn icosphere_counts_and_closed_genus_zero() {
        for k in 0..=3 {
            let m = icosphere(k);
            let t = topo(&m);
            let (v, f) = (m.positions.len(), m.triangles.len());
            assert_eq!(v, 10 * 4usize.pow(k) + 2);
            assert_eq!(f, 20 * 4usize.pow(k));
            assert_eq!(t.stats.edges, 3 * f / 2);
            assert_eq!(
                v as i64 - t.stats.edges as i64 + f as i64,
                2,
                "genus 0 at k = {k}"
            );
            let i = info(&m, &t).unwrap();
            assert!(i.closed, "closed at k = {k}");
            assert_eq!(i.components, 1);
            assert_eq!(i.non_manifold_vertices, 0);
            assert_eq!(t.stats.fixed_vertices, 0);
            assert_eq!(m.source.input_faces, f);
        }
    }

    #[test]
    fn icosphere_2_is_the_papers_sphere() {
        let m = icosphere(2);
        assert_eq!(m.positions.len(), 162);
        assert_eq!(m.triangles.len(), 320);
        assert!(m.positions.iter().all(|p| (p.length() - 1.0).abs() < 1e-12));
        // Inscribed in the unit ball: below 4π/3, by 3.4 % at k = 2 (4.047), 0.9 % at k = 3.
        let exact = 4.0 * PI / 3.0;
        let v = volume(&m.positions, &m.triangles);
        assert!(v > 0.0, "outward orientation gives positive volume");
        assert!(
            v < exact && (exact - v) / exact < 0.04,
            "volume {v} vs {exact}"
        );
        let m3 = icosphere(3);
        let v3 = volume(&m3.positions, &m3.triangles);
        assert!(
            v3 > v && v3 < exact && (exact - v3) / exact < 0.01,
            "volume {v3} vs {exact}"
        );
        // Every triangle outward: its normal points away from the centre.
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            assert!((b - a).cross(c - a).dot(a + b + c) > 0.0);
        }
    }

    #[test]
    fn torus_is_closed_genus_one_outward() {
        let m = torus(2);
        let t = topo(&m);
        let i = info(&m, &t).unwrap();
        assert_eq!(m.positions.len(), 64 * 32);
        assert_eq!(m.triangles.len(), 2 * 64 * 32);
        assert!(i.closed);
        assert_eq!(i.components, 1);
        assert_eq!(t.stats.non_manifold_vertices, 0);
        assert_eq!(t.stats.fixed_vertices, 0);
        let chi = m.positions.len() as i64 - t.stats.edges as i64 + m.triangles.len() as i64;
        assert_eq!(chi, 0, "Euler characteristic of a torus");
        let exact = 2.0 * PI * PI * 1.0 * 0.4 * 0.4;
        assert!(i.volume > 0.0);
        assert!(
            (i.volume - exact).abs() / exact < 0.03,
            "volume {} vs {exact}",
            i.volume
        );
        // No duplicate vertices.
        let mut b = bits(&m);
        b.sort_unstable();
        b.dedup();
        assert_eq!(b.len(), m.positions.len());
    }

    #[test]
    fn noise_is_deterministic_per_seed() {
        let mut a = icosphere(2);
        let mut b = icosphere(2);
        let mut c = icosphere(2);
        add_normal_noise(&mut a, 0.3, 7);
        add_normal_noise(&mut b, 0.3, 7);
        add_normal_noise(&mut c, 0.3, 8);
        assert_eq!(bits(&a), bits(&b));
        assert_ne!(bits(&a), bits(&c));
        assert_ne!(bits(&a), bits(&icosphere(2)));
        assert!(a.positions.iter().all(|p| p.is_finite()));
        // The displacement is along the radius (the sphere's normal) with roughly the asked size.
        let h = mean_edge_length(&icosphere(2).positions, &topo(&a));
        let r2: f64 = a
            .positions
            .iter()
            .map(|p| (p.length() - 1.0).powi(2))
            .sum::<f64>();
        let rms = (r2 / a.positions.len() as f64).sqrt();
        assert!(rms > 0.15 * h && rms < 0.45 * h, "rms {rms} vs 0.3 × {h}");
    }

    #[test]
    fn zero_sigma_leaves_positions_bit_identical() {
        let mut m = torus(1);
        let before = bits(&m);
        add_normal_noise(&mut m, 0.0, 42);
        assert_eq!(bits(&m), before);
    }

    #[test]
    fn zero_normal_means_no_displacement() {
        // An unreferenced vertex and a doubled (cancelling) pair of triangles: no normal, no move.
        let mut m = Mesh::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::splat(5.0)],
            vec![[0, 1, 2], [0, 2, 1]],
        );
        let before = bits(&m);
        add_normal_noise(&mut m, 1.0, 3);
        assert_eq!(bits(&m), before);
    }

    #[test]
    fn gaussian_has_unit_variance() {
        let mut g = Gaussian::new(1);
        let n = 100_000;
        let xs: Vec<f64> = (0..n).map(|_| g.sample()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(
            mean.abs() < 0.02 && (var - 1.0).abs() < 0.02,
            "mean {mean} var {var}"
        );
    }
}
