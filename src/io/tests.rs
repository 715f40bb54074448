//! Tests of the readers and writers. `ply-rs-bw` serves as an independent oracle: it produces the
//! big-endian and ASCII versions of files and checks what our writer puts out.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Encoding, Ply, Property};
use ply_rs_bw::writer::Writer;

use super::*;

// ---------------------------------------------------------------------------------------------
// Fixtures and helpers

/// A closed octahedron whose coordinates are not exact `f32`s, with every vertex first used in id
/// order (so that STL's first-appearance numbering gives the same ids back).
fn octahedron() -> Mesh {
    let [a, b, c] = [1.234_567_891_234, 0.876_543_21, 1.111_111_111];
    let o = DVec3::new(0.1, -0.2, 0.3);
    let positions = [
        [a, 0.0, 0.0],
        [0.0, b, 0.0],
        [0.0, 0.0, c],
        [-a, 0.0, 0.0],
        [0.0, -b, 0.0],
        [0.0, 0.0, -c],
    ]
    .map(|p| DVec3::from_array(p) + o)
    .to_vec();
    let triangles = vec![
        [0, 1, 2],
        [1, 3, 2],
        [3, 4, 2],
        [4, 0, 2],
        [1, 0, 5],
        [3, 1, 5],
        [4, 3, 5],
        [0, 4, 5],
    ];
    Mesh::new(positions, triangles)
}

/// A unit cube made of 6 outward quads, kept as polygons.
fn cube() -> Mesh {
    let positions = (0..8)
        .map(|i| DVec3::new((i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2) as f64) * 0.3)
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let triangles = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    let mut mesh = Mesh::new(positions, triangles);
    mesh.source.face_sizes = Some(Arc::new(vec![4; 6]));
    mesh
}

fn rounded(positions: &[DVec3]) -> Vec<DVec3> {
    positions.iter().map(|p| p.as_vec3().as_dvec3()).collect()
}

/// Positions as `f32`: what a single-precision output must reproduce exactly. (Text outputs read
/// back as the decimal they print, the shortest that reads back to the same `f32`.)
fn single(positions: &[DVec3]) -> Vec<glam::Vec3> {
    positions.iter().map(|p| p.as_vec3()).collect()
}

fn roundtrip(mesh: &Mesh, name: &str) -> Mesh {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    write_mesh(&path, mesh).unwrap();
    read_mesh(&path).unwrap()
}

fn write_bytes(mesh: &Mesh, name: &str) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    write_mesh(&path, mesh).unwrap();
    std::fs::read(path).unwrap()
}

/// Parses bytes as if read from a file called `name`.
fn parse_as(bytes: &[u8], name: &str) -> std::result::Result<Mesh, String> {
    parse(bytes, Path::new(name))
}

/// A binary little-endian PLY: `header` lines between `format` and `end_header`, then `body`.
fn binary_ply(header: &str, body: &[u8]) -> Vec<u8> {
    let mut bytes =
        format!("ply\nformat binary_little_endian 1.0\n{header}end_header\n").into_bytes();
    bytes.extend_from_slice(body);
    bytes
}

const XYZ_FACES: &str = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                         element face 1\nproperty list uchar int vertex_indices\n";

fn floats(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn face(indices: &[i32]) -> Vec<u8> {
    let mut bytes = vec![indices.len() as u8];
    bytes.extend(indices.iter().flat_map(|v| v.to_le_bytes()));
    bytes
}

/// A valid one-triangle binary PLY and the length of its header.
fn triangle_ply() -> (Vec<u8>, usize) {
    let header = binary_ply(XYZ_FACES, &[]).len();
    let mut body = floats(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    body.extend(face(&[0, 1, 2]));
    (binary_ply(XYZ_FACES, &body), header)
}

fn meshes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

fn oracle_read(bytes: &[u8]) -> Ply<DefaultElement> {
    Parser::<DefaultElement>::new()
        .read_ply(&mut &bytes[..])
        .expect("ply-rs-bw reads the file")
}

fn oracle_write(ply: &Ply<DefaultElement>, encoding: Encoding) -> Vec<u8> {
    let mut ply = ply.clone();
    ply.header.encoding = encoding;
    let mut out = Vec::new();
    Writer::new()
        .write_ply(&mut out, &mut ply)
        .expect("ply-rs-bw writes the file");
    out
}

fn scalar(p: &Property) -> f64 {
    match *p {
        Property::Char(v) => v.into(),
        Property::UChar(v) => v.into(),
        Property::Short(v) => v.into(),
        Property::UShort(v) => v.into(),
        Property::Int(v) => v.into(),
        Property::UInt(v) => v.into(),
        Property::Float(v) => v.into(),
        Property::Double(v) => v,
        ref list => panic!("not a scalar: {list:?}"),
    }
}

fn list(p: &Property) -> Vec<i64> {
    match p {
        Property::ListUChar(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x.into()).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x.into()).collect(),
        other => panic!("not an integer list: {other:?}"),
    }
}

/// Positions and fan-triangulated faces as ply-rs-bw decodes them.
fn oracle_mesh(ply: &Ply<DefaultElement>) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let positions = ply.payload["vertex"]
        .iter()
        .map(|v| DVec3::new(scalar(&v["x"]), scalar(&v["y"]), scalar(&v["z"])))
        .collect();
    let mut triangles = Vec::new();
    for f in ply.payload.get("face").into_iter().flatten() {
        let c = list(&f["vertex_indices"]);
        triangles.extend(
            c[1..]
                .windows(2)
                .map(|w| [c[0] as u32, w[0] as u32, w[1] as u32]),
        );
    }
    (positions, triangles)
}

// ---------------------------------------------------------------------------------------------
// Round trips

#[test]
fn every_format_round_trips() {
    let mesh = octahedron();
    for name in ["m.ply", "m.obj", "m.off", "m.stl", "M.PLY", "m.Obj"] {
        let back = roundtrip(&mesh, name);
        assert_eq!(
            single(&back.positions),
            single(&mesh.positions),
            "{name}: f32-exact positions"
        );
        if name.ends_with("ply") || name.ends_with("stl") {
            assert_eq!(
                back.positions,
                rounded(&mesh.positions),
                "{name}: binary f32"
            );
        }
        assert_eq!(back.triangles, mesh.triangles, "{name}");
        assert_eq!(back.source.input_faces, 8, "{name}");
        assert_eq!(back.source.polygons_triangulated, 0, "{name}");
        assert_eq!(
            back.source.format,
            Format::from_extension(Path::new(name)),
            "{name}"
        );
    }
}

#[test]
fn second_round_trip_is_exact_and_byte_identical() {
    for name in ["m.ply", "m.obj", "m.off", "m.stl"] {
        let once = roundtrip(&octahedron(), name);
        let twice = roundtrip(&once, name);
        assert_eq!(twice.positions, once.positions, "{name}");
        assert_eq!(
            write_bytes(&once, name),
            write_bytes(&twice, name),
            "{name}"
        );
    }
}

#[test]
fn polygons_are_fan_triangulated_and_written_back_as_polygons() {
    let mesh = cube();
    for name in ["c.ply", "c.obj", "c.off"] {
        let back = roundtrip(&mesh, name);
        assert_eq!(single(&back.positions), single(&mesh.positions), "{name}");
        assert_eq!(back.triangles, mesh.triangles, "{name}");
        assert_eq!(back.source.input_faces, 6, "{name}");
        assert_eq!(back.source.polygons_triangulated, 6, "{name}");
        assert_eq!(
            back.source.face_sizes.as_deref(),
            Some(&vec![4; 6]),
            "{name}"
        );
    }
    let text = String::from_utf8(write_bytes(&mesh, "c.obj")).unwrap();
    assert!(text.contains("\nf 1 3 4 2\n"), "{text}");
    // STL has no polygons: triangles.
    let back = roundtrip(&mesh, "c.stl");
    assert_eq!(back.triangles.len(), 12);
    assert_eq!(back.source.face_sizes, None);
}

#[test]
fn double_precision_stays_double() {
    let mut mesh = octahedron();
    mesh.source.precision = Precision::Double;
    for name in ["d.ply", "d.obj", "d.off"] {
        let back = roundtrip(&mesh, name);
        assert_eq!(back.positions, mesh.positions, "{name}: f64-exact");
        assert_eq!(back.source.precision, Precision::Double, "{name}");
    }
    let bytes = write_bytes(&mesh, "d.ply");
    assert!(bytes.windows(17).any(|w| w == b"property double x"));
    // Text inputs that an f32 reproduces stay single precision.
    let back = roundtrip(&roundtrip(&octahedron(), "f.obj"), "f.off");
    assert_eq!(back.source.precision, Precision::Float);
}

#[test]
fn double_ply_input_stays_double_through_a_ply_round_trip() {
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
                property double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
                0.1 0.2 0.3\n1.000000000001 0 0\n0 1e-300 1\n3 0 1 2\n";
    let mesh = parse_as(text.as_bytes(), "d.ply").unwrap();
    assert_eq!(mesh.positions[1].x, 1.000000000001);
    assert_eq!(mesh.source.precision, Precision::Double);
    let back = roundtrip(&mesh, "d.ply");
    assert_eq!(back.positions, mesh.positions);
    let bytes = write_bytes(&mesh, "d.ply");
    assert!(bytes.starts_with(b"ply\nformat ascii 1.0\n"));
}

/// A `uchar` index list over more than 256 vertices is written back when its faces use only
/// the first 256 (the type must hold the indices, not the vertex count).
#[test]
fn a_uchar_index_list_over_many_vertices_writes_back() {
    let mut text = String::from(
        "ply\nformat ascii 1.0\nelement vertex 300\nproperty float x\nproperty float y\n\
         property float z\nelement face 1\nproperty list uchar uchar vertex_indices\nend_header\n",
    );
    for i in 0..300 {
        text.push_str(&format!("{i} {} 0\n", i % 7));
    }
    text.push_str("3 0 1 255\n");
    let mesh = parse_as(text.as_bytes(), "u.ply").unwrap();
    let back = roundtrip(&mesh, "u.ply");
    assert_eq!(back.triangles.to_vec(), vec![[0, 1, 255]]);
    assert_eq!(back.positions.len(), 300);
}

/// A `double` in any coordinate, not only `x`, keeps every output in double precision.
#[test]
fn a_double_y_or_z_keeps_double_precision() {
    for (types, at) in [
        (["float", "double", "double"], 1),
        (["float", "float", "double"], 2),
    ] {
        let [x, y, z] = types;
        let text = format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty {x} x\nproperty {y} y\n\
             property {z} z\nelement face 1\nproperty list uchar int vertex_indices\n\
             end_header\n0 0.123456789012345 0.123456789012345\n1 0 0\n0 1 0\n3 0 1 2\n"
        );
        let mesh = parse_as(text.as_bytes(), "m.ply").unwrap();
        assert_eq!(mesh.source.precision, Precision::Double, "{types:?}");
        for name in ["m.obj", "m.off"] {
            let back = roundtrip(&mesh, name);
            assert_eq!(back.positions[0][at], 0.123456789012345, "{types:?} {name}");
        }
    }
}

/// A hand-written ASCII PLY with colours, a list between the coordinates and the normals, a quad,
/// face quality, another element, comments and obj_info.
const RICH: &str = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info scanner 42\r\n\
element vertex 5\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\n\
property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\nproperty list uchar float uv\r\n\
property float nx\r\nproperty float ny\r\nproperty float nz\r\nproperty float confidence\r\n\
element face 3\r\nproperty list uchar int vertex_indices\r\nproperty float quality\r\n\
element edge 2\r\nproperty int vertex1\r\nproperty int vertex2\r\nend_header\r\n\
0 0 0 255 0 0 2 0.5 0.25 9 9 9 0.5\r\n\
1 0 0 0 255 0 0 9 9 9 0.25\r\n\
1 1 0 0 0 255 1 7 9 9 9 0.125\r\n\
0 1 0 10 20 30 3 1 2 3 9 9 9 1\r\n\
0.5 0.5 1 1 2 3 0 9 9 9 0.1\r\n\
4 3 2 1 0 0.25\r\n\
3 0 1 4 0.5\r\n\
3 1 2 4 0.75\r\n\
0 4\r\n\
2 3\r\n";

#[test]
fn extra_ply_properties_vertex_order_and_polygons_survive_in_every_encoding() {
    let input = oracle_read(RICH.as_bytes());
    for encoding in [
        Encoding::Ascii,
        Encoding::BinaryLittleEndian,
        Encoding::BinaryBigEndian,
    ] {
        let bytes = oracle_write(&input, encoding);
        let mut mesh = parse_as(&bytes, "rich.ply").unwrap();
        assert_eq!(mesh.positions.len(), 5);
        assert_eq!(mesh.triangles, [[3, 2, 1], [3, 1, 0], [0, 1, 4], [1, 2, 4]]);
        assert_eq!(
            (mesh.source.input_faces, mesh.source.polygons_triangulated),
            (3, 1)
        );
        // Smoothing moves vertices, nothing else.
        for p in &mut mesh.positions {
            *p = *p * 2.0 + DVec3::new(0.1, 0.2, 0.3);
        }
        let out = write_bytes(&mesh, "out.ply");
        let expected_format = match encoding {
            Encoding::Ascii => "format ascii 1.0",
            _ => "format binary_little_endian 1.0", // big-endian becomes little-endian
        };
        assert!(
            out.starts_with(format!("ply\n{expected_format}\n").as_bytes()),
            "{encoding:?}"
        );

        let output = oracle_read(&out);
        assert_eq!(output.header.comments, ["made by hand"], "{encoding:?}");
        assert_eq!(output.header.obj_infos, ["scanner 42"], "{encoding:?}");
        let names = |ply: &Ply<DefaultElement>| -> Vec<(String, Vec<String>)> {
            ply.header
                .elements
                .values()
                .map(|e| (e.name.clone(), e.properties.keys().cloned().collect()))
                .collect()
        };
        assert_eq!(
            names(&output),
            names(&input),
            "{encoding:?}: same elements and properties"
        );
        let normals = vertex_normals(&mesh.positions, &mesh.triangles);
        for (i, (a, b)) in input.payload["vertex"]
            .iter()
            .zip(&output.payload["vertex"])
            .enumerate()
        {
            for key in ["red", "green", "blue", "uv", "confidence"] {
                assert_eq!(a[key], b[key], "{encoding:?} vertex {i} {key}");
            }
            let p = DVec3::new(scalar(&b["x"]), scalar(&b["y"]), scalar(&b["z"]));
            assert_eq!(
                p,
                mesh.positions[i].as_vec3().as_dvec3(),
                "{encoding:?}: moved, in vertex order"
            );
            let n = DVec3::new(scalar(&b["nx"]), scalar(&b["ny"]), scalar(&b["nz"]));
            assert_eq!(
                n,
                normals[i].as_vec3().as_dvec3(),
                "{encoding:?}: normals recomputed"
            );
        }
        assert_eq!(
            input.payload["face"], output.payload["face"],
            "{encoding:?}: faces as they were"
        );
        assert_eq!(
            input.payload["edge"], output.payload["edge"],
            "{encoding:?}: other elements kept"
        );
        assert_eq!(
            Property::Float(0.1),
            output.payload["vertex"][4]["confidence"],
            "{encoding:?}"
        );
    }
}

#[test]
fn recomputed_normals_are_area_weighted_and_unit() {
    // Two triangles at a right angle, areas 1/2 (normal +z) and 1 (normal +y): the shared
    // vertices' normal leans twice as much to the bigger one.
    let p = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 2.]]
        .map(DVec3::from_array)
        .to_vec();
    let n = vertex_normals(&p, &[[0, 1, 2], [0, 3, 1]]);
    let expected = DVec3::new(0.0, 2.0, 1.0).normalize();
    assert!(
        (n[0] - expected).length() < 1e-15 && (n[1] - expected).length() < 1e-15,
        "{n:?}"
    );
    assert_eq!(n[2], DVec3::Z);
    let alone = vertex_normals(&p, &[[0, 1, 1]]);
    assert_eq!(alone, [DVec3::ZERO; 4], "no area, no direction");
}

#[test]
fn every_scalar_type_reads_and_round_trips_in_every_encoding() {
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty char a\nproperty uchar b\n\
                property short c\nproperty ushort d\nproperty int e\nproperty uint f\n\
                property float x\nproperty double y\nproperty short z\nproperty double w\n\
                element face 1\nproperty list ushort uint vertex_indices\nend_header\n\
                -128 255 -32768 65535 -2147483648 4294967295 0.5 0.25 -7 1e300\n\
                127 0 32767 0 2147483647 0 1.5 -0.125 12 -1e-300\n\
                0 1 2 3 4 5 -2.5 3.75 -32768 0\n\
                3 2 1 0\n";
    let input = oracle_read(text.as_bytes());
    for encoding in [
        Encoding::Ascii,
        Encoding::BinaryLittleEndian,
        Encoding::BinaryBigEndian,
    ] {
        let mesh = parse_as(&oracle_write(&input, encoding), "types.ply").unwrap();
        assert_eq!(
            mesh.positions[0],
            DVec3::new(0.5, 0.25, -7.0),
            "{encoding:?}"
        );
        assert_eq!(
            mesh.positions[2],
            DVec3::new(-2.5, 3.75, -32768.0),
            "{encoding:?}"
        );
        assert_eq!(mesh.triangles, [[2, 1, 0]], "{encoding:?}");
        let output = oracle_read(&write_bytes(&mesh, "types.ply"));
        assert_eq!(
            output.payload, input.payload,
            "{encoding:?}: every value as it was"
        );
    }
    // The sized type names and `vertex_index` read the same.
    let aliases = text
        .replace("char a", "int8 a")
        .replace("uchar b", "uint8 b")
        .replace("float x", "float32 x")
        .replace("double y", "float64 y")
        .replace("uint vertex_indices", "uint32 vertex_index");
    let mesh = parse_as(aliases.as_bytes(), "aliases.ply").unwrap();
    assert_eq!(
        mesh.positions,
        parse_as(text.as_bytes(), "t.ply").unwrap().positions
    );
    assert_eq!(mesh.triangles, [[2, 1, 0]]);
}

#[test]
fn integer_coordinates_that_no_longer_fit_are_refused() {
    let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty uchar x\nproperty uchar y\n\
                property uchar z\nend_header\n1 2 3\n";
    let mut mesh = parse_as(text.as_bytes(), "u.ply").unwrap();
    mesh.positions[0].y = 300.0;
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("u.ply");
    let e = write_mesh(&target, &mesh).unwrap_err().to_string();
    assert!(
        e.contains("vertex 0: coordinate 300 does not fit PLY property 'y' (uchar)"),
        "{e}"
    );
    assert!(!target.exists());
}

// ---------------------------------------------------------------------------------------------
// Real meshes

#[test]
fn the_shared_meshes_read_with_their_documented_counts() {
    let expected = [
        ("fertility-9k.ply", 4_494, 9_000),
        ("demosthenes-17k.ply", 8_394, 16_719),
        ("kitten-25k.ply", 12_623, 25_246),
        ("stanford-bunny.ply", 35_947, 69_451),
        ("armadillo-86k.ply", 43_243, 86_482),
        ("horse.ply", 48_485, 96_966),
    ];
    for (name, vertices, faces) in expected {
        let path = meshes_dir().join(name);
        let mesh = read_mesh(&path).unwrap_or_else(|e| panic!("{e} (the tests read tests/data)"));
        assert_eq!(
            (mesh.positions.len(), mesh.triangles.len()),
            (vertices, faces),
            "{name}"
        );
        assert_eq!(mesh.source.input_faces, faces, "{name}");
        assert_eq!(mesh.source.polygons_triangulated, 0, "{name}");
        // The same numbers as an independent decoder.
        let (positions, triangles) = oracle_mesh(&oracle_read(&std::fs::read(&path).unwrap()));
        assert_eq!(mesh.positions, positions, "{name}");
        assert_eq!(mesh.triangles, triangles, "{name}");
    }
}

#[test]
fn big_endian_and_ascii_versions_read_the_same_as_little_endian() {
    for name in ["kitten-25k.ply", "fertility-9k.ply"] {
        let bytes = std::fs::read(meshes_dir().join(name)).unwrap();
        let little = parse_as(&bytes, name).unwrap();
        let ply = oracle_read(&bytes);
        for encoding in [Encoding::BinaryBigEndian, Encoding::Ascii] {
            let mesh = parse_as(&oracle_write(&ply, encoding), name).unwrap();
            assert_eq!(mesh.positions, little.positions, "{name} {encoding:?}");
            assert_eq!(mesh.triangles, little.triangles, "{name} {encoding:?}");
        }
    }
}

#[test]
fn a_real_mesh_round_trips_through_every_format() {
    let mesh = read_mesh(&meshes_dir().join("fertility-9k.ply")).unwrap();
    let ply = write_bytes(&mesh, "f.ply");
    assert_eq!(
        ply,
        std::fs::read(meshes_dir().join("fertility-9k.ply")).unwrap(),
        "byte-identical PLY"
    );
    for name in ["f.obj", "f.off"] {
        let back = roundtrip(&mesh, name);
        assert_eq!(single(&back.positions), single(&mesh.positions), "{name}");
        assert_eq!(back.triangles, mesh.triangles, "{name}");
    }
    // STL numbers vertices by first appearance: the same triangles, corner by corner.
    let corners = |m: &Mesh| -> Vec<DVec3> {
        m.triangles
            .iter()
            .flatten()
            .map(|&v| m.positions[v as usize])
            .collect()
    };
    let back = roundtrip(&mesh, "f.stl");
    assert_eq!(corners(&back), corners(&mesh));
    assert_eq!(
        back.positions.len(),
        mesh.positions.len(),
        "every corner merged back into its vertex"
    );
}

// ---------------------------------------------------------------------------------------------
// Other readers' details

#[test]
fn obj_corner_forms_negative_indices_and_ignored_statements() {
    let text = "# a comment\r\nmtllib x.mtl\r\no thing\r\nv 0 0 0\r\nv 1 0 0 # inline comment\r\n\
                v 1 1 0 0.5 0.5 0.5\r\nv 0 1 0\r\nvt 0 0\r\nvn 0 0 1\r\ns off\r\nusemtl m\r\n\
                f 1/1/1 2/1/1 3/1/1 4/1/1\r\nf -4//1 -2//1 -1//1\r\nf 1/1 2/1 3/1\r\nl 1 2\r\n";
    let mesh = parse_as(text.as_bytes(), "m.obj").unwrap();
    assert_eq!(mesh.positions.len(), 4);
    assert_eq!(mesh.triangles, [[0, 1, 2], [0, 2, 3], [0, 2, 3], [0, 1, 2]]);
    assert_eq!(
        (mesh.source.input_faces, mesh.source.polygons_triangulated),
        (3, 1)
    );
    // Faces may come before the vertices they use.
    let forward = parse_as(b"f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", "m.obj").unwrap();
    assert_eq!(forward.triangles, [[0, 1, 2]]);
}

#[test]
fn off_variants_comments_and_colours() {
    let text = "# comment first\nCOFF\n4 2 0\n0 0 0 1 0 0 1\n1 0 0 0 1 0 1\n1 1 0 0 0 1 1\n\
                0 1 0 1 1 1 1\n3 0 1 2 255 0 0\n3 0 2 3 # no colour\n\n";
    let mesh = parse_as(text.as_bytes(), "m.off").unwrap();
    assert_eq!(mesh.triangles, [[0, 1, 2], [0, 2, 3]]);
    let same_line = parse_as(b"OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2 2\n", "m.off").unwrap();
    assert_eq!(
        same_line.triangles,
        [[0, 1, 2], [0, 2, 2]],
        "degenerate polygon kept"
    );
}

#[test]
fn stl_merges_equal_corners_only() {
    let facet = |corners: [[f32; 3]; 3]| {
        let mut b = vec![0; 12];
        b.extend(corners.iter().flatten().flat_map(|x| x.to_le_bytes()));
        b.extend([0, 0]);
        b
    };
    // The header starts with "solid", as many binary exporters write: the size decides.
    let mut bytes = b"solid but binary".to_vec();
    bytes.resize(80, b' ');
    bytes.extend(3u32.to_le_bytes());
    bytes.extend(facet([[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]]));
    bytes.extend(facet([[1., 0., 0.], [1., 1., 0.], [0., 1., 0.]]));
    bytes.extend(facet([[-0., 0., -0.], [1., 0., 0.], [0., 1., 0.]]));
    let mesh = parse_as(&bytes, "m.stl").unwrap();
    assert_eq!(mesh.positions.len(), 4, "-0.0 is merged with 0.0");
    assert_eq!(mesh.triangles, [[0, 1, 2], [1, 3, 2], [0, 1, 2]]);
    // A vertex is placed where it first appears: a -0.0 seen first stays -0.0 (the output bytes
    // of a mesh without mixed zeros are those of a bitwise merge).
    let first_negative = [&bytes[..84], &bytes[84 + 100..], &bytes[84..84 + 100]].concat();
    let mesh = parse_as(&first_negative, "m.stl").unwrap();
    assert_eq!(mesh.triangles, [[0, 1, 2], [0, 1, 2], [1, 3, 2]]);
    assert!(mesh.positions[0].x.is_sign_negative() && mesh.positions[0].z.is_sign_negative());
    // Nearby but different values stay apart.
    let tiny = facet([[f32::MIN_POSITIVE, 0., 0.], [1., 0., 0.], [0., 1., 0.]]);
    let mut apart = [&bytes[..84 + 100], &tiny[..]].concat();
    apart[80..84].copy_from_slice(&3u32.to_le_bytes());
    assert_eq!(parse_as(&apart, "m.stl").unwrap().positions.len(), 5);

    let ascii = "solid name with words\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n\
                 vertex 1 0 0\n   vertex 1 1 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid name\n\
                 solid second\nfacet normal 0 0 0 outer loop vertex 0 0 0 vertex 1 1 0 vertex 1 0 0 \
                 endloop endfacet\nendsolid\n";
    let mesh = parse_as(ascii.as_bytes(), "m.stl").unwrap();
    assert_eq!(mesh.positions.len(), 4);
    assert_eq!(mesh.triangles, [[0, 1, 2], [0, 2, 3], [0, 2, 1]]);
    assert_eq!(mesh.source.polygons_triangulated, 1);
}

#[test]
fn degenerate_and_duplicate_faces_are_kept() {
    let mut body = floats(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    for f in [[0, 1, 2], [0, 1, 2], [0, 0, 1]] {
        body.extend(face(&f));
    }
    let bytes = binary_ply(&XYZ_FACES.replace("face 1", "face 3"), &body);
    let mesh = parse_as(&bytes, "d.ply").unwrap();
    assert_eq!(mesh.triangles, [[0, 1, 2], [0, 1, 2], [0, 0, 1]]);
    assert_eq!(roundtrip(&mesh, "d.ply").triangles, mesh.triangles);
}

#[test]
fn trailing_whitespace_and_empty_meshes_are_valid() {
    let (mut bytes, _) = triangle_ply();
    bytes.extend(b"\r\n \n");
    assert_eq!(parse_as(&bytes, "t.ply").unwrap().triangles, [[0, 1, 2]]);
    let empty = binary_ply(
        "element vertex 0\nproperty float x\nproperty float y\nproperty float z\n",
        b"",
    );
    let mesh = parse_as(&empty, "e.ply").unwrap();
    assert!(mesh.positions.is_empty() && mesh.triangles.is_empty());
    assert_eq!(roundtrip(&mesh, "e.ply").positions, []);
}

// ---------------------------------------------------------------------------------------------
// Bad input: every case must give InvalidInput with this message.

#[test]
fn malformed_inputs_give_clear_one_line_errors() {
    let (good, header) = triangle_ply();
    let with_face = |f: &[i32]| {
        let mut body = floats(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
        body.extend(face(&[0, 1, 2]));
        body.extend(face(f));
        binary_ply(&XYZ_FACES.replace("face 1", "face 2"), &body)
    };
    let second_face = header + 36 + 13;
    let ascii = |body: &str| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
             property uchar red\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n{body}"
        )
        .into_bytes()
    };
    let mut nan = good.clone();
    nan[header + 16..header + 20].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut big = good.clone();
    big.extend(b"\nxyz");
    let lying = binary_ply(
        &XYZ_FACES.replace("vertex 3", "vertex 4000000000"),
        &good[header..],
    );
    let lying_start = lying.len() - (good.len() - header);
    let lying_faces = binary_ply(
        &XYZ_FACES.replace("face 1", "face 1000000000000"),
        &good[header..],
    );
    let lying_faces_start = lying_faces.len() - (good.len() - header) + 36;
    // In ASCII the data's size says nothing about the counts: the index width is the first limit.
    let too_many = format!(
        "ply\nformat ascii 1.0\n{}end_header\n0 0 0\n",
        XYZ_FACES.replace("vertex 3", "vertex 5000000000")
    )
    .into_bytes();
    let mut stl_truncated = b"solid exported as binary".to_vec();
    stl_truncated.resize(80, b' ');
    stl_truncated.extend(1u32.to_le_bytes());
    stl_truncated.resize(120, 0);
    let stl_ascii = "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendfacet\n";

    let cases: Vec<(&str, Vec<u8>, String)> = vec![
        ("e.ply", vec![], "empty file".into()),
        ("x.dat", b"hello world\n".to_vec(), "unknown format".into()),
        ("x.ply", b"hello world\n".to_vec(), "not a PLY file".into()),
        ("h.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n".to_vec(), "no end_header".into()),
        ("h.ply", b"ply\nformat binary_little_endian 2.0\nend_header\n".to_vec(), "unsupported PLY version".into()),
        ("h.ply", b"ply\nelement vertex 1\nproperty float x\nend_header\n".to_vec(), "no format line".into()),
        ("h.ply", binary_ply("element vertex 1\nproperty flaot x\n", b""), "header line 4: unknown type \"flaot\"".into()),
        ("h.ply", binary_ply("element vertex 1\nproperty list float int x\n", b""), "not an integer type".into()),
        ("h.ply", binary_ply("element vertex -1\nproperty float x\n", b""), "is not a count".into()),
        ("h.ply", binary_ply("element point 1\nproperty float x\n", &[0; 4]), "no 'vertex' element".into()),
        ("h.ply", binary_ply("element vertex 0\nproperty float x\nproperty float y\n", b""), "no scalar property 'z'".into()),
        ("h.ply", binary_ply("element vertex 0\nelement face 0\n", b""), "element 'vertex' has no properties".into()),
        ("h.ply", binary_ply("element vertex 1\nproperty float x\nproperty float x\n", b""), "a second property 'x'".into()),
        ("h.ply", binary_ply("bogus line\n", b""), "header line 3: unknown keyword \"bogus\"".into()),
        (
            "l.ply",
            lying,
            format!("vertex (byte {lying_start}): the header declares 4000000000 records of at least 12 bytes, but only 49 bytes are left"),
        ),
        (
            "l.ply",
            lying_faces,
            format!("face (byte {lying_faces_start}): the header declares 1000000000000 records of at least 1 bytes, but only 13 bytes are left"),
        ),
        ("l.ply", too_many, "element vertex 5000000000: more vertices than 32-bit indices can address".into()),
        ("t.ply", good[..good.len() - 3].to_vec(), format!("face 0 (byte {}): file ends inside the record", header + 36)),
        ("t.ply", good[..header + 30].to_vec(), format!("vertex (byte {header}): the header declares 3 records")),
        ("g.ply", big, format!("byte {}: 3 bytes of unexpected data after the last element", good.len() + 1)),
        ("n.ply", nan, format!("vertex 1 (byte {}): coordinate is not finite (1, NaN, 0)", header + 12)),
        ("r.ply", with_face(&[0, 1, 99]), format!("face 1 (byte {second_face}): vertex index 99 out of range (0..3)")),
        ("r.ply", with_face(&[0, -1, 2]), format!("face 1 (byte {second_face}): vertex index -1 is negative")),
        ("r.ply", with_face(&[0, 1]), format!("face 1 (byte {second_face}): face has 2 vertices, at least 3 are needed")),
        ("a.ply", ascii("0 0 0 1\n1 0 0 2\n3 0 1 2\n"), "face 0 (line 13): vertex index 2 out of range (0..2)".into()),
        ("a.ply", ascii("0 0 0 1\n1 zero 0 2\n3 0 1 1\n"), "vertex 1 (line 12): \"zero\" is not a number ('y' is float)".into()),
        ("a.ply", ascii("0 0 0 1\n1 inf 0 2\n3 0 1 1\n"), "vertex 1 (line 12): coordinate is not finite (1, inf, 0)".into()),
        ("a.ply", ascii("0 0 0 1\n1 0 0 300\n3 0 1 1\n"), "vertex 1 (line 12): value 300 does not fit 'red' (uchar)".into()),
        ("a.ply", ascii("0 0 0 1\n1 1e39 0 2\n3 0 1 1\n"), "vertex 1 (line 12): value \"1e39\" does not fit 'y' (float)".into()),
        ("a.ply", ascii("0 0 0 1 7\n1 0 0 2\n3 0 1 1\n"), "vertex 0 (line 11): unexpected value \"7\" after the last property".into()),
        ("a.ply", ascii("0 0 0 1\n1 0 0\n3 0 1 1\n"), "vertex 1 (line 12): too few values: 'red' is missing".into()),
        ("a.ply", ascii("0 0 0 1\n\n1 0 0 2\n3 0 1 1\n"), "vertex 1 (line 12): too few values".into()),
        ("a.ply", ascii("0 0 0 1\n1 0 0 2\n3 0 1 1\n3 0 1 1\n"), "line 14: unexpected data after the last element".into()),
        ("a.ply", ascii("0 0 0 1\n1 0 0 2\n"), "face 0 (line 13): file ends early".into()),
        ("a.ply", ascii("0 0 0 1\n1 0 0 2\n3 0 1.5 1\n"), "face 0 (line 13): \"1.5\" is not an integer".into()),
        (
            "c.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
              element face 1\nproperty list char int vertex_indices\nend_header\n0 0 0\n-1\n"
                .to_vec(),
            "face 0 (line 11): negative list count -1".into(),
        ),
        ("m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n".to_vec(), "face 0 (line 4): vertex index 9 out of range (1..=3)".into()),
        ("m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n".to_vec(), "face 0 (line 4): vertex index 0 (OBJ indices start at 1)".into()),
        ("m.obj", b"v 0 0 0\nf -1 -2 -3\n".to_vec(), "vertex index -2 points before the first vertex".into()),
        ("m.obj", b"v 0 0 0\nv 1 nan 0\n".to_vec(), "vertex 1 (line 2): coordinate is not finite".into()),
        ("m.obj", b"v 0 0 0\nv 1 x 0\n".to_vec(), "vertex 1 (line 2): \"x\" is not a number".into()),
        ("m.obj", b"v 0 0 0\nv 1 0\n".to_vec(), "vertex 1 (line 2): 2 coordinates, 3 are needed".into()),
        ("m.obj", b"v 0 0 0\nv 1 0 0\nf 1 2\n".to_vec(), "face 0 (line 3): face has 2 vertices".into()),
        ("m.obj", b"v 0 0 0\nf 1/x 1 1\n".to_vec(), "face 0 (line 2): \"x\" is not an integer".into()),
        ("m.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n".to_vec(), "vertex 2 (line 5): file ends early (the header declares 3 vertices)".into()),
        ("m.off", b"OFF\n1 1000000 0\n0 0 0\n3 0 0 0\n".to_vec(), "face 1 (line 5): file ends early (the header declares 1000000 faces)".into()),
        ("m.off", b"OFF\n3 -1 0\n".to_vec(), "counts (line 2): negative count".into()),
        ("m.off", b"OFF\n3\n".to_vec(), "counts (line 2): expected 'vertices faces edges'".into()),
        ("m.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n".to_vec(), "face 0 (line 6): vertex index 3 out of range (0..3)".into()),
        ("m.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n".to_vec(), "line 7: unexpected data after the last face".into()),
        ("m.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n".to_vec(), "face 0 (line 6): face lists 3 vertices but has only 2".into()),
        ("m.off", b"OFF BINARY\n".to_vec(), "binary OFF is not supported".into()),
        ("m.off", b"4OFF\n".to_vec(), "(4-D or n-D OFF) is not supported".into()),
        ("m.stl", [vec![b' '; 99], vec![0]].concat(), "binary STL: the header declares 538976288 triangles (26948814484 bytes) but the file has 100 bytes".into()),
        ("m.stl", [vec![0xff; 49], vec![0]].concat(), "binary STL: 50 bytes, shorter than the 84-byte header".into()),
        ("m.stl", vec![0; 100], "the file is 100 zero bytes: not a mesh file".into()),
        ("m.stl", stl_truncated, "binary STL: the header declares 1 triangles (134 bytes) but the file has 120 bytes".into()),
        ("m.stl", stl_ascii.as_bytes().to_vec(), "facet 0 (line 7): expected 'endloop', found \"endfacet\"".into()),
        ("m.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n".to_vec(), "facet 0 (line 5): file ends early, expected 'endloop'".into()),
        ("m.stl", b"solid s\nfacet normal 0 0 1 outer loop vertex 0 0 inf".to_vec(), "facet 0 (line 2): coordinate is not finite".into()),
        ("m.stl", b"solid s\nendsolid\ngarbage\n".to_vec(), "line 3: expected 'solid', found \"garbage\"".into()),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes, expected) in &cases {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        match read_mesh(&path) {
            Err(e @ Error::InvalidInput { .. }) => {
                let message = e.to_string();
                assert!(
                    message.contains(expected.as_str()),
                    "{name}: {message:?} lacks {expected:?}"
                );
                assert!(
                    message.starts_with(&path.display().to_string()),
                    "{message}"
                );
                assert!(!message.contains('\n'), "one line: {message:?}");
            }
            other => panic!("{name} ({expected}): {other:?}"),
        }
    }
    assert!(cases.len() >= 40);
}

#[test]
fn a_header_claiming_a_trillion_vertices_fails_fast() {
    let (good, header) = triangle_ply();
    for count in ["4000000000", "1000000000000", "18446744073709551615"] {
        let bytes = binary_ply(
            &XYZ_FACES.replace("face 1", &format!("face {count}")),
            &good[header..],
        );
        let start = std::time::Instant::now();
        let e = parse_as(&bytes, "l.ply").unwrap_err();
        assert!(
            start.elapsed().as_millis() < 100 && e.contains(count),
            "{e}"
        );
    }
    let ascii = "ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n\
                 property float z\nend_header\n0 0 0\n";
    let e = parse_as(ascii.as_bytes(), "a.ply").unwrap_err();
    assert!(
        e.contains(
            "vertex 1 (line 9): file ends early (the header declares 4000000000 vertex records)"
        ),
        "{e}"
    );
    let off = b"OFF\n1000000000 1 0\n0 0 0\n";
    let e = parse_as(off, "m.off").unwrap_err();
    assert!(
        e.contains("vertex 1 (line 4): file ends early (the header declares 1000000000 vertices)"),
        "{e}"
    );
}

/// Every truncation and many random byte changes of valid files of every format: an error or a
/// mesh, never a panic, and errors stay on one line.
#[test]
fn damaged_files_never_panic() {
    let mut samples: Vec<(&str, Vec<u8>)> = vec![
        ("r.ply", RICH.as_bytes().to_vec()),
        ("t.ply", triangle_ply().0),
        ("c.obj", write_bytes(&cube(), "c.obj")),
        ("c.off", write_bytes(&cube(), "c.off")),
        ("c.stl", write_bytes(&cube(), "c.stl")),
        ("s.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid s\n".to_vec()),
    ];
    let rich = oracle_read(RICH.as_bytes());
    samples.push(("le.ply", oracle_write(&rich, Encoding::BinaryLittleEndian)));
    samples.push(("be.ply", oracle_write(&rich, Encoding::BinaryBigEndian)));
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut random = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for (name, bytes) in &samples {
        let check = |bytes: &[u8]| {
            if let Err(e) = parse_as(bytes, name) {
                assert!(!e.contains('\n'), "{name}: {e:?}");
            }
        };
        for len in 0..bytes.len() {
            check(&bytes[..len]);
        }
        for _ in 0..2000 {
            let mut damaged = bytes.clone();
            for _ in 0..1 + random() % 3 {
                let at = random() as usize % damaged.len();
                damaged[at] = match random() % 4 {
                    0 => random() as u8,
                    1 => b'\n',
                    2 => b'9',
                    _ => 0xff,
                };
            }
            check(&damaged);
        }
    }
}

/// A file held open reads again as it first read, whatever happened to its name (renamed away,
/// deleted); rewritten in place (another size, another modification time), the second read is an
/// error that says nothing was written.
#[test]
fn a_kept_file_reads_again_unless_it_changed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.ply");
    let heap = crate::mesh::Storage::heap();
    let mesh = crate::shapes::icosphere(2);
    write_mesh(&path, &mesh).unwrap();
    // As stored (the positions rounded to the file's `float`).
    let stored = read_mesh(&path).unwrap();
    let kept = || {
        let (first, kept) = read_mesh_kept(&path, &heap, &Meter::default()).unwrap();
        assert_eq!(&first.triangles[..], &stored.triangles[..]);
        kept.expect("a file is kept")
    };
    let same = |again: Result<(Mesh, usize)>| {
        let (again, vertices) = again.unwrap();
        assert_eq!(&again.triangles[..], &stored.triangles[..]);
        assert_eq!(&again.positions[..], &stored.positions[..]);
        assert_eq!(vertices, stored.positions.len());
    };
    let decode = Coordinates::Decode;
    same(kept().read_again(&heap, &Meter::default(), decode));
    let k = kept();
    std::fs::rename(&path, dir.path().join("away.ply")).unwrap();
    same(k.read_again(&heap, &Meter::default(), decode));
    std::fs::rename(dir.path().join("away.ply"), &path).unwrap();
    let k = kept();
    std::fs::remove_file(&path).unwrap();
    same(k.read_again(&heap, &Meter::default(), decode));
    write_mesh(&path, &mesh).unwrap();

    let changed = |change: &dyn Fn(&Path), what: &str| {
        write_mesh(&path, &mesh).unwrap();
        let k = kept();
        change(&path);
        let e = k
            .read_again(&heap, &Meter::default(), Coordinates::Skip)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            format!(
                "{}: file changed on disk during the run ({what}); nothing was written",
                path.display()
            )
        );
    };
    let len = std::fs::metadata(&path).unwrap().len();
    changed(
        &|p| {
            let mut f = std::fs::OpenOptions::new().append(true).open(p).unwrap();
            f.write_all(b"more").unwrap();
        },
        &format!("size {len} -> {} bytes", len + 4),
    );
    changed(
        &|p| {
            let f = std::fs::OpenOptions::new().write(true).open(p).unwrap();
            let mtime = f.metadata().unwrap().modified().unwrap();
            f.set_modified(mtime + std::time::Duration::from_secs(5))
                .unwrap();
        },
        "modification time changed",
    );
}

/// Issue #33: the write's second read of its input passes over the coordinates it has no use
/// for, so that the disk holds the triangles alone beside the smoothed positions: binary (both
/// byte orders) and ASCII PLY, records of one length or with a list among the vertex properties
/// (and a colour), plain or compressed. The triangles and the vertex count are the first read's;
/// the scratch files made are the triangles' alone (other formats decode the positions anyway).
#[test]
fn reading_again_without_coordinates_keeps_the_triangles_alone() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = crate::shapes::icosphere(2);
    let (n, m) = (mesh.positions.len(), mesh.triangles.len());
    // The sphere with a colour and, with `list`, a list of 0–2 tags among the vertex properties,
    // as ASCII; its binary encodings through ply-rs-bw.
    let ascii = |list: bool| -> Vec<u8> {
        let tags = match list {
            true => "property list uchar int tags\n",
            false => "",
        };
        let mut text = format!(
            "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\n{tags}\
             property float y\nproperty float z\nproperty uchar red\nelement face {m}\n\
             property list uchar int vertex_indices\nend_header\n"
        );
        for (k, p) in mesh.positions.iter().enumerate() {
            let listed = match list {
                true => format!(" {}{}", k % 3, " 7".repeat(k % 3)),
                false => String::new(),
            };
            text += &format!("{}{listed} {} {} {}\n", p.x, p.y, p.z, k % 256);
        }
        for t in mesh.triangles.iter() {
            text += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
        }
        text.into_bytes()
    };
    let mut files = Vec::new();
    for list in [false, true] {
        let text = ascii(list);
        let parsed = oracle_read(&text);
        let encodings = [
            ("ascii", text),
            ("le", oracle_write(&parsed, Encoding::BinaryLittleEndian)),
            ("be", oracle_write(&parsed, Encoding::BinaryBigEndian)),
        ];
        for (name, bytes) in encodings {
            let path = dir.path().join(format!("{name}-{list}.ply"));
            std::fs::write(&path, bytes).unwrap();
            files.push((path, true));
        }
    }
    let packed = dir.path().join("packed.ply.gz");
    let listed_be = oracle_write(&oracle_read(&ascii(true)), Encoding::BinaryBigEndian);
    std::fs::write(&packed, gz(&listed_be)).unwrap();
    files.push((packed, true));
    let obj = dir.path().join("m.obj");
    write_mesh(&obj, &mesh).unwrap();
    files.push((obj, false));
    for (path, skips) in &files {
        let (path, skips) = (path, *skips);
        let first = read_mesh(path).unwrap();
        assert_eq!(&first.triangles[..], &mesh.triangles[..], "{path:?}");
        for coordinates in [Coordinates::Skip, Coordinates::Decode] {
            let scratch_dir = tempfile::tempdir().unwrap();
            let scratch = crate::mesh::Storage::scratch(scratch_dir.path()).unwrap();
            let (_, kept) = read_mesh_kept(path, &scratch, &Meter::default()).unwrap();
            let before = scratch.mapped_bytes();
            let (again, vertices) = kept
                .unwrap()
                .read_again(&scratch, &Meter::default(), coordinates)
                .unwrap();
            let made = scratch.mapped_bytes() - before;
            assert_eq!(&again.triangles[..], &mesh.triangles[..], "{path:?}");
            assert_eq!(vertices, n, "{path:?}");
            // A small compressed file is inflated in memory: only the arrays are in scratch.
            if skips && coordinates == Coordinates::Skip {
                assert!(again.positions.is_empty(), "{path:?}");
                assert_eq!(made, 12 * m as u64, "{path:?}: the triangles alone");
            } else {
                assert_eq!(&again.positions[..], &first.positions[..], "{path:?}");
                if skips {
                    assert_eq!(made, (24 * n + 12 * m) as u64, "{path:?}");
                }
            }
        }
    }
}

#[test]
fn a_file_changed_while_it_is_read_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.ply");
    let (good, _) = triangle_ply();
    let heap = crate::mesh::Storage::heap();
    let read = |change: &dyn Fn(&Path)| {
        read_mesh_observed(&path, &heap, &Meter::default(), change)
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    let changed = |change: &dyn Fn(&Path)| {
        std::fs::write(&path, &good).unwrap();
        read(change)
    };
    let message = |what: &str| {
        format!(
            "{}: file changed while it was being read ({what})",
            path.display()
        )
    };
    let append = |p: &Path| {
        let mut f = std::fs::OpenOptions::new().append(true).open(p).unwrap();
        f.write_all(b"more").unwrap();
    };
    let truncate = |p: &Path| {
        let f = std::fs::OpenOptions::new().write(true).open(p).unwrap();
        f.set_len(10).unwrap();
    };
    let touch = |p: &Path| {
        let f = std::fs::OpenOptions::new().write(true).open(p).unwrap();
        let mtime = f.metadata().unwrap().modified().unwrap();
        f.set_modified(mtime + std::time::Duration::from_secs(5))
            .unwrap();
    };
    let n = good.len();
    assert_eq!(
        changed(&append),
        Err(message(&format!("size {n} -> {} bytes", n + 4)))
    );
    assert_eq!(
        changed(&truncate),
        Err(message(&format!("size {n} -> 10 bytes")))
    );
    assert_eq!(changed(&touch), Err(message("modification time changed")));
    // The change is reported rather than what the decode made of the bytes it saw.
    std::fs::write(&path, &good[..n - 1]).unwrap();
    assert_eq!(
        read(&append),
        Err(message(&format!("size {} -> {} bytes", n - 1, n + 3)))
    );
    // A new file renamed over the path is another inode: the opened one reads consistently.
    let replace = |p: &Path| {
        let other = p.with_extension("new");
        std::fs::write(&other, b"junk").unwrap();
        std::fs::rename(&other, p).unwrap();
    };
    assert_eq!(changed(&replace), Ok(()));
    assert_eq!(changed(&|_| ()), Ok(()));
}

// ---------------------------------------------------------------------------------------------
// Writing

#[test]
fn failed_writes_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut bad = octahedron();
    bad.positions[3].y = f64::NAN;
    let target = dir.path().join("nan.ply");
    let e = write_mesh(&target, &bad).unwrap_err();
    assert!(
        matches!(e, Error::InvalidInput { .. })
            && e.to_string().contains("vertex 3 has a non-finite"),
        "{e}"
    );

    let mut out_of_range = octahedron();
    out_of_range.triangles[2][1] = 6;
    write_mesh(&dir.path().join("range.obj"), &out_of_range).unwrap_err();

    let huge = Mesh::new(vec![DVec3::splat(1e300)], vec![]);
    let e = write_mesh(&dir.path().join("huge.stl"), &huge).unwrap_err();
    assert!(
        e.to_string().contains("does not fit single precision"),
        "{e}"
    );

    let e = write_mesh(&dir.path().join("mesh.xyz"), &octahedron()).unwrap_err();
    assert!(
        matches!(e, Error::InvalidInput { .. })
            && e.to_string().contains("mesh.xyz: unknown output extension"),
        "{e}"
    );

    // A directory where the output should go: the final rename fails after a complete write.
    let blocked = dir.path().join("blocked.ply");
    std::fs::create_dir(&blocked).unwrap();
    write_mesh(&blocked, &octahedron()).unwrap_err();
    assert!(blocked.is_dir());

    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left, ["blocked.ply"], "no output, no temporary file");
}

#[test]
fn a_source_layout_that_no_longer_matches_the_mesh_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = parse_as(RICH.as_bytes(), "rich.ply").unwrap();

    let mut fewer = mesh.clone();
    fewer.positions.heap_mut().pop();
    fewer.triangles.heap_mut().clear();
    let e = write_mesh(&dir.path().join("a.ply"), &fewer)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("the mesh has 4 vertices but its PLY source has 5"),
        "{e}"
    );

    let mut rewired = mesh.clone();
    rewired.triangles[0] = [0, 1, 2];
    let e = write_mesh(&dir.path().join("b.ply"), &rewired)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no longer match the PLY source's faces"), "{e}");
    let e = write_mesh(&dir.path().join("b.obj"), &rewired)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no longer match the source's polygons (face 0)"),
        "{e}"
    );

    // Clearing the source writes the plain layout instead.
    rewired.source = Source::default();
    let back = roundtrip(&rewired, "c.ply");
    assert_eq!(back.triangles, rewired.triangles);
    assert!(std::fs::read_dir(dir.path()).unwrap().next().is_none());
}

#[test]
fn plain_ply_layout_is_the_documented_one() {
    let bytes = write_bytes(&octahedron(), "o.ply");
    let header = "ply\nformat binary_little_endian 1.0\nelement vertex 6\nproperty float x\nproperty float y\n\
                  property float z\nelement face 8\nproperty list uchar int vertex_indices\nend_header\n";
    assert!(bytes.starts_with(header.as_bytes()));
    assert_eq!(bytes.len(), header.len() + 6 * 12 + 8 * 13);
}

#[test]
fn source_debug_does_not_dump_data() {
    let mesh = read_mesh(&meshes_dir().join("kitten-25k.ply")).unwrap();
    let text = format!("{:?}", mesh.source);
    assert!(
        text.len() < 2000 && text.contains("BinaryLittleEndian"),
        "{text}"
    );
}

/// The parallel binary decoders (fixed-size chunks of vertices and triangles) against the
/// sequential rules: the first bad record is the one reported, wherever the chunk boundaries fall,
/// and a polygon far into the face list still goes through the general path.
#[test]
fn parallel_binary_decode_reports_the_first_problem_and_handles_late_polygons() {
    let n = 100_000usize; // several decoder chunks of vertices and of faces
    let header = |faces: usize| {
        format!(
            "element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n\
             element face {faces}\nproperty list uchar int vertex_indices\n"
        )
    };
    let coords: Vec<f32> = (0..3 * n).map(|i| (i % 97) as f32).collect();
    let tris: Vec<[i32; 3]> = (0..n as i32 - 2).map(|i| [i, i + 1, i + 2]).collect();
    let body = |coords: &[f32], faces: &[Vec<i32>]| {
        let mut b = floats(coords);
        for f in faces {
            b.extend(face(f));
        }
        b
    };
    let faces: Vec<Vec<i32>> = tris.iter().map(|t| t.to_vec()).collect();

    let ok = parse_as(
        &binary_ply(&header(faces.len()), &body(&coords, &faces)),
        "a.ply",
    )
    .unwrap();
    assert_eq!(ok.triangles.len(), tris.len());
    assert_eq!(ok.triangles[77_777], [77_777, 77_778, 77_779]);
    assert_eq!(ok.positions[n - 1].z, coords[3 * n - 1] as f64);

    // Two bad indices in different chunks: the first is reported.
    let mut bad = faces.clone();
    bad[90_000][1] = n as i32;
    bad[70_000][2] = -1;
    let e = parse_as(
        &binary_ply(&header(bad.len()), &body(&coords, &bad)),
        "b.ply",
    )
    .unwrap_err();
    assert!(e.contains("face 70000") || e.contains("70000"), "{e}");
    assert!(!e.contains("90000"), "{e}");

    // Two non-finite coordinates in different chunks: the first vertex is reported.
    let mut nan = coords.clone();
    nan[3 * 80_000] = f32::NAN;
    nan[3 * 40_000 + 1] = f32::INFINITY;
    let e = parse_as(
        &binary_ply(&header(faces.len()), &body(&nan, &faces)),
        "c.ply",
    )
    .unwrap_err();
    assert!(e.contains("40000") && !e.contains("80000"), "{e}");

    // A quad late in the list: fan-triangulated, everything before it intact.
    let mut quad = faces.clone();
    quad[95_000] = vec![1, 2, 3, 4];
    let m = parse_as(
        &binary_ply(&header(quad.len()), &body(&coords, &quad)),
        "d.ply",
    )
    .unwrap();
    assert_eq!(m.triangles.len(), tris.len() + 1);
    assert_eq!(m.triangles[94_999], [94_999, 95_000, 95_001]);
    assert_eq!(&m.triangles[95_000..95_002], &[[1, 2, 3], [1, 3, 4]]);
    assert_eq!(m.source.polygons_triangulated, 1);
}

// ---------------------------------------------------------------------------------------------
// Recognition: nothing unrecognised reads as a mesh

/// Prose, zeros, compressed data, other encodings: under every name, refused, never an empty mesh.
#[test]
fn unrecognised_bytes_are_refused_under_every_name() {
    let obj = write_bytes(&octahedron(), "o.obj");
    let utf16: Vec<u8> = obj.iter().flat_map(|&b| [b, 0]).collect();
    let inputs: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "prose",
            b"the quick brown fox\njumps over the lazy dog\n".to_vec(),
            "",
        ),
        (
            "zeros",
            vec![0; 300],
            "the file is 300 zero bytes: not a mesh file",
        ),
        (
            "xz",
            [&b"\xfd7zXZ\x00"[..], &obj].concat(),
            "xz-compressed data: decompress it first",
        ),
        ("utf16", utf16.clone(), "UTF-16 text: save it as UTF-8"),
        (
            "utf16 bom",
            [&b"\xff\xfe"[..], &utf16].concat(),
            "UTF-16 text: save it as UTF-8",
        ),
        (
            "cr",
            obj.iter()
                .map(|&b| if b == b'\n' { b'\r' } else { b })
                .collect(),
            "lines end with a bare carriage return",
        ),
    ];
    for ext in ["obj", "ply", "off", "stl", "dat"] {
        let name = format!("m.{ext}");
        for (what, bytes, message) in &inputs {
            let e = parse_as(bytes, &name)
                .map(|m| m.positions.len())
                .unwrap_err();
            assert!(
                e.starts_with(message) && !e.contains('\n'),
                "{what} as {name}: {e}"
            );
        }
    }
    // What each reader says about prose on its own.
    let prose = &inputs[0].1;
    for (name, message) in [
        ("m.obj", "no OBJ vertex or face found"),
        ("m.ply", "not a PLY file (the first line is not 'ply')"),
        ("m.off", "line 1: not an OFF file (\"the\" instead of OFF)"),
        (
            "m.stl",
            "not an STL file: text that does not start with 'solid'",
        ),
    ] {
        assert_eq!(parse_as(prose, name).map(|_| ()), Err(message.into()));
    }
}

#[test]
fn obj_keeps_unknown_statements_and_refuses_what_is_not_a_statement() {
    let mut text = String::from_utf8(write_bytes(&octahedron(), "o.obj")).unwrap();
    text += "vendor_ext 1 2 3\nZBrushPolyGroup 4\nthe end\n";
    let mesh = parse_as(text.as_bytes(), "m.obj").unwrap();
    assert_eq!(mesh.triangles.len(), 8);
    for (line, shown) in [
        ("1.5 2 3", "\"1.5\""),
        ("-v 0 0 0", "\"-v\""),
        ("\u{e9}t\u{e9}", "\"\u{e9}t\u{e9}\""),
    ] {
        let bad = format!("{text}{line}\n");
        assert_eq!(
            parse_as(bad.as_bytes(), "m.obj").map(|_| ()),
            Err(format!(
                "line {}: {shown} is not an OBJ statement",
                text.lines().count() + 1
            ))
        );
    }
    // Vertices alone are a mesh (a point cloud); a file with neither is not.
    assert_eq!(parse_as(b"v 0 0 0\n", "m.obj").unwrap().positions.len(), 1);
    assert_eq!(
        parse_as(b"o thing\ng part\n", "m.obj").map(|_| ()),
        Err("no OBJ vertex or face found".into())
    );
}

/// The same file with and without a UTF-8 byte-order mark reads the same, in every text format;
/// a binary PLY's byte offsets still count from the file's first byte.
#[test]
fn a_utf8_byte_order_mark_is_skipped_in_every_text_format() {
    let rich = oracle_read(RICH.as_bytes());
    let samples = [
        ("m.obj", write_bytes(&octahedron(), "m.obj")),
        ("m.off", write_bytes(&cube(), "m.off")),
        ("m.ply", RICH.as_bytes().to_vec()),
        ("b.ply", oracle_write(&rich, Encoding::BinaryLittleEndian)),
        ("m.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid s\n".to_vec()),
    ];
    for (name, bytes) in samples {
        let plain = parse_as(&bytes, name).unwrap();
        let marked = parse_as(&[&b"\xef\xbb\xbf"[..], &bytes].concat(), name).unwrap();
        assert_eq!(marked.positions[..], plain.positions[..], "{name}");
        assert_eq!(marked.triangles[..], plain.triangles[..], "{name}");
        assert!(!plain.positions.is_empty());
    }
    let (mut good, header) = triangle_ply();
    good[header..header + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let marked = [&b"\xef\xbb\xbf"[..], &good].concat();
    assert_eq!(
        parse_as(&marked, "n.ply").map(|_| ()),
        Err(format!(
            "vertex 0 (byte {}): coordinate is not finite (NaN, 0, 0)",
            header + 3
        ))
    );
}

#[test]
fn header_lines_are_bounded() {
    let long = "x".repeat(super::MAX_HEADER_LINE);
    let refused = |name: &str, text: String, message: &str| {
        let start = std::time::Instant::now();
        assert_eq!(
            parse_as(text.as_bytes(), name).map(|_| ()),
            Err(message.into())
        );
        assert!(start.elapsed().as_millis() < 500);
    };
    // One byte over the limit is refused; the limit itself is a line like any other.
    refused(
        "m.ply",
        format!("ply\nformat ascii 1.0\ncomment {long}\n"),
        "header line 3 is longer than 64 KiB",
    );
    let at_limit = format!(
        "ply\nformat ascii 1.0\ncomment {}\nend_header\n",
        &long[8..]
    );
    assert_eq!(
        parse_as(at_limit.as_bytes(), "m.ply").map(|_| ()),
        Err("no 'vertex' element".into())
    );
    refused(
        "m.off",
        format!("OFF {long}\n"),
        "line 1 is longer than 64 KiB",
    );
    refused(
        "m.off",
        format!("OFF\n3 1 0 {long}\n"),
        "line 2 is longer than 64 KiB",
    );
    refused(
        "m.stl",
        format!("solid {long}\n"),
        "line 1: the solid's name runs on for more than 64 KiB",
    );
    refused(
        "m.stl",
        format!(
            "solid s\nfacet normal 0 0 1 outer loop vertex 0 0 0 vertex 1 0 0 vertex 0 1 0 endloop endfacet\nendsolid {long}\n"
        ),
        "line 3: the solid's name runs on for more than 64 KiB",
    );
}

// ---------------------------------------------------------------------------------------------
// Positions as stored

/// The bits of each coordinate (`-0.0` and `0.0` differ).
fn bits(positions: &[DVec3]) -> Vec<[u64; 3]> {
    positions
        .iter()
        .map(|p| p.to_array().map(f64::to_bits))
        .collect()
}

/// Writes `mesh` as `name` and checks that [`Stored::round`] gives, bit for bit, the positions
/// that read back: by vertex, or by triangle corner for STL (which renumbers its vertices).
fn assert_stored_reads_back(mesh: &Mesh, name: &str) {
    let stored = Stored::of(Path::new(name), mesh).unwrap();
    let back = roundtrip(mesh, name);
    let expected: Vec<DVec3> = mesh.positions.iter().map(|&p| stored.round(p)).collect();
    if name.ends_with(".stl") {
        let corners = |m: &[[u32; 3]], p: &[DVec3]| -> Vec<DVec3> {
            m.iter().flatten().map(|&v| p[v as usize]).collect()
        };
        assert_eq!(
            bits(&corners(&back.triangles, &back.positions)),
            bits(&corners(&mesh.triangles, &expected)),
            "{name}"
        );
    } else {
        assert_eq!(bits(&back.positions), bits(&expected), "{name}");
    }
    assert_eq!(
        stored.is_exact(),
        bits(&expected) == bits(&mesh.positions),
        "{name}: exact only if nothing is rounded"
    );
}

/// Moves every vertex by an amount no float type holds exactly, scaled so that coordinates span
/// many magnitudes (text in single precision switches to the exponent form outside 1e-5..1e16).
fn moved(mesh: &Mesh, scale: f64) -> Mesh {
    let mut m = mesh.clone();
    for (k, p) in m.positions.iter_mut().enumerate() {
        *p = (*p * 1.000_000_123_456 + DVec3::new(0.012_345_678_9, -0.3, 1e-3) * k as f64) * scale;
    }
    m
}

#[test]
fn stored_positions_are_those_read_back_in_every_format_and_layout() {
    for scale in [1.0, 1e-7, 3.3e4, 1e18] {
        let mesh = moved(&octahedron(), scale);
        for name in ["m.ply", "m.obj", "m.off", "m.stl"] {
            assert_stored_reads_back(&mesh, name);
        }
        let mut double = mesh.clone();
        double.source.precision = Precision::Double;
        for name in ["d.ply", "d.obj", "d.off", "d.stl"] {
            assert_stored_reads_back(&double, name);
        }
    }
    // Layouts kept from the input: PLY with every coordinate type (float, double, short) in
    // every encoding, ASCII STL, OBJ and OFF text with extra columns.
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty double y\n\
                property short z\nproperty uchar red\nelement face 1\n\
                property list uchar int vertex_indices\nend_header\n\
                0.5 0.25 -7 1\n1.5 -0.125 12 2\n-2.5 3.75 -300 3\n3 0 1 2\n";
    let input = oracle_read(text.as_bytes());
    for encoding in [
        Encoding::Ascii,
        Encoding::BinaryLittleEndian,
        Encoding::BinaryBigEndian,
    ] {
        let mesh = parse_as(&oracle_write(&input, encoding), "t.ply").unwrap();
        assert_stored_reads_back(&moved(&mesh, 1.7), "t.ply");
        assert_stored_reads_back(&moved(&mesh, 1.7), "t.obj");
    }
    let stl = "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n\
               endloop\nendfacet\nendsolid s\n";
    let mesh = parse_as(stl.as_bytes(), "s.stl").unwrap();
    assert_stored_reads_back(&moved(&mesh, 0.37), "s.stl");
    let obj = "# kept\nv 0.1 0.2 0.3 1.0\nv 1 0 0\nv 0 1 0.000001\nvt 0 0\nf 1/1 2/1 3/1\n";
    let mesh = parse_as(obj.as_bytes(), "o.obj").unwrap();
    for scale in [0.37, 1e-9, 1e20] {
        assert_stored_reads_back(&moved(&mesh, scale), "o.obj");
    }
    let off = "COFF\n3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n3 0 1 2\n";
    let mesh = parse_as(off.as_bytes(), "c.off").unwrap();
    assert_stored_reads_back(&moved(&mesh, 0.37), "c.off");
    let mesh = read_mesh(&meshes_dir().join("fertility-9k.ply")).unwrap();
    for name in ["f.ply", "f.obj", "f.off", "f.stl"] {
        assert_stored_reads_back(&moved(&mesh, 1.0), name);
    }
    assert_eq!(Stored::of(Path::new("m.xyz"), &octahedron()), None);
}

/// Normals stored in integer types are written as normalized integers (`char` n × 127, `uchar`
/// (n + 1) / 2 × 255, …), pointing where the float normals of the same mesh point: not rounded
/// to -1, 0 or 1.
#[test]
fn integer_normals_are_written_as_normalized_integers() {
    let header = |t: &str| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n\
             property float z\nproperty {t} nx\nproperty {t} ny\nproperty {t} nz\n\
             element face 8\nproperty list uchar int vertex_indices\nend_header\n"
        )
    };
    let oct = octahedron();
    let body = |zero: &str| {
        let mut b = String::new();
        for p in oct.positions.iter() {
            // Tilted, so that the normals have components other than 0 and ±1.
            let q = DVec3::new(
                p.x * 1.5 + 0.25 * p.y,
                p.y + 0.3 * p.z,
                p.z * 0.75 + 0.2 * p.x,
            );
            b += &format!("{} {} {} {zero} {zero} {zero}\n", q.x, q.y, q.z);
        }
        for t in oct.triangles.iter() {
            b += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
        }
        b
    };
    let normals_of = |t: &str, zero: &str| -> Vec<[f64; 3]> {
        let mesh = parse_as(format!("{}{}", header(t), body(zero)).as_bytes(), "n.ply").unwrap();
        let out = String::from_utf8(write_bytes(&mesh, "out.ply")).unwrap();
        let rows = out.split("end_header\n").nth(1).unwrap().lines().take(6);
        rows.map(|r| {
            let f: Vec<f64> = r.split(' ').map(|x| x.parse().unwrap()).collect();
            [f[3], f[4], f[5]]
        })
        .collect()
    };
    let want = normals_of("float", "0");
    for (t, zero, decode) in [
        ("char", "0", (|x: f64| x / 127.0) as fn(f64) -> f64),
        ("short", "0", |x| x / 32767.0),
        ("uchar", "127", |x| x / 255.0 * 2.0 - 1.0),
        ("ushort", "32767", |x| x / 65535.0 * 2.0 - 1.0),
    ] {
        let got = normals_of(t, zero);
        for (g, w) in got.iter().zip(&want) {
            let g = DVec3::from(g.map(decode));
            let w = DVec3::from(*w);
            assert!(
                w.length() > 0.99 && g.angle_between(w) < 0.02,
                "{t}: {g} vs {w}"
            );
        }
    }
    let inner = |c: &f64| c.abs() > 0.05 && c.abs() < 0.95;
    assert!(
        want.iter().flatten().filter(|c| inner(c)).count() >= 4,
        "{want:?}"
    );
}

/// Points on (and, by an `f64` rounding, just beyond) the sphere of radius `limit` about an
/// origin stored exactly: each rounded as every stored type keeps it, within the bound and a
/// stored value itself.
#[test]
fn round_within_keeps_the_bound_for_every_stored_type() {
    use ply::Scalar::{F32, I16, U8};
    let types = [
        (
            Stored([Axis::Binary(F32); 3]),
            1e-4,
            DVec3::new(60.123, -20.5, 3.25),
        ),
        (
            Stored([Axis::SingleText; 3]),
            1e-4,
            DVec3::new(-8.2311, 0.0039, 21.47),
        ),
        (
            Stored([Axis::Binary(U8); 3]),
            2.5,
            DVec3::new(100.0, 7.0, 250.0),
        ),
        (
            Stored([Axis::Binary(I16); 3]),
            3.7,
            DVec3::new(-300.0, 12.0, 0.0),
        ),
    ];
    let mut moved = 0;
    for (stored, limit, origin) in types {
        let origin = stored.round(origin);
        for k in 0..2000 {
            // Directions spread over the sphere (a spiral), at the bound and one ulp beyond.
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / 2000.0;
            let a = k as f64 * 2.399963;
            let r = (1.0 - z * z).sqrt();
            let dir = DVec3::new(r * a.cos(), r * a.sin(), z);
            let p = origin + dir * limit * (1.0 + f64::EPSILON * (k % 2) as f64);
            let q = stored.round_within(p, origin, limit);
            assert!(q.distance(origin) <= limit, "{stored:?} {p} -> {q}");
            assert_eq!(stored.round(q), q, "{stored:?}: {q} is not a stored value");
            moved += usize::from(stored.round(p) != q);
        }
    }
    // The nearest stored value is beyond the bound for many of them: the rule did work.
    assert!(moved > 1000, "{moved}");
}

// ---------------------------------------------------------------------------------------------
// gzip

fn gz(bytes: &[u8]) -> Vec<u8> {
    let mut e = gzip::encoder(Vec::new());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn same_mesh(a: &Mesh, b: &Mesh) -> bool {
    a.positions[..] == b.positions[..] && a.triangles[..] == b.triangles[..]
}

#[test]
fn gzip_inputs_read_as_what_they_hold_in_memory_in_scratch_and_from_a_stream() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["o.ply", "o.obj", "o.off", "o.stl"] {
        let plain = write_bytes(&octahedron(), name);
        let want = parse_as(&plain, name).unwrap();
        let packed = gz(&plain);
        // Bytes: named with `.gz` or as the format (OBJ has no signature: its name tells).
        for n in [format!("{name}.gz"), name.to_string()] {
            assert!(same_mesh(&parse_as(&packed, &n).unwrap(), &want), "{n}");
        }
        // Two members one after another are one stream, as zcat reads them.
        let (a, b) = plain.split_at(plain.len() / 3);
        let members = [gz(a), gz(b)].concat();
        assert!(same_mesh(
            &parse_as(&members, &format!("{name}.gz")).unwrap(),
            &want
        ));
        // Files: onto the heap, into scratch files (an out-of-core run), and read again.
        let path = dir.path().join(format!("{name}.gz"));
        std::fs::write(&path, &members).unwrap();
        assert!(same_mesh(&read_mesh(&path).unwrap(), &want), "{name}");
        let scratch = crate::mesh::Storage::scratch(dir.path()).unwrap();
        let meter = Meter::new(members.len() as u64);
        let (mesh, kept) = read_mesh_kept(&path, &scratch, &meter).unwrap();
        assert!(same_mesh(&mesh, &want), "{name} in scratch");
        assert_eq!(
            meter.done(),
            members.len() as u64,
            "the compressed bytes are counted"
        );
        let (again, _) = kept
            .unwrap()
            .read_again(&scratch, &Meter::default(), Coordinates::Decode)
            .unwrap();
        assert!(same_mesh(&again, &want));
        // A pipe.
        #[cfg(unix)]
        {
            let fifo = dir.path().join(format!("pipe-{name}"));
            let made = std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .unwrap();
            assert!(made.success());
            let writer = {
                let (fifo, members) = (fifo.clone(), members.clone());
                std::thread::spawn(move || std::fs::write(fifo, members).unwrap())
            };
            let from_pipe = read_mesh(&fifo);
            writer.join().unwrap();
            assert!(same_mesh(&from_pipe.unwrap(), &want), "{name} from a pipe");
        }
    }
    // Nothing of the scratch files is left behind.
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains("scratch"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn damaged_gzip_inputs_say_what_is_wrong() {
    let plain = write_bytes(&octahedron(), "o.ply");
    let packed = gz(&plain);
    let cut = &packed[..packed.len() - 10];
    let mut bad_crc = packed.clone();
    let n = bad_crc.len();
    bad_crc[n - 8] ^= 1;
    let mut bad_data = packed.clone();
    bad_data[12] ^= 0xff;
    let twice = gz(&packed);
    let empty = gz(b"");
    for (what, bytes, message) in [
        (
            "cut",
            cut.to_vec(),
            "gzip data ends early: the file is cut short",
        ),
        ("crc", bad_crc, "gzip data is damaged ("),
        ("data", bad_data, "gzip data is damaged ("),
        (
            "twice",
            twice,
            "gzip-compressed twice: decompress the outer layer first",
        ),
        ("empty", empty, "gzip-compressed, and holds nothing"),
        ("header only", b"\x1f\x8b".to_vec(), "gzip data "),
    ] {
        let e = parse_as(&bytes, "o.ply.gz").map(|_| ()).unwrap_err();
        assert!(e.starts_with(message) && !e.contains('\n'), "{what}: {e}");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("o.ply.gz");
        std::fs::write(&path, &bytes).unwrap();
        let e = read_mesh(&path).map(|_| ()).unwrap_err().to_string();
        assert!(
            e.contains("o.ply.gz: ") && e.contains(message),
            "{what}: {e}"
        );
    }
}

#[test]
fn gz_outputs_are_compressed_and_hold_the_plain_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = octahedron();
    for name in ["o.ply", "o.obj", "o.off", "o.stl"] {
        let plain = write_bytes(&mesh, name);
        let path = dir.path().join(format!("{name}.gz"));
        write_mesh(&path, &mesh).unwrap();
        let packed = std::fs::read(&path).unwrap();
        assert!(gzip::is_gzip(&packed), "{name}");
        let mut inflated = Vec::new();
        flate2::read::GzDecoder::new(&packed[..])
            .read_to_end(&mut inflated)
            .unwrap();
        assert_eq!(inflated, plain, "{name}");
        assert_eq!(
            Format::from_extension(&path),
            Format::from_extension(Path::new(name))
        );
    }
    // The streamed writer too.
    let streamed = dir.path().join("s.ply.gz");
    write_ply_streamed_in(&streamed, Precision::Float, 6, 8, &[], |out| {
        for p in mesh.positions.iter() {
            out.vertex(*p)?;
        }
        for t in mesh.triangles.iter() {
            out.triangle(*t)?;
        }
        Ok(())
    })
    .unwrap();
    let back = read_mesh(&streamed).unwrap();
    assert_eq!(back.triangles[..], mesh.triangles[..]);
    // glTF is refused, and nothing is written.
    let glb = dir.path().join("o.glb.gz");
    let e = write_mesh(&glb, &mesh).unwrap_err().to_string();
    assert!(e.contains("drop the .gz"), "{e}");
    assert!(!glb.exists());
}

// ---------------------------------------------------------------------------------------------
// Triangle strips

/// A PLY of the octahedron's vertices and `strips` (one record each) in a `tristrips` element.
fn strips_ply(ascii: bool, strips: &[&[i32]]) -> Vec<u8> {
    let m = octahedron();
    let format = if ascii {
        "ascii"
    } else {
        "binary_little_endian"
    };
    let mut out = format!(
        "ply\nformat {format} 1.0\nelement vertex 6\nproperty double x\nproperty double y\n\
         property double z\nelement tristrips {}\nproperty list int int vertex_indices\n\
         end_header\n",
        strips.len()
    )
    .into_bytes();
    for p in m.positions.iter() {
        if ascii {
            out.extend(format!("{} {} {}\n", p.x, p.y, p.z).bytes());
        } else {
            p.to_array()
                .iter()
                .for_each(|c| out.extend(c.to_le_bytes()));
        }
    }
    for s in strips {
        if ascii {
            let ids: Vec<String> = s.iter().map(|v| v.to_string()).collect();
            out.extend(format!("{} {}\n", s.len(), ids.join(" ")).bytes());
        } else {
            out.extend((s.len() as i32).to_le_bytes());
            s.iter().for_each(|v| out.extend(v.to_le_bytes()));
        }
    }
    out
}

#[test]
fn triangle_strips_become_triangles_of_one_orientation_and_are_written_back() {
    // Triangle k of a strip v0 v1 v2 … is (vk, vk+1, vk+2), every odd one turned to
    // (vk+1, vk, vk+2): 0 1 2 3 → (0,1,2) (2,1,3); after the restart 1 0 5 3 4 → (1,0,5) (5,0,3)
    // (5,3,4).
    let strip: &[i32] = &[0, 1, 2, 3, -1, 1, 0, 5, 3, 4, 4, 4, 5];
    let want = vec![
        [0, 1, 2],
        [2, 1, 3],
        [1, 0, 5],
        [5, 0, 3],
        [5, 3, 4],
        // 3 4 4, 4 4 4 and 4 4 5 repeat a vertex: joins, left out.
    ];
    for ascii in [false, true] {
        let bytes = strips_ply(ascii, &[strip, &[4, 3, 5]]);
        let mesh = parse_as(&bytes, "s.ply").unwrap();
        let mut all = want.clone();
        all.push([4, 3, 5]);
        assert_eq!(mesh.triangles[..], all[..], "ascii {ascii}");
        // Written back: the strips as they were, only the positions new.
        let mut moved = mesh.clone();
        for p in moved.positions.iter_mut() {
            *p *= 2.0;
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.ply");
        write_mesh(&path, &moved).unwrap();
        let out = std::fs::read(&path).unwrap();
        let header_end = |b: &[u8]| b.windows(11).position(|w| w == b"end_header\n").unwrap();
        assert_eq!(out[..header_end(&out)], bytes[..header_end(&bytes)]);
        let back = read_mesh(&path).unwrap();
        assert_eq!(back.triangles[..], all[..]);
        assert_eq!(back.positions[..], moved.positions[..]);
        // Other connectivity cannot be written as those strips.
        let mut other = mesh.clone();
        other.triangles.truncate(2);
        let e = write_mesh(&path, &other).unwrap_err().to_string();
        assert!(e.contains("triangle strips"), "{e}");
    }
    // Bad ids are named; a face element beside strips is refused.
    let e = parse_as(&strips_ply(true, &[&[0, 1, 6]]), "s.ply")
        .map(|_| ())
        .unwrap_err();
    assert!(e.contains("tristrips 0") && e.contains("6"), "{e}");
    let e = parse_as(&strips_ply(true, &[&[0, 1, -2]]), "s.ply")
        .map(|_| ())
        .unwrap_err();
    assert!(e.contains("tristrips 0") && e.contains("-2"), "{e}");
    let both = String::from_utf8(strips_ply(true, &[&[0, 1, 2]]))
        .unwrap()
        .replace(
            "end_header",
            "element face 0\nproperty list uchar int vertex_indices\nend_header",
        );
    let e = parse_as(both.as_bytes(), "s.ply").map(|_| ()).unwrap_err();
    assert!(e.contains("both a face and a tristrips element"), "{e}");
}

// ---------------------------------------------------------------------------------------------
// The precision of a fixed-point text input

#[test]
fn a_fixed_point_text_input_is_written_at_its_own_decimals() {
    let mesh = octahedron();
    let dir = tempfile::tempdir().unwrap();
    let fixed = |p: DVec3| format!("{:.6} {:.6} {:.6}", p.x, p.y, p.z);
    let obj: String = mesh
        .positions
        .iter()
        .map(|&p| format!("v {}\n", fixed(p)))
        .collect::<String>()
        + &mesh
            .triangles
            .iter()
            .map(|t| format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1))
            .collect::<String>();
    let off = format!(
        "OFF\n6 8 0\n{}",
        mesh.positions
            .iter()
            .map(|&p| fixed(p) + "\n")
            .collect::<String>()
    ) + &mesh
        .triangles
        .iter()
        .map(|t| format!("3 {} {} {}\n", t[0], t[1], t[2]))
        .collect::<String>();
    for (name, text) in [("o.obj", obj), ("o.off", off)] {
        let mut read = parse_as(text.as_bytes(), name).unwrap();
        assert_eq!(read.source.decimals, Some(6), "{name}");
        // Smoothed positions: no longer six decimals.
        for p in read.positions.iter_mut() {
            *p += DVec3::new(1.0 / 3.0, -1.0 / 7.0, 1e-9);
        }
        let path = dir.path().join(name);
        write_mesh(&path, &read).unwrap();
        let written = std::fs::read_to_string(&path).unwrap();
        let back = read_mesh(&path).unwrap();
        let stored = Stored::of(&path, &read).unwrap();
        for (a, b) in read.positions.iter().zip(back.positions.iter()) {
            assert_eq!(
                stored.round(*a),
                *b,
                "{name}: the statistics' rounding is the file's"
            );
            assert!(
                (*a - *b).abs().max_element() <= 5e-7 + 1e-12,
                "{name}: {a} -> {b}"
            );
        }
        let longest = written
            .split_whitespace()
            .filter_map(|t| t.split_once('.'))
            .map(|(_, decimals)| decimals.len())
            .max();
        assert_eq!(longest, Some(6), "{name}:\n{written}");
        // The deviation bound holds in the file too.
        let (p, origin) = (read.positions[0], mesh.positions[0]);
        let limit = p.distance(origin) - 1e-9;
        let within = stored.round_within(
            origin + (p - origin) * (limit / p.distance(origin)),
            origin,
            limit,
        );
        assert!(within.distance(origin) <= limit, "{name}");
        assert_eq!(stored.round(within), within);
    }
    // Mixed decimals: the shortest text, as before.
    let mixed = parse_as(
        b"v 0.1 0.25 0.125\nv 1.5 0 0\nv 0 1.0000 0\nf 1 2 3\n",
        "m.obj",
    )
    .unwrap();
    assert_eq!(mixed.source.decimals, None);
}

/// Records written in parallel pieces come out in order: a mesh of several pieces of vertices
/// and faces whose vertex records carry a colour (the stored-records path) and whose face list
/// uses `ushort` counts and `uint` indices (the general face encoder), smoothed (moved) and
/// written, reads back through the oracle with every vertex's new position, its colour, and
/// every face.
#[test]
fn records_written_in_parallel_pieces_keep_their_order() {
    let sphere = crate::shapes::icosphere(6);
    let (n, m) = (sphere.positions.len(), sphere.triangles.len());
    assert!(n > 2 * 16384 && m > 4 * 16384, "several pieces of each");
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n\
         property float y\nproperty float z\nproperty uchar red\nelement face {m}\n\
         property list ushort uint vertex_indices\nend_header\n"
    )
    .into_bytes();
    for (i, p) in sphere.positions.iter().enumerate() {
        for x in [p.x, p.y, p.z] {
            bytes.extend_from_slice(&(x as f32).to_le_bytes());
        }
        bytes.push((i % 251) as u8);
    }
    for t in sphere.triangles.iter() {
        bytes.extend_from_slice(&3u16.to_le_bytes());
        for &v in t {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.ply"), dir.path().join("out.ply"));
    std::fs::write(&input, &bytes).unwrap();
    let mut mesh = read_mesh(&input).unwrap();
    let moved: Vec<DVec3> = (0..n)
        .map(|i| mesh.positions[i] * (1.0 + i as f64 * 1e-6))
        .collect();
    mesh.positions.copy_from_slice(&moved);
    write_mesh(&output, &mesh).unwrap();
    let ply = oracle_read(&std::fs::read(&output).unwrap());
    let (positions, triangles) = oracle_mesh(&ply);
    assert_eq!(triangles, sphere.triangles.to_vec());
    for (i, (p, v)) in positions.iter().zip(&ply.payload["vertex"]).enumerate() {
        assert_eq!(*p, moved[i].as_vec3().as_dvec3(), "vertex {i}");
        assert_eq!(scalar(&v["red"]), (i % 251) as f64, "vertex {i}");
    }
}

/// The pipeline writes its pieces in item order over several steps (a last short piece and
/// step included), for any thread count, and returns the first piece's error.
#[test]
fn encoded_pieces_are_written_in_item_order() {
    let piece = piece_len(4);
    let count = 2 * PIECES_PER_STEP * piece + 3 * piece + 17;
    let encode = |range: std::ops::Range<usize>, buf: &mut Vec<u8>| {
        for i in range {
            buf.extend_from_slice(&(i as u32).to_le_bytes());
        }
        Ok(())
    };
    let want: Vec<u8> = (0..count as u32).flat_map(u32::to_le_bytes).collect();
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let mut out = Vec::new();
        pool.install(|| write_encoded(&mut out, count, 4, encode))
            .unwrap();
        assert!(out == want, "{threads} threads");
        let failing = |range: std::ops::Range<usize>, buf: &mut Vec<u8>| match range.start / piece {
            k if k == PIECES_PER_STEP + 2 || k == PIECES_PER_STEP + 5 => {
                Err(std::io::Error::other(format!("piece {k}")))
            }
            _ => encode(range, buf),
        };
        let e = pool.install(|| write_encoded(&mut Vec::new(), count, 4, failing));
        assert_eq!(
            e.unwrap_err().to_string(),
            format!("piece {}", PIECES_PER_STEP + 2)
        );
    }
    let mut out = Vec::new();
    write_encoded(&mut out, 0, 4, encode).unwrap();
    assert!(out.is_empty());
}

/// The text writers' plain paths encode in parallel pieces too: a sphere of several pieces as
/// OBJ (with colours) and OFF give the same bytes on pools of 1 and 3 threads, and read back to
/// the positions as spelled and the faces.
#[test]
fn text_written_in_parallel_pieces_is_the_one_thread_text() {
    let mut sphere = crate::shapes::icosphere(6);
    let n = sphere.positions.len();
    assert!(n > 4 * piece_len(40), "several pieces");
    sphere.source.precision = Precision::Float;
    let dir = tempfile::tempdir().unwrap();
    let colour = |i: usize| [(i % 256) as u8, 7, 200];
    let quality = vec![0.5; n];
    let values = VertexValues {
        quality: &quality,
        colours: Some(&colour),
    };
    let written = |threads: usize, name: &str, mesh: &Mesh, colours: bool| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let path = dir.path().join(format!("{threads}-{name}"));
        pool.install(|| match colours {
            true => write_mesh_with(&path, mesh, &values, &Meter::default()),
            false => write_mesh(&path, mesh),
        })
        .unwrap();
        std::fs::read(&path).unwrap()
    };
    for (name, mesh, colours) in [("s.obj", &sphere, true), ("s.off", &sphere, false)] {
        let one = written(1, name, mesh, colours);
        assert!(one == written(3, name, mesh, colours), "{name}");
        let path = dir.path().join(format!("1-{name}"));
        let back = read_mesh(&path).unwrap();
        assert_eq!(back.triangles.to_vec(), mesh.triangles.to_vec(), "{name}");
        for (a, b) in back.positions.iter().zip(mesh.positions.iter()) {
            assert_eq!(a.as_vec3(), b.as_vec3(), "{name}");
        }
    }
}
