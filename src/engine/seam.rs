//! The seam of a sweep's patches, for [`Moves::Seam`]: the vertices that stencils of other
//! patches move too, and their positions when a measured sweep starts. Each patch measures how
//! far its other vertices moved, and the loop these after the sweep, so a measured iteration
//! needs no copy of the whole mesh's positions (12 B per triangle, out of core a pass over the
//! scratch).
//!
//! An edge stencil `(i, j)`, `i < j`, and a triangle stencil belong to the patch of their
//! smallest vertex, and patches are ascending ranges of vertices: a patch moves its own vertices
//! and neighbours of them in later patches. So a vertex is moved by another patch only when it
//! has a neighbour in an earlier one (its smallest neighbour is below its patch's start).
//!
//! [`Moves::Seam`]: crate::smooth::method::Moves::Seam

use std::ops::Range;

use glam::DVec3;

use crate::error::Result;
use crate::mesh::{Buf, Storage};
use crate::partition::Patch;
use crate::smooth::laplacian::StepStats;
use crate::smooth::method::SeamPart;
use crate::topology::Topology;

use super::reduce;

/// The seam's vertices, ascending, and their positions at the start of the current sweep.
#[derive(Debug, Default)]
pub struct Seam {
    vertices: Buf<u32>,
    positions: Buf<DVec3>,
}

impl Seam {
    /// The seam of the patches that `runs` names (a process's own), in `storage`.
    pub fn of(
        topo: &Topology,
        patches: &[Patch],
        runs: impl Fn(usize) -> bool + Sync,
        storage: &Storage,
    ) -> Result<Seam> {
        let vertices = crate::partition::select_vertices(patches, runs, storage, |p, v| {
            topo.neighbors(v)
                .first()
                .is_some_and(|&u| u < p.vertices.start)
        })?;
        let positions = storage.zeroed(vertices.len())?;
        Ok(Seam {
            vertices,
            positions,
        })
    }

    /// Take the seam's positions from `pos`, before a measured sweep.
    pub fn capture(&mut self, pos: &[DVec3]) {
        let vertices = &self.vertices;
        reduce::for_chunks_mut(&mut self.positions, |first, out| {
            let seam = &vertices[first..first + out.len()];
            for (p, &v) in out.iter_mut().zip(seam) {
                *p = pos[v as usize];
            }
        });
    }

    /// The part of the seam in the patch of `vertices`.
    pub fn part(&self, vertices: &Range<u32>) -> SeamPart<'_> {
        let at = |v: u32| self.vertices.partition_point(|&s| s < v);
        SeamPart {
            seam: &self.vertices[at(vertices.start)..at(vertices.end)],
        }
    }

    /// How far the seam's vertices moved to `pos` since [`Seam::capture`], summed in ascending
    /// vertex order (in fixed chunks, so for any thread count).
    pub fn moves(&self, pos: &[DVec3]) -> StepStats {
        reduce::moves(&self.vertices, |k, &v| {
            pos[v as usize].distance(self.positions[k])
        })
    }
}
