//! Moving a coarse level's displacement onto the finer level, and the global volume correction.
//! Pure functions over slices and a [`Topology`]; parallel over fixed-size chunks, so results do
//! not depend on the thread count.

use glam::DVec3;
use rayon::prelude::*;

use crate::engine::reduce::{self, CHUNK};
use crate::error::Result;
use crate::mesh::{Buf, Storage};
use crate::smooth::laplacian;
use crate::topology::Topology;

/// How a fine vertex follows its coarse representative.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Transfer {
    /// Each fine vertex moves exactly as its cluster's representative: piecewise constant, with
    /// steps between clusters that the fine-level smoothing then removes.
    Constant,
    /// The piecewise-constant field diffused over the fine mesh (Jacobi steps of the umbrella
    /// operator on the displacements) across about one cluster's width, so that neighbouring
    /// clusters blend instead of stepping.
    Smooth,
    /// Shepard interpolation on the coarse surface: each fine vertex takes the average of the
    /// displacements of its representative and the representative's coarse neighbours, weighted
    /// by `(1 − (d/R)²)²` of its distance `d` to their positions as built, `R` = 1.5 cells. A
    /// partition of unity that varies continuously with position, in one pass.
    #[default]
    Interpolate,
}

impl Transfer {
    pub const ALL: [Transfer; 3] = [Transfer::Constant, Transfer::Smooth, Transfer::Interpolate];

    pub fn name(self) -> &'static str {
        match self {
            Transfer::Constant => "constant",
            Transfer::Smooth => "smooth",
            Transfer::Interpolate => "interpolate",
        }
    }
}

/// A coarse level as the transfer reads it.
pub struct Coarse<'a> {
    pub topo: &'a Topology,
    /// Positions as built (before smoothing): where each representative sat on the surface.
    pub rest: &'a [DVec3],
    /// Displacement of each coarse vertex.
    pub disp: &'a [DVec3],
    /// Cell edge of the level.
    pub cell: f64,
}

/// Add to `pos` (fine level) the displacement of each vertex's representative `map[v]` as `how`
/// says (`passes` diffusion steps for [`Transfer::Smooth`]). Fixed vertices do not move.
pub fn apply(
    storage: &Storage,
    topo: &Topology,
    map: &[u32],
    coarse: &Coarse,
    pos: &mut [DVec3],
    how: Transfer,
    passes: usize,
) -> Result<()> {
    let n = pos.len();
    let fixed = topo.fixed_mask();
    let mut d: Buf<DVec3> = storage.zeroed(n)?;
    let radius2 = (1.5 * coarse.cell).powi(2);
    let src: &[DVec3] = pos;
    d.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
        for (k, x) in out.iter_mut().enumerate() {
            let v = c * CHUNK + k;
            let rep = map[v];
            *x = if fixed[v] != 0 {
                DVec3::ZERO
            } else if how == Transfer::Interpolate {
                shepard(coarse, rep, src[v], radius2)
            } else {
                coarse.disp[rep as usize]
            };
        }
    });
    if how == Transfer::Smooth && passes > 0 {
        let mut tmp: Buf<DVec3> = storage.zeroed(n)?;
        for _ in 0..passes {
            tmp.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
                laplacian::jacobi_step(topo, &d, out, c * CHUNK, 0.5);
            });
            std::mem::swap(&mut d, &mut tmp);
        }
    }
    pos.par_chunks_mut(CHUNK)
        .zip(d.par_chunks(CHUNK))
        .for_each(|(p, d)| p.iter_mut().zip(d).for_each(|(p, d)| *p += *d));
    Ok(())
}

/// The [`Transfer::Interpolate`] displacement at `p`, whose representative is `rep`.
fn shepard(coarse: &Coarse, rep: u32, p: DVec3, radius2: f64) -> DVec3 {
    let weight = |u: u32| {
        let x = 1.0 - p.distance_squared(coarse.rest[u as usize]) / radius2;
        if x > 0.0 { x * x } else { 0.0 }
    };
    let (mut sum, mut wsum) = (DVec3::ZERO, 0.0);
    for u in std::iter::once(rep).chain(coarse.topo.neighbors(rep).iter().copied()) {
        let w = weight(u);
        sum += w * coarse.disp[u as usize];
        wsum += w;
    }
    if wsum > 0.0 {
        sum / wsum
    } else {
        coarse.disp[rep as usize]
    }
}

/// Translate every movable vertex along its volume gradient (the area-weighted normal / 3) by one
/// common factor `t` so that the volume about `origin` becomes `target`: the global form of the vcs
/// step 2. With the gradients `g` fixed, `V(p + t g)` is exactly a cubic in `t` (each triangle's
/// determinant is trilinear); its coefficients take one pass over the triangles, Newton on the
/// cubic gives `t` to rounding, and a second round removes what rounding left. Returns the
/// remaining relative volume error.
pub fn restore_volume(
    storage: &Storage,
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut [DVec3],
    target: f64,
    origin: DVec3,
) -> Result<f64> {
    restore_volume_within(storage, topo, triangles, pos, target, origin, None)
}

/// Rounds of [`restore_volume_within`] with a bound, beyond the two without: each round the
/// vertices the translation took out of their balls are put back and hold still, and the others
/// make up their share.
const BOUNDED_ROUNDS: usize = 16;

/// [`restore_volume`]; with `bound = Some((input, limit))` no vertex ends farther than `limit`
/// from its `input` position (indexed like `pos`): a vertex a round takes farther is put back on
/// its ball and moves no more, and the next round asks the volume of the others. The error
/// returned is what is left after at most `BOUNDED_ROUNDS` (16) + 2 rounds (not 0 when the bound
/// holds every vertex still).
pub fn restore_volume_within(
    storage: &Storage,
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut [DVec3],
    target: f64,
    origin: DVec3,
    bound: Option<(&[DVec3], f64)>,
) -> Result<f64> {
    let n = pos.len();
    let scale = target.abs().max(f64::MIN_POSITIVE);
    let mut grad: Buf<DVec3> = storage.zeroed(n)?;
    let mut held: Buf<u8> = storage.zeroed(if bound.is_some() { n } else { 0 })?;
    let rounds = 2 + if bound.is_some() { BOUNDED_ROUNDS } else { 0 };
    let mut err = (reduce::volume(pos, triangles, origin) - target) / scale;
    for _ in 0..rounds {
        if err.abs() <= 1e-14 {
            break;
        }
        let fixed = topo.fixed_mask();
        let (src, still): (&[DVec3], &[u8]) = (pos, &held);
        grad.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
            for (k, g) in out.iter_mut().enumerate() {
                let v = (c * CHUNK + k) as u32;
                *g = if fixed[v as usize] != 0 || still.get(v as usize).is_some_and(|&h| h != 0) {
                    DVec3::ZERO
                } else {
                    volume_gradient(topo, triangles, src, v, src[v as usize])
                };
            }
        });
        let cubic = volume_cubic(triangles, pos, &grad, origin);
        let Some(t) = solve_cubic(cubic, target) else {
            break;
        };
        pos.par_chunks_mut(CHUNK)
            .zip(grad.par_chunks(CHUNK))
            .for_each(|(p, g)| p.iter_mut().zip(g).for_each(|(p, g)| *p += t * *g));
        if let Some((input, limit)) = bound {
            pos.par_chunks_mut(CHUNK)
                .zip(held.par_chunks_mut(CHUNK))
                .enumerate()
                .for_each(|(c, (p, h))| {
                    for (k, (p, h)) in p.iter_mut().zip(h).enumerate() {
                        let inside = laplacian::clamp_to_ball(*p, input[c * CHUNK + k], limit);
                        if inside != *p {
                            *p = inside;
                            *h = 1;
                        }
                    }
                });
        }
        err = (reduce::volume(pos, triangles, origin) - target) / scale;
    }
    Ok(err)
}

/// Coefficients `[c0, c1, c2, c3]` of `V(p + t g) = c0 + c1 t + c2 t² + c3 t³` about `origin`.
fn volume_cubic(triangles: &[[u32; 3]], pos: &[DVec3], grad: &[DVec3], origin: DVec3) -> [f64; 4] {
    let det = |a: DVec3, b: DVec3, c: DVec3| a.dot(b.cross(c));
    let parts: Vec<[f64; 4]> = triangles
        .par_chunks(CHUNK)
        .map(|ch| {
            let mut s = [0.0; 4];
            for t in ch {
                let [a, b, c] = t.map(|v| pos[v as usize] - origin);
                let [ga, gb, gc] = t.map(|v| grad[v as usize]);
                s[0] += det(a, b, c);
                s[1] += det(ga, b, c) + det(a, gb, c) + det(a, b, gc);
                s[2] += det(ga, gb, c) + det(ga, b, gc) + det(a, gb, gc);
                s[3] += det(ga, gb, gc);
            }
            s
        })
        .collect();
    let mut s = [0.0; 4];
    for p in &parts {
        for k in 0..4 {
            s[k] += p[k] / 6.0;
        }
    }
    s
}

/// The root of `cubic(t) = target` nearest 0, by Newton from 0; `None` if the slope vanishes.
fn solve_cubic(c: [f64; 4], target: f64) -> Option<f64> {
    let mut t = 0.0;
    for _ in 0..50 {
        let f = c[0] + t * (c[1] + t * (c[2] + t * c[3])) - target;
        let df = c[1] + t * (2.0 * c[2] + t * 3.0 * c[3]);
        if !(df.abs() > 0.0 && df.is_finite()) {
            return None;
        }
        let step = f / df;
        t -= step;
        if step.abs() <= 1e-16 * t.abs().max(f64::MIN_POSITIVE) {
            break;
        }
    }
    t.is_finite().then_some(t)
}

/// The normal component of `now − rest` at every vertex (normals from the volume gradient at `now`,
/// i.e. area-weighted), into `out`. Vertices without a normal get no displacement.
///
/// Why only the normal part: on a clustered level the umbrella energy that vcs minimises also
/// evens out the irregular vertex spacing, a tangential motion of up to a coarse edge that says
/// nothing about the shape; handed down, it would drag whole clusters of fine vertices along the
/// surface (measured: 5× the vertex-to-vertex distance to the clean mesh of plain vcs).
pub fn normal_displacement(
    topo: &Topology,
    triangles: &[[u32; 3]],
    now: &[DVec3],
    rest: &[DVec3],
    out: &mut [DVec3],
) {
    out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
        for (k, d) in out.iter_mut().enumerate() {
            let v = c * CHUNK + k;
            let n = volume_gradient(topo, triangles, now, v as u32, now[v]).normalize_or_zero();
            *d = n * n.dot(now[v] - rest[v]);
        }
    });
}

/// `∂V/∂p_v = (1/6) Σ_{t ∋ v} (p_b − o) × (p_c − o)`, with `(v, b, c)` cyclic in `t`'s order.
fn volume_gradient(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &[DVec3],
    v: u32,
    origin: DVec3,
) -> DVec3 {
    topo.faces_of(v, triangles).fold(DVec3::ZERO, |s, f| {
        let t = triangles[f as usize];
        let i = t.iter().position(|&u| u == v).unwrap_or(0);
        let b = pos[t[(i + 1) % 3] as usize] - origin;
        let c = pos[t[(i + 2) % 3] as usize] - origin;
        s + b.cross(c)
    }) / 6.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes;

    #[test]
    fn restore_volume_reaches_the_target_and_leaves_fixed_vertices() {
        let mut m = shapes::icosphere(3);
        let topo = Topology::build(m.positions.len(), &m.triangles).unwrap();
        let target = reduce::volume(&m.positions, &m.triangles, DVec3::ZERO);
        for p in m.positions.iter_mut() {
            *p *= 0.9;
        }
        let err = restore_volume(
            &Storage::heap(),
            &topo,
            &m.triangles,
            &mut m.positions,
            target,
            DVec3::ZERO,
        )
        .unwrap();
        assert!(err.abs() < 1e-14, "{err:e}");
        let v = reduce::volume(&m.positions, &m.triangles, DVec3::ZERO);
        assert!(((v - target) / target).abs() < 1e-14);
        // A uniform shrink comes back as a uniform inflation: still a sphere.
        let r: Vec<f64> = m.positions.iter().map(|p| p.length()).collect();
        let (lo, hi) = r
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
        // (The gradient is area-weighted: vertices with larger areas move a little more.)
        assert!(hi - lo < 0.05, "{lo}..{hi}");
    }

    #[test]
    fn a_common_displacement_reaches_every_fine_vertex_unchanged() {
        let fine = shapes::icosphere(3);
        let coarse = shapes::icosphere(1);
        let ft = Topology::build(fine.positions.len(), &fine.triangles).unwrap();
        let ct = Topology::build(coarse.positions.len(), &coarse.triangles).unwrap();
        // Nearest coarse vertex as the representative.
        let map: Vec<u32> = fine
            .positions
            .iter()
            .map(|p| {
                (0..coarse.positions.len())
                    .min_by(|&a, &b| {
                        p.distance(coarse.positions[a])
                            .total_cmp(&p.distance(coarse.positions[b]))
                    })
                    .unwrap() as u32
            })
            .collect();
        let d = DVec3::new(0.01, -0.02, 0.03);
        let disp = vec![d; coarse.positions.len()];
        for how in Transfer::ALL {
            let c = Coarse {
                topo: &ct,
                rest: &coarse.positions,
                disp: &disp,
                cell: 0.6,
            };
            let mut pos = fine.positions.to_vec();
            apply(&Storage::heap(), &ft, &map, &c, &mut pos, how, 4).unwrap();
            for (a, b) in pos.iter().zip(fine.positions.iter()) {
                assert!((*a - *b - d).length() < 1e-15, "{how:?}");
            }
        }
    }
}
