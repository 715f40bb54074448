//! How the iteration loop ([`super::iterate`]) and the automatic stop ([`super::auto`]) see the
//! processes that run them: [`Share`], and the single process that owns everything, [`Alone`].

use std::ops::Range;

use glam::DVec3;

use super::observer::{AutoStopStats, IterationRecord};
use crate::error::Result;

/// A process's share of the work and its link to the processes holding the rest. A single process
/// owns everything and shares nothing ([`Alone`]); a rank of the cluster engine owns a block of
/// patches and brings the copies other ranks hold up to date after every colour and step.
pub trait Share {
    /// The vertices this process updates.
    fn owned(&self) -> Range<usize>;
    /// The triangles this process owns: it sums their volume and area and computes their
    /// entries of a method's per-triangle fields.
    fn triangles(&self) -> Range<usize>;
    /// Whether this process applies the stencils of patch `p`.
    fn runs_patch(&self, p: usize) -> bool;
    /// Before the patches of a colour run.
    fn colour_start(&mut self, pos: &[DVec3]);
    /// After the patches of a colour ran: exchange the positions they changed.
    fn colour_end(&mut self, pos: &mut [DVec3]);
    /// After a Jacobi step wrote the owned entries of `field`: exchange them.
    fn step_end(&mut self, field: &mut [DVec3]);
    /// The same for a scalar field (the automatic stop's).
    fn step_end_scalar(&mut self, field: &mut [f64]);
    /// After a pass wrote the owned entries of a per-triangle `field`: exchange them.
    fn face_end(&mut self, field: &mut [DVec3]);
    /// The same for a per-triangle scalar field.
    fn face_end_scalar(&mut self, field: &mut [f64]);
    /// Bring `vertices`' entries of `pos` up to date from the processes that own them, wherever
    /// they are (the boundary loops, which every process walks whole).
    fn gather(&mut self, pos: &mut [DVec3], vertices: &[u32]);
    /// Element-wise sums and maxima over all processes.
    fn sum(&self, local: &[f64]) -> Vec<f64>;
    fn max(&self, local: &[f64]) -> Vec<f64>;
    /// Element-wise integer sums over all processes (wrapping; exact in any order).
    fn sum_counts(&self, local: Vec<u64>) -> Vec<u64>;
    /// After iteration `record.iteration`, whose positions are in `pos` (checkpoints go here);
    /// `last`: the run ends with it; `auto`: what the automatic stop measured so far, when the
    /// run has one.
    fn iteration_end(
        &mut self,
        record: &IterationRecord,
        pos: &[DVec3],
        last: bool,
        auto: Option<&AutoStopStats>,
    ) -> Result<()>;
    /// Whether this process reports to the observer.
    fn leads(&self) -> bool;
    /// The threads of the parallel work, when the loop itself runs outside them (a rank keeps its
    /// communicator on the calling thread); `None`: the current pool.
    fn pool(&self) -> Option<&rayon::ThreadPool>;
}

/// `f` on the share's threads.
pub(super) fn on_pool<R: Send>(share: &dyn Share, f: impl FnOnce() -> R + Send) -> R {
    match share.pool() {
        Some(pool) => pool.install(f),
        None => f(),
    }
}

/// The single process: owns all vertices and triangles.
pub struct Alone {
    pub vertices: usize,
    pub triangles: usize,
}

impl Share for Alone {
    fn owned(&self) -> Range<usize> {
        0..self.vertices
    }
    fn triangles(&self) -> Range<usize> {
        0..self.triangles
    }
    fn runs_patch(&self, _: usize) -> bool {
        true
    }
    fn colour_start(&mut self, _: &[DVec3]) {}
    fn colour_end(&mut self, _: &mut [DVec3]) {}
    fn step_end(&mut self, _: &mut [DVec3]) {}
    fn step_end_scalar(&mut self, _: &mut [f64]) {}
    fn face_end(&mut self, _: &mut [DVec3]) {}
    fn face_end_scalar(&mut self, _: &mut [f64]) {}
    fn gather(&mut self, _: &mut [DVec3], _: &[u32]) {}
    fn sum(&self, local: &[f64]) -> Vec<f64> {
        local.to_vec()
    }
    fn max(&self, local: &[f64]) -> Vec<f64> {
        local.to_vec()
    }
    fn sum_counts(&self, local: Vec<u64>) -> Vec<u64> {
        local
    }
    fn iteration_end(
        &mut self,
        _: &IterationRecord,
        _: &[DVec3],
        _: bool,
        _: Option<&AutoStopStats>,
    ) -> Result<()> {
        Ok(())
    }
    fn leads(&self) -> bool {
        true
    }
    fn pool(&self) -> Option<&rayon::ThreadPool> {
        None
    }
}
