//! gzip-compressed meshes (`scan.ply.gz`, `model.obj.gz`, …): inputs recognised by their magic
//! bytes whatever their name, decompressed as a stream; outputs compressed when their name ends in
//! `.gz`.
//!
//! An input is decompressed once, before it is decoded: into memory, or, when the run stores its
//! arrays in scratch files (a mesh larger than its memory budget), into an unlinked scratch file
//! that is then mapped like any input file. The format inside is recognised from its own first
//! bytes, and from the name without `.gz` where only an extension tells (OBJ, `.gltf`). Several
//! gzip members one after another (as `cat a.gz b.gz` makes) are one stream, as `zcat` reads them.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, Write};
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;

use crate::error::{Error, Result};
use crate::mesh::Storage;
use crate::meter::Meter;

/// The first two bytes of every gzip member.
const MAGIC: &[u8] = b"\x1f\x8b";

/// The size of the reads and writes of a decompression.
const CHUNK: usize = 1 << 20;

/// Whether bytes starting with `head` are gzip-compressed.
pub(crate) fn is_gzip(head: &[u8]) -> bool {
    head.starts_with(MAGIC)
}

/// Whether a file name asks for gzip compression: it ends in `.gz`, in any case.
pub(crate) fn has_gz_extension(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
}

/// Why an output at `path`, of `format` (from its name), cannot be what its name asks: a glTF
/// output named `….gz` (its buffers are separate files or a GLB's chunk).
pub(crate) fn refused_output(format: crate::mesh::Format, path: &Path) -> Option<&'static str> {
    use crate::mesh::Format::{Glb, Gltf};
    (matches!(format, Gltf | Glb) && has_gz_extension(path)).then_some(
        "a glTF output is not gzip-compressed (its buffers are separate files or in a .glb): \
         drop the .gz",
    )
}

/// The name of what a `.gz` file holds (`scan.ply.gz` → `scan.ply`); other names as they are.
pub(crate) fn inner_name(path: &Path) -> PathBuf {
    match has_gz_extension(path) {
        true => path.with_extension(""),
        false => path.to_path_buf(),
    }
}

/// The decompressed size of a gzip file (`None` for any other file, and for a stream, which is
/// not opened), from its last member's trailer (the size modulo 2³²): the smallest size with that
/// remainder that is at least the compressed size. A guess for choosing between memory and
/// scratch, never trusted for anything else.
pub(crate) fn guessed_size(path: &Path) -> Option<u64> {
    let len = std::fs::metadata(path).ok().filter(|m| m.is_file())?.len();
    let mut file = File::open(path).ok()?;
    let mut magic = [0u8; 2];
    file.read_exact(&mut magic).ok()?;
    if !is_gzip(&magic) || len < 18 {
        return None;
    }
    let mut trailer = [0u8; 4];
    file.seek(std::io::SeekFrom::Start(len - 4)).ok()?;
    file.read_exact(&mut trailer).ok()?;
    let modulo = u64::from(u32::from_le_bytes(trailer));
    let wraps = len.saturating_sub(modulo).div_ceil(1 << 32);
    Some(modulo + (wraps << 32))
}

/// What a decompression made.
pub(super) enum Inflated {
    Memory(Vec<u8>),
    /// An unlinked scratch file holding the bytes, and their length.
    Scratch(File, u64),
}

/// Decompresses the whole of `file` (a regular file whose first bytes are gzip's magic), counting
/// the compressed bytes read into `meter`: into a scratch file when `storage` stores in files,
/// else into memory.
pub(super) fn inflate(
    file: &mut File,
    path: &Path,
    storage: &Storage,
    meter: &Meter,
) -> Result<Inflated> {
    file.rewind().map_err(|e| Error::io(path, e))?;
    let compressed = BufReader::with_capacity(CHUNK, Metered { inner: file, meter });
    let mut decoder = MultiGzDecoder::new(compressed);
    match storage.unnamed_file() {
        None => inflate_in_memory(&mut decoder, u64::MAX)
            .map(Inflated::Memory)
            .map_err(|what| refusal(path, what)),
        Some(scratch) => {
            let scratch = scratch?;
            let mut out = BufWriter::with_capacity(CHUNK, scratch);
            let mut chunk = vec![0u8; CHUNK];
            let mut total = 0u64;
            loop {
                let n = match decoder.read(&mut chunk) {
                    Ok(0) => break,
                    Ok(n) => n,
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    Err(e) => return Err(Error::invalid(path, corrupt(&e))),
                };
                out.write_all(&chunk[..n])
                    .map_err(|e| scratch_failed(path, &e))?;
                total += n as u64;
            }
            let scratch = out
                .into_inner()
                .map_err(|e| scratch_failed(path, e.error()))?;
            Ok(Inflated::Scratch(scratch, total))
        }
    }
}

/// Decompresses `gz` (bytes starting with gzip's magic) into memory, refusing more than `limit`
/// bytes; the error is the message without the path.
pub(super) fn inflate_in_memory(
    gz: &mut impl Read,
    limit: u64,
) -> std::result::Result<Vec<u8>, Failure> {
    let mut bytes = Vec::new();
    loop {
        if bytes.len() == bytes.capacity() {
            bytes
                .try_reserve(bytes.len().max(CHUNK))
                .map_err(|_| Failure::Memory(bytes.len() as u64))?;
        }
        let start = bytes.len();
        bytes.resize(bytes.capacity(), 0);
        let read = gz.read(&mut bytes[start..]);
        bytes.truncate(start + *read.as_ref().unwrap_or(&0));
        match read {
            Ok(0) => return Ok(bytes),
            Ok(_) if bytes.len() as u64 > limit => return Err(Failure::Limit(limit)),
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Failure::Corrupt(corrupt(&e))),
        }
    }
}

/// Why a decompression into memory stopped.
#[derive(Debug)]
pub(super) enum Failure {
    /// The gzip data is damaged or cut short (the message).
    Corrupt(String),
    /// Memory ran out after this many decompressed bytes.
    Memory(u64),
    /// More than this many bytes came out.
    Limit(u64),
}

impl Failure {
    /// The one-line message, without the path.
    pub(super) fn message(&self) -> String {
        match self {
            Failure::Corrupt(what) => what.clone(),
            Failure::Memory(bytes) => format!(
                "not enough memory to decompress more than {bytes} bytes: decompress it to a \
                 file first, or give the run a memory budget so that it decompresses to scratch"
            ),
            Failure::Limit(limit) => format!(
                "decompresses to more than {limit} bytes, more than a stream may hold: save it \
                 to a file"
            ),
        }
    }
}

fn refusal(path: &Path, failure: Failure) -> Error {
    match failure {
        Failure::Corrupt(what) => Error::invalid(path, what),
        other => Error::resource(format!("{}: {}", path.display(), other.message())),
    }
}

/// A decoder's error as a message: a cut-off stream, or damaged data.
fn corrupt(e: &std::io::Error) -> String {
    match e.kind() {
        std::io::ErrorKind::UnexpectedEof => {
            "gzip data ends early: the file is cut short".to_string()
        }
        _ => format!("gzip data is damaged ({e})"),
    }
}

fn scratch_failed(path: &Path, e: &std::io::Error) -> Error {
    Error::resource(format!(
        "{}: cannot write its decompressed bytes to the scratch directory ({e}); free space there \
         or choose another scratch directory",
        path.display()
    ))
}

/// A reader counting the bytes read through it into a meter.
struct Metered<'a, R> {
    inner: R,
    meter: &'a Meter,
}

impl<R: Read> Read for Metered<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.meter.add(n as u64);
        Ok(n)
    }
}

/// Writes through gzip compression into `out`; [`finish`](flate2::write::GzEncoder::finish)
/// writes the trailer. The default level (6), as `gzip` uses.
pub(super) fn encoder<W: Write>(out: W) -> flate2::write::GzEncoder<W> {
    flate2::write::GzEncoder::new(out, flate2::Compression::default())
}
