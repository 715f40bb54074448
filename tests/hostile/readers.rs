//! The readers on inputs the corpus cannot hold (devices, named pipes, directories, files of
//! gigabytes, header lines longer than a corpus file), and what the corpus's accepted quirks must
//! give beyond "it smooths": a UTF-8 byte-order mark loses no vertex, `-0.0` in STL opens no
//! crack, upper-case ASCII STL is read as ASCII.

use std::path::Path;
use std::process::{Child, Output};
use std::time::{Duration, Instant};

use super::cases;
use crate::util::{command, failed_with, json, ok, vcsmooth};

/// `vcsmooth ARGS` that must finish within `limit` (killed and failed otherwise), with how long
/// it took.
fn within(limit: Duration, args: &[&std::ffi::OsStr]) -> (Output, Duration) {
    let start = Instant::now();
    let mut child: Child = command()
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("vcsmooth {args:?} still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    (child.wait_with_output().unwrap(), start.elapsed())
}

/// `smooth` and `info` on `input` both fail at once with exactly `what`, and leave no output.
fn refused_fast(input: &Path, what: &str) {
    let dir = tempfile::tempdir().unwrap();
    let output = dir.path().join("out.ply");
    let line = format!("{}: {what}", input.display());
    let limit = Duration::from_secs(10);
    for args in [
        vec!["info".as_ref(), input.as_os_str()],
        vec!["smooth".as_ref(), input.as_os_str(), output.as_os_str()],
    ] {
        let (out, took) = within(limit, &args);
        failed_with(&out, &line).unwrap_or_else(|e| panic!("{args:?}: {e}"));
        assert!(took < Duration::from_secs(2), "{args:?} took {took:?}");
    }
    assert!(!output.exists());
}

fn info(path: &Path) -> serde_json::Value {
    json(&ok(vcsmooth([
        "info".as_ref(),
        path.as_os_str(),
        "--json".as_ref(),
    ])))
}

#[test]
fn endless_devices_and_directories_are_refused_without_reading_them() {
    for (device, what) in [
        (
            "/dev/zero",
            "the first 65536 bytes are all zero: not a mesh file",
        ),
        ("/dev/null", "empty file"),
    ] {
        if Path::new(device).exists() {
            refused_fast(Path::new(device), what);
        }
    }
    let dir = tempfile::tempdir().unwrap();
    refused_fast(dir.path(), "is a directory, not a mesh file");
}

#[test]
fn a_mesh_streamed_through_a_named_pipe_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("mesh.ply");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        return;
    }
    let source = crate::util::scan("horse.ply");
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::write(&fifo, std::fs::read(source).unwrap()))
    };
    let streamed = info(&fifo);
    writer.join().unwrap().unwrap();
    let file = info(&crate::util::scan("horse.ply"));
    assert_eq!(streamed["vertices"], file["vertices"]);
    assert_eq!(streamed["volume"], file["volume"]);
}

#[test]
fn a_zeroed_file_of_gigabytes_is_refused_from_its_first_bytes() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["sparse.ply", "sparse.obj", "sparse.stl"] {
        let path = dir.path().join(name);
        // Sparse: no disk space, but 8 GiB to read (or map and fault in) for a reader that looks
        // further than its first bytes.
        let file = std::fs::File::create(&path).unwrap();
        file.set_len(8 << 30).unwrap();
        drop(file);
        refused_fast(&path, "the first 65536 bytes are all zero: not a mesh file");
    }
}

#[test]
fn a_header_that_runs_on_is_refused_at_its_limit() {
    let dir = tempfile::tempdir().unwrap();
    let long = "x".repeat(1 << 20);
    let write = |name: &str, text: String| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let ply = write(
        "long_line.ply",
        format!("ply\nformat ascii 1.0\ncomment {long}\n"),
    );
    refused_fast(&ply, "header line 3 is longer than 64 KiB");
    let many = "comment a short line\n".repeat(60_000);
    let ply = write(
        "long_header.ply",
        format!("ply\nformat ascii 1.0\n{many}end_header\n"),
    );
    refused_fast(
        &ply,
        "header: no end_header line in the first 1 MiB (line 49934)",
    );
    let counts = "1 ".repeat(1 << 19);
    let off = write("long_counts.off", format!("OFF\n{counts}\n"));
    refused_fast(&off, "line 2 is longer than 64 KiB");
    let stl = write("long_name.stl", format!("solid {long}\nendsolid\n"));
    refused_fast(
        &stl,
        "line 1: the solid's name runs on for more than 64 KiB",
    );
}

#[test]
fn a_utf8_byte_order_mark_loses_nothing() {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in cases::octa_with_bom() {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let info = info(&path);
        assert_eq!(
            (&info["vertices"], &info["triangles"], &info["closed"]),
            (&6.into(), &8.into(), &true.into()),
            "{name}: {info}"
        );
    }
}

#[test]
fn stl_corners_merge_by_value_so_negative_zero_opens_no_crack() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("negative_zero.stl");
    std::fs::write(&input, cases::octa_stl_negative_zero()).unwrap();
    let before = info(&input);
    assert_eq!(
        (
            &before["vertices"],
            &before["boundary_edges"],
            &before["closed"]
        ),
        (&6.into(), &0.into(), &true.into()),
        "{before}"
    );
    let output = dir.path().join("smoothed.stl");
    ok(vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--iterations".as_ref(),
        "3".as_ref(),
    ]));
    let after = info(&output);
    assert_eq!(
        (&after["vertices"], &after["closed"]),
        (&6.into(), &true.into()),
        "{after}"
    );
}

#[test]
fn upper_and_mixed_case_ascii_stl_read_as_ascii() {
    let dir = tempfile::tempdir().unwrap();
    for (name, keywords) in [
        (
            "upper.stl",
            [
                "SOLID",
                "FACET NORMAL",
                "OUTER LOOP",
                "VERTEX",
                "ENDLOOP",
                "ENDFACET",
                "ENDSOLID",
            ],
        ),
        (
            "mixed.stl",
            [
                "Solid",
                "facet Normal",
                "Outer loop",
                "Vertex",
                "EndLoop",
                "endFacet",
                "EndSolid",
            ],
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, cases::octa_stl_cased(keywords)).unwrap();
        let info = info(&path);
        assert_eq!(
            (&info["vertices"], &info["triangles"], &info["closed"]),
            (&6.into(), &8.into(), &true.into()),
            "{name}: {info}"
        );
    }
}
