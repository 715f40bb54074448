//! `vcsmooth bench [--sizes ...] [--methods ...] [--threads ...] [--iterations N] [--repeats R]
//! [--json]`: throughput on generated meshes (see [`crate::modes::bench`]), as tables or JSON.

use std::io::Write;
use std::path::PathBuf;

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cli::output::{print_json, stdout_error};
use crate::cli::progress::Progress;
use crate::cli::report::{count, fixed};
use crate::cli::shared::{MAX_THREADS, distinct};
use crate::engine::memory::format_size;
use crate::error::Result;
use crate::modes::bench::{self as core, BenchReport, BenchSettings};
use crate::report::Tool;
use crate::smooth::Method;

/// The long help of `vcsmooth bench`.
pub const BENCH_ABOUT: &str = "\
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

Example: vcsmooth bench --sizes 1M,4M --threads 1,2 --json";

/// `vcsmooth bench [--sizes ...] [--methods ...] [--threads ...] [--iterations N] [--repeats R] [--json]`
#[derive(Debug, Clone, ClapArgs)]
pub struct BenchArgs {
    /// Comma-separated mesh sizes: triangle counts (decimal K/M/G suffixes), each mapped to the icosphere level with the nearest triangle count (1M → level 8, 1.31M triangles; 4M → level 9, 5.24M), or icoK for level K exactly.
    #[arg(long, value_name = "SIZE,...", value_delimiter = ',', default_value = "1M",
          value_parser = core::parse_size)]
    pub sizes: Vec<core::SizeSpec>,
    /// Comma-separated methods to time.
    #[arg(long, value_enum, value_delimiter = ',', value_name = "M,M,...",
          default_values_t = Method::BENCH)]
    pub methods: Vec<Method>,
    /// Comma-separated thread counts, each 1 to 4096 [default: 1 and all cores].
    #[arg(long, value_name = "N,...", value_delimiter = ',', allow_negative_numbers = true,
          value_parser = clap::value_parser!(u32).range(1..=MAX_THREADS as i64))]
    pub threads: Vec<u32>,
    /// Iterations per smoothing run.
    #[arg(long, value_name = "N", default_value_t = 3, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub iterations: u32,
    /// Repeats of every timing; the median is reported.
    #[arg(long, value_name = "R", default_value_t = 3, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeats: u32,
    /// Vertices per patch [default: 16384].
    #[arg(long, value_name = "VERTICES", allow_negative_numbers = true, value_parser = crate::cli::shared::whole_in(1, u32::MAX as u64 - 1))]
    pub patch_size: Option<u64>,
    /// Directory for the temporary PLY file (a tmpfs such as /dev/shm leaves out the disk's fsync) [default: the system's temporary directory].
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Print JSON instead of a table [default: table].
    #[arg(long)]
    pub json: bool,
}

/// `vcsmooth bench`, resolved.
#[derive(Debug, Clone)]
pub struct BenchConfig {
    pub settings: BenchSettings,
    pub json: bool,
}

impl BenchConfig {
    pub fn from_args(a: BenchArgs) -> Result<BenchConfig> {
        let defaults = BenchSettings::default();
        let threads = distinct(a.threads.into_iter().map(|t| t as usize));
        let settings = BenchSettings {
            sizes: core::normalize_sizes(a.sizes),
            methods: distinct(a.methods),
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
        core::check(&settings)?;
        Ok(BenchConfig {
            settings,
            json: a.json,
        })
    }
}

/// The JSON of `vcsmooth bench --json`: the tool and every figure of [`BenchReport`].
#[derive(Debug, Clone, Serialize)]
pub struct BenchDoc {
    pub tool: Tool,
    #[serde(flatten)]
    pub report: BenchReport,
}

/// `vcsmooth bench`.
pub fn run(cfg: &BenchConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    let report = core::run(&cfg.settings, &mut |m| progress.phase(m))?;
    progress.finish();
    if cfg.json {
        let doc = BenchDoc {
            tool: Tool::this(),
            report,
        };
        print_json(out, &doc)
    } else {
        print_bench(out, &report)
    }
}

/// Print the tables of `vcsmooth bench`: per size (PLY I/O, memory), per thread count (plan), per
/// method (throughput).
fn print_bench(out: &mut dyn Write, r: &BenchReport) -> Result<()> {
    let s = &r.settings;
    let load = r.machine.load_average.map_or(String::from("unknown"), |l| {
        format!("{:.2} {:.2} {:.2}", l[0], l[1], l[2])
    });
    let mut t = format!(
        "noisy icospheres (noise {} × mean edge), {} × {} (median); {} cores, load average {load}\n\n",
        core::NOISE,
        count(s.iterations, "iteration"),
        count(s.repeats, "repeat"),
        r.machine.cores,
    );
    t += &format!(
        "{:<8} {:>5} {:>10} {:>10} {:>9} {:>10} {:>10} {:>11} {:>8}\n",
        "size",
        "level",
        "vertices",
        "triangles",
        "PLY MB",
        "write GB/s",
        "read GB/s",
        "peak anon",
        "B/tri"
    );
    for z in &r.sizes {
        t += &format!(
            "{:<8} {:>5} {:>10} {:>10} {:>9} {:>10} {:>10} {:>11} {:>8.1}\n",
            z.label,
            z.level,
            z.vertices,
            z.triangles,
            sig(z.ply.file_bytes as f64 / 1e6),
            sig(z.ply.write_gb_per_second),
            sig(z.ply.read_gb_per_second),
            format_size(z.memory.peak_anon),
            z.memory.anon_bytes_per_triangle
        );
    }
    t += &format!(
        "\n{:<8} {:>7} {:>7} {:>7} {:>10} {:>9} {:>9} {:>9}\n",
        "size", "threads", "patches", "colours", "prepare s", "reorder", "topology", "partition"
    );
    for z in &r.sizes {
        for run in &z.runs {
            let p = &run.prepare;
            t += &format!(
                "{:<8} {:>7} {:>7} {:>7} {:>10} {:>9} {:>9} {:>9}\n",
                z.label,
                run.threads,
                run.patches,
                run.colours,
                sig(p.total_seconds),
                sig(p.reorder_seconds),
                sig(p.topology_seconds),
                sig(p.partition_seconds)
            );
        }
    }
    t += &format!(
        "\n{:<8} {:>7} {:<13} {:>12} {:>13} {:>12} {:>12}\n",
        "size", "threads", "method", "s/iteration", "Mtriangles/s", "Mstencils/s", "volume %"
    );
    for z in &r.sizes {
        for run in &z.runs {
            for m in &run.methods {
                let stencils = m
                    .stencils_per_second
                    .map_or(String::from("-"), |x| sig(x / 1e6));
                t += &format!(
                    "{:<8} {:>7} {:<13} {:>12} {:>13} {:>12} {:>12}\n",
                    z.label,
                    run.threads,
                    m.method.name(),
                    sig(m.seconds_per_iteration),
                    sig(m.triangles_per_second / 1e6),
                    stencils,
                    fixed(m.volume_pct, 6)
                );
            }
        }
    }
    t += &format!("\n{} s in all\n", sig(r.seconds));
    out.write_all(t.as_bytes()).map_err(stdout_error)
}

/// A measurement with 4 significant digits in fixed point (at most 9 decimals).
fn sig(x: f64) -> String {
    if !x.is_finite() {
        return crate::cli::report::UNDEFINED.to_string();
    }
    if x == 0.0 {
        return "0".to_string();
    }
    let decimals = (3 - x.abs().log10().floor() as i32).clamp(0, 9) as usize;
    format!("{x:.decimals$}")
}
