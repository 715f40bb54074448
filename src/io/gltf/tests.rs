//! Unit tests of the glTF reader and writer.

use glam::DVec3;

use super::read::read_vec3;
use super::uri::{base64_decode, base64_encode, percent_decode, percent_encode};
use super::*;

#[test]
fn base64_round_trips() {
    for n in 0..10 {
        let bytes: Vec<u8> = (0..n).map(|i| (i * 37 + 5) as u8).collect();
        assert_eq!(base64_decode(base64_encode(&bytes).as_bytes()), Some(bytes));
    }
    assert_eq!(base64_encode(b"Man"), "TWFu");
    assert_eq!(base64_encode(b"M"), "TQ==");
    assert_eq!(base64_decode(b"T!=="), None);
}

/// Two triangle primitives (one indexed, one not), a third sharing the first's positions, and
/// a line primitive, all in one embedded buffer.
fn primitives() -> Vec<u8> {
    let mut bin = Vec::new();
    // Accessor 0: a tetrahedron's 4 corners; 1: 6 corners of two loose triangles; 2: 2 line ends.
    let points: [[f32; 3]; 12] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [5.0, 0.0, 0.0],
        [6.0, 0.0, 0.0],
        [5.0, 1.0, 0.0],
        [7.0, 0.0, 0.0],
        [8.0, 0.0, 0.0],
        [7.0, 1.0, 0.0],
        [9.0, 9.0, 9.0],
        [9.0, 9.0, 8.0],
    ];
    for c in points.iter().flatten() {
        bin.extend_from_slice(&c.to_le_bytes());
    }
    for i in [0u8, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3] {
        bin.push(i);
    }
    let json = serde_json::json!({
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": bin.len(),
            "uri": format!("data:application/gltf-buffer;base64,{}", base64_encode(&bin))}],
        "bufferViews": [{"buffer": 0, "byteLength": 144}, {"buffer": 0, "byteOffset": 144, "byteLength": 12}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 0, "byteOffset": 48, "componentType": 5126, "count": 6, "type": "VEC3"},
            {"bufferView": 0, "byteOffset": 120, "componentType": 5126, "count": 2, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5121, "count": 6, "type": "SCALAR"},
            {"bufferView": 1, "byteOffset": 6, "componentType": 5121, "count": 6, "type": "SCALAR"}
        ],
        "meshes": [
            {"primitives": [
                {"attributes": {"POSITION": 0}, "indices": 3},
                {"attributes": {"POSITION": 2}, "mode": 1}
            ]},
            {"primitives": [
                {"attributes": {"POSITION": 1, "_ID": 1}},
                {"attributes": {"POSITION": 0}, "indices": 4, "mode": 4}
            ]}
        ]
    });
    serde_json::to_vec(&json).unwrap()
}

#[test]
fn primitives_are_concatenated_and_lines_left_alone() {
    let mesh = read(&primitives(), false, None).unwrap();
    // The tetrahedron's 4 vertices once (two primitives share them), then the loose 6.
    assert_eq!(mesh.positions.len(), 10);
    assert_eq!(mesh.positions[4], DVec3::new(5.0, 0.0, 0.0));
    assert_eq!(
        mesh.triangles.to_vec(),
        [
            [0, 2, 1],
            [0, 1, 3],
            [4, 5, 6],
            [7, 8, 9],
            [0, 3, 2],
            [1, 2, 3]
        ]
    );
    let carried = mesh.source.layout.as_ref().unwrap().carries();
    assert_eq!(carried.other, ["_ID"]);
    assert!(!carried.uvs && !carried.normals && !carried.materials);

    // Written back: the line's points and the indices keep their bytes.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.gltf");
    let mut moved = mesh.clone();
    moved
        .positions
        .iter_mut()
        .for_each(|p| *p += DVec3::splat(0.5));
    crate::io::write_mesh(&out, &moved).unwrap();
    let back = crate::io::read_mesh(&out).unwrap();
    assert_eq!(back.positions.to_vec(), moved.positions.to_vec());
    assert_eq!(back.triangles.to_vec(), mesh.triangles.to_vec());
    let json: Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let uri = json["buffers"][0]["uri"].as_str().unwrap();
    let head = "data:application/gltf-buffer;base64,";
    let bin = base64_decode(uri.strip_prefix(head).unwrap().as_bytes()).unwrap();
    assert_eq!(read_vec3(&bin, 120), DVec3::splat(9.0));
    assert_eq!(read_vec3(&bin, 132), DVec3::new(9.0, 9.0, 8.0));
    assert_eq!(bin[144..], [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]);
    assert_eq!(
        json["accessors"][1]["min"],
        serde_json::json!([5.5, 0.5, 0.5])
    );
    assert!(
        json["accessors"][2].get("min").is_none(),
        "a line's bounds set"
    );

    // Not to a .glb, and an external buffer needs a directory.
    let glb = dir.path().join("out.glb");
    let e = crate::io::write_mesh(&glb, &moved).unwrap_err().to_string();
    assert!(e.contains("a .gltf input is written as .gltf"), "{e}");
    let text = String::from_utf8(primitives()).unwrap();
    let external = text.replacen("data:application/gltf-buffer;base64,", "x.bin#", 1);
    let e = read(external.as_bytes(), false, None).unwrap_err();
    assert!(
        e.contains("cannot be read without the file's directory"),
        "{e}"
    );
}

#[test]
fn stored_positions_are_those_read_back() {
    let mut mesh = read(&primitives(), false, None).unwrap();
    for p in mesh.positions.iter_mut() {
        *p = *p * 1.000_000_123 + DVec3::new(0.1, -0.7, 1e-9);
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.gltf");
    crate::io::write_mesh(&out, &mesh).unwrap();
    let back = crate::io::read_mesh(&out).unwrap();
    let stored = crate::io::Stored::of(&out, &mesh).unwrap();
    let expected: Vec<DVec3> = mesh.positions.iter().map(|&p| stored.round(p)).collect();
    assert_eq!(back.positions.to_vec(), expected);
    assert!(!stored.is_exact());
}

#[test]
fn percent_escapes_round_trip() {
    assert_eq!(percent_encode("a b%.bin"), "a%20b%25.bin");
    assert_eq!(percent_decode("a%20b%25.bin").as_deref(), Some("a b%.bin"));
    assert_eq!(percent_decode("a%2"), None);
}

#[test]
fn runs_join_spans_naming_the_same_elements_only() {
    let span = |accessor, buffer, offset, stride, count| Span {
        accessor,
        buffer,
        offset,
        stride,
        count,
    };
    let spans = [
        (span(0, 0, 120, 12, 10), 0), // elements 10..20
        (span(1, 0, 0, 12, 10), 0),   // 0..10: touches the first, shares nothing
        (span(2, 0, 180, 12, 10), 0), // 15..25: overlaps the first
        (span(3, 0, 124, 12, 5), 0),  // out of step: a run of its own
        (span(4, 1, 120, 12, 10), 0), // another buffer
        (span(5, 0, 120, 12, 10), 1), // another tag
        (span(6, 0, 0, 12, 0), 0),    // empty
    ];
    let (runs, place) = super::runs::runs(&spans);
    let got: Vec<(usize, usize, usize)> =
        runs.iter().map(|r| (r.accessor, r.first, r.end)).collect();
    assert_eq!(
        got,
        [
            (0, 10, 25),
            (1, 0, 10),
            (3, 10, 15),
            (4, 10, 20),
            (5, 10, 20)
        ]
    );
    assert_eq!(
        place,
        [
            Some((0, 0)),
            Some((1, 0)),
            Some((0, 5)),
            Some((2, 0)),
            Some((3, 0)),
            Some((4, 0)),
            None
        ]
    );
    assert_eq!(runs[2].byte(10), 124);
}

/// A Draco GLB's binary chunk as a `data:` URI of a `.gltf`: decoded into that buffer, which is
/// written re-encoded (the decoded data with it) and reads back to the same mesh, uncompressed.
#[test]
fn draco_in_a_data_uri_is_decoded_into_it() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/formats/torus_box.draco_sequential.glb"
    );
    let glb = std::fs::read(path).unwrap();
    let draco = read(&glb, true, None).unwrap();
    let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    let json_len = word(12);
    let mut json: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let bin = &glb[28 + json_len..28 + json_len + word(20 + json_len)];
    json["buffers"][0]["uri"] = format!(
        "data:application/octet-stream;base64,{}",
        base64_encode(bin)
    )
    .into();
    let mesh = read(&serde_json::to_vec(&json).unwrap(), false, None).unwrap();
    assert_eq!(mesh.positions.to_vec(), draco.positions.to_vec());
    assert_eq!(mesh.triangles.to_vec(), draco.triangles.to_vec());
    let layout = mesh.source.layout.as_deref().unwrap();
    let layout = layout.as_any().downcast_ref::<GltfLayout>().unwrap();
    assert!(layout.decompressed());
    assert!(matches!(
        layout.buffers[0].as_ref().map(|b| (&b.origin, b.extended)),
        Some((Origin::Data(_), true))
    ));
    assert!(!layout.json.to_string().contains(super::draco::EXTENSION));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.gltf");
    write(&out, &mesh, None).unwrap();
    let files: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        files,
        ["out.gltf"],
        "the decoded data stays in the data URI"
    );
    let back = read(&std::fs::read(&out).unwrap(), false, None).unwrap();
    assert_eq!(back.triangles.to_vec(), mesh.triangles.to_vec());
    let back_layout = back.source.layout.as_deref().unwrap();
    let back_layout = back_layout.as_any().downcast_ref::<GltfLayout>().unwrap();
    assert!(
        !back_layout.decompressed(),
        "already plain: nothing to decode"
    );
}
