//! Mesh file input and output. Knows nothing of smoothing.
//!
//! - [`read_mesh`] reads only regular files. It recognises the file from its first 64 KiB before
//!   anything else is read (`detect`): `ply` magic, GLB's `glTF` magic, `OFF` magic, a binary
//!   STL whose size is exactly `84 + 50·n`, an ASCII STL starting with `solid`, and otherwise the
//!   extension (`.obj`, `.gltf`); gzip is decompressed first and what it holds recognised so
//!   (`gzip`); other compressed data, UTF-16 text and zeroed files are refused there. Then it maps
//!   the file (one `unsafe` boundary, with a plain-read fallback) and decodes it.
//! - [`write_mesh`] picks the writer from the output's extension (`.ply .obj .off .stl .gltf
//!   .glb`, any case; the first four with `.gz` after it are gzip-compressed) and writes atomically: a temporary file beside the target, flushed, synced
//!   and renamed into place only when complete; on failure nothing is left under the target's
//!   name (a `.gltf` output's new buffer files are each written so, before it).
//! - [`write_ply_streamed`] writes a mesh larger than memory as binary PLY, its vertices and
//!   triangles handed over one at a time (e.g. by [`crate::shapes::Subdivision`]): the same
//!   header and records as [`write_mesh`] writes for that mesh, written atomically too.
//!
//! # Formats
//!
//! | format | read | write |
//! |---|---|---|
//! | PLY | binary little/big-endian (memory-mapped, own header parser, stride decode); ASCII (own strict parser, see `ply::ascii`); faces or triangle strips (`tristrips`, kept as they are for a PLY output) | the input's layout when it came from PLY, else binary little-endian `x y z float` (or `double`, see [`Precision`]) + `list uchar int vertex_indices` |
//! | OBJ | `v` (first three numbers), `f` with `i`, `i/t`, `i//n`, `i/t/n` and negative (relative) indices (`vt`/`vn` references checked too); every other statement whose keyword is a name kept (see `obj`) | the input's text with only the `v` positions and the `vn` normals rewritten when it came from OBJ (see `obj::layout`), else `v` + `f` |
//! | OFF | `OFF` and its `C`/`N`/`ST` variants (vertex colours, normals, texture coordinates, face colours), `#` comments | the input's text with new `x y z` (and normals) when it carried colours, normals or texture coordinates, else `OFF` |
//! | STL | binary and ASCII (keywords in any case) | binary (with the input's header and attribute bytes when it came from binary STL); ASCII with the input's solid names when it came from ASCII STL |
//! | glTF 2.0 | `.glb`, and `.gltf` with external or `data:` URI buffers: the triangle primitives of every mesh, Draco-compressed ones decoded (see `gltf`) | from a glTF input, to the same kind: its JSON and buffers with new positions and normals; from any other, a plain glTF (positions, normals, indices) |
//!
//! Text (OBJ, OFF, ASCII STL, a PLY header) is ASCII or UTF-8, with an optional UTF-8 byte-order
//! mark, which is skipped; lines end with LF or CRLF. A header line (PLY, OFF's magic and counts,
//! STL's `solid` line) is at most 64 KiB, a PLY header at most 1 MiB.
//!
//! # Conventions
//!
//! - Vertices keep the file's order and ids (0-based); unreferenced vertices are kept.
//! - Faces keep their orientation. A polygon `(v0, v1, …, vn)` is fan-triangulated into
//!   `(v0, v1, v2), (v0, v2, v3), …`; [`Source::polygons_triangulated`] counts such faces and
//!   [`Source::face_sizes`] keeps the corner counts so that PLY/OBJ/OFF outputs write the original
//!   polygons back. Degenerate faces (a repeated index) and duplicate faces are valid and kept.
//! - STL stores every triangle with its own three corners: the reader merges corners whose
//!   coordinates are equal (as values: `0.0` and `-0.0` are one vertex) into one vertex, numbered
//!   in order of first appearance and placed where it first appears, so that the mesh has
//!   connectivity. STL coordinates are single precision by definition; ASCII STL values are
//!   rounded to `f32` before merging.
//! - Positions are `f64` in memory. A `float` output rounds them to `f32`; ASCII outputs print the
//!   shortest text that reads back to the same value (`f32` or `f64` as the precision says), or,
//!   for an OBJ or OFF input whose coordinates all had one number of decimals (at least 4: a
//!   fixed-point export), the shortest text of the value rounded to those decimals
//!   ([`Source::decimals`]).
//!
//! # PLY round trip
//!
//! A mesh read from PLY carries its header model and every record the mesh itself cannot
//! regenerate ([`PlyLayout`]); written to PLY it keeps every element and property (colour,
//! confidence, quality, any other element), the vertex order, the original polygons, the property
//! types (a `float` coordinate stays `float`, a `double` stays `double`), the comments and `obj_info`
//! lines, and the encoding: ASCII stays ASCII, binary stays binary, and **big-endian becomes
//! little-endian** (records are held little-endian in memory; every reader understands both).
//! Only `x y z` change, and **the normals `nx ny nz` are recomputed** from the new positions
//! (area-weighted face normals, normalised; a vertex with no area around it gets `0 0 0`) instead
//! of being copied stale. Type names are written in their classic spelling (`float`, not `float32`).
//! A source layout describes the input: a mesh whose vertex count or triangles no longer match it
//! is refused by the writer (clear `mesh.source.layout` to write a plain PLY).
//!
//! # Bad input
//!
//! Every reader is strict and never panics: malformed input gives [`Error::InvalidInput`] with a
//! one-line message naming the element and its byte offset or line, e.g.
//! `face 12 (byte 3456): vertex index 99 out of range (0..50)`. Element numbers count from 0, lines
//! from 1. Header counts are checked against the file size before anything is allocated from them.
//! Rejected: NaN/Inf coordinates, indices out of range or negative, faces with fewer than 3
//! corners, truncated data, trailing non-whitespace after the data, a missing `end_header`, tokens
//! that are not numbers, unknown formats, and any file in which nothing was recognised: anything
//! but a regular file (a directory, a device such as `/dev/zero`, a named pipe), a file of zero
//! bytes, compressed data (but gzip) or an archive, UTF-16 or UTF-32 text, lines ending in a bare carriage
//! return, an OBJ without a single `v` or `f` statement or with a line that starts with something
//! other than a keyword (binary data, prose with punctuation). Each says what the file looks like,
//! e.g. `gzip-compressed data: decompress it first`. A well-formed empty mesh (`OFF` with
//! `0 0 0`, a PLY with 0 vertices) is read as one. A binary PLY header whose counts need more
//! bytes than the file has is reported as such before any count is used, however large (a 1 KB
//! file claiming 10^12 vertices fails in microseconds). Tokens that are not UTF-8 are shown with their bytes
//! escaped (`"\xff\xfe"`). The corpus in `tests/corpus/cases.rs` lists every such case with its
//! exact message, and `fuzz/` fuzzes each reader.
//!
//! # Faults
//!
//! - **A file changing while it is read**: the size and modification time of the opened file are
//!   compared before and after the decode; a difference gives `file changed while it was being read
//!   (size A -> B bytes)` or `(modification time changed)`, reported in preference to whatever the
//!   decode made of the changed bytes. A file *replaced* by a rename is another inode and the opened
//!   one is read consistently. A mapped file **truncated** during the decode raises `SIGBUS`, which
//!   kills the process: nothing is written, but the message is the signal's, not ours.
//! - **Killed while writing** (`SIGKILL`, power loss): the output is written to
//!   `.<name>.tmp-<pid>-<n>` beside the target and renamed over it only when complete and synced,
//!   so the target holds either its previous content or the complete new file. SIGINT, SIGTERM
//!   and SIGHUP remove it (`crate::signals`, set up by the command line). SIGKILL cannot: a stale
//!   `.<name>.tmp-*` can remain (hidden, never under the target's name), and the next write of the
//!   same target removes it once the process `<pid>` is gone (per `/proc` of the machine that
//!   writes: on a file system shared by several machines, a temporary file of a process running
//!   elsewhere can be taken for a leftover, and that run then fails at its rename).
//! - **Disk full or any write error**: the error is reported as `<target>: <os error>` (e.g. `No
//!   space left on device (os error 28)`), the temporary file is removed and the previous target, if
//!   any, is left as it was.

mod atomic;
mod detect;
mod digest;
mod gltf;
mod gzip;
mod obj;
mod off;
mod ply;
mod png;
mod stl;
mod stream;
mod text;

pub(crate) use atomic::{Destination, destination, write_atomically};
pub use digest::{Sha256, sha256_counted, sha256_file};
pub(crate) use gltf::{buffer_name_of, referenced_files};
pub(crate) use gzip::refused_output;

use std::fs::File;
use std::io::{Read, Write};
use std::path::Path;
use std::sync::Arc;

pub use self::png::{encode_png, write_png};
pub use crate::mesh::{Format, Precision, Source};
pub use gltf::GltfLayout;
pub(crate) use ply::header_counts;
pub use ply::{PlyEncoding, PlyLayout};
pub use stream::{PlyStream, write_ply_streamed, write_ply_streamed_in};
pub(crate) use text::{
    Digits, F32, F64, Fixed, MAX_HEADER_LINE, Spelling, bad_index, fits_single, integer, lines,
    number, show, text_position, tokens, vertex_normals, without_bom, write_xyz,
};

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::meter::{Counted, Meter};

/// The size of the bytes an input file holds: its length, or for a gzip-compressed file a guess
/// at its decompressed length (see `gzip`), for the choice between memory and scratch.
pub fn content_size(path: &Path) -> Result<u64> {
    match gzip::guessed_size(path) {
        Some(size) => Ok(size),
        None => Ok(std::fs::metadata(path)
            .map_err(|e| Error::io(path, e))?
            .len()),
    }
}

/// What [`not_carried`] names for a glTF input's Draco compression, which a glTF output does not
/// keep (its geometry is written uncompressed).
pub const DRACO_DROPPED: &str = "Draco compression";

/// What a mesh read from a file carried that its output at `path` will not: texture coordinates,
/// colours, normals, materials and the file's other properties when the output is another format
/// (which is written plain: positions and faces, and into glTF normals and a PLY's per-vertex
/// colours and texture coordinates), polygons when it holds triangles only, and a glTF input's
/// Draco compression ([`DRACO_DROPPED`]). Empty when nothing is lost (the same format keeps
/// everything; a mesh from no file carried nothing). For the one line that tells a user so.
pub fn not_carried(source: &Source, path: &Path) -> Vec<String> {
    let (Some(from), Some(to)) = (source.format, Format::from_extension(path)) else {
        return Vec::new();
    };
    let mut lost = Vec::new();
    let gltf = matches!(to, Format::Gltf | Format::Glb);
    if from != to {
        let carried = source
            .layout
            .as_ref()
            .map(|l| l.carries())
            .unwrap_or_default();
        // A plain glTF takes per-vertex colours and texture coordinates.
        let (colours, uvs) = match (gltf, source.layout.as_deref()) {
            (true, Some(l)) => l.has_vertex_attributes(),
            _ => (false, false),
        };
        for (had, what) in [
            (carried.uvs && !uvs, "texture coordinates"),
            (carried.colours && !colours, "colours"),
            // A plain glTF has its own (recomputed) normals.
            (carried.normals && !gltf, "normals"),
            (carried.materials, "materials"),
        ] {
            if had {
                lost.push(what.to_string());
            }
        }
        if !carried.other.is_empty() {
            lost.push(format!("other data ({})", carried.other.join(", ")));
        }
    }
    if gltf && GltfLayout::of(source).is_some_and(GltfLayout::decompressed) {
        lost.push(DRACO_DROPPED.to_string());
    }
    if source.polygons_triangulated > 0 && (gltf || to == Format::Stl) {
        lost.push(format!(
            "{} polygons (written as their triangles)",
            source.polygons_triangulated
        ));
    }
    lost
}

/// Read a mesh file onto the heap.
pub fn read_mesh(path: &Path) -> Result<Mesh> {
    read_mesh_in(path, &crate::mesh::Storage::heap())
}

/// Read a mesh file, placing the positions and triangles of a binary PLY as `storage` says (in
/// memory-mapped scratch files for inputs larger than memory). Other formats, and big-endian
/// bodies (byte-swapped through memory), are read onto the heap.
pub fn read_mesh_in(path: &Path, storage: &crate::mesh::Storage) -> Result<Mesh> {
    read_mesh_metered(path, storage, &Meter::default())
}

/// [`read_mesh_in`], counting the file's bytes into `meter`, whose total the caller sets to the
/// file's size: the binary PLY decoders count as they go, once per chunk of records; the other
/// readers count the whole file when they are done. The same mesh.
pub fn read_mesh_metered(
    path: &Path,
    storage: &crate::mesh::Storage,
    meter: &Meter,
) -> Result<Mesh> {
    read_mesh_kept(path, storage, meter).map(|(mesh, _)| mesh)
}

/// [`read_mesh_metered`], also handing back the file held open for [`Kept::read_again`] (not for
/// a stream, which cannot be read twice).
pub fn read_mesh_kept(
    path: &Path,
    storage: &crate::mesh::Storage,
    meter: &Meter,
) -> Result<(Mesh, Option<Kept>)> {
    let read = read_mesh_observed(path, storage, meter, |_| ())?;
    meter.complete();
    Ok(read)
}

/// An input file held open after it was read, so that a long run can read it again instead of
/// keeping all it read: the same file whatever is renamed or deleted under its name meanwhile, and
/// its size and modification time to tell whether it was rewritten in place.
#[derive(Debug)]
pub struct Kept {
    file: File,
    path: std::path::PathBuf,
    /// The file as it was read.
    seen: std::fs::Metadata,
}

impl Kept {
    /// The mesh read again, as the first read made it; an error, before any decoding, if the file
    /// changed since (and, as every read, if it changes while being read).
    /// With [`Coordinates::Skip`] a binary or ASCII PLY file's vertex records are passed over
    /// (the mesh has no positions, and its layout keeps no vertex records for a writer; other
    /// formats decode them anyway). Returns the mesh and the file's vertex count.
    pub fn read_again(
        mut self,
        storage: &crate::mesh::Storage,
        meter: &Meter,
        coordinates: Coordinates,
    ) -> Result<(Mesh, usize)> {
        let path = self.path.clone();
        let now = self.file.metadata().map_err(|e| Error::io(&path, e))?;
        if let Some(what) = change(&self.seen, &now) {
            return Err(Error::invalid(
                &path,
                format!("file changed on disk during the run ({what}); nothing was written"),
            ));
        }
        std::io::Seek::seek(&mut self.file, std::io::SeekFrom::Start(0))
            .map_err(|e| Error::io(&path, e))?;
        let read = read_open(
            &mut self.file,
            now.len(),
            &path,
            storage,
            meter,
            coordinates,
        )?;
        changed_while_read(&mut self.file, &now, &path)?;
        meter.complete();
        Ok(read)
    }
}

/// Decode a mesh from bytes already in memory, choosing the reader as [`read_mesh`] does (by
/// content, else by the extension of `name`, which also prefixes error messages). For fuzzing and
/// for inputs that do not come from a file.
pub fn read_mesh_bytes(bytes: &[u8], name: &Path) -> Result<Mesh> {
    parse(bytes, name).map_err(|what| Error::invalid(name, what))
}

/// Decode `bytes` with the reader of `format`, whatever their content looks like (the fuzz
/// targets use it so that each one exercises its own reader). `name` prefixes error messages.
pub fn read_format_bytes(bytes: &[u8], format: Format, name: &Path) -> Result<Mesh> {
    decode(bytes, format).map_err(|what| Error::invalid(name, what))
}

/// [`read_mesh`] calling `decoded(path)` between the decode and the final size/mtime check, so
/// that the unit tests can change the file exactly there.
fn read_mesh_observed(
    path: &Path,
    storage: &crate::mesh::Storage,
    meter: &Meter,
    decoded: impl FnOnce(&Path),
) -> Result<(Mesh, Option<Kept>)> {
    // The type before opening: opening a named pipe blocks until a writer comes.
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    let kind = detect::file_type(&meta).map_err(|what| Error::invalid(path, what))?;
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let before = file.metadata().map_err(|e| Error::io(path, e))?;
    // Again on the opened file, in case another one was put under the name meanwhile.
    if detect::file_type(&before).map_err(|what| Error::invalid(path, what))? != kind {
        return Err(Error::invalid(path, "file replaced while it was opened"));
    }
    if kind == detect::Kind::Stream {
        return read_stream(&mut file, path).map(|mesh| (mesh, None));
    }
    let mesh = read_open(
        &mut file,
        before.len(),
        path,
        storage,
        meter,
        Coordinates::Decode,
    )
    .map(|(mesh, _)| mesh);
    decoded(path);
    changed_while_read(&mut file, &before, path)?;
    let kept = Kept {
        file,
        path: path.to_path_buf(),
        seen: before,
    };
    Ok((mesh?, Some(kept)))
}

/// A file rewritten under us decodes into a mix of old and new bytes, or into an error about
/// bytes that are no longer there: compare the size and modification time seen before and after
/// the decode, and report a change before whatever the decode made of it. (A file replaced by a
/// rename is another inode: the one opened is read consistently.)
fn changed_while_read(file: &mut File, before: &std::fs::Metadata, path: &Path) -> Result<()> {
    let after = file.metadata().map_err(|e| Error::io(path, e))?;
    match change(before, &after) {
        Some(what) => Err(Error::invalid(
            path,
            format!("file changed while it was being read ({what})"),
        )),
        None => Ok(()),
    }
}

/// How a file's size or modification time differs between two looks at it, if it does.
fn change(before: &std::fs::Metadata, after: &std::fs::Metadata) -> Option<String> {
    if before.len() != after.len() {
        Some(format!("size {} -> {} bytes", before.len(), after.len()))
    } else if before.modified().ok() != after.modified().ok() {
        Some("modification time changed".to_string())
    } else {
        None
    }
}

/// Write `mesh` to `path`, choosing the format from the extension, atomically.
pub fn write_mesh(path: &Path, mesh: &Mesh) -> Result<()> {
    write_mesh_metered(path, mesh, &Meter::default())
}

/// Values added to every vertex of a written mesh (a deviation field): PLY only, as the vertex
/// properties `float quality` and, with colours, `uchar red green blue`, after the vertex's own
/// properties; a property of those names that the mesh's PLY layout already has keeps its place
/// and takes the new values (an integer `quality` becomes `float`). Everything else is written as
/// without them.
#[derive(Clone, Copy)]
pub struct VertexValues<'a> {
    /// One value per vertex.
    pub quality: &'a [f64],
    /// The colour of vertex `i`.
    pub colours: Option<&'a (dyn Fn(usize) -> [u8; 3] + Sync)>,
}

/// Why an output cannot carry [`VertexValues`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValuesRefused {
    /// The format (named) carries per-vertex colours but no per-vertex value.
    ColoursOnly(&'static str),
    /// The format carries neither.
    Unsupported,
}

impl std::fmt::Display for ValuesRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self {
            ValuesRefused::ColoursOnly(format) => write!(
                f,
                "{format} carries per-vertex colours but no per-vertex value: ask for the colours, or write a PLY"
            ),
            ValuesRefused::Unsupported => f.write_str(
                "per-vertex values are written into PLY outputs (and as colours into OBJ and glTF outputs) only",
            ),
        }
    }
}

/// Whether an output at `path` can carry [`VertexValues`], with their colours or without.
/// PLY carries both (`quality`, `red green blue`); OBJ the colours alone (`v x y z r g b`, which
/// MeshLab and CloudCompare read), glTF too (`COLOR_0`).
pub fn check_vertex_values(path: &Path, colours: bool) -> std::result::Result<(), ValuesRefused> {
    match Format::from_extension(path) {
        Some(Format::Ply) => Ok(()),
        Some(Format::Obj | Format::Gltf | Format::Glb) if colours => Ok(()),
        Some(Format::Obj) => Err(ValuesRefused::ColoursOnly("an OBJ file")),
        Some(Format::Gltf | Format::Glb) => {
            Err(ValuesRefused::ColoursOnly("a glTF file (COLOR_0)"))
        }
        _ => Err(ValuesRefused::Unsupported),
    }
}

/// [`write_mesh_metered`] with `values` in the vertices (see [`VertexValues`]).
pub fn write_mesh_with(
    path: &Path,
    mesh: &Mesh,
    values: &VertexValues,
    meter: &Meter,
) -> Result<()> {
    check_vertex_values(path, values.colours.is_some())
        .map_err(|what| Error::invalid(path, format!("cannot write: {what}")))?;
    if values.quality.len() != mesh.positions.len() {
        return Err(Error::topology(format!(
            "{} vertex values for {} vertices",
            values.quality.len(),
            mesh.positions.len()
        )));
    }
    write_mesh_counted(path, mesh, Some(values), meter)?;
    match meter.done() {
        0 => meter.complete(),
        written => meter.set_total(written),
    }
    Ok(())
}

/// [`write_mesh`], counting the bytes written into `meter` once per MiB (glTF: when it is
/// done). The caller's total is an estimate (a text file's size is known once written): it is
/// set to the bytes written when the write succeeds. The same file.
pub fn write_mesh_metered(path: &Path, mesh: &Mesh, meter: &Meter) -> Result<()> {
    write_mesh_counted(path, mesh, None, meter)?;
    match meter.done() {
        0 => meter.complete(),
        written => meter.set_total(written),
    }
    Ok(())
}

fn write_mesh_counted(
    path: &Path,
    mesh: &Mesh,
    values: Option<&VertexValues>,
    meter: &Meter,
) -> Result<()> {
    let format = Format::from_extension(path).ok_or_else(|| {
        Error::invalid(
            path,
            "unknown output extension (use .ply, .obj, .off, .stl, .gltf or .glb)",
        )
    })?;
    // Everything that can make a mesh unwritable is found here, before a file exists.
    check_mesh(mesh)
        .and_then(|()| match format {
            Format::Ply => ply::check_writable(mesh),
            Format::Obj | Format::Off => {
                let faces = match format {
                    Format::Off => off::check_writable(mesh),
                    _ => Faces::of(mesh)
                        .check()
                        .and_then(|()| obj::check_writable(mesh)),
                };
                faces.and_then(|()| match mesh.source.precision {
                    Precision::Float => fits_single(mesh),
                    Precision::Double => Ok(()),
                })
            }
            Format::Stl => stl::check_writable(mesh),
            Format::Gltf | Format::Glb => match gzip::refused_output(format, path) {
                Some(why) => Err(why.to_string()),
                None => gltf::check_writable(mesh, format),
            },
        })
        .map_err(|what| Error::invalid(path, format!("cannot write: {what}")))?;
    if let Format::Gltf | Format::Glb = format {
        // Also writes buffer files beside the output, each atomically.
        return gltf::write(path, mesh, values.and_then(|v| v.colours));
    }
    if gzip::has_gz_extension(path) {
        // The meter counts the bytes before compression: the estimate it started from is theirs.
        return atomic::write_atomically(path, |out| {
            let mut gz = gzip::encoder(out);
            write_as(format, &mut Counted::new(&mut gz, meter), mesh, values)?;
            gz.finish().map(|_| ())
        });
    }
    atomic::write_atomically(path, |out| {
        write_as(format, &mut Counted::new(out, meter), mesh, values)
    })
}

/// `mesh` into `out` as `format` says (not glTF, which writes its own files), with `values` (PLY;
/// OBJ their colours; checked before).
fn write_as(
    format: Format,
    out: &mut impl Write,
    mesh: &Mesh,
    values: Option<&VertexValues>,
) -> std::io::Result<()> {
    match format {
        Format::Ply => ply::write(out, mesh, values),
        Format::Obj => obj::write(out, mesh, values.and_then(|v| v.colours)),
        Format::Off => off::write(out, mesh),
        Format::Stl => stl::write(out, mesh),
        Format::Gltf | Format::Glb => Err(std::io::Error::other("glTF is written by gltf::write")),
    }
}

/// How the coordinates of a mesh read back from the file that [`write_mesh`] makes of it, so that
/// a caller can measure an output as stored without reading it back (a run's output statistics).
/// Each coordinate is stored on its own, so this is a function of the value alone: rounded to
/// the file's type, or printed as text and parsed again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stored([Axis; 3]);

/// How one coordinate is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Axis {
    /// As this binary type: PLY's types (ASCII PLY parses each as its type, so the same), `float`
    /// for STL (ASCII STL parses `f32`) and glTF, `double` for text in double precision (the
    /// shortest text that reads back to the same `f64`).
    Binary(ply::Scalar),
    /// Text in single precision (OBJ, OFF): the shortest text of the `f32`, read back as `f64`.
    SingleText,
    /// Text rounded to this many decimals (OBJ, OFF of a fixed-point input, see
    /// [`Source::decimals`]), read back as `f64`.
    Decimals(u8),
}

impl Stored {
    /// What [`write_mesh`] stores for `mesh` at `path` (the format from its extension); `None`
    /// when it would not write it (an unknown extension, a PLY layout without coordinates).
    pub fn of(path: &Path, mesh: &Mesh) -> Option<Stored> {
        use ply::Scalar::{F32, F64};
        let text = match (mesh.source.decimals, mesh.source.precision) {
            (Some(d), _) => Axis::Decimals(d),
            (None, Precision::Float) => Axis::SingleText,
            (None, Precision::Double) => Axis::Binary(F64),
        };
        Some(Stored(match Format::from_extension(path)? {
            Format::Ply => ply::coordinate_types(mesh)?.map(Axis::Binary),
            Format::Obj | Format::Off => [text; 3],
            Format::Stl | Format::Gltf | Format::Glb => [Axis::Binary(F32); 3],
        }))
    }

    /// Whether every `f64` reads back as itself.
    pub fn is_exact(&self) -> bool {
        self.0 == [Axis::Binary(ply::Scalar::F64); 3]
    }

    /// Whether every `f64` reads back as itself rounded to `f32` (a binary `float` layout).
    pub fn is_f32(&self) -> bool {
        self.0 == [Axis::Binary(ply::Scalar::F32); 3]
    }

    /// `p` as it reads back. `p` must be writable (see [`write_mesh`]'s checks: in the range of
    /// an integer type, finite in `f32`).
    pub fn round(&self, p: glam::DVec3) -> glam::DVec3 {
        let axis = |a: Axis, x: f64| match a {
            // The common case, without the round trip through bytes (the same value).
            Axis::Binary(ply::Scalar::F32) => f64::from(x as f32),
            Axis::Binary(t) => {
                let mut bytes = [0u8; 8];
                t.put(x, &mut bytes);
                t.get(&bytes).unwrap_or(x)
            }
            Axis::SingleText => reread(F32(x as f32), x),
            Axis::Decimals(d) => reread(Fixed(x, d), x),
        };
        let [a, b, c] = self.0;
        glam::DVec3::new(axis(a, p.x), axis(b, p.y), axis(c, p.z))
    }

    /// `p` as it reads back, kept within `limit` of `origin` when `p` is (the deviation bound
    /// must hold in the file as written, not only in `f64`): the nearest stored value when it is
    /// within the bound; else each axis that rounding moved away from `origin` takes the stored
    /// neighbour on `origin`'s side of `p` instead, so that no axis lies farther from `origin`
    /// than `p`'s does (when `origin` is itself stored exactly, as an input written back in its
    /// own type is); then, while still beyond (`p` itself may lie beyond by an `f64` rounding),
    /// the axis whose step toward `origin` shortens the distance most steps, a few times at most.
    pub fn round_within(&self, p: glam::DVec3, origin: glam::DVec3, limit: f64) -> glam::DVec3 {
        let mut r = self.round(p);
        if self.is_exact() || r.distance(origin) <= limit {
            return r;
        }
        for i in 0..3 {
            if (r[i] - origin[i]).abs() > (p[i] - origin[i]).abs() {
                r[i] = self.step_toward(i, r[i], origin[i]);
            }
        }
        for _ in 0..4 {
            if r.distance(origin) <= limit {
                break;
            }
            let shortest = (0..3)
                .map(|i| {
                    let mut q = r;
                    q[i] = self.step_toward(i, r[i], origin[i]);
                    q
                })
                .min_by(|a, b| a.distance(origin).total_cmp(&b.distance(origin)));
            match shortest {
                Some(q) if q != r => r = q,
                _ => break,
            }
        }
        r
    }

    /// The stored value of axis `i` next to the stored value `x`, on `toward`'s side; `x` when no
    /// stored value lies closer to `toward`.
    fn step_toward(&self, i: usize, x: f64, toward: f64) -> f64 {
        if x == toward {
            return x;
        }
        let up = toward > x;
        let next = match self.0[i] {
            Axis::Binary(ply::Scalar::F64) => return x,
            Axis::Binary(t) if t.int_range().is_some() => x + if up { 1.0 } else { -1.0 },
            Axis::Decimals(d) => {
                let step = 10f64.powi(-i32::from(d));
                x + if up { step } else { -step }
            }
            // `x` reads back from an `f32` (its text, for text), which it rounds to again.
            Axis::Binary(_) | Axis::SingleText => {
                let f = x as f32;
                f64::from(next_f32(f, up))
            }
        };
        let mut one = *self;
        one.0 = [self.0[i]; 3];
        let stepped = one.round(glam::DVec3::splat(next)).x;
        // Past `toward`, the step is kept only if it ends nearer.
        match (stepped - toward).abs() < (x - toward).abs() {
            true => stepped,
            false => x,
        }
    }
}

/// The value a writer's `text` of `x` reads back as, the text made on the stack: this runs for
/// every coordinate of an output.
fn reread(text: impl std::fmt::Display, x: f64) -> f64 {
    let mut bytes = [0u8; 48];
    let mut rest = &mut bytes[..];
    let _ = write!(rest, "{text}");
    let len = 48 - rest.len();
    number(&bytes[..len]).unwrap_or(x)
}

/// The `f32` next to the finite `f`, above it when `up`, else below (`f32::next_up` and
/// `next_down` are younger than the crate's minimum Rust version).
fn next_f32(f: f32, up: bool) -> f32 {
    if f == 0.0 {
        let tiny = f32::from_bits(1);
        return if up { tiny } else { -tiny };
    }
    // Away from zero the magnitude's bits grow by one, toward zero they shrink by one.
    let away = (f > 0.0) == up;
    let bits = f.to_bits();
    f32::from_bits(if away { bits + 1 } else { bits - 1 })
}

/// Recognises and decodes an opened regular file of `len` bytes: its first bytes are read and
/// recognised before the whole file is mapped (a zeroed or compressed file of any size is refused
/// after one read of at most 64 KiB).
fn read_open(
    file: &mut File,
    len: u64,
    path: &Path,
    storage: &crate::mesh::Storage,
    meter: &Meter,
    coordinates: Coordinates,
) -> Result<(Mesh, usize)> {
    let mut head = Vec::with_capacity(detect::HEAD.min(usize::try_from(len).unwrap_or(0)));
    Read::take(&mut *file, detect::HEAD as u64)
        .read_to_end(&mut head)
        .map_err(|e| Error::io(path, e))?;
    if gzip::is_gzip(&head) {
        // The compressed bytes are what `meter` counts; the decode of what they hold is not.
        let contents = match gzip::inflate(file, path, storage, meter)? {
            gzip::Inflated::Memory(bytes) => Contents::Read(bytes),
            gzip::Inflated::Scratch(mut scratch, len) => {
                std::io::Seek::rewind(&mut scratch).map_err(|e| Error::io(path, e))?;
                Contents::load(&mut scratch, Vec::new(), len).map_err(|e| Error::io(path, e))?
            }
        };
        let len = contents.len() as u64;
        let format = detect::detect_inner(&contents, len, path)
            .map_err(|what| Error::invalid(path, what))?;
        let meter = &Meter::default();
        return decode_contents(&contents, format, path, storage, meter, coordinates);
    }
    let format = detect::detect(&head, len, path).map_err(|what| Error::invalid(path, what))?;
    let contents = Contents::load(file, head, len).map_err(|e| Error::io(path, e))?;
    decode_contents(&contents, format, path, storage, meter, coordinates)
}

/// Whether a read decodes the vertex coordinates, or passes over them where the format lets it
/// (a write that holds the smoothed positions reads its input again for the rest).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coordinates {
    Decode,
    Skip,
}

/// Decodes a whole input's bytes with the reader of `format` (see [`Coordinates`]); returns the
/// mesh and its vertex count.
fn decode_contents(
    contents: &Contents,
    format: Format,
    path: &Path,
    storage: &crate::mesh::Storage,
    meter: &Meter,
    coordinates: Coordinates,
) -> Result<(Mesh, usize)> {
    let counted = |mesh: Mesh| {
        let n = mesh.positions.len();
        (mesh, n)
    };
    match format {
        Format::Ply => {
            ply::read_metered(contents, storage, meter, coordinates).map_err(|e| match e {
                ply::ReadError::Invalid(what) => Error::invalid(path, what),
                ply::ReadError::Storage(e) => e,
            })
        }
        // External buffers are relative to the file's directory.
        Format::Gltf | Format::Glb => {
            let dir = path.parent().unwrap_or(Path::new(""));
            gltf::read(contents, format == Format::Glb, Some(dir))
                .map(counted)
                .map_err(|what| Error::invalid(path, what))
        }
        format => decode(contents, format)
            .map(counted)
            .map_err(|what| Error::invalid(path, what)),
    }
}

/// Reads a stream (a pipe, a character device) into memory and decodes it: its first bytes are
/// checked before the rest is read, and it may not exceed [`detect::STREAM_LIMIT`].
fn read_stream(file: &mut File, path: &Path) -> Result<Mesh> {
    let mut bytes = Vec::new();
    let mut limit = detect::STREAM_LIMIT;
    let mut checked = false;
    let mut unrecognised = None;
    loop {
        if bytes.len() == bytes.capacity() {
            bytes
                .try_reserve(bytes.len().max(detect::HEAD))
                .map_err(|_| {
                    Error::resource(format!(
                        "{}: not enough memory to read more than {} bytes from a stream: save it \
                     to a file (files are memory-mapped)",
                        path.display(),
                        bytes.len()
                    ))
                })?;
        }
        let start = bytes.len();
        let spare = bytes.capacity() - start;
        bytes.resize(bytes.capacity(), 0);
        let read = file.read(&mut bytes[start..start + spare]);
        bytes.truncate(start + *read.as_ref().unwrap_or(&0));
        let n = match read {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(Error::io(path, e)),
        };
        if !checked && gzip::is_gzip(&bytes) {
            let mut rest =
                flate2::read::MultiGzDecoder::new(std::io::Cursor::new(bytes).chain(file));
            let inflated = gzip::inflate_in_memory(&mut rest, detect::STREAM_LIMIT)
                .map_err(|failure| Error::invalid(path, failure.message()))?;
            return parse_inflated(&inflated, path).map_err(|what| Error::invalid(path, what));
        }
        if !checked && (bytes.len() >= detect::HEAD || n == 0) {
            // What the first bytes show decides now; only a binary STL has no signature, and
            // then its triangle count bounds the read.
            let len = if n == 0 { bytes.len() as u64 } else { u64::MAX };
            detect::refuse(&bytes, len).map_err(|what| Error::invalid(path, what))?;
            let binary_stl = |format| format == Format::Stl && !stl::is_ascii(without_bom(&bytes));
            match detect::detect(&bytes, len, path) {
                Ok(format) if n > 0 && binary_stl(format) => {
                    let stl = detect::binary_stl_length(&bytes).unwrap_or(0);
                    if stl > limit {
                        return Err(Error::invalid(
                            path,
                            format!(
                                "binary STL: the header declares {stl} bytes, more than a \
                                 stream may hold ({limit}): save it to a file"
                            ),
                        ));
                    }
                    limit = stl;
                }
                Ok(_) => {}
                Err(what) => match detect::binary_stl_length(&bytes) {
                    Some(stl) if n > 0 && stl <= limit => {
                        limit = stl;
                        unrecognised = Some(what);
                    }
                    _ => return Err(Error::invalid(path, what)),
                },
            }
            checked = true;
        }
        if n == 0 {
            break;
        }
        if bytes.len() as u64 > limit {
            if let Some(what) = unrecognised {
                return Err(Error::invalid(path, what));
            }
            return Err(Error::invalid(
                path,
                format!(
                    "a stream of more than {limit} bytes: save it to a file (files are \
                     memory-mapped, of any size)"
                ),
            ));
        }
    }
    parse(&bytes, path).map_err(|what| Error::invalid(path, what))
}

/// Decode a whole file's bytes; the error is the message without the path.
fn parse(bytes: &[u8], path: &Path) -> std::result::Result<Mesh, String> {
    if gzip::is_gzip(bytes) {
        let inflated =
            gzip::inflate_in_memory(&mut flate2::read::MultiGzDecoder::new(bytes), u64::MAX)
                .map_err(|failure| failure.message())?;
        return parse_inflated(&inflated, path);
    }
    decode(bytes, detect::detect(bytes, bytes.len() as u64, path)?)
}

/// Decode what the gzip data `path` held decompressed to (gzip again is refused).
fn parse_inflated(inflated: &[u8], path: &Path) -> std::result::Result<Mesh, String> {
    decode(
        inflated,
        detect::detect_inner(inflated, inflated.len() as u64, path)?,
    )
}

/// Decode bytes with one format's reader; the error is the message without the path.
fn decode(bytes: &[u8], format: Format) -> std::result::Result<Mesh, String> {
    match format {
        Format::Ply => ply::read(bytes),
        Format::Obj => obj::read(bytes),
        Format::Off => off::read(bytes),
        Format::Stl => stl::read(bytes),
        Format::Gltf | Format::Glb => gltf::read(bytes, format == Format::Glb, None),
    }
}

/// The bytes of an input file: memory-mapped when possible, read into memory otherwise.
enum Contents {
    Mapped(memmap2::Mmap),
    Read(Vec<u8>),
}

impl Contents {
    /// The whole of a regular file of `len` bytes whose first bytes, `head`, were read already.
    fn load(file: &mut File, mut head: Vec<u8>, len: u64) -> std::io::Result<Contents> {
        if len > 0 {
            // `populate` (MAP_POPULATE): every byte is read anyway, and faulting the pages in with
            // one call costs much less than one fault per page (armadillo: 0.8 → 1.2 GB/s).
            //
            // SAFETY: the map is read-only and lives only inside `read_mesh`: every reader copies
            // what it keeps into owned buffers, so no reference into it outlives this call. What
            // Rust cannot rule out is another process modifying or truncating the file meanwhile.
            // A truncation raises SIGBUS (the process dies before any output is renamed into
            // place); a modification is caught by `read_mesh` comparing size and mtime afterwards.
            // This is the trade every mmap-based reader (ripgrep, …) makes for zero-copy input.
            if let Ok(map) = unsafe { memmap2::MmapOptions::new().populate().map(&*file) } {
                return Ok(Contents::Mapped(map));
            }
        }
        // Not mappable (a file system without mmap): read the rest after the head.
        head.reserve(usize::try_from(len).unwrap_or(0).saturating_sub(head.len()));
        file.read_to_end(&mut head)?;
        Ok(Contents::Read(head))
    }
}

impl std::ops::Deref for Contents {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Contents::Mapped(map) => map,
            Contents::Read(bytes) => bytes,
        }
    }
}

/// Bytes of records per piece of [`write_encoded`].
const PIECE_BYTES: usize = 1 << 18;

/// Pieces [`write_encoded`] encodes at once: one step of its pipeline.
const PIECES_PER_STEP: usize = 16;

/// Items per piece of [`write_encoded`] for records of `record` bytes.
fn piece_len(record: usize) -> usize {
    (PIECE_BYTES / record.max(1)).max(1)
}

/// Writes the records of items `0..count`, about `record` bytes each, to `out` in their order,
/// `encode(range, buf)` appending those of the items `range` to `buf`. Pieces of about
/// [`PIECE_BYTES`] are encoded in parallel, a step of them while the step before is written: the
/// write is not one thread's encoding, and two steps' buffers (about 8 MiB, more where text
/// lines run longer than `record`) are what it holds. The bytes do not depend on the threads;
/// the first error (in item order) is returned.
pub(crate) fn write_encoded(
    out: &mut impl Write,
    count: usize,
    record: usize,
    encode: impl Fn(std::ops::Range<usize>, &mut Vec<u8>) -> std::io::Result<()> + Sync,
) -> std::io::Result<()> {
    use rayon::prelude::*;
    let piece = piece_len(record);
    if rayon::current_num_threads() == 1 {
        // Nothing to overlap: one buffer, piece after piece.
        let mut buf = Vec::new();
        for start in (0..count).step_by(piece) {
            buf.clear();
            encode(start..(start + piece).min(count), &mut buf)?;
            out.write_all(&buf)?;
        }
        return Ok(());
    }
    let pieces = count.div_ceil(piece);
    let steps = pieces.div_ceil(PIECES_PER_STEP);
    let encode_step = |step: usize, bufs: &mut Vec<Vec<u8>>| -> std::io::Result<()> {
        let first = step * PIECES_PER_STEP;
        bufs.resize_with(PIECES_PER_STEP.min(pieces - first), Vec::new);
        // Each piece's result kept, so that the first error is the first piece's, not the one
        // that happened first.
        let results: Vec<std::io::Result<()>> = bufs
            .par_iter_mut()
            .enumerate()
            .map(|(k, buf)| {
                buf.clear();
                let start = (first + k) * piece;
                encode(start..(start + piece).min(count), buf)
            })
            .collect();
        results.into_iter().collect()
    };
    let (mut ready, mut next) = (Vec::new(), Vec::new());
    if steps > 0 {
        encode_step(0, &mut ready)?;
    }
    for step in 1..=steps {
        let mut encoded = Ok(());
        let written = rayon::in_place_scope(|scope| {
            if step < steps {
                let (next, encoded) = (&mut next, &mut encoded);
                scope.spawn(move |_| *encoded = encode_step(step, next));
            }
            ready.iter().try_for_each(|buf| out.write_all(buf))
        });
        written?;
        encoded?;
        std::mem::swap(&mut ready, &mut next);
    }
    Ok(())
}

/// The text writers' face lines, `face(buf, corners)` appending one: triangles through
/// [`write_encoded`] (lines of about 24 bytes), polygons line by line.
pub(crate) fn write_face_lines(
    out: &mut impl Write,
    faces: &Faces,
    face: impl Fn(&mut Vec<u8>, &[u32]) -> std::io::Result<()> + Sync,
) -> std::io::Result<()> {
    match faces.sizes {
        None => write_encoded(out, faces.triangles.len(), 24, |range, buf| {
            faces.triangles[range].iter().try_for_each(|t| face(buf, t))
        }),
        Some(_) => {
            let mut line = Vec::new();
            faces.try_for_each(|corners| {
                line.clear();
                face(&mut line, corners)?;
                out.write_all(&line)
            })
        }
    }
}

/// The first index of `items` where `pred` holds, the chunks searched in parallel (the checks
/// before a write look at every position and triangle).
pub(crate) fn first_where<T: Sync>(items: &[T], pred: impl Fn(&T) -> bool + Sync) -> Option<usize> {
    use rayon::prelude::*;
    const CHUNK: usize = 1 << 16;
    items
        .par_chunks(CHUNK)
        .enumerate()
        .filter_map(|(c, chunk)| chunk.iter().position(&pred).map(|k| c * CHUNK + k))
        .min()
}

/// Positions finite and triangle indices in range: the preconditions of every writer.
fn check_mesh(mesh: &Mesh) -> std::result::Result<(), String> {
    if let Some(i) = first_where(&mesh.positions, |p| !p.is_finite()) {
        return Err(format!(
            "vertex {i} has a non-finite coordinate {}",
            mesh.positions[i]
        ));
    }
    let n = mesh.positions.len();
    if let Some(t) = first_where(&mesh.triangles, |t| t.iter().any(|&v| v as usize >= n)) {
        return Err(format!(
            "triangle {t} {:?} has a vertex index out of range (0..{n})",
            mesh.triangles[t]
        ));
    }
    Ok(())
}

/// Collects a reader's faces: fan-triangulates polygons and starts remembering corner counts once
/// the first polygon appears (a triangle-only mesh pays nothing for it).
pub(crate) struct FaceBuilder {
    /// Written by index while preallocated slots remain, pushed (on the heap) after that.
    triangles: crate::mesh::Buf<[u32; 3]>,
    filled: usize,
    sizes: Option<Vec<u32>>,
    faces: usize,
    polygons: usize,
}

impl FaceBuilder {
    /// `capacity` must be a count already checked against the input's size.
    pub(crate) fn with_capacity(capacity: usize) -> Self {
        FaceBuilder {
            triangles: Vec::with_capacity(capacity).into(),
            filled: 0,
            sizes: None,
            faces: 0,
            polygons: 0,
        }
    }

    /// `faces` slots from `storage` (mapped scratch for huge inputs): exact for a triangle-only
    /// input; polygons beyond the slots move the array to the heap.
    pub(crate) fn in_storage(storage: &crate::mesh::Storage, faces: usize) -> Result<Self> {
        Ok(FaceBuilder {
            triangles: storage.zeroed(faces)?,
            filled: 0,
            sizes: None,
            faces: 0,
            polygons: 0,
        })
    }

    #[inline]
    fn put(&mut self, t: [u32; 3]) {
        if self.filled < self.triangles.len() {
            self.triangles[self.filled] = t;
        } else {
            self.triangles.push(t);
        }
        self.filled += 1;
    }

    #[inline]
    pub(crate) fn triangle(&mut self, t: [u32; 3]) {
        self.put(t);
        if let Some(sizes) = &mut self.sizes {
            sizes.push(3);
        }
        self.faces += 1;
    }

    /// For a builder with no face yet and at least `count` preallocated slots: let `fill` write
    /// `count` triangles into the slots at once; if it says it wrote them all, they count as
    /// `count` triangle faces, else the builder is left with no face (and the slots unspecified).
    pub(crate) fn fill_triangles(
        &mut self,
        count: usize,
        fill: impl FnOnce(&mut [[u32; 3]]) -> bool,
    ) -> bool {
        if self.faces != 0 || self.filled != 0 || self.triangles.len() < count {
            return false;
        }
        if !fill(&mut self.triangles[..count]) {
            return false;
        }
        self.filled = count;
        self.faces = count;
        true
    }

    /// Faces so far.
    pub(crate) fn len(&self) -> usize {
        self.faces
    }

    /// Triangles so far.
    pub(crate) fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles[..self.filled.min(self.triangles.len())]
    }

    /// A face with at least 3 corners (the readers reject fewer).
    pub(crate) fn polygon(&mut self, corners: &[u32]) {
        if let [a, b, c] = *corners {
            return self.triangle([a, b, c]);
        }
        let sizes = self.sizes.get_or_insert_with(|| vec![3; self.faces]);
        sizes.push(u32::try_from(corners.len()).unwrap_or(u32::MAX));
        for w in corners[1..].windows(2) {
            self.put([corners[0], w[0], w[1]]);
        }
        self.faces += 1;
        self.polygons += 1;
    }

    /// The mesh with these faces, and the face counts recorded in `source`.
    pub(crate) fn into_mesh(
        mut self,
        positions: impl Into<crate::mesh::Buf<glam::DVec3>>,
        mut source: Source,
    ) -> Mesh {
        self.triangles.truncate(self.filled);
        source.input_faces = self.faces;
        source.polygons_triangulated = self.polygons;
        source.face_sizes = self.sizes.map(Arc::new);
        Mesh {
            positions: positions.into(),
            triangles: self.triangles,
            source,
        }
    }
}

/// A mesh's faces as writers see them: the original polygons when the source kept their sizes,
/// else the triangles.
pub(crate) struct Faces<'a> {
    triangles: &'a [[u32; 3]],
    sizes: Option<&'a [u32]>,
}

impl<'a> Faces<'a> {
    pub(crate) fn of(mesh: &'a Mesh) -> Self {
        Faces {
            triangles: &mesh.triangles,
            sizes: mesh.source.face_sizes.as_deref().map(|s| &s[..]),
        }
    }

    /// Whether the triangles are still exactly the fans of the recorded polygons.
    pub(crate) fn check(&self) -> std::result::Result<(), String> {
        let Some(sizes) = self.sizes else {
            return Ok(());
        };
        let mut t = 0;
        for (f, &n) in sizes.iter().enumerate() {
            let fan = self.triangles.get(t..t + (n as usize).saturating_sub(2));
            let ok = n >= 3
                && fan.is_some_and(|fan| {
                    fan.windows(2)
                        .all(|w| w[1][0] == w[0][0] && w[1][1] == w[0][2])
                });
            if !ok {
                return Err(format!(
                    "the triangles no longer match the source's polygons (face {f}); \
                     clear mesh.source.face_sizes after changing connectivity"
                ));
            }
            t += n as usize - 2;
        }
        if t != self.triangles.len() {
            return Err(format!(
                "the source's polygons make {t} triangles but the mesh has {}; \
                 clear mesh.source.face_sizes after changing connectivity",
                self.triangles.len()
            ));
        }
        Ok(())
    }

    pub(crate) fn len(&self) -> usize {
        self.sizes.map_or(self.triangles.len(), <[u32]>::len)
    }

    pub(crate) fn max_corners(&self) -> usize {
        match self.sizes {
            Some(sizes) => sizes.iter().max().map_or(3, |&n| n as usize),
            None => 3,
        }
    }

    /// Calls `f` with each face's corners in order. Assumes [`Faces::check`] passed.
    pub(crate) fn try_for_each<E>(
        &self,
        mut f: impl FnMut(&[u32]) -> std::result::Result<(), E>,
    ) -> std::result::Result<(), E> {
        let Some(sizes) = self.sizes else {
            return self.triangles.iter().try_for_each(|t| f(t));
        };
        let mut corners = Vec::new();
        let mut fans = self.triangles.iter();
        for &n in sizes {
            corners.clear();
            for (k, t) in fans
                .by_ref()
                .take((n as usize).saturating_sub(2))
                .enumerate()
            {
                if k == 0 {
                    corners.extend_from_slice(&t[..2]);
                }
                corners.push(t[2]);
            }
            f(&corners)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
