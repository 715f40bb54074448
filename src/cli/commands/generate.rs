//! `vcsmooth generate sphere|torus|mesh OUT [--subdivisions K] [--from MESH] [--subdivide L] ...`:
//! write a closed test mesh (icosphere or torus) or a refined base mesh, optionally with Gaussian
//! noise along the normals; with `--subdivide` (and for `mesh`) streamed straight to binary PLY.

use std::io::Write;
use std::path::PathBuf;

use clap::{Args as ClapArgs, ValueEnum};

use crate::cli::flags;
use crate::cli::output::{check_files, mesh_output, output_format, stdout_error};
use crate::cli::progress::Progress;
use crate::cli::shared::finite_f64;
use crate::engine::memory;
use crate::error::{Error, Result};
use crate::io::{self, Format};
use crate::shapes;

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
    /// Output mesh; .ply, .obj, .off or .stl (each with .gz to compress), .gltf or .glb (.ply only with --subdivide).
    #[arg(value_name = "OUT")]
    pub output: PathBuf,
    /// Subdivision level K of sphere or torus (sphere: 20·4^K triangles; K = 2 is the paper's 162-vertex sphere).
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    pub subdivisions: Option<u32>,
    /// Base mesh for the `mesh` shape (any readable mesh, e.g. a scan).
    #[arg(long, value_name = "MESH")]
    pub from: Option<PathBuf>,
    /// Split every triangle of the base into 4^L, streamed straight to a binary PLY without holding the output in memory (for meshes of hundreds of millions of triangles).
    #[arg(long, value_name = "L", allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(0..=15))]
    pub subdivide: Option<u32>,
    /// Gaussian noise along vertex normals, standard deviation relative to the mean edge length.
    #[arg(long, value_name = "SIGMA", default_value_t = 0.0, value_parser = finite_f64, allow_hyphen_values = true)]
    pub noise: f64,
    /// Random seed of the noise (same seed, same mesh).
    #[arg(long, value_name = "S", default_value_t = 1, allow_negative_numbers = true, value_parser = crate::cli::shared::whole_in(0, u64::MAX))]
    pub seed: u64,
    /// Memory allowed, with K/M/G/T suffixes (binary units): a mesh that would need more is refused before any work [default: 3/4 of the available memory, or less under a cgroup limit or ulimit].
    #[arg(long, value_name = "SIZE", value_parser = memory::parse_size)]
    pub memory_budget: Option<u64>,
}

/// `vcsmooth generate`, resolved.
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
    pub budget: memory::Budget,
}

impl GenerateConfig {
    pub fn from_args(a: GenerateArgs) -> Result<GenerateConfig> {
        mesh_output(&a.output)?;
        let reads: Vec<_> = a
            .from
            .as_deref()
            .map(|f| ("--from", f))
            .into_iter()
            .collect();
        check_files(&reads, Some(("OUT", &a.output)), &[])?;
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
        let streamed = a.subdivide.is_some() || a.shape == Shape::Mesh;
        if streamed && output_format(&a.output) != Some(Format::Ply) {
            return Err(Error::invalid(
                &a.output,
                "generate mesh and --subdivide stream binary PLY only; use a .ply output",
            ));
        }
        Ok(GenerateConfig {
            shape: a.shape,
            output: a.output,
            subdivisions,
            from: a.from,
            subdivide: a.subdivide,
            noise: a.noise,
            seed: a.seed,
            budget: memory::budget_or_default(a.memory_budget)?,
        })
    }
}

/// `vcsmooth generate`.
pub fn run(cfg: &GenerateConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    if cfg.shape == Shape::Mesh || cfg.subdivide.is_some() {
        return run_streamed(cfg, progress, out);
    }
    let k = cfg.subdivisions;
    let max = max_subdivisions(cfg.shape);
    if k > max {
        return Err(Error::invalid(
            &cfg.output,
            format!(
                "--subdivisions {k} is too large: the largest {} level is {max} ({} triangles; ×4 per level)",
                shape_name(cfg.shape),
                triangles_at(cfg.shape, max)
            ),
        ));
    }
    check_memory(cfg, k, "--subdivide L streams larger meshes")?;

    progress.phase(format!("generating {} level {k}", shape_name(cfg.shape)));
    let mut mesh = match cfg.shape {
        Shape::Sphere => shapes::icosphere(k),
        // `mesh` always takes the streamed path above.
        Shape::Torus | Shape::Mesh => shapes::torus(k),
    };
    if cfg.noise > 0.0 {
        progress.phase("adding noise");
        shapes::add_normal_noise(&mut mesh, cfg.noise, cfg.seed);
    }
    progress.phase(format!("writing {}", cfg.output.display()));
    io::write_mesh(&cfg.output, &mesh)?;
    progress.finish();
    writeln!(
        out,
        "{}: {} level {k}, {} vertices, {} triangles, noise {} × mean edge length (seed {})",
        cfg.output.display(),
        shape_name(cfg.shape),
        mesh.positions.len(),
        mesh.triangles.len(),
        cfg.noise,
        cfg.seed
    )
    .map_err(stdout_error)
}

/// `vcsmooth generate … --subdivide L` (and the `mesh` shape): refine a base mesh and stream it.
fn run_streamed(cfg: &GenerateConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    if cfg.from.is_none() {
        // The base is generated in memory (the refined output is streamed).
        check_memory(cfg, cfg.subdivisions, "its 4^L pieces are streamed")?;
    }
    let base = match (&cfg.from, cfg.shape) {
        (Some(path), _) => {
            progress.phase(format!("reading {}", path.display()));
            io::read_mesh(path)?
        }
        (None, Shape::Sphere) => {
            shapes::icosphere(cfg.subdivisions.min(shapes::ICOSPHERE_MAX_SUBDIVISIONS))
        }
        (None, _) => shapes::torus(cfg.subdivisions.min(shapes::TORUS_MAX_SUBDIVISIONS)),
    };
    let levels = cfg.subdivide.unwrap_or(0);
    progress.phase(format!(
        "writing {} (streamed, ×{} triangles)",
        cfg.output.display(),
        1u64 << (2 * levels)
    ));
    let n = shapes::Subdivision::new(&base, levels, cfg.noise, cfg.seed)
        .map_err(|e| e.in_file(&cfg.output))?;
    let comment = format!(
        "vcsmooth generate: {} triangles x {}^2",
        n.base_triangles(),
        n.pieces()
    );
    // A mesh from a file keeps its precision (`double` when `float` cannot hold it).
    let precision = base.source.precision;
    io::write_ply_streamed_in(
        &cfg.output,
        precision,
        n.vertices(),
        n.triangles(),
        &[&comment],
        |w| {
            n.for_each_vertex(|p| w.vertex(p))?;
            n.for_each_triangle(|t| w.triangle(t))
        },
    )?;
    progress.finish();
    writeln!(
        out,
        "{}: {} triangles of {} split into 4^{levels}: {} vertices, {} triangles, noise {} × mean edge length (seed {})",
        cfg.output.display(),
        base.triangles.len(),
        cfg.from.as_ref().map_or_else(|| shape_name(cfg.shape).to_string(), |p| p.display().to_string()),
        n.vertices(),
        n.triangles(),
        cfg.noise,
        cfg.seed
    )
    .map_err(stdout_error)
}

fn shape_name(s: Shape) -> &'static str {
    match s {
        Shape::Sphere => "sphere",
        Shape::Torus => "torus",
        Shape::Mesh => "mesh",
    }
}

/// The largest subdivision level the generator accepts for `shape`.
fn max_subdivisions(shape: Shape) -> u32 {
    match shape {
        Shape::Sphere => shapes::ICOSPHERE_MAX_SUBDIVISIONS,
        Shape::Torus => shapes::TORUS_MAX_SUBDIVISIONS,
        Shape::Mesh => 0,
    }
}

/// Triangles of `shape` at level `k` (≤ its maximum): sphere `20·4^k`, torus `256·4^k`.
fn triangles_at(shape: Shape, k: u32) -> u64 {
    let base = match shape {
        Shape::Sphere => 20,
        Shape::Torus => 256,
        Shape::Mesh => 0,
    };
    base << (2 * k.min(max_subdivisions(shape)))
}

/// Refuse, before any work, a level `k` whose mesh the memory budget cannot hold (`hint`: what
/// else to try).
fn check_memory(cfg: &GenerateConfig, k: u32, hint: &str) -> Result<()> {
    let k = k.min(max_subdivisions(cfg.shape));
    let triangles = triangles_at(cfg.shape, k);
    let need = memory::generate_bytes(triangles, cfg.noise > 0.0);
    let what = format!(
        "{} level {k} ({triangles} triangles)",
        shape_name(cfg.shape)
    );
    memory::check_fits(&what, need, cfg.budget).map_err(|e| {
        Error::resource(format!(
            "{}: {e}; choose a smaller --subdivisions ({hint}) or raise --memory-budget",
            cfg.output.display()
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_counts_match_the_generators() {
        assert_eq!(triangles_at(Shape::Sphere, 3), 1280);
        for shape in [Shape::Sphere, Shape::Torus] {
            let mesh = match shape {
                Shape::Sphere => shapes::icosphere(1),
                _ => shapes::torus(1),
            };
            assert_eq!(triangles_at(shape, 1), mesh.triangles.len() as u64);
            assert!(triangles_at(shape, max_subdivisions(shape)) < 1 << 31);
        }
    }
}
