//! Writing PLY: the plain layout and its record encoders, the checks and the writer.

use std::borrow::Cow;
use std::io::{self, Write};
use std::ops::Range;

use glam::DVec3;
use rayon::prelude::*;

use super::header::{Element, FaceRole, Kind, Property, Roles, Scalar, walk_record};
use super::read::{Origin, decode_faces, decode_strips};
use super::{Fallible, PlyEncoding, PlyLayout, ascii};
use crate::io::{
    FaceBuilder, Faces, Precision, VertexValues, first_where, vertex_normals, write_encoded,
};
use crate::mesh::Mesh;
use crate::meter::Meter;

/// The record types of the plain layout (a mesh without a PLY source, and the streamed output of
/// `io::stream`): `x y z` of one floating-point type, then `list <count> <index> vertex_indices`.
/// Its encoders, [`put_xyz`] and [`put_face`], are the ones every binary PLY writer uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PlainRecords {
    pub(crate) coordinate: Scalar,
    pub(crate) count: Scalar,
    pub(crate) index: Scalar,
}

impl PlainRecords {
    /// The types for `vertices` vertices and faces of at most `max_corners` corners: `float` or
    /// `double` as `precision` says, the smallest count type that holds `max_corners` (`uchar`
    /// for triangles), `int` indices (`uint` beyond `i32::MAX` vertices).
    pub(crate) fn new(vertices: usize, max_corners: usize, precision: Precision) -> Self {
        let coordinate = match precision {
            Precision::Float => Scalar::F32,
            Precision::Double => Scalar::F64,
        };
        let count = [Scalar::U8, Scalar::U16, Scalar::U32]
            .into_iter()
            .find(|t| t.holds(max_corners as f64))
            .unwrap_or(Scalar::U32);
        let index = if vertices <= i32::MAX as usize {
            Scalar::I32
        } else {
            Scalar::U32
        };
        PlainRecords {
            coordinate,
            count,
            index,
        }
    }

    /// The binary little-endian header model of `vertices` vertices and `faces` faces, with the
    /// header lines `meta` (each a whole `comment …` or `obj_info …` line).
    pub(crate) fn layout(self, vertices: usize, faces: usize, meta: Vec<String>) -> PlyLayout {
        let prop = |name: &str, kind| Property {
            name: name.into(),
            kind,
        };
        PlyLayout {
            encoding: PlyEncoding::BinaryLittleEndian,
            meta,
            elements: vec![
                Element {
                    name: "vertex".into(),
                    count: vertices,
                    props: ["x", "y", "z"]
                        .map(|n| prop(n, Kind::Scalar(self.coordinate)))
                        .into(),
                    records: None,
                },
                Element {
                    name: "face".into(),
                    count: faces,
                    props: vec![prop("vertex_indices", Kind::List(self.count, self.index))],
                    records: None,
                },
            ],
        }
    }
}

/// Appends the binary record of `x y z`, each of type `coordinate` (floats round to nearest).
#[inline]
pub(crate) fn put_xyz(coordinate: Scalar, p: DVec3, buf: &mut Vec<u8>) {
    match coordinate {
        Scalar::F32 => {
            for x in [p.x, p.y, p.z] {
                buf.extend_from_slice(&(x as f32).to_le_bytes());
            }
        }
        Scalar::F64 => {
            for x in [p.x, p.y, p.z] {
                buf.extend_from_slice(&x.to_le_bytes());
            }
        }
        t => {
            let (at, size) = (buf.len(), t.size());
            buf.resize(at + 3 * size, 0);
            for (c, x) in [p.x, p.y, p.z].into_iter().enumerate() {
                t.put(x, &mut buf[at + c * size..]);
            }
        }
    }
}

/// Appends the binary record of a face, `list <count> <index>`: its corner count, then its
/// vertex ids (writers check that the types hold them first).
#[inline]
pub(crate) fn put_face(count: Scalar, index: Scalar, corners: &[u32], buf: &mut Vec<u8>) {
    if (count, index) == (Scalar::U8, Scalar::I32) {
        buf.push(corners.len() as u8);
        for &v in corners {
            buf.extend_from_slice(&(v as i32).to_le_bytes());
        }
    } else {
        let at = buf.len();
        buf.resize(at + count.size() + corners.len() * index.size(), 0);
        count.put(corners.len() as f64, &mut buf[at..]);
        for (k, &v) in corners.iter().enumerate() {
            index.put(v.into(), &mut buf[at + count.size() + k * index.size()..]);
        }
    }
}

/// The layout a PLY output follows: the source's, or the plain one.
fn layout_of(mesh: &Mesh) -> Cow<'_, PlyLayout> {
    let own = mesh.source.layout.as_deref();
    match own.and_then(|l| l.as_any().downcast_ref::<PlyLayout>()) {
        Some(layout) => Cow::Borrowed(layout),
        None => Cow::Owned(PlyLayout::plain(mesh)),
    }
}

/// The types a PLY output stores `x y z` in, those of [`layout_of`]; `None` when the layout has
/// no usable vertex element (the writer refuses such a mesh).
pub(crate) fn coordinate_types(mesh: &Mesh) -> Option<[Scalar; 3]> {
    let own = mesh.source.layout.as_deref();
    let Some(layout) = own.and_then(|l| l.as_any().downcast_ref::<PlyLayout>()) else {
        // The plain layout's, without building it.
        return Some([PlainRecords::new(0, 3, mesh.source.precision).coordinate; 3]);
    };
    let roles = Roles::find(&layout.elements).ok()?;
    let vertex = &layout.elements[roles.vertex];
    Some(roles.xyz.map(|k| vertex.scalar(k)))
}

/// Whether `mesh` (already checked by `io::check_mesh`) can be written as PLY.
pub(crate) fn check_writable(mesh: &Mesh) -> Fallible<()> {
    let layout = layout_of(mesh);
    let roles = Roles::find(&layout.elements)?;
    let vertex = &layout.elements[roles.vertex];
    if vertex.count != mesh.positions.len() {
        return Err(format!(
            "the mesh has {} vertices but its PLY source has {}; clear mesh.source.layout after \
             adding or removing vertices",
            mesh.positions.len(),
            vertex.count
        ));
    }
    for (c, &k) in roles.xyz.iter().enumerate() {
        let t = vertex.scalar(k);
        if let Some(i) = first_where(&mesh.positions, |p| !t.holds(p[c])) {
            let (v, name) = (mesh.positions[i][c], &vertex.props[k].name);
            return Err(format!(
                "vertex {i}: coordinate {v} does not fit PLY property '{name}' ({})",
                t.name()
            ));
        }
    }
    // Kept records (strips always, faces with other properties) are written as they are: they
    // must still decode to the mesh's triangles.
    let unchanged = |what: &str, capacity, decode: &dyn Fn(&mut FaceBuilder) -> Fallible<usize>| {
        let mut faces = FaceBuilder::with_capacity(capacity);
        match decode(&mut faces).is_ok_and(|_| faces.triangles() == &mesh.triangles[..]) {
            true => Ok(()),
            false => Err(format!(
                "the triangles no longer match the PLY source's {what}; clear \
                 mesh.source.layout after changing connectivity"
            )),
        }
    };
    if let Some(strips) = roles.strips {
        let el = &layout.elements[strips.element];
        return unchanged("triangle strips", 0, &|faces| match el.records.as_deref() {
            Some(records) => {
                decode_strips(records, el, strips, roles.vertices, Origin::Byte(0), faces)
            }
            None => Err("no records".into()),
        });
    }
    let Some(face) = roles.face else {
        if !mesh.triangles.is_empty() {
            return Err("the mesh has triangles but its PLY source has no face element".into());
        }
        return Ok(());
    };
    let el = &layout.elements[face.element];
    if let Some(records) = &el.records {
        return unchanged("faces", el.count, &|faces| {
            let meter = Meter::default();
            decode_faces(
                records,
                el,
                face,
                roles.vertices,
                Origin::Byte(0),
                faces,
                &meter,
            )
        });
    }
    let faces = Faces::of(mesh);
    faces.check()?;
    let FaceRole { count, index, .. } = face;
    if !count.holds(faces.max_corners() as f64) {
        return Err(format!(
            "a face has {} corners, more than a PLY {} count holds",
            faces.max_corners(),
            count.name()
        ));
    }
    // The indices the faces use, not the vertex count: a `uchar` list may index the first 256
    // vertices of many.
    let largest = mesh
        .triangles
        .par_chunks(1 << 16)
        .filter_map(|chunk| chunk.iter().flatten().max())
        .max();
    if let Some(&v) = largest.filter(|&&v| !index.holds(v as f64)) {
        return Err(format!(
            "vertex index {v} does not fit the PLY index type {}",
            index.name()
        ));
    }
    Ok(())
}

/// Writes `mesh` as PLY, with `values` in its vertices when given; [`check_writable`] passed.
pub(crate) fn write(
    out: &mut impl Write,
    mesh: &Mesh,
    values: Option<&VertexValues>,
) -> io::Result<()> {
    let layout = layout_of(mesh);
    let roles = Roles::find(&layout.elements).map_err(io::Error::other)?;
    // The face element to rebuild from the mesh, unless its records are stored.
    let face = roles
        .face
        .filter(|f| layout.elements[f.element].records.is_none());
    let faces = Faces::of(mesh);
    let ascii = layout.encoding == PlyEncoding::Ascii;
    let props = values.map(|v| output_properties(&layout.elements[roles.vertex], v));

    write_header(
        out,
        &layout,
        |e, el| match face {
            Some(f) if f.element == e => faces.len(),
            _ => el.count,
        },
        props.as_deref().map(|p| (roles.vertex, p)),
    )?;
    for (e, el) in layout.elements.iter().enumerate() {
        if e == roles.vertex {
            match (values, &props) {
                (Some(v), Some(props)) => write_vertices_with(out, el, props, mesh, v, ascii)?,
                _ => write_vertices(out, el, mesh, ascii)?,
            }
        } else if let Some(f) = face.filter(|f| f.element == e) {
            write_faces(out, el, f, &faces, ascii)?;
        } else if let Some(records) = &el.records {
            emit(out, &el.props, records, ascii)?;
        }
    }
    Ok(())
}

/// The name of the vertex property that holds a [`VertexValues`] scalar.
const QUALITY: &str = "quality";
/// The names of the colour properties.
const COLOURS: [&str; 3] = ["red", "green", "blue"];

/// The vertex properties written with `values`: `el`'s own, then `float quality` and `uchar red
/// green blue` (with colours), each unless `el` has it already (then it takes the values in its
/// place: a `quality` of an integer type becomes `float`, which holds the field).
fn output_properties(el: &Element, values: &VertexValues) -> Vec<Property> {
    let mut added: Vec<Property> = el
        .props
        .iter()
        .map(|p| match p.kind {
            Kind::Scalar(t) if p.name == QUALITY && t.int_range().is_some() => Property {
                name: p.name.clone(),
                kind: Kind::Scalar(Scalar::F32),
            },
            _ => p.clone(),
        })
        .collect();
    let mut add = |name: &str, t: Scalar| {
        if el.prop(name).is_none() {
            added.push(Property {
                name: name.into(),
                kind: Kind::Scalar(t),
            });
        }
    };
    add(QUALITY, Scalar::F32);
    if values.colours.is_some() {
        COLOURS.iter().for_each(|c| add(c, Scalar::U8));
    }
    added
}

/// Writes the header of `layout` (big-endian is written as little-endian), with `count(e, el)`
/// records for element `e` and, when `props` is `Some((e, list))`, the properties `list` for
/// element `e` instead of its own; every PLY writer's header.
pub(crate) fn write_header(
    out: &mut impl Write,
    layout: &PlyLayout,
    count: impl Fn(usize, &Element) -> usize,
    props: Option<(usize, &[Property])>,
) -> io::Result<()> {
    out.write_all(b"ply\n")?;
    let encoding = match layout.encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian | PlyEncoding::BinaryBigEndian => "binary_little_endian",
    };
    writeln!(out, "format {encoding} 1.0")?;
    for line in &layout.meta {
        writeln!(out, "{line}")?;
    }
    for (e, el) in layout.elements.iter().enumerate() {
        writeln!(out, "element {} {}", el.name, count(e, el))?;
        let list = match props {
            Some((k, list)) if k == e => list,
            _ => &el.props,
        };
        for p in list {
            match p.kind {
                Kind::Scalar(t) => writeln!(out, "property {} {}", t.name(), p.name)?,
                Kind::List(c, t) => {
                    writeln!(out, "property list {} {} {}", c.name(), t.name(), p.name)?
                }
            }
        }
    }
    out.write_all(b"end_header\n")
}

/// Writes little-endian records as they are, or as ASCII lines.
fn emit(out: &mut impl Write, props: &[Property], records: &[u8], ascii: bool) -> io::Result<()> {
    if ascii {
        ascii::write_records(out, props, records)
    } else {
        out.write_all(records)
    }
}

/// What a vertex property is rebuilt from.
#[derive(Clone, Copy, PartialEq)]
enum Value {
    Coordinate(usize),
    Normal(usize),
}

/// Writes the vertex records: the stored ones with `x y z` (and normals) replaced, or records
/// built from scratch.
fn write_vertices(out: &mut impl Write, el: &Element, mesh: &Mesh, ascii: bool) -> io::Result<()> {
    let targets: Vec<(usize, Scalar, Value)> = el
        .props
        .iter()
        .enumerate()
        .filter_map(|(k, p)| {
            let value = match p.name.as_str() {
                "x" => Value::Coordinate(0),
                "y" => Value::Coordinate(1),
                "z" => Value::Coordinate(2),
                "nx" => Value::Normal(0),
                "ny" => Value::Normal(1),
                "nz" => Value::Normal(2),
                _ => return None,
            };
            match p.kind {
                Kind::Scalar(t) => Some((k, t, value)),
                Kind::List(..) => None,
            }
        })
        .collect();
    let normals = if targets.iter().any(|t| matches!(t.2, Value::Normal(_))) {
        vertex_normals(&mesh.positions, &mesh.triangles)
    } else {
        Vec::new()
    };
    let value = |i: usize, t: Scalar, v: Value| match v {
        Value::Coordinate(c) => mesh.positions[i][c],
        Value::Normal(c) => t.unit_component(normals[i][c]),
    };

    let Some(stride) = el.stride() else {
        // Lists in the vertex element: rare enough for one walk over a copy of the records.
        let records = el.records.as_deref().unwrap_or_default();
        let mut patched = records.to_vec();
        let mut fields = Vec::new();
        let mut pos = 0;
        for i in 0..mesh.positions.len() {
            pos = walk_record(records, pos, &el.props, false, &mut fields)
                .map_err(|_| io::Error::other("stored PLY vertex records are corrupt"))?;
            for &(k, t, v) in &targets {
                t.put(value(i, t, v), &mut patched[fields[k].at..]);
            }
        }
        return emit(out, &el.props, &patched, ascii);
    };
    let targets: Vec<(usize, Scalar, Value)> = targets
        .iter()
        .map(|&(k, t, v)| (el.offset(k), t, v))
        .collect();
    // The plain layout, `x y z` of one floating-point type and nothing else: encode straight
    // from the positions.
    let plain = match &el.props[..] {
        [x, y, z] if [&x.name, &y.name, &z.name] == ["x", "y", "z"] => {
            match [x, y, z].map(|p| p.kind) {
                [Kind::Scalar(t), Kind::Scalar(u), Kind::Scalar(v)]
                    if t == u && u == v && matches!(t, Scalar::F32 | Scalar::F64) =>
                {
                    Some(t)
                }
                _ => None,
            }
        }
        _ => None,
    };
    if let (false, None, Some(coordinate)) = (ascii, &el.records, plain) {
        return write_encoded(out, mesh.positions.len(), stride, |range, buf| {
            for p in &mesh.positions[range] {
                put_xyz(coordinate, *p, buf);
            }
            Ok(())
        });
    }
    let encode = |range: Range<usize>, buf: &mut Vec<u8>| {
        let (start, end) = (range.start, range.end);
        match &el.records {
            Some(records) => buf.extend_from_slice(&records[start * stride..end * stride]),
            None => buf.resize((end - start) * stride, 0),
        }
        for (record, i) in buf.chunks_exact_mut(stride).zip(start..) {
            for &(at, t, v) in &targets {
                t.put(value(i, t, v), &mut record[at..]);
            }
        }
        Ok(())
    };
    match ascii {
        // Text goes through `emit` record by record, sequentially.
        true => {
            let mut buf = Vec::with_capacity(PIECE * stride);
            for start in (0..mesh.positions.len()).step_by(PIECE) {
                buf.clear();
                encode(start..(start + PIECE).min(mesh.positions.len()), &mut buf)?;
                emit(out, &el.props, &buf, ascii)?;
            }
            Ok(())
        }
        false => write_encoded(out, mesh.positions.len(), stride, encode),
    }
}

/// Records per buffer of the sequential text writer.
const PIECE: usize = 1 << 14;

/// What a vertex property written with [`VertexValues`] is rebuilt from.
#[derive(Clone, Copy, PartialEq)]
enum Role {
    Coordinate(usize),
    Normal(usize),
    Quality,
    Colour(usize),
}

impl Role {
    fn of(name: &str, colours: bool) -> Option<Role> {
        Some(match name {
            "x" => Role::Coordinate(0),
            "y" => Role::Coordinate(1),
            "z" => Role::Coordinate(2),
            "nx" => Role::Normal(0),
            "ny" => Role::Normal(1),
            "nz" => Role::Normal(2),
            QUALITY => Role::Quality,
            _ if colours => Role::Colour(COLOURS.iter().position(|c| *c == name)?),
            _ => return None,
        })
    }
}

/// [`write_vertices`] with `values`, the vertex element's properties written as `props`
/// ([`output_properties`]): each record as it would be without them, its `quality` and colour
/// properties (when it has them) replaced, then the added properties appended.
fn write_vertices_with(
    out: &mut impl Write,
    el: &Element,
    props: &[Property],
    mesh: &Mesh,
    values: &VertexValues,
    ascii: bool,
) -> io::Result<()> {
    let own = el.props.len();
    let retyped = el.props.iter().zip(props).any(|(a, b)| a.kind != b.kind);
    // (property, type, role) of every scalar property rebuilt here.
    let targets: Vec<(usize, Scalar, Role)> = props
        .iter()
        .enumerate()
        .filter_map(|(k, p)| match p.kind {
            Kind::Scalar(t) => Some((k, t, Role::of(&p.name, values.colours.is_some())?)),
            Kind::List(..) => None,
        })
        .collect();
    let normals = match targets.iter().any(|t| matches!(t.2, Role::Normal(_))) {
        true => vertex_normals(&mesh.positions, &mesh.triangles),
        false => Vec::new(),
    };
    let put = |record: &mut [u8], at: &dyn Fn(usize) -> usize, i: usize| {
        let mut colour = None;
        for &(k, t, role) in &targets {
            let v = match role {
                Role::Coordinate(c) => mesh.positions[i][c],
                Role::Normal(c) => t.unit_component(normals[i][c]),
                Role::Quality => values.quality[i],
                Role::Colour(c) => {
                    let rgb = *colour.get_or_insert_with(|| values.colours.map(|f| f(i)));
                    f64::from(rgb.map_or(0, |rgb| rgb[c]))
                }
            };
            t.put(v, &mut record[at(k)..]);
        }
    };
    let extra: usize = props[own..].iter().map(|p| scalar_of(p).size()).sum();
    const FLUSH: usize = 1 << 20; // bytes per buffer
    let mut buf = Vec::with_capacity(FLUSH + 1024);
    let stored = el.records.as_deref();
    // The plain layout (then `props` is it, `float quality` and with colours `uchar red green
    // blue`) in binary: encoded straight from the arrays, as the plain layout's own fast path.
    let plain = matches!(&el.props[..], [x, y, z] if [&x.name, &y.name, &z.name] == ["x", "y", "z"]
            && x.kind == y.kind && y.kind == z.kind
            && matches!(x.kind, Kind::Scalar(Scalar::F32 | Scalar::F64)));
    if let (false, None, true) = (ascii, stored, plain) {
        let Kind::Scalar(coordinate) = el.props[0].kind else {
            unreachable!("matched above")
        };
        for start in (0..mesh.positions.len()).step_by(1 << 15) {
            let end = (start + (1 << 15)).min(mesh.positions.len());
            buf.clear();
            for i in start..end {
                put_xyz(coordinate, mesh.positions[i], &mut buf);
                buf.extend_from_slice(&(values.quality[i] as f32).to_le_bytes());
                if let Some(colour) = values.colours {
                    buf.extend_from_slice(&colour(i));
                }
            }
            out.write_all(&buf)?;
        }
        return Ok(());
    }
    if let Some(stride) = el.stride().filter(|_| !retyped) {
        // Fixed records: every property at the same offset in each.
        let offsets: Vec<usize> = (0..props.len())
            .map(|k| props[..k].iter().map(|p| scalar_of(p).size()).sum())
            .collect();
        let at = |k: usize| offsets[k];
        let wide = stride + extra;
        for i in 0..mesh.positions.len() {
            let start = buf.len();
            match stored {
                Some(r) => buf.extend_from_slice(&r[i * stride..(i + 1) * stride]),
                None => buf.resize(start + stride, 0),
            }
            buf.resize(start + wide, 0);
            put(&mut buf[start..], &at, i);
            if buf.len() >= FLUSH {
                emit(out, props, &buf, ascii)?;
                buf.clear();
            }
        }
        return emit(out, props, &buf, ascii);
    }
    // Lists in the vertex element, or a property retyped (then its records are stored): each
    // record walked and copied field by field, a retyped field as zeros of its new size.
    let records = stored.unwrap_or_default();
    let corrupt = || io::Error::other("stored PLY vertex records are corrupt");
    let (mut fields, mut pos, mut record) = (Vec::new(), 0, Vec::new());
    for i in 0..mesh.positions.len() {
        let end =
            walk_record(records, pos, &el.props, false, &mut fields).map_err(|_| corrupt())?;
        record.clear();
        for k in 0..own {
            let next = fields.get(k + 1).map_or(end, |f| f.at);
            match el.props[k].kind == props[k].kind {
                true => record.extend_from_slice(&records[fields[k].at..next]),
                false => record.resize(record.len() + scalar_of(&props[k]).size(), 0),
            }
        }
        record.resize(record.len() + extra, 0);
        walk_record(&record, 0, props, false, &mut fields).map_err(|_| corrupt())?;
        put(&mut record, &|k| fields[k].at, i);
        buf.extend_from_slice(&record);
        pos = end;
        if buf.len() >= FLUSH {
            emit(out, props, &buf, ascii)?;
            buf.clear();
        }
    }
    emit(out, props, &buf, ascii)
}

/// The type of a scalar property (a list's item type).
fn scalar_of(p: &Property) -> Scalar {
    match p.kind {
        Kind::Scalar(t) | Kind::List(_, t) => t,
    }
}

/// Writes a face element made of only the index list, from the mesh's polygons or triangles.
fn write_faces(
    out: &mut impl Write,
    el: &Element,
    face: FaceRole,
    faces: &Faces,
    ascii: bool,
) -> io::Result<()> {
    let FaceRole { count, index, .. } = face;
    const FLUSH: usize = 1 << 20; // bytes per buffer
    if !ascii && faces.sizes.is_none() {
        // Triangles: records of one length, encoded in parallel pieces.
        let record = count.size() + 3 * index.size();
        return write_encoded(out, faces.triangles.len(), record, |range, buf| {
            for t in &faces.triangles[range] {
                put_face(count, index, t, buf);
            }
            Ok(())
        });
    }
    let mut buf = Vec::with_capacity(FLUSH + 1024);
    faces.try_for_each(|corners| {
        put_face(count, index, corners, &mut buf);
        if buf.len() >= FLUSH {
            emit(out, &el.props, &buf, ascii)?;
            buf.clear();
        }
        Ok::<_, io::Error>(())
    })?;
    emit(out, &el.props, &buf, ascii)
}
