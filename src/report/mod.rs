//! The report model: what a run and a mesh file's statistics are, as the `vcsmooth` command
//! line writes them to JSON (`smooth --report`, `info --json`) and the Python binding returns
//! them. The renderings (tables, JSON files) belong to their front ends; the fields are a
//! contract (see the README).

use std::path::Path;

use serde::Serialize;

use crate::engine::{self, EngineSettings, IterationRecord};
use crate::io::Format;
use crate::mesh::Carried;
use crate::metrics::MeshInfo;
use crate::smooth::{Options, SweepStats};

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
    /// The SHA-256 of the file's bytes (64 hexadecimal digits), when it was taken: a run's input,
    /// read before the run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sha256: Option<String>,
    pub stats: MeshInfo,
    /// An output's: what the input carried that this file's format does not (texture
    /// coordinates, colours, normals, materials, other properties, polygons); absent when none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub dropped: Vec<String>,
}

impl FileStats {
    pub fn new(path: &Path, format: Option<Format>, stats: MeshInfo) -> Self {
        FileStats {
            path: path.display().to_string(),
            format: format.map(format_name),
            sha256: None,
            stats: undefined_as_nan(&stats),
            dropped: Vec::new(),
        }
    }
}

/// The machine a run ran on, as far as its result could depend on it (it does not: the output is
/// the same on any machine; recorded to read the timings).
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    /// Cores the process may use (its CPU affinity), and threads the run used.
    pub cores: usize,
    pub threads: usize,
    pub os: &'static str,
    pub arch: &'static str,
}

impl Machine {
    /// This machine, running `threads` threads.
    pub fn this(threads: usize) -> Machine {
        Machine {
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            threads,
            os: std::env::consts::OS,
            arch: std::env::consts::ARCH,
        }
    }
}

/// `info` with the figures that are not defined for its mesh set to NaN, which JSON writes as
/// `null` and the tables as `undefined`, and −0 as 0. The library reports them as 0: the
/// bounding box of no vertices, the mean length of no edges, the roughness (a mean over interior
/// manifold edges) of a mesh that has none.
pub fn undefined_as_nan(info: &MeshInfo) -> MeshInfo {
    let nan_if = |undefined: bool, x: f64| if undefined { f64::NAN } else { x + 0.0 };
    let no_vertex = info.vertices == 0;
    let interior = info
        .edges
        .saturating_sub(info.boundary_edges + info.non_manifold_edges);
    MeshInfo {
        volume: info.volume + 0.0,
        area: info.area + 0.0,
        bbox_min: info.bbox_min.map(|x| nan_if(no_vertex, x)),
        bbox_max: info.bbox_max.map(|x| nan_if(no_vertex, x)),
        bbox_diagonal: nan_if(no_vertex, info.bbox_diagonal),
        mean_edge_length: nan_if(info.edges == 0, info.mean_edge_length),
        roughness_deg: nan_if(interior == 0, info.roughness_deg),
        ..info.clone()
    }
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
            // `+ 0.0`: an empty sum is −0.
            seconds: records.iter().map(|r| r.seconds).sum::<f64>() + 0.0,
        }
    }

    /// [`Summary::of`] a run's records; with `--multires`, the output's volume and area as the
    /// run measured them after its final correction (the coarse levels move the mesh even when
    /// the input level runs no iteration).
    pub fn of_run(
        records: &[IterationRecord],
        multires: Option<&crate::multires::MultiresStats>,
    ) -> Summary {
        let mut s = Summary::of(records);
        if let Some(m) = multires {
            (s.volume_pct, s.area_pct) = (m.volume_pct, m.area_pct);
        }
        s
    }
}

/// Lower-case name of a format, as in file extensions.
pub fn format_name(f: Format) -> String {
    format!("{f:?}").to_ascii_lowercase()
}

/// The JSON report of `vcsmooth smooth --report FILE.json`.
#[derive(Debug, Clone, Serialize)]
pub struct SmoothReport {
    pub tool: Tool,
    /// [`crate::RESULTS_VERSION`]: the same options on the same input give the same output
    /// bytes within one results version.
    pub results_version: u32,
    pub command: &'static str,
    /// The command line as given, and the directory it ran in (its relative paths start there):
    /// run again there with the same input, it writes the same bytes.
    pub argv: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub working_directory: Option<String>,
    pub options: Options,
    pub engine: EngineSettings,
    pub input: FileStats,
    /// Statistics of the smoothed f64 positions (before the output format's rounding).
    pub output: FileStats,
    pub plan: crate::engine::PlanStats,
    pub memory: crate::engine::MemoryStats,
    pub timings: crate::engine::PhaseTimings,
    /// Bytes read from and written to the disk per phase, from `/proc/self/io`
    /// ([`crate::engine::disk`]); `null` where it cannot be read and for the cluster engine.
    pub disk: Option<crate::engine::DiskTraffic>,
    /// Ranks, halo traffic and checkpoints, for runs of the cluster engine.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster: Option<crate::engine::ClusterStats>,
    pub summary: Summary,
    /// Iterations that ran (fewer than `options.iterations` when the automatic stop ended the run).
    pub iterations_run: usize,
    /// With `--iterations auto`: what the stop rule measured and why the run ended.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub auto_stop: Option<crate::engine::AutoStopStats>,
    /// One row per iteration (with `--multires`: of the input level).
    pub iterations: Vec<IterationRecord>,
    /// Per level of `--multires`: vertices, method, iterations, seconds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub multires: Option<crate::multires::MultiresStats>,
    /// The deviation of the output (as stored) from the input, when the run measured it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub deviation: Option<crate::metrics::DeviationStats>,
    pub machine: Machine,
}

impl SmoothReport {
    /// The report of `run`, made by `argv` with `options` and `engine` from `files` (input,
    /// output); statistics the run did not measure are empty.
    pub fn new(
        argv: Vec<String>,
        options: Options,
        settings: EngineSettings,
        files: (&std::path::Path, &std::path::Path),
        run: &engine::Report,
        multires: Option<crate::multires::MultiresStats>,
    ) -> SmoothReport {
        let stats = |s: &Option<crate::metrics::MeshInfo>| s.clone().unwrap_or_default();
        SmoothReport {
            tool: Tool::this(),
            results_version: crate::RESULTS_VERSION,
            command: "smooth",
            argv,
            working_directory: std::env::current_dir()
                .ok()
                .map(|d| d.display().to_string()),
            options,
            engine: settings,
            input: FileStats::new(files.0, run.input_format, stats(&run.input_stats)),
            output: FileStats {
                dropped: run.dropped.clone(),
                ..FileStats::new(
                    files.1,
                    Format::from_extension(files.1),
                    stats(&run.output_stats),
                )
            },
            plan: run.plan.clone(),
            memory: run.memory.clone(),
            timings: run.timings,
            disk: run.disk,
            cluster: run.cluster.clone(),
            summary: Summary::of_run(&run.records, multires.as_ref()),
            iterations_run: run.iterations_run,
            auto_stop: run.auto_stop.clone(),
            iterations: run.records.clone(),
            multires,
            deviation: run.deviation.clone(),
            machine: Machine::this(run.plan.threads),
        }
    }
}

/// The JSON of `vcsmooth info --json`: the path, the format, every [`MeshInfo`] field (`null` for
/// a figure the mesh does not define, see [`undefined_as_nan`]) and `carries`, what the file
/// carries besides positions and faces (all `false` for a file whose reader kept no layout).
#[derive(Debug, Clone, Serialize)]
pub struct InfoDoc {
    pub path: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub format: Option<String>,
    #[serde(flatten)]
    pub info: MeshInfo,
    pub carries: Carried,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undefined_figures_are_nan_and_never_minus_zero() {
        let flat = MeshInfo {
            vertices: 3,
            edges: 3,
            boundary_edges: 3,
            volume: -0.0,
            ..Default::default()
        };
        let f = undefined_as_nan(&flat);
        assert!(f.roughness_deg.is_nan() && !f.mean_edge_length.is_nan());
        assert!(f.volume.is_sign_positive() && !f.bbox_diagonal.is_nan());
        let json = serde_json::to_string(&undefined_as_nan(&MeshInfo::default())).unwrap();
        assert!(json.contains("\"bbox_min\":[null,null,null]"), "{json}");
        assert!(
            json.contains("\"roughness_deg\":null") && !json.contains("-0"),
            "{json}"
        );
    }
}
