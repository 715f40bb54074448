//! glTF geometry shared between primitives and meshes is one surface. Every shared file here is
//! checked against a reference: the same sphere as one primitive, its triangles in the order the
//! shared file gives them once each. Smoothing both must give the same positions bit for bit, the
//! shared file must keep its sharing (the same accessors, views and references, one copy of the
//! data), and every accessor naming a vertex must read its one position.

use std::path::Path;

use glam::DVec3;
use serde_json::{Value, json};

use crate::util::{fails, json as parse_json, noisy_sphere, ok, vcsmooth};

/// A glTF buffer being built: its bytes, views and accessors.
#[derive(Default)]
struct Bin {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Bin {
    fn view(&mut self, data: &[u8]) -> usize {
        self.views
            .push(json!({"buffer": 0, "byteOffset": self.bytes.len(), "byteLength": data.len()}));
        self.bytes.extend_from_slice(data);
        while self.bytes.len() % 4 != 0 {
            self.bytes.push(0);
        }
        self.views.len() - 1
    }

    fn accessor(&mut self, a: Value) -> usize {
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    /// A float `VEC3` accessor of `points` in a view of its own.
    fn vec3(&mut self, points: &[DVec3]) -> usize {
        let data: Vec<u8> = points
            .iter()
            .flat_map(|p| p.as_vec3().to_array())
            .flat_map(f32::to_le_bytes)
            .collect();
        let view = self.view(&data);
        self.accessor(json!({"bufferView": view, "componentType": 5126, "count": points.len(), "type": "VEC3"}))
    }

    /// A `u32` index accessor of `triangles` in a view of its own.
    fn indices(&mut self, triangles: &[[u32; 3]]) -> usize {
        let data: Vec<u8> = triangles
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let view = self.view(&data);
        self.accessor(json!({"bufferView": view, "componentType": 5125, "count": 3 * triangles.len(), "type": "SCALAR"}))
    }

    /// Another accessor over the same bytes as `accessor`.
    fn alias(&mut self, accessor: usize) -> usize {
        let a = self.accessors[accessor].clone();
        self.accessor(a)
    }

    /// An accessor over elements `first..first + count` of `accessor`'s.
    fn part(&mut self, accessor: usize, first: usize, count: usize) -> usize {
        let mut a = self.accessors[accessor].clone();
        let at = a.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
        a["byteOffset"] = json!(at + 12 * first);
        a["count"] = json!(count);
        self.accessor(a)
    }

    /// A GLB of this buffer with these meshes, one node for each of `nodes` (a mesh, or a mesh
    /// and a transform).
    fn glb(&self, meshes: Value, nodes: Vec<Value>) -> Vec<u8> {
        let doc = json!({
            "asset": {"version": "2.0", "generator": "hostile_gltf"},
            "scene": 0,
            "scenes": [{"nodes": (0..nodes.len()).collect::<Vec<_>>()}],
            "nodes": nodes,
            "meshes": meshes,
            "buffers": [{"byteLength": self.bytes.len()}],
            "bufferViews": self.views,
            "accessors": self.accessors,
        });
        let mut text = serde_json::to_vec(&doc).unwrap();
        while text.len() % 4 != 0 {
            text.push(b' ');
        }
        let mut out = b"glTF".to_vec();
        let total = 12 + 8 + text.len() + 8 + self.bytes.len();
        for word in [2, total, text.len()] {
            out.extend_from_slice(&(word as u32).to_le_bytes());
        }
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&(self.bytes.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bytes);
        out
    }
}

fn prim(position: usize, indices: usize) -> Value {
    json!({"attributes": {"POSITION": position}, "indices": indices})
}

fn node(mesh: usize) -> Value {
    json!({"mesh": mesh})
}

/// A GLB's JSON and binary chunk.
fn unglb(bytes: &[u8]) -> (Value, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let n = word(12);
    let json = serde_json::from_slice(&bytes[20..20 + n]).unwrap();
    let at = 20 + n;
    (json, bytes[at + 8..at + 8 + word(at)].to_vec())
}

/// The elements of `VEC3` accessor `a` of a GLB.
fn elements(json: &Value, bin: &[u8], a: usize) -> Vec<[f32; 3]> {
    let acc = &json["accessors"][a];
    let view = &json["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let at = |v: &Value| v.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
    let start = at(view) + at(acc);
    let stride = view.get("byteStride").and_then(Value::as_u64).unwrap_or(12) as usize;
    (0..acc["count"].as_u64().unwrap() as usize)
        .map(|i| {
            let f = |k: usize| {
                let b = start + i * stride + 4 * k;
                f32::from_le_bytes(bin[b..b + 4].try_into().unwrap())
            };
            [f(0), f(1), f(2)]
        })
        .collect()
}

fn info(path: &Path) -> Value {
    parse_json(&ok(vcsmooth([
        "info".as_ref(),
        path.as_os_str(),
        "--json".as_ref(),
    ])))
}

fn count(info: &Value, key: &str) -> u64 {
    info[key]
        .as_u64()
        .unwrap_or_else(|| panic!("no {key} in {info}"))
}

fn smooth(input: &Path, output: &Path) {
    ok(vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--iterations".as_ref(),
        "3".as_ref(),
    ]));
}

/// The sphere every case shares: its positions and triangles.
fn sphere() -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let m = noisy_sphere(2, 0.3, 11);
    (m.positions.to_vec(), m.triangles.to_vec())
}

/// Smooths `shared` and the reference (the sphere as one primitive, `order` its triangles) and
/// checks: the shared file reads as the one closed sphere, smooths exactly like it, keeps its
/// JSON but for `min`/`max`, and every accessor in `positions` (each with the first sphere vertex
/// it starts at) reads the smoothed sphere's positions.
fn same_as_one_sphere(name: &str, shared: &[u8], order: &[[u32; 3]], positions: &[(usize, usize)]) {
    let dir = tempfile::tempdir().unwrap();
    let at = |n: &str| dir.path().join(n);
    let (points, _) = sphere();
    let mut reference = Bin::default();
    let (p, i) = (reference.vec3(&points), reference.indices(order));
    let one = reference.glb(json!([{"primitives": [prim(p, i)]}]), vec![node(0)]);
    std::fs::write(at("one.glb"), one).unwrap();
    std::fs::write(at("shared.glb"), shared).unwrap();

    let (a, b) = (info(&at("one.glb")), info(&at("shared.glb")));
    for key in [
        "vertices",
        "triangles",
        "non_manifold_edges",
        "boundary_edges",
    ] {
        assert_eq!(count(&a, key), count(&b, key), "{name}: {key}");
    }
    assert_eq!(count(&b, "non_manifold_edges"), 0, "{name}");

    smooth(&at("one.glb"), &at("one-out.glb"));
    smooth(&at("shared.glb"), &at("shared-out.glb"));
    let (one_json, one_bin) = unglb(&std::fs::read(at("one-out.glb")).unwrap());
    let smoothed = elements(&one_json, &one_bin, 0);
    let input: Vec<[f32; 3]> = points.iter().map(|p| p.as_vec3().to_array()).collect();
    assert_ne!(smoothed, input, "{name}: the reference did not move");

    let (in_json, _) = unglb(shared);
    let (out_json, out_bin) = unglb(&std::fs::read(at("shared-out.glb")).unwrap());
    assert_eq!(
        out_bin.len(),
        unglb(shared).1.len(),
        "{name}: the buffer grew"
    );
    let mut stripped = out_json.clone();
    for a in stripped["accessors"].as_array_mut().unwrap() {
        let a = a.as_object_mut().unwrap();
        a.remove("min");
        a.remove("max");
    }
    assert_eq!(stripped, in_json, "{name}: the JSON changed beyond min/max");
    for &(accessor, first) in positions {
        let got = elements(&out_json, &out_bin, accessor);
        assert_eq!(
            got,
            smoothed[first..first + got.len()],
            "{name}: accessor {accessor}"
        );
        let lo: Vec<f32> = (0..3)
            .map(|k| got.iter().map(|p| p[k]).fold(f32::INFINITY, f32::min))
            .collect();
        let min: Vec<f32> = serde_json::from_value(out_json["accessors"][accessor]["min"].clone())
            .unwrap_or_else(|_| panic!("{name}: accessor {accessor} has no min"));
        assert_eq!(min, lo, "{name}: accessor {accessor}'s min");
    }
}

/// The same primitive (one `POSITION` accessor, one index accessor) twice: in two meshes each
/// placed by its own node, in one mesh as two primitives, and one mesh placed by two nodes with
/// different transforms.
#[test]
fn one_primitive_named_twice_is_one_surface() {
    let (points, triangles) = sphere();
    let mut bin = Bin::default();
    let (p, i) = (bin.vec3(&points), bin.indices(&triangles));
    let cases = [
        (
            "two meshes",
            bin.glb(
                json!([{"primitives": [prim(p, i)]}, {"primitives": [prim(p, i)]}]),
                vec![node(0), json!({"mesh": 1, "translation": [3.0, 0.0, 0.0]})],
            ),
        ),
        (
            "two primitives",
            bin.glb(
                json!([{"primitives": [prim(p, i), prim(p, i)]}]),
                vec![node(0)],
            ),
        ),
        (
            "two nodes",
            bin.glb(
                json!([{"primitives": [prim(p, i)]}]),
                vec![
                    json!({"mesh": 0, "scale": [2.0, 2.0, 2.0]}),
                    json!({"mesh": 0, "scale": [-1.0, 1.0, 1.0], "translation": [0.0, 5.0, 0.0]}),
                ],
            ),
        ),
    ];
    for (name, file) in cases {
        same_as_one_sphere(name, &file, &triangles, &[(p, 0)]);
    }
}

/// Accessors that are not the same index but name the same bytes: a second `POSITION` and index
/// accessor over the first ones' views (as exporters write one set per mesh), and `NORMAL`
/// accessors aliased the same way.
#[test]
fn accessors_over_the_same_bytes_are_the_same_vertices() {
    let (points, triangles) = sphere();
    let mut bin = Bin::default();
    let (p, i) = (bin.vec3(&points), bin.indices(&triangles));
    let normals: Vec<DVec3> = points.iter().map(|p| p.normalize()).collect();
    let n = bin.vec3(&normals);
    let (p2, i2, n2) = (bin.alias(p), bin.alias(i), bin.alias(n));
    let with_normals = |p: usize, i: usize, n: usize| json!({"primitives": [{"attributes": {"POSITION": p, "NORMAL": n}, "indices": i}]});
    let file = bin.glb(
        json!([with_normals(p, i, n), with_normals(p2, i2, n2)]),
        vec![node(0), node(1)],
    );
    same_as_one_sphere("aliased", &file, &triangles, &[(p, 0), (p2, 0)]);
    let (json, out) = {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.glb"), dir.path().join("b.glb"));
        std::fs::write(&a, &file).unwrap();
        smooth(&a, &b);
        unglb(&std::fs::read(&b).unwrap())
    };
    // The normals were recomputed once, for the one surface: unit length, the same through both.
    let (first, second) = (elements(&json, &out, n), elements(&json, &out, n2));
    assert_eq!(first, second);
    assert_ne!(
        first,
        normals
            .iter()
            .map(|p| p.as_vec3().to_array())
            .collect::<Vec<_>>()
    );
    for v in &first {
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-5, "a normal of length {len}");
    }
}

/// Two primitives on one `POSITION` accessor with index accessors of their own: disjoint halves,
/// overlapping parts (the overlap once), and the second the whole surface again in the other
/// winding (a back face).
#[test]
fn index_accessors_over_shared_positions_give_each_triangle_once() {
    let (points, triangles) = sphere();
    let n = triangles.len();
    let reversed: Vec<[u32; 3]> = triangles.iter().map(|&[a, b, c]| [a, c, b]).collect();
    type Triangles<'a> = &'a [[u32; 3]];
    let cases: [(&str, Triangles, Triangles); 4] = [
        ("disjoint", &triangles[..n / 2], &triangles[n / 2..]),
        ("overlapping", &triangles[..2 * n / 3], &triangles[n / 3..]),
        (
            "the second within the first",
            &triangles,
            &triangles[n / 4..n / 2],
        ),
        ("a back face", &triangles, &reversed),
    ];
    for (name, first, second) in cases {
        let mut bin = Bin::default();
        let p = bin.vec3(&points);
        let (a, b) = (bin.indices(first), bin.indices(second));
        let file = bin.glb(
            json!([{"primitives": [prim(p, a)]}, {"primitives": [prim(p, b)]}]),
            vec![node(0), node(1)],
        );
        same_as_one_sphere(name, &file, &triangles, &[(p, 0)]);
    }
}

/// A `POSITION` accessor over part of another's elements (a sub-range of the same view): the
/// vertices in both are the same vertices.
#[test]
fn an_accessor_over_part_of_the_positions_shares_those_vertices() {
    let (points, triangles) = sphere();
    let k = points.len() / 3;
    let (high, low): (Vec<[u32; 3]>, Vec<[u32; 3]>) = triangles
        .iter()
        .partition(|t| t.iter().all(|&v| v as usize >= k));
    let rebased: Vec<[u32; 3]> = high.iter().map(|t| t.map(|v| v - k as u32)).collect();
    assert!(!high.is_empty() && !low.is_empty());
    let mut bin = Bin::default();
    let p = bin.vec3(&points);
    let (a, b) = (bin.indices(&low), bin.indices(&rebased));
    let part = bin.part(p, k, points.len() - k);
    let file = bin.glb(
        json!([{"primitives": [prim(p, a), prim(part, b)]}]),
        vec![node(0)],
    );
    let order: Vec<[u32; 3]> = low.iter().chain(&high).copied().collect();
    same_as_one_sphere("part", &file, &order, &[(p, 0), (part, k)]);

    // The part first: the vertices keep the buffer's order all the same.
    let file = bin.glb(
        json!([{"primitives": [prim(part, b), prim(p, a)]}]),
        vec![node(0)],
    );
    let order: Vec<[u32; 3]> = high.iter().chain(&low).copied().collect();
    same_as_one_sphere("part first", &file, &order, &[(p, 0), (part, k)]);
}

/// One index accessor on two different `POSITION` accessors (their own bytes) is two surfaces:
/// each is closed and manifold, and each moves.
#[test]
fn shared_indices_on_different_positions_are_two_surfaces() {
    let dir = tempfile::tempdir().unwrap();
    let (points, triangles) = sphere();
    let moved: Vec<DVec3> = points.iter().map(|&p| p + DVec3::X * 4.0).collect();
    let mut bin = Bin::default();
    let (p, i) = (bin.vec3(&points), bin.indices(&triangles));
    let q = bin.vec3(&moved);
    let file = bin.glb(
        json!([{"primitives": [prim(p, i), prim(q, i)]}]),
        vec![node(0)],
    );
    let (input, output) = (dir.path().join("two.glb"), dir.path().join("out.glb"));
    std::fs::write(&input, &file).unwrap();
    let i0 = info(&input);
    assert_eq!(count(&i0, "vertices"), 2 * points.len() as u64);
    assert_eq!(count(&i0, "triangles"), 2 * triangles.len() as u64);
    assert_eq!(count(&i0, "non_manifold_edges"), 0);
    assert_eq!(count(&i0, "components"), 2);
    smooth(&input, &output);
    let (json, out) = unglb(&std::fs::read(&output).unwrap());
    for (a, before) in [(p, &points), (q, &moved)] {
        let before: Vec<[f32; 3]> = before.iter().map(|p| p.as_vec3().to_array()).collect();
        let after = elements(&json, &out, a);
        let moved = before.iter().zip(&after).filter(|(x, y)| x != y).count();
        assert!(
            moved > before.len() / 2,
            "accessor {a}: {moved} vertices moved"
        );
    }
}

/// Elements that overlap without lining up (an accessor 4 bytes into another's) cannot be one
/// vertex each: refused, one line, no output.
#[test]
fn positions_overlapping_out_of_step_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (points, triangles) = sphere();
    let mut bin = Bin::default();
    let (p, i) = (bin.vec3(&points), bin.indices(&triangles));
    let mut skewed = bin.accessors[p].clone();
    skewed["byteOffset"] = json!(4);
    skewed["count"] = json!(points.len() - 1);
    let s = bin.accessor(skewed);
    let few: Vec<[u32; 3]> = triangles
        .iter()
        .filter(|t| t.iter().all(|&v| (v as usize) < points.len() - 1))
        .copied()
        .collect();
    let j = bin.indices(&few);
    let file = bin.glb(
        json!([{"primitives": [prim(p, i), prim(s, j)]}]),
        vec![node(0)],
    );
    let (input, output) = (dir.path().join("skew.glb"), dir.path().join("out.glb"));
    std::fs::write(&input, &file).unwrap();
    let o = vcsmooth(["smooth".as_ref(), input.as_os_str(), output.as_os_str()]);
    fails(&o, 1, &["skew.glb", "shares bytes"]);
    assert!(!output.exists());
}
