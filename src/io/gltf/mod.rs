//! glTF 2.0: binary `.glb` and JSON `.gltf` whose buffers are external files or embedded
//! `data:` URIs.
//!
//! # What is read
//!
//! Every triangle primitive (`mode` 4, the default) of every mesh: its `POSITION` accessor (float
//! `VEC3`) and its indices (`u8`/`u16`/`u32`, or none: consecutive triples). The engine sees one
//! mesh, the concatenation of the `POSITION` data in order of first use: a primitive's vertices
//! are its own (nothing is merged by value across primitives), except that primitives naming the
//! same `POSITION` elements share those vertices, as the file says. An element is its bytes: the
//! same accessor, another accessor over the same bytes, or one over part of them (a sub-range of
//! the same view) names the same vertices. Shared geometry is one surface, so a triangle is read
//! once: a triangle of another primitive on the same three vertices (the same index accessor
//! again, an overlapping part of another, either winding) is not read again (counted twice, each
//! of its edges would have four faces, and a non-manifold edge never moves). Within one primitive
//! every triangle is kept as the file has it. Primitives of other modes (points, lines, strips,
//! fans) are left untouched and not smoothed.
//!
//! Node transforms are ignored: a mesh is smoothed in its own local space, once, however many
//! nodes place it (scaled or mirrored instances all receive the same smoothed mesh), and so are
//! two meshes whose primitives name the same data.
//!
//! # What is written
//!
//! A glTF input only to its own kind: a GLB input as `.glb`, a `.gltf` input as `.gltf` (a glTF
//! input can be written to PLY, OBJ, OFF or STL as a plain mesh). A mesh that was not read from
//! glTF is written as a plain glTF ([`GltfLayout::plain`]: one primitive of float `POSITION` and
//! `NORMAL` and `u32` indices, in the GLB's chunk or a `.bin` beside the `.gltf`), through the same
//! writer. The JSON and every buffer are carried
//! through: the smoothed positions overwrite the `POSITION` data in place (same accessor, buffer
//! view and byte layout: shared data stays one copy, so every accessor naming a vertex reads
//! its one smoothed position and every index stays valid), `NORMAL` data is recomputed from
//! them (area-weighted, normalised), and the `POSITION` accessors' `min`/`max` (and a `NORMAL`
//! accessor's, if it has them) are updated.
//! Everything else — other attributes, materials, images, nodes, extras, extensions — keeps its
//! bytes and values (the JSON is re-serialised, so key order and spacing may change). A changed
//! buffer is written as the GLB's binary chunk, re-encoded into its `data:` URI, or, when it was
//! an external file, written beside the output as `<output stem>.bin` (`<stem>-1.bin`, … for
//! more than one) and its `uri` updated: the input's files are never overwritten. A buffer that
//! received decoded Draco data is always written so. Unchanged
//! external files (textures, other buffers) keep their relative URIs, so they must be beside the
//! output too. Tangents (`TANGENT`) and morph targets are carried as they were.
//!
//! # Draco
//!
//! Draco-compressed primitives (`KHR_draco_mesh_compression`) are decoded first (see `draco`:
//! each attribute into its accessor's own type, appended as plain views to the buffer that held
//! the compressed data, the extension removed from the primitive and the file), so the rest of
//! the reader, the smoothing and the writer see an ordinary glTF: a glTF output is therefore
//! written uncompressed, and [`GltfLayout::decompressed`] tells a caller to say so. The
//! compressed bytes stay in their buffer, unused. Data several primitives share is decoded once.
//! A Draco attribute whose type is not its accessor's, counts that differ from the accessors',
//! and Draco on a primitive that is not triangles are refused, and data that does not decode is
//! one line: `mesh M primitive P: Draco data could not be decoded (<the decoder's message>)`.
//!
//! # Refused
//!
//! Sparse accessors on positions or indices, meshopt compression (`EXT_meshopt_compression`),
//! non-float positions (`KHR_mesh_quantization`), missing buffers, accessors and indices out of
//! range, truncated GLB chunks, NaN or infinite positions, and external buffers when the file's
//! directory is unknown (bytes not read from a file).

use std::fmt;
use std::path::PathBuf;

use serde_json::Value;

use crate::mesh::{Carried, FileLayout};

mod draco;
mod read;
mod runs;
mod uri;
mod write;

pub(super) use read::read;
pub(crate) use write::{buffer_name_of, referenced_files};
pub(super) use write::{check_writable, write};

/// A GLB starts with these four bytes.
pub(super) fn has_magic(head: &[u8]) -> bool {
    head.starts_with(b"glTF")
}

const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
const FLOAT: u64 = 5126;
/// Meshopt compression, refused (Draco is decoded: see `draco`).
const MESHOPT: &str = "EXT_meshopt_compression";

/// What a glTF input holds beyond the mesh: its JSON, the buffers the geometry lives in, and where
/// each vertex range and normal array sits in them.
pub struct GltfLayout {
    json: Value,
    binary: bool,
    /// The buffers the geometry uses (index = the JSON's buffer index); `None` for the others.
    buffers: Vec<Option<Loaded>>,
    /// Each distinct `POSITION` accessor and its first vertex in the mesh.
    positions: Vec<(Span, usize)>,
    /// Each `NORMAL` accessor of a triangle primitive and the first vertex of its positions.
    normals: Vec<(Span, usize)>,
    vertices: usize,
    triangles: usize,
    carried: Carried,
    /// The directory the input's external files are relative to, when it came from a file.
    dir: Option<PathBuf>,
    /// Whether the input had Draco-compressed primitives (decoded on read; written uncompressed).
    decompressed: bool,
}

/// One buffer's bytes and where they came from.
struct Loaded {
    bytes: Vec<u8>,
    origin: Origin,
    /// Decoded Draco data was appended: the buffer is written out even if no geometry in it
    /// changed.
    extended: bool,
}

enum Origin {
    /// The GLB's binary chunk.
    Chunk,
    /// A `data:` URI; the text before its comma (`data:…;base64`).
    Data(String),
    /// An external file, as resolved against the input's directory.
    File(PathBuf),
    /// Made for the output ([`GltfLayout::plain`]): the GLB's binary chunk, or a `.bin` beside a
    /// `.gltf`.
    New,
}

/// Where a float `VEC3` accessor's elements are: `count` elements of 12 bytes every `stride`
/// bytes from `offset` in buffer `buffer`.
#[derive(Debug, Clone, Copy)]
struct Span {
    accessor: usize,
    buffer: usize,
    offset: usize,
    stride: usize,
    count: usize,
}

// By hand: the buffers hold megabytes that a `{:?}` must not dump.
impl fmt::Debug for GltfLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GltfLayout")
            .field("binary", &self.binary)
            .field("positions", &self.positions.len())
            .field("normals", &self.normals.len())
            .field("vertices", &self.vertices)
            .field("triangles", &self.triangles)
            .field("decompressed", &self.decompressed)
            .finish()
    }
}

impl GltfLayout {
    /// Whether the input had Draco-compressed (`KHR_draco_mesh_compression`) primitives. They
    /// were decoded on read and a glTF output holds them uncompressed (larger than the input):
    /// a caller writing one should say so, e.g. `note: OUT: written without Draco compression`.
    ///
    /// For a mesh, see [`GltfLayout::decompressed_in`].
    pub fn decompressed(&self) -> bool {
        self.decompressed
    }

    /// Whether `mesh` was read from a glTF with Draco-compressed primitives (see
    /// [`GltfLayout::decompressed`]); false for any other mesh, or once its layout is cleared.
    pub fn decompressed_in(mesh: &crate::mesh::Mesh) -> bool {
        GltfLayout::of(&mesh.source).is_some_and(GltfLayout::decompressed)
    }

    /// The layout a mesh read from glTF carries in its `source`, if any.
    pub(crate) fn of(source: &crate::mesh::Source) -> Option<&GltfLayout> {
        source
            .layout
            .as_deref()
            .and_then(|l| l.as_any().downcast_ref::<GltfLayout>())
    }
}

impl FileLayout for GltfLayout {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
    fn carries(&self) -> Carried {
        self.carried.clone()
    }
}

/// The array under `key`, or none.
fn array<'a>(v: &'a Value, key: &str) -> &'a [Value] {
    v.get(key)
        .and_then(Value::as_array)
        .map_or(&[], Vec::as_slice)
}

fn index(v: &Value) -> Option<usize> {
    v.as_u64().and_then(|i| usize::try_from(i).ok())
}

/// A non-negative integer field, `default` when absent.
fn field(v: &Value, key: &str, default: Option<usize>) -> std::result::Result<usize, String> {
    match v.get(key) {
        None => default.ok_or_else(|| format!("no {key}")),
        Some(x) => index(x).ok_or_else(|| format!("{key} is not a non-negative integer")),
    }
}

#[cfg(test)]
mod tests;
