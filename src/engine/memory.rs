//! Memory: the budget, the process's anonymous memory, and the choice between heap and scratch.
//!
//! "Anonymous memory" is `RssAnon` of `/proc/self/status`: heap and stacks, excluding file-backed
//! pages (the memory-mapped input and scratch files, which the kernel can drop and re-read).
//! This is the figure `--memory-budget` limits.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use crate::error::{Error, Result};

/// The smallest budget the tool accepts: room for the process itself, its thread stacks and the
/// per-patch working buffers, with everything large in scratch files.
pub const MIN_BUDGET: u64 = 64 << 20;

/// The memory model: bytes of anonymous memory per triangle, the one place every estimate of the
/// tool comes from (the heap-or-scratch choice of a run, `bench`'s size check, `slurm-script`'s
/// `--mem`, `generate`'s check).
///
/// In core ([`Storage::heap`](crate::mesh::Storage::heap)) the peak of a `smooth` run was measured
/// at 87–95 B per triangle on a 5.2M-triangle sphere (laplacian, taubin, vcs); the model adds a
/// fifth for the reports' statistics and the allocator.
pub const HEAP_BYTES_PER_TRIANGLE: u64 = 114;
/// A run whose options bound the deviation (`max_deviation`) keeps the input positions beside
/// the working ones: f64 positions at about half a vertex per triangle, in the plan's storage.
pub const DEVIATION_BYTES_PER_TRIANGLE: u64 = 12;
/// A run that stops automatically ([`Options::auto_stop`](crate::Options)) keeps four arrays per
/// vertex beside the working positions (unit normals, their offsets, a noise field and its second
/// buffer: 48 B per vertex at about half a vertex per triangle), in the plan's storage.
pub const AUTO_BYTES_PER_TRIANGLE: u64 = 24;
/// A file run that measures the deviation field ([`crate::engine::DeviationSettings`]) keeps the
/// input's f64 positions through the run in core (the field then adds two f64 per vertex at the
/// write, beside what the plan gave back).
pub const FIELD_BYTES_PER_TRIANGLE: u64 = 12;
/// An in-memory [`Mesh`](crate::Mesh) itself: f64 positions (about half a vertex per triangle)
/// and u32 triangles.
pub const MESH_BYTES_PER_TRIANGLE: u64 = 24;
/// Bytes per triangle of a binary PLY file (12 B per vertex at about half a vertex per triangle,
/// 13 B per face): how the model turns a file size into triangles before reading. Text formats
/// spend more per triangle, so they are overestimated, which only sends them to scratch sooner.
pub const FILE_BYTES_PER_TRIANGLE: u64 = 19;
/// `generate`: the mesh of one level and the one before it, and the write buffers (measured 32 B
/// at level 8); with noise also the adjacency and normals it builds (measured 38 B more).
pub const GENERATE_BYTES_PER_TRIANGLE: u64 = 48;
pub const NOISE_BYTES_PER_TRIANGLE: u64 = 48;
/// `subdivide` (and each round of `refine`), per output triangle: the output mesh (f64 positions at
/// about half a vertex per triangle, u32 triangles: 24 B) and the last bisection pass's arrays
/// over its input triangles, which can be nearly as many when that pass splits few of them
/// (input triangles 12 B, half-edges 48, edge ids 12, edge starts, lengths and midpoints at 1.5
/// edges per triangle 39, work list 8, marks and longest edges 3: about 122 B), rounded up for
/// the allocator. Measured peaks of `subdivide` and `refine` (RssAnon) were 111–127 B per output
/// triangle on a noisy sphere; `refine`'s smoothing of the output needs less
/// ([`HEAP_BYTES_PER_TRIANGLE`]).
pub const SUBDIVIDE_BYTES_PER_TRIANGLE: u64 = 160;
/// In core, a vertex beyond the half a vertex per triangle that [`HEAP_BYTES_PER_TRIANGLE`]
/// counts: its positions (input, reordered, working), neighbour sums, order and adjacency offsets.
/// Measured 90 B per unreferenced vertex (920k of them beside a sphere, `vcs`), rounded up; a
/// file whose header says it holds many more vertices than half its faces is charged for them.
pub const HEAP_BYTES_PER_VERTEX: u64 = 104;
/// The schedule of a plan cut into patches (each patch's near patches, both conflict graphs,
/// colours and halos) is held on the heap whatever the storage: [`PATCH_BYTES`] per patch plus
/// [`NEAR_BYTES`] divided by the patch size, since smaller patches have more near patches each.
/// Measured on a 1.3M-triangle sphere: 2.9, 2.0, 1.6 and 1.3 KiB per patch at patch sizes 1, 2,
/// 4 and 8, 0.9–1.1 KiB from 16 to 1024.
pub const PATCH_BYTES: u64 = 1024;
pub const NEAR_BYTES: u64 = 3072;

/// Memory for the process itself, its thread stacks and buffers, on top of the per-triangle part.
pub const BASE_BYTES: u64 = 256 << 20;

/// Bytes of memory per iteration of a run, which keeps one [`IterationRecord`] per iteration for
/// its report (`--stats last` too: an unmeasured iteration still has its stencil counts and
/// time): the 88 B record, twice while its vector grows, a copy in the command line's report and
/// that copy's pretty-printed JSON (about 450 B, twice while it grows).
///
/// [`IterationRecord`]: super::IterationRecord
pub const RECORD_BYTES: u64 = 1024;

/// Memory the records of `iterations` iterations take ([`RECORD_BYTES`] each).
pub fn records_bytes(iterations: usize) -> u64 {
    (iterations as u64).saturating_mul(RECORD_BYTES)
}

/// The records of a run count against its budget: a run whose records alone would take more than
/// half of it is refused before any work (the other half is for the mesh, in memory or as the
/// working set of its scratch files). Records grow one per iteration as the run goes, so without
/// this check a huge iteration count would exhaust the memory hours into the run.
pub fn check_records(iterations: usize, budget: u64) -> Result<()> {
    let need = records_bytes(iterations);
    if need > budget / 2 {
        return Err(Error::parameter(
            "iterations",
            format!(
                "{iterations}: not enough memory for one record per iteration ({} needed, more than half the memory budget of {}); run at most {} iterations, or raise the budget",
                format_size(need),
                format_size(budget),
                budget / 2 / RECORD_BYTES
            ),
        ));
    }
    Ok(())
}

/// Anonymous memory an in-core smoothing run of `triangles` triangles needs.
pub fn in_core_bytes(triangles: u64) -> u64 {
    triangles.saturating_mul(HEAP_BYTES_PER_TRIANGLE)
}

/// [`in_core_bytes`] of the mesh in a file of `size` bytes.
pub fn in_core_bytes_of_file(size: u64) -> u64 {
    size.saturating_mul(HEAP_BYTES_PER_TRIANGLE) / FILE_BYTES_PER_TRIANGLE
}

/// [`in_core_bytes_of_file`] of a run with `opts`: [`DEVIATION_BYTES_PER_TRIANGLE`] more when it
/// keeps the input positions ([`crate::Options::keeps_input`]), [`AUTO_BYTES_PER_TRIANGLE`] more when it
/// stops automatically, and the method's per-triangle fields ([`face_field_bytes`]), or the
/// crease detection's ([`CREASE_FIELD_BYTES_PER_TRIANGLE`]) when those are more: the crease
/// fields are dropped before the method's are allocated.
pub fn in_core_bytes_of_file_with(size: u64, opts: &crate::Options) -> u64 {
    let mut per_triangle = HEAP_BYTES_PER_TRIANGLE;
    if opts.keeps_input() {
        per_triangle += DEVIATION_BYTES_PER_TRIANGLE;
    }
    if opts.auto_stop {
        per_triangle += AUTO_BYTES_PER_TRIANGLE;
    }
    let creases = match opts.crease_angle {
        Some(_) => CREASE_FIELD_BYTES_PER_TRIANGLE,
        None => 0,
    };
    per_triangle += face_field_bytes(opts.method).max(creases);
    size.saturating_mul(per_triangle) / FILE_BYTES_PER_TRIANGLE
}

/// Bytes per triangle of the crease detection's face fields (`Plan::crease`: the guided
/// filter's, [`crate::smooth::guided::FACE_VECTORS`] vectors and `FACE_SCALARS` scalars), alive
/// while the plan is made.
pub const CREASE_FIELD_BYTES_PER_TRIANGLE: u64 = field_bytes(
    crate::smooth::guided::FACE_VECTORS,
    crate::smooth::guided::FACE_SCALARS,
);

/// Bytes per triangle of `method`'s per-triangle fields ([`crate::smooth::method::Needs`]).
pub fn face_field_bytes(method: crate::Method) -> u64 {
    let needs = method.unit().needs();
    field_bytes(needs.face_vectors, needs.face_scalars)
}

/// Bytes per triangle of `vectors` 3-vector fields and `scalars` scalar fields, in f64.
const fn field_bytes(vectors: usize, scalars: usize) -> u64 {
    (vectors * 24 + scalars * 8) as u64
}

/// [`in_core_bytes_of_file_with`], and [`FIELD_BYTES_PER_TRIANGLE`] more when the run measures
/// the deviation field (`field`).
pub fn in_core_bytes_of_run(size: u64, opts: &crate::Options, field: bool) -> u64 {
    let extra = match field {
        true => size.saturating_mul(FIELD_BYTES_PER_TRIANGLE) / FILE_BYTES_PER_TRIANGLE,
        false => 0,
    };
    in_core_bytes_of_file_with(size, opts).saturating_add(extra)
}

/// Memory a job needs to smooth a file of `size` bytes in core with `opts`, the process included.
pub fn job_bytes_of_file(size: u64, opts: &crate::Options) -> u64 {
    in_core_bytes_of_file_with(size, opts).saturating_add(BASE_BYTES)
}

/// [`in_core_bytes_of_run`] from the counts a file's header gives: the triangles at their model
/// and each vertex beyond half a vertex per triangle at [`HEAP_BYTES_PER_VERTEX`] (with the
/// input positions, automatic-stop fields and deviation field that `opts` and `field` keep per
/// vertex).
pub fn in_core_bytes_of_counts(
    vertices: u64,
    triangles: u64,
    opts: &crate::Options,
    field: bool,
) -> u64 {
    let as_file = triangles.saturating_mul(FILE_BYTES_PER_TRIANGLE);
    let mut per_vertex = HEAP_BYTES_PER_VERTEX;
    if opts.keeps_input() {
        per_vertex += 2 * DEVIATION_BYTES_PER_TRIANGLE;
    }
    if opts.auto_stop {
        per_vertex += 2 * AUTO_BYTES_PER_TRIANGLE;
    }
    if field {
        per_vertex += 2 * FIELD_BYTES_PER_TRIANGLE;
    }
    let extra = vertices.saturating_sub(triangles / 2);
    in_core_bytes_of_run(as_file, opts, field).saturating_add(extra.saturating_mul(per_vertex))
}

/// Heap bytes of the schedule of `vertices` cut into patches of `patch_size` (none for one
/// patch); see [`PATCH_BYTES`].
pub fn schedule_bytes(vertices: u64, patch_size: usize) -> u64 {
    let size = patch_size.max(1) as u64;
    if vertices <= size {
        return 0;
    }
    vertices
        .div_ceil(size)
        .saturating_mul(PATCH_BYTES + NEAR_BYTES / size)
}

/// The schedule of `vertices` in patches of `patch_size` is on the heap whatever the storage: a
/// patch size whose schedule would take more than half of `budget` is refused before the plan is
/// made, naming the smallest patch size that fits.
pub fn check_schedule(vertices: u64, patch_size: usize, budget: u64) -> Result<()> {
    let need = schedule_bytes(vertices, patch_size);
    if need <= budget / 2 {
        return Ok(());
    }
    let mut fits = patch_size.max(1);
    while schedule_bytes(vertices, fits) > budget / 2 && (fits as u64) < vertices {
        fits *= 2;
    }
    Err(Error::parameter(
        "patch_size",
        format!(
            "{patch_size}: {} patches of {vertices} vertices need about {} for their schedule, more than half the memory budget of {}; use a patch size of {fits} or more (the default is {}), or raise the budget",
            vertices.div_ceil(patch_size.max(1) as u64),
            format_size(need),
            format_size(budget),
            crate::engine::DEFAULT_PATCH_SIZE
        ),
    ))
}

/// Memory to smooth a mesh of `triangles` that is also held in memory beside the plan (`bench`).
pub fn in_core_bytes_with_mesh(triangles: u64) -> u64 {
    in_core_bytes(triangles).saturating_add(triangles.saturating_mul(MESH_BYTES_PER_TRIANGLE))
}

/// The heap an in-memory [`Mesh`](crate::Mesh) of these counts holds: f64 positions, u32
/// triangles (what a text format costs when its mesh is read before it can go to scratch).
pub fn mesh_bytes(vertices: u64, triangles: u64) -> u64 {
    vertices
        .saturating_mul(24)
        .saturating_add(triangles.saturating_mul(12))
}

/// Memory to generate a mesh of `triangles`, with or without noise.
pub fn generate_bytes(triangles: u64, noise: bool) -> u64 {
    let per = GENERATE_BYTES_PER_TRIANGLE + if noise { NOISE_BYTES_PER_TRIANGLE } else { 0 };
    triangles.saturating_mul(per)
}

/// Memory to subdivide a mesh into `triangles` triangles in memory.
pub fn subdivide_bytes(triangles: u64) -> u64 {
    triangles.saturating_mul(SUBDIVIDE_BYTES_PER_TRIANGLE)
}

/// Refuse work estimated to need `need` bytes for `what` when `budget` cannot hold it, before
/// anything is allocated: `not enough memory for WHAT (NEED needed, budget B from SOURCE)`.
pub fn check_fits(what: &str, need: u64, budget: Budget) -> Result<()> {
    if need <= budget.bytes {
        return Ok(());
    }
    let from = match budget.source {
        BudgetSource::Flag => "as given",
        BudgetSource::Available => "3/4 of the available memory",
        BudgetSource::Cgroup => "3/4 of the cgroup's memory limit left",
        BudgetSource::Rlimit => "3/4 of the address-space or data rlimit left",
        BudgetSource::Fallback => "a default",
    };
    Err(Error::resource(format!(
        "not enough memory for {what} ({} needed, budget {}, {from})",
        format_size(need),
        format_size(budget.bytes)
    )))
}

/// The budget `given` (checked), else the default.
pub fn budget_or_default(given: Option<u64>) -> Result<Budget> {
    match given {
        Some(bytes) => {
            check_budget(bytes)?;
            Ok(Budget {
                bytes,
                source: BudgetSource::Flag,
            })
        }
        None => Ok(default_budget()),
    }
}

pub use crate::mesh::storage::{format_size, not_enough, parse_size};

/// The value of `key` (e.g. `"MemAvailable:"`) in a `/proc` text whose lines read `Key: N kB`,
/// in bytes.
fn parse_kib(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kib: u64 = line[key.len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    kib.checked_mul(1024)
}

fn read_kib(file: &str, key: &str) -> Option<u64> {
    parse_kib(&std::fs::read_to_string(file).ok()?, key)
}

/// The process's anonymous resident memory in bytes (`RssAnon`), if the OS tells.
pub fn rss_anon() -> Option<u64> {
    read_kib("/proc/self/status", "RssAnon:")
}

/// The memory the system can give without swapping (`MemAvailable`), if the OS tells.
pub fn mem_available() -> Option<u64> {
    read_kib("/proc/meminfo", "MemAvailable:")
}

/// Where a run's memory budget came from (the report's `memory.budget_source`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BudgetSource {
    /// Given by the caller (`memory_budget`).
    Flag,
    /// The system's available memory (`MemAvailable`).
    Available,
    /// The memory limit of the process's control group (v2 `memory.max`, v1
    /// `memory.limit_in_bytes`) minus what the group already uses: a batch job's `--mem`.
    Cgroup,
    /// A resource limit of the process (`RLIMIT_AS`, `RLIMIT_DATA`: `ulimit -v`, `ulimit -d`)
    /// minus what it already uses.
    Rlimit,
    /// Nothing known: 1 GiB.
    #[default]
    Fallback,
}

/// A memory budget and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Budget {
    pub bytes: u64,
    pub source: BudgetSource,
}

/// The default budget: three quarters of the tightest of the memory the system has available,
/// the headroom of the process's control groups and the headroom under its address-space and
/// data rlimits (1 GiB if none is known). A budget that ignored a job's cgroup limit would be
/// killed by the kernel without a word; one that ignored `ulimit -v` would abort on a failed
/// allocation. It is not raised to [`MIN_BUDGET`]: a smaller limit gives a smaller budget, and the
/// checks against it fail with a clear error instead of the kernel's kill.
pub fn default_budget() -> Budget {
    let limits = [
        (BudgetSource::Available, mem_available()),
        (
            BudgetSource::Cgroup,
            cgroup_headroom(&|p| std::fs::read_to_string(p).ok()),
        ),
        (BudgetSource::Rlimit, rlimit_headroom()),
    ];
    budget_of(&limits)
}

/// Three quarters of the smallest of `limits` (the first on a tie), or 1 GiB if none is known.
fn budget_of(limits: &[(BudgetSource, Option<u64>)]) -> Budget {
    limits
        .iter()
        .filter_map(|&(source, bytes)| Some((source, bytes?)))
        .min_by_key(|&(_, bytes)| bytes)
        .map_or(
            Budget {
                bytes: 1 << 30,
                source: BudgetSource::Fallback,
            },
            |(source, bytes)| Budget {
                bytes: bytes / 4 * 3,
                source,
            },
        )
}

/// A cgroup limit file's value: `None` for `max` (no limit) or anything unreadable.
fn parse_cgroup_value(text: &str) -> Option<u64> {
    text.trim().parse().ok()
}

/// The process's cgroup paths in `/proc/self/cgroup`: the v2 path (line `0::PATH`) and the path
/// in the v1 hierarchy that has the `memory` controller (line `N:...memory...:PATH`).
fn parse_cgroup_paths(text: &str) -> (Option<&str>, Option<&str>) {
    let (mut v2, mut v1) = (None, None);
    for line in text.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(controllers), Some(path)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        if id == "0" && controllers.is_empty() {
            v2 = Some(path);
        } else if controllers.split(',').any(|c| c == "memory") {
            v1 = Some(path);
        }
    }
    (v2, v1)
}

/// The smallest `limit − usage` over the cgroup at `path` under `root` and its ancestors (a
/// group is bounded by every group above it); `None` when no group sets a limit. `read` returns a
/// file's text (the one place that touches the file system, so tests can give sample trees).
fn group_headroom(
    read: &dyn Fn(&str) -> Option<String>,
    root: &str,
    path: &str,
    limit_file: &str,
    usage_file: &str,
) -> Option<u64> {
    let mut dir = path.trim_end_matches('/').to_string();
    let mut tightest: Option<u64> = None;
    loop {
        let limit = read(&format!("{root}{dir}/{limit_file}"))
            .as_deref()
            .and_then(parse_cgroup_value);
        if let Some(limit) = limit {
            let usage = read(&format!("{root}{dir}/{usage_file}"))
                .as_deref()
                .and_then(parse_cgroup_value)
                .unwrap_or(0);
            let room = limit.saturating_sub(usage);
            tightest = Some(tightest.map_or(room, |t| t.min(room)));
        }
        match dir.rfind('/') {
            Some(at) => dir.truncate(at),
            None => return tightest,
        }
    }
}

/// The headroom of the process's memory cgroups, v2 and v1 (the tighter if both limit).
fn cgroup_headroom(read: &dyn Fn(&str) -> Option<String>) -> Option<u64> {
    let text = read("/proc/self/cgroup")?;
    let (v2, v1) = parse_cgroup_paths(&text);
    let v2 =
        v2.and_then(|p| group_headroom(read, "/sys/fs/cgroup", p, "memory.max", "memory.current"));
    let v1 = v1.and_then(|p| {
        group_headroom(
            read,
            "/sys/fs/cgroup/memory",
            p,
            "memory.limit_in_bytes",
            "memory.usage_in_bytes",
        )
    });
    [v2, v1].into_iter().flatten().min()
}

/// The soft limit of the row `name` (e.g. `"Max address space"`) of `/proc/self/limits`, in its
/// units; `None` when unlimited or absent.
fn parse_limit(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    line[name.len()..].split_whitespace().next()?.parse().ok()
}

/// Address space the C allocator reserves for each thread that allocates (glibc: a 64 MiB arena
/// per thread, up to eight per core). It is not memory, but `RLIMIT_AS` counts it.
const ARENA_BYTES: u64 = 64 << 20;

/// The room left under `RLIMIT_AS` (minus `VmSize`: every mapping counts, files included, and
/// the arenas of the threads to come, one per core and one for the sampler) and `RLIMIT_DATA`
/// (minus `VmData`), the tighter of the two; `None` when neither is set.
fn rlimit_headroom() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()) as u64 + 1;
    rlimit_room(&limits, &status, threads * ARENA_BYTES)
}

/// [`rlimit_headroom`] from the texts of `/proc/self/limits` and `/proc/self/status`, keeping
/// `arenas` bytes of address space aside.
fn rlimit_room(limits: &str, status: &str, arenas: u64) -> Option<u64> {
    let room = |limit: &str, used: &str, aside: u64| {
        let limit = parse_limit(limits, limit)?;
        let used = parse_kib(status, used).unwrap_or(0).saturating_add(aside);
        Some(limit.saturating_sub(used))
    };
    [
        room("Max address space", "VmSize:", arenas),
        room("Max data size", "VmData:", 0),
    ]
    .into_iter()
    .flatten()
    .min()
}

/// Check a user-given budget.
pub fn check_budget(budget: u64) -> Result<()> {
    if budget < MIN_BUDGET {
        return Err(Error::parameter(
            "memory_budget",
            format!(
                "{} is below the minimum of {}",
                format_size(budget),
                format_size(MIN_BUDGET)
            ),
        ));
    }
    Ok(())
}

/// Samples `RssAnon` in the background and keeps the peak.
pub struct PeakSampler {
    peak: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl PeakSampler {
    /// Start sampling every `interval`.
    pub fn start(interval: Duration) -> PeakSampler {
        let peak = Arc::new(AtomicU64::new(rss_anon().unwrap_or(0)));
        let stop = Arc::new(AtomicBool::new(false));
        let (p, s) = (peak.clone(), stop.clone());
        let handle = std::thread::Builder::new()
            .name("rss-sampler".into())
            .spawn(move || {
                while !s.load(Ordering::Relaxed) {
                    if let Some(r) = rss_anon() {
                        p.fetch_max(r, Ordering::Relaxed);
                    }
                    std::thread::sleep(interval);
                }
            })
            .ok();
        PeakSampler { peak, stop, handle }
    }

    /// The largest `RssAnon` seen so far (including now).
    pub fn peak(&self) -> u64 {
        if let Some(r) = rss_anon() {
            self.peak.fetch_max(r, Ordering::Relaxed);
        }
        self.peak.load(Ordering::Relaxed)
    }
}

impl Drop for PeakSampler {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_binary_suffixes() {
        assert_eq!(parse_size("1G"), Ok(1 << 30));
        assert_eq!(parse_size("512m"), Ok(512 << 20));
        assert_eq!(parse_size("64K"), Ok(64 << 10));
        assert_eq!(parse_size("1.5G"), Ok(3 << 29));
        assert_eq!(parse_size("1000"), Ok(1000));
        assert!(parse_size("lots").is_err());
        assert!(parse_size("-1G").is_err());
        assert!(parse_size("5X").is_err());
        assert!(check_budget(1 << 20).is_err());
        assert!(check_budget(1 << 30).is_ok());
        assert_eq!(format_size(3 << 29), "1.50 GiB");
    }

    /// A file system of sample texts.
    fn tree(files: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> + use<> {
        let files: Vec<(String, String)> = files
            .iter()
            .map(|(p, t)| (p.to_string(), t.to_string()))
            .collect();
        move |path: &str| {
            files
                .iter()
                .find(|(p, _)| p == path)
                .map(|(_, t)| t.clone())
        }
    }

    #[test]
    fn cgroup_v2_limits_are_read_up_the_tree_and_the_tightest_wins() {
        // A Slurm job: the job's group limits 100 MB, its step's group none, the user's 1 GB.
        let read = tree(&[
            ("/proc/self/cgroup", "0::/user/job_7/step_0\n"),
            ("/sys/fs/cgroup/user/job_7/step_0/memory.max", "max\n"),
            (
                "/sys/fs/cgroup/user/job_7/step_0/memory.current",
                "5000000\n",
            ),
            ("/sys/fs/cgroup/user/job_7/memory.max", "100000000\n"),
            ("/sys/fs/cgroup/user/job_7/memory.current", "30000000\n"),
            ("/sys/fs/cgroup/user/memory.max", "1000000000\n"),
            ("/sys/fs/cgroup/user/memory.current", "950000000\n"),
        ]);
        // The user's group has only 50 MB left, less than the job's 70 MB.
        assert_eq!(cgroup_headroom(&read), Some(50_000_000));
        // Without limits: nothing known.
        let free = tree(&[
            ("/proc/self/cgroup", "0::/a\n"),
            ("/sys/fs/cgroup/a/memory.max", "max\n"),
        ]);
        assert_eq!(cgroup_headroom(&free), None);
        // Over the limit already: no room, not an underflow.
        let full = tree(&[
            ("/proc/self/cgroup", "0::/a\n"),
            ("/sys/fs/cgroup/a/memory.max", "100\n"),
            ("/sys/fs/cgroup/a/memory.current", "120\n"),
        ]);
        assert_eq!(cgroup_headroom(&full), Some(0));
    }

    #[test]
    fn cgroup_v1_memory_hierarchy_is_found_among_the_controllers() {
        let text = "12:pids:/x\n4:memory:/process_api/abc\n3:cpu,cpuacct:/\n0::/\n";
        assert_eq!(
            parse_cgroup_paths(text),
            (Some("/"), Some("/process_api/abc"))
        );
        let read = tree(&[
            ("/proc/self/cgroup", text),
            (
                "/sys/fs/cgroup/memory/memory.limit_in_bytes",
                "9223372036854771712\n",
            ),
            (
                "/sys/fs/cgroup/memory/memory.usage_in_bytes",
                "8717778944\n",
            ),
            (
                "/sys/fs/cgroup/memory/process_api/abc/memory.limit_in_bytes",
                "104857600\n",
            ),
            (
                "/sys/fs/cgroup/memory/process_api/abc/memory.usage_in_bytes",
                "4857600\n",
            ),
        ]);
        assert_eq!(cgroup_headroom(&read), Some(100_000_000));
        // No cgroup file at all (not Linux, or /proc not mounted).
        assert_eq!(cgroup_headroom(&tree(&[])), None);
    }

    #[test]
    fn rlimits_leave_the_room_above_what_is_mapped() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units     \n\
            Max data size             unlimited            unlimited            bytes     \n\
            Max stack size            8388608              unlimited            bytes     \n\
            Max address space         307200000            unlimited            bytes     \n";
        let status =
            "Name:\tvcsmooth\nVmPeak:\t  120000 kB\nVmSize:\t  100000 kB\nVmData:\t 20000 kB\n";
        assert_eq!(parse_limit(limits, "Max address space"), Some(307_200_000));
        assert_eq!(parse_limit(limits, "Max data size"), None);
        assert_eq!(
            rlimit_room(limits, status, 0),
            Some(307_200_000 - 102_400_000)
        );
        // The arenas of threads to come are kept aside from the address space.
        assert_eq!(
            rlimit_room(limits, status, 100_000_000),
            Some(307_200_000 - 202_400_000)
        );
        // `ulimit -d`: the data limit minus the data segment; the tighter of the two counts.
        let both = limits.replace(
            "Max data size             unlimited",
            "Max data size             50000000 ",
        );
        assert_eq!(rlimit_room(&both, status, 0), Some(50_000_000 - 20_480_000));
        let none = limits.replace("307200000", "unlimited");
        assert_eq!(rlimit_room(&none, status, 0), None);
    }

    #[test]
    fn the_budget_is_three_quarters_of_the_tightest_limit() {
        let b = budget_of(&[
            (BudgetSource::Available, Some(8 << 30)),
            (BudgetSource::Cgroup, Some(100 << 20)),
            (BudgetSource::Rlimit, None),
        ]);
        assert_eq!((b.bytes, b.source), (75 << 20, BudgetSource::Cgroup));
        let b = budget_of(&[
            (BudgetSource::Available, Some(8 << 30)),
            (BudgetSource::Cgroup, None),
            (BudgetSource::Rlimit, Some(200 << 20)),
        ]);
        assert_eq!((b.bytes, b.source), (150 << 20, BudgetSource::Rlimit));
        let b = budget_of(&[(BudgetSource::Available, None)]);
        assert_eq!((b.bytes, b.source), (1 << 30, BudgetSource::Fallback));
        // This machine: whatever it says, never more than three quarters of what is available
        // (read before and after, since other processes change it meanwhile).
        let before = mem_available();
        let here = default_budget();
        if let (Some(a), Some(b)) = (before, mem_available()) {
            assert!(here.bytes <= a.max(b) / 4 * 3);
        }
    }

    #[test]
    fn rss_is_measured_and_the_sampler_sees_an_allocation() {
        // Other tests share this process, so only an absolute floor is robust: the peak can only
        // have grown past what this test holds.
        let s = PeakSampler::start(Duration::from_millis(1));
        assert!(s.peak() > 0);
        let v = vec![1u8; 256 << 20];
        std::hint::black_box(&v);
        assert!(
            s.peak() >= 250 << 20,
            "peak {} below the 256 MiB held",
            s.peak()
        );
    }
}
