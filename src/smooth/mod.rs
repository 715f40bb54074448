//! Pure smoothing kernels and the methods made of them. No I/O, no threads: each kernel works on
//! a [`Topology`] and position slices, so the same kernel smooths a whole mesh or one patch (with
//! local ids and halo).
//!
//! A method is one unit: a type implementing [`Smoother`] (see [`method`]), listed once in the
//! registry below ([`Method`], [`Method::unit`]). Everything else (the engine, the cluster, the
//! command line, Python) asks the unit what it needs and never names a method.
//!
//! | method | what | reference |
//! |---|---|---|
//! | `laplacian` | umbrella Laplacian, forward Euler `p += λ L(p)`, Jacobi | Liu et al. 2002, eq. 3–6 |
//! | `taubin` | a λ step then a μ step per iteration | Taubin 1995 |
//! | `lem` | local energy minimisation on edge stencils | Liu et al. §2.3, eq. 7–9 |
//! | `vcs` | edge stencils + 2-step volume restoration | Liu et al. §3, §3.1 |
//! | `vcs-triangle` | the same on triangle stencils | Liu et al. §3.2 |
//! | `vcs-lowpass` | Taubin's λ\|μ displacement + exact volume restoration on 2-ring stencils | [`lowpass`], docs/quality-research.md |
//! | `vcs-guided` | guided normal filtering and a fit to the filtered normals + exact volume restoration on 2-ring stencils: keeps sharp edges | [`guided`], Zhang et al. 2015, Sun et al. 2007 |
//! | `hc` | an umbrella average pushed back towards the input, two Jacobi passes | [`hc`], Vollmer et al. 1999 |
//!
//! Umbrella operator: `L(v) = (1/deg v) Σ_{u∈N(v)} p_u − p_v`. Fixed vertices (see
//! [`crate::topology`]) never move; a stencil with a fixed free vertex is skipped and counted.

use std::fmt;
use std::marker::PhantomData;
use std::ops::Range;
use std::str::FromStr;

use glam::DVec3;

pub mod boundary;
pub mod guided;
pub mod hc;
pub mod laplacian;
pub mod lowpass;
pub mod method;
mod methods;
pub mod noise;
pub mod rings;
pub mod stencil;
pub mod tiled;

pub use crate::topology::Topology;
pub use method::{Control, Smoother};

/// A smoothing method, selectable by name: the registry of the methods' units ([`Method::unit`]).
/// `Method::ALL` lists them in documentation order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    Laplacian,
    Taubin,
    Lem,
    Vcs,
    VcsTriangle,
    /// The default: it keeps the volume as `vcs` does and the detail as `taubin` does
    /// (docs/quality-research.md).
    #[default]
    VcsLowpass,
    /// Feature-preserving: keeps a machined part's edges and the volume.
    VcsGuided,
    Hc,
}

impl Method {
    /// Every method, in documentation order.
    pub const ALL: [Method; 8] = [
        Method::Laplacian,
        Method::Taubin,
        Method::Lem,
        Method::Vcs,
        Method::VcsTriangle,
        Method::VcsLowpass,
        Method::VcsGuided,
        Method::Hc,
    ];

    /// The method for a part with sharp edges (machined, CAD), which a run left to the default
    /// names in its summary.
    pub const SHARP_EDGES: Method = Method::VcsGuided;
    /// The coarse levels' method of the multiresolution mode when none is named.
    pub const MULTIRES_COARSE: Method = Method::Vcs;
    /// The input level's method of the multiresolution mode when none is named: the cheapest
    /// Jacobi filter.
    pub const MULTIRES_FINE: Method = Method::Laplacian;
    /// `refine`'s method between its rounds: the paper's refinement figures smooth with vcs (Fig. 5).
    pub const REFINE: Method = Method::Vcs;
    /// `curves`' methods when none are named: the paper's Fig. 4.
    pub const CURVES: [Method; 3] = [Method::Vcs, Method::Lem, Method::Laplacian];
    /// `bench`'s methods when none are named: the two Jacobi filters and the paper's method.
    pub const BENCH: [Method; 3] = [Method::Laplacian, Method::Taubin, Method::Vcs];

    /// The method's unit: everything the engine, the command line and Python need of it.
    pub fn unit(self) -> &'static dyn Smoother {
        match self {
            Method::Laplacian => &methods::Laplacian,
            Method::Taubin => &methods::Taubin,
            Method::Lem => &methods::LEM,
            Method::Vcs => &methods::VCS,
            Method::VcsTriangle => &methods::VCS_TRIANGLE,
            Method::VcsLowpass => &methods::VcsLowpass,
            Method::VcsGuided => &methods::VcsGuided,
            Method::Hc => &hc::Hc,
        }
    }

    /// The method's command-line name.
    pub fn name(self) -> &'static str {
        self.unit().name()
    }

    /// Vertex-wise Jacobi steps over all vertices, no stencils.
    pub fn is_jacobi(self) -> bool {
        self.unit().schedule(&Options::default()).is_jacobi()
    }

    /// Whether the method works stencil by stencil (Gauss–Seidel) rather than vertex-wise (Jacobi).
    pub fn is_stencil(self) -> bool {
        !self.is_jacobi()
    }

    /// Every stencil restores its local volume exactly.
    pub fn keeps_volume(self) -> bool {
        self.unit().keeps_volume()
    }

    /// The methods that accept `control`, in documentation order.
    pub fn accepting(control: Control) -> impl Iterator<Item = Method> {
        Method::ALL
            .into_iter()
            .filter(move |m| m.unit().accepts(control))
    }

    /// [`Method::accepting`] as a list in prose ending in `conjunction`: "a, b and c", "a or b".
    pub fn names_accepting(control: Control, conjunction: &str) -> String {
        let names: Vec<&str> = Method::accepting(control).map(Method::name).collect();
        match names.split_last() {
            None => String::new(),
            Some((last, [])) => last.to_string(),
            Some((last, rest)) => format!("{} {conjunction} {last}", rest.join(", ")),
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl serde::Serialize for Method {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = Method::ALL.iter().map(|m| m.name()).collect();
                format!(
                    "unknown method '{s}' (expected one of: {})",
                    names.join(", ")
                )
            })
    }
}

/// What to smooth with: the method and its parameters. These define the result (with the plan's
/// layout, see [`crate::engine::Layout`]); how the work is run (threads, memory, statistics) is
/// [`crate::engine::EngineSettings`].
///
/// | field | default | used by |
/// |---|---|---|
/// | `method` | [`Method::VcsLowpass`] | — |
/// | `iterations` | 10 | every method; with `auto_stop`, the cap |
/// | `auto_stop` | false | every method: stop when the noise is gone (see [`crate::engine::auto`]) |
/// | `lambda` | 0.5 | `laplacian` (its step), `taubin` and `vcs-lowpass` (their first step) |
/// | `mu` | the method's: −0.53 for `taubin`, −0.52 for `vcs-lowpass` | `taubin` and `vcs-lowpass` (their second step; negative, `|μ| > λ`) |
/// | `reject_energy_increase` | false | `lem`, `vcs`, `vcs-triangle` |
/// | `crease_angle` | none | every method: edges whose faces' normals differ by more than this many degrees (on a denoised copy of the input, along lines as sharp on the input) are creases; corners are fixed, crease line vertices smoothed along their lines (see the field) |
/// | `max_deviation` | none | every method: no vertex ends farther than this from its input position (see below) |
/// | `weld`, `weld_tolerance` | true, 0 | every method: vertices at one position (or, with a tolerance, closer than it) are smoothed as one |
///
/// The stencil methods (`lem`, `vcs`, `vcs-triangle`) have no step size: each stencil is moved to
/// its local energy minimum (and, for `vcs`, translated back to its volume).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Options {
    pub method: Method,
    /// Iterations; each applies every eligible stencil (or every vertex update) once. With
    /// `auto_stop`, the most that may run (the command line's `--iterations auto` caps at
    /// [`crate::engine::auto::DEFAULT_CAP`]).
    pub iterations: usize,
    /// Stop early, after the iteration at which the noise is gone by the rule of
    /// [`crate::engine::auto`] (data-driven, from the input alone); the report says how many
    /// ran and why they stopped. In the multiresolution mode the input level stops so.
    /// Absent from JSON when false, so that the reports and batch settings keys of runs without
    /// it do not depend on it.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub auto_stop: bool,
    /// Laplacian step size λ (`laplacian`, and the first step of `taubin`).
    pub lambda: f64,
    /// Taubin's second step size μ (negative); `None`: the method's own
    /// ([`Smoother::default_mu`](method::Smoother::default_mu)), read through [`Options::mu`].
    pub mu: Option<f64>,
    /// Skip a stencil whose 2-step result has a higher stencil energy than before (§3.1).
    pub reject_energy_increase: bool,
    /// Crease angle in degrees, in (0, 180): an edge of two triangles whose normals differ by
    /// more than this on a denoised copy of the input (a guided filter of its face normals and
    /// the positions fitted to them, so that noise makes no creases; see `Plan::crease`), on a
    /// line as sharp on the input, is a crease. Corners (three
    /// or more crease edges) are fixed; a vertex on a crease line (two crease edges going on
    /// nearly straight, see [`Topology::line_neighbors`]) is smoothed along its line by
    /// `laplacian`, `taubin` and `vcs-lowpass` (the umbrella of its two crease neighbours),
    /// moved as any vertex by `vcs-guided` (whose fit to the filtered normals keeps edges),
    /// and fixed by `hc`, `lem`, `vcs` and `vcs-triangle`. `None`: no creases.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub crease_angle: Option<f64>,
    /// Largest distance, in model units (> 0, finite), a vertex may end from its input position.
    /// The stencil methods skip a stencil that would move a free vertex farther, `vcs-lowpass`
    /// holds such vertices of a block back and restores the block's volume with the others (their volume stays exact; counted in [`SweepStats::deviation_limited`]); `laplacian` and `taubin`
    /// clamp each vertex to the ball of this radius around its input position, which does not
    /// keep the volume (they never did). `None`: no bound.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_deviation: Option<f64>,
    /// What happens to the boundary loops of an open mesh (see [`Boundary`]).
    #[serde(skip_serializing_if = "Boundary::is_fixed")]
    pub boundary: Boundary,
    /// Vertices at exactly one position are one vertex to smooth: a texture seam's or an
    /// unmerged STL's copies move together instead of being boundary that never moves (see
    /// [`crate::partition`]); the file keeps its vertices. In JSON only when off.
    #[serde(skip_serializing_if = "is_true")]
    pub weld: bool,
    /// With `weld`, also weld vertices closer than this (a seam whose copies an exporter rounded
    /// apart; see [`crate::partition::Weld::Within`]). 0: exactly equal positions only. In JSON
    /// only when above 0.
    #[serde(skip_serializing_if = "is_no_tolerance")]
    pub weld_tolerance: f64,
}

fn is_no_tolerance(x: &f64) -> bool {
    *x == 0.0
}

fn is_true(b: &bool) -> bool {
    *b
}

/// What happens to the boundary loops of an open mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Boundary {
    /// Boundary vertices never move.
    #[default]
    Fixed,
    /// `lem`, `vcs`, `vcs-triangle` and `vcs-lowpass` smooth every boundary loop with boundary
    /// stencils ([`boundary`]): all but `lem` keep each loop's vector area along its normal (so
    /// each hole keeps its size); `lem`, which keeps no volume, keeps no area either. Interior
    /// stencils treat boundary vertices as fixed.
    Smooth,
}

impl Boundary {
    /// Both, in documentation order.
    pub const ALL: [Boundary; 2] = [Boundary::Fixed, Boundary::Smooth];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Boundary::Fixed => "fixed",
            Boundary::Smooth => "smooth",
        }
    }

    /// Whether boundary vertices stay where they are (the default).
    pub fn is_fixed(&self) -> bool {
        *self == Boundary::Fixed
    }
}

impl FromStr for Boundary {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Boundary::ALL
            .into_iter()
            .find(|b| b.name() == s)
            .ok_or_else(|| format!("unknown boundary mode '{s}' (expected fixed or smooth)"))
    }
}

impl Options {
    /// Taubin's second step size: the one asked for, or the method's own.
    pub fn mu(&self) -> f64 {
        self.mu.unwrap_or_else(|| self.method.unit().default_mu())
    }

    /// The same options with every default the method decides written out (`mu`), as a report
    /// shows them.
    pub fn resolved(self) -> Options {
        Options {
            mu: Some(self.mu()),
            ..self
        }
    }

    /// Whether a run keeps the input positions beside the working ones: for a deviation bound,
    /// or because the method reads them ([`method::Needs::input`]).
    pub fn keeps_input(&self) -> bool {
        self.max_deviation.is_some() || self.method.unit().needs().input
    }

    /// Which vertices are welded into one to smooth (`weld`, `weld_tolerance`).
    pub fn welding(&self) -> crate::partition::Weld {
        use crate::partition::Weld;
        match (self.weld, self.weld_tolerance) {
            (false, _) => Weld::Off,
            (true, d) if d > 0.0 => Weld::Within(d),
            (true, _) => Weld::Exact,
        }
    }

    /// Check the options: the step sizes in their ranges (see [`check_step`]).
    pub fn check(&self) -> crate::Result<()> {
        check_step("lambda", self.lambda)?;
        check_step("mu", self.mu())?;
        if let Some(a) = self.crease_angle {
            if !(a > 0.0 && a < 180.0) {
                return Err(crate::Error::parameter(
                    "crease_angle",
                    format!("must be in (0, 180) degrees, got {a}"),
                ));
            }
        }
        if self.boundary == Boundary::Smooth && !self.method.unit().accepts(Control::SmoothBoundary)
        {
            return Err(crate::Error::parameter(
                "boundary",
                format!(
                    "smooth works with {}, not {}",
                    Method::names_accepting(Control::SmoothBoundary, "and"),
                    self.method
                ),
            ));
        }
        let d = self.weld_tolerance;
        if !(d >= 0.0 && d.is_finite()) {
            return Err(crate::Error::parameter(
                "weld_tolerance",
                format!("must be a finite number of at least 0, got {d}"),
            ));
        }
        if d > 0.0 && !self.weld {
            return Err(crate::Error::parameter(
                "weld_tolerance",
                "welds vertices, which weld off does not: give one of them",
            ));
        }
        if let Some(d) = self.max_deviation {
            if !(d > 0.0 && d.is_finite()) {
                return Err(crate::Error::parameter(
                    "max_deviation",
                    format!("must be a finite number above 0, got {d}"),
                ));
            }
        }
        Ok(())
    }
}

/// Check one step size by its name: `lambda` in (0, 1], `mu` in [−1, 0), both finite.
///
/// Why these ranges: the umbrella Laplacian's eigenvalues lie in [−2, 0], so the step
/// `p += λ L(p)` damps every frequency only for 0 < λ ≤ 1 (a larger λ overshoots and a run
/// diverges; λ ≤ 0 does nothing or sharpens). Taubin's second step is the inflating one: μ < 0,
/// and, as λ, at most 1 in size.
pub fn check_step(name: &'static str, x: f64) -> crate::Result<()> {
    let (ok, range) = match name {
        "mu" => (
            (-1.0..0.0).contains(&x),
            "[-1, 0) (Taubin's inflating step is negative)",
        ),
        _ => (
            x > 0.0 && x <= 1.0,
            "(0, 1] (a larger Laplacian step overshoots)",
        ),
    };
    if !x.is_finite() {
        return Err(crate::Error::parameter(
            name,
            format!("must be a finite number, got {x}"),
        ));
    }
    if !ok {
        return Err(crate::Error::parameter(
            name,
            format!("must be in {range}, got {x}"),
        ));
    }
    Ok(())
}

impl Default for Options {
    fn default() -> Self {
        Options {
            method: Method::default(),
            iterations: 10,
            auto_stop: false,
            lambda: 0.5,
            mu: None,
            reject_energy_increase: false,
            crease_angle: None,
            max_deviation: None,
            boundary: Boundary::Fixed,
            weld: true,
            weld_tolerance: 0.0,
        }
    }
}

/// What one sweep did, per stencil or vertex.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct SweepStats {
    /// Stencils (or vertices, for Jacobi methods) whose result was written.
    pub applied: u64,
    /// Stencils with a fixed (boundary or non-manifold) free vertex.
    pub skipped_fixed: u64,
    /// Stencils whose normal matrix or volume gradient was too small to solve, or whose result was
    /// not finite or would have moved a vertex farther than a few times the stencil's size.
    pub skipped_degenerate: u64,
    /// Stencils rejected because their energy would have increased.
    pub rejected: u64,
    /// Stencils skipped because they would have moved a free vertex farther than the options'
    /// `max_deviation` from its input position.
    #[serde(default)]
    pub deviation_limited: u64,
    /// Boundary stencils (`boundary: smooth`) among `applied`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub boundary_applied: u64,
    /// Boundary stencils among the skipped and rejected ones.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub boundary_skipped: u64,
}

fn is_zero(x: &u64) -> bool {
    *x == 0
}

impl SweepStats {
    /// Add another sweep's counts to these.
    pub fn add(&mut self, o: &SweepStats) {
        self.applied += o.applied;
        self.skipped_fixed += o.skipped_fixed;
        self.skipped_degenerate += o.skipped_degenerate;
        self.rejected += o.rejected;
        self.deviation_limited += o.deviation_limited;
        self.boundary_applied += o.boundary_applied;
        self.boundary_skipped += o.boundary_skipped;
    }

    /// Stencils considered: applied + skipped + rejected.
    pub fn considered(&self) -> u64 {
        self.applied
            + self.skipped_fixed
            + self.skipped_degenerate
            + self.rejected
            + self.deviation_limited
    }
}

/// Per-vertex vector storage as the stencil kernels see it: a plain slice for one thread, or a
/// shared view ([`SharedField`]) when patches of one colour run in parallel.
pub trait Field {
    /// The value at vertex `v`.
    fn get(&self, v: u32) -> DVec3;
    /// Add `d` to the value at vertex `v`.
    fn add(&mut self, v: u32, d: DVec3);
    /// Set the value at vertex `v`.
    fn set(&mut self, v: u32, value: DVec3);
}

impl Field for [DVec3] {
    #[inline]
    fn get(&self, v: u32) -> DVec3 {
        self[v as usize]
    }
    #[inline]
    fn add(&mut self, v: u32, d: DVec3) {
        self[v as usize] += d;
    }
    #[inline]
    fn set(&mut self, v: u32, value: DVec3) {
        self[v as usize] = value;
    }
}

/// A per-vertex array shared by the threads that run the patches of one colour.
///
/// Each thread gets its own copy and accesses the array through raw pointers; soundness rests on
/// the schedule: no element is touched by two threads when one of them writes.
#[derive(Clone, Copy)]
pub struct SharedField<'a> {
    ptr: *mut DVec3,
    len: usize,
    _borrow: PhantomData<&'a mut [DVec3]>,
}

// SAFETY: access is through `Field` only, whose users (see `SharedField::new`) guarantee that
// threads touch disjoint elements.
unsafe impl Send for SharedField<'_> {}
unsafe impl Sync for SharedField<'_> {}

impl<'a> SharedField<'a> {
    /// Whether the view holds no element (a field the run does not keep).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Share `data` between threads.
    ///
    /// # Safety
    /// While any copy of the view is in use from several threads, no element may be accessed by
    /// two threads where one of them writes (the colouring of [`crate::schedule`] guarantees this for
    /// the stencils of the patches of one colour), and `data` is not used except through the view.
    /// Every vertex passed to `get`/`add` must be below `data.len()`: the kernels take vertices
    /// from a [`Topology`] of `data.len()` vertices, whose build rejects out-of-range indices.
    pub unsafe fn new(data: &'a mut [DVec3]) -> Self {
        SharedField {
            ptr: data.as_mut_ptr(),
            len: data.len(),
            _borrow: PhantomData,
        }
    }
}

impl Field for SharedField<'_> {
    #[inline]
    fn get(&self, v: u32) -> DVec3 {
        debug_assert!((v as usize) < self.len, "vertex {v} out of range");
        // SAFETY: in bounds and no concurrent writer, by the contract of `new`.
        unsafe { self.ptr.add(v as usize).read() }
    }
    #[inline]
    fn add(&mut self, v: u32, d: DVec3) {
        debug_assert!((v as usize) < self.len, "vertex {v} out of range");
        // SAFETY: in bounds, and this thread is the only one touching element v (contract of `new`).
        unsafe {
            let p = self.ptr.add(v as usize);
            p.write(p.read() + d);
        }
    }
    #[inline]
    fn set(&mut self, v: u32, value: DVec3) {
        debug_assert!((v as usize) < self.len, "vertex {v} out of range");
        // SAFETY: as for `add`.
        unsafe { self.ptr.add(v as usize).write(value) }
    }
}

/// `1/d` for the degrees of nearly every vertex, so that the kernels load it instead of dividing
/// (and every degree a byte can hold, for the local rows of [`crate::smooth::tiled`]).
pub(crate) static INV_DEGREE: [f64; 256] = {
    let mut t = [0.0; 256];
    let mut d = 1;
    while d < 256 {
        t[d] = 1.0 / d as f64;
        d += 1;
    }
    t
};

/// `1/d` (0 for d = 0). The table holds the correctly rounded quotient, the same value a division
/// gives, so results do not depend on which path a degree takes.
#[inline]
pub(crate) fn inv_deg(d: usize) -> f64 {
    match INV_DEGREE.get(d) {
        Some(&x) => x,
        None => 1.0 / d as f64,
    }
}

/// Sum of neighbour positions per vertex, `S(v) = Σ_{u∈N(v)} p_u`: the cache that makes an umbrella
/// Laplacian `S(v)/deg(v) − p_v` cost O(1) inside the stencil kernels.
pub fn neighbor_sums(topo: &Topology, pos: &[DVec3]) -> Vec<DVec3> {
    let mut sums = vec![DVec3::ZERO; topo.len()];
    neighbor_sums_into(topo, pos, &mut sums, 0);
    sums
}

/// [`neighbor_sums`] for the vertices `first .. first + out.len()`, into `out`.
pub fn neighbor_sums_into(topo: &Topology, pos: &[DVec3], out: &mut [DVec3], first: usize) {
    for (k, s) in out.iter_mut().enumerate() {
        *s = neighbor_sum(topo, pos, (first + k) as u32);
    }
}

/// The neighbour sums that the stencils of the patch owning `vertices` read, taken afresh from
/// `pos` when the patch starts: those of its vertices and of the two rings around them (a
/// stencil's free vertices lie within one ring of the patch, their neighbours within two). What
/// the stencils then write into `sums` keeps them up to date within the patch; no sum is read by
/// another patch before it rebuilds its own, so the sums need not outlive a patch (the schedule's
/// colouring keeps this apart from the other patches of a colour: [`crate::schedule`]).
pub fn rebuild_patch_sums<P: Field + ?Sized, S: Field + ?Sized>(
    topo: &Topology,
    pos: &P,
    sums: &mut S,
    vertices: Range<u32>,
) {
    for v in vertices.clone().chain(two_rings(topo, &vertices)) {
        sums.set(v, neighbor_sum(topo, pos, v));
    }
}

/// The vertices outside `vertices` within two rings of them, ascending.
fn two_rings(topo: &Topology, vertices: &Range<u32>) -> Vec<u32> {
    let mut rings = crate::topology::rings_outside(topo, vertices, 2).concat();
    rings.sort_unstable();
    rings
}

/// The neighbours of the vertices `of` outside the patch of `vertices`, ascending, each once.
pub(crate) fn neighbors_outside(
    topo: &Topology,
    of: impl IntoIterator<Item = u32>,
    vertices: &Range<u32>,
) -> Vec<u32> {
    let mut out: Vec<u32> = of
        .into_iter()
        .flat_map(|v| topo.neighbors(v).iter().copied())
        .filter(|u| !vertices.contains(u))
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// A field held by a patch itself while it runs: its vertices' values in one array, a few
/// rings' around them beside a sorted list of those vertices. The neighbour sums of
/// [`rebuild_patch_sums`] ([`PatchField::rebuild_sums`]) and the default method's λ step
/// ([`lowpass`]) are held so out of core, the same bits as in the array of the mesh's size,
/// which would be 12 B per triangle more of scratch to pass through the page cache. In core the
/// array is cheaper to read (no test of which part holds a vertex).
pub struct PatchField {
    first: u32,
    /// The values of the patch's vertices, from `first` on.
    inner: Vec<DVec3>,
    /// The rings around them, ascending, and their values.
    ring: Vec<u32>,
    outer: Vec<DVec3>,
}

impl PatchField {
    /// The neighbour sums of the patch of `vertices` and its two rings, from `pos`.
    pub fn rebuild_sums<P: Field + ?Sized>(
        topo: &Topology,
        pos: &P,
        vertices: Range<u32>,
    ) -> PatchField {
        let ring = two_rings(topo, &vertices);
        PatchField {
            first: vertices.start,
            inner: vertices.map(|v| neighbor_sum(topo, pos, v)).collect(),
            outer: ring.iter().map(|&v| neighbor_sum(topo, pos, v)).collect(),
            ring,
        }
    }

    /// The field of the vertices from `first` on (`inner`) and of the vertices `ring` (ascending,
    /// none of them among the first), `outer` in the same order.
    pub fn new(first: u32, inner: Vec<DVec3>, ring: Vec<u32>, outer: Vec<DVec3>) -> PatchField {
        let mine = first as usize..first as usize + inner.len();
        debug_assert!(ring.is_sorted() && ring.len() == outer.len());
        debug_assert!(ring.iter().all(|&v| !mine.contains(&(v as usize))));
        PatchField {
            first,
            inner,
            ring,
            outer,
        }
    }

    /// Where `v`'s value is held.
    #[inline]
    fn slot_mut(&mut self, v: u32) -> &mut DVec3 {
        let i = v.wrapping_sub(self.first) as usize;
        if i < self.inner.len() {
            &mut self.inner[i]
        } else {
            let k = self.ring_slot(v);
            &mut self.outer[k]
        }
    }

    /// The slot of `v`, one of the rings (kept out of the kernels' inlined code: most reads are
    /// the patch's own vertices). A vertex beyond them has none: the patch never reads it.
    #[cold]
    #[inline(never)]
    fn ring_slot(&self, v: u32) -> usize {
        self.ring
            .binary_search(&v)
            .unwrap_or_else(|_| panic!("vertex {v} is beyond the patch's rings"))
    }
}

impl Field for PatchField {
    #[inline]
    fn get(&self, v: u32) -> DVec3 {
        let i = v.wrapping_sub(self.first) as usize;
        match self.inner.get(i) {
            Some(&s) => s,
            None => self.outer[self.ring_slot(v)],
        }
    }
    #[inline]
    fn add(&mut self, v: u32, d: DVec3) {
        *self.slot_mut(v) += d;
    }
    #[inline]
    fn set(&mut self, v: u32, value: DVec3) {
        *self.slot_mut(v) = value;
    }
}

/// `Σ_{u∈N(v)} field_u`, summed in the neighbour order (every kernel's order, so their bits agree).
#[inline]
pub(crate) fn neighbor_sum<P: Field + ?Sized>(topo: &Topology, field: &P, v: u32) -> DVec3 {
    topo.neighbors(v)
        .iter()
        .fold(DVec3::ZERO, |s, &u| s + field.get(u))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_sizes_are_checked_in_their_ranges() {
        assert!(Options::default().check().is_ok());
        let with = |lambda, mu| Options {
            lambda,
            mu: Some(mu),
            ..Options::default()
        };
        assert!(with(1.0, -1.0).check().is_ok());
        for (lambda, mu, name) in [
            (0.0, -0.5, "lambda"),
            (1.5, -0.5, "lambda"),
            (f64::NEG_INFINITY, -0.5, "lambda"),
            (0.5, 0.0, "mu"),
            (0.5, -1.5, "mu"),
            (0.5, f64::NAN, "mu"),
        ] {
            match with(lambda, mu).check() {
                Err(crate::Error::Parameter { name: n, .. }) => assert_eq!(n, name),
                other => panic!("{lambda} {mu}: {other:?}"),
            }
        }
    }
}
