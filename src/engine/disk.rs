//! The process's disk traffic per phase of a run, from `/proc/self/io` (Linux; elsewhere, or
//! where the file cannot be read, there are no figures and the run goes on).
//!
//! What the kernel counts there, for the whole process (all its threads):
//! - `read_bytes`: bytes the process had read from a block device, page-cache hits excluded and
//!   pages of memory-mapped files faulted in from the disk included;
//! - `write_bytes`: bytes of file pages the process dirtied on a block device, counted when
//!   dirtied (written back later by the kernel), so a scratch page dirtied again after its
//!   write-back counts again;
//! - `cancelled_write_bytes`: of those, bytes dropped before their write-back (a file truncated
//!   or deleted first, as an unlinked scratch file is when the run lets it go), counted when the
//!   file goes: often in a later phase than the one that dirtied them;
//! - `rchar`, `wchar`: bytes through `read` and `write` system calls, from the cache or not
//!   (the process's own reads of `/proc` included), and nothing through a memory map.
//!
//! A file system without a block device (tmpfs, `/dev/shm`) adds nothing to the first three.
//! The engine's phases follow one another, so a phase's figures are its own and those of nothing
//! else but the process's background threads (the memory sampler reads `/proc`).

use std::sync::Arc;

use super::observer::{IterationRecord, Meter, Moment, Observer, Phase};

/// The bytes a process moved, as counted by `/proc/self/io` (see the module doc): since it
/// started ([`DiskBytes::now`]), or over a phase (in a [`DiskTraffic`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct DiskBytes {
    /// `read_bytes`: read from the disk (page-cache hits excluded).
    pub disk_read_bytes: u64,
    /// `write_bytes`: dirtied in files on a disk, to be written back.
    pub disk_written_bytes: u64,
    /// `cancelled_write_bytes`: dirty pages dropped before their write-back (their file gone),
    /// counted when dropped.
    pub disk_write_cancelled_bytes: u64,
    /// `rchar`: through `read` system calls, from the disk or the page cache.
    pub syscall_read_bytes: u64,
    /// `wchar`: through `write` system calls.
    pub syscall_written_bytes: u64,
}

impl DiskBytes {
    /// The process's counters now; `None` where `/proc/self/io` is missing or unreadable.
    pub fn now() -> Option<DiskBytes> {
        parse(&std::fs::read_to_string("/proc/self/io").ok()?)
    }

    /// What was moved from `earlier` to `self` (counters only grow; saturating all the same).
    fn since(self, earlier: DiskBytes) -> DiskBytes {
        DiskBytes {
            disk_read_bytes: self.disk_read_bytes.saturating_sub(earlier.disk_read_bytes),
            disk_written_bytes: self
                .disk_written_bytes
                .saturating_sub(earlier.disk_written_bytes),
            disk_write_cancelled_bytes: self
                .disk_write_cancelled_bytes
                .saturating_sub(earlier.disk_write_cancelled_bytes),
            syscall_read_bytes: self
                .syscall_read_bytes
                .saturating_sub(earlier.syscall_read_bytes),
            syscall_written_bytes: self
                .syscall_written_bytes
                .saturating_sub(earlier.syscall_written_bytes),
        }
    }

    fn add(&mut self, other: DiskBytes) {
        self.disk_read_bytes += other.disk_read_bytes;
        self.disk_written_bytes += other.disk_written_bytes;
        self.disk_write_cancelled_bytes += other.disk_write_cancelled_bytes;
        self.syscall_read_bytes += other.syscall_read_bytes;
        self.syscall_written_bytes += other.syscall_written_bytes;
    }
}

/// The text of `/proc/self/io` (`name: value` lines), or `None` when one of the five counters is
/// missing (a kernel without I/O accounting has only the system call ones) or not a number.
fn parse(text: &str) -> Option<DiskBytes> {
    let field = |name: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(name)?.strip_prefix(':'))
            .and_then(|v| v.trim().parse().ok())
    };
    Some(DiskBytes {
        disk_read_bytes: field("read_bytes")?,
        disk_written_bytes: field("write_bytes")?,
        disk_write_cancelled_bytes: field("cancelled_write_bytes")?,
        syscall_read_bytes: field("rchar")?,
        syscall_written_bytes: field("wchar")?,
    })
}

/// A run's disk traffic per phase: the phases of [`super::PhaseTimings`], and `restore`.
/// Bytes moved between phases (the pictures, the output's statistics of an in-memory run) are
/// only in `total`, so the phases sum to at most `total`.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct DiskTraffic {
    /// Reading the input; out of core also its second read for the write.
    pub ingest: DiskBytes,
    pub reorder: DiskBytes,
    pub topology: DiskBytes,
    pub partition: DiskBytes,
    /// The iterations, with their statistics.
    pub smoothing: DiskBytes,
    /// Putting the positions back in the input's order (no timing of its own: in `total`).
    pub restore: DiskBytes,
    /// The output, and its statistics measured beside the write.
    pub write: DiskBytes,
    /// The input's statistics (the output's are in `write`).
    pub metrics: DiskBytes,
    pub deviation: DiskBytes,
    /// The whole run, from its start to the end of the write.
    pub total: DiskBytes,
}

/// The figure of `traffic` that a phase's bytes go to; `None` for the phases whose bytes are only
/// in the total (hashing: the cluster engine's, which has no figures; drawing: between phases).
fn figure(traffic: &mut DiskTraffic, phase: Phase) -> Option<&mut DiskBytes> {
    match phase {
        Phase::Read => Some(&mut traffic.ingest),
        Phase::Reorder => Some(&mut traffic.reorder),
        Phase::Topology => Some(&mut traffic.topology),
        Phase::Schedule => Some(&mut traffic.partition),
        Phase::Statistics => Some(&mut traffic.metrics),
        Phase::Smooth => Some(&mut traffic.smoothing),
        Phase::Restore => Some(&mut traffic.restore),
        Phase::Write => Some(&mut traffic.write),
        Phase::Hash | Phase::Render => None,
    }
}

/// A run's observer, passed everything on to `inner`, that takes the disk counters at the start
/// and end of every phase it is told of: the phases are the ones the run's display shows.
pub(crate) struct DiskMeter<'a> {
    inner: &'a mut dyn Observer,
    /// The counters when the run started; `None` without `/proc/self/io`.
    start: Option<DiskBytes>,
    /// The counters when the current phase started.
    phase: Option<DiskBytes>,
    traffic: DiskTraffic,
}

impl<'a> DiskMeter<'a> {
    /// The run starts now.
    pub fn new(inner: &'a mut dyn Observer) -> DiskMeter<'a> {
        DiskMeter {
            inner,
            start: DiskBytes::now(),
            phase: None,
            traffic: DiskTraffic::default(),
        }
    }

    /// Adds the bytes moved since `before` (from [`DiskBytes::now`]) to `traffic.deviation`: a
    /// phase that observers are not told of.
    pub fn add_deviation(&mut self, before: Option<DiskBytes>) {
        if let (Some(before), Some(now)) = (before, DiskBytes::now()) {
            self.traffic.deviation.add(now.since(before));
        }
    }

    /// The run has ended: its traffic, `None` when the counters could not be read at its start
    /// or now.
    pub fn finish(&self) -> Option<DiskTraffic> {
        let total = DiskBytes::now()?.since(self.start?);
        Some(DiskTraffic {
            total,
            ..self.traffic
        })
    }
}

impl Observer for DiskMeter<'_> {
    fn iteration(&mut self, record: &IterationRecord, total: usize) {
        self.inner.iteration(record, total);
    }

    fn iteration_part(&mut self, done: usize, of: usize) {
        self.inner.iteration_part(done, of);
    }

    fn phase_start(&mut self, phase: Phase, meter: &Arc<Meter>) {
        self.inner.phase_start(phase, meter);
        // Taken after the display's start, so that its work falls outside the phase.
        self.phase = self.start.and_then(|_| DiskBytes::now());
    }

    fn phase_end(&mut self, phase: Phase) {
        if let (Some(before), Some(now)) = (self.phase.take(), DiskBytes::now())
            && let Some(f) = figure(&mut self.traffic, phase)
        {
            f.add(now.since(before));
        }
        self.inner.phase_end(phase);
    }

    fn interrupted(&mut self) -> bool {
        self.inner.interrupted()
    }

    fn mesh_at(
        &mut self,
        moment: Moment,
        positions: &[glam::DVec3],
        triangles: &[[u32; 3]],
        storage: &crate::mesh::Storage,
    ) -> crate::Result<()> {
        self.inner.mesh_at(moment, positions, triangles, storage)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `/proc/self/io` as a 6.x kernel writes it.
    const IO: &str = "rchar: 4292\nwchar: 1137\nsyscr: 11\nsyscw: 3\nread_bytes: 8192\n\
                      write_bytes: 12288\ncancelled_write_bytes: 4096\n";

    #[test]
    fn the_counters_are_read_by_name() {
        let io = parse(IO).unwrap();
        assert_eq!(
            io,
            DiskBytes {
                disk_read_bytes: 8192,
                disk_written_bytes: 12288,
                disk_write_cancelled_bytes: 4096,
                syscall_read_bytes: 4292,
                syscall_written_bytes: 1137,
            }
        );
        // `read_bytes` is not taken for `cancelled_write_bytes` or the reverse, in any order.
        let reversed: String = IO.lines().rev().map(|l| format!("{l}\n")).collect();
        assert_eq!(parse(&reversed), Some(io));
    }

    #[test]
    fn a_missing_or_broken_counter_gives_no_figures() {
        // Without task I/O accounting the kernel writes only the system call counters.
        assert_eq!(parse("rchar: 1\nwchar: 2\nsyscr: 3\nsyscw: 4\n"), None);
        assert_eq!(parse(&IO.replace("8192", "lots")), None);
        assert_eq!(parse(""), None);
    }

    #[test]
    fn differences_never_go_below_zero() {
        let (a, b) = (parse(IO).unwrap(), DiskBytes::default());
        assert_eq!(b.since(a), DiskBytes::default());
        let mut sum = a.since(b);
        sum.add(a);
        assert_eq!(sum.disk_written_bytes, 2 * 12288);
    }

    #[test]
    fn where_the_kernel_tells_a_write_counts() {
        let Some(before) = DiskBytes::now() else {
            return; // not Linux, or no /proc: nothing to measure
        };
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("f"), [7u8; 10_000]).unwrap();
        let moved = DiskBytes::now().unwrap().since(before);
        assert!(moved.syscall_written_bytes >= 10_000, "{moved:?}");
    }
}
