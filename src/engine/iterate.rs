//! The one iteration loop. Every run smooths through [`iterate`]: in-memory meshes, file runs in
//! memory or in scratch files, multiresolution levels, benchmarks and the ranks of the cluster
//! engine, which plug in through [`Share`]. The loop never names a method: it runs the
//! [`Schedule`] the method's unit ([`Smoother`]) declares.
//!
//! Order contract (part of the result's definition, so runs are reproducible):
//! - [`Schedule::Stencils`]: Gauss–Seidel, step after step of the streaming order and colour
//!   after colour within a step ([`crate::schedule`]) of the plan's colouring for the method's
//!   footprint; within a colour the patches run in parallel (they touch disjoint data),
//!   each applying the stencils it owns in the unit's fixed order ([`Smoother::sweep_patch`];
//!   edge stencils `(i, j)`, `i < j`, ascending by `(i, j)`; triangle stencils in the plan's
//!   triangle order; ring stencils by ascending vertex). Before each sweep, the unit's
//!   [`Smoother::prepare`] (a method's shares: its own Jacobi passes; the stencil methods'
//!   neighbour sums are rebuilt by each patch).
//! - `boundary: smooth`: the loops' normals are measured before the sweep; a unit applies its
//!   boundary stencils inside its patch sweep, or (when [`Smoother::boundary_pass`] says so) in
//!   a pass of their own over the edge colouring after its stencils, each patch's ascending;
//!   after the last colour, [`Loops::restore`] walks every loop in order.
//! - [`Schedule::Umbrella`] and [`Schedule::TwoPass`]: Jacobi (every vertex from the previous
//!   positions), so the order is irrelevant: the output is bit-identical for any thread count
//!   and tile size.
//!
//! With [`Options::auto_stop`] the loop asks its [`AutoStop`] after every iteration whether to go
//! on (see [`super::auto`]); its measurements are reductions over fixed chunks, so the iteration
//! at which a run stops does not depend on the thread count or the storage either.

use std::ops::Range;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use super::auto::AutoStop;
use super::observer::{AutoStopStats, IterationRecord, Observer, Statistics};
use super::reduce;
use super::seam::Seam;
use super::share::on_pool;
pub use super::share::{Alone, Share};
use crate::error::{Error, Result};
use crate::metrics;
use crate::partition::Patch;
use crate::schedule::{LANES, Prefetch};
use crate::smooth::boundary::{self, Loops};
use crate::smooth::laplacian::{self, Previous, StepStats};
use crate::smooth::method::{
    Exec, FaceFields, Footprint, Moves, PassFields, PatchMesh, PatchSweep, Schedule,
};
use crate::smooth::stencil::{self, StencilParams};
use crate::smooth::tiled::{Measure, Measured, TilePlan};
use crate::smooth::{Options, SharedField, Smoother, SweepStats};
use crate::topology::Topology;

/// What the percentages of the records are relative to: the input's centroid (a fixed point, so
/// that the volume of an open mesh is followed consistently), volume and area.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct Reference {
    pub origin: [f64; 3],
    pub volume: f64,
    pub area: f64,
}

impl Reference {
    /// Measured on the current positions (every process gets the same bits).
    pub fn measure(mesh: &Sweep, pos: &[DVec3], share: &dyn Share) -> Reference {
        let owned = &pos[share.owned()];
        let sum = on_pool(share, || reduce::position_sum(owned));
        let total = share.sum(&sum.to_array());
        let origin = DVec3::from_slice(&total) / mesh.topo.len().max(1) as f64;
        let (volume, area) = volume_area(mesh, pos, origin, share);
        Reference {
            origin: origin.to_array(),
            volume,
            area,
        }
    }
}

fn volume_area(mesh: &Sweep, pos: &[DVec3], origin: DVec3, share: &dyn Share) -> (f64, f64) {
    let tris = &mesh.tris[share.triangles()];
    let (v, a) = on_pool(share, || reduce::volume_area(pos, tris, origin));
    let total = share.sum(&[v, a]);
    (total[0], total[1])
}

/// Where an iteration's record takes its volume and area from.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Volume {
    /// Not measured (NaN in the record).
    Unmeasured,
    /// Measured on the positions the record is made with ([`volume_area`]).
    Measure,
    /// Measured already (the volume and the area, about the run's origin), by this process.
    Sums(f64, f64),
}

impl Volume {
    fn when(measure: bool) -> Volume {
        match measure {
            true => Volume::Measure,
            false => Volume::Unmeasured,
        }
    }
}

/// The mesh as the loop sees it: topology, triangles, patches and their colours.
pub struct Sweep<'a> {
    pub topo: &'a Topology,
    pub tris: &'a [[u32; 3]],
    /// Whether `tris` are sorted by their first corner, which is their smallest (the plan's
    /// Morton layout, not the input's own order).
    pub sorted: bool,
    pub patches: &'a [Patch],
    pub colours: &'a [Vec<u32>],
    /// The colours of the wider ring stencils ([`Footprint::Ring`], see [`crate::schedule`]).
    pub ring_colours: &'a [Vec<u32>],
    /// Read-ahead hints for memory-mapped arrays (the next colour's patches).
    pub prefetch: Option<&'a Prefetch>,
    /// Whether `laplacian` and `taubin` may hold a [`TilePlan`] on the heap (the mesh is in memory).
    pub tiles: bool,
    /// The boundary loops of `boundary: smooth` when found beforehand (a cluster rank's, from
    /// the stored plan); `None`: found from the mesh when the options ask for them.
    pub loops: Option<&'a Loops>,
    /// The patches' border when the method's shares are kept for it alone
    /// ([`PatchMesh::border`]; `scratch` then holds one entry per border vertex).
    pub border: Option<&'a [u32]>,
}

impl Sweep<'_> {
    /// The colouring of stencils with `footprint`.
    fn colours(&self, footprint: Footprint) -> &[Vec<u32>] {
        match footprint {
            Footprint::Edge => self.colours,
            Footprint::Ring => self.ring_colours,
        }
    }
}

/// The arrays the loop works in, one entry per vertex each (a rank touches only its region), but
/// `scratch` with [`Sweep::border`]: one per border vertex.
pub struct Buffers<'b> {
    /// The positions: smoothed in place.
    pub pos: &'b mut [DVec3],
    /// What the stencils read beside the positions: a method's shares ([`Smoother::prepare`];
    /// with [`Sweep::border`], one per border vertex), the neighbour sums each patch of a stencil
    /// method rebuilds, or the second buffer of the Jacobi steps.
    pub scratch: &'b mut [DVec3],
    /// The stencil methods' copy before a measured sweep (and the spare buffer of their
    /// preparation), or the auxiliary field of a [`Schedule::TwoPass`] method; may be empty for
    /// [`Schedule::Umbrella`].
    pub prev: &'b mut [DVec3],
    /// The method's byte field ([`Needs::counts`](crate::smooth::method::Needs)), filled by the
    /// loop before its first iteration; empty when the method has none.
    pub counts: &'b mut [u8],
    /// The method's per-triangle fields ([`Needs::face_vectors`](crate::smooth::method::Needs),
    /// `face_scalars`); empty when it has none.
    pub face_vectors: &'b mut [DVec3],
    pub face_scalars: &'b mut [f64],
    /// The input positions, read when the options keep them ([`Options::keeps_input`]); empty
    /// otherwise.
    pub input: &'b [DVec3],
    /// The seam of the process's patches ([`Seam`]), for a unit whose [`Smoother::moves`] are
    /// [`Moves::Seam`] when the run copies no positions ([`copies_positions`]).
    pub seam: Option<&'b mut Seam>,
    /// The automatic stop's state, required when the options ask for it (`auto_stop`); a run
    /// that resumes after iteration 1 passes it started and resumed.
    pub auto: Option<&'b mut AutoStop>,
}

/// Iterations `first ..= opts.iterations` of `opts` on `mesh`, measuring the statistics `when`
/// says relative to `reference`; with `opts.auto_stop`, from the first and only up to the one
/// at which `buf.auto` stops the run (an automatically stopped run measures the displacement of
/// every iteration, and the volume and area of its last one whatever `when` says). Returns their
/// records, one per iteration, which grow as the iterations run (a record the memory cannot hold
/// is an [`Error::Resource`](crate::Error), not an abort; every run bounds them up front, see
/// [`memory::check_records`](super::memory)).
#[allow(clippy::too_many_arguments)]
pub fn iterate(
    mesh: &Sweep,
    buf: Buffers,
    opts: &Options,
    first: usize,
    when: Statistics,
    reference: &Reference,
    share: &mut dyn Share,
    observer: &mut dyn Observer,
) -> Result<Vec<IterationRecord>> {
    let run = Run::new(mesh, opts, when, reference, share, observer, true);
    run.all(buf, first)
}

/// [`iterate`] keeping no record (the observer still sees each): for runs whose records nobody
/// reads, so that their memory does not grow with the iteration count.
pub(crate) fn iterate_unrecorded(
    mesh: &Sweep,
    buf: Buffers,
    opts: &Options,
    when: Statistics,
    reference: &Reference,
    share: &mut dyn Share,
    observer: &mut dyn Observer,
) -> Result<()> {
    let run = Run::new(mesh, opts, when, reference, share, observer, false);
    run.all(buf, 1).map(drop)
}

impl<'r, 'a> Run<'r, 'a> {
    fn new(
        mesh: &'r Sweep<'a>,
        opts: &'r Options,
        when: Statistics,
        reference: &Reference,
        share: &'r mut dyn Share,
        observer: &'r mut dyn Observer,
        keep: bool,
    ) -> Self {
        Run {
            mesh,
            opts,
            when,
            origin: DVec3::from_array(reference.origin),
            reference: *reference,
            movable: (mesh.topo.len() - mesh.topo.stats.fixed_vertices).max(1),
            share,
            observer,
            keep,
            records: Vec::new(),
        }
    }

    /// Every iteration from `first` (until the automatic stop ends the run); the records kept.
    fn all(mut self, mut buf: Buffers, first: usize) -> Result<Vec<IterationRecord>> {
        if !self.opts.auto_stop {
            buf.auto = None;
        } else if buf
            .auto
            .as_ref()
            .is_none_or(|a| (first == 1) == a.started())
        {
            return Err(Error::parameter(
                "auto_stop",
                "needs the stop's buffers, started when (and only when) the run resumes",
            ));
        }
        if let Some(auto) = buf.auto.as_deref_mut() {
            if first == 1 {
                let (mesh, pos, origin) = (self.mesh, &*buf.pos, self.origin);
                auto.start(mesh.topo, mesh.tris, pos, origin, &mut *self.share);
            }
            if auto.stopped_by().is_some() {
                return Ok(self.records);
            }
        }
        let unit = self.opts.method.unit();
        match unit.schedule(self.opts) {
            Schedule::Umbrella(factors) => self.jacobi(buf, first, &factors)?,
            Schedule::TwoPass => self.two_pass(unit, buf, first)?,
            Schedule::Stencils(footprint) => self.stencils(unit, footprint, buf, first)?,
        }
        Ok(self.records)
    }
}

struct Run<'r, 'a> {
    mesh: &'r Sweep<'a>,
    opts: &'r Options,
    when: Statistics,
    origin: DVec3,
    reference: Reference,
    movable: usize,
    share: &'r mut dyn Share,
    observer: &'r mut dyn Observer,
    /// Whether `records` keeps the records.
    keep: bool,
    records: Vec<IterationRecord>,
}

impl Run<'_, '_> {
    /// Gauss–Seidel sweeps of a stencil method, colour after colour.
    fn stencils(
        &mut self,
        unit: &dyn Smoother,
        footprint: Footprint,
        buf: Buffers,
        first: usize,
    ) -> Result<()> {
        let Buffers {
            pos,
            scratch: sums,
            prev,
            counts,
            face_vectors,
            face_scalars,
            input,
            mut seam,
            mut auto,
        } = buf;
        let no_seam = Seam::default();
        let mesh = self.mesh;
        let owned = self.share.owned();
        // The loops of `boundary: smooth`, their normals measured at each iteration's start.
        let mut loops = (self.opts.boundary == crate::smooth::Boundary::Smooth).then(|| {
            mesh.loops
                .cloned()
                .unwrap_or_else(|| Loops::find(mesh.topo, mesh.tris))
        });
        let total = self.opts.iterations;
        let colours = mesh.colours(footprint);
        if let Some(loops) = &loops {
            // Each process holds every loop vertex from here on: the restoring pass that ends
            // each iteration leaves them the same in all.
            self.share.gather(pos, loops.vertices());
        }
        if unit.needs().counts {
            unit.start(mesh.topo, &mut self.exec(), counts);
        }
        for it in first..=total {
            let wanted = self.when.wanted(it, total);
            // An automatically stopped run measures every displacement (the rule of the methods
            // without a scalar analogue reads it).
            let measure = wanted || auto.is_some();
            let start = Instant::now();
            // `prev` is the preparation's spare buffer until the positions are copied into it.
            let opts = self.opts;
            let patch_mesh = PatchMesh {
                topo: mesh.topo,
                tris: mesh.tris,
                sorted: mesh.sorted,
                border: mesh.border,
            };
            let faces = FaceFields {
                vectors: face_vectors,
                scalars: face_scalars,
            };
            unit.prepare(
                patch_mesh,
                opts,
                &mut self.exec(),
                pos,
                sums,
                prev,
                counts,
                faces,
            );
            let own_moves = measure && !copies_positions(unit, self.opts);
            if own_moves && let Some(seam) = seam.as_deref_mut() {
                on_pool(&*self.share, || seam.capture(pos));
            }
            if measure && !own_moves {
                let now = &pos[owned.clone()];
                on_pool(&*self.share, || {
                    reduce::for_chunks_mut(&mut prev[owned.clone()], |at, out| {
                        out.copy_from_slice(&now[at..at + out.len()])
                    })
                });
            }
            if let Some(loops) = &mut loops {
                loops.measure(pos);
            }
            let params = stencil_params(unit, self.opts, input);
            let in_sweep = loops.as_ref().filter(|_| !unit.boundary_pass());
            let swept = self.sweep_colours(
                colours,
                Pass::Stencils(unit, self.opts),
                pos,
                sums,
                params,
                in_sweep,
                own_moves.then(|| seam.as_deref().unwrap_or(&no_seam)),
            );
            let mut sweep = swept.stencils;
            if unit.boundary_pass()
                && let Some(loops) = &loops
            {
                // The boundary stencils run after the method's, in the edge colouring (they are
                // edge stencils); what they write into `sums` is not read again.
                sweep.add(
                    &self
                        .sweep_colours(
                            mesh.colours,
                            Pass::Boundaries,
                            pos,
                            sums,
                            params,
                            Some(loops),
                            None,
                        )
                        .stencils,
                );
            }
            if let Some(loops) = &mut loops {
                // Every process walks every loop whole, from the same positions, so each holds
                // the same result for every loop vertex.
                self.share.gather(pos, loops.vertices());
                loops.restore(mesh.topo, mesh.tris, pos, params.deviation);
            }
            let seconds = start.elapsed().as_secs_f64();
            let moved = match own_moves {
                true => {
                    // A process that ran no patch moved nothing; the seam's moves follow the
                    // patches'.
                    let patches = swept.moved.unwrap_or_default();
                    Some(match seam.as_deref() {
                        Some(seam) => patches.then(on_pool(&*self.share, || seam.moves(pos))),
                        None => patches,
                    })
                }
                false => measure.then(|| {
                    let (now, before) = (&pos[owned.clone()], &prev[owned.clone()]);
                    on_pool(&*self.share, || reduce::displacement(now, before))
                }),
            };
            let stop = self.stop_after(auto.as_deref_mut(), pos, Some(prev));
            let last = stop || it == total;
            let record =
                self.record(it, pos, moved, Volume::when(wanted || stop), sweep, seconds)?;
            self.keep(
                &record,
                pos,
                last,
                auto.as_deref().map(AutoStop::stats).as_ref(),
            )?;
            if stop {
                break;
            }
        }
        Ok(())
    }

    /// The loop's side of a method's passes ([`Exec`]), on the share's threads.
    fn exec(&mut self) -> ShareExec<'_> {
        ShareExec {
            share: &mut *self.share,
        }
    }

    /// One Gauss–Seidel pass of `pass` over `colours`, colour after colour, each colour's patches
    /// in parallel, the changes exchanged after each colour; with `measure` (the seam, empty but
    /// for [`Moves::Seam`]), the moves the patches measured ([`Smoother::moves`]), summed in the
    /// order of the colours and of their patches, so for any thread count.
    #[allow(clippy::too_many_arguments)]
    fn sweep_colours(
        &mut self,
        colours: &[Vec<u32>],
        pass: Pass,
        pos: &mut [DVec3],
        sums: &mut [DVec3],
        params: StencilParams,
        loops: Option<&Loops>,
        measure: Option<&Seam>,
    ) -> PatchSweep {
        let mesh = self.mesh;
        let mut sweep = PatchSweep::default();
        // Out of core the read-ahead brings each patch's pages and its rings'; a fault that misses
        // reads its page alone. With the kernel's read-around each brought 8 MiB, and past the
        // page cache the sweep read 8 times what it held per iteration. Passes in order (the
        // statistics) keep the read-around.
        let at_random = |pos: &[DVec3], sums: &[DVec3], random: bool| {
            if mesh.prefetch.is_some() {
                crate::mesh::storage::read_at_random(pos, random);
                crate::mesh::storage::read_at_random(sums, random);
                crate::mesh::storage::read_at_random(mesh.tris, random);
                mesh.topo.read_at_random(random);
            }
        };
        at_random(pos, sums, true);
        for (c, colour) in colours.iter().enumerate() {
            if let Some(prefetch) = mesh.prefetch {
                // Read ahead the patches of the colours after this one, about a step of them (at
                // the end, the first ones again: the next iteration's); at the start, this
                // colour's too, which no earlier sweep of the run asked for.
                let this = colours[c].iter().take(if c == 0 { LANES } else { 0 });
                let ahead = colours.iter().cycle().skip(c + 1).flatten();
                for &p in this.chain(ahead.take(LANES)) {
                    prefetch.hint(p);
                }
            }
            let mine: Vec<Patch> = colour
                .iter()
                .map(|&p| p as usize)
                .filter(|&p| self.share.runs_patch(p))
                .map(|p| mesh.patches[p].clone())
                .collect();
            self.share.colour_start(pos);
            // SAFETY: the views are used only by the patches of this colour, which touch
            // disjoint positions and sums (the colouring invariant of `schedule` for the
            // method's footprint; a ring stencil only reads `sums`); `pos` and `sums` are not
            // used otherwise while the views live.
            let (pv, sv) = unsafe { (SharedField::new(pos), SharedField::new(sums)) };
            let done = on_pool(&*self.share, || {
                sweep_patches(mesh, pv, sv, &mine, pass, params, loops, measure)
            });
            sweep = sweep.then(done);
            self.share.colour_end(pos);
            if self.share.leads() {
                self.observer.iteration_part(c + 1, colours.len());
            }
        }
        at_random(pos, sums, false);
        sweep
    }

    /// Whether the automatic stop (when there is one) ends the run after the iteration that left
    /// `pos`; `prev`: the positions before it (read by the stencil methods' rule).
    fn stop_after(
        &mut self,
        auto: Option<&mut AutoStop>,
        pos: &[DVec3],
        prev: Option<&[DVec3]>,
    ) -> bool {
        let Some(auto) = auto else {
            return false;
        };
        auto.after(self.mesh.topo, pos, prev, &mut *self.share)
            .is_some()
    }

    /// [`Schedule::Umbrella`]: rounds of Jacobi steps with `factors` per iteration,
    /// ping-ponging between `pos` and `scratch` (the result ends in `pos`).
    ///
    /// With a [`TilePlan`] (when the mesh may hold one, and as long as every tile can be planned)
    /// a round runs several iterations in one pass over memory. With statistics every iteration
    /// (and the triangles sorted by their first corner, as the plan sorts them), each tile
    /// measures every iteration's displacement and its triangles' volume and area itself, so a
    /// round runs up to the plan's depth less one in steps (the tiles keep one ring more exact,
    /// the corners of their triangles). Otherwise a round runs up to the depth in steps and never
    /// past a measured iteration (it ends the round, its displacement measured in the round and
    /// its volume after it), and with the automatic stop one iteration. The iterations of a round
    /// share its time equally in their records; the first round also plans the tiles. Without a
    /// plan every iteration is one or two plain steps over the owned vertices, each followed by
    /// the exchange. All give bit-identical positions.
    fn jacobi(&mut self, buf: Buffers, first_iteration: usize, factors: &[f64]) -> Result<()> {
        let Buffers {
            pos,
            scratch,
            input,
            mut auto,
            ..
        } = buf;
        // With a deviation bound every step is a plain, clamped one.
        let clamp = self.opts.max_deviation.map(|limit| (input, limit));
        let mesh = self.mesh;
        let total = self.opts.iterations;
        let owned = self.share.owned();
        let sweep = self.vertex_counts(factors.len() as u64);
        let mut start = Instant::now();
        // Planned tile by tile by the first round (see `TilePlan::new`); dropped if a tile cannot be.
        // Only a process that owns every vertex: a round writes all of `dst` and exchanges nothing.
        let mut plan = (mesh.tiles && owned.len() == mesh.topo.len() && clamp.is_none())
            .then(|| TilePlan::new(mesh.topo));
        // Whether the current positions are in `scratch` (else in `pos`).
        let mut in_scratch = false;
        let mut first = first_iteration;
        while first <= total {
            // Measured inside the tiles (the triangles sorted, so that each tile has a run of
            // them): rounds of `depth − 1` steps, whatever they measure. Otherwise a round ends
            // at a measured iteration, whose volume is measured after it; and the automatic stop
            // looks at every iteration's result, one per round.
            let per = factors.len();
            let inside = plan.as_ref().is_some_and(|p| p.depth() > per)
                && mesh.sorted
                && auto.is_none()
                && self.when == Statistics::Every;
            let per_round = match &plan {
                Some(p) if inside => (p.depth() - 1) / per,
                Some(p) if auto.is_none() => (p.depth() / per).max(1),
                _ => 1,
            };
            let mut last = first;
            while last < total
                && last - first + 1 < per_round
                && (inside || !self.when.wanted(last, total))
            {
                last += 1;
            }
            let when = self.when;
            let wanted = |it: usize| when.wanted(it, total);
            let measure = wanted(last) || auto.is_some();
            let (src, dst): (&mut [DVec3], &mut [DVec3]) = if in_scratch {
                (&mut *scratch, &mut *pos)
            } else {
                (&mut *pos, &mut *scratch)
            };
            // Per iteration of the round: its displacement and volume, where measured.
            let mut measured: Vec<(Option<StepStats>, Volume)> =
                vec![(None, Volume::Unmeasured); last - first + 1];
            match &plan {
                Some(tiles) => {
                    let steps: Vec<f64> = (first..=last).flat_map(|_| factors.to_vec()).collect();
                    let iterations = match inside {
                        true => (first..=last)
                            .enumerate()
                            .filter(|&(_, it)| wanted(it))
                            .fold(0u64, |bits, (j, _)| bits | 1 << j),
                        false => (measure as u64) << (last - first),
                    };
                    let m = Measure {
                        per,
                        iterations,
                        block: reduce::CHUNK,
                        volume: inside.then_some((mesh.tris, self.origin)),
                    };
                    let m = (iterations != 0).then_some(m);
                    let Some(rounds) = on_pool(&*self.share, || round(tiles, src, dst, &steps, m))
                    else {
                        // A tile could not be planned: the same iterations in plain steps, from
                        // the untouched `src`.
                        plan = None;
                        continue;
                    };
                    in_scratch = !in_scratch;
                    let named = (0..measured.len()).filter(|&j| iterations >> j & 1 == 1);
                    for (j, r) in named.zip(rounds) {
                        // The tiles' sums when they measured inside (`inside`), else after.
                        let volume = r.sums.map_or(Volume::Measure, |(det, area)| {
                            Volume::Sums(det / 6.0, area / 2.0)
                        });
                        measured[j] = (Some(r.moved), volume);
                    }
                }
                None => {
                    let mut moved = self.step(src, dst, &owned, factors[0], Previous::Src, clamp);
                    if let Some(&mu) = factors.get(1) {
                        // The pair goes `src` → `dst` → `src`: the μ step measures against the
                        // position it overwrites, the one before the pair.
                        moved = self.step(dst, src, &owned, mu, Previous::Dst, clamp);
                    } else {
                        in_scratch = !in_scratch;
                    }
                    if measure {
                        measured[0] = (Some(moved), Volume::Measure);
                    }
                }
            };
            let seconds = start.elapsed().as_secs_f64() / (last - first + 1) as f64;
            let current: &[DVec3] = if in_scratch { scratch } else { pos };
            let stop = self.stop_after(auto.as_deref_mut(), current, None);
            for (it, (moved, mut volume)) in (first..=last).zip(measured) {
                if !(wanted(it) || it == last && stop) {
                    // Measured for the automatic stop only: no volume in the record.
                    volume = Volume::Unmeasured;
                }
                let ends = it == last && (stop || it == total);
                let record = self.record(it, current, moved, volume, sweep, seconds)?;
                let stats = auto.as_deref().map(AutoStop::stats);
                self.keep(&record, current, ends, stats.as_ref())?;
            }
            if stop {
                break;
            }
            first = last + 1;
            start = Instant::now();
        }
        if in_scratch {
            pos[owned.clone()].copy_from_slice(&scratch[owned]);
        }
        Ok(())
    }

    /// The counts of a Jacobi iteration that updates every owned vertex `steps` times.
    fn vertex_counts(&self, steps: u64) -> SweepStats {
        let (owned, topo) = (self.share.owned(), self.mesh.topo.parts());
        // Crease line vertices move (along their lines).
        let fixed = owned
            .clone()
            .filter(|&v| !topo.is_free_or_on_line(v as u32))
            .count() as u64;
        SweepStats {
            applied: (owned.len() as u64 - fixed) * steps,
            skipped_fixed: fixed * steps,
            ..Default::default()
        }
    }

    /// [`Schedule::TwoPass`]: per iteration the unit's pass 0 into the auxiliary field `prev`,
    /// then its pass 1 into the new positions, each exchanged, ping-ponging between `pos` and
    /// `scratch` (the result ends in `pos`).
    fn two_pass(&mut self, unit: &dyn Smoother, buf: Buffers, first: usize) -> Result<()> {
        let Buffers {
            pos,
            scratch,
            prev: aux,
            input,
            mut auto,
            ..
        } = buf;
        let (topo, opts) = (self.mesh.topo, self.opts);
        let total = opts.iterations;
        let owned = self.share.owned();
        let sweep = self.vertex_counts(1);
        let limit = opts.max_deviation;
        let mut in_scratch = false;
        for it in first..=total {
            let wanted = self.when.wanted(it, total);
            let start = Instant::now();
            let (src, dst): (&mut [DVec3], &mut [DVec3]) = if in_scratch {
                (&mut *scratch, &mut *pos)
            } else {
                (&mut *pos, &mut *scratch)
            };
            let src: &[DVec3] = src;
            let fields = PassFields {
                pos: src,
                input,
                aux: &[],
                limit,
            };
            self.exec().vertex_pass(aux, &|first, out| {
                unit.pass(0, topo, opts, fields, first, out);
            });
            let fields = PassFields { aux, ..fields };
            let out = &mut dst[owned.clone()];
            let offset = owned.start;
            let moved = on_pool(&*self.share, || {
                reduce::map_fold_mut(
                    out,
                    |at, out| unit.pass(1, topo, opts, fields, offset + at, out),
                    StepStats::default(),
                    StepStats::then,
                )
            });
            self.share.step_end(dst);
            in_scratch = !in_scratch;
            let seconds = start.elapsed().as_secs_f64();
            let stop = self.stop_after(auto.as_deref_mut(), dst, Some(src));
            let measured = (wanted || auto.is_some()).then_some(moved);
            let record = self.record(
                it,
                dst,
                measured,
                Volume::when(wanted || stop),
                sweep,
                seconds,
            )?;
            let stats = auto.as_deref().map(AutoStop::stats);
            self.keep(&record, dst, stop || it == total, stats.as_ref())?;
            if stop {
                break;
            }
        }
        if in_scratch {
            pos[owned.clone()].copy_from_slice(&scratch[owned]);
        }
        Ok(())
    }

    /// One plain Jacobi step over the owned vertices, measured against `previous`, then exchanged;
    /// `clamp`: the input positions and the largest distance from them (`max_deviation`).
    fn step(
        &mut self,
        src: &[DVec3],
        dst: &mut [DVec3],
        owned: &Range<usize>,
        factor: f64,
        previous: Previous,
        clamp: Option<(&[DVec3], f64)>,
    ) -> StepStats {
        let topo = self.mesh.topo;
        let offset = owned.start;
        let out = &mut dst[owned.clone()];
        let moved = on_pool(&*self.share, || {
            reduce::map_fold_mut(
                out,
                |at, out| match clamp {
                    None => laplacian::jacobi_step_measured(
                        topo,
                        src,
                        out,
                        offset + at,
                        factor,
                        previous,
                    ),
                    Some((input, limit)) => laplacian::jacobi_step_clamped(
                        topo,
                        src,
                        out,
                        offset + at,
                        factor,
                        previous,
                        input,
                        limit,
                    ),
                },
                StepStats::default(),
                StepStats::then,
            )
        });
        self.share.step_end(dst);
        moved
    }

    /// The record of iteration `it`, which ended at `pos`, shown to the observer; `moved` is its
    /// displacement when it is measured, `None` otherwise; `volume`: where its volume and area
    /// come from.
    fn record(
        &mut self,
        it: usize,
        pos: &[DVec3],
        moved: Option<StepStats>,
        volume: Volume,
        stencils: SweepStats,
        seconds: f64,
    ) -> Result<IterationRecord> {
        let (volume, area) = match volume {
            Volume::Unmeasured => (f64::NAN, f64::NAN),
            Volume::Measure => volume_area(self.mesh, pos, self.origin, &*self.share),
            Volume::Sums(v, a) => {
                let total = self.share.sum(&[v, a]);
                (total[0], total[1])
            }
        };
        let (max_d, sum_d) = moved.map_or((f64::NAN, f64::NAN), |m| {
            (m.max_displacement, m.sum_displacement)
        });
        let counts = [
            stencils.applied,
            stencils.skipped_fixed,
            stencils.skipped_degenerate,
            stencils.rejected,
            stencils.deviation_limited,
            stencils.boundary_applied,
            stencils.boundary_skipped,
        ];
        let mut local = vec![sum_d];
        local.extend(counts.iter().map(|&c| c as f64));
        let sums = self.share.sum(&local);
        let maxima = self.share.max(&[max_d, seconds]);
        let record = IterationRecord {
            iteration: it,
            volume,
            volume_pct: metrics::percent(volume, self.reference.volume),
            area_pct: metrics::percent(area, self.reference.area),
            // The maximum of NaNs is not NaN: an unmeasured iteration stays NaN on every rank.
            max_displacement: if moved.is_some() { maxima[0] } else { f64::NAN },
            mean_displacement: sums[0] / self.movable as f64,
            stencils: SweepStats {
                applied: sums[1] as u64,
                skipped_fixed: sums[2] as u64,
                skipped_degenerate: sums[3] as u64,
                rejected: sums[4] as u64,
                deviation_limited: sums[5] as u64,
                boundary_applied: sums[6] as u64,
                boundary_skipped: sums[7] as u64,
            },
            seconds: maxima[1],
        };
        if self.share.leads() {
            self.observer.iteration(&record, self.opts.iterations);
            if self.observer.interrupted() {
                return Err(Error::Interrupted);
            }
        }
        Ok(record)
    }

    /// After [`Run::record`]: the share's end of the iteration (a checkpoint), then the record
    /// kept; `last`: the run ends with this iteration.
    fn keep(
        &mut self,
        record: &IterationRecord,
        pos: &[DVec3],
        last: bool,
        auto: Option<&AutoStopStats>,
    ) -> Result<()> {
        self.share.iteration_end(record, pos, last, auto)?;
        if self.keep {
            self.records.try_reserve(1).map_err(|_| {
                let bytes = (self.records.len() as u64 + 1)
                    .saturating_mul(std::mem::size_of::<IterationRecord>() as u64);
                super::memory::not_enough("the iteration records", bytes, None)
            })?;
            self.records.push(*record);
        }
        Ok(())
    }
}

/// Whether a run of the stencil method `unit` with `opts` copies the positions before each
/// measured sweep (into the loop's `prev`): unless the unit's patches measure its moves
/// ([`Smoother::moves`]), with no pass after it that moves vertices (smoothed boundaries) and no
/// automatic stop (its rule reads the copy).
pub fn copies_positions(unit: &dyn Smoother, opts: &Options) -> bool {
    unit.moves() == Moves::Copied
        || opts.boundary == crate::smooth::Boundary::Smooth
        || opts.auto_stop
}

/// Whether a run of `unit` with `opts` out of core keeps the method's shares for the patches'
/// border alone ([`Sweep::border`]): not when the boundary loops are smoothed, whose stencils,
/// after the method's, use the array of the mesh's size as neighbour sums.
pub fn keeps_border(unit: &dyn Smoother, opts: &Options) -> bool {
    unit.needs().border && opts.boundary != crate::smooth::Boundary::Smooth
}

/// Whether a run of `unit` with `opts` keeps the seam of its patches ([`Seam`]) in place of the
/// copy of the positions.
pub fn keeps_seam(unit: &dyn Smoother, opts: &Options) -> bool {
    unit.moves() == Moves::Seam && !copies_positions(unit, opts)
}

/// The stencil kernel's parameters for `unit` with `opts`; `input`: the input positions, read
/// when `opts.max_deviation` bounds the deviation.
fn stencil_params<'a>(
    unit: &dyn Smoother,
    opts: &Options,
    input: &'a [DVec3],
) -> StencilParams<'a> {
    StencilParams {
        volume: unit.stencil_volume(),
        reject_energy_increase: opts.reject_energy_increase,
        deviation: opts
            .max_deviation
            .map(|limit| stencil::Deviation { input, limit }),
    }
}

/// The stencils of `patches` (all of one colour, so they touch disjoint data), in parallel on the
/// current rayon pool through the shared views, each patch's in ascending order; with `loops`
/// (`boundary: smooth`), the boundary stencils too. Their sweeps are added in the order of
/// `patches` (the moves they measure with `measure` are sums).
#[allow(clippy::too_many_arguments)]
fn sweep_patches(
    mesh: &Sweep,
    pos: SharedField,
    sums: SharedField,
    patches: &[Patch],
    pass: Pass,
    params: StencilParams,
    loops: Option<&Loops>,
    measure: Option<&Seam>,
) -> PatchSweep {
    let (topo, tris, sorted) = (mesh.topo, mesh.tris, mesh.sorted);
    let swept: Vec<PatchSweep> = patches
        .par_iter()
        .map(|patch| {
            let (mut pv, mut sv) = (pos, sums);
            match (pass, loops) {
                (Pass::Stencils(unit, opts), _) => unit.sweep_patch(
                    PatchMesh {
                        topo,
                        tris,
                        sorted,
                        border: mesh.border,
                    },
                    opts,
                    patch.vertices.clone(),
                    patch.triangles.clone(),
                    &mut pv,
                    &mut sv,
                    params,
                    loops,
                    measure.map(|seam| seam.part(&patch.vertices)),
                ),
                (Pass::Boundaries, Some(loops)) => {
                    let edges = patch.edges(topo);
                    boundary::sweep_edges(topo, tris, &mut pv, &mut sv, edges, params, loops, false)
                        .into()
                }
                (Pass::Boundaries, None) => PatchSweep::default(),
            }
        })
        .collect();
    swept
        .into_iter()
        .fold(PatchSweep::default(), PatchSweep::then)
}

/// What a sweep over patches applies: the method's stencils (with its boundary stencils in
/// place when the loops are smoothed), or the boundary stencils alone (the pass after the
/// method's, for a unit whose [`Smoother::boundary_pass`] says so).
#[derive(Clone, Copy)]
enum Pass<'u> {
    Stencils(&'u dyn Smoother, &'u Options),
    Boundaries,
}

/// The loop's side of a method's passes: chunks of the owned vertices on the share's threads,
/// each pass exchanged. Over an [`Alone`], the passes of one process over the whole mesh (the
/// crease detection's normal filter, `Plan::crease`).
pub(super) struct ShareExec<'s> {
    pub(super) share: &'s mut dyn Share,
}

/// `f(first, out)` over the entries `owned` of `field` (`out` holds entries `first ..`), in fixed
/// chunks on the process's pool: a vertex or triangle pass before its exchange.
fn owned_pass<T: Send>(
    share: &dyn Share,
    owned: std::ops::Range<usize>,
    field: &mut [T],
    f: &(dyn Fn(usize, &mut [T]) + Sync),
) {
    let first = owned.start;
    on_pool(share, || {
        reduce::for_chunks_mut(&mut field[owned], |at, out| f(first + at, out))
    });
}

impl Exec for ShareExec<'_> {
    fn vertex_pass(&mut self, field: &mut [DVec3], f: &(dyn Fn(usize, &mut [DVec3]) + Sync)) {
        owned_pass(&*self.share, self.share.owned(), field, f);
        self.share.step_end(field);
    }

    fn vertex_pass_u8(&mut self, field: &mut [u8], f: &(dyn Fn(usize, &mut [u8]) + Sync)) {
        owned_pass(&*self.share, self.share.owned(), field, f);
    }

    fn face_pass(&mut self, field: &mut [DVec3], f: &(dyn Fn(usize, &mut [DVec3]) + Sync)) {
        owned_pass(&*self.share, self.share.triangles(), field, f);
        self.share.face_end(field);
    }

    fn face_pass_f64(&mut self, field: &mut [f64], f: &(dyn Fn(usize, &mut [f64]) + Sync)) {
        owned_pass(&*self.share, self.share.triangles(), field, f);
        self.share.face_end_scalar(field);
    }
}

// A tile holds whole chunks, so that a round sums the displacement chunk by chunk as plain steps do.
const _: () = assert!(crate::smooth::tiled::TILE % reduce::CHUNK == 0);

/// One round of `factors.len()` Jacobi steps from `src` into `dst`, tile by tile in parallel (see
/// [`TilePlan::run_tile`]), with the iterations `measure` names measured: for each, in order, how
/// far the vertices moved and (with [`Measure::volume`]) the determinant and doubled-area sums.
/// The displacement is summed per [`reduce::CHUNK`] block in block order, exactly as plain steps
/// sum it, and the volume's sums tile after tile, so neither depends on the thread count (nor
/// the displacement on the tile size or the storage). `None` when a tile cannot be planned: then
/// `src` is untouched.
pub fn round(
    plan: &TilePlan,
    src: &[DVec3],
    dst: &mut [DVec3],
    factors: &[f64],
    measure: Option<Measure>,
) -> Option<Vec<RoundMeasure>> {
    let per_tile: Vec<Option<Vec<Measured>>> = dst
        .par_chunks_mut(plan.tile_size())
        .enumerate()
        .map(|(t, out)| plan.run_tile(t, src, out, factors, measure))
        .collect();
    let count = measure.map_or(0, |m| m.iterations.count_ones() as usize);
    let mut total = vec![
        RoundMeasure {
            moved: StepStats::default(),
            sums: measure.and_then(|m| m.volume).map(|_| (-0.0, -0.0)),
        };
        count
    ];
    for tile in per_tile {
        for (sum, m) in total.iter_mut().zip(tile?) {
            sum.moved = m.blocks.into_iter().fold(sum.moved, StepStats::then);
            sum.sums = sum
                .sums
                .zip(m.sums)
                .map(|((v, a), (tv, ta))| (v + tv, a + ta));
        }
    }
    Some(total)
}

/// What a round measured of one iteration over the whole mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoundMeasure {
    pub moved: StepStats,
    /// `(Σ det, Σ doubled area)` about the measure's origin, when [`Measure::volume`] asked.
    pub sums: Option<(f64, f64)>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes;

    /// A noisy sphere in a random vertex order (so that rings reach far), with an open hole (so
    /// that some vertices are fixed).
    fn shuffled_open_sphere() -> (Topology, Vec<DVec3>, Vec<[u32; 3]>) {
        let mut mesh = shapes::icosphere(5);
        shapes::add_normal_noise(&mut mesh, 0.3, 4);
        let n = mesh.positions.len();
        let perm = crate::shapes::permutation(n, 0x9e37_79b9_7f4a_7c15u64);
        let mut pos = vec![DVec3::ZERO; n];
        for (old, &new) in perm.iter().enumerate() {
            pos[new as usize] = mesh.positions[old];
        }
        let mut tris: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| perm[v as usize]))
            .collect();
        tris.truncate(tris.len() - 3);
        let topo = Topology::build(n, &tris).unwrap();
        assert!(topo.stats.fixed_vertices > 0);
        // As the plan keeps them: smallest corner first, sorted by it.
        for t in &mut tris {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            t.rotate_left(k);
        }
        tris.sort_unstable();
        (topo, pos, tris)
    }

    /// `pos`, then its positions after each plain step of `factors`, in turn.
    fn plain_steps(topo: &Topology, pos: &[DVec3], factors: &[f64]) -> Vec<Vec<DVec3>> {
        let mut steps = vec![pos.to_vec()];
        for &f in factors {
            let mut next = vec![DVec3::ZERO; pos.len()];
            laplacian::jacobi_step(topo, steps.last().unwrap(), &mut next, 0, f);
            steps.push(next);
        }
        steps
    }

    /// The displacement of the last of `k` steps, one per iteration.
    fn last_step(k: usize) -> Option<Measure<'static>> {
        Some(Measure {
            per: 1,
            iterations: 1 << (k - 1),
            block: reduce::CHUNK,
            volume: None,
        })
    }

    #[test]
    fn a_round_equals_plain_steps_for_any_tile_depth_and_thread_count() {
        let (topo, pos, _) = shuffled_open_sphere();
        let n = pos.len();
        let factors = [0.5, -0.53, 0.5, -0.53, 0.5, -0.53];
        let want = plain_steps(&topo, &pos, &factors);
        for (tile, depth) in [(1, 6), (97, 3), (1000, 6), (n, 8)] {
            let plan = TilePlan::lazy(&topo, tile, depth);
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                for k in 1..=depth.min(factors.len()) {
                    let mut got = vec![DVec3::ZERO; n];
                    let st = pool
                        .install(|| round(&plan, &pos, &mut got, &factors[..k], last_step(k)))
                        .unwrap()[0]
                        .moved;
                    assert_eq!(
                        got, want[k],
                        "tile {tile}, depth {depth}, {threads} threads, {k} steps"
                    );
                    let d: Vec<f64> = (0..n)
                        .map(|v| want[k][v].distance(want[k - 1][v]))
                        .collect();
                    let max = d.iter().cloned().fold(0.0, f64::max);
                    assert_eq!(st.max_displacement, max);
                    let sum: f64 = d.iter().sum();
                    assert!((st.sum_displacement - sum).abs() <= 1e-12 * sum);
                    assert_eq!(st.moved as usize, n - topo.stats.fixed_vertices);
                    // The same bits as the plain step measured over the engine's chunks, when the
                    // tiles hold whole chunks (as the engine's tiles do) or one tile holds all.
                    if tile % reduce::CHUNK != 0 && tile < n {
                        continue;
                    }
                    let mut out = vec![DVec3::ZERO; n];
                    let plain = reduce::map_fold_mut(
                        &mut out,
                        |at, o| {
                            let (from, f) = (&want[k - 1], factors[k - 1]);
                            laplacian::jacobi_step_measured(&topo, from, o, at, f, Previous::Src)
                        },
                        StepStats::default(),
                        StepStats::then,
                    );
                    assert_eq!(st.sum_displacement, plain.sum_displacement);
                }
            }
        }
    }

    #[test]
    fn statistics_do_not_depend_on_the_thread_count() {
        let (topo, pos, tris) = shuffled_open_sphere();
        let plan = TilePlan::lazy(&topo, 300, 4);
        let measure = Some(Measure {
            per: 2,
            iterations: 1,
            block: reduce::CHUNK,
            volume: Some((&tris[..], DVec3::new(0.1, -0.2, 0.3))),
        });
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut out = vec![DVec3::ZERO; pos.len()];
            pool.install(|| round(&plan, &pos, &mut out, &[0.5, -0.53], measure))
                .unwrap()
        };
        assert_eq!(run(1), run(4));
    }

    /// A round that measures several of its iterations inside the tiles gives each the
    /// displacement and the volume's sums of the plain steps (the largest move the same bits,
    /// the sums up to their order), keeps the positions of the plain steps, and gives the same
    /// bits for any thread count.
    #[test]
    fn a_round_measures_each_named_iteration_inside_the_tiles() {
        let (topo, pos, tris) = shuffled_open_sphere();
        let n = pos.len();
        let origin = DVec3::new(0.25, -0.5, 0.125);
        let factors = [0.5, -0.53, 0.5, -0.53, 0.5, -0.53];
        let want = plain_steps(&topo, &pos, &factors);
        for (tile, depth) in [(1, 7), (97, 5), (1000, 7), (n, 8)] {
            let plan = TilePlan::lazy(&topo, tile, depth);
            // Whole iterations of two steps, one step short of the depth.
            let k = (depth - 1) / 2 * 2;
            // Every iteration but the second.
            let iterations = (1u64 << (k / 2)) - 1 - 0b10;
            let measure = Some(Measure {
                per: 2,
                iterations,
                block: reduce::CHUNK,
                volume: Some((&tris[..], origin)),
            });
            let mut runs = Vec::new();
            for threads in [1, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut got = vec![DVec3::ZERO; n];
                let r = pool
                    .install(|| round(&plan, &pos, &mut got, &factors[..k], measure))
                    .unwrap();
                assert_eq!(
                    got, want[k],
                    "tile {tile}, depth {depth}, {threads} threads"
                );
                runs.push(r);
            }
            assert_eq!(runs[0], runs[1], "tile {tile}, depth {depth}");
            let named: Vec<usize> = (0..k / 2).filter(|&j| iterations >> j & 1 == 1).collect();
            assert_eq!(runs[0].len(), named.len());
            for (r, &j) in runs[0].iter().zip(&named) {
                let (from, to) = (&want[2 * j], &want[2 * j + 2]);
                let d: Vec<f64> = (0..n).map(|v| to[v].distance(from[v])).collect();
                assert_eq!(
                    r.moved.max_displacement,
                    d.iter().cloned().fold(0.0, f64::max)
                );
                let sum: f64 = d.iter().sum();
                assert!((r.moved.sum_displacement - sum).abs() <= 1e-12 * sum);
                let (det, area) = crate::metrics::determinant_and_area_sums(to, &tris, origin);
                let (got_det, got_area) = r.sums.unwrap();
                assert!(
                    (got_det - det).abs() <= 1e-12 * det.abs(),
                    "{got_det} {det}"
                );
                assert!((got_area - area).abs() <= 1e-12 * area, "{got_area} {area}");
            }
        }
    }

    #[test]
    fn rings_of_an_ordered_sphere_stay_small() {
        // Morton-ordered (as the engine orders every mesh), the rings cost a fraction of the tile.
        let mesh = shapes::icosphere(6);
        let storage = crate::mesh::Storage::heap();
        let r = crate::partition::reorder(&storage, &mesh.positions, &mesh.triangles).unwrap();
        let topo = Topology::build(r.positions.len(), &r.triangles).unwrap();
        let plan = TilePlan::lazy(&topo, 4096, 8);
        let mut out = vec![DVec3::ZERO; r.positions.len()];
        round(&plan, &r.positions, &mut out, &[0.5], None).expect("every tile planned");
        assert!(plan.overhead() < 2.0, "{}", plan.overhead());
    }

    #[test]
    fn a_tile_beyond_16_bit_ids_gives_no_plan() {
        // A closed bipyramid over a rim of 70,000 vertices: a tile of 65,536 rim vertices has
        // neighbours beyond 16-bit local ids.
        let m = 70_000u32;
        let tris: Vec<[u32; 3]> = (0..m)
            .flat_map(|k| [[m, k, (k + 1) % m], [m + 1, (k + 1) % m, k]])
            .collect();
        let topo = Topology::build(m as usize + 2, &tris).unwrap();
        // The round says so and leaves its input alone.
        let pos: Vec<DVec3> = (0..m + 2).map(|k| DVec3::new(k as f64, 1.0, 0.0)).collect();
        let mut out = vec![DVec3::ZERO; pos.len()];
        let plan = TilePlan::lazy(&topo, 1 << 16, 1);
        assert!(round(&plan, &pos, &mut out, &[0.5], None).is_none());
    }
}
