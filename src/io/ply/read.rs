//! Reading PLY: the body decoded into a mesh (positions, faces) and the records kept for output.

use std::borrow::Cow;
use std::fmt;
use std::sync::Arc;

use glam::DVec3;
use rayon::prelude::*;

use super::header::{
    Element, FaceRole, Field, Header, Kind, Roles, Scalar, WalkError, parse_header, walk_record,
};
use super::{Fallible, PlyEncoding, PlyLayout, ascii};
use crate::io::{Coordinates, FaceBuilder, Format, Precision, Source, bad_index};
use crate::mesh::{Buf, Mesh, Storage};
use crate::meter::Meter;

/// Where an element's records came from, to name a record's place in messages.
#[derive(Clone, Copy)]
pub(super) enum Origin {
    /// File offset of the element's first byte.
    Byte(usize),
    /// Line of the element's first record (ASCII: one record per line).
    Line(usize),
}

impl Origin {
    fn at(self, record: usize, offset: usize) -> String {
        match self {
            Origin::Byte(start) => format!("byte {}", start + offset),
            Origin::Line(first) => format!("line {}", first + record),
        }
    }
}

/// Message for record `i` of `el`, starting `offset` bytes into the element's records.
fn fail(el: &Element, i: usize, origin: Origin, offset: usize, what: impl fmt::Display) -> String {
    format!("{} {i} ({}): {what}", el.name, origin.at(i, offset))
}

fn truncated(el: &Element, i: usize, origin: Origin, offset: usize) -> String {
    let what = format!(
        "file ends inside the record (the header declares {} {} records)",
        el.count, el.name
    );
    fail(el, i, origin, offset, what)
}

fn walk_failed(el: &Element, i: usize, origin: Origin, offset: usize, e: WalkError) -> String {
    match e {
        WalkError::Truncated => truncated(el, i, origin, offset),
        WalkError::NegativeCount(n) => {
            fail(el, i, origin, offset, format!("negative list count {n}"))
        }
    }
}

/// `N` bytes at `at`; callers pass offsets inside a record they have bounds-checked.
#[inline]
fn bytes_at<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    let mut a = [0; N];
    a.copy_from_slice(&b[at..at + N]);
    a
}

/// Reads a PLY file of any encoding.
/// Why [`read_in`] failed: the file (a message without the path), or the scratch storage.
pub(crate) enum ReadError {
    Invalid(String),
    Storage(crate::error::Error),
}

impl From<String> for ReadError {
    fn from(what: String) -> Self {
        ReadError::Invalid(what)
    }
}

/// Reads a PLY file's bytes onto the heap.
pub(crate) fn read(bytes: &[u8]) -> Fallible<Mesh> {
    read_in(bytes, &Storage::heap()).map_err(|e| match e {
        ReadError::Invalid(what) => what,
        ReadError::Storage(e) => e.to_string(),
    })
}

/// Reads a PLY file's bytes, decoding positions and triangles into arrays from `storage`.
pub(crate) fn read_in(bytes: &[u8], storage: &Storage) -> Result<Mesh, ReadError> {
    read_metered(bytes, storage, &Meter::default(), Coordinates::Decode).map(|(mesh, _)| mesh)
}

/// [`read_in`], counting into `meter` where it stands in `bytes`: the header, each element as it
/// ends, and the vertices and triangles of a binary body chunk by chunk as they are decoded.
/// With [`Coordinates::Skip`] the vertex records are passed over (the mesh has no positions);
/// returns the mesh and the file's vertex count.
pub(crate) fn read_metered(
    bytes: &[u8],
    storage: &Storage,
    meter: &Meter,
    coordinates: Coordinates,
) -> Result<(Mesh, usize), ReadError> {
    let header = parse_header(bytes)?;
    meter.reach(header.body as u64);
    let body = &bytes[header.body..];
    if header.encoding != PlyEncoding::Ascii {
        check_counts(&header, body.len())?;
    }
    let roles = Roles::find(&header.elements)?;
    let mut elements = header.elements;
    let mut mesh = Decoded {
        storage,
        meter,
        coordinates,
        positions: Buf::default(),
        faces: None,
    };
    match header.encoding {
        PlyEncoding::Ascii => {
            let records = ascii::parse_body(body, header.lines + 1, &elements)?;
            let mut line = header.lines + 1;
            for (e, data) in records.into_iter().enumerate() {
                let origin = Origin::Line(line);
                mesh.take(&roles, e, &mut elements[e], Cow::Owned(data), origin)?;
                line += elements[e].count;
            }
        }
        encoding => {
            let big = encoding == PlyEncoding::BinaryBigEndian;
            let mut pos = 0;
            for (e, el) in elements.iter_mut().enumerate() {
                let rest = &body[pos..];
                let origin = Origin::Byte(header.body + pos);
                // Nothing is allocated from a count before the bytes are known to be there.
                if el
                    .count
                    .checked_mul(el.min_record())
                    .is_none_or(|n| n > rest.len())
                {
                    return Err(format!(
                        "{} (byte {}): the header declares {} records of at least {} bytes, \
                         but only {} bytes are left",
                        el.name,
                        header.body + pos,
                        el.count,
                        el.min_record(),
                        rest.len()
                    )
                    .into());
                }
                // Records of one length that are passed over need no byte swap to be measured.
                let passed_over = mesh.passes_over(&roles, e) && el.stride().is_some();
                let data = if big && !passed_over {
                    Cow::Owned(to_little_endian(rest, el, origin)?)
                } else {
                    Cow::Borrowed(rest)
                };
                pos += mesh.take(&roles, e, el, data, origin)?;
                meter.reach((header.body + pos) as u64);
            }
            let trailing = &body[pos..];
            if let Some(k) = trailing.iter().position(|b| !b.is_ascii_whitespace()) {
                return Err(format!(
                    "byte {}: {} bytes of unexpected data after the last element",
                    header.body + pos + k,
                    trailing.len() - k
                )
                .into());
            }
        }
    }
    // A `double` in any coordinate asks for double precision wherever the output has a choice.
    let vertices = elements[roles.vertex].count;
    let double = |k: usize| elements[roles.vertex].props[k].kind == Kind::Scalar(Scalar::F64);
    let precision = match roles.xyz.iter().any(|&k| double(k)) {
        true => Precision::Double,
        false => Precision::Float,
    };
    let layout = PlyLayout {
        encoding: header.encoding,
        meta: header.meta,
        elements,
    };
    let source = Source {
        format: Some(Format::Ply),
        precision,
        layout: Some(Arc::new(layout)),
        ..Source::default()
    };
    let faces = mesh.faces.unwrap_or_else(|| FaceBuilder::with_capacity(0));
    Ok((faces.into_mesh(mesh.positions, source), vertices))
}

/// A binary header whose counts need more bytes than the body has is a lie (a truncated transfer,
/// a bad exporter): say so before anything else is made of the counts, even a count too large for
/// 32-bit indices. Element offsets are exact while the elements before have fixed-size records,
/// and lower bounds after a list element.
fn check_counts(header: &Header, body: usize) -> Fallible<()> {
    let mut start = 0usize;
    let mut exact = true;
    for el in &header.elements {
        let rest = body - start;
        let need = el.count.checked_mul(el.min_record());
        if need.is_none_or(|n| n > rest) {
            let (at, left) = if exact {
                ("byte", "only")
            } else {
                ("after byte", "at most")
            };
            return Err(format!(
                "{} ({at} {}): the header declares {} records of at least {} bytes, \
                 but {left} {rest} bytes are left",
                el.name,
                header.body + start,
                el.count,
                el.min_record(),
            ));
        }
        start += need.unwrap_or(0);
        exact &= el.stride().is_some();
    }
    Ok(())
}

/// What the elements decode into.
struct Decoded<'s> {
    storage: &'s Storage,
    /// Counts the bytes of the vertices and faces as the binary decoders go.
    meter: &'s Meter,
    coordinates: Coordinates,
    positions: Buf<DVec3>,
    faces: Option<FaceBuilder>,
}

impl Decoded<'_> {
    /// Whether element `e` is the vertices a read for the triangles alone passes over.
    fn passes_over(&self, roles: &Roles, e: usize) -> bool {
        e == roles.vertex && self.coordinates == Coordinates::Skip
    }

    /// Decodes element `e` from `data` (little-endian; for a little-endian file, the rest of the
    /// body), keeps its records when the writer will need them, and returns its length in bytes.
    fn take(
        &mut self,
        roles: &Roles,
        e: usize,
        el: &mut Element,
        data: Cow<[u8]>,
        origin: Origin,
    ) -> Result<usize, ReadError> {
        if self.passes_over(roles, e) {
            // Measured, not decoded, and its records not kept: the read is for the triangles.
            return Ok(extent(&data, el, origin)?);
        }
        let len = if e == roles.vertex {
            let mut positions = self.storage.zeroed(el.count).map_err(ReadError::Storage)?;
            let len = decode_positions(&data, el, roles.xyz, origin, &mut positions, self.meter)?;
            self.positions = positions;
            len
        } else if let Some(face) = roles.face.filter(|f| f.element == e) {
            let mut faces =
                FaceBuilder::in_storage(self.storage, el.count).map_err(ReadError::Storage)?;
            let len = decode_faces(
                &data,
                el,
                face,
                roles.vertices,
                origin,
                &mut faces,
                self.meter,
            )?;
            self.faces = Some(faces);
            len
        } else if let Some(strips) = roles.strips.filter(|s| s.element == e) {
            let mut faces = FaceBuilder::with_capacity(0);
            let len = decode_strips(&data, el, strips, roles.vertices, origin, &mut faces)?;
            self.meter.add(len as u64);
            self.faces = Some(faces);
            len
        } else {
            extent(&data, el, origin)?
        };
        if !roles.rebuildable(e, el) {
            el.records = Some(match data {
                Cow::Borrowed(b) => b[..len].to_vec(),
                Cow::Owned(mut v) => {
                    v.truncate(len);
                    v
                }
            });
        }
        Ok(len)
    }
}

/// The length of an element that is only carried along.
fn extent(data: &[u8], el: &Element, origin: Origin) -> Fallible<usize> {
    if let Some(stride) = el.stride() {
        let len = el.count * stride; // no overflow: the caller checked count · min_record
        if len > data.len() {
            let i = data.len() / stride;
            return Err(truncated(el, i, origin, i * stride));
        }
        return Ok(len);
    }
    let mut fields = Vec::new();
    let mut pos = 0;
    for i in 0..el.count {
        pos = walk_record(data, pos, &el.props, false, &mut fields)
            .map_err(|e| walk_failed(el, i, origin, pos, e))?;
    }
    Ok(pos)
}

/// Copies an element's big-endian records into little-endian ones.
fn to_little_endian(data: &[u8], el: &Element, origin: Origin) -> Fallible<Vec<u8>> {
    if let Some(stride) = el.stride() {
        let len = el.count * stride; // no overflow: the caller checked count · min_record
        let Some(records) = data.get(..len) else {
            let i = data.len() / stride;
            return Err(truncated(el, i, origin, i * stride));
        };
        let mut out = records.to_vec();
        let fields: Vec<(usize, usize)> = (0..el.props.len())
            .map(|k| (el.offset(k), el.scalar(k).size()))
            .filter(|&(_, size)| size > 1)
            .collect();
        for record in out.chunks_exact_mut(stride) {
            for &(at, size) in &fields {
                record[at..at + size].reverse();
            }
        }
        return Ok(out);
    }
    let mut out = Vec::new();
    let mut fields = Vec::new();
    let mut pos = 0;
    for i in 0..el.count {
        let end = walk_record(data, pos, &el.props, true, &mut fields)
            .map_err(|e| walk_failed(el, i, origin, pos, e))?;
        let base = out.len();
        out.extend_from_slice(&data[pos..end]);
        for (p, f) in el.props.iter().zip(&fields) {
            let at = base + f.at - pos;
            match p.kind {
                Kind::Scalar(t) => out[at..at + t.size()].reverse(),
                Kind::List(c, t) => {
                    out[at..at + c.size()].reverse();
                    let items = &mut out[at + c.size()..at + c.size() + f.n * t.size()];
                    items.chunks_exact_mut(t.size()).for_each(<[u8]>::reverse);
                }
            }
        }
        pos = end;
    }
    Ok(out)
}

/// Decodes `x y z` of every vertex, rejecting NaN and infinities; returns the element's length.
/// Decodes the vertex coordinates into `positions` (one slot per record, already allocated from a
/// count the caller checked against the file size); returns the element's length in bytes.
fn decode_positions(
    data: &[u8],
    el: &Element,
    xyz: [usize; 3],
    origin: Origin,
    positions: &mut [DVec3],
    meter: &Meter,
) -> Fallible<usize> {
    let types = xyz.map(|k| el.scalar(k));
    let not_finite = |i: usize, offset: usize, p: DVec3| {
        fail(
            el,
            i,
            origin,
            offset,
            format!("coordinate is not finite ({}, {}, {})", p.x, p.y, p.z),
        )
    };
    if let Some(stride) = el.stride() {
        let len = el.count * stride;
        let Some(records) = data.get(..len) else {
            let i = data.len() / stride;
            return Err(truncated(el, i, origin, i * stride));
        };
        let at = xyz.map(|k| el.offset(k));
        let decoded = match types {
            [Scalar::F32, Scalar::F32, Scalar::F32] => decode_fixed(
                records,
                stride,
                at,
                |b: [u8; 4]| f32::from_le_bytes(b).into(),
                positions,
                meter,
            ),
            [Scalar::F64, Scalar::F64, Scalar::F64] => {
                decode_fixed(records, stride, at, f64::from_le_bytes, positions, meter)
            }
            _ => decode_any(records, stride, at, types, positions),
        };
        decoded.map_err(|(i, p)| not_finite(i, i * stride, p))?;
        return Ok(len);
    }
    let mut fields = Vec::new();
    let mut pos = 0;
    for (i, slot) in positions.iter_mut().enumerate().take(el.count) {
        let end = walk_record(data, pos, &el.props, false, &mut fields)
            .map_err(|e| walk_failed(el, i, origin, pos, e))?;
        let p = DVec3::from_array(std::array::from_fn(|c| {
            types[c].get(&data[fields[xyz[c]].at..]).unwrap_or(f64::NAN)
        }));
        if !p.is_finite() {
            return Err(not_finite(i, pos, p));
        }
        *slot = p;
        pos = end;
    }
    Ok(pos)
}

/// Vertices per parallel work item of the binary decoders.
const DECODE_CHUNK: usize = 1 << 15;

/// Fixed-stride decode of three coordinates of one type (`N` bytes each) at offsets `at`, in
/// parallel over fixed-size chunks of vertices. Returns the first non-finite position with its
/// record number (the lowest, whatever the thread count).
#[inline]
fn decode_fixed<const N: usize>(
    records: &[u8],
    stride: usize,
    at: [usize; 3],
    value: impl Fn([u8; N]) -> f64 + Sync,
    positions: &mut [DVec3],
    meter: &Meter,
) -> Result<(), (usize, DVec3)> {
    let failures: Vec<(usize, DVec3)> = positions
        .par_chunks_mut(DECODE_CHUNK)
        .zip(records.par_chunks(DECODE_CHUNK * stride))
        .enumerate()
        .filter_map(|(c, (out, records))| {
            for (i, (r, out)) in records.chunks_exact(stride).zip(out).enumerate() {
                let p = DVec3::new(
                    value(bytes_at(r, at[0])),
                    value(bytes_at(r, at[1])),
                    value(bytes_at(r, at[2])),
                );
                if !p.is_finite() {
                    return Some((c * DECODE_CHUNK + i, p));
                }
                *out = p;
            }
            meter.add(records.len() as u64);
            None
        })
        .collect();
    match failures.first() {
        Some(&f) => Err(f),
        None => Ok(()),
    }
}

/// [`decode_fixed`] for coordinates of mixed or integer types.
fn decode_any(
    records: &[u8],
    stride: usize,
    at: [usize; 3],
    types: [Scalar; 3],
    positions: &mut [DVec3],
) -> Result<(), (usize, DVec3)> {
    for (i, (r, out)) in records
        .chunks_exact(stride)
        .zip(positions.iter_mut())
        .enumerate()
    {
        let p = DVec3::from_array(std::array::from_fn(|c| {
            types[c].get(&r[at[c]..]).unwrap_or(f64::NAN)
        }));
        if !p.is_finite() {
            return Err((i, p));
        }
        *out = p;
    }
    Ok(())
}

/// Decodes the faces, validating every index against the `vertices` count; returns the element's
/// length in bytes.
pub(super) fn decode_faces(
    data: &[u8],
    el: &Element,
    face: FaceRole,
    vertices: u32,
    origin: Origin,
    faces: &mut FaceBuilder,
    meter: &Meter,
) -> Fallible<usize> {
    match (el.props.len(), face.count, face.index) {
        (1, Scalar::U8, Scalar::I32) => {
            faces_u8_32(data, el, vertices, origin, faces, meter, |b| {
                i32::from_le_bytes(b).into()
            })
        }
        (1, Scalar::U8, Scalar::U32) => {
            faces_u8_32(data, el, vertices, origin, faces, meter, |b| {
                u32::from_le_bytes(b).into()
            })
        }
        _ => faces_any(data, el, face, vertices, origin, faces),
    }
}

fn too_few(n: usize) -> String {
    format!("face has {n} vertices, at least 3 are needed")
}

/// The fast path: faces of only `list uchar int|uint` — one pass that decodes, validates and
/// fan-triangulates.
#[inline]
fn faces_u8_32(
    data: &[u8],
    el: &Element,
    vertices: u32,
    origin: Origin,
    faces: &mut FaceBuilder,
    meter: &Meter,
    index: impl Fn([u8; 4]) -> i64 + Sync,
) -> Fallible<usize> {
    let valid = |v: i64| (0..i64::from(vertices)).contains(&v);
    // The common case first: every face a triangle with valid indices, 13-byte records decoded in
    // parallel. Anything else (a polygon, a bad index, a short body) is left to the sequential
    // loop below, which finds and reports the first problem exactly as it always has.
    let len = el.count.checked_mul(13);
    if let Some(body) = len.and_then(|len| data.get(..len)) {
        let parallel = faces.fill_triangles(el.count, |out| {
            out.par_chunks_mut(DECODE_CHUNK)
                .zip(body.par_chunks(DECODE_CHUNK * 13))
                .all(|(out, records)| {
                    let fine = records.chunks_exact(13).zip(out).all(|(r, t)| {
                        let v = [1, 5, 9].map(|at| index(bytes_at(r, at)));
                        *t = v.map(|v| v as u32);
                        r[0] == 3 && v.iter().all(|&v| valid(v))
                    });
                    // At most the element's bytes: the caller's count at its end only reaches.
                    meter.add(records.len() as u64);
                    fine
                })
        });
        if parallel {
            return Ok(body.len());
        }
    }
    let mut corners = Vec::new();
    let mut pos = 0;
    for i in 0..el.count {
        let Some(&n) = data.get(pos) else {
            return Err(truncated(el, i, origin, pos));
        };
        let n = usize::from(n);
        let Some(items) = data.get(pos + 1..pos + 1 + 4 * n) else {
            return Err(truncated(el, i, origin, pos));
        };
        if n == 3 {
            let t = [0, 4, 8].map(|at| index(bytes_at(items, at)));
            if let Some(&v) = t.iter().find(|&&v| !valid(v)) {
                return Err(fail(el, i, origin, pos, bad_index(v, vertices as usize)));
            }
            faces.triangle(t.map(|v| v as u32));
        } else {
            if n < 3 {
                return Err(fail(el, i, origin, pos, too_few(n)));
            }
            corners.clear();
            for c in items.chunks_exact(4) {
                let v = index(bytes_at(c, 0));
                if !valid(v) {
                    return Err(fail(el, i, origin, pos, bad_index(v, vertices as usize)));
                }
                corners.push(v as u32);
            }
            faces.polygon(&corners);
        }
        pos += 1 + 4 * n;
    }
    Ok(pos)
}

/// Faces of any layout: other properties around the list, any count and index types.
fn faces_any(
    data: &[u8],
    el: &Element,
    face: FaceRole,
    vertices: u32,
    origin: Origin,
    faces: &mut FaceBuilder,
) -> Fallible<usize> {
    let mut corners = Vec::new();
    each_index_list(data, el, face, origin, |i, pos, ids| {
        if ids.len() < 3 {
            return Err(fail(el, i, origin, pos, too_few(ids.len())));
        }
        corners.clear();
        for v in ids {
            if !(0..i64::from(vertices)).contains(&v) {
                return Err(fail(el, i, origin, pos, bad_index(v, vertices as usize)));
            }
            corners.push(v as u32);
        }
        faces.polygon(&corners);
        Ok(())
    })
}

/// Walks the records of `el` (any layout), handing `each` a record's number, its start and the
/// ids of `role`'s list; returns the element's length in bytes.
fn each_index_list(
    data: &[u8],
    el: &Element,
    role: FaceRole,
    origin: Origin,
    mut each: impl FnMut(usize, usize, &mut dyn ExactSizeIterator<Item = i64>) -> Fallible<()>,
) -> Fallible<usize> {
    let FaceRole {
        list,
        count,
        index: item,
        ..
    } = role;
    let mut fields = Vec::new();
    let mut pos = 0;
    for i in 0..el.count {
        let end = walk_record(data, pos, &el.props, false, &mut fields)
            .map_err(|e| walk_failed(el, i, origin, pos, e))?;
        let Field { at, n } = fields[list];
        // In bounds: `walk_record` checked the list; an integer type converts exactly.
        let mut ids = (0..n).map(|k| {
            item.get(&data[at + count.size() + k * item.size()..])
                .unwrap_or(-2.0) as i64
        });
        each(i, pos, &mut ids)?;
        pos = end;
    }
    Ok(pos)
}

/// Decodes triangle strips into triangles, validating every id against the `vertices` count;
/// returns the element's length in bytes. In a strip `v0 v1 v2 v3 …` triangle `k` is
/// `(vk, vk+1, vk+2)`, every second one turned (`(vk+1, vk, vk+2)`) so that all keep one
/// orientation; `-1` ends a strip and starts the next. Triangles with a repeated vertex only join
/// strips together and are left out, as MeshLab leaves them out.
pub(super) fn decode_strips(
    data: &[u8],
    el: &Element,
    strips: FaceRole,
    vertices: u32,
    origin: Origin,
    faces: &mut FaceBuilder,
) -> Fallible<usize> {
    each_index_list(data, el, strips, origin, |i, pos, ids| {
        // The last two ids of the strip so far, and its length.
        let (mut a, mut b, mut run) = (0u32, 0u32, 0usize);
        for v in ids {
            if v == -1 {
                run = 0;
                continue;
            }
            if !(0..i64::from(vertices)).contains(&v) {
                return Err(fail(el, i, origin, pos, bad_index(v, vertices as usize)));
            }
            let c = v as u32;
            if run >= 2 && a != b && b != c && a != c {
                faces.triangle(if run % 2 == 0 { [a, b, c] } else { [b, a, c] });
            }
            (a, b, run) = (b, c, run + 1);
        }
        Ok(())
    })
}
