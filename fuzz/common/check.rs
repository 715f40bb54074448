//! What every fuzz target asserts about one reader on one input.

use std::path::Path;

use vcsmooth::io::{Format, read_format_bytes, read_mesh_bytes};

/// Decodes `data` with `format`'s reader (and once more through content detection, as
/// `read_mesh` would) and checks the result: an error is one line naming the file; a mesh has
/// finite positions and triangle indices in range, and its face bookkeeping is consistent; an
/// OBJ mesh has a vertex (OBJ has no header: bytes in which no `v` or `f` was recognised are
/// refused, never read as an empty mesh).
pub fn read(data: &[u8], format: Format, name: &str) {
    let name = Path::new(name);
    let own = read_format_bytes(data, format, name);
    if let (Format::Obj, Ok(mesh)) = (format, &own) {
        assert!(!mesh.positions.is_empty(), "an OBJ without vertices accepted");
    }
    check(own, name);
    check(read_mesh_bytes(data, name), name);
}

fn check(result: vcsmooth::Result<vcsmooth::Mesh>, name: &Path) {
    match result {
        Err(e) => {
            let message = e.to_string();
            assert!(!message.contains('\n'), "multi-line error: {message:?}");
            assert!(
                message.starts_with(&format!("{}: ", name.display())),
                "error does not name the file: {message:?}"
            );
        }
        Ok(mesh) => {
            let n = mesh.positions.len();
            assert!(
                mesh.positions.iter().all(|p| p.is_finite()),
                "non-finite position accepted"
            );
            assert!(
                mesh.triangles.iter().flatten().all(|&v| (v as usize) < n),
                "triangle index out of range accepted"
            );
            let s = &mesh.source;
            assert!(s.input_faces <= mesh.triangles.len());
            assert!(s.polygons_triangulated <= s.input_faces);
            if let Some(sizes) = &s.face_sizes {
                assert_eq!(sizes.len(), s.input_faces);
                let fans: usize = sizes.iter().map(|&k| k as usize - 2).sum();
                assert_eq!(fans, mesh.triangles.len());
            }
        }
    }
}
