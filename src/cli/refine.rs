//! `vcsmooth subdivide` and `vcsmooth refine`: the paper's adaptive subdivision (§4) and its
//! refine-and-smooth workflow (Figs. 5–7), through [`crate::modes::refine`]. Both read the whole mesh,
//! work in memory and write the result atomically only when everything succeeded.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args as ClapArgs;

use super::output::stdout_error;
use super::progress::Progress;
use crate::error::{Error, Result};
use crate::io;
use crate::modes::refine::{self, RefineOptions};
use crate::smooth::Method;

/// `vcsmooth subdivide IN OUT --max-edge DELTA`
#[derive(Debug, Clone, ClapArgs)]
pub struct SubdivideArgs {
    /// Input mesh (PLY, OBJ, OFF or STL).
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Output mesh; .ply, .obj, .off or .stl. Written atomically, never on failure.
    #[arg(value_name = "OUT")]
    pub output: PathBuf,
    /// δ: split triangles (conforming longest-edge bisection) until no edge is longer than this; new vertices lie on the input's triangles.
    #[arg(long, value_name = "DELTA", allow_negative_numbers = true, value_parser = length)]
    pub max_edge: f64,
}

/// `vcsmooth refine IN OUT --max-edge DELTA --rounds R [--iterations N] [--method M] [--threads T]`
#[derive(Debug, Clone, ClapArgs)]
pub struct RefineArgs {
    /// Input mesh (PLY, OBJ, OFF or STL).
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Output mesh; .ply, .obj, .off or .stl. Written atomically, never on failure.
    #[arg(value_name = "OUT")]
    pub output: PathBuf,
    /// δ of every subdivision (see `subdivide`).
    #[arg(long, value_name = "DELTA", allow_negative_numbers = true, value_parser = length)]
    pub max_edge: f64,
    /// Rounds of subdivide-then-smooth (the paper's Figs. 5–7 show two after a first smoothing).
    #[arg(long, value_name = "R", value_parser = clap::value_parser!(u32).range(1..=64))]
    pub rounds: u32,
    /// Smoothing iterations after each subdivision.
    #[arg(long, value_name = "N", default_value_t = 5, value_parser = clap::value_parser!(u32).range(0..=100_000))]
    pub iterations: u32,
    /// Smoothing method (the paper uses vcs, Fig. 5, and vcs-triangle, Fig. 6).
    #[arg(long, value_enum, default_value_t = Method::Vcs)]
    pub method: Method,
    /// Worker threads of the smoothing [default: all cores].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub threads: Option<u32>,
}

/// Resolved `vcsmooth subdivide`.
#[derive(Debug, Clone)]
pub struct SubdivideConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub max_edge: f64,
}

/// Resolved `vcsmooth refine`.
#[derive(Debug, Clone)]
pub struct RefineConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub options: RefineOptions,
    pub threads: Option<usize>,
}

impl SubdivideConfig {
    pub fn from_args(a: SubdivideArgs) -> Result<SubdivideConfig> {
        refine::check_max_edge(a.max_edge)?;
        mesh_output(&a.output)?;
        Ok(SubdivideConfig {
            input: a.input,
            output: a.output,
            max_edge: a.max_edge,
        })
    }
}

impl RefineConfig {
    pub fn from_args(a: RefineArgs) -> Result<RefineConfig> {
        refine::check_max_edge(a.max_edge)?;
        mesh_output(&a.output)?;
        let mut options = RefineOptions {
            max_edge: a.max_edge,
            rounds: a.rounds as usize,
            ..Default::default()
        };
        options.smoothing.method = a.method;
        options.smoothing.iterations = a.iterations as usize;
        Ok(RefineConfig {
            input: a.input,
            output: a.output,
            options,
            threads: a.threads.map(|t| t as usize),
        })
    }
}

/// A `--max-edge` value: a finite number > 0 (clap value parser).
fn length(s: &str) -> std::result::Result<f64, String> {
    let x: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(format!("'{s}' is not a finite length > 0"))
    }
}

/// Check that a mesh can be written to `path`: known extension, existing directory.
fn mesh_output(path: &Path) -> Result<()> {
    if super::config::output_format(path).is_none() {
        return Err(Error::invalid(
            path,
            "unknown or missing output format (expected .ply, .obj, .off or .stl)",
        ));
    }
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() && !dir.is_dir() => Err(Error::invalid(
            path,
            format!("directory '{}' does not exist", dir.display()),
        )),
        _ => Ok(()),
    }
}

/// `vcsmooth subdivide IN OUT --max-edge DELTA`.
pub fn subdivide(
    cfg: &SubdivideConfig,
    progress: &mut Progress,
    out: &mut dyn Write,
) -> Result<()> {
    progress.phase(format!("reading {}", cfg.input.display()));
    let mut mesh = io::read_mesh(&cfg.input)?;
    progress.phase("subdividing");
    let s = refine::subdivide(&mut mesh, cfg.max_edge).map_err(|e| e.in_file(&cfg.input))?;
    progress.phase(format!("writing {}", cfg.output.display()));
    io::write_mesh(&cfg.output, &mesh)?;
    progress.finish();
    writeln!(
        out,
        "{} -> {}: max edge {}: {} vertices, {} triangles -> {} vertices, {} triangles; longest edge {:.6} -> {:.6} ({} bisection passes)",
        cfg.input.display(),
        cfg.output.display(),
        cfg.max_edge,
        s.vertices_before,
        s.triangles_before,
        s.vertices_after,
        s.triangles_after,
        s.max_edge_before,
        s.max_edge_after,
        s.passes
    )
    .map_err(stdout_error)
}

/// `vcsmooth refine IN OUT --max-edge DELTA --rounds R [--iterations N] [--method M]`.
pub fn refine(cfg: &RefineConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.input.display()));
    let mut mesh = io::read_mesh(&cfg.input)?;
    let (v0, t0) = (mesh.positions.len(), mesh.triangles.len());
    let volume0 = crate::metrics::volume(&mesh.positions, &mesh.triangles);
    progress.phase(format!(
        "refining and smoothing, {} rounds",
        cfg.options.rounds
    ));
    let records = refine::refine(&mut mesh, &cfg.options, cfg.threads, progress)
        .map_err(|e| e.in_file(&cfg.input))?;
    progress.phase(format!("writing {}", cfg.output.display()));
    io::write_mesh(&cfg.output, &mesh)?;
    progress.finish();
    let volume1 = crate::metrics::volume(&mesh.positions, &mesh.triangles);
    let max_edge = records.last().map_or_else(
        || refine::max_edge_of(&mesh.positions, &mesh.triangles),
        |r| r.max_edge_smoothed,
    );
    writeln!(
        out,
        "{} -> {}: {} rounds of subdivide (max edge {}) + {} × {}: {} vertices, {} triangles -> {} vertices, {} triangles; longest edge {:.6}; volume {:.9} %",
        cfg.input.display(),
        cfg.output.display(),
        cfg.options.rounds,
        cfg.options.max_edge,
        cfg.options.smoothing.iterations,
        cfg.options.smoothing.method,
        v0,
        t0,
        mesh.positions.len(),
        mesh.triangles.len(),
        max_edge,
        pct(volume1, volume0)
    )
    .map_err(stdout_error)?;
    for r in &records {
        writeln!(
            out,
            "round {}: {} -> {} triangles, volume after subdivision {:.9} %, after smoothing {:.9} %, longest edge {:.6}",
            r.round,
            r.subdivision.triangles_before,
            r.subdivision.triangles_after,
            pct(r.volume_subdivided, r.volume_before),
            pct(r.volume_smoothed, r.volume_before),
            r.max_edge_smoothed
        )
        .map_err(stdout_error)?;
    }
    Ok(())
}

fn pct(x: f64, reference: f64) -> f64 {
    if reference == 0.0 {
        100.0
    } else {
        100.0 * x / reference
    }
}
