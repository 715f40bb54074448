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
