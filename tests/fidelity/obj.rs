//! Fidelity of obj files (see tests/fidelity.rs): a textured, vertex-coloured cube with `mtllib`,
//! `o`, `g`, `s`, `usemtl`, per-corner `vt` and `vn`, relative indices, quads and triangles
//! (`tests/data/fidelity/textured.obj`) comes back from `smooth` with only its `v` coordinates and
//! `vn` normals rewritten.

use std::path::{Path, PathBuf};

use glam::DVec3;
use vcsmooth::io;

use crate::util::{failed_with, json, ok, root, vcsmooth};

fn fixture() -> PathBuf {
    root().join("tests/data/fidelity/textured.obj")
}

fn smooth(input: &Path, output: &Path, args: &[&str]) {
    let mut all = vec!["smooth", input.to_str().unwrap(), output.to_str().unwrap()];
    all.extend(args);
    ok(vcsmooth(all));
}

/// A `v` or `vn` line cut around its first three numbers: the text before them, the numbers,
/// and the text after them.
fn cut(line: &str) -> (&str, DVec3, &str) {
    let mut spans = line.split_ascii_whitespace().map(|t| {
        let start = t.as_ptr() as usize - line.as_ptr() as usize;
        (start, start + t.len())
    });
    spans.next();
    let spans: Vec<_> = spans.take(3).collect();
    let xyz = spans.iter().map(|&(s, e)| line[s..e].parse().unwrap());
    let xyz: Vec<f64> = xyz.collect();
    (
        &line[..spans[0].0],
        DVec3::from_slice(&xyz),
        &line[spans[2].1..],
    )
}

/// 0-based index of OBJ reference `r` among `defined` elements.
fn resolve(r: &str, defined: usize) -> usize {
    let r: i64 = r.parse().unwrap();
    if r < 0 {
        (defined as i64 + r) as usize
    } else {
        r as usize - 1
    }
}

/// The normal of every `vn` by the documented rule, from the OBJ text: the normalised sum, over
/// the corners that refer to it, of the cross products of the face's fan triangles with that
/// corner; `None` for a normal no corner refers to.
fn expected_normals(text: &str) -> Vec<Option<DVec3>> {
    let (mut positions, mut sums) = (Vec::new(), Vec::new());
    for line in text.lines() {
        match line.split_ascii_whitespace().next() {
            Some("v") => positions.push(cut(line).1),
            Some("vn") => sums.push(DVec3::ZERO),
            Some("f") => {
                let corners: Vec<(usize, Option<usize>)> = line
                    .split_ascii_whitespace()
                    .skip(1)
                    .map(|c| {
                        let parts: Vec<&str> = c.split('/').collect();
                        let n = parts.get(2).map(|n| resolve(n, sums.len()));
                        (resolve(parts[0], positions.len()), n)
                    })
                    .collect();
                for k in 1..corners.len() - 1 {
                    let fan = [0, k, k + 1];
                    let [a, b, c] = fan.map(|j| positions[corners[j].0]);
                    for j in fan {
                        if let Some(n) = corners[j].1 {
                            sums[n] += (b - a).cross(c - a);
                        }
                    }
                }
            }
            _ => {}
        }
    }
    sums.iter().map(|n| n.try_normalize()).collect()
}

fn volume(path: &Path) -> f64 {
    let info = json(&ok(vcsmooth(["info", path.to_str().unwrap(), "--json"])));
    info["volume"].as_f64().unwrap()
}

#[test]
fn a_smoothed_textured_obj_keeps_every_line_but_positions_and_normals() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.obj");
    smooth(&fixture(), &out, &[]);
    let before = std::fs::read_to_string(fixture()).unwrap();
    let after = std::fs::read_to_string(&out).unwrap();
    assert_eq!(before.lines().count(), after.lines().count());

    let expected = expected_normals(&after);
    let (mut moved, mut turned, mut normals) = (0, 0, 0);
    for (a, b) in before.lines().zip(after.lines()) {
        match a.split_ascii_whitespace().next() {
            Some(keyword @ ("v" | "vn")) => {
                let ((head_a, p, tail_a), (head_b, q, tail_b)) = (cut(a), cut(b));
                // The keyword, and the colour and comment after the numbers, byte for byte.
                assert_eq!((head_a, tail_a), (head_b, tail_b), "{a:?} -> {b:?}");
                if keyword == "v" {
                    moved += usize::from(p.distance(q) > 1e-3);
                    continue;
                }
                let k = normals;
                normals += 1;
                let Some(e) = expected[k] else {
                    // No corner refers to it: kept as it was.
                    assert_eq!(a, b);
                    continue;
                };
                turned += usize::from(p.distance(q) > 1e-3);
                assert!((q.length() - 1.0).abs() < 1e-6, "vn {k}: {q}");
                assert!(q.distance(e) < 1e-6, "vn {k}: {q}, expected {e}");
            }
            _ => assert_eq!(a, b),
        }
    }
    assert_eq!(normals, expected.len());
    // Smoothing moved the vertices, and the normals followed.
    assert!(moved > 20 && turned > 20, "{moved} moved, {turned} turned");
    // The smooth normals of the vertices only on the top (which uses its flat normal) and the
    // side without normals are used by no corner: the two centres and the middle of their edge.
    assert_eq!(expected.iter().filter(|e| e.is_none()).count(), 3);

    let (v0, v1) = (volume(&fixture()), volume(&out));
    assert!(((v1 - v0) / v0).abs() < 1e-6, "volume {v0} -> {v1}");
}

/// With nothing smoothed, the positions are written back as the text they came as (shortest
/// round-trip text), and only the `vn` lines change (recomputed from the noisy input).
#[test]
fn an_unsmoothed_textured_obj_changes_only_its_normals() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.obj");
    smooth(&fixture(), &out, &["--iterations", "0"]);
    let before = std::fs::read_to_string(fixture()).unwrap();
    let after = std::fs::read_to_string(&out).unwrap();
    let mut normals = 0;
    for (a, b) in before.lines().zip(after.lines()) {
        if a.starts_with("vn ") {
            normals += 1;
        } else {
            assert_eq!(a, b);
        }
    }
    assert_eq!(normals, 27);
    assert_eq!(
        before.len() - before.trim_end().len(),
        1,
        "one final newline"
    );
    assert!(after.ends_with('\n') && !after.ends_with("\n\n"));
}

#[test]
fn the_textured_obj_carries_uvs_colours_normals_materials_and_other_statements() {
    let mesh = io::read_mesh(&fixture()).unwrap();
    let carried = mesh.source.layout.unwrap().carries();
    assert!(carried.uvs && carried.colours && carried.normals && carried.materials);
    assert_eq!(carried.other, ["o", "vendor_tag", "g", "s"]);

    // A bare OBJ (only `v x y z` and `f`) keeps nothing and is written as before.
    let bare = io::read_mesh_bytes(
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
        Path::new("bare.obj"),
    )
    .unwrap();
    assert!(bare.source.layout.is_none());
}

#[test]
fn a_textured_obj_with_other_faces_is_not_written_over_its_text() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = io::read_mesh(&fixture()).unwrap();
    mesh.triangles.heap_mut()[0].swap(1, 2);
    mesh.source.face_sizes = None;
    let e = io::write_mesh(&dir.path().join("a.obj"), &mesh)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no longer match the OBJ source's faces"), "{e}");
    // Without the layout it is a plain OBJ.
    mesh.source.layout = None;
    io::write_mesh(&dir.path().join("a.obj"), &mesh).unwrap();
}

/// Texture and normal references are written back, so they must exist.
#[test]
fn an_obj_referring_to_missing_texture_coordinates_or_normals_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let head = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvn 0 0 1\n";
    for (face, problem) in [
        (
            "f 1/1 2/2 3/3",
            "face 0 (line 7): texture index 3 out of range (1..=2)",
        ),
        (
            "f 1//1 2//1 3//2",
            "face 0 (line 7): normal index 2 out of range (1..=1)",
        ),
        (
            "f 1/-3 2/1 3/2",
            "face 0 (line 7): texture index -3 points before the first texture coordinate (2 \
             defined so far)",
        ),
        (
            "f 1/0 2/1 3/2",
            "face 0 (line 7): texture index 0 (OBJ indices start at 1)",
        ),
    ] {
        let input = dir.path().join("bad.obj");
        let output = dir.path().join("out.obj");
        std::fs::write(&input, format!("{head}{face}\n")).unwrap();
        let run = vcsmooth(["smooth", input.to_str().unwrap(), output.to_str().unwrap()]);
        let line = format!("{}: {problem}", input.display());
        failed_with(&run, &line).unwrap();
        assert!(!output.exists());
    }
}
