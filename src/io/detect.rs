//! What a file is, decided from its type and its first bytes before anything else is read: a
//! mesh format, or a refusal that says what the file looks like instead.
//!
//! Regular files are mapped; named pipes and character devices (`<(zcat mesh.ply.gz)`,
//! `/dev/stdin`) are streams, read into memory up to [`STREAM_LIMIT`]; directories, block devices
//! and sockets are refused from their metadata. The first [`HEAD`] bytes decide, in this order
//! (a stream's before the rest of it is read, so that `/dev/zero` is refused at once):
//!
//! 1. nothing, or only zero bytes (an unwritten or zeroed file): refused;
//! 2. a compression or archive signature (zip, bzip2, xz, zstd, 7-Zip; gzip where the caller has
//!    not decompressed it already) or a UTF-16/UTF-32 byte-order mark: refused, saying what to do;
//! 3. the line `ply` (after an optional UTF-8 byte-order mark), or GLB's magic `glTF`;
//! 4. a binary STL, by its exact size `84 + 50·n` (its 80-byte header is free-form, so it is
//!    recognised before any text rule can misread it);
//! 5. UTF-16 without a byte-order mark (every other byte zero) and text whose lines end with a
//!    bare carriage return (classic Mac OS): refused, saying what to do;
//! 6. after an optional UTF-8 byte-order mark: an OFF magic word, an ASCII STL (`solid` in any
//!    case, then `facet` or `endsolid`);
//! 7. otherwise the extension (OBJ and `.gltf` JSON have no signature; a `.ply`, `.off` or `.stl` file that was not
//!    recognised gets its own reader's message about what is wrong).

use std::fs::Metadata;
use std::path::Path;

use super::{Format, gltf, off, ply, stl, without_bom};

/// How many bytes of a file recognise it: everything below is decided from them alone.
pub(super) const HEAD: usize = 64 << 10;

/// How an input is read, from its file type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    /// A regular file: memory-mapped.
    File,
    /// A named pipe or a character device: read into memory, at most [`STREAM_LIMIT`] bytes.
    Stream,
}

/// The most a stream is read into memory: a larger mesh is saved to a file first (files of any
/// size are mapped, and can go out of core).
pub(super) const STREAM_LIMIT: u64 = 4 << 30;

/// How `meta` (taken without opening the file) is read, or why it is refused.
pub(super) fn file_type(meta: &Metadata) -> Result<Kind, String> {
    let t = meta.file_type();
    if t.is_file() {
        return Ok(Kind::File);
    }
    if t.is_dir() {
        return Err("is a directory, not a mesh file".into());
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() || t.is_char_device() {
            return Ok(Kind::Stream);
        }
        let kind = if t.is_block_device() {
            "a block device"
        } else if t.is_socket() {
            "a socket"
        } else {
            "a special file"
        };
        Err(format!("not a regular file ({kind})"))
    }
    #[cfg(not(unix))]
    Err("not a regular file".into())
}

/// Compressed data and archives, by their magic bytes, with what to do about them.
const SIGNATURES: &[(&[u8], &str)] = &[
    (b"\x1f\x8b", "gzip-compressed data: decompress it first"),
    (b"PK\x03\x04", "zip archive: extract the mesh first"),
    (b"PK\x05\x06", "zip archive (empty): extract the mesh first"),
    (b"\xfd7zXZ\x00", "xz-compressed data: decompress it first"),
    (
        b"\x28\xb5\x2f\xfd",
        "zstd-compressed data: decompress it first",
    ),
    (
        b"7z\xbc\xaf\x27\x1c",
        "7-Zip archive: extract the mesh first",
    ),
    // UTF-32 before UTF-16: FF FE 00 00 starts with the UTF-16 little-endian mark.
    (b"\xff\xfe\x00\x00", "UTF-32 text: save it as UTF-8"),
    (b"\x00\x00\xfe\xff", "UTF-32 text: save it as UTF-8"),
    (b"\xff\xfe", "UTF-16 text: save it as UTF-8"),
    (b"\xfe\xff", "UTF-16 text: save it as UTF-8"),
];

/// The format of the `len` bytes `head` starts with, decompressed from the gzip file `path`: as
/// [`detect`] would see them in a file named without `.gz`; gzip inside gzip is refused.
pub(super) fn detect_inner(head: &[u8], len: u64, path: &Path) -> Result<Format, String> {
    if len == 0 {
        return Err("gzip-compressed, and holds nothing".into());
    }
    if super::gzip::is_gzip(head) {
        return Err("gzip-compressed twice: decompress the outer layer first".into());
    }
    detect(head, len, &super::gzip::inner_name(path))
}

/// The format of a file of `len` bytes whose first bytes are `head` (all of them when the file is
/// shorter than [`HEAD`]), or why it is refused. `path` gives the extension for OBJ.
pub(super) fn detect(head: &[u8], len: u64, path: &Path) -> Result<Format, String> {
    let head = &head[..head.len().min(HEAD)];
    refuse(head, len)?;
    let text = without_bom(head);
    if ply::has_magic(text) {
        return Ok(Format::Ply);
    }
    if gltf::has_magic(head) {
        return Ok(Format::Glb);
    }
    if stl::is_binary(head, len) {
        return Ok(Format::Stl);
    }
    if is_utf16(head) {
        return Err("UTF-16 text: save it as UTF-8".into());
    }
    if has_bare_cr(head) {
        return Err("lines end with a bare carriage return (classic Mac OS): \
                    convert the line endings to LF"
            .into());
    }
    if off::has_magic(text) {
        return Ok(Format::Off);
    }
    if stl::is_ascii(text) {
        return Ok(Format::Stl);
    }
    Format::from_extension(path).ok_or_else(|| {
        "unknown format: not PLY, GLB, OFF or STL by content, and the extension is not \
         .ply, .obj, .off, .stl, .gltf or .glb"
            .into()
    })
}

/// The refusals decided by the first bytes alone, whatever the length: zero bytes only,
/// compressed data, archives, UTF-16/UTF-32 byte-order marks. `len` is the file's length
/// (`u64::MAX` for a stream not read to its end).
pub(super) fn refuse(head: &[u8], len: u64) -> Result<(), String> {
    if len == 0 || head.is_empty() {
        return Err("empty file".into());
    }
    if head.iter().all(|&b| b == 0) {
        return Err(if head.len() as u64 == len {
            format!("the file is {len} zero bytes: not a mesh file")
        } else {
            format!(
                "the first {} bytes are all zero: not a mesh file",
                head.len()
            )
        });
    }
    if let Some((_, what)) = SIGNATURES.iter().find(|(magic, _)| head.starts_with(magic)) {
        return Err((*what).into());
    }
    // bzip2: `BZh` and the block size, a digit from 1 to 9 (text may start with `BZh`).
    if head.starts_with(b"BZh") && head.get(3).is_some_and(|b| (b'1'..=b'9').contains(b)) {
        return Err("bzip2-compressed data: decompress it first".into());
    }
    Ok(())
}

/// The length a binary STL starting with `head` would have, from its triangle count (a stream
/// has no length to check it against until it is read).
pub(super) fn binary_stl_length(head: &[u8]) -> Option<u64> {
    let count = head.get(80..84)?;
    Some(84 + 50 * u64::from(u32::from_le_bytes(count.try_into().ok()?)))
}

/// Whether the text starts as UTF-16 without a byte-order mark: in three quarters or more of its
/// first 32 characters one byte of the pair is zero and the other printable ASCII (the rest may be
/// other characters).
fn is_utf16(head: &[u8]) -> bool {
    let pairs = || head.chunks_exact(2).take(32);
    let n = pairs().count();
    let text = |b: u8| b.is_ascii_graphic() || b.is_ascii_whitespace();
    let most = |ascii_first: bool| {
        // Little-endian: the ASCII byte first; big-endian: the zero byte first.
        let ascii = |p: &[u8]| {
            if ascii_first {
                text(p[0]) && p[1] == 0
            } else {
                p[0] == 0 && text(p[1])
            }
        };
        n >= 2 && pairs().filter(|p| ascii(p)).count() * 4 >= n * 3
    };
    most(true) || most(false)
}

/// Whether the first line (up to the first `\n`) is text that holds a carriage return followed
/// by more text: lines that end with `\r` alone. A `\r` before `\n` (CRLF) is an ordinary line end.
fn has_bare_cr(head: &[u8]) -> bool {
    let line = head.split(|&b| b == b'\n').next().unwrap_or_default();
    let text = line
        .iter()
        .all(|&b| b >= 0x20 || matches!(b, b'\t' | b'\r' | b'\x0c'));
    text && line
        .windows(2)
        .any(|w| w[0] == b'\r' && !matches!(w[1], b'\r' | b'\n'))
}
