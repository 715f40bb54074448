//! `vcsmooth subdivide IN OUT --max-edge DELTA`: the paper's adaptive subdivision (§4), through
//! [`crate::modes::refine`]. It reads the whole mesh, works in memory and writes the result
//! atomically only when everything succeeded.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args as ClapArgs;

use crate::cli::output::stdout_error;
use crate::cli::progress::Progress;
use crate::cli::shared::{InOut, length};
use crate::engine::memory;
use crate::error::{Error, Result};
use crate::io;
use crate::mesh::{Carried, Mesh};
use crate::modes::refine;

/// `vcsmooth subdivide IN OUT --max-edge DELTA`
#[derive(Debug, Clone, ClapArgs)]
pub struct SubdivideArgs {
    #[command(flatten)]
    pub files: InOut,
    /// δ: split triangles (conforming longest-edge bisection) until no edge is longer than this; new vertices lie on the input's triangles.
    #[arg(long, value_name = "DELTA", allow_hyphen_values = true, value_parser = length)]
    pub max_edge: f64,
    /// Memory allowed, with K/M/G/T suffixes (binary units): a δ whose output, estimated from above from the edge lengths, would need more is refused before any work [default: 3/4 of the available memory, or less under a cgroup limit or ulimit].
    #[arg(long, value_name = "SIZE", value_parser = memory::parse_size)]
    pub memory_budget: Option<u64>,
}

/// `vcsmooth subdivide`, resolved.
#[derive(Debug, Clone)]
pub struct SubdivideConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub max_edge: f64,
    pub budget: memory::Budget,
}

impl SubdivideConfig {
    pub fn from_args(a: SubdivideArgs) -> Result<SubdivideConfig> {
        a.files.check_refined(a.max_edge)?;
        Ok(SubdivideConfig {
            input: a.files.input,
            output: a.files.output,
            max_edge: a.max_edge,
            budget: memory::budget_or_default(a.memory_budget)?,
        })
    }
}

/// `vcsmooth subdivide`.
pub fn run(cfg: &SubdivideConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.input.display()));
    let mut mesh = io::read_mesh(&cfg.input)?;
    check_memory(&mesh, cfg.max_edge, cfg.budget, &cfg.output, "")?;
    progress.phase("subdividing");
    let carried = carried(&mesh);
    let s = refine::subdivide(&mut mesh, cfg.max_edge).map_err(|e| e.in_file(&cfg.input))?;
    progress.phase(format!("writing {}", cfg.output.display()));
    io::write_mesh(&cfg.output, &mesh)?;
    // Said once the output is there: a refused write is one line.
    note_dropped(&cfg.input, &carried, &mesh);
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

/// Refuse, before it allocates anything, a subdivision of `mesh` to `max_edge` whose output
/// ([`refine::estimate_triangles`], an estimate from above) the budget cannot hold; `round` is
/// prefixed to the problem (`refine`'s later rounds). A δ beyond [`refine::MAX_TRIANGLES`] is left
/// to [`refine::subdivide`], which refuses it by that limit.
pub(crate) fn check_memory(
    mesh: &Mesh,
    max_edge: f64,
    budget: memory::Budget,
    output: &Path,
    round: &str,
) -> Result<()> {
    if refine::triangles_at_least(mesh, max_edge) > refine::MAX_TRIANGLES as f64 {
        return Ok(());
    }
    let triangles = refine::estimate_triangles(mesh, max_edge);
    // The smoothing of `refine` needs less per triangle than the subdivision; the larger counts.
    let need =
        memory::subdivide_bytes(triangles as u64).max(memory::in_core_bytes(triangles as u64));
    let what = format!("about {triangles:.3e} triangles");
    memory::check_fits(&what, need, budget).map_err(|e| {
        Error::resource(format!(
            "{}: {round}--max-edge {max_edge}: {e}; choose a larger --max-edge or raise --memory-budget",
            output.display(),
        ))
    })
}

/// What `mesh`'s source layout carries besides positions and faces.
pub(crate) fn carried(mesh: &Mesh) -> Carried {
    mesh.source
        .layout
        .as_ref()
        .map(|l| l.carries())
        .unwrap_or_default()
}

/// One `vcsmooth: note:` line on stderr naming what `before` carried and `mesh` (subdivided) no
/// longer does: the properties a subdivision could not give its new vertices and faces
/// ([`crate::mesh::FileLayout::subdivided`]). Nothing when nothing was dropped.
pub(crate) fn note_dropped(input: &Path, before: &Carried, mesh: &Mesh) {
    let after = carried(mesh);
    let mut dropped: Vec<String> = [
        (before.colours && !after.colours, "colours"),
        (before.uvs && !after.uvs, "texture coordinates"),
        (before.normals && !after.normals, "normals"),
        (before.materials && !after.materials, "materials"),
    ]
    .iter()
    .filter(|(lost, _)| *lost)
    .map(|(_, what)| what.to_string())
    .collect();
    dropped.extend(
        before
            .other
            .iter()
            .filter(|o| !after.other.contains(o))
            .cloned(),
    );
    if !dropped.is_empty() {
        // Not `eprintln!`: stderr may be a closed pipe, and this must not panic.
        let _ = writeln!(
            std::io::stderr(),
            "vcsmooth: note: {}: subdivision dropped {}: only a PLY input's properties are interpolated at new vertices",
            input.display(),
            dropped.join(", ")
        );
    }
}
