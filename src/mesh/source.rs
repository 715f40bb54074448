//! What a mesh carried in its file besides positions and triangles: the format, the coordinate
//! precision, the polygons before triangulation, and the file's own layout, so that a writer can
//! reproduce the input and `info` can say how it was read.

use std::any::Any;
use std::fmt;
use std::path::Path;
use std::sync::Arc;

/// Mesh file formats vcsmooth reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Format {
    #[default]
    Ply,
    Obj,
    Off,
    Stl,
    /// glTF 2.0 JSON (`.gltf`), buffers external or embedded.
    Gltf,
    /// glTF 2.0 binary (`.glb`).
    Glb,
}

impl Format {
    /// The format a file name's extension stands for (`.ply .obj .off .stl .gltf .glb`, any case),
    /// looking through a final `.gz` (`scan.ply.gz` is PLY, gzip-compressed).
    pub fn from_extension(path: &Path) -> Option<Format> {
        let mut ext = path.extension()?.to_str()?.to_ascii_lowercase();
        if ext == "gz" {
            ext = Path::new(path.file_stem()?)
                .extension()?
                .to_str()?
                .to_ascii_lowercase();
        }
        match ext.as_str() {
            "ply" => Some(Format::Ply),
            "obj" => Some(Format::Obj),
            "off" => Some(Format::Off),
            "stl" => Some(Format::Stl),
            "gltf" => Some(Format::Gltf),
            "glb" => Some(Format::Glb),
            _ => None,
        }
    }
}

/// Precision of coordinates in outputs that do not follow a PLY layout: the `x y z` type of a plain
/// PLY and the number of digits in OBJ/OFF text. (STL is always single precision; a PLY output
/// from a PLY input keeps the input's property types whatever this says.)
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    /// `f32`: PLY `float`, and text that reads back to the same `f32`.
    #[default]
    Float,
    /// `f64`: PLY `double`, and text that reads back to the same `f64`.
    Double,
}

/// What a reader learned about the input beyond positions and triangles, kept so that a writer can
/// reproduce the input's layout (PLY extra properties, precision, vertex order) and so that `info`
/// can report how the input was interpreted.
#[derive(Clone, Default)]
pub struct Source {
    /// The format the mesh was read from; `None` for generated meshes.
    pub format: Option<Format>,
    /// Number of faces in the input file (before fan triangulation).
    pub input_faces: usize,
    /// Number of input faces with more than 3 corners, fan-triangulated on read.
    pub polygons_triangulated: usize,
    /// Coordinate precision of the input: `Double` for PLY `double` coordinates and for text whose
    /// numbers an `f32` cannot reproduce, else `Float`. Set it to ask a writer for double precision.
    pub precision: Precision,
    /// The decimals every coordinate of a text input (OBJ, OFF) was written with, when that was one
    /// number, at least 4 (a fixed-point export such as `%.6f`): OBJ and OFF outputs then write
    /// coordinates rounded to it, in the shortest text of the rounded value, so that the output is
    /// as precise as the input and no longer. `None`: the shortest text of `precision`.
    pub decimals: Option<u8>,
    /// Corner count of every input face, in order; kept only when some face had more than 3
    /// corners. The mesh's triangles are then the fans of these polygons, which lets writers put the
    /// polygons back.
    pub face_sizes: Option<Arc<Vec<u32>>>,
    /// The layout of the file beyond the above, kept by its reader for a faithful output (a PLY
    /// input's header and extra records); `None` for other inputs and generated meshes. Clear it
    /// after changing the connectivity, to write a plain file.
    pub layout: Option<Arc<dyn FileLayout>>,
}

/// A file's layout as its reader in [`crate::io`] kept it: opaque to everything but that reader's
/// writer, which finds its own type again through [`FileLayout::as_any`].
pub trait FileLayout: fmt::Debug + Send + Sync {
    fn as_any(&self) -> &dyn Any;
    /// What the file carries besides positions and faces, for `info` to report (and the writer of
    /// the same format to keep).
    fn carries(&self) -> Carried {
        Carried::default()
    }
    /// Whether [`FileLayout::vertex_colours`] and [`FileLayout::vertex_uvs`] give values (cheap:
    /// nothing is read).
    fn has_vertex_attributes(&self) -> (bool, bool) {
        (false, false)
    }
    /// One RGB colour per vertex, each channel in `0..=1`, when the file has them per vertex (a
    /// plain glTF output writes them as `COLOR_0`).
    fn vertex_colours(&self) -> Option<Vec<[f32; 3]>> {
        None
    }
    /// One texture coordinate per vertex, as the file has them (origin at the image's bottom
    /// left), when it has them per vertex (a plain glTF output writes them as `TEXCOORD_0`).
    fn vertex_uvs(&self) -> Option<Vec<[f32; 2]>> {
        None
    }
    /// This layout after a subdivision appended vertices at edge midpoints (`parents[i]`: the two
    /// endpoints of vertex `n + i`, `n` the vertex count before; each may itself be a new vertex
    /// earlier in the list) and replaced the faces by `triangles` (`face_of[t]`: the input face
    /// that triangle `t` lies in). `None`: the layout cannot follow, the output is written plain, and
    /// what it carried is dropped (callers compare [`FileLayout::carries`] to say what).
    fn subdivided(
        &self,
        _parents: &[[u32; 2]],
        _triangles: &[[u32; 3]],
        _face_of: &[u32],
    ) -> Option<Arc<dyn FileLayout>> {
        None
    }
}

/// What a file carries besides positions and faces. A writer of the same format keeps all of it
/// (normals are recomputed from the smoothed positions); `info` reports it.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Carried {
    /// Texture coordinates (OBJ `vt`, PLY `u v`/`s t`/`texture_u`, glTF `TEXCOORD_n`, OFF `ST`).
    pub uvs: bool,
    /// Per-vertex or per-face colours (OBJ `v x y z r g b`, PLY `red green blue`, OFF `C`/`COFF`,
    /// glTF `COLOR_n`, STL attribute colours).
    pub colours: bool,
    /// Normals, recomputed on write (OBJ `vn`, PLY `nx ny nz`, glTF `NORMAL`, OFF `N`).
    pub normals: bool,
    /// Materials (OBJ `mtllib`/`usemtl`, glTF materials and images).
    pub materials: bool,
    /// Anything else kept, each named as the file names it (PLY properties and elements, OBJ
    /// statements, STL attribute bytes, glTF attributes and extras).
    pub other: Vec<String>,
}

// By hand: `face_sizes` and `layout` hold millions of entries that a `{:?}` must not dump.
impl fmt::Debug for Source {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Source")
            .field("format", &self.format)
            .field("input_faces", &self.input_faces)
            .field("polygons_triangulated", &self.polygons_triangulated)
            .field("precision", &self.precision)
            .field("face_sizes", &self.face_sizes.as_ref().map(|s| s.len()))
            .field("layout", &self.layout)
            .finish()
    }
}
