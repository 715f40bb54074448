//! One mesh over several processes (MPI ranks), with checkpoints.
//!
//! The unit of distribution is the patch of the out-of-core engine ([`crate::engine::Plan`]):
//! rank 0 prepares the plan once (Morton reorder, adjacency, patches, colours) into a work
//! directory on a shared file system ([`store`]); every rank maps it and owns a contiguous block of
//! patches, i.e. a contiguous range `A` of reordered vertices. A rank keeps positions and
//! neighbour sums for its *region*: `A` and three rings around it (a stencil of an owned patch
//! reads up to two rings out; the sums a patch rebuilds for ring 2 need the positions of ring 3).
//! Its arrays are indexed by global vertex id but only the region's pages are ever touched
//! ([`Buf::sparse`]), so a rank's memory follows its region, not the mesh.
//!
//! Every rank runs the engine's one iteration loop ([`crate::engine::iterate`]), plugged in as its
//! [`Share`]: per iteration, colour after colour, each rank applies the stencils of its patches of that
//! colour (in parallel on its threads), then sends every position it changed that another rank's
//! region holds to that rank ([`Comm::exchange`]). Patches of one colour touch disjoint data and
//! every region copy is brought up to date before the next colour, so each stencil sees exactly
//! the values it sees in the single-process engine: **the output is bit-identical to
//! `vcsmooth smooth` at the same `--patch-size`, for any number of ranks and threads.** Jacobi
//! methods (a [`crate::smooth::method::Schedule`] of Jacobi passes) update owned vertices and
//! exchange them after each pass.
//!
//! Which values to send is decided once: rank `r`'s *border* `X_r` is its three outer rings plus
//! the owned vertices within three rings of another rank; the vertices two regions share are
//! exactly `X_r ∩ X_s`.
//!
//! A method's per-triangle fields (`vcs-guided`'s normal filter) go the same way: a rank computes
//! the entries of its owned triangles (those whose first corner it owns) in every pass, and then
//! receives those of its triangle halo ([`face_halo`]: the triangles at the corners of its own
//! triangles and at its owned vertices, all that such a pass and the vertex passes after it read)
//! from their owners. Each pass reads only the previous passes' fields, so a filter that reaches
//! many rings out over its iterations needs a halo of one triangle ring, exchanged after every
//! pass, and each entry is computed once, by its owner, from the values one process reads.
//!
//! Checkpoints: after every `--checkpoint-every` iterations (and the last), each rank writes its
//! owned positions into the work directory and rank 0 records the iteration ([`store`]). A run
//! started again with the same input, options, patch size and pins resumes after the last recorded
//! iteration, with any number of ranks. The output is assembled by rank 0 from the input and the
//! final positions file, on the heap or in scratch files by `--memory-budget` as in `smooth`, so no
//! rank ever holds the whole mesh in memory.

pub mod comm;
pub mod store;

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub use comm::{Comm, Local, Single};
use glam::DVec3;
use store::{PlanKey, StateDoc, StoredPlan, WorkDir};

use crate::engine::auto::AutoStop;
use crate::engine::iterate::{Buffers, Reference, Share, Sweep, iterate, keeps_seam};
use crate::engine::seam::Seam;
use crate::engine::{
    self, ClusterStats, EngineSettings, IterationRecord, MemoryStats, Observer, PhaseTimings,
    PlanStats, Report, Statistics, memory, run,
};
use crate::error::{Error, Result};
use crate::mesh::{Buf, Storage};
use crate::partition::Patch;
use crate::smooth::Options;
use crate::smooth::boundary::{self, Loops};
use crate::{io, metrics};

/// Rings of the region around a rank's owned vertices (see the module doc).
const REGION_RINGS: usize = 3;

/// Where the work directory is and how often to checkpoint.
#[derive(Debug, Clone)]
pub struct ClusterSettings {
    pub work_dir: PathBuf,
    /// Keep the work directory after success (`--checkpoint DIR`); otherwise it is removed.
    pub keep: bool,
    /// Write positions every this many iterations (the last iteration is always written).
    pub checkpoint_every: usize,
}

/// Smooth `input` into `output` with the ranks of `comm` (see the module doc). Every rank calls
/// it with the same arguments; rank 0 reports progress to `observer` and returns the full
/// statistics, the others return theirs.
pub fn run_file(
    comm: &dyn Comm,
    input: &Path,
    output: &Path,
    opts: &Options,
    engine: &EngineSettings,
    cluster: &ClusterSettings,
    observer: &mut dyn Observer,
) -> Result<Report> {
    if cluster.checkpoint_every == 0 {
        return Err(Error::parameter("checkpoint_every", "must be at least 1"));
    }
    let start = agree(
        comm,
        run::Start::new(opts, engine),
        "another rank could not start (its options, memory budget or threads)",
    )?;
    let pool = &start.pool;
    let work = WorkDir::new(&cluster.work_dir);
    let mut t = PhaseTimings::default();

    // 1. The plan: rank 0 makes it unless a matching one is there; the others wait for it.
    let made = if comm.rank() == 0 {
        ensure_plan(&work, input, output, opts, engine, &start, &mut t, observer).map(Some)
    } else {
        Ok(None)
    };
    let input_sha256 = agree(comm, made, "rank 0 could not prepare the plan")?;

    // 2. Every rank maps the plan and finds its part.
    let smoothing_sampler = memory::PeakSampler::start(std::time::Duration::from_millis(20));
    let opened = work.open_plan().and_then(|plan| {
        let state = work.read_state()?;
        if state.done > opts.iterations {
            return Err(Error::invalid(
                &work.dir,
                format!(
                    "the checkpoint has {} iterations done, more than the {} asked for",
                    state.done, opts.iterations
                ),
            ));
        }
        Ok((plan, state))
    });
    let (plan, state) = agree(comm, opened, "another rank could not open the plan")?;
    let clock = Instant::now();
    let needs = opts.method.unit().needs();
    let part = Part::new(comm, &plan, needs.face_vectors + needs.face_scalars > 0)?;
    t.partition += clock.elapsed().as_secs_f64();

    // 3. Smooth from the checkpoint on.
    let clock = Instant::now();
    let resumed_after = state.done;
    let rank = RankRun {
        comm,
        pool,
        plan: &plan,
        part: &part,
        work: &work,
        state,
        checkpoint_every: cluster.checkpoint_every,
        before: Vec::new(),
        traffic: Traffic::default(),
    };
    let arrays = agree(comm, rank.load(), "another rank could not load its part")?;
    let smoothed = rank.iterate(arrays, opts, engine.statistics, observer);
    let (state, traffic, auto_stop) = agree(comm, smoothed, "another rank failed while smoothing")?;
    t.smoothing = clock.elapsed().as_secs_f64();
    let smoothing_peak = smoothing_sampler.peak() as f64;
    drop(smoothing_sampler);

    // 4. Rank 0 writes the output in the input's order.
    let mut dropped = Vec::new();
    let written = if comm.rank() == 0 {
        write_output(
            &work,
            &plan,
            &state,
            (input, output),
            (opts, engine),
            &start,
            &mut t,
            observer,
            &mut dropped,
        )
    } else {
        Ok(None)
    };
    let output_stats = agree(comm, written, "rank 0 could not write the output")?;
    t.total = start.clock.elapsed().as_secs_f64();

    // 5. Figures of all ranks.
    let iterations_run = (state.done - resumed_after).max(1) as f64;
    let owned = part.owned.len() as f64;
    let region = (part.owned.len() + part.rings.iter().map(Vec::len).sum::<usize>()) as f64;
    let values = traffic.values as f64 / iterations_run;
    let bytes = traffic.bytes as f64 / iterations_run;
    let peak = start.sampler.peak() as f64;
    let maxima = comm.max(&[owned, -owned, region, bytes, peak, smoothing_peak]);
    let sums = comm.sum(&[values]);
    let doc = &plan.doc;
    let report = Report {
        input_format: io::Format::from_extension(input),
        vertices: doc.vertices,
        triangles: doc.triangles,
        iterations_run: state.records.len(),
        auto_stop,
        records: state.records,
        input_stats: engine.with_stats.then(|| doc.input_stats.clone()).flatten(),
        output_stats,
        plan: pool.install(|| {
            let (colours, halo) = engine::plan::footprint_colouring(
                opts.method.unit().schedule(opts).footprint(),
                (&doc.colours, &doc.halo),
                (&doc.ring_colours, &doc.ring_halo),
            );
            PlanStats::new(
                doc.key.patch_size,
                colours.len(),
                halo,
                doc.crossing_edge_stencils,
                engine::plan::FixedVertices::of(&doc.topology, doc.welded),
            )
        }),
        memory: MemoryStats {
            budget: start.budget.bytes,
            budget_source: start.budget.source,
            storage: "cluster",
            scratch_bytes: 0,
            scratch_peak_bytes: 0,
            peak_anon: maxima[4] as u64,
            bytes_read: std::fs::metadata(input).map_or(0, |m| m.len()),
            bytes_written: std::fs::metadata(output).map_or(0, |m| m.len()),
        },
        timings: t,
        disk: None,
        cluster: Some(ClusterStats {
            ranks: comm.size(),
            resumed_after,
            checkpoint_every: cluster.checkpoint_every,
            owned_vertices_min: (-maxima[1]) as u64,
            owned_vertices_max: maxima[0] as u64,
            region_vertices_max: maxima[2] as u64,
            halo_values_per_iteration: sums[0] as u64,
            halo_bytes_per_iteration_max: maxima[3] as u64,
            peak_anon_max: maxima[4] as u64,
            smoothing_peak_anon_max: maxima[5] as u64,
        }),
        deviation: None,
        input_sha256,
        dropped,
    };
    // Every rank unmaps the plan before rank 0 removes it (on NFS a file still mapped somewhere
    // is kept as a hidden `.nfs*` file, and its directory cannot go).
    drop(plan);
    comm.all(true);
    if comm.rank() == 0 && !cluster.keep {
        work.remove();
    }
    Ok(report)
}

/// Turn a per-rank result into a collective one: every rank goes on only if all succeeded. A rank
/// that failed returns its own error; the others return `other`.
fn agree<T>(comm: &dyn Comm, r: Result<T>, other: &str) -> Result<T> {
    let ok = comm.all(r.is_ok());
    match r {
        Err(e) => Err(e),
        Ok(_) if !ok => Err(Error::Peer {
            what: other.to_string(),
        }),
        Ok(v) => Ok(v),
    }
}

/// Rank 0: reuse the plan in the work directory if it was made from the same input (by content),
/// options, patch size and pins; otherwise prepare it as the engine's run does ([`run::prepare`])
/// and store it there. Returns the input's SHA-256.
#[allow(clippy::too_many_arguments)]
fn ensure_plan(
    work: &WorkDir,
    input: &Path,
    output: &Path,
    opts: &Options,
    engine: &EngineSettings,
    start: &run::Start,
    t: &mut PhaseTimings,
    observer: &mut dyn Observer,
) -> Result<String> {
    let clock = Instant::now();
    let key = PlanKey::of(input, opts, engine.patch_size, &engine.pins, observer)?;
    t.hash = clock.elapsed().as_secs_f64();
    let hash = key.input_sha256[0].clone();
    if let Some(doc) = work.read_plan_doc()?
        && doc.key == key
    {
        return Ok(hash);
    }
    // Pinned vertices and creases are fixed in the stored topology (`fixed.u8`), which every rank
    // maps.
    let run::Prepared {
        storage,
        mesh,
        plan,
        ..
    } = run::prepare(input, output, opts, engine, start, t, observer)?;
    t.add_preparation(&plan.timings);
    start.pool.install(|| {
        // Measured always: a resumed run may ask for a report that the first run did not.
        let input_stats = Some(plan.info(&mesh.source, &storage)?);
        drop(mesh);
        // The ranks find the loops of `boundary: smooth` here rather than each reading every face.
        let loops = match opts.boundary {
            crate::smooth::Boundary::Smooth => {
                boundary::boundary_edges(&plan.topology, &plan.reordered.triangles)
            }
            crate::smooth::Boundary::Fixed => Vec::new(),
        };
        // A resumed run measures the input again: a deviation bound, the automatic stop's replay,
        // the hole areas that smooth boundaries keep.
        let keep_input = opts.keeps_input() || opts.auto_stop || !loops.is_empty();
        work.write_plan(&plan, key, input_stats, keep_input, &loops)
    })?;
    Ok(hash)
}

/// Rank 0: the input with the final positions, written as the engine's run writes
/// ([`run::write_measured`]); output statistics if asked.
#[allow(clippy::too_many_arguments)]
fn write_output(
    work: &WorkDir,
    plan: &StoredPlan,
    state: &StateDoc,
    (input, output): (&Path, &Path),
    (opts, engine): (&Options, &EngineSettings),
    start: &run::Start,
    t: &mut PhaseTimings,
    observer: &mut dyn Observer,
    dropped: &mut Vec<String>,
) -> Result<Option<metrics::MeshInfo>> {
    // Assembling the output keeps no per-run arrays beside the mesh: the default options' model.
    let storage = engine::storage_for(
        input,
        output,
        engine,
        start.mesh_budget,
        &Options::default(),
    )?;
    let clock = Instant::now();
    let mut mesh = io::read_mesh_in(input, &storage)?;
    t.ingest += clock.elapsed().as_secs_f64();
    if mesh.positions.len() != plan.doc.vertices || mesh.triangles.len() != plan.doc.triangles {
        return Err(Error::invalid(
            input,
            "changed since the plan was made (vertex or triangle count differs)",
        ));
    }
    let mut last = work.map_positions(state.slot, plan.doc.vertices)?;
    // The deviation bound holds in the file as written, as in one process.
    if let (Some(limit), Some(stored)) = (opts.max_deviation, io::Stored::of(output, &mesh)) {
        let input = work.map_input(plan.doc.vertices)?;
        let mut rounded = storage.copy_of(&last)?;
        start
            .pool
            .install(|| engine::within_as_stored(&mut rounded, &input, limit, &stored));
        last = rounded;
    }
    for (new, &old) in plan.order.iter().enumerate() {
        mesh.positions[old as usize] = last[crate::partition::source_of(&plan.welded_to, new)];
    }
    let bytes_read = std::fs::metadata(input).map_or(0, |m| m.len());
    *dropped = io::not_carried(&mesh.source, output);
    let measure = engine
        .with_stats
        .then_some(|| output_stats(plan, &storage, output, &mesh, &last));
    run::write_measured(
        &start.pool,
        output,
        &mesh,
        None,
        bytes_read,
        t,
        observer,
        measure,
    )
}

/// The statistics of the output as stored, as a single-process run gives them
/// ([`engine::run::stored_output_stats`]), from a copy of the final positions (`last`, in plan
/// order, mapped read-only).
fn output_stats(
    plan: &StoredPlan,
    storage: &crate::mesh::Storage,
    output: &Path,
    mesh: &crate::Mesh,
    last: &[DVec3],
) -> Result<Option<metrics::MeshInfo>> {
    let Some(info) = plan.doc.input_stats.clone() else {
        return Ok(None);
    };
    let mut positions = storage.copy_of(last)?;
    crate::partition::follow_welds(&mut positions, &plan.welded_to);
    let (tris, topo) = (&plan.triangles, &plan.topology);
    Ok(engine::run::stored_output_stats(
        info,
        output,
        mesh,
        &mut positions,
        engine::run::Afterwards::Unread,
        tris,
        topo,
        &crate::meter::Meter::default(),
    ))
}

/// A rank's share of the plan and what it exchanges with whom.
struct Part {
    /// Owned patches, a contiguous block.
    patches: Range<usize>,
    /// Owned vertices (the patches' ranges, contiguous) and owned triangles.
    owned: Range<u32>,
    triangles: Range<u32>,
    /// The rings outside `owned`, ring 1 first.
    rings: Vec<Vec<u32>>,
    /// Vertices this rank shares with some other rank's region, ascending.
    shared: Vec<u32>,
    /// Per other rank: positions in `shared` of the vertices both regions hold.
    links: Vec<(usize, Vec<u32>)>,
    /// Per other rank: the owned triangles whose per-triangle fields it reads, ascending (see
    /// [`face_halo`]); empty when the method has no such fields.
    face_links: Vec<(usize, Vec<u32>)>,
}

impl Part {
    /// `faces`: the method has per-triangle fields, whose halos are exchanged too.
    fn new(comm: &dyn Comm, plan: &StoredPlan, faces: bool) -> Result<Part> {
        let doc = &plan.doc;
        let (r, size) = (comm.rank(), comm.size());
        let count = doc.patches.len();
        let patches = count * r / size..count * (r + 1) / size;
        let span = |ps: &Range<usize>, k: usize| {
            if ps.is_empty() {
                None
            } else {
                Some((doc.patches[ps.start][k], doc.patches[ps.end - 1][k + 1]))
            }
        };
        let owned = span(&patches, 0).map_or(0..0, |(a, b)| a..b);
        let triangles = span(&patches, 2).map_or(0..0, |(a, b)| a..b);
        let found = rings_around(plan, owned.clone())
            .map_err(|msg| Error::invalid(&plan.dir, format!("the plan is damaged: {msg}")));
        let (rings, inner) = agree(comm, found, "another rank found a damaged plan")?;
        let mut border: Vec<u32> = rings.iter().flatten().chain(&inner).copied().collect();
        border.sort_unstable();
        // Everyone learns everyone's border; the shared vertices are the pairwise intersections.
        let others = comm.exchange(
            (0..size)
                .map(|s| {
                    if s == r {
                        Vec::new()
                    } else {
                        border.iter().map(|&v| v as u64).collect()
                    }
                })
                .collect(),
        );
        let mut pairs: Vec<(usize, Vec<u32>)> = Vec::new();
        for (s, theirs) in others.iter().enumerate() {
            if s == r {
                continue;
            }
            let common = intersect(&border, theirs);
            if !common.is_empty() {
                pairs.push((s, common));
            }
        }
        let mut shared: Vec<u32> = pairs.iter().flat_map(|(_, c)| c.iter().copied()).collect();
        shared.sort_unstable();
        shared.dedup();
        let links = pairs
            .into_iter()
            .map(|(s, common)| {
                let at = common
                    .iter()
                    .map(|v| shared.binary_search(v).expect("in the union") as u32)
                    .collect();
                (s, at)
            })
            .collect();
        let face_links = match faces {
            true => face_links(comm, &face_halo(plan, &owned, &triangles), &triangles),
            false => Vec::new(),
        };
        Ok(Part {
            patches,
            owned,
            triangles,
            rings,
            shared,
            links,
            face_links,
        })
    }
}

/// The [`REGION_RINGS`] rings outside `owned`, and the owned vertices within that many rings of
/// the outside. Checks the adjacency and triangles of every vertex whose entries the rank will
/// use, so a damaged plan is an error, not an out-of-range access.
fn rings_around(
    plan: &StoredPlan,
    owned: Range<u32>,
) -> std::result::Result<(Vec<Vec<u32>>, Vec<u32>), String> {
    let topo = &plan.topology;
    let n = plan.doc.vertices as u32;
    let check = |v: u32| -> std::result::Result<(), String> {
        if v >= n || !topo.check_vertex(v) {
            return Err(format!("the adjacency of vertex {v} is damaged"));
        }
        for f in topo.faces_of(v, &plan.triangles) {
            if plan.triangles[f as usize].iter().any(|&u| u >= n) {
                return Err(format!("triangle {f} names a vertex out of range"));
            }
        }
        Ok(())
    };
    let inside = |v: u32| owned.contains(&v);
    let mut seen = std::collections::HashSet::new();
    let mut ring = Vec::new();
    for v in owned.clone() {
        check(v)?;
        for &u in topo.neighbors(v) {
            if !inside(u) && seen.insert(u) {
                ring.push(u);
            }
        }
    }
    let mut rings = vec![ring];
    while rings.len() < REGION_RINGS {
        let mut next = Vec::new();
        for &v in rings.last().into_iter().flatten() {
            check(v)?;
            for &u in topo.neighbors(v) {
                if !inside(u) && seen.insert(u) {
                    next.push(u);
                }
            }
        }
        rings.push(next);
    }
    for ring in &mut rings {
        ring.sort_unstable();
    }
    // Inward: owned vertices next to ring 1, then their owned neighbours, up to the same depth.
    let mut near = vec![false; owned.len()];
    let mut front: Vec<u32> = Vec::new();
    for &v in &rings[0] {
        for &u in topo.neighbors(v) {
            if inside(u) && !std::mem::replace(&mut near[(u - owned.start) as usize], true) {
                front.push(u);
            }
        }
    }
    let mut inner = front.clone();
    for _ in 1..REGION_RINGS {
        let mut next = Vec::new();
        for &v in &front {
            for &u in topo.neighbors(v) {
                if inside(u) && !std::mem::replace(&mut near[(u - owned.start) as usize], true) {
                    next.push(u);
                }
            }
        }
        inner.extend_from_slice(&next);
        front = next;
    }
    Ok((rings, inner))
}

/// The triangles outside the owned ones (`triangles`, those whose first corner is in `owned`)
/// whose per-triangle fields a rank reads: those at a corner of an owned triangle (a triangle's
/// entries read the triangles at its corners, [`crate::smooth::method::Exec::face_pass`]) or
/// at an owned vertex (a vertex reads the triangles around it). Ascending. Their corners are in
/// the owned vertices and ring 1, whose adjacency [`rings_around`] checked.
fn face_halo(plan: &StoredPlan, owned: &Range<u32>, triangles: &Range<u32>) -> Vec<u32> {
    let topo = &plan.topology;
    let outside = |f: &u32| !triangles.contains(f);
    let mut halo: Vec<u32> = Vec::new();
    for v in owned.clone() {
        halo.extend(topo.faces_of(v, &plan.triangles).filter(outside));
    }
    for t in triangles.clone() {
        for &c in plan.triangles[t as usize]
            .iter()
            .filter(|c| !owned.contains(*c))
        {
            halo.extend(topo.faces_of(c, &plan.triangles).filter(outside));
        }
    }
    halo.sort_unstable();
    halo.dedup();
    halo
}

/// Every rank learns every other's triangle halo; per other rank, the owned triangles
/// (`triangles`) in its halo.
fn face_links(comm: &dyn Comm, halo: &[u32], triangles: &Range<u32>) -> Vec<(usize, Vec<u32>)> {
    let r = comm.rank();
    let wanted = comm.exchange(
        (0..comm.size())
            .map(|s| match s == r {
                true => Vec::new(),
                false => halo.iter().map(|&f| f as u64).collect(),
            })
            .collect(),
    );
    wanted
        .iter()
        .enumerate()
        .filter(|&(s, _)| s != r)
        .filter_map(|(s, theirs)| {
            let mine: Vec<u32> = theirs
                .iter()
                .map(|&f| f as u32)
                .filter(|f| triangles.contains(f))
                .collect();
            (!mine.is_empty()).then_some((s, mine))
        })
        .collect()
}

/// Sorted intersection of two ascending lists.
fn intersect(a: &[u32], b: &[u64]) -> Vec<u32> {
    let (mut i, mut j, mut out) = (0, 0, Vec::new());
    while i < a.len() && j < b.len() {
        match (a[i] as u64).cmp(&b[j]) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                out.push(a[i]);
                i += 1;
                j += 1;
            }
        }
    }
    out
}

/// Halo traffic of a run.
#[derive(Default)]
struct Traffic {
    /// Vertex entries and bytes sent to other ranks.
    values: u64,
    bytes: u64,
}

/// One rank: its arrays, and its side of the engine's loop ([`Share`]).
struct RankRun<'a> {
    comm: &'a dyn Comm,
    /// The rank's threads (the communicator stays on the calling thread).
    pool: &'a rayon::ThreadPool,
    plan: &'a StoredPlan,
    part: &'a Part,
    work: &'a WorkDir,
    state: StateDoc,
    checkpoint_every: usize,
    /// The shared vertices' positions before the current colour (see [`snapshot`]).
    before: Vec<DVec3>,
    traffic: Traffic,
}

impl<'a> RankRun<'a> {
    /// The rank's arrays, by global id: positions (owned and the region's rings from the
    /// checkpoint), the second buffer and the previous positions; only the region's pages are
    /// ever touched.
    fn load(&self) -> Result<[Buf<DVec3>; 3]> {
        let n = self.plan.doc.vertices;
        let mut pos: Buf<DVec3> = Buf::sparse(n)?;
        let saved = self.work.map_positions(self.state.slot, n)?;
        let owned = self.owned();
        pos[owned.clone()].copy_from_slice(&saved[owned]);
        for &v in self.part.rings.iter().flatten() {
            pos[v as usize] = saved[v as usize];
        }
        Ok([pos, Buf::sparse(n)?, Buf::sparse(n)?])
    }

    /// Iterations `done + 1 ..= opts.iterations` through the engine's loop, with checkpoints
    /// (until the automatic stop ends the run, when the options ask for it); returns the final
    /// state, and what the automatic stop measured.
    fn iterate(
        mut self,
        arrays: [Buf<DVec3>; 3],
        opts: &Options,
        when: Statistics,
        observer: &mut dyn Observer,
    ) -> Result<(StateDoc, Traffic, Option<engine::AutoStopStats>)> {
        let [mut pos, mut scratch, mut prev] = arrays;
        let n = self.plan.doc.vertices;
        // Only the region's pages of the input are ever read (the free vertices' entries).
        let input = match opts.keeps_input() || (opts.auto_stop && self.state.done > 0) {
            true => Some(self.work.map_input(n)?),
            false => None,
        };
        let loops = match opts.boundary {
            crate::smooth::Boundary::Smooth => {
                let edges = self.work.read_loops(&self.plan.doc)?;
                let mut loops = Loops::from_edges(&self.plan.topology, &self.plan.triangles, edges);
                if self.state.done > 0 && !loops.is_empty() {
                    // The hole areas to keep are the input's, which an uninterrupted run
                    // measures at its first iteration, not those of the checkpoint.
                    loops.measure(&self.work.map_input(n)?);
                }
                Some(loops)
            }
            crate::smooth::Boundary::Fixed => None,
        };
        let patches: Vec<Patch> = (0..self.plan.doc.patches.len())
            .map(|p| self.plan.doc.patch(p))
            .collect();
        let plan = self.plan;
        let mesh = Sweep {
            topo: &plan.topology,
            tris: &plan.triangles,
            // A cluster's plan is always laid out in patches.
            sorted: true,
            patches: &patches,
            colours: &plan.doc.colours,
            ring_colours: &plan.doc.ring_colours,
            prefetch: None,
            tiles: false,
            loops: loops.as_ref(),
            // A rank's shares are exchanged whole with the other ranks'.
            border: None,
        };
        let reference = match self.state.reference {
            Some(r) => r,
            None => {
                let r = Reference::measure(&mesh, &pos, &self);
                self.state.reference = Some(r);
                r
            }
        };
        let mut auto = match opts.auto_stop {
            true => Some(AutoStop::sparse(n, opts)?),
            false => None,
        };
        if let (Some(auto), Some(input)) = (&mut auto, &input)
            && self.state.done > 0
        {
            // Measure the input again and replay the rule up to the checkpoint.
            let origin = DVec3::from_array(reference.origin);
            let (removed, stopped) = (self.state.auto_removed.clone(), self.state.auto_stopped);
            auto.start(mesh.topo, mesh.tris, input, origin, &mut self);
            auto.resume(mesh.topo, &removed, stopped, &mut self);
        }
        let first = self.state.done + 1;
        let needs = opts.method.unit().needs();
        let mut counts: Buf<u8> = match needs.counts {
            true => Buf::sparse(n)?,
            false => Buf::default(),
        };
        let faces = mesh.tris.len();
        let mut face_vectors: Buf<DVec3> = Buf::sparse(needs.face_vectors * faces)?;
        let mut face_scalars: Buf<f64> = Buf::sparse(needs.face_scalars * faces)?;
        // The seam of the rank's own patches, for a method whose patches measure their moves.
        let unit = opts.method.unit();
        let mut seam = match keeps_seam(unit, opts) {
            true => {
                let mine = self.part.patches.clone();
                let runs = move |p: usize| mine.contains(&p);
                Some(Seam::of(mesh.topo, mesh.patches, runs, &Storage::heap())?)
            }
            false => None,
        };
        let buffers = Buffers {
            pos: &mut pos,
            scratch: &mut scratch,
            prev: &mut prev,
            counts: &mut counts,
            face_vectors: &mut face_vectors,
            face_scalars: &mut face_scalars,
            input: input
                .as_deref()
                .filter(|_| opts.keeps_input())
                .unwrap_or(&[]),
            seam: seam.as_mut(),
            auto: auto.as_mut(),
        };
        iterate(
            &mesh, buffers, opts, first, when, &reference, &mut self, observer,
        )?;
        Ok((self.state, self.traffic, auto.map(|a| a.stats())))
    }

    /// Write the owned positions of iteration `it` into the free slot; once all ranks have,
    /// rank 0 switches the state to it.
    fn checkpoint(&mut self, it: usize, pos: &[DVec3]) -> Result<()> {
        let slot = 1 - self.state.slot;
        let owned = self.owned();
        let written = self.work.write_positions(slot, owned.start, &pos[owned]);
        agree(
            self.comm,
            written,
            "another rank could not write its checkpoint",
        )?;
        self.state.done = it;
        self.state.slot = slot;
        let recorded = if self.comm.rank() == 0 {
            self.work.write_state(&self.state)
        } else {
            Ok(())
        };
        agree(
            self.comm,
            recorded,
            "rank 0 could not record the checkpoint",
        )
    }
}

impl Share for RankRun<'_> {
    fn owned(&self) -> Range<usize> {
        self.part.owned.start as usize..self.part.owned.end as usize
    }

    fn triangles(&self) -> Range<usize> {
        self.part.triangles.start as usize..self.part.triangles.end as usize
    }

    fn runs_patch(&self, p: usize) -> bool {
        self.part.patches.contains(&p)
    }

    fn colour_start(&mut self, pos: &[DVec3]) {
        self.before = snapshot(self.part, pos);
    }

    fn colour_end(&mut self, pos: &mut [DVec3]) {
        send_changes(self.comm, self.part, &self.before, pos, &mut self.traffic);
    }

    fn step_end(&mut self, field: &mut [DVec3]) {
        send_owned(self.comm, self.part, field, &mut self.traffic);
    }

    fn step_end_scalar(&mut self, field: &mut [f64]) {
        send_owned(self.comm, self.part, field, &mut self.traffic);
    }

    fn face_end(&mut self, field: &mut [DVec3]) {
        send_faces(self.comm, self.part, field, &mut self.traffic);
    }

    fn face_end_scalar(&mut self, field: &mut [f64]) {
        send_faces(self.comm, self.part, field, &mut self.traffic);
    }

    fn gather(&mut self, pos: &mut [DVec3], vertices: &[u32]) {
        let owned = self.owned();
        let mut mine = Vec::new();
        for &v in vertices.iter().filter(|&&v| owned.contains(&(v as usize))) {
            mine.push(v as u64);
            pos[v as usize].put(&mut mine);
        }
        let (r, others) = (self.comm.rank(), self.comm.size() - 1);
        let send = (0..self.comm.size())
            .map(|s| if s == r { Vec::new() } else { mine.clone() })
            .collect();
        self.traffic.values += (mine.len() / 4 * others) as u64;
        self.traffic.bytes += (8 * mine.len() * others) as u64;
        for msg in self.comm.exchange(send) {
            assert!(msg.len() % 4 == 0, "malformed loop message");
            for e in msg.chunks_exact(4) {
                pos[e[0] as usize] = DVec3::get(&e[1..]);
            }
        }
    }

    fn sum(&self, local: &[f64]) -> Vec<f64> {
        self.comm.sum(local)
    }

    fn max(&self, local: &[f64]) -> Vec<f64> {
        self.comm.max(local)
    }

    fn sum_counts(&self, local: Vec<u64>) -> Vec<u64> {
        self.comm.sum_counts(&local)
    }

    fn iteration_end(
        &mut self,
        record: &IterationRecord,
        pos: &[DVec3],
        last: bool,
        auto: Option<&engine::AutoStopStats>,
    ) -> Result<()> {
        self.state.records.push(*record);
        if let Some(auto) = auto {
            self.state.auto_removed = auto.removed.clone();
            self.state.auto_stopped = last.then_some(auto.stopped_by);
        }
        let it = record.iteration;
        if it % self.checkpoint_every == 0 || last {
            self.checkpoint(it, pos)?;
        }
        Ok(())
    }

    fn leads(&self) -> bool {
        self.comm.rank() == 0
    }

    fn pool(&self) -> Option<&rayon::ThreadPool> {
        Some(self.pool)
    }
}

/// Positions of the shared vertices, to find what a colour phase changed.
fn snapshot(part: &Part, pos: &[DVec3]) -> Vec<DVec3> {
    part.shared.iter().map(|&v| pos[v as usize]).collect()
}

/// After a colour phase: send each linked rank the shared vertices whose position changed
/// (vertex, position), and apply what the others changed. Positions are all a colour's stencils
/// leave for others to read: neighbour sums are rebuilt by each patch, and the shares a method
/// prepares before its sweep are exchanged when they are made.
fn send_changes(
    comm: &dyn Comm,
    part: &Part,
    before: &[DVec3],
    pos: &mut [DVec3],
    traffic: &mut Traffic,
) {
    let same =
        |a: DVec3, b: DVec3| a.to_array().map(f64::to_bits) == b.to_array().map(f64::to_bits);
    let changed: Vec<bool> = part
        .shared
        .iter()
        .zip(before)
        .map(|(&v, &b)| !same(pos[v as usize], b))
        .collect();
    let got = exchange_values(comm, &part.links, traffic, 4, |k, msg| {
        let k = k as usize;
        if changed[k] {
            let v = part.shared[k] as usize;
            msg.push(v as u64);
            msg.extend(pos[v].to_array().map(f64::to_bits));
        }
    });
    for msg in got {
        for e in msg.chunks_exact(4) {
            pos[e[0] as usize] = DVec3::get(&e[1..]);
        }
    }
}

/// A value of a per-vertex field as it travels: a fixed number of u64 words.
trait Words: Copy {
    const WORDS: usize;
    fn put(self, out: &mut Vec<u64>);
    fn get(words: &[u64]) -> Self;
}

impl Words for DVec3 {
    const WORDS: usize = 3;
    fn put(self, out: &mut Vec<u64>) {
        out.extend(self.to_array().map(f64::to_bits));
    }
    fn get(w: &[u64]) -> Self {
        DVec3::new(
            f64::from_bits(w[0]),
            f64::from_bits(w[1]),
            f64::from_bits(w[2]),
        )
    }
}

impl Words for f64 {
    const WORDS: usize = 1;
    fn put(self, out: &mut Vec<u64>) {
        out.push(self.to_bits());
    }
    fn get(w: &[u64]) -> Self {
        f64::from_bits(w[0])
    }
}

/// After a Jacobi step: send each linked rank the owned vertices it holds (vertex, value).
fn send_owned<T: Words>(comm: &dyn Comm, part: &Part, field: &mut [T], traffic: &mut Traffic) {
    let got = exchange_values(comm, &part.links, traffic, 1 + T::WORDS, |k, msg| {
        let v = part.shared[k as usize];
        if part.owned.contains(&v) {
            msg.push(v as u64);
            field[v as usize].put(msg);
        }
    });
    for msg in got {
        for e in msg.chunks_exact(1 + T::WORDS) {
            field[e[0] as usize] = T::get(&e[1..]);
        }
    }
}

/// After a pass over the owned triangles: send each linked rank the owned triangles in its halo
/// (triangle, value), and apply what the others sent.
fn send_faces<T: Words>(comm: &dyn Comm, part: &Part, field: &mut [T], traffic: &mut Traffic) {
    let got = exchange_values(comm, &part.face_links, traffic, 1 + T::WORDS, |f, msg| {
        msg.push(f as u64);
        field[f as usize].put(msg);
    });
    for msg in got {
        for e in msg.chunks_exact(1 + T::WORDS) {
            field[e[0] as usize] = T::get(&e[1..]);
        }
    }
}

/// Build one message per linked rank of `links` with `fill(entry of its list, message)`,
/// exchange, and return the messages received (entries of `words` u64 each, checked).
fn exchange_values(
    comm: &dyn Comm,
    links: &[(usize, Vec<u32>)],
    traffic: &mut Traffic,
    words: usize,
    mut fill: impl FnMut(u32, &mut Vec<u64>),
) -> Vec<Vec<u64>> {
    let mut send = vec![Vec::new(); comm.size()];
    for (s, at) in links {
        let msg = &mut send[*s];
        for &k in at {
            fill(k, msg);
        }
        traffic.values += (msg.len() / words) as u64;
        traffic.bytes += 8 * msg.len() as u64;
    }
    let got = comm.exchange(send);
    for msg in &got {
        assert!(msg.len() % words == 0, "malformed halo message");
    }
    got
}

/// Run `f` with the communicator of this process: MPI's world when built with the `mpi` feature
/// (a single process started without `mpirun` is a world of one), else a single rank. MPI is
/// initialised and finalised around `f`.
pub fn with_world<R>(f: impl FnOnce(&dyn Comm) -> R) -> R {
    #[cfg(feature = "mpi")]
    {
        match mpi::initialize_with_threading(mpi::Threading::Funneled) {
            Some((universe, _)) => {
                let world = comm::Mpi {
                    world: mpi::topology::Communicator::duplicate(&universe.world()),
                };
                let r = f(&world);
                drop(world);
                drop(universe);
                r
            }
            None => f(&Single),
        }
    }
    #[cfg(not(feature = "mpi"))]
    f(&Single)
}
