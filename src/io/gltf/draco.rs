//! Draco (`KHR_draco_mesh_compression`): a compressed primitive is decoded into plain accessors
//! before the rest of the reader runs, so that it is read, smoothed and written like any other.
//!
//! For each Draco primitive, every attribute the extension maps to a Draco attribute, and the
//! indices, are decoded into their accessors' own types (the values Draco gives, converted to
//! nothing: a type that differs is refused) and appended, tightly packed, as new buffer views of
//! the buffer that holds the compressed data (a GLB's binary chunk, a `data:` URI or an external
//! file, written as any changed buffer is). The accessors name those views, the primitive loses
//! its extension entry, and `KHR_draco_mesh_compression` leaves `extensionsUsed` and
//! `extensionsRequired`. The compressed bytes stay in their buffer, in a view no accessor names
//! (removing them would renumber every later view). A primitive whose accessors already all have
//! buffer views (the uncompressed fallback a file may carry when the extension is optional) is
//! read from those and not decoded. Data several primitives share (the same compressed view) is
//! decoded once; an accessor several primitives name is filled once.

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::path::Path;

use draco_core::{
    DataType, DecodeLimits, DecoderBuffer, Mesh as DracoMesh, MeshDecoder, PointAttribute,
    PointIndex,
};
use serde_json::{Map, Value, json};

use super::read::Reader;
use super::{Loaded, array, field, index};

/// The extension's name, in a primitive's `extensions` and the file's `extensionsUsed`.
pub(super) const EXTENSION: &str = "KHR_draco_mesh_compression";

const ARRAY_BUFFER: u64 = 34962;
const ELEMENT_ARRAY_BUFFER: u64 = 34963;

/// One Draco primitive: where it is, its compressed view, and each decoded accessor with the
/// Draco attribute (unique id) that fills it.
struct Job {
    mesh: usize,
    primitive: usize,
    view: usize,
    attributes: Vec<(String, usize, u32)>,
    indices: Option<usize>,
}

impl Job {
    fn at(&self, what: impl std::fmt::Display) -> String {
        format!("mesh {} primitive {}: {what}", self.mesh, self.primitive)
    }
}

/// Decoded bytes for one accessor: the bytes, the view's stride when elements are padded to 4
/// bytes, its target, and for indices the component type chosen.
struct Filled {
    accessor: Accessor,
    buffer: usize,
    bytes: Vec<u8>,
    stride: Option<usize>,
    target: u64,
    indices: Option<u64>,
}

/// An accessor of the file, or a new one for the indices of a primitive that had none.
enum Accessor {
    Existing(usize),
    NewIndices { mesh: usize, primitive: usize },
}

/// Makes every Draco primitive of `json` plain (see the module doc). Returns the buffers loaded
/// on the way, decoded data appended (for the reader to go on with), and whether the file had any
/// Draco primitive. A file without one is left as it is and nothing is loaded.
pub(super) fn decompress(
    json: &mut Value,
    chunk: Option<&[u8]>,
    dir: Option<&Path>,
) -> std::result::Result<(Vec<Option<Loaded>>, bool), String> {
    let jobs = jobs(json)?;
    let listed = ["extensionsUsed", "extensionsRequired"]
        .iter()
        .any(|k| array(json, k).iter().any(|n| n.as_str() == Some(EXTENSION)));
    if jobs.is_empty() && !listed {
        return Ok((Vec::new(), false));
    }
    let mut reader = Reader::new(json, chunk, dir);
    let mut filled: Vec<Filled> = Vec::new();
    // Each filled accessor and what filled it: the compressed view and the Draco attribute id
    // (u32::MAX for indices, which no attribute id can be).
    let mut source: HashMap<usize, (usize, u32)> = HashMap::new();
    let mut decoded: HashMap<usize, DracoMesh> = HashMap::new();
    let accessors = array(json, "accessors");
    let get = |job: &Job, what: &str, k: usize| {
        accessors.get(k).ok_or_else(|| {
            job.at(format_args!(
                "{what} accessor {k} out of range (0..{})",
                accessors.len()
            ))
        })
    };
    for job in &jobs {
        let named: Vec<(usize, u32)> = job
            .attributes
            .iter()
            .map(|a| (a.1, a.2))
            .chain(job.indices.map(|k| (k, u32::MAX)))
            .collect();
        if named.iter().all(|&(k, _)| {
            accessors
                .get(k)
                .is_some_and(|a| a.get("bufferView").is_some())
        }) && job.indices.is_some()
        {
            continue; // the uncompressed fallback is complete: read as the file has it
        }
        let mut todo = false;
        for &(k, id) in &named {
            match source.get(&k) {
                Some(&s) if s == (job.view, id) => {}
                Some(_) => {
                    return Err(job.at(format_args!(
                        "accessor {k} is filled by two different Draco attributes"
                    )));
                }
                None => todo = true,
            }
        }
        if !todo && job.indices.is_some() {
            continue; // all shared with primitives already decoded
        }
        let mesh =
            match decoded.entry(job.view) {
                Entry::Occupied(known) => known.into_mut(),
                Entry::Vacant(new) => {
                    let bytes = view_bytes(json, &mut reader, job.view).map_err(|e| job.at(e))?;
                    new.insert(decode(bytes).map_err(|e| {
                        job.at(format_args!("Draco data could not be decoded ({e})"))
                    })?)
                }
            };
        let buffer = view_buffer(json, job.view).map_err(|e| job.at(e))?;
        for (name, accessor, id) in &job.attributes {
            if source.contains_key(accessor) {
                continue;
            }
            let a = get(job, name, *accessor)?;
            let (bytes, stride) = attribute_bytes(mesh, *id, a)
                .map_err(|e| job.at(format_args!("{name} (accessor {accessor}): {e}")))?;
            source.insert(*accessor, (job.view, *id));
            filled.push(Filled {
                accessor: Accessor::Existing(*accessor),
                buffer,
                bytes,
                stride,
                target: ARRAY_BUFFER,
                indices: None,
            });
        }
        if job.indices.is_none_or(|k| !source.contains_key(&k)) {
            let a = job.indices.map(|k| get(job, "indices", k)).transpose()?;
            let (bytes, ct) =
                index_bytes(mesh, a).map_err(|e| job.at(format_args!("indices: {e}")))?;
            let accessor = match job.indices {
                Some(k) => {
                    source.insert(k, (job.view, u32::MAX));
                    Accessor::Existing(k)
                }
                None => Accessor::NewIndices {
                    mesh: job.mesh,
                    primitive: job.primitive,
                },
            };
            filled.push(Filled {
                accessor,
                buffer,
                bytes,
                stride: None,
                target: ELEMENT_ARRAY_BUFFER,
                indices: Some(ct),
            });
        }
    }
    drop(decoded);
    let mut buffers = reader.into_buffers();
    apply(json, &jobs, &mut buffers, filled);
    Ok((buffers, !jobs.is_empty()))
}

/// Every Draco primitive of the file, checked for what a decode needs.
fn jobs(json: &Value) -> std::result::Result<Vec<Job>, String> {
    let mut jobs = Vec::new();
    for (m, mesh) in array(json, "meshes").iter().enumerate() {
        for (p, prim) in array(mesh, "primitives").iter().enumerate() {
            let Some(ext) = prim.pointer(&format!("/extensions/{EXTENSION}")) else {
                continue;
            };
            let at = |what: String| format!("mesh {m} primitive {p}: {what}");
            if prim.get("mode").map_or(Some(4), Value::as_u64) != Some(4) {
                return Err(at(format!(
                    "{EXTENSION} on a primitive that is not triangles (mode {}): not supported",
                    prim["mode"]
                )));
            }
            let view =
                field(ext, "bufferView", None).map_err(|e| at(format!("{EXTENSION}: {e}")))?;
            let ids = ext
                .get("attributes")
                .and_then(Value::as_object)
                .ok_or_else(|| at(format!("{EXTENSION} has no attributes")))?;
            let named = prim.get("attributes").and_then(Value::as_object);
            let mut attributes = Vec::new();
            for (name, id) in ids {
                let id = id
                    .as_u64()
                    .and_then(|i| u32::try_from(i).ok())
                    .filter(|&i| i != u32::MAX)
                    .ok_or_else(|| at(format!("{EXTENSION}: attribute {name} is not an id")))?;
                // An id for an attribute the primitive does not have names nothing to fill.
                let Some(accessor) = named.and_then(|a| a.get(name)) else {
                    continue;
                };
                let accessor = index(accessor)
                    .ok_or_else(|| at(format!("{name} is not an accessor index")))?;
                attributes.push((name.clone(), accessor, id));
            }
            let indices = match prim.get("indices") {
                None => None,
                Some(i) => {
                    Some(index(i).ok_or_else(|| at("indices is not an accessor index".into()))?)
                }
            };
            jobs.push(Job {
                mesh: m,
                primitive: p,
                view,
                attributes,
                indices,
            });
        }
    }
    Ok(jobs)
}

/// The buffer a view is in.
fn view_buffer(json: &Value, view: usize) -> std::result::Result<usize, String> {
    let views = array(json, "bufferViews");
    let v = views.get(view).ok_or_else(|| {
        format!(
            "{EXTENSION}: bufferView {view} out of range (0..{})",
            views.len()
        )
    })?;
    field(v, "buffer", None).map_err(|e| format!("bufferView {view}: {e}"))
}

/// A view's buffer and bytes, the buffer loaded.
fn view_bytes<'r>(
    json: &Value,
    reader: &'r mut Reader,
    view: usize,
) -> std::result::Result<&'r [u8], String> {
    let buffer = view_buffer(json, view)?;
    let v = &array(json, "bufferViews")[view];
    let vat = |e: String| format!("bufferView {view}: {e}");
    let offset = field(v, "byteOffset", Some(0)).map_err(vat)?;
    let length = field(v, "byteLength", None).map_err(vat)?;
    let bytes = reader.load(buffer)?;
    let have = bytes.len();
    let bytes = offset
        .checked_add(length)
        .and_then(|end| bytes.get(offset..end))
        .ok_or_else(|| {
            format!(
                "bufferView {view}: bytes {offset}..+{length} beyond buffer {buffer} ({have} bytes)"
            )
        })?;
    Ok(bytes)
}

/// A Draco mesh from its bytes. Counts up to what the engine can index (2^32) are taken; the
/// decoder's own budget still refuses a count that the stream's bytes cannot back.
fn decode(bytes: &[u8]) -> std::result::Result<DracoMesh, String> {
    let limits = DecodeLimits::default()
        .with_max_points(u64::from(u32::MAX))
        .with_max_faces(u64::from(u32::MAX))
        .with_max_decoded_bytes(u64::MAX);
    let mut buffer = DecoderBuffer::new(bytes).with_limits(limits);
    let mut mesh = DracoMesh::new();
    MeshDecoder::new()
        .decode(&mut buffer, &mut mesh)
        // On one line whatever the decoder says.
        .map_err(|e| e.to_string().replace(['\n', '\r'], " "))?;
    Ok(mesh)
}

/// glTF's component type of a Draco data type, if glTF has it.
fn component_type(t: DataType) -> Option<u64> {
    Some(match t {
        DataType::Int8 => 5120,
        DataType::Uint8 => 5121,
        DataType::Int16 => 5122,
        DataType::Uint16 => 5123,
        DataType::Uint32 => 5125,
        DataType::Float32 => 5126,
        _ => return None,
    })
}

fn component_size(ct: u64) -> usize {
    match ct {
        5120 | 5121 => 1,
        5122 | 5123 => 2,
        _ => 4,
    }
}

fn components(kind: &str) -> Option<usize> {
    Some(match kind {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" => 4,
        "MAT2" => 4,
        "MAT3" => 9,
        "MAT4" => 16,
        _ => return None,
    })
}

/// The values of Draco attribute `id` for every point, in accessor `a`'s layout (elements padded
/// to 4 bytes, the stride returned, when an element is not a multiple of 4: vertex attributes
/// must be aligned so). The accessor's type must be the decoded one and its count the points'.
fn attribute_bytes(
    mesh: &DracoMesh,
    id: u32,
    a: &Value,
) -> std::result::Result<(Vec<u8>, Option<usize>), String> {
    let att: &PointAttribute = (0..mesh.num_attributes())
        .map(|i| mesh.attribute(i))
        .find(|att| att.unique_id() == id)
        .ok_or_else(|| format!("the Draco data has no attribute with id {id}"))?;
    let ct = a.get("componentType").and_then(Value::as_u64);
    let kind = a.get("type").and_then(Value::as_str);
    let nc = kind
        .and_then(components)
        .ok_or_else(|| format!("type {} is not an accessor type", kind.unwrap_or("missing")))?;
    let decoded = component_type(att.data_type());
    if decoded.is_none() || decoded != ct || usize::from(att.num_components()) != nc {
        return Err(format!(
            "the Draco data is {} × {:?} but the accessor is {} × componentType {}: not supported",
            att.num_components(),
            att.data_type(),
            nc,
            ct.map_or("missing".into(), |c| c.to_string())
        ));
    }
    let points = mesh.num_points();
    let count = field(a, "count", None)?;
    if count != points {
        return Err(format!(
            "the accessor's count is {count} but the Draco data has {points} points"
        ));
    }
    let element = nc * component_size(ct.unwrap_or(0));
    let stride = element.next_multiple_of(4);
    let data = att.buffer().data();
    // A decoded attribute's values start at its buffer's first byte (as the crate's own readers
    // take them).
    let from = 0;
    let step = usize::try_from(att.byte_stride()).map_err(|_| "negative byte stride")?;
    let mut out = Vec::with_capacity(points * stride);
    if att.is_mapping_identity() && from == 0 && step == element && stride == element {
        let all = data
            .get(..points * element)
            .ok_or("the Draco data holds fewer values than points")?;
        out.extend_from_slice(all);
    } else {
        for p in 0..points {
            let v = att.mapped_index(PointIndex(p as u32)).0 as usize;
            let value = v
                .checked_mul(step)
                .and_then(|b| b.checked_add(from))
                .and_then(|b| data.get(b..b.checked_add(element)?))
                .ok_or_else(|| {
                    format!("point {p} names value {v}, which the data does not hold")
                })?;
            out.extend_from_slice(value);
            out.resize(out.len() + stride - element, 0);
        }
    }
    Ok((out, (stride != element).then_some(stride)))
}

/// The triangles' corners in accessor `a`'s component type when they fit it (else `u32`, returned
/// as the type to set), checked against the points and the accessor's count.
fn index_bytes(mesh: &DracoMesh, a: Option<&Value>) -> std::result::Result<(Vec<u8>, u64), String> {
    let faces = mesh.faces();
    let points = mesh.num_points();
    if let Some(a) = a {
        let count = field(a, "count", None)?;
        if count != 3 * faces.len() {
            return Err(format!(
                "the accessor's count is {count} but the Draco data has {} triangles ({} indices)",
                faces.len(),
                3 * faces.len()
            ));
        }
    }
    let mut top = 0;
    for &[x, y, z] in faces {
        top = top.max(x.0).max(y.0).max(z.0);
    }
    if !faces.is_empty() && top as usize >= points {
        return Err(format!("the Draco data names point {top} of {points}"));
    }
    let declared = a
        .and_then(|a| a.get("componentType"))
        .and_then(Value::as_u64);
    let ct = match declared {
        Some(5121) if top <= u32::from(u8::MAX) => 5121,
        Some(5123) if top <= u32::from(u16::MAX) => 5123,
        None if top <= u32::from(u16::MAX) => 5123,
        _ => 5125,
    };
    let size = component_size(ct);
    let mut out = Vec::with_capacity(3 * faces.len() * size);
    for corner in faces.iter().flatten() {
        out.extend_from_slice(&corner.0.to_le_bytes()[..size]);
    }
    Ok((out, ct))
}

/// Appends the decoded data to the buffers and rewrites the JSON to name it.
fn apply(json: &mut Value, jobs: &[Job], buffers: &mut [Option<Loaded>], filled: Vec<Filled>) {
    let mut views: Vec<Value> = array(json, "bufferViews").to_vec();
    let mut accessors: Vec<Value> = array(json, "accessors").to_vec();
    for f in filled {
        let loaded = buffers[f.buffer]
            .as_mut()
            .expect("the compressed data's buffer is loaded");
        loaded.extended = true;
        let bytes = &mut loaded.bytes;
        bytes.resize(bytes.len().next_multiple_of(4), 0);
        let offset = bytes.len();
        bytes.extend_from_slice(&f.bytes);
        let mut view = json!({
            "buffer": f.buffer, "byteOffset": offset, "byteLength": f.bytes.len(),
            "target": f.target,
        });
        if let Some(stride) = f.stride {
            view["byteStride"] = stride.into();
        }
        let k = match f.accessor {
            Accessor::Existing(k) => k,
            Accessor::NewIndices { mesh, primitive } => {
                let size = component_size(f.indices.unwrap_or(5125));
                accessors.push(json!({"count": f.bytes.len() / size, "type": "SCALAR"}));
                json["meshes"][mesh]["primitives"][primitive]["indices"] =
                    (accessors.len() - 1).into();
                accessors.len() - 1
            }
        };
        let a = accessors[k]
            .as_object_mut()
            .expect("a decoded accessor is an object");
        if let Some(ct) = f.indices {
            a.insert("componentType".into(), ct.into());
        }
        a.insert("bufferView".into(), views.len().into());
        a.remove("byteOffset");
        set_min_max(a, &f.bytes, f.stride);
        views.push(view);
    }
    json["bufferViews"] = Value::Array(views);
    json["accessors"] = Value::Array(accessors);
    for (i, loaded) in buffers.iter().enumerate() {
        if let Some(l) = loaded.as_ref().filter(|l| l.extended) {
            json["buffers"][i]["byteLength"] = l.bytes.len().into();
        }
    }
    for job in jobs {
        let prim = &mut json["meshes"][job.mesh]["primitives"][job.primitive];
        let Some(prim) = prim.as_object_mut() else {
            continue;
        };
        if let Some(ext) = prim.get_mut("extensions").and_then(Value::as_object_mut) {
            ext.remove(EXTENSION);
            if ext.is_empty() {
                prim.remove("extensions");
            }
        }
    }
    for key in ["extensionsUsed", "extensionsRequired"] {
        let Some(list) = json.get_mut(key).and_then(Value::as_array_mut) else {
            continue;
        };
        list.retain(|n| n.as_str() != Some(EXTENSION));
        if list.is_empty() {
            if let Some(j) = json.as_object_mut() {
                j.remove(key);
            }
        }
    }
}

/// Sets an accessor's `min`/`max`, if it has them, to its decoded values'.
fn set_min_max(a: &mut Map<String, Value>, bytes: &[u8], stride: Option<usize>) {
    if a.get("min").is_none() && a.get("max").is_none() {
        return;
    }
    let ct = a.get("componentType").and_then(Value::as_u64).unwrap_or(0);
    let Some(nc) = a.get("type").and_then(Value::as_str).and_then(components) else {
        return;
    };
    let size = component_size(ct);
    let step = stride.unwrap_or(nc * size);
    let value = |b: &[u8]| -> f64 {
        match ct {
            5120 => f64::from(b[0] as i8),
            5121 => f64::from(b[0]),
            5122 => f64::from(i16::from_le_bytes([b[0], b[1]])),
            5123 => f64::from(u16::from_le_bytes([b[0], b[1]])),
            5125 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            _ => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        }
    };
    let (mut lo, mut hi) = (vec![f64::INFINITY; nc], vec![f64::NEG_INFINITY; nc]);
    for element in bytes.chunks(step).filter(|e| e.len() >= nc * size) {
        for k in 0..nc {
            let v = value(&element[k * size..]);
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        }
    }
    if lo.iter().any(|v| !v.is_finite()) {
        return; // no elements (or not finite): left as the file had them
    }
    // Floats as the shortest decimal of their f32, integers as integers.
    let number = |v: f64| match ct {
        5126 => {
            let v = (v as f32).to_string().parse().unwrap_or(v);
            serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)
        }
        _ => Value::from(v as i64),
    };
    a.insert("min".into(), lo.into_iter().map(number).collect());
    a.insert("max".into(), hi.into_iter().map(number).collect());
}
