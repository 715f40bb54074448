//! Moving a coarse level's displacement onto the finer level, and the global volume correction.
//! Pure functions over slices and a [`Topology`]; parallel over fixed-size chunks, so results do
//! not depend on the thread count.

use glam::DVec3;
use rayon::prelude::*;

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
    #[default]
    Smooth,
}

impl Transfer {
    pub const ALL: [Transfer; 2] = [Transfer::Constant, Transfer::Smooth];

    pub fn name(self) -> &'static str {
        match self {
            Transfer::Constant => "constant",
            Transfer::Smooth => "smooth",
        }
    }
}

/// Fixed-size chunks keep every parallel result independent of the thread count.
const CHUNK: usize = 1 << 14;

/// Add to `pos` (fine level) the displacement `coarse` of each vertex's representative `map[v]`,
/// blended by `passes` diffusion steps for [`Transfer::Smooth`]. Fixed vertices do not move.
pub fn apply(
    storage: &Storage,
    topo: &Topology,
    map: &[u32],
    coarse: &[DVec3],
    pos: &mut [DVec3],
    how: Transfer,
    passes: usize,
) -> Result<()> {
    let n = pos.len();
    let fixed = topo.fixed_mask();
    let mut d: Buf<DVec3> = storage.zeroed(n)?;
    d.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
        for (k, x) in out.iter_mut().enumerate() {
            let v = c * CHUNK + k;
            *x = if fixed[v] != 0 {
                DVec3::ZERO
            } else {
                coarse[map[v] as usize]
            };
        }
    });
    if how == Transfer::Smooth && passes > 0 {
        let mut tmp: Buf<DVec3> = storage.zeroed(n)?;
        for _ in 0..passes {
            tmp.par_chunks_mut(CHUNK)
                .enumerate()
                .for_each(|(c, out)| {
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

/// Signed volume about `origin`, summed in fixed-size chunks.
pub fn volume(pos: &[DVec3], triangles: &[[u32; 3]], origin: DVec3) -> f64 {
    let parts: Vec<f64> = triangles
        .par_chunks(CHUNK)
        .map(|ch| {
            ch.iter()
                .map(|t| {
                    let [a, b, c] = t.map(|v| pos[v as usize] - origin);
                    a.dot(b.cross(c))
                })
                .sum::<f64>()
        })
        .collect();
    parts.iter().sum::<f64>() / 6.0
}

/// Translate every movable vertex along its volume gradient (the area-weighted normal / 3) by one
/// common factor so that the volume about `origin` becomes `target`: the global form of the vcs
/// step 2. The volume is a cubic in the factor; Newton steps reach `target` to rounding in two or
/// three passes. Returns the remaining relative volume error.
pub fn restore_volume(
    storage: &Storage,
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut [DVec3],
    target: f64,
    origin: DVec3,
) -> Result<f64> {
    let n = pos.len();
    let scale = target.abs().max(f64::MIN_POSITIVE);
    let mut grad: Buf<DVec3> = storage.zeroed(n)?;
    let mut err = (volume(pos, triangles, origin) - target) / scale;
    for _ in 0..6 {
        if err.abs() <= 1e-14 {
            break;
        }
        let fixed = topo.fixed_mask();
        let src: &[DVec3] = pos;
        grad.par_chunks_mut(CHUNK).enumerate().for_each(|(c, out)| {
            for (k, g) in out.iter_mut().enumerate() {
                let v = (c * CHUNK + k) as u32;
                *g = if fixed[v as usize] != 0 {
                    DVec3::ZERO
                } else {
                    volume_gradient(topo, triangles, src, v, origin)
                };
            }
        });
        let gg: f64 = grad
            .par_chunks(CHUNK)
            .map(|ch| ch.iter().map(|g| g.length_squared()).sum::<f64>())
            .collect::<Vec<_>>()
            .iter()
            .sum();
        if !(gg > 0.0 && gg.is_finite()) {
            break;
        }
        let t = -err * scale / gg;
        pos.par_chunks_mut(CHUNK)
            .zip(grad.par_chunks(CHUNK))
            .for_each(|(p, g)| p.iter_mut().zip(g).for_each(|(p, g)| *p += t * *g));
        err = (volume(pos, triangles, origin) - target) / scale;
    }
    Ok(err)
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
            let n = volume_gradient(topo, triangles, now, v as u32, now[v])
                .normalize_or_zero();
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
    topo.faces_of(v)
        .iter()
        .fold(DVec3::ZERO, |s, &f| {
            let t = triangles[f as usize];
            let i = t.iter().position(|&u| u == v).unwrap_or(0);
            let b = pos[t[(i + 1) % 3] as usize] - origin;
            let c = pos[t[(i + 2) % 3] as usize] - origin;
            s + b.cross(c)
        })
        / 6.0
}
