//! Resolved, validated configuration: what [`super::run`] executes. Built from [`super::Args`] by
//! [`Config::from_args`], which makes the checks clap cannot (output formats by extension, plot
//! files are SVG, directories of the files to write exist), so that a run fails before reading
//! or smoothing anything rather than after.

use std::path::{Path, PathBuf};

use super::args::{Args, Command, EngineArgs, MethodParams, Shape};
use super::flags;
use crate::error::{Error, Result};
use crate::io::Format;
use crate::smooth::{Method, Options};

/// One resolved command.
#[derive(Debug, Clone)]
pub enum Config {
    Smooth(SmoothConfig),
    Info(InfoConfig),
    Compare(CompareConfig),
    Generate(GenerateConfig),
    Curves(CurvesConfig),
    Demo(DemoConfig),
    Bench(BenchConfig),
    Batch(super::batch::BatchConfig),
    SlurmScript(super::batch::SlurmScriptConfig),
    Subdivide(super::refine::SubdivideConfig),
    Refine(super::refine::RefineConfig),
}

/// `vcsmooth bench`.
#[derive(Debug, Clone)]
pub struct BenchConfig {
    pub settings: crate::modes::bench::BenchSettings,
    pub json: bool,
}

impl BenchConfig {
    fn from_args(a: super::args::BenchArgs) -> Result<BenchConfig> {
        let defaults = crate::modes::bench::BenchSettings::default();
        let mut methods: Vec<Method> = Vec::new();
        for m in a.methods {
            if !methods.contains(&m) {
                methods.push(m);
            }
        }
        let mut threads: Vec<usize> = Vec::new();
        for t in a.threads {
            if !threads.contains(&(t as usize)) {
                threads.push(t as usize);
            }
        }
        let settings = crate::modes::bench::BenchSettings {
            sizes: crate::modes::bench::normalize_sizes(a.sizes),
            methods,
            threads: if threads.is_empty() {
                defaults.threads
            } else {
                threads
            },
            iterations: a.iterations as usize,
            repeats: a.repeats as usize,
            patch_size: a.patch_size.map_or(defaults.patch_size, |p| p as usize),
            dir: a.dir.unwrap_or(defaults.dir),
        };
        crate::modes::bench::check(&settings)?;
        Ok(BenchConfig {
            settings,
            json: a.json,
        })
    }
}

/// `vcsmooth demo`.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    pub subdivisions: u32,
    pub iterations: usize,
    pub noise: f64,
    pub engine: EngineConfig,
}

/// How the engine runs (threads, patch size, memory budget, scratch directory).
pub type EngineConfig = crate::engine::EngineSettings;

/// `vcsmooth smooth`.
#[derive(Debug, Clone)]
pub struct SmoothConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub options: Options,
    pub engine: EngineConfig,
    pub report: Option<PathBuf>,
    pub plot: Option<PathBuf>,
    /// `--multires` and its options.
    pub multires: Option<crate::multires::MultiresOptions>,
    /// `--checkpoint DIR` (kept) and `--checkpoint-every`.
    pub checkpoint: Option<PathBuf>,
    pub checkpoint_every: usize,
    /// Which iterations measure their statistics.
    pub stats: super::args::Stats,
    /// The command line as given, recorded in the report.
    pub argv: Vec<String>,
}

impl SmoothConfig {
    /// How a run over `ranks` ranks uses its work directory; `None` for the plain engine (one
    /// rank, no checkpoint).
    pub fn cluster(&self, ranks: usize) -> Option<crate::cluster::ClusterSettings> {
        let (work_dir, keep) = match &self.checkpoint {
            Some(dir) => (dir.clone(), true),
            None if ranks > 1 => {
                let mut name = self.output.as_os_str().to_owned();
                name.push(".vcsmooth-work");
                (PathBuf::from(name), false)
            }
            None => return None,
        };
        Some(crate::cluster::ClusterSettings {
            work_dir,
            keep,
            checkpoint_every: self.checkpoint_every,
        })
    }
}

/// `vcsmooth info`.
#[derive(Debug, Clone)]
pub struct InfoConfig {
    pub input: PathBuf,
    pub json: bool,
}

/// `vcsmooth compare`.
#[derive(Debug, Clone)]
pub struct CompareConfig {
    pub a: PathBuf,
    pub b: PathBuf,
    pub json: bool,
}

/// `vcsmooth generate`.
#[derive(Debug, Clone)]
pub struct GenerateConfig {
    pub shape: Shape,
    pub output: PathBuf,
    /// Level of sphere or torus (0 for `mesh`).
    pub subdivisions: u32,
    /// Base mesh file of the `mesh` shape.
    pub from: Option<PathBuf>,
    /// Levels of streamed flat subdivision.
    pub subdivide: Option<u32>,
    /// Noise standard deviation relative to the mean edge length (≥ 0).
    pub noise: f64,
    pub seed: u64,
}

/// `vcsmooth curves`.
#[derive(Debug, Clone)]
pub struct CurvesConfig {
    pub input: PathBuf,
    /// Distinct methods, in the order given.
    pub methods: Vec<Method>,
    /// Options shared by every method (`method` is replaced per run).
    pub options: Options,
    pub engine: EngineConfig,
    pub plot: PathBuf,
    pub json: bool,
}

impl Config {
    /// Resolve and validate parsed flags. `argv` is the command line, kept for reports.
    pub fn from_args(args: Args, argv: Vec<String>) -> Result<Config> {
        Ok(match args.command {
            Command::Smooth(a) => {
                mesh_output(&a.output)?;
                if let Some(r) = &a.report {
                    parent_exists(r)?;
                }
                if let Some(p) = &a.plot {
                    svg_output(p)?;
                    if a.stats != super::args::Stats::Every {
                        return Err(flags::parameter(
                            "plot",
                            "draws the volume of every iteration: it needs --stats every",
                        ));
                    }
                }
                let mut engine = engine(&a.smoothing.engine)?;
                engine.with_stats = a.report.is_some();
                engine.statistics = match a.stats {
                    super::args::Stats::Every => crate::engine::Statistics::Every,
                    super::args::Stats::Last => crate::engine::Statistics::Last,
                };
                let options = options(
                    a.smoothing.method,
                    a.smoothing.iterations,
                    &a.smoothing.params,
                );
                let multires = a.multires.resolve(&options)?;
                if multires.is_some() && a.cluster.checkpoint.is_some() {
                    return Err(flags::parameter(
                        "multires",
                        "cannot be combined with --checkpoint (it runs in one process)",
                    ));
                }
                Config::Smooth(SmoothConfig {
                    multires,
                    options,
                    engine,
                    input: a.input,
                    output: a.output,
                    report: a.report,
                    plot: a.plot,
                    checkpoint: a.cluster.checkpoint,
                    checkpoint_every: a.cluster.checkpoint_every as usize,
                    stats: a.stats,
                    argv,
                })
            }
            Command::Info(a) => Config::Info(InfoConfig {
                input: a.input,
                json: a.json,
            }),
            Command::Compare(a) => Config::Compare(CompareConfig {
                a: a.a,
                b: a.b,
                json: a.json,
            }),
            Command::Generate(a) => {
                mesh_output(&a.output)?;
                if a.noise < 0.0 {
                    return Err(flags::parameter(
                        "noise",
                        format!("must be at least 0, got {}", a.noise),
                    ));
                }
                let subdivisions = match (a.shape, a.subdivisions, &a.from) {
                    (Shape::Mesh, None, Some(_)) => 0,
                    (Shape::Mesh, _, None) => {
                        return Err(Error::Usage {
                            what: "generate mesh needs --from MESH".into(),
                        });
                    }
                    (Shape::Mesh, Some(_), _) => {
                        return Err(flags::parameter(
                            "subdivisions",
                            "is for sphere and torus; refine a mesh with --subdivide",
                        ));
                    }
                    (_, _, Some(_)) => {
                        return Err(flags::parameter("from", "goes with the shape `mesh`"));
                    }
                    (_, None, None) => {
                        return Err(Error::Usage {
                            what: "generate sphere|torus needs --subdivisions K".into(),
                        });
                    }
                    (_, Some(k), None) => k,
                };
                if a.subdivide.is_some() && output_format(&a.output) != Some(Format::Ply) {
                    return Err(Error::invalid(
                        &a.output,
                        "--subdivide streams binary PLY only; use a .ply output",
                    ));
                }
                Config::Generate(GenerateConfig {
                    shape: a.shape,
                    output: a.output,
                    subdivisions,
                    from: a.from,
                    subdivide: a.subdivide,
                    noise: a.noise,
                    seed: a.seed,
                })
            }
            Command::Curves(a) => {
                svg_output(&a.plot)?;
                let mut methods: Vec<Method> = Vec::new();
                for m in a.methods {
                    if !methods.contains(&m) {
                        methods.push(m);
                    }
                }
                if methods.is_empty() {
                    return Err(flags::parameter("methods", "names no method"));
                }
                Config::Curves(CurvesConfig {
                    options: options(methods[0], a.iterations as usize, &a.params),
                    engine: engine(&a.engine)?,
                    input: a.input,
                    methods,
                    plot: a.plot,
                    json: a.json,
                })
            }
            Command::Demo(a) => {
                if !(a.noise.is_finite() && a.noise >= 0.0) {
                    return Err(flags::parameter(
                        "noise",
                        format!("must be a finite number ≥ 0, got {}", a.noise),
                    ));
                }
                Config::Demo(DemoConfig {
                    subdivisions: a.subdivisions,
                    iterations: a.iterations as usize,
                    noise: a.noise,
                    engine: engine(&a.engine)?,
                })
            }
            Command::Bench(a) => Config::Bench(BenchConfig::from_args(a)?),
            Command::Batch(a) => Config::Batch(super::batch::BatchConfig::from_args(a)?),
            Command::SlurmScript(a) => {
                Config::SlurmScript(super::batch::SlurmScriptConfig::from_args(a)?)
            }
            Command::Subdivide(a) => {
                Config::Subdivide(super::refine::SubdivideConfig::from_args(a)?)
            }
            Command::Refine(a) => Config::Refine(super::refine::RefineConfig::from_args(a)?),
        })
    }
}

pub(super) fn options(method: Method, iterations: usize, p: &MethodParams) -> Options {
    Options {
        method,
        iterations,
        lambda: p.lambda,
        mu: p.mu,
        reject_energy_increase: p.reject_energy_increase,
    }
}

pub(super) fn engine(e: &EngineArgs) -> Result<EngineConfig> {
    if let Some(b) = e.memory_budget {
        crate::engine::memory::check_budget(b)?;
    }
    if let Some(dir) = &e.scratch {
        if !dir.is_dir() {
            return Err(Error::invalid(
                dir,
                "--scratch must be an existing directory",
            ));
        }
    }
    Ok(EngineConfig {
        threads: e.threads.map(|t| t as usize),
        patch_size: e
            .patch_size
            .map_or(crate::engine::DEFAULT_PATCH_SIZE, |p| p as usize),
        memory_budget: e.memory_budget,
        scratch: e.scratch.clone(),
        with_stats: false,
        statistics: crate::engine::Statistics::Every,
    })
}

/// The mesh format written for `path`, from its extension (case-insensitive), as the writer sees it.
pub fn output_format(path: &Path) -> Option<Format> {
    Format::from_extension(path)
}

/// Check that a mesh can be written to `path`: known extension, existing directory.
fn mesh_output(path: &Path) -> Result<()> {
    if output_format(path).is_none() {
        let what = match path.extension() {
            Some(e) => format!("unknown output format '.{}'", e.to_string_lossy()),
            None => "output file has no extension".to_string(),
        };
        return Err(Error::invalid(
            path,
            format!("{what} (expected .ply, .obj, .off or .stl)"),
        ));
    }
    parent_exists(path)
}

/// Check that a plot can be written to `path`: `.svg`, existing directory.
fn svg_output(path: &Path) -> Result<()> {
    let ok = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    if !ok {
        return Err(Error::invalid(
            path,
            "plots are written as SVG: the file name must end in .svg",
        ));
    }
    parent_exists(path)
}

/// Check that the directory `path` would be created in exists.
fn parent_exists(path: &Path) -> Result<()> {
    if path.as_os_str().is_empty() {
        return Err(Error::Usage {
            what: "an output file name is empty".into(),
        });
    }
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() && !dir.is_dir() => Err(Error::invalid(
            path,
            format!("directory '{}' does not exist", dir.display()),
        )),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn resolve(argv: &[&str]) -> Result<Config> {
        Config::from_args(Args::try_parse_from(argv).unwrap(), vec![])
    }

    #[test]
    fn output_extensions() {
        assert_eq!(output_format(Path::new("a/b.PLY")), Some(Format::Ply));
        assert_eq!(output_format(Path::new("b.stl")), Some(Format::Stl));
        assert_eq!(output_format(Path::new("b.xyz")), None);
        assert_eq!(output_format(Path::new("b")), None);
        let e = resolve(&["vcsmooth", "smooth", "a.ply", "b.xyz"])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("b.xyz") && e.contains("unknown output format"),
            "{e}"
        );
        assert!(
            resolve(&[
                "vcsmooth",
                "generate",
                "torus",
                "t.vtk",
                "--subdivisions",
                "1"
            ])
            .is_err()
        );
    }

    #[test]
    fn plot_must_be_svg_and_directory_must_exist() {
        assert!(resolve(&["vcsmooth", "smooth", "a.ply", "b.ply", "--plot", "v.png"]).is_err());
        assert!(resolve(&["vcsmooth", "curves", "a.ply", "--plot", "v.pdf"]).is_err());
        let e = resolve(&["vcsmooth", "smooth", "a.ply", "/no/such/dir/b.ply"]).unwrap_err();
        assert!(e.to_string().contains("does not exist"), "{e}");
        assert!(resolve(&["vcsmooth", "smooth", "a.ply", "b.ply", "--plot", "v.svg"]).is_ok());
    }

    #[test]
    fn curves_methods_deduplicated_and_options_carried() {
        let c = resolve(&[
            "vcsmooth",
            "curves",
            "a.ply",
            "--plot",
            "c.svg",
            "--methods",
            "vcs,lem,vcs",
            "--lambda",
            "0.3",
            "--iterations",
            "6",
            "--threads",
            "2",
        ])
        .unwrap();
        let Config::Curves(c) = c else {
            panic!("not curves")
        };
        assert_eq!(c.methods, vec![Method::Vcs, Method::Lem]);
        assert_eq!(c.options.lambda, 0.3);
        assert_eq!(c.options.iterations, 6);
        assert_eq!(c.engine.threads, Some(2));
    }

    #[test]
    fn negative_noise_refused() {
        assert!(
            resolve(&[
                "vcsmooth",
                "generate",
                "sphere",
                "s.ply",
                "--subdivisions",
                "1",
                "--noise=-1"
            ])
            .is_err()
        );
    }
}
