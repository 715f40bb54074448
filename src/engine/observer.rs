//! What a run tells while it goes: each long [`Phase`] with a [`Meter`] of its work, and one
//! [`IterationRecord`] per iteration, handed to an [`Observer`] (the CLI draws progress bars from
//! them); the records are also returned in the run's result.

use std::sync::Arc;

pub use crate::meter::Meter;
use crate::smooth::SweepStats;

/// A long phase of a run, in the order a file run goes through them ([`Observer::phase_start`]).
/// An in-memory run ([`crate::smooth_with`]) has no `Read` and `Write`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Phase {
    /// Taking the SHA-256 of the input and of the files it names, in bytes: the cluster engine
    /// identifies a checkpoint's input by its content.
    Hash,
    /// Reading and decoding the input, in bytes of the file. The binary PLY decoders count as
    /// they go; other readers count the file when they are done with it.
    Read,
    /// The Morton reorder of vertices and triangles, in items (vertices and triangles of each of
    /// its passes; the two sorts count when they end).
    Reorder,
    /// The topology (vertex-face and vertex-vertex adjacency, fixed vertices), in items (triangles
    /// and vertices of each of its passes); the orientation of the faces counts when it ends.
    Topology,
    /// Cutting the patches and colouring them, in items (patches whose neighbourhood is found;
    /// each of the two colourings counts as many when it ends).
    Schedule,
    /// The input's statistics (only when asked for, `EngineSettings::with_stats`), in steps: the
    /// connectivity figures, then the geometry.
    Statistics,
    /// The iterations (their cap with the automatic stop, which counts the rest as done when it
    /// stops). [`Observer::iteration`] tells more about each.
    Smooth,
    /// Putting the smoothed positions back in the input's vertex order for the output, in items
    /// (vertices placed).
    Restore,
    /// Drawing pictures of the mesh (a caller's, told by its [`Observer`]), in items (triangles
    /// drawn).
    Render,
    /// Writing the output, in bytes of the file. The total is the expected size (the input's size
    /// for an output of the input's format, else an estimate), set to the size written at the end.
    Write,
}

impl Phase {
    /// What a display shows: "reading", "reordering", …
    pub fn name(self) -> &'static str {
        match self {
            Phase::Hash => "hashing",
            Phase::Read => "reading",
            Phase::Reorder => "reordering",
            Phase::Topology => "building topology",
            Phase::Schedule => "colouring patches",
            Phase::Statistics => "measuring",
            Phase::Smooth => "smoothing",
            Phase::Restore => "restoring input order",
            Phase::Render => "drawing pictures",
            Phase::Write => "writing",
        }
    }

    /// The unit its meter counts.
    pub fn unit(self) -> Unit {
        match self {
            Phase::Hash | Phase::Read | Phase::Write => Unit::Bytes,
            Phase::Reorder | Phase::Topology | Phase::Schedule | Phase::Restore | Phase::Render => {
                Unit::Items
            }
            Phase::Statistics => Unit::Steps,
            Phase::Smooth => Unit::Iterations,
        }
    }
}

/// What a [`Phase`]'s meter counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Unit {
    Bytes,
    /// Vertices, triangles or patches handled, summed over the phase's passes.
    Items,
    Steps,
    Iterations,
}

/// Statistics of one iteration, relative to the input where a percentage is given. The figures of
/// an iteration that was not measured (see [`Statistics`]) are NaN, `null` in JSON.
///
/// The positions of a run are bit-identical for any thread count, storage and rank count; these
/// figures are sums over the mesh, and where the cluster engine's ranks add their shares their
/// last bits depend on the rank count.
#[derive(Debug, Clone, Copy, Default, serde::Serialize, serde::Deserialize)]
pub struct IterationRecord {
    /// 1-based iteration number.
    pub iteration: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub volume: f64,
    /// Volume as a percentage of the input volume (NaN, undefined, when the input volume is 0).
    #[serde(deserialize_with = "nan_if_null")]
    pub volume_pct: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub area_pct: f64,
    /// Largest distance any vertex moved in this iteration.
    #[serde(deserialize_with = "nan_if_null")]
    pub max_displacement: f64,
    /// Mean distance moved over the movable (non-fixed) vertices.
    #[serde(deserialize_with = "nan_if_null")]
    pub mean_displacement: f64,
    pub stencils: SweepStats,
    /// Seconds of the sweep: for `laplacian` and `taubin` with the displacement, which they
    /// measure in the same pass; never the volume and area statistics. Iterations that ran as one
    /// round of Jacobi steps (see [`Statistics`]) share its time equally, the round that builds
    /// the tile plan counting its construction.
    pub seconds: f64,
}

/// JSON has no NaN: serde_json writes it as `null`, and this reads `null` back as NaN (a resumed
/// cluster run reads the records of unmeasured iterations from its checkpoint).
pub(crate) fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Which iterations measure their volume, area and displacement, a setting of the run.
///
/// Each measurement costs passes over the whole mesh (volume and area: one over the triangles,
/// about as long as a `taubin` iteration; the displacement of the stencil methods: a copy and a
/// pass over the positions). Iterations that are not measured have NaN volume, area and
/// displacements (`null` in JSON); the sweep and its counts are the same. `laplacian` and `taubin`
/// run the iterations up to the next measured one as one round, several steps per pass over
/// memory (bit-identical results), so measuring fewer also makes them faster.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Statistics {
    /// After every iteration.
    #[default]
    Every,
    /// After the last iteration only.
    Last,
}

impl Statistics {
    /// Whether iteration `iteration` (1-based) of `total` is measured.
    pub fn wanted(self, iteration: usize, total: usize) -> bool {
        match self {
            Statistics::Every => true,
            Statistics::Last => iteration == total,
        }
    }
}

/// Why an automatically stopped run ended (the rule and its constants: `engine::auto`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopReason {
    /// σ̂ is 0: no iteration ran.
    NoNoise,
    /// `R_k >` `DETAIL_RATIO` (the other methods: `O_k >` their `Settle::removed`): the last
    /// iteration removed shape as well as noise.
    Detail,
    /// `E_k − E_{k−1} <` `NOISE_GONE`: the filter has removed what it can of the noise.
    NoiseRemoved,
    /// The mean displacement fell below `Settle::moved` × σ̂ (the methods without a filter).
    Settled,
    /// The cap (`Options::iterations`).
    Cap,
}

impl StopReason {
    /// How the command line says it.
    pub fn describe(self) -> &'static str {
        match self {
            StopReason::NoNoise => "no noise measured",
            StopReason::Detail => "the last iteration removed detail, not only noise",
            StopReason::NoiseRemoved => "the noise the filter can remove is gone",
            StopReason::Settled => "the vertices stopped moving",
            StopReason::Cap => "the cap was reached",
        }
    }
}

/// What the automatic stop measured, for the report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AutoStopStats {
    /// The cap (`Options::iterations`).
    pub cap: usize,
    pub stopped_by: StopReason,
    /// σ̂, in model units (along the normals).
    pub noise_estimate: f64,
    /// σ̂ from the median absolute deviation alone (`σ̂_m` of [`crate::engine::auto`]).
    pub noise_estimate_median: f64,
    /// σ̂ from the root mean square (`σ̂_e`): above [`crate::engine::auto::HEAVY_TAILS`] times
    /// the median's, the noise is heavy-tailed (impulsive) and σ̂ follows this one.
    pub noise_estimate_rms: f64,
    /// `O_k` of each iteration run (for `laplacian` measured along the edges, see
    /// [`crate::engine::auto`]).
    pub removed: Vec<f64>,
    /// `E_k` of each iteration run (`null` for the stencil methods, which have none; for
    /// `laplacian` along the edges, as its `O_k`).
    pub expected: Vec<f64>,
}

/// Receives progress from long runs.
pub trait Observer: Send {
    /// Called after each iteration with its record and the total number of iterations (with
    /// the automatic stop, `Options::auto_stop`, the cap: the run may end sooner).
    fn iteration(&mut self, _record: &IterationRecord, _total: usize) {}

    /// Inside an iteration: `done` of its `of` parts (the colours of a stencil sweep) are done.
    /// Called between the parts, on the loop's thread, so that a display moves within long
    /// iterations.
    fn iteration_part(&mut self, _done: usize, _of: usize) {}

    /// A long phase begins. `meter` counts its work in [`Phase::unit`] from the threads doing it:
    /// keep a clone and read it from any thread (a display's timer) until
    /// [`Observer::phase_end`]; its count only grows. Phases do not nest.
    fn phase_start(&mut self, _phase: Phase, _meter: &Arc<Meter>) {}

    /// The phase that began last has ended: when it succeeded, its meter reads `done == total`.
    /// Called on failure too, before the error is returned.
    fn phase_end(&mut self, _phase: Phase) {}

    /// Asked after each iteration (once [`Observer::iteration`] has seen it) and after each
    /// phase before the write (reading, reordering, the topology, the schedule, the statistics,
    /// restoring the input order):
    /// `true` ends the run there with [`Error::Interrupted`](crate::Error::Interrupted), before
    /// anything is written. A host that cannot end the process on a signal (the Python bindings) stops a
    /// long run this way; the cluster engine's ranks never ask.
    fn interrupted(&mut self) -> bool {
        false
    }

    /// The mesh being smoothed, just before the iterations and just after them ([`Moment`]), on
    /// the run's thread pool: its positions and triangles in the plan's vertex order, and the
    /// `storage` that holds the run's arrays (heap or scratch), where what the observer keeps of
    /// them belongs. Told by a file run in one process ([`crate::engine::run_file`], the
    /// multiresolution mode's) and an in-memory run, not by the cluster engine. An error ends the
    /// run there, before anything is written. The pictures of a run are drawn here.
    fn mesh_at(
        &mut self,
        _moment: Moment,
        _positions: &[glam::DVec3],
        _triangles: &[[u32; 3]],
        _storage: &crate::mesh::Storage,
    ) -> crate::Result<()> {
        Ok(())
    }
}

/// When [`Observer::mesh_at`] is told.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Moment {
    /// The input's positions, before the first iteration.
    BeforeSmoothing,
    /// The smoothed positions, after the last iteration.
    AfterSmoothing,
}

/// An observer that ignores everything.
pub struct Quiet;
impl Observer for Quiet {}

/// `work` as `phase` of `total` units: `observer` is told when it starts (with the meter that
/// `work` counts into) and when it ends, whether it succeeded or not; then, if it succeeded, asked
/// whether the run is [interrupted](Observer::interrupted), so that a host without signals (the
/// Python bindings) stops a long preparation at the next phase, not only between iterations.
pub(crate) fn metered<T>(
    observer: &mut dyn Observer,
    phase: Phase,
    total: u64,
    work: impl FnOnce(&Meter) -> crate::Result<T>,
) -> crate::Result<T> {
    let meter = Arc::new(Meter::new(total));
    observer.phase_start(phase, &meter);
    let out = work(&meter);
    observer.phase_end(phase);
    if out.is_ok() && observer.interrupted() {
        return Err(crate::Error::Interrupted);
    }
    out
}

/// The smoothing step's observer: counts the iterations into the [`Phase::Smooth`] meter and
/// passes them and `interrupted` on to the run's observer (no phase: phases do not nest).
pub(crate) struct IterationMeter<'a> {
    pub inner: &'a mut dyn Observer,
    pub meter: &'a Meter,
}

impl Observer for IterationMeter<'_> {
    fn iteration(&mut self, record: &IterationRecord, total: usize) {
        self.meter.reach(record.iteration as u64);
        self.inner.iteration(record, total);
    }

    fn iteration_part(&mut self, done: usize, of: usize) {
        self.inner.iteration_part(done, of);
    }

    fn interrupted(&mut self) -> bool {
        self.inner.interrupted()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::EngineSettings;
    use crate::{Error, Method, Options};

    /// Stops the run once iteration `after` is done; remembers the last iteration seen.
    struct StopAfter {
        after: usize,
        seen: usize,
    }

    impl Observer for StopAfter {
        fn iteration(&mut self, record: &IterationRecord, _total: usize) {
            self.seen = record.iteration;
        }
        fn interrupted(&mut self) -> bool {
            self.seen >= self.after
        }
    }

    #[test]
    fn an_interrupting_observer_stops_the_run_before_anything_is_written() {
        let mesh = crate::shapes::icosphere(2);
        for method in [Method::Vcs, Method::Laplacian] {
            let opts = Options {
                method,
                ..Options::default()
            };
            let mut smoothed = mesh.clone();
            let mut stop = StopAfter { after: 2, seen: 0 };
            let e = crate::smooth_with(&mut smoothed, &opts, &EngineSettings::default(), &mut stop);
            assert!(matches!(e, Err(Error::Interrupted)), "{method}: {e:?}");
            assert_eq!(stop.seen, 2);
            assert_eq!(&smoothed.positions[..], &mesh.positions[..]);
        }
        let dir = tempfile::tempdir().unwrap();
        let (input, output) = (dir.path().join("in.ply"), dir.path().join("out.ply"));
        crate::io::write_mesh(&input, &mesh).unwrap();
        let mut stop = StopAfter { after: 1, seen: 0 };
        let e = crate::engine::run_file(
            &input,
            &output,
            &Options::default(),
            &EngineSettings::default(),
            &mut stop,
        );
        assert!(matches!(e, Err(Error::Interrupted)), "{e:?}");
        let files: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(files.len(), 1, "only the input: {files:?}");
    }

    /// Interrupts once phase `after` has ended; remembers the phases that ended and whether an
    /// iteration was seen.
    struct StopAfterPhase {
        after: Phase,
        ended: Vec<Phase>,
        iterations: usize,
    }

    impl Observer for StopAfterPhase {
        fn phase_end(&mut self, phase: Phase) {
            self.ended.push(phase);
        }
        fn iteration(&mut self, _: &IterationRecord, _: usize) {
            self.iterations += 1;
        }
        fn interrupted(&mut self) -> bool {
            self.ended.contains(&self.after)
        }
    }

    #[test]
    fn an_interrupted_preparation_ends_at_the_next_phase() {
        let mesh = crate::shapes::icosphere(3);
        let dir = tempfile::tempdir().unwrap();
        let (input, output) = (dir.path().join("in.ply"), dir.path().join("out.ply"));
        crate::io::write_mesh(&input, &mesh).unwrap();
        let engine = EngineSettings {
            with_stats: true,
            ..EngineSettings::default()
        };
        for after in [
            Phase::Read,
            Phase::Reorder,
            Phase::Topology,
            Phase::Schedule,
            Phase::Statistics,
            Phase::Restore,
        ] {
            let mut stop = StopAfterPhase {
                after,
                ended: Vec::new(),
                iterations: 0,
            };
            let e =
                crate::engine::run_file(&input, &output, &Options::default(), &engine, &mut stop);
            assert!(matches!(e, Err(Error::Interrupted)), "{after:?}: {e:?}");
            assert_eq!(stop.ended.last(), Some(&after), "{:?}", stop.ended);
            // Restoring the order comes after the iterations.
            assert_eq!(stop.iterations == 0, after != Phase::Restore, "{after:?}");
            assert!(!output.exists(), "{after:?}");
        }
        // In memory: the plan's phases are asked too.
        let mut smoothed = mesh.clone();
        let mut stop = StopAfterPhase {
            after: Phase::Topology,
            ended: Vec::new(),
            iterations: 0,
        };
        let e = crate::smooth_with(&mut smoothed, &Options::default(), &engine, &mut stop);
        assert!(matches!(e, Err(Error::Interrupted)), "{e:?}");
        assert_eq!(stop.iterations, 0);
        assert_eq!(&smoothed.positions[..], &mesh.positions[..]);
    }

    #[test]
    fn unmeasured_records_survive_json() {
        let r = IterationRecord {
            iteration: 3,
            volume: f64::NAN,
            volume_pct: f64::NAN,
            area_pct: f64::NAN,
            max_displacement: f64::NAN,
            mean_displacement: f64::NAN,
            seconds: 0.5,
            ..Default::default()
        };
        let text = serde_json::to_string(&r).unwrap();
        assert!(text.contains("\"volume\":null"), "{text}");
        let back: IterationRecord = serde_json::from_str(&text).unwrap();
        assert_eq!(back.iteration, 3);
        assert!(back.volume.is_nan() && back.max_displacement.is_nan());
        let measured: IterationRecord = serde_json::from_str(
            &serde_json::to_string(&IterationRecord { volume: 2.5, ..r }).unwrap(),
        )
        .unwrap();
        assert_eq!(measured.volume, 2.5);
    }
}
