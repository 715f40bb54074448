//! glTF 2.0: binary `.glb` and JSON `.gltf` whose buffers are external files or embedded
//! `data:` URIs.
//!
//! # What is read
//!
//! Every triangle primitive (`mode` 4, the default) of every mesh: its `POSITION` accessor (float
//! `VEC3`) and its indices (`u8`/`u16`/`u32`, or none: consecutive triples). The engine sees one
//! mesh, the concatenation of the distinct `POSITION` accessors in order of first use: a
//! primitive's vertices are its own (nothing is merged across primitives), except that primitives
//! naming the same `POSITION` accessor share those vertices, as the file says. Primitives of other
//! modes (points, lines, strips, fans) are left untouched and not smoothed.
//!
//! Node transforms are ignored: a mesh is smoothed in its own local space, once, however many
//! nodes place it (scaled or mirrored instances all receive the same smoothed mesh).
//!
//! # What is written
//!
//! Only to the input's own kind: a GLB input as `.glb`, a `.gltf` input as `.gltf`; a mesh that
//! was not read from glTF is refused (glTF output keeps a glTF input's scene; a glTF input can be
//! written to PLY, OBJ, OFF or STL as a plain mesh). The JSON and every buffer are carried
//! through: the smoothed positions overwrite the `POSITION` data in place (same accessor, buffer
//! view and byte layout), `NORMAL` data is recomputed from them (area-weighted, normalised), and
//! the `POSITION` accessors' `min`/`max` (and a `NORMAL` accessor's, if it has them) are updated.
//! Everything else — other attributes, materials, images, nodes, extras, extensions — keeps its
//! bytes and values (the JSON is re-serialised, so key order and spacing may change). A changed
//! buffer is written as the GLB's binary chunk, re-encoded into its `data:` URI, or, when it was
//! an external file, written beside the output as `<output stem>.bin` (`<stem>-1.bin`, … for
//! more than one) and its `uri` updated: the input's files are never overwritten. Unchanged
//! external files (textures, other buffers) keep their relative URIs, so they must be beside the
//! output too. Tangents (`TANGENT`) and morph targets are carried as they were.
//!
//! # Refused
//!
//! Sparse accessors on positions or indices, Draco (`KHR_draco_mesh_compression`) and meshopt
//! (`EXT_meshopt_compression`) compression, non-float positions (`KHR_mesh_quantization`),
//! missing buffers, accessors and indices out of range, truncated GLB chunks, NaN or infinite
//! positions, and external buffers when the file's directory is unknown (bytes not read from a
//! file).

use std::collections::HashMap;
use std::fmt;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde_json::Value;

use super::FaceBuilder;
use crate::error::{Error, Result};
use crate::mesh::{Carried, FileLayout, Format, Mesh, Source};

/// A GLB starts with these four bytes.
pub(super) fn has_magic(head: &[u8]) -> bool {
    head.starts_with(b"glTF")
}

const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
const FLOAT: u64 = 5126;
const COMPRESSIONS: [&str; 2] = ["KHR_draco_mesh_compression", "EXT_meshopt_compression"];

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
}

/// One buffer's bytes and where they came from.
struct Loaded {
    bytes: Vec<u8>,
    origin: Origin,
}

enum Origin {
    /// The GLB's binary chunk.
    Chunk,
    /// A `data:` URI; the text before its comma (`data:…;base64`).
    Data(String),
    /// An external file, as resolved against the input's directory.
    File(PathBuf),
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
            .finish()
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

/// Reads a GLB (`binary`) or a `.gltf`; `dir` is the directory external buffers are relative to
/// (`None` when the bytes come from no file: external buffers are then refused).
pub(super) fn read(
    bytes: &[u8],
    binary: bool,
    dir: Option<&Path>,
) -> std::result::Result<Mesh, String> {
    let (json, chunk) = if binary {
        let (json, chunk) = glb_chunks(bytes)?;
        (json, chunk)
    } else {
        (super::without_bom(bytes), None)
    };
    let json: Value = serde_json::from_slice(json).map_err(|e| format!("glTF JSON: {e}"))?;
    let mut reader = Reader {
        json: &json,
        chunk,
        dir,
        buffers: Vec::new(),
    };
    reader.check_top()?;
    let mut positions: Vec<(Span, usize)> = Vec::new();
    let mut first_vertex: HashMap<usize, usize> = HashMap::new();
    let mut all = Vec::new();
    let mut normals = Vec::new();
    let mut corners: Vec<[u32; 3]> = Vec::new();
    let mut carried = Carried {
        materials: json
            .get("materials")
            .and_then(Value::as_array)
            .is_some_and(|m| !m.is_empty()),
        ..Carried::default()
    };
    for (m, mesh) in array(&json, "meshes").iter().enumerate() {
        for (p, prim) in array(mesh, "primitives").iter().enumerate() {
            let at = |what: String| format!("mesh {m} primitive {p}: {what}");
            let attributes = prim.get("attributes").and_then(Value::as_object);
            for name in attributes.into_iter().flat_map(|a| a.keys()) {
                note_attribute(&mut carried, name);
            }
            if let Some(ext) = prim.get("extensions").and_then(Value::as_object) {
                if let Some(c) = COMPRESSIONS.iter().find(|c| ext.contains_key(**c)) {
                    return Err(at(format!("{c} compression is not supported")));
                }
            }
            if prim.get("mode").map_or(Some(4), Value::as_u64) != Some(4) {
                continue;
            }
            let position = attributes
                .and_then(|a| a.get("POSITION"))
                .ok_or_else(|| at("a triangle primitive without POSITION".into()))?;
            let position =
                index(position).ok_or_else(|| at("POSITION is not an accessor index".into()))?;
            let span = reader.vec3(position, "POSITION").map_err(at)?;
            let base = match first_vertex.get(&position) {
                Some(&base) => base,
                None => {
                    let base = all.len();
                    let buffer = reader.bytes(span.buffer);
                    for i in 0..span.count {
                        let v = read_vec3(buffer, span.offset + i * span.stride);
                        if !v.is_finite() {
                            return Err(at(format!(
                                "POSITION accessor {position}: vertex {i} is not finite ({}, {}, {})",
                                v.x, v.y, v.z
                            )));
                        }
                        all.push(v);
                    }
                    first_vertex.insert(position, base);
                    positions.push((span, base));
                    base
                }
            };
            if let Some(normal) = attributes.and_then(|a| a.get("NORMAL")) {
                let normal =
                    index(normal).ok_or_else(|| at("NORMAL is not an accessor index".into()))?;
                let n = reader.vec3(normal, "NORMAL").map_err(at)?;
                if n.count != span.count {
                    return Err(at(format!(
                        "NORMAL has {} elements but POSITION has {}",
                        n.count, span.count
                    )));
                }
                normals.push((n, base));
            }
            let ids = match prim.get("indices") {
                Some(i) => {
                    let i =
                        index(i).ok_or_else(|| at("indices is not an accessor index".into()))?;
                    reader.indices(i).map_err(at)?
                }
                None => (0..span.count as u32).collect(),
            };
            if ids.len() % 3 != 0 {
                return Err(at(format!("{} indices do not make triangles", ids.len())));
            }
            for t in ids.chunks_exact(3) {
                if let Some(&v) = t.iter().find(|&&v| v as usize >= span.count) {
                    return Err(at(format!(
                        "vertex index {v} out of range (0..{})",
                        span.count
                    )));
                }
                let vertex = |k: usize| u32::try_from(base + t[k] as usize).unwrap_or(u32::MAX);
                corners.push([vertex(0), vertex(1), vertex(2)]);
            }
        }
    }
    if u32::try_from(all.len()).is_err() {
        return Err(format!("{} vertices: more than 2^32", all.len()));
    }
    for name in array(&json, "extensionsUsed")
        .iter()
        .filter_map(Value::as_str)
    {
        push_other(&mut carried, name);
    }
    check_rewritten_bytes(&json, &reader, &positions, &normals)?;
    let buffers = reader.buffers;
    let mut faces = FaceBuilder::with_capacity(corners.len());
    corners.iter().for_each(|&t| faces.triangle(t));
    let layout = GltfLayout {
        json,
        binary,
        buffers,
        positions,
        normals,
        vertices: all.len(),
        triangles: corners.len(),
        carried,
        dir: dir.map(Path::to_path_buf),
    };
    let source = Source {
        format: Some(if binary { Format::Glb } else { Format::Gltf }),
        layout: Some(std::sync::Arc::new(layout)),
        ..Source::default()
    };
    Ok(faces.into_mesh(all, source))
}

/// The JSON chunk and the binary chunk (if any) of a GLB.
fn glb_chunks(bytes: &[u8]) -> std::result::Result<(&[u8], Option<&[u8]>), String> {
    let word = |at: usize| {
        bytes
            .get(at..at + 4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]) as usize)
    };
    if !has_magic(bytes) {
        return Err("not a GLB file (no glTF magic)".into());
    }
    let version = word(4).ok_or("GLB header truncated")?;
    if version != 2 {
        return Err(format!("GLB version {version} is not supported (2 only)"));
    }
    let length = word(8).ok_or("GLB header truncated")?;
    if length > bytes.len() {
        return Err(format!(
            "GLB truncated: the header declares {length} bytes, the file has {}",
            bytes.len()
        ));
    }
    let mut chunks = Vec::new();
    let mut at = 12;
    while at < length {
        let (Some(len), Some(kind)) = (word(at), word(at + 4)) else {
            return Err(format!("GLB chunk header at byte {at} truncated"));
        };
        let data = at + 8;
        if len > length.saturating_sub(data) {
            return Err(format!(
                "GLB chunk at byte {at} truncated: it declares {len} bytes, {} remain",
                length.saturating_sub(data)
            ));
        }
        chunks.push((kind as u32, &bytes[data..data + len]));
        at = data + len;
    }
    match chunks.as_slice() {
        [(CHUNK_JSON, json), rest @ ..] => {
            let bin = rest.iter().find(|(k, _)| *k == CHUNK_BIN).map(|(_, b)| *b);
            Ok((json, bin))
        }
        _ => Err("GLB has no JSON chunk first".into()),
    }
}

struct Reader<'a> {
    json: &'a Value,
    chunk: Option<&'a [u8]>,
    dir: Option<&'a Path>,
    buffers: Vec<Option<Loaded>>,
}

impl<'a> Reader<'a> {
    /// The version and the extensions the whole file needs.
    fn check_top(&self) -> std::result::Result<(), String> {
        let version = self
            .json
            .pointer("/asset/version")
            .and_then(Value::as_str)
            .ok_or("not glTF: no asset.version")?;
        if !version.starts_with("2.") {
            return Err(format!(
                "glTF version {version} is not supported (2.x only)"
            ));
        }
        for key in ["extensionsUsed", "extensionsRequired"] {
            let names = array(self.json, key);
            if let Some(c) = COMPRESSIONS
                .iter()
                .find(|c| names.iter().any(|n| n.as_str() == Some(**c)))
            {
                return Err(format!("{c} compression is not supported"));
            }
        }
        Ok(())
    }

    /// A float `VEC3` accessor (`what` names its attribute), its buffer loaded.
    fn vec3(&mut self, accessor: usize, what: &str) -> std::result::Result<Span, String> {
        let a = self.accessor(accessor, what)?;
        let kind = a.get("type").and_then(Value::as_str);
        let component = a.get("componentType").and_then(Value::as_u64);
        if component != Some(FLOAT) || kind != Some("VEC3") {
            return Err(format!(
                "{what} accessor {accessor} is not float VEC3 (componentType {}, type {}): \
                 quantized data (KHR_mesh_quantization) is not supported",
                component.map_or("missing".into(), |c| c.to_string()),
                kind.unwrap_or("missing")
            ));
        }
        self.span(accessor, a, 12, what)
    }

    /// The values of an index accessor.
    fn indices(&mut self, accessor: usize) -> std::result::Result<Vec<u32>, String> {
        let a = self.accessor(accessor, "indices")?;
        let size = match a.get("componentType").and_then(Value::as_u64) {
            Some(5121) => 1,
            Some(5123) => 2,
            Some(5125) => 4,
            c => {
                return Err(format!(
                    "indices accessor {accessor}: componentType {} is not an unsigned integer type",
                    c.map_or("missing".into(), |c| c.to_string())
                ));
            }
        };
        if a.get("type").and_then(Value::as_str) != Some("SCALAR") {
            return Err(format!("indices accessor {accessor} is not SCALAR"));
        }
        let span = self.span(accessor, a, size, "indices")?;
        let bytes = self.bytes(span.buffer);
        Ok((0..span.count)
            .map(|i| {
                let b = &bytes[span.offset + i * span.stride..];
                match size {
                    1 => u32::from(b[0]),
                    2 => u32::from(u16::from_le_bytes([b[0], b[1]])),
                    _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                }
            })
            .collect())
    }

    fn accessor(&self, accessor: usize, what: &str) -> std::result::Result<&'a Value, String> {
        let accessors = array(self.json, "accessors");
        let a = accessors.get(accessor).ok_or_else(|| {
            format!(
                "{what} accessor {accessor} out of range (0..{})",
                accessors.len()
            )
        })?;
        if a.get("sparse").is_some() {
            return Err(format!(
                "{what} accessor {accessor} is sparse: not supported"
            ));
        }
        Ok(a)
    }

    /// Where accessor `a`'s elements of `size` bytes lie, checked against its view and buffer.
    fn span(
        &mut self,
        accessor: usize,
        a: &Value,
        size: usize,
        what: &str,
    ) -> std::result::Result<Span, String> {
        let at = format!("{what} accessor {accessor}");
        let view = a
            .get("bufferView")
            .ok_or_else(|| format!("{at} has no bufferView"))?;
        let view = index(view).ok_or_else(|| format!("{at}: bufferView is not an index"))?;
        let json = self.json;
        let views = array(json, "bufferViews");
        let v = views
            .get(view)
            .ok_or_else(|| format!("{at}: bufferView {view} out of range (0..{})", views.len()))?;
        let count = field(a, "count", None).map_err(|e| format!("{at}: {e}"))?;
        let a_offset = field(a, "byteOffset", Some(0)).map_err(|e| format!("{at}: {e}"))?;
        let vat = format!("bufferView {view}");
        let buffer = field(v, "buffer", None).map_err(|e| format!("{vat}: {e}"))?;
        let v_offset = field(v, "byteOffset", Some(0)).map_err(|e| format!("{vat}: {e}"))?;
        let v_length = field(v, "byteLength", None).map_err(|e| format!("{vat}: {e}"))?;
        let stride = field(v, "byteStride", Some(size)).map_err(|e| format!("{vat}: {e}"))?;
        if stride < size {
            return Err(format!(
                "{vat}: byteStride {stride} is less than an element ({size} bytes)"
            ));
        }
        let needed = match count {
            0 => Some(a_offset),
            n => (n - 1)
                .checked_mul(stride)
                .and_then(|b| b.checked_add(a_offset)?.checked_add(size)),
        };
        if needed.is_none_or(|n| n > v_length) {
            return Err(format!(
                "{at}: {count} elements from byte {a_offset} do not fit its bufferView ({v_length} bytes)"
            ));
        }
        let end = v_offset.checked_add(v_length);
        let have = self.load(buffer)?.len();
        if end.is_none_or(|e| e > have) {
            return Err(format!(
                "{vat}: bytes {v_offset}..+{v_length} beyond buffer {buffer} ({have} bytes)"
            ));
        }
        Ok(Span {
            accessor,
            buffer,
            offset: v_offset + a_offset,
            stride,
            count,
        })
    }

    /// A loaded buffer's bytes.
    fn bytes(&self, buffer: usize) -> &[u8] {
        self.buffers[buffer].as_ref().map_or(&[], |b| &b.bytes)
    }

    /// Loads buffer `i` (once) and returns its bytes, at most its `byteLength`.
    fn load(&mut self, i: usize) -> std::result::Result<&[u8], String> {
        let buffers = array(self.json, "buffers");
        let b = buffers
            .get(i)
            .ok_or_else(|| format!("buffer {i} out of range (0..{})", buffers.len()))?;
        if self.buffers.len() < buffers.len() {
            self.buffers.resize_with(buffers.len(), || None);
        }
        if self.buffers[i].is_none() {
            let length = field(b, "byteLength", None).map_err(|e| format!("buffer {i}: {e}"))?;
            let (mut bytes, origin) = match b.get("uri").map(|u| u.as_str()) {
                None => match self.chunk {
                    Some(chunk) if i == 0 => (chunk.to_vec(), Origin::Chunk),
                    _ => {
                        return Err(format!(
                            "buffer {i} has no uri and the file no binary chunk"
                        ));
                    }
                },
                Some(None) => return Err(format!("buffer {i}: uri is not a string")),
                Some(Some(uri)) => {
                    load_uri(uri, self.dir, length).map_err(|e| format!("buffer {i}: {e}"))?
                }
            };
            if bytes.len() < length {
                return Err(format!(
                    "buffer {i}: byteLength {length} but only {} bytes of data",
                    bytes.len()
                ));
            }
            bytes.truncate(length);
            self.buffers[i] = Some(Loaded { bytes, origin });
        }
        Ok(self.bytes(i))
    }
}

/// The bytes a write replaces, every element of the `POSITION` and `NORMAL` accessors, must hold
/// nothing else: not each other (a `NORMAL` that is the `POSITION` accessor), not indices, not
/// another attribute, not an image. Interleaved views are fine: only the elements' own bytes count.
fn check_rewritten_bytes(
    json: &Value,
    reader: &Reader,
    positions: &[(Span, usize)],
    normals: &[(Span, usize)],
) -> std::result::Result<(), String> {
    let mut masks: HashMap<usize, Vec<u64>> = HashMap::new();
    let mut rewritten: Vec<usize> = Vec::new();
    let spans = positions.iter().map(|(s, _)| (s, "POSITION"));
    for (span, what) in spans.chain(normals.iter().map(|(s, _)| (s, "NORMAL"))) {
        if rewritten.contains(&span.accessor) {
            if what == "NORMAL" && positions.iter().any(|(p, _)| p.accessor == span.accessor) {
                return Err(format!(
                    "accessor {} is both POSITION and NORMAL: the recomputed normals would \
                     replace the positions",
                    span.accessor
                ));
            }
            continue;
        }
        rewritten.push(span.accessor);
        let len = reader.bytes(span.buffer).len();
        let mask = masks
            .entry(span.buffer)
            .or_insert_with(|| vec![0; len.div_ceil(64)]);
        for i in 0..span.count {
            let at = span.offset + i * span.stride;
            for b in at..at + 12 {
                if mask[b / 64] >> (b % 64) & 1 == 1 {
                    return Err(format!(
                        "{what} accessor {} shares bytes with another POSITION or NORMAL \
                         accessor: one would overwrite the other",
                        span.accessor
                    ));
                }
                mask[b / 64] |= 1 << (b % 64);
            }
        }
    }
    let marked = |buffer: usize, bytes: std::ops::Range<usize>| {
        masks.get(&buffer).is_some_and(|mask| {
            let end = bytes.end.min(mask.len() * 64);
            (bytes.start..end).any(|b| mask[b / 64] >> (b % 64) & 1 == 1)
        })
    };
    let views = array(json, "bufferViews");
    let view_of = |a: &Value| a.get("bufferView").and_then(index);
    let accessors = array(json, "accessors");
    let written_views: Vec<usize> = rewritten
        .iter()
        .filter_map(|&k| accessors.get(k).and_then(view_of))
        .collect();
    let clash = |what: String| {
        Err(format!(
            "{what} shares bytes with the POSITION or NORMAL data, which a write replaces"
        ))
    };
    // Views that hold no rewritten accessor: every byte of theirs is someone else's.
    for (v, view) in views.iter().enumerate() {
        let (Ok(buffer), Ok(offset), Ok(length)) = (
            field(view, "buffer", None),
            field(view, "byteOffset", Some(0)),
            field(view, "byteLength", None),
        ) else {
            continue;
        };
        if !written_views.contains(&v) && marked(buffer, offset..offset.saturating_add(length)) {
            return clash(format!("bufferView {v}"));
        }
    }
    // Other accessors in the rewritten views (interleaved attributes): their elements' bytes.
    for (k, a) in accessors.iter().enumerate() {
        let Some(v) = view_of(a).filter(|v| !rewritten.contains(&k) && written_views.contains(v))
        else {
            continue;
        };
        let view = &views[v];
        let size = element_size(a);
        let (Ok(buffer), Ok(v_offset), Ok(a_offset), Ok(count)) = (
            field(view, "buffer", None),
            field(view, "byteOffset", Some(0)),
            field(a, "byteOffset", Some(0)),
            field(a, "count", None),
        ) else {
            continue;
        };
        let stride = field(view, "byteStride", Some(size)).unwrap_or(size);
        let start = v_offset.saturating_add(a_offset);
        // Elements past the end of the buffer hold none of its bytes (a lying count).
        let in_buffer = reader.bytes(buffer).len().saturating_sub(start) / stride.max(1) + 1;
        let hits = (0..count.min(in_buffer)).any(|i| {
            let at = start.saturating_add(i.saturating_mul(stride));
            marked(buffer, at..at.saturating_add(size))
        });
        if hits {
            return clash(format!("accessor {k}"));
        }
    }
    Ok(())
}

/// Bytes of one element of accessor `a` (its component size times its components; 16 for a type
/// this reader does not know, the largest vector).
fn element_size(a: &Value) -> usize {
    let component = match a.get("componentType").and_then(Value::as_u64) {
        Some(5120 | 5121) => 1,
        Some(5122 | 5123) => 2,
        _ => 4,
    };
    let components = match a.get("type").and_then(Value::as_str) {
        Some("SCALAR") => 1,
        Some("VEC2") => 2,
        Some("VEC3") => 3,
        Some("MAT2") => 4,
        Some("MAT3") => 9,
        Some("MAT4") => 16,
        _ => 4,
    };
    component * components
}

/// A `data:` URI's bytes, or an external file's (its first `length` bytes), resolved against `dir`.
fn load_uri(
    uri: &str,
    dir: Option<&Path>,
    length: usize,
) -> std::result::Result<(Vec<u8>, Origin), String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (head, data) = rest.split_once(',').ok_or("data URI without a comma")?;
        if !head.ends_with(";base64") {
            return Err("data URI is not base64".into());
        }
        let bytes = base64_decode(data.as_bytes()).ok_or("data URI: invalid base64")?;
        return Ok((bytes, Origin::Data(format!("data:{head}"))));
    }
    let Some(dir) = dir else {
        return Err(format!(
            "external file {:?} cannot be read without the file's directory",
            uri
        ));
    };
    let name = percent_decode(uri).ok_or_else(|| format!("uri {uri:?} is not valid"))?;
    let path = dir.join(name);
    // The uri, quoted: a file name may hold any character, a line break too.
    let cannot = |e: std::io::Error| format!("cannot read {uri:?}: {e}");
    let file = std::fs::File::open(&path).map_err(cannot)?;
    // A device or a pipe would be read without end (only `length` bytes are used).
    if !file.metadata().map_err(cannot)?.is_file() {
        return Err(format!("{uri:?} is not a regular file"));
    }
    let mut bytes = Vec::new();
    file.take(length as u64)
        .read_to_end(&mut bytes)
        .map_err(cannot)?;
    Ok((bytes, Origin::File(path)))
}

/// Records what an attribute name says the file carries.
fn note_attribute(carried: &mut Carried, name: &str) {
    match name {
        "POSITION" => {}
        "NORMAL" => carried.normals = true,
        n if n.starts_with("TEXCOORD_") => carried.uvs = true,
        n if n.starts_with("COLOR_") => carried.colours = true,
        n => push_other(carried, n),
    }
}

fn push_other(carried: &mut Carried, name: &str) {
    if !carried.other.iter().any(|o| o == name) {
        carried.other.push(name.to_string());
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

fn read_vec3(bytes: &[u8], at: usize) -> DVec3 {
    let f = |k: usize| {
        let b = &bytes[at + 4 * k..at + 4 * k + 4];
        f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    DVec3::new(f(0), f(1), f(2))
}

fn write_vec3(bytes: &mut [u8], at: usize, v: [f32; 3]) {
    for (k, c) in v.iter().enumerate() {
        bytes[at + 4 * k..at + 4 * k + 4].copy_from_slice(&c.to_le_bytes());
    }
}

/// The layout a mesh read from glTF carries, if any.
fn layout_of(mesh: &Mesh) -> Option<&GltfLayout> {
    mesh.source
        .layout
        .as_deref()
        .and_then(|l| l.as_any().downcast_ref::<GltfLayout>())
}

/// Whether `mesh` (already checked by `io::check_mesh`) can be written as `format`.
pub(super) fn check_writable(mesh: &Mesh, format: Format) -> std::result::Result<(), String> {
    let layout = layout_of(mesh).ok_or(
        "glTF output needs a glTF input (it keeps the input's scene); write .ply, .obj, .off or .stl",
    )?;
    match (layout.binary, format) {
        (true, Format::Glb) | (false, Format::Gltf) => {}
        (true, _) => return Err("a GLB input is written as .glb".into()),
        (false, _) => return Err("a .gltf input is written as .gltf".into()),
    }
    if mesh.positions.len() != layout.vertices || mesh.triangles.len() != layout.triangles {
        return Err(format!(
            "the mesh has {} vertices and {} triangles but its glTF source has {} and {}; clear \
             mesh.source.layout after changing the mesh",
            mesh.positions.len(),
            mesh.triangles.len(),
            layout.vertices,
            layout.triangles
        ));
    }
    super::fits_single(mesh)
}

/// Writes `mesh` (checked by [`check_writable`]) to `path`, with its changed external buffers
/// beside it, each atomically. Every file is complete on disk before any is renamed into place
/// (buffers first, so the glTF never names a missing file): a failure while writing leaves no
/// new file and changes none.
pub(super) fn write(path: &Path, mesh: &Mesh) -> Result<()> {
    let Some(layout) = layout_of(mesh) else {
        return Err(Error::invalid(path, "cannot write: not a glTF mesh"));
    };
    let mut json = layout.json.clone();
    let mut buffers: Vec<Option<Vec<u8>>> = layout
        .buffers
        .iter()
        .map(|b| b.as_ref().map(|b| b.bytes.clone()))
        .collect();
    let mut changed = vec![false; buffers.len()];
    for &(span, base) in &layout.positions {
        let bytes = buffers[span.buffer].as_mut().expect("a loaded buffer");
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for i in 0..span.count {
            let p = mesh.positions[base + i].as_vec3().to_array();
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
            write_vec3(bytes, span.offset + i * span.stride, p);
        }
        changed[span.buffer] = true;
        if span.count > 0 {
            set_bounds(&mut json, span.accessor, lo, hi, false);
        }
    }
    if !layout.normals.is_empty() {
        let normals = super::vertex_normals(&mesh.positions, &mesh.triangles);
        for &(span, base) in &layout.normals {
            let bytes = buffers[span.buffer].as_mut().expect("a loaded buffer");
            let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
            for i in 0..span.count {
                let n = normals[base + i].as_vec3().to_array();
                for k in 0..3 {
                    lo[k] = lo[k].min(n[k]);
                    hi[k] = hi[k].max(n[k]);
                }
                write_vec3(bytes, span.offset + i * span.stride, n);
            }
            changed[span.buffer] = true;
            if span.count > 0 {
                set_bounds(&mut json, span.accessor, lo, hi, true);
            }
        }
    }
    let mut chunk = None;
    let mut staged = Vec::new();
    let mut chosen = Vec::new();
    // Buffers go beside the file the output's links lead to, where its relative URIs point.
    let beside = match super::atomic::destination(path) {
        Ok(super::atomic::Destination::Replace(real)) => real,
        _ => path.to_path_buf(),
    };
    for (i, loaded) in layout.buffers.iter().enumerate() {
        let (Some(loaded), true) = (loaded, changed[i]) else {
            continue;
        };
        let bytes = buffers[i].take().expect("a loaded buffer");
        match &loaded.origin {
            Origin::Chunk => chunk = Some(bytes),
            Origin::Data(head) => {
                json["buffers"][i]["uri"] =
                    Value::String(format!("{head},{}", base64_encode(&bytes)));
            }
            Origin::File(_) => {
                let bin = bin_path(&beside, &chosen, layout);
                staged.push(super::atomic::stage(&bin, |out| out.write_all(&bytes))?);
                chosen.push(bin.clone());
                let name = bin
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                json["buffers"][i]["uri"] = Value::String(percent_encode(&name));
            }
        }
    }
    let text = serde_json::to_vec(&json)
        .map_err(|e| Error::invalid(path, format!("cannot write: {e}")))?;
    let gltf = if layout.binary {
        let chunk = chunk.or_else(|| {
            // The binary chunk was not changed (no geometry in it): carried as it was.
            layout
                .buffers
                .iter()
                .flatten()
                .find(|b| matches!(b.origin, Origin::Chunk))
                .map(|b| b.bytes.clone())
        });
        super::atomic::stage(path, |out| write_glb(out, &text, chunk.as_deref()))?
    } else {
        super::atomic::stage(path, |out| out.write_all(&text))?
    };
    for bin in staged {
        bin.commit()?;
    }
    gltf.commit()
}

/// Sets an accessor's `min`/`max` to `lo`/`hi` (only if it had them, when `if_present`).
fn set_bounds(json: &mut Value, accessor: usize, lo: [f32; 3], hi: [f32; 3], if_present: bool) {
    let a = &mut json["accessors"][accessor];
    // The shortest decimal that reads back to the same `f32`, whatever the reader's precision.
    let number = |v: f32| {
        let v = v.to_string().parse().unwrap_or(f64::from(v));
        serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
    };
    for (key, v) in [("min", lo), ("max", hi)] {
        if !if_present || a.get(key).is_some() {
            a[key] = Value::Array(v.iter().map(|&c| number(c)).collect());
        }
    }
}

/// The next changed external buffer of an output, named after it: `STEM.bin`, else `STEM-K.bin`
/// for the first K that is free. Free means none of the names `chosen` for its other buffers, nor
/// a file the input names (any buffer or image, used by the geometry or not), nor an existing
/// file unless the output being replaced names it (its own buffer from an earlier run): nothing
/// else is ever written over.
fn bin_path(output: &Path, chosen: &[PathBuf], layout: &GltfLayout) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut inputs: Vec<PathBuf> = layout
        .buffers
        .iter()
        .flatten()
        .filter_map(|b| match &b.origin {
            Origin::File(p) => Some(p.clone()),
            _ => None,
        })
        .collect();
    if let Some(dir) = &layout.dir {
        inputs.extend(named_files(&layout.json, dir));
    }
    let inputs: Vec<PathBuf> = inputs.iter().map(|p| canonical(p)).collect();
    let replaced: Vec<PathBuf> = referenced_files(output)
        .iter()
        .map(|p| canonical(p))
        .collect();
    let chosen: Vec<PathBuf> = chosen.iter().map(|p| canonical(p)).collect();
    let mut k = 0;
    loop {
        let name = if k == 0 {
            format!("{stem}.bin")
        } else {
            format!("{stem}-{k}.bin")
        };
        let candidate = output.with_file_name(name);
        let resolved = canonical(&candidate);
        let taken = inputs.contains(&resolved)
            || chosen.contains(&resolved)
            || (std::fs::symlink_metadata(&candidate).is_ok() && !replaced.contains(&resolved));
        if !taken {
            return candidate;
        }
        k += 1;
    }
}

/// Whether `name` is one [`bin_path`] may give a buffer of the glTF output `output` (`STEM.bin`
/// or `STEM-K.bin`; a `.glb` too keeps an input's external buffers external), so that no side
/// file of a run is given such a name.
pub(crate) fn buffer_name_of(output: &Path, name: &std::ffi::OsStr) -> bool {
    let gltf = output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"));
    let (Some(stem), Some(name)) = (output.file_stem(), name.to_str()) else {
        return false;
    };
    let Some(rest) = stem.to_str().and_then(|s| name.strip_prefix(s)) else {
        return false;
    };
    let Some(k) = rest.strip_suffix(".bin") else {
        return false;
    };
    gltf && (k.is_empty()
        || k.strip_prefix('-')
            .is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit())))
}

/// The directory `path` is in (`.` for a bare file name).
fn directory_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// `path` with its directory made canonical (the file itself need not exist).
fn canonical(path: &Path) -> PathBuf {
    match (std::fs::canonicalize(directory_of(path)), path.file_name()) {
        (Ok(d), Some(name)) => d.join(name),
        _ => path.to_path_buf(),
    }
}

/// The external files (buffers and images, not `data:` URIs) a glTF's JSON names, relative to
/// `dir`.
fn named_files(json: &Value, dir: &Path) -> Vec<PathBuf> {
    ["buffers", "images"]
        .iter()
        .flat_map(|key| array(json, key))
        .filter_map(|item| item.get("uri")?.as_str())
        .filter(|uri| !uri.starts_with("data:"))
        .filter_map(percent_decode)
        .map(|name| dir.join(name))
        .collect()
}

/// The external files the glTF or GLB at `path` names (see [`named_files`]); none when `path`
/// is not such a file or cannot be read. Only a GLB's JSON chunk is read, and a text file only
/// when it is named `.gltf`.
pub(crate) fn referenced_files(path: &Path) -> Vec<PathBuf> {
    let json = || -> Option<Value> {
        let mut file = std::fs::File::open(path).ok()?;
        let size = file.metadata().ok()?.len();
        let mut head = Vec::new();
        (&mut file).take(20).read_to_end(&mut head).ok()?;
        if head.len() == 20 && has_magic(&head) {
            let len = u32::from_le_bytes([head[12], head[13], head[14], head[15]]);
            if u64::from(len) > size {
                return None;
            }
            let mut text = Vec::new();
            file.take(u64::from(len)).read_to_end(&mut text).ok()?;
            return serde_json::from_slice(&text).ok();
        }
        let gltf = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("gltf"));
        if !gltf {
            return None;
        }
        let bytes = std::fs::read(path).ok()?;
        serde_json::from_slice(super::without_bom(&bytes)).ok()
    };
    json()
        .map(|j| named_files(&j, directory_of(path)))
        .unwrap_or_default()
}

/// A GLB: header, JSON chunk (padded with spaces), binary chunk (padded with zeros).
fn write_glb(out: &mut impl Write, json: &[u8], bin: Option<&[u8]>) -> std::io::Result<()> {
    let pad = |n: usize| (4 - n % 4) % 4;
    let json_len = json.len() + pad(json.len());
    let bin_len = bin.map_or(0, |b| b.len() + pad(b.len()));
    let total = 12 + 8 + json_len + bin.map_or(0, |_| 8 + bin_len);
    let word = |n: usize| {
        u32::try_from(n)
            .map(u32::to_le_bytes)
            .map_err(|_| std::io::Error::other("more than 4 GiB: too large for a GLB"))
    };
    out.write_all(b"glTF")?;
    out.write_all(&2u32.to_le_bytes())?;
    out.write_all(&word(total)?)?;
    out.write_all(&word(json_len)?)?;
    out.write_all(&CHUNK_JSON.to_le_bytes())?;
    out.write_all(json)?;
    out.write_all(&b"   "[..pad(json.len())])?;
    if let Some(bin) = bin {
        out.write_all(&word(bin_len)?)?;
        out.write_all(&CHUNK_BIN.to_le_bytes())?;
        out.write_all(bin)?;
        out.write_all(&[0; 3][..pad(bin.len())])?;
    }
    Ok(())
}

const BASE64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

fn base64_encode(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(BASE64[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// Standard base64 with optional padding; `None` on any other character.
fn base64_decode(text: &[u8]) -> Option<Vec<u8>> {
    let text = text
        .strip_suffix(b"==")
        .or_else(|| text.strip_suffix(b"="))
        .unwrap_or(text);
    let mut out = Vec::with_capacity(text.len() / 4 * 3 + 2);
    let (mut acc, mut bits) = (0u32, 0);
    for &c in text {
        let v = BASE64.iter().position(|&b| b == c)? as u32;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

/// A relative URI reference's `%XX` escapes decoded.
fn percent_decode(uri: &str) -> Option<String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// A file name as a relative URI: everything but unreserved characters escaped.
fn percent_encode(name: &str) -> String {
    name.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                (b as char).to_string()
            }
            b => format!("%{b:02X}"),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips() {
        for n in 0..10 {
            let bytes: Vec<u8> = (0..n).map(|i| (i * 37 + 5) as u8).collect();
            assert_eq!(base64_decode(base64_encode(&bytes).as_bytes()), Some(bytes));
        }
        assert_eq!(base64_encode(b"Man"), "TWFu");
        assert_eq!(base64_encode(b"M"), "TQ==");
        assert_eq!(base64_decode(b"T!=="), None);
    }

    /// Two triangle primitives (one indexed, one not), a third sharing the first's positions, and
    /// a line primitive, all in one embedded buffer.
    fn primitives() -> Vec<u8> {
        let mut bin = Vec::new();
        // Accessor 0: a tetrahedron's 4 corners; 1: 6 corners of two loose triangles; 2: 2 line ends.
        let points: [[f32; 3]; 12] = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [5.0, 1.0, 0.0],
            [7.0, 0.0, 0.0],
            [8.0, 0.0, 0.0],
            [7.0, 1.0, 0.0],
            [9.0, 9.0, 9.0],
            [9.0, 9.0, 8.0],
        ];
        for c in points.iter().flatten() {
            bin.extend_from_slice(&c.to_le_bytes());
        }
        for i in [0u8, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3] {
            bin.push(i);
        }
        let json = serde_json::json!({
            "asset": {"version": "2.0"},
            "buffers": [{"byteLength": bin.len(),
                "uri": format!("data:application/gltf-buffer;base64,{}", base64_encode(&bin))}],
            "bufferViews": [{"buffer": 0, "byteLength": 144}, {"buffer": 0, "byteOffset": 144, "byteLength": 12}],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                {"bufferView": 0, "byteOffset": 48, "componentType": 5126, "count": 6, "type": "VEC3"},
                {"bufferView": 0, "byteOffset": 120, "componentType": 5126, "count": 2, "type": "VEC3"},
                {"bufferView": 1, "componentType": 5121, "count": 6, "type": "SCALAR"},
                {"bufferView": 1, "byteOffset": 6, "componentType": 5121, "count": 6, "type": "SCALAR"}
            ],
            "meshes": [
                {"primitives": [
                    {"attributes": {"POSITION": 0}, "indices": 3},
                    {"attributes": {"POSITION": 2}, "mode": 1}
                ]},
                {"primitives": [
                    {"attributes": {"POSITION": 1, "_ID": 1}},
                    {"attributes": {"POSITION": 0}, "indices": 4, "mode": 4}
                ]}
            ]
        });
        serde_json::to_vec(&json).unwrap()
    }

    #[test]
    fn primitives_are_concatenated_and_lines_left_alone() {
        let mesh = read(&primitives(), false, None).unwrap();
        // The tetrahedron's 4 vertices once (two primitives share them), then the loose 6.
        assert_eq!(mesh.positions.len(), 10);
        assert_eq!(mesh.positions[4], DVec3::new(5.0, 0.0, 0.0));
        assert_eq!(
            mesh.triangles.to_vec(),
            [
                [0, 2, 1],
                [0, 1, 3],
                [4, 5, 6],
                [7, 8, 9],
                [0, 3, 2],
                [1, 2, 3]
            ]
        );
        let carried = mesh.source.layout.as_ref().unwrap().carries();
        assert_eq!(carried.other, ["_ID"]);
        assert!(!carried.uvs && !carried.normals && !carried.materials);

        // Written back: the line's points and the indices keep their bytes.
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.gltf");
        let mut moved = mesh.clone();
        moved
            .positions
            .iter_mut()
            .for_each(|p| *p += DVec3::splat(0.5));
        crate::io::write_mesh(&out, &moved).unwrap();
        let back = crate::io::read_mesh(&out).unwrap();
        assert_eq!(back.positions.to_vec(), moved.positions.to_vec());
        assert_eq!(back.triangles.to_vec(), mesh.triangles.to_vec());
        let json: Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
        let uri = json["buffers"][0]["uri"].as_str().unwrap();
        let head = "data:application/gltf-buffer;base64,";
        let bin = base64_decode(uri.strip_prefix(head).unwrap().as_bytes()).unwrap();
        assert_eq!(read_vec3(&bin, 120), DVec3::splat(9.0));
        assert_eq!(read_vec3(&bin, 132), DVec3::new(9.0, 9.0, 8.0));
        assert_eq!(bin[144..], [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]);
        assert_eq!(
            json["accessors"][1]["min"],
            serde_json::json!([5.5, 0.5, 0.5])
        );
        assert!(
            json["accessors"][2].get("min").is_none(),
            "a line's bounds set"
        );

        // Not to a .glb, and an external buffer needs a directory.
        let glb = dir.path().join("out.glb");
        let e = crate::io::write_mesh(&glb, &moved).unwrap_err().to_string();
        assert!(e.contains("a .gltf input is written as .gltf"), "{e}");
        let text = String::from_utf8(primitives()).unwrap();
        let external = text.replacen("data:application/gltf-buffer;base64,", "x.bin#", 1);
        let e = read(external.as_bytes(), false, None).unwrap_err();
        assert!(
            e.contains("cannot be read without the file's directory"),
            "{e}"
        );
    }

    #[test]
    fn stored_positions_are_those_read_back() {
        let mut mesh = read(&primitives(), false, None).unwrap();
        for p in mesh.positions.iter_mut() {
            *p = *p * 1.000_000_123 + DVec3::new(0.1, -0.7, 1e-9);
        }
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.gltf");
        crate::io::write_mesh(&out, &mesh).unwrap();
        let back = crate::io::read_mesh(&out).unwrap();
        let stored = crate::io::Stored::of(&out, &mesh).unwrap();
        let expected: Vec<DVec3> = mesh.positions.iter().map(|&p| stored.round(p)).collect();
        assert_eq!(back.positions.to_vec(), expected);
        assert!(!stored.is_exact());
    }

    #[test]
    fn percent_escapes_round_trip() {
        assert_eq!(percent_encode("a b%.bin"), "a%20b%25.bin");
        assert_eq!(percent_decode("a%20b%25.bin").as_deref(), Some("a b%.bin"));
        assert_eq!(percent_decode("a%2"), None);
    }
}
