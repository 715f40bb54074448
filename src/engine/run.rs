//! A run from file to file: read, plan, smooth, write, with the figures of every phase.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use super::auto::AutoStopStats;
use super::deviation::{self, DeviationSettings};
use super::disk::{DiskBytes, DiskMeter, DiskTraffic};
use super::memory::{self, Budget, BudgetSource, PeakSampler};
use super::observer::{
    IterationMeter, IterationRecord, Meter, Moment, Observer, Phase, Statistics, metered,
};
use super::pins::Pins;
use super::plan::{DEFAULT_PATCH_SIZE, Layout, Plan, PlanStats, PrepTimings};
use super::reduce;
use crate::error::{Error, Result};
use crate::io;
use crate::mesh::{Buf, Mesh, Storage};
use crate::metrics::{DeviationStats, MeshInfo};
use crate::partition::Input;
use crate::smooth::Options;

/// How the engine runs: threads, patches, memory, statistics, pins. Only `patch_size` and `pins`
/// are part of the result's definition: outputs are identical for any thread count and memory
/// budget for the same patch size and pins.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct EngineSettings {
    /// Worker threads; `None`: all cores.
    pub threads: Option<usize>,
    /// Vertices per patch. Default [`DEFAULT_PATCH_SIZE`].
    pub patch_size: usize,
    /// Anonymous memory a file run may use (see [`memory`]); `None`: three quarters of the
    /// available memory, or less under a cgroup limit or an rlimit (see
    /// [`memory::default_budget`]). An in-memory mesh ([`crate::smooth()`]) is smoothed on the
    /// heap whatever this says.
    pub memory_budget: Option<u64>,
    /// Where a file run's scratch files go when its mesh does not fit the budget; `None`: beside
    /// the output.
    pub scratch: Option<PathBuf>,
    /// Measure input and output statistics (for a report).
    pub with_stats: bool,
    /// Which iterations measure volume, area and displacement. Default: every one.
    pub statistics: Statistics,
    /// Vertices that never move, in the input's order (see [`Pins`]). Default: none.
    pub pins: Pins,
    /// The deviation field of a file run: measured, written into the output, checked against a
    /// tolerance (see [`DeviationSettings`]). Default: none. It adds to the output's vertices and
    /// changes nothing else of it. Absent from JSON when off.
    #[serde(skip_serializing_if = "DeviationSettings::is_off")]
    pub deviation: DeviationSettings,
}

impl Default for EngineSettings {
    fn default() -> Self {
        EngineSettings {
            threads: None,
            patch_size: DEFAULT_PATCH_SIZE,
            memory_budget: None,
            scratch: None,
            with_stats: false,
            statistics: Statistics::Every,
            pins: Pins::None,
            deviation: DeviationSettings::default(),
        }
    }
}

impl EngineSettings {
    /// The memory budget: as given (checked), or the default (see [`memory::default_budget`]).
    pub fn budget(&self) -> Result<u64> {
        Ok(self.budget_and_source()?.bytes)
    }

    /// [`EngineSettings::budget`] and where it came from.
    pub fn budget_and_source(&self) -> Result<Budget> {
        memory::budget_or_default(self.memory_budget)
    }

    /// The plan layout these settings ask for.
    pub fn layout(&self) -> Layout {
        Layout::Patches(self.patch_size)
    }
}

/// What a run did: the records of its iterations and the figures of its phases.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    #[serde(skip)]
    pub input_format: Option<io::Format>,
    pub vertices: usize,
    pub triangles: usize,
    pub records: Vec<IterationRecord>,
    /// Iterations that ran: `records.len()`, fewer than the options' `iterations` when the
    /// automatic stop ended the run.
    pub iterations_run: usize,
    /// What the automatic stop measured and why it stopped, when the options asked for it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub auto_stop: Option<AutoStopStats>,
    pub input_stats: Option<MeshInfo>,
    /// A file run's: measured on the output file's positions as stored (rounded to its coordinate
    /// type); an in-memory run's ([`crate::smooth()`]): on the f64 positions.
    pub output_stats: Option<MeshInfo>,
    pub plan: PlanStats,
    pub memory: MemoryStats,
    pub timings: PhaseTimings,
    /// Bytes the process read and wrote, per phase (see [`super::disk`]); `None` where
    /// `/proc/self/io` cannot be read, and for the cluster engine (several processes).
    pub disk: Option<DiskTraffic>,
    /// Ranks, halo traffic and checkpoints of a cluster run ([`crate::cluster`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster: Option<ClusterStats>,
    /// The deviation of the output as stored from the input, when the settings ask for it
    /// ([`EngineSettings::deviation`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub deviation: Option<DeviationStats>,
    /// The input file's SHA-256, when the run took it: the cluster engine identifies the input
    /// of its checkpoint by content.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub input_sha256: Option<String>,
    /// What the input carried that the output does not ([`io::not_carried`]), for a file run.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub dropped: Vec<String>,
}

/// What a run of the cluster engine ([`crate::cluster`]) adds to its [`Report`].
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct ClusterStats {
    pub ranks: usize,
    /// Iterations found completed in the checkpoint when this run started.
    pub resumed_after: usize,
    pub checkpoint_every: usize,
    pub owned_vertices_min: u64,
    pub owned_vertices_max: u64,
    /// Vertices a rank holds (owned and its three rings), largest over the ranks.
    pub region_vertices_max: u64,
    /// Vertex values sent per iteration, all ranks together, and the largest share of one rank.
    pub halo_values_per_iteration: u64,
    pub halo_bytes_per_iteration_max: u64,
    /// Largest peak anonymous memory of a rank over the whole run (rank 0's includes preparing
    /// the plan), and while smoothing only.
    pub peak_anon_max: u64,
    pub smoothing_peak_anon_max: u64,
}

/// Memory and I/O of a run.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct MemoryStats {
    pub budget: u64,
    /// Where `budget` came from: "flag", "available", "cgroup", "rlimit" or "fallback".
    pub budget_source: BudgetSource,
    /// "heap" when the mesh fits the budget, else "scratch" (memory-mapped files); "cluster" for
    /// the ranks of the cluster engine.
    pub storage: &'static str,
    /// Bytes of all the scratch files the run made, one after another.
    pub scratch_bytes: u64,
    /// The most bytes of scratch files alive at one time: the free space the scratch directory
    /// needed.
    pub scratch_peak_bytes: u64,
    /// Peak anonymous resident memory (RssAnon), file-backed pages excluded; 0 if unknown.
    pub peak_anon: u64,
    pub bytes_read: u64,
    pub bytes_written: u64,
}

/// Seconds per phase.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct PhaseTimings {
    /// Reading the input; out of core also its second read for the write (see [`run_file`]).
    pub ingest: f64,
    pub reorder: f64,
    pub topology: f64,
    pub partition: f64,
    pub smoothing: f64,
    pub write: f64,
    pub metrics: f64,
    /// The deviation field and its statistics (in the write phase, before the write).
    pub deviation: f64,
    /// The input's SHA-256: for a report's record, taken by the command line beside the run (not
    /// in `total`); in a cluster run, the key of its checkpoint (in `total`).
    pub hash: f64,
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
/// vertex order and layout). Out of core (a binary PLY read into scratch files) the input, held
/// open, is read a second time for the write instead of keeping its triangles while smoothing; a
/// file rewritten in place meanwhile is an error, and nothing is written.
pub fn run_file(
    input: &Path,
    output: &Path,
    opts: &Options,
    engine: &EngineSettings,
    observer: &mut dyn Observer,
) -> Result<Report> {
    run_file_with(
        input,
        output,
        opts,
        engine,
        observer,
        |plan, storage, obs| plan.smooth_stopped(storage, opts, engine.statistics, obs),
    )
}

/// What a smoothing step returns: the iteration records, and what the automatic stop measured.
pub(crate) type Stopped = (Vec<IterationRecord>, Option<AutoStopStats>);

/// [`run_file`] with the smoothing step given: `smooth(plan, storage, observer)` moves the plan's
/// positions and returns the iteration records and the automatic stop's figures (the
/// multiresolution mode's levels plug in here).
pub(crate) fn run_file_with(
    input: &Path,
    output: &Path,
    opts: &Options,
    engine: &EngineSettings,
    observer: &mut dyn Observer,
    smooth: impl FnOnce(&mut Plan, &Storage, &mut dyn Observer) -> Result<Stopped> + Send,
) -> Result<Report> {
    // The phases the observer is told of are the ones whose disk traffic is taken.
    let observer = &mut DiskMeter::new(observer);
    let start = Start::new(opts, engine)?;
    let mut t = PhaseTimings::default();
    let Prepared {
        storage,
        mut mesh,
        counts: (n, n_triangles),
        kept,
        mut plan,
        bytes_read,
    } = prepare(input, output, opts, engine, &start, &mut t, observer)?;

    let smoothed = start.pool.install(|| -> Result<_> {
        // The plan holds its own (reordered) copy: in core the input-order positions are not
        // needed until the write, so their memory is given back while smoothing (the peak of an
        // in-core run). Out of core (`kept`) `prepare` gave the input's arrays back already, and
        // the file, held open, is read again for the write.
        // The deviation field needs the input positions at the write: kept in core, read again
        // out of core.
        let mut input_positions = match engine.deviation.is_on() {
            true => std::mem::take(&mut mesh.positions),
            false => Buf::default(),
        };
        mesh.positions = Buf::default();
        let smoothed = smooth_planned(
            &mut plan,
            &storage,
            opts,
            engine,
            &mesh.source,
            &mut t,
            observer,
            |plan, obs| smooth(plan, &storage, obs),
        )?;
        let r = &plan.reordered;
        observer.mesh_at(Moment::AfterSmoothing, &r.positions, &r.triangles, &storage)?;
        // Out of core the output is measured here, and the plan's connectivity is given back
        // before the positions are put back in the input's order when the measure leaves them
        // as they are (its layout is `f64` or `f32`): what is alive then is the positions twice
        // and the permutation, not the whole plan beside the restored positions (40 B per
        // triangle less). Else (integers, text: positions rounded in place for the measure, and
        // the write's normals come from the unrounded ones) the output is measured after the
        // restore. The plan is given back before the input is read again. In core the output is
        // measured beside the write.
        let early = kept.is_some() && !measuring_rounds_in_place(output, &mesh);
        let mut measured = None;
        if early {
            if engine.with_stats {
                // The restore reads the positions next.
                measured = Some(measure_output(
                    &mut plan,
                    output,
                    &mesh,
                    &smoothed,
                    Afterwards::Read,
                    observer,
                    &mut t,
                )?);
            }
            plan.release_connectivity();
        }
        mesh.positions = metered(observer, Phase::Restore, n as u64, |m| {
            let mut positions = storage.zeroed(n)?;
            plan.positions_in_input_order_metered(&mut positions, m);
            Ok(positions)
        })?;
        let Some(kept) = kept else {
            // The plan is kept past the write only to measure the output as written, beside it.
            return Ok((smoothed, input_positions, Some(plan), None));
        };
        if !early && engine.with_stats {
            // Integers or text (an `f32` output is measured early), rounded in place.
            measured = Some(measure_output(
                &mut plan,
                output,
                &mesh,
                &smoothed,
                Afterwards::Unread,
                observer,
                &mut t,
            )?);
        }
        drop(plan);
        let clock = Instant::now();
        // The input's positions are read again only when the deviation is measured
        // (`--deviation-stats`, `--deviation-field`, `--tolerance`): the write has the smoothed
        // ones (12 B per triangle less on the disk beside the input and output).
        let coordinates = match engine.deviation.is_on() {
            true => io::Coordinates::Decode,
            false => io::Coordinates::Skip,
        };
        let (read, vertices) = metered(observer, Phase::Read, bytes_read, |m| {
            kept.read_again(&storage, m, coordinates)
        })?;
        t.ingest += clock.elapsed().as_secs_f64();
        if vertices != n || read.triangles.len() != n_triangles {
            return Err(Error::invalid(
                input,
                "read again for the write, it holds another mesh; nothing was written",
            ));
        }
        mesh.triangles = read.triangles;
        if engine.deviation.is_on() {
            input_positions = read.positions;
        }
        Ok((smoothed, input_positions, None, measured))
    })?;

    let (mut smoothed, input_positions, plan, measured) = smoothed;
    let field = match engine.deviation.is_on() {
        true => {
            let clock = Instant::now();
            let disk = DiskBytes::now();
            let stored = io::Stored::of(output, &mesh);
            let made = start.pool.install(|| -> Result<_> {
                let field = deviation::field(
                    &storage,
                    &input_positions,
                    &mesh.positions,
                    &mesh.triangles,
                    stored.as_ref(),
                )?;
                let stats = deviation::statistics(&field, engine.deviation.tolerance);
                Ok((field, stats))
            })?;
            t.deviation = clock.elapsed().as_secs_f64();
            observer.add_deviation(disk);
            Some(made)
        }
        false => None,
    };
    drop(input_positions);
    smoothed.deviation = field.as_ref().map(|(_, stats)| stats.clone());
    let scale = field
        .as_ref()
        .map_or(0.0, |(_, stats)| engine.deviation.colour_scale(stats));
    let colour = |i: usize| {
        let signed = field.as_ref().map_or(0.0, |(f, _)| f.signed[i]);
        crate::metrics::deviation::colour(signed, scale)
    };
    let values = field
        .as_ref()
        .filter(|_| engine.deviation.field)
        .map(|(f, _)| io::VertexValues {
            quality: &f.signed,
            colours: match engine.deviation.colours {
                true => Some(&colour as &(dyn Fn(usize) -> [u8; 3] + Sync)),
                false => None,
            },
        });

    let (m, sm) = (&mesh, &smoothed);
    let measure = plan.filter(|_| engine.with_stats).map(|mut plan| {
        // Beside the write, whose progress the display shows.
        move || {
            let unseen = Meter::default();
            Ok(output_stats(
                &mut plan,
                output,
                m,
                sm,
                Afterwards::Unread,
                &unseen,
            ))
        }
    });
    let written = write_measured(
        &start.pool,
        output,
        &mesh,
        values.as_ref(),
        bytes_read,
        &mut t,
        observer,
        measure,
    )?;
    smoothed.output_stats = measured.unwrap_or(written);
    t.total = start.clock.elapsed().as_secs_f64();
    let memory = MemoryStats {
        budget: start.budget.bytes,
        budget_source: start.budget.source,
        storage: if storage.is_mapped() {
            "scratch"
        } else {
            "heap"
        },
        scratch_bytes: storage.mapped_bytes(),
        scratch_peak_bytes: storage.peak_mapped_bytes(),
        peak_anon: start.sampler.peak(),
        bytes_read,
        bytes_written: std::fs::metadata(output).map(|m| m.len()).unwrap_or(0),
    };
    let disk = observer.finish();
    let mut report = smoothed.report(&mesh, start.pool.current_num_threads(), memory, t, disk);
    report.dropped = io::not_carried(&mesh.source, output);
    Ok(report)
}

/// What every file run sets up first, once: the options checked, the memory budget parsed and
/// checked against the iteration records, the thread pool, the clock and the memory sampler.
pub(crate) struct Start {
    pub clock: Instant,
    pub sampler: PeakSampler,
    pub budget: Budget,
    /// The budget less the iteration records: the mesh decides heap or scratch in it.
    pub mesh_budget: u64,
    pub pool: rayon::ThreadPool,
}

impl Start {
    pub(crate) fn new(opts: &Options, engine: &EngineSettings) -> Result<Start> {
        opts.check()?;
        engine.deviation.check()?;
        let clock = Instant::now();
        let sampler = PeakSampler::start(std::time::Duration::from_millis(20));
        let budget = engine.budget_and_source()?;
        memory::check_records(opts.iterations, budget.bytes)?;
        let pool = super::thread_pool(engine.threads)?;
        let mesh_budget = budget
            .bytes
            .saturating_sub(memory::records_bytes(opts.iterations));
        Ok(Start {
            clock,
            sampler,
            budget,
            mesh_budget,
            pool,
        })
    }
}

/// A read input and its plan, pinned and creased, ready to smooth.
pub(crate) struct Prepared {
    pub storage: Storage,
    /// The input: out of core (held open in `kept`, its triangles in scratch) its source alone,
    /// its arrays given back once the plan has its copy.
    pub mesh: Mesh,
    /// The input's vertices and triangles.
    pub counts: (usize, usize),
    /// The input held open for a second read (see [`io::read_mesh_kept`]), when it is out of
    /// core: then `mesh` holds its source alone.
    pub kept: Option<io::Kept>,
    pub plan: Plan,
    pub bytes_read: u64,
}

/// Read `input` into the storage its size asks for within `start`'s budget (heap or scratch),
/// resolve the pins and make the plan on `start`'s pool; reading timed into `t`, the plan's
/// phases told to `observer`.
pub(crate) fn prepare(
    input: &Path,
    output: &Path,
    opts: &Options,
    engine: &EngineSettings,
    start: &Start,
    t: &mut PhaseTimings,
    observer: &mut dyn Observer,
) -> Result<Prepared> {
    let bytes_read = std::fs::metadata(input)
        .map_err(|e| Error::io(input, e))?
        .len();
    let storage = storage_for(input, output, engine, start.mesh_budget, opts)?;
    let clock = Instant::now();
    let (mesh, kept) = metered(observer, Phase::Read, bytes_read, |m| {
        io::read_mesh_kept(input, &storage, m)
    })?;
    t.ingest += clock.elapsed().as_secs_f64();
    if mesh.triangles.is_empty() && opts.iterations > 0 {
        return Err(Error::invalid(
            input,
            "no triangles to smooth (a point cloud or an empty mesh)",
        ));
    }
    check_in_memory_budget(input, &storage, &mesh, start.mesh_budget)?;
    let pins = engine.pins.resolve(&mesh, Some(input))?.unwrap_or_default();
    let counts = (mesh.positions.len(), mesh.triangles.len());
    // Only an input whose triangles went to scratch is read again (in core it stays in memory).
    let kept = kept.filter(|_| mesh.triangles.is_mapped());
    let mut mesh = mesh;
    let plan = start.pool.install(|| -> Result<_> {
        let (layout, weld) = (engine.layout(), opts.welding());
        // Out of core the input is read again for the write, so its positions are given to the
        // reorder, which lets them go once the plan has its copy (before the triangles are
        // renumbered beside them: 12 B per triangle at the phase's peak).
        let positions = match kept.is_some() {
            true => Input::Given(std::mem::take(&mut mesh.positions)),
            false => Input::Lent(&mesh.positions),
        };
        // A run that measures its input counts its components as the reorder sorts the
        // triangles (no pass of its own over them; a plan without the count finds them when
        // it is measured, `Plan::info_metered`).
        let ordered = Plan::reorder(
            &storage,
            positions,
            &mesh.triangles,
            layout,
            weld,
            engine.with_stats,
            observer,
        )
        .map_err(|e| e.in_file(input))?;
        if kept.is_some() {
            // Out of core the input is read again for the write: its arrays go as soon as the
            // plan has its copy, not after the topology is built beside them (24 B per triangle
            // less at the run's peak).
            mesh.triangles = Buf::default();
        }
        let mut plan = Plan::of_reordered(&storage, ordered, layout, observer)
            .map_err(|e| e.in_file(input))?;
        plan.pin(&pins);
        plan.crease(&storage, opts.crease_angle)
            .map_err(|e| e.in_file(input))?;
        plan.stored = io::Stored::of(output, &mesh);
        Ok(plan)
    })?;
    Ok(Prepared {
        storage,
        mesh,
        counts,
        kept,
        plan,
        bytes_read,
    })
}

/// Write `mesh` to `output` (atomically, see [`io::write_mesh`]) on `pool`, its progress told to
/// `observer` against the size it should have; `measure`, if given, measures the output beside
/// the (sequential) write, inside its phase. Seconds go into `t`; returns what `measure` gave
/// (`None` without it).
#[allow(clippy::too_many_arguments)]
pub(crate) fn write_measured(
    pool: &rayon::ThreadPool,
    output: &Path,
    mesh: &Mesh,
    values: Option<&io::VertexValues>,
    input_bytes: u64,
    t: &mut PhaseTimings,
    observer: &mut dyn Observer,
    measure: Option<impl FnOnce() -> Result<Option<MeshInfo>> + Send>,
) -> Result<Option<MeshInfo>> {
    let meter = Arc::new(Meter::new(expected_output_bytes(input_bytes, output, mesh)));
    observer.phase_start(Phase::Write, &meter);
    let (written, measured) = pool.install(|| {
        rayon::join(
            || {
                let clock = Instant::now();
                match values {
                    Some(v) => io::write_mesh_with(output, mesh, v, &meter),
                    None => io::write_mesh_metered(output, mesh, &meter),
                }
                .map(|()| clock.elapsed().as_secs_f64())
            },
            || {
                let clock = Instant::now();
                let stats = measure.map(|f| f());
                (stats, clock.elapsed().as_secs_f64())
            },
        )
    });
    observer.phase_end(Phase::Write);
    t.write = written?;
    let (stats, seconds) = measured;
    match stats {
        Some(stats) => {
            t.metrics += seconds;
            stats
        }
        None => Ok(None),
    }
}

/// [`output_stats`] as a phase of its own, timed into `t`.
fn measure_output(
    plan: &mut Plan,
    output: &Path,
    mesh: &Mesh,
    smoothed: &Smoothed,
    afterwards: Afterwards,
    observer: &mut dyn Observer,
    t: &mut PhaseTimings,
) -> Result<Option<MeshInfo>> {
    let clock = Instant::now();
    let vertices = plan.len() as u64;
    let stats = metered(observer, Phase::Statistics, vertices, |m| {
        Ok(output_stats(plan, output, mesh, smoothed, afterwards, m))
    })?;
    t.metrics += clock.elapsed().as_secs_f64();
    Ok(stats)
}

/// The statistics of the output file as stored (rounded to its coordinate type: `float`, or
/// `uchar`, `short`, … of a PLY layout, or printed as single-precision text), from the plan's
/// positions as [`stored_output_stats`] reads them, without reading the file back. The counts
/// are the input's: the output has the same connectivity. STL rebuilds its vertices from the
/// triangles' corners when read; its figures are those of the plan's vertices in `f32`. The
/// vertices are counted into `meter` as they are measured.
fn output_stats(
    plan: &mut Plan,
    output: &Path,
    mesh: &Mesh,
    smoothed: &Smoothed,
    afterwards: Afterwards,
    meter: &Meter,
) -> Option<MeshInfo> {
    let r = &mut plan.reordered;
    let info = smoothed.input_stats.clone()?;
    stored_output_stats(
        info,
        output,
        mesh,
        &mut r.positions,
        afterwards,
        &r.triangles,
        &plan.topology,
        meter,
    )
}

/// Whether the positions [`stored_output_stats`] measures are read after it (then an `f32`
/// output is measured through [`crate::metrics::AsF32`]) or not (then they are rounded in place
/// once, which costs less than rounding each read).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Afterwards {
    Read,
    Unread,
}

/// `info`, the input's statistics, with the geometry of `positions` (plan order, over the plan's
/// `triangles` and `topo`) as the write stores them in `output`: read as stored when that is
/// `f64`, or `f32` with the positions read `afterwards`; else rounded here in place as
/// [`io::Stored`] says ([`measuring_rounds_in_place`]). `None` for an output that `write_mesh`
/// refuses (its error is the write's). The engine's and the cluster's writes measure their
/// outputs so.
#[allow(clippy::too_many_arguments)]
pub(crate) fn stored_output_stats(
    mut info: MeshInfo,
    output: &Path,
    mesh: &Mesh,
    positions: &mut [glam::DVec3],
    afterwards: Afterwards,
    triangles: &[[u32; 3]],
    topo: &crate::Topology,
    meter: &Meter,
) -> Option<MeshInfo> {
    let stored = io::Stored::of(output, mesh)?;
    let origin = glam::DVec3::from(info.volume_origin);
    let geometry = if stored.is_exact() {
        reduce::geometry_about(positions, triangles, topo, origin, meter)
    } else if stored.is_f32() && afterwards == Afterwards::Read {
        let read = crate::metrics::AsF32(positions);
        reduce::geometry_about_as(positions, &read, triangles, topo, origin, meter)
    } else {
        reduce::for_chunks_mut(positions, |_, chunk| {
            chunk.iter_mut().for_each(|p| *p = stored.round(*p))
        });
        reduce::geometry_about(positions, triangles, topo, origin, meter)
    };
    info.set_geometry(geometry);
    Some(info)
}

/// Whether [`stored_output_stats`] rounds the positions in place to measure `mesh` written to
/// `output` (a layout other than `f64` or `f32`: integers, text).
fn measuring_rounds_in_place(output: &Path, mesh: &Mesh) -> bool {
    io::Stored::of(output, mesh).is_some_and(|s| !s.is_exact() && !s.is_f32())
}

/// Smooth an in-memory `mesh` in place (see [`crate::smooth()`], the crate's front door).
pub(crate) fn run_mesh(
    mesh: &mut Mesh,
    opts: &Options,
    engine: &EngineSettings,
    layout: Layout,
    observer: &mut dyn Observer,
) -> Result<Report> {
    opts.check()?;
    // As file runs do: an iteration count whose records the memory cannot hold is refused
    // before any work, not hours into the run.
    memory::check_records(opts.iterations, engine.budget_and_source()?.bytes)?;
    let observer = &mut DiskMeter::new(observer);
    let start = Instant::now();
    let pool = super::thread_pool(engine.threads)?;
    let storage = Storage::heap();
    let mut t = PhaseTimings::default();
    let pins = engine.pins.resolve(mesh, None)?.unwrap_or_default();
    let smoothed = pool.install(|| -> Result<_> {
        let mut plan = Plan::new_observed(
            &storage,
            &mesh.positions,
            &mesh.triangles,
            layout,
            opts.welding(),
            observer,
        )?;
        plan.pin(&pins);
        plan.crease(&storage, opts.crease_angle)?;
        let mut smoothed = smooth_planned(
            &mut plan,
            &storage,
            opts,
            engine,
            &mesh.source,
            &mut t,
            observer,
            |plan, obs| plan.smooth_stopped(&storage, opts, engine.statistics, obs),
        )?;
        let r = &plan.reordered;
        observer.mesh_at(Moment::AfterSmoothing, &r.positions, &r.triangles, &storage)?;
        let clock = Instant::now();
        smoothed.output_stats = smoothed.input_stats.clone().map(|mut info| {
            let origin = glam::DVec3::from(info.volume_origin);
            info.set_geometry(plan.geometry_about(origin, &Meter::default()));
            info
        });
        t.metrics += clock.elapsed().as_secs_f64();
        // Not `metered`: the caller's mesh is smoothed by now, so there is nothing left to stop.
        let meter = Arc::new(Meter::new(mesh.positions.len() as u64));
        observer.phase_start(Phase::Restore, &meter);
        plan.positions_in_input_order_metered(&mut mesh.positions, &meter);
        observer.phase_end(Phase::Restore);
        Ok(smoothed)
    })?;
    t.total = start.elapsed().as_secs_f64();
    let memory = MemoryStats {
        storage: "heap",
        ..MemoryStats::default()
    };
    let disk = observer.finish();
    Ok(smoothed.report(mesh, pool.current_num_threads(), memory, t, disk))
}

/// What the smoothing phase of a run gives its report.
struct Smoothed {
    records: Vec<IterationRecord>,
    auto_stop: Option<AutoStopStats>,
    input_stats: Option<MeshInfo>,
    output_stats: Option<MeshInfo>,
    plan: PlanStats,
    deviation: Option<DeviationStats>,
}

/// The phases both runs share, on the current pool: the input's statistics (when asked) and
/// `smooth(plan, observer)` (the output's statistics are each run's own); the plan's preparation
/// and these phases timed into `t`, and told to `observer`. `storage` places the statistics'
/// working arrays as it placed the plan's.
#[allow(clippy::too_many_arguments)]
fn smooth_planned(
    plan: &mut Plan,
    storage: &Storage,
    opts: &Options,
    engine: &EngineSettings,
    source: &crate::mesh::Source,
    t: &mut PhaseTimings,
    observer: &mut dyn Observer,
    smooth: impl FnOnce(&mut Plan, &mut dyn Observer) -> Result<Stopped>,
) -> Result<Smoothed> {
    t.add_preparation(&plan.timings);
    let r = &plan.reordered;
    observer.mesh_at(Moment::BeforeSmoothing, &r.positions, &r.triangles, storage)?;
    let clock = Instant::now();
    let input_stats = match engine.with_stats {
        true => Some(metered(
            observer,
            Phase::Statistics,
            plan.len() as u64,
            |m| plan.info_metered(source, storage, m),
        )?),
        false => None,
    };
    t.metrics += clock.elapsed().as_secs_f64();

    let clock = Instant::now();
    let meter = Arc::new(Meter::new(opts.iterations as u64));
    observer.phase_start(Phase::Smooth, &meter);
    let counted = &mut IterationMeter {
        inner: &mut *observer,
        meter: &meter,
    };
    let stopped = smooth(plan, counted);
    if stopped.is_ok() {
        // The automatic stop may end before the cap: the rest is not to be done.
        meter.complete();
    }
    observer.phase_end(Phase::Smooth);
    let (records, auto_stop) = stopped?;
    plan.follow_welds();
    t.smoothing = clock.elapsed().as_secs_f64();

    Ok(Smoothed {
        records,
        auto_stop,
        input_stats,
        output_stats: None,
        plan: plan.stats(opts.method.unit().schedule(opts).footprint()),
        deviation: None,
    })
}

impl Smoothed {
    fn report(
        self,
        mesh: &Mesh,
        threads: usize,
        memory: MemoryStats,
        timings: PhaseTimings,
        disk: Option<DiskTraffic>,
    ) -> Report {
        Report {
            input_format: mesh.source.format,
            vertices: mesh.positions.len(),
            triangles: mesh.triangles.len(),
            iterations_run: self.records.len(),
            auto_stop: self.auto_stop,
            records: self.records,
            input_stats: self.input_stats,
            output_stats: self.output_stats,
            plan: PlanStats {
                threads,
                ..self.plan
            },
            memory,
            timings,
            disk,
            cluster: None,
            deviation: self.deviation,
            input_sha256: None,
            dropped: Vec::new(),
        }
    }
}

/// What the output of `mesh` at `output` should weigh, for the write's meter: the input's size
/// when it is written in the input's format (the same layout and counts: exact for binary files,
/// close for text), else a rough size per vertex and triangle of the output's format. The write
/// corrects it once done.
fn expected_output_bytes(input_bytes: u64, output: &Path, mesh: &Mesh) -> u64 {
    let format = io::Format::from_extension(output);
    if format.is_some() && format == mesh.source.format {
        return input_bytes;
    }
    let (v, t) = (mesh.positions.len() as u64, mesh.triangles.len() as u64);
    match format {
        Some(io::Format::Stl) => 84 + 50 * t,
        Some(io::Format::Obj | io::Format::Off) => 30 * v + 20 * t,
        _ => 12 * v + 13 * t,
    }
}

/// Heap or scratch, decided before reading by the memory model: from the file size
/// ([`memory::in_core_bytes_of_run`], which counts what `opts` and the deviation field keep
/// beside the positions), or from a PLY header's counts when they say more
/// ([`memory::in_core_bytes_of_counts`]: a file of many vertices and few faces), with the
/// schedule of its patches ([`memory::schedule_bytes`]), which is on the heap either way.
pub(crate) fn storage_for(
    input: &Path,
    output: &Path,
    engine: &EngineSettings,
    budget: u64,
    opts: &Options,
) -> Result<Storage> {
    let size = io::content_size(input)?;
    let field = engine.deviation.is_on();
    let by_size = memory::in_core_bytes_of_run(size, opts, field);
    let (by_counts, vertices) = match io::header_counts(input) {
        Some((v, f)) => (memory::in_core_bytes_of_counts(v, f, opts, field), v),
        None => (0, size / memory::FILE_BYTES_PER_TRIANGLE / 2),
    };
    let schedule = memory::schedule_bytes(vertices, engine.patch_size);
    if by_size.max(by_counts).saturating_add(schedule) <= budget {
        return Ok(Storage::heap().with_budget(budget));
    }
    let dir = match &engine.scratch {
        Some(d) => d.clone(),
        None => scratch_beside(output),
    };
    Ok(Storage::scratch(&dir)?.with_budget(budget))
}

/// Only binary PLY decodes straight into scratch; other formats land on the heap. Refuse to go on
/// rather than silently exceed the budget.
fn check_in_memory_budget(input: &Path, storage: &Storage, mesh: &Mesh, budget: u64) -> Result<()> {
    let heap = memory::mesh_bytes(mesh.positions.len() as u64, mesh.triangles.len() as u64);
    if storage.is_mapped() && !mesh.positions.is_mapped() && heap > budget {
        return Err(Error::resource(format!(
            "{}: this format is read into memory ({}), more than the memory budget of {}; convert it to binary PLY on a larger machine, or raise the budget",
            input.display(),
            memory::format_size(heap),
            memory::format_size(budget)
        )));
    }
    Ok(())
}

/// The directory of `output` (the current directory for a bare file name).
fn scratch_beside(output: &Path) -> PathBuf {
    match output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}
