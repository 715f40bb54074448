//! What a run tells while it goes: one [`IterationRecord`] per iteration, handed to an
//! [`Observer`] (the CLI draws a progress bar from it) and returned in the run's result.

use crate::smooth::SweepStats;

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
    /// Volume as a percentage of the input volume (100 when the input volume is 0).
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
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
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
    /// `R_k >` `DETAIL_RATIO` (the stencil methods: `O_k >` `REMOVED_ENOUGH`): the last
    /// iteration removed shape as well as noise.
    Detail,
    /// `E_k − E_{k−1} <` `NOISE_GONE`: the filter has removed what it can of the noise.
    NoiseRemoved,
    /// The mean displacement fell below `SETTLED` × σ̂ (the stencil methods).
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
    /// `O_k` of each iteration run.
    pub removed: Vec<f64>,
    /// `E_k` of each iteration run (`null` for the stencil methods, which have none).
    pub expected: Vec<f64>,
}

/// Receives progress from long runs.
pub trait Observer: Send {
    /// Called after each iteration with its record and the total number of iterations (with
    /// the automatic stop, `Options::auto_stop`, the cap: the run may end sooner).
    fn iteration(&mut self, _record: &IterationRecord, _total: usize) {}

    /// Asked after each iteration (once [`Observer::iteration`] has seen it): `true` ends the
    /// run there with [`Error::Interrupted`](crate::Error::Interrupted), before anything is
    /// written. A host that cannot end the process on a signal (the Python bindings) stops a
    /// long run this way; the cluster engine's ranks never ask.
    fn interrupted(&mut self) -> bool {
        false
    }
}

/// An observer that ignores everything.
pub struct Quiet;
impl Observer for Quiet {}

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
