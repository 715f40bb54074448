//! What the engine asks of a smoothing method: the [`Smoother`] trait, which every method
//! implements once in its own type, and [`Exec`], what a method's iteration may ask of the process
//! that runs it.
//!
//! The engine, the cluster, the command line and the Python binding never name a method: they
//! take its unit from the registry ([`Method::unit`](super::Method::unit)) and ask it. A method
//! says how its iterations are scheduled ([`Schedule`]: Jacobi steps over all vertices, or
//! Gauss–Seidel stencils over a [`Footprint`] of rings, for the conflict colouring), which
//! per-vertex buffers it needs beside the positions ([`Needs`]), whether it keeps the volume,
//! its automatic-stop rule ([`StopRule`]), the controls it accepts ([`Control`]), and its name
//! and help line. Another executor of the kernels (a GPU one) would be another implementation of
//! [`Exec`] and of the engine's loop over the same trait, not a fork of either.

use std::ops::Range;

use glam::DVec3;

use super::boundary::Loops;
use super::laplacian::StepStats;
use super::stencil::StencilParams;
use super::{Field, Options, SharedField, SweepStats, Topology};

/// What the stencils of one patch did ([`Smoother::sweep_patch`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PatchSweep {
    pub stencils: SweepStats,
    /// How far the patch's vertices moved, when measured: each distance from the position before
    /// the sweep to the one written, summed in ascending vertex order.
    pub moved: Option<StepStats>,
}

impl PatchSweep {
    /// Add the sweep of a following patch (its moves summed after these).
    pub fn then(self, o: PatchSweep) -> PatchSweep {
        let mut stencils = self.stencils;
        stencils.add(&o.stencils);
        let moved = match (self.moved, o.moved) {
            (Some(a), Some(b)) => Some(a.then(b)),
            (a, b) => a.or(b),
        };
        PatchSweep { stencils, moved }
    }
}

impl From<SweepStats> for PatchSweep {
    fn from(stencils: SweepStats) -> PatchSweep {
        PatchSweep {
            stencils,
            moved: None,
        }
    }
}

/// Who measures how far a stencil method's sweep moved each vertex ([`Smoother::moves`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Moves {
    /// The loop: it copies the positions before the sweep and compares them after.
    Copied,
    /// The patches: each vertex is moved by its own patch alone, which measures its moves as it
    /// writes them.
    Own,
    /// The patches and the loop: a patch's stencils also move vertices of later patches (an
    /// edge stencil `(i, j)` and a triangle stencil belong to the patch of their smallest
    /// vertex), and the colours run patches out of their order. Each patch measures, when it
    /// ends, its vertices that no other patch moves (no neighbour in an earlier patch) against
    /// its own copy taken when it starts; the loop measures the others, the seam, after the
    /// sweep against their positions at its start.
    Seam,
}

/// What a measured patch sweep leaves out of its moves: its vertices that stencils of other
/// patches move too, ascending (for [`Moves::Seam`]; empty otherwise), which the loop measures.
#[derive(Debug, Clone, Copy, Default)]
pub struct SeamPart<'a> {
    pub seam: &'a [u32],
}

impl SeamPart<'_> {
    /// How far the vertices `vertices` but the seam's moved to `pos`, each from its entry in
    /// `copy` (the positions when the patch started, one per vertex); summed in ascending
    /// vertex order.
    pub fn moves<P: Field + ?Sized>(
        &self,
        pos: &P,
        vertices: Range<u32>,
        copy: &[DVec3],
    ) -> StepStats {
        let mut seam = self.seam.iter().peekable();
        let (mut max, mut sum) = (0.0f64, 0.0);
        for (v, &before) in vertices.zip(copy) {
            if seam.next_if(|&&s| s == v).is_some() {
                continue;
            }
            let d = pos.get(v).distance(before);
            max = max.max(d);
            sum += d;
        }
        debug_assert!(seam.next().is_none(), "the seam's vertices are the patch's");
        StepStats {
            moved: 0,
            max_displacement: max,
            sum_displacement: sum,
        }
    }
}

/// How the iterations of a method are scheduled.
#[derive(Debug, Clone, PartialEq)]
pub enum Schedule {
    /// Umbrella steps `p += f L(p)`, Jacobi (every vertex from the previous positions), one per
    /// factor per iteration: the order of work is irrelevant, and the engine may run several
    /// steps in one pass over memory (tiles).
    Umbrella(Vec<f64>),
    /// Two Jacobi passes of the method's own per iteration ([`Smoother::pass`]): the first from
    /// the positions into the auxiliary field, the second from both into the new positions.
    TwoPass,
    /// Stencils applied one after another, each seeing the latest positions, colour after colour
    /// of the plan's colouring for this footprint ([`Smoother::sweep_patch`]).
    Stencils(Footprint),
}

impl Schedule {
    /// Whether every vertex is updated from the previous positions (no colouring needed).
    pub fn is_jacobi(&self) -> bool {
        !matches!(self, Schedule::Stencils(_))
    }

    /// The colouring the plan's figures are reported for: a Jacobi method's are those of the
    /// edge stencils.
    pub fn footprint(&self) -> Footprint {
        match self {
            Schedule::Stencils(f) => *f,
            _ => Footprint::Edge,
        }
    }
}

/// How far a stencil reads and writes around its free vertices, for the conflict colouring of
/// the patches (see [`crate::schedule`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Footprint {
    /// Edge and triangle stencils: they write their free vertices and the neighbour sums of one
    /// ring, and read two rings.
    Edge,
    /// Vertex-ring stencils of radius [`super::rings::RING_RADIUS`]: wider, their own colouring.
    Ring,
}

/// The per-vertex buffers a method needs besides the positions and the engine's second buffer.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Needs {
    /// The input positions, whatever the options (a deviation bound keeps them anyway).
    pub input: bool,
    /// An auxiliary vector field ([`Schedule::TwoPass`]).
    pub aux: bool,
    /// A vector field per vertex (per border vertex with [`PatchMesh::border`]) that
    /// [`Smoother::prepare`] fills before each sweep and the stencils read
    /// ([`Schedule::Stencils`]; a Jacobi method's second buffer is there anyway).
    /// Without it, a stencil method gets the array only in core, for its neighbour sums (out of
    /// core each patch holds its own: [`super::PatchField::rebuild_sums`]).
    pub shares: bool,
    /// Whether a patch can compute the shares of its vertices whose neighbours are all its own
    /// when it starts, from the positions then (nothing has moved them yet), so that a run out of
    /// core keeps them only for the patches' borders ([`PatchMesh::border`]).
    pub border: bool,
    /// A byte per vertex, filled once per run by [`Smoother::start`].
    pub counts: bool,
    /// Vector fields per triangle ([`FaceFields::vectors`], this many times the triangle count).
    pub face_vectors: usize,
    /// Scalar fields per triangle ([`FaceFields::scalars`]).
    pub face_scalars: usize,
}

/// A method's per-triangle fields ([`Needs::face_vectors`], [`Needs::face_scalars`]), one after
/// another in the plan's triangle order; empty when it has none.
pub struct FaceFields<'a> {
    pub vectors: &'a mut [DVec3],
    pub scalars: &'a mut [f64],
}

/// What ends an automatically stopped run of the method (see [`crate::engine::auto`]).
#[derive(Debug, Clone, PartialEq)]
pub enum StopRule {
    /// A low-pass filter with a scalar analogue: these umbrella step factors per iteration, run
    /// on white noise, tell what the filter would remove from pure noise.
    Filter(Vec<f64>),
    /// The same for a low-pass filter that shrinks (`laplacian`): its gain falls from the
    /// lowest frequencies on, so every iteration also moves a curved surface inwards by about
    /// λ times its curvature, a displacement the scalar analogue does not make and which grows
    /// with every iteration. Both energies are measured on the displacement's differences along
    /// the edges, which tilt the normals, so that a shrink nearly uniform over a vertex's
    /// neighbours hardly counts as shape removed (docs/quality-research.md §17).
    ShrinkingFilter(Vec<f64>),
    /// No scalar analogue: stop when an iteration moves the vertices little, or when the
    /// iterations together removed more than the noise.
    Settle(Settle),
}

/// The thresholds of [`StopRule::Settle`], in units of the noise estimate σ̂.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settle {
    /// Stop when an iteration's mean displacement is below this many σ̂.
    pub moved: f64,
    /// Stop when the iterations together removed more than this many times the noise energy
    /// along the normals: the rest was shape.
    pub removed: f64,
}

impl Settle {
    /// The stencil methods' (`lem`, `vcs`, `vcs-triangle`): a scalar stencil minimiser removes
    /// most white noise at once, then stalls (docs/quality-research.md §5).
    pub const STENCILS: Settle = Settle {
        moved: 0.05,
        removed: 4.0 / 3.0,
    };
    /// The methods that keep improving in ever smaller steps (`hc`, which converges towards the
    /// input, and `vcs-guided`, whose normal filter keeps the edges a low-pass filter rounds):
    /// they stop at a twentieth of a stencil method's step, or when 1.15 times the noise energy
    /// is gone (docs/quality-research.md §15, chosen on the denoising pairs).
    pub const SLOW: Settle = Settle {
        moved: 0.015,
        removed: 1.15,
    };
}

/// The controls a method may or may not accept; [`Options::check`] refuses the others.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// `lambda`: a Laplacian step size.
    Lambda,
    /// `mu`: Taubin's second, inflating step size.
    Mu,
    /// `boundary: smooth`: boundary loops smoothed with boundary stencils.
    SmoothBoundary,
    /// `reject_energy_increase`: the stencils' energy test.
    RejectEnergyIncrease,
    /// The coarse levels of the multiresolution mode.
    MultiresCoarse,
    /// The fine level of the multiresolution mode.
    MultiresFine,
}

/// The mesh and the stencils of one patch, as a method's sweep sees them.
#[derive(Clone, Copy)]
pub struct PatchMesh<'a> {
    pub topo: &'a Topology,
    /// The plan's triangles (consistently oriented): the stencils' volumes read them.
    pub tris: &'a [[u32; 3]],
    /// Whether `tris` are sorted by their first corner, which is their smallest (the plan's
    /// Morton layout, not the input's own order).
    pub sorted: bool,
    /// For a method whose shares are kept only on the patches' borders ([`Needs::border`]) in
    /// a run without the array of the mesh's size (out of core): the vertices with a neighbour
    /// in another patch, ascending. [`Smoother::prepare`]'s `sums` and
    /// [`Smoother::sweep_patch`]'s then hold one entry per such vertex, in this order.
    pub border: Option<&'a [u32]>,
}

/// What the passes of a [`Schedule::TwoPass`] method read.
#[derive(Clone, Copy)]
pub struct PassFields<'a> {
    /// The positions at the iteration's start.
    pub pos: &'a [DVec3],
    /// The input positions ([`Needs::input`]).
    pub input: &'a [DVec3],
    /// The auxiliary field: as the first pass wrote it (empty in the first pass).
    pub aux: &'a [DVec3],
    /// A deviation bound: the last pass keeps every vertex within this distance of its input
    /// position.
    pub limit: Option<f64>,
}

/// What a method's iteration asks of the process that runs it: passes over the vertices it owns,
/// kept in step with the copies other processes hold (a single process owns everything).
pub trait Exec {
    /// `f(first, out)` over the owned entries of `field`, cut into fixed chunks that may run in
    /// parallel (`out` holds vertices `first ..`); then the entries other processes hold are
    /// brought up to date. Every entry must depend only on what `f` reads, never on the split.
    fn vertex_pass(&mut self, field: &mut [DVec3], f: &(dyn Fn(usize, &mut [DVec3]) + Sync));
    /// The same for a byte field only this process reads (no exchange).
    fn vertex_pass_u8(&mut self, field: &mut [u8], f: &(dyn Fn(usize, &mut [u8]) + Sync));
    /// `f(first, out)` over the owned entries of a per-triangle `field` (`out` holds triangles
    /// `first ..`), in fixed chunks that may run in parallel; then the entries other processes
    /// hold are brought up to date. Every entry must depend only on what `f` reads, and `f` may
    /// read only the entries of the triangles at the entry's corners and positions within two
    /// rings of them: a rank of the cluster engine holds no others (`crate::cluster`).
    fn face_pass(&mut self, field: &mut [DVec3], f: &(dyn Fn(usize, &mut [DVec3]) + Sync));
    /// The same for a per-triangle scalar field.
    fn face_pass_f64(&mut self, field: &mut [f64], f: &(dyn Fn(usize, &mut [f64]) + Sync));
}

/// A smoothing method: everything the engine needs of it (see the module doc). Implemented once
/// per method, in `smooth/`; listed in the registry, [`super::Method`].
pub trait Smoother: Sync {
    /// The command-line and Python name.
    fn name(&self) -> &'static str;
    /// One line for `--help` and the documentation.
    fn help(&self) -> &'static str;
    /// How its iterations are scheduled, with `opts`'s parameters.
    fn schedule(&self, opts: &Options) -> Schedule;
    /// Whether every stencil restores its local volume exactly.
    fn keeps_volume(&self) -> bool;
    /// Buffers beyond the positions and the second buffer.
    fn needs(&self) -> Needs {
        Needs::default()
    }
    /// The automatic stop's rule, with `opts`'s parameters.
    fn stop_rule(&self, opts: &Options) -> StopRule;
    /// Whether the method takes `control`.
    fn accepts(&self, control: Control) -> bool;
    /// Its second step size μ when none is asked for ([`Control::Mu`]; Taubin's own value).
    fn default_mu(&self) -> f64 {
        -0.53
    }

    /// Once per run, before the first iteration: fill the method's byte field ([`Needs::counts`]).
    fn start(&self, _topo: &Topology, _exec: &mut dyn Exec, _counts: &mut [u8]) {}

    /// [`Schedule::Stencils`]: before every sweep, what its stencils read beside the positions
    /// into `sums` (nothing by default: the neighbour sums of the stencil methods are rebuilt by
    /// each patch, [`super::rebuild_patch_sums`]); `spare` is a buffer the method may use (it is
    /// overwritten after; empty for a unit that [`Smoother::measures_moves`] when the run keeps no
    /// copy), `counts` its byte field, `faces` its per-triangle fields.
    #[allow(clippy::too_many_arguments)]
    fn prepare(
        &self,
        _mesh: PatchMesh,
        _opts: &Options,
        _exec: &mut dyn Exec,
        _pos: &[DVec3],
        _sums: &mut [DVec3],
        _spare: &mut [DVec3],
        _counts: &[u8],
        _faces: FaceFields,
    ) {
    }

    /// [`Schedule::Stencils`]: the stencils of one patch (the vertices `vertices` and triangles
    /// `triangles` it owns), in their fixed ascending order, through views that the patches of
    /// one colour share; with `loops` (`boundary: smooth`) the boundary stencils too, unless
    /// [`Smoother::boundary_pass`] says they run after. With `measure` (given only to a unit
    /// whose [`Smoother::moves`] are not [`Moves::Copied`]), also how far the patch's vertices
    /// moved.
    #[allow(clippy::too_many_arguments)]
    fn sweep_patch(
        &self,
        _mesh: PatchMesh,
        _opts: &Options,
        _vertices: Range<u32>,
        _triangles: Range<u32>,
        _pos: &mut SharedField,
        _sums: &mut SharedField,
        _params: StencilParams,
        _loops: Option<&Loops>,
        _measure: Option<SeamPart>,
    ) -> PatchSweep {
        unreachable!("{} has no stencils", self.name())
    }

    /// [`Schedule::Stencils`]: how a measured sweep's moves are measured, [`Moves`]. Unless
    /// they are [`Moves::Copied`], the loop copies no positions before a measured sweep (but with
    /// smoothed boundaries, whose pass moves loop vertices too, and with the automatic stop,
    /// whose rule reads the copy), and [`Smoother::prepare`]'s `spare` is empty.
    fn moves(&self) -> Moves {
        Moves::Copied
    }

    /// [`Schedule::Stencils`] with smoothed boundaries: whether the boundary stencils run in a
    /// pass of their own after the method's, over the edge colouring (else inside
    /// [`Smoother::sweep_patch`]).
    fn boundary_pass(&self) -> bool {
        false
    }

    /// [`Schedule::Stencils`]: whether the stencils restore their volume themselves through the
    /// shared volume step ([`StencilParams::volume`]).
    fn stencil_volume(&self) -> bool {
        false
    }

    /// [`Schedule::TwoPass`]: pass `k` (0 or 1) for the vertices `first .. first + out.len()`.
    /// Pass 0 writes the auxiliary field; pass 1 writes the new positions, fixed vertices copied
    /// unchanged, and returns how far they moved from `fields.pos` (pass 0's figures are not
    /// read). Each entry depends only on `fields`, so any split gives the same bits.
    fn pass(
        &self,
        _k: usize,
        _topo: &Topology,
        _opts: &Options,
        _fields: PassFields,
        _first: usize,
        _out: &mut [DVec3],
    ) -> StepStats {
        unreachable!("{} has no passes", self.name())
    }
}
