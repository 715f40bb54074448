//! Hostile input and faults, end to end through the `vcsmooth` binary (DESIGN invariants
//! 4 and 5).
//!
//! - `corpus_*`: every file of the generated corpus (`tests/corpus/cases.rs`) through `vcsmooth
//!   smooth IN OUT` and `vcsmooth info IN`: a malformed one exits non-zero with exactly one stderr
//!   line `vcsmooth: error: <IN>: <what>`, no panic text and no output file; a tricky valid one is
//!   smoothed and described.
//! - degenerate, duplicate and non-manifold input is processed, counted, and its affected vertices
//!   stay where they are.
//! - faults: SIGKILL at several moments of a run (mid-write included) leaves the previous output
//!   intact; a full disk (a real 256 KiB tmpfs when it can be mounted, an injected `EFBIG` always)
//!   gives one clear line and no partial output.

mod batch;
mod cli;
mod geometry;
mod memory;
mod readers;
mod signals;

#[path = "corpus/cases.rs"]
mod cases;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use cases::{Case, Expect};
use glam::DVec3;
use vcsmooth::Mesh;

use crate::util::{
    BIN, command, failed_with, generate_sphere, json, listing, noisy_sphere, ok, stderr, vcsmooth,
};

/// Runs one corpus case through `smooth` and `info`; returns what is wrong.
fn run_case(dir: &Path, case: &Case) -> Result<(), String> {
    let sub = dir.join(case.name.replace('.', "_"));
    std::fs::create_dir(&sub).unwrap();
    let input = sub.join(case.name);
    std::fs::write(&input, &case.bytes).unwrap();
    let ext = Path::new(case.name)
        .extension()
        .and_then(|e| e.to_str())
        .filter(|e| ["ply", "obj", "off", "stl"].contains(e))
        .unwrap_or("ply");
    let output = sub.join(format!("smoothed.{ext}"));
    let smooth = vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--iterations".as_ref(),
        "2".as_ref(),
    ]);
    let info = vcsmooth(["info".as_ref(), input.as_os_str(), "--json".as_ref()]);
    match &case.expect {
        Expect::Error(what) => {
            let line = format!("{}: {what}", input.display());
            failed_with(&smooth, &line).map_err(|e| format!("smooth: {e}"))?;
            failed_with(&info, &line).map_err(|e| format!("info: {e}"))?;
            if output.exists() || listing(&sub).len() != 1 {
                return Err(format!("files left: {:?}", listing(&sub)));
            }
        }
        Expect::Valid => {
            for (what, out) in [("smooth", &smooth), ("info", &info)] {
                // A note (what a conversion drops) informs; anything else is a complaint.
                let complaint = stderr(out)
                    .lines()
                    .any(|l| !l.starts_with("vcsmooth: note: "));
                if !out.status.success() || complaint {
                    return Err(format!(
                        "{what}: {:?}, stderr {:?}",
                        out.status,
                        stderr(out)
                    ));
                }
            }
            let back = vcsmooth::io::read_mesh(&output).map_err(|e| e.to_string())?;
            if back.positions.iter().any(|p| !p.is_finite()) {
                return Err("non-finite output".into());
            }
            let json: serde_json::Value =
                serde_json::from_slice(&info.stdout).map_err(|e| e.to_string())?;
            if json["vertices"].as_u64() != Some(back.positions.len() as u64) {
                return Err(format!(
                    "info says {json}, output has {} vertices",
                    back.positions.len()
                ));
            }
        }
    }
    Ok(())
}

#[test]
fn corpus_through_the_binary() {
    let cases = cases::cases();
    let errors = cases
        .iter()
        .filter(|c| matches!(c.expect, Expect::Error(_)));
    assert!(errors.count() >= 40, "at least 40 malformed files");
    let mut seen = std::collections::HashSet::new();
    assert!(
        cases.iter().all(|c| seen.insert(c.name)),
        "names are unique"
    );
    for c in &cases {
        assert!(c.bytes.len() < 10 << 10, "{} is small", c.name);
    }

    let dir = tempfile::tempdir().unwrap();
    // Two workers: the cases are independent processes.
    let failures: Vec<String> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..2)
            .map(|w| {
                let (dir, cases) = (dir.path(), &cases);
                s.spawn(move || {
                    cases
                        .iter()
                        .skip(w)
                        .step_by(2)
                        .filter_map(|c| run_case(dir, c).err().map(|e| format!("{}: {e}", c.name)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().unwrap())
            .collect()
    });
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

/// `VCSMOOTH_DUMP_CORPUS=DIR cargo test --test tests dump_corpus` writes the corpus files to DIR
/// (e.g. to seed the fuzzers); without the variable it does nothing.
#[test]
fn dump_corpus() {
    let Some(dir) = std::env::var_os("VCSMOOTH_DUMP_CORPUS") else {
        return;
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir).unwrap();
    for case in cases::cases() {
        std::fs::write(dir.join(case.name), &case.bytes).unwrap();
    }
}

#[test]
fn a_trillion_vertex_header_on_a_1kb_file_fails_fast() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("liar.ply");
    let header =
        "element vertex 1000000000000\nproperty float x\nproperty float y\nproperty float z\n";
    let offset = cases::ply_le_header_len(header);
    let bytes = cases::ply_le(header, &vec![0; 1024 - offset]);
    assert_eq!(bytes.len(), 1024);
    std::fs::write(&input, &bytes).unwrap();
    let what = format!(
        "vertex (byte {offset}): the header declares 1000000000000 records of at least 12 bytes, \
         but only {} bytes are left",
        1024 - offset
    );
    // Under a 1 GiB address-space limit: any allocation sized from the count (12 TB) would abort.
    for limited in [false, true] {
        let start = Instant::now();
        let out = if limited {
            Command::new("sh")
                .args(["-c", "ulimit -v 1048576 && exec \"$0\" \"$@\"", BIN, "info"])
                .arg(&input)
                .output()
                .unwrap()
        } else {
            vcsmooth(["info".as_ref(), input.as_os_str()])
        };
        let took = start.elapsed();
        failed_with(&out, &format!("{}: {what}", input.display())).unwrap();
        assert!(took < Duration::from_millis(500), "took {took:?}");
    }
}

// ---------------------------------------------------------------------------------------------
// Valid but unusual topology

fn write_ply(path: &Path, mesh: &Mesh) {
    vcsmooth::io::write_mesh(path, mesh).unwrap();
}

fn info_json(path: &Path) -> serde_json::Value {
    json(&ok(vcsmooth([
        "info".as_ref(),
        path.as_os_str(),
        "--json".as_ref(),
    ])))
}

#[test]
fn degenerate_and_duplicate_faces_are_processed_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = noisy_sphere(2, 0.3, 7);
    let t0 = mesh.triangles[0];
    mesh.triangles.push([t0[0], t0[0], t0[1]]); // a repeated index
    mesh.triangles.push([5, 5, 5]); // a point
    mesh.triangles.push(t0); // a duplicate
    let input = dir.path().join("degenerate.ply");
    write_ply(&input, &mesh);
    let info = info_json(&input);
    assert_eq!(info["degenerate_triangles"], 2, "{info}");
    assert_eq!(info["triangles"], 323, "{info}");
    assert_eq!(info["input_faces"], 323, "{info}");
    // The duplicate makes its three edges carry three triangles each.
    assert_eq!(info["non_manifold_edges"], 3, "{info}");

    let output = dir.path().join("out.ply");
    ok(vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--method".as_ref(),
        "vcs".as_ref(),
    ]));
    let back = vcsmooth::io::read_mesh(&output).unwrap();
    assert_eq!(back.triangles, mesh.triangles);
    assert!(back.positions.iter().all(|p| p.is_finite()));
    for v in [t0[0], t0[1], t0[2], 5] {
        let (a, b) = (
            mesh.positions[v as usize].as_vec3(),
            back.positions[v as usize].as_vec3(),
        );
        assert_eq!(a, b, "vertex {v} of a degenerate or duplicate face moved");
    }
}

/// Reflects `p` in the plane through `o` with unit normal `n`.
fn mirror(p: DVec3, o: DVec3, n: DVec3) -> DVec3 {
    p - 2.0 * (p - o).dot(n) * n
}

/// `a` and its mirror image in the plane through `o` with normal `n`, glued at the vertices
/// `shared` (the mirror's copies of them are dropped, so they are used by both halves).
fn glued(a: &Mesh, o: DVec3, n: DVec3, shared: &[u32]) -> Mesh {
    let count = a.positions.len() as u32;
    let mut positions = a.positions.to_vec();
    let mut index = vec![0; count as usize];
    for v in 0..count {
        index[v as usize] = if shared.contains(&v) {
            v
        } else {
            positions.push(mirror(a.positions[v as usize], o, n));
            positions.len() as u32 - 1
        };
    }
    let mut triangles = a.triangles.to_vec();
    // A reflection turns the faces inside out: reverse them to keep the mirror outward.
    triangles.extend(a.triangles.iter().map(|t| {
        [
            index[t[0] as usize],
            index[t[2] as usize],
            index[t[1] as usize],
        ]
    }));
    Mesh::new(positions, triangles)
}

#[test]
fn non_manifold_vertices_and_edges_stay_fixed_and_the_rest_is_smoothed() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = noisy_sphere(2, 0.3, 11);
    let p = |v: u32| sphere.positions[v as usize];

    // Two spheres touching at vertex 0 (a non-manifold vertex) ...
    let tip = glued(&sphere, p(0), p(0).normalize(), &[0]);
    // ... and two spheres sharing the edge (a, b): four triangles on one edge.
    let [a, b, _] = sphere.triangles[0];
    let d = (p(b) - p(a)).normalize();
    let m = (p(a) + p(b)) / 2.0;
    let fin = glued(&sphere, p(a), (m - m.dot(d) * d).normalize(), &[a, b]);

    for (name, mesh, fixed, key) in [
        ("vertex.ply", tip, vec![0], "non_manifold_vertices"),
        ("edge.ply", fin, vec![a, b], "non_manifold_edges"),
    ] {
        let input = dir.path().join(name);
        write_ply(&input, &mesh);
        let info = info_json(&input);
        assert!(info[key].as_u64() >= Some(1), "{name}: {info}");
        let output = dir.path().join(format!("smoothed-{name}"));
        let out = vcsmooth([
            "smooth".as_ref(),
            input.as_os_str(),
            output.as_os_str(),
            "--method".as_ref(),
            "vcs".as_ref(),
            "--iterations".as_ref(),
            "3".as_ref(),
        ]);
        assert!(out.status.success(), "{name}: {}", stderr(&out));
        let back = vcsmooth::io::read_mesh(&output).unwrap();
        let before: Vec<_> = mesh.positions.iter().map(|p| p.as_vec3()).collect();
        let after: Vec<_> = back.positions.iter().map(|p| p.as_vec3()).collect();
        for (v, (x, y)) in before.iter().zip(&after).enumerate() {
            if fixed.contains(&(v as u32)) {
                assert_eq!(x, y, "{name}: non-manifold vertex {v} moved");
            } else {
                assert_ne!(x, y, "{name}: vertex {v} was not smoothed");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Faults

/// Whether `name` is the atomic writer's temporary name for `target` (`.<target>.tmp-<pid>-<n>`).
fn is_temp_of(name: &str, target: &str) -> bool {
    name.strip_prefix(&format!(".{target}.tmp-"))
        .and_then(|rest| rest.split_once('-'))
        .is_some_and(|(pid, n)| {
            !pid.is_empty()
                && !n.is_empty()
                && pid.bytes().all(|b| b.is_ascii_digit())
                && n.bytes().all(|b| b.is_ascii_digit())
        })
}

/// Size of the first temporary file of `out.ply` in `dir`, if there is one.
fn temp_size(dir: &Path) -> Option<u64> {
    std::fs::read_dir(dir).ok()?.find_map(|e| {
        let e = e.ok()?;
        is_temp_of(&e.file_name().to_string_lossy(), "out.ply")
            .then(|| e.metadata().map_or(0, |m| m.len()))
    })
}

#[test]
fn killing_a_run_at_any_moment_leaves_the_previous_output_intact() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("big.ply");
    generate_sphere(&input, 8, None, None);
    let output = d.join("out.ply");
    // One complete run: how long a run takes, and what it writes.
    let complete = d.join("complete.ply");
    let clock = Instant::now();
    let out = vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        complete.as_os_str(),
        "--iterations".as_ref(),
        "0".as_ref(),
    ]);
    let took = clock.elapsed().as_millis() as u64;
    ok(out);
    let complete = std::fs::read(&complete).unwrap();
    std::fs::remove_file(d.join("complete.ply")).unwrap();
    let previous = b"the previous output, which must survive".to_vec();

    enum When {
        After(u64),
        TempExists,
        TempHasBytes(u64),
    }
    let size = complete.len() as u64;
    let moments = [
        When::After(0),
        When::After(took / 4),
        When::After(took / 2),
        When::After(took * 3 / 4),
        When::TempExists,
        When::TempHasBytes(size / 8),
        When::TempHasBytes(size / 2),
        When::TempHasBytes(size * 7 / 8),
    ];
    let mut killed_mid_write = 0;
    for when in &moments {
        std::fs::write(&output, &previous).unwrap();
        let mut child = command()
            .args([
                "smooth".as_ref(),
                input.as_os_str(),
                output.as_os_str(),
                "--iterations".as_ref(),
                "0".as_ref(),
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let start = Instant::now();
        let mut seen = None;
        loop {
            let ready = match *when {
                When::After(ms) => start.elapsed() >= Duration::from_millis(ms),
                When::TempExists => {
                    seen = temp_size(d);
                    seen.is_some()
                }
                When::TempHasBytes(n) => {
                    seen = temp_size(d);
                    seen.is_some_and(|s| s >= n)
                }
            };
            if ready
                || child.try_wait().unwrap().is_some()
                || start.elapsed() > Duration::from_secs(60)
            {
                break;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        let finished = child.try_wait().unwrap().is_some();
        child.kill().unwrap(); // SIGKILL; harmless if it already exited
        child.wait().unwrap();
        if !finished && seen.is_some() {
            killed_mid_write += 1;
        }
        let left = listing(d)
            .into_iter()
            .filter(|n| n != "big.ply" && n != "out.ply");
        eprintln!(
            "killed after {:?}: finished {finished}, temp seen with {seen:?} bytes, left {:?}",
            start.elapsed(),
            left.collect::<Vec<_>>()
        );
        let now = std::fs::read(&output).unwrap();
        if finished {
            // Too late to kill: then the output must be complete.
            assert!(now == complete, "a finished run left an incomplete output");
        } else {
            // The run may still rename its complete file between `try_wait` and the kill: the
            // output is then complete. Never anything in between.
            assert!(
                now == previous || now == complete,
                "a kill left a partial output (temp had {seen:?} bytes)"
            );
        }
        // Whatever a kill leaves is a temporary file, never something under the output's name.
        for name in listing(d) {
            if name != "big.ply" && name != "out.ply" {
                assert!(is_temp_of(&name, "out.ply"), "left behind: {name}");
                std::fs::remove_file(d.join(name)).unwrap();
            }
        }
    }
    assert!(
        killed_mid_write >= 3,
        "the test must kill at least twice while writing"
    );

    // Left alone, the same run replaces the output with the complete mesh.
    ok(vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--iterations".as_ref(),
        "0".as_ref(),
    ]));
    assert!(std::fs::read(&output).unwrap() == complete);
    assert_eq!(listing(d), ["big.ply", "out.ply"]);
}

/// A level-5 sphere: its PLY output (≈ 390 KB) does not fit 256 KiB.
fn medium_input(dir: &Path) -> PathBuf {
    let input = dir.join("in.ply");
    generate_sphere(&input, 5, None, None);
    input
}

/// `smooth IN DIR/out.ply` over a previous output must fail with `<out>: <os_error>` and leave the
/// previous output as it was and no temporary file.
fn check_write_failure(out: &Output, dir: &Path, os_error: &str) {
    let output = dir.join("out.ply");
    failed_with(out, &format!("{}: {os_error}", output.display())).unwrap();
    assert_eq!(std::fs::read(&output).unwrap(), b"previous");
    assert_eq!(listing(dir), ["out.ply"]);
}

#[test]
fn an_injected_write_error_gives_one_line_and_no_partial_output() {
    // RLIMIT_FSIZE with SIGXFSZ ignored (an ignored signal stays ignored across exec): the write
    // that crosses 64 KiB fails with EFBIG, as a full disk fails with ENOSPC.
    let dir = tempfile::tempdir().unwrap();
    let input = medium_input(dir.path());
    let outdir = dir.path().join("out");
    std::fs::create_dir(&outdir).unwrap();
    std::fs::write(outdir.join("out.ply"), b"previous").unwrap();
    let out = Command::new("sh")
        .args([
            "-c",
            "trap '' XFSZ; ulimit -f 128 && exec \"$0\" \"$@\"",
            BIN,
            "smooth",
        ])
        .arg(&input)
        .arg(outdir.join("out.ply"))
        .output()
        .unwrap();
    check_write_failure(&out, &outdir, "File too large (os error 27)");
}

/// Unmounts on drop, also when the test fails.
struct Mount(PathBuf);

impl Drop for Mount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

#[test]
fn a_full_disk_gives_one_line_and_no_partial_output() {
    let dir = tempfile::tempdir().unwrap();
    let input = medium_input(dir.path());
    let full = dir.path().join("full");
    std::fs::create_dir(&full).unwrap();
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=256k", "tmpfs"])
        .arg(&full)
        .output();
    match mounted {
        Ok(m) if m.status.success() => {
            let _mount = Mount(full.clone());
            std::fs::write(full.join("out.ply"), b"previous").unwrap();
            let out = vcsmooth([
                "smooth".as_ref(),
                input.as_os_str(),
                full.join("out.ply").as_os_str(),
            ]);
            check_write_failure(&out, &full, "No space left on device (os error 28)");
        }
        other => {
            // Not root, or a sandbox without mount: say so; the injected-error test above
            // covers the same path with EFBIG.
            let why = match other {
                Ok(m) => String::from_utf8_lossy(&m.stderr).trim().to_string(),
                Err(e) => e.to_string(),
            };
            eprintln!(
                "NOTE: cannot mount a tmpfs ({why}); the real full-disk case was NOT run, only the injected one"
            );
            an_injected_write_error_gives_one_line_and_no_partial_output();
        }
    }
}
