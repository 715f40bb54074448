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

mod ascii;
mod header;
mod read;
mod write;

use super::Faces;
use crate::mesh::Mesh;
use header::{Element, Kind, walk_record};

pub(crate) use header::{Scalar, has_magic, header_counts};
pub(crate) use read::{ReadError, read, read_metered};
pub(crate) use write::{
    PlainRecords, check_writable, coordinate_types, put_face, put_xyz, write, write_header,
};

type Fallible<T> = Result<T, String>;

/// How a PLY file's body is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlyEncoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
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

    fn has_vertex_attributes(&self) -> (bool, bool) {
        (
            self.vertex_columns(&COLOUR_NAMES).is_some(),
            self.vertex_columns(&UV_NAMES).is_some(),
        )
    }

    fn vertex_colours(&self) -> Option<Vec<[f32; 3]>> {
        let ([r, g, b], el, records) = self.vertex_columns(&COLOUR_NAMES)?;
        // Integer channels span their type (`uchar`: 0..=255); float ones are 0..=1 already.
        let channel = |k: usize, record: &[u8]| {
            let t = el.scalar(k);
            let v = t.get(&record[el.offset(k)..]).unwrap_or(0.0);
            let max = t.int_range().map_or(1.0, |(_, max)| max as f64);
            (v / max).clamp(0.0, 1.0) as f32
        };
        Some(
            records
                .map(|rec| [channel(r, rec), channel(g, rec), channel(b, rec)])
                .collect(),
        )
    }

    fn vertex_uvs(&self) -> Option<Vec<[f32; 2]>> {
        let ([u, v], el, records) = self.vertex_columns(&UV_NAMES)?;
        let value = |k: usize, record: &[u8]| {
            el.scalar(k).get(&record[el.offset(k)..]).unwrap_or(0.0) as f32
        };
        Some(records.map(|rec| [value(u, rec), value(v, rec)]).collect())
    }

    /// A new vertex's scalar properties are the mean of its edge's two endpoints', rounded to
    /// the property's type (integers to nearest, half away from zero); coordinates and normals
    /// are rewritten from the mesh anyway. A child face keeps its input face's properties, with
    /// its own three corners. Other elements are kept as they are. `None` (dropped) when the
    /// vertex element has list properties or the stored records do not walk.
    fn subdivided(
        &self,
        parents: &[[u32; 2]],
        triangles: &[[u32; 3]],
        face_of: &[u32],
    ) -> Option<std::sync::Arc<dyn crate::mesh::FileLayout>> {
        let roles = header::Roles::find(&self.elements).ok()?;
        // Strips cannot be split: the subdivided mesh is written as plain faces.
        if roles.strips.is_some() {
            return None;
        }
        let mut elements = Vec::with_capacity(self.elements.len());
        for (e, el) in self.elements.iter().enumerate() {
            let mut el = el.clone();
            if e == roles.vertex {
                if el.records.is_some() {
                    let stride = el.stride()?;
                    let fields: Vec<(usize, Scalar)> = (0..el.props.len())
                        .map(|k| (el.offset(k), el.scalar(k)))
                        .collect();
                    let records = el.records.as_mut()?;
                    records.truncate(el.count * stride);
                    records.reserve_exact(parents.len() * stride);
                    for &[a, b] in parents {
                        let (a, b) = (a as usize * stride, b as usize * stride);
                        let at = records.len();
                        records.resize(at + stride, 0);
                        for &(o, t) in &fields {
                            let va = t.get(&records[a + o..])?;
                            let vb = t.get(&records[b + o..])?;
                            t.put(0.5 * va + 0.5 * vb, &mut records[at + o..]);
                        }
                    }
                }
                el.count += parents.len();
            } else if let Some(face) = roles.face.filter(|f| f.element == e) {
                if let Some(records) = el.records.as_ref() {
                    let mut starts = Vec::with_capacity(el.count);
                    let (mut fields, mut pos) = (Vec::new(), 0);
                    for _ in 0..el.count {
                        starts.push(pos);
                        pos = walk_record(records, pos, &el.props, false, &mut fields).ok()?;
                    }
                    let mut out = Vec::with_capacity(triangles.len() * (pos / el.count.max(1)));
                    for (t, &f) in triangles.iter().zip(face_of) {
                        walk_record(
                            records,
                            *starts.get(f as usize)?,
                            &el.props,
                            false,
                            &mut fields,
                        )
                        .ok()?;
                        for (k, p) in el.props.iter().enumerate() {
                            let at = fields[k].at;
                            match p.kind {
                                _ if k == face.list => {
                                    put_face(face.count, face.index, t, &mut out)
                                }
                                Kind::Scalar(s) => {
                                    out.extend_from_slice(&records[at..at + s.size()])
                                }
                                Kind::List(c, s) => out.extend_from_slice(
                                    &records[at..at + c.size() + fields[k].n * s.size()],
                                ),
                            }
                        }
                    }
                    el.records = Some(out);
                }
                el.count = triangles.len();
            }
            elements.push(el);
        }
        Some(std::sync::Arc::new(PlyLayout {
            encoding: self.encoding,
            meta: self.meta.clone(),
            elements,
        }))
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

/// The names a vertex's colour channels go by, in order of preference.
const COLOUR_NAMES: [[&str; 3]; 3] = [
    ["red", "green", "blue"],
    ["r", "g", "b"],
    ["diffuse_red", "diffuse_green", "diffuse_blue"],
];

/// The names a vertex's texture coordinates go by, in order of preference.
const UV_NAMES: [[&str; 2]; 4] = [
    ["u", "v"],
    ["s", "t"],
    ["texture_u", "texture_v"],
    ["texture_s", "texture_t"],
];

impl PlyLayout {
    /// The first of `names` whose properties the vertex element has, all scalars, with the element
    /// and its records (kept, without lists), one slice a vertex.
    fn vertex_columns<const N: usize>(
        &self,
        names: &[[&str; N]],
    ) -> Option<([usize; N], &Element, std::slice::ChunksExact<'_, u8>)> {
        let el = self.elements.iter().find(|e| e.name == "vertex")?;
        let stride = el.stride()?;
        let records = el.records.as_ref()?;
        let columns = names.iter().find_map(|set| {
            let ks = set.map(|name| el.prop(name));
            ks.iter()
                .all(Option::is_some)
                .then(|| ks.map(|k| k.unwrap_or(0)))
        })?;
        let rows = records
            .get(..el.count * stride)?
            .chunks_exact(stride.max(1));
        Some((columns, el, rows))
    }
}
