//! Smooth boundaries: `--boundary fixed|smooth` and the library's
//! `Options::boundary`. On the open scans (bunny, demosthenes) with noise, `smooth` makes every
//! boundary loop smoother while its vector area (the hole's size) and the mesh's volume stay
//! exact; `fixed` is today's result; results do not depend on the thread count or the storage.

use std::collections::HashMap;
use std::path::Path;

use glam::DVec3;
use vcsmooth::engine::{self, Quiet};
use vcsmooth::mesh::Storage;
use vcsmooth::{Boundary, Mesh, Method, Options, io, metrics, shapes};

use crate::util::{
    cluster_settings, engine_settings, fails, noisy_sphere, ok, planned_positions, read_json,
    read_scan, run_ranks, vcsmooth,
};

/// The open scans of `tests/data`.
const OPEN_SCANS: [&str; 2] = ["stanford-bunny.ply", "demosthenes-17k.ply"];

/// The boundary loops of `m`: each a cycle of vertices in the direction its faces run along it.
/// Only loops through vertices on exactly two boundary edges (all of the scans').
fn loops(m: &Mesh) -> Vec<Vec<u32>> {
    let mut count: HashMap<[u32; 2], u32> = HashMap::new();
    for t in m.triangles.iter() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry([a.min(b), a.max(b)]).or_default() += 1;
        }
    }
    let mut next: HashMap<u32, u32> = HashMap::new();
    let mut starts: HashMap<u32, usize> = HashMap::new();
    for t in m.triangles.iter() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if count[&[a.min(b), a.max(b)]] == 1 {
                next.insert(a, b);
                *starts.entry(a).or_default() += 1;
            }
        }
    }
    assert!(
        starts.values().all(|&c| c == 1),
        "a vertex on 4 boundary edges"
    );
    let mut firsts: Vec<u32> = next.keys().copied().collect();
    firsts.sort_unstable();
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::new();
    for v in firsts {
        if seen.contains(&v) {
            continue;
        }
        let mut cycle = vec![v];
        seen.insert(v);
        let mut at = next[&v];
        while at != v {
            assert!(seen.insert(at), "boundary is not a set of cycles");
            cycle.push(at);
            at = next[&at];
        }
        out.push(cycle);
    }
    out
}

/// A loop's vector area `½ Σ p_k × p_{k+1}`, summed about its first vertex.
fn vector_area(pos: &[DVec3], cycle: &[u32]) -> DVec3 {
    let o = pos[cycle[0] as usize];
    let n = cycle.len();
    (0..n).fold(DVec3::ZERO, |s, k| {
        let (p, q) = (
            pos[cycle[k] as usize] - o,
            pos[cycle[(k + 1) % n] as usize] - o,
        );
        s + 0.5 * p.cross(q)
    })
}

/// A loop's curve energy `Σ |½ (p_prev + p_next) − p|²`: its roughness.
fn curve_energy(pos: &[DVec3], cycle: &[u32]) -> f64 {
    let n = cycle.len();
    let p = |k: usize| pos[cycle[k % n] as usize];
    (0..n)
        .map(|k| (0.5 * (p(k + n - 1) + p(k + 1)) - p(k)).length_squared())
        .sum()
}

/// The scan `name` with normal noise of `sigma` mean edge lengths.
fn noisy_scan(name: &str, sigma: f64) -> Mesh {
    let mut m = read_scan(name);
    shapes::add_normal_noise(&mut m, sigma, 11);
    m
}

fn opts(method: Method, boundary: Boundary) -> Options {
    Options {
        method,
        boundary,
        ..Options::default()
    }
}

/// Smooth a copy of `m` on `threads` threads with patches of `patch_size`.
fn smoothed(m: &Mesh, o: &Options, patch_size: usize, threads: usize) -> (Mesh, engine::Report) {
    let mut out = m.clone();
    let report = engine::smooth_with(
        &mut out,
        o,
        &engine_settings(patch_size, threads),
        &mut Quiet,
    )
    .unwrap();
    (out, report)
}

fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// The stencil methods that smooth boundaries.
const METHODS: [Method; 4] = [
    Method::Vcs,
    Method::VcsTriangle,
    Method::VcsLowpass,
    Method::Lem,
];

/// On both open scans with noise, every method keeps each loop's vector-area magnitude (the
/// hole's size) to 1e-9 while the loop's curve energy falls at least threefold, and counts its
/// boundary stencils; `fixed` leaves every loop vertex where it was.
#[test]
fn smooth_keeps_each_hole_and_smooths_its_loop() {
    for name in OPEN_SCANS {
        let m = noisy_scan(name, 0.3);
        let ls = loops(&m);
        assert!(!ls.is_empty(), "{name}: no boundary");
        for method in METHODS {
            let (out, report) = smoothed(&m, &opts(method, Boundary::Smooth), 1024, 2);
            let st = report.records.last().unwrap().stencils;
            assert!(st.boundary_applied > 0, "{name} {method}: {st:?}");
            for l in &ls {
                let (a0, a1) = (vector_area(&m.positions, l), vector_area(&out.positions, l));
                let rel = (a1.length() - a0.length()).abs() / a0.length();
                assert!(
                    rel <= 1e-9,
                    "{name} {method}, loop of {}: |A| {rel:e}",
                    l.len()
                );
                let (e0, e1) = (
                    curve_energy(&m.positions, l),
                    curve_energy(&out.positions, l),
                );
                assert!(
                    e1 < e0 / 3.0,
                    "{name} {method}, loop of {}: {e0} -> {e1}",
                    l.len()
                );
            }
            let (fixed, report) = smoothed(&m, &opts(method, Boundary::Fixed), 1024, 2);
            let st = report.records.last().unwrap().stencils;
            assert_eq!((st.boundary_applied, st.boundary_skipped), (0, 0));
            for &v in ls.iter().flatten() {
                assert_eq!(fixed.positions[v as usize], m.positions[v as usize]);
            }
        }
    }
}

/// On a closed mesh there is nothing to smooth along a boundary: `smooth` gives `fixed`'s bits,
/// with the volume kept to 1e-9.
#[test]
fn a_closed_mesh_is_unchanged_by_the_mode() {
    let m = noisy_sphere(3, 0.3, 5);
    for method in METHODS {
        let (a, _) = smoothed(&m, &opts(method, Boundary::Smooth), 256, 2);
        let (b, _) = smoothed(&m, &opts(method, Boundary::Fixed), 256, 2);
        assert!(a.positions == b.positions, "{method}");
        if method != Method::Lem {
            let (v0, v1) = (
                metrics::volume(&m.positions, &m.triangles),
                metrics::volume(&a.positions, &a.triangles),
            );
            assert!(((v1 - v0) / v0).abs() <= 1e-9, "{method}: {v0} -> {v1}");
        }
    }
}

/// The volume of an open scan about a fixed point (its input centroid): exact with `fixed` (every
/// interior stencil keeps its local volume), and with `smooth` moved only by the boundary
/// stencils, by far less than `lem` moves it.
#[test]
fn the_volume_of_an_open_scan_stays_put() {
    let m = noisy_scan("demosthenes-17k.ply", 0.3);
    let centre = m.positions.iter().sum::<DVec3>() / m.positions.len() as f64;
    let v0 = metrics::volume_about(&m.positions, &m.triangles, centre);
    let change = |method, boundary| {
        let (out, _) = smoothed(&m, &opts(method, boundary), 1024, 2);
        (metrics::volume_about(&out.positions, &out.triangles, centre) - v0).abs() / v0.abs()
    };
    let fixed = change(Method::Vcs, Boundary::Fixed);
    assert!(fixed <= 1e-9, "{fixed:e}");
    let lem = change(Method::Lem, Boundary::Smooth);
    for method in [Method::Vcs, Method::VcsLowpass] {
        let smooth = change(method, Boundary::Smooth);
        assert!(smooth <= 1e-4, "{method}: {smooth:e}");
        assert!(smooth * 10.0 < lem, "{method}: {smooth:e} vs lem {lem:e}");
    }
}

/// The same bits for 1, 2 and 3 threads, on the heap and in scratch files.
#[test]
fn identical_for_any_thread_count_and_storage() {
    let m = noisy_scan("stanford-bunny.ply", 0.3);
    let dir = tempfile::tempdir().unwrap();
    let mapped = Storage::scratch(dir.path()).unwrap();
    for method in METHODS {
        let o = Options {
            iterations: 3,
            ..opts(method, Boundary::Smooth)
        };
        let run = |storage: &Storage, threads: usize| {
            planned_positions(&m, storage, threads, 512, &o, |_| {})
        };
        let heap = run(&Storage::heap(), 1);
        assert!(
            run(&Storage::heap(), 2) == heap,
            "{method}: 2 threads differ"
        );
        assert!(
            run(&mapped, 3) == heap,
            "{method}: scratch, 3 threads differ"
        );
    }
}

/// The command line on the bunny refined to 1.1 M triangles, with noise: a `--memory-budget`
/// that sends it to scratch files writes the heap's bytes, so does another thread count; the
/// report counts the boundary stencils and names the mode only when it is `smooth`.
#[test]
fn the_command_line_smooths_boundaries_in_scratch_too() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bunny.ply");
    let bunny = crate::util::scan("stanford-bunny.ply");
    ok(vcsmooth([
        "generate",
        "mesh",
        &s(&input),
        "--from",
        &s(&bunny),
        "--subdivide",
        "2",
        "--noise",
        "0.3",
    ]));
    let run = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let report = dir.path().join(format!("{name}.json"));
        let mut args = vec![
            "smooth".to_string(),
            s(&input),
            s(&out),
            "--iterations".into(),
            "1".into(),
            "--patch-size".into(),
            "4096".into(),
            "--report".into(),
            s(&report),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        ok(vcsmooth(&args));
        (std::fs::read(&out).unwrap(), read_json(&report))
    };
    let smooth = ["--boundary", "smooth"];
    let (heap, r) = run("heap.ply", &[&smooth[..], &["--threads", "1"]].concat());
    assert_eq!(r["memory"]["storage"], "heap");
    assert_eq!(r["options"]["boundary"], "smooth", "{}", r["options"]);
    let st = &r["iterations"][0]["stencils"];
    assert!(st["boundary_applied"].as_u64().unwrap() > 800, "{st}");
    let sdir = s(dir.path());
    let budget = [
        "--memory-budget",
        "64M",
        "--scratch",
        &sdir,
        "--threads",
        "2",
    ];
    let (mapped, r) = run("mapped.ply", &[&smooth[..], &budget].concat());
    assert_eq!(r["memory"]["storage"], "scratch");
    assert!(heap == mapped, "scratch differs from heap");
    let (fixed, r) = run("fixed.ply", &["--boundary", "fixed"]);
    assert!(r["options"].get("boundary").is_none(), "{}", r["options"]);
    assert!(
        r["iterations"][0]["stencils"]
            .get("boundary_applied")
            .is_none()
    );
    let (default, _) = run("default.ply", &[]);
    assert!(fixed == default && fixed != heap);
}

#[test]
fn bad_values_and_unsupported_modes_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("demo.ply");
    io::write_mesh(&input, &read_scan("demosthenes-17k.ply")).unwrap();
    let out = dir.path().join("out.ply");
    for value in ["wavy", "", "Smooth"] {
        let o = vcsmooth(["smooth", &s(&input), &s(&out), "--boundary", value]);
        fails(&o, 2, &["--boundary"]);
    }
    for method in ["laplacian", "taubin"] {
        let o = vcsmooth([
            "smooth",
            &s(&input),
            &s(&out),
            "--boundary",
            "smooth",
            "--method",
            method,
        ]);
        assert!(!o.status.success());
        fails(&o, o.status.code().unwrap(), &["--boundary", method]);
    }
    let o = vcsmooth([
        "smooth",
        &s(&input),
        &s(&out),
        "--boundary",
        "smooth",
        "--multires",
    ]);
    assert!(!o.status.success());
    fails(&o, o.status.code().unwrap(), &["--boundary"]);
    assert!(!out.exists());
}

/// The cluster engine's ranks walk the loops as one process does: the same bytes on 1–3 ranks
/// (the bunny's five loops cross ranks), also with the automatic stop and a deviation bound,
/// and a checkpointed run resumes to them.
#[test]
fn the_ranks_of_the_cluster_engine_smooth_boundaries_as_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("bunny.ply");
    io::write_mesh(&input, &noisy_scan("stanford-bunny.ply", 0.3)).unwrap();
    let with = |method, iterations, auto_stop, max_deviation| Options {
        iterations,
        auto_stop,
        max_deviation,
        ..opts(method, Boundary::Smooth)
    };
    for (what, o) in [
        ("vcs", with(Method::Vcs, 3, false, None)),
        ("vcs-triangle", with(Method::VcsTriangle, 2, false, None)),
        ("vcs-lowpass", with(Method::VcsLowpass, 2, false, None)),
        ("vcs auto, bounded", with(Method::Vcs, 30, true, Some(0.05))),
    ] {
        let single = dir.path().join("single.ply");
        let plain =
            engine::run_file(&input, &single, &o, &engine_settings(1024, 2), &mut Quiet).unwrap();
        assert!(
            plain.records.last().unwrap().stencils.boundary_applied > 0,
            "{what}"
        );
        let expected = std::fs::read(&single).unwrap();
        for ranks in [1, 2, 3] {
            let out = dir.path().join(format!("out-{ranks}.ply"));
            let run = run_ranks(
                ranks,
                &input,
                &out,
                &o,
                &engine_settings(1024, 1),
                &cluster_settings(&dir.path().join(format!("work-{ranks}")), false, 1),
            )
            .remove(0)
            .unwrap();
            assert!(
                std::fs::read(&out).unwrap() == expected,
                "{what} on {ranks} ranks differs from one process"
            );
            assert_eq!(run.iterations_run, plain.iterations_run, "{what}");
            let (a, b) = (run.records.last().unwrap(), plain.records.last().unwrap());
            assert_eq!(a.stencils, b.stencils, "{what}");
        }
    }
    // Two iterations on 2 ranks, kept; then three on 3 ranks: the uninterrupted bytes.
    let o = with(Method::Vcs, 3, false, None);
    let single = dir.path().join("single.ply");
    engine::run_file(&input, &single, &o, &engine_settings(1024, 2), &mut Quiet).unwrap();
    let (work, out) = (dir.path().join("ck"), dir.path().join("resumed.ply"));
    for (ranks, iterations) in [(2, 2), (3, 3)] {
        let o = Options { iterations, ..o };
        run_ranks(
            ranks,
            &input,
            &out,
            &o,
            &engine_settings(1024, 1),
            &cluster_settings(&work, true, 1),
        )
        .remove(0)
        .unwrap();
    }
    assert!(std::fs::read(&out).unwrap() == std::fs::read(&single).unwrap());
}

/// `batch` certifies the mode (a run with another mode redoes the mesh) and `slurm-script`
/// repeats it.
#[test]
fn batch_certifies_the_mode_and_slurm_script_repeats_it() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).unwrap();
    io::write_mesh(&inputs.join("demo.ply"), &read_scan("demosthenes-17k.ply")).unwrap();
    let outdir = dir.path().join("out");
    let batch = |extra: &[&str]| {
        let mut args = vec![
            "batch".to_string(),
            s(&inputs),
            s(&outdir),
            "--iterations".into(),
            "2".into(),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        ok(vcsmooth(&args))
    };
    let smooth = ["--boundary", "smooth"];
    assert_eq!(batch(&smooth).matches("\ndone ").count(), 1);
    assert_eq!(batch(&smooth).matches("\nskipped ").count(), 1);
    assert_eq!(batch(&[]).matches("\ndone ").count(), 1);
    let script = ok(vcsmooth([
        "slurm-script",
        &s(&inputs),
        &s(&outdir),
        "--boundary",
        "smooth",
    ]));
    assert!(script.contains(" --boundary smooth "), "{script}");
    let script = ok(vcsmooth(["slurm-script", &s(&inputs), &s(&outdir)]));
    assert!(!script.contains("--boundary"), "{script}");
}

/// Without `--method`, `--boundary smooth` runs the default method, vcs-lowpass, and says so.
#[test]
fn smooth_boundaries_without_a_method_run_the_default_method() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("demo.ply");
    io::write_mesh(&input, &read_scan("demosthenes-17k.ply")).unwrap();
    let out = dir.path().join("out.ply");
    let text = ok(vcsmooth([
        "smooth",
        &s(&input),
        &s(&out),
        "--boundary",
        "smooth",
        "--iterations",
        "2",
    ]));
    assert!(
        text.contains("out.ply: vcs-lowpass, 2 iterations"),
        "{text}"
    );
}
