//! `vcsmooth refine IN OUT --max-edge DELTA --rounds R ...`: the paper's refine-and-smooth workflow
//! (Figs. 5–7), through [`crate::modes::refine`]. It reads the whole mesh, works in memory and
//! writes the result atomically only when everything succeeded.

use std::io::Write;
use std::path::PathBuf;

use clap::Args as ClapArgs;

use crate::cli::commands::subdivide::check_memory;
use crate::cli::output::stdout_error;
use crate::cli::progress::Progress;
use crate::cli::report::{percent_of, percent_text};
use crate::cli::shared::{InOut, MAX_THREADS, length};
use crate::engine::memory;
use crate::error::Result;
use crate::io;
use crate::mesh::Mesh;
use crate::modes::refine::{self, RefineOptions};
use crate::smooth::Method;

/// `vcsmooth refine IN OUT --max-edge DELTA --rounds R [--iterations N] [--method M] [--threads T] [--memory-budget SIZE]`
#[derive(Debug, Clone, ClapArgs)]
pub struct RefineArgs {
    #[command(flatten)]
    pub files: InOut,
    /// δ of every subdivision (see `subdivide`).
    #[arg(long, value_name = "DELTA", allow_hyphen_values = true, value_parser = length)]
    pub max_edge: f64,
    /// Rounds of subdivide-then-smooth (the paper's Figs. 5–7 show two after a first smoothing).
    #[arg(long, value_name = "R", allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub rounds: u32,
    /// Smoothing iterations after each subdivision.
    #[arg(long, value_name = "N", default_value_t = 5, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(0..=100_000))]
    pub iterations: u32,
    /// Smoothing method (the paper uses vcs, Fig. 5, and vcs-triangle, Fig. 6).
    #[arg(long, value_enum, default_value_t = Method::REFINE)]
    pub method: Method,
    /// Worker threads of the smoothing, 1 to 4096 [default: all cores].
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=MAX_THREADS as i64))]
    pub threads: Option<u32>,
    /// Memory allowed, with K/M/G/T suffixes (binary units): a round whose subdivision, estimated from above from the edge lengths, would need more is refused before it starts (the first before any work) [default: 3/4 of the available memory, or less under a cgroup limit or ulimit].
    #[arg(long, value_name = "SIZE", value_parser = memory::parse_size)]
    pub memory_budget: Option<u64>,
}

/// `vcsmooth refine`, resolved.
#[derive(Debug, Clone)]
pub struct RefineConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub options: RefineOptions,
    pub threads: Option<usize>,
    pub budget: memory::Budget,
}

impl RefineConfig {
    pub fn from_args(a: RefineArgs) -> Result<RefineConfig> {
        a.files.check_refined(a.max_edge)?;
        let mut options = RefineOptions {
            max_edge: a.max_edge,
            rounds: a.rounds as usize,
            ..Default::default()
        };
        options.smoothing.method = a.method;
        options.smoothing.iterations = a.iterations as usize;
        options.smoothing.check()?;
        Ok(RefineConfig {
            input: a.files.input,
            output: a.files.output,
            options,
            threads: a.threads.map(|t| t as usize),
            budget: memory::budget_or_default(a.memory_budget)?,
        })
    }
}

/// `vcsmooth refine`.
pub fn run(cfg: &RefineConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.input.display()));
    let mut mesh = io::read_mesh(&cfg.input)?;
    let (v0, t0) = (mesh.positions.len(), mesh.triangles.len());
    // Every volume about the input's centroid: an open mesh's depends on the point.
    let origin = crate::metrics::centroid(&mesh.positions);
    let volume0 = crate::metrics::volume_about(&mesh.positions, &mesh.triangles, origin);
    progress.phase(format!(
        "refining and smoothing, {} rounds",
        cfg.options.rounds
    ));
    // Every round's output is built in memory: its size is checked before the round starts.
    let mut check = |round: usize, m: &Mesh| {
        let prefix = if round > 1 {
            format!("round {round}: ")
        } else {
            String::new()
        };
        check_memory(m, cfg.options.max_edge, cfg.budget, &cfg.output, &prefix)
    };
    let carried = super::subdivide::carried(&mesh);
    let records =
        refine::refine_checked(&mut mesh, &cfg.options, cfg.threads, progress, &mut check)
            .map_err(|e| e.in_file(&cfg.input))?;
    progress.phase(format!("writing {}", cfg.output.display()));
    io::write_mesh(&cfg.output, &mesh)?;
    // Said once the output is there: a refused write is one line.
    super::subdivide::note_dropped(&cfg.input, &carried, &mesh);
    progress.finish();
    let volume1 = crate::metrics::volume_about(&mesh.positions, &mesh.triangles, origin);
    let max_edge = records.last().map_or_else(
        || refine::max_edge_of(&mesh.positions, &mesh.triangles),
        |r| r.max_edge_smoothed,
    );
    writeln!(
        out,
        "{} -> {}: {} rounds of subdivide (max edge {}) + {} × {}: {} vertices, {} triangles -> {} vertices, {} triangles; longest edge {:.6}; volume {}",
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
        volume_pct(volume1, volume0)
    )
    .map_err(stdout_error)?;
    for r in &records {
        writeln!(
            out,
            "round {}: {} -> {} triangles, volume after subdivision {}, after smoothing {}, longest edge {:.6}",
            r.round,
            r.subdivision.triangles_before,
            r.subdivision.triangles_after,
            volume_pct(r.volume_subdivided, r.volume_before),
            volume_pct(r.volume_smoothed, r.volume_before),
            r.max_edge_smoothed
        )
        .map_err(stdout_error)?;
    }
    Ok(())
}

/// `volume` as `12.345678901 %` of `reference`, or [`UNDEFINED`] when the reference is 0 (an open
/// or flat mesh).
fn volume_pct(volume: f64, reference: f64) -> String {
    percent_text(percent_of(volume, reference), 9)
}
