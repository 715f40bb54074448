//! PLY: the header model and its parser, the binary decoder (mapped bytes in, stride decode out)
//! and the writer for both encodings.
//!
//! Records are held little-endian whatever the input's encoding: `ascii` encodes ASCII bodies,
//! big-endian bodies are byte-swapped once. Everything after that — positions, faces, validation,
//! output — is one code path over little-endian bytes, decoded with `from_le_bytes` on byte slices
//! (records are unaligned; they are never cast to `&[f32]`).
//!
//! The common layout (`x y z float`, then `list uchar int vertex_indices`) takes a fast path: one
//! pass over the mapped bytes that decodes, validates every index and fan-triangulates, with no
//! allocation per element. Other layouts go through [`walk_record`], which finds every field of a
//! record whatever its lists.

use std::borrow::Cow;
use std::fmt;

use crate::mesh::{Buf, Storage};
use crate::meter::Meter;
use std::io::{self, Write};
use std::sync::Arc;

use glam::DVec3;
use rayon::prelude::*;

mod ascii;

use super::{FaceBuilder, Faces, Format, Precision, Source, bad_index, vertex_normals};
use crate::mesh::Mesh;

type Fallible<T> = Result<T, String>;

/// How a PLY file's body is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyEncoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &[u8]) -> Option<Scalar> {
        Some(match name {
            b"char" | b"int8" => Scalar::I8,
            b"uchar" | b"uint8" => Scalar::U8,
            b"short" | b"int16" => Scalar::I16,
            b"ushort" | b"uint16" => Scalar::U16,
            b"int" | b"int32" => Scalar::I32,
            b"uint" | b"uint32" => Scalar::U32,
            b"float" | b"float32" => Scalar::F32,
            b"double" | b"float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// The classic name, which every PLY reader understands.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The smallest and largest value of an integer type; `None` for floating-point types.
    pub(crate) fn int_range(self) -> Option<(i64, i64)> {
        match self {
            Scalar::I8 => Some((i8::MIN.into(), i8::MAX.into())),
            Scalar::U8 => Some((0, u8::MAX.into())),
            Scalar::I16 => Some((i16::MIN.into(), i16::MAX.into())),
            Scalar::U16 => Some((0, u16::MAX.into())),
            Scalar::I32 => Some((i32::MIN.into(), i32::MAX.into())),
            Scalar::U32 => Some((0, u32::MAX.into())),
            Scalar::F32 | Scalar::F64 => None,
        }
    }

    /// The little-endian value at the start of `b`; `None` when `b` is too short. Every type
    /// converts to `f64` exactly.
    pub(crate) fn get(self, b: &[u8]) -> Option<f64> {
        Some(match self {
            Scalar::I8 => i8::from_le_bytes(*b.first_chunk()?).into(),
            Scalar::U8 => u8::from_le_bytes(*b.first_chunk()?).into(),
            Scalar::I16 => i16::from_le_bytes(*b.first_chunk()?).into(),
            Scalar::U16 => u16::from_le_bytes(*b.first_chunk()?).into(),
            Scalar::I32 => i32::from_le_bytes(*b.first_chunk()?).into(),
            Scalar::U32 => u32::from_le_bytes(*b.first_chunk()?).into(),
            Scalar::F32 => f32::from_le_bytes(*b.first_chunk()?).into(),
            Scalar::F64 => f64::from_le_bytes(*b.first_chunk()?),
        })
    }

    /// [`Scalar::get`] for a value stored big-endian when `big` is set.
    fn get_in(self, b: &[u8], big: bool) -> Option<f64> {
        if !big {
            return self.get(b);
        }
        let n = self.size();
        let mut le = [0; 8];
        le[..n].copy_from_slice(b.get(..n)?);
        le[..n].reverse();
        self.get(&le)
    }

    /// Stores `v` little-endian in `out[..self.size()]`: floats round to nearest, integers round
    /// and saturate (writers check [`Scalar::holds`] first).
    pub(crate) fn put(self, v: f64, out: &mut [u8]) {
        let v = if self.int_range().is_some() {
            v.round()
        } else {
            v
        };
        match self {
            Scalar::I8 => out[..1].copy_from_slice(&(v as i8).to_le_bytes()),
            Scalar::U8 => out[..1].copy_from_slice(&(v as u8).to_le_bytes()),
            Scalar::I16 => out[..2].copy_from_slice(&(v as i16).to_le_bytes()),
            Scalar::U16 => out[..2].copy_from_slice(&(v as u16).to_le_bytes()),
            Scalar::I32 => out[..4].copy_from_slice(&(v as i32).to_le_bytes()),
            Scalar::U32 => out[..4].copy_from_slice(&(v as u32).to_le_bytes()),
            Scalar::F32 => out[..4].copy_from_slice(&(v as f32).to_le_bytes()),
            Scalar::F64 => out[..8].copy_from_slice(&v.to_le_bytes()),
        }
    }

    /// A unit-vector component `c` (in [-1, 1]) as this type stores it: floats as it is, integers
    /// as normalized integers (the convention of glTF and GPU formats): a signed type holds
    /// `c × MAX`, an unsigned one `(c + 1) / 2 × MAX`, so that a normal keeps its direction
    /// instead of rounding to -1, 0 or 1.
    pub(crate) fn unit_component(self, c: f64) -> f64 {
        match self.int_range() {
            Some((lo, hi)) if lo < 0 => c * hi as f64,
            Some((_, hi)) => (c + 1.0) / 2.0 * hi as f64,
            None => c,
        }
    }

    /// Whether [`Scalar::put`] stores `v` without saturating or overflowing to infinity.
    pub(crate) fn holds(self, v: f64) -> bool {
        match (self, self.int_range()) {
            (_, Some((lo, hi))) => (lo as f64..=hi as f64).contains(&v.round()),
            (Scalar::F32, None) => (v as f32).is_finite() || !v.is_finite(),
            _ => true,
        }
    }
}

/// A property's type: a scalar, or a list with its count and item types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    Scalar(Scalar),
    List(Scalar, Scalar),
}

#[derive(Debug, Clone)]
pub(crate) struct Property {
    pub(crate) name: String,
    pub(crate) kind: Kind,
}

/// An element of the header and, when the mesh cannot regenerate them, its records.
#[derive(Clone)]
pub(crate) struct Element {
    pub(crate) name: String,
    pub(crate) count: usize,
    pub(crate) props: Vec<Property>,
    /// The records, little-endian, in file order; `None` when the writer rebuilds them from the
    /// mesh (a vertex element of only `x y z nx ny nz`, a face element of only the index list).
    pub(crate) records: Option<Vec<u8>>,
}

// By hand: the records run to gigabytes.
impl fmt::Debug for Element {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Element")
            .field("name", &self.name)
            .field("count", &self.count)
            .field("props", &self.props)
            .field("stored_bytes", &self.records.as_ref().map(Vec::len))
            .finish()
    }
}

impl Element {
    /// Record size when there is no list property.
    fn stride(&self) -> Option<usize> {
        self.props.iter().try_fold(0, |size, p| match p.kind {
            Kind::Scalar(t) => Some(size + t.size()),
            Kind::List(..) => None,
        })
    }

    /// Size of the smallest possible record (every list empty).
    fn min_record(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(t) | Kind::List(t, _) => t.size(),
            })
            .sum()
    }

    fn prop(&self, name: &str) -> Option<usize> {
        self.props.iter().position(|p| p.name == name)
    }

    /// Byte offset of property `k` in a record without lists.
    fn offset(&self, k: usize) -> usize {
        (0..k).map(|j| self.scalar(j).size()).sum()
    }

    /// The type of property `k`, a scalar (for a list: its item type).
    fn scalar(&self, k: usize) -> Scalar {
        match self.props[k].kind {
            Kind::Scalar(t) | Kind::List(_, t) => t,
        }
    }
}

/// A PLY input's header model and the records the mesh cannot regenerate, so that a PLY output
/// reproduces the input (see the module documentation of [`crate::io`]).
#[derive(Debug, Clone)]
pub struct PlyLayout {
    encoding: PlyEncoding,
    /// `comment …` and `obj_info …` lines, in header order.
    meta: Vec<String>,
    elements: Vec<Element>,
}

impl crate::mesh::FileLayout for PlyLayout {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    /// By property name, in the vertex and face elements: texture coordinates (`u v`, `s t`,
    /// `texture_u texture_v`, `texcoord`, …), colours (`red green blue alpha`, `r g b a`,
    /// `diffuse_red` …), normals (`nx ny nz`), materials (`material_index`); every other property
    /// is named in `other` as `element.property`, and every other element by its name.
    fn carries(&self) -> crate::mesh::Carried {
        let mut carried = crate::mesh::Carried::default();
        for el in &self.elements {
            if el.name != "vertex" && el.name != "face" {
                carried.other.push(el.name.clone());
                continue;
            }
            for p in &el.props {
                let name = p.name.as_str();
                match name {
                    "x" | "y" | "z" if el.name == "vertex" => {}
                    "vertex_indices" | "vertex_index" if el.name == "face" => {}
                    "nx" | "ny" | "nz" => carried.normals = true,
                    "u" | "v" | "s" | "t" | "texture_u" | "texture_v" | "texture_s"
                    | "texture_t" | "texcoord" | "texcoords" => carried.uvs = true,
                    "red" | "green" | "blue" | "alpha" | "r" | "g" | "b" | "a" => {
                        carried.colours = true
                    }
                    _ if name.starts_with("diffuse_")
                        || name.starts_with("ambient_")
                        || name.starts_with("specular_") =>
                    {
                        carried.colours = true
                    }
                    "material_index" => carried.materials = true,
                    _ => carried.other.push(format!("{}.{name}", el.name)),
                }
            }
        }
        carried
    }
}

impl PlyLayout {
    /// The input's encoding (outputs use it, except that big-endian becomes little-endian).
    pub fn encoding(&self) -> PlyEncoding {
        self.encoding
    }

    /// The input's `comment` and `obj_info` lines, in header order.
    pub fn comments(&self) -> impl Iterator<Item = &str> {
        self.meta.iter().map(String::as_str)
    }

    /// The names of the vertex element's properties, in header order.
    pub fn vertex_properties(&self) -> Vec<&str> {
        self.elements
            .iter()
            .find(|e| e.name == "vertex")
            .map(|e| e.props.iter().map(|p| p.name.as_str()).collect())
            .unwrap_or_default()
    }

    /// Call `f(i, value)` with the value of the scalar vertex property `name` of every vertex `i`,
    /// in file order (every PLY type converts to `f64` exactly). Fails, with a message that names
    /// the property and lists those present, when there is no such property, when it is a list,
    /// or when it is a coordinate or a normal (`x y z nx ny nz`, which the mesh holds).
    pub fn vertex_values(&self, name: &str, mut f: impl FnMut(usize, f64)) -> Fallible<()> {
        let listed = || self.vertex_properties().join(", ");
        let Some(el) = self.elements.iter().find(|e| e.name == "vertex") else {
            return Err(format!(
                "has no vertex property '{name}' (no vertex element)"
            ));
        };
        let Some(k) = el.prop(name) else {
            return Err(format!(
                "has no vertex property '{name}' (its vertex properties: {})",
                listed()
            ));
        };
        let Kind::Scalar(t) = el.props[k].kind else {
            return Err(format!(
                "vertex property '{name}' is a list, not one number per vertex"
            ));
        };
        // The writer rebuilds these from the mesh, and stores no records for a vertex element of
        // only these.
        let records = el
            .records
            .as_deref()
            .filter(|_| !matches!(name, "x" | "y" | "z" | "nx" | "ny" | "nz"));
        let Some(records) = records else {
            return Err(format!(
                "vertex property '{name}' is a coordinate or normal, not a per-vertex flag \
                 (its vertex properties: {})",
                listed()
            ));
        };
        let corrupt = || "stored PLY vertex records are corrupt".to_string();
        match el.stride() {
            Some(stride) => {
                let at = el.offset(k);
                for (i, r) in records.chunks_exact(stride).take(el.count).enumerate() {
                    f(i, t.get(&r[at..]).ok_or_else(corrupt)?);
                }
            }
            None => {
                let (mut fields, mut pos) = (Vec::new(), 0);
                for i in 0..el.count {
                    pos = walk_record(records, pos, &el.props, false, &mut fields)
                        .map_err(|_| corrupt())?;
                    f(i, t.get(&records[fields[k].at..]).ok_or_else(corrupt)?);
                }
            }
        }
        Ok(())
    }

    /// The layout of a mesh without a PLY source: binary little-endian `x y z` in the mesh's
    /// precision and the smallest list types that hold its faces (`uchar` / `int` in practice).
    fn plain(mesh: &Mesh) -> PlyLayout {
        let faces = Faces::of(mesh);
        let records = PlainRecords::new(
            mesh.positions.len(),
            faces.max_corners(),
            mesh.source.precision,
        );
        records.layout(mesh.positions.len(), faces.len(), Vec::new())
    }
}

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

/// A parsed header.
pub(crate) struct Header {
    pub(crate) encoding: PlyEncoding,
    pub(crate) meta: Vec<String>,
    pub(crate) elements: Vec<Element>,
    /// Byte offset of the body.
    pub(crate) body: usize,
    /// Number of header lines: the body's first line is `lines + 1`.
    pub(crate) lines: usize,
}

/// The longest header: a file that has no `end_header` by then is refused there.
const MAX_HEADER: usize = 1 << 20;

/// Whether the text (after any byte-order mark) starts with the line `ply`.
pub(crate) fn has_magic(text: &[u8]) -> bool {
    text.split(|&b| b == b'\n')
        .next()
        .is_some_and(|l| l.trim_ascii() == b"ply")
}

/// Parses the header. Lines end with `\n` or `\r\n`; blank lines are skipped; the body starts
/// right after the `end_header` line's `\n`. A UTF-8 byte-order mark before `ply` is skipped
/// (byte offsets still count from the file's first byte). A line longer than
/// [`super::MAX_HEADER_LINE`], or a header longer than [`MAX_HEADER`], is refused as soon as it
/// is seen.
pub(crate) fn parse_header(bytes: &[u8]) -> Fallible<Header> {
    let mut encoding = None;
    let mut meta = Vec::new();
    let mut elements: Vec<Element> = Vec::new();
    let mut pos = bytes.len() - super::without_bom(bytes).len();
    let mut line = 0;
    loop {
        let window = &bytes[pos..bytes.len().min(pos + super::MAX_HEADER_LINE + 1)];
        let Some(len) = window.iter().position(|&b| b == b'\n') else {
            if window.len() > super::MAX_HEADER_LINE {
                return Err(format!(
                    "header line {} is longer than {} KiB",
                    line + 1,
                    super::MAX_HEADER_LINE >> 10
                ));
            }
            return Err(format!(
                "header: no end_header line (the file ends at line {})",
                line + 1
            ));
        };
        if pos + len >= MAX_HEADER {
            return Err(format!(
                "header: no end_header line in the first {} MiB (line {})",
                MAX_HEADER >> 20,
                line + 1
            ));
        }
        let text = &bytes[pos..pos + len];
        pos += len + 1;
        line += 1;
        if line == 1 {
            if text.trim_ascii() != b"ply" {
                return Err("not a PLY file (the first line is not 'ply')".into());
            }
            continue;
        }
        let at = |what: String| format!("header line {line}: {what}");
        let mut words = super::tokens(text);
        let Some(keyword) = words.next() else {
            continue;
        };
        let words: Vec<&[u8]> = words.collect();
        match (keyword, &words[..]) {
            (b"comment" | b"obj_info", _) => {
                meta.push(String::from_utf8_lossy(text.trim_ascii()).into_owned());
            }
            (b"format", [name, version]) => {
                if encoding.is_some() {
                    return Err(at("a second format line".into()));
                }
                encoding = Some(match *name {
                    b"ascii" => PlyEncoding::Ascii,
                    b"binary_little_endian" => PlyEncoding::BinaryLittleEndian,
                    b"binary_big_endian" => PlyEncoding::BinaryBigEndian,
                    other => return Err(at(format!("unknown format {}", super::show(other)))),
                });
                if super::number(version) != Ok(1.0) {
                    return Err(at(format!(
                        "unsupported PLY version {}",
                        super::show(version)
                    )));
                }
            }
            (b"element", [name, count]) => {
                let name = word(name).map_err(at)?;
                let count = std::str::from_utf8(count)
                    .ok()
                    .filter(|c| c.bytes().all(|b| b.is_ascii_digit()))
                    .and_then(|c| c.parse::<usize>().ok())
                    .ok_or_else(|| {
                        at(format!(
                            "element count {} is not a count",
                            super::show(count)
                        ))
                    })?;
                if elements.iter().any(|e| e.name == name) {
                    return Err(at(format!("a second element '{name}'")));
                }
                elements.push(Element {
                    name,
                    count,
                    props: Vec::new(),
                    records: None,
                });
            }
            (b"property", [rest @ .., name]) => {
                let name = word(name).map_err(at)?;
                let scalar = |t: &[u8]| {
                    Scalar::from_name(t)
                        .ok_or_else(|| at(format!("unknown type {}", super::show(t))))
                };
                let kind = match rest {
                    [t] => Kind::Scalar(scalar(t)?),
                    [b"list", c, t] => {
                        let c = scalar(c)?;
                        if c.int_range().is_none() {
                            return Err(at(format!(
                                "list count type {} is not an integer type",
                                c.name()
                            )));
                        }
                        Kind::List(c, scalar(t)?)
                    }
                    _ => return Err(at("malformed property line".into())),
                };
                let Some(element) = elements.last_mut() else {
                    return Err(at("property before any element".into()));
                };
                if element.prop(&name).is_some() {
                    return Err(at(format!(
                        "a second property '{name}' in element '{}'",
                        element.name
                    )));
                }
                element.props.push(Property { name, kind });
            }
            (b"end_header", []) => break,
            (b"format" | b"element" | b"property" | b"end_header", _) => {
                return Err(at(format!(
                    "malformed {} line",
                    String::from_utf8_lossy(keyword)
                )));
            }
            (other, _) => return Err(at(format!("unknown keyword {}", super::show(other)))),
        }
    }
    let encoding = encoding.ok_or("header: no format line")?;
    if let Some(e) = elements.iter().find(|e| e.props.is_empty()) {
        return Err(format!("header: element '{}' has no properties", e.name));
    }
    Ok(Header {
        encoding,
        meta,
        elements,
        body: pos,
        lines: line,
    })
}

/// A header name: printable ASCII.
fn word(w: &[u8]) -> Result<String, String> {
    match std::str::from_utf8(w) {
        Ok(s) if s.bytes().all(|b| b.is_ascii_graphic()) => Ok(s.into()),
        _ => Err(format!("name {} is not printable ASCII", super::show(w))),
    }
}

/// Where the mesh lives in the elements: the vertex element with its `x y z`, the face element.
struct Roles {
    vertex: usize,
    /// The vertex count, which fits 32-bit indices.
    vertices: u32,
    xyz: [usize; 3],
    face: Option<FaceRole>,
}

/// The face element, its index list property and the list's count and index types.
#[derive(Clone, Copy)]
struct FaceRole {
    element: usize,
    list: usize,
    count: Scalar,
    index: Scalar,
}

impl Roles {
    fn find(elements: &[Element]) -> Fallible<Roles> {
        let vertex = elements
            .iter()
            .position(|e| e.name == "vertex")
            .ok_or("no 'vertex' element")?;
        let v = &elements[vertex];
        let vertices = u32::try_from(v.count).map_err(|_| {
            format!(
                "element vertex {}: more vertices than 32-bit indices can address",
                v.count
            )
        })?;
        let mut xyz = [0; 3];
        for (k, name) in xyz.iter_mut().zip(["x", "y", "z"]) {
            *k = v
                .prop(name)
                .filter(|&k| matches!(v.props[k].kind, Kind::Scalar(_)))
                .ok_or_else(|| format!("the vertex element has no scalar property '{name}'"))?;
        }
        let face = match elements.iter().position(|e| e.name == "face") {
            None => None,
            Some(f) => {
                let el = &elements[f];
                let list = el
                    .prop("vertex_indices")
                    .or_else(|| el.prop("vertex_index"))
                    .ok_or("the face element has no 'vertex_indices' property")?;
                match el.props[list].kind {
                    Kind::List(count, index) if index.int_range().is_some() => Some(FaceRole {
                        element: f,
                        list,
                        count,
                        index,
                    }),
                    _ => {
                        return Err(format!(
                            "'{}' is not a list of integers",
                            el.props[list].name
                        ));
                    }
                }
            }
        };
        Ok(Roles {
            vertex,
            vertices,
            xyz,
            face,
        })
    }

    /// Whether the writer can rebuild element `e`'s records from the mesh alone.
    fn rebuildable(&self, e: usize, el: &Element) -> bool {
        if e == self.vertex {
            el.props.iter().all(|p| {
                matches!(p.kind, Kind::Scalar(_))
                    && matches!(p.name.as_str(), "x" | "y" | "z" | "nx" | "ny" | "nz")
            })
        } else {
            self.face.is_some_and(|f| f.element == e) && el.props.len() == 1
        }
    }
}

/// Where an element's records came from, to name a record's place in messages.
#[derive(Clone, Copy)]
enum Origin {
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

/// One field of a record: a scalar at `at`, or a list whose count is at `at`, with `n` items.
#[derive(Clone, Copy)]
pub(crate) struct Field {
    pub(crate) at: usize,
    pub(crate) n: usize,
}

pub(crate) enum WalkError {
    Truncated,
    NegativeCount(f64),
}

/// Finds the fields (one per property, into `fields`) of the record starting at `data[start..]`
/// and returns where it ends. `big`: list counts are big-endian. Checks that every field lies
/// inside `data`, so callers may index with the offsets.
pub(crate) fn walk_record(
    data: &[u8],
    start: usize,
    props: &[Property],
    big: bool,
    fields: &mut Vec<Field>,
) -> Result<usize, WalkError> {
    fields.clear();
    let mut at = start;
    for p in props {
        let (n, end) = match p.kind {
            Kind::Scalar(t) => (1, at.checked_add(t.size())),
            Kind::List(c, t) => {
                let n = c.get_in(data.get(at..).ok_or(WalkError::Truncated)?, big);
                let n = n.ok_or(WalkError::Truncated)?;
                if n < 0.0 {
                    return Err(WalkError::NegativeCount(n));
                }
                let n = n as usize;
                (
                    n,
                    n.checked_mul(t.size())
                        .and_then(|b| b.checked_add(at + c.size())),
                )
            }
        };
        let end = end
            .filter(|&end| end <= data.len())
            .ok_or(WalkError::Truncated)?;
        fields.push(Field { at, n });
        at = end;
    }
    Ok(at)
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
    read_metered(bytes, storage, &Meter::default())
}

/// [`read_in`], counting into `meter` where it stands in `bytes`: the header, each element as it
/// ends, and the vertices and triangles of a binary body chunk by chunk as they are decoded.
pub(crate) fn read_metered(
    bytes: &[u8],
    storage: &Storage,
    meter: &Meter,
) -> Result<Mesh, ReadError> {
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
                let data = if big {
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
    Ok(faces.into_mesh(mesh.positions, source))
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
    positions: Buf<DVec3>,
    faces: Option<FaceBuilder>,
}

impl Decoded<'_> {
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
fn decode_faces(
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
    let FaceRole {
        list,
        count,
        index: item,
        ..
    } = face;
    let mut fields = Vec::new();
    let mut corners = Vec::new();
    let mut pos = 0;
    for i in 0..el.count {
        let end = walk_record(data, pos, &el.props, false, &mut fields)
            .map_err(|e| walk_failed(el, i, origin, pos, e))?;
        let Field { at, n } = fields[list];
        if n < 3 {
            return Err(fail(el, i, origin, pos, too_few(n)));
        }
        corners.clear();
        for k in 0..n {
            // In bounds: `walk_record` checked the list; an integer type converts exactly.
            let v = item
                .get(&data[at + count.size() + k * item.size()..])
                .unwrap_or(-1.0) as i64;
            if !(0..i64::from(vertices)).contains(&v) {
                return Err(fail(el, i, origin, pos, bad_index(v, vertices as usize)));
            }
            corners.push(v as u32);
        }
        faces.polygon(&corners);
        pos = end;
    }
    Ok(pos)
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
        if let Some(i) = mesh.positions.iter().position(|p| !t.holds(p[c])) {
            let (v, name) = (mesh.positions[i][c], &vertex.props[k].name);
            return Err(format!(
                "vertex {i}: coordinate {v} does not fit PLY property '{name}' ({})",
                t.name()
            ));
        }
    }
    let Some(face) = roles.face else {
        if !mesh.triangles.is_empty() {
            return Err("the mesh has triangles but its PLY source has no face element".into());
        }
        return Ok(());
    };
    let el = &layout.elements[face.element];
    if let Some(records) = &el.records {
        let mut faces = FaceBuilder::with_capacity(el.count);
        let same = decode_faces(
            records,
            el,
            face,
            roles.vertices,
            Origin::Byte(0),
            &mut faces,
            &Meter::default(),
        )
        .is_ok_and(|_| faces.triangles() == &mesh.triangles[..]);
        if !same {
            return Err(
                "the triangles no longer match the PLY source's faces; clear \
                        mesh.source.layout after changing connectivity"
                    .into(),
            );
        }
        return Ok(());
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
    let largest = mesh.triangles.iter().flatten().max();
    if let Some(&v) = largest.filter(|&&v| !index.holds(v as f64)) {
        return Err(format!(
            "vertex index {v} does not fit the PLY index type {}",
            index.name()
        ));
    }
    Ok(())
}

/// Writes `mesh` as PLY; [`check_writable`] passed.
pub(crate) fn write(out: &mut impl Write, mesh: &Mesh) -> io::Result<()> {
    let layout = layout_of(mesh);
    let roles = Roles::find(&layout.elements).map_err(io::Error::other)?;
    // The face element to rebuild from the mesh, unless its records are stored.
    let face = roles
        .face
        .filter(|f| layout.elements[f.element].records.is_none());
    let faces = Faces::of(mesh);
    let ascii = layout.encoding == PlyEncoding::Ascii;

    write_header(out, &layout, |e, el| match face {
        Some(f) if f.element == e => faces.len(),
        _ => el.count,
    })?;
    for (e, el) in layout.elements.iter().enumerate() {
        if e == roles.vertex {
            write_vertices(out, el, mesh, ascii)?;
        } else if let Some(f) = face.filter(|f| f.element == e) {
            write_faces(out, el, f, &faces, ascii)?;
        } else if let Some(records) = &el.records {
            emit(out, &el.props, records, ascii)?;
        }
    }
    Ok(())
}

/// Writes the header of `layout` (big-endian is written as little-endian), with `count(e, el)`
/// records for element `e`; every PLY writer's header.
pub(crate) fn write_header(
    out: &mut impl Write,
    layout: &PlyLayout,
    count: impl Fn(usize, &Element) -> usize,
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
        for p in &el.props {
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
    const CHUNK: usize = 1 << 15; // records per buffer
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
        let mut buf = Vec::with_capacity(CHUNK * stride);
        for chunk in mesh.positions.chunks(CHUNK) {
            buf.clear();
            for p in chunk {
                put_xyz(coordinate, *p, &mut buf);
            }
            out.write_all(&buf)?;
        }
        return Ok(());
    }
    let mut buf = Vec::with_capacity(CHUNK * stride);
    for start in (0..mesh.positions.len()).step_by(CHUNK) {
        let end = (start + CHUNK).min(mesh.positions.len());
        buf.clear();
        match &el.records {
            Some(records) => buf.extend_from_slice(&records[start * stride..end * stride]),
            None => buf.resize((end - start) * stride, 0),
        }
        for (record, i) in buf.chunks_exact_mut(stride).zip(start..) {
            for &(at, t, v) in &targets {
                t.put(value(i, t, v), &mut record[at..]);
            }
        }
        emit(out, &el.props, &buf, ascii)?;
    }
    Ok(())
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
    if !ascii && faces.sizes.is_none() && (count, index) == (Scalar::U8, Scalar::I32) {
        // Triangles as `list uchar int`: fixed 13-byte records, encoded in one tight loop.
        let mut buf = Vec::with_capacity(FLUSH);
        for chunk in faces.triangles.chunks(FLUSH / 13) {
            buf.clear();
            for t in chunk {
                put_face(Scalar::U8, Scalar::I32, t, &mut buf);
            }
            out.write_all(&buf)?;
        }
        return Ok(());
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
