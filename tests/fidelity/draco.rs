//! Draco-compressed glTF (see tests/fidelity.rs): `tests/data/formats/torus_box.*.glb`, a bumpy
//! torus with a UV seam and a box, compressed by Google's encoder (EdgeBreaker, EdgeBreaker at
//! speed 0 = valence connectivity, sequential). Each reads to the uncompressed original's
//! triangles within the quantisation, is smoothed and written uncompressed with every other
//! attribute carried and the volume kept, also from a `.gltf` with an external `.bin`; damaged
//! Draco data and meshopt are refused in one line.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde_json::{Value, json};
use vcsmooth::io;

use super::gltf::{glb, unglb, volume};
use crate::util::{fails, ok, root, vcsmooth};

const DRACO: [&str; 3] = [
    "torus_box.draco_edgebreaker.glb",
    "torus_box.draco_edgebreaker_speed0.glb",
    "torus_box.draco_sequential.glb",
];

/// The volume is kept exactly, then the positions are stored as `f32` (glTF's only float): each
/// coordinate moves by up to half an ulp (2^-24 relative), the volume by some 1e-9 (2.3e-9
/// measured here), so 1e-9 is out of reach; a volume not kept fails by far (plain Laplacian
/// smoothing loses 24 % of this torus in ten iterations).
const VOLUME: f64 = 1e-8;

fn formats(name: &str) -> PathBuf {
    root().join("tests/data/formats").join(name)
}

/// An accessor's elements as floats (float or unsigned normalised-or-not components), read from
/// `bin` (the GLB's buffer 0).
pub(super) fn elements(json: &Value, bin: &[u8], accessor: usize) -> Vec<Vec<f64>> {
    let a = &json["accessors"][accessor];
    let v = &json["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
    assert_eq!(v["buffer"], 0);
    let n = match a["type"].as_str().unwrap() {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" => 4,
        t => panic!("type {t}"),
    };
    let ct = a["componentType"].as_u64().unwrap();
    let size = match ct {
        5121 => 1,
        5123 => 2,
        _ => 4,
    };
    let stride = v["byteStride"].as_u64().map_or(n * size, |s| s as usize);
    let start = v["byteOffset"].as_u64().unwrap_or(0) as usize
        + a["byteOffset"].as_u64().unwrap_or(0) as usize;
    (0..a["count"].as_u64().unwrap() as usize)
        .map(|i| {
            (0..n)
                .map(|k| {
                    let b = &bin[start + i * stride + k * size..];
                    match ct {
                        5121 => f64::from(b[0]),
                        5123 => f64::from(u16::from_le_bytes([b[0], b[1]])),
                        5125 => f64::from(u32::from_le_bytes(b[..4].try_into().unwrap())),
                        5126 => f64::from(f32::from_le_bytes(b[..4].try_into().unwrap())),
                        c => panic!("componentType {c}"),
                    }
                })
                .collect()
        })
        .collect()
}

fn draco_left(json: &Value) -> bool {
    json.to_string().contains("KHR_draco_mesh_compression")
}

fn smooth(input: &Path, output: &Path, extra: &[&str]) -> String {
    let mut args: Vec<&std::ffi::OsStr> =
        vec!["smooth".as_ref(), input.as_os_str(), output.as_os_str()];
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    ok(vcsmooth(args))
}

/// The positions and triangles of a glTF file, as the library reads it.
fn read(path: &Path) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let mesh = io::read_mesh(path).unwrap();
    (mesh.positions.to_vec(), mesh.triangles.to_vec())
}

/// Each Draco file reads to the original's triangles (each corner's position within half a
/// 14-bit quantisation step of the bounding box, per coordinate; winding kept; as many
/// triangles), and knows it was decompressed.
#[test]
fn draco_reads_to_the_original_triangles() {
    let (original, original_triangles) = read(&formats("torus_box.glb"));
    let (lo, hi) = original
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    // Draco quantises each primitive's positions on a grid of 2^14 - 1 steps over its largest
    // extent; the whole file's extent bounds every primitive's.
    let step = (hi - lo).max_element() / f64::from((1 << 14) - 1);
    let bound = 0.5 * step * 3f64.sqrt() * 1.001;
    assert!(bound < 1e-3, "bound {bound}");
    // Original vertices at one position (the UV seam's copies) are one class.
    let mut class: Vec<usize> = (0..original.len()).collect();
    for i in 0..original.len() {
        for j in 0..i {
            if original[i].distance(original[j]) < 1e-5 {
                class[i] = class[j];
                break;
            }
        }
    }
    let key = |t: [usize; 3]| {
        // Rotated to start at the least: the winding is kept.
        let r = (0..3).min_by_key(|&k| t[k]).unwrap();
        [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
    };
    let mut expected: HashMap<[usize; 3], i32> = HashMap::new();
    for t in &original_triangles {
        *expected
            .entry(key(t.map(|v| class[v as usize])))
            .or_default() += 1;
    }
    for name in DRACO {
        let mesh = io::read_mesh(&formats(name)).unwrap();
        assert!(
            io::GltfLayout::decompressed_in(&mesh),
            "{name}: not flagged as decompressed"
        );
        assert_eq!(mesh.triangles.len(), original_triangles.len(), "{name}");
        let mut worst: f64 = 0.0;
        let nearest: Vec<usize> = mesh
            .positions
            .iter()
            .map(|p| {
                let (j, d) = original
                    .iter()
                    .enumerate()
                    .map(|(j, q)| (j, p.distance(*q)))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .unwrap();
                worst = worst.max(d);
                class[j]
            })
            .collect();
        assert!(
            worst <= bound,
            "{name}: a position is {worst} away (bound {bound})"
        );
        let mut got: HashMap<[usize; 3], i32> = HashMap::new();
        for t in mesh.triangles.iter() {
            *got.entry(key(t.map(|v| nearest[v as usize]))).or_default() += 1;
        }
        assert_eq!(got, expected, "{name}: other triangles");
    }
    let plain = io::read_mesh(&formats("torus_box.glb")).unwrap();
    assert!(!io::GltfLayout::decompressed_in(&plain));
}

/// Smoothing a Draco GLB writes a plain GLB: no Draco left, every attribute but positions and
/// normals as decoded (the same bytes as a conversion writes), the UVs and colours within the
/// quantisation of the original's, the volume kept.
#[test]
fn draco_glb_is_smoothed_and_written_uncompressed() {
    let dir = tempfile::tempdir().unwrap();
    let (json0, bin0) = unglb(&std::fs::read(formats("torus_box.glb")).unwrap());
    let uv0 = elements(&json0, &bin0, attribute(&json0, 0, "TEXCOORD_0"));
    let colour0 = elements(&json0, &bin0, attribute(&json0, 0, "COLOR_0"));
    for name in DRACO {
        let input = formats(name);
        let plain = dir.path().join(format!("plain-{name}"));
        let output = dir.path().join(format!("out-{name}"));
        smooth(&input, &plain, &["--iterations", "0"]);
        // The one note that says the output is not compressed.
        let out = vcsmooth(["smooth".as_ref(), input.as_os_str(), output.as_os_str()]);
        let err = String::from_utf8_lossy(&out.stderr);
        let notes: Vec<&str> = err.lines().filter(|l| l.contains("note:")).collect();
        assert!(out.status.success(), "{err}");
        assert_eq!(notes.len(), 1, "{err}");
        assert!(
            notes[0].contains("written without the input's Draco compression"),
            "{err}"
        );
        let (jp, bp) = unglb(&std::fs::read(&plain).unwrap());
        let (jo, bo) = unglb(&std::fs::read(&output).unwrap());
        for j in [&jp, &jo] {
            assert!(!draco_left(j), "{name}: Draco left in {j}");
        }
        for attr in ["TEXCOORD_0", "COLOR_0"] {
            let (a, b) = (attribute(&jp, 0, attr), attribute(&jo, 0, attr));
            assert_eq!(
                elements(&jp, &bp, a),
                elements(&jo, &bo, b),
                "{name}: {attr} not carried"
            );
        }
        // The positions moved; everything is read back.
        let (pp, tp) = read(&plain);
        let (po, to) = read(&output);
        assert_eq!(tp, to, "{name}: triangles changed");
        assert!(
            pp.iter().zip(&po).any(|(a, b)| a != b),
            "{name}: nothing moved"
        );
        let (v0, v1) = (volume(&input), volume(&output));
        assert!(
            ((v1 - v0) / v0).abs() <= VOLUME,
            "{name}: volume {v0} -> {v1}"
        );
        // Each decoded vertex has the UV and colour of an original vertex at its position, within
        // the quantisation (12 bits for UVs, 8 for colours, over their ranges [0, 1]).
        let uv = elements(&jp, &bp, attribute(&jp, 0, "TEXCOORD_0"));
        let colour = elements(&jp, &bp, attribute(&jp, 0, "COLOR_0"));
        let positions = elements(&jp, &bp, attribute(&jp, 0, "POSITION"));
        let p0 = elements(&json0, &bin0, attribute(&json0, 0, "POSITION"));
        let close = |a: &[f64], b: &[f64], within: f64| {
            a.iter().zip(b).all(|(x, y)| (x - y).abs() <= within)
        };
        for i in 0..uv.len() {
            let found = (0..p0.len()).any(|j| {
                close(&positions[i], &p0[j], 1e-3)
                    && close(&uv[i], &uv0[j], 0.5 / 4095.0 * 1.001)
                    && close(&colour[i], &colour0[j], 0.5 / 255.0 * 1.001)
            });
            assert!(found, "{name}: vertex {i} has no original match");
        }
    }
}

/// The accessor of attribute `name` of mesh `mesh`'s first primitive.
pub(super) fn attribute(json: &Value, mesh: usize, name: &str) -> usize {
    json["meshes"][mesh]["primitives"][0]["attributes"][name]
        .as_u64()
        .unwrap_or_else(|| panic!("no {name}")) as usize
}

/// A `.gltf` with an external `.bin` made from a Draco GLB: read, smoothed, its decoded data
/// written to the output's `.bin`, the input's files untouched.
#[test]
fn draco_gltf_with_external_bin() {
    let dir = tempfile::tempdir().unwrap();
    let (mut json, bin) = unglb(&std::fs::read(formats(DRACO[0])).unwrap());
    json["buffers"][0]["uri"] = json!("in.bin");
    let input = dir.path().join("in.gltf");
    std::fs::write(&input, serde_json::to_vec(&json).unwrap()).unwrap();
    std::fs::write(dir.path().join("in.bin"), &bin).unwrap();
    let output = dir.path().join("out.gltf");
    smooth(&input, &output, &[]);
    assert_eq!(std::fs::read(dir.path().join("in.bin")).unwrap(), bin);
    let after: Value = serde_json::from_slice(&std::fs::read(&output).unwrap()).unwrap();
    assert!(!draco_left(&after));
    assert_eq!(after["buffers"][0]["uri"], "out.bin");
    let out_bin = std::fs::read(dir.path().join("out.bin")).unwrap();
    assert_eq!(
        out_bin.len() as u64,
        after["buffers"][0]["byteLength"].as_u64().unwrap()
    );
    let (_, t_in) = read(&input);
    let (_, t_out) = read(&output);
    assert_eq!(t_in, t_out);
    let (v0, v1) = (volume(&input), volume(&output));
    assert!(((v1 - v0) / v0).abs() <= VOLUME, "volume {v0} -> {v1}");
    // The same data as from the GLB.
    let from_glb = read(&formats(DRACO[0]));
    assert_eq!(read(&input), from_glb);
}

/// Two primitives naming the same Draco data and accessors are one surface, decoded once: the
/// output holds one copy of it.
#[test]
fn shared_draco_data_is_decoded_once() {
    let dir = tempfile::tempdir().unwrap();
    let (mut json, bin) = unglb(&std::fs::read(formats(DRACO[0])).unwrap());
    let torus = json["meshes"][0].clone();
    json["meshes"].as_array_mut().unwrap().push(torus);
    let nodes = json["nodes"].as_array().unwrap().len();
    json["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!({"mesh": 2, "translation": [5.0, 0.0, 0.0]}));
    json["scenes"][0]["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!(nodes));
    let input = dir.path().join("twice.glb");
    std::fs::write(&input, glb(&json, &bin)).unwrap();
    let once = io::read_mesh(&formats(DRACO[0])).unwrap();
    let twice = io::read_mesh(&input).unwrap();
    assert_eq!(twice.positions.len(), once.positions.len());
    assert_eq!(twice.triangles.len(), once.triangles.len());
    let output = dir.path().join("out.glb");
    smooth(&input, &output, &[]);
    let (after, out_bin) = unglb(&std::fs::read(&output).unwrap());
    let (single, single_bin) = unglb(
        &std::fs::read(&{
            let o = dir.path().join("single.glb");
            smooth(&formats(DRACO[0]), &o, &[]);
            o
        })
        .unwrap(),
    );
    assert_eq!(out_bin.len(), single_bin.len(), "decoded twice");
    assert_eq!(
        after["meshes"][2]["primitives"][0]["attributes"],
        after["meshes"][0]["primitives"][0]["attributes"]
    );
    assert_eq!(
        after["bufferViews"].as_array().unwrap().len(),
        single["bufferViews"].as_array().unwrap().len()
    );
}

/// Damaged Draco data, counts that disagree with the accessors, and meshopt: one line each.
#[test]
fn damaged_draco_and_meshopt_are_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (json, bin) = unglb(&std::fs::read(formats(DRACO[0])).unwrap());
    let ext = "/meshes/0/primitives/0/extensions/KHR_draco_mesh_compression/bufferView";
    let view = json.pointer(ext).unwrap().as_u64().unwrap() as usize;
    let offset = json["bufferViews"][view]["byteOffset"]
        .as_u64()
        .unwrap_or(0) as usize;
    let length = json["bufferViews"][view]["byteLength"].as_u64().unwrap() as usize;
    let mut truncated = json.clone();
    truncated["bufferViews"][view]["byteLength"] = json!(length / 2);
    let mut no_magic = bin.clone();
    no_magic[offset..offset + 5].copy_from_slice(b"XXXXX");
    let mut zeroed = bin.clone();
    zeroed[offset + 16..offset + length].fill(0);
    let mut count = json.clone();
    let position = attribute(&json, 0, "POSITION");
    count["accessors"][position]["count"] = json!(1000);
    let mut meshopt = json.clone();
    meshopt["extensionsUsed"]
        .as_array_mut()
        .unwrap()
        .push(json!("EXT_meshopt_compression"));
    let cases: Vec<(&str, Vec<u8>, Vec<&str>)> = vec![
        (
            "truncated.glb",
            glb(&truncated, &bin),
            vec!["mesh 0 primitive 0: Draco data could not be decoded ("],
        ),
        (
            "magic.glb",
            glb(&json, &no_magic),
            vec!["mesh 0 primitive 0: Draco data could not be decoded ("],
        ),
        (
            "zeroed.glb",
            glb(&json, &zeroed),
            vec!["mesh 0 primitive 0: Draco data could not be decoded ("],
        ),
        (
            "count.glb",
            glb(&count, &bin),
            vec![
                "mesh 0 primitive 0: POSITION",
                "count is 1000",
                "1617 points",
            ],
        ),
        (
            "meshopt.glb",
            glb(&meshopt, &bin),
            vec!["EXT_meshopt_compression (meshopt-compressed geometry) is not supported"],
        ),
    ];
    for (name, bytes, mentions) in cases {
        let input = dir.path().join(name);
        std::fs::write(&input, bytes).unwrap();
        let out = vcsmooth(["info".as_ref(), input.as_os_str()]);
        fails(&out, 1, &mentions);
        assert!(
            !crate::util::stderr(&out).contains("compression compression"),
            "{name}"
        );
        let output = dir.path().join(format!("out-{name}"));
        let out = vcsmooth(["smooth".as_ref(), input.as_os_str(), output.as_os_str()]);
        fails(&out, 1, &mentions);
        assert!(!output.exists(), "{name}: an output was written");
    }
}
