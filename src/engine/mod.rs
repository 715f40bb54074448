//! The engine: the one place that combines the plan, the kernels and the threads.
//!
//! - [`plan`]: a [`Plan`] orders the mesh (Morton curve), builds its [`Topology`](crate::Topology), cuts it into
//!   patches and colours them; built once, smoothed any number of times.
//! - [`deviation`]: the deviation field of a run's output against its input (or of two meshes)
//!   and its statistics.
//! - [`auto`]: the automatic stop (`Options::auto_stop`): when the noise is gone.
//! - [`iterate`]: the one iteration loop: Jacobi rounds for `laplacian` and `taubin`, colour by
//!   colour Gauss–Seidel sweeps for the stencil methods, statistics when asked. The cluster
//!   engine's ranks run the same loop, exchanging halos through its [`share::Share`] hook.
//! - [`share`]: how the loop and the automatic stop see the processes that run them.
//! - [`reduce`]: deterministic parallel sums (volume, area, centroid, displacement, neighbour
//!   sums) over fixed-size chunks, so results do not depend on the thread count.
//! - [`observer`]: per-iteration records and the [`Observer`] that receives them.
//! - [`run`]: the run from file to file, its settings and its [`Report`].
//! - [`pins`]: the caller's pinned vertices ([`Pins`]), fixed in the plan's topology.
//! - [`memory`]: the memory budget, the memory model (bytes per triangle) and peak sampling.
//! - [`disk`]: the disk traffic of a run's phases, from `/proc/self/io`.

pub mod auto;
pub mod deviation;
pub mod disk;
pub mod iterate;
pub mod memory;
pub mod observer;
pub mod pins;
pub mod plan;
pub mod reduce;
pub mod run;
pub mod seam;
pub mod share;

use glam::DVec3;

pub use auto::{AutoStopStats, StopReason};
pub use deviation::DeviationSettings;
pub use disk::{DiskBytes, DiskTraffic};
pub use iterate::Reference;
pub use observer::{IterationRecord, Meter, Moment, Observer, Phase, Quiet, Statistics, Unit};
pub use pins::{PinSet, Pins};
pub use plan::{
    DEFAULT_PATCH_SIZE, FixedVertices, Layout, Plan, PlanStats, PrepTimings, mesh_info,
};
pub use run::{ClusterStats, EngineSettings, MemoryStats, PhaseTimings, Report, run_file};
pub(crate) use run::{run_file_with, storage_for};

use crate::error::{Error, Result};
use crate::mesh::{Buf, Mesh, Storage};
use crate::schedule;
use crate::smooth::Options;

/// Smooth `mesh` in place with `opts` (method, iterations, step sizes), on all cores, and return
/// what the run did. The result is the one `vcsmooth smooth` writes for the same mesh and options
/// with the default patch size: bit-identical for any thread count.
///
/// ```
/// let mut mesh = vcsmooth::shapes::icosphere(3);
/// vcsmooth::shapes::add_normal_noise(&mut mesh, 0.3, 7);
/// let opts = vcsmooth::Options::default(); // vcs, 10 iterations
/// let report = vcsmooth::smooth(&mut mesh, &opts)?;
/// assert!((report.records.last().unwrap().volume_pct - 100.0).abs() < 1e-6);
/// # Ok::<(), vcsmooth::Error>(())
/// ```
pub fn smooth(mesh: &mut Mesh, opts: &Options) -> Result<Report> {
    smooth_with(mesh, opts, &EngineSettings::default(), &mut Quiet)
}

/// [`smooth`] with the engine's settings (threads, patch size, statistics) and an observer.
pub fn smooth_with(
    mesh: &mut Mesh,
    opts: &Options,
    engine: &EngineSettings,
    observer: &mut dyn Observer,
) -> Result<Report> {
    run::run_mesh(mesh, opts, engine, engine.layout(), observer)
}

/// [`smooth_with`] in the input's own vertex order as one patch ([`Layout::Whole`]): the
/// sequential reference order, which `refine` and `curves` use.
pub fn smooth_in_order(
    mesh: &mut Mesh,
    opts: &Options,
    engine: &EngineSettings,
    observer: &mut dyn Observer,
) -> Result<Report> {
    run::run_mesh(mesh, opts, engine, Layout::Whole, observer)
}

impl Plan {
    /// Smooth the plan's positions in place with `opts` on the current rayon pool, measuring the
    /// statistics `when` says (see [`iterate`] for the order of work). `storage` places the
    /// working buffers (the one the plan was built on). The result is bit-identical for any
    /// number of threads and any storage placement.
    pub fn smooth(
        &mut self,
        storage: &Storage,
        opts: &Options,
        when: Statistics,
        observer: &mut dyn Observer,
    ) -> Result<Vec<IterationRecord>> {
        Ok(self.smooth_stopped(storage, opts, when, observer)?.0)
    }

    /// [`Plan::smooth`], and with `opts.auto_stop` what the automatic stop measured (the records
    /// say how many iterations ran; this says why they stopped).
    pub fn smooth_stopped(
        &mut self,
        storage: &Storage,
        opts: &Options,
        when: Statistics,
        observer: &mut dyn Observer,
    ) -> Result<(Vec<IterationRecord>, Option<AutoStopStats>)> {
        let mut records = Vec::new();
        let auto = self.smooth_into(storage, opts, when, observer, Some(&mut records), None)?;
        Ok((records, auto))
    }

    /// [`Plan::smooth_stopped`] with the records' volumes and areas measured against `reference`
    /// instead of the positions the smoothing starts from (the multiresolution mode's input
    /// level, whose smoothing starts from the coarse levels' result), and the deviation bound
    /// measured from `input` (indexed like the plan's positions) when given. The automatic stop still
    /// estimates the noise on the positions it starts from, and takes its offsets about the
    /// reference's origin.
    pub(crate) fn smooth_against(
        &mut self,
        storage: &Storage,
        opts: &Options,
        when: Statistics,
        reference: Reference,
        input: Option<&[DVec3]>,
        observer: &mut dyn Observer,
    ) -> Result<(Vec<IterationRecord>, Option<AutoStopStats>)> {
        let mut records = Vec::new();
        let against = Some((reference, input));
        let auto = self.smooth_into(storage, opts, when, observer, Some(&mut records), against)?;
        Ok((records, auto))
    }

    /// [`Plan::smooth`] measuring only the last iteration and keeping no record: a step whose
    /// records nobody reads (a coarse level of the multiresolution mode), so that its memory does
    /// not grow with the iteration count.
    pub fn smooth_unrecorded(&mut self, storage: &Storage, opts: &Options) -> Result<()> {
        self.smooth_into(storage, opts, Statistics::Last, &mut Quiet, None, None)
            .map(drop)
    }

    /// [`Plan::smooth`], the records into `records` when given; what the automatic stop
    /// measured, when the options ask for it.
    fn smooth_into(
        &mut self,
        storage: &Storage,
        opts: &Options,
        when: Statistics,
        observer: &mut dyn Observer,
        records: Option<&mut Vec<IterationRecord>>,
        against: Option<(Reference, Option<&[DVec3]>)>,
    ) -> Result<Option<AutoStopStats>> {
        let (reference, input_positions) = match against {
            Some((r, input)) => (Some(r), input),
            None => (None, None),
        };
        opts.check()?;
        let Plan {
            reordered,
            topology: topo,
            patches,
            schedule,
            in_memory,
            stored,
            layout,
            ..
        } = self;
        let n = reordered.positions.len();
        let (schedule_of, needs) = (
            opts.method.unit().schedule(opts),
            opts.method.unit().needs(),
        );
        let sized = |wanted: bool| if wanted { n } else { 0 };
        // The stencil methods' copy before a measured sweep and their spare buffer, unless the
        // method measures its moves itself.
        let copies =
            !schedule_of.is_jacobi() && iterate::copies_positions(opts.method.unit(), opts);
        let mut prev: Buf<DVec3> = storage.zeroed(sized(copies || needs.aux))?;
        // Instead of the copy, the seam's positions, for a method whose patches measure it.
        let mut seam = match iterate::keeps_seam(opts.method.unit(), opts) {
            true => Some(seam::Seam::of(topo, patches, |_| true, storage)?),
            false => None,
        };
        // Out of core a stencil method's neighbour sums are each patch's own
        // (`PatchField::rebuild_sums`): an array of the mesh's size would be 12 B per triangle
        // more to pass through the page cache.
        let keep_sums = *in_memory;
        // Out of core a method that can is given its shares on the patches' border alone: the
        // patches take the others' as they start.
        let border_only = !*in_memory && iterate::keeps_border(opts.method.unit(), opts);
        let border: Option<Buf<u32>> = match border_only {
            true => Some(crate::partition::patch_border(topo, patches, storage)?),
            false => None,
        };
        let mut scratch: Buf<DVec3> = match &border {
            Some(border) => storage.zeroed(border.len())?,
            None => storage.zeroed(sized(schedule_of.is_jacobi() || needs.shares || keep_sums))?,
        };
        let mut counts: Buf<u8> = storage.zeroed(sized(needs.counts))?;
        let faces = reordered.triangles.len();
        let mut face_vectors: Buf<DVec3> = storage.zeroed(needs.face_vectors * faces)?;
        let mut face_scalars: Buf<f64> = storage.zeroed(needs.face_scalars * faces)?;
        // The input positions, for a deviation bound or a method that reads them: in the plan's
        // storage (scratch out of core).
        let input: Buf<DVec3> = match opts.keeps_input() {
            true => storage.copy_of(input_positions.unwrap_or(&reordered.positions))?,
            false => Buf::default(),
        };
        let mut auto = match opts.auto_stop {
            true => Some(auto::AutoStop::new(storage, n, opts)?),
            false => None,
        };
        // The read-ahead advises each patch's vertex range: not of the border's array, which is
        // indexed otherwise (and small).
        let advisors: Vec<_> = [
            reordered.positions.advisor(),
            scratch.advisor().filter(|_| border.is_none()),
            input.advisor(),
        ]
        .into_iter()
        .flatten()
        .collect();
        // Out of core the read-ahead brings each patch's ranges and its rings' pages, scattered
        // over other patches, and the sweep's faults read their page alone
        // (`iterate::sweep_colours`).
        // Only for the stencil sweeps of a plan cut into patches: Jacobi methods read no rings.
        let rings = match !advisors.is_empty() && !schedule_of.is_jacobi() && patches.len() > 1 {
            true => Some(schedule::PatchRings::of(topo, patches, schedule, storage)?),
            false => None,
        };
        let ahead = schedule::ReadAhead {
            topo,
            patches,
            rings: rings.as_ref(),
            vertices: advisors,
            triangles: reordered.triangles.advisor(),
        };
        let tris: &[[u32; 3]] = &reordered.triangles;
        let pos: &mut [DVec3] = &mut reordered.positions;
        let mut alone = iterate::Alone {
            vertices: n,
            triangles: tris.len(),
        };
        schedule::with_prefetch(ahead, |prefetch| {
            let mesh = iterate::Sweep {
                topo,
                tris,
                sorted: !matches!(layout, Layout::Whole),
                patches,
                colours: &schedule.colours,
                ring_colours: &schedule.ring_colours,
                prefetch: (!*in_memory).then_some(prefetch),
                loops: None,
                tiles: *in_memory,
                border: border.as_deref(),
            };
            let reference = reference.unwrap_or_else(|| Reference::measure(&mesh, pos, &alone));
            let buffers = iterate::Buffers {
                pos,
                scratch: &mut scratch,
                prev: &mut prev,
                counts: &mut counts,
                face_vectors: &mut face_vectors,
                face_scalars: &mut face_scalars,
                input: &input,
                seam: seam.as_mut(),
                auto: auto.as_mut(),
            };
            match records {
                Some(records) => {
                    *records = iterate::iterate(
                        &mesh, buffers, opts, 1, when, &reference, &mut alone, observer,
                    )?;
                    Ok(())
                }
                None => iterate::iterate_unrecorded(
                    &mesh, buffers, opts, when, &reference, &mut alone, observer,
                ),
            }
        })?;
        if let (Some(limit), Some(stored)) = (opts.max_deviation, stored) {
            within_as_stored(pos, &input, limit, stored);
        }
        Ok(auto.map(|a| a.stats()))
    }
}

/// `pos` rounded as `stored` keeps them, each within `limit` of its `input` position (see
/// [`crate::io::Stored::round_within`]): the deviation bound, held in the file as written.
pub(crate) fn within_as_stored(
    pos: &mut [DVec3],
    input: &[DVec3],
    limit: f64,
    stored: &crate::io::Stored,
) {
    if stored.is_exact() {
        return;
    }
    reduce::for_chunks_mut(pos, |start, chunk| {
        for (p, o) in chunk.iter_mut().zip(&input[start..]) {
            *p = stored.round_within(*p, *o, limit);
        }
    });
}

/// The most worker threads a pool may have: far beyond any machine's cores, and small enough
/// that a mistyped count fails at once instead of spawning threads for seconds.
pub const MAX_THREADS: usize = 4096;

/// A rayon pool of `threads` threads (all cores when `None`; at most [`MAX_THREADS`]).
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if !(1..=MAX_THREADS).contains(&n) {
            return Err(Error::parameter(
                "threads",
                format!("must be in 1..={MAX_THREADS}, got {n}"),
            ));
        }
        builder = builder.num_threads(n);
    }
    builder
        .build()
        .map_err(|e| Error::resource(format!("thread pool: {e}")))
}
