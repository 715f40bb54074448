//! In-memory mesh storage: f64 working positions and triangles, plus what the writer needs to
//! reproduce the input's layout (extra properties, precision, original polygons).
//!
//! Connectivity lives in [`crate::topology::Topology`], built from `triangles`; positions are kept
//! apart so that kernels can smooth a position buffer against an immutable topology.

use glam::DVec3;

/// A triangle mesh as read from a file.
///
/// - `positions`: one per input vertex, in the input's order (unreferenced vertices included).
/// - `triangles`: vertex indices into `positions`; polygons of the input are fan-triangulated
///   (`(v0, v1, v2), (v0, v2, v3), …`), keeping the input's orientation.
/// - `source`: what the file carried besides them, for a faithful round trip ([`Source`]).
///
/// The arrays are [`Buf`]s: on the heap, or in memory-mapped scratch files for meshes larger than
/// the memory budget (see [`crate::io::read_mesh_in`]); either way they deref to slices.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub positions: Buf<DVec3>,
    pub triangles: Buf<[u32; 3]>,
    pub source: Source,
}

impl Mesh {
    /// A mesh with no source layout: written as a plain `x y z` + triangle list.
    pub fn new(positions: Vec<DVec3>, triangles: Vec<[u32; 3]>) -> Self {
        Mesh {
            positions: positions.into(),
            triangles: triangles.into(),
            source: Default::default(),
        }
    }
}

pub mod source;
pub mod storage;
pub use source::{Carried, FileLayout, Format, Precision, Source};
pub use storage::{Buf, Storage};
