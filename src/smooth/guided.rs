//! `vcs-guided`: a feature-preserving first step for Liu et al.'s 2-step approach (their §4:
//! "other operators can also be adopted in the first step"): guided normal filtering (Zhang et
//! al. 2015) of the face normals, the vertices moved to fit the filtered normals (Sun et al.
//! 2007), and the resulting displacement spread over 2-ring stencils, each of
//! which restores its faces' volume exactly ([`super::rings`]). A low-pass filter rounds the
//! edges of a machined part as it removes the noise; the normal filter does not average across an
//! edge, because its range weight compares *guidance* normals, each the mean normal of the most
//! consistent (flattest, least edge-crossing) patch next to the face, which stay apart across
//! an edge even where the noisy normals do not.
//!
//! One iteration on positions `P` (each step a Jacobi pass: every entry from the previous field,
//! so any split of the work gives the same bits):
//! 1. `n_f` = the unit normal of face `f`, `A_f` twice its area.
//! 2. [`NORMAL_ITERATIONS`] times: the consistency `H(P_j)` and the area-weighted mean normal
//!    `m_j` of every face's patch `P_j` (the faces that share a corner with `j`); the guidance
//!    `g_i = m_k` for the `k ∈ P_i` of least `H(P_k)` (or `n_i` itself if even that `H` is
//!    above [`GUIDANCE_LIMIT`]: at a corner, where every patch crosses an edge); then
//!    `n_i ← normalize(Σ_{j∈P_i} A_j K_s(|c_i − c_j|) K_r(|g_i − g_j|) n_j)`,
//!    `K(x) = exp(−x² / 2σ²)`, `σ_s` = [`SPACE_SCALE`] × the mean centroid distance of `i` to the
//!    rest of `P_i` (so the filter follows a scan's varying density), `σ_r` = [`SIGMA_RANGE`].
//! 3. [`VERTEX_ITERATIONS`] Jacobi steps `p_v += (1/|F_v|) Σ_{f∋v} n_f (n_f · (c_f − p_v))`:
//!    each vertex moves towards the planes of its faces' filtered normals (fixed vertices stay).
//! 4. The displacement `D` from `P` to the result of 3 is applied on 2-ring stencils
//!    ([`super::rings::shares_into`], [`super::rings::sweep_rings`]):
//!    volume exact, whatever step 3 did to it.
//!
//! `H(P) = D(P) · R(P)` (Zhang et al. eq. 4): `D` the largest difference of two unit normals in
//! `P`, `R = max φ / (ε + Σ φ)` over the edges `e` at the corners of the face, `φ(e)` the
//! difference of the unit normals of its two faces. A flat patch has `H = 0`; a patch across an
//! edge has a large `D`; a patch whose normals vary smoothly and a little everywhere (noise) has a
//! small `R`.

use glam::DVec3;

use super::method::Exec;
use crate::topology::TopologyParts;

// The defaults were chosen on the machined denoising pairs (tools/denoise_table.py): the largest
// ratio of the normal error to `taubin`'s over Fandisk 0.3/0.7, Block, SharpSphere and Twelve is
// least here (0.55); more filter iterations or a wider spatial weight flatten the curved parts of
// SharpSphere into facets, a narrower range weight leaves high noise (Fandisk 0.7) unfiltered.

/// Normal-filter iterations per iteration of the method.
pub const NORMAL_ITERATIONS: usize = 3;
/// Vertex-update steps per iteration of the method.
pub const VERTEX_ITERATIONS: usize = 5;
/// `σ_r`, the range of the normal filter's weight on guidance differences (unit normals, so
/// scale-free: 0.45 is a difference of about 26°).
pub const SIGMA_RANGE: f64 = 0.45;
/// `σ_s` over the mean distance of a face's centroid to those of its patch (scale-free).
pub const SPACE_SCALE: f64 = 0.5;
/// The consistency `H` above which a face is its own guidance. Next to a corner every patch
/// crosses an edge (a clean cube's corner faces have `H` ≈ 0.3), and the mean of such a patch,
/// as guidance, averages the corner's planes: the corner is cut a little more at each iteration.
/// Noisy flat patches stay below it up to Gaussian noise of 0.7 × the mean edge (Fandisk 0.7); at
/// 0.2 that pair loses a third of its gain, at 0.3 the cube's corners are cut again.
pub const GUIDANCE_LIMIT: f64 = 0.25;
/// Filter iterations before the crease test (`crease_angle` of [`crate::Options`]; see
/// `Plan::crease`), on the input's positions, with the range weight cut at the crease angle.
/// Chosen on the machined denoising pairs (tools/denoise_table.py) at 40°: with 3 iterations
/// Fandisk 0.7 has twice its 700 true crease vertices, with 10 about as many (655) as it has,
/// more change little. The cut keeps a clean mesh's edges as sharp as they are: without it,
/// ten iterations blend the 63° edges of the clean Twelve below 60° and none is found at 60°.
pub const CREASE_ITERATIONS: usize = 10;
/// Steps of [`fit_into`] that fit a copy of the input's positions to those filtered normals
/// before the crease test (`Plan::crease`). On Fandisk 0.7 the edges along a crease zigzag
/// across it (the median cosine of a true crease edge to its crease was 0.80, against 0.98
/// clean): on the input, 33 of the 57 line vertices found were on its creases; on the fitted
/// copy, with the checks of `Topology::crease`, 41 of 44 (docs/quality-research.md §19).
pub const CREASE_FIT_STEPS: usize = 5;
/// Filter iterations on the fitted copy, whose normals the crease test then reads.
pub const CREASE_REFILTER_ITERATIONS: usize = 3;
/// The `cut` of [`filter_into`] that cuts nothing (a cosine is never below it): `vcs-guided`'s.
pub const NO_CUT: f64 = -2.0;
/// `ε` of `R(P)`: keeps a flat patch's `R` at 0 instead of 0/0.
const EPSILON_R: f64 = 1e-12;

/// Face fields the method keeps beside the positions: the normals, the patches' mean normals
/// (then the filtered normals) and the guidance ([`super::method::Needs::face_vectors`]), and the
/// areas and the patches' consistencies ([`super::method::Needs::face_scalars`]).
pub const FACE_VECTORS: usize = 3;
pub const FACE_SCALARS: usize = 2;

/// The faces that share a corner with `t` (`t` among them), each once, into `out`: the fan of
/// each corner without the faces that hold an earlier corner.
fn patch_of(topo: &TopologyParts, tris: &[[u32; 3]], t: u32, out: &mut Vec<u32>) {
    out.clear();
    let [a, b, c] = tris[t as usize];
    out.extend(topo.faces_of(a, tris));
    out.extend(
        topo.faces_of(b, tris)
            .filter(|&f| !tris[f as usize].contains(&a)),
    );
    out.extend(topo.faces_of(c, tris).filter(|&f| {
        let tf = tris[f as usize];
        !tf.contains(&a) && !tf.contains(&b)
    }));
}

fn centroid(tris: &[[u32; 3]], pos: &[DVec3], t: u32) -> DVec3 {
    let [a, b, c] = tris[t as usize];
    (pos[a as usize] + pos[b as usize] + pos[c as usize]) * (1.0 / 3.0)
}

fn unit(n: DVec3) -> DVec3 {
    let len = n.length();
    if len > 0.0 { n / len } else { DVec3::ZERO }
}

/// Step 1 for the faces `first .. first + out.len()`: unit normals (zero for a degenerate face).
pub fn normals_into(tris: &[[u32; 3]], pos: &[DVec3], out: &mut [DVec3], first: usize) {
    for (k, o) in out.iter_mut().enumerate() {
        *o = unit(cross(tris, pos, (first + k) as u32));
    }
}

/// Twice the area of the faces `first .. first + out.len()`: the filter's area weights.
pub fn areas_into(tris: &[[u32; 3]], pos: &[DVec3], out: &mut [f64], first: usize) {
    for (k, o) in out.iter_mut().enumerate() {
        *o = cross(tris, pos, (first + k) as u32).length();
    }
}

fn cross(tris: &[[u32; 3]], pos: &[DVec3], t: u32) -> DVec3 {
    let [a, b, c] = tris[t as usize];
    let a = pos[a as usize];
    (pos[b as usize] - a).cross(pos[c as usize] - a)
}

/// `H(P_t)` for the faces `first .. first + out.len()`, from the normal field `normals`.
pub fn consistency_into(
    topo: &TopologyParts,
    tris: &[[u32; 3]],
    normals: &[DVec3],
    out: &mut [f64],
    first: usize,
) {
    let mut patch = Vec::with_capacity(32);
    let mut units = Vec::with_capacity(32);
    let mut fan = Vec::with_capacity(32);
    for (k, o) in out.iter_mut().enumerate() {
        let t = (first + k) as u32;
        patch_of(topo, tris, t, &mut patch);
        units.clear();
        units.extend(patch.iter().map(|&j| normals[j as usize]));
        let mut spread = 0.0f64;
        for (a, na) in units.iter().enumerate() {
            for nb in &units[a + 1..] {
                spread = spread.max((*na - *nb).length_squared());
            }
        }
        // The edges at the corners of `t`: two faces of a corner's fan that share a second
        // vertex, counted at the corner of lowest id among those they share.
        let corners = tris[t as usize];
        let (mut largest, mut sum) = (0.0f64, 0.0f64);
        for &c in &corners {
            fan.clear();
            fan.extend(topo.faces_of(c, tris));
            for (x, &fa) in fan.iter().enumerate() {
                let ta = tris[fa as usize];
                for &fb in &fan[x + 1..] {
                    let tb = tris[fb as usize];
                    let Some(other) = ta.iter().copied().find(|&w| w != c && tb.contains(&w))
                    else {
                        continue;
                    };
                    if other < c && corners.contains(&other) {
                        continue;
                    }
                    let phi = (normals[fa as usize] - normals[fb as usize]).length();
                    largest = largest.max(phi);
                    sum += phi;
                }
            }
        }
        *o = spread.sqrt() * (largest / (EPSILON_R + sum));
    }
}

/// `m_t`, the area-weighted mean unit normal of `P_t`, for the faces `first .. first + out.len()`.
pub fn patch_means_into(
    topo: &TopologyParts,
    tris: &[[u32; 3]],
    normals: &[DVec3],
    areas: &[f64],
    out: &mut [DVec3],
    first: usize,
) {
    let mut patch = Vec::with_capacity(32);
    for (k, o) in out.iter_mut().enumerate() {
        patch_of(topo, tris, (first + k) as u32, &mut patch);
        let sum = patch.iter().fold(DVec3::ZERO, |s, &j| {
            s + normals[j as usize] * areas[j as usize]
        });
        *o = unit(sum);
    }
}

/// `g_t`, the mean normal of the most consistent patch among those of `P_t` (ties: the lower
/// face id), or `t`'s own normal in `normals` where even that patch is less consistent than
/// [`GUIDANCE_LIMIT`], for the faces `first .. first + out.len()`.
pub fn guidance_into(
    topo: &TopologyParts,
    tris: &[[u32; 3]],
    consistency: &[f64],
    means: &[DVec3],
    normals: &[DVec3],
    out: &mut [DVec3],
    first: usize,
) {
    let mut patch = Vec::with_capacity(32);
    for (k, o) in out.iter_mut().enumerate() {
        let t = (first + k) as u32;
        patch_of(topo, tris, t, &mut patch);
        let mut best = t;
        for &j in &patch {
            let (h, hb) = (consistency[j as usize], consistency[best as usize]);
            if h < hb || (h == hb && j < best) {
                best = j;
            }
        }
        *o = if consistency[best as usize] > GUIDANCE_LIMIT {
            normals[t as usize]
        } else {
            means[best as usize]
        };
    }
}

/// Step 2's filter for the faces `first .. first + out.len()`: the new unit normals from
/// `normals`, their areas and the guidance. A face whose guidance makes a cosine below
/// `cut` with `t`'s gets no weight at all ([`NO_CUT`]: none is cut).
#[allow(clippy::too_many_arguments)]
pub fn filter_into(
    topo: &TopologyParts,
    tris: &[[u32; 3]],
    pos: &[DVec3],
    normals: &[DVec3],
    areas: &[f64],
    guidance: &[DVec3],
    cut: f64,
    out: &mut [DVec3],
    first: usize,
) {
    let mut patch = Vec::with_capacity(32);
    let mut centroids = Vec::with_capacity(32);
    let range = -0.5 / (SIGMA_RANGE * SIGMA_RANGE);
    for (k, o) in out.iter_mut().enumerate() {
        let t = (first + k) as u32;
        let (g, c) = (guidance[t as usize], centroid(tris, pos, t));
        patch_of(topo, tris, t, &mut patch);
        centroids.clear();
        centroids.extend(
            patch
                .iter()
                .map(|&j| (centroid(tris, pos, j) - c).length_squared()),
        );
        let others = patch.len().saturating_sub(1);
        let spacing: f64 = centroids.iter().map(|d2| d2.sqrt()).sum();
        let space = if others > 0 && spacing > 0.0 {
            let sigma = SPACE_SCALE * spacing / others as f64;
            -0.5 / (sigma * sigma)
        } else {
            0.0
        };
        let mut sum = DVec3::ZERO;
        for (&j, &d2) in patch.iter().zip(&centroids) {
            let gj = guidance[j as usize];
            if g.dot(gj) < cut {
                continue;
            }
            let w = areas[j as usize] * (space * d2 + range * (g - gj).length_squared()).exp();
            sum += normals[j as usize] * w;
        }
        *o = unit(sum);
    }
}

/// Steps 1 and 2 on the fixed positions `pos`: the unit normals of `tris`, filtered
/// `iterations` times; returns the filtered field, one of `vectors`' fields. `vectors` and
/// `scalars` hold [`FACE_VECTORS`] and [`FACE_SCALARS`] fields of `tris.len()` entries (the
/// normals, the patches' means and the guidance; the areas and the consistencies: a method's
/// [`FaceFields`](super::method::FaceFields)), each pass a Jacobi pass through `exec`, so any split of the work gives the
/// same bits. The result borrows only `vectors`: the scalars may go once it is made. Used by
/// `vcs-guided` and by the crease detection ([`crate::Topology::crease`]'s callers).
#[allow(clippy::too_many_arguments)]
pub fn filter_normals<'v>(
    exec: &mut dyn Exec,
    topo: &TopologyParts,
    tris: &[[u32; 3]],
    pos: &[DVec3],
    vectors: &'v mut [DVec3],
    scalars: &mut [f64],
    iterations: usize,
    cut: f64,
) -> &'v [DVec3] {
    let n = tris.len();
    let (normals, rest) = vectors.split_at_mut(n);
    let (means, guidance) = rest.split_at_mut(n);
    let guidance = &mut guidance[..n];
    let (areas, consistency) = scalars.split_at_mut(n);
    let consistency = &mut consistency[..n];
    exec.face_pass_f64(areas, &|first, out| areas_into(tris, pos, out, first));
    let areas: &[f64] = areas;
    // `means` takes the filtered normals once the guidance is made from it, and the two swap
    // roles: the normals of each filter iteration are those of the one before.
    let (mut normals, mut means) = (normals, means);
    exec.face_pass(normals, &|first, out| normals_into(tris, pos, out, first));
    for _ in 0..iterations {
        let field: &[DVec3] = normals;
        exec.face_pass_f64(consistency, &|first, out| {
            consistency_into(topo, tris, field, out, first)
        });
        exec.face_pass(means, &|first, out| {
            patch_means_into(topo, tris, field, areas, out, first)
        });
        let (h, m): (&[f64], &[DVec3]) = (consistency, means);
        exec.face_pass(guidance, &|first, out| {
            guidance_into(topo, tris, h, m, field, out, first)
        });
        let g: &[DVec3] = guidance;
        exec.face_pass(means, &|first, out| {
            filter_into(topo, tris, pos, field, areas, g, cut, out, first)
        });
        std::mem::swap(&mut normals, &mut means);
    }
    normals
}

/// Step 3, one Jacobi step for the vertices `first .. first + out.len()`, from positions `from`
/// and the filtered `normals`; fixed vertices keep their position.
pub fn fit_into(
    topo: &TopologyParts,
    tris: &[[u32; 3]],
    normals: &[DVec3],
    from: &[DVec3],
    out: &mut [DVec3],
    first: usize,
) {
    for (k, o) in out.iter_mut().enumerate() {
        let v = (first + k) as u32;
        let p = from[v as usize];
        if !topo.is_free_or_on_line(v) {
            *o = p;
            continue;
        }
        let (mut step, mut count) = (DVec3::ZERO, 0usize);
        for f in topo.faces_of(v, tris) {
            let n = normals[f as usize];
            step += n * n.dot(centroid(tris, from, f) - p);
            count += 1;
        }
        *o = match count {
            0 => p,
            _ => p + step * (1.0 / count as f64),
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::topology::Topology;

    /// Two squares folded at 90° along the x axis: four triangles in the plane z = 0 (y ≥ 0) and
    /// four in the plane y = 0 (z ≤ 0).
    fn fold() -> (Topology, Vec<[u32; 3]>, Vec<DVec3>) {
        let mut pos = Vec::new();
        for &(y, z) in &[(2.0, 0.0), (1.0, 0.0), (0.0, 0.0), (0.0, -1.0), (0.0, -2.0)] {
            for x in 0..3 {
                pos.push(DVec3::new(x as f64, y, z));
            }
        }
        let mut tris = Vec::new();
        for row in 0..4u32 {
            for col in 0..2u32 {
                let a = row * 3 + col;
                tris.push([a, a + 3, a + 1]);
                tris.push([a + 1, a + 3, a + 4]);
            }
        }
        let topo = Topology::build(pos.len(), &tris).unwrap();
        (topo, tris, pos)
    }

    fn normals_of(tris: &[[u32; 3]], pos: &[DVec3]) -> Vec<DVec3> {
        let mut n = vec![DVec3::ZERO; tris.len()];
        normals_into(tris, pos, &mut n, 0);
        n
    }

    fn areas_of(tris: &[[u32; 3]], pos: &[DVec3]) -> Vec<f64> {
        let mut a = vec![0.0; tris.len()];
        areas_into(tris, pos, &mut a, 0);
        a
    }

    #[test]
    fn a_flat_patch_is_fully_consistent_and_one_across_the_fold_is_not() {
        let (topo, tris, pos) = fold();
        let n = normals_of(&tris, &pos);
        let mut h = vec![0.0; tris.len()];
        consistency_into(&topo.parts(), &tris, &n, &mut h, 0);
        // Faces 0 and 1 (row 0) touch no vertex of the fold (y = 0 is row 2).
        assert_eq!(h[0], 0.0);
        // Face 4 (row 2) has corners on the fold: its patch holds both planes.
        assert!(h[4] > 0.1, "{}", h[4]);
    }

    #[test]
    fn the_filter_keeps_a_clean_fold() {
        let (topo, tris, pos) = fold();
        let parts = topo.parts();
        let n = normals_of(&tris, &pos);
        let (mut h, mut m, mut g, mut out) = (
            vec![0.0; tris.len()],
            vec![DVec3::ZERO; tris.len()],
            vec![DVec3::ZERO; tris.len()],
            vec![DVec3::ZERO; tris.len()],
        );
        consistency_into(&parts, &tris, &n, &mut h, 0);
        let areas = areas_of(&tris, &pos);
        patch_means_into(&parts, &tris, &n, &areas, &mut m, 0);
        guidance_into(&parts, &tris, &h, &m, &n, &mut g, 0);
        filter_into(&parts, &tris, &pos, &n, &areas, &g, NO_CUT, &mut out, 0);
        // Every face's guidance lies in its own plane, so a face of the other plane weighs at
        // most K_r(√2) = exp(−1/σ_r²) of a face of its own: the normal tilts less than that.
        let bound = (-1.0 / (SIGMA_RANGE * SIGMA_RANGE)).exp();
        for (a, b) in n.iter().zip(&out) {
            assert!((*a - *b).length() < bound, "{a} -> {b}");
        }
    }

    #[test]
    fn fitting_moves_a_raised_vertex_back_into_its_plane() {
        let (topo, tris, mut pos) = fold();
        // Vertex 4 (x = 1, y = 1, z = 0) lies inside the flat half; the fold's vertices are fixed
        // by nothing here, so raise it and fit with the clean normals.
        let clean = normals_of(&tris, &pos);
        pos[4].z += 0.3;
        let mut out = pos.clone();
        fit_into(&topo.parts(), &tris, &clean, &pos, &mut out, 0);
        assert!(out[4].z.abs() < 0.3 * 0.5, "{}", out[4].z);
        // A vertex on the boundary is fixed: it stays.
        assert_eq!(out[0], pos[0]);
    }
}
