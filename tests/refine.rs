//! Adaptive subdivision (`vcsmooth::refine`, `vcsmooth subdivide`, `vcsmooth refine`): every
//! output edge ≤ δ, closed manifolds stay closed, manifold and oriented, new vertices lie on the
//! input's triangles, open meshes keep their boundary, and the smoothing rounds keep the volume.

use std::path::{Path, PathBuf};

use glam::DVec3;
use vcsmooth::engine::Quiet;
use vcsmooth::modes::refine::{self, RefineOptions};
use vcsmooth::topology::Topology;
use vcsmooth::{Mesh, io, metrics, shapes};

use crate::util::{arg, generate_sphere, noisy_sphere, ok, read_scan, vcsmooth};

fn bbox_diagonal(pos: &[DVec3]) -> f64 {
    let lo = pos.iter().fold(DVec3::splat(f64::MAX), |a, &p| a.min(p));
    let hi = pos.iter().fold(DVec3::splat(f64::MIN), |a, &p| a.max(p));
    (hi - lo).length()
}

/// Distance from `p` to the segment `[a, b]`.
fn segment_distance(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let d = b - a;
    let t = if d.length_squared() > 0.0 {
        ((p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + t * d)).length()
}

/// Distance from `p` to the triangle `abc` (its plane where the projection falls inside, else
/// its nearest side).
fn triangle_distance(p: DVec3, [a, b, c]: [DVec3; 3]) -> f64 {
    let n = (b - a).cross(c - a);
    let sides = segment_distance(p, a, b)
        .min(segment_distance(p, b, c))
        .min(segment_distance(p, c, a));
    if n.length_squared() == 0.0 {
        return sides;
    }
    let inside = [(a, b), (b, c), (c, a)]
        .iter()
        .all(|&(u, v)| (v - u).cross(p - u).dot(n) >= 0.0);
    if inside {
        (p - a).dot(n).abs() / n.length()
    } else {
        sides
    }
}

/// Assert that every vertex of `out` with id ≥ `input.positions.len()` lies on a triangle of
/// `input` within `1e-9 ×` the bounding-box diagonal, and that the old vertices did not move.
/// A uniform grid over the input triangles' boxes keeps this fast on real scans.
fn assert_new_vertices_on_input(input: &Mesh, out: &Mesh) {
    let n = input.positions.len();
    assert_eq!(
        &out.positions[..n],
        &input.positions[..],
        "old vertices moved"
    );
    let tol = 1e-9 * bbox_diagonal(&input.positions);
    let tri = |t: &[u32; 3]| t.map(|v| input.positions[v as usize]);
    let lo = input
        .positions
        .iter()
        .fold(DVec3::splat(f64::MAX), |a, &p| a.min(p));
    let cells = 32.0;
    let size = (bbox_diagonal(&input.positions) / cells).max(1e-300);
    let cell_of = |p: DVec3| ((p - lo) / size).floor().as_ivec3();
    let mut grid: std::collections::HashMap<glam::IVec3, Vec<usize>> = Default::default();
    for (f, t) in input.triangles.iter().enumerate() {
        let [a, b, c] = tri(t);
        let (c0, c1) = (
            cell_of(a.min(b).min(c) - tol),
            cell_of(a.max(b).max(c) + tol),
        );
        for x in c0.x..=c1.x {
            for y in c0.y..=c1.y {
                for z in c0.z..=c1.z {
                    grid.entry(glam::IVec3::new(x, y, z)).or_default().push(f);
                }
            }
        }
    }
    for (v, &p) in out.positions.iter().enumerate().skip(n) {
        let best = grid
            .get(&cell_of(p))
            .into_iter()
            .flatten()
            .map(|&f| triangle_distance(p, tri(&input.triangles[f])))
            .fold(f64::INFINITY, f64::min);
        assert!(
            best <= tol,
            "new vertex {v} at {p} is {best} off the input surface"
        );
    }
}

/// Subdivide a copy of `input` to `delta` and check the invariants of a closed manifold.
fn subdivide_closed(input: &Mesh, delta: f64) -> (Mesh, refine::SubdivideStats) {
    let mut out = input.clone();
    let s = refine::subdivide(&mut out, delta).unwrap();
    let max = refine::max_edge_of(&out.positions, &out.triangles);
    assert!(max <= delta * (1.0 + 1e-12), "max edge {max} > δ = {delta}");
    assert_eq!(s.max_edge_after, max);
    assert_eq!(
        (s.vertices_after, s.triangles_after),
        (out.positions.len(), out.triangles.len())
    );
    let topo = Topology::build(out.positions.len(), &out.triangles).unwrap();
    let st = &topo.stats;
    assert_eq!(
        (
            st.boundary_edges,
            st.non_manifold_edges,
            st.non_manifold_vertices
        ),
        (0, 0, 0),
        "{st:?}"
    );
    // Euler characteristic unchanged (same genus, one surface).
    let euler = |m: &Mesh, t: &Topology| {
        m.positions.len() as i64 - t.stats.edges as i64 + m.triangles.len() as i64
    };
    let topo_in = Topology::build(input.positions.len(), &input.triangles).unwrap();
    assert_eq!(euler(&out, &topo), euler(input, &topo_in));
    // Orientation kept and new points on the old faces: the volume does not change.
    let (v0, v1) = (
        metrics::volume(&input.positions, &input.triangles),
        metrics::volume(&out.positions, &out.triangles),
    );
    assert!(((v1 - v0) / v0).abs() <= 1e-9, "volume {v0} -> {v1}");
    let (a0, a1) = (
        metrics::area(&input.positions, &input.triangles),
        metrics::area(&out.positions, &out.triangles),
    );
    assert!(((a1 - a0) / a0).abs() <= 1e-9, "area {a0} -> {a1}");
    assert_new_vertices_on_input(input, &out);
    (out, s)
}

#[test]
fn icosahedron_closed_manifold_on_surface() {
    let ico = shapes::icosphere(0);
    for delta in [0.9, 0.3, 0.1] {
        let (out, s) = subdivide_closed(&ico, delta);
        eprintln!(
            "icosahedron δ={delta}: {} → {} triangles, {} → {} vertices, max edge {:.4} → {:.4}, {} passes, volume {:.12}",
            s.triangles_before,
            s.triangles_after,
            s.vertices_before,
            s.vertices_after,
            s.max_edge_before,
            s.max_edge_after,
            s.passes,
            metrics::volume(&out.positions, &out.triangles)
        );
        assert!(s.triangles_after > 20);
    }
}

#[test]
fn torus_closed_manifold_on_surface() {
    let torus = shapes::torus(0);
    let (_, s) = subdivide_closed(&torus, 0.08);
    assert!(s.triangles_after > s.triangles_before);
}

#[test]
fn real_scan_closed_manifold_on_surface() {
    let input = read_scan("fertility-9k.ply");
    let delta = bbox_diagonal(&input.positions) / 100.0;
    let (out, s) = subdivide_closed(&input, delta);
    eprintln!(
        "fertility δ={delta:.3}: {} → {} triangles, max edge {:.3} → {:.3}",
        s.triangles_before, s.triangles_after, s.max_edge_before, s.max_edge_after
    );
    // The PLY layout follows the new vertices and faces, and the mesh can be written as PLY.
    assert!(out.source.layout.is_some());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.ply");
    io::write_mesh(&path, &out).unwrap();
    assert_eq!(
        io::read_mesh(&path).unwrap().triangles.len(),
        s.triangles_after
    );
}

/// Directed boundary edges (those whose reverse is not in the mesh).
fn boundary(m: &Mesh) -> Vec<[u32; 2]> {
    let set: std::collections::HashSet<[u32; 2]> = m
        .triangles
        .iter()
        .flat_map(|t| (0..3).map(move |c| [t[c], t[(c + 1) % 3]]))
        .collect();
    set.iter()
        .filter(|e| !set.contains(&[e[1], e[0]]))
        .copied()
        .collect()
}

#[test]
fn open_mesh_keeps_its_boundary() {
    // A sphere with a hole: drop the triangles around vertex 0.
    let sphere = shapes::icosphere(1);
    let tris: Vec<[u32; 3]> = sphere
        .triangles
        .iter()
        .filter(|t| !t.contains(&0))
        .copied()
        .collect();
    let input = Mesh::new(sphere.positions.to_vec(), tris);
    let delta = 0.12;
    let mut out = input.clone();
    refine::subdivide(&mut out, delta).unwrap();
    assert!(refine::max_edge_of(&out.positions, &out.triangles) <= delta * (1.0 + 1e-12));
    let topo = Topology::build(out.positions.len(), &out.triangles).unwrap();
    assert_eq!(topo.stats.non_manifold_edges, 0);
    assert_eq!(topo.stats.non_manifold_vertices, 0);
    let (b_in, b_out) = (boundary(&input), boundary(&out));
    assert!(b_out.len() > b_in.len(), "boundary edges were not split");
    let length = |m: &Mesh, b: &[[u32; 2]]| -> f64 {
        b.iter()
            .map(|e| (m.positions[e[0] as usize] - m.positions[e[1] as usize]).length())
            .sum()
    };
    let (l_in, l_out) = (length(&input, &b_in), length(&out, &b_out));
    assert!(((l_out - l_in) / l_in).abs() < 1e-12, "{l_in} vs {l_out}");
    // Every output boundary vertex lies on an input boundary edge.
    for e in &b_out {
        let p = out.positions[e[0] as usize];
        let d = b_in
            .iter()
            .map(|b| {
                segment_distance(
                    p,
                    input.positions[b[0] as usize],
                    input.positions[b[1] as usize],
                )
            })
            .fold(f64::INFINITY, f64::min);
        assert!(d < 1e-12, "boundary vertex {} off the input boundary", e[0]);
    }
    assert_new_vertices_on_input(&input, &out);
    let (a0, a1) = (
        metrics::area(&input.positions, &input.triangles),
        metrics::area(&out.positions, &out.triangles),
    );
    assert!(((a1 - a0) / a0).abs() < 1e-12);
}

#[test]
fn refine_rounds_preserve_volume() {
    let noisy = noisy_sphere(1, 0.3, 3);
    for (input, delta) in [(shapes::icosphere(0), 0.3), (noisy, 0.15)] {
        let mut mesh = input.clone();
        let opts = RefineOptions {
            max_edge: delta,
            rounds: 3,
            ..Default::default()
        };
        assert_eq!(opts.smoothing.method, vcsmooth::Method::Vcs);
        assert_eq!(opts.smoothing.iterations, 5);
        let records = refine::refine(&mut mesh, &opts, Some(2), &mut Quiet).unwrap();
        assert_eq!(records.len(), 3);
        let v0 = metrics::volume(&input.positions, &input.triangles);
        for r in &records {
            assert!(r.subdivision.max_edge_after <= delta * (1.0 + 1e-12));
            let sub = ((r.volume_subdivided - r.volume_before) / r.volume_before).abs();
            let round = ((r.volume_smoothed - r.volume_before) / r.volume_before).abs();
            assert!(
                sub <= 1e-12 && round <= 1e-9,
                "round {}: {sub:e}, {round:e}",
                r.round
            );
            eprintln!(
                "refine δ={delta}, round {}: {} → {} triangles, volume {:.12} → {:.12}, max edge after smoothing {:.4}",
                r.round,
                r.subdivision.triangles_before,
                r.subdivision.triangles_after,
                r.volume_before,
                r.volume_smoothed,
                r.max_edge_smoothed
            );
        }
        let v1 = metrics::volume(&mesh.positions, &mesh.triangles);
        assert!(((v1 - v0) / v0).abs() <= 1e-9);
        let topo = Topology::build(mesh.positions.len(), &mesh.triangles).unwrap();
        assert_eq!(topo.stats.boundary_edges + topo.stats.non_manifold_edges, 0);
        // Smoothing moved the new vertices (the surface got rounder, the volume did not change).
        assert_ne!(
            &mesh.positions[..input.positions.len()],
            &input.positions[..]
        );
    }
}

// ---- the binary ----

fn sphere_file(dir: &Path) -> PathBuf {
    let path = dir.join("sphere.ply");
    generate_sphere(&path, 1, Some(0.2), None);
    path
}

#[test]
fn cli_subdivide_and_refine() {
    let dir = tempfile::tempdir().unwrap();
    let input = sphere_file(dir.path());
    let mesh_in = io::read_mesh(&input).unwrap();
    let v_in = metrics::volume(&mesh_in.positions, &mesh_in.triangles);
    let delta = 0.2;

    let sub = dir.path().join("sub.ply");
    let text = ok(vcsmooth([
        "subdivide".as_ref(),
        input.as_os_str(),
        sub.as_os_str(),
        "--max-edge".as_ref(),
        "0.2".as_ref(),
    ]));
    assert_eq!(text.lines().count(), 1, "{text}");
    assert!(
        text.contains("80 triangles ->") && text.contains("42 vertices"),
        "{text}"
    );
    let m = io::read_mesh(&sub).unwrap();
    // Float output: positions rounded to f32.
    assert!(refine::max_edge_of(&m.positions, &m.triangles) <= delta * (1.0 + 1e-6));
    let v = metrics::volume(&m.positions, &m.triangles);
    assert!(((v - v_in) / v_in).abs() <= 1e-6);

    let out = dir.path().join("refined.obj");
    let text = ok(vcsmooth([
        "refine".as_ref(),
        input.as_os_str(),
        out.as_os_str(),
        "--max-edge".as_ref(),
        "0.2".as_ref(),
        "--rounds".as_ref(),
        "2".as_ref(),
        "--iterations".as_ref(),
        "4".as_ref(),
    ]));
    assert!(
        text.starts_with(&format!("{} -> {}", input.display(), out.display())),
        "{text}"
    );
    assert!(text.contains("round 2:"), "{text}");
    let m = io::read_mesh(&out).unwrap();
    let v = metrics::volume(&m.positions, &m.triangles);
    assert!(((v - v_in) / v_in).abs() <= 1e-6, "{v_in} -> {v}");
    let topo = Topology::build(m.positions.len(), &m.triangles).unwrap();
    assert_eq!(topo.stats.boundary_edges + topo.stats.non_manifold_edges, 0);
    assert!(m.triangles.len() > 80);
}

#[test]
fn cli_bad_max_edge_refused_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let input = sphere_file(dir.path());
    let out = dir.path().join("out.ply");
    for bad in ["0", "-1", "NaN", "inf", "abc", "1e-7"] {
        for cmd in ["subdivide", "refine"] {
            let mut args: Vec<&std::ffi::OsStr> = vec![
                cmd.as_ref(),
                input.as_os_str(),
                out.as_os_str(),
                "--max-edge".as_ref(),
                bad.as_ref(),
            ];
            if cmd == "refine" {
                args.extend([std::ffi::OsStr::new("--rounds"), std::ffi::OsStr::new("1")]);
            }
            let o = vcsmooth(&args);
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(!o.status.success(), "{cmd} --max-edge {bad} accepted");
            assert!(
                err.starts_with("vcsmooth: error:") && err.trim_end().lines().count() == 1,
                "{cmd} {bad}: {err}"
            );
            if bad == "1e-7" {
                assert!(err.contains("2^31"), "{err}");
            } else {
                assert!(err.contains("--max-edge"), "{err}");
            }
            assert!(!out.exists(), "{cmd} {bad} wrote an output");
        }
    }
}

/// The memory check sizes the output from above: a budget that the old lower bound on the
/// triangles (1.35e6 here, 129 MiB at 96 B) let through, while the run made 3.4e6 triangles and
/// peaked at 430 MiB, is refused before any work, by `subdivide` and by `refine`; one line, no
/// output.
#[test]
fn a_budget_below_the_output_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("sphere.ply");
    generate_sphere(&input, 3, Some(0.3), None);
    let out = dir.path().join("out.ply");
    let input = input.to_str().unwrap();
    let out_s = out.to_str().unwrap();
    let budget = ["--max-edge", "0.005", "--memory-budget", "256M"];
    for args in [
        [&["subdivide", input, out_s][..], &budget].concat(),
        [&["refine", input, out_s, "--rounds", "1"][..], &budget].concat(),
    ] {
        let o = vcsmooth(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} accepted");
        let lines: Vec<&str> = err.trim_end().lines().collect();
        assert_eq!(lines.len(), 1, "{err}");
        for m in [
            "vcsmooth: error: ",
            "--max-edge 0.005",
            "not enough memory",
            "triangles",
            "--memory-budget",
        ] {
            assert!(lines[0].contains(m), "'{m}' not in: {err}");
        }
        assert!(!out.exists(), "{args:?} wrote an output");
    }
}

/// The estimate the memory checks use is never below the triangles made, and close above them
/// (δ a hair below a fraction of the longest edge: at exactly `longest/2^k`, rounding decides
/// whether halves of exactly δ are split once more).
#[test]
fn the_triangle_estimate_is_close_and_from_above() {
    let mut meshes = vec![shapes::icosphere(1), shapes::torus(0)];
    let mut noisy = shapes::icosphere(2);
    shapes::add_normal_noise(&mut noisy, 0.3, 1);
    meshes.push(noisy);
    for mesh in &meshes {
        let longest = refine::max_edge_of(&mesh.positions, &mesh.triangles);
        for f in [1.0, 0.7, 0.5, 0.45, 0.3, 0.23, 0.1, 0.05, 0.03, 0.011] {
            let delta = longest * f * (1.0 - 1e-6);
            let estimate = refine::estimate_triangles(mesh, delta);
            let mut m = mesh.clone();
            let made = refine::subdivide(&mut m, delta).unwrap().triangles_after as f64;
            assert!(
                made <= estimate && estimate <= 1.3 * made,
                "δ = {delta}: {made} made, {estimate} estimated"
            );
            assert!(refine::triangles_at_least(mesh, delta) <= made);
        }
    }
}

// ---- properties through subdivision (hostile use #11) ----

/// An octahedron PLY (`encoding`: `ascii`, `binary_little_endian`, `binary_big_endian`) with
/// `uchar red green blue` (per vertex, hand-picked), `double quality` (an affine function of the
/// position, so every midpoint's value is known) and a per-face `uchar label` (the octant of the
/// face, which every child face lies in).
fn coloured_octahedron(path: &Path, encoding: &str) {
    let v: Vec<[f32; 3]> = crate::util::octa_v();
    let f: Vec<[i32; 3]> = crate::util::octa_f();
    let colours = [
        [255u8, 0, 0],
        [0, 255, 0],
        [0, 0, 255],
        [10, 20, 31],
        [200, 201, 3],
        [7, 7, 7],
    ];
    let mut out = format!(
        "ply\nformat {encoding} 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty double quality\nelement face {}\nproperty list uchar int vertex_indices\nproperty uchar label\nend_header\n",
        v.len(),
        f.len()
    )
    .into_bytes();
    let big = encoding == "binary_big_endian";
    let put = |out: &mut Vec<u8>, le: &[u8]| {
        let mut b = le.to_vec();
        if big {
            b.reverse();
        }
        out.extend_from_slice(&b);
    };
    for (p, c) in v.iter().zip(colours) {
        let q = quality(DVec3::new(p[0].into(), p[1].into(), p[2].into()));
        if encoding == "ascii" {
            out.extend(
                format!(
                    "{} {} {} {} {} {} {q:?}\n",
                    p[0], p[1], p[2], c[0], c[1], c[2]
                )
                .bytes(),
            );
        } else {
            p.iter().for_each(|x| put(&mut out, &x.to_le_bytes()));
            out.extend_from_slice(&c);
            put(&mut out, &q.to_le_bytes());
        }
    }
    for t in &f {
        let label = octant(t.map(|i| {
            let p = v[i as usize];
            DVec3::new(p[0].into(), p[1].into(), p[2].into())
        }));
        if encoding == "ascii" {
            out.extend(format!("3 {} {} {} {label}\n", t[0], t[1], t[2]).bytes());
        } else {
            out.push(3);
            t.iter().for_each(|i| put(&mut out, &i.to_le_bytes()));
            out.push(label);
        }
    }
    std::fs::write(path, out).unwrap();
}

fn quality(p: DVec3) -> f64 {
    10.0 + p.x + 2.0 * p.y + 3.0 * p.z
}

fn octant(t: [DVec3; 3]) -> u8 {
    let c = (t[0] + t[1] + t[2]) / 3.0;
    (c.x > 0.0) as u8 | ((c.y > 0.0) as u8) << 1 | ((c.z > 0.0) as u8) << 2
}

/// The values of vertex property `name` of a PLY file.
fn vertex_values(m: &Mesh, name: &str) -> Vec<f64> {
    let layout = m.source.layout.as_ref().expect("a PLY layout");
    let ply = layout.as_any().downcast_ref::<io::PlyLayout>().unwrap();
    let mut out = vec![f64::NAN; m.positions.len()];
    ply.vertex_values(name, |i, x| out[i] = x).unwrap();
    out
}

/// Vertex colours and quality, and face labels, survive `subdivide` and `refine` (with and
/// without smoothing) in every PLY encoding: the input's vertices keep theirs exactly, a new
/// vertex's colour is the rounded mean of the two vertices of the edge it split (two collinear
/// neighbours it is the midpoint of), its quality (affine in the position) is the midpoint's, and
/// every child face keeps its parent's label. Nothing is said on stderr: nothing was dropped.
#[test]
fn subdivision_interpolates_vertex_properties_and_copies_face_properties() {
    let dir = tempfile::tempdir().unwrap();
    for encoding in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let input = dir.path().join(format!("{encoding}.ply"));
        coloured_octahedron(&input, encoding);
        let before = io::read_mesh(&input).unwrap();
        let n = before.positions.len();
        let colour_of = |m: &Mesh| -> Vec<[f64; 3]> {
            let [r, g, b] = ["red", "green", "blue"].map(|c| vertex_values(m, c));
            (0..m.positions.len()).map(|i| [r[i], g[i], b[i]]).collect()
        };
        let c0 = colour_of(&before);
        for (cmd, extra) in [
            ("subdivide", &[][..]),
            ("refine", &["--rounds", "2", "--iterations", "0"][..]),
            ("refine", &["--rounds", "2", "--iterations", "3"][..]),
        ] {
            let out = dir.path().join(format!("{encoding}-{cmd}.ply"));
            let mut args = vec![
                cmd.to_string(),
                arg(&input),
                arg(&out),
                "--max-edge".into(),
                "0.3".into(),
            ];
            args.extend(extra.iter().map(|s| s.to_string()));
            let o = vcsmooth(&args);
            assert!(
                crate::util::stderr(&o).is_empty(),
                "{cmd} {extra:?}: {}",
                crate::util::stderr(&o)
            );
            ok(o);
            let m = io::read_mesh(&out).unwrap();
            assert!(m.positions.len() > 4 * n, "{cmd}");
            let c = colour_of(&m);
            assert_eq!(
                &c[..n],
                &c0[..],
                "{encoding} {cmd} {extra:?}: input vertices keep theirs"
            );
            let moved = extra.contains(&"3");
            if !moved {
                let q = vertex_values(&m, "quality");
                for v in 0..m.positions.len() {
                    let p = m.positions[v];
                    assert!(
                        (q[v] - quality(p)).abs() < 1e-5,
                        "{encoding} {cmd}: quality of {v}"
                    );
                    if v < n {
                        continue;
                    }
                    // The edge it split: two earlier vertices it is the midpoint of (a later
                    // pass may have split that edge again).
                    let found = (0..v).any(|a| {
                        (a + 1..v).any(|b| {
                            (m.positions[a] + m.positions[b] - 2.0 * p).length() < 1e-5
                                && (0..3).all(|k| c[v][k] == (0.5 * (c[a][k] + c[b][k])).round())
                        })
                    });
                    assert!(
                        found,
                        "{encoding} {cmd}: vertex {v}'s colour {:?} is no edge's mean",
                        c[v]
                    );
                }
                if encoding == "ascii" {
                    let text = std::fs::read_to_string(&out).unwrap();
                    let body = text.split("end_header\n").nth(1).unwrap();
                    let faces: Vec<&str> = body.lines().skip(m.positions.len()).collect();
                    assert_eq!(faces.len(), m.triangles.len());
                    for (line, t) in faces.iter().zip(m.triangles.iter()) {
                        let label: u8 = line.split_whitespace().nth(4).unwrap().parse().unwrap();
                        assert_eq!(label, octant(t.map(|i| m.positions[i as usize])), "{line}");
                    }
                }
            }
        }
    }
}

/// What a subdivision cannot carry is dropped with one `vcsmooth: note:` line naming it, and the
/// run succeeds: OBJ vertex colours (`v x y z r g b`) and a PLY vertex element with a list.
#[test]
fn subdivision_says_what_it_drops() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("c.obj");
    let mut text = String::new();
    for p in crate::util::octa_v() {
        text += &format!("v {} {} {} 0.5 0.25 1\n", p[0], p[1], p[2]);
    }
    for t in crate::util::octa_f() {
        text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(&obj, text).unwrap();
    let ply = dir.path().join("l.ply");
    let mut text = "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\nproperty float z\nproperty list uchar int tags\nelement face 8\nproperty list uchar int vertex_indices\nend_header\n".to_string();
    for p in crate::util::octa_v() {
        text += &format!("{} {} {} 1 7\n", p[0], p[1], p[2]);
    }
    for t in crate::util::octa_f() {
        text += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    std::fs::write(&ply, text).unwrap();
    for (input, what) in [(&obj, "colours"), (&ply, "vertex.tags")] {
        for cmd in ["subdivide", "refine"] {
            let out = dir.path().join(format!("out-{cmd}.ply"));
            let o = vcsmooth(
                [
                    cmd,
                    &arg(input),
                    &arg(&out),
                    "--max-edge",
                    "0.5",
                    "--rounds",
                    "1",
                ][..if cmd == "refine" { 7 } else { 5 }]
                    .to_vec(),
            );
            let err = crate::util::stderr(&o);
            assert_eq!(err.lines().count(), 1, "{err}");
            assert!(
                err.starts_with("vcsmooth: note: ") && err.contains(what),
                "{err}"
            );
            ok(o);
        }
    }
}
