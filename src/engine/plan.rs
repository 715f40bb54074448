//! The plan of a run: the mesh in the engine's vertex order, its topology, its patches and their
//! colours. Built once, smoothed any number of times (benchmarks, multiresolution levels, the
//! methods of `demo`), and stored by the cluster engine for its ranks.

use std::time::Instant;

use glam::DVec3;

use rayon::prelude::*;

use super::observer::{Meter, Observer, Phase, Quiet, metered};
use super::reduce;
use crate::error::{Error, Result};
use crate::mesh::{Buf, Storage};
use crate::partition::{self, Patch, Reordered, Weld};
use crate::schedule::{self, Schedule};
use crate::smooth::method::Footprint;
use crate::topology::Topology;

/// How a plan orders and cuts the mesh. Part of the result's definition: the stencil methods
/// apply their stencils colour by colour, patch by patch, so two layouts give different (equally
/// valid) results; the same layout gives bit-identical results for any thread count and storage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// Vertices sorted along the Morton curve and cut into patches of this many vertices (what
    /// `smooth` and every file run use; see [`crate::partition`]).
    Patches(usize),
    /// The input's own order as one patch: stencils in ascending `(i, j)` (edges) or in the
    /// input's triangle order (triangle stencils), the order of the sequential reference.
    Whole,
}

/// Default vertices per patch: small enough that a 1M-triangle mesh has dozens of patches to
/// share among threads, large enough that the per-patch scheduling cost is negligible.
pub const DEFAULT_PATCH_SIZE: usize = 16_384;

impl Default for Layout {
    fn default() -> Self {
        Layout::Patches(DEFAULT_PATCH_SIZE)
    }
}

/// A mesh prepared for smoothing (see the module doc).
#[derive(Debug)]
pub struct Plan {
    /// Positions and triangles in the plan's vertex order, with the permutation back.
    pub reordered: Reordered,
    pub topology: Topology,
    pub patches: Vec<Patch>,
    pub schedule: Schedule,
    /// How the plan orders and cuts the mesh.
    pub layout: Layout,
    /// Whether its arrays are on the heap (else in memory-mapped scratch files): the smoothing
    /// then holds its tile plans and buffers in memory too.
    pub in_memory: bool,
    /// How the smoothed positions will be stored (a file run's output; `None`: as they are):
    /// a deviation bound then holds for the stored values (see [`crate::io::Stored::round_within`]).
    pub stored: Option<crate::io::Stored>,
    /// Seconds spent in each preparation phase.
    pub timings: PrepTimings,
    /// The mesh's connected components ([`crate::metrics::components`]), when the run counted
    /// them before building the topology, so that their forest was not alive beside it.
    pub components: Option<usize>,
}

/// Seconds spent preparing.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct PrepTimings {
    pub reorder: f64,
    pub topology: f64,
    pub partition: f64,
}

/// The patch decomposition of a run, for reports.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct PlanStats {
    pub patch_size: usize,
    pub patches: usize,
    /// Colours per iteration: those of every step of the streaming order, added up.
    pub colours: usize,
    /// Steps of the streaming order ([`crate::schedule::steps`]): the length of a lane.
    pub steps: usize,
    /// Vertices outside a patch's own range that its stencils read: smallest, mean, largest.
    pub halo_min: u32,
    pub halo_mean: f64,
    pub halo_max: u32,
    /// Edge stencils whose two vertices lie in different patches (each applied once, by the
    /// patch of its smaller vertex).
    pub crossing_edge_stencils: u64,
    pub threads: usize,
    /// The vertices no stencil moves, and why.
    pub fixed: FixedVertices,
}

/// How many of a plan's vertices no method moves, and the counts behind them (one vertex can have
/// several reasons): what a run says when most of a mesh cannot move.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct FixedVertices {
    pub vertices: usize,
    pub fixed: usize,
    pub boundary_edges: usize,
    pub non_manifold_edges: usize,
    pub non_manifold_vertices: usize,
    /// Vertices of no triangle, welded copies not included.
    pub unreferenced: usize,
    /// Welded copies: vertices at the position of another, which move with it.
    pub welded: usize,
    pub pinned: usize,
    pub on_creases: usize,
}

impl FixedVertices {
    /// The counts of a plan's topology `stats`, whose `welded` copies it counts as unreferenced
    /// and fixed: here they are neither (they move with the vertex they are welded to).
    pub fn of(stats: &crate::topology::TopologyStats, welded: usize) -> FixedVertices {
        FixedVertices {
            vertices: stats.vertices,
            fixed: stats
                .fixed_vertices
                .min(stats.vertices)
                .saturating_sub(welded),
            boundary_edges: stats.boundary_edges,
            non_manifold_edges: stats.non_manifold_edges,
            non_manifold_vertices: stats.non_manifold_vertices,
            unreferenced: stats.unreferenced_vertices.saturating_sub(welded),
            welded,
            pinned: stats.pinned_vertices,
            on_creases: stats.crease_vertices,
        }
    }
}

/// The statistics of `mesh` as a run sees it: its copies welded as `weld` says (see
/// [`crate::partition`]), its faces oriented; in the input's order, in memory (what `info`
/// prints).
pub fn mesh_info(mesh: &crate::Mesh, weld: Weld) -> Result<crate::metrics::MeshInfo> {
    let storage = Storage::heap();
    let mut r = Reordered::in_input_order(&storage, &mesh.positions, &mesh.triangles, weld)?;
    let mut topology = Topology::build(mesh.positions.len(), &r.triangles)?;
    topology.orient(&mut r.triangles, &r.positions);
    let mut info = crate::metrics::info_of(&r.positions, &r.triangles, &mesh.source, &topology)?;
    info.count_welded(r.welded);
    Ok(info)
}

/// The mesh in a plan's order, the seconds it took and, where the reorder counted them, its
/// connected components ([`Plan::reorder`]).
pub struct Ordered {
    pub reordered: Reordered,
    pub seconds: f64,
    pub components: Option<usize>,
}

impl Plan {
    /// Order, build the topology, cut and colour the patches as `layout` says, placing the large
    /// arrays as `storage` says. Runs on the current rayon pool (the result does not depend on it).
    pub fn new(
        storage: &Storage,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        layout: Layout,
    ) -> Result<Plan> {
        Plan::new_observed(
            storage,
            positions,
            triangles,
            layout,
            Weld::Exact,
            &mut Quiet,
        )
    }

    /// [`Plan::new`], telling `observer` how far each phase is ([`Phase::Reorder`],
    /// [`Phase::Topology`], [`Phase::Schedule`]). The same plan whatever the observer.
    pub fn new_observed(
        storage: &Storage,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        layout: Layout,
        weld: Weld,
        observer: &mut dyn Observer,
    ) -> Result<Plan> {
        let positions = partition::Input::Lent(positions);
        let ordered = Plan::reorder(storage, positions, triangles, layout, weld, false, observer)?;
        Plan::of_reordered(storage, ordered, layout, observer)
    }

    /// The first phase of [`Plan::new_observed`]: the mesh in the plan's order, a copy that the
    /// rest of the plan is built from alone (so the caller may give the input's arrays back;
    /// positions given rather than lent go as soon as they are copied). With `components`, a
    /// layout of patches also counts the mesh's connected components as it sorts the triangles
    /// ([`partition::reorder_counted`]).
    #[allow(clippy::too_many_arguments)]
    pub fn reorder(
        storage: &Storage,
        positions: partition::Input,
        triangles: &[[u32; 3]],
        layout: Layout,
        weld: Weld,
        components: bool,
        observer: &mut dyn Observer,
    ) -> Result<Ordered> {
        let (n, t) = (positions.len() as u64, triangles.len() as u64);
        let clock = Instant::now();
        let (reordered, components) = match layout {
            Layout::Patches(0) => {
                return Err(Error::parameter("patch_size", "must be at least 1"));
            }
            Layout::Patches(size) => {
                if let Some(budget) = storage.budget() {
                    super::memory::check_schedule(n, size, budget)?;
                }
                metered(
                    observer,
                    Phase::Reorder,
                    partition::REORDER_PASSES.items(n, t),
                    |m| {
                        partition::reorder_counted(
                            storage, positions, triangles, weld, components, m,
                        )
                    },
                )?
            }
            Layout::Whole => (
                Reordered::in_input_order(storage, &positions, triangles, weld)?,
                None,
            ),
        };
        Ok(Ordered {
            reordered,
            seconds: clock.elapsed().as_secs_f64(),
            components,
        })
    }

    /// The rest of [`Plan::new_observed`] after [`Plan::reorder`]: the topology, the patches and
    /// their schedule.
    pub fn of_reordered(
        storage: &Storage,
        ordered: Ordered,
        layout: Layout,
        observer: &mut dyn Observer,
    ) -> Result<Plan> {
        let Ordered {
            mut reordered,
            seconds: reorder,
            components,
        } = ordered;
        let (vertices, triangles) = (reordered.positions.len(), reordered.triangles.len());
        let (n, t) = (vertices as u64, triangles as u64);
        let clock = Instant::now();
        let topology = metered(
            observer,
            Phase::Topology,
            Topology::BUILD_PASSES.items(n, t) + t,
            |m| -> Result<Topology> {
                // Out of core, in the plan's layout, the faces are found in the triangles' runs
                // (the build never holds the vertex → face list: 16 B per triangle). In memory
                // the lists stay: a walk of the runs costs `vcs` about a third more time.
                let tris = &reordered.triangles;
                let mut topology = match storage.is_mapped() && matches!(layout, Layout::Patches(_))
                {
                    true => Topology::build_runs_metered(storage, vertices, tris, m)?,
                    false => Topology::build_metered(storage, vertices, tris, m)?,
                };
                // The plan's copy of the faces is what the stencils' volumes read; the output
                // keeps the input's faces.
                topology.orient(&mut reordered.triangles, &reordered.positions);
                m.add(t);
                Ok(topology)
            },
        )?;
        let topology_s = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let (patches, schedule) = match layout {
            Layout::Patches(size) => {
                let patches = partition::patches(vertices, &reordered.triangles, size);
                let total = schedule::SCHEDULE_PASSES * patches.len() as u64;
                let schedule = metered(observer, Phase::Schedule, total, |m| {
                    Ok(schedule::schedule_metered(&topology, &patches, m))
                })?;
                (patches, schedule)
            }
            Layout::Whole => (
                vec![Patch {
                    vertices: 0..vertices as u32,
                    triangles: 0..triangles as u32,
                }],
                Schedule::single(),
            ),
        };
        Ok(Plan {
            reordered,
            topology,
            patches,
            schedule,
            layout,
            in_memory: !storage.is_mapped(),
            stored: None,
            timings: PrepTimings {
                reorder,
                topology: topology_s,
                partition: clock.elapsed().as_secs_f64(),
            },
            components,
        })
    }

    /// Vertices of the mesh.
    pub fn len(&self) -> usize {
        self.reordered.positions.len()
    }

    /// Whether the mesh has no vertices.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Copy the plan's (smoothed) positions into `out` in the input's vertex order, each welded
    /// copy at its vertex's position, on the current pool.
    pub fn positions_in_input_order(&self, out: &mut [DVec3]) {
        self.positions_in_input_order_metered(out, &Meter::default());
    }

    /// [`Plan::positions_in_input_order`], counting its work into `meter` (see
    /// [`partition::scatter_metered`]).
    pub fn positions_in_input_order_metered(&self, out: &mut [DVec3], meter: &Meter) {
        let r = &self.reordered;
        partition::scatter_metered(out, &r.order, |new| r.positions[r.source_of(new)], meter);
    }

    /// Give back the triangles and the adjacency, once only the positions are left to put back
    /// in the input's order ([`Plan::positions_in_input_order_metered`]).
    pub fn release_connectivity(&mut self) {
        self.reordered.triangles = Buf::default();
        self.topology = Topology::default();
        self.patches = Vec::new();
    }

    /// Move each welded copy to the position of the vertex it is welded to (see
    /// [`Reordered::welded_to`]): after smoothing, so that the plan's positions are the output's.
    pub fn follow_welds(&mut self) {
        let r = &mut self.reordered;
        partition::follow_welds(&mut r.positions, &r.welded_to);
    }

    /// Set the plan's positions from `input`, given in the input's vertex order (to smooth the
    /// same mesh again from its start), on the current pool.
    pub fn set_positions_from_input(&mut self, input: &[DVec3]) {
        let Reordered {
            order, positions, ..
        } = &mut self.reordered;
        reduce::for_chunks_mut(positions, |first, chunk| {
            for (p, &old) in chunk.iter_mut().zip(&order[first..]) {
                *p = input[old as usize];
            }
        });
    }

    /// Statistics of the current positions (see [`reduce::geometry`] for the order of the sums);
    /// the working array of the component count is placed as `storage` says.
    pub fn info(
        &self,
        source: &crate::mesh::Source,
        storage: &Storage,
    ) -> Result<crate::metrics::MeshInfo> {
        self.info_metered(source, storage, &Meter::default())
    }

    /// [`Plan::info`], counting the vertices its geometry pass measured into `meter` (the
    /// connectivity figures before it are counts the topology keeps).
    pub fn info_metered(
        &self,
        source: &crate::mesh::Source,
        storage: &Storage,
        meter: &Meter,
    ) -> Result<crate::metrics::MeshInfo> {
        let triangles = &self.reordered.triangles;
        let components = match self.components {
            Some(count) => count,
            None => crate::metrics::components(self.len(), triangles, storage, &Meter::default())?,
        };
        let mut info = crate::metrics::connectivity(
            self.len(),
            triangles.len(),
            source,
            &self.topology,
            components,
        );
        info.count_welded(self.reordered.welded);
        let origin = reduce::centroid(&self.reordered.positions);
        info.set_geometry(self.geometry_about(origin, meter));
        Ok(info)
    }

    /// The figures of [`Plan::info`] that depend on the positions, of the current positions,
    /// with the volume about `origin`; the vertices counted into `meter` as they are measured.
    pub fn geometry_about(&self, origin: glam::DVec3, meter: &Meter) -> crate::metrics::Geometry {
        let Reordered {
            positions,
            triangles,
            ..
        } = &self.reordered;
        reduce::geometry_about(positions, triangles, &self.topology, origin, meter)
    }

    /// The decomposition's figures for reports, with the colouring and halo of `footprint`
    /// (see [`Schedule::ring_colours`]); a method's is `method.unit().schedule(opts).footprint()`.
    pub fn stats(&self, footprint: Footprint) -> PlanStats {
        let (colours, halo) = footprint_colouring(
            footprint,
            (&self.schedule.colours, &self.schedule.halo),
            (&self.schedule.ring_colours, &self.schedule.ring_halo),
        );
        let patch_size = match self.layout {
            Layout::Patches(size) => size,
            Layout::Whole => self.len(),
        };
        PlanStats::new(
            patch_size,
            colours.len(),
            halo,
            self.patches
                .par_iter()
                .map(|p| p.crossing_edges(&self.topology))
                .sum(),
            FixedVertices::of(&self.topology.stats, self.reordered.welded),
        )
    }
}

/// Of an edge colouring and a ring colouring (each colours and halo counts), the one for stencils
/// of `footprint`.
pub fn footprint_colouring<'a>(
    footprint: Footprint,
    edge: (&'a [Vec<u32>], &'a [u32]),
    ring: (&'a [Vec<u32>], &'a [u32]),
) -> (&'a [Vec<u32>], &'a [u32]) {
    match footprint {
        Footprint::Edge => edge,
        Footprint::Ring => ring,
    }
}

impl PlanStats {
    /// The figures of a plan of `halo.len()` patches (one halo count each), on the current pool.
    pub fn new(
        patch_size: usize,
        colours: usize,
        halo: &[u32],
        crossing: u64,
        fixed: FixedVertices,
    ) -> PlanStats {
        PlanStats {
            patch_size,
            patches: halo.len(),
            colours,
            steps: crate::schedule::steps(halo.len()),
            halo_min: halo.iter().copied().min().unwrap_or(0),
            // `+ 0.0`: an empty sum is −0.
            halo_mean: (halo.iter().map(|&h| h as f64).sum::<f64>() + 0.0)
                / halo.len().max(1) as f64,
            halo_max: halo.iter().copied().max().unwrap_or(0),
            crossing_edge_stencils: crossing,
            threads: rayon::current_num_threads(),
            fixed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::topology::FaceParts;

    #[test]
    fn out_of_core_a_plan_finds_its_faces_in_runs_and_never_holds_lists() {
        // An open sphere with a degenerate face, in a shuffled vertex order.
        let sphere = crate::shapes::icosphere(5);
        let n = sphere.positions.len();
        let perm = crate::shapes::permutation(n, 5);
        let mut positions = vec![DVec3::ZERO; n];
        for (v, &p) in sphere.positions.iter().enumerate() {
            positions[perm[v] as usize] = p;
        }
        let mut triangles: Vec<[u32; 3]> = sphere.triangles[40..]
            .iter()
            .map(|t| t.map(|v| perm[v as usize]))
            .collect();
        triangles.push([triangles[7][0], triangles[7][0], triangles[9][1]]);
        let m = triangles.len();
        let layout = Layout::Patches(512);
        let listed = Plan::new(&Storage::heap(), &positions, &triangles, layout).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let storage = Storage::scratch(dir.path()).unwrap();
        let runs = Plan::new(&storage, &positions, &triangles, layout).unwrap();
        assert!(matches!(
            listed.topology.parts().faces,
            FaceParts::Lists { .. }
        ));
        assert!(matches!(
            runs.topology.parts().faces,
            FaceParts::Runs { .. }
        ));
        assert_eq!(runs.reordered.triangles, listed.reordered.triangles);
        let tris: &[[u32; 3]] = &runs.reordered.triangles;
        for v in 0..n as u32 {
            assert!(
                runs.topology
                    .faces_of(v, tris)
                    .eq(listed.topology.faces_of(v, tris)),
                "faces of {v}"
            );
        }
        // The lists (12 B per face and its offsets) gave way to the runs' starts (4 B per
        // vertex), and nothing on the disk holds them any more: the scratch is the plan's
        // positions, triangles, permutation and topology alone.
        let faces = 3 * (m - 1);
        assert_eq!(
            listed.topology.heap_bytes() - runs.topology.heap_bytes(),
            4 * faces - 4 * (n + 1) + 8 * (n + 1)
        );
        let plan_bytes = 24 * n + 12 * m + 4 * n + runs.topology.heap_bytes();
        let held = storage.held_bytes() as usize;
        assert_eq!(held, plan_bytes, "bytes on the disk against the plan's");
        // Nor did the build ever hold a vertex → face list (12 B per face) beside the plan.
        let peak = storage.peak_mapped_bytes() as usize;
        assert!(
            peak <= plan_bytes + 4 * m,
            "{peak} at the peak, {plan_bytes} in the plan"
        );
    }
}
