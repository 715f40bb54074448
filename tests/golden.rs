//! Results are a contract: the output bytes of a fixed set of runs are hashed and compared with
//! `tests/golden/hashes.txt`. A refactor or an optimisation changes none of them. A change that
//! must change a result bumps `vcsmooth::RESULTS_VERSION`, says why in `CHANGELOG.md` and its
//! commit, and re-records the file on purpose: `VCSMOOTH_GOLDEN=record cargo test golden`
//! rewrites it, and refuses to while the results version is the one the hashes were recorded at.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use vcsmooth::{Method, Options};

use crate::util::{
    cluster_settings, engine_settings, generate_sphere, ok, root, run_ranks, scan, vcsmooth,
};

fn hashes_file() -> PathBuf {
    root().join("tests/golden/hashes.txt")
}

/// 64-bit FNV-1a: stable across platforms and Rust versions (std's hasher is not).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// One golden run: `vcsmooth smooth IN OUT ARGS...` (or another command when `command` says so).
struct Run {
    name: &'static str,
    input: PathBuf,
    ext: &'static str,
    args: &'static [&'static str],
}

/// The runs: every method on 1 and 2 threads with many patches, heap and scratch storage,
/// `--reject-energy-increase`, `--stats last`, multires, the output formats, real scans (open,
/// inward-oriented, with unreferenced vertices).
fn runs(sphere: &Path, torus: &Path, big: &Path) -> Vec<Run> {
    let mut runs = Vec::new();
    let methods = [
        "laplacian",
        "taubin",
        "lem",
        "vcs",
        "vcs-triangle",
        "vcs-lowpass",
        "vcs-guided",
    ];
    for (m, t) in methods
        .iter()
        .flat_map(|m| ["1", "2"].into_iter().map(move |t| (*m, t)))
    {
        let args: &'static [&'static str] = Box::leak(
            vec![
                "--method",
                m,
                "--iterations",
                "4",
                "--threads",
                t,
                "--patch-size",
                "300",
            ]
            .into_boxed_slice(),
        );
        runs.push(Run {
            name: Box::leak(format!("sphere4-{m}-t{t}").into_boxed_str()),
            input: sphere.to_path_buf(),
            ext: "ply",
            args,
        });
    }
    let more: [(&'static str, &Path, &'static str, &'static [&'static str]); 24] = [
        (
            "sphere4-vcs-reject",
            sphere,
            "ply",
            &[
                "--method",
                "vcs",
                "--iterations",
                "5",
                "--reject-energy-increase",
                "--patch-size",
                "300",
            ],
        ),
        (
            "sphere4-lem-reject",
            sphere,
            "ply",
            &[
                "--method",
                "lem",
                "--iterations",
                "5",
                "--reject-energy-increase",
            ],
        ),
        (
            "sphere4-vcs-triangle-reject",
            sphere,
            "ply",
            &[
                "--method",
                "vcs-triangle",
                "--iterations",
                "3",
                "--reject-energy-increase",
                "--threads",
                "2",
                "--patch-size",
                "300",
            ],
        ),
        (
            "sphere4-laplacian-stats-last",
            sphere,
            "ply",
            &[
                "--method",
                "laplacian",
                "--iterations",
                "13",
                "--stats",
                "last",
                "--threads",
                "2",
            ],
        ),
        (
            "sphere4-taubin-stats-last",
            sphere,
            "ply",
            &[
                "--method",
                "taubin",
                "--iterations",
                "11",
                "--stats",
                "last",
                "--lambda",
                "0.6",
                "--mu",
                "-0.62",
            ],
        ),
        (
            "sphere4-vcs-stats-last",
            sphere,
            "ply",
            &[
                "--method",
                "vcs",
                "--iterations",
                "3",
                "--stats",
                "last",
                "--threads",
                "2",
                "--patch-size",
                "300",
            ],
        ),
        (
            "torus-vcs-obj",
            torus,
            "obj",
            &["--method", "vcs", "--iterations", "3"],
        ),
        (
            "torus-taubin-off",
            torus,
            "off",
            &["--method", "taubin", "--iterations", "3"],
        ),
        (
            "torus-vcs-stl",
            torus,
            "stl",
            &["--method", "vcs", "--iterations", "2"],
        ),
        ("torus-convert-ply", torus, "ply", &["--iterations", "0"]),
        (
            "bunny-vcs",
            &scan("stanford-bunny.ply"),
            "ply",
            &[
                "--method",
                "vcs",
                "--iterations",
                "3",
                "--threads",
                "2",
                "--patch-size",
                "4096",
            ],
        ),
        (
            "horse-vcs-triangle",
            &scan("horse.ply"),
            "ply",
            &[
                "--method",
                "vcs-triangle",
                "--iterations",
                "2",
                "--threads",
                "2",
                "--patch-size",
                "4096",
            ],
        ),
        (
            "demosthenes-taubin",
            &scan("demosthenes-17k.ply"),
            "ply",
            &["--method", "taubin", "--iterations", "9", "--stats", "last"],
        ),
        (
            "demosthenes-hc-deviation",
            &scan("demosthenes-17k.ply"),
            "ply",
            &[
                "--method",
                "hc",
                "--iterations",
                "7",
                "--max-deviation",
                "0.002",
            ],
        ),
        (
            "armadillo-multires",
            &scan("armadillo-86k.ply"),
            "ply",
            &["--multires", "--iterations", "3", "--threads", "2"],
        ),
        (
            "kitten-multires-3-taubin",
            &scan("kitten-25k.ply"),
            "ply",
            &[
                "--multires",
                "--levels",
                "3",
                "--coarse-iterations",
                "4",
                "--fine-method",
                "taubin",
                "--iterations",
                "2",
                "--transfer",
                "smooth",
            ],
        ),
        (
            "fandisk-vcs-guided",
            &scan("denoising/Fandisk0.3-noisy.ply"),
            "ply",
            &[
                "--method",
                "vcs-guided",
                "--threads",
                "2",
                "--patch-size",
                "2000",
            ],
        ),
        (
            "fertility-vcs-lowpass",
            &scan("fertility-9k.ply"),
            "ply",
            &["--threads", "2"],
        ),
        (
            "twelve-vcs-lowpass-auto",
            &scan("denoising/Twelve0.5Impulsive-noisy.ply"),
            "ply",
            &["--iterations", "auto", "--threads", "2"],
        ),
        (
            "twelve-vcs-guided-auto",
            &scan("denoising/Twelve0.5Impulsive-noisy.ply"),
            "ply",
            &["--method", "vcs-guided", "--iterations", "auto"],
        ),
        (
            "bunny-vcs-lowpass-creases-deviation",
            &scan("stanford-bunny.ply"),
            "ply",
            &[
                "--method",
                "vcs-lowpass",
                "--iterations",
                "3",
                "--threads",
                "2",
                "--patch-size",
                "4096",
                "--crease-angle",
                "40",
                "--max-deviation",
                "0.0005",
            ],
        ),
        (
            "fertility-vcs-deviation",
            &scan("fertility-9k.ply"),
            "ply",
            &[
                "--method",
                "vcs",
                "--iterations",
                "4",
                "--max-deviation",
                "0.3",
                "--patch-size",
                "1000",
            ],
        ),
        (
            "kitten-taubin-creases-deviation",
            &scan("kitten-25k.ply"),
            "ply",
            &[
                "--method",
                "taubin",
                "--iterations",
                "5",
                "--crease-angle",
                "30",
                "--max-deviation",
                "0.05",
            ],
        ),
        (
            "fertility-lem",
            &scan("fertility-9k.ply"),
            "ply",
            &[
                "--method",
                "lem",
                "--iterations",
                "3",
                "--threads",
                "1",
                "--patch-size",
                "1000",
            ],
        ),
    ];
    for (name, input, ext, args) in more {
        runs.push(Run {
            name,
            input: input.to_path_buf(),
            ext,
            args,
        });
    }
    // Scratch storage (memory-mapped arrays): the smallest sphere that exceeds the 64 MiB minimum budget.
    for (name, args) in [
        (
            "sphere8-vcs-scratch",
            &[
                "--method",
                "vcs",
                "--iterations",
                "1",
                "--threads",
                "2",
                "--patch-size",
                "4096",
                "--memory-budget",
                "64M",
            ][..],
        ),
        (
            "sphere8-taubin-scratch",
            &[
                "--method",
                "taubin",
                "--iterations",
                "2",
                "--threads",
                "2",
                "--memory-budget",
                "64M",
            ][..],
        ),
        (
            "sphere8-taubin-heap",
            &["--method", "taubin", "--iterations", "2", "--threads", "1"][..],
        ),
        (
            "sphere8-vcs-heap",
            &[
                "--method",
                "vcs",
                "--iterations",
                "1",
                "--threads",
                "1",
                "--patch-size",
                "4096",
            ][..],
        ),
    ] {
        runs.push(Run {
            name,
            input: big.to_path_buf(),
            ext: "ply",
            args,
        });
    }
    runs
}

/// The line of `hashes.txt` that names the results version the hashes were recorded at.
const VERSION_KEY: &str = "results_version";

fn read_expected() -> BTreeMap<String, String> {
    let text = std::fs::read_to_string(hashes_file()).unwrap_or_default();
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let (name, hash) = l.split_once(' ').expect("`name hash` per line");
            (name.to_string(), hash.trim().to_string())
        })
        .collect()
}

#[test]
fn golden_outputs_are_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    let mut got = BTreeMap::new();
    let mut hash_file = |name: &str, path: &Path| {
        let bytes = std::fs::read(path).unwrap();
        got.insert(name.to_string(), format!("{:016x}", fnv1a(&bytes)));
    };

    // Generated inputs are golden too: `generate` must keep writing the same bytes.
    let (sphere, torus, big) = (p("sphere4.ply"), p("torus.obj"), p("sphere8.ply"));
    generate_sphere(&sphere, 4, Some(0.3), Some(7));
    ok(vcsmooth([
        "generate",
        "torus",
        torus.to_str().unwrap(),
        "--subdivisions",
        "3",
        "--noise",
        "0.2",
        "--seed",
        "3",
    ]));
    generate_sphere(&big, 8, Some(0.3), None);
    let sub = p("kitten-sub.ply");
    ok(vcsmooth([
        "generate",
        "mesh",
        sub.to_str().unwrap(),
        "--from",
        scan("kitten-25k.ply").to_str().unwrap(),
        "--subdivide",
        "1",
        "--noise",
        "0.2",
    ]));
    for (name, path) in [
        ("gen-sphere4", &sphere),
        ("gen-torus-obj", &torus),
        ("gen-sphere8", &big),
        ("gen-kitten-sub1", &sub),
    ] {
        hash_file(name, path);
    }

    for run in runs(&sphere, &torus, &big) {
        let out = p(&format!("{}.{}", run.name, run.ext));
        let mut args: Vec<std::ffi::OsString> = vec![
            "smooth".into(),
            run.input.clone().into(),
            out.clone().into(),
        ];
        args.extend(run.args.iter().map(Into::into));
        ok(vcsmooth(&args));
        hash_file(run.name, &out);
    }

    // A seamed mesh (the sphere split along its equator, as texture seams split files), welded:
    // the default method and vcs, with its seam-free twin's settings.
    let seamed = p("seamed4.ply");
    let one = vcsmooth::io::read_mesh(&sphere).unwrap();
    vcsmooth::io::write_mesh(&seamed, &crate::util::seamed(&one).0).unwrap();
    hash_file("gen-seamed4", &seamed);
    for (name, method) in [
        ("seamed4-vcs-lowpass", "vcs-lowpass"),
        ("seamed4-vcs", "vcs"),
    ] {
        let out = p(&format!("{name}.ply"));
        ok(vcsmooth([
            "smooth",
            seamed.to_str().unwrap(),
            out.to_str().unwrap(),
            "--method",
            method,
            "--iterations",
            "4",
            "--patch-size",
            "300",
        ]));
        hash_file(name, &out);
    }

    // The paper's adaptive refinement: subdivide + vcs rounds.
    let refined = p("fertility-refine.ply");
    ok(vcsmooth([
        "refine",
        scan("fertility-9k.ply").to_str().unwrap(),
        refined.to_str().unwrap(),
        "--max-edge",
        "4",
        "--rounds",
        "2",
        "--iterations",
        "2",
    ]));
    hash_file("fertility-refine", &refined);

    // Thread ranks of the cluster engine (the same code path MPI ranks take).
    for (method, iterations) in [(Method::Vcs, 2), (Method::Taubin, 3)] {
        let name = format!("armadillo-ranks3-{}", method.name());
        let out = p(&format!("{name}.ply"));
        let work = p(&format!("{name}-work"));
        let opts = Options {
            method,
            iterations,
            ..Options::default()
        };
        let input = scan("armadillo-86k.ply");
        let engine = engine_settings(2048, 2);
        let settings = cluster_settings(&work, false, 1);
        for rank in run_ranks(3, &input, &out, &opts, &engine, &settings) {
            rank.unwrap();
        }
        hash_file(&name, &out);
    }

    let mut expected = read_expected();
    let recorded_version = expected.remove(VERSION_KEY);
    let version = vcsmooth::RESULTS_VERSION.to_string();
    if std::env::var("VCSMOOTH_GOLDEN").as_deref() == Ok("record") {
        // A change of results comes with a new results version, never silently.
        let changed: Vec<&String> = got
            .iter()
            .filter(|(name, hash)| expected.get(*name).is_some_and(|e| e != *hash))
            .map(|(name, _)| name)
            .collect();
        assert!(
            changed.is_empty() || recorded_version.as_ref() != Some(&version),
            "these runs change at the recorded results version {version}: {changed:?}; bump \
             vcsmooth::RESULTS_VERSION and say why in CHANGELOG.md before re-recording"
        );
        let mut text = String::from(
            "# Output hashes (64-bit FNV-1a of the file bytes) of the runs in tests/golden.rs.\n# Re-record only on purpose: VCSMOOTH_GOLDEN=record cargo test golden\n",
        );
        text.push_str(&format!("{VERSION_KEY} {version}\n"));
        for (name, hash) in &got {
            text.push_str(&format!("{name} {hash}\n"));
        }
        std::fs::create_dir_all(hashes_file().parent().unwrap()).unwrap();
        std::fs::write(hashes_file(), text).unwrap();
        return;
    }
    // Runs that differ only in what may not change a result give the same bytes.
    let mut same = vec![
        ("sphere8-vcs-heap", "sphere8-vcs-scratch"),
        ("sphere8-taubin-heap", "sphere8-taubin-scratch"),
    ];
    for m in ["laplacian", "taubin", "lem", "vcs", "vcs-triangle"] {
        let pair = (format!("sphere4-{m}-t1"), format!("sphere4-{m}-t2"));
        same.push((
            Box::leak(pair.0.into_boxed_str()),
            Box::leak(pair.1.into_boxed_str()),
        ));
    }
    for (a, b) in same {
        assert_eq!(got[a], got[b], "{a} and {b} differ");
    }

    assert_eq!(
        recorded_version.as_ref(),
        Some(&version),
        "the hashes were recorded at another results version: re-record them"
    );
    let mut wrong = Vec::new();
    for (name, hash) in &got {
        match expected.get(name) {
            Some(e) if e == hash => {}
            Some(e) => wrong.push(format!("{name}: expected {e}, got {hash}")),
            None => wrong.push(format!("{name}: no recorded hash (got {hash})")),
        }
    }
    for name in expected.keys().filter(|n| !got.contains_key(*n)) {
        wrong.push(format!("{name}: recorded but not run"));
    }
    assert!(
        wrong.is_empty(),
        "golden outputs changed:\n{}",
        wrong.join("\n")
    );
}
