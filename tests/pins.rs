//! Pinned vertices: `--pin FILE` and `--pin-property NAME`, and the library's
//! `EngineSettings::pins`. A pinned vertex keeps its record byte for byte in every method, for any
//! thread count, in core and out of core, in multiresolution and over the cluster engine's ranks;
//! vcs keeps the volume; bad pins are one-line errors that write nothing.

use std::path::{Path, PathBuf};

use vcsmooth::engine::{self, EngineSettings, Pins, Quiet};
use vcsmooth::mesh::Storage;
use vcsmooth::{Error, Method, Options, io};

use crate::util::{
    cluster_settings, engine_settings, fails, generate_sphere, noisy_sphere, ok, planned_positions,
    read_json, run_ranks, vcsmooth,
};

/// The vertex records of a binary PLY file whose vertex element comes first and has scalar
/// properties only.
fn vertex_records(path: &Path) -> Vec<Vec<u8>> {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("a PLY header")
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let (mut count, mut stride, mut in_vertex) = (0, 0, false);
    for line in header.lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", "vertex", n] => {
                count = n.parse::<usize>().unwrap();
                in_vertex = true;
            }
            ["element", ..] => in_vertex = false,
            ["property", ty, _] if in_vertex => {
                stride += match *ty {
                    "char" | "uchar" | "int8" | "uint8" => 1,
                    "short" | "ushort" | "int16" | "uint16" => 2,
                    "int" | "uint" | "float" | "int32" | "uint32" | "float32" => 4,
                    "double" | "float64" => 8,
                    other => panic!("type {other}"),
                }
            }
            _ => {}
        }
    }
    bytes[end..end + count * stride]
        .chunks_exact(stride)
        .map(<[u8]>::to_vec)
        .collect()
}

/// Assert that `output` keeps the vertex records of `input` exactly where `pinned` says, and that
/// some other vertex moved.
fn assert_pinned(input: &Path, output: &Path, pinned: &[usize], what: &str) {
    let (a, b) = (vertex_records(input), vertex_records(output));
    assert_eq!(a.len(), b.len(), "{what}");
    for &v in pinned {
        assert!(a[v] == b[v], "{what}: pinned vertex {v} moved");
    }
    let moved = (0..a.len()).filter(|v| a[*v] != b[*v]).count();
    assert!(moved > a.len() / 2, "{what}: only {moved} vertices moved");
}

/// Every seventh vertex, and 1.
fn pinned_of(n: usize) -> Vec<usize> {
    let mut p: Vec<usize> = (0..n).step_by(7).collect();
    p.push(1);
    p.sort();
    p
}

/// A pin file naming `pinned` with comments, a blank line and a duplicate.
fn write_pin_file(path: &Path, pinned: &[usize]) {
    let mut text = String::from("# pinned vertices\n\n");
    for v in pinned {
        text += &format!("{v}  # kept\n");
    }
    text += "1\n";
    std::fs::write(path, text).unwrap();
}

/// A noisy sphere of `level` written as binary PLY, with its pin file (see [`pinned_of`]).
fn sphere_with_pins(dir: &Path, level: u32) -> (PathBuf, PathBuf, Vec<usize>) {
    let input = dir.join("in.ply");
    let mesh = noisy_sphere(level, 0.3, 5);
    io::write_mesh(&input, &mesh).unwrap();
    let pins = dir.join("pins.txt");
    let pinned = pinned_of(mesh.positions.len());
    write_pin_file(&pins, &pinned);
    (input, pins, pinned)
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

#[test]
fn pinned_vertices_keep_their_bytes_in_every_method_and_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let (input, pins, pinned) = sphere_with_pins(dir.path(), 4);
    let runs: [(&str, &[&str]); 6] = [
        ("laplacian", &["--method", "laplacian"]),
        ("taubin", &["--method", "taubin"]),
        ("lem", &["--method", "lem"]),
        ("vcs", &["--method", "vcs"]),
        ("vcs-triangle", &["--method", "vcs-triangle"]),
        ("multires", &["--multires", "--coarse-iterations", "2"]),
    ];
    for (name, extra) in runs {
        let mut outputs = Vec::new();
        for threads in ["1", "3"] {
            let out = dir.path().join(format!("{name}-{threads}.ply"));
            let report = dir.path().join(format!("{name}-{threads}.json"));
            let mut args = vec![
                "smooth".to_string(),
                s(&input),
                s(&out),
                "--pin".into(),
                s(&pins),
                "--iterations".into(),
                "3".into(),
                "--patch-size".into(),
                "512".into(),
                "--threads".into(),
                threads.into(),
                "--report".into(),
                s(&report),
            ];
            args.extend(extra.iter().map(|a| a.to_string()));
            ok(vcsmooth(&args));
            assert_pinned(&input, &out, &pinned, &format!("{name}, {threads} threads"));
            let r = read_json(&report);
            let distinct = pinned.len();
            assert_eq!(r["input"]["stats"]["pinned_vertices"], distinct as u64);
            assert!(r["input"]["stats"]["fixed_vertices"].as_u64().unwrap() >= distinct as u64);
            assert_eq!(r["engine"]["pins"]["file"], s(&pins));
            outputs.push(std::fs::read(&out).unwrap());
        }
        assert!(outputs[0] == outputs[1], "{name}: 1 and 3 threads differ");
    }
}

#[test]
fn pins_change_nothing_else_when_they_pin_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (input, _, _) = sphere_with_pins(dir.path(), 3);
    let empty = dir.path().join("empty.txt");
    std::fs::write(&empty, "# nothing pinned\n\n").unwrap();
    let (a, b) = (dir.path().join("a.ply"), dir.path().join("b.ply"));
    ok(vcsmooth([
        "smooth",
        &s(&input),
        &s(&a),
        "--iterations",
        "2",
    ]));
    ok(vcsmooth([
        "smooth",
        &s(&input),
        &s(&b),
        "--iterations",
        "2",
        "--pin",
        &s(&empty),
    ]));
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap());
}

/// The patch engine on scratch storage gives the heap's bits with pins, for every method.
#[test]
fn pinned_plans_in_scratch_equal_heap() {
    let mesh = noisy_sphere(4, 0.3, 9);
    let n = mesh.positions.len();
    let pinned = pinned_of(n);
    let pins = Pins::Indices(pinned.iter().map(|&v| v as u32).collect())
        .resolve(&mesh, None)
        .unwrap()
        .unwrap();
    assert_eq!(pins.len(), pinned.len());
    let scratch = tempfile::tempdir().unwrap();
    let mapped = Storage::scratch(scratch.path()).unwrap();
    for method in Method::ALL {
        let opts = Options {
            method,
            iterations: 3,
            ..Options::default()
        };
        let run = |storage: &Storage, threads: usize| {
            planned_positions(&mesh, storage, threads, 512, &opts, |plan| {
                plan.pin(&pins);
                assert_eq!(plan.topology.stats.pinned_vertices, pins.len());
            })
        };
        let heap = run(&Storage::heap(), 1);
        assert!(
            run(&mapped, 3) == heap,
            "{method}: scratch differs from heap"
        );
        for &v in &pinned {
            assert_eq!(heap[v], mesh.positions[v], "{method}: vertex {v} moved");
        }
    }
}

/// A file run that goes out of core (`--memory-budget`) keeps the pins and the in-core bits.
#[test]
fn pins_hold_out_of_core() {
    let dir = tempfile::tempdir().unwrap();
    let scratch = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    // Level 8 (1.3M triangles) is the smallest sphere whose in-core estimate exceeds 64M.
    generate_sphere(&input, 8, Some(0.3), None);
    let pins = dir.path().join("pins.txt");
    let pinned: Vec<usize> = (0..655_362).step_by(997).collect();
    write_pin_file(&pins, &pinned);
    let run = |name: &str, extra: &[&str]| {
        let out = dir.path().join(format!("{name}.ply"));
        let report = dir.path().join(format!("{name}.json"));
        let mut args = vec![
            "smooth".to_string(),
            s(&input),
            s(&out),
            "--iterations".into(),
            "1".into(),
            "--patch-size".into(),
            "4096".into(),
            "--pin".into(),
            s(&pins),
            "--report".into(),
            s(&report),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        ok(vcsmooth(&args));
        (out, read_json(&report))
    };
    let (heap, rh) = run("heap", &["--threads", "1"]);
    assert_eq!(rh["memory"]["storage"], "heap");
    let sdir = s(scratch.path());
    let (mapped, rm) = run(
        "mapped",
        &[
            "--threads",
            "2",
            "--memory-budget",
            "64M",
            "--scratch",
            &sdir,
        ],
    );
    assert_eq!(rm["memory"]["storage"], "scratch");
    assert_pinned(&input, &heap, &pinned, "heap");
    assert!(
        std::fs::read(&heap).unwrap() == std::fs::read(&mapped).unwrap(),
        "scratch differs from heap"
    );
}

#[test]
fn vcs_keeps_the_volume_with_pins() {
    let dir = tempfile::tempdir().unwrap();
    let (input, pins, pinned) = sphere_with_pins(dir.path(), 4);
    let out = dir.path().join("out.ply");
    let engine = EngineSettings {
        with_stats: true,
        pins: Pins::File(pins),
        ..engine_settings(512, 2)
    };
    let opts = Options {
        iterations: 5,
        ..Options::default()
    };
    let run = engine::run_file(&input, &out, &opts, &engine, &mut Quiet).unwrap();
    let last = run.records.last().unwrap();
    assert!(
        (last.volume_pct - 100.0).abs() < 1e-7,
        "{}",
        last.volume_pct
    );
    assert!(last.stencils.applied > 0);
    let stats = run.input_stats.unwrap();
    assert_eq!(stats.pinned_vertices, pinned.len());
    assert_pinned(&input, &out, &pinned, "vcs");
}

/// The front door (`vcsmooth::smooth_with`) takes indices or a mask in the input's order.
#[test]
fn in_memory_meshes_take_indices_and_masks() {
    let mesh = noisy_sphere(3, 0.3, 2);
    let n = mesh.positions.len();
    let pinned = pinned_of(n);
    let mut mask = vec![false; n];
    pinned.iter().for_each(|&v| mask[v] = true);
    let opts = Options::default();
    let mut results = Vec::new();
    for pins in [
        Pins::Indices(pinned.iter().map(|&v| v as u32).collect()),
        Pins::Mask(mask),
    ] {
        let mut m = mesh.clone();
        let engine = EngineSettings {
            pins,
            ..EngineSettings::default()
        };
        vcsmooth::smooth_with(&mut m, &opts, &engine, &mut Quiet).unwrap();
        for &v in &pinned {
            assert_eq!(m.positions[v], mesh.positions[v], "vertex {v} moved");
        }
        results.push(m.positions.to_vec());
    }
    assert!(results[0] == results[1], "indices and mask differ");

    let bad = |pins: Pins| {
        let engine = EngineSettings {
            pins,
            ..EngineSettings::default()
        };
        match vcsmooth::smooth_with(&mut mesh.clone(), &opts, &engine, &mut Quiet) {
            Err(Error::Parameter { name, problem }) => format!("{name} {problem}"),
            other => panic!("expected a parameter error, got {other:?}"),
        }
    };
    let e = bad(Pins::Indices(vec![3, n as u32]));
    assert!(e.contains(&format!("vertex index {n}")) && e.contains(&format!("{n} vertices")));
    assert!(bad(Pins::Mask(vec![true; 3])).contains("3 flags"));
    assert!(bad(Pins::Property("pin".into())).contains("PLY"));
}

#[test]
fn the_ranks_of_the_cluster_engine_keep_the_pins() {
    let dir = tempfile::tempdir().unwrap();
    let (input, pins, pinned) = sphere_with_pins(dir.path(), 4);
    let opts = Options {
        iterations: 3,
        ..Options::default()
    };
    let pinned_engine = |threads| EngineSettings {
        pins: Pins::File(pins.clone()),
        ..engine_settings(512, threads)
    };
    let reference = dir.path().join("plain.ply");
    engine::run_file(&input, &reference, &opts, &pinned_engine(2), &mut Quiet).unwrap();
    assert_pinned(&input, &reference, &pinned, "single process");
    let expected = std::fs::read(&reference).unwrap();
    for ranks in [1, 3] {
        let out = dir.path().join(format!("ranks-{ranks}.ply"));
        let work = dir.path().join(format!("ranks-{ranks}.work"));
        run_ranks(
            ranks,
            &input,
            &out,
            &opts,
            &pinned_engine(1),
            &cluster_settings(&work, false, 1),
        )
        .remove(0)
        .unwrap();
        assert!(
            std::fs::read(&out).unwrap() == expected,
            "{ranks} ranks differ from the single-process engine"
        );
    }
    // A plan kept without pins is not reused for a run with them.
    let work = dir.path().join("kept.work");
    let out = dir.path().join("kept.ply");
    let kept = cluster_settings(&work, true, 1);
    run_ranks(2, &input, &out, &opts, &engine_settings(512, 1), &kept)
        .remove(0)
        .unwrap();
    assert!(std::fs::read(&out).unwrap() != expected);
    run_ranks(2, &input, &out, &opts, &pinned_engine(1), &kept)
        .remove(0)
        .unwrap();
    assert!(
        std::fs::read(&out).unwrap() == expected,
        "stale plan reused"
    );
}

/// A binary PLY of a noisy sphere with the extra vertex properties `uchar pin` and
/// `float quality`, non-zero on `pinned`.
fn sphere_with_properties(path: &Path, pinned: &[usize]) -> usize {
    let mesh = noisy_sphere(4, 0.3, 3);
    let n = mesh.positions.len();
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n\
         property float y\nproperty float z\nproperty uchar pin\nproperty float quality\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.triangles.len()
    )
    .into_bytes();
    for (v, p) in mesh.positions.iter().enumerate() {
        for c in p.as_vec3().to_array() {
            bytes.extend(c.to_le_bytes());
        }
        let on = pinned.contains(&v);
        bytes.push(if on { 3 } else { 0 });
        bytes.extend((if on { 0.5f32 } else { 0.0 }).to_le_bytes());
    }
    for t in mesh.triangles.iter() {
        bytes.push(3);
        for &i in t {
            bytes.extend((i as i32).to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
    n
}

#[test]
fn pin_property_pins_non_zero_vertices() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("props.ply");
    let pinned = pinned_of(2562);
    let n = sphere_with_properties(&input, &pinned);
    assert_eq!(n, 2562);
    let mut outputs = Vec::new();
    for name in ["pin", "quality"] {
        let out = dir.path().join(format!("{name}.ply"));
        let report = dir.path().join(format!("{name}.json"));
        ok(vcsmooth([
            "smooth",
            &s(&input),
            &s(&out),
            "--pin-property",
            name,
            "--iterations",
            "3",
            "--report",
            &s(&report),
        ]));
        assert_pinned(&input, &out, &pinned, name);
        let r = read_json(&report);
        assert_eq!(r["input"]["stats"]["pinned_vertices"], pinned.len() as u64);
        assert_eq!(r["engine"]["pins"]["property"], name);
        outputs.push(std::fs::read(&out).unwrap());
    }
    assert!(outputs[0] == outputs[1]);
    // The same through the library, on the mesh as read.
    let mut mesh = io::read_mesh(&input).unwrap();
    let before = mesh.positions.to_vec();
    let engine = EngineSettings {
        pins: Pins::Property("pin".into()),
        ..EngineSettings::default()
    };
    vcsmooth::smooth_with(&mut mesh, &Options::default(), &engine, &mut Quiet).unwrap();
    for &v in &pinned {
        assert_eq!(mesh.positions[v], before[v]);
    }
}

#[test]
fn bad_pins_are_one_line_errors_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (input, pins, _) = sphere_with_pins(dir.path(), 3);
    let out = dir.path().join("out.ply");
    let file = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        s(&p)
    };
    let not_a_number = file("words.txt", "# header\n4\nabc\n");
    let negative = file("negative.txt", "-1\n");
    let too_large = file("large.txt", "0\n642\n");
    let missing = s(&dir.path().join("missing.txt"));
    let props = dir.path().join("props.ply");
    sphere_with_properties(&props, &[0, 1]);
    let obj = dir.path().join("in.obj");
    io::write_mesh(&obj, &noisy_sphere(2, 0.1, 1)).unwrap();
    let report_over_pins = ["--pin".to_string(), s(&pins), "--report".into(), s(&pins)];
    let cases: Vec<(String, Vec<String>, i32, Vec<String>)> = vec![
        (
            s(&input),
            vec!["--pin".into(), not_a_number.clone()],
            2,
            vec![not_a_number, "line 3".into(), "'abc'".into()],
        ),
        (
            s(&input),
            vec!["--pin".into(), negative.clone()],
            2,
            vec![negative, "line 1".into(), "'-1'".into()],
        ),
        (
            s(&input),
            vec!["--pin".into(), too_large.clone()],
            1,
            vec![
                too_large,
                "line 2".into(),
                "vertex index 642".into(),
                "642 vertices".into(),
            ],
        ),
        (
            s(&input),
            vec!["--pin".into(), missing.clone()],
            2,
            vec![missing],
        ),
        (
            s(&obj),
            vec!["--pin-property".into(), "pin".into()],
            1,
            vec![s(&obj), "'pin'".into(), "PLY".into()],
        ),
        (
            s(&props),
            vec!["--pin-property".into(), "weight".into()],
            1,
            vec![s(&props), "'weight'".into(), "x, y, z, pin, quality".into()],
        ),
        (
            s(&props),
            vec!["--pin-property".into(), "x".into()],
            1,
            vec!["'x'".into(), "coordinate".into()],
        ),
        (
            s(&input),
            report_over_pins.to_vec(),
            2,
            vec!["--report".into(), "--pin".into()],
        ),
        (
            s(&input),
            vec![
                "--pin".into(),
                s(&pins),
                "--pin-property".into(),
                "pin".into(),
            ],
            2,
            vec!["--pin".into()],
        ),
    ];
    for (input, extra, code, mentions) in cases {
        let mut args = vec!["smooth".to_string(), input, s(&out)];
        args.extend(extra.iter().cloned());
        let o = vcsmooth(&args);
        let mentions: Vec<&str> = mentions.iter().map(String::as_str).collect();
        fails(&o, code, &mentions);
        assert!(!out.exists(), "{extra:?} wrote an output");
    }
    // One list of indices cannot name the vertices of several meshes: batch takes no --pin.
    let o = vcsmooth([
        "batch",
        &s(dir.path()),
        &s(&dir.path().join("batch-out")),
        "--pin",
        &s(&pins),
    ]);
    fails(&o, 2, &["--pin FILE", "--pin-property NAME"]);
}

/// Hostile pin files are refused like hostile meshes, bounded and at once: devices, pipes and
/// directories (`/dev/zero` ran until the OOM killer), binary data, endless lines, indices no
/// mesh has; a file of 20 million lines under a 600 MB address-space limit (it aborted) is read
/// as a stream and fails at its first index out of range. One line, no output, no panic.
#[test]
fn hostile_pin_files_are_bounded_and_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let (input, _, _) = sphere_with_pins(dir.path(), 3);
    let out = dir.path().join("out.ply");
    let file = |name: &str, bytes: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        s(&p)
    };
    let fifo = dir.path().join("pins.fifo");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    let mut long = b"1\n".to_vec();
    long.extend(std::iter::repeat_n(b'7', 100_000));
    let mut binary = b"1\n2\n".to_vec();
    binary.extend((0..4096u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8));
    let mut cases: Vec<(String, i32, Vec<&str>)> = vec![
        (
            "/dev/zero".into(),
            2,
            vec!["not a file of vertex indices", "device"],
        ),
        (
            "/dev/urandom".into(),
            2,
            vec!["not a file of vertex indices", "device"],
        ),
        ("/dev/null".into(), 2, vec!["not a file of vertex indices"]),
        (s(dir.path()), 2, vec!["a directory"]),
        (
            file("zeros.txt", &[0u8; 1 << 20]),
            2,
            vec!["line 1", "NUL byte"],
        ),
        (file("binary.txt", &binary), 2, vec!["line 3"]),
        (
            file("long.txt", &long),
            2,
            vec!["line 2", "longer than 64 KiB"],
        ),
        (
            file("no-newline.txt", &vec![b'5'; 1 << 20]),
            2,
            vec!["line 1", "longer than 64 KiB"],
        ),
        (
            file("huge-index.txt", b"3\n4294967296\n"),
            2,
            vec!["line 2", "4294967296", "out of range"],
        ),
    ];
    if made.is_ok_and(|s| s.success()) {
        cases.push((s(&fifo), 2, vec!["not a file of vertex indices", "pipe"]));
    }
    for (pins, code, mentions) in &cases {
        let o = vcsmooth(["smooth", &s(&input), &s(&out), "--pin", pins]);
        let mut all = vec![pins.as_str()];
        all.extend(mentions);
        fails(&o, *code, &all);
        assert!(!out.exists(), "{pins} wrote an output");
    }
    // 20 million lines, read under an address-space limit: streamed into the mesh's bit set and
    // failing at the first index the mesh does not have, not after holding the whole file.
    let big = dir.path().join("big.txt");
    let mut text = Vec::with_capacity(170 << 20);
    for i in 0..20_000_000u32 {
        text.extend_from_slice(format!("{i}\n").as_bytes());
    }
    std::fs::write(&big, &text).unwrap();
    drop(text);
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 600000; exec \"$0\" \"$@\"")
        .args([
            crate::util::BIN,
            "smooth",
            &s(&input),
            &s(&out),
            "--pin",
            &s(&big),
        ])
        .output()
        .unwrap();
    fails(
        &o,
        1,
        &[&s(&big), "line 643", "vertex index 642", "642 vertices"],
    );
    assert!(!out.exists());
}

/// `batch --pin-property`: pinned outputs, and markers that certify the pins (a rerun without
/// them redoes the mesh).
#[test]
fn batch_pins_by_property_and_certifies_it() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).unwrap();
    let input = inputs.join("m.ply");
    let pinned = pinned_of(2562);
    sphere_with_properties(&input, &pinned);
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
    let text = batch(&["--pin-property", "pin"]);
    assert_eq!(text.matches("\ndone ").count(), 1, "{text}");
    let output = outdir.join("m.ply");
    assert_pinned(&input, &output, &pinned, "batch");
    let text = batch(&["--pin-property", "pin"]);
    assert_eq!(text.matches("\nskipped ").count(), 1, "{text}");
    let text = batch(&[]);
    assert_eq!(text.matches("\ndone ").count(), 1, "{text}");
    assert!(vertex_records(&input)[0] != vertex_records(&output)[0]);
    // The job script repeats the flag for its batch.
    let script = ok(vcsmooth([
        "slurm-script",
        &s(&inputs),
        &s(&outdir),
        "--pin-property",
        "pin",
    ]));
    assert!(script.contains(" --pin-property pin "), "{script}");
}

/// An ASCII PLY whose vertex element has a list (`tags`) and a `short` flag: the records are
/// walked, and the pinned vertices keep their coordinates.
#[test]
fn pin_property_in_ascii_records_with_lists() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = noisy_sphere(3, 0.3, 4);
    let n = mesh.positions.len();
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
         property float z\nproperty list uchar int tags\nproperty short keep\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.triangles.len()
    );
    for (v, p) in mesh.positions.iter().enumerate() {
        let [x, y, z] = p.as_vec3().to_array();
        let keep = if v % 5 == 0 { -2 } else { 0 };
        text += &format!("{x} {y} {z} 2 {v} 7 {keep}\n");
    }
    for t in mesh.triangles.iter() {
        text += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    let input = dir.path().join("tags.ply");
    std::fs::write(&input, text).unwrap();
    let out = dir.path().join("out.ply");
    ok(vcsmooth([
        "smooth",
        &s(&input),
        &s(&out),
        "--pin-property",
        "keep",
        "--iterations",
        "3",
    ]));
    let (a, b) = (io::read_mesh(&input).unwrap(), io::read_mesh(&out).unwrap());
    let moved = (0..n).filter(|&v| a.positions[v] != b.positions[v]).count();
    for v in (0..n).step_by(5) {
        assert_eq!(a.positions[v], b.positions[v], "vertex {v} moved");
    }
    assert!(moved > n / 2, "only {moved} moved");
}
