//! Files keep everything they carried: every attribute but positions and normals
//! comes back byte- or value-identical after smoothing, the volume is kept, and `info` says what a
//! file carries. One module a format.

mod draco;
mod gltf;
mod obj;
mod off_stl;
mod packed;
