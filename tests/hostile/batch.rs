//! `batch` against a hostile file system: a marker is trusted only while it holds (its output is
//! there and unchanged, its input unchanged, the settings the same), and the summary counts as
//! done exactly what a rerun would skip; inputs that cannot be read fail one line each; OUTDIR =
//! the input directory is refused; the summary is never written over a file of the batch.

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, SystemTime};

use serde_json::Value;

use crate::util::{generate_sphere, listing, ok, read_json, stderr, stdout, vcsmooth};

/// `m0.ply` … `m{n-1}.ply` (small noisy spheres) in `dir/in`.
fn inputs(dir: &Path, n: usize) -> PathBuf {
    let input = dir.join("in");
    std::fs::create_dir(&input).unwrap();
    for k in 0..n {
        let path = input.join(format!("m{k}.ply"));
        generate_sphere(&path, 2, Some(0.3), Some(k as u64));
    }
    input
}

fn batch(input: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "batch".to_string(),
        input.display().to_string(),
        out.display().to_string(),
    ];
    if !extra.contains(&"--iterations") {
        args.extend(["--iterations".into(), "2".into()]);
    }
    args.extend(extra.iter().map(|s| s.to_string()));
    vcsmooth(&args)
}

fn summary(out: &Path, input: &Path) -> Output {
    vcsmooth([
        "batch".as_ref(),
        "--summary".as_ref(),
        out.as_os_str(),
        "--inputs".as_ref(),
        input.as_os_str(),
        "--json".as_ref(),
        "-".as_ref(),
    ])
}

/// The names a batch run's stdout says it smoothed (`done`), skipped and redid.
fn verdicts(text: &str) -> (Vec<String>, Vec<String>, Vec<String>) {
    let names = |prefix: &str| -> Vec<String> {
        let mut v: Vec<String> = text
            .lines()
            .filter_map(|l| l.strip_prefix(prefix))
            .map(|rest| {
                let file = rest.split([' ', ':']).next().unwrap();
                Path::new(file)
                    .file_stem()
                    .unwrap()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect();
        v.sort();
        v
    };
    (names("done "), names("skipped "), names("redoing "))
}

/// The stems the summary lists as missing.
fn missing(o: &Output) -> Vec<String> {
    let s: Value = serde_json::from_slice(&o.stdout).unwrap();
    let mut v: Vec<String> = s["missing"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            Path::new(m.as_str().unwrap())
                .file_stem()
                .unwrap()
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    v.sort();
    v
}

fn set_mtime(path: &Path, t: SystemTime) {
    let f = std::fs::File::options().write(true).open(path).unwrap();
    f.set_modified(t).unwrap();
}

#[test]
fn a_marker_is_trusted_only_while_it_holds_and_the_summary_agrees() {
    let dir = tempfile::tempdir().unwrap();
    let input = inputs(dir.path(), 5);
    let out = dir.path().join("out");
    ok(batch(&input, &out, &[]));
    let marker = |k: usize| out.join(".done").join(format!("m{k}.json"));
    let m = read_json(&marker(0));
    assert!(m["certifies"]["input"]["size"].as_u64().unwrap() > 0, "{m}");
    assert!(m["certifies"]["output"]["mtime_ns"].is_i64(), "{m}");

    // m0: output deleted. m1: input rewritten with the same size, a later time. m2: garbage marker.
    // m3: a marker of an earlier version (certifies nothing). m4: untouched.
    std::fs::remove_file(out.join("m0.ply")).unwrap();
    let m1 = input.join("m1.ply");
    let bytes = std::fs::read(&m1).unwrap();
    std::fs::write(&m1, &bytes).unwrap();
    set_mtime(&m1, SystemTime::now() + Duration::from_secs(5));
    std::fs::write(marker(2), b"{ not json").unwrap();
    let mut old: Value = read_json(&marker(3));
    old.as_object_mut().unwrap().remove("certifies");
    std::fs::write(marker(3), old.to_string()).unwrap();

    // The summary counts as missing exactly what the rerun redoes.
    let s = summary(&out, &input);
    assert_eq!(s.status.code(), Some(1), "{}", stderr(&s));
    assert_eq!(missing(&s), ["m0", "m1", "m2", "m3"]);
    let text = ok(batch(&input, &out, &[]));
    let (done, skipped, redone) = verdicts(&text);
    assert_eq!(done, ["m0", "m1", "m2", "m3"], "{text}");
    assert_eq!(redone, ["m0", "m1", "m2", "m3"], "{text}");
    assert_eq!(skipped, ["m4"], "{text}");
    assert!(missing(&summary(&out, &input)).is_empty());
    ok(summary(&out, &input));

    // The output changed behind the batch's back (same size): redone.
    let m4 = out.join("m4.ply");
    set_mtime(&m4, SystemTime::now() - Duration::from_secs(3600));
    assert_eq!(missing(&summary(&out, &input)), ["m4"]);
    let (done, skipped, _) = verdicts(&ok(batch(&input, &out, &[])));
    assert_eq!((done.len(), skipped.len()), (1, 4));

    // Other options: everything is redone, and nothing when they are given again.
    let text = ok(batch(&input, &out, &["--iterations", "3"]));
    let (done, skipped, redone) = verdicts(&text);
    assert_eq!(
        (done.len(), skipped.len(), redone.len()),
        (5, 0, 5),
        "{text}"
    );
    assert!(text.contains("iterations 2 -> 3"), "{text}");
    let (done, skipped, _) = verdicts(&ok(batch(&input, &out, &["--iterations", "3"])));
    assert_eq!((done.len(), skipped.len()), (0, 5));
    assert_eq!(read_json(&marker(4))["iterations"], 3);
}

#[test]
fn the_summary_reports_markers_that_no_longer_hold_also_without_the_input_list() {
    let dir = tempfile::tempdir().unwrap();
    let input = inputs(dir.path(), 2);
    let out = dir.path().join("out");
    ok(batch(&input, &out, &[]));
    let table = vcsmooth(["batch".as_ref(), "--summary".as_ref(), out.as_os_str()]);
    ok(table);
    std::fs::remove_file(out.join("m1.ply")).unwrap();
    let o = vcsmooth(["batch".as_ref(), "--summary".as_ref(), out.as_os_str()]);
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 2, "{err}");
    assert!(
        lines[0].starts_with("vcsmooth: error: ") && lines[0].contains("m1.ply"),
        "{err}"
    );
    assert!(lines[1].contains("1 markers no longer hold"), "{err}");
    assert!(stdout(&o).contains("total (1)"), "{}", stdout(&o));
}

#[test]
fn entries_that_cannot_be_read_fail_one_line_each_and_are_missing() {
    let dir = tempfile::tempdir().unwrap();
    let input = inputs(dir.path(), 2);
    std::os::unix::fs::symlink("nowhere.ply", input.join("m7.ply")).unwrap();
    std::fs::create_dir(input.join("m8.ply")).unwrap();
    let bad = input.join("m9.ply");
    std::fs::write(&bad, b"ply\nformat ascii 1.0\nelement vertex 3\n").unwrap();
    let out = dir.path().join("out");
    for _ in 0..2 {
        // Twice: a failure is retried, not forgotten.
        let o = batch(&input, &out, &[]);
        assert_eq!(o.status.code(), Some(1));
        let err = stderr(&o);
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 3, "{err}");
        for (line, name, what) in [
            (
                lines[0],
                "m7.ply",
                "a symbolic link to 'nowhere.ply', which does not exist",
            ),
            (lines[1], "m8.ply", "not a regular file"),
            (lines[2], "m9.ply", ""),
        ] {
            let prefix = format!("vcsmooth: error: {}: ", input.join(name).display());
            assert!(line.starts_with(&prefix) && line.contains(what), "{err}");
        }
        assert!(stdout(&o).contains(" 3 failed"), "{}", stdout(&o));
        let (done, _, _) = verdicts(&stdout(&o));
        assert!(done.len() <= 2);
    }
    assert_eq!(missing(&summary(&out, &input)), ["m7", "m8", "m9"]);
}

#[test]
fn outdir_as_the_input_directory_is_refused_and_a_list_file_works_twice() {
    let dir = tempfile::tempdir().unwrap();
    let input = inputs(dir.path(), 2);
    let before = listing(&input);
    for _ in 0..2 {
        let o = batch(&input, &input, &["--format", "obj"]);
        crate::util::fails(&o, 1, &["OUTDIR is the input directory"]);
        assert_eq!(listing(&input), before);
    }
    // The same files named by a list: the outputs beside the inputs are never read as inputs.
    let list = dir.path().join("list.txt");
    std::fs::write(&list, "in/m0.ply\nin/m1.ply\n").unwrap();
    let (done, _, _) = verdicts(&ok(batch(&list, &input, &["--format", "obj"])));
    assert_eq!(done, ["m0", "m1"]);
    let (done, skipped, _) = verdicts(&ok(batch(&list, &input, &["--format", "obj"])));
    assert_eq!((done.len(), skipped.len()), (0, 2));
    // Its own format there would overwrite the inputs: refused.
    let o = batch(&list, &input, &[]);
    crate::util::fails(&o, 1, &["m0.ply", "would overwrite it"]);
}

#[test]
fn the_summary_is_never_written_over_a_file_of_the_batch() {
    let dir = tempfile::tempdir().unwrap();
    let input = inputs(dir.path(), 2);
    let out = dir.path().join("out");
    ok(batch(&input, &out, &[]));
    let list = dir.path().join("list.txt");
    std::fs::write(&list, "in/m0.ply\nin/m1.ply\n").unwrap();
    let targets = [
        (input.join("m0.ply"), "is an input"),
        (out.join("m1.ply"), "is an output"),
        (out.join("m1.obj"), "is an output"), // one that a later run with --format obj would write
        (out.join(".done/m0.json"), "is a marker"),
        (list.clone(), "is the input list"),
    ];
    for (target, what) in &targets {
        let before = std::fs::read(target).ok();
        for inputs in [Some(&list), None] {
            if inputs.is_none() && target.extension().is_some_and(|e| e == "obj" || e == "txt") {
                continue; // without the list, only what the markers name is known
            }
            let mut args = vec![
                "batch".to_string(),
                "--summary".into(),
                out.display().to_string(),
                "--json".into(),
                target.display().to_string(),
            ];
            if let Some(l) = inputs {
                args.extend(["--inputs".into(), l.display().to_string()]);
            }
            let o = vcsmooth(&args);
            crate::util::fails(&o, 1, &[what, "the summary would overwrite it"]);
            assert_eq!(std::fs::read(target).ok(), before, "{}", target.display());
        }
    }
    // A relative path through a symbolic link to an input is the same file.
    std::os::unix::fs::symlink(&input, dir.path().join("alias")).unwrap();
    let o = crate::util::command()
        .current_dir(dir.path())
        .args(["batch", "--summary", "out", "--json", "alias/m1.ply"])
        .output()
        .unwrap();
    crate::util::fails(&o, 1, &["is an input"]);
}

#[test]
fn summary_flags_without_summary_are_refused_not_ignored() {
    let dir = tempfile::tempdir().unwrap();
    let input = inputs(dir.path(), 1);
    let out = dir.path().join("out");
    let json = dir.path().join("s.json");
    for extra in [
        vec!["--json", json.to_str().unwrap()],
        vec!["--inputs", input.to_str().unwrap()],
    ] {
        let o = batch(&input, &out, &extra);
        crate::util::fails(&o, 2, &["go with --summary"]);
        assert!(!out.exists() && !json.exists(), "{extra:?} did work");
    }
}
