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
/// Memory for the process itself, its thread stacks and buffers, on top of the per-triangle part.
pub const BASE_BYTES: u64 = 256 << 20;

/// Anonymous memory an in-core smoothing run of `triangles` triangles needs.
pub fn in_core_bytes(triangles: u64) -> u64 {
    triangles.saturating_mul(HEAP_BYTES_PER_TRIANGLE)
}

/// [`in_core_bytes`] of the mesh in a file of `size` bytes.
pub fn in_core_bytes_of_file(size: u64) -> u64 {
    size.saturating_mul(HEAP_BYTES_PER_TRIANGLE) / FILE_BYTES_PER_TRIANGLE
}

/// Memory a job needs to smooth a file of `size` bytes in core, the process included.
pub fn job_bytes_of_file(size: u64) -> u64 {
    in_core_bytes_of_file(size).saturating_add(BASE_BYTES)
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

pub use crate::mesh::storage::{format_size, parse_size};

fn read_kib(file: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(file).ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kib: u64 = line[key.len()..]
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib * 1024)
}

/// The process's anonymous resident memory in bytes (`RssAnon`), if the OS tells.
pub fn rss_anon() -> Option<u64> {
    read_kib("/proc/self/status", "RssAnon:")
}

/// The memory the system can give without swapping (`MemAvailable`), if the OS tells.
pub fn mem_available() -> Option<u64> {
    read_kib("/proc/meminfo", "MemAvailable:")
}

/// The default budget: three quarters of the available memory (1 GiB if unknown).
pub fn default_budget() -> u64 {
    mem_available()
        .map_or(1 << 30, |m| m / 4 * 3)
        .max(MIN_BUDGET)
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
