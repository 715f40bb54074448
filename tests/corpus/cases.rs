//! The hostile-input corpus, generated: every malformed or tricky file the readers must handle,
//! with what each must produce. `tests/hostile.rs` runs every case through the `vcsmooth` binary;
//! `VCSMOOTH_DUMP_CORPUS=DIR cargo test --test tests dump_corpus` writes the files to DIR (the
//! fuzzers' seed corpora are made that way, see `fuzz/README.md`).
//!
//! An error case gives the message after `vcsmooth: error: <path>: `, exactly: it names the
//! element and its byte offset (binary) or line (text). Element numbers count from 0, lines from 1.

use crate::util::{octa_f, octa_v};

/// One file of the corpus.
pub struct Case {
    /// File name; its extension matters for OBJ (no signature) and for unknown formats.
    pub name: &'static str,
    pub bytes: Vec<u8>,
    pub expect: Expect,
}

pub enum Expect {
    /// Refused with exactly this message (after `<path>: `).
    Error(String),
    /// Read and smoothed without complaint.
    Valid,
}

fn error(name: &'static str, bytes: impl Into<Vec<u8>>, what: impl Into<String>) -> Case {
    Case {
        name,
        bytes: bytes.into(),
        expect: Expect::Error(what.into()),
    }
}

fn valid(name: &'static str, bytes: impl Into<Vec<u8>>) -> Case {
    Case {
        name,
        bytes: bytes.into(),
        expect: Expect::Valid,
    }
}

// ---------------------------------------------------------------------------------------------
// Building blocks

/// A unit cube of quads, outward.
const CUBE_OFF: &str = "OFF\n8 6 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n\
                        4 0 3 2 1\n4 4 5 6 7\n4 0 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7\n";
const CUBE_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
                        vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 -1 0\n\
                        f 1 4 3 2\nf 5 6 7 8\nf 1/1 2/2 6/3 5/4\nf 2//1 3//1 7//1 6//1\nf -6 -5 -1 -2\nf 4 1 5 8\n";

const XYZ: &str = "property float x\nproperty float y\nproperty float z\n";
const FACES: &str = "property list uchar int vertex_indices\n";

/// `ply`, a binary little-endian format line, `header` and `end_header`, then `body`.
pub fn ply_le(header: &str, body: &[u8]) -> Vec<u8> {
    let mut bytes =
        format!("ply\nformat binary_little_endian 1.0\n{header}end_header\n").into_bytes();
    bytes.extend_from_slice(body);
    bytes
}

/// Length of [`ply_le`]'s header for `header`: the byte offset of the first record.
pub fn ply_le_header_len(header: &str) -> usize {
    ply_le(header, &[]).len()
}

fn ply_ascii(header: &str, body: &str) -> Vec<u8> {
    format!("ply\nformat ascii 1.0\n{header}end_header\n{body}").into_bytes()
}

fn f32s(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// A binary face record `uchar n, int × n`.
fn face(indices: &[i32]) -> Vec<u8> {
    let mut bytes = vec![indices.len() as u8];
    bytes.extend(indices.iter().flat_map(|v| v.to_le_bytes()));
    bytes
}

/// The header of an `x y z float` + `list uchar int` PLY with these counts.
fn xyz_header(vertices: u64, faces: u64) -> String {
    format!("element vertex {vertices}\n{XYZ}element face {faces}\n{FACES}")
}

/// One triangle: 3 vertices, 1 face (binary little-endian body).
fn triangle_body(indices: &[i32]) -> Vec<u8> {
    let mut body = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    body.extend(face(indices));
    body
}

/// The octahedron as binary little-endian PLY records, with `extra` faces after its own.
fn octa_body(extra: &[&[i32]]) -> Vec<u8> {
    let mut body: Vec<u8> = octa_v().iter().flat_map(|p| f32s(p)).collect();
    for f in octa_f().iter().map(|f| &f[..]).chain(extra.iter().copied()) {
        body.extend(face(f));
    }
    body
}

pub fn octa_ply(extra: &[&[i32]]) -> Vec<u8> {
    ply_le(&xyz_header(6, 8 + extra.len() as u64), &octa_body(extra))
}

/// The octahedron in ASCII PLY lines: `v` lines then faces, joined with `eol`.
fn octa_ascii_ply(eol: &str) -> Vec<u8> {
    let mut text = format!(
        "ply{eol}format ascii 1.0{eol}comment made by a scanner{eol}obj_info serial 42{eol}\
         element vertex 6{eol}property float x{eol}property float y{eol}property float z{eol}\
         element face 8{eol}property list uchar int vertex_indices{eol}end_header{eol}"
    );
    for p in octa_v() {
        text += &format!("{} {} {}{eol}", p[0], p[1], p[2]);
    }
    for f in octa_f() {
        text += &format!("3 {} {} {}{eol}", f[0], f[1], f[2]);
    }
    text.into_bytes()
}

fn octa_obj(eol: &str) -> Vec<u8> {
    let mut text = format!("# exported{eol}o octahedron{eol}");
    for p in octa_v() {
        text += &format!("v {} {} {}{eol}", p[0], p[1], p[2]);
    }
    for f in octa_f() {
        text += &format!("f {} {} {}{eol}", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    text.into_bytes()
}

fn octa_off(eol: &str) -> Vec<u8> {
    let mut text = format!("OFF{eol}# comment{eol}6 8 12{eol}");
    for p in octa_v() {
        text += &format!("{} {} {}{eol}", p[0], p[1], p[2]);
    }
    for f in octa_f() {
        text += &format!("3 {} {} {}{eol}", f[0], f[1], f[2]);
    }
    text.into_bytes()
}

fn octa_stl_ascii(eol: &str) -> Vec<u8> {
    let mut text = format!("solid octa{eol}");
    let corners = octa_v();
    for f in octa_f() {
        text += &format!("facet normal 0 0 0{eol}outer loop{eol}");
        for v in f {
            let p = corners[v as usize];
            text += &format!("vertex {} {} {}{eol}", p[0], p[1], p[2]);
        }
        text += &format!("endloop{eol}endfacet{eol}");
    }
    text += &format!("endsolid octa{eol}");
    text.into_bytes()
}

/// A binary STL: 80-byte header, count, then 50-byte facets (normal, 3 corners, attribute).
fn stl_binary(count: u32, facets: &[[[f32; 3]; 3]]) -> Vec<u8> {
    let mut bytes = b"binary stl".to_vec();
    bytes.resize(80, b' ');
    bytes.extend(count.to_le_bytes());
    for f in facets {
        bytes.extend(f32s(&[0.; 3]));
        for p in f {
            bytes.extend(f32s(p));
        }
        bytes.extend([0, 0]);
    }
    bytes
}

fn octa_facets() -> Vec<[[f32; 3]; 3]> {
    let corners = octa_v();
    octa_f()
        .iter()
        .map(|f| f.map(|v| corners[v as usize]))
        .collect()
}

/// The octahedron with its coordinates stored as PLY type `ty` (offset by `shift` so that unsigned
/// types hold them) and extra vertex properties of every type; the list count is `count_ty` and
/// the index type `index_ty`. Binary little-endian, big-endian or ASCII as `format` says.
fn typed_octa(ty: &str, shift: f64, count_ty: &str, index_ty: &str, format: &str) -> Vec<u8> {
    let extras = [
        "char", "uchar", "short", "ushort", "int", "uint", "float", "double", "int8", "uint8",
        "int16", "uint16", "int32", "uint32", "float32", "float64",
    ];
    let mut header = format!(
        "ply\nformat {format} 1.0\nelement vertex 6\nproperty {ty} x\nproperty {ty} y\nproperty {ty} z\n"
    );
    for (i, e) in extras.iter().enumerate() {
        header += &format!("property {e} extra{i}\n");
    }
    header += &format!(
        "element face 8\nproperty list {count_ty} {index_ty} vertex_indices\nend_header\n"
    );
    let mut bytes = header.into_bytes();
    let big = format.contains("big");
    let ascii = format == "ascii";
    // Every scalar type encoded from a small non-negative value.
    let encode = |bytes: &mut Vec<u8>, ty: &str, v: f64| {
        if ascii {
            bytes.extend(format!("{v} ").into_bytes());
            return;
        }
        let mut le: Vec<u8> = match ty {
            "char" | "int8" => (v as i8).to_le_bytes().to_vec(),
            "uchar" | "uint8" => (v as u8).to_le_bytes().to_vec(),
            "short" | "int16" => (v as i16).to_le_bytes().to_vec(),
            "ushort" | "uint16" => (v as u16).to_le_bytes().to_vec(),
            "int" | "int32" => (v as i32).to_le_bytes().to_vec(),
            "uint" | "uint32" => (v as u32).to_le_bytes().to_vec(),
            "float" | "float32" => (v as f32).to_le_bytes().to_vec(),
            "double" | "float64" => v.to_le_bytes().to_vec(),
            _ => unreachable!("{ty}"),
        };
        if big {
            le.reverse();
        }
        bytes.extend(le);
    };
    for p in octa_v() {
        for c in p {
            encode(&mut bytes, ty, f64::from(c) + shift);
        }
        for (i, e) in extras.iter().enumerate() {
            encode(&mut bytes, e, (i % 100) as f64);
        }
        if ascii {
            bytes.push(b'\n');
        }
    }
    for f in octa_f() {
        encode(&mut bytes, count_ty, 3.);
        for v in f {
            encode(&mut bytes, index_ty, f64::from(v));
        }
        if ascii {
            bytes.push(b'\n');
        }
    }
    bytes
}

// ---------------------------------------------------------------------------------------------
// The corpus

pub fn cases() -> Vec<Case> {
    let tri = xyz_header(3, 1);
    let h = ply_le_header_len(&tri);
    let good = ply_le(&tri, &triangle_body(&[0, 1, 2]));
    let ascii_xyz =
        |vertices: u64, faces: u64, body: &str| ply_ascii(&xyz_header(vertices, faces), body);

    let mut cases = vec![
        // --- any format
        error("empty.ply", b"".to_vec(), "empty file"),
        error("empty.obj", b"".to_vec(), "empty file"),
        error("unknown_format.dat", b"hello world\n".to_vec(), "unknown format: not PLY, GLB, OFF or STL by content, and the extension is not .ply, .obj, .off, .stl, .gltf or .glb"),
        error("unknown_format.ply", b"hello world\n".to_vec(), "not a PLY file (the first line is not 'ply')"),
        error("unknown_format_binary.bin", vec![0x7f, b'E', b'L', b'F', 2, 1, 1, 0], "unknown format: not PLY, GLB, OFF or STL by content, and the extension is not .ply, .obj, .off, .stl, .gltf or .glb"),
        // --- PLY header
        error("missing_end_header.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n".to_vec(), "header: no end_header line (the file ends at line 5)"),
        error("missing_format.ply", b"ply\nelement vertex 0\nproperty float x\nend_header\n".to_vec(), "header: no format line"),
        error("unsupported_version.ply", b"ply\nformat binary_little_endian 2.0\nend_header\n".to_vec(), "header line 2: unsupported PLY version \"2.0\""),
        error("unknown_property_type.ply", ply_le("element vertex 1\nproperty flaot x\n", b""), "header line 4: unknown type \"flaot\""),
        error("property_before_element.ply", ply_le(&format!("{XYZ}element vertex 0\n"), b""), "header line 3: property before any element"),
        error("missing_z.ply", ply_le("element vertex 0\nproperty float x\nproperty float y\n", b""), "the vertex element has no scalar property 'z'"),
        error("negative_count.ply", ply_le(&format!("element vertex -3\n{XYZ}"), b""), "header line 3: element count \"-3\" is not a count"),
        error("count_not_a_number.ply", ply_le(&format!("element vertex 3.5\n{XYZ}"), b""), "header line 3: element count \"3.5\" is not a count"),
        error("binary_header_garbage.ply", ply_le("\u{1}\u{2}\u{3}\n", b""), "header line 3: unknown keyword \"\\u{1}\\u{2}\\u{3}\""),
        // --- PLY counts and data
        error("vertex_count_larger_than_data.ply", ply_le(&xyz_header(4, 1), &triangle_body(&[0, 1, 2])), "face 0 (byte 217): face has 0 vertices, at least 3 are needed"),
        error("face_count_larger_than_data.ply", ply_le(&xyz_header(3, 2), &triangle_body(&[0, 1, 2])), "face 1 (byte 218): file ends inside the record (the header declares 2 face records)"),
        error("truncated_in_vertex.ply", good[..h + 30].to_vec(), "vertex (byte 169): the header declares 3 records of at least 12 bytes, but only 30 bytes are left"),
        error("truncated_in_face.ply", good[..good.len() - 3].to_vec(), "face 0 (byte 205): file ends inside the record (the header declares 1 face records)"),
        error("trillion_vertices.ply", ply_le(&xyz_header(1_000_000_000_000, 1), &[0; 1000]), "vertex (byte 181): the header declares 1000000000000 records of at least 12 bytes, but only 1000 bytes are left"),
        error("u64_max_faces.ply", ply_le(&xyz_header(3, u64::MAX), &triangle_body(&[0, 1, 2])), "face (byte 224): the header declares 18446744073709551615 records of at least 1 bytes, but only 13 bytes are left"),
        error("count_overflows_u64.ply", ply_le(&xyz_header(3, 1).replace("face 1", "face 18446744073709551616"), &triangle_body(&[0, 1, 2])), "header line 7: element count \"18446744073709551616\" is not a count"),
        error("five_billion_vertices_no_data.ply", ply_le(&xyz_header(5_000_000_000, 0), &[]), "vertex (byte 178): the header declares 5000000000 records of at least 12 bytes, but only 0 bytes are left"),
        error("ascii_five_billion_vertices.ply", ascii_xyz(5_000_000_000, 0, "0 0 0\n"), "element vertex 5000000000: more vertices than 32-bit indices can address"),
        error("trailing_garbage.ply", [good.clone(), b"\nGARBAGE".to_vec()].concat(), "byte 219: 7 bytes of unexpected data after the last element"),
        error("trailing_zero_bytes.ply", [good.clone(), vec![0; 4]].concat(), "byte 218: 4 bytes of unexpected data after the last element"),
        error("face_index_out_of_range.ply", ply_le(&tri, &triangle_body(&[0, 1, 3])), "face 0 (byte 205): vertex index 3 out of range (0..3)"),
        error("face_index_negative.ply", ply_le(&tri, &triangle_body(&[0, -1, 2])), "face 0 (byte 205): vertex index -1 is negative"),
        error("face_index_i32_min.ply", ply_le(&tri, &triangle_body(&[0, i32::MIN, 2])), "face 0 (byte 205): vertex index -2147483648 is negative"),
        error("face_with_2_vertices.ply", ply_le(&tri, &triangle_body(&[0, 1])), "face 0 (byte 205): face has 2 vertices, at least 3 are needed"),
        error("face_with_0_vertices.ply", ply_le(&tri, &triangle_body(&[])), "face 0 (byte 205): face has 0 vertices, at least 3 are needed"),
        error("nan_coordinate.ply", { let mut b = good.clone(); b[h + 16..h + 20].copy_from_slice(&f32::NAN.to_le_bytes()); b }, "vertex 1 (byte 181): coordinate is not finite (1, NaN, 0)"),
        error("inf_coordinate.ply", { let mut b = good.clone(); b[h..h + 4].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes()); b }, "vertex 0 (byte 169): coordinate is not finite (-inf, 0, 0)"),
        error("inf_double_coordinate_be.ply", {
            let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\nend_header\n".to_vec();
            b.extend(0f64.to_be_bytes());
            b.extend(f64::INFINITY.to_be_bytes());
            b.extend(0f64.to_be_bytes());
            b
        }, "vertex 0 (byte 115): coordinate is not finite (0, inf, 0)"),
        error("truncated_big_endian.ply", {
            let mut b = format!("ply\nformat binary_big_endian 1.0\n{tri}end_header\n").into_bytes();
            b.extend([0u8; 20]);
            b
        }, "vertex (byte 166): the header declares 3 records of at least 12 bytes, but only 20 bytes are left"),
        // A 260-corner polygon written with a `uchar` count: the count wraps to 4 and the rest
        // of the polygon is read as more data than the header declares.
        error("list_count_uchar_wrapped.ply", {
            let mut body = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
            body.push(4); // 260 mod 256
            body.extend((0..260).flat_map(|i: i32| (i % 3).to_le_bytes()));
            ply_le(&tri, &body)
        }, "byte 222: 1024 bytes of unexpected data after the last element"),
        error("list_count_char_negative.ply", {
            let mut body = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
            body.push(0x80);
            ply_le(&tri.replace("list uchar", "list char"), &body)
        }, "face 0 (byte 204): negative list count -128"),
        error("list_count_uint_huge.ply", {
            let mut body = f32s(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
            body.extend(u32::MAX.to_le_bytes());
            body.extend(0i32.to_le_bytes());
            ply_le(&tri.replace("list uchar", "list uint"), &body)
        }, "face 0 (byte 204): file ends inside the record (the header declares 1 face records)"),
        error("list_count_float_type.ply", ply_le(&tri.replace("list uchar", "list float"), &triangle_body(&[0, 1, 2])), "header line 8: list count type float is not an integer type"),
        error("ascii_list_count_overflows_uchar.ply", ascii_xyz(3, 1, "0 0 0\n1 0 0\n0 1 0\n300 0 1 2\n"), "face 0 (line 13): value 300 does not fit 'vertex_indices' (uchar)"),
        error("ascii_index_overflows_int.ply", ascii_xyz(3, 1, "0 0 0\n1 0 0\n0 1 0\n3 0 1 4294967296\n"), "face 0 (line 13): value 4294967296 does not fit 'vertex_indices' (int)"),
        error("ascii_index_out_of_range.ply", ascii_xyz(3, 1, "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"), "face 0 (line 13): vertex index 3 out of range (0..3)"),
        error("ascii_index_negative.ply", ascii_xyz(3, 1, "0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n"), "face 0 (line 13): vertex index -1 is negative"),
        error("ascii_face_with_2_vertices.ply", ascii_xyz(3, 1, "0 0 0\n1 0 0\n0 1 0\n2 0 1\n"), "face 0 (line 13): face has 2 vertices, at least 3 are needed"),
        error("ascii_nan.ply", ascii_xyz(3, 1, "0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n"), "vertex 1 (line 11): coordinate is not finite (1, NaN, 0)"),
        error("ascii_overflow_to_inf.ply", ascii_xyz(3, 1, "0 0 0\n1 0 1e999\n0 1 0\n3 0 1 2\n"), "vertex 1 (line 11): value \"1e999\" does not fit 'z' (float)"),
        error("ascii_not_a_number.ply", ascii_xyz(3, 1, "0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n"), "vertex 1 (line 11): \"zero\" is not a number ('y' is float)"),
        error("ascii_decimal_comma.ply", ascii_xyz(3, 1, "0 0 0\n1,5 0 0\n0 1 0\n3 0 1 2\n"), "vertex 1 (line 11): \"1,5\" is not a number ('x' is float)"),
        error("ascii_too_few_values.ply", ascii_xyz(3, 1, "0 0 0\n1 0\n0 1 0\n3 0 1 2\n"), "vertex 1 (line 11): too few values: 'z' is missing"),
        error("ascii_counts_larger_than_data.ply", ascii_xyz(4, 1, "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"), "vertex 3 (line 13): unexpected value \"2\" after the last property"),
        error("ascii_trailing_garbage.ply", ascii_xyz(3, 1, "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\nthe end\n"), "line 14: unexpected data after the last element: \"the\""),
        error("ascii_trillion_faces.ply", ascii_xyz(3, 1_000_000_000_000, "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"), "face 1 (line 14): file ends early (the header declares 1000000000000 face records)"),
        // --- OBJ
        error("index_out_of_range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n".to_vec(), "face 0 (line 4): vertex index 4 out of range (1..=3)"),
        error("index_zero.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n".to_vec(), "face 0 (line 4): vertex index 0 (OBJ indices start at 1)"),
        error("relative_index_before_first.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n".to_vec(), "face 0 (line 4): vertex index -4 points before the first vertex (3 defined so far)"),
        error("index_overflows_i64.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n".to_vec(), "face 0 (line 4): \"99999999999999999999\" is not an integer"),
        error("face_with_2_vertices.obj", b"v 0 0 0\nv 1 0 0\nf 1 2\n".to_vec(), "face 0 (line 3): face has 2 vertices, at least 3 are needed"),
        error("nan.obj", b"v 0 0 0\nv NaN 0 0\n".to_vec(), "vertex 1 (line 2): coordinate is not finite (NaN, 0, 0)"),
        error("inf.obj", b"v 0 0 0\nv 0 -inf 0\n".to_vec(), "vertex 1 (line 2): coordinate is not finite (0, -inf, 0)"),
        error("not_a_number.obj", b"v 0 0 0\nv 0 0 1.2.3\n".to_vec(), "vertex 1 (line 2): \"1.2.3\" is not a number"),
        error("two_coordinates.obj", b"v 0 0 0\nv 1 0\n".to_vec(), "vertex 1 (line 2): 2 coordinates, 3 are needed"),
        error("bad_corner.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x 2 3\n".to_vec(), "face 0 (line 4): \"x\" is not an integer"),
        error("binary_junk.obj", vec![b'v', b' ', 0xff, 0xfe, b'\n'], "vertex 0 (line 1): \"\\xff\\xfe\" is not a number"),
        // --- OFF
        error("counts_larger_than_data.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n".to_vec(), "vertex 2 (line 5): file ends early (the header declares 3 vertices)"),
        error("billion_vertices.off", b"OFF\n1000000000 1 0\n0 0 0\n".to_vec(), "vertex 1 (line 4): file ends early (the header declares 1000000000 vertices)"),
        error("negative_count.off", b"OFF\n3 -1 0\n".to_vec(), "counts (line 2): negative count"),
        error("missing_counts.off", b"OFF\n".to_vec(), "line 2: file ends before the counts"),
        error("index_out_of_range.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n".to_vec(), "face 0 (line 6): vertex index 3 out of range (0..3)"),
        error("index_negative.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n".to_vec(), "face 0 (line 6): vertex index -1 is negative"),
        error("face_with_2_vertices.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n".to_vec(), "face 0 (line 6): face has 2 vertices, at least 3 are needed"),
        error("face_count_lies.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n".to_vec(), "face 0 (line 6): face lists 3 vertices but has only 2"),
        error("trailing_garbage.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n".to_vec(), "line 7: unexpected data after the last face: \"3\""),
        error("nan.off", b"OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n".to_vec(), "vertex 1 (line 4): coordinate is not finite (NaN, 0, 0)"),
        error("not_a_number.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 one 0\n3 0 1 2\n".to_vec(), "vertex 2 (line 5): \"one\" is not a number"),
        error("binary.off", b"OFF BINARY\n".to_vec(), "line 1: binary OFF is not supported"),
        // --- STL
        error("shorter_than_header.stl", { let mut b = b"binary".to_vec(); b.resize(50, 0); b }, "binary STL: 50 bytes, shorter than the 84-byte header"),
        error("binary_truncated.stl", stl_binary(2, &octa_facets()[..1]), "binary STL: the header declares 2 triangles (184 bytes) but the file has 134 bytes"),
        error("binary_trailing_garbage.stl", [stl_binary(1, &octa_facets()[..1]), b"junk".to_vec()].concat(), "binary STL: the header declares 1 triangles (134 bytes) but the file has 138 bytes"),
        error("binary_billion_triangles.stl", stl_binary(1_000_000_000, &octa_facets()), "binary STL: the header declares 1000000000 triangles (50000000084 bytes) but the file has 484 bytes"),
        error("binary_nan.stl", stl_binary(1, &[[[0., 0., 0.], [1., f32::NAN, 0.], [0., 1., 0.]]]), "facet 0 (byte 108): coordinate is not finite (1, NaN, 0)"),
        error("binary_inf.stl", stl_binary(1, &[[[0., 0., 0.], [1., 0., 0.], [0., 1., f32::INFINITY]]]), "facet 0 (byte 120): coordinate is not finite (0, 1, inf)"),
        error("ascii_missing_endloop.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendfacet\nendsolid s\n".to_vec(), "facet 0 (line 7): expected 'endloop', found \"endfacet\""),
        error("ascii_truncated.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n".to_vec(), "facet 0 (line 5): file ends early, expected 'endloop'"),
        error("ascii_not_a_number.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 O 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid s\n".to_vec(), "facet 0 (line 5): expected a number, found \"O\""),
        error("ascii_inf.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 1e40\nendloop\nendfacet\nendsolid s\n".to_vec(), "facet 0 (line 6): coordinate is not finite (0, 1, inf)"),
        error("ascii_trailing_garbage.stl", [octa_stl_ascii("\n"), b"garbage\n".to_vec()].concat(), "line 59: expected 'solid', found \"garbage\""),
        error("ascii_facet_with_2_vertices.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid s\n".to_vec(), "facet 0 (line 6): 2 vertices, at least 3 are needed"),
        // --- valid but tricky
        valid("octahedron.ply", octa_ply(&[])),
        valid("crlf_ascii.ply", octa_ascii_ply("\r\n")),
        valid("comments_and_obj_info.ply", octa_ascii_ply("\n")),
        valid("comments_and_obj_info_binary.ply", {
            let mut b = b"ply\nformat binary_little_endian 1.0\ncomment one\ncomment\nobj_info two words\n".to_vec();
            b.extend(xyz_header(6, 8).into_bytes());
            b.extend(b"comment between elements\nend_header\n");
            b.extend(octa_body(&[]));
            b
        }),
        valid("crlf.obj", octa_obj("\r\n")),
        valid("crlf.off", octa_off("\r\n")),
        valid("crlf_ascii.stl", octa_stl_ascii("\r\n")),
        valid("octahedron_binary.stl", stl_binary(8, &octa_facets())),
        valid("binary_header_starting_with_solid.stl", {
            let mut b = stl_binary(8, &octa_facets());
            b[..10].copy_from_slice(b"solid octa");
            b
        }),
        valid("quad_facet.stl", [
            octa_stl_ascii("\n"),
            b"solid quad\nfacet normal 0 0 1\nouter loop\nvertex 5 0 0\nvertex 6 0 0\nvertex 6 1 0\nvertex 5 1 0\nendloop\nendfacet\nendsolid quad\n".to_vec(),
        ].concat()),
        valid("cube_quads.off", CUBE_OFF),
        valid("cube_quads.obj", CUBE_OBJ),
        valid("face_element_first.ply", {
            let mut text = "ply\nformat ascii 1.0\nelement face 8\nproperty list uchar int vertex_indices\nelement vertex 6\n".to_string();
            text += XYZ;
            text += "end_header\n";
            for f in octa_f() {
                text += &format!("3 {} {} {}\n", f[0], f[1], f[2]);
            }
            for p in octa_v() {
                text += &format!("{} {} {}\n", p[0], p[1], p[2]);
            }
            text
        }),
        valid("end_header_crlf_binary.ply", {
            let mut b = b"ply\r\nformat binary_little_endian 1.0\r\n".to_vec();
            b.extend(xyz_header(6, 8).replace('\n', "\r\n").into_bytes());
            b.extend(b"end_header\r\n");
            b.extend(octa_body(&[]));
            b
        }),
        valid("degenerate_and_duplicate_faces.ply", octa_ply(&[&[0, 0, 2], &[4, 4, 4], &[0, 2, 4]])),
        valid("degenerate_and_duplicate_faces.obj", [octa_obj("\n"), b"f 1 1 3\nf 1 3 5\n".to_vec()].concat()),
    ];
    for (ty, shift) in [
        ("char", 1.),
        ("uchar", 10.),
        ("short", 1.),
        ("ushort", 10.),
        ("int", 1.),
        ("uint", 10.),
        ("float", 0.),
        ("double", 0.),
        ("int8", 0.),
        ("uint8", 10.),
        ("int16", 0.),
        ("uint16", 10.),
        ("int32", 0.),
        ("uint32", 10.),
        ("float32", 0.5),
        ("float64", 0.5),
    ] {
        let name: &'static str = format!("coordinates_{ty}.ply").leak();
        cases.push(valid(
            name,
            typed_octa(ty, shift, "uchar", "int", "binary_little_endian"),
        ));
    }
    for (count, index, format) in [
        ("ushort", "uint", "binary_big_endian"),
        ("uint", "ushort", "binary_little_endian"),
        ("uint8", "int32", "ascii"),
        ("int16", "uint32", "binary_big_endian"),
    ] {
        let name: &'static str = format!("list_{count}_{index}_{format}.ply").leak();
        cases.push(valid(name, typed_octa("double", 0., count, index, format)));
    }
    cases.extend(recognition());
    cases
}

/// `text` in UTF-16, little- or big-endian, with or without a byte-order mark.
fn utf16(text: &[u8], big: bool, bom: bool) -> Vec<u8> {
    let mut out = Vec::new();
    let units = std::str::from_utf8(text).unwrap().encode_utf16();
    for u in bom.then_some(0xfeff).into_iter().chain(units) {
        out.extend(if big {
            u.to_be_bytes()
        } else {
            u.to_le_bytes()
        });
    }
    out
}

/// The octahedron as binary STL with every zero coordinate of every other facet written `-0.0`:
/// merged bit for bit, its corners would fall apart into cracks.
pub fn octa_stl_negative_zero() -> Vec<u8> {
    let facets: Vec<[[f32; 3]; 3]> = octa_facets()
        .into_iter()
        .enumerate()
        .map(|(i, f)| f.map(|p| p.map(|x| if x == 0. && i % 2 == 1 { -0. } else { x })))
        .collect();
    stl_binary(facets.len() as u32, &facets)
}

/// The octahedron as ASCII STL with upper- or mixed-case keywords.
pub fn octa_stl_cased(keywords: [&str; 7]) -> Vec<u8> {
    let [solid, facet, outer, vertex, endloop, endfacet, endsolid] = keywords;
    let mut text = format!("{solid} octa\n");
    let corners = octa_v();
    for f in octa_f() {
        text += &format!("{facet} 0 0 0\n{outer}\n");
        for v in f {
            let p = corners[v as usize];
            text += &format!("{vertex} {} {} {}\n", p[0], p[1], p[2]);
        }
        text += &format!("{endloop}\n{endfacet}\n");
    }
    text += &format!("{endsolid} octa\n");
    text.into_bytes()
}

/// The octahedron in each text format with a UTF-8 byte-order mark in front (`name`, bytes).
pub fn octa_with_bom() -> Vec<(&'static str, Vec<u8>)> {
    let bom = |bytes: Vec<u8>| [b"\xef\xbb\xbf".to_vec(), bytes].concat();
    vec![
        ("bom.obj", bom(octa_obj("\n"))),
        ("bom_crlf.obj", bom(octa_obj("\r\n"))),
        ("bom.off", bom(octa_off("\n"))),
        ("bom_ascii.ply", bom(octa_ascii_ply("\n"))),
        ("bom_binary.ply", bom(octa_ply(&[]))),
        ("bom_ascii.stl", bom(octa_stl_ascii("\n"))),
    ]
}

/// `bytes`, gzip-compressed.
fn gz(bytes: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

/// Files in which no mesh format is recognised, or whose text encoding is not one the readers
/// take: each refused with what it looks like, never read as an empty mesh. And the text quirks
/// that are accepted (a UTF-8 byte-order mark, keywords in any case, `-0.0` in STL).
fn recognition() -> Vec<Case> {
    // `v 0 0 0`, `v 1 0 0`, `v 0 1 0`, `f 1 2 3`, gzip-compressed.
    const GZIP: &[u8] = b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x02\x03\x2b\x53\x30\x00\x41\xae\x32\x05\x43\x28\x6d\x00\x62\x71\xa5\x01\x49\x23\x05\x63\x2e\x00\x43\xf9\x6e\x2a\x20\x00\x00\x00";
    // GZIP compressed again.
    const GZIP_TWICE: &[u8] = b"\x1f\x8b\x08\x00\x00\x00\x00\x00\x02\x03\x93\xef\xe6\x60\x00\x01\x26\x66\xed\x60\x03\x06\xc7\x75\x46\xac\xce\x1a\xb9\x0c\x49\x85\x4b\x19\x3d\x95\x59\x93\xf5\x18\x9c\x7f\xe6\x69\x29\x00\xe5\x01\xf8\xac\x4e\x2d\x28\x00\x00\x00";
    let junk =
        |magic: &[u8]| [magic, &b"\x00\x17\xa9junk that follows a magic number"[..]].concat();
    let obj = octa_obj("\n");
    let in_utf16 = "UTF-16 text: save it as UTF-8";
    let bare_cr =
        "lines end with a bare carriage return (classic Mac OS): convert the line endings to LF";
    let no_obj = "no OBJ vertex or face found";
    let mut cases = vec![
        // --- compressed data and archives, whatever the name
        // --- gzip: what it holds is read (an OBJ here), whatever the name; damage is named
        valid("gzip.obj", gz(&obj)),
        valid("mesh.obj.gz", gz(&obj)),
        valid("mesh.ply.gz", gz(&octa_ply(&[]))),
        error(
            "gzip.ply",
            GZIP,
            "not a PLY file (the first line is not 'ply')",
        ),
        error(
            "gzip.stl",
            GZIP,
            "not an STL file: text that does not start with 'solid'",
        ),
        error(
            "cut.obj.gz",
            &GZIP[..GZIP.len() - 12],
            "gzip data ends early: the file is cut short",
        ),
        error(
            "twice.obj.gz",
            GZIP_TWICE,
            "gzip-compressed twice: decompress the outer layer first",
        ),
        error(
            "zip.obj",
            junk(b"PK\x03\x04"),
            "zip archive: extract the mesh first",
        ),
        error(
            "bzip2.off",
            junk(b"BZh9"),
            "bzip2-compressed data: decompress it first",
        ),
        error(
            "xz.stl",
            junk(b"\xfd7zXZ\x00"),
            "xz-compressed data: decompress it first",
        ),
        error(
            "zstd.ply",
            junk(b"\x28\xb5\x2f\xfd"),
            "zstd-compressed data: decompress it first",
        ),
        error(
            "7z.obj",
            junk(b"7z\xbc\xaf\x27\x1c"),
            "7-Zip archive: extract the mesh first",
        ),
        // --- text in another encoding
        error("utf16le_bom.obj", utf16(&obj, false, true), in_utf16),
        error("utf16be_bom.obj", utf16(&obj, true, true), in_utf16),
        error("utf16le_no_bom.obj", utf16(&obj, false, false), in_utf16),
        error("utf16be_no_bom.obj", utf16(&obj, true, false), in_utf16),
        error(
            "utf16le_bom.off",
            utf16(&octa_off("\n"), false, true),
            in_utf16,
        ),
        error(
            "utf16le_no_bom.ply",
            utf16(&octa_ascii_ply("\n"), false, false),
            in_utf16,
        ),
        error(
            "utf16be_no_bom.stl",
            utf16(&octa_stl_ascii("\r\n"), true, false),
            in_utf16,
        ),
        error(
            "utf32le_bom.obj",
            [
                b"\xff\xfe\x00\x00".to_vec(),
                obj.iter().flat_map(|&b| [b, 0, 0, 0]).collect(),
            ]
            .concat(),
            "UTF-32 text: save it as UTF-8",
        ),
        error("cr_only.obj", octa_obj("\r"), bare_cr),
        error("cr_only.off", octa_off("\r"), bare_cr),
        error("cr_only.ply", octa_ascii_ply("\r"), bare_cr),
        error("cr_only.stl", octa_stl_ascii("\r"), bare_cr),
        // --- zeroed files (an unwritten download, a sparse file)
        error(
            "zeros.obj",
            vec![0; 1000],
            "the file is 1000 zero bytes: not a mesh file",
        ),
        error(
            "zeros.ply",
            vec![0; 10],
            "the file is 10 zero bytes: not a mesh file",
        ),
        error(
            "zeros.off",
            vec![0; 2],
            "the file is 2 zero bytes: not a mesh file",
        ),
        error(
            "zeros.stl",
            vec![0; 84],
            "the file is 84 zero bytes: not a mesh file",
        ),
        // --- text or binary data that is not the format its name says
        error(
            "prose.obj",
            "the quick brown fox\njumps over the lazy dog\n",
            no_obj,
        ),
        error(
            "prose_with_punctuation.obj",
            "Hello, reader.\nThis is not a mesh.\n",
            "line 1: \"Hello,\" is not an OBJ statement",
        ),
        error(
            "comments_only.obj",
            "# exported by nothing\n# at all\n",
            no_obj,
        ),
        error("blank_lines_only.obj", "\n  \n\t\r\n", no_obj),
        error(
            "statements_without_geometry.obj",
            "mtllib m.mtl\no empty\ng group\nusemtl red\ns off\n",
            no_obj,
        ),
        error(
            "numbers_first.obj",
            "0 0 0\n1 0 0\n0 1 0\n",
            "line 1: \"0\" is not an OBJ statement",
        ),
        error(
            "nul_bytes.obj",
            [b"\x00\x00\x00\x01v 0 0 0\n".to_vec(), obj.clone()].concat(),
            "line 1: \"\\0\\0\\0\\u{1}v\" is not an OBJ statement",
        ),
        error(
            "invalid_utf8_keyword.obj",
            [obj.clone(), b"\xff\xfe 1 2 3\n".to_vec()].concat(),
            "line 17: \"\\xff\\xfe\" is not an OBJ statement",
        ),
        error(
            "png_named.obj",
            b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00\x01".to_vec(),
            "line 1: \"\\x89PNG\" is not an OBJ statement",
        ),
        error(
            "prose.off",
            "This is not an OFF file.\n",
            "line 1: not an OFF file (\"This\" instead of OFF)",
        ),
        error(
            "prose.stl",
            "hello world\n",
            "not an STL file: text that does not start with 'solid'",
        ),
        error(
            "solid_then_prose.stl",
            "solid s\nhello world\n",
            "facet 0 (line 2): expected 'facet' or 'endsolid', found \"hello\"",
        ),
        // --- digits and separators that are not ASCII
        error(
            "fullwidth_digits.obj",
            "v \u{ff11} 0 0\n",
            "vertex 0 (line 1): \"\u{ff11}\" is not a number",
        ),
        error(
            "arabic_indic_digits.off",
            "OFF\n3 1 0\n\u{661} 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
            "vertex 0 (line 3): \"\u{661}\" is not a number",
        ),
        error(
            "no_break_space.obj",
            "v 0\u{a0}1 0\n",
            "vertex 0 (line 1): \"0\\u{a0}1\" is not a number",
        ),
        error(
            "fullwidth_digits.stl",
            "solid s\nfacet normal 0 0 1\nouter loop\nvertex \u{ff11} 0 0\n",
            "facet 0 (line 4): expected a number, found \"\u{ff11}\"",
        ),
        error(
            "arabic_indic_count.ply",
            ascii_ply_counts("\u{663}"),
            "header line 3: element count \"\u{663}\" is not a count",
        ),
        // --- a binary STL whose header is free-form text
        error(
            "binary_header_with_newlines.stl",
            {
                let mut b = stl_binary(8, &octa_facets());
                b.truncate(b.len() - 1);
                b[..14].copy_from_slice(b"solid x\nfacet\n");
                b
            },
            "binary STL: the header declares 8 triangles (484 bytes) but the file has 483 bytes",
        ),
        // --- accepted
        valid(
            "trailing_statement.obj",
            [obj.clone(), b"the_end of file\n".to_vec()].concat(),
        ),
        valid("negative_zero.stl", octa_stl_negative_zero()),
        valid(
            "uppercase_ascii.stl",
            octa_stl_cased([
                "SOLID",
                "FACET NORMAL",
                "OUTER LOOP",
                "VERTEX",
                "ENDLOOP",
                "ENDFACET",
                "ENDSOLID",
            ]),
        ),
        valid(
            "mixed_case_ascii.stl",
            octa_stl_cased([
                "Solid",
                "Facet Normal",
                "Outer Loop",
                "Vertex",
                "EndLoop",
                "EndFacet",
                "EndSolid",
            ]),
        ),
        valid("binary_header_solid_uppercase.stl", {
            let mut b = stl_binary(8, &octa_facets());
            b[..10].copy_from_slice(b"SOLID octa");
            b
        }),
    ];
    cases.extend(
        octa_with_bom()
            .into_iter()
            .map(|(name, bytes)| valid(name, bytes)),
    );
    cases
}

/// An ASCII PLY of one triangle whose vertex count is `count`.
fn ascii_ply_counts(count: &str) -> String {
    format!("ply\nformat ascii 1.0\nelement vertex {count}\n{XYZ}end_header\n0 0 0\n")
}
