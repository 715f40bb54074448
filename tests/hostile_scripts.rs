//! Hostile use of what vcsmooth writes around a run: the Slurm script it prints, the side files
//! and outputs it writes through links and devices, the checkpoint directory, and option
//! combinations no run could make.
//!
//! - every piece of text of `slurm-script` that comes from a path or a flag is quoted (shell
//!   words) or escaped (comments), so that no file name (newline, CR, `$()`, backticks, quotes,
//!   `#`, non-UTF-8 bytes) runs as code; the scripts run with a fake `sbatch` and do the batch;
//! - a file written through a symbolic link lands in the link's target and the link stays; one
//!   that leads to a device, a pipe or this process's standard output is written through as a
//!   stream;
//! - `--checkpoint` may not be, nor lie inside, any file of the run, nor hold one;
//! - an inconsistent combination of smoothing options is the same usage error, the same line,
//!   for every command, before any work.

use std::ffi::{OsStr, OsString};
use std::os::unix::ffi::{OsStrExt, OsStringExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use crate::util::{BIN, command, failed_with, fails, generate_sphere, json, ok, stderr, vcsmooth};

/// A directory with a small noisy sphere `s.ply` and a folder `in/` of two of them.
fn fixture() -> (tempfile::TempDir, PathBuf, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s.ply");
    generate_sphere(&s, 1, Some(0.2), Some(3));
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).unwrap();
    std::fs::copy(&s, inputs.join("a.ply")).unwrap();
    std::fs::copy(&s, inputs.join("b.ply")).unwrap();
    (dir, s, inputs)
}

/// `vcsmooth ARGS` with each argument an `OsStr` (paths as they are).
fn run(args: &[&OsStr]) -> Output {
    vcsmooth(args)
}

// ---------------------------------------------------------------------------------------------
// Options no run could make

#[test]
fn inconsistent_options_are_one_usage_line_for_every_command() {
    let (dir, s, inputs) = fixture();
    let d = dir.path();
    let out = d.join("o.ply");
    let outdir = d.join("out");
    let plot = d.join("p.svg");
    let plot_text = plot.display().to_string();
    let report = d.join("r.json").display().to_string();
    for method in ["laplacian", "taubin", "hc"] {
        let bad = ["--method", method, "--boundary", "smooth"];
        let with = |head: &[&OsStr], tail: &[&str]| {
            let mut args: Vec<OsString> = head.iter().map(|a| a.to_os_string()).collect();
            args.extend(tail.iter().map(OsString::from));
            vcsmooth(&args)
        };
        // smooth says it; every other command must say exactly the same.
        let reference = with(&["smooth".as_ref(), s.as_os_str(), out.as_os_str()], &bad);
        fails(&reference, 2, &["--boundary smooth", method]);
        let line = stderr(&reference);
        let line = line.trim_end().strip_prefix("vcsmooth: error: ").unwrap();
        let mut runs: Vec<(String, Output)> = Vec::new();
        let smooth = ["smooth".as_ref(), s.as_os_str(), out.as_os_str()];
        for extra in [
            &["--multires"][..],
            &["--multires", "--levels", "3"],
            &["--iterations", "auto"],
            &["--report", &report, "--plot", &plot_text],
        ] {
            let mut tail: Vec<&str> = extra.to_vec();
            tail.extend(bad);
            runs.push((format!("smooth {extra:?}"), with(&smooth, &tail)));
        }
        let batch = ["batch".as_ref(), inputs.as_os_str(), outdir.as_os_str()];
        runs.push(("batch".into(), with(&batch, &bad)));
        let mut tail = vec!["--task-index", "1", "--task-count", "2"];
        tail.extend(bad);
        runs.push(("batch share".into(), with(&batch, &tail)));
        let slurm = [
            "slurm-script".as_ref(),
            inputs.as_os_str(),
            outdir.as_os_str(),
        ];
        runs.push(("slurm-script".into(), with(&slurm, &bad)));
        let curves = [
            "curves".as_ref(),
            s.as_os_str(),
            "--plot".as_ref(),
            plot.as_os_str(),
        ];
        let methods = format!("vcs,{method}");
        let tail = ["--methods", &methods, "--boundary", "smooth"];
        runs.push(("curves".into(), with(&curves, &tail)));
        for (what, o) in &runs {
            failed_with(o, line).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(o.status.code(), Some(2), "{what}");
            assert!(
                o.stdout.is_empty(),
                "{what}: {}",
                String::from_utf8_lossy(&o.stdout)
            );
        }
        for p in [&out, &outdir, &plot, &d.join("r.json")] {
            assert!(!p.exists(), "{} written", p.display());
        }
    }
    // A consistent combination still runs everywhere it did.
    let o = vcsmooth([
        "smooth".as_ref(),
        s.as_os_str(),
        out.as_os_str(),
        "--method".as_ref(),
        "vcs".as_ref(),
        "--boundary".as_ref(),
        "smooth".as_ref(),
        "--iterations".as_ref(),
        "1".as_ref(),
    ]);
    ok(o);
    let o = vcsmooth([
        "curves".as_ref(),
        s.as_os_str(),
        "--plot".as_ref(),
        plot.as_os_str(),
        "--methods".as_ref(),
        "vcs,lem".as_ref(),
        "--boundary".as_ref(),
        "smooth".as_ref(),
        "--iterations".as_ref(),
        "1".as_ref(),
    ]);
    ok(o);
}

// ---------------------------------------------------------------------------------------------
// The checkpoint directory

#[test]
fn checkpoint_directory_never_takes_a_file_place_nor_holds_one() {
    let (dir, s, _) = fixture();
    let d = dir.path();
    let before = std::fs::read(&s).unwrap();
    let smooth = |out: &Path, extra: &[&OsStr]| {
        let mut args: Vec<&OsStr> = vec!["smooth".as_ref(), s.as_os_str(), out.as_os_str()];
        args.extend_from_slice(&["--iterations".as_ref(), "1".as_ref()]);
        args.extend_from_slice(extra);
        run(&args)
    };
    let out = d.join("o.ply");
    let sub = d.join("sub");
    std::fs::create_dir(&sub).unwrap();
    let spelled = sub.join("..").join("o.ply");
    let link = d.join("link.ply");
    std::os::unix::fs::symlink(&s, &link).unwrap();
    let cases: Vec<(PathBuf, Vec<OsString>, &str)> = vec![
        (
            out.clone(),
            vec![],
            "--checkpoint names the same path as OUT",
        ),
        (spelled, vec![], "--checkpoint names the same path as OUT"),
        (out.join("work"), vec![], "--checkpoint is inside OUT"),
        (
            out.join("a").join("b"),
            vec![],
            "--checkpoint is inside OUT",
        ),
        (s.clone(), vec![], "--checkpoint names the same path as IN"),
        (
            link.clone(),
            vec![],
            "--checkpoint names the same path as IN",
        ),
        (s.join("w"), vec![], "--checkpoint is inside IN"),
        (
            d.join("r.json"),
            vec!["--report".into(), d.join("r.json").into()],
            "--checkpoint names the same path as --report",
        ),
        (
            d.join("p.svg").join("w"),
            vec!["--plot".into(), d.join("p.svg").into()],
            "--checkpoint is inside --plot",
        ),
    ];
    for (ck, extra, says) in &cases {
        let mut args: Vec<&OsStr> = vec!["--checkpoint".as_ref(), ck.as_os_str()];
        args.extend(extra.iter().map(|a| a.as_os_str()));
        let o = smooth(&out, &args);
        fails(&o, 2, &[says, "the work directory would take its place"]);
        assert!(!out.exists(), "{}: output written", ck.display());
        assert!(!d.join("r.json").exists() && !d.join("p.svg").exists());
    }
    assert_eq!(std::fs::read(&s).unwrap(), before);
    assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());

    // A file where the directory or a folder above it would be.
    let file = d.join("f.txt");
    std::fs::write(&file, b"keep").unwrap();
    let o = smooth(&out, &["--checkpoint".as_ref(), file.as_os_str()]);
    fails(&o, 2, &["--checkpoint exists and is not a directory"]);
    let o = smooth(&out, &["--checkpoint".as_ref(), file.join("w").as_os_str()]);
    fails(
        &o,
        2,
        &["--checkpoint cannot be made", "is not a directory"],
    );
    assert_eq!(std::fs::read(&file).unwrap(), b"keep");

    // A side file that is one of the files the run keeps in the directory.
    let ck = d.join("ck");
    ok(smooth(&out, &["--checkpoint".as_ref(), ck.as_os_str()]));
    let state = std::fs::read(ck.join("state.json")).unwrap();
    for (flag, name) in [("--report", "state.json"), ("--report", "plan.json")] {
        for side in [ck.join(name), sub.join("..").join("ck").join(name)] {
            let o = smooth(
                &out,
                &[
                    "--checkpoint".as_ref(),
                    ck.as_os_str(),
                    flag.as_ref(),
                    side.as_os_str(),
                ],
            );
            fails(&o, 2, &["names a file of the --checkpoint directory"]);
        }
    }
    assert_eq!(std::fs::read(ck.join("state.json")).unwrap(), state);
    // Any other file in it is the user's to choose.
    let report = ck.join("mine.json");
    ok(smooth(
        &out,
        &[
            "--checkpoint".as_ref(),
            ck.as_os_str(),
            "--report".as_ref(),
            report.as_os_str(),
        ],
    ));
    json(&std::fs::read_to_string(&report).unwrap());
}

// ---------------------------------------------------------------------------------------------
// Files written through links, devices and descriptors

/// The first JSON value of `bytes` and the text after it.
fn json_then_text(bytes: &[u8]) -> (serde_json::Value, String) {
    let mut values = serde_json::Deserializer::from_slice(bytes).into_iter::<serde_json::Value>();
    let value = values
        .next()
        .unwrap_or_else(|| panic!("no JSON in {:?}", String::from_utf8_lossy(bytes)))
        .unwrap();
    let rest = String::from_utf8_lossy(&bytes[values.byte_offset()..]).into_owned();
    (value, rest)
}

fn is_link(p: &Path) -> bool {
    std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_symlink())
}

#[test]
fn side_files_through_links_land_in_the_target_and_keep_the_link() {
    let (dir, s, inputs) = fixture();
    let d = dir.path();
    let elsewhere = d.join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    let links = d.join("links");
    std::fs::create_dir(&links).unwrap();
    std::fs::write(elsewhere.join("r.json"), b"old").unwrap();
    // An absolute link, a relative one, a chain, and one whose target does not exist yet.
    let report = links.join("r.json");
    std::os::unix::fs::symlink(elsewhere.join("r.json"), &report).unwrap();
    let plot = links.join("p.svg");
    std::os::unix::fs::symlink("../elsewhere/p.svg", &plot).unwrap();
    let chained = links.join("chain.json");
    std::os::unix::fs::symlink("r.json", &chained).unwrap();
    let out = d.join("o.ply");
    let o = run(&[
        "smooth".as_ref(),
        s.as_os_str(),
        out.as_os_str(),
        "--iterations".as_ref(),
        "2".as_ref(),
        "--report".as_ref(),
        report.as_os_str(),
        "--plot".as_ref(),
        plot.as_os_str(),
    ]);
    ok(o);
    assert!(is_link(&report) && is_link(&plot));
    let doc = json(&std::fs::read_to_string(elsewhere.join("r.json")).unwrap());
    assert_eq!(doc["command"], "smooth");
    let svg = std::fs::read_to_string(elsewhere.join("p.svg")).unwrap();
    assert!(svg.contains("<svg"), "{svg}");
    // Only the links where they were, no temporary file beside them or their targets.
    let names = |p: &Path| crate::util::listing(p);
    assert_eq!(names(&links), ["chain.json", "p.svg", "r.json"]);
    assert_eq!(names(&elsewhere), ["p.svg", "r.json"]);

    // The main output through a link: the target is smoothed in place, the link stays.
    let target = elsewhere.join("mesh.ply");
    std::fs::copy(&s, &target).unwrap();
    let link = links.join("mesh.ply");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let before = std::fs::read(&target).unwrap();
    ok(run(&[
        "smooth".as_ref(),
        link.as_os_str(),
        link.as_os_str(),
        "--iterations".as_ref(),
        "2".as_ref(),
    ]));
    assert!(is_link(&link));
    assert_ne!(std::fs::read(&target).unwrap(), before);
    assert_eq!(
        std::fs::read(&target).unwrap(),
        std::fs::read(&out).unwrap()
    );

    // batch --summary --json through a chain of links.
    let outdir = d.join("out");
    ok(run(&[
        "batch".as_ref(),
        inputs.as_os_str(),
        outdir.as_os_str(),
        "--iterations".as_ref(),
        "1".as_ref(),
    ]));
    ok(run(&[
        "batch".as_ref(),
        "--summary".as_ref(),
        outdir.as_os_str(),
        "--json".as_ref(),
        chained.as_os_str(),
    ]));
    assert!(is_link(&chained) && is_link(&report));
    let summary = json(&std::fs::read_to_string(elsewhere.join("r.json")).unwrap());
    assert_eq!(
        summary["meshes"].as_array().map(Vec::len),
        Some(2),
        "{summary}"
    );
}

#[test]
fn side_files_through_devices_and_stdout_are_streams() {
    let (dir, s, inputs) = fixture();
    let d = dir.path();
    let out = d.join("o.ply");
    // Links of our own: a regression replaces them, never the system's /dev/stdout.
    let stdout_link = d.join("stdout.json");
    std::os::unix::fs::symlink("/dev/stdout", &stdout_link).unwrap();
    let fd_link = d.join("fd1.json");
    std::os::unix::fs::symlink("/proc/self/fd/1", &fd_link).unwrap();
    let null_link = d.join("null.json");
    std::os::unix::fs::symlink("/dev/null", &null_link).unwrap();
    let smooth = |report: &Path| {
        let mut cmd = command();
        cmd.args([
            "smooth".as_ref(),
            s.as_os_str(),
            out.as_os_str(),
            "--iterations".as_ref(),
            "2".as_ref(),
            "--report".as_ref(),
            report.as_os_str(),
        ]);
        cmd
    };
    // stdout a pipe: the report, then the table.
    for link in [&stdout_link, &fd_link] {
        let o = smooth(link).output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let (doc, rest) = json_then_text(&o.stdout);
        assert_eq!(doc["command"], "smooth", "{doc}");
        assert!(rest.contains(" -> ") && rest.contains("seconds:"), "{rest}");
        assert!(is_link(link));
    }
    // stdout a file: the same, in the file, the table after the report (not over it).
    let captured = d.join("captured.txt");
    let file = std::fs::File::create(&captured).unwrap();
    let o = smooth(&stdout_link).stdout(file).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let (doc, rest) = json_then_text(&std::fs::read(&captured).unwrap());
    assert_eq!(doc["command"], "smooth");
    assert!(rest.contains("seconds:"), "{rest}");
    assert!(is_link(&stdout_link));
    // A character device.
    ok(smooth(&null_link).output().unwrap());
    assert!(is_link(&null_link));
    // batch --summary --json to stdout through a link: JSON, then the table.
    let outdir = d.join("out");
    ok(run(&[
        "batch".as_ref(),
        inputs.as_os_str(),
        outdir.as_os_str(),
        "--iterations".as_ref(),
        "1".as_ref(),
    ]));
    let o = run(&[
        "batch".as_ref(),
        "--summary".as_ref(),
        outdir.as_os_str(),
        "--json".as_ref(),
        stdout_link.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (doc, rest) = json_then_text(&o.stdout);
    assert_eq!(doc["meshes"].as_array().map(Vec::len), Some(2), "{doc}");
    assert!(rest.contains("total (2)"), "{rest}");
    assert!(is_link(&stdout_link));
    // The output mesh itself is replaced by renaming: a device there is refused, link kept.
    let mesh_link = d.join("null.ply");
    std::os::unix::fs::symlink("/dev/null", &mesh_link).unwrap();
    let o = run(&["smooth".as_ref(), s.as_os_str(), mesh_link.as_os_str()]);
    fails(&o, 2, &["is not a regular file"]);
    assert!(is_link(&mesh_link));
    // Links the run cannot follow are one line each, nothing written.
    let looped = d.join("loop.json");
    std::os::unix::fs::symlink("loop.json", &looped).unwrap();
    std::fs::remove_file(&out).unwrap();
    let o = smooth(&looped).output().unwrap();
    fails(&o, 2, &["symbolic links"]);
    assert!(!out.exists());
}

// ---------------------------------------------------------------------------------------------
// The Slurm script

/// Names that would run code or break lines if a script took them as text: the issue's, and one
/// with every shell metacharacter, a CR, a here-document's end marker and bytes that are not
/// UTF-8.
fn hostile_names() -> Vec<OsString> {
    let mut all = b"a'b\"c $(touch PWNED) `touch PWNED` ;touch PWNED& |x \\ #y\rtouch PWNED\n\
                    VCSMOOTH_EOF\ntouch PWNED\n%z "
        .to_vec();
    all.extend_from_slice(b"\xff\xfe\x1b[2J");
    // One a list file (UTF-8 lines) can name.
    let listable = b"l $(touch PWNED) `touch PWNED` 'q\" #h ;& \\ \x1b".to_vec();
    vec![
        OsString::from("in\ntouch PWNED #"),
        OsString::from_vec(all),
        OsString::from_vec(listable),
    ]
}

/// A folder `bin` in `dir` with a fake `sbatch` that logs its arguments and answers a job id.
fn fake_sbatch(dir: &Path) -> PathBuf {
    let bin = dir.join("bin");
    std::fs::create_dir(&bin).unwrap();
    let log = dir.join("sbatch.log");
    let script = format!(
        "#!/bin/sh\nprintf '%s\\n' \"$*\" >> '{}'\necho 42\n",
        log.display()
    );
    let sbatch = bin.join("sbatch");
    std::fs::write(&sbatch, script).unwrap();
    let mut perms = std::fs::metadata(&sbatch).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
    std::fs::set_permissions(&sbatch, perms).unwrap();
    bin
}

/// Runs `bash SCRIPT ARGS` in `cwd` with `bin` first on PATH and `env` set.
fn bash(script: &Path, cwd: &Path, bin: &Path, env: &[(&str, &str)]) -> Output {
    let path = std::env::var_os("PATH").unwrap_or_default();
    let mut paths = vec![bin.to_path_buf()];
    paths.extend(std::env::split_paths(&path));
    let mut cmd = Command::new("bash");
    cmd.arg(script)
        .current_dir(cwd)
        .env("PATH", std::env::join_paths(paths).unwrap())
        .stdin(Stdio::null());
    for v in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_MAX",
    ] {
        cmd.env_remove(v);
    }
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().unwrap()
}

/// Every file named PWNED under `dir`.
fn pwned(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if e.file_name() == "PWNED" {
                found.push(p.clone());
            }
            if e.file_type().unwrap().is_dir() {
                todo.push(p);
            }
        }
    }
    found
}

#[test]
fn slurm_script_runs_no_text_of_a_file_name_and_its_jobs_do_the_batch() {
    for (k, name) in hostile_names().into_iter().enumerate() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let cwd = d.join("cwd");
        std::fs::create_dir(&cwd).unwrap();
        let bin = fake_sbatch(d);
        // The input folder, the meshes in it and the executable's folder all carry the name.
        let inputs = d.join(&name);
        std::fs::create_dir(&inputs).unwrap();
        let mut mesh = name.clone();
        mesh.push(".ply");
        let mesh = OsString::from_vec(
            mesh.into_vec()
                .into_iter()
                .map(|b| if b == b'/' { b'_' } else { b })
                .collect(),
        );
        generate_sphere(&d.join("m.ply"), 1, Some(0.2), Some(1));
        std::fs::rename(d.join("m.ply"), inputs.join(&mesh)).unwrap();
        generate_sphere(&d.join("plain.ply"), 0, Some(0.1), Some(2));
        std::fs::rename(d.join("plain.ply"), inputs.join("plain.ply")).unwrap();
        let exe_dir = d.join(&name).join("bin");
        std::fs::create_dir(&exe_dir).unwrap();
        let exe = exe_dir.join("vcsmooth");
        std::os::unix::fs::symlink(BIN, &exe).unwrap();
        let outdir = d.join("out");
        for list_mode in [false, true] {
            let source = if list_mode {
                // A list file whose own name is hostile, naming the meshes.
                let mut list_name = name.clone();
                list_name.push(".txt");
                let list = d.join(list_name);
                let mut text = inputs.join(&mesh).into_os_string().into_vec();
                text.push(b'\n');
                // A list is UTF-8 lines: names with a line break or other bytes have none.
                if text[..text.len() - 1].contains(&b'\n') || std::str::from_utf8(&text).is_err() {
                    continue;
                }
                std::fs::write(&list, text).unwrap();
                list
            } else {
                inputs.clone()
            };
            let o = run(&[
                "slurm-script".as_ref(),
                source.as_os_str(),
                outdir.as_os_str(),
                "--iterations".as_ref(),
                "2".as_ref(),
                "--vcsmooth".as_ref(),
                exe.as_os_str(),
                "--max-array-size".as_ref(),
                "2".as_ref(),
            ]);
            assert!(o.status.success(), "{k}: {}", stderr(&o));
            let script = d.join("submit.sh");
            std::fs::write(&script, &o.stdout).unwrap();
            let text = String::from_utf8(o.stdout.clone()).expect("the script is UTF-8");
            assert!(
                !text.contains("\ntouch") && !text.contains('\r') && !text.contains('\u{1b}'),
                "{k}: a name's line break or control character reached the script:\n{text}"
            );
            let syntax = Command::new("bash")
                .arg("-n")
                .arg(&script)
                .output()
                .unwrap();
            assert!(syntax.status.success(), "{k}: {}", stderr(&syntax));

            let submitted = bash(&script, &cwd, &bin, &[]);
            assert!(submitted.status.success(), "{k}: {}", stderr(&submitted));
            assert!(
                String::from_utf8_lossy(&submitted.stdout).contains("array job 42, summary job 42")
            );
            assert_eq!(pwned(d), Vec::<PathBuf>::new(), "{k}: injected code ran");
            let log = std::fs::read_to_string(d.join("sbatch.log")).unwrap();
            assert!(
                log.contains("array.sbatch") && log.contains("summary.sbatch"),
                "{log}"
            );

            // The jobs, run as Slurm would (one task each), smooth every input and gather them.
            let jobs = outdir.join(".slurm");
            let tasks: &[&str] = if list_mode { &["0"] } else { &["0", "1"] };
            for task in tasks {
                let o = bash(
                    &jobs.join("array.sbatch"),
                    &cwd,
                    &bin,
                    &[("SLURM_ARRAY_TASK_ID", task)],
                );
                assert!(o.status.success(), "{k} task {task}: {}", stderr(&o));
            }
            let o = bash(&jobs.join("summary.sbatch"), &cwd, &bin, &[]);
            assert!(o.status.success(), "{k} summary: {}", stderr(&o));
            let summary = json(&std::fs::read_to_string(outdir.join("summary.json")).unwrap());
            let expected = if list_mode { 1 } else { 2 };
            assert_eq!(
                summary["meshes"].as_array().map(Vec::len),
                Some(expected),
                "{summary}"
            );
            // batch names outputs by the input's stem, lossily: count them.
            let outputs = crate::util::listing(&outdir)
                .into_iter()
                .filter(|f| f.ends_with(".ply"))
                .count();
            assert_eq!(
                outputs,
                expected,
                "{k}: {:?}",
                crate::util::listing(&outdir)
            );
            assert_eq!(pwned(d), Vec::<PathBuf>::new(), "{k}: injected code ran");
            std::fs::remove_dir_all(&outdir).unwrap();
        }
    }
}

#[test]
fn slurm_script_flags_reach_batch_as_their_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bin = fake_sbatch(d);
    let inputs = d.join("in");
    std::fs::create_dir(&inputs).unwrap();
    generate_sphere(&inputs.join("a.ply"), 0, None, None);
    // A fake vcsmooth that records its arguments, NUL-separated.
    let args_file = d.join("args");
    let fake = d.join("fake-vcsmooth");
    std::fs::write(
        &fake,
        format!(
            "#!/bin/sh\nprintf '%s\\0' \"$@\" > '{}'\n",
            args_file.display()
        ),
    )
    .unwrap();
    let mut perms = std::fs::metadata(&fake).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
    std::fs::set_permissions(&fake, perms).unwrap();
    for name in hostile_names() {
        let scratch = d.join(&name);
        std::fs::create_dir_all(&scratch).unwrap();
        let property = OsString::from_vec(
            name.as_bytes()
                .iter()
                .copied()
                .filter(|&b| b < 0x80)
                .collect(),
        );
        let outdir = d.join("out");
        let o = run(&[
            "slurm-script".as_ref(),
            inputs.as_os_str(),
            outdir.as_os_str(),
            "--vcsmooth".as_ref(),
            fake.as_os_str(),
            "--scratch".as_ref(),
            scratch.as_os_str(),
            "--pin-property".as_ref(),
            property.as_os_str(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let script = d.join("submit.sh");
        std::fs::write(&script, &o.stdout).unwrap();
        assert!(bash(&script, d, &bin, &[]).status.success());
        assert_eq!(pwned(d), Vec::<PathBuf>::new(), "injected code ran");
        let jobs = outdir.join(".slurm");
        let o = bash(
            &jobs.join("array.sbatch"),
            d,
            &bin,
            &[("SLURM_ARRAY_TASK_ID", "0")],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let recorded = std::fs::read(&args_file).unwrap();
        let args: Vec<&[u8]> = recorded.split(|&b| b == 0).collect();
        let after = |flag: &str| {
            let i = args.iter().position(|a| *a == flag.as_bytes()).unwrap();
            args[i + 1]
        };
        assert_eq!(args[0], b"batch");
        assert_eq!(args[1], inputs.as_os_str().as_bytes());
        assert_eq!(args[2], outdir.as_os_str().as_bytes());
        assert_eq!(after("--scratch"), scratch.as_os_str().as_bytes());
        assert_eq!(after("--pin-property"), property.as_bytes());
        assert_eq!(after("--task-index"), b"0");
        std::fs::remove_dir_all(&outdir).unwrap();
        std::fs::remove_file(&args_file).unwrap();
    }
}

#[test]
fn slurm_script_refuses_what_sbatch_would_read_otherwise() {
    let (dir, _, inputs) = fixture();
    let d = dir.path();
    let outdir = d.join("out");
    let script = |extra: &[&OsStr], outdir: &Path| {
        let mut args: Vec<&OsStr> = vec![
            "slurm-script".as_ref(),
            inputs.as_os_str(),
            outdir.as_os_str(),
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    for (flag, value) in [
        ("--partition", "debug#x"),
        ("--partition", "a\\b"),
        ("--time", "1:00\n#SBATCH --x"),
        ("--job-name", "a\u{1b}b"),
        ("--job-name", "it's"),
        ("--job-name", ""),
    ] {
        let o = script(&[flag.as_ref(), value.as_ref()], &outdir);
        fails(&o, 2, &[flag, "must be one word"]);
        assert!(o.stdout.is_empty());
        assert!(
            !stderr(&o).contains('\u{1b}'),
            "a control character printed raw"
        );
    }
    for bad in ["o#ut", "o\\ut", "o%ut", "o ut", "o\nut"] {
        let o = script(&[], &d.join(bad));
        fails(&o, 1, &["OUTDIR must be UTF-8 without whitespace"]);
        assert!(o.stdout.is_empty());
    }
    let o = script(&[], &d.join(OsStr::from_bytes(b"o\xffut")));
    fails(&o, 1, &["OUTDIR must be UTF-8"]);
}
