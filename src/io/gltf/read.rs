//! Reading glTF: GLB chunks, accessors and buffers into one mesh and the layout a write needs.

use std::collections::{HashMap, HashSet};
use std::io::Read;
use std::ops::Range;
use std::path::Path;

use glam::DVec3;
use serde_json::Value;

use super::runs::runs;
use super::uri::{base64_decode, percent_decode};
use super::{
    CHUNK_BIN, CHUNK_JSON, FLOAT, GltfLayout, Loaded, MESHOPT, Origin, Span, array, field,
    has_magic, index,
};
use crate::io::FaceBuilder;
use crate::mesh::{Carried, Format, Mesh, Source};

/// Reads a GLB (`binary`) or a `.gltf`; `dir` is the directory external buffers are relative to
/// (`None` when the bytes come from no file: external buffers are then refused).
pub(crate) fn read(
    bytes: &[u8],
    binary: bool,
    dir: Option<&Path>,
) -> std::result::Result<Mesh, String> {
    let (json, chunk) = if binary {
        let (json, chunk) = glb_chunks(bytes)?;
        (json, chunk)
    } else {
        (crate::io::without_bom(bytes), None)
    };
    let mut json: Value = serde_json::from_slice(json).map_err(|e| format!("glTF JSON: {e}"))?;
    Reader::new(&json, chunk, dir).check_top()?;
    // Draco primitives become plain ones, their data decoded into the buffers loaded so far.
    let (buffers, decompressed) = super::draco::decompress(&mut json, chunk, dir)?;
    let mut reader = Reader {
        json: &json,
        chunk,
        dir,
        buffers,
    };
    let mut prims: Vec<Primitive> = Vec::new();
    let mut checked: HashSet<usize> = HashSet::new();
    // Each primitive's triangles in its own POSITION accessor's numbering until the vertices are
    // known.
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
            if prim.pointer(&format!("/extensions/{MESHOPT}")).is_some() {
                return Err(at(meshopt_refused()));
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
            if checked.insert(position) {
                let buffer = reader.bytes(span.buffer);
                for i in 0..span.count {
                    let v = read_vec3(buffer, span.offset + i * span.stride);
                    if !v.is_finite() {
                        return Err(at(format!(
                            "POSITION accessor {position}: vertex {i} is not finite ({}, {}, {})",
                            v.x, v.y, v.z
                        )));
                    }
                }
            }
            let normal = match attributes.and_then(|a| a.get("NORMAL")) {
                Some(normal) => {
                    let normal = index(normal)
                        .ok_or_else(|| at("NORMAL is not an accessor index".into()))?;
                    let n = reader.vec3(normal, "NORMAL").map_err(at)?;
                    if n.count != span.count {
                        return Err(at(format!(
                            "NORMAL has {} elements but POSITION has {}",
                            n.count, span.count
                        )));
                    }
                    Some(n)
                }
                None => None,
            };
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
            let from = corners.len();
            for t in ids.chunks_exact(3) {
                if let Some(&v) = t.iter().find(|&&v| v as usize >= span.count) {
                    return Err(at(format!(
                        "vertex index {v} out of range (0..{})",
                        span.count
                    )));
                }
                corners.push([t[0], t[1], t[2]]);
            }
            prims.push(Primitive {
                span,
                normal,
                triangles: from..corners.len(),
            });
        }
    }
    let (all, positions, normals, corners) = shared_geometry(&reader, &prims, corners)?;
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
        decompressed,
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

/// Meshopt is not decoded: what a file using it is told.
fn meshopt_refused() -> String {
    format!("{MESHOPT} (meshopt-compressed geometry) is not supported")
}

/// Reads accessors and loads buffers (each once) of a glTF's JSON.
pub(super) struct Reader<'a> {
    json: &'a Value,
    chunk: Option<&'a [u8]>,
    dir: Option<&'a Path>,
    buffers: Vec<Option<Loaded>>,
}

impl<'a> Reader<'a> {
    /// A reader of `json` with no buffer loaded yet.
    pub(super) fn new(json: &'a Value, chunk: Option<&'a [u8]>, dir: Option<&'a Path>) -> Self {
        Reader {
            json,
            chunk,
            dir,
            buffers: Vec::new(),
        }
    }

    /// The buffers loaded (index = the JSON's buffer index; `None` for the others).
    pub(super) fn into_buffers(self) -> Vec<Option<Loaded>> {
        self.buffers
    }

    /// The version, and no meshopt (Draco is decoded: see `draco`).
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
            if array(self.json, key)
                .iter()
                .any(|n| n.as_str() == Some(MESHOPT))
            {
                return Err(meshopt_refused());
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
    pub(super) fn load(&mut self, i: usize) -> std::result::Result<&[u8], String> {
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
            self.buffers[i] = Some(Loaded {
                bytes,
                origin,
                extended: false,
            });
        }
        Ok(self.bytes(i))
    }
}

/// A triangle primitive as read: its `POSITION` and `NORMAL` data, and where its triangles are in
/// the corners read so far.
struct Primitive {
    span: Span,
    normal: Option<Span>,
    triangles: Range<usize>,
}

/// Vertices, `POSITION` and `NORMAL` accessors with their first vertices, and triangles.
type Geometry = (
    Vec<DVec3>,
    Vec<(Span, usize)>,
    Vec<(Span, usize)>,
    Vec<[u32; 3]>,
);

/// The one mesh the primitives make. Each element of `POSITION` data is one vertex however many
/// accessors and primitives name it (runs of elements in order of first use, each in its order in
/// the buffer): shared geometry is one surface. So a triangle is read once: one whose vertices
/// another primitive already gave (the same index data, or an overlapping part of other index
/// data, in either winding) is that primitive's triangle again; within one primitive every
/// triangle is kept as the file has it, as in the other formats. `corners` are in each
/// primitive's own numbering.
fn shared_geometry(
    reader: &Reader,
    prims: &[Primitive],
    mut corners: Vec<[u32; 3]>,
) -> std::result::Result<Geometry, String> {
    let mut accessors: Vec<(Span, i64)> = Vec::new();
    let mut number: HashMap<usize, usize> = HashMap::new();
    let of_prim: Vec<usize> = prims
        .iter()
        .map(|p| {
            *number.entry(p.span.accessor).or_insert_with(|| {
                accessors.push((p.span, 0));
                accessors.len() - 1
            })
        })
        .collect();
    let (runs, place) = runs(&accessors);
    let mut bases = Vec::with_capacity(runs.len());
    let mut total = 0;
    for run in &runs {
        bases.push(total);
        total += run.len();
    }
    if u32::try_from(total).is_err() {
        return Err(format!("{total} vertices: more than 2^32"));
    }
    let mut all = Vec::with_capacity(total);
    for run in &runs {
        let bytes = reader.bytes(run.buffer);
        all.extend((run.first..run.end).map(|k| read_vec3(bytes, run.byte(k))));
    }
    let base_of = |k: usize| place[k].map_or(0, |(r, at)| bases[r] + at);
    let positions = accessors
        .iter()
        .enumerate()
        .map(|(k, &(span, _))| (span, base_of(k)))
        .collect();
    let normals = prims
        .iter()
        .zip(&of_prim)
        .filter_map(|(p, &k)| Some((p.normal?, base_of(k))))
        .collect();
    let mut users = vec![0usize; runs.len()];
    for &k in &of_prim {
        if let Some((r, _)) = place[k] {
            users[r] += 1;
        }
    }
    let mut first_from: HashMap<[u32; 3], usize> = HashMap::new();
    let mut kept = 0;
    for (i, (p, &k)) in prims.iter().zip(&of_prim).enumerate() {
        let base = base_of(k) as u32;
        let shared = place[k].is_some_and(|(r, _)| users[r] > 1);
        for j in p.triangles.clone() {
            let t = corners[j].map(|v| base + v);
            if shared {
                let mut key = t;
                key.sort_unstable();
                if *first_from.entry(key).or_insert(i) != i {
                    continue;
                }
            }
            corners[kept] = t;
            kept += 1;
        }
    }
    corners.truncate(kept);
    Ok((all, positions, normals, corners))
}

/// The bytes a write replaces, every element of the `POSITION` and `NORMAL` accessors, must hold
/// nothing else: not each other (a `NORMAL` that is the `POSITION` accessor), not indices, not
/// another attribute, not an image. Interleaved views are fine: only the elements' own bytes count.
/// Accessors naming the same elements (see [`runs`]) write the same values there.
fn check_rewritten_bytes(
    json: &Value,
    reader: &Reader,
    positions: &[(Span, usize)],
    normals: &[(Span, usize)],
) -> std::result::Result<(), String> {
    let mut rewritten: Vec<usize> = Vec::new();
    let mut tagged: Vec<(Span, i64)> = Vec::new();
    for &(span, _) in positions {
        rewritten.push(span.accessor);
        tagged.push((span, 0));
    }
    let (position_runs, _) = runs(&tagged);
    // A normal element belongs to one vertex: aliased NORMAL accessors share a run only when their
    // common elements are the normals of the same vertices.
    tagged.clear();
    for &(span, base) in normals {
        if rewritten.contains(&span.accessor) {
            if positions.iter().any(|(p, _)| p.accessor == span.accessor) {
                return Err(format!(
                    "accessor {} is both POSITION and NORMAL: the recomputed normals would \
                     replace the positions",
                    span.accessor
                ));
            }
            continue;
        }
        rewritten.push(span.accessor);
        let vertex_of_element_0 = base as i64 - (span.offset / span.stride) as i64;
        tagged.push((span, vertex_of_element_0));
    }
    let (normal_runs, _) = runs(&tagged);
    let mut masks: HashMap<usize, Vec<u64>> = HashMap::new();
    let all_runs = position_runs.iter().map(|r| (r, "POSITION"));
    for (run, what) in all_runs.chain(normal_runs.iter().map(|r| (r, "NORMAL"))) {
        let len = reader.bytes(run.buffer).len();
        let mask = masks
            .entry(run.buffer)
            .or_insert_with(|| vec![0; len.div_ceil(64)]);
        for k in run.first..run.end {
            let at = run.byte(k);
            for b in at..at + 12 {
                if mask[b / 64] >> (b % 64) & 1 == 1 {
                    return Err(format!(
                        "{what} accessor {} shares bytes with another POSITION or NORMAL \
                         accessor: one would overwrite the other",
                        run.accessor
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

pub(super) fn read_vec3(bytes: &[u8], at: usize) -> DVec3 {
    let f = |k: usize| {
        let b = &bytes[at + 4 * k..at + 4 * k + 4];
        f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    DVec3::new(f(0), f(1), f(2))
}
