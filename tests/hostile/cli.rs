//! Hostile command lines: paths that would destroy a file, output locations that cannot
//! be written, undefined quantities, out-of-range values.
//!
//! - no side file (report, plot) may name an input, the output or another side file, however it
//!   is spelled (`./a/../x`, a symbolic or hard link): one line naming the flag, nothing written;
//! - an output that cannot be written is refused before the input is even read (a missing input
//!   then goes unnoticed: the error names the output);
//! - `compare` and `info` print `undefined` (JSON `null`) for what a mesh does not define, and
//!   never NaN, inf or −0;
//! - every numeric flag is checked against its range at once, the message naming flag and range;
//! - `tools/compare_peers.py --workdir` creates a missing directory.

use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::util::{fails, generate_sphere, json, listing, ok, stdout, vcsmooth};

/// Runs `vcsmooth` with `args`, the paths given as they are.
fn run(args: &[&dyn AsRef<std::ffi::OsStr>]) -> Output {
    vcsmooth(args.iter().map(|a| a.as_ref()))
}

/// A directory with a noisy sphere `scan.ply` in it.
fn scan_dir() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("scan.ply");
    generate_sphere(&scan, 2, Some(0.2), None);
    (dir, scan)
}

#[test]
fn side_files_never_replace_an_input_the_output_or_each_other() {
    let (dir, scan) = scan_dir();
    let d = dir.path();
    let before = std::fs::read(&scan).unwrap();
    std::fs::create_dir(d.join("a")).unwrap();
    std::os::unix::fs::symlink(&scan, d.join("link.ply")).unwrap();
    std::fs::hard_link(&scan, d.join("hard.ply")).unwrap();
    std::fs::hard_link(&scan, d.join("hard.svg")).unwrap();
    let out = d.join("out.ply");
    let s = |p: &str| d.join(p).display().to_string();
    let smooth = |extra: &[String]| {
        let mut args = vec!["smooth".to_string(), s("scan.ply"), s("out.ply")];
        args.extend_from_slice(extra);
        vcsmooth(&args)
    };
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec!["--report".into(), s("scan.ply")], "--report"),
        (vec!["--report".into(), s("out.ply")], "--report"),
        (vec!["--report".into(), s("a/../scan.ply")], "--report"),
        (vec!["--report".into(), s("hard.ply")], "--report"),
        (vec!["--report".into(), s("link.ply")], "--report"),
        (vec!["--plot".into(), s("hard.svg")], "--plot"),
        (
            vec![
                "--report".into(),
                s("r.svg"),
                "--plot".into(),
                s("a/../r.svg"),
            ],
            "--plot",
        ),
    ];
    for (extra, flag) in &cases {
        let o = smooth(extra);
        fails(&o, 2, &[flag, "names the same file"]);
        assert!(!out.exists(), "{extra:?} wrote the output");
        assert!(!d.join("r.svg").exists(), "{extra:?} wrote a side file");
    }
    // The output may be the input, spelled otherwise or linked: a hard link is a name of its
    // own, replaced atomically (the input keeps its bytes); a symbolic link is followed (below).
    ok(vcsmooth([
        "smooth".to_string(),
        s("scan.ply"),
        s("hard.ply"),
    ]));
    assert_eq!(
        std::fs::read(&scan).unwrap(),
        before,
        "hard.ply changed the input"
    );
    fails(
        &run(&[&"curves", &scan, &"--plot", &d.join("hard.svg")]),
        2,
        &["--plot names the same file as IN"],
    );
    ok(run(&[
        &"generate",
        &"mesh",
        &d.join("hard.ply"),
        &"--from",
        &scan,
        &"--subdivide",
        &"1",
    ]));
    assert_eq!(std::fs::read(&scan).unwrap(), before, "the input changed");
    assert_eq!(
        listing(d),
        ["a", "hard.ply", "hard.svg", "link.ply", "scan.ply"]
    );

    // Distinct side files are written, and the check leaves nothing behind.
    ok(smooth(&[
        "--report".into(),
        s("a/r.json"),
        "--plot".into(),
        s("a/r.svg"),
    ]));
    assert_eq!(listing(&d.join("a")), ["r.json", "r.svg"]);
    assert!(out.is_file());

    // Through a symbolic link to the input, the input itself is smoothed in place, atomically,
    // and the link stays a link.
    ok(vcsmooth([
        "smooth".to_string(),
        s("scan.ply"),
        s("link.ply"),
    ]));
    assert!(d.join("link.ply").is_symlink(), "link.ply replaced");
    assert_ne!(
        std::fs::read(&scan).unwrap(),
        before,
        "the input not smoothed"
    );
    assert_eq!(std::fs::read(&scan).unwrap(), std::fs::read(&out).unwrap());
}

#[test]
fn output_locations_are_checked_before_the_input_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The input does not exist: an error about the output proves it was checked first.
    let missing = d.join("missing.ply");
    std::fs::create_dir(d.join("x.ply")).unwrap();
    std::fs::create_dir(d.join("x.svg")).unwrap();
    std::fs::write(d.join("file"), b"not a directory").unwrap();
    let mut bad: Vec<(std::path::PathBuf, &str)> = vec![
        (d.join("nowhere/out.ply"), "does not exist"),
        (d.join("x.ply"), "is a directory"),
        (d.join("file/out.ply"), "is not a directory"),
    ];
    if Path::new("/proc/self").is_dir() {
        // A file system where nobody, root included, creates files.
        bad.push(("/proc/out.ply".into(), "cannot create files in '/proc'"));
    }
    let ro = d.join("ro");
    std::fs::create_dir(&ro).unwrap();
    let mut perms = std::fs::metadata(&ro).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o555);
    std::fs::set_permissions(&ro, perms).unwrap();
    if std::fs::write(ro.join("probe"), b"").is_err() {
        bad.push((ro.join("out.ply"), "Permission denied"));
    } else {
        eprintln!("NOTE: running as root: the read-only directory case was not run");
        std::fs::remove_file(ro.join("probe")).unwrap();
    }
    for (out, problem) in &bad {
        let svg = out.with_extension("svg");
        let runs: Vec<(&str, Output, &Path)> = vec![
            ("smooth", run(&[&"smooth", &missing, out]), out),
            (
                "multires",
                run(&[&"smooth", &missing, out, &"--multires"]),
                out,
            ),
            (
                "report",
                run(&[&"smooth", &missing, &d.join("ok.ply"), &"--report", out]),
                out,
            ),
            (
                "subdivide",
                run(&[&"subdivide", &missing, out, &"--max-edge", &"1"]),
                out,
            ),
            (
                "refine",
                run(&[
                    &"refine",
                    &missing,
                    out,
                    &"--max-edge",
                    &"1",
                    &"--rounds",
                    &"1",
                ]),
                out,
            ),
            (
                "generate",
                run(&[&"generate", &"mesh", out, &"--from", &missing]),
                out,
            ),
            ("curves", run(&[&"curves", &missing, &"--plot", &svg]), &svg),
        ];
        for (what, o, target) in &runs {
            if *what == "smooth" || *what == "generate" {
                // The same class through every command; one message checked in full.
                fails(o, 2, &[&target.display().to_string(), problem]);
            } else if o.status.code() != Some(2)
                || !stdout(o).is_empty()
                || !crate::util::stderr(o).contains(&target.display().to_string())
            {
                panic!(
                    "{what} with {}: {:?} {}",
                    target.display(),
                    o.status,
                    crate::util::stderr(o)
                );
            }
        }
    }
    assert!(!d.join("ok.ply").exists());
    assert_eq!(listing(&ro), Vec::<String>::new());
}

/// Asserts that `text` shows no NaN, infinity or negative zero.
fn no_made_up_numbers(text: &str) {
    for word in text.split(|c: char| c.is_whitespace() || ",:[](){}\"".contains(c)) {
        let lower = word.to_ascii_lowercase();
        assert!(
            !lower.contains("nan") && !lower.contains("inf"),
            "'{word}' in {text}"
        );
        let negative_zero = word
            .strip_prefix('-')
            .is_some_and(|r| !r.is_empty() && r.bytes().all(|b| b"0.e".contains(&b)));
        assert!(!negative_zero, "'{word}' in {text}");
    }
}

#[test]
fn undefined_quantities_read_undefined_and_null() {
    let dir = tempfile::tempdir().unwrap();
    let flat = dir.path().join("flat.obj");
    std::fs::write(&flat, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let point = dir.path().join("point.obj");
    std::fs::write(&point, "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n").unwrap();

    // A flat triangle has no volume: volume ratio and roughness are undefined, the area ratio is 1.
    let c = json(&ok(run(&[&"compare", &flat, &flat, &"--json"])));
    assert!(c["volume_ratio"].is_null(), "{c}");
    assert_eq!(c["area_ratio"].as_f64(), Some(1.0), "{c}");
    let table = ok(run(&[&"compare", &flat, &flat]));
    assert!(table.contains("volume ratio b/a   undefined"), "{table}");
    no_made_up_numbers(&table);

    // Three vertices at one point: no bounding box diagonal, no normal, no area.
    let text = ok(run(&[&"compare", &point, &point, &"--json"]));
    no_made_up_numbers(&text);
    let c = json(&text);
    for key in [
        "rms_relative",
        "max_relative",
        "mean_normal_angle_deg",
        "volume_ratio",
        "area_ratio",
    ] {
        assert!(c[key].is_null(), "{key}: {c}");
    }
    let table = ok(run(&[&"compare", &point, &point]));
    assert!(table.contains("mean normal angle  undefined"), "{table}");
    no_made_up_numbers(&table);

    let i = json(&ok(run(&[&"info", &flat, &"--json"])));
    assert!(i["roughness_deg"].is_null(), "{i}");
    assert!(i["mean_edge_length"].as_f64() > Some(1.0), "{i}");
    let table = ok(run(&[&"info", &flat]));
    assert!(
        table.contains("roughness              undefined"),
        "{table}"
    );
    no_made_up_numbers(&table);

    // refine's volume percentages of a mesh without volume.
    let out = dir.path().join("refined.obj");
    let text = ok(run(&[
        &"refine",
        &flat,
        &out,
        &"--max-edge",
        &"0.5",
        &"--rounds",
        &"1",
    ]));
    assert!(
        text.contains("volume after subdivision undefined"),
        "{text}"
    );
    no_made_up_numbers(&text);
}

/// A noisy `n × n` grid sheet as OBJ text, its coordinate `fixed` (0: x, 2: z) 0 on its border and
/// `lift` inside (0: flat).
fn sheet(n: usize, fixed: usize, lift: f64) -> String {
    let mut text = String::new();
    for j in 0..n {
        for i in 0..n {
            let interior = (1..n - 1).contains(&i) && (1..n - 1).contains(&j);
            let wobble = if interior {
                ((i * 7 + j * 3) % 5) as f64 * 0.05
            } else {
                0.0
            };
            let (u, v) = (i as f64 + wobble, j as f64 - wobble);
            let h = if interior { lift } else { 0.0 };
            let p = if fixed == 0 { [h, u, v] } else { [u, v, h] };
            text += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i + 1;
            let (b, c, d) = (a + 1, a + n, a + n + 1);
            text += &format!("f {a} {b} {d}\nf {a} {d} {c}\n");
        }
    }
    text
}

/// A volume ratio against an input of volume exactly 0 (a flat sheet) is
/// undefined wherever it is shown: the summary and iteration table of `smooth` (one process,
/// `--checkpoint`, `--multires`), its report, `curves`, `batch` and its summary. An open sheet
/// that is not flat has a volume (measured about the centroid): it keeps its numbers.
#[test]
fn a_ratio_against_zero_volume_is_undefined_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, axis) in [("flat-z.obj", 2), ("flat-x.obj", 0)] {
        let input = d.join(name);
        std::fs::write(&input, sheet(7, axis, 0.0)).unwrap();
        for method in ["vcs", "laplacian", "taubin"] {
            for extra in [&[][..], &["--checkpoint", "ck"][..], &["--multires"][..]] {
                if extra == ["--multires"] && method != "vcs" {
                    continue;
                }
                let (out, report) = (d.join("out.obj"), d.join("r.json"));
                let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![
                    &"smooth",
                    &input,
                    &out,
                    &"--iterations",
                    &"3",
                    &"--method",
                    &method,
                    &"--stats",
                    &"every",
                    &"--report",
                    &report,
                ];
                let ck = d.join("ck");
                for e in extra {
                    args.push(if *e == "ck" { &ck } else { e });
                }
                let text = ok(run(&args));
                let what = format!("{name} {method} {extra:?}");
                assert!(
                    text.contains("; volume undefined, area 100.0000 %"),
                    "{what}: {text}"
                );
                assert!(!text.contains("volume 100.000000"), "{what}: {text}");
                assert!(text.contains("    undefined   100.0000"), "{what}: {text}");
                no_made_up_numbers(&text);
                let r = crate::util::read_json(&report);
                assert!(r["summary"]["volume_pct"].is_null(), "{what}: {r}");
                for it in r["iterations"].as_array().unwrap() {
                    assert!(it["volume_pct"].is_null(), "{what}: {it}");
                    assert_eq!(it["volume"].as_f64(), Some(0.0), "{what}: {it}");
                }
            }
        }
    }
    let plot = d.join("c.svg");
    let table = ok(run(&[
        &"curves",
        &d.join("flat-z.obj"),
        &"--iterations",
        &"2",
        &"--plot",
        &plot,
    ]));
    for line in table
        .lines()
        .filter(|l| l.trim_start().starts_with(char::is_numeric))
    {
        assert_eq!(line.matches("undefined").count(), 3, "{table}");
    }
    no_made_up_numbers(&table);

    let (inputs, outdir) = (d.join("in"), d.join("outdir"));
    std::fs::create_dir(&inputs).unwrap();
    std::fs::write(inputs.join("flat.obj"), sheet(7, 2, 0.0)).unwrap();
    std::fs::write(inputs.join("raised.obj"), sheet(7, 2, 5.0)).unwrap();
    let text = ok(run(&[&"batch", &inputs, &outdir, &"--iterations", &"2"]));
    assert!(
        text.contains("flat.ply: 72 triangles, 2 × vcs-lowpass, volume undefined,"),
        "{text}"
    );
    assert!(
        text.contains("raised.ply: 72 triangles, 2 × vcs-lowpass, volume 100.000000 %"),
        "{text}"
    );
    let json_path = d.join("summary.json");
    let summary = ok(run(&[
        &"batch",
        &"--summary",
        &outdir,
        &"--json",
        &json_path,
    ]));
    assert!(
        summary
            .lines()
            .any(|l| l.starts_with("flat ") && l.contains(" undefined ")),
        "{summary}"
    );
    no_made_up_numbers(&summary);
    let s = crate::util::read_json(&json_path);
    let rows = s["meshes"].as_array().unwrap();
    assert!(rows[0]["volume_pct"].is_null(), "{s}");
    // The extremes are over the defined ratios only.
    assert_eq!(s["totals"]["min_volume_pct"], rows[1]["volume_pct"], "{s}");
}

#[test]
fn numeric_flags_are_refused_outside_their_range_at_once() {
    let (dir, scan) = scan_dir();
    let out = dir.path().join("out.ply");
    let s = scan.display().to_string();
    let o = out.display().to_string();
    let smooth = |extra: &[&str]| -> Vec<String> {
        let mut v = vec!["smooth".to_string(), s.clone(), o.clone()];
        v.extend(extra.iter().map(|a| a.to_string()));
        v
    };
    let cases: Vec<(Vec<String>, &[&str])> = vec![
        (smooth(&["--lambda", "-inf"]), &["--lambda", "finite"]),
        (smooth(&["--lambda", "50"]), &["--lambda", "(0, 1]"]),
        (smooth(&["--lambda", "0"]), &["--lambda", "(0, 1]"]),
        (smooth(&["--mu", "0.5"]), &["--mu", "[-1, 0)"]),
        (smooth(&["--mu", "-5"]), &["--mu", "[-1, 0)"]),
        (smooth(&["--mu", "-nan"]), &["--mu", "finite"]),
        (smooth(&["--iterations", "-1"]), &["--iterations", "0..="]),
        (smooth(&["--patch-size", "-3"]), &["--patch-size", "1..="]),
        (
            smooth(&["--threads", "1000000000"]),
            &["--threads", "1..=4096"],
        ),
        (smooth(&["--threads", "-2"]), &["--threads", "1..=4096"]),
        (smooth(&["--memory-budget", "-1"]), &["--memory-budget"]),
        (
            smooth(&["--checkpoint-every", "-1"]),
            &["--checkpoint-every", "1..="],
        ),
        (
            smooth(&["--multires", "--cell-factor", "-inf"]),
            &["--cell-factor", "finite"],
        ),
        (
            smooth(&["--multires", "--coarse-iterations", "-1"]),
            &["--coarse-iterations", "0..="],
        ),
        (
            vec![
                "curves".into(),
                s.clone(),
                "--plot".into(),
                "p.svg".into(),
                "--lambda".into(),
                "2".into(),
            ],
            &["--lambda", "(0, 1]"],
        ),
        (
            [
                "generate",
                "sphere",
                &o,
                "--subdivisions",
                "1",
                "--noise",
                "-1",
            ]
            .map(String::from)
            .to_vec(),
            &["--noise", "at least 0"],
        ),
        (
            ["generate", "sphere", &o, "--subdivisions", "-1"]
                .map(String::from)
                .to_vec(),
            &["--subdivisions"],
        ),
        (
            ["demo", "--noise", "-inf"].map(String::from).to_vec(),
            &["--noise", "finite"],
        ),
        (
            ["refine", &s, &o, "--max-edge", "-inf", "--rounds", "1"]
                .map(String::from)
                .to_vec(),
            &["--max-edge", "finite"],
        ),
        (
            [
                "refine",
                &s,
                &o,
                "--max-edge",
                "1",
                "--rounds",
                "1",
                "--threads",
                "5000",
            ]
            .map(String::from)
            .to_vec(),
            &["--threads", "1..=4096"],
        ),
        (
            ["bench", "--threads", "1,100000"]
                .map(String::from)
                .to_vec(),
            &["--threads", "1..=4096"],
        ),
    ];
    for (args, mentions) in &cases {
        let start = Instant::now();
        let result = vcsmooth(args);
        let took = start.elapsed();
        fails(&result, 2, mentions);
        assert!(took < Duration::from_secs(2), "{args:?} took {took:?}");
        assert!(!out.exists(), "{args:?} wrote the output");
    }
    // Taubin's μ is negative by definition: accepted, as are the ranges' ends.
    ok(vcsmooth(smooth(&[
        "--method",
        "taubin",
        "--lambda",
        "1",
        "--mu",
        "-1",
        "--iterations",
        "2",
        "--threads",
        "4096",
    ])));
    assert!(out.is_file());
}

#[test]
fn compare_peers_creates_its_work_directory() {
    let python = Command::new("python3").arg("--version").output();
    if !python.is_ok_and(|o| o.status.success()) {
        eprintln!("NOTE: no python3: compare_peers.py was not run");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A stand-in numpy module: the script stops with its own error once it needs numpy, after
    // the checks of its arguments.
    std::fs::create_dir(d.join("stub")).unwrap();
    std::fs::write(d.join("stub/numpy.py"), "").unwrap();
    std::fs::write(d.join("file"), "").unwrap();
    let script = crate::util::root().join("tools/compare_peers.py");
    let peers = |workdir: &Path| {
        Command::new("python3")
            .arg(&script)
            .args([
                "--peers",
                "",
                "--methods",
                "vcs",
                "--vcsmooth",
                crate::util::BIN,
            ])
            .arg("--workdir")
            .arg(workdir)
            .env("PYTHONPATH", d.join("stub"))
            .output()
            .unwrap()
    };
    let new = d.join("new/sub");
    let o = peers(&new);
    let err = crate::util::stderr(&o);
    assert!(new.is_dir(), "{err}");
    assert!(!err.contains("FileNotFoundError"), "{err}");

    let o = peers(&d.join("file/sub"));
    let err = crate::util::stderr(&o);
    assert!(!o.status.success());
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("--workdir") && err.contains("cannot create"),
        "{err}"
    );
}
