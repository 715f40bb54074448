//! `vcs-guided`, the feature-preserving method, on a pair of the denoising literature (Fandisk,
//! Gaussian noise 0.3 × mean edge; tests/data/denoising/PROVENANCE.md): it keeps the edges that a
//! low-pass filter rounds, keeps the volume exactly, and gives the same bytes however it runs.

use std::path::PathBuf;

use glam::DVec3;
use vcsmooth::{Mesh, Method, Options, io};

use crate::util::*;

fn pair(kind: &str) -> PathBuf {
    root().join(format!("tests/data/denoising/Fandisk0.3-{kind}.ply"))
}

fn volume(m: &Mesh) -> f64 {
    let p = |i: u32| m.positions[i as usize];
    m.triangles
        .iter()
        .map(|t| p(t[0]).dot(p(t[1]).cross(p(t[2]))))
        .sum::<f64>()
        / 6.0
}

fn smoothed(method: Method) -> Mesh {
    let mut mesh = io::read_mesh(&pair("noisy")).unwrap();
    let opts = Options {
        method,
        ..Options::default()
    };
    vcsmooth::smooth(&mut mesh, &opts).unwrap();
    mesh
}

#[test]
fn guided_filtering_keeps_the_edges_and_the_volume() {
    let noisy = io::read_mesh(&pair("noisy")).unwrap();
    let clean = io::read_mesh(&pair("clean")).unwrap();
    let guided = smoothed(Method::VcsGuided);
    let taubin = smoothed(Method::Taubin);
    let (e_guided, e_taubin) = (normal_error(&guided, &clean), normal_error(&taubin, &clean));
    // Measured: 3.38° against 9.94° (noisy: 28.4°); the target is 0.6×.
    assert!(
        e_guided < 0.6 * e_taubin,
        "vcs-guided {e_guided:.2}°, taubin {e_taubin:.2}°"
    );
    let (v0, v1) = (volume(&noisy), volume(&guided));
    assert!(((v1 - v0) / v0).abs() <= 1e-9, "volume {v0} -> {v1}");
    // And it is not the identity: the noise went.
    assert!(e_guided < 0.25 * normal_error(&noisy, &clean));
}

#[test]
fn a_clean_cube_keeps_its_edges_and_corners() {
    // A cube's faces are flat and its edges sharp: a feature-preserving filter keeps them where a
    // low-pass one rounds them. Measured (10 iterations): vcs-guided moves a vertex 0.0048 on
    // average and 0.016 at most (a corner), vcs-lowpass 0.060 and 0.131.
    let moved = |method: Method| {
        let (v, f) = (cube_positions(), cube_triangles());
        let mut mesh = Mesh::new(v.clone(), f);
        let opts = Options {
            method,
            iterations: 10,
            ..Options::default()
        };
        vcsmooth::smooth(&mut mesh, &opts).unwrap();
        let d: Vec<f64> = v
            .iter()
            .zip(&mesh.positions)
            .map(|(a, b)| (*a - *b).length())
            .collect();
        (
            d.iter().sum::<f64>() / d.len() as f64,
            d.iter().cloned().fold(0.0, f64::max),
        )
    };
    let (guided, lowpass) = (moved(Method::VcsGuided), moved(Method::VcsLowpass));
    assert!(
        lowpass.0 > 1e-2,
        "vcs-lowpass moved the cube by {lowpass:?}"
    );
    assert!(
        guided.0 < 0.2 * lowpass.0,
        "mean: vcs-guided {guided:?}, vcs-lowpass {lowpass:?}"
    );
    assert!(
        guided.1 < 0.25 * lowpass.1,
        "max: vcs-guided {guided:?}, vcs-lowpass {lowpass:?}"
    );
}

/// A unit cube, each face split into a 4 × 4 grid of squares, two triangles each, outward.
fn cube_positions() -> Vec<DVec3> {
    cube().0
}

fn cube_triangles() -> Vec<[u32; 3]> {
    cube().1
}

fn cube() -> (Vec<DVec3>, Vec<[u32; 3]>) {
    const N: u32 = 4;
    let mut pos: Vec<DVec3> = Vec::new();
    let mut tris = Vec::new();
    let id = |p: DVec3, pos: &mut Vec<DVec3>| -> u32 {
        match pos.iter().position(|q| (*q - p).length() < 1e-12) {
            Some(i) => i as u32,
            None => {
                pos.push(p);
                (pos.len() - 1) as u32
            }
        }
    };
    for axis in 0..3 {
        for side in [0.0, 1.0] {
            for i in 0..N {
                for j in 0..N {
                    let at = |a: u32, b: u32| {
                        let (u, w) = (a as f64 / N as f64, b as f64 / N as f64);
                        let mut p = [0.0; 3];
                        p[axis] = side;
                        p[(axis + 1) % 3] = u;
                        p[(axis + 2) % 3] = w;
                        DVec3::from_array(p)
                    };
                    let q = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                    let q = q.map(|p| id(p, &mut pos));
                    let (a, b) = if side == 1.0 {
                        ([q[0], q[1], q[2]], [q[0], q[2], q[3]])
                    } else {
                        ([q[0], q[2], q[1]], [q[0], q[3], q[2]])
                    };
                    tris.push(a);
                    tris.push(b);
                }
            }
        }
    }
    (pos, tris)
}

#[test]
fn the_same_bytes_for_any_thread_count_and_storage() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("noisy.ply");
    // Level 8 (1.3M triangles) is the smallest sphere whose in-core estimate exceeds 64M.
    generate_sphere(&input, 8, Some(0.3), Some(7));
    let run = |name: &str, extra: &[&str]| {
        let (out, report) = (
            dir.path().join(name),
            dir.path().join(format!("{name}.json")),
        );
        let mut args = vec![
            "smooth".to_string(),
            input.display().to_string(),
            out.display().to_string(),
            "--method".into(),
            "vcs-guided".into(),
            "--iterations".into(),
            "1".into(),
            "--patch-size".into(),
            "4096".into(),
            "--report".into(),
            report.display().to_string(),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        ok(vcsmooth(&args));
        (std::fs::read(&out).unwrap(), read_json(&report))
    };
    let (one, r1) = run("t1.ply", &["--threads", "1"]);
    let (two, _) = run("t2.ply", &["--threads", "2"]);
    let (mapped, rm) = run("mapped.ply", &["--threads", "2", "--memory-budget", "64M"]);
    assert_eq!(r1["memory"]["storage"], "heap");
    assert_eq!(rm["memory"]["storage"], "scratch");
    assert!(one == two, "1 and 2 threads differ");
    assert!(one == mapped, "scratch differs from heap");
    let volume = r1["iterations"][0]["volume_pct"].as_f64().unwrap();
    assert!((volume - 100.0).abs() < 1e-7, "{volume}");
}
