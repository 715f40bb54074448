//! How far a long phase is: a [`Meter`] is a pair of atomic counters, work done out of a total,
//! that the phase's loops bump once per chunk of work ([`STEP`] items, or a MiB of I/O) from any
//! thread, and that a display reads from its own thread whenever it likes. Nothing else: no
//! lock, no callback into the display, no allocation, so a loop pays one relaxed atomic add per
//! chunk, and what the loops compute and in which order is untouched.
//!
//! The count only grows ([`Meter::add`], [`Meter::reach`]): a reader sees it non-decreasing. A
//! phase that counts its work exactly ends with `done == total`; one that cannot count a step as it
//! goes (a sort, a reader without a parallel fast path) counts it whole when the step ends.

use std::sync::atomic::{AtomicU64, Ordering};

/// Items a parallel loop handles between two bumps of its meter: the engine's chunk size, so that
/// a loop already cut into chunks bumps once per chunk.
pub const STEP: usize = 1 << 14;

/// Bytes a reader or a writer moves between two bumps of its meter.
pub const BYTES: u64 = 1 << 20;

/// Work done out of a total (see the module doc). `Meter::default()` counts for nobody: what a
/// caller without a display passes.
#[derive(Debug, Default)]
pub struct Meter {
    done: AtomicU64,
    total: AtomicU64,
}

impl Meter {
    /// A meter of `total` units, none done.
    pub fn new(total: u64) -> Meter {
        Meter {
            done: AtomicU64::new(0),
            total: AtomicU64::new(total),
        }
    }

    /// `n` more units done.
    #[inline]
    pub fn add(&self, n: u64) {
        // Relaxed: the counters order nothing else; a reader only wants a recent value.
        self.done.fetch_add(n, Ordering::Relaxed);
    }

    /// At least `n` units done (a step that knows where it stands rather than how much it did).
    #[inline]
    pub fn reach(&self, n: u64) {
        self.done.fetch_max(n, Ordering::Relaxed);
    }

    /// All `total` units done.
    pub fn complete(&self) {
        self.reach(self.total());
    }

    /// Units done so far.
    pub fn done(&self) -> u64 {
        self.done.load(Ordering::Relaxed)
    }

    /// Units in the phase: fixed when it starts, except where only an estimate was known then (a
    /// text output's size), which the phase corrects when it ends.
    pub fn total(&self) -> u64 {
        self.total.load(Ordering::Relaxed)
    }

    /// Correct the total (see [`Meter::total`]).
    pub fn set_total(&self, total: u64) {
        self.total.store(total, Ordering::Relaxed);
    }
}

/// A phase's passes over the vertices and over the triangles: its meter's total for a mesh is
/// [`Passes::items`].
#[derive(Debug, Clone, Copy)]
pub struct Passes {
    pub vertices: u64,
    pub triangles: u64,
}

impl Passes {
    /// Items of these passes over `vertices` vertices and `triangles` triangles.
    pub const fn items(self, vertices: u64, triangles: u64) -> u64 {
        self.vertices * vertices + self.triangles * triangles
    }
}

/// A [`std::io::Write`] that counts the bytes through it into a meter, once per [`BYTES`] (the
/// writers make many small writes: the count is kept here and handed on in large steps). The bytes
/// are passed on unchanged.
pub(crate) struct Counted<'m, W> {
    inner: W,
    meter: &'m Meter,
    pending: u64,
}

impl<'m, W: std::io::Write> Counted<'m, W> {
    pub fn new(inner: W, meter: &'m Meter) -> Self {
        Counted {
            inner,
            meter,
            pending: 0,
        }
    }

    #[inline]
    fn count(&mut self, n: usize) {
        self.pending += n as u64;
        if self.pending >= BYTES {
            self.meter.add(std::mem::take(&mut self.pending));
        }
    }
}

impl<W> Drop for Counted<'_, W> {
    fn drop(&mut self) {
        self.meter.add(self.pending);
    }
}

impl<W: std::io::Write> std::io::Write for Counted<'_, W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.count(n);
        Ok(n)
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.inner.write_all(buf)?;
        self.count(buf.len());
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn counted_passes_bytes_on_and_counts_them_all() {
        let meter = Meter::new(0);
        let mut out = Vec::new();
        {
            let mut w = Counted::new(&mut out, &meter);
            for k in 0..3000u32 {
                write!(w, "{k} ").unwrap();
                w.write_all(&[7; 1000]).unwrap();
            }
            // Counted in steps of a MiB while writing; the rest when the writer is dropped.
            assert!(meter.done() >= 2 * BYTES);
        }
        assert_eq!(meter.done(), out.len() as u64);
        let mut want = Vec::new();
        for k in 0..3000u32 {
            write!(want, "{k} ").unwrap();
            want.extend_from_slice(&[7; 1000]);
        }
        assert_eq!(out, want);
    }

    #[test]
    fn the_count_never_goes_back() {
        let m = Meter::new(10);
        m.add(4);
        m.reach(3);
        assert_eq!(m.done(), 4);
        m.reach(7);
        m.complete();
        assert_eq!((m.done(), m.total()), (10, 10));
    }
}
