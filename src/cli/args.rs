//! Raw command-line flags (clap). Only parsing and per-flag validation live here (numbers parse,
//! `--threads ≥ 1`, λ and μ finite); checks that need several flags or the file system are made
//! when the flags are resolved into a [`super::Config`].

use std::path::PathBuf;

use clap::builder::PossibleValue;
use clap::{Args as ClapArgs, Parser, Subcommand, ValueEnum};

use crate::smooth::Method;

/// vcsmooth: smooth triangle meshes without shrinking them (volume-constrained smoothing, Liu et al. 2002).
#[derive(Debug, Clone, Parser)]
#[command(name = "vcsmooth", version, about, long_about = None, propagate_version = true)]
pub struct Args {
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands. Their names and flags are a contract: scripts depend on them.
#[derive(Debug, Clone, Subcommand)]
pub enum Command {
    /// Smooth a mesh file and write the result (format chosen by OUT's extension).
    Smooth(SmoothArgs),
    /// Print vertices, faces, edges, boundary, components, volume, area, bounding box of a mesh.
    Info(InfoArgs),
    /// Compare two meshes with the same connectivity (distances, normals, volume and area ratios).
    Compare(CompareArgs),
    /// Write a closed test mesh (icosphere or torus), optionally with Gaussian noise along normals.
    Generate(GenerateArgs),
    /// Run several methods from the same input and plot volume % per iteration (the paper's Fig. 4).
    Curves(CurvesArgs),
    /// Smooth a generated noisy sphere with every method and print volume and roughness per method.
    Demo(DemoArgs),
    /// Measure throughput on generated meshes: smoothing, plan, PLY I/O, memory (to size jobs).
    #[command(long_about = BENCH_ABOUT)]
    Bench(BenchArgs),
    /// Smooth many meshes as one share of a job array (Slurm's), with per-input success markers; --summary gathers them.
    Batch(super::batch::BatchArgs),
    /// Print a ready Slurm script: an array job running `batch` over the inputs, and a dependent summary job.
    SlurmScript(super::batch::SlurmScriptArgs),
    /// Split triangles until no edge is longer than --max-edge (the paper's adaptive subdivision, §4).
    Subdivide(super::refine::SubdivideArgs),
    /// Alternate subdivide and vcs smoothing --rounds times (the paper's Figs. 5–7).
    Refine(super::refine::RefineArgs),
}

const BENCH_ABOUT: &str = "\
Measure end-to-end throughput on generated noisy icospheres: triangles and stencils per second per
iteration of each method on each thread count, the plan's preparation time (reorder, topology,
partition), binary PLY write and read in GB/s, and the peak anonymous memory per triangle.

Sizes run smallest first; every timing is the median of --repeats runs (seconds per iteration: the
median over all iterations of all repeats). Run it on a cluster node, with that node's thread counts,
to size jobs: a run of N iterations on T triangles takes about N × T / (triangles per second), plus
the preparation and the I/O, and needs about T × (bytes per triangle) of memory in-core (a `smooth`
run whose mesh exceeds its --memory-budget puts the large arrays in scratch files instead). Figures
drop on a loaded machine: the table's first line gives the load average. The defaults take about a
minute on 2 cores.

Example: vcsmooth bench --sizes 1M,4M --methods laplacian,taubin,vcs --threads 1,2 --json";

/// `vcsmooth bench [--sizes ...] [--methods ...] [--threads ...] [--iterations N] [--repeats R] [--json]`
#[derive(Debug, Clone, ClapArgs)]
pub struct BenchArgs {
    /// Comma-separated mesh sizes: triangle counts (decimal K/M/G suffixes), each mapped to the icosphere level with the nearest triangle count (1M → level 8, 1.31M triangles; 4M → level 9, 5.24M), or icoK for level K exactly.
    #[arg(long, value_name = "SIZE,...", value_delimiter = ',', default_value = "1M",
          value_parser = crate::modes::bench::parse_size)]
    pub sizes: Vec<crate::modes::bench::SizeSpec>,
    /// Comma-separated methods to time.
    #[arg(long, value_enum, value_delimiter = ',', value_name = "M,M,...",
          default_values_t = [Method::Laplacian, Method::Taubin, Method::Vcs])]
    pub methods: Vec<Method>,
    /// Comma-separated thread counts [default: 1 and all cores].
    #[arg(long, value_name = "N,...", value_delimiter = ',',
          value_parser = clap::value_parser!(u32).range(1..))]
    pub threads: Vec<u32>,
    /// Iterations per smoothing run.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub iterations: u32,
    /// Repeats of every timing; the median is reported.
    #[arg(long, value_name = "R", default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeats: u32,
    /// Vertices per patch [default: 16384].
    #[arg(long, value_name = "VERTICES", value_parser = clap::value_parser!(u64).range(1..u32::MAX as u64))]
    pub patch_size: Option<u64>,
    /// Directory for the temporary PLY file (a tmpfs such as /dev/shm leaves out the disk's fsync) [default: the system's temporary directory].
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Print JSON instead of a table [default: table].
    #[arg(long)]
    pub json: bool,
}

/// `vcsmooth demo [--subdivisions K] [--iterations N] [--noise SIGMA]`
#[derive(Debug, Clone, ClapArgs)]
pub struct DemoArgs {
    /// Icosphere level of the embedded test mesh (20·4^K triangles).
    #[arg(long, value_name = "K", default_value_t = 4, value_parser = clap::value_parser!(u32).range(0..=10))]
    pub subdivisions: u32,
    /// Iterations per method.
    #[arg(long, value_name = "N", default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..10_000))]
    pub iterations: u64,
    /// Noise along normals, × the mean edge length.
    #[arg(long, value_name = "SIGMA", default_value_t = 0.3)]
    pub noise: f64,
    #[command(flatten)]
    pub engine: EngineArgs,
}

/// The smoothing flags shared by `smooth` and `batch`: method, iterations, step sizes, engine.
#[derive(Debug, Clone, ClapArgs)]
pub struct SmoothingArgs {
    /// Smoothing method.
    #[arg(long, value_enum, default_value_t = Method::Vcs)]
    pub method: Method,
    /// Number of iterations; 0 only converts the file's format.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 10,
        allow_negative_numbers = true
    )]
    pub iterations: usize,
    #[command(flatten)]
    pub params: MethodParams,
    #[command(flatten)]
    pub engine: EngineArgs,
}

/// `vcsmooth smooth IN OUT ...`
#[derive(Debug, Clone, ClapArgs)]
pub struct SmoothArgs {
    /// Input mesh (PLY, OBJ, OFF or STL).
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Output mesh; .ply, .obj, .off or .stl. Written atomically, never on failure.
    #[arg(value_name = "OUT")]
    pub output: PathBuf,
    #[command(flatten)]
    pub smoothing: SmoothingArgs,
    #[command(flatten)]
    pub multires: super::multires::MultiresArgs,
    /// Write a JSON report (options, input/output statistics, timings, per-iteration table).
    #[arg(long, value_name = "FILE.json")]
    pub report: Option<PathBuf>,
    /// Write an SVG plot of volume % per iteration.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Which iterations measure volume, area and displacement (each costs passes over the whole mesh, about one taubin iteration for volume and area); the others show '-' in the table and null in the report.
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = Stats::Every)]
    pub stats: Stats,
    #[command(flatten)]
    pub cluster: ClusterArgs,
}

/// When `smooth` measures the per-iteration statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Stats {
    /// After every iteration.
    Every,
    /// After the last iteration only.
    Last,
}

/// Checkpoints and MPI ranks (see the README's "One mesh over MPI ranks").
#[derive(Debug, Clone, ClapArgs)]
pub struct ClusterArgs {
    /// Keep the prepared plan and the positions after every --checkpoint-every iterations in DIR
    /// (on a file system all ranks see); a run started again with the same input, options and patch
    /// size resumes after the last completed iteration. Under mpirun/srun without it, a work
    /// directory OUT.vcsmooth-work is used and removed after success.
    #[arg(long, value_name = "DIR")]
    pub checkpoint: Option<PathBuf>,
    /// Iterations between checkpoints (the last iteration is always written).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..), allow_negative_numbers = true)]
    pub checkpoint_every: u64,
}

/// Step sizes and stencil options shared by `smooth` and `curves`.
#[derive(Debug, Clone, ClapArgs)]
pub struct MethodParams {
    /// Laplacian step size λ (laplacian, and the first step of taubin).
    #[arg(long, value_name = "X", default_value_t = 0.5, value_parser = finite_f64, allow_negative_numbers = true)]
    pub lambda: f64,
    /// Taubin's second step size μ (negative).
    #[arg(long, value_name = "Y", default_value_t = -0.53, value_parser = finite_f64, allow_negative_numbers = true)]
    pub mu: f64,
    /// Skip a stencil whose result has a higher stencil energy than before (lem, vcs, vcs-triangle) [default: off].
    #[arg(long)]
    pub reject_energy_increase: bool,
}

/// How the engine runs: threads, patches, memory.
#[derive(Debug, Clone, ClapArgs)]
pub struct EngineArgs {
    /// Worker threads [default: all cores].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..), allow_negative_numbers = true)]
    pub threads: Option<u32>,
    /// Vertices per patch; the result is identical for any thread count and memory budget for a given patch size [default: 16384].
    #[arg(long, value_name = "VERTICES", value_parser = clap::value_parser!(u64).range(1..u32::MAX as u64), allow_negative_numbers = true)]
    pub patch_size: Option<u64>,
    /// Anonymous memory allowed, with K/M/G/T suffixes (binary units); larger meshes go to memory-mapped scratch files [default: 3/4 of available memory].
    #[arg(long, value_name = "SIZE", value_parser = crate::engine::memory::parse_size)]
    pub memory_budget: Option<u64>,
    /// Directory for scratch files (removed on exit, even on error) [default: the output's directory].
    #[arg(long, value_name = "DIR")]
    pub scratch: Option<PathBuf>,
}

/// `vcsmooth info IN [--json]`
#[derive(Debug, Clone, ClapArgs)]
pub struct InfoArgs {
    /// Mesh to describe.
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Print JSON instead of a table [default: table].
    #[arg(long)]
    pub json: bool,
}

/// `vcsmooth compare A B [--json]`
#[derive(Debug, Clone, ClapArgs)]
pub struct CompareArgs {
    /// Reference mesh.
    #[arg(value_name = "A")]
    pub a: PathBuf,
    /// Mesh compared against A (same vertex count and triangles).
    #[arg(value_name = "B")]
    pub b: PathBuf,
    /// Print JSON instead of a table [default: table].
    #[arg(long)]
    pub json: bool,
}

/// Shapes `generate` can write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shape {
    /// Unit icosphere: 10·4^K + 2 vertices, 20·4^K triangles.
    Sphere,
    /// Torus around the z axis (radii 1 and 0.4); the grid resolution doubles with each level.
    Torus,
    /// The mesh given by --from (e.g. a real scan), refined with --subdivide.
    Mesh,
}

/// `vcsmooth generate sphere|torus|mesh OUT [--subdivisions K] [--from MESH] [--subdivide L] ...`
#[derive(Debug, Clone, ClapArgs)]
pub struct GenerateArgs {
    /// Shape to generate.
    #[arg(value_enum)]
    pub shape: Shape,
    /// Output mesh; .ply, .obj, .off or .stl (.ply only with --subdivide).
    #[arg(value_name = "OUT")]
    pub output: PathBuf,
    /// Subdivision level K of sphere or torus (sphere: 20·4^K triangles; K = 2 is the paper's 162-vertex sphere).
    #[arg(long, value_name = "K")]
    pub subdivisions: Option<u32>,
    /// Base mesh for the `mesh` shape (any readable mesh, e.g. a scan).
    #[arg(long, value_name = "MESH")]
    pub from: Option<PathBuf>,
    /// Split every triangle of the base into 4^L, streamed straight to a binary PLY without holding the output in memory (for meshes of hundreds of millions of triangles).
    #[arg(long, value_name = "L", value_parser = clap::value_parser!(u32).range(0..=15))]
    pub subdivide: Option<u32>,
    /// Gaussian noise along vertex normals, standard deviation relative to the mean edge length.
    #[arg(long, value_name = "SIGMA", default_value_t = 0.0, value_parser = finite_f64)]
    pub noise: f64,
    /// Random seed of the noise (same seed, same mesh).
    #[arg(long, value_name = "S", default_value_t = 1)]
    pub seed: u64,
}

/// `vcsmooth curves IN --plot FILE.svg ...`
#[derive(Debug, Clone, ClapArgs)]
pub struct CurvesArgs {
    /// Input mesh (PLY, OBJ, OFF or STL).
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Comma-separated methods to run, each from the same input.
    #[arg(long, value_enum, value_delimiter = ',', value_name = "M,M,...",
          default_values_t = [Method::Vcs, Method::Lem, Method::Laplacian])]
    pub methods: Vec<Method>,
    /// Iterations per method (at least 1).
    #[arg(long, value_name = "N", default_value_t = 10, allow_negative_numbers = true,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub iterations: u32,
    #[command(flatten)]
    pub params: MethodParams,
    #[command(flatten)]
    pub engine: EngineArgs,
    /// SVG file for the volume curves, one line per method with a legend.
    #[arg(long, value_name = "FILE.svg", required = true)]
    pub plot: PathBuf,
    /// Print JSON instead of a table [default: table].
    #[arg(long)]
    pub json: bool,
}

/// A float that must be finite (clap value parser).
fn finite_f64(s: &str) -> Result<f64, String> {
    let x: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("'{s}' is not a finite number"))
    }
}

impl ValueEnum for Method {
    fn value_variants<'a>() -> &'a [Self] {
        &Method::ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        let help = match self {
            Method::Laplacian => "umbrella Laplacian, p += λ L(p) (shrinks)",
            Method::Taubin => "λ|μ: a λ step then a μ step (Taubin 1995)",
            Method::Lem => "local energy minimisation on edge stencils, no volume constraint",
            Method::Vcs => "volume-constrained smoothing on edge stencils (Liu et al. 2002)",
            Method::VcsTriangle => "volume-constrained smoothing on triangle stencils",
        };
        Some(PossibleValue::new(self.name()).help(help))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn clap_definition_is_consistent() {
        Args::command().debug_assert();
    }

    #[test]
    fn defaults_match_the_contract() {
        let a = Args::try_parse_from(["vcsmooth", "smooth", "in.ply", "out.ply"]).unwrap();
        let Command::Smooth(s) = a.command else {
            panic!("not smooth")
        };
        let s = s.smoothing;
        assert_eq!(s.method, Method::Vcs);
        assert_eq!(s.iterations, 10);
        assert_eq!(s.params.lambda, 0.5);
        assert_eq!(s.params.mu, -0.53);
        assert!(!s.params.reject_energy_increase);
        assert_eq!(s.engine.threads, None);

        let a = Args::try_parse_from(["vcsmooth", "curves", "in.ply", "--plot", "c.svg"]).unwrap();
        let Command::Curves(c) = a.command else {
            panic!("not curves")
        };
        assert_eq!(c.methods, vec![Method::Vcs, Method::Lem, Method::Laplacian]);
    }

    #[test]
    fn rejects_bad_values() {
        for argv in [
            &[
                "vcsmooth",
                "smooth",
                "a.ply",
                "b.ply",
                "--iterations",
                "abc",
            ][..],
            &["vcsmooth", "smooth", "a.ply", "b.ply", "--method", "median"],
            &["vcsmooth", "smooth", "a.ply", "b.ply", "--lambda", "nan"],
            &["vcsmooth", "smooth", "a.ply", "b.ply", "--mu", "inf"],
            &["vcsmooth", "smooth", "a.ply", "b.ply", "--threads", "0"],
            &[
                "vcsmooth",
                "curves",
                "a.ply",
                "--plot",
                "c.svg",
                "--iterations",
                "0",
            ],
            &["vcsmooth", "curves", "a.ply"],
            &[
                "vcsmooth",
                "generate",
                "cube",
                "a.ply",
                "--subdivisions",
                "1",
            ],
        ] {
            assert!(Args::try_parse_from(argv).is_err(), "{argv:?} accepted");
        }
        let a = Args::try_parse_from(["vcsmooth", "smooth", "a", "b", "--mu", "-0.6"]).unwrap();
        let Command::Smooth(s) = a.command else {
            panic!("not smooth")
        };
        assert_eq!(s.smoothing.params.mu, -0.6);
    }
}
