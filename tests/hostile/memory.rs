//! Memory: no allocation sized from a user's count before work, a default budget that respects the
//! process's limits (cgroup, rlimit), a failed allocation as one line (never an abort), and
//! reports that describe the output as it is stored.

use std::path::Path;
use std::process::Output;
use std::time::{Duration, Instant};

use vcsmooth::{Topology, io, metrics, shapes};

use crate::util::{BIN, generate_sphere, read_json, stderr, vcsmooth};

/// Exactly one line `vcsmooth: error: …` naming each of `mentions`, a non-zero exit, no abort.
fn one_line_error(o: &Output, mentions: &[&str]) {
    let err = stderr(o);
    assert!(
        o.status.code().is_some_and(|c| c != 0),
        "status {:?}: {err}",
        o.status
    );
    let lines: Vec<&str> = err.trim_end().lines().collect();
    assert_eq!(lines.len(), 1, "not one line: {err:?}");
    assert!(lines[0].starts_with("vcsmooth: error: "), "{err}");
    for m in mentions {
        assert!(lines[0].contains(m), "'{m}' not in: {err}");
    }
}

/// `vcsmooth ARGS` under `ulimit -v KIB` (the address-space rlimit).
fn under_ulimit_v(kib: u64, args: &[&str]) -> Output {
    let script = format!("ulimit -v {kib} && exec \"$0\" \"$@\"");
    std::process::Command::new("sh")
        .env("RUST_BACKTRACE", "1")
        .stdin(std::process::Stdio::null())
        .args(["-c", &script, BIN])
        .args(args)
        .output()
        .expect("run sh")
}

#[test]
fn huge_iteration_counts_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    generate_sphere(&input, 2, Some(0.3), None);
    let out = dir.path().join("out.ply");
    for n in ["18446744073709551615", "300000000"] {
        for stats in ["every", "last"] {
            let start = Instant::now();
            let o = vcsmooth([
                "smooth",
                input.to_str().unwrap(),
                out.to_str().unwrap(),
                "--iterations",
                n,
                "--stats",
                stats,
            ]);
            // Refused up front: one record per iteration would not fit the budget.
            one_line_error(&o, &["--iterations", "not enough memory", "budget"]);
            assert!(start.elapsed() < Duration::from_secs(30));
            assert!(!out.exists());
        }
    }
    // With a budget of 64 MiB, 32768 records fit and one more does not.
    let budget = |n: &str| {
        vcsmooth([
            "smooth",
            input.to_str().unwrap(),
            out.to_str().unwrap(),
            "--iterations",
            n,
            "--memory-budget",
            "64M",
            "--method",
            "laplacian",
            "--stats",
            "last",
        ])
    };
    one_line_error(&budget("32769"), &["run at most 32768 iterations"]);
    assert!(budget("32768").status.success());
}

#[test]
fn commands_under_an_address_space_limit_fail_in_one_line_or_succeed() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.ply");
    generate_sphere(&input, 6, Some(0.3), None);
    let p = |name: &str| dir.path().join(name).display().to_string();
    let (out, sub, gen_) = (p("out.ply"), p("sub.ply"), p("gen.ply"));
    let report = p("report.json");
    let input = input.display().to_string();
    let runs: [(&[&str], &str); 5] = [
        (&["smooth", &input, &out, "--iterations", "2"], &out),
        (
            &[
                "smooth",
                &input,
                &out,
                "--iterations",
                "2",
                "--report",
                &report,
            ],
            &out,
        ),
        (&["subdivide", &input, &sub, "--max-edge", "0.002"], &sub),
        (
            &[
                "generate",
                "sphere",
                &gen_,
                "--subdivisions",
                "10",
                "--noise",
                "0.1",
            ],
            &gen_,
        ),
        (
            &[
                "generate",
                "sphere",
                &gen_,
                "--subdivisions",
                "10",
                "--subdivide",
                "1",
            ],
            &gen_,
        ),
    ];
    for (args, output) in runs {
        let _ = std::fs::remove_file(output);
        let o = under_ulimit_v(300_000, args);
        if o.status.success() {
            assert!(Path::new(output).is_file(), "{args:?}");
        } else {
            one_line_error(&o, &[]);
            assert!(!Path::new(output).exists(), "{args:?}");
        }
    }
    // What cannot fit says what it needs and the budget, which came from the rlimit.
    let o = under_ulimit_v(300_000, &["subdivide", &input, &sub, "--max-edge", "0.002"]);
    one_line_error(
        &o,
        &[
            "not enough memory",
            "needed, budget",
            "rlimit",
            "--max-edge",
        ],
    );
    // So does `refine`, which had no check: the first round's subdivision aborted the process.
    let o = under_ulimit_v(
        300_000,
        &[
            "refine",
            &input,
            &sub,
            "--max-edge",
            "0.002",
            "--rounds",
            "1",
        ],
    );
    one_line_error(
        &o,
        &[
            "not enough memory",
            "needed, budget",
            "rlimit",
            "--max-edge",
            "--memory-budget",
        ],
    );
    assert!(!Path::new(&sub).exists());
    let o = under_ulimit_v(
        300_000,
        &["generate", "sphere", &gen_, "--subdivisions", "10"],
    );
    one_line_error(
        &o,
        &["not enough memory", "--subdivisions", "--memory-budget"],
    );
    // A small run reports where its budget came from.
    let small = p("small.ply");
    generate_sphere(Path::new(&small), 2, Some(0.3), None);
    let o = under_ulimit_v(
        1_000_000,
        &[
            "smooth",
            &small,
            &out,
            "--iterations",
            "2",
            "--report",
            &report,
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let r = read_json(Path::new(&report));
    assert_eq!(r["memory"]["budget_source"], "rlimit");
    assert!(r["memory"]["budget"].as_u64().unwrap() < 1_000_000 << 10);
}

/// A PLY of `mesh` with `uchar` coordinates (scaled into 0..=255).
fn uchar_ply(path: &Path, level: u32) {
    let mesh = shapes::icosphere(level);
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty uchar x\nproperty uchar y\nproperty uchar z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    )
    .into_bytes();
    for p in mesh.positions.iter() {
        for c in p.to_array() {
            bytes.push((128.0 + 100.0 * c).round() as u8);
        }
    }
    for t in mesh.triangles.iter() {
        bytes.push(3);
        for v in t {
            bytes.extend((*v as i32).to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn the_report_measures_the_output_as_stored() {
    let dir = tempfile::tempdir().unwrap();
    let uchar = dir.path().join("uchar.ply");
    uchar_ply(&uchar, 3);
    let float = dir.path().join("float.ply");
    generate_sphere(&float, 3, Some(0.3), None);
    for (input, name) in [(&uchar, "uchar"), (&float, "float"), (&float, "obj")] {
        let ext = if name == "obj" { "obj" } else { "ply" };
        let out = dir.path().join(format!("{name}-out.{ext}"));
        let report = dir.path().join(format!("{name}.json"));
        let o = vcsmooth([
            "smooth",
            input.to_str().unwrap(),
            out.to_str().unwrap(),
            "--iterations",
            "5",
            "--report",
            report.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let r = read_json(&report);
        let written = io::read_mesh(&out).unwrap();
        let topo = Topology::build(written.positions.len(), &written.triangles).unwrap();
        let stored = metrics::info(&written, &topo).unwrap();
        // The sums run in another vertex order: equal to the last bits' rounding.
        let close = |key: &str, want: f64| {
            let got = r["output"]["stats"][key].as_f64().unwrap();
            assert!(
                (got - want).abs() <= 1e-12 * want.abs(),
                "{name}: the report's {key} is {got}, the file's {want}"
            );
        };
        close("volume", stored.volume);
        close("area", stored.area);
        close("mean_edge_length", stored.mean_edge_length);
    }
}
