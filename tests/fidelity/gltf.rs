//! Fidelity of glTF files (see tests/fidelity.rs): a GLB, a `.gltf` with an external `.bin` and
//! one with an embedded data URI, each a noisy icosphere with `TEXCOORD_0`, `COLOR_0`, `NORMAL`
//! (interleaved with `POSITION`), a material, an extension and extras, all built here. After
//! smoothing, only the position and normal bytes of the buffer and the `POSITION` accessor's
//! `min`/`max` (and a changed buffer's `uri`) may differ; every refusal is one line.

use std::path::Path;

use serde_json::{Value, json};
use vcsmooth::io;

use crate::util::{fails, json as parse_json, noisy_sphere, ok, vcsmooth};

/// Bytes per vertex of the interleaved `POSITION` + `NORMAL` view.
const STRIDE: usize = 24;

/// A sphere's glTF: its JSON (buffer 0 without a uri) and its binary buffer. Layout of the buffer:
/// interleaved positions and normals, then UVs, then RGBA8 colours, then `u16` indices.
fn sphere() -> (Value, Vec<u8>) {
    sphere_of(&noisy_sphere(2, 0.3, 7))
}

/// [`sphere`]'s glTF of any mesh `m` (each vertex its own UV).
fn sphere_of(m: &vcsmooth::Mesh) -> (Value, Vec<u8>) {
    let n = m.positions.len();
    let mut bin = Vec::new();
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for p in m.positions.iter() {
        let p = p.as_vec3().to_array();
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
        let normal = glam::Vec3::from(p).normalize().to_array();
        for c in p.iter().chain(&normal) {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let uv_at = bin.len();
    for i in 0..n {
        for c in [i as f32 / n as f32, 1.0 - i as f32 / n as f32] {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let colour_at = bin.len();
    for i in 0..n {
        bin.extend_from_slice(&[(i * 7) as u8, (i * 13) as u8, (i * 29) as u8, 255]);
    }
    let index_at = bin.len();
    for t in m.triangles.iter() {
        for &v in t {
            bin.extend_from_slice(&(v as u16).to_le_bytes());
        }
    }
    let index_len = bin.len() - index_at;
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let json = json!({
        "asset": {"version": "2.0", "generator": "vcsmooth tests"},
        "extensionsUsed": ["KHR_materials_unlit"],
        "extras": {"scan": "fixture", "id": 16},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": [10.0, 0.0, 0.0]}],
        "materials": [{
            "name": "skin",
            "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.6, 0.5, 1.0]},
            "extensions": {"KHR_materials_unlit": {}}
        }],
        "meshes": [{
            "name": "sphere",
            "extras": {"note": "noisy"},
            "primitives": [{
                "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "COLOR_0": 3},
                "indices": 4,
                "material": 0
            }]
        }],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": uv_at, "byteStride": STRIDE, "target": 34962},
            {"buffer": 0, "byteOffset": uv_at, "byteLength": colour_at - uv_at, "target": 34962},
            {"buffer": 0, "byteOffset": colour_at, "byteLength": index_at - colour_at, "target": 34962},
            {"buffer": 0, "byteOffset": index_at, "byteLength": index_len, "target": 34963}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi},
            {"bufferView": 0, "byteOffset": 12, "componentType": 5126, "count": n, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5126, "count": n, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5121, "normalized": true, "count": n, "type": "VEC4"},
            {"bufferView": 3, "componentType": 5123, "count": m.triangles.len() * 3, "type": "SCALAR"}
        ]
    });
    (json, bin)
}

/// A GLB of `json` and `bin` (each chunk padded to 4 bytes).
pub(super) fn glb(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut text = serde_json::to_vec(json).unwrap();
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let mut bin = bin.to_vec();
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// The JSON and binary chunk of a GLB (checking its header and lengths).
pub(super) fn unglb(bytes: &[u8]) -> (Value, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&bytes[..4], b"glTF");
    assert_eq!(word(4), 2);
    assert_eq!(word(8), bytes.len());
    let json_len = word(12);
    assert_eq!(&bytes[16..20], b"JSON");
    let json = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let at = 20 + json_len;
    assert_eq!(&bytes[at + 4..at + 8], b"BIN\0");
    (json, bytes[at + 8..at + 8 + word(at)].to_vec())
}

fn smooth(input: &Path, output: &Path) {
    ok(vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
    ]));
}

/// The volume `vcsmooth info` measures on the mesh file at `path`.
pub(super) fn volume(path: &Path) -> f64 {
    parse_json(&ok(vcsmooth([
        "info".as_ref(),
        path.as_os_str(),
        "--json".as_ref(),
    ])))["volume"]
        .as_f64()
        .unwrap()
}

fn f32_at(bin: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(bin[at..at + 4].try_into().unwrap())
}

/// The smoothed buffer `after` differs from `before` only in position and normal bytes, the
/// positions moved, the normals are unit length, and `json_after` is `json_before` but for the
/// position bounds (which match the new positions) and buffer 0's uri.
fn check_smoothed(json_before: &Value, bin_before: &[u8], json_after: &Value, bin_after: &[u8]) {
    assert_eq!(bin_before.len(), bin_after.len());
    let n = json_before["accessors"][0]["count"].as_u64().unwrap() as usize;
    let geometry = n * STRIDE;
    assert_eq!(
        bin_before[geometry..],
        bin_after[geometry..],
        "UVs, colours or indices changed"
    );
    let mut moved = 0;
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for i in 0..n {
        let at = i * STRIDE;
        let p: Vec<f32> = (0..3).map(|k| f32_at(bin_after, at + 4 * k)).collect();
        let normal: Vec<f32> = (0..3).map(|k| f32_at(bin_after, at + 12 + 4 * k)).collect();
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
        let length = normal.iter().map(|c| c * c).sum::<f32>().sqrt();
        assert!(
            (length - 1.0).abs() < 1e-5,
            "normal {i} has length {length}"
        );
        // Outward on a sphere.
        let dot: f32 = p.iter().zip(&normal).map(|(a, b)| a * b).sum();
        assert!(dot > 0.0, "normal {i} points inwards");
        if bin_before[at..at + 12] != bin_after[at..at + 12] {
            moved += 1;
        }
    }
    assert!(moved > n / 2, "only {moved} of {n} vertices moved");
    let bounds = &json_after["accessors"][0];
    let single = |v: &Value| -> Vec<f32> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_f64().unwrap() as f32)
            .collect()
    };
    assert_eq!(single(&bounds["min"]), lo);
    assert_eq!(single(&bounds["max"]), hi);
    let strip = |json: &Value| {
        let mut json = json.clone();
        let a = json["accessors"][0].as_object_mut().unwrap();
        a.remove("min");
        a.remove("max");
        json["buffers"][0].as_object_mut().unwrap().remove("uri");
        json
    };
    assert_eq!(strip(json_before), strip(json_after));
}

#[test]
fn glb_keeps_everything_but_positions_and_normals() {
    let dir = tempfile::tempdir().unwrap();
    let (json, bin) = sphere();
    let input = dir.path().join("scan.glb");
    std::fs::write(&input, glb(&json, &bin)).unwrap();
    let output = dir.path().join("smooth.glb");
    smooth(&input, &output);
    let (json_after, bin_after) = unglb(&std::fs::read(&output).unwrap());
    check_smoothed(&json, &bin, &json_after, &bin_after);
    let (v0, v1) = (volume(&input), volume(&output));
    assert!(((v1 - v0) / v0).abs() < 1e-6, "volume {v0} -> {v1}");

    let carried = io::read_mesh(&input)
        .unwrap()
        .source
        .layout
        .unwrap()
        .carries();
    assert!(carried.uvs && carried.colours && carried.normals && carried.materials);
    assert_eq!(carried.other, ["KHR_materials_unlit"]);

    // As a plain mesh to another format; from another format as a plain glTF (one primitive:
    // positions, normals, indices), which reads back as the same mesh; never GLB to .gltf.
    let ply = dir.path().join("smooth.ply");
    smooth(&input, &ply);
    let back = io::read_mesh(&ply).unwrap();
    assert_eq!(back.positions.len(), json["accessors"][0]["count"]);
    for name in ["plain.glb", "plain.gltf"] {
        let out = dir.path().join(name);
        ok(vcsmooth([
            "smooth".as_ref(),
            ply.as_os_str(),
            out.as_os_str(),
            "--iterations".as_ref(),
            "0".as_ref(),
        ]));
        let plain = io::read_mesh(&out).unwrap();
        assert_eq!(plain.positions[..], back.positions[..], "{name}");
        assert_eq!(plain.triangles[..], back.triangles[..], "{name}");
        let carried = plain.source.layout.as_ref().unwrap().carries();
        assert!(carried.normals && !carried.uvs, "{name}: {carried:?}");
    }
    assert!(dir.path().join("plain.bin").is_file());
    let o = vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        dir.path().join("x.gltf").as_os_str(),
    ]);
    fails(&o, 1, &["x.gltf", "a GLB input is written as .glb"]);
    assert!(!dir.path().join("x.gltf").exists());
}

/// A texture seam (the sphere split along its equator, each copy with its own UV) is welded:
/// every vertex moves, each copy exactly as its original, and the UVs, colours and indices keep
/// their bytes; with `--no-weld` the seam stays where it was.
#[test]
fn a_texture_seam_is_smoothed_and_keeps_its_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let whole = noisy_sphere(2, 0.3, 7);
    let (m, copy_of) = crate::util::seamed(&whole);
    let (json, bin) = sphere_of(&m);
    let input = dir.path().join("seamed.glb");
    std::fs::write(&input, glb(&json, &bin)).unwrap();
    let output = dir.path().join("smooth.glb");
    smooth(&input, &output);
    let (json_after, bin_after) = unglb(&std::fs::read(&output).unwrap());
    check_smoothed(&json, &bin, &json_after, &bin_after);
    let before = io::read_mesh(&input).unwrap().positions;
    let after = io::read_mesh(&output).unwrap().positions;
    for (v, &of) in copy_of.iter().enumerate() {
        assert_ne!(after[v], before[v], "vertex {v} did not move");
        assert_eq!(after[v], after[of as usize], "copy {v} of {of}");
    }

    let apart = dir.path().join("apart.glb");
    ok(vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        apart.as_os_str(),
        "--no-weld".as_ref(),
    ]));
    let after = io::read_mesh(&apart).unwrap().positions;
    let copies = whole.positions.len()..m.positions.len();
    assert!(copies.len() > 10);
    for v in copies {
        let of = copy_of[v] as usize;
        assert_eq!(after[v], before[v], "copy {v} moved without welding");
        assert_eq!(
            after[of], before[of],
            "seam vertex {of} moved without welding"
        );
    }
}

#[test]
fn gltf_with_an_external_bin_writes_its_own_bin() {
    let dir = tempfile::tempdir().unwrap();
    let (mut json, bin) = sphere();
    // A percent-escaped uri, as glTF spells a space.
    json["buffers"][0]["uri"] = json!("scan%20data.bin");
    let input = dir.path().join("scan.gltf");
    std::fs::write(&input, serde_json::to_vec_pretty(&json).unwrap()).unwrap();
    std::fs::write(dir.path().join("scan data.bin"), &bin).unwrap();
    let output = dir.path().join("smooth.gltf");
    smooth(&input, &output);
    let after = crate::util::read_json(&output);
    assert_eq!(after["buffers"][0]["uri"], "smooth.bin");
    let bin_after = std::fs::read(dir.path().join("smooth.bin")).unwrap();
    check_smoothed(&json, &bin, &after, &bin_after);
    assert_eq!(
        std::fs::read(dir.path().join("scan data.bin")).unwrap(),
        bin
    );
    let (v0, v1) = (volume(&input), volume(&output));
    assert!(((v1 - v0) / v0).abs() < 1e-6, "volume {v0} -> {v1}");

    // Smoothing in place never overwrites the input's buffer, even one named after the output.
    let mut json2 = json.clone();
    json2["buffers"][0]["uri"] = json!("again.bin");
    let again = dir.path().join("again.gltf");
    std::fs::write(&again, serde_json::to_vec(&json2).unwrap()).unwrap();
    std::fs::write(dir.path().join("again.bin"), &bin).unwrap();
    smooth(&again, &again);
    assert_eq!(std::fs::read(dir.path().join("again.bin")).unwrap(), bin);
    let after = crate::util::read_json(&again);
    assert_eq!(after["buffers"][0]["uri"], "again-1.bin");
    let bin_after = std::fs::read(dir.path().join("again-1.bin")).unwrap();
    check_smoothed(&json2, &bin, &after, &bin_after);

    // An earlier output's buffer replaced by a link to the input's: written through, the link
    // overwrote the input's buffer. The output takes another name; the link and its target stay.
    let linked = dir.path().join("linked.gltf");
    smooth(&input, &linked);
    std::fs::remove_file(dir.path().join("linked.bin")).unwrap();
    std::os::unix::fs::symlink("scan data.bin", dir.path().join("linked.bin")).unwrap();
    smooth(&input, &linked);
    assert!(
        std::fs::read(dir.path().join("scan data.bin")).unwrap() == bin,
        "the input's buffer was written through the link"
    );
    assert!(
        std::fs::symlink_metadata(dir.path().join("linked.bin"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let after = crate::util::read_json(&linked);
    assert_eq!(after["buffers"][0]["uri"], "linked-1.bin");
    let bin_after = std::fs::read(dir.path().join("linked-1.bin")).unwrap();
    check_smoothed(&json, &bin, &after, &bin_after);
}

/// `batch` takes a directory's `.gltf` and `.glb` files like its other meshes, written in the
/// batch's format (PLY by default); the inputs and their buffer stay as they were.
#[test]
fn batch_smooths_a_directorys_gltf_and_glb_files() {
    let dir = tempfile::tempdir().unwrap();
    let (inputs, outdir) = (dir.path().join("in"), dir.path().join("out"));
    std::fs::create_dir(&inputs).unwrap();
    let (mut json, bin) = sphere();
    std::fs::write(inputs.join("blob.glb"), glb(&json, &bin)).unwrap();
    json["buffers"][0]["uri"] = json!("scan.bin");
    let text = serde_json::to_vec(&json).unwrap();
    std::fs::write(inputs.join("scan.gltf"), &text).unwrap();
    std::fs::write(inputs.join("scan.bin"), &bin).unwrap();
    ok(vcsmooth([
        "batch".as_ref(),
        inputs.as_os_str(),
        outdir.as_os_str(),
    ]));
    for (name, input) in [("blob", "blob.glb"), ("scan", "scan.gltf")] {
        let out = outdir.join(format!("{name}.ply"));
        let back = io::read_mesh(&out).unwrap();
        assert_eq!(
            back.positions.len(),
            json["accessors"][0]["count"],
            "{name}"
        );
        let (v0, v1) = (volume(&inputs.join(input)), volume(&out));
        assert!(((v1 - v0) / v0).abs() < 1e-6, "{name}: volume {v0} -> {v1}");
    }
    assert_eq!(std::fs::read(inputs.join("scan.gltf")).unwrap(), text);
    assert_eq!(std::fs::read(inputs.join("scan.bin")).unwrap(), bin);
    assert_eq!(std::fs::read_dir(&inputs).unwrap().count(), 3);
}

/// The files around a `.gltf` are never written over: not another buffer of the input (one
/// named like the output's buffer), not a file the user has, not one named by a side file; a run
/// again replaces its own earlier buffer instead of leaving it behind.
#[test]
fn the_files_around_a_gltf_are_never_written_over() {
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name);
    let (mut json, bin) = sphere();
    json["buffers"][0]["uri"] = json!("geom.bin");
    // A second buffer the geometry does not use, named as the output's buffer would be.
    let other = b"sixteen bytes!!!".to_vec();
    json["buffers"]
        .as_array_mut()
        .unwrap()
        .push(json!({"uri": "out.bin", "byteLength": 16}));
    std::fs::write(at("scene.gltf"), serde_json::to_vec(&json).unwrap()).unwrap();
    std::fs::write(at("geom.bin"), &bin).unwrap();
    std::fs::write(at("out.bin"), &other).unwrap();
    let run = |args: &[&str]| {
        let mut all: Vec<std::ffi::OsString> = vec!["smooth".into(), at("scene.gltf").into()];
        all.extend(args.iter().map(|a| match a.starts_with('-') {
            true => a.into(),
            false => at(a).into_os_string(),
        }));
        vcsmooth(all)
    };

    ok(run(&["out.gltf"]));
    assert_eq!(std::fs::read(at("out.bin")).unwrap(), other);
    let after = crate::util::read_json(&at("out.gltf"));
    assert_eq!(after["buffers"][0]["uri"], "out-1.bin");
    assert_eq!(after["buffers"][1]["uri"], "out.bin");
    check_smoothed(
        &json,
        &bin,
        &after,
        &std::fs::read(at("out-1.bin")).unwrap(),
    );
    // Again: its own buffer from the first run is replaced, not a third file made.
    ok(run(&["out.gltf"]));
    assert_eq!(
        crate::util::read_json(&at("out.gltf"))["buffers"][0]["uri"],
        "out-1.bin"
    );
    assert!(!at("out-2.bin").exists());

    // A file of the user's named like the buffer stays as it was.
    std::fs::write(at("mine.bin"), b"mine").unwrap();
    ok(run(&["mine.gltf"]));
    assert_eq!(std::fs::read(at("mine.bin")).unwrap(), b"mine");
    assert_eq!(
        crate::util::read_json(&at("mine.gltf"))["buffers"][0]["uri"],
        "mine-1.bin"
    );

    // A report over one of the input's buffers, or where the output's buffer goes: refused
    // before any work.
    let o = run(&["a.gltf", "--report", "geom.bin"]);
    fails(&o, 2, &["geom.bin", "a file IN names"]);
    assert_eq!(std::fs::read(at("geom.bin")).unwrap(), bin);
    let o = run(&["b.gltf", "--report", "b.bin"]);
    fails(&o, 2, &["b.bin", "buffers of OUT"]);
    let o = run(&["b.gltf", "--report", "b-2.bin"]);
    fails(&o, 2, &["b-2.bin", "buffers of OUT"]);
    assert!(!at("b.gltf").exists() && !at("a.gltf").exists());
    // Names that only look alike are free.
    ok(run(&["b.gltf", "--report", "b-x.bin"]));
}

/// `json` with a second buffer: copies of buffer 0's views and accessors on buffer 1, and a
/// second primitive using them; the buffers named `a` and `b`.
fn two_buffers(json: &Value, a: &str, b: &str) -> Value {
    let mut two = json.clone();
    let length = json["buffers"][0]["byteLength"].clone();
    two["buffers"] = json!([{"uri": a, "byteLength": length}, {"uri": b, "byteLength": length}]);
    let views = json["bufferViews"].as_array().unwrap().clone();
    let accessors = json["accessors"].as_array().unwrap().clone();
    for mut v in views.iter().cloned() {
        v["buffer"] = json!(1);
        two["bufferViews"].as_array_mut().unwrap().push(v);
    }
    for mut x in accessors.iter().cloned() {
        x["bufferView"] = json!(x["bufferView"].as_u64().unwrap() + views.len() as u64);
        two["accessors"].as_array_mut().unwrap().push(x);
    }
    let k = accessors.len();
    two["meshes"][0]["primitives"]
        .as_array_mut()
        .unwrap()
        .push(json!({
            "attributes": {"POSITION": k, "NORMAL": k + 1, "TEXCOORD_0": k + 2, "COLOR_0": k + 3},
            "indices": k + 4
        }));
    two
}

/// Each changed buffer of a `.gltf` gets a file of its own, also when the first free names are
/// taken by a user's file or by the input's own buffers (smoothing in place).
#[test]
fn every_buffer_gets_its_own_file() {
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name);
    let (json, bin) = sphere();
    let triangles = |path: &Path| {
        let o = ok(vcsmooth([
            "info".as_ref(),
            path.as_os_str(),
            "--json".as_ref(),
        ]));
        parse_json(&o)["triangles"].as_u64().unwrap()
    };
    for (input, a, b, output) in [
        ("m.gltf", "a.bin", "b.bin", "out.gltf"),
        ("s.gltf", "s.bin", "s-1.bin", "s.gltf"),
    ] {
        std::fs::write(
            at(input),
            serde_json::to_vec(&two_buffers(&json, a, b)).unwrap(),
        )
        .unwrap();
        std::fs::write(at(a), &bin).unwrap();
        std::fs::write(at(b), &bin).unwrap();
        std::fs::write(at("out.bin"), b"mine").unwrap();
        let before = triangles(&at(input));
        smooth(&at(input), &at(output));
        let after = crate::util::read_json(&at(output));
        let (u0, u1) = (&after["buffers"][0]["uri"], &after["buffers"][1]["uri"]);
        assert_ne!(u0, u1, "{input}");
        for name in [a, b] {
            assert_eq!(std::fs::read(at(name)).unwrap(), bin, "{input}: {name}");
        }
        assert_eq!(std::fs::read(at("out.bin")).unwrap(), b"mine");
        assert_eq!(triangles(&at(output)), before, "{input}");
    }
}

/// A file whose `POSITION` or `NORMAL` bytes hold something else too (another attribute, another
/// view, or each other) is refused when read: writing the new positions and normals would change it.
#[test]
fn rewritten_bytes_shared_with_other_data_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (json, bin) = sphere();
    let cases = [
        (
            "same.glb",
            "/meshes/0/primitives/0/attributes/NORMAL",
            json!(0),
            "both POSITION and NORMAL",
        ),
        // TEXCOORD_0 interleaved over the positions themselves.
        (
            "uv.glb",
            "/accessors/2/bufferView",
            json!(0),
            "accessor 2 shares bytes",
        ),
        // The colours' view over the start of the positions' view.
        (
            "view.glb",
            "/bufferViews/2/byteOffset",
            json!(0),
            "bufferView 2 shares bytes",
        ),
    ];
    for (name, pointer, value, message) in cases {
        let mut bad = json.clone();
        *bad.pointer_mut(pointer).unwrap() = value;
        let path = dir.path().join(name);
        std::fs::write(&path, glb(&bad, &bin)).unwrap();
        let o = vcsmooth(["info".as_ref(), path.as_os_str()]);
        fails(&o, 1, &[name, message]);
    }
}

/// A GLB output keeps an input's external buffer external, as a `.gltf` does: a side file named
/// like it is refused before any work; and a buffer that is not a regular file is refused.
#[test]
fn a_glbs_external_buffers_are_guarded_too() {
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name);
    let (mut json, bin) = sphere();
    json["buffers"][0]["uri"] = json!("m.bin");
    std::fs::write(at("m.glb"), glb(&json, &[])).unwrap();
    std::fs::write(at("m.bin"), &bin).unwrap();
    let o = vcsmooth([
        "smooth".as_ref(),
        at("m.glb").as_os_str(),
        at("out.glb").as_os_str(),
        "--report".as_ref(),
        at("out.bin").as_os_str(),
    ]);
    fails(&o, 2, &["out.bin", "buffers of OUT"]);
    assert!(!at("out.glb").exists() && !at("out.bin").exists());

    json["buffers"][0]["uri"] = json!("/dev/zero");
    std::fs::write(at("z.gltf"), serde_json::to_vec(&json).unwrap()).unwrap();
    let o = vcsmooth(["info".as_ref(), at("z.gltf").as_os_str()]);
    fails(&o, 1, &["z.gltf", "not a regular file"]);
}

/// A `.gltf` whose writing fails changes nothing: an earlier output and the buffer it names stay
/// as they were, and no new file is left (the buffer was once renamed into place before the
/// `.gltf` was written, so the earlier output named the new geometry).
#[test]
fn a_failed_gltf_write_changes_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name);
    let (mut json, bin) = sphere();
    json["buffers"][0]["uri"] = json!("geom.bin");
    // The JSON, not the buffer, crosses the file-size limit below.
    json["extras"]["notes"] = json!("x".repeat(100_000));
    std::fs::write(at("scene.gltf"), serde_json::to_vec(&json).unwrap()).unwrap();
    std::fs::write(at("geom.bin"), &bin).unwrap();
    assert!(bin.len() < 32 << 10);
    let smooth_args = |iterations: &str| {
        vec![
            "smooth".into(),
            at("scene.gltf").into_os_string(),
            at("out.gltf").into_os_string(),
            "--iterations".into(),
            std::ffi::OsString::from(iterations),
        ]
    };
    ok(vcsmooth(smooth_args("2")));
    let before = [
        std::fs::read(at("out.gltf")).unwrap(),
        std::fs::read(at("out.bin")).unwrap(),
    ];
    let files = crate::util::listing(dir.path());
    // RLIMIT_FSIZE with SIGXFSZ ignored: a write past 64 KiB fails with EFBIG.
    let out = std::process::Command::new("sh")
        .args([
            "-c",
            "trap '' XFSZ; ulimit -f 128 && exec \"$0\" \"$@\"",
            crate::util::BIN,
        ])
        .args(smooth_args("5"))
        .output()
        .unwrap();
    fails(&out, 1, &["out.gltf", "File too large"]);
    assert_eq!(std::fs::read(at("out.gltf")).unwrap(), before[0]);
    assert_eq!(std::fs::read(at("out.bin")).unwrap(), before[1]);
    assert_eq!(crate::util::listing(dir.path()), files);
}

#[test]
fn gltf_with_a_data_uri_is_re_encoded() {
    let dir = tempfile::tempdir().unwrap();
    let (mut json, bin) = sphere();
    json["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        base64_text(&bin)
    ));
    let input = dir.path().join("embedded.gltf");
    std::fs::write(&input, serde_json::to_vec(&json).unwrap()).unwrap();
    let output = dir.path().join("out.gltf");
    smooth(&input, &output);
    let after = crate::util::read_json(&output);
    let uri = after["buffers"][0]["uri"].as_str().unwrap();
    let data = uri
        .strip_prefix("data:application/octet-stream;base64,")
        .expect("a data URI of the same media type");
    check_smoothed(&json, &bin, &after, &unbase64(data));
    assert_eq!(
        crate::util::listing(dir.path()).len(),
        2,
        "no other file written"
    );
}

/// Every refusal is one line naming the file and the problem, and writes nothing.
#[test]
fn malformed_gltf_is_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (json, bin) = sphere();
    let with = |edit: &dyn Fn(&mut Value)| {
        let mut j = json.clone();
        edit(&mut j);
        glb(&j, &bin)
    };
    let mut nan = bin.clone();
    nan[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut far_index = bin.clone();
    let index_at = json["bufferViews"][3]["byteOffset"].as_u64().unwrap() as usize;
    far_index[index_at..index_at + 2].copy_from_slice(&9999u16.to_le_bytes());
    let whole = glb(&json, &bin);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "sparse.glb",
            with(&|j| j["accessors"][0]["sparse"] = json!({"count": 1})),
            "POSITION accessor 0 is sparse: not supported",
        ),
        (
            "meshopt.glb",
            with(&|j| {
                j["meshes"][0]["primitives"][0]["extensions"] =
                    json!({"EXT_meshopt_compression": {}})
            }),
            "EXT_meshopt_compression (meshopt-compressed geometry) is not supported",
        ),
        (
            "quantized.glb",
            with(&|j| j["accessors"][0]["componentType"] = json!(5123)),
            "KHR_mesh_quantization",
        ),
        (
            "no_buffer.glb",
            with(&|j| j["bufferViews"][0]["buffer"] = json!(3)),
            "buffer 3 out of range (0..1)",
        ),
        (
            "missing_bin.glb",
            with(&|j| j["buffers"][0]["uri"] = json!("nowhere.bin")),
            "cannot read",
        ),
        (
            "accessor.glb",
            with(&|j| j["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99)),
            "POSITION accessor 99 out of range (0..5)",
        ),
        (
            "index.glb",
            glb(&json, &far_index),
            "vertex index 9999 out of range",
        ),
        ("nan.glb", glb(&json, &nan), "vertex 0 is not finite"),
        (
            "truncated.glb",
            whole[..whole.len() - 100].to_vec(),
            "GLB truncated",
        ),
        (
            "chunk.glb",
            {
                let mut b = whole.clone();
                let len = b.len() as u32 - 8;
                b[8..12].copy_from_slice(&len.to_le_bytes());
                b.truncate(len as usize);
                b
            },
            "truncated",
        ),
    ];
    for (name, bytes, message) in cases {
        let input = dir.path().join(name);
        std::fs::write(&input, bytes).unwrap();
        let output = dir.path().join("out.glb");
        let o = vcsmooth(["smooth".as_ref(), input.as_os_str(), output.as_os_str()]);
        fails(&o, 1, &[name, message]);
        assert!(!output.exists(), "{name}: output written");
    }
}

fn base64_text(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = c
            .iter()
            .enumerate()
            .fold(0u32, |n, (k, &b)| n | u32::from(b) << (16 - 8 * k));
        for k in 0..=c.len() {
            s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
        }
        s.extend(std::iter::repeat_n('=', 3 - c.len()));
    }
    s
}

fn unbase64(text: &str) -> Vec<u8> {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = Vec::new();
    let (mut acc, mut bits) = (0u32, 0);
    for c in text.bytes().filter(|&c| c != b'=') {
        acc = acc << 6 | A.iter().position(|&a| a == c).unwrap() as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    out
}

/// The deviation field's colours go into a glTF output as `COLOR_0` (normalized `u8` RGBA, in a
/// view appended to the positions' buffer), replacing the colours the primitive had: the same
/// bytes as a PLY output's `red green blue` of the same run, the positions those of a plain run,
/// in a GLB and in a `.gltf` with an external buffer. A value without colours is a usage error.
#[test]
fn deviation_colours_go_into_color_0() {
    let dir = tempfile::tempdir().unwrap();
    let (json, bin) = sphere();
    let n = json["accessors"][0]["count"].as_u64().unwrap() as usize;
    let glb_in = dir.path().join("scan.glb");
    std::fs::write(&glb_in, glb(&json, &bin)).unwrap();
    let mut external = json.clone();
    external["buffers"][0]["uri"] = json!("scan.bin");
    let gltf_in = dir.path().join("scan.gltf");
    std::fs::write(&gltf_in, serde_json::to_vec(&external).unwrap()).unwrap();
    std::fs::write(dir.path().join("scan.bin"), &bin).unwrap();
    let field = ["--deviation-field", "--deviation-colours"];
    let run = |input: &Path, output: &Path, args: &[&str]| {
        let mut all = vec![
            "smooth".to_string(),
            input.display().to_string(),
            output.display().to_string(),
        ];
        all.extend(args.iter().map(|a| a.to_string()));
        ok(vcsmooth(&all));
    };
    let ply = dir.path().join("out.ply");
    run(&glb_in, &ply, &field);
    let reference: Vec<[u8; 4]> = {
        let mesh = io::read_mesh(&ply).unwrap();
        let layout = mesh.source.layout.as_ref().unwrap();
        let layout = layout.as_any().downcast_ref::<io::PlyLayout>().unwrap();
        let mut rgb = vec![[0u8, 0, 0, 255]; n];
        for (k, name) in ["red", "green", "blue"].iter().enumerate() {
            layout
                .vertex_values(name, |i, v| rgb[i][k] = v as u8)
                .unwrap();
        }
        rgb
    };
    assert!(reference.iter().any(|c| c[0] > c[2]) && reference.iter().any(|c| c[2] > c[0]));
    let colours_of = |json: &Value, bin: &[u8]| -> Vec<[u8; 4]> {
        let a = json["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"]
            .as_u64()
            .unwrap() as usize;
        assert_ne!(a, 3, "the old colours are still drawn");
        let acc = &json["accessors"][a];
        assert_eq!(
            (acc["componentType"].as_u64(), acc["type"].as_str()),
            (Some(5121), Some("VEC4"))
        );
        assert_eq!(acc["normalized"], true);
        assert_eq!(acc["count"].as_u64(), Some(n as u64));
        let view = &json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let at = |v: &Value| v.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
        let start = at(view) + at(acc);
        assert!(at(view) + view["byteLength"].as_u64().unwrap() as usize <= bin.len());
        assert!(start % 4 == 0 && start + 4 * n <= bin.len());
        assert_eq!(
            json["buffers"][0]["byteLength"].as_u64(),
            Some(bin.len() as u64)
        );
        (0..n)
            .map(|i| bin[start + 4 * i..start + 4 * i + 4].try_into().unwrap())
            .collect()
    };
    for (input, out, plain) in [
        (&glb_in, "out.glb", "plain.glb"),
        (&gltf_in, "out.gltf", "plain.gltf"),
    ] {
        let (out, plain) = (dir.path().join(out), dir.path().join(plain));
        run(input, &out, &field);
        run(input, &plain, &[]);
        let (doc, data) = if out.extension().unwrap() == "glb" {
            unglb(&std::fs::read(&out).unwrap())
        } else {
            let doc: Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
            let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_string();
            (doc, std::fs::read(dir.path().join(uri)).unwrap())
        };
        assert!(colours_of(&doc, &data) == reference, "{}", out.display());
        let (a, b) = (io::read_mesh(&out).unwrap(), io::read_mesh(&plain).unwrap());
        assert_eq!(a.positions, b.positions, "{}", out.display());
        assert_eq!(a.triangles, b.triangles);
    }
    assert!(std::fs::read(dir.path().join("scan.bin")).unwrap() == bin);

    let bare = dir.path().join("bare.glb");
    let o = vcsmooth([
        "smooth".as_ref(),
        glb_in.as_os_str(),
        bare.as_os_str(),
        "--deviation-field".as_ref(),
    ]);
    fails(&o, 2, &["bare.glb", "COLOR_0", "--deviation-colours"]);
    assert!(!bare.exists());
}

/// A plain glTF from a PLY with per-vertex colours and texture coordinates carries them
/// (`COLOR_0` in 0..=1, `TEXCOORD_0` turned to glTF's top-left origin), and says nothing dropped.
#[test]
fn a_plain_gltf_carries_a_ply_s_vertex_colours_and_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("tet.ply");
    let rows = [
        "0 0 0 255 0 0 0 0",
        "1 0 0 0 255 0 1 0.25",
        "0 1 0 0 0 255 0 1",
        "0 0 1 51 102 204 0.5 0.75",
    ];
    std::fs::write(
        &ply,
        format!(
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
             property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
             property float s\nproperty float t\nelement face 4\n\
             property list uchar int vertex_indices\nend_header\n{}\n\
             3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
            rows.join("\n")
        ),
    )
    .unwrap();
    let glb = dir.path().join("tet.glb");
    let out = vcsmooth(["smooth".as_ref(), ply.as_os_str(), glb.as_os_str()]);
    assert!(out.status.success());
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("note:"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (json, bin) = unglb(&std::fs::read(&glb).unwrap());
    let colours = super::draco::elements(&json, &bin, super::draco::attribute(&json, 0, "COLOR_0"));
    let uvs = super::draco::elements(&json, &bin, super::draco::attribute(&json, 0, "TEXCOORD_0"));
    for (i, row) in rows.iter().enumerate() {
        let v: Vec<f64> = row.split(' ').map(|t| t.parse().unwrap()).collect();
        for c in 0..3 {
            assert!(
                (colours[i][c] - v[3 + c] / 255.0).abs() < 1e-6,
                "vertex {i}"
            );
        }
        assert!((uvs[i][0] - v[6]).abs() < 1e-7 && (uvs[i][1] - (1.0 - v[7])).abs() < 1e-7);
    }
}
