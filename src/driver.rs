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
use crate::mesh::{Buf, Storage};
use crate::metrics;
use crate::partition::{self, Patch, Reordered};
use crate::schedule::{self, Schedule, SharedField};
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
    validate(opts)?;
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            return Err(Error::Config("--threads must be at least 1".into()));
        }
        builder = builder.num_threads(n);
    }
    let pool = builder
        .build()
        .map_err(|e| Error::Config(format!("thread pool: {e}")))?;
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
    let movable = (topo.len() - topo.stats.fixed_vertices).max(1);
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
                let sums = &mut smooth::neighbor_sums(topo, pos)[..];
                stencil::sweep_edges(topo, triangles, pos, sums, topo.edges(), params, &mut ws)
            }
            Method::VcsTriangle => {
                let params = stencil_params(opts);
                let sums = &mut smooth::neighbor_sums(topo, pos)[..];
                let faces = 0..triangles.len() as u32;
                stencil::sweep_triangles(topo, triangles, pos, sums, faces, params, &mut ws)
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
    SweepStats {
        applied,
        skipped_fixed,
        ..Default::default()
    }
}

fn percent(x: f64, reference: f64) -> f64 {
    if reference == 0.0 {
        100.0
    } else {
        100.0 * x / reference
    }
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
    smooth_positions(
        &topo,
        &mesh.triangles,
        &mut mesh.positions,
        opts,
        threads,
        observer,
    )
}

/// A mesh prepared for patch-parallel smoothing: reordered along the Morton curve, with its
/// topology, patches and colouring (the reusable plan of repeated runs and benchmarks).
#[derive(Debug)]
pub struct Prepared {
    pub reordered: Reordered,
    pub topology: Topology,
    pub patches: Vec<Patch>,
    pub schedule: Schedule,
    /// Seconds spent in each preparation phase.
    pub timings: PrepTimings,
}

/// Seconds spent preparing.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct PrepTimings {
    pub reorder: f64,
    pub topology: f64,
    pub partition: f64,
}

impl Prepared {
    /// Reorder, build the topology, cut patches of `patch_size` vertices and colour them, placing
    /// the large arrays as `storage` says. Run inside the rayon pool that will smooth.
    pub fn new(
        storage: &Storage,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        patch_size: usize,
    ) -> Result<Prepared> {
        if patch_size == 0 {
            return Err(Error::Config("--patch-size must be at least 1".into()));
        }
        let t = Instant::now();
        let reordered = partition::reorder(storage, positions, triangles)?;
        let reorder_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let topology = Topology::build_in(storage, positions.len(), &reordered.triangles)?;
        let topology_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let patches = partition::patches(positions.len(), &reordered.triangles, patch_size);
        let schedule = schedule::schedule(&topology, &patches);
        let timings = PrepTimings {
            reorder: reorder_s,
            topology: topology_s,
            partition: t.elapsed().as_secs_f64(),
        };
        Ok(Prepared {
            reordered,
            topology,
            patches,
            schedule,
            timings,
        })
    }

    /// Copy the (smoothed) positions back into the input's vertex order.
    pub fn positions_in_input_order(&self, out: &mut [DVec3]) {
        for (new, &old) in self.reordered.order.iter().enumerate() {
            out[old as usize] = self.reordered.positions[new];
        }
    }

    /// Smooth the reordered positions in place, patch-parallel on the current rayon pool.
    ///
    /// Stencil methods run colour after colour; within a colour the patches run in parallel, each
    /// applying the stencils it owns in ascending order (see [`crate::schedule`]). Jacobi methods
    /// update fixed-size vertex chunks in parallel. The result is bit-identical for any number of
    /// threads and any storage placement, for a given patch size.
    pub fn smooth(
        &mut self,
        storage: &Storage,
        opts: &Options,
        observer: &mut dyn Observer,
    ) -> Result<Vec<IterationRecord>> {
        validate(opts)?;
        let Prepared {
            reordered,
            topology: topo,
            patches,
            schedule,
            ..
        } = self;
        let tris: &[[u32; 3]] = &reordered.triangles;
        let pos: &mut [DVec3] = &mut reordered.positions;
        let origin = metrics::centroid(pos);
        let v_in = volume_par(pos, tris, origin);
        let a_in = area_par(pos, tris);
        let movable = (topo.len() - topo.stats.fixed_vertices).max(1);
        let mut prev: Buf<DVec3> = storage.zeroed(pos.len())?;
        let mut scratch: Buf<DVec3> = storage.zeroed(pos.len())?;
        let mut records = Vec::with_capacity(opts.iterations);
        for it in 1..=opts.iterations {
            let start = Instant::now();
            prev.copy_from_slice(pos);
            let stencils = match opts.method {
                Method::Laplacian => jacobi(topo, &prev, pos, opts.lambda),
                Method::Taubin => {
                    let mut s = jacobi(topo, &prev, &mut scratch, opts.lambda);
                    s.add(&jacobi(topo, &scratch, pos, opts.mu));
                    s
                }
                Method::Lem | Method::Vcs | Method::VcsTriangle => {
                    // `scratch` holds the neighbour sums, fresh each iteration.
                    const CHUNK: usize = 1 << 14;
                    scratch
                        .par_chunks_mut(CHUNK)
                        .enumerate()
                        .for_each(|(c, out)| smooth::neighbor_sums_into(topo, pos, out, c * CHUNK));
                    sweep_colours(topo, tris, pos, &mut scratch, patches, schedule, opts)
                }
            };
            let seconds = start.elapsed().as_secs_f64();
            let (max_d, sum_d) = displacement_par(pos, &prev);
            let volume = volume_par(pos, tris, origin);
            let record = IterationRecord {
                iteration: it,
                volume,
                volume_pct: percent(volume, v_in),
                area_pct: percent(area_par(pos, tris), a_in),
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
}

/// One Gauss–Seidel pass of the stencil method over all patches, colour by colour.
fn sweep_colours(
    topo: &Topology,
    tris: &[[u32; 3]],
    pos: &mut [DVec3],
    sums: &mut [DVec3],
    patches: &[Patch],
    schedule: &Schedule,
    opts: &Options,
) -> SweepStats {
    let params = stencil_params(opts);
    // SAFETY: the views are used only by the patches of one colour at a time, which touch disjoint
    // positions and sums (the colouring invariant of `schedule`); `pos` and `sums` are not used
    // otherwise while the views live.
    let (pos_view, sums_view) = unsafe { (SharedField::new(pos), SharedField::new(sums)) };
    let mut total = SweepStats::default();
    for colour in &schedule.colours {
        let stats = colour
            .par_iter()
            .map_init(Workspace::default, |ws, &p| {
                let (mut pv, mut sv) = (pos_view, sums_view);
                let patch = &patches[p as usize];
                if opts.method == Method::VcsTriangle {
                    let faces = patch.triangles.clone();
                    stencil::sweep_triangles(topo, tris, &mut pv, &mut sv, faces, params, ws)
                } else {
                    stencil::sweep_edges(
                        topo,
                        tris,
                        &mut pv,
                        &mut sv,
                        patch.edges(topo),
                        params,
                        ws,
                    )
                }
            })
            .reduce(SweepStats::default, |mut a, b| {
                a.add(&b);
                a
            });
        total.add(&stats);
    }
    total
}

/// Fixed-size chunks make the parallel sums below independent of the thread count.
const SUM_CHUNK: usize = 1 << 15;

fn volume_par(pos: &[DVec3], tris: &[[u32; 3]], origin: DVec3) -> f64 {
    let parts: Vec<f64> = tris
        .par_chunks(SUM_CHUNK)
        .map(|c| metrics::volume_about(pos, c, origin))
        .collect();
    parts.iter().sum()
}

fn area_par(pos: &[DVec3], tris: &[[u32; 3]]) -> f64 {
    let parts: Vec<f64> = tris
        .par_chunks(SUM_CHUNK)
        .map(|c| metrics::area(pos, c))
        .collect();
    parts.iter().sum()
}

/// Largest and summed vertex displacement between `a` and `b`.
fn displacement_par(a: &[DVec3], b: &[DVec3]) -> (f64, f64) {
    let parts: Vec<(f64, f64)> = a
        .par_chunks(SUM_CHUNK)
        .zip(b.par_chunks(SUM_CHUNK))
        .map(|(x, y)| {
            x.iter().zip(y).fold((0.0f64, 0.0), |(m, s), (p, q)| {
                let d = p.distance(*q);
                (m.max(d), s + d)
            })
        })
        .collect();
    parts
        .iter()
        .fold((0.0, 0.0), |(m, s), &(pm, ps)| (m.max(pm), s + ps))
}

fn validate(opts: &Options) -> Result<()> {
    for (name, x) in [("lambda", opts.lambda), ("mu", opts.mu)] {
        if !x.is_finite() {
            return Err(Error::Config(format!(
                "--{name} must be a finite number, got {x}"
            )));
        }
    }
    Ok(())
}
