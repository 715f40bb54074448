//! Geometry and topology that smoothing must survive, end to end through the binary:
//!
//! - closed debris of a few vertices beside a real surface: its stencils are degenerate (a
//!   triangle stencil collapses a tetrahedron to a point, where no translation restores the
//!   volume) and are skipped and counted, never sent to infinity;
//! - faces that are not consistently oriented: counted by `info`, measured and smoothed as if
//!   they were (the result matches the consistent mesh's), written back as they came; a
//!   non-orientable surface is smoothed with the vertices of its seam fixed;
//! - a vertex of enormous degree (a filled hole's fan, a cone's cap): `info` and smoothing stay
//!   linear in the degree (the hub is fixed, above `MAX_FREE_DEGREE` neighbours).

use std::path::Path;

use glam::DVec3;
use serde_json::Value;
use vcsmooth::Mesh;

use crate::util::{json, noisy_sphere, ok, read_json, vcsmooth};

fn write(path: &Path, mesh: &Mesh) {
    vcsmooth::io::write_mesh(path, mesh).unwrap();
}

fn info(path: &Path) -> Value {
    json(&ok(vcsmooth([
        "info".as_ref(),
        path.as_os_str(),
        "--json".as_ref(),
    ])))
}

/// `vcsmooth smooth IN OUT --method M --iterations N --report R`: the report and the output.
fn smooth(dir: &Path, input: &Path, method: &str, iterations: u32) -> (Value, Mesh) {
    let output = dir.join(format!("out-{method}.ply"));
    let report = dir.join(format!("report-{method}.json"));
    ok(vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--method".as_ref(),
        method.as_ref(),
        "--iterations".as_ref(),
        iterations.to_string().as_ref(),
        "--report".as_ref(),
        report.as_os_str(),
    ]));
    (
        read_json(&report),
        vcsmooth::io::read_mesh(&output).unwrap(),
    )
}

/// The positions as the file holds them (f32).
fn stored(positions: &[DVec3]) -> Vec<[f32; 3]> {
    positions.iter().map(|p| p.as_vec3().to_array()).collect()
}

fn volume(positions: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    vcsmooth::metrics::volume(positions, triangles)
}

/// `base` with `piece` added as a separate component (its vertex ids shifted).
fn with_component(base: &Mesh, piece: (Vec<DVec3>, Vec<[u32; 3]>)) -> Mesh {
    let n = base.positions.len() as u32;
    let mut positions = base.positions.to_vec();
    positions.extend(piece.0);
    let mut triangles = base.triangles.to_vec();
    triangles.extend(piece.1.iter().map(|t| t.map(|v| v + n)));
    Mesh::new(positions, triangles)
}

/// A closed tetrahedron of edge `size` at `at`, outward.
fn tetrahedron(at: DVec3, size: f64) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let corners = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(0.3, 0.2, 0.9)];
    (
        corners.iter().map(|c| at + size * *c).collect(),
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
}

#[test]
fn closed_debris_beside_a_surface_is_skipped_not_sent_to_infinity() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = noisy_sphere(3, 0.3, 5);
    // Two pieces of debris: a tetrahedron and a much flatter one further out.
    let mesh = with_component(&sphere, tetrahedron(DVec3::new(3.0, 0.0, 0.0), 0.01));
    let mut flat = tetrahedron(DVec3::new(0.0, -4.0, 1.0), 0.2);
    flat.0[3].z = 1.0 + 1e-7;
    let mesh = with_component(&mesh, flat);
    let input = dir.path().join("debris.ply");
    write(&input, &mesh);
    let debris = sphere.positions.len()..mesh.positions.len();
    let before = stored(&mesh.positions);

    for method in ["vcs", "vcs-triangle", "lem"] {
        let (report, out) = smooth(dir.path(), &input, method, 3);
        let after = stored(&out.positions);
        assert!(out.positions.iter().all(|p| p.is_finite()), "{method}");
        // Nothing leaves the input's bounding box by more than a tenth of the sphere.
        let lo = mesh
            .positions
            .iter()
            .fold(DVec3::INFINITY, |a, p| a.min(*p));
        let hi = mesh
            .positions
            .iter()
            .fold(DVec3::NEG_INFINITY, |a, p| a.max(*p));
        for (v, p) in out.positions.iter().enumerate() {
            assert!(
                p.cmpge(lo - 0.1).all() && p.cmple(hi + 0.1).all(),
                "{method}: vertex {v} went to {p}"
            );
        }
        if method == "lem" {
            continue; // no volume constraint: lem may shrink the debris
        }
        // The volume stencils of the debris are degenerate: skipped, counted, nothing moved.
        for v in debris.clone() {
            assert_eq!(before[v], after[v], "{method}: debris vertex {v} moved");
        }
        let per_iteration = if method == "vcs" { 12 } else { 8 };
        for it in report["iterations"].as_array().unwrap() {
            let degenerate = it["stencils"]["skipped_degenerate"].as_u64().unwrap();
            assert!(degenerate >= per_iteration, "{method}: {it}");
            let pct = it["volume_pct"].as_f64().unwrap();
            assert!((pct - 100.0).abs() < 1e-6, "{method}: volume {pct} %");
        }
        let v0 = volume(&mesh.positions, &mesh.triangles);
        let v1 = volume(&out.positions, &mesh.triangles);
        assert!(((v1 - v0) / v0).abs() < 1e-6, "{method}: {v0} -> {v1}");
    }
}

/// `mesh` with the faces whose index satisfies `flip` reversed.
fn flipped(mesh: &Mesh, flip: impl Fn(usize) -> bool) -> Mesh {
    let triangles = mesh
        .triangles
        .iter()
        .enumerate()
        .map(|(k, t)| if flip(k) { [t[0], t[2], t[1]] } else { *t })
        .collect();
    Mesh::new(mesh.positions.to_vec(), triangles)
}

fn radius_range(positions: &[DVec3]) -> (f64, f64) {
    positions
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
            (lo.min(p.length()), hi.max(p.length()))
        })
}

#[test]
fn inconsistently_oriented_faces_are_counted_and_smoothed_as_if_consistent() {
    let dir = tempfile::tempdir().unwrap();
    let clean = noisy_sphere(3, 0.3, 9);
    let clean_path = dir.path().join("clean.ply");
    write(&clean_path, &clean);
    let v_clean = volume(&clean.positions, &clean.triangles);
    let (_, reference) = smooth(dir.path(), &clean_path, "vcs", 10);
    let reference = reference.positions.to_vec();

    type Flip = fn(usize) -> bool;
    let cases: [(&str, Flip); 3] = [
        ("every-other", |k| k % 2 == 1),
        ("every-other-mirrored", |k| k % 2 == 0),
        ("one-in-1280", |k| k == 777),
    ];
    for (name, flip) in cases {
        let mesh = flipped(&clean, flip);
        let case = dir.path().join(name);
        std::fs::create_dir(&case).unwrap();
        let input = case.join("in.ply");
        write(&input, &mesh);

        let i = info(&input);
        let bad = i["inconsistent_orientation_edges"].as_u64().unwrap();
        assert!(bad >= 3, "{name}: {i}");
        assert_eq!(i["non_orientable_components"], 0, "{name}: {i}");
        assert_eq!(i["fixed_vertices"], 0, "{name}: {i}");
        assert_eq!(i["closed"], true, "{name}: {i}");
        // Measured with the faces oriented: the clean sphere's volume, outward.
        let v = i["volume"].as_f64().unwrap();
        assert!(
            ((v - v_clean) / v_clean).abs() < 1e-6,
            "{name}: {v} vs {v_clean}"
        );
        let text = ok(vcsmooth(["info".as_ref(), input.as_os_str()]));
        assert!(
            text.lines()
                .any(|l| l.starts_with("orientation") && l.contains(&format!("{bad} edges"))),
            "{name}: {text}"
        );

        let (report, out) = smooth(&case, &input, "vcs", 10);
        assert_eq!(out.triangles, mesh.triangles, "{name}: faces rewritten");
        assert_eq!(
            report["input"]["stats"]["inconsistent_orientation_edges"], bad,
            "{name}"
        );
        // The same result as the consistent mesh (up to the order of the sums).
        let far = out
            .positions
            .iter()
            .zip(&reference)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f64::max);
        assert!(
            far < 1e-5,
            "{name}: {far} from the consistent mesh's result"
        );
        let v1 = volume(&out.positions, &clean.triangles);
        assert!(
            ((v1 - v_clean) / v_clean).abs() < 1e-6,
            "{name}: volume {v1}"
        );
        let (lo0, hi0) = radius_range(&clean.positions);
        let (lo1, hi1) = radius_range(&out.positions);
        assert!(
            lo1 > lo0 && hi1 < hi0,
            "{name}: radii {lo0}..{hi0} -> {lo1}..{hi1}"
        );

        let (report, out) = smooth(&case, &input, "vcs-triangle", 10);
        assert_eq!(out.triangles, mesh.triangles, "{name}");
        let v1 = volume(&out.positions, &clean.triangles);
        assert!(
            ((v1 - v_clean) / v_clean).abs() < 1e-6,
            "{name}: vcs-triangle volume {v1}"
        );
        let last = report["iterations"]
            .as_array()
            .unwrap()
            .last()
            .unwrap()
            .clone();
        assert_eq!(last["stencils"]["skipped_degenerate"], 0, "{name}: {last}");
    }
}

/// The figure-8 immersion of a Klein bottle on a `u × v` grid: rows glued straight, the last
/// column glued to the first upside down (a closed, non-orientable surface).
fn klein_bottle(u: u32, v: u32) -> Mesh {
    let id = |i: u32, j: u32| {
        let (i, j) = if i == u {
            (0, (v - j % v) % v)
        } else {
            (i, j % v)
        };
        i * v + j
    };
    let mut triangles = Vec::new();
    for i in 0..u {
        for j in 0..v {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    let mut positions = Vec::new();
    for i in 0..u {
        for j in 0..v {
            let t = std::f64::consts::TAU * i as f64 / u as f64;
            let s = std::f64::consts::TAU * j as f64 / v as f64;
            let (c, sn) = ((t / 2.0).cos(), (t / 2.0).sin());
            let r = 3.0 + c * s.sin() - sn * (2.0 * s).sin();
            positions.push(DVec3::new(
                r * t.cos(),
                r * t.sin(),
                sn * s.sin() + c * (2.0 * s).sin(),
            ));
        }
    }
    Mesh::new(positions, triangles)
}

#[test]
fn a_non_orientable_surface_is_smoothed_with_its_seam_fixed() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = klein_bottle(48, 16);
    let input = dir.path().join("klein.ply");
    write(&input, &mesh);
    let i = info(&input);
    assert_eq!(i["closed"], true, "{i}");
    assert_eq!(i["non_orientable_components"], 1, "{i}");
    let seam_of = |i: &Value| {
        let seams = i["orientation_seam_edges"].as_u64().unwrap();
        let fixed = i["fixed_vertices"].as_u64().unwrap();
        assert!(seams >= 1 && fixed >= 2 && fixed <= 2 * seams, "{i}");
        fixed
    };
    seam_of(&i);

    for method in ["vcs", "vcs-triangle"] {
        let (report, out) = smooth(dir.path(), &input, method, 3);
        assert_eq!(out.triangles, mesh.triangles);
        // Where the seam runs depends on the order the faces are walked in (the plan's order
        // here, the file's in `info`): the run reports its own.
        let stats = &report["input"]["stats"];
        assert_eq!(stats["non_orientable_components"], 1, "{stats}");
        let fixed = seam_of(stats);
        let (before, after) = (stored(&mesh.positions), stored(&out.positions));
        let still = before.iter().zip(&after).filter(|(a, b)| a == b).count();
        // The seam's vertices stay; every other vertex is smoothed.
        assert_eq!(still as u64, fixed, "{method}");
        assert!(
            out.positions
                .iter()
                .all(|p| p.is_finite() && p.length() < 5.0)
        );
        let it = &report["iterations"][0]["stencils"];
        assert!(it["skipped_fixed"].as_u64().unwrap() > 0, "{method}: {it}");
    }
}

#[test]
fn a_hub_of_200k_neighbours_neither_hangs_info_nor_smoothing() {
    // A closed bipyramid: two apexes over a wavy rim of 200,000 vertices (fan caps, as a filled
    // hole makes). Quadratic work in the hubs' degree would be 4·10^10 steps: minutes, not the
    // second this takes.
    let dir = tempfile::tempdir().unwrap();
    let d: u32 = 200_000;
    let mut positions: Vec<DVec3> = (0..d)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / d as f64;
            DVec3::new(a.cos(), a.sin(), 0.01 * (k % 7) as f64 / 7.0)
        })
        .collect();
    positions.extend([DVec3::Z, DVec3::NEG_Z]);
    let mut triangles = Vec::new();
    for k in 0..d {
        triangles.push([d, k, (k + 1) % d]);
        triangles.push([d + 1, (k + 1) % d, k]);
    }
    let mesh = Mesh::new(positions, triangles);
    let input = dir.path().join("hub.ply");
    write(&input, &mesh);

    let i = info(&input);
    assert_eq!(i["high_degree_vertices"], 2, "{i}");
    assert_eq!(i["fixed_vertices"], 2, "{i}");
    assert_eq!(i["edges"], 3 * d as u64, "{i}");
    assert_eq!(i["closed"], true, "{i}");
    assert!(i["roughness_deg"].as_f64().unwrap() > 0.0, "{i}");

    for method in ["vcs", "vcs-triangle"] {
        let (report, out) = smooth(dir.path(), &input, method, 1);
        let (before, after) = (stored(&mesh.positions), stored(&out.positions));
        assert_eq!(
            before[d as usize..],
            after[d as usize..],
            "{method}: a hub moved"
        );
        let st = &report["iterations"][0]["stencils"];
        // Every stencil with a hub as a free vertex is skipped as fixed; the rim's are applied.
        let (fixed, applied) = if method == "vcs" {
            (2 * d, d)
        } else {
            (2 * d, 0)
        };
        assert_eq!(st["skipped_fixed"], fixed as u64, "{method}: {st}");
        assert_eq!(st["applied"], applied as u64, "{method}: {st}");
    }
}
