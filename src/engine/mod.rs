//! The one place that combines topology, kernels and threads: runs a smoothing method for a number
//! of iterations and records per-iteration statistics.
//!
//! Order contract (part of the result's definition, so runs are reproducible):
//! - `lem`, `vcs`: edge stencils `(i, j)`, `i < j`, in ascending `(i, j)` order, Gauss–Seidel.
//! - `vcs-triangle`: triangle stencils in the input's triangle order, Gauss–Seidel.
//! - `laplacian`, `taubin`: Jacobi (every vertex from the previous positions), so the order is
//!   irrelevant and any thread count gives bit-identical output.

pub mod memory;

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::io;
use crate::mesh::{Buf, Storage};
use crate::metrics::{self, MeshInfo};
use crate::partition::{self, Patch, Reordered};
use crate::schedule::{self, Prefetch, Schedule, SharedField};
use crate::smooth::tiled::{self, TilePlan};
use crate::smooth::{
    self, Method, Options, SweepStats,
    laplacian::{self, Previous, StepStats},
    stencil::{self, StencilParams, Workspace},
};
use crate::topology::Topology;
use memory as resources;

/// Statistics of one iteration, relative to the input where a percentage is given.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
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
    /// Seconds of the sweep: for `laplacian` and `taubin` with the displacement, which they
    /// measure in the same pass; never the volume and area statistics. Iterations that ran as one
    /// round of Jacobi steps (see [`Observer::statistics`]) share its time equally, the round that
    /// builds the tile plan counting its construction.
    pub seconds: f64,
}

/// Receives progress from long runs; the CLI renders it as a progress bar.
pub trait Observer: Send {
    /// Called after each iteration with its record and the total number of iterations.
    fn iteration(&mut self, _record: &IterationRecord, _total: usize) {}

    /// Whether iteration `iteration` (1-based) of `total` needs its statistics: volume, area and
    /// displacement. Each costs passes over the whole mesh (volume and area: one over the
    /// triangles, about as long as a `taubin` iteration; displacement for the stencil methods: a
    /// copy and a pass over the positions). When this returns false the volume and area fields of
    /// the record are NaN (`null` in JSON), and so are the displacements; the sweep and its counts
    /// are the same. `laplacian` and `taubin` run the iterations up to the next one that wants its
    /// statistics as one round, several steps per pass over memory (bit-identical results), so
    /// asking for fewer statistics also makes them faster. Default: every iteration.
    fn statistics(&self, _iteration: usize, _total: usize) -> bool {
        true
    }
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
    // The stencil methods' copy before each sweep, for the displacement.
    let mut prev = vec![
        DVec3::ZERO;
        if opts.method.is_jacobi() {
            0
        } else {
            pos.len()
        }
    ];
    let mut scratch = vec![DVec3::ZERO; pos.len()];
    let params = stencil_params(opts);
    let mut ws = Workspace::default();
    let records = iterate(
        topo,
        triangles,
        pos,
        &mut prev,
        &mut scratch,
        opts,
        observer,
        true,
        |pos, sums| {
            if opts.method == Method::VcsTriangle {
                let faces = 0..triangles.len() as u32;
                stencil::sweep_triangles(topo, triangles, pos, sums, faces, params, &mut ws)
            } else {
                stencil::sweep_edges(topo, triangles, pos, sums, topo.edges(), params, &mut ws)
            }
        },
    );
    Ok(records)
}

/// The iteration loop both engines share: Jacobi methods in [`jacobi_rounds`], stencil methods
/// through `stencil_sweep(positions, neighbour sums)`; then the per-iteration statistics.
/// `tiles`: whether the Jacobi methods may hold a [`TilePlan`] on the heap (the mesh is in memory).
#[allow(clippy::too_many_arguments)]
fn iterate(
    topo: &Topology,
    tris: &[[u32; 3]],
    pos: &mut [DVec3],
    prev: &mut [DVec3],
    scratch: &mut [DVec3],
    opts: &Options,
    observer: &mut dyn Observer,
    tiles: bool,
    mut stencil_sweep: impl FnMut(&mut [DVec3], &mut [DVec3]) -> SweepStats,
) -> Vec<IterationRecord> {
    let stats = Statistics::new(topo, tris, pos);
    if opts.method.is_jacobi() {
        return jacobi_rounds(topo, &stats, pos, scratch, opts, observer, tiles);
    }
    let mut records = Vec::with_capacity(opts.iterations);
    for it in 1..=opts.iterations {
        let measure = observer.statistics(it, opts.iterations);
        let start = Instant::now();
        if measure {
            prev.copy_from_slice(pos);
        }
        // `scratch` holds the neighbour sums, fresh each iteration.
        const CHUNK: usize = 1 << 14;
        scratch
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, out)| smooth::neighbor_sums_into(topo, pos, out, c * CHUNK));
        let sweep = stencil_sweep(pos, scratch);
        // Timed as it always was: the sweep, not the displacement pass that follows it.
        let seconds = start.elapsed().as_secs_f64();
        let moved = measure.then(|| displacement_par(pos, prev));
        let record = stats.record(it, pos, moved, sweep, seconds);
        observer.iteration(&record, opts.iterations);
        records.push(record);
    }
    records
}

/// What the per-iteration records are relative to.
struct Statistics<'a> {
    tris: &'a [[u32; 3]],
    /// A fixed reference point, so that the volume of an open mesh is followed consistently.
    origin: DVec3,
    volume: f64,
    area: f64,
    movable: usize,
}

impl<'a> Statistics<'a> {
    fn new(topo: &Topology, tris: &'a [[u32; 3]], pos: &[DVec3]) -> Self {
        let origin = metrics::centroid(pos);
        let (volume, area) = volume_area_par(pos, tris, origin);
        Statistics {
            tris,
            origin,
            volume,
            area,
            movable: (topo.len() - topo.stats.fixed_vertices).max(1),
        }
    }

    /// The record of iteration `it` that ended at `pos`; `moved` is its displacement when the
    /// statistics were wanted (then the volume and area are measured too), `None` otherwise.
    fn record(
        &self,
        it: usize,
        pos: &[DVec3],
        moved: Option<StepStats>,
        stencils: SweepStats,
        seconds: f64,
    ) -> IterationRecord {
        let (volume, area) = match moved {
            Some(_) => volume_area_par(pos, self.tris, self.origin),
            None => (f64::NAN, f64::NAN),
        };
        let moved = moved.unwrap_or(StepStats {
            moved: 0,
            max_displacement: f64::NAN,
            sum_displacement: f64::NAN,
        });
        IterationRecord {
            iteration: it,
            volume,
            volume_pct: percent(volume, self.volume),
            area_pct: percent(area, self.area),
            max_displacement: moved.max_displacement,
            mean_displacement: moved.sum_displacement / self.movable as f64,
            stencils,
            seconds,
        }
    }
}

/// `laplacian` and `taubin`: rounds of Jacobi steps, ping-ponging between `pos` and `scratch`
/// (the result ends in `pos`).
///
/// With a [`TilePlan`] (when `tiles`, and as long as every tile can be planned) a round runs
/// several iterations in one pass over memory: up to the plan's depth in steps, and never past an
/// iteration whose statistics are wanted (it ends the round, and its displacement is measured in
/// the round). The iterations of a round share its time equally in their records; the first round
/// also plans the tiles. Without a plan every iteration is one or two plain steps over fixed-size
/// chunks. Both give bit-identical positions.
fn jacobi_rounds(
    topo: &Topology,
    stats: &Statistics,
    pos: &mut [DVec3],
    scratch: &mut [DVec3],
    opts: &Options,
    observer: &mut dyn Observer,
    tiles: bool,
) -> Vec<IterationRecord> {
    let total = opts.iterations;
    let factors: &[f64] = if opts.method == Method::Taubin {
        &[opts.lambda, opts.mu]
    } else {
        &[opts.lambda]
    };
    let mut start = Instant::now();
    // Planned tile by tile by the first round (see `TilePlan::new`); dropped if a tile cannot be.
    let mut plan = tiles.then(|| TilePlan::new(topo));
    let movable = (topo.len() - topo.stats.fixed_vertices) as u64;
    let sweep = SweepStats {
        applied: movable * factors.len() as u64,
        skipped_fixed: (topo.len() as u64 - movable) * factors.len() as u64,
        ..Default::default()
    };
    let mut records = Vec::with_capacity(total);
    // Whether the current positions are in `scratch` (else in `pos`).
    let mut in_scratch = false;
    let mut first = 1;
    while first <= total {
        let per_round = plan
            .as_ref()
            .map_or(1, |p| (p.depth() / factors.len()).max(1));
        let mut last = first;
        while last < total && last - first + 1 < per_round && !observer.statistics(last, total) {
            last += 1;
        }
        let measure = observer.statistics(last, total);
        let (src, dst): (&[DVec3], &mut [DVec3]) = if in_scratch {
            (scratch, pos)
        } else {
            (pos, scratch)
        };
        let moved = match &plan {
            Some(tiled) => {
                let steps: Vec<f64> = (first..=last).flat_map(|_| factors.to_vec()).collect();
                let measured = measure.then_some(steps.len() - factors.len());
                let Some(st) = tiled::round(tiled, src, dst, &steps, measured) else {
                    // A tile could not be planned: the same iterations in plain steps, from the
                    // untouched `src`.
                    plan = None;
                    continue;
                };
                in_scratch = !in_scratch;
                measure.then_some(st)
            }
            None if factors.len() == 1 => {
                in_scratch = !in_scratch;
                let moved = jacobi_measured(topo, src, dst, factors[0], Previous::Src);
                measure.then_some(moved)
            }
            None => {
                // The pair goes `src` → `dst` → `src`: the μ step measures against the position
                // it overwrites, the one before the pair.
                jacobi_measured(topo, src, dst, factors[0], Previous::Src);
                let (src, dst): (&[DVec3], &mut [DVec3]) = if in_scratch {
                    (pos, scratch)
                } else {
                    (scratch, pos)
                };
                let moved = jacobi_measured(topo, src, dst, factors[1], Previous::Dst);
                measure.then_some(moved)
            }
        };
        let seconds = start.elapsed().as_secs_f64() / (last - first + 1) as f64;
        let current: &[DVec3] = if in_scratch { scratch } else { pos };
        for it in first..=last {
            let moved = if it == last { moved } else { None };
            let record = stats.record(it, current, moved, sweep, seconds);
            observer.iteration(&record, total);
            records.push(record);
        }
        first = last + 1;
        start = Instant::now();
    }
    if in_scratch {
        pos.copy_from_slice(scratch);
    }
    records
}

pub(crate) fn stencil_params(opts: &Options) -> StencilParams {
    StencilParams {
        volume: matches!(opts.method, Method::Vcs | Method::VcsTriangle),
        reject_energy_increase: opts.reject_energy_increase,
    }
}

/// Vertices per work item of the Jacobi steps and of the statistics sums. Fixed-size chunks, combined
/// in chunk order, make every result independent of the thread count.
const JACOBI_CHUNK: usize = 1 << 14;

/// A Jacobi step over all vertices, split into fixed-size chunks across the pool's threads, that
/// also measures the displacement from the previous positions (see [`Previous`]).
fn jacobi_measured(
    topo: &Topology,
    src: &[DVec3],
    dst: &mut [DVec3],
    lambda: f64,
    previous: Previous,
) -> StepStats {
    let parts: Vec<StepStats> = dst
        .par_chunks_mut(JACOBI_CHUNK)
        .enumerate()
        .map(|(c, out)| {
            laplacian::jacobi_step_measured(topo, src, out, c * JACOBI_CHUNK, lambda, previous)
        })
        .collect();
    parts
        .into_iter()
        .fold(StepStats::default(), StepStats::then)
}

pub(crate) fn percent(x: f64, reference: f64) -> f64 {
    if x.is_nan() {
        f64::NAN
    } else if reference == 0.0 {
        100.0
    } else {
        100.0 * x / reference
    }
}

/// Smooth a whole in-memory mesh: builds its topology and runs [`smooth_positions`].
///
/// ```no_run
/// let mut mesh = vcsmooth::mesh::generate::icosphere(3);
/// vcsmooth::mesh::generate::add_normal_noise(&mut mesh, 0.3, 7);
/// let opts = vcsmooth::Options::default(); // vcs, 10 iterations
/// let records = vcsmooth::engine::smooth_mesh(&mut mesh, &opts, None, &mut vcsmooth::engine::Quiet)?;
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
        let n = reordered.positions.len();
        // The stencil methods' copy before each sweep, for the displacement.
        let mut prev: Buf<DVec3> = storage.zeroed(if opts.method.is_jacobi() { 0 } else { n })?;
        let mut scratch: Buf<DVec3> = storage.zeroed(n)?;
        let advisors: Vec<_> = [reordered.positions.advisor(), scratch.advisor()]
            .into_iter()
            .flatten()
            .collect();
        let pos: &mut [DVec3] = &mut reordered.positions;
        let queue = 2 * rayon::current_num_threads();
        Ok(schedule::with_prefetch(topo, advisors, queue, |prefetch| {
            iterate(
                topo,
                tris,
                pos,
                &mut prev,
                &mut scratch,
                opts,
                observer,
                !storage.is_mapped(),
                |pos, sums| sweep_colours(topo, tris, pos, sums, patches, schedule, opts, prefetch),
            )
        }))
    }
}

/// One Gauss–Seidel pass of the stencil method over all patches, colour by colour.
#[allow(clippy::too_many_arguments)]
fn sweep_colours(
    topo: &Topology,
    tris: &[[u32; 3]],
    pos: &mut [DVec3],
    sums: &mut [DVec3],
    patches: &[Patch],
    schedule: &Schedule,
    opts: &Options,
    prefetch: &Prefetch,
) -> SweepStats {
    let params = stencil_params(opts);
    // SAFETY: the views are used only by the patches of one colour at a time, which touch disjoint
    // positions and sums (the colouring invariant of `schedule`); `pos` and `sums` are not used
    // otherwise while the views live.
    let (pos_view, sums_view) = unsafe { (SharedField::new(pos), SharedField::new(sums)) };
    let mut total = SweepStats::default();
    for (c, colour) in schedule.colours.iter().enumerate() {
        // Read ahead the next colour (or, at the end, the first: the next iteration starts there).
        let next = &schedule.colours[(c + 1) % schedule.colours.len()];
        for &p in next {
            prefetch.hint(patches[p as usize].vertices.clone());
        }
        let mine: Vec<Patch> = colour
            .iter()
            .map(|&p| patches[p as usize].clone())
            .collect();
        let stats = sweep_patches(topo, tris, pos_view, sums_view, &mine, opts.method, params);
        total.add(&stats);
    }
    total
}

/// The stencils of `patches` (all of one colour, so they touch disjoint data), in parallel on the
/// current rayon pool through the shared views, each patch's in ascending order.
pub(crate) fn sweep_patches(
    topo: &Topology,
    tris: &[[u32; 3]],
    pos: SharedField,
    sums: SharedField,
    patches: &[Patch],
    method: Method,
    params: StencilParams,
) -> SweepStats {
    patches
        .par_iter()
        .map_init(Workspace::default, |ws, patch| {
            let (mut pv, mut sv) = (pos, sums);
            if method == Method::VcsTriangle {
                let faces = patch.triangles.clone();
                stencil::sweep_triangles(topo, tris, &mut pv, &mut sv, faces, params, ws)
            } else {
                let edges = patch.edges(topo);
                stencil::sweep_edges(topo, tris, &mut pv, &mut sv, edges, params, ws)
            }
        })
        .reduce(SweepStats::default, |mut a, b| {
            a.add(&b);
            a
        })
}

/// Fixed-size chunks make the parallel sums below independent of the thread count.
const SUM_CHUNK: usize = 1 << 15;

/// Volume about `origin` and area, in one pass over the triangles.
pub(crate) fn volume_area_par(pos: &[DVec3], tris: &[[u32; 3]], origin: DVec3) -> (f64, f64) {
    let parts: Vec<(f64, f64)> = tris
        .par_chunks(SUM_CHUNK)
        .map(|chunk| {
            let (mut v, mut a) = (0.0, 0.0);
            for &[i, j, k] in chunk {
                let p = pos[i as usize] - origin;
                let q = pos[j as usize] - origin;
                let r = pos[k as usize] - origin;
                v += p.dot(q.cross(r));
                a += (q - p).cross(r - p).length();
            }
            (v, a)
        })
        .collect();
    let (v, a) = parts
        .iter()
        .fold((0.0, 0.0), |(v, a), &(pv, pa)| (v + pv, a + pa));
    (v / 6.0, a / 2.0)
}

/// Largest and summed vertex displacement between `a` and `b`.
pub(crate) fn displacement_par(a: &[DVec3], b: &[DVec3]) -> StepStats {
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
    let (max, sum) = parts
        .iter()
        .fold((0.0f64, 0.0), |(m, s), &(pm, ps)| (m.max(pm), s + ps));
    StepStats {
        moved: 0,
        max_displacement: max,
        sum_displacement: sum,
    }
}

pub(crate) fn validate(opts: &Options) -> Result<()> {
    for (name, x) in [("lambda", opts.lambda), ("mu", opts.mu)] {
        if !x.is_finite() {
            return Err(Error::Config(format!(
                "--{name} must be a finite number, got {x}"
            )));
        }
    }
    Ok(())
}

/// How the patch engine runs a file.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct EngineSettings {
    /// Worker threads; `None`: all cores.
    pub threads: Option<usize>,
    /// Vertices per patch (part of the result's definition: outputs are identical for any thread
    /// count and memory budget only for the same patch size).
    pub patch_size: usize,
    /// Anonymous memory allowed; `None`: three quarters of the available memory.
    pub memory_budget: Option<u64>,
    /// Where scratch files go when the mesh does not fit the budget; `None`: beside the output.
    pub scratch: Option<PathBuf>,
    /// Measure input and output statistics (for a report).
    pub with_stats: bool,
}

/// Default vertices per patch: small enough that a 1M-triangle mesh has dozens of patches to
/// share among threads, large enough that the per-patch scheduling cost is negligible.
pub const DEFAULT_PATCH_SIZE: usize = 16_384;

impl Default for EngineSettings {
    fn default() -> Self {
        EngineSettings {
            threads: None,
            patch_size: DEFAULT_PATCH_SIZE,
            memory_budget: None,
            scratch: None,
            with_stats: false,
        }
    }
}

impl EngineSettings {
    /// The memory budget: as given (checked), or three quarters of the available memory.
    pub fn budget(&self) -> Result<u64> {
        match self.memory_budget {
            Some(b) => {
                resources::check_budget(b)?;
                Ok(b)
            }
            None => Ok(resources::default_budget()),
        }
    }
}

/// What `run_file` did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FileRun {
    #[serde(skip)]
    pub input_format: Option<io::Format>,
    pub vertices: usize,
    pub triangles: usize,
    pub records: Vec<IterationRecord>,
    pub input_stats: Option<MeshInfo>,
    /// Measured on the f64 positions before the output format rounds them.
    pub output_stats: Option<MeshInfo>,
    pub plan: PlanStats,
    pub memory: MemoryStats,
    pub timings: PhaseTimings,
    /// Ranks, halo traffic and checkpoints of a cluster run ([`crate::cluster`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster: Option<crate::cluster::ClusterStats>,
}

/// The patch decomposition of a run.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct PlanStats {
    pub patch_size: usize,
    pub patches: usize,
    pub colours: usize,
    /// Vertices outside a patch's own range that its stencils read: smallest, mean, largest.
    pub halo_min: u32,
    pub halo_mean: f64,
    pub halo_max: u32,
    /// Edge stencils whose two vertices lie in different patches (each applied once, by the
    /// patch of its smaller vertex).
    pub crossing_edge_stencils: u64,
    pub threads: usize,
}

/// Memory and I/O of a run.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct MemoryStats {
    pub budget: u64,
    /// "heap" when the mesh fits the budget, else "scratch" (memory-mapped files).
    pub storage: &'static str,
    pub scratch_bytes: u64,
    /// Peak anonymous resident memory (RssAnon), file-backed pages excluded; 0 if unknown.
    pub peak_anon: u64,
    pub bytes_read: u64,
    pub bytes_written: u64,
}

/// Seconds per phase.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct PhaseTimings {
    pub ingest: f64,
    pub reorder: f64,
    pub topology: f64,
    pub partition: f64,
    pub smoothing: f64,
    pub write: f64,
    pub metrics: f64,
    pub total: f64,
}

impl PhaseTimings {
    /// Take the reorder, topology and partition seconds of a preparation.
    pub fn add_preparation(&mut self, p: &PrepTimings) {
        self.reorder += p.reorder;
        self.topology += p.topology;
        self.partition += p.partition;
    }
}

/// Read `input`, smooth it patch-parallel with `opts`, write `output` (atomically, in the input's
/// vertex order and layout). The one place that wires I/O, partition, schedule and kernels.
pub fn run_file(
    input: &Path,
    output: &Path,
    opts: &Options,
    engine: &EngineSettings,
    observer: &mut dyn Observer,
) -> Result<FileRun> {
    run_file_with(
        input,
        output,
        opts,
        engine,
        observer,
        |prep, storage, obs| prep.smooth(storage, opts, obs),
    )
}

/// [`run_file`] with the smoothing step given: `smooth(plan, storage, observer)` moves the plan's
/// reordered positions and returns the iteration records (multiresolution mode plugs in here).
pub fn run_file_with(
    input: &Path,
    output: &Path,
    opts: &Options,
    engine: &EngineSettings,
    observer: &mut dyn Observer,
    smooth: impl FnOnce(&mut Prepared, &Storage, &mut dyn Observer) -> Result<Vec<IterationRecord>>
    + Send,
) -> Result<FileRun> {
    validate(opts)?;
    let start = Instant::now();
    let sampler = resources::PeakSampler::start(std::time::Duration::from_millis(20));
    let budget = engine.budget()?;
    let pool = thread_pool(engine.threads)?;
    let mut t = PhaseTimings::default();

    let bytes_read = std::fs::metadata(input)
        .map_err(|e| Error::io(input, e))?
        .len();
    let storage = storage_for(input, output, engine, budget)?;

    let clock = Instant::now();
    let mut mesh = io::read_mesh_in(input, &storage)?;
    t.ingest = clock.elapsed().as_secs_f64();
    check_in_memory_budget(input, &storage, &mesh, budget)?;

    let run = pool.install(|| -> Result<_> {
        let mut prep = Prepared::new(
            &storage,
            &mesh.positions,
            &mesh.triangles,
            engine.patch_size,
        )
        .map_err(|e| e.in_file(input))?;
        t.add_preparation(&prep.timings);
        // The plan holds its own (reordered) copy: the input-order positions are not needed until
        // the write, so their memory is given back while smoothing (the peak of an in-core run).
        let n = mesh.positions.len();
        mesh.positions = Buf::default();
        let clock = Instant::now();
        let input_stats = engine.with_stats.then(|| prep.info(&mesh.source));
        t.metrics += clock.elapsed().as_secs_f64();

        let clock = Instant::now();
        let records = smooth(&mut prep, &storage, observer)?;
        t.smoothing = clock.elapsed().as_secs_f64();

        let clock = Instant::now();
        let output_stats = engine.with_stats.then(|| prep.info(&mesh.source));
        t.metrics += clock.elapsed().as_secs_f64();
        mesh.positions = storage.zeroed(n)?;
        prep.positions_in_input_order(&mut mesh.positions);
        Ok((records, input_stats, output_stats, prep.plan_stats()))
    })?;
    let (records, input_stats, output_stats, mut plan) = run;
    plan.threads = pool.current_num_threads();

    let clock = Instant::now();
    io::write_mesh(output, &mesh)?;
    t.write = clock.elapsed().as_secs_f64();
    t.total = start.elapsed().as_secs_f64();
    let memory = MemoryStats {
        budget,
        storage: if storage.is_mapped() {
            "scratch"
        } else {
            "heap"
        },
        scratch_bytes: storage.mapped_bytes(),
        peak_anon: sampler.peak(),
        bytes_read,
        bytes_written: std::fs::metadata(output).map(|m| m.len()).unwrap_or(0),
    };
    Ok(FileRun {
        input_format: mesh.source.format,
        vertices: mesh.positions.len(),
        triangles: mesh.triangles.len(),
        records,
        input_stats,
        output_stats,
        plan,
        memory,
        timings: t,
        cluster: None,
    })
}

impl Prepared {
    /// Statistics of the current (reordered) mesh; every figure is order-independent.
    pub fn info(&self, source: &io::Source) -> MeshInfo {
        metrics::info_of(
            &self.reordered.positions,
            &self.reordered.triangles,
            source,
            &self.topology,
        )
    }

    /// The decomposition's figures for reports.
    pub fn plan_stats(&self) -> PlanStats {
        PlanStats::new(
            self.patches.first().map_or(0, |p| p.vertices.len()),
            self.schedule.colours.len(),
            &self.schedule.halo,
            self.patches
                .iter()
                .map(|p| p.crossing_edges(&self.topology))
                .sum(),
        )
    }
}

impl PlanStats {
    /// The figures of a plan of `halo.len()` patches (one halo count each), on the current pool.
    pub fn new(patch_size: usize, colours: usize, halo: &[u32], crossing: u64) -> PlanStats {
        PlanStats {
            patch_size,
            patches: halo.len(),
            colours,
            halo_min: halo.iter().copied().min().unwrap_or(0),
            halo_mean: halo.iter().map(|&h| h as f64).sum::<f64>() / halo.len().max(1) as f64,
            halo_max: halo.iter().copied().max().unwrap_or(0),
            crossing_edge_stencils: crossing,
            threads: rayon::current_num_threads(),
        }
    }
}

/// Heap or scratch, decided before reading from the file size: a binary PLY of T triangles is
/// about 19·T bytes and the engine needs about 105·T, so 6 × the file size (text formats, larger
/// per triangle, are overestimated, which only sends them to scratch sooner).
pub(crate) fn storage_for(
    input: &Path,
    output: &Path,
    engine: &EngineSettings,
    budget: u64,
) -> Result<Storage> {
    let size = std::fs::metadata(input)
        .map_err(|e| Error::io(input, e))?
        .len();
    if size.saturating_mul(6) <= budget {
        return Ok(Storage::heap());
    }
    let dir = match &engine.scratch {
        Some(d) => d.clone(),
        None => scratch_beside(output),
    };
    Storage::scratch(&dir)
}

/// Only binary PLY decodes straight into scratch; other formats land on the heap. Refuse to go on
/// rather than silently exceed the budget.
pub(crate) fn check_in_memory_budget(
    input: &Path,
    storage: &Storage,
    mesh: &crate::Mesh,
    budget: u64,
) -> Result<()> {
    let heap = (mesh.positions.len() * 24 + mesh.triangles.len() * 12) as u64;
    if storage.is_mapped() && !mesh.positions.is_mapped() && heap > budget {
        return Err(Error::invalid(
            input,
            format!(
                "this format is read into memory ({}), more than --memory-budget {}; convert it to binary PLY (vcsmooth smooth IN OUT.ply --iterations 0) on a larger machine, or raise the budget",
                resources::format_size(heap),
                resources::format_size(budget)
            ),
        ));
    }
    Ok(())
}

/// A rayon pool of `threads` threads (all cores when `None`).
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            return Err(Error::Config("--threads must be at least 1".into()));
        }
        builder = builder.num_threads(n);
    }
    builder
        .build()
        .map_err(|e| Error::Config(format!("thread pool: {e}")))
}

/// The directory of `output` (the current directory for a bare file name).
fn scratch_beside(output: &Path) -> PathBuf {
    match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}
