//! The cluster engine: one mesh over several ranks, with checkpoints. Ranks run here as
//! threads exchanging through `cluster::Local`, the same code path MPI ranks take; tests/engines.rs
//! repeats the essentials with real OpenMPI processes.

use std::path::{Path, PathBuf};
use std::process::Stdio;

use vcsmooth::cluster::{Comm, Local};
use vcsmooth::engine::{self, EngineSettings, Quiet, Report, Statistics};
use vcsmooth::{Method, Options, io, shapes};

use crate::util::{
    cluster_settings, command, engine_settings, iterations_done, noisy_sphere, ok, read_json,
    run_ranks, scan, vcsmooth,
};

/// A noisy sphere of `level` written to `dir/sphere.ply`.
fn sphere_file(dir: &Path, level: u32) -> PathBuf {
    let path = dir.join("sphere.ply");
    io::write_mesh(&path, &noisy_sphere(level, 0.4, 11)).unwrap();
    path
}

#[test]
fn any_number_of_ranks_gives_the_single_process_output_bit_for_bit() {
    let tmp = tempfile::tempdir().unwrap();
    let input = scan("armadillo-86k.ply");
    for (method, iterations) in [
        (Method::Vcs, 3),
        (Method::Taubin, 4),
        (Method::VcsTriangle, 2),
        (Method::Lem, 2),
        (Method::Laplacian, 3),
        (Method::Hc, 3),
    ] {
        let opts = Options {
            method,
            iterations,
            ..Options::default()
        };
        let reference = tmp.path().join(format!("{method}-plain.ply"));
        let plain = engine::run_file(
            &input,
            &reference,
            &opts,
            &EngineSettings {
                with_stats: true,
                ..engine_settings(300, 2)
            },
            &mut Quiet,
        )
        .unwrap();
        let expected = std::fs::read(&reference).unwrap();
        // Patches of 300 vertices: more than one step of the streaming order.
        assert_eq!(plain.plan.steps, 2);
        for ranks in [1, 2, 3, 5] {
            let out = tmp.path().join(format!("{method}-{ranks}.ply"));
            let work = tmp.path().join(format!("{method}-{ranks}.work"));
            let run = run_ranks(
                ranks,
                &input,
                &out,
                &opts,
                &EngineSettings {
                    with_stats: true,
                    ..engine_settings(300, 1)
                },
                &cluster_settings(&work, false, 1),
            )
            .remove(0)
            .unwrap();
            assert!(
                std::fs::read(&out).unwrap() == expected,
                "{method} on {ranks} ranks differs from the single-process engine"
            );
            assert!(
                !work.exists(),
                "the work directory is removed without --checkpoint"
            );
            let stats = run.cluster.clone().unwrap();
            assert_eq!(stats.ranks, ranks);
            if ranks > 1 {
                assert!(
                    stats.halo_values_per_iteration > 0,
                    "ranks must exchange halos"
                );
            }
            assert_eq!(run.records.len(), iterations);
            let (a, b) = (run.records.last().unwrap(), plain.records.last().unwrap());
            assert!(
                (a.volume_pct - b.volume_pct).abs() < 1e-9,
                "{method}: {} vs {}",
                a.volume_pct,
                b.volume_pct
            );
            assert_eq!(a.stencils, b.stencils);
            // The statistics of the input and of the output as stored, bit for bit.
            let stats = |r: &Report| serde_json::to_string(&(&r.input_stats, &r.output_stats));
            assert!(plain.output_stats.is_some());
            assert_eq!(
                stats(&run).unwrap(),
                stats(&plain).unwrap(),
                "{method}, {ranks} ranks"
            );
        }
    }
}

/// `vcs-guided` on ranks: its normal filter reads, pass after pass, the triangles around each
/// triangle, so near a rank's border it reads triangles another rank owns; their fields travel
/// after every pass. 2 and 3 ranks write the bytes of one process, with creases and with the
/// automatic stop too, and a checkpointed run resumes on another rank count.
#[test]
fn vcs_guided_on_ranks_gives_the_single_process_output_bit_for_bit() {
    let tmp = tempfile::tempdir().unwrap();
    let sphere = sphere_file(tmp.path(), 4);
    let fandisk = scan("denoising/Fandisk0.3-noisy.ply");
    let guided = Options {
        method: Method::VcsGuided,
        iterations: 3,
        ..Options::default()
    };
    let creases = Options {
        crease_angle: Some(40.0),
        ..guided
    };
    let auto = Options {
        iterations: 40,
        auto_stop: true,
        ..guided
    };
    for (what, input, opts, patch) in [
        ("plain", &sphere, guided, 300),
        ("creases", &fandisk, creases, 1024),
        ("auto", &sphere, auto, 300),
    ] {
        let reference = tmp.path().join(format!("{what}-plain.ply"));
        let settings = engine_settings(patch, 2);
        let plain = engine::run_file(input, &reference, &opts, &settings, &mut Quiet).unwrap();
        let expected = std::fs::read(&reference).unwrap();
        for ranks in [2, 3] {
            let out = tmp.path().join(format!("{what}-{ranks}.ply"));
            let work = tmp.path().join(format!("{what}-{ranks}.work"));
            let settings = engine_settings(patch, 1);
            let cluster = cluster_settings(&work, false, 1);
            let run = run_ranks(ranks, input, &out, &opts, &settings, &cluster)
                .remove(0)
                .unwrap();
            assert!(
                run.plan.patches >= 2 * ranks,
                "{what}: {}",
                run.plan.patches
            );
            assert!(run.cluster.unwrap().halo_values_per_iteration > 0);
            assert_eq!(run.iterations_run, plain.iterations_run, "{what}");
            assert!(
                std::fs::read(&out).unwrap() == expected,
                "vcs-guided, {what}, on {ranks} ranks differs from one process"
            );
        }
    }

    // One iteration on 2 ranks, resumed to three on 3.
    let work = tmp.path().join("ck");
    let out = tmp.path().join("resumed.ply");
    let once = Options {
        iterations: 1,
        ..guided
    };
    let settings = engine_settings(300, 1);
    run_ranks(
        2,
        &sphere,
        &out,
        &once,
        &settings,
        &cluster_settings(&work, true, 1),
    )
    .remove(0)
    .unwrap();
    let resumed = run_ranks(
        3,
        &sphere,
        &out,
        &guided,
        &settings,
        &cluster_settings(&work, true, 1),
    )
    .remove(0)
    .unwrap();
    assert_eq!(resumed.cluster.unwrap().resumed_after, 1);
    assert!(
        std::fs::read(&out).unwrap() == std::fs::read(tmp.path().join("plain-plain.ply")).unwrap(),
        "vcs-guided resumed on 3 ranks differs from one process"
    );
}

#[test]
fn a_run_resumes_from_its_checkpoint_with_another_rank_count() {
    let tmp = tempfile::tempdir().unwrap();
    let input = sphere_file(tmp.path(), 5);
    let opts = |iterations| Options {
        iterations,
        ..Options::default()
    };
    let plain = tmp.path().join("plain.ply");
    engine::run_file(
        &input,
        &plain,
        &opts(5),
        &engine_settings(700, 2),
        &mut Quiet,
    )
    .unwrap();

    let work = tmp.path().join("ck");
    let out = tmp.path().join("out.ply");
    let first = run_ranks(
        2,
        &input,
        &out,
        &opts(2),
        &engine_settings(700, 1),
        &cluster_settings(&work, true, 1),
    )
    .remove(0)
    .unwrap();
    assert_eq!(first.cluster.unwrap().resumed_after, 0);
    assert!(
        work.join("plan.json").exists(),
        "--checkpoint keeps the work directory"
    );
    let second = run_ranks(
        3,
        &input,
        &out,
        &opts(5),
        &engine_settings(700, 1),
        &cluster_settings(&work, true, 2),
    )
    .remove(0)
    .unwrap();
    assert_eq!(second.cluster.as_ref().unwrap().resumed_after, 2);
    assert_eq!(
        second.records.len(),
        5,
        "records of the earlier run are kept"
    );
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&plain).unwrap());

    // Asking for fewer iterations than the checkpoint holds is an error, not a silent rerun.
    let err = run_ranks(
        2,
        &input,
        &out,
        &opts(3),
        &engine_settings(700, 1),
        &cluster_settings(&work, true, 1),
    )
    .remove(0)
    .unwrap_err();
    assert!(err.to_string().contains("5 iterations done"), "{err}");

    // Other options make a new plan instead of resuming a foreign one.
    let taubin = Options {
        method: Method::Taubin,
        ..opts(2)
    };
    let run = run_ranks(
        2,
        &input,
        &out,
        &taubin,
        &engine_settings(700, 1),
        &cluster_settings(&work, true, 1),
    )
    .remove(0)
    .unwrap();
    assert_eq!(run.cluster.unwrap().resumed_after, 0);
}

#[test]
fn a_damaged_plan_is_an_error_on_every_rank_not_a_panic() {
    let tmp = tempfile::tempdir().unwrap();
    let input = sphere_file(tmp.path(), 3);
    let work = tmp.path().join("ck");
    let out = tmp.path().join("out.ply");
    let opts = Options {
        iterations: 1,
        ..Options::default()
    };
    run_ranks(
        2,
        &input,
        &out,
        &opts,
        &engine_settings(100, 1),
        &cluster_settings(&work, true, 1),
    )
    .remove(0)
    .unwrap();
    std::fs::remove_file(&out).unwrap();
    let more = Options {
        iterations: 2,
        ..opts
    };
    let resume = || {
        let settings = cluster_settings(&work, true, 1);
        run_ranks(2, &input, &out, &more, &engine_settings(100, 1), &settings)
            .remove(0)
            .unwrap_err()
    };
    // An out-of-range neighbour in the adjacency.
    let vv = work.join("vv.u32");
    let good = std::fs::read(&vv).unwrap();
    let mut bad = good.clone();
    bad[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
    std::fs::write(&vv, bad).unwrap();
    let err = resume();
    assert!(err.to_string().contains("damaged"), "{err}");
    assert!(!out.exists());
    std::fs::write(&vv, good).unwrap();
    // A truncated positions slot.
    for slot in ["positions-0.f64", "positions-1.f64"] {
        let f = std::fs::OpenOptions::new()
            .write(true)
            .open(work.join(slot))
            .unwrap();
        f.set_len(100).unwrap();
    }
    let err = resume();
    assert!(err.to_string().contains("positions-"), "{err}");
    assert!(!out.exists());
    // An unreadable state.
    std::fs::write(work.join("state.json"), "{ not json").unwrap();
    let err = resume();
    assert!(err.to_string().contains("state.json"), "{err}");
    assert!(!out.exists());
}

#[test]
fn more_ranks_than_patches_and_a_mesh_with_boundary() {
    let tmp = tempfile::tempdir().unwrap();
    // An open mesh (boundary vertices stay fixed) cut into 3 patches, over 4 ranks: one rank owns
    // nothing and must still take part in every exchange.
    let mut m = shapes::icosphere(3);
    let keep = m.triangles.len() - 40;
    m.triangles.truncate(keep);
    shapes::add_normal_noise(&mut m, 0.3, 5);
    let input = tmp.path().join("open.ply");
    io::write_mesh(&input, &m).unwrap();
    let opts = Options {
        iterations: 3,
        ..Options::default()
    };
    let plain = tmp.path().join("plain.ply");
    engine::run_file(&input, &plain, &opts, &engine_settings(250, 1), &mut Quiet).unwrap();
    let out = tmp.path().join("out.ply");
    let run = run_ranks(
        4,
        &input,
        &out,
        &opts,
        &engine_settings(250, 1),
        &cluster_settings(&tmp.path().join("w"), false, 1),
    )
    .remove(0)
    .unwrap();
    assert_eq!(run.plan.patches, 3);
    assert_eq!(run.cluster.unwrap().owned_vertices_min, 0);
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&plain).unwrap());
}

#[test]
fn a_killed_run_resumes_to_the_uninterrupted_output() {
    let tmp = tempfile::tempdir().unwrap();
    let input = sphere_file(tmp.path(), 7);
    let args = |out: &Path| -> Vec<String> {
        [
            "smooth",
            input.to_str().unwrap(),
            out.to_str().unwrap(),
            "--iterations",
            "12",
            "--patch-size",
            "4096",
        ]
        .map(String::from)
        .to_vec()
    };
    let plain = tmp.path().join("plain.ply");
    ok(vcsmooth(args(&plain)));

    let work = tmp.path().join("ck");
    let out = tmp.path().join("out.ply");
    let mut child = command()
        .args(args(&out))
        .args(["--checkpoint", work.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it once it has recorded some iterations but not all.
    let done = || iterations_done(&work) as usize;
    let start = std::time::Instant::now();
    while done() < 2 && start.elapsed().as_secs() < 300 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let at_kill = done();
    assert!(
        (2..12).contains(&at_kill),
        "killed after {at_kill} iterations"
    );
    assert!(!out.exists(), "no output from a killed run");

    ok(command()
        .args(args(&out))
        .args(["--checkpoint", work.to_str().unwrap(), "--report"])
        .arg(tmp.path().join("r.json"))
        .output()
        .unwrap());
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&plain).unwrap());
    let report = read_json(&tmp.path().join("r.json"));
    assert!(report["cluster"]["resumed_after"].as_u64().unwrap() >= at_kill as u64);
    assert_eq!(report["iterations"].as_array().unwrap().len(), 12);
}

/// A resumed `--boundary smooth` run keeps the input's hole areas, not the checkpoint's: the
/// same bits as a run never stopped (the bunny × 4 with noise, in double precision so that no
/// difference hides in the rounding to `float`).
#[test]
fn a_resumed_run_keeps_the_input_hole_areas() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("bunny.ply");
    ok(vcsmooth([
        "generate".as_ref(),
        "mesh".as_ref(),
        input.as_os_str(),
        "--from".as_ref(),
        crate::util::scan("stanford-bunny.ply").as_os_str(),
        "--subdivide".as_ref(),
        "1".as_ref(),
        "--noise".as_ref(),
        "0.3".as_ref(),
        "--seed".as_ref(),
        "4".as_ref(),
    ]));
    let mut mesh = io::read_mesh(&input).unwrap();
    mesh.source.layout = None;
    mesh.source.precision = io::Precision::Double;
    io::write_mesh(&input, &mesh).unwrap();
    let head = std::fs::read(&input).unwrap();
    assert!(head.windows(17).any(|w| w == b"property double x"));
    let smooth = |out: &Path, iterations: &str, checkpoint: Option<&Path>| {
        let mut args: Vec<std::ffi::OsString> = vec!["smooth".into(), input.clone().into()];
        args.push(out.into());
        for a in [
            "--method",
            "vcs",
            "--boundary",
            "smooth",
            "--iterations",
            iterations,
        ] {
            args.push(a.into());
        }
        if let Some(work) = checkpoint {
            args.extend(["--checkpoint".into(), work.into()]);
        }
        ok(vcsmooth(args))
    };
    let plain = tmp.path().join("plain.ply");
    smooth(&plain, "6", None);
    let out = tmp.path().join("out.ply");
    for stop in [2, 4] {
        let work = tmp.path().join(format!("ck{stop}"));
        smooth(&out, &stop.to_string(), Some(&work));
        assert!(smooth(&out, "6", Some(&work)).contains(&format!("resumed after {stop}")));
        let same = std::fs::read(&out).unwrap() == std::fs::read(&plain).unwrap();
        assert!(same, "resumed after {stop} of 6 iterations");
    }
}

#[test]
fn comm_sum_is_identical_on_every_rank() {
    let comms = Local::group(3);
    let sums: Vec<Vec<f64>> = std::thread::scope(|s| {
        let hs: Vec<_> = comms
            .iter()
            .map(|c| s.spawn(move || c.sum(&[0.1 * (c.rank() as f64 + 1.0), 1e16])))
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(sums.windows(2).all(|w| w[0] == w[1]));
}

/// With statistics of the last iteration only (`--stats last`), the checkpoint holds records whose
/// figures are NaN (`null` in its JSON): a resumed run reads them back, and every rank reports the
/// unmeasured iterations as NaN, as one process does.
#[test]
fn a_run_measuring_only_its_last_iteration_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let input = sphere_file(tmp.path(), 4);
    let engine = EngineSettings {
        statistics: Statistics::Last,
        ..engine_settings(300, 1)
    };
    let opts = |iterations| Options {
        method: Method::Taubin,
        iterations,
        ..Options::default()
    };
    let plain = tmp.path().join("plain.ply");
    let single = engine::run_file(&input, &plain, &opts(4), &engine, &mut Quiet).unwrap();
    let (work, out) = (tmp.path().join("ck"), tmp.path().join("out.ply"));
    for (iterations, resumed) in [(2, 0), (4, 2)] {
        let run = run_ranks(
            2,
            &input,
            &out,
            &opts(iterations),
            &engine,
            &cluster_settings(&work, true, 1),
        )
        .remove(0)
        .unwrap();
        assert_eq!(run.cluster.unwrap().resumed_after, resumed);
        assert_eq!(run.records.len(), iterations);
        // Measured: the last iteration of each run (the first run's stays in the checkpoint).
        let measured: Vec<bool> = run
            .records
            .iter()
            .map(|r| r.volume_pct.is_finite())
            .collect();
        let want: &[bool] = if resumed == 0 {
            &[false, true]
        } else {
            &[false, true, false, true]
        };
        assert_eq!(measured, want);
        for r in run.records.iter().filter(|r| !r.volume_pct.is_finite()) {
            assert!(r.volume.is_nan() && r.max_displacement.is_nan(), "{r:?}");
        }
    }
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&plain).unwrap());
    assert!(
        single.records[..3]
            .iter()
            .all(|r| r.max_displacement.is_nan())
    );
}

#[test]
fn iteration_counts_the_budget_cannot_record_are_refused_on_every_rank() {
    let dir = tempfile::tempdir().unwrap();
    let input = sphere_file(dir.path(), 2);
    let output = dir.path().join("out.ply");
    let opts = Options {
        iterations: 1 << 40,
        ..Options::default()
    };
    let engine = engine_settings(16384, 1);
    let settings = cluster_settings(&dir.path().join("work"), false, 1);
    for result in run_ranks(2, &input, &output, &opts, &engine, &settings) {
        let e = result.expect_err("refused");
        assert!(e.to_string().contains("record per iteration"), "{e}");
    }
    assert!(!output.exists());
}

/// A checkpoint belongs to the content it was made from, not to a file name, size and time: a
/// mesh of the same name, size and modification time in another folder is smoothed afresh (it
/// got the first mesh's result, exit 0), while the same bytes under another name resume. A
/// glTF whose external buffer changed is another input too. The report's `input.sha256` is the
/// one the checkpoint was keyed by.
#[test]
fn a_checkpoint_is_reused_only_for_the_same_content() {
    let tmp = tempfile::tempdir().unwrap();
    let folder = |name: &str| {
        let d = tmp.path().join(name);
        std::fs::create_dir(&d).unwrap();
        d
    };
    let (a, b, c) = (folder("a"), folder("b"), folder("c"));
    let first = a.join("scan.ply");
    let second = b.join("scan.ply");
    io::write_mesh(&first, &noisy_sphere(4, 0.4, 1)).unwrap();
    io::write_mesh(&second, &noisy_sphere(4, 0.4, 2)).unwrap();
    let when = std::fs::metadata(&first).unwrap().modified().unwrap();
    for f in [&first, &second] {
        let file = std::fs::File::options().write(true).open(f).unwrap();
        file.set_modified(when).unwrap();
    }
    assert_eq!(
        std::fs::metadata(&first).unwrap().len(),
        std::fs::metadata(&second).unwrap().len()
    );
    assert_ne!(
        std::fs::read(&first).unwrap(),
        std::fs::read(&second).unwrap()
    );
    let renamed = c.join("renamed.ply");
    std::fs::copy(&first, &renamed).unwrap();

    let work = tmp.path().join("ck");
    let smooth = |input: &Path, out: &Path, checkpoint: bool| {
        let report = tmp.path().join("r.json");
        let mut args = vec![
            "smooth".to_string(),
            input.display().to_string(),
            out.display().to_string(),
            "--iterations".into(),
            "3".into(),
            "--report".into(),
            report.display().to_string(),
        ];
        if checkpoint {
            args.extend(["--checkpoint".into(), work.display().to_string()]);
        }
        ok(vcsmooth(args));
        read_json(&report)
    };
    let out = |name: &str| tmp.path().join(name);
    let r = smooth(&first, &out("first.ply"), true);
    assert_eq!(r["cluster"]["resumed_after"], 0);
    let hash = io::sha256_file(&first).unwrap();
    assert_eq!(r["input"]["sha256"].as_str(), Some(hash.as_str()));

    // Same name, size and time, other bytes: a new plan, and its own result.
    let r = smooth(&second, &out("second.ply"), true);
    assert_eq!(
        r["cluster"]["resumed_after"], 0,
        "a foreign checkpoint was resumed"
    );
    smooth(&second, &out("second-plain.ply"), false);
    assert_eq!(
        std::fs::read(out("second.ply")).unwrap(),
        std::fs::read(out("second-plain.ply")).unwrap()
    );
    assert_ne!(
        std::fs::read(out("second.ply")).unwrap(),
        std::fs::read(out("first.ply")).unwrap()
    );

    // The same bytes as the plan's, under another name: resumed, with the same output.
    smooth(&first, &out("again.ply"), true);
    let r = smooth(&renamed, &out("renamed.ply"), true);
    assert_eq!(
        r["cluster"]["resumed_after"], 3,
        "the same content was not resumed"
    );
    assert_eq!(
        std::fs::read(out("renamed.ply")).unwrap(),
        std::fs::read(out("first.ply")).unwrap()
    );

    // A .gltf's geometry lives in its buffer: another buffer behind the same JSON is another
    // input.
    let gltf = c.join("scan.gltf");
    let write_gltf = |seed: u64| {
        let m = noisy_sphere(4, 0.4, seed);
        let mut bin: Vec<u8> = m
            .positions
            .iter()
            .flat_map(|p| p.as_vec3().to_array())
            .flat_map(f32::to_le_bytes)
            .collect();
        let at = bin.len();
        bin.extend(m.triangles.iter().flatten().flat_map(|v| v.to_le_bytes()));
        let doc = serde_json::json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
            "buffers": [{"uri": "scan.bin", "byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": at},
                {"buffer": 0, "byteOffset": at, "byteLength": bin.len() - at},
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": m.positions.len(),
                 "type": "VEC3", "min": [-2.0, -2.0, -2.0], "max": [2.0, 2.0, 2.0]},
                {"bufferView": 1, "componentType": 5125, "count": 3 * m.triangles.len(),
                 "type": "SCALAR"},
            ],
        });
        std::fs::write(c.join("scan.bin"), bin).unwrap();
        std::fs::write(&gltf, serde_json::to_vec(&doc).unwrap()).unwrap();
    };
    write_gltf(1);
    let json = std::fs::read(&gltf).unwrap();
    let json_time = std::fs::metadata(&gltf).unwrap().modified().unwrap();
    smooth(&gltf, &out("g1.gltf"), true);
    let r = smooth(&gltf, &out("g1.gltf"), true);
    assert_eq!(r["cluster"]["resumed_after"], 3);
    write_gltf(2);
    let file = std::fs::File::options().write(true).open(&gltf).unwrap();
    file.set_modified(json_time).unwrap();
    assert!(
        std::fs::read(&gltf).unwrap() == json,
        "the same JSON, another buffer"
    );
    let r = smooth(&gltf, &out("g2.gltf"), true);
    assert_eq!(
        r["cluster"]["resumed_after"], 0,
        "a changed buffer was not noticed"
    );
}

/// A plan made out of core finds its faces in the triangles' runs and stores their starts
/// (`face_runs.u32`) rather than the vertex → face lists; ranks that map it write the bytes of
/// the in-core single-process run, for `vcs` and the default method.
#[test]
fn a_plan_made_out_of_core_stores_face_runs_and_ranks_give_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    // Large enough (1.3M triangles) for the least budget to put the plan on the disk.
    let input = sphere_file(tmp.path(), 8);
    for method in [Method::Vcs, Method::VcsLowpass] {
        let opts = Options {
            method,
            iterations: 1,
            ..Options::default()
        };
        let reference = tmp.path().join(format!("{method}-plain.ply"));
        engine::run_file(
            &input,
            &reference,
            &opts,
            &engine_settings(4000, 2),
            &mut Quiet,
        )
        .unwrap();
        let expected = std::fs::read(&reference).unwrap();
        let ranks = 2;
        let out = tmp.path().join(format!("{method}-{ranks}.ply"));
        let work = tmp.path().join(format!("{method}-{ranks}.work"));
        let engine = EngineSettings {
            memory_budget: Some(64 << 20),
            scratch: Some(tmp.path().to_path_buf()),
            ..engine_settings(4000, 1)
        };
        run_ranks(
            ranks,
            &input,
            &out,
            &opts,
            &engine,
            &cluster_settings(&work, true, 1),
        )
        .into_iter()
        .for_each(|r| {
            r.unwrap();
        });
        assert!(
            std::fs::read(&out).unwrap() == expected,
            "{method} on {ranks} ranks from a plan out of core differs"
        );
        assert!(
            work.join("face_runs.u32").exists(),
            "{method}: the runs stored"
        );
        assert!(!work.join("vf.u32").exists() && !work.join("vf_offsets.u64").exists());
    }
}
