//! Mesh file input and output. Knows nothing of smoothing.
//!
//! - [`read_mesh`] picks the reader from the file's content/extension: PLY (binary little- and
//!   big-endian through a memory-mapped fast path; ASCII and unusual layouts through `ply-rs-bw`),
//!   OBJ, OFF, STL (ASCII and binary).
//! - [`write_mesh`] picks the writer from the output's extension and writes atomically: a temporary
//!   file beside the target, renamed into place only when complete.

use std::path::Path;

use crate::error::Result;
use crate::mesh::Mesh;

/// Mesh file formats vcsmooth reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Format {
    #[default]
    Ply,
    Obj,
    Off,
    Stl,
}

/// What a reader learned about the input beyond positions and triangles, kept so that a writer can
/// reproduce the input's layout (PLY extra properties, precision, vertex order) and so that `info`
/// can report how the input was interpreted.
#[derive(Debug, Clone, Default)]
pub struct Source {
    /// The format the mesh was read from; `None` for generated meshes.
    pub format: Option<Format>,
    /// Number of faces in the input file (before fan triangulation).
    pub input_faces: usize,
    /// Number of input faces with more than 3 corners, fan-triangulated on read.
    pub polygons_triangulated: usize,
}

/// Read a mesh file.
pub fn read_mesh(path: &Path) -> Result<Mesh> {
    let _ = path;
    todo!("io helper")
}

/// Write `mesh` to `path`, choosing the format from the extension, atomically.
pub fn write_mesh(path: &Path, mesh: &Mesh) -> Result<()> {
    let _ = (path, mesh);
    todo!("io helper")
}
