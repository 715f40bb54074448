//! End-to-end throughput on generated meshes: the library side of `vcsmooth bench`.
//!
//! For each requested size (an icosphere level, see [`parse_size`]), smallest first, [`run`]:
//!
//! 1. generates a unit icosphere with Gaussian noise along the normals (σ = [`NOISE`] × the mean
//!    edge length, seed 1), so that the stencils see a realistic noisy scan rather than an exact
//!    sphere;
//! 2. writes it as binary little-endian PLY into a temporary file and reads it back, `repeats`
//!    times each: write and read GB/s (10⁹ bytes per second) of the median times. The write is
//!    [`io::write_mesh`] as `smooth` uses it: atomic, so it includes an `fsync` (use a tmpfs such
//!    as `/dev/shm` as the directory to measure the encoder and the page cache alone); the read
//!    comes from the page cache (the file was just written);
//! 3. for each thread count: builds the plan ([`Plan::new`]: reorder, topology, partition and
//!    schedule) `repeats` times (median), then for each method runs `repeats` smoothing runs of
//!    `iterations` iterations from the same noisy positions. Seconds per iteration are the median
//!    over all iterations of all repeats of [`IterationRecord::seconds`] (the sweep alone, without
//!    the per-iteration volume and area statistics); triangles per second and stencils per second
//!    (edge or triangle stencils considered, for the stencil methods) follow from it;
//! 4. samples the process's anonymous memory (`RssAnon`) throughout, from just after generation
//!    to the end of the size's runs: the peak, and the peak above the process's anonymous memory
//!    when [`run`] began, per triangle. That figure covers the mesh, the plan and the smoothing
//!    buffers, as an in-core `smooth` run holds them. Sizes run smallest first so that memory
//!    freed by a smaller size but kept by the allocator cannot inflate a larger size's figure.
//!
//! [`IterationRecord::seconds`]: crate::engine::IterationRecord

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::engine::{self, Layout, Plan, Quiet, Statistics, memory};
use crate::error::{Error, Result};
use crate::io;
use crate::mesh::{Mesh, Storage};
use crate::shapes;
use crate::smooth::{Method, Options};

/// Noise of the generated meshes, × the mean edge length.
pub const NOISE: f64 = 0.3;

/// One requested mesh size: an icosphere level.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SizeSpec {
    /// The size as the user wrote it (`1M`, `ico8`, …).
    pub label: String,
    /// Icosphere subdivision level.
    pub level: u32,
    /// Triangles at that level: `20·4^level`.
    pub triangles: u64,
}

/// Triangles of the icosphere at `level`: `20·4^level`.
pub fn icosphere_triangles(level: u32) -> u64 {
    20u64 << (2 * level)
}

/// Parse one size: `icoK` (icosphere level K exactly, 20·4^K triangles) or a triangle count with
/// an optional decimal suffix `K` (10³), `M` (10⁶) or `G` (10⁹), e.g. `1M`, `4M`, `250K`, `1.5M`,
/// `80000`. A count maps to the icosphere level whose triangle count is nearest on a logarithmic
/// scale: `1M` → level 8 (1 310 720 triangles), `4M` → level 9 (5 242 880), `100K` → level 6
/// (81 920), `1K` → level 3 (1 280).
pub fn parse_size(s: &str) -> std::result::Result<SizeSpec, String> {
    let t = s.trim();
    let max = shapes::ICOSPHERE_MAX_SUBDIVISIONS;
    let lower = t.to_ascii_lowercase();
    if let Some(level) = lower.strip_prefix("ico") {
        let level: u32 = level
            .parse()
            .map_err(|_| format!("'{s}': expected icoK with K a level 0..={max}, e.g. ico8"))?;
        if level > max {
            return Err(format!(
                "'{s}': icosphere level {level} exceeds the maximum of {max}"
            ));
        }
        return Ok(SizeSpec {
            label: t.to_string(),
            level,
            triangles: icosphere_triangles(level),
        });
    }
    let (num, mult) = match lower.chars().last() {
        Some('k') => (&t[..t.len() - 1], 1e3),
        Some('m') => (&t[..t.len() - 1], 1e6),
        Some('g') => (&t[..t.len() - 1], 1e9),
        _ => (t, 1.0),
    };
    let bad = || format!("'{s}' is not a size: use a triangle count such as 1M, 4M, 250K, or icoK");
    let x: f64 = num.trim().parse().map_err(|_| bad())?;
    let n = x * mult;
    if !n.is_finite() || n < 1.0 {
        return Err(bad());
    }
    let largest = icosphere_triangles(max) as f64;
    if n > largest * 2.0 {
        return Err(format!(
            "'{s}' is too large: the largest icosphere (level {max}) has {} triangles",
            icosphere_triangles(max)
        ));
    }
    let distance = |k: u32| (icosphere_triangles(k) as f64 / n).ln().abs();
    let level = (0..=max)
        .min_by(|&a, &b| distance(a).total_cmp(&distance(b)))
        .unwrap_or(0);
    Ok(SizeSpec {
        label: t.to_string(),
        level,
        triangles: icosphere_triangles(level),
    })
}

/// Keep one size per level, smallest first (the order [`run`] needs for its memory figures).
pub fn normalize_sizes(mut sizes: Vec<SizeSpec>) -> Vec<SizeSpec> {
    sizes.sort_by_key(|s| s.level);
    sizes.dedup_by_key(|s| s.level);
    sizes
}

/// What [`run`] measures.
#[derive(Debug, Clone, Serialize)]
pub struct BenchSettings {
    /// Sizes, smallest first, one per level (see [`normalize_sizes`]).
    pub sizes: Vec<SizeSpec>,
    pub methods: Vec<Method>,
    /// Thread counts, each ≥ 1.
    pub threads: Vec<usize>,
    /// Iterations per smoothing run (≥ 1).
    pub iterations: usize,
    /// Repeats of every timing; the median is reported (≥ 1).
    pub repeats: usize,
    pub patch_size: usize,
    /// Directory of the temporary PLY file.
    pub dir: PathBuf,
}

impl Default for BenchSettings {
    fn default() -> Self {
        BenchSettings {
            sizes: vec![parse_size("1M").expect("valid size")],
            methods: Method::BENCH.to_vec(),
            threads: default_threads(),
            iterations: 3,
            repeats: 3,
            patch_size: engine::DEFAULT_PATCH_SIZE,
            dir: std::env::temp_dir(),
        }
    }
}

impl BenchSettings {
    /// The options `method` is timed with: its defaults, `iterations` of them.
    pub fn options(&self, method: Method) -> Options {
        Options {
            method,
            iterations: self.iterations,
            ..Default::default()
        }
    }
}

/// One thread, and all cores (just `[1]` on one core).
pub fn default_threads() -> Vec<usize> {
    let cores = cores();
    if cores > 1 { vec![1, cores] } else { vec![1] }
}

fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Everything [`run`] measured.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub machine: Machine,
    pub settings: BenchSettings,
    pub sizes: Vec<SizeResult>,
    /// Wall-clock seconds of the whole benchmark.
    pub seconds: f64,
}

/// The machine the figures come from.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    /// Logical cores available to the process.
    pub cores: usize,
    /// `MemAvailable` when the run began, bytes (absent where unknown).
    pub mem_available: Option<u64>,
    /// 1, 5 and 15-minute load averages when the run began (absent where unknown): a loaded
    /// machine gives lower figures.
    pub load_average: Option<[f64; 3]>,
}

impl Machine {
    fn now() -> Machine {
        Machine {
            cores: cores(),
            mem_available: memory::mem_available(),
            load_average: load_average(),
        }
    }
}

fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = text.split_whitespace().map(|w| w.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

/// The figures of one size.
#[derive(Debug, Clone, Serialize)]
pub struct SizeResult {
    pub label: String,
    pub level: u32,
    pub vertices: usize,
    pub triangles: usize,
    /// Seconds to generate the noisy icosphere.
    pub generate_seconds: f64,
    pub ply: PlyResult,
    pub memory: MemoryResult,
    /// One entry per thread count.
    pub runs: Vec<ThreadRun>,
}

/// Binary little-endian PLY write and read of the generated mesh (median times).
#[derive(Debug, Clone, Serialize)]
pub struct PlyResult {
    pub file_bytes: u64,
    /// Atomic write, `fsync` included.
    pub write_seconds: f64,
    pub write_gb_per_second: f64,
    /// Read from the page cache.
    pub read_seconds: f64,
    pub read_gb_per_second: f64,
}

/// Anonymous memory (`RssAnon`) of the process while a size ran.
#[derive(Debug, Clone, Serialize)]
pub struct MemoryResult {
    /// When the benchmark began.
    pub baseline_anon: u64,
    /// The largest value while this size ran.
    pub peak_anon: u64,
    /// `(peak − baseline) / triangles`: what an in-core run of this mesh holds per triangle.
    pub anon_bytes_per_triangle: f64,
}

/// The runs of one size on one thread count.
#[derive(Debug, Clone, Serialize)]
pub struct ThreadRun {
    pub threads: usize,
    pub patches: usize,
    pub colours: usize,
    /// The preparation with the median total time.
    pub prepare: PrepareResult,
    pub methods: Vec<MethodResult>,
}

/// Seconds of the plan's phases.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct PrepareResult {
    pub reorder_seconds: f64,
    pub topology_seconds: f64,
    /// Patches and their colouring.
    pub partition_seconds: f64,
    pub total_seconds: f64,
}

/// Smoothing throughput of one method.
#[derive(Debug, Clone, Serialize)]
pub struct MethodResult {
    pub method: Method,
    /// Median seconds of one iteration (see the module documentation).
    pub seconds_per_iteration: f64,
    pub triangles_per_second: f64,
    /// Stencils considered per iteration (stencil methods only: edges for `lem` and `vcs`,
    /// triangles for `vcs-triangle`).
    pub stencils_per_iteration: Option<u64>,
    pub stencils_per_second: Option<f64>,
    /// Volume after the last iteration of a run, % of the input's.
    pub volume_pct: f64,
}

/// The median of `xs` (mean of the two middle values for an even count; 0 for none).
pub fn median(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return 0.0;
    }
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        (v[m - 1] + v[m]) / 2.0
    }
}

/// Check settings before any work: non-empty lists, counts ≥ 1, an existing directory, and enough
/// available memory for the largest size.
pub fn check(settings: &BenchSettings) -> Result<()> {
    for (name, empty) in [
        ("sizes", settings.sizes.is_empty()),
        ("methods", settings.methods.is_empty()),
        ("threads", settings.threads.is_empty()),
    ] {
        if empty {
            return Err(Error::parameter(name, "must name at least one value"));
        }
    }
    for &method in &settings.methods {
        settings.options(method).check()?;
    }
    if settings.threads.contains(&0) {
        return Err(Error::parameter("threads", "must be at least 1"));
    }
    for (name, n) in [
        ("iterations", settings.iterations),
        ("repeats", settings.repeats),
        ("patch_size", settings.patch_size),
    ] {
        if n == 0 {
            return Err(Error::parameter(name, "must be at least 1"));
        }
    }
    if !settings.dir.is_dir() {
        return Err(Error::parameter(
            "dir",
            format!(
                "must be an existing directory, not {}",
                settings.dir.display()
            ),
        ));
    }
    let largest = settings
        .sizes
        .iter()
        .map(|s| s.triangles)
        .max()
        .unwrap_or(0);
    let need = memory::in_core_bytes_with_mesh(largest);
    if let Some(available) = memory::mem_available() {
        if need > available {
            return Err(Error::resource(format!(
                "the largest size, {largest} triangles, needs about {} of memory, but only {} is available",
                memory::format_size(need),
                memory::format_size(available)
            )));
        }
    }
    Ok(())
}

/// Run the benchmark. `phase` is told what is under way (for a progress display).
pub fn run(settings: &BenchSettings, phase: &mut dyn FnMut(String)) -> Result<BenchReport> {
    check(settings)?;
    let start = Instant::now();
    let machine = Machine::now();
    let baseline = memory::rss_anon().unwrap_or(0);
    let mut sizes = Vec::with_capacity(settings.sizes.len());
    for size in &settings.sizes {
        sizes.push(run_size(settings, size, baseline, phase)?);
    }
    Ok(BenchReport {
        machine,
        settings: settings.clone(),
        sizes,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Removes the temporary PLY file however the run ends.
struct TempFile(PathBuf);

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn run_size(
    settings: &BenchSettings,
    size: &SizeSpec,
    baseline: u64,
    phase: &mut dyn FnMut(String),
) -> Result<SizeResult> {
    phase(format!(
        "{}: generating icosphere level {} ({} triangles)",
        size.label, size.level, size.triangles
    ));
    let clock = Instant::now();
    let mut mesh = shapes::icosphere(size.level);
    shapes::add_normal_noise(&mut mesh, NOISE, 1);
    let generate_seconds = clock.elapsed().as_secs_f64();

    let sampler = memory::PeakSampler::start(Duration::from_millis(10));
    phase(format!("{}: PLY write and read", size.label));
    let ply = ply_round_trip(settings, size, &mesh)?;

    let mut runs = Vec::with_capacity(settings.threads.len());
    for &threads in &settings.threads {
        runs.push(run_threads(settings, size, &mesh, threads, phase)?);
    }
    let peak = sampler.peak();
    drop(sampler);
    let triangles = mesh.triangles.len();
    Ok(SizeResult {
        label: size.label.clone(),
        level: size.level,
        vertices: mesh.positions.len(),
        triangles,
        generate_seconds,
        ply,
        memory: MemoryResult {
            baseline_anon: baseline,
            peak_anon: peak,
            anon_bytes_per_triangle: peak.saturating_sub(baseline) as f64 / triangles.max(1) as f64,
        },
        runs,
    })
}

/// Write `mesh` as binary PLY and read it back, `repeats` times each.
fn ply_round_trip(settings: &BenchSettings, size: &SizeSpec, mesh: &Mesh) -> Result<PlyResult> {
    let name = format!(
        "vcsmooth-bench-{}-ico{}.ply",
        std::process::id(),
        size.level
    );
    let file = TempFile(settings.dir.join(name));
    let path: &Path = &file.0;
    let mut writes = Vec::with_capacity(settings.repeats);
    let mut reads = Vec::with_capacity(settings.repeats);
    for _ in 0..settings.repeats {
        let clock = Instant::now();
        io::write_mesh(path, mesh)?;
        writes.push(clock.elapsed().as_secs_f64());
    }
    let file_bytes = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    for _ in 0..settings.repeats {
        let clock = Instant::now();
        let back = io::read_mesh(path)?;
        reads.push(clock.elapsed().as_secs_f64());
        if back.triangles.len() != mesh.triangles.len() {
            return Err(Error::invalid(path, "read back a different triangle count"));
        }
    }
    let (write_seconds, read_seconds) = (median(&writes), median(&reads));
    let gbps = |s: f64| file_bytes as f64 / s.max(1e-9) / 1e9;
    Ok(PlyResult {
        file_bytes,
        write_seconds,
        write_gb_per_second: gbps(write_seconds),
        read_seconds,
        read_gb_per_second: gbps(read_seconds),
    })
}

/// Prepare and smooth `mesh` with every method on a pool of `threads` threads.
fn run_threads(
    settings: &BenchSettings,
    size: &SizeSpec,
    mesh: &Mesh,
    threads: usize,
    phase: &mut dyn FnMut(String),
) -> Result<ThreadRun> {
    let pool = engine::thread_pool(Some(threads))?;
    let storage = Storage::heap();
    phase(format!("{}: preparing on {threads} threads", size.label));
    let (mut plan, prepare) = pool.install(|| prepare(settings, &storage, mesh))?;
    // The edge colouring's figures (the sizes' table has one plan column for all methods).
    let stats = plan.stats(crate::smooth::method::Footprint::Edge);
    let triangles = mesh.triangles.len() as f64;
    let mut methods = Vec::with_capacity(settings.methods.len());
    for &method in &settings.methods {
        phase(format!(
            "{}: {method} on {threads} threads, {} × {} iterations",
            size.label, settings.repeats, settings.iterations
        ));
        let opts = settings.options(method);
        let mut seconds = Vec::with_capacity(settings.repeats * settings.iterations);
        let mut stencils = 0;
        let mut volume_pct = 100.0;
        for _ in 0..settings.repeats {
            plan.set_positions_from_input(&mesh.positions);
            let records =
                pool.install(|| plan.smooth(&storage, &opts, Statistics::Every, &mut Quiet))?;
            seconds.extend(records.iter().map(|r| r.seconds));
            if let Some(last) = records.last() {
                stencils = last.stencils.considered();
                volume_pct = last.volume_pct;
            }
        }
        let per_iteration = median(&seconds).max(1e-12);
        let stencil = method.is_stencil();
        methods.push(MethodResult {
            method,
            seconds_per_iteration: per_iteration,
            triangles_per_second: triangles / per_iteration,
            stencils_per_iteration: stencil.then_some(stencils),
            stencils_per_second: stencil.then_some(stencils as f64 / per_iteration),
            volume_pct,
        });
    }
    Ok(ThreadRun {
        threads,
        patches: stats.patches,
        colours: stats.colours,
        prepare,
        methods,
    })
}

/// Build the plan `repeats` times (dropping the previous one first, so that only one is held);
/// returns the last and the timings of the median run.
fn prepare(
    settings: &BenchSettings,
    storage: &Storage,
    mesh: &Mesh,
) -> Result<(Plan, PrepareResult)> {
    let mut timings = Vec::with_capacity(settings.repeats);
    let mut plan = None;
    for _ in 0..settings.repeats {
        drop(plan.take());
        let clock = Instant::now();
        let p = Plan::new(
            storage,
            &mesh.positions,
            &mesh.triangles,
            Layout::Patches(settings.patch_size),
        )?;
        let total = clock.elapsed().as_secs_f64();
        timings.push(PrepareResult {
            reorder_seconds: p.timings.reorder,
            topology_seconds: p.timings.topology,
            partition_seconds: p.timings.partition,
            total_seconds: total,
        });
        plan = Some(p);
    }
    let plan = plan.ok_or_else(|| Error::parameter("repeats", "must be at least 1"))?;
    timings.sort_by(|a, b| a.total_seconds.total_cmp(&b.total_seconds));
    Ok((plan, timings[timings.len() / 2]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(s: &str) -> u32 {
        parse_size(s).unwrap().level
    }

    #[test]
    fn triangle_counts_map_to_the_nearest_icosphere_level() {
        assert_eq!(level("1M"), 8);
        assert_eq!(level("1m"), 8);
        assert_eq!(level("4M"), 9);
        assert_eq!(level("100K"), 6);
        assert_eq!(level("1K"), 3);
        assert_eq!(level("1.5M"), 8);
        assert_eq!(level("1310720"), 8);
        assert_eq!(level("20"), 0);
        assert_eq!(level("1"), 0);
        assert_eq!(level(" 16M "), 10);
        let s = parse_size("1M").unwrap();
        assert_eq!((s.label.as_str(), s.triangles), ("1M", 1_310_720));
    }

    #[test]
    fn icosphere_levels_are_taken_exactly() {
        assert_eq!(level("ico0"), 0);
        assert_eq!(level("ico8"), 8);
        assert_eq!(level("ICO9"), 9);
        assert_eq!(parse_size("ico2").unwrap().triangles, 320);
        assert_eq!(
            level(&format!("ico{}", shapes::ICOSPHERE_MAX_SUBDIVISIONS)),
            shapes::ICOSPHERE_MAX_SUBDIVISIONS
        );
    }

    #[test]
    fn bad_sizes_are_refused() {
        for s in [
            "", "M", "lots", "0", "-1M", "0.1", "nan", "inf", "1X", "ico", "ico-1", "ico13", "1T",
            "100G",
        ] {
            assert!(parse_size(s).is_err(), "{s:?} accepted");
        }
        let e = parse_size("100G").unwrap_err();
        assert!(e.contains("too large"), "{e}");
    }

    #[test]
    fn sizes_are_sorted_and_deduplicated_by_level() {
        let sizes = ["4M", "1M", "ico8", "5M"].map(|s| parse_size(s).unwrap());
        let n = normalize_sizes(sizes.to_vec());
        let labels: Vec<_> = n.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(labels, ["1M", "4M"]);
    }

    #[test]
    fn medians() {
        assert_eq!(median(&[]), 0.0);
        assert_eq!(median(&[3.0]), 3.0);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
    }

    #[test]
    fn a_tiny_run_reports_positive_figures() {
        let dir = std::env::temp_dir();
        let settings = BenchSettings {
            sizes: vec![parse_size("ico2").unwrap()],
            methods: vec![Method::Vcs, Method::Laplacian],
            threads: vec![1, 2],
            iterations: 2,
            repeats: 1,
            patch_size: 64,
            dir,
        };
        let report = run(&settings, &mut |_| {}).unwrap();
        let size = &report.sizes[0];
        assert_eq!(size.triangles, 320);
        assert!(size.ply.file_bytes > 0 && size.ply.read_gb_per_second > 0.0);
        assert_eq!(size.runs.len(), 2);
        for run in &size.runs {
            assert!(run.patches > 1);
            let vcs = &run.methods[0];
            assert_eq!(vcs.stencils_per_iteration, Some(480));
            assert!(vcs.stencils_per_second.unwrap() > 0.0);
            assert!((vcs.volume_pct - 100.0).abs() < 1e-6);
            let lap = &run.methods[1];
            assert!(lap.stencils_per_second.is_none() && lap.triangles_per_second > 0.0);
            assert!(lap.volume_pct < 100.0);
        }
        // No temporary file is left behind.
        let name = format!("vcsmooth-bench-{}-ico2.ply", std::process::id());
        assert!(!settings.dir.join(name).exists());
    }
}
