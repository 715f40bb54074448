//! `vcsmooth subdivide IN OUT --max-edge DELTA`: the paper's adaptive subdivision (§4), through
//! [`crate::modes::refine`]. It reads the whole mesh, works in memory and writes the result
//! atomically only when everything succeeded.

use std::io::Write;
use std::path::PathBuf;

use clap::Args as ClapArgs;

use crate::cli::output::{check_files, refined_mesh_output, stdout_error};
use crate::cli::progress::Progress;
use crate::cli::shared::{InOut, length};
use crate::error::Result;
use crate::io;
use crate::modes::refine;

/// `vcsmooth subdivide IN OUT --max-edge DELTA`
#[derive(Debug, Clone, ClapArgs)]
pub struct SubdivideArgs {
    #[command(flatten)]
    pub files: InOut,
    /// δ: split triangles (conforming longest-edge bisection) until no edge is longer than this; new vertices lie on the input's triangles.
    #[arg(long, value_name = "DELTA", allow_hyphen_values = true, value_parser = length)]
    pub max_edge: f64,
}

/// `vcsmooth subdivide`, resolved.
#[derive(Debug, Clone)]
pub struct SubdivideConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub max_edge: f64,
}

impl SubdivideConfig {
    pub fn from_args(a: SubdivideArgs) -> Result<SubdivideConfig> {
        refine::check_max_edge(a.max_edge)?;
        refined_mesh_output(&a.files.output)?;
        check_files(&[("IN", &a.files.input)], &[("OUT", &a.files.output)])?;
        Ok(SubdivideConfig {
            input: a.files.input,
            output: a.files.output,
            max_edge: a.max_edge,
        })
    }
}

/// `vcsmooth subdivide`.
pub fn run(cfg: &SubdivideConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
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
