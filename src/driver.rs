//! The one place that combines topology, kernels and threads: runs a smoothing method for a number
//! of iterations and records per-iteration statistics.
//!
//! Order contract (part of the result's definition, so runs are reproducible):
//! - `lem`, `vcs`: edge stencils `(i, j)`, `i < j`, in ascending `(i, j)` order, Gauss–Seidel.
//! - `vcs-triangle`: triangle stencils in the input's triangle order, Gauss–Seidel.
//! - `laplacian`, `taubin`: Jacobi (every vertex from the previous positions), so the order is
//!   irrelevant and any thread count gives bit-identical output.

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::metrics;
use crate::smooth::{
    self, Method, Options, SweepStats, laplacian,
    stencil::{self, StencilParams, Workspace},
};
use crate::topology::Topology;

/// Statistics of one iteration, relative to the input where a percentage is given.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct IterationRecord {
    /// 1-based iteration number.
    pub iteration: usize,
    pub volume: f64,
    /// Volume as a percentage of the input volume (100 when the input volume is 0).
    pub volume_pct: f64,
    pub area_pct: f64,
    /// Largest distance any vertex moved in this iteration.
    pub max_displacement: f64,
    /// Mean distance moved over the movable (non-fixed) vertices.
    pub mean_displacement: f64,
    pub stencils: SweepStats,
    pub seconds: f64,
}

/// Receives progress from long runs; the CLI renders it as a progress bar.
pub trait Observer: Send {
    /// Called after each iteration with its record and the total number of iterations.
    fn iteration(&mut self, _record: &IterationRecord, _total: usize) {}
}

/// An observer that ignores everything.
pub struct Quiet;
impl Observer for Quiet {}

/// Smooth `pos` in place on `topo` (built from `triangles`) with `opts`, on `threads` threads
/// (`None`: all cores). Returns one record per iteration.
pub fn smooth_positions(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut [DVec3],
    opts: &Options,
    threads: Option<usize>,
    observer: &mut dyn Observer,
) -> Result<Vec<IterationRecord>> {
    if pos.len() != topo.len() {
        return Err(Error::Config(format!(
            "{} positions for a topology of {} vertices",
            pos.len(),
            topo.len()
        )));
    }
    for (name, x) in [("lambda", opts.lambda), ("mu", opts.mu)] {
        if !x.is_finite() {
            return Err(Error::Config(format!("--{name} must be a finite number, got {x}")));
        }
    }
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            return Err(Error::Config("--threads must be at least 1".into()));
        }
        builder = builder.num_threads(n);
    }
    let pool = builder.build().map_err(|e| Error::Config(format!("thread pool: {e}")))?;
    pool.install(|| run(topo, triangles, pos, opts, observer))
}

fn run(
    topo: &Topology,
    triangles: &[[u32; 3]],
    pos: &mut [DVec3],
    opts: &Options,
    observer: &mut dyn Observer,
) -> Result<Vec<IterationRecord>> {
    // A fixed reference point, so that the volume of an open mesh is followed consistently.
    let origin = metrics::centroid(pos);
    let v_in = metrics::volume_about(pos, triangles, origin);
    let a_in = metrics::area(pos, triangles);
    let movable = topo.fixed_mask().iter().filter(|&&f| !f).count().max(1);
    let mut prev = pos.to_vec();
    let mut ws = Workspace::default();
    let mut records = Vec::with_capacity(opts.iterations);
    for it in 1..=opts.iterations {
        let start = Instant::now();
        prev.copy_from_slice(pos);
        let stencils = match opts.method {
            Method::Laplacian => jacobi(topo, &prev, pos, opts.lambda),
            Method::Taubin => {
                let mut s = jacobi(topo, &prev, pos, opts.lambda);
                let mid = pos.to_vec();
                s.add(&jacobi(topo, &mid, pos, opts.mu));
                s
            }
            Method::Lem | Method::Vcs => {
                let params = stencil_params(opts);
                let mut sums = smooth::neighbor_sums(topo, pos);
                stencil::sweep_edges(topo, triangles, pos, &mut sums, topo.edges(), params, &mut ws)
            }
            Method::VcsTriangle => {
                let params = stencil_params(opts);
                let mut sums = smooth::neighbor_sums(topo, pos);
                let faces = 0..triangles.len() as u32;
                stencil::sweep_triangles(topo, triangles, pos, &mut sums, faces, params, &mut ws)
            }
        };
        let seconds = start.elapsed().as_secs_f64();
        let (max_d, sum_d) = pos
            .par_iter()
            .zip(prev.par_iter())
            .map(|(a, b)| {
                let d = a.distance(*b);
                (d, d)
            })
            .reduce(|| (0.0, 0.0), |x, y| (x.0.max(y.0), x.1 + y.1));
        let volume = metrics::volume_about(pos, triangles, origin);
        let record = IterationRecord {
            iteration: it,
            volume,
            volume_pct: percent(volume, v_in),
            area_pct: percent(metrics::area(pos, triangles), a_in),
            max_displacement: max_d,
            mean_displacement: sum_d / movable as f64,
            stencils,
            seconds,
        };
        observer.iteration(&record, opts.iterations);
        records.push(record);
    }
    Ok(records)
}

fn stencil_params(opts: &Options) -> StencilParams {
    StencilParams {
        volume: matches!(opts.method, Method::Vcs | Method::VcsTriangle),
        reject_energy_increase: opts.reject_energy_increase,
    }
}

/// A Jacobi step over all vertices, split into fixed-size chunks across the pool's threads.
fn jacobi(topo: &Topology, src: &[DVec3], dst: &mut [DVec3], lambda: f64) -> SweepStats {
    const CHUNK: usize = 1 << 14;
    let applied = dst
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, out)| laplacian::jacobi_step(topo, src, out, c * CHUNK, lambda))
        .sum::<u64>();
    let skipped_fixed = topo.len() as u64 - applied;
    SweepStats { applied, skipped_fixed, ..Default::default() }
}

fn percent(x: f64, reference: f64) -> f64 {
    if reference == 0.0 { 100.0 } else { 100.0 * x / reference }
}

/// Smooth a whole in-memory mesh: builds its topology and runs [`smooth_positions`].
///
/// ```no_run
/// let mut mesh = vcsmooth::generate::icosphere(3);
/// vcsmooth::generate::add_normal_noise(&mut mesh, 0.3, 7);
/// let opts = vcsmooth::Options::default(); // vcs, 10 iterations
/// let records = vcsmooth::driver::smooth_mesh(&mut mesh, &opts, None, &mut vcsmooth::driver::Quiet)?;
/// assert!((records.last().unwrap().volume_pct - 100.0).abs() < 1e-6);
/// # Ok::<(), vcsmooth::Error>(())
/// ```
pub fn smooth_mesh(
    mesh: &mut crate::Mesh,
    opts: &Options,
    threads: Option<usize>,
    observer: &mut dyn Observer,
) -> Result<Vec<IterationRecord>> {
    let topo = Topology::build(mesh.positions.len(), &mesh.triangles)?;
    smooth_positions(&topo, &mesh.triangles, &mut mesh.positions, opts, threads, observer)
}
