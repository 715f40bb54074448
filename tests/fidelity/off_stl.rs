//! Fidelity of OFF and STL files (see tests/fidelity.rs), and what `info` says a PLY carries.
//!
//! OFF: a file with colours, normals or texture coordinates comes back as the same text with only
//! each vertex's `x y z` (and `nx ny nz`, recomputed) changed. STL: a binary file's header and
//! attribute bytes come back unchanged with recomputed facet normals; an ASCII file keeps its
//! solid's name.

use std::fmt::Write as _;
use std::path::Path;

use glam::DVec3;
use serde_json::Value;
use vcsmooth::{Mesh, io, metrics};

use crate::util::{json, noisy_sphere, ok, vcsmooth};

/// A noisy sphere: enough vertices for smoothing to move every one of them.
fn sphere() -> Mesh {
    noisy_sphere(2, 0.3, 16)
}

/// `vcsmooth smooth IN OUT --iterations 3` (vcs: the volume is kept).
fn smooth(input: &Path, output: &Path) {
    ok(vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--iterations".as_ref(),
        "3".as_ref(),
    ]));
}

fn volume(mesh: &Mesh) -> f64 {
    metrics::volume(&mesh.positions, &mesh.triangles)
}

/// `text` with the tokens `columns` of the `count` vertex lines starting at line `first` (from
/// 0) replaced by `_`: what must stay identical after smoothing.
fn masked(text: &str, first: usize, count: usize, columns: &[usize]) -> String {
    let mut out = String::new();
    for (i, line) in text.split_inclusive('\n').enumerate() {
        if (first..first + count).contains(&i) {
            let (code, comment) = line.split_at(line.find('#').unwrap_or(line.len()));
            let mut k = 0;
            let mut in_token = false;
            for c in code.chars() {
                if c.is_ascii_whitespace() {
                    in_token = false;
                    out.push(c);
                } else {
                    if !in_token {
                        in_token = true;
                        if columns.contains(&k) {
                            out.push('_');
                        }
                        k += 1;
                    }
                    if !columns.contains(&(k - 1)) {
                        out.push(c);
                    }
                }
            }
            out.push_str(comment);
        } else {
            out.push_str(line);
        }
    }
    out
}

/// The numbers of vertex line `v` (after `first` lines of header).
fn vertex_numbers(text: &str, first: usize, v: usize) -> Vec<f64> {
    let line = text.lines().nth(first + v).unwrap();
    let code = line.split('#').next().unwrap();
    code.split_ascii_whitespace()
        .map(|t| t.parse().unwrap())
        .collect()
}

/// Writes `mesh` as OFF with magic `magic`, a comment, each vertex line `x y z` + `extra(v)` and
/// each face line `3 i j k` + `face_extra(f)`; CRLF line ends when `crlf`.
fn off_text(
    mesh: &Mesh,
    magic: &str,
    extra: impl Fn(usize) -> String,
    face_extra: impl Fn(usize) -> String,
    crlf: bool,
) -> String {
    let end = if crlf { "\r\n" } else { "\n" };
    let mut s = format!("{magic}{end}# scanned by hand{end}");
    write!(
        s,
        "{} {} 0{end}",
        mesh.positions.len(),
        mesh.triangles.len()
    )
    .unwrap();
    for (v, p) in mesh.positions.iter().enumerate() {
        let p = p.as_vec3();
        write!(s, "{} {} {}{}{end}", p.x, p.y, p.z, extra(v)).unwrap();
    }
    for (f, t) in mesh.triangles.iter().enumerate() {
        write!(s, "3 {} {} {}{}{end}", t[0], t[1], t[2], face_extra(f)).unwrap();
    }
    s
}

/// Smooths `text` as an OFF file and checks that everything but the `columns` of the vertex lines
/// (which start on line 3) came back byte-identical, that the coordinates moved and that the
/// volume was kept; returns the output's text.
fn smooth_off(text: &str, columns: &[usize]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.off"), dir.path().join("out.off"));
    std::fs::write(&input, text).unwrap();
    smooth(&input, &output);
    let out = std::fs::read_to_string(&output).unwrap();
    let n = sphere().positions.len();
    assert_eq!(masked(&out, 3, n, columns), masked(text, 3, n, columns));
    assert_ne!(out, text, "the coordinates did not change");
    let (before, after) = (
        io::read_mesh(&input).unwrap(),
        io::read_mesh(&output).unwrap(),
    );
    assert_eq!(before.triangles, after.triangles);
    let (v0, v1) = (volume(&before), volume(&after));
    assert!((v1 - v0).abs() < 1e-5 * v0.abs(), "volume {v0} -> {v1}");
    out
}

#[test]
fn off_vertex_and_face_colours_come_back_byte_identical() {
    let mesh = sphere();
    let text = off_text(
        &mesh,
        "OFF",
        |v| format!(" {} {} {}", v % 256, (v * 7) % 256, 255 - v % 256),
        |f| format!(" 0.{f} 0.5 1"),
        false,
    );
    smooth_off(&text, &[0, 1, 2]);
}

#[test]
fn coff_with_comments_and_crlf_comes_back_byte_identical() {
    let mesh = sphere();
    let text = off_text(
        &mesh,
        "COFF",
        |v| format!("\t{} 20 30 255   # vertex {v}", v % 256),
        |_| String::new(),
        true,
    );
    let out = smooth_off(&text, &[0, 1, 2]);
    assert!(out.contains("# vertex 7\r\n"));
}

#[test]
fn stcnoff_keeps_uvs_and_colours_and_recomputes_the_normals() {
    let mesh = sphere();
    let text = off_text(
        &mesh,
        "STCNOFF",
        // A stale normal, a colour and texture coordinates.
        |v| format!(" 0 0 1 0.1 0.2 0.3 1 0.{v} 0.25"),
        |_| String::new(),
        false,
    );
    let out = smooth_off(&text, &[0, 1, 2, 3, 4, 5]);
    let smoothed = io::read_mesh_bytes(out.as_bytes(), Path::new("out.off")).unwrap();
    let mut normals = vec![DVec3::ZERO; mesh.positions.len()];
    for t in &smoothed.triangles {
        let [a, b, c] = t.map(|v| smoothed.positions[v as usize]);
        for &v in t {
            normals[v as usize] += (b - a).cross(c - a);
        }
    }
    for (v, n) in normals.iter().enumerate() {
        let numbers = vertex_numbers(&out, 3, v);
        let written = DVec3::new(numbers[3], numbers[4], numbers[5]);
        assert!(
            (written.length() - 1.0).abs() < 1e-6,
            "vertex {v}: {written}"
        );
        assert!(written.dot(n.normalize()) > 1.0 - 1e-6, "vertex {v}");
    }
}

#[test]
fn a_plain_off_stays_plain() {
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.off"), dir.path().join("out.off"));
    let text = off_text(
        &sphere(),
        "OFF",
        |_| String::new(),
        |_| String::new(),
        false,
    );
    std::fs::write(&input, text).unwrap();
    smooth(&input, &output);
    // The plain writer: no comment.
    let out = std::fs::read_to_string(&output).unwrap();
    assert!(out.starts_with("OFF\n") && !out.contains('#'));
    let doc = json(&ok(vcsmooth([
        "info".as_ref(),
        input.as_os_str(),
        "--json".as_ref(),
    ])));
    assert_eq!(doc["carries"], nothing_carried());
}

#[test]
fn an_off_layout_refuses_changed_connectivity() {
    let text = off_text(
        &sphere(),
        "COFF",
        |_| " 1 0 0".into(),
        |_| String::new(),
        false,
    );
    let mut mesh = io::read_mesh_bytes(text.as_bytes(), Path::new("in.off")).unwrap();
    mesh.triangles.swap(0, 1);
    let dir = tempfile::tempdir().unwrap();
    let e = io::write_mesh(&dir.path().join("out.off"), &mesh).unwrap_err();
    assert!(
        e.to_string().contains("no longer match the OFF source"),
        "{e}"
    );
    mesh.source.layout = None;
    io::write_mesh(&dir.path().join("out.off"), &mesh).unwrap();
}

fn nothing_carried() -> Value {
    json(r#"{"uvs": false, "colours": false, "normals": false, "materials": false, "other": []}"#)
}

/// A binary STL of `mesh` with `header` and facet `f`'s attribute `attribute(f)`.
fn binary_stl(mesh: &Mesh, header: &[u8; 80], attribute: impl Fn(usize) -> u16) -> Vec<u8> {
    let mut b = header.to_vec();
    b.extend((mesh.triangles.len() as u32).to_le_bytes());
    for (f, t) in mesh.triangles.iter().enumerate() {
        // A stale normal.
        for x in [0f32, 0.0, 1.0] {
            b.extend(x.to_le_bytes());
        }
        for &v in t {
            for x in mesh.positions[v as usize].as_vec3().to_array() {
                b.extend(x.to_le_bytes());
            }
        }
        b.extend(attribute(f).to_le_bytes());
    }
    b
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

#[test]
fn binary_stl_keeps_header_and_attribute_bytes_and_recomputes_normals() {
    let mesh = sphere();
    let mut header = [b'.'; 80];
    let text = b"COLOR=\xff\x80\x00\xff exported by a VisCAM-like tool";
    header[..text.len()].copy_from_slice(text);
    let input_bytes = binary_stl(&mesh, &header, |f| 0x8000 | (f as u16 * 37));
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.stl"), dir.path().join("out.stl"));
    std::fs::write(&input, &input_bytes).unwrap();

    let info = ok(vcsmooth(["info".as_ref(), input.as_os_str()]));
    assert!(
        info.lines()
            .any(|l| l.starts_with("carries") && l.ends_with("colours, other: attribute bytes")),
        "{info}"
    );
    smooth(&input, &output);
    let out = std::fs::read(&output).unwrap();
    assert_eq!(out.len(), input_bytes.len());
    assert_eq!(out[..84], input_bytes[..84], "header and count");
    let mut moved = false;
    for f in 0..mesh.triangles.len() {
        let at = 84 + 50 * f;
        assert_eq!(
            out[at + 48..at + 50],
            input_bytes[at + 48..at + 50],
            "facet {f}"
        );
        let v = |k: usize| {
            DVec3::from_array(std::array::from_fn(|c| {
                f64::from(f32_at(&out, at + 4 * (3 * k + c)))
            }))
        };
        let (normal, a, b, c) = (v(0), v(1), v(2), v(3));
        let facet = (b - a).cross(c - a).normalize();
        assert!((normal.length() - 1.0).abs() < 1e-6, "facet {f}: {normal}");
        assert!(
            normal.dot(facet) > 1.0 - 1e-5,
            "facet {f}: {normal} vs {facet}"
        );
        moved |= out[at + 12..at + 48] != input_bytes[at + 12..at + 48];
    }
    assert!(moved, "smoothing moved nothing");
    let (before, after) = (
        io::read_mesh(&input).unwrap(),
        io::read_mesh(&output).unwrap(),
    );
    let (v0, v1) = (volume(&before), volume(&after));
    assert!((v1 - v0).abs() < 1e-5 * v0.abs(), "volume {v0} -> {v1}");
}

#[test]
fn binary_stl_with_zero_attributes_carries_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.stl");
    std::fs::write(&input, binary_stl(&sphere(), &[b' '; 80], |_| 0)).unwrap();
    let doc = json(&ok(vcsmooth([
        "info".as_ref(),
        input.as_os_str(),
        "--json".as_ref(),
    ])));
    assert_eq!(doc["carries"], nothing_carried());
}

#[test]
fn ascii_stl_keeps_its_solid_names() {
    let mesh = sphere();
    let mut text = String::new();
    // Two solids, the second with the last two facets.
    let split = mesh.triangles.len() - 2;
    for (name, range) in [
        ("left part", 0..split),
        ("Right", split..mesh.triangles.len()),
    ] {
        writeln!(text, "solid {name}").unwrap();
        for t in &mesh.triangles[range] {
            text.push_str("facet normal 0 0 0\nouter loop\n");
            for &v in t {
                let p = mesh.positions[v as usize].as_vec3();
                writeln!(text, "vertex {} {} {}", p.x, p.y, p.z).unwrap();
            }
            text.push_str("endloop\nendfacet\n");
        }
        writeln!(text, "endsolid {name}").unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.stl"), dir.path().join("out.stl"));
    std::fs::write(&input, &text).unwrap();
    smooth(&input, &output);
    let out = std::fs::read_to_string(&output).unwrap();
    let names: Vec<&str> = out
        .lines()
        .filter(|l| l.starts_with("solid") || l.starts_with("endsolid"))
        .collect();
    assert_eq!(
        names,
        [
            "solid left part",
            "endsolid left part",
            "solid Right",
            "endsolid Right"
        ]
    );
    let facets_after = |name: &str| {
        out.split(&format!("solid {name}\n"))
            .nth(1)
            .unwrap()
            .split("endsolid")
            .next()
            .unwrap()
            .matches("endfacet")
            .count()
    };
    assert_eq!(facets_after("Right"), 2);
    let after = io::read_mesh(&output).unwrap();
    let before = io::read_mesh(&input).unwrap();
    assert_eq!(after.triangles, before.triangles);
    assert_ne!(after.positions, before.positions);
}

#[test]
fn info_reports_ply_colours_normals_and_other_properties() {
    let mesh = sphere();
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         property float confidence\nelement face {}\nproperty list uchar int vertex_indices\n\
         end_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    );
    for p in &mesh.positions {
        let p = p.as_vec3();
        writeln!(s, "{} {} {} 0 0 1 200 100 50 0.5", p.x, p.y, p.z).unwrap();
    }
    for t in &mesh.triangles {
        writeln!(s, "3 {} {} {}", t[0], t[1], t[2]).unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("c.ply");
    std::fs::write(&input, s).unwrap();
    let info = ok(vcsmooth(["info".as_ref(), input.as_os_str()]));
    let row = info.lines().find(|l| l.starts_with("carries")).unwrap();
    assert!(
        row.ends_with("colours, normals (recomputed on write), other: vertex.confidence"),
        "{row}"
    );
    let doc = json(&ok(vcsmooth([
        "info".as_ref(),
        input.as_os_str(),
        "--json".as_ref(),
    ])));
    let expected = json(
        r#"{"uvs": false, "colours": true, "normals": true, "materials": false,
            "other": ["vertex.confidence"]}"#,
    );
    assert_eq!(doc["carries"], expected);
    // The existing fields are still there.
    assert_eq!(doc["vertices"], mesh.positions.len());
    assert_eq!(doc["format"], "ply");
}

#[test]
fn info_of_a_generated_mesh_carries_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.ply");
    crate::util::generate_sphere(&path, 1, None, None);
    let doc = json(&ok(vcsmooth([
        "info".as_ref(),
        path.as_os_str(),
        "--json".as_ref(),
    ])));
    // A plain binary PLY of x y z and faces.
    assert_eq!(doc["carries"], nothing_carried());
}
