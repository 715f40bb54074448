//! What the commands print and record: the JSON report of `smooth`, the JSON documents of `info`,
//! `compare` and `curves`, and their human-readable tables.

use std::io::Write;
use std::path::Path;

use serde::Serialize;

use super::config::EngineConfig;
use super::output::stdout_error;
use crate::engine::IterationRecord;
use crate::error::Result;
use crate::io::Format;
use crate::metrics::{Comparison, MeshInfo};
use crate::smooth::{Method, Options, SweepStats};

/// The program that wrote a report.
#[derive(Debug, Clone, Serialize)]
pub struct Tool {
    pub name: &'static str,
    pub version: &'static str,
}

impl Tool {
    pub fn this() -> Tool {
        Tool {
            name: env!("CARGO_PKG_NAME"),
            version: env!("CARGO_PKG_VERSION"),
        }
    }
}

/// A mesh file and what was measured on it.
#[derive(Debug, Clone, Serialize)]
pub struct FileStats {
    pub path: String,
    /// `ply`, `obj`, `off`, `stl`; absent when unknown.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub format: Option<String>,
    pub stats: MeshInfo,
}

impl FileStats {
    pub fn new(path: &Path, format: Option<Format>, stats: MeshInfo) -> Self {
        FileStats {
            path: path.display().to_string(),
            format: format.map(format_name),
            stats,
        }
    }
}

/// Wall-clock seconds per phase of `smooth`.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Timings {
    pub read: f64,
    pub topology: f64,
    pub smoothing: f64,
    pub write: f64,
    /// Measuring input and output statistics for the report.
    pub metrics: f64,
    pub total: f64,
}

/// Totals over all iterations of a run.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Summary {
    /// Final volume and area as a percentage of the input's (100 after 0 iterations).
    pub volume_pct: f64,
    pub area_pct: f64,
    pub stencils: SweepStats,
    /// Sum of the per-iteration smoothing seconds.
    pub seconds: f64,
}

impl Summary {
    pub fn of(records: &[IterationRecord]) -> Summary {
        let mut stencils = SweepStats::default();
        for r in records {
            stencils.add(&r.stencils);
        }
        Summary {
            volume_pct: records.last().map_or(100.0, |r| r.volume_pct),
            area_pct: records.last().map_or(100.0, |r| r.area_pct),
            stencils,
            seconds: records.iter().map(|r| r.seconds).sum(),
        }
    }
}

/// The JSON report of `vcsmooth smooth --report FILE.json`.
#[derive(Debug, Clone, Serialize)]
pub struct SmoothReport {
    pub tool: Tool,
    pub command: &'static str,
    /// The command line as given.
    pub argv: Vec<String>,
    pub options: Options,
    pub engine: EngineConfig,
    pub input: FileStats,
    /// Statistics of the smoothed f64 positions (before the output format's rounding).
    pub output: FileStats,
    pub plan: crate::engine::PlanStats,
    pub memory: crate::engine::MemoryStats,
    pub timings: crate::engine::PhaseTimings,
    /// Ranks, halo traffic and checkpoints, for runs of the cluster engine.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster: Option<crate::engine::ClusterStats>,
    pub summary: Summary,
    /// One row per iteration (with `--multires`: of the input level).
    pub iterations: Vec<IterationRecord>,
    /// Per level of `--multires`: vertices, method, iterations, seconds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub multires: Option<crate::multires::MultiresStats>,
}

/// The JSON of `vcsmooth info --json`: the path, the format and every [`MeshInfo`] field.
#[derive(Debug, Clone, Serialize)]
pub struct InfoDoc {
    pub path: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub format: Option<String>,
    #[serde(flatten)]
    pub info: MeshInfo,
}

/// The JSON of `vcsmooth compare --json`.
#[derive(Debug, Clone, Serialize)]
pub struct CompareDoc {
    pub a: String,
    pub b: String,
    #[serde(flatten)]
    pub comparison: Comparison,
}

/// One method's run in `vcsmooth curves`.
#[derive(Debug, Clone, Serialize)]
pub struct CurveDoc {
    pub method: Method,
    /// Volume % at iterations 0 (100), 1, …, N.
    pub volume_pct: Vec<f64>,
    pub seconds: f64,
    pub iterations: Vec<IterationRecord>,
}

/// The JSON of `vcsmooth curves --json`.
#[derive(Debug, Clone, Serialize)]
pub struct CurvesDoc {
    pub tool: Tool,
    pub input: String,
    pub iterations: usize,
    pub lambda: f64,
    pub mu: f64,
    pub reject_energy_increase: bool,
    pub plot: String,
    pub curves: Vec<CurveDoc>,
}

/// Lower-case name of a format, as in file extensions.
pub fn format_name(f: Format) -> String {
    format!("{f:?}").to_ascii_lowercase()
}

/// Print the per-iteration table of a run.
pub fn print_iterations(out: &mut dyn Write, records: &[IterationRecord]) -> Result<()> {
    let mut text = format!(
        "{:>5} {:>12} {:>10} {:>11} {:>11} {:>10} {:>9} {:>10} {:>9} {:>9}\n",
        "iter",
        "volume %",
        "area %",
        "max disp",
        "mean disp",
        "applied",
        "fixed",
        "degenerate",
        "rejected",
        "seconds"
    );
    // Statistics not measured (`smooth --stats last`) are NaN: shown as '-'.
    let measured = |x: f64, text: String| if x.is_nan() { "-".into() } else { text };
    for r in records {
        let s = &r.stencils;
        text += &format!(
            "{:>5} {:>12} {:>10} {:>11} {:>11} {:>10} {:>9} {:>10} {:>9} {:>9.3}\n",
            r.iteration,
            measured(r.volume_pct, format!("{:.6}", r.volume_pct)),
            measured(r.area_pct, format!("{:.4}", r.area_pct)),
            measured(r.max_displacement, format!("{:.4e}", r.max_displacement)),
            measured(r.mean_displacement, format!("{:.4e}", r.mean_displacement)),
            s.applied,
            s.skipped_fixed,
            s.skipped_degenerate,
            s.rejected,
            r.seconds
        );
    }
    out.write_all(text.as_bytes()).map_err(stdout_error)
}

/// Print `info` as aligned `key  value` lines.
pub fn print_info(out: &mut dyn Write, doc: &InfoDoc) -> Result<()> {
    let i = &doc.info;
    let mut rows: Vec<(&str, String)> = vec![("file", doc.path.clone())];
    if let Some(f) = &doc.format {
        rows.push(("format", f.clone()));
    }
    rows.push(("vertices", i.vertices.to_string()));
    let faces = if i.polygons_triangulated > 0 {
        format!(
            "{} triangles from {} ({} fan-triangulated)",
            i.triangles,
            count(i.input_faces, "input face"),
            count(i.polygons_triangulated, "polygon")
        )
    } else {
        format!("{} triangles", i.triangles)
    };
    rows.push(("faces", faces));
    rows.push(("edges", i.edges.to_string()));
    rows.push(("boundary edges", i.boundary_edges.to_string()));
    rows.push(("non-manifold edges", i.non_manifold_edges.to_string()));
    rows.push(("non-manifold vertices", i.non_manifold_vertices.to_string()));
    rows.push(("degenerate triangles", i.degenerate_triangles.to_string()));
    rows.push(("components", i.components.to_string()));
    rows.push(("unreferenced vertices", i.unreferenced_vertices.to_string()));
    rows.push(("closed", if i.closed { "yes" } else { "no" }.to_string()));
    rows.push(("signed volume", num(i.volume)));
    rows.push(("area", num(i.area)));
    rows.push(("bbox min", vec3(i.bbox_min)));
    rows.push(("bbox max", vec3(i.bbox_max)));
    rows.push(("bbox diagonal", num(i.bbox_diagonal)));
    rows.push(("mean edge length", num(i.mean_edge_length)));
    rows.push((
        "roughness",
        format!("{:.4} deg (mean dihedral angle)", i.roughness_deg),
    ));
    print_rows(out, &rows)
}

/// Print a comparison as aligned `key  value` lines.
pub fn print_comparison(out: &mut dyn Write, doc: &CompareDoc) -> Result<()> {
    let c = &doc.comparison;
    let rows: Vec<(&str, String)> = vec![
        ("a", doc.a.clone()),
        ("b", doc.b.clone()),
        (
            "rms distance",
            format!(
                "{} ({} of the bbox diagonal of a)",
                num(c.rms_distance),
                num(c.rms_relative)
            ),
        ),
        (
            "max distance",
            format!(
                "{} ({} of the bbox diagonal of a)",
                num(c.max_distance),
                num(c.max_relative)
            ),
        ),
        (
            "mean normal angle",
            format!("{:.6} deg", c.mean_normal_angle_deg),
        ),
        ("volume ratio b/a", format!("{:.9}", c.volume_ratio)),
        ("area ratio b/a", format!("{:.9}", c.area_ratio)),
    ];
    print_rows(out, &rows)
}

/// Print the iteration × method table of volume percentages.
pub fn print_curves(out: &mut dyn Write, doc: &CurvesDoc) -> Result<()> {
    let mut text = format!("{:>5}", "iter");
    for c in &doc.curves {
        text += &format!(" {:>14}", format!("{} %", c.method.name()));
    }
    text.push('\n');
    for it in 0..=doc.iterations {
        text += &format!("{it:>5}");
        for c in &doc.curves {
            match c.volume_pct.get(it) {
                Some(v) => text += &format!(" {v:>14.6}"),
                None => text += &format!(" {:>14}", "-"),
            }
        }
        text.push('\n');
    }
    text += &format!("{:>5}", "secs");
    for c in &doc.curves {
        text += &format!(" {:>14.3}", c.seconds);
    }
    text.push('\n');
    out.write_all(text.as_bytes()).map_err(stdout_error)
}

fn vec3(v: [f64; 3]) -> String {
    format!("{} {} {}", num(v[0]), num(v[1]), num(v[2]))
}

/// `n word` or `n words`.
pub fn count(n: usize, word: &str) -> String {
    if n == 1 {
        format!("1 {word}")
    } else {
        format!("{n} {word}s")
    }
}

/// A number for people: 9 significant digits, fixed-point between 1e-3 and 1e7, else scientific.
fn num(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || !x.is_finite() {
        format!("{x}")
    } else if (1e-3..1e7).contains(&a) {
        let decimals = (8 - a.log10().floor() as i32).clamp(0, 11) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.8e}")
    }
}

fn print_rows(out: &mut dyn Write, rows: &[(&str, String)]) -> Result<()> {
    let width = rows.iter().map(|(k, _)| k.len()).max().unwrap_or(0);
    let mut text = String::new();
    for (k, v) in rows {
        text += &format!("{k:<width$}  {v}\n");
    }
    out.write_all(text.as_bytes()).map_err(stdout_error)
}

#[cfg(test)]
mod tests {
    use super::num;

    #[test]
    fn numbers_for_people() {
        assert_eq!(num(4.186713092382924), "4.18671309");
        assert_eq!(num(-1.07786905), "-1.07786905");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(123456.789), "123456.789");
        assert_eq!(num(2.5e-7), "2.50000000e-7");
    }
}

/// The JSON of `vcsmooth bench --json`: the tool and every figure of [`crate::modes::bench::BenchReport`].
#[derive(Debug, Clone, Serialize)]
pub struct BenchDoc {
    pub tool: Tool,
    #[serde(flatten)]
    pub report: crate::modes::bench::BenchReport,
}

/// Print the tables of `vcsmooth bench`: per size (PLY I/O, memory), per thread count (plan), per
/// method (throughput).
pub fn print_bench(out: &mut dyn Write, r: &crate::modes::bench::BenchReport) -> Result<()> {
    use crate::engine::memory::format_size;
    let s = &r.settings;
    let load = r.machine.load_average.map_or(String::from("unknown"), |l| {
        format!("{:.2} {:.2} {:.2}", l[0], l[1], l[2])
    });
    let mut t = format!(
        "noisy icospheres (noise {} × mean edge), {} × {} (median); {} cores, load average {load}\n\n",
        crate::modes::bench::NOISE,
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
                    "{:<8} {:>7} {:<13} {:>12} {:>13} {:>12} {:>12.6}\n",
                    z.label,
                    run.threads,
                    m.method.name(),
                    sig(m.seconds_per_iteration),
                    sig(m.triangles_per_second / 1e6),
                    stencils,
                    m.volume_pct
                );
            }
        }
    }
    t += &format!("\n{} s in all\n", sig(r.seconds));
    out.write_all(t.as_bytes()).map_err(stdout_error)
}

/// A measurement with 4 significant digits in fixed point (at most 9 decimals).
fn sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let decimals = (3 - x.abs().log10().floor() as i32).clamp(0, 9) as usize;
    format!("{x:.decimals$}")
}
