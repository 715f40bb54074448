//! Where large arrays live: on the heap, or in memory-mapped scratch files when the mesh is larger
//! than the memory budget. File-backed pages are the kernel's page cache, not the process's
//! anonymous memory, so a mesh far larger than the budget streams through without being swapped.
//!
//! Scratch files are unlinked as soon as they are mapped: the mapping keeps them alive, and they
//! vanish when the array is dropped, when the process ends, or when it is killed. No run leaves
//! scratch behind.

use std::fs::OpenOptions;
use std::marker::PhantomData;
use std::ops::{Deref, DerefMut};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use glam::DVec3;
use memmap2::{Mmap, MmapMut};

use crate::error::{Error, Result};
use crate::signals::Temporary;

/// Plain data that may be stored as raw bytes in a scratch file.
///
/// # Safety
/// Implementors must be `repr(C)`/primitive types without padding or pointers, for which every bit
/// pattern (in particular all zeros) is a valid value.
pub unsafe trait Pod: Copy + Send + Sync + 'static {}
// SAFETY: primitive numbers and arrays of them: every bit pattern is valid, no padding.
unsafe impl Pod for u8 {}
unsafe impl Pod for u32 {}
unsafe impl Pod for u64 {}
unsafe impl Pod for usize {}
unsafe impl Pod for f32 {}
unsafe impl Pod for f64 {}
unsafe impl Pod for [u32; 2] {}
unsafe impl Pod for [u32; 3] {}
unsafe impl Pod for [f32; 3] {}
unsafe impl Pod for [u64; 2] {}
// SAFETY: glam's DVec3 is `#[repr(C)] { x: f64, y: f64, z: f64 }`: three f64s, no padding.
unsafe impl Pod for DVec3 {}

/// Chooses where new arrays go: the heap, or a scratch directory.
#[derive(Debug)]
pub struct Storage {
    scratch: Option<PathBuf>,
    /// The run's memory budget, named when a heap array cannot be allocated.
    budget: Option<u64>,
    /// Bytes of scratch files: made so far, alive now, the most at any time (for reports).
    held: Arc<Held>,
    counter: AtomicUsize,
}

/// Scratch bytes made in all, alive now and at most, shared with the arrays that hold them.
#[derive(Debug, Default)]
struct Held {
    total: AtomicU64,
    now: AtomicU64,
    peak: AtomicU64,
}

/// One scratch file's share of [`Held`], given back when its array is dropped.
struct Holding {
    held: Arc<Held>,
    bytes: u64,
}

impl Holding {
    fn new(held: &Arc<Held>, bytes: u64) -> Holding {
        held.total.fetch_add(bytes, Ordering::Relaxed);
        let now = held.now.fetch_add(bytes, Ordering::Relaxed) + bytes;
        held.peak.fetch_max(now, Ordering::Relaxed);
        Holding {
            held: held.clone(),
            bytes,
        }
    }
}

impl Drop for Holding {
    fn drop(&mut self) {
        self.held.now.fetch_sub(self.bytes, Ordering::Relaxed);
    }
}

impl Storage {
    /// All arrays on the heap.
    pub fn heap() -> Self {
        Storage {
            scratch: None,
            budget: None,
            held: Arc::default(),
            counter: AtomicUsize::new(0),
        }
    }

    /// Large arrays in scratch files under `dir` (which must exist and be writable).
    pub fn scratch(dir: &Path) -> Result<Self> {
        let meta = std::fs::metadata(dir).map_err(|e| Error::io(dir, e))?;
        if !meta.is_dir() {
            return Err(Error::io(
                dir,
                std::io::Error::new(
                    std::io::ErrorKind::NotADirectory,
                    "scratch path is not a directory",
                ),
            ));
        }
        Ok(Storage {
            scratch: Some(dir.to_path_buf()),
            budget: None,
            held: Arc::default(),
            counter: AtomicUsize::new(0),
        })
    }

    /// The same storage naming `budget` in its errors (an allocation that fails on the heap says
    /// what it needed and the budget the run had).
    pub fn with_budget(self, budget: u64) -> Self {
        Storage {
            budget: Some(budget),
            ..self
        }
    }

    /// The run's memory budget, when it was given one ([`Storage::with_budget`]).
    pub fn budget(&self) -> Option<u64> {
        self.budget
    }

    /// Whether arrays go to scratch files.
    pub fn is_mapped(&self) -> bool {
        self.scratch.is_some()
    }

    /// Total bytes placed in scratch files.
    pub fn mapped_bytes(&self) -> u64 {
        self.held.total.load(Ordering::Relaxed)
    }

    /// Bytes of scratch files alive now.
    pub fn held_bytes(&self) -> u64 {
        self.held.now.load(Ordering::Relaxed)
    }

    /// The most bytes of scratch files alive at one time: the disk space the run needed.
    pub fn peak_mapped_bytes(&self) -> u64 {
        self.held.peak.load(Ordering::Relaxed)
    }

    /// A zero-filled array of `len` elements. On the heap, an allocation the system refuses is an
    /// [`Error::Resource`] naming the size and the budget, never an abort.
    pub fn zeroed<T: Pod>(&self, len: usize) -> Result<Buf<T>> {
        let bytes = len.checked_mul(std::mem::size_of::<T>()).ok_or_else(|| {
            Error::resource(format!(
                "an array of {len} elements overflows the address space"
            ))
        })?;
        let Some(dir) = &self.scratch else {
            return self.heap_zeroed(len).map(Buf::from_vec);
        };
        // The mapping keeps the unlinked file's data alive.
        let (file, path) = self.scratch_file(dir)?;
        reserve(&file, bytes as u64).map_err(|e| {
            Error::resource(format!(
                "{}: cannot reserve {} of scratch space ({e}); free space there or choose another scratch directory",
                dir.display(),
                format_size(bytes as u64)
            ))
        })?;
        if bytes == 0 {
            return Ok(Buf::from_vec(Vec::new()));
        }
        // SAFETY: the file was just created by us, is unlinked (no other process can open it by
        // name), and is only accessed through this mapping, so nobody truncates or changes it
        // underneath; `Buf` ties the slice's lifetime to the mapping.
        let map = unsafe { MmapMut::map_mut(&file) }.map_err(|e| Error::io(&path, e))?;
        // SAFETY: a second, read-only view of the same file, used only to give the kernel
        // read-ahead advice (`Advisor`); its bytes are never read through it.
        let advice = unsafe { Mmap::map(&file) }.map_err(|e| Error::io(&path, e))?;
        let holding = Holding::new(&self.held, bytes as u64);
        Ok(Buf {
            inner: Inner::Map(map, Some(Arc::new(advice)), Some(holding)),
            len,
            _t: PhantomData,
        })
    }

    /// An empty file in the scratch directory, already unlinked (nothing is left behind on any
    /// exit), for data of a size not known in advance (a decompressed input); `None` on the heap.
    pub(crate) fn unnamed_file(&self) -> Option<Result<std::fs::File>> {
        let dir = self.scratch.as_ref()?;
        Some(self.scratch_file(dir).map(|(file, _)| file))
    }

    /// A new file in `dir`, opened and unlinked at once (nothing is left behind on any exit), and
    /// the name it had (for messages).
    fn scratch_file(&self, dir: &Path) -> Result<(std::fs::File, PathBuf)> {
        let n = self.counter.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!(".vcsmooth-scratch-{}-{n}", std::process::id()));
        // Registered until unlinked, so that a signal in between removes it too.
        let (temp, file) = Temporary::create(path.clone(), |p| {
            OpenOptions::new()
                .read(true)
                .write(true)
                .create_new(true)
                .open(p)
        })
        .map_err(|e| Error::io(&path, e))?;
        temp.remove().map_err(|e| Error::io(&path, e))?;
        Ok((file, path))
    }

    /// A zero-filled working array that is dropped soon after use: on the heap, an anonymous
    /// mapping ([`Buf::sparse`]) whose pages go back to the system when it is dropped. A freed heap
    /// block below glibc's mapping threshold (up to 32 MiB) stays with the process for reuse, and
    /// so counts in the run's peak to its end. In scratch storage, as [`Storage::zeroed`].
    pub fn working<T: Pod>(&self, len: usize) -> Result<Buf<T>> {
        match self.scratch {
            Some(_) => self.zeroed(len),
            None => Buf::sparse(len),
        }
    }

    /// An empty heap vector with room for `len` elements, or the error saying how much was needed.
    /// `len` zeros on the heap, from the allocator's zeroed memory: large arrays come as fresh
    /// pages that are zero already, so nothing is written until the array is used (by the threads
    /// that use it), instead of one thread writing every zero first.
    fn heap_zeroed<T: Pod>(&self, len: usize) -> Result<Vec<T>> {
        let failed = || {
            let bytes = (len as u64).saturating_mul(std::mem::size_of::<T>() as u64);
            not_enough(&format!("an array of {len} elements"), bytes, self.budget)
        };
        let layout = std::alloc::Layout::array::<T>(len).map_err(|_| failed())?;
        if layout.size() == 0 {
            return Ok(Vec::new());
        }
        // SAFETY: the layout's size is not zero.
        let ptr = unsafe { std::alloc::alloc_zeroed(layout) }.cast::<T>();
        if ptr.is_null() {
            return Err(failed());
        }
        // SAFETY: `ptr` comes from the global allocator with the layout of `len` elements of `T`
        // (what a `Vec` of capacity `len` holds), and all of them are zeros, which `Pod` makes
        // valid values.
        Ok(unsafe { Vec::from_raw_parts(ptr, len, len) })
    }

    fn heap_vec<T: Pod>(&self, len: usize) -> Result<Vec<T>> {
        let mut v = Vec::new();
        v.try_reserve_exact(len).map_err(|_| {
            let bytes = (len as u64).saturating_mul(std::mem::size_of::<T>() as u64);
            not_enough(&format!("an array of {len} elements"), bytes, self.budget)
        })?;
        Ok(v)
    }

    /// An array holding a copy of `data`.
    pub fn copy_of<T: Pod>(&self, data: &[T]) -> Result<Buf<T>> {
        if !self.is_mapped() {
            let mut v = self.heap_vec(data.len())?;
            v.extend_from_slice(data);
            return Ok(Buf::from_vec(v));
        }
        let mut b = self.zeroed(data.len())?;
        b.copy_from_slice(data);
        Ok(b)
    }
}

impl<T: Pod> Buf<T> {
    /// Map the file at `path`, which must hold exactly `len` elements, privately: the array reads
    /// the file's pages on demand and writes stay in this process (copy-on-write). The cluster
    /// engine maps the plan's arrays this way, so each rank touches only the pages of its region.
    ///
    /// The file must not be truncated or rewritten while mapped (the work directory's files are
    /// written once, before any rank maps them).
    pub fn map_file(path: &Path, len: usize) -> Result<Buf<T>> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let bytes = len
            .checked_mul(std::mem::size_of::<T>())
            .ok_or_else(|| Error::invalid(path, format!("{len} elements overflow")))?;
        let actual = file.metadata().map_err(|e| Error::io(path, e))?.len();
        if actual != bytes as u64 {
            return Err(Error::invalid(
                path,
                format!("holds {actual} bytes, expected {bytes} ({len} elements)"),
            ));
        }
        if bytes == 0 {
            return Ok(Buf::from_vec(Vec::new()));
        }
        // SAFETY: the size was checked above; the file belongs to our work directory and is not
        // changed while mapped (see the doc); the private mapping never writes to it.
        let map = unsafe { memmap2::MmapOptions::new().map_copy(&file) }
            .map_err(|e| Error::io(path, e))?;
        // SAFETY: as above; a read-only view for read-ahead advice only.
        let advice = unsafe { Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
        Ok(Buf {
            inner: Inner::Map(map, Some(Arc::new(advice)), None),
            len,
            _t: PhantomData,
        })
    }

    /// A zero-filled array of `len` elements whose pages exist only once touched: anonymous memory
    /// mapped without reserving swap. A rank of the cluster engine indexes its arrays by global
    /// vertex id but touches only its region, so its memory follows the region, not the mesh.
    pub fn sparse(len: usize) -> Result<Buf<T>> {
        let bytes = len.checked_mul(std::mem::size_of::<T>()).ok_or_else(|| {
            Error::resource(format!(
                "an array of {len} elements overflows the address space"
            ))
        })?;
        if bytes == 0 {
            return Ok(Buf::from_vec(Vec::new()));
        }
        let map = memmap2::MmapOptions::new()
            .len(bytes)
            .no_reserve_swap()
            .map_anon()
            .map_err(|e| {
                Error::resource(format!(
                    "cannot map {} of address space: {e}",
                    format_size(bytes as u64)
                ))
            })?;
        // Anonymous memory has no file to read ahead: no advice mapping.
        Ok(Buf {
            inner: Inner::Map(map, None, None),
            len,
            _t: PhantomData,
        })
    }
}

/// The page size advice is given in; on a system of larger pages, advice that does not start one is
/// refused (a hint lost, nothing else).
const PAGE: usize = 4096;

/// The byte ranges of whole pages (4 KiB) that element `ranges` of `elem` bytes each touch, given
/// by ascending start: pages that touch or overlap merged into one run.
pub fn page_runs(
    ranges: impl IntoIterator<Item = std::ops::Range<usize>>,
    elem: usize,
) -> Vec<std::ops::Range<usize>> {
    let mut runs: Vec<std::ops::Range<usize>> = Vec::new();
    for r in ranges.into_iter().filter(|r| !r.is_empty()) {
        debug_assert!(
            runs.last().is_none_or(|l| r.start * elem >= l.start),
            "not ascending"
        );
        let (start, end) = (
            r.start * elem / PAGE * PAGE,
            (r.end * elem).div_ceil(PAGE) * PAGE,
        );
        match runs.last_mut() {
            Some(last) if start <= last.end => last.end = last.end.max(end),
            _ => runs.push(start..end),
        }
    }
    runs
}

/// How the pages of `data`, a mapped array or the part of one from a page's start, are read on
/// a fault (a hint: data not from a page's start gets none; on heap memory, which is not read
/// from a file, it does nothing). `true`: a
/// fault reads its own page alone, for a pass whose read-ahead brings what it reads and which
/// touches the rest here and there (the sweep, out of core). `false`: the kernel's default, which
/// reads a window around the faulting page (the device's read-ahead, 8 MiB on this project's test
/// machine): right for a pass in order, 8 MiB from the disk for each scattered page missed.
///
/// Whether the kernel took the advice.
pub fn read_at_random<T>(data: &[T], random: bool) -> bool {
    #[cfg(target_os = "linux")]
    {
        unsafe extern "C" {
            fn madvise(
                addr: *mut std::ffi::c_void,
                len: usize,
                advice: std::ffi::c_int,
            ) -> std::ffi::c_int;
        }
        let (start, bytes) = (data.as_ptr() as usize, std::mem::size_of_val(data));
        if bytes == 0 || start % PAGE != 0 {
            return false;
        }
        // MADV_RANDOM and MADV_NORMAL.
        let advice = if random { 1 } else { 0 };
        let len = bytes.div_ceil(PAGE) * PAGE;
        // SAFETY: `data` starts a page, and every page its bytes are in is mapped (the length
        // rounded up stays in its last page); MADV_RANDOM and MADV_NORMAL change how pages are
        // read, never their bytes.
        unsafe { madvise(start as *mut std::ffi::c_void, len, advice) == 0 }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (data, random);
        false
    }
}

/// The raw bytes of a slice of plain data (for writing arrays to files as they are in memory).
pub fn as_bytes<T: Pod>(data: &[T]) -> &[u8] {
    // SAFETY: `Pod` types have no padding, so every byte is initialised; u8 has alignment 1.
    unsafe { std::slice::from_raw_parts(data.as_ptr().cast::<u8>(), std::mem::size_of_val(data)) }
}

/// The raw bytes of a mutable slice of plain data (for reading arrays from files).
pub fn as_bytes_mut<T: Pod>(data: &mut [T]) -> &mut [u8] {
    // SAFETY: as `as_bytes`; any bytes written are a valid `T` because `Pod` accepts every bit
    // pattern.
    unsafe {
        std::slice::from_raw_parts_mut(data.as_mut_ptr().cast::<u8>(), std::mem::size_of_val(data))
    }
}

/// Give the file `bytes` of real blocks. A sparse file would map fine and then kill the process
/// with SIGBUS on the first page the full disk cannot hold; allocating up front turns a lack of
/// space into a clean error before any work is done. On Linux `posix_fallocate` allocates the
/// blocks without writing them (glibc writes zeros itself where the file system cannot); elsewhere
/// the zeros are written here.
fn reserve(file: &std::fs::File, bytes: u64) -> std::io::Result<()> {
    if bytes == 0 {
        return Ok(());
    }
    #[cfg(all(target_os = "linux", target_pointer_width = "64"))]
    {
        use std::os::fd::AsRawFd;
        unsafe extern "C" {
            // `off_t` is 64 bits on every 64-bit Linux ABI.
            fn posix_fallocate(fd: std::ffi::c_int, offset: i64, len: i64) -> std::ffi::c_int;
        }
        let len = i64::try_from(bytes)
            .map_err(|_| std::io::Error::from(std::io::ErrorKind::FileTooLarge))?;
        // SAFETY: a plain system call on an open descriptor we own; it touches no memory of ours.
        let e = unsafe { posix_fallocate(file.as_raw_fd(), 0, len) };
        if e == 0 {
            Ok(())
        } else {
            Err(std::io::Error::from_raw_os_error(e))
        }
    }
    #[cfg(not(all(target_os = "linux", target_pointer_width = "64")))]
    {
        use std::io::Write;
        const BLOCK: usize = 1 << 20;
        let zeros = vec![0u8; BLOCK];
        let mut w: &std::fs::File = file;
        let mut left = bytes;
        while left > 0 {
            let n = left.min(BLOCK as u64) as usize;
            w.write_all(&zeros[..n])?;
            left -= n as u64;
        }
        Ok(())
    }
}

enum Inner<T> {
    Heap(Vec<T>),
    /// The mapping, its read-ahead twin, and for a scratch file its share of the storage's
    /// scratch bytes.
    Map(
        MmapMut,
        Option<Arc<Mmap>>,
        #[allow(dead_code, reason = "held for its drop, which gives the bytes back")]
        Option<Holding>,
    ),
}

/// Read-ahead advice for a mapped array, usable from another thread while the array itself is
/// borrowed mutably: `madvise(WILLNEED)` on a second mapping of the same file touches no data, it
/// only asks the kernel to bring the pages into the page cache.
#[derive(Clone)]
pub struct Advisor {
    map: Arc<Mmap>,
    elem: usize,
}

impl Advisor {
    /// Ask for elements `range` to be read ahead (a hint: errors are ignored).
    pub fn will_need(&self, range: std::ops::Range<usize>) {
        self.will_need_bytes(range.start * self.elem, range.end * self.elem);
    }

    /// [`Advisor::will_need`] for each of `ranges`, given by ascending start: the pages they
    /// touch, one request per run of touching pages ([`page_runs`]; scattered elements).
    pub fn will_need_each(&self, ranges: impl IntoIterator<Item = std::ops::Range<usize>>) {
        for run in page_runs(ranges, self.elem) {
            self.will_need_bytes(run.start, run.end);
        }
    }

    fn will_need_bytes(&self, start: usize, end: usize) {
        let (start, end) = (start.min(self.map.len()), end.min(self.map.len()));
        if end > start {
            let _ = self
                .map
                .advise_range(memmap2::Advice::WillNeed, start, end - start);
        }
    }
}

/// An array on the heap or in a mapped scratch file; derefs to a slice either way.
pub struct Buf<T: Pod> {
    inner: Inner<T>,
    len: usize,
    _t: PhantomData<T>,
}

impl<T: Pod> Buf<T> {
    /// Wrap a heap vector.
    pub fn from_vec(v: Vec<T>) -> Self {
        let len = v.len();
        Buf {
            inner: Inner::Heap(v),
            len,
            _t: PhantomData,
        }
    }

    /// Whether the array lives in a scratch file.
    pub fn is_mapped(&self) -> bool {
        matches!(self.inner, Inner::Map(..))
    }

    /// The array as a growable heap vector, moving a mapped array to the heap first (editing
    /// meshes element by element is for small meshes: tests, generators).
    pub fn heap_mut(&mut self) -> &mut Vec<T> {
        if let Inner::Map(..) = self.inner {
            *self = Buf::from_vec(self.to_vec());
        }
        match &mut self.inner {
            Inner::Heap(v) => v,
            Inner::Map(..) => unreachable!("moved to the heap above"),
        }
    }

    /// Read-ahead advice for this array; `None` on the heap.
    pub fn advisor(&self) -> Option<Advisor> {
        match &self.inner {
            Inner::Heap(_) => None,
            Inner::Map(_, advice, _) => advice.as_ref().map(|map| Advisor {
                map: map.clone(),
                elem: std::mem::size_of::<T>(),
            }),
        }
    }

    /// Keep the first `n` elements (a mapped array keeps its file, and shows only `n`).
    pub fn truncate(&mut self, n: usize) {
        match &mut self.inner {
            Inner::Heap(v) => v.truncate(n),
            Inner::Map(..) => self.len = self.len.min(n),
        }
    }

    /// Append an element (see [`Buf::heap_mut`]).
    pub fn push(&mut self, x: T) {
        self.heap_mut().push(x);
        self.len += 1;
    }
}

impl<T: Pod> Extend<T> for Buf<T> {
    fn extend<I: IntoIterator<Item = T>>(&mut self, iter: I) {
        let v = self.heap_mut();
        v.extend(iter);
        self.len = v.len();
    }
}

impl<T: Pod + PartialEq, const N: usize> PartialEq<[T; N]> for Buf<T> {
    fn eq(&self, other: &[T; N]) -> bool {
        self[..] == other[..]
    }
}

impl<T: Pod> From<Vec<T>> for Buf<T> {
    fn from(v: Vec<T>) -> Self {
        Buf::from_vec(v)
    }
}

impl<'a, T: Pod> IntoIterator for &'a Buf<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<'a, T: Pod> IntoIterator for &'a mut Buf<T> {
    type Item = &'a mut T;
    type IntoIter = std::slice::IterMut<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter_mut()
    }
}

impl<T: Pod + PartialEq> PartialEq for Buf<T> {
    fn eq(&self, other: &Self) -> bool {
        self[..] == other[..]
    }
}

impl<T: Pod + PartialEq> PartialEq<Buf<T>> for &[T] {
    fn eq(&self, other: &Buf<T>) -> bool {
        self[..] == other[..]
    }
}

impl<T: Pod + PartialEq> PartialEq<Vec<T>> for Buf<T> {
    fn eq(&self, other: &Vec<T>) -> bool {
        self[..] == other[..]
    }
}

impl<T: Pod> Default for Buf<T> {
    fn default() -> Self {
        Buf::from_vec(Vec::new())
    }
}

impl<T: Pod> Deref for Buf<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        match &self.inner {
            Inner::Heap(v) => v,
            // SAFETY: the mapping is page-aligned (so aligned for any T), holds exactly
            // `len * size_of::<T>()` bytes, and `Pod` makes every bit pattern a valid T.
            Inner::Map(m, ..) => unsafe {
                std::slice::from_raw_parts(m.as_ptr().cast::<T>(), self.len)
            },
        }
    }
}

impl<T: Pod> DerefMut for Buf<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        match &mut self.inner {
            Inner::Heap(v) => v,
            // SAFETY: as in `deref`; `&mut self` makes the access exclusive.
            Inner::Map(m, ..) => unsafe {
                std::slice::from_raw_parts_mut(m.as_mut_ptr().cast::<T>(), self.len)
            },
        }
    }
}

impl<T: Pod + std::fmt::Debug> std::fmt::Debug for Buf<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Buf<{}>[{}; {}]",
            std::any::type_name::<T>(),
            self.len,
            if self.is_mapped() { "mapped" } else { "heap" }
        )
    }
}

impl<T: Pod> Clone for Buf<T> {
    /// Clones onto the heap.
    fn clone(&self) -> Self {
        Buf::from_vec(self.to_vec())
    }
}

/// Parse a size such as `1G`, `512M`, `64K`, `1.5G` or `123456` (bytes); binary units.
pub fn parse_size(s: &str) -> std::result::Result<u64, String> {
    let t = s.trim();
    let (num, mult) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let m = match c.to_ascii_uppercase() {
                'K' => 1u64 << 10,
                'M' => 1 << 20,
                'G' => 1 << 30,
                'T' => 1 << 40,
                'B' => 1,
                _ => {
                    return Err(format!(
                        "'{s}': unknown size suffix '{c}' (use K, M, G or T)"
                    ));
                }
            };
            (&t[..i], m)
        }
        _ => (t, 1),
    };
    let x: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a size (e.g. 512M, 1G)"))?;
    if !x.is_finite() || x < 0.0 {
        return Err(format!("'{s}' is not a size (e.g. 512M, 1G)"));
    }
    let bytes = x * mult as f64;
    if bytes >= u64::MAX as f64 {
        return Err(format!("'{s}' is too large"));
    }
    Ok(bytes as u64)
}

/// The error of an allocation that failed: `what` names the array, `bytes` its size; `budget`
/// the run's budget when there is one.
pub fn not_enough(what: &str, bytes: u64, budget: Option<u64>) -> Error {
    Error::resource(match budget {
        Some(b) => format!(
            "not enough memory for {what} ({} needed, budget {})",
            format_size(bytes),
            format_size(b)
        ),
        None => format!(
            "not enough memory for {what} ({} needed)",
            format_size(bytes)
        ),
    })
}

/// Format a byte count with a binary unit, e.g. `1.50 GiB`.
pub fn format_size(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut x = bytes as f64;
    let mut u = 0;
    while x >= 1024.0 && u < UNITS.len() - 1 {
        x /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{x:.2} {}", UNITS[u])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn working_arrays_are_mappings_given_back_when_dropped() {
        // On the heap an anonymous mapping (not a heap block glibc would keep), zero-filled and
        // writable; in scratch storage a scratch file, counted as one.
        let mut a: Buf<u32> = Storage::heap().working(100_000).unwrap();
        assert!(a.is_mapped() && a.iter().all(|&x| x == 0));
        a[99_999] = 7;
        assert_eq!(a.iter().map(|&x| x as u64).sum::<u64>(), 7);
        let dir = tempfile::tempdir().unwrap();
        let s = Storage::scratch(dir.path()).unwrap();
        let b: Buf<u32> = s.working(1000).unwrap();
        assert!(b.is_mapped());
        assert_eq!(s.mapped_bytes(), 4000);
        assert!(Storage::heap().working::<u32>(0).unwrap().is_empty());
    }

    #[test]
    fn mapped_arrays_work_like_heap_ones_and_leave_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let s = Storage::scratch(dir.path()).unwrap();
        let mut a: Buf<DVec3> = s.zeroed(1000).unwrap();
        assert!(a.is_mapped());
        assert!(a.iter().all(|p| *p == DVec3::ZERO));
        a[999] = DVec3::new(1.0, 2.0, 3.0);
        let b = s.copy_of(&a[..]).unwrap();
        assert_eq!(b[999], DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(s.mapped_bytes(), 2 * 1000 * 24);
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            0,
            "scratch files must be unlinked"
        );
        let h: Buf<u32> = Storage::heap().zeroed(5).unwrap();
        assert!(!h.is_mapped() && h.len() == 5);
    }

    #[test]
    fn page_runs_merge_the_pages_that_touch() {
        // u32 elements: 1,024 a page.
        let runs = page_runs(
            [0..1, 5..9, 1023..1025, 4096..4097, 4097..4098, 9000..9000],
            4,
        );
        assert_eq!(runs, [0..8192, 16384..20480]);
        // A run that ends where the next begins is one run; a page between them keeps two.
        assert_eq!(page_runs([0..1024, 1024..1025], 4), vec![0..8192]);
        assert_eq!(page_runs([0..1, 2048..2049], 4), [0..4096, 8192..12288]);
        // 24-byte positions straddling a page boundary take both pages.
        assert_eq!(page_runs(std::iter::once(170..171), 24), vec![0..8192]);
        assert!(page_runs(std::iter::empty(), 8).is_empty());
    }

    #[test]
    #[cfg(target_os = "linux")]
    fn a_mapped_array_takes_random_read_advice_and_keeps_its_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let s = Storage::scratch(dir.path()).unwrap();
        let mut a: Buf<u64> = s.zeroed(10_000).unwrap();
        a.iter_mut()
            .enumerate()
            .for_each(|(i, x)| *x = i as u64 * 3);
        assert!(read_at_random(&a, true));
        assert!(a.iter().enumerate().all(|(i, &x)| x == i as u64 * 3));
        assert!(read_at_random(&a, false));
        // Not from a page's start, or empty: no advice.
        assert!(!read_at_random(&a[1..], true));
        assert!(!read_at_random(&a[..0], true));
    }

    #[test]
    fn the_scratch_peak_counts_the_files_alive_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let s = Storage::scratch(dir.path()).unwrap();
        let a: Buf<u32> = s.zeroed(1000).unwrap();
        let b: Buf<u32> = s.zeroed(3000).unwrap();
        drop(a);
        let c: Buf<u32> = s.zeroed(500).unwrap();
        assert_eq!(s.peak_mapped_bytes(), 4 * 4000, "a and b together");
        drop((b, c));
        let d: Buf<u32> = s.zeroed(4500).unwrap();
        assert_eq!(s.peak_mapped_bytes(), 4 * 4500, "d alone is more");
        assert_eq!(s.mapped_bytes(), 4 * 9000);
        let heap = Storage::heap();
        let _e: Buf<u32> = heap.zeroed(1000).unwrap();
        assert_eq!(heap.peak_mapped_bytes(), 0);
        drop(d);
    }

    #[test]
    fn scratch_must_be_a_directory() {
        let f = tempfile::NamedTempFile::new().unwrap();
        assert!(Storage::scratch(f.path()).is_err());
    }
}
