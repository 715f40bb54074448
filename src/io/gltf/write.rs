//! Writing glTF: new positions and normals into the input's buffers, the names of the buffer files
//! beside the output, and GLB framing.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::uri::{base64_encode, percent_decode, percent_encode};
use super::{CHUNK_BIN, CHUNK_JSON, GltfLayout, Origin, array, has_magic};
use crate::error::{Error, Result};
use crate::mesh::{Format, Mesh};

fn write_vec3(bytes: &mut [u8], at: usize, v: [f32; 3]) {
    for (k, c) in v.iter().enumerate() {
        bytes[at + 4 * k..at + 4 * k + 4].copy_from_slice(&c.to_le_bytes());
    }
}

/// The layout a mesh read from glTF carries, if any.
fn layout_of(mesh: &Mesh) -> Option<&GltfLayout> {
    GltfLayout::of(&mesh.source)
}

/// Whether `mesh` (already checked by `io::check_mesh`) can be written as `format`: a glTF input
/// to its own kind, any other mesh with at least one triangle as a plain glTF
/// ([`GltfLayout::plain`]).
pub(crate) fn check_writable(mesh: &Mesh, format: Format) -> std::result::Result<(), String> {
    let Some(layout) = layout_of(mesh) else {
        if mesh.triangles.is_empty() {
            return Err("a glTF primitive needs at least one triangle".into());
        }
        return crate::io::fits_single(mesh);
    };
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
    crate::io::fits_single(mesh)
}

/// Writes `mesh` (checked by [`check_writable`]) to `path`, with its changed external buffers
/// beside it, each atomically. Every file is complete on disk before any is renamed into place
/// (buffers first, so the glTF never names a missing file): a failure while writing leaves no
/// new file and changes none.
///
/// With `colours`, every primitive drawn from the mesh's positions gets them as its `COLOR_0`
/// (normalized `u8` RGBA, opaque; one accessor per positions accessor, in a view appended to the
/// first positions buffer), replacing any it had.
pub(crate) fn write(
    path: &Path,
    mesh: &Mesh,
    colours: Option<&(dyn Fn(usize) -> [u8; 3] + Sync + '_)>,
) -> Result<()> {
    let plain;
    let layout = match layout_of(mesh) {
        Some(layout) => layout,
        None => {
            plain = GltfLayout::plain(mesh, Format::from_extension(path) == Some(Format::Glb));
            &plain
        }
    };
    let mut json = layout.json.clone();
    let mut buffers: Vec<Option<Vec<u8>>> = layout
        .buffers
        .iter()
        .map(|b| b.as_ref().map(|b| b.bytes.clone()))
        .collect();
    // Buffers holding decoded Draco data are new bytes, whatever else changed.
    let mut changed: Vec<bool> = layout
        .buffers
        .iter()
        .map(|b| b.as_ref().is_some_and(|b| b.extended))
        .collect();
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
        let normals = crate::io::vertex_normals(&mesh.positions, &mesh.triangles);
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
    if let (Some(colour), Some(&(first, _))) = (colours, layout.positions.first()) {
        let bytes = buffers[first.buffer].as_mut().expect("a loaded buffer");
        append_colours(&mut json, bytes, first.buffer, &layout.positions, colour);
        changed[first.buffer] = true;
    }
    let mut chunk = None;
    let mut staged = Vec::new();
    let mut chosen = Vec::new();
    // Buffers go beside the file the output's links lead to, where its relative URIs point.
    let beside = match crate::io::atomic::destination(path) {
        Ok(crate::io::atomic::Destination::Replace(real)) => real,
        _ => path.to_path_buf(),
    };
    for (i, loaded) in layout.buffers.iter().enumerate() {
        let (Some(loaded), true) = (loaded, changed[i]) else {
            continue;
        };
        let bytes = buffers[i].take().expect("a loaded buffer");
        match &loaded.origin {
            Origin::Chunk => chunk = Some(bytes),
            Origin::New if layout.binary => chunk = Some(bytes),
            Origin::Data(head) => {
                json["buffers"][i]["uri"] =
                    Value::String(format!("{head},{}", base64_encode(&bytes)));
            }
            Origin::File(_) | Origin::New => {
                let bin = bin_path(&beside, &chosen, layout);
                staged.push(crate::io::atomic::stage(&bin, |out| out.write_all(&bytes))?);
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
        crate::io::atomic::stage(path, |out| write_glb(out, &text, chunk.as_deref()))?
    } else {
        crate::io::atomic::stage(path, |out| out.write_all(&text))?
    };
    for bin in staged {
        bin.commit()?;
    }
    gltf.commit()
}

/// Appends to `bytes` (buffer `buffer`) one view of RGBA colours for every positions accessor in
/// `positions` (with the mesh vertex its first element is), one accessor each, and points each
/// primitive's `COLOR_0` at the accessor of its `POSITION`. The buffer's `byteLength` follows.
fn append_colours(
    json: &mut Value,
    bytes: &mut Vec<u8>,
    buffer: usize,
    positions: &[(super::Span, usize)],
    colour: &(dyn Fn(usize) -> [u8; 3] + Sync + '_),
) {
    bytes.resize(bytes.len().next_multiple_of(4), 0);
    let start = bytes.len();
    let mut accessors: Vec<(usize, usize, usize)> = Vec::new();
    for &(span, base) in positions {
        if accessors.iter().any(|a| a.0 == span.accessor) {
            continue;
        }
        let at = bytes.len() - start;
        for i in 0..span.count {
            let [r, g, b] = colour(base + i);
            bytes.extend_from_slice(&[r, g, b, 255]);
        }
        accessors.push((span.accessor, at, span.count));
    }
    let view = array(json, "bufferViews").len();
    let length = bytes.len() - start;
    json["bufferViews"] = Value::Array(
        array(json, "bufferViews")
            .iter()
            .cloned()
            .chain([serde_json::json!({
                "buffer": buffer, "byteOffset": start, "byteLength": length, "byteStride": 4,
                "target": 34962,
            })])
            .collect(),
    );
    let mut list: Vec<Value> = array(json, "accessors").to_vec();
    let mut colour_of = std::collections::HashMap::new();
    for (position, at, count) in accessors {
        colour_of.insert(position, list.len());
        list.push(serde_json::json!({
            "bufferView": view, "byteOffset": at, "componentType": 5121,
            "normalized": true, "count": count, "type": "VEC4",
        }));
    }
    json["accessors"] = Value::Array(list);
    json["buffers"][buffer]["byteLength"] = bytes.len().into();
    if let Some(meshes) = json.get_mut("meshes").and_then(Value::as_array_mut) {
        for primitive in meshes
            .iter_mut()
            .filter_map(|m| m.get_mut("primitives").and_then(Value::as_array_mut))
            .flatten()
        {
            let position = primitive["attributes"]["POSITION"].as_u64();
            if let Some(&c) = position.and_then(|p| colour_of.get(&(p as usize))) {
                primitive["attributes"]["COLOR_0"] = c.into();
            }
        }
    }
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
    // Compared as the files they are: a candidate that is a link to an input's buffer (an
    // earlier output's buffer replaced by one) would be written through onto the input.
    let real = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| canonical(p));
    let inputs: Vec<PathBuf> = inputs.iter().map(|p| real(p)).collect();
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
        let taken = inputs.contains(&real(&candidate))
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
        // Only a regular file: opening a pipe would wait for a writer, or take its first bytes.
        if !std::fs::metadata(path).ok()?.is_file() {
            return None;
        }
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
        serde_json::from_slice(crate::io::without_bom(&bytes)).ok()
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

impl GltfLayout {
    /// A glTF of `mesh` alone, for a mesh that was not read from glTF: one node of one mesh of one
    /// triangle primitive, float `POSITION` and `NORMAL` (filled by [`write`]) and `u32` indices in
    /// one buffer, the GLB's binary chunk (`binary`) or a `.bin` beside the `.gltf`; and the
    /// per-vertex colours (float `COLOR_0`) and texture coordinates (`TEXCOORD_0`, turned to
    /// glTF's top-left origin) of its file when it had them ([`crate::mesh::FileLayout`]).
    pub(super) fn plain(mesh: &Mesh, binary: bool) -> GltfLayout {
        let (n, t) = (mesh.positions.len(), mesh.triangles.len());
        let mut bytes = vec![0u8; 24 * n];
        bytes.reserve(12 * t);
        for tri in mesh.triangles.iter() {
            tri.iter()
                .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
        }
        let view = |offset: usize, length: usize, target: u32| serde_json::json!({"buffer": 0, "byteOffset": offset, "byteLength": length, "target": target});
        let vec3 = |view: usize| serde_json::json!({"bufferView": view, "componentType": super::FLOAT, "count": n, "type": "VEC3"});
        let mut json = serde_json::json!({
            "asset": {"version": "2.0", "generator": concat!("vcsmooth ", env!("CARGO_PKG_VERSION"))},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "mode": 4}]}],
            "accessors": [
                vec3(0),
                vec3(1),
                {"bufferView": 2, "componentType": 5125, "count": 3 * t, "type": "SCALAR"},
            ],
            "bufferViews": [
                view(0, 12 * n, 34962),
                view(12 * n, 12 * n, 34962),
                view(24 * n, 12 * t, 34963),
            ],
            // Its byteLength once every view is in.
            "buffers": [{}],
        });
        let file = mesh.source.layout.as_deref();
        let mut add = |json: &mut Value, name: &str, kind: &str, values: Vec<f32>| {
            let offset = bytes.len();
            values
                .iter()
                .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
            let views = json["bufferViews"].as_array_mut().expect("an array");
            views.push(view(offset, 4 * values.len(), 34962));
            let at = views.len() - 1;
            let accessors = json["accessors"].as_array_mut().expect("an array");
            accessors.push(serde_json::json!(
                {"bufferView": at, "componentType": super::FLOAT, "count": n, "type": kind}
            ));
            json["meshes"][0]["primitives"][0]["attributes"][name] = (accessors.len() - 1).into();
        };
        if let Some(colours) = file
            .and_then(|f| f.vertex_colours())
            .filter(|c| c.len() == n)
        {
            add(&mut json, "COLOR_0", "VEC3", colours.concat());
        }
        if let Some(uvs) = file.and_then(|f| f.vertex_uvs()).filter(|u| u.len() == n) {
            let flipped: Vec<f32> = uvs.iter().flat_map(|&[u, v]| [u, 1.0 - v]).collect();
            add(&mut json, "TEXCOORD_0", "VEC2", flipped);
        }
        json["buffers"][0]["byteLength"] = bytes.len().into();
        let span = |accessor: usize| super::Span {
            accessor,
            buffer: 0,
            offset: 12 * n * accessor,
            stride: 12,
            count: n,
        };
        GltfLayout {
            json,
            binary,
            buffers: vec![Some(super::Loaded {
                bytes,
                origin: Origin::New,
                extended: true,
            })],
            positions: vec![(span(0), 0)],
            normals: vec![(span(1), 0)],
            vertices: n,
            triangles: t,
            carried: Default::default(),
            dir: None,
            decompressed: false,
        }
    }
}
