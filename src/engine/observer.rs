//! What a run tells while it goes: one [`IterationRecord`] per iteration, handed to an
//! [`Observer`] (the CLI draws a progress bar from it) and returned in the run's result.

use crate::smooth::SweepStats;

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
    /// round of Jacobi steps (see [`Statistics`]) share its time equally, the round that builds
    /// the tile plan counting its construction.
    pub seconds: f64,
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

/// Receives progress from long runs.
pub trait Observer: Send {
    /// Called after each iteration with its record and the total number of iterations.
    fn iteration(&mut self, _record: &IterationRecord, _total: usize) {}
}

/// An observer that ignores everything.
pub struct Quiet;
impl Observer for Quiet {}
