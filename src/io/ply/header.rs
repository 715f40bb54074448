//! The PLY header: its model (scalar types, elements, properties, the mesh's roles in them), its
//! parser, and the walk that finds a record's fields.

use std::fmt;

use super::{Fallible, PlyEncoding};

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
    pub(super) fn stride(&self) -> Option<usize> {
        self.props.iter().try_fold(0, |size, p| match p.kind {
            Kind::Scalar(t) => Some(size + t.size()),
            Kind::List(..) => None,
        })
    }

    /// Size of the smallest possible record (every list empty).
    pub(super) fn min_record(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(t) | Kind::List(t, _) => t.size(),
            })
            .sum()
    }

    pub(super) fn prop(&self, name: &str) -> Option<usize> {
        self.props.iter().position(|p| p.name == name)
    }

    /// Byte offset of property `k` in a record without lists.
    pub(super) fn offset(&self, k: usize) -> usize {
        (0..k).map(|j| self.scalar(j).size()).sum()
    }

    /// The type of property `k`, a scalar (for a list: its item type).
    pub(super) fn scalar(&self, k: usize) -> Scalar {
        match self.props[k].kind {
            Kind::Scalar(t) | Kind::List(_, t) => t,
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

/// The vertex and face counts a PLY file's header declares, read from its first bytes only; `None`
/// when `path` is not a regular file with a readable PLY header (the reader says why later).
pub(crate) fn header_counts(path: &std::path::Path) -> Option<(u64, u64)> {
    use std::io::Read;
    if !std::fs::metadata(path).ok()?.is_file() {
        return None;
    }
    let mut head = Vec::new();
    let mut file = std::fs::File::open(path).ok()?;
    (&mut file)
        .take(MAX_HEADER as u64)
        .read_to_end(&mut head)
        .ok()?;
    if crate::io::gzip::is_gzip(&head) {
        // A `.ply.gz`: the header is the start of what it holds.
        std::io::Seek::rewind(&mut file).ok()?;
        head.clear();
        // A header cut short by the limit fails to parse below, as it would uncompressed.
        let _ = flate2::read::MultiGzDecoder::new(std::io::BufReader::new(file))
            .take(MAX_HEADER as u64)
            .read_to_end(&mut head);
    }
    if !has_magic(crate::io::without_bom(&head)) {
        return None;
    }
    let header = parse_header(&head).ok()?;
    let count = |name: &str| {
        header
            .elements
            .iter()
            .find(|e| e.name == name)
            .map_or(0, |e| e.count as u64)
    };
    Some((count("vertex"), count("face")))
}

/// Whether the text (after any byte-order mark) starts with the line `ply`.
pub(crate) fn has_magic(text: &[u8]) -> bool {
    text.split(|&b| b == b'\n')
        .next()
        .is_some_and(|l| l.trim_ascii() == b"ply")
}

/// Parses the header. Lines end with `\n` or `\r\n`; blank lines are skipped; the body starts
/// right after the `end_header` line's `\n`. A UTF-8 byte-order mark before `ply` is skipped
/// (byte offsets still count from the file's first byte). A line longer than
/// [`crate::io::MAX_HEADER_LINE`], or a header longer than [`MAX_HEADER`], is refused as soon as it
/// is seen.
pub(crate) fn parse_header(bytes: &[u8]) -> Fallible<Header> {
    let mut encoding = None;
    let mut meta = Vec::new();
    let mut elements: Vec<Element> = Vec::new();
    let mut pos = bytes.len() - crate::io::without_bom(bytes).len();
    let mut line = 0;
    loop {
        let window = &bytes[pos..bytes.len().min(pos + crate::io::MAX_HEADER_LINE + 1)];
        let Some(len) = window.iter().position(|&b| b == b'\n') else {
            if window.len() > crate::io::MAX_HEADER_LINE {
                return Err(format!(
                    "header line {} is longer than {} KiB",
                    line + 1,
                    crate::io::MAX_HEADER_LINE >> 10
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
        let mut words = crate::io::tokens(text);
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
                    other => return Err(at(format!("unknown format {}", crate::io::show(other)))),
                });
                if crate::io::number(version) != Ok(1.0) {
                    return Err(at(format!(
                        "unsupported PLY version {}",
                        crate::io::show(version)
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
                            crate::io::show(count)
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
                        .ok_or_else(|| at(format!("unknown type {}", crate::io::show(t))))
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
            (other, _) => return Err(at(format!("unknown keyword {}", crate::io::show(other)))),
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
        _ => Err(format!(
            "name {} is not printable ASCII",
            crate::io::show(w)
        )),
    }
}

/// Where the mesh lives in the elements: the vertex element with its `x y z`, the face element,
/// or instead of it triangle strips.
pub(super) struct Roles {
    pub(super) vertex: usize,
    /// The vertex count, which fits 32-bit indices.
    pub(super) vertices: u32,
    pub(super) xyz: [usize; 3],
    pub(super) face: Option<FaceRole>,
    /// A `tristrips` element (as Stanford's and Cyberware's scans have): each record one or more
    /// strips of vertex ids, `-1` starting a new one. Its records are always kept and written
    /// back as they are: smoothing changes no connectivity.
    pub(super) strips: Option<FaceRole>,
}

/// The face (or strips) element, its index list property and the list's count and index types.
#[derive(Clone, Copy)]
pub(super) struct FaceRole {
    pub(super) element: usize,
    pub(super) list: usize,
    pub(super) count: Scalar,
    pub(super) index: Scalar,
}

impl Roles {
    pub(super) fn find(elements: &[Element]) -> Fallible<Roles> {
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
        let face = index_lists(elements, "face")?;
        let strips = index_lists(elements, "tristrips")?;
        if face.is_some() && strips.is_some() {
            return Err("both a face and a tristrips element: only one of them is read".into());
        }
        Ok(Roles {
            vertex,
            vertices,
            xyz,
            face,
            strips,
        })
    }

    /// Whether the writer can rebuild element `e`'s records from the mesh alone.
    pub(super) fn rebuildable(&self, e: usize, el: &Element) -> bool {
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

/// The element called `name` and its list of vertex ids, if the file has that element.
fn index_lists(elements: &[Element], name: &str) -> Fallible<Option<FaceRole>> {
    let Some(e) = elements.iter().position(|e| e.name == name) else {
        return Ok(None);
    };
    let el = &elements[e];
    let list = el
        .prop("vertex_indices")
        .or_else(|| el.prop("vertex_index"))
        .ok_or_else(|| format!("the {name} element has no 'vertex_indices' property"))?;
    match el.props[list].kind {
        Kind::List(count, index) if index.int_range().is_some() => Ok(Some(FaceRole {
            element: e,
            list,
            count,
            index,
        })),
        _ => Err(format!(
            "'{}' is not a list of integers",
            el.props[list].name
        )),
    }
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
