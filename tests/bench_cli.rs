//! `vcsmooth bench` end to end: a tiny run's JSON has every figure, positive and finite.

use serde_json::Value;

use crate::util::{command, vcsmooth};

fn positive(v: &Value, what: &str) -> f64 {
    let x = v
        .as_f64()
        .unwrap_or_else(|| panic!("{what} is not a number: {v}"));
    assert!(x.is_finite() && x > 0.0, "{what} = {x}");
    x
}

#[test]
fn bench_json_has_positive_finite_figures() {
    let dir = tempfile::tempdir().unwrap();
    let out = command()
        .args(["bench", "--sizes", "1K", "--methods", "vcs,laplacian"])
        .args([
            "--threads",
            "1",
            "--repeats",
            "1",
            "--iterations",
            "2",
            "--json",
        ])
        .arg("--dir")
        .arg(dir.path())
        .output()
        .expect("run vcsmooth");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "stderr: {stderr}");
    let doc: Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");

    assert_eq!(doc["tool"]["name"], "vcsmooth");
    positive(&doc["machine"]["cores"], "cores");
    positive(&doc["seconds"], "seconds");
    let sizes = doc["sizes"].as_array().expect("sizes");
    assert_eq!(sizes.len(), 1);
    let size = &sizes[0];
    assert_eq!(size["label"], "1K");
    assert_eq!(size["level"], 3);
    assert_eq!(size["triangles"], 1280);
    positive(&size["vertices"], "vertices");
    positive(&size["generate_seconds"], "generate_seconds");
    for key in [
        "file_bytes",
        "write_seconds",
        "write_gb_per_second",
        "read_seconds",
        "read_gb_per_second",
    ] {
        positive(&size["ply"][key], key);
    }
    for key in ["baseline_anon", "peak_anon"] {
        positive(&size["memory"][key], key);
    }
    let per_triangle = &size["memory"]["anon_bytes_per_triangle"];
    assert!(
        per_triangle
            .as_f64()
            .is_some_and(|x| x.is_finite() && x >= 0.0)
    );

    let runs = size["runs"].as_array().expect("runs");
    assert_eq!(runs.len(), 1);
    let run = &runs[0];
    assert_eq!(run["threads"], 1);
    positive(&run["patches"], "patches");
    positive(&run["colours"], "colours");
    for key in [
        "reorder_seconds",
        "topology_seconds",
        "partition_seconds",
        "total_seconds",
    ] {
        positive(&run["prepare"][key], key);
    }
    let methods = run["methods"].as_array().expect("methods");
    let names: Vec<&str> = methods
        .iter()
        .map(|m| m["method"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["vcs", "laplacian"]);
    for m in methods {
        positive(&m["seconds_per_iteration"], "seconds_per_iteration");
        positive(&m["triangles_per_second"], "triangles_per_second");
        positive(&m["volume_pct"], "volume_pct");
    }
    // Stencil figures for the stencil method only: 1 920 edges of the level-3 icosphere.
    assert_eq!(methods[0]["stencils_per_iteration"], 1920);
    positive(&methods[0]["stencils_per_second"], "stencils_per_second");
    assert!(methods[1]["stencils_per_second"].is_null());
    // The temporary PLY file is gone.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn bench_table_and_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = command()
        .args(["bench", "--sizes", "ico1", "--methods", "taubin"])
        .args(["--threads", "1", "--repeats", "1", "--iterations", "1"])
        .arg("--dir")
        .arg(dir.path())
        .output()
        .expect("run vcsmooth");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for word in [
        "write GB/s",
        "read GB/s",
        "B/tri",
        "prepare s",
        "Mtriangles/s",
        "taubin",
    ] {
        assert!(text.contains(word), "'{word}' not in:\n{text}");
    }

    for args in [
        &["bench", "--sizes", "lots"][..],
        &["bench", "--sizes", "100G"],
        &["bench", "--threads", "0"],
        &["bench", "--repeats", "0"],
        &["bench", "--methods", "median"],
        &["bench", "--dir", "/no/such/dir"],
    ] {
        let out = vcsmooth(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("vcsmooth: error: "), "{err}");
    }
}
