//! The flag groups several commands share, each with its resolution into the library's settings:
//! a command's `IN OUT`, the smoothing flags (method, iterations, step sizes) and the engine flags
//! (threads, patches, memory); and the value parsers more than one command uses.

use std::path::PathBuf;

use clap::builder::PossibleValue;
use clap::{Args as ClapArgs, ValueEnum};

use crate::engine::{EngineSettings, Statistics};
use crate::error::{Error, Result};
use crate::smooth::{Boundary, Control, Method, Options};

/// `IN OUT` of the commands that turn one mesh file into another (`smooth`, `subdivide`, `refine`).
#[derive(Debug, Clone, ClapArgs)]
pub struct InOut {
    /// Input mesh (PLY, OBJ, OFF, STL, glTF or GLB; any of them gzip-compressed).
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Output mesh; .ply, .obj, .off, .stl (each with .gz to compress), .gltf or .glb (a glTF input keeps its scene in its own kind). Written atomically, never on failure.
    #[arg(value_name = "OUT")]
    pub output: PathBuf,
}

impl InOut {
    /// What `subdivide` and `refine` check before any work: the bound `max_edge`, an output that
    /// can hold a refined mesh, and the files (see [`crate::cli::output::check_files`]).
    pub fn check_refined(&self, max_edge: f64) -> Result<()> {
        crate::modes::refine::check_max_edge(max_edge)?;
        crate::cli::output::mesh_output(&self.output)?;
        crate::cli::output::check_files(&[("IN", &self.input)], Some(("OUT", &self.output)), &[])
    }
}

/// The smoothing flags shared by `smooth`, `batch` and `slurm-script`: method, iterations, step
/// sizes, engine.
#[derive(Debug, Clone, ClapArgs)]
pub struct SmoothingArgs {
    /// Smoothing method [default: vcs-lowpass; with --multires, vcs].
    #[arg(long, value_enum)]
    pub method: Option<Method>,
    /// Number of iterations (0 only converts the file's format), or 'auto': stop when the noise is gone, after at most 100 iterations. 'auto' estimates the noise from the input (the spread of the second difference of the normal Laplacian) and stops when an iteration removes more along the normals than noise explains, or when little noise is left to remove (see the README).
    #[arg(
        long,
        value_name = "N|auto",
        default_value = "10",
        allow_negative_numbers = true,
        value_parser = iterations
    )]
    pub iterations: Iterations,
    #[command(flatten)]
    pub params: MethodParams,
    #[command(flatten)]
    pub engine: EngineArgs,
}

impl SmoothingArgs {
    /// The smoothing these flags ask for, `default` the method without `--method` (checked as
    /// [`MethodParams::options`] checks it), its defaults resolved (the report names them).
    pub fn options(&self, default: Method) -> Result<Options> {
        let method = self.method.unwrap_or(default);
        let options = match self.iterations {
            Iterations::Count(n) => self.params.options(method, n)?,
            Iterations::Auto => Options {
                auto_stop: true,
                ..self
                    .params
                    .options(method, crate::engine::auto::DEFAULT_CAP)?
            },
        };
        Ok(options.resolved())
    }
}

/// `--iterations`: a count, or `auto` (the library's `auto_stop`, capped at
/// [`crate::engine::auto::DEFAULT_CAP`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Iterations {
    Count(usize),
    Auto,
}

impl std::fmt::Display for Iterations {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Iterations::Count(n) => write!(f, "{n}"),
            Iterations::Auto => f.write_str("auto"),
        }
    }
}

/// `--iterations` (clap value parser): a whole number or `auto`.
pub fn iterations(s: &str) -> std::result::Result<Iterations, String> {
    if s.trim() == "auto" {
        return Ok(Iterations::Auto);
    }
    whole(s)
        .map(Iterations::Count)
        .map_err(|e| format!("{e}, nor 'auto'"))
}

/// Step sizes and stencil options shared by `smooth` and `curves`.
#[derive(Debug, Clone, ClapArgs)]
pub struct MethodParams {
    /// Laplacian step size λ, in (0, 1].
    #[arg(long, value_name = "X", default_value_t = 0.5, value_parser = step_lambda, allow_hyphen_values = true,
          help = used_by("Laplacian step size λ, in (0, 1]", Control::Lambda, ""))]
    pub lambda: f64,
    /// Taubin's second step size μ, in [-1, 0).
    #[arg(long, value_name = "Y", value_parser = step_mu, allow_hyphen_values = true,
          help = used_by("Taubin's second step size μ, in [-1, 0)", Control::Mu, &mu_defaults()))]
    pub mu: Option<f64>,
    /// Skip a stencil whose result has a higher stencil energy than before.
    #[arg(long, help = used_by(
        "Skip a stencil whose result has a higher stencil energy than before",
        Control::RejectEnergyIncrease,
        " [default: off]"
    ))]
    pub reject_energy_increase: bool,
    /// Creases: edges whose two faces' normals differ by more than DEG degrees, in (0, 180), on a denoised copy of the input (its face normals filtered, the positions fitted to them: noise makes no creases), along lines that are as sharp on the input; a vertex on a crease line (two crease edges, nearly straight) is smoothed along it by laplacian, taubin and vcs-lowpass, fitted by vcs-guided, and fixed by the other methods; corners (three or more) stay where they are [default: none].
    #[arg(long, value_name = "DEG", value_parser = crease_angle, allow_hyphen_values = true)]
    pub crease_angle: Option<f64>,
    /// No vertex ends farther than D (model units, > 0) from its input position.
    #[arg(long, value_name = "D", value_parser = length, allow_hyphen_values = true, help = deviation_help())]
    pub max_deviation: Option<f64>,
    /// Boundary loops of open meshes: fixed, or smooth (each loop is smoothed as a curve).
    #[arg(long, value_enum, value_name = "MODE", default_value_t = Boundary::Fixed, help = boundary_help())]
    pub boundary: Boundary,
    /// Keep vertices that share a position apart: a texture seam or unmerged STL corners stay boundary that never moves, as in results version 4 and before [default: copies are one vertex to smooth, and each takes the same new position].
    #[arg(long)]
    pub no_weld: bool,
    /// Also weld vertices closer than D (model units, > 0): the copies of a seam that an exporter rounded apart. Each vertex joins the nearest earlier one within D that is not itself joined; a chain of vertices each within D of the next is not pulled together [default: exactly equal positions only].
    #[arg(long, value_name = "D", value_parser = length, allow_hyphen_values = true, conflicts_with = "no_weld")]
    pub weld_tolerance: Option<f64>,
}

/// `--mu`'s defaults, each method's own.
fn mu_defaults() -> String {
    let each: Vec<String> = Method::accepting(Control::Mu)
        .map(|m| format!("{} for {}", m.unit().default_mu(), m.name()))
        .collect();
    format!(" [default: {}]", each.join(", "))
}

/// A flag's help line, `what`, with the methods that take `control` in parentheses, then `tail`.
fn used_by(what: &str, control: Control, tail: &str) -> String {
    format!("{what} ({}){tail}", Method::names_accepting(control, "and"))
}

/// `--max-deviation`'s help line: which methods skip stencils, which clamp vertices.
fn deviation_help() -> String {
    let names = |jacobi: bool| {
        let ms: Vec<&str> = Method::ALL
            .iter()
            .filter(|m| m.is_jacobi() == jacobi)
            .map(|m| m.name())
            .collect();
        ms.join(", ")
    };
    format!(
        "No vertex ends farther than D (model units, > 0) from its input position: the stencil methods ({}) skip a stencil that would move one farther, or hold such vertices of a block back and restore the block's volume with the others (the volume stays exact); {} clamp each vertex (they do not keep the volume) [default: none]",
        names(false),
        names(true)
    )
}

/// `--boundary`'s help line: which methods smooth the loops, and which keep the holes' sizes.
fn boundary_help() -> String {
    let smooth: Vec<Method> = Method::accepting(Control::SmoothBoundary).collect();
    let names = |ms: &[Method]| ms.iter().map(|m| m.name()).collect::<Vec<_>>().join(", ");
    let keep: Vec<Method> = smooth
        .iter()
        .copied()
        .filter(|m| m.keeps_volume())
        .collect();
    format!(
        "Boundary loops of open meshes: fixed, or smooth ({}: each loop is smoothed as a curve; {} keep each hole's size exactly)",
        names(&smooth),
        names(&keep)
    )
}

impl MethodParams {
    /// `iterations` of `method` with these parameters, checked ([`Options::check`]): every
    /// command that smooths resolves its flags through here while it parses them, so a
    /// combination no run could make (`--boundary smooth` with a method that keeps its boundary
    /// fixed) is the same usage error, the same line, before any work, whatever the command.
    pub fn options(&self, method: Method, iterations: usize) -> Result<Options> {
        let options = Options {
            method,
            iterations,
            auto_stop: false,
            lambda: self.lambda,
            mu: self.mu,
            reject_energy_increase: self.reject_energy_increase,
            crease_angle: self.crease_angle,
            max_deviation: self.max_deviation,
            boundary: self.boundary,
            weld: !self.no_weld,
            weld_tolerance: self.weld_tolerance.unwrap_or(0.0),
        };
        options.check()?;
        Ok(options)
    }
}

/// How the engine runs: threads, patches, memory.
#[derive(Debug, Clone, ClapArgs)]
pub struct EngineArgs {
    /// Worker threads, 1 to 4096 [default: all cores].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=MAX_THREADS as i64), allow_negative_numbers = true)]
    pub threads: Option<u32>,
    /// Vertices per patch; the result is identical for any thread count and memory budget for a given patch size. Each patch holds about 1 KiB of schedule in memory (up to 4 KiB for patches of a few vertices): a size whose schedule would take more than half the memory budget is refused [default: 16384].
    #[arg(long, value_name = "VERTICES", value_parser = whole_in(1, u32::MAX as u64 - 1), allow_negative_numbers = true)]
    pub patch_size: Option<u64>,
    /// Anonymous memory allowed, with K/M/G/T suffixes (binary units); larger meshes go to memory-mapped scratch files [default: 3/4 of available memory, or of a tighter cgroup limit or rlimit].
    #[arg(long, value_name = "SIZE", value_parser = crate::engine::memory::parse_size, allow_hyphen_values = true)]
    pub memory_budget: Option<u64>,
    /// Directory for scratch files (removed on exit, even on error) [default: the output's directory].
    #[arg(long, value_name = "DIR")]
    pub scratch: Option<PathBuf>,
}

impl EngineArgs {
    /// The engine settings: the budget checked, the scratch directory present.
    pub fn resolve(&self) -> Result<EngineSettings> {
        if let Some(b) = self.memory_budget {
            crate::engine::memory::check_budget(b)?;
        }
        if let Some(dir) = &self.scratch {
            if !dir.is_dir() {
                return Err(Error::invalid(
                    dir,
                    "--scratch must be an existing directory",
                ));
            }
        }
        Ok(EngineSettings {
            threads: self.threads.map(|t| t as usize),
            patch_size: self
                .patch_size
                .map_or(crate::engine::DEFAULT_PATCH_SIZE, |p| p as usize),
            memory_budget: self.memory_budget,
            scratch: self.scratch.clone(),
            with_stats: false,
            statistics: crate::engine::Statistics::Every,
            pins: crate::engine::Pins::None,
            deviation: Default::default(),
        })
    }
}

/// The deviation field's colours and the tolerance (`smooth`, `compare`; each has its own
/// `--deviation-field`).
#[derive(Debug, Clone, ClapArgs)]
pub struct DeviationArgs {
    /// Print the deviation's statistics (RMS, mean and extremes of the deviation; RMS, mean, largest and percentiles 50/90/99/99.9 of the distance; a histogram), also in the JSON; implied by --deviation-field and --tolerance [default: off].
    #[arg(long)]
    pub deviation_stats: bool,
    /// With --deviation-field, also the deviation's colour map as the PLY vertex properties 'red green blue' (OBJ: 'v x y z r g b', in 0..1; glTF: COLOR_0): blue inward, white unmoved, red outward, saturated at --tolerance (or at the largest deviation) [default: off].
    #[arg(long, requires = "deviation_field")]
    pub deviation_colours: bool,
    /// Tolerance in model units (> 0): when any vertex lies farther than D (from its input position; compare: from its vertex in A, or from B's surface), say how many and the largest, and exit with code 3; every file is still written [default: none].
    #[arg(long, value_name = "D", value_parser = length, allow_hyphen_values = true)]
    pub tolerance: Option<f64>,
}

/// Exit code of a run that did all it was asked but found vertices beyond `--tolerance`.
pub const EXIT_TOLERANCE: u8 = 3;

/// The tolerance's verdict of `stats` as an error for the exit code ([`Error::Tolerance`]), or
/// `Ok` when within it (or without a tolerance).
pub fn tolerance_verdict(
    what: &std::path::Path,
    stats: &crate::metrics::DeviationStats,
) -> Result<()> {
    match &stats.tolerance {
        Some(t) if !t.within => Err(Error::Tolerance {
            what: format!(
                "{}: {} of {} vertices lie beyond the tolerance {} (largest {}, vertex {})",
                what.display(),
                t.beyond,
                stats.vertices,
                t.limit,
                crate::cli::report::num(stats.distance_max),
                stats.distance_max_vertex
            ),
        }),
        _ => Ok(()),
    }
}

/// Pinned vertices, `smooth`'s flags (`batch` and `slurm-script` take `--pin-property` alone:
/// one list of indices cannot name the vertices of several meshes).
#[derive(Debug, Clone, ClapArgs)]
pub struct PinArgs {
    /// Vertices that never move: a text file of 0-based vertex indices, one per line ('#' comments allowed); a stencil containing one is skipped, so volumes stay exact.
    #[arg(long, value_name = "FILE", conflicts_with = "pin_property")]
    pub pin: Option<PathBuf>,
    #[command(flatten)]
    pub property: PinPropertyArg,
}

/// `--pin-property` (`smooth`, `batch`, `slurm-script`).
#[derive(Debug, Clone, ClapArgs)]
pub struct PinPropertyArg {
    /// Pin the vertices whose PLY vertex property NAME (any numeric type) is non-zero.
    #[arg(long, value_name = "NAME")]
    pub pin_property: Option<String>,
}

impl PinArgs {
    /// The pins these flags ask for; a pin file is read at once, so that a malformed one fails
    /// before the mesh is read.
    pub fn resolve(&self) -> Result<crate::engine::Pins> {
        match &self.pin {
            Some(file) => {
                let pins = crate::engine::Pins::File(file.clone());
                pins.key()?;
                Ok(pins)
            }
            None => Ok(self.property.resolve()),
        }
    }
}

impl PinPropertyArg {
    /// The pins this flag asks for.
    pub fn resolve(&self) -> crate::engine::Pins {
        match &self.pin_property {
            Some(name) => crate::engine::Pins::Property(name.clone()),
            None => crate::engine::Pins::None,
        }
    }
}

/// The most worker threads a command accepts (`--threads`, `--cpus`): the engine's limit.
pub const MAX_THREADS: u32 = crate::engine::MAX_THREADS as u32;

/// The values of a list flag without repeats, in the order first given.
pub fn distinct<T: PartialEq>(values: impl IntoIterator<Item = T>) -> Vec<T> {
    let mut out: Vec<T> = Vec::new();
    for v in values {
        if !out.contains(&v) {
            out.push(v);
        }
    }
    out
}

/// A number (clap value parsers).
fn number(s: &str) -> std::result::Result<f64, String> {
    s.trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))
}

/// A count with no bound but its type's (clap value parser): `-1` is refused with the range,
/// where Rust's parser would only say "invalid digit".
pub fn whole(s: &str) -> std::result::Result<usize, String> {
    whole_in(0, usize::MAX as u64)(s).map(|n| n as usize)
}

/// A whole number in `lo..=hi` (clap value parser).
pub fn whole_in(
    lo: u64,
    hi: u64,
) -> impl Fn(&str) -> std::result::Result<u64, String> + Clone + Send + Sync + 'static {
    move |s| match s.trim().parse::<u64>() {
        Ok(n) if (lo..=hi).contains(&n) => Ok(n),
        _ => Err(format!("'{s}' is not a whole number in {lo}..={hi}")),
    }
}

/// A float that must be finite (clap value parser).
pub fn finite_f64(s: &str) -> std::result::Result<f64, String> {
    let x = number(s)?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("'{s}' is not a finite number"))
    }
}

/// A step size of the library parameter `name` (`lambda` or `mu`) in its range
/// ([`crate::smooth::check_step`]).
fn step(name: &'static str, s: &str) -> std::result::Result<f64, String> {
    let x = finite_f64(s)?;
    crate::smooth::check_step(name, x).map_err(|e| match e {
        Error::Parameter { problem, .. } => problem,
        other => other.to_string(),
    })?;
    Ok(x)
}

/// `--lambda` (clap value parser).
fn step_lambda(s: &str) -> std::result::Result<f64, String> {
    step("lambda", s)
}

/// `--mu` (clap value parser).
fn step_mu(s: &str) -> std::result::Result<f64, String> {
    step("mu", s)
}

/// `--crease-angle`: degrees in (0, 180) (clap value parser).
fn crease_angle(s: &str) -> std::result::Result<f64, String> {
    let x = number(s)?;
    if x > 0.0 && x < 180.0 {
        Ok(x)
    } else {
        Err(format!("'{s}' is not an angle in (0, 180) degrees"))
    }
}

/// A length such as `--max-edge`: a finite number > 0 (clap value parser).
pub fn length(s: &str) -> std::result::Result<f64, String> {
    let x = number(s)?;
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(format!("'{s}' is not a finite length > 0"))
    }
}

impl ValueEnum for Statistics {
    fn value_variants<'a>() -> &'a [Self] {
        &[Statistics::Every, Statistics::Last]
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(match self {
            Statistics::Every => PossibleValue::new("every").help("After every iteration"),
            Statistics::Last => PossibleValue::new("last").help("After the last iteration only"),
        })
    }
}

impl ValueEnum for Method {
    fn value_variants<'a>() -> &'a [Self] {
        &Method::ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        Some(PossibleValue::new(self.name()).help(self.unit().help()))
    }
}

impl ValueEnum for Boundary {
    fn value_variants<'a>() -> &'a [Self] {
        &Boundary::ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        let help = match self {
            Boundary::Fixed => "boundary vertices stay where they are",
            Boundary::Smooth => "smooth each boundary loop, keeping its vector area",
        };
        Some(PossibleValue::new(self.name()).help(help))
    }
}

/// Whether `--deviation-field` can go into `path` (with `--deviation-colours` or without): the
/// usage error naming the flags when not.
pub fn check_deviation_field(path: &std::path::Path, colours: bool) -> Result<()> {
    use crate::io::ValuesRefused;
    crate::io::check_vertex_values(path, colours).map_err(|why| {
        let what = match why {
            ValuesRefused::ColoursOnly(format) => format!(
                "{format} carries per-vertex colours but no per-vertex value: add --deviation-colours, or write a PLY"
            ),
            ValuesRefused::Unsupported => why.to_string(),
        };
        crate::Error::invalid(path, format!("--deviation-field: {what}"))
    })
}

/// One line for a run in which more than half of the vertices of its triangles cannot move
/// freely (or none can): how many, why, and what to try; `None` otherwise. `boundary_smooth`:
/// the run moves boundary vertices along their loops; `weld`: the run welds copies (no
/// `--no-weld`).
pub fn fixed_warning(
    fixed: &crate::engine::plan::FixedVertices,
    boundary_smooth: bool,
    weld: bool,
) -> Option<String> {
    // Vertices of no triangle are not part of the surface; welded copies move with another.
    let n = fixed
        .vertices
        .saturating_sub(fixed.unreferenced + fixed.welded);
    let f = fixed.fixed.saturating_sub(fixed.unreferenced);
    if n == 0 || 2 * f <= n {
        return None;
    }
    let mut why = Vec::new();
    let mut try_ = Vec::new();
    if fixed.boundary_edges > 0 {
        match weld {
            true => {
                why.push(format!(
                    "{} boundary edges (open borders, or seams whose copies are not at exactly one position)",
                    fixed.boundary_edges
                ));
                try_.push(
                    "--weld-tolerance D to weld the copies of seams that lie within D of each other"
                        .to_string(),
                );
            }
            false => {
                why.push(format!(
                    "{} boundary edges (open borders, or seams where the file splits vertices: texture seams, unmerged corners)",
                    fixed.boundary_edges
                ));
                try_.push("without --no-weld, to smooth across seams".to_string());
            }
        }
        if !boundary_smooth {
            try_.push(format!(
                "--boundary smooth ({}) to move boundary vertices along their loops",
                Method::names_accepting(Control::SmoothBoundary, "or")
            ));
        }
    }
    if fixed.non_manifold_edges + fixed.non_manifold_vertices > 0 {
        why.push(format!(
            "{} non-manifold edges and {} non-manifold vertices",
            fixed.non_manifold_edges, fixed.non_manifold_vertices
        ));
    }
    if fixed.pinned > 0 {
        why.push(format!("{} pinned", fixed.pinned));
        try_.push("pin fewer vertices".to_string());
    }
    if fixed.on_creases > 0 {
        why.push(format!("{} on creases", fixed.on_creases));
        try_.push("a larger --crease-angle".to_string());
    }
    let mut line = match (f == n, boundary_smooth && fixed.boundary_edges > 0) {
        (true, false) => {
            format!("none of the {n} vertices can move, so the output has the input's positions")
        }
        (true, true) => format!(
            "none of the {n} vertices can move freely (boundary vertices only along their loops)"
        ),
        (false, _) => format!(
            "{f} of {n} vertices ({:.0} %) cannot move freely",
            100.0 * f as f64 / n as f64
        ),
    };
    if !why.is_empty() {
        line += &format!(": {}", why.join(", "));
    }
    if !try_.is_empty() {
        line += &format!("; try: {}", try_.join("; "));
    }
    Some(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_parsers() {
        assert_eq!(finite_f64(" -0.6"), Ok(-0.6));
        assert_eq!(finite_f64("x"), Err("'x' is not a number".into()));
        assert_eq!(
            finite_f64("inf"),
            Err("'inf' is not a finite number".into())
        );
        assert_eq!(whole("7"), Ok(7));
        assert_eq!(
            whole_in(1, 9)("-1"),
            Err("'-1' is not a whole number in 1..=9".into())
        );
        assert!(whole_in(1, 9)("0").is_err() && whole_in(1, 9)("10").is_err());
        assert_eq!(iterations(" 12"), Ok(Iterations::Count(12)));
        assert_eq!(iterations("auto"), Ok(Iterations::Auto));
        for bad in ["autox", "Auto", "-1", "1.5", ""] {
            let e = iterations(bad).unwrap_err();
            let want = format!(
                "'{bad}' is not a whole number in 0..={}, nor 'auto'",
                usize::MAX
            );
            assert_eq!(e, want);
        }
        assert_eq!(Iterations::Auto.to_string(), "auto");
        assert_eq!(step_lambda("1"), Ok(1.0));
        assert_eq!(step_mu("-1"), Ok(-1.0));
        for bad in ["0", "1.5", "-0.5", "-inf"] {
            let e = step_lambda(bad).unwrap_err();
            assert!(e.contains("(0, 1]") || e.contains("finite"), "{bad}: {e}");
        }
        for bad in ["0", "0.5", "-1.01", "nan"] {
            assert!(step_mu(bad).is_err(), "{bad}");
        }
        assert_eq!(length("0.5"), Ok(0.5));
        assert_eq!(length("0"), Err("'0' is not a finite length > 0".into()));
        assert_eq!(
            length("nan"),
            Err("'nan' is not a finite length > 0".into())
        );
    }

    #[test]
    fn distinct_keeps_the_first_order() {
        assert_eq!(distinct([3, 1, 3, 2, 1]), vec![3, 1, 2]);
    }
}
