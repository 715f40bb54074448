//! The deviation field (`smooth --deviation-field`, `compare`), its statistics, the tolerance's
//! exit code, and the record of a run in `--report`: known displacements give the known field and
//! figures; the field is the same for any thread count, memory budget and storage, and the same as
//! `compare` measures on the files; the output is otherwise unchanged.

use std::path::Path;

use glam::DVec3;
use vcsmooth::io::{self, PlyLayout};
use vcsmooth::{Mesh, metrics};

use crate::util::{fails, json, ok, read_json, scan, stderr, stdout, vcsmooth};

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// A flat `n × n` grid in the plane z = 0, unit spacing, two triangles per cell (normals +z).
fn grid(n: u32) -> Mesh {
    let positions = (0..n * n)
        .map(|i| DVec3::new((i % n) as f64, (i / n) as f64, 0.0))
        .collect();
    let mut triangles = Vec::new();
    for y in 0..n - 1 {
        for x in 0..n - 1 {
            let v = y * n + x;
            triangles.push([v, v + 1, v + n + 1]);
            triangles.push([v, v + n + 1, v + n]);
        }
    }
    Mesh::new(positions, triangles)
}

/// The grid with every fourth vertex moved down by 0.5 and the others up by 0.25.
fn displaced(a: &Mesh) -> Mesh {
    let mut b = a.clone();
    for (i, p) in b.positions.iter_mut().enumerate() {
        p.z += if i % 4 == 0 { -0.5 } else { 0.25 };
    }
    b
}

/// The values of the PLY vertex property `name` of the file at `path`.
fn vertex_values(path: &Path, name: &str) -> Vec<f64> {
    let mesh = io::read_mesh(path).unwrap();
    let layout = mesh.source.layout.as_ref().expect("a PLY layout");
    let ply = layout.as_any().downcast_ref::<PlyLayout>().unwrap();
    let mut values = vec![f64::NAN; mesh.positions.len()];
    ply.vertex_values(name, |i, v| values[i] = v).unwrap();
    values
}

#[test]
fn a_known_displacement_gives_the_known_field_and_statistics() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (grid(20), displaced(&grid(20)));
    let (pa, pb, field) = (
        dir.path().join("a.ply"),
        dir.path().join("b.ply"),
        dir.path().join("field.ply"),
    );
    io::write_mesh(&pa, &a).unwrap();
    io::write_mesh(&pb, &b).unwrap();
    let doc = json(&ok(vcsmooth([
        "compare",
        &s(&pa),
        &s(&pb),
        "--json",
        "--deviation-field",
        &s(&field),
        "--deviation-colours",
    ])));
    let d = &doc["deviation"];
    let n = 400u64;
    assert_eq!(d["measure"], "vertex");
    assert_eq!(d["vertices"].as_u64(), Some(n));
    // 100 vertices at −0.5, 300 at +0.25: exact in binary.
    assert_eq!(d["mean"].as_f64(), Some(0.0625), "{d}");
    assert_eq!(d["rms"].as_f64(), Some((7.0f64 / 64.0).sqrt()));
    assert_eq!(
        (d["min"].as_f64(), d["max"].as_f64()),
        (Some(-0.5), Some(0.25))
    );
    assert_eq!(d["distance_max"].as_f64(), Some(0.5));
    assert_eq!(d["distance_max_vertex"].as_u64(), Some(0));
    assert_eq!(d["distance_mean"].as_f64(), Some(0.3125));
    let p: Vec<(f64, f64)> = d["percentiles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["percent"].as_f64().unwrap(),
                p["distance"].as_f64().unwrap(),
            )
        })
        .collect();
    assert_eq!(p, [(50.0, 0.25), (90.0, 0.5), (99.0, 0.5), (99.9, 0.5)]);
    let h = &d["histogram"];
    assert_eq!(
        (h["min"].as_f64(), h["max"].as_f64()),
        (Some(-0.5), Some(0.5))
    );
    let counts: Vec<u64> = h["counts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_u64().unwrap())
        .collect();
    assert_eq!(counts.len(), metrics::deviation::HISTOGRAM_BINS);
    assert_eq!(
        (counts[0], counts[15], counts.iter().sum::<u64>()),
        (100, 300, n)
    );
    assert!(d.get("tolerance").is_none());
    // The compare figures are the field's.
    assert_eq!(doc["max_distance"].as_f64(), Some(0.5));

    // The file: B's vertices with the field as `quality` and its colours.
    let q = vertex_values(&field, "quality");
    for (i, v) in q.iter().enumerate() {
        assert_eq!(*v, if i % 4 == 0 { -0.5 } else { 0.25 }, "vertex {i}");
    }
    let (red, blue) = (vertex_values(&field, "red"), vertex_values(&field, "blue"));
    // Saturated at the largest deviation, 0.5: −0.5 full blue, +0.25 half red.
    assert_eq!((red[0], blue[0]), (0.0, 255.0));
    assert_eq!((red[1], blue[1]), (255.0, 128.0));
    let written = io::read_mesh(&field).unwrap();
    assert_eq!(&written.positions[..], &b.positions[..]);
    assert_eq!(&written.triangles[..], &b.triangles[..]);

    // The library's pure function gives the same field.
    assert_eq!(
        metrics::signed_deviations(&a.positions, &b.positions, &a.triangles),
        q
    );
}

#[test]
fn the_tolerance_has_its_own_exit_code_and_still_writes() {
    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (dir.path().join("a.ply"), dir.path().join("b.ply"));
    io::write_mesh(&pa, &grid(10)).unwrap();
    io::write_mesh(&pb, &displaced(&grid(10))).unwrap();
    let field = dir.path().join("f.ply");
    let beyond = vcsmooth([
        "compare",
        &s(&pa),
        &s(&pb),
        "--tolerance",
        "0.3",
        "--deviation-field",
        &s(&field),
    ]);
    assert_eq!(beyond.status.code(), Some(3), "{}", stderr(&beyond));
    let err = stderr(&beyond);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("vcsmooth: tolerance: "), "{err}");
    // 25 of the 100 vertices moved by 0.5, the first of them vertex 0.
    assert!(
        err.contains("25 of 100 vertices") && err.contains("vertex 0"),
        "{err}"
    );
    assert!(stdout(&beyond).contains("tolerance 0.3: 25 vertices beyond"));
    assert!(
        field.is_file(),
        "the field is written beyond the tolerance too"
    );
    let within = vcsmooth(["compare", &s(&pa), &s(&pb), "--tolerance", "0.5", "--json"]);
    let doc = json(&ok(within));
    assert_eq!(doc["deviation"]["tolerance"]["beyond"].as_u64(), Some(0));
    assert_eq!(doc["deviation"]["tolerance"]["within"], true);

    // smooth: beyond a tolerance, exit 3 with the output and the report written.
    let sphere = dir.path().join("sphere.ply");
    crate::util::generate_sphere(&sphere, 3, Some(0.3), None);
    let (out, report) = (dir.path().join("out.ply"), dir.path().join("r.json"));
    let run = vcsmooth([
        "smooth",
        &s(&sphere),
        &s(&out),
        "--tolerance",
        "1e-6",
        "--report",
        &s(&report),
    ]);
    assert_eq!(run.status.code(), Some(3), "{}", stderr(&run));
    assert!(out.is_file() && report.is_file());
    let r = read_json(&report);
    let t = &r["deviation"]["tolerance"];
    assert!(
        t["beyond"].as_u64().unwrap() > 0 && t["within"] == false,
        "{t}"
    );
    let run = vcsmooth(["smooth", &s(&sphere), &s(&out), "--tolerance", "10"]);
    assert_eq!(run.status.code(), Some(0), "{}", stderr(&run));
    assert!(stdout(&run).contains("tolerance 10: every vertex within"));

    // The same run's help documents the code.
    let help = ok(vcsmooth(["smooth", "--help"]));
    assert!(help.contains("exit with code 3"), "{help}");
}

#[test]
fn usage_errors_of_the_field_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = dir.path().join("sphere.ply");
    crate::util::generate_sphere(&sphere, 2, None, None);
    let obj = dir.path().join("out.obj");
    let o = vcsmooth(["smooth", &s(&sphere), &s(&obj), "--deviation-field"]);
    fails(&o, 2, &["out.obj", "colours", "PLY"]);
    assert!(!obj.exists());
    let off = dir.path().join("out.off");
    let o = vcsmooth([
        "smooth",
        &s(&sphere),
        &s(&off),
        "--deviation-field",
        "--deviation-colours",
    ]);
    fails(&o, 2, &["out.off", "PLY"]);
    assert!(!off.exists());
    let o = vcsmooth(["smooth", &s(&sphere), &s(&obj), "--tolerance", "-1"]);
    assert_eq!(o.status.code(), Some(2));
    // The cluster engine does not measure it: refused before any work.
    let ck = dir.path().join("ck");
    let out = dir.path().join("out.ply");
    let o = vcsmooth([
        "smooth",
        &s(&sphere),
        &s(&out),
        "--checkpoint",
        &s(&ck),
        "--tolerance",
        "1",
    ]);
    fails(&o, 2, &["--tolerance", "--checkpoint"]);
    assert!(!ck.exists() && !out.exists());
    // compare's field may not overwrite one of its inputs.
    let o = vcsmooth([
        "compare",
        &s(&sphere),
        &s(&sphere),
        "--deviation-field",
        &s(&sphere),
    ]);
    fails(&o, 2, &["--deviation-field"]);
    // --surface against a point cloud: no surface to measure to.
    let cloud = dir.path().join("cloud.ply");
    io::write_mesh(&cloud, &Mesh::new(vec![DVec3::ZERO; 3], Vec::new())).unwrap();
    let o = vcsmooth(["compare", &s(&sphere), &s(&cloud), "--surface"]);
    fails(&o, 1, &["cloud.ply", "no triangles"]);
}

/// An OBJ output carries the field's colours (`v x y z r g b`, in [0, 1]): the same bytes as a
/// PLY output's `red green blue` of the same run, over 255; from an OBJ input the numbers that
/// followed a position (old colours) give way to them and the rest of the line stays.
#[test]
fn an_obj_output_carries_the_colours() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = dir.path().join("sphere.ply");
    crate::util::generate_sphere(&sphere, 3, Some(0.3), Some(4));
    let (ply, obj) = (dir.path().join("out.ply"), dir.path().join("out.obj"));
    let field = ["--deviation-field", "--deviation-colours"];
    for out in [&ply, &obj] {
        let mut args = vec!["smooth".to_string(), s(&sphere), s(out)];
        args.extend(field.iter().map(|a| a.to_string()));
        ok(vcsmooth(&args));
    }
    let rgb: Vec<[f64; 3]> = {
        let [r, g, b] = ["red", "green", "blue"].map(|c| vertex_values(&ply, c));
        (0..r.len()).map(|i| [r[i], g[i], b[i]]).collect()
    };
    let colours_of = |path: &Path| -> Vec<[f64; 3]> {
        let text = std::fs::read_to_string(path).unwrap();
        text.lines()
            .filter(|l| l.starts_with("v "))
            .map(|l| {
                let n: Vec<f64> = l
                    .split_whitespace()
                    .skip(4)
                    .take(3)
                    .map(|t| t.parse().unwrap())
                    .collect();
                assert_eq!(n.len(), 3, "{l}");
                [0, 1, 2].map(|k| (n[k] * 255.0).round())
            })
            .collect()
    };
    assert_eq!(colours_of(&obj), rgb);
    assert!(rgb.iter().any(|c| c[0] > c[2]) && rgb.iter().any(|c| c[2] > c[0]));
    // The positions are those of the plain OBJ run.
    let plain = dir.path().join("plain.obj");
    ok(vcsmooth(["smooth", &s(&sphere), &s(&plain)]));
    let (a, b) = (io::read_mesh(&plain).unwrap(), io::read_mesh(&obj).unwrap());
    assert_eq!(a.positions, b.positions);
    // From an OBJ input with colours and comments: its colours replaced, its comments kept.
    let input = dir.path().join("coloured.obj");
    let mut text = String::new();
    for (i, p) in a.positions.iter().enumerate() {
        text += &format!("v {} {} {} 0.1 0.2 0.3 # vertex {i}\n", p.x, p.y, p.z);
    }
    for t in &a.triangles {
        text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(&input, text).unwrap();
    let again = dir.path().join("again.obj");
    let mut args = vec!["smooth".to_string(), s(&input), s(&again)];
    args.extend(field.iter().map(|a| a.to_string()));
    ok(vcsmooth(&args));
    let written = std::fs::read_to_string(&again).unwrap();
    let first = written.lines().find(|l| l.starts_with("v ")).unwrap();
    assert!(first.ends_with(" # vertex 0"), "{first}");
    assert_eq!(first.split_whitespace().count(), 7 + 3, "{first}");
    assert!(!written.contains(" 0.1 0.2 0.3"), "old colours kept");
}

#[test]
fn surface_distances_between_meshes_without_shared_vertices() {
    let dir = tempfile::tempdir().unwrap();
    let (pa, pb) = (dir.path().join("a.ply"), dir.path().join("b.ply"));
    // A: the grid lifted by 0.75; B: a coarser grid twice as wide at z = 0 (other vertices).
    let mut a = grid(11);
    a.positions.iter_mut().for_each(|p| p.z = 0.75);
    let mut b = grid(6);
    b.positions.iter_mut().for_each(|p| *p *= 2.0);
    io::write_mesh(&pa, &a).unwrap();
    io::write_mesh(&pb, &b).unwrap();
    let doc = json(&ok(vcsmooth([
        "compare",
        &s(&pa),
        &s(&pb),
        "--surface",
        "--json",
    ])));
    let d = &doc["deviation"];
    assert_eq!(d["measure"], "surface");
    // Every vertex of A lies 0.75 above B's plane: B is below A, against A's normals.
    assert_eq!(
        (d["min"].as_f64(), d["max"].as_f64()),
        (Some(-0.75), Some(-0.75))
    );
    assert_eq!(d["distance_rms"].as_f64(), Some(0.75));
    assert_eq!(doc["rms_distance"].as_f64(), Some(0.75));
    assert!(doc["mean_normal_angle_deg"].is_null());
    // Without --surface these meshes do not compare.
    fails(&vcsmooth(["compare", &s(&pa), &s(&pb)]), 1, &["b.ply"]);
}

/// Runs `smooth` on `input` into `name` with the field and a report, `extra` flags added; the
/// output's bytes and the report.
fn smoothed(dir: &Path, input: &Path, name: &str, extra: &[&str]) -> (Vec<u8>, serde_json::Value) {
    let (out, report) = (dir.join(name), dir.join(format!("{name}.json")));
    let mut args = vec![
        "smooth".to_string(),
        s(input),
        s(&out),
        "--iterations".into(),
        "2".into(),
        "--patch-size".into(),
        "4096".into(),
        "--report".into(),
        s(&report),
    ];
    args.extend(extra.iter().map(|a| a.to_string()));
    ok(vcsmooth(&args));
    (std::fs::read(&out).unwrap(), read_json(&report))
}

/// The bunny refined to 1.1 M triangles, with noise: the field (the output's bytes) and its
/// statistics are the same on 1 and 2 threads, on the heap and in scratch files under a 64 MiB
/// budget; they are what `compare` measures on the files; and the output is, but for the added
/// properties, the output without the field.
#[test]
fn the_field_is_the_same_for_any_threads_budget_and_storage() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bunny.ply");
    ok(vcsmooth([
        "generate",
        "mesh",
        &s(&input),
        "--from",
        &s(&scan("stanford-bunny.ply")),
        "--subdivide",
        "2",
        "--noise",
        "0.3",
    ]));
    let field = ["--deviation-field", "--deviation-colours"];
    let (heap, r) = smoothed(
        dir.path(),
        &input,
        "heap.ply",
        &[&field[..], &["--threads", "1"]].concat(),
    );
    assert_eq!(r["memory"]["storage"], "heap");
    let sdir = s(dir.path());
    let budget = [
        "--memory-budget",
        "64M",
        "--scratch",
        &sdir,
        "--threads",
        "2",
    ];
    let (mapped, r2) = smoothed(
        dir.path(),
        &input,
        "mapped.ply",
        &[&field[..], &budget].concat(),
    );
    assert_eq!(r2["memory"]["storage"], "scratch");
    assert!(
        heap == mapped,
        "the field in scratch differs from the heap's"
    );
    assert_eq!(r["deviation"], r2["deviation"]);
    let (two, r3) = smoothed(
        dir.path(),
        &input,
        "two.ply",
        &[&field[..], &["--threads", "2"]].concat(),
    );
    assert!(heap == two, "2 threads differ from 1");
    assert_eq!(r["deviation"], r3["deviation"]);
    let d = &r["deviation"];
    assert!(d["distance_max"].as_f64().unwrap() > 0.0 && d["rms"].as_f64().unwrap() > 0.0);

    // What compare measures on the files is the field written.
    let from_compare = dir.path().join("compare.ply");
    let doc = json(&ok(vcsmooth([
        "compare",
        &s(&input),
        &s(&dir.path().join("heap.ply")),
        "--json",
        "--deviation-field",
        &s(&from_compare),
        "--deviation-colours",
    ])));
    assert!(std::fs::read(&from_compare).unwrap() == heap);
    assert_eq!(doc["deviation"], r["deviation"]);

    // Without the field: the same positions and faces, and the header less the added lines.
    let (plain, _) = smoothed(dir.path(), &input, "plain.ply", &[]);
    let header = |bytes: &[u8]| {
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        String::from_utf8(bytes[..end].to_vec()).unwrap()
    };
    let with = header(&heap).replace(
        "property float quality\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n",
        "",
    );
    assert_eq!(with, header(&plain));
    let read = |name: &str| io::read_mesh(&dir.path().join(name)).unwrap();
    let (a, b) = (read("heap.ply"), read("plain.ply"));
    assert!(a.positions[..] == b.positions[..] && a.triangles[..] == b.triangles[..]);
}

/// The report records the input's SHA-256, the tool, the results version, the options and the
/// machine; its command line, run again, writes the same bytes.
#[test]
fn the_report_is_a_record_that_reproduces_the_output() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    crate::util::generate_sphere(&input, 3, Some(0.3), Some(4));
    let (out, report) = (dir.path().join("out.ply"), dir.path().join("r.json"));
    ok(vcsmooth([
        "smooth",
        &s(&input),
        &s(&out),
        "--method",
        "vcs",
        "--iterations",
        "3",
        "--report",
        &s(&report),
        "--deviation-stats",
    ]));
    let r = read_json(&report);
    let mut hash = io::Sha256::default();
    hash.update(&std::fs::read(&input).unwrap());
    assert_eq!(r["input"]["sha256"].as_str(), Some(hash.hex().as_str()));
    assert_eq!(r["tool"]["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(
        r["results_version"].as_u64(),
        Some(vcsmooth::RESULTS_VERSION as u64)
    );
    assert!(r["machine"]["cores"].as_u64().unwrap() >= 1);
    assert_eq!(r["options"]["method"], "vcs");
    assert!(r["deviation"]["rms"].as_f64().unwrap() > 0.0);
    let first = std::fs::read(&out).unwrap();
    std::fs::remove_file(&out).unwrap();
    let argv: Vec<String> = r["argv"]
        .as_array()
        .unwrap()
        .iter()
        .skip(1)
        .map(|a| a.as_str().unwrap().to_string())
        .collect();
    ok(vcsmooth(&argv));
    assert!(
        std::fs::read(&out).unwrap() == first,
        "the report's command wrote other bytes"
    );
}

/// An ASCII PLY that carries its own `quality` (`uchar`) and another property: the field takes
/// the `quality` in its place as `float`, the other property and the encoding stay.
#[test]
fn an_existing_quality_takes_the_field_in_its_place() {
    let dir = tempfile::tempdir().unwrap();
    let header = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                  property float z\nproperty uchar quality\nproperty float confidence\n\
                  element face 2\nproperty list uchar int vertex_indices\nend_header\n";
    let body = |z: &str| {
        format!("0 0 0 7 0.5\n1 0 0 7 0.5\n0 1 0 7 0.5\n1 1 {z} 7 0.5\n3 0 1 2\n3 1 3 2\n")
    };
    let (pa, pb, field) = (
        dir.path().join("a.ply"),
        dir.path().join("b.ply"),
        dir.path().join("f.ply"),
    );
    std::fs::write(&pa, format!("{header}{}", body("0"))).unwrap();
    std::fs::write(&pb, format!("{header}{}", body("0.25"))).unwrap();
    ok(vcsmooth([
        "compare",
        &s(&pa),
        &s(&pb),
        "--deviation-field",
        &s(&field),
        "--deviation-colours",
    ]));
    let text = std::fs::read_to_string(&field).unwrap();
    let want = header
        .replace("uchar quality", "float quality")
        .replace(
            "property float confidence\n",
            "property float confidence\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n",
        );
    assert!(text.starts_with(&want), "{text}");
    assert!(text.contains("\n1 1 0.25 0.25 0.5 255 0 0\n"), "{text}");
    assert!(text.contains("\n0 0 0 0 0.5 255 255 255\n"), "{text}");
    assert_eq!(vertex_values(&field, "confidence"), [0.5; 4]);
}
