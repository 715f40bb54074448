//! The methods of the design, in the terms of [`Smoother`]: a type each, but one for the three
//! stencil methods of Liu et al. ([`StencilMethod`]). Their kernels are in [`super::laplacian`],
//! [`super::stencil`], [`super::boundary`], [`super::lowpass`] and [`super::guided`]; `hc`'s unit
//! is beside its kernel, [`super::hc`].

use std::ops::Range;

use glam::DVec3;

use super::boundary::{self, Loops};
use super::method::{
    Control, Exec, FaceFields, Footprint, Moves, Needs, PatchMesh, PatchSweep, Schedule, SeamPart,
    Settle, Smoother, StopRule,
};
use super::stencil::{self, StencilParams};
use super::{
    Field, Options, PatchField, SharedField, SweepStats, Topology, guided, laplacian, lowpass,
    rings,
};

/// Umbrella Laplacian, forward Euler `p += λ L(p)`, Jacobi (Liu et al. 2002, eq. 3–6). Shrinks.
pub struct Laplacian;

impl Smoother for Laplacian {
    fn name(&self) -> &'static str {
        "laplacian"
    }
    fn help(&self) -> &'static str {
        "umbrella Laplacian, p += λ L(p) (shrinks)"
    }
    fn schedule(&self, opts: &Options) -> Schedule {
        Schedule::Umbrella(vec![opts.lambda])
    }
    fn keeps_volume(&self) -> bool {
        false
    }
    fn stop_rule(&self, opts: &Options) -> StopRule {
        StopRule::ShrinkingFilter(vec![opts.lambda])
    }
    fn accepts(&self, control: Control) -> bool {
        matches!(control, Control::Lambda | Control::MultiresFine)
    }
}

/// Taubin's λ|μ: a λ step then a μ step per iteration (Taubin 1995).
pub struct Taubin;

impl Smoother for Taubin {
    fn name(&self) -> &'static str {
        "taubin"
    }
    fn help(&self) -> &'static str {
        "λ|μ: a λ step then a μ step (Taubin 1995)"
    }
    fn schedule(&self, opts: &Options) -> Schedule {
        Schedule::Umbrella(vec![opts.lambda, opts.mu()])
    }
    fn keeps_volume(&self) -> bool {
        false
    }
    fn stop_rule(&self, opts: &Options) -> StopRule {
        StopRule::Filter(vec![opts.lambda, opts.mu()])
    }
    fn accepts(&self, control: Control) -> bool {
        matches!(
            control,
            Control::Lambda | Control::Mu | Control::MultiresFine
        )
    }
}

/// The edge stencils' sweep of a patch: its edges `(i, j)`, `i` in `vertices`, ascending; with
/// `loops`, an edge that is a boundary stencil gets the boundary kernel in its place.
fn sweep_edge_stencils<P: Field + ?Sized, S: Field + ?Sized>(
    mesh: PatchMesh,
    vertices: Range<u32>,
    pos: &mut P,
    sums: &mut S,
    params: StencilParams,
    loops: Option<&Loops>,
) -> SweepStats {
    let edges = mesh.topo.edges_from(vertices);
    match loops {
        Some(loops) => {
            boundary::sweep_edges(mesh.topo, mesh.tris, pos, sums, edges, params, loops, true)
        }
        None => stencil::sweep_edges(mesh.topo, mesh.tris, pos, sums, edges, params),
    }
}

/// The free vertices of a stencil of [`StencilMethod`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Free {
    /// The two ends of an edge.
    Edge,
    /// The three corners of a triangle.
    Triangle,
}

/// The stencil methods of Liu et al.: each stencil moved to its local energy minimum (§2.3,
/// eq. 7–9), then, with `volume`, translated back to its volume (§3, the 2-step approximation
/// of §3.1). `lem`, `vcs` and `vcs-triangle` are three values of it.
pub struct StencilMethod {
    pub name: &'static str,
    pub help: &'static str,
    pub free: Free,
    pub volume: bool,
}

/// Local energy minimisation on edge stencils, no volume constraint (Liu et al. §2.3, eq. 7–9).
pub const LEM: StencilMethod = StencilMethod {
    name: "lem",
    help: "local energy minimisation on edge stencils, no volume constraint",
    free: Free::Edge,
    volume: false,
};

/// Volume-constrained smoothing on edge stencils, the 2-step approximation (Liu et al. §3, §3.1).
pub const VCS: StencilMethod = StencilMethod {
    name: "vcs",
    help: "volume-constrained smoothing on edge stencils (Liu et al. 2002)",
    free: Free::Edge,
    volume: true,
};

/// Volume-constrained smoothing on triangle stencils, 3 free vertices (Liu et al. §3.2).
pub const VCS_TRIANGLE: StencilMethod = StencilMethod {
    name: "vcs-triangle",
    help: "volume-constrained smoothing on triangle stencils",
    free: Free::Triangle,
    volume: true,
};

impl Smoother for StencilMethod {
    fn name(&self) -> &'static str {
        self.name
    }
    fn help(&self) -> &'static str {
        self.help
    }
    fn schedule(&self, _: &Options) -> Schedule {
        Schedule::Stencils(Footprint::Edge)
    }
    fn keeps_volume(&self) -> bool {
        self.volume
    }
    fn stop_rule(&self, _: &Options) -> StopRule {
        StopRule::Settle(Settle::STENCILS)
    }
    /// The volume-keeping ones also run the coarse levels of the multiresolution mode.
    fn accepts(&self, control: Control) -> bool {
        match control {
            Control::SmoothBoundary | Control::RejectEnergyIncrease => true,
            Control::MultiresCoarse => self.volume,
            _ => false,
        }
    }
    fn stencil_volume(&self) -> bool {
        self.volume
    }
    /// The patch's neighbour sums rebuilt ([`super::rebuild_patch_sums`]) in `sums`, or in the
    /// patch alone ([`PatchField::rebuild_sums`]) when the run keeps no such array (out of
    /// core), then [`StencilMethod::sweep_with`]: the same bits either way.
    fn sweep_patch(
        &self,
        mesh: PatchMesh,
        _: &Options,
        vertices: Range<u32>,
        triangles: Range<u32>,
        pos: &mut SharedField,
        sums: &mut SharedField,
        params: StencilParams,
        loops: Option<&Loops>,
        measure: Option<SeamPart>,
    ) -> PatchSweep {
        let copy: Option<Vec<DVec3>> =
            measure.map(|_| vertices.clone().map(|v| pos.get(v)).collect());
        let stencils = match sums.is_empty() {
            true => {
                let mut own = PatchField::rebuild_sums(mesh.topo, &*pos, vertices.clone());
                self.sweep_with(
                    mesh,
                    vertices.clone(),
                    triangles,
                    pos,
                    &mut own,
                    params,
                    loops,
                )
            }
            false => {
                super::rebuild_patch_sums(mesh.topo, &*pos, &mut *sums, vertices.clone());
                self.sweep_with(mesh, vertices.clone(), triangles, pos, sums, params, loops)
            }
        };
        PatchSweep {
            stencils,
            moved: measure
                .zip(copy)
                .map(|(seam, copy)| seam.moves(&*pos, vertices, &copy)),
        }
    }
    /// An edge or a triangle stencil moves its other ends in later patches.
    fn moves(&self) -> Moves {
        Moves::Seam
    }
}

impl StencilMethod {
    /// The stencils of the patch of `vertices` and `triangles` with the neighbour sums `sums`.
    /// Edge stencils: [`sweep_edge_stencils`]. Triangle stencils: the patch's triangles in the
    /// plan's order, then (with `loops`) its boundary edges, ascending.
    #[allow(clippy::too_many_arguments)]
    fn sweep_with<P: Field + ?Sized, S: Field + ?Sized>(
        &self,
        mesh: PatchMesh,
        vertices: Range<u32>,
        triangles: Range<u32>,
        pos: &mut P,
        sums: &mut S,
        params: StencilParams,
        loops: Option<&Loops>,
    ) -> SweepStats {
        let (topo, tris) = (mesh.topo, mesh.tris);
        match self.free {
            Free::Edge => sweep_edge_stencils(mesh, vertices, pos, sums, params, loops),
            Free::Triangle => {
                let mut st = stencil::sweep_triangles(topo, tris, pos, sums, triangles, params);
                if let Some(loops) = loops {
                    let edges = topo.edges_from(vertices);
                    st.add(&boundary::sweep_edges(
                        topo, tris, pos, sums, edges, params, loops, false,
                    ));
                }
                st
            }
        }
    }
}

/// Taubin's λ|μ displacement, the volume restored exactly block by block ([`lowpass`]): keeps
/// the volume as `vcs` does and the detail as `taubin` does (docs/quality-research.md). The
/// default method.
pub struct VcsLowpass;

impl Smoother for VcsLowpass {
    fn name(&self) -> &'static str {
        "vcs-lowpass"
    }
    fn help(&self) -> &'static str {
        "Taubin's λ|μ displacement, volume restored exactly on blocks of 4096+ vertices"
    }
    fn schedule(&self, _: &Options) -> Schedule {
        Schedule::Stencils(Footprint::Edge)
    }
    fn keeps_volume(&self) -> bool {
        true
    }
    fn needs(&self) -> Needs {
        Needs {
            shares: true,
            border: true,
            ..Needs::default()
        }
    }
    fn stop_rule(&self, opts: &Options) -> StopRule {
        StopRule::Filter(vec![opts.lambda, opts.mu()])
    }
    fn accepts(&self, control: Control) -> bool {
        matches!(
            control,
            Control::Lambda | Control::Mu | Control::SmoothBoundary
        )
    }
    /// Closer to −λ than Taubin's: the filter inflates mid frequencies less (its gain at small
    /// k is `1 − (λ + μ) k`), and the blocks restore what it shrinks (docs/quality-research.md).
    fn default_mu(&self) -> f64 {
        -0.52
    }
    /// The λ step of step 1's pair from `pos` into `sums`, exchanged; each block takes the μ step
    /// from it for its own vertices ([`lowpass::sweep_blocks`]). Every entry depends only on
    /// `pos`, so any split gives the same bits. With [`PatchMesh::border`], only the border's
    /// (the patches take the others' themselves: [`Smoother::sweep_patch`]).
    fn prepare(
        &self,
        mesh: PatchMesh,
        opts: &Options,
        exec: &mut dyn Exec,
        pos: &[DVec3],
        sums: &mut [DVec3],
        _: &mut [DVec3],
        _: &[u8],
        _: FaceFields,
    ) {
        let (topo, lambda) = (mesh.topo, opts.lambda);
        match mesh.border {
            None => exec.vertex_pass(sums, &|first, out| {
                laplacian::jacobi_step(topo, pos, out, first, lambda);
            }),
            // Only a single process keeps the border alone (the cluster's ranks exchange the
            // whole array through `exec`), so nothing is exchanged here.
            Some(border) => lowpass::border_step(topo, pos, border, sums, lambda),
        }
    }
    /// The blocks of the patch's vertices, ascending; its boundary stencils run after
    /// ([`Smoother::boundary_pass`]).
    fn sweep_patch(
        &self,
        mesh: PatchMesh,
        opts: &Options,
        vertices: Range<u32>,
        _: Range<u32>,
        pos: &mut SharedField,
        sums: &mut SharedField,
        params: StencilParams,
        _: Option<&Loops>,
        measure: Option<SeamPart>,
    ) -> PatchSweep {
        let (deviation, mu) = (params.deviation, opts.mu());
        let measure = measure.is_some();
        match mesh.border {
            None => lowpass::sweep_blocks(mesh, pos, sums, mu, vertices, deviation, measure),
            Some(border) => {
                let step = lowpass::patch_step(
                    mesh.topo,
                    &*pos,
                    border,
                    sums,
                    vertices.clone(),
                    opts.lambda,
                );
                lowpass::sweep_blocks(mesh, pos, &step, mu, vertices, deviation, measure)
            }
        }
    }
    fn boundary_pass(&self) -> bool {
        true
    }
    /// A vertex is moved by its own block alone, once per sweep.
    fn moves(&self) -> Moves {
        Moves::Own
    }
}

/// Guided normal filtering, the vertices fitted to the filtered normals, and that displacement
/// spread over 2-ring stencils, each restoring its faces' volume exactly ([`guided`],
/// [`rings`]): keeps sharp edges and the volume.
pub struct VcsGuided;

impl Smoother for VcsGuided {
    fn name(&self) -> &'static str {
        "vcs-guided"
    }
    fn help(&self) -> &'static str {
        "feature-preserving: guided normal filtering, volume restored exactly on 2-ring stencils"
    }
    fn schedule(&self, _: &Options) -> Schedule {
        Schedule::Stencils(Footprint::Ring)
    }
    fn keeps_volume(&self) -> bool {
        true
    }
    fn needs(&self) -> Needs {
        Needs {
            counts: true,
            shares: true,
            face_vectors: guided::FACE_VECTORS,
            face_scalars: guided::FACE_SCALARS,
            ..Needs::default()
        }
    }
    fn stop_rule(&self, _: &Options) -> StopRule {
        StopRule::Settle(Settle::SLOW)
    }
    fn accepts(&self, control: Control) -> bool {
        matches!(control, Control::SmoothBoundary)
    }
    /// The stencil sizes, which depend on the topology alone.
    fn start(&self, topo: &Topology, exec: &mut dyn Exec, counts: &mut [u8]) {
        exec.vertex_pass_u8(counts, &|first, out| rings::counts_into(topo, out, first));
    }
    /// Steps 1–3 of [`guided`] into `spare` (the vertex steps alternate between `spare` and
    /// `sums`, ending in `spare`), then the shares of that displacement into `sums`
    /// ([`rings::shares_into`]). Every pass is a Jacobi pass, so any split gives the same bits.
    fn prepare(
        &self,
        mesh: PatchMesh,
        _: &Options,
        exec: &mut dyn Exec,
        pos: &[DVec3],
        sums: &mut [DVec3],
        spare: &mut [DVec3],
        counts: &[u8],
        faces: FaceFields,
    ) {
        let (topo, tris) = (mesh.topo, mesh.tris);
        let parts = topo.parts();
        let parts = &parts;
        let iterations = guided::NORMAL_ITERATIONS;
        let filtered = guided::filter_normals(
            exec,
            parts,
            tris,
            pos,
            faces.vectors,
            faces.scalars,
            iterations,
            guided::NO_CUT,
        );
        exec.vertex_pass(spare, &|first, out| {
            guided::fit_into(parts, tris, filtered, pos, out, first)
        });
        const _: () = assert!(guided::VERTEX_ITERATIONS % 2 == 1);
        for _ in 0..guided::VERTEX_ITERATIONS / 2 {
            let from: &[DVec3] = spare;
            exec.vertex_pass(sums, &|first, out| {
                guided::fit_into(parts, tris, filtered, from, out, first)
            });
            let from: &[DVec3] = sums;
            exec.vertex_pass(spare, &|first, out| {
                guided::fit_into(parts, tris, filtered, from, out, first)
            });
        }
        let fitted: &[DVec3] = spare;
        exec.vertex_pass(sums, &|first, out| {
            let counts = &counts[first..first + out.len()];
            rings::shares_into(topo, pos, fitted, counts, out, first)
        });
    }
    fn sweep_patch(
        &self,
        mesh: PatchMesh,
        _: &Options,
        vertices: Range<u32>,
        _: Range<u32>,
        pos: &mut SharedField,
        sums: &mut SharedField,
        params: StencilParams,
        _: Option<&Loops>,
        _: Option<SeamPart>,
    ) -> PatchSweep {
        rings::sweep_rings(mesh.topo, mesh.tris, pos, sums, vertices, params.deviation).into()
    }
    fn boundary_pass(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::partition;
    use crate::smooth::neighbor_sums;

    /// Each patch of a stencil method rebuilds every neighbour sum its stencils read: started
    /// from sums that are NaN everywhere, a sweep of the patches one by one gives the bits of one
    /// started from the exact sums, and so does one whose sums each patch holds alone. A sum
    /// read but not rebuilt would spread its NaN. On a noisy open sphere (its border loop
    /// smoothed too, whose interior stencils read sums as well), small patches, so that most
    /// stencils reach outside their patch.
    #[test]
    fn a_patch_reads_only_the_sums_it_rebuilds() {
        let (pos, tris) = crate::shapes::open_sorted_sphere(4, 5);
        let topo = Topology::build(pos.len(), &tris).unwrap();
        let patches = partition::patches(pos.len(), &tris, 97);
        let mut loops = Loops::find(&topo, &tris);
        loops.measure(&pos);
        let mesh = PatchMesh {
            topo: &topo,
            tris: &tris,
            sorted: true,
            border: None,
        };
        let params = StencilParams {
            volume: true,
            reject_energy_increase: false,
            deviation: None,
        };
        for unit in [&LEM, &VCS, &VCS_TRIANGLE] {
            for smooth_loops in [None, Some(&loops)] {
                let run = |start: Vec<DVec3>| {
                    let (mut p, mut s) = (pos.clone(), start);
                    // SAFETY: one thread, nothing else uses the arrays while the views live.
                    let (mut pv, mut sv) =
                        unsafe { (SharedField::new(&mut p), SharedField::new(&mut s)) };
                    let params = StencilParams {
                        volume: unit.volume,
                        ..params
                    };
                    let mut st = SweepStats::default();
                    for patch in &patches {
                        st.add(
                            &unit
                                .sweep_patch(
                                    mesh,
                                    &Options::default(),
                                    patch.vertices.clone(),
                                    patch.triangles.clone(),
                                    &mut pv,
                                    &mut sv,
                                    params,
                                    smooth_loops,
                                    None,
                                )
                                .stencils,
                        );
                    }
                    (p, st.applied)
                };
                let (exact, applied) = run(neighbor_sums(&topo, &pos));
                let (from_nan, _) = run(vec![DVec3::NAN; pos.len()]);
                assert!(applied > 0 && exact != pos, "{}", unit.name);
                assert!(from_nan.iter().all(|p| p.is_finite()), "{}", unit.name);
                assert_eq!(exact, from_nan, "{}", unit.name);
                // No array of the mesh's size (out of core): the sums held by each patch
                // ([`PatchField::rebuild_sums`], which panics on a vertex beyond its two rings),
                // the same bits.
                let (own, _) = run(Vec::new());
                assert_eq!(exact, own, "{}", unit.name);
            }
        }
    }

    /// The default method out of core keeps its λ step for the patches' border alone: a sweep of
    /// the patches one by one, each taking the step of its other vertices as it starts, gives the
    /// bits of the step of the whole mesh, with and without a deviation bound. A border vertex's
    /// step taken at its patch's start instead would read neighbours that earlier patches moved,
    /// and an inner vertex's taken when its block starts would read vertices the patch's earlier
    /// blocks moved. On noisy open spheres cut into small patches (one block each, most reaching
    /// outside their patch) and into patches of four blocks.
    #[test]
    fn the_default_method_on_the_border_alone_gives_the_bits_of_the_whole_step() {
        for (level, patch_size) in [(4, 97), (6, 4 * lowpass::BLOCK as usize)] {
            let (pos, tris) = crate::shapes::open_sorted_sphere(level, 5);
            let topo = Topology::build(pos.len(), &tris).unwrap();
            let patches = partition::patches(pos.len(), &tris, patch_size);
            let border =
                partition::patch_border(&topo, &patches, &crate::mesh::Storage::heap()).unwrap();
            assert!(!border.is_empty() && border.len() < pos.len() && border.is_sorted());
            let opts = Options {
                method: crate::smooth::Method::VcsLowpass,
                ..Options::default()
            };
            let bound = stencil::Deviation {
                input: &pos,
                limit: 0.01,
            };
            for deviation in [None, Some(bound)] {
                let params = StencilParams {
                    volume: true,
                    reject_energy_increase: false,
                    deviation,
                };
                let run = |border: Option<&[u32]>| {
                    let mut p = pos.clone();
                    // The λ step as `VcsLowpass::prepare` takes it, from the sweep's start.
                    let mut shares = match border {
                        None => {
                            let mut all = vec![DVec3::ZERO; pos.len()];
                            laplacian::jacobi_step(&topo, &p, &mut all, 0, opts.lambda);
                            all
                        }
                        Some(border) => {
                            let mut some = vec![DVec3::ZERO; border.len()];
                            lowpass::border_step(&topo, &p, border, &mut some, opts.lambda);
                            some
                        }
                    };
                    let mesh = PatchMesh {
                        topo: &topo,
                        tris: &tris,
                        sorted: true,
                        border,
                    };
                    // SAFETY: one thread, nothing else uses the arrays while the views live.
                    let (mut pv, mut sv) =
                        unsafe { (SharedField::new(&mut p), SharedField::new(&mut shares)) };
                    let mut st = SweepStats::default();
                    for patch in &patches {
                        let swept = VcsLowpass.sweep_patch(
                            mesh,
                            &opts,
                            patch.vertices.clone(),
                            patch.triangles.clone(),
                            &mut pv,
                            &mut sv,
                            params,
                            None,
                            None,
                        );
                        st.add(&swept.stencils);
                    }
                    (p, st.applied + st.deviation_limited)
                };
                let (whole, blocks) = run(None);
                let (own, own_blocks) = run(Some(&border));
                assert!(blocks > 0 && whole != pos);
                assert_eq!(blocks, own_blocks);
                assert_eq!(whole, own, "level {level}, deviation {deviation:?}");
            }
        }
    }
}
