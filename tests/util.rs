//! Helpers and fixtures shared by the integration tests (`tests/tests.rs`) and the MPI-only tests
//! (`tests/engines.rs`): running the `vcsmooth` binary and checking what it did, reading JSON, the
//! real scans of `tests/data`, generated spheres, the octahedron, checkpoints, and the cluster engine
//! on thread ranks. Each exists here once; what belongs to one area alone (the hostile corpus, the
//! golden hashes, refine's geometry checks) stays in its module.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use serde_json::Value;
use vcsmooth::cluster::{self, ClusterSettings, Local};
use vcsmooth::engine::{EngineSettings, Quiet, Report};
use vcsmooth::{Mesh, Options, io, shapes};

// ---------------------------------------------------------------------------------------------
// The binary

/// The `vcsmooth` binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_vcsmooth");

/// `vcsmooth` as a command to complete (arguments, environment) before running it: no stdin, and
/// none of the Slurm array variables, so that a test never picks up the task of a Slurm job it
/// happens to run in.
pub fn command() -> Command {
    let mut cmd = Command::new(BIN);
    for v in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_MAX",
    ] {
        cmd.env_remove(v);
    }
    cmd.stdin(Stdio::null());
    cmd
}

/// Run `vcsmooth ARGS...` to completion.
pub fn vcsmooth<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    command().args(args).output().expect("run vcsmooth")
}

/// A path as a command-line argument.
pub fn arg(p: &Path) -> String {
    p.display().to_string()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Assert success and return stdout.
pub fn ok(o: Output) -> String {
    assert!(
        o.status.success(),
        "exit {:?}, stderr: {}\nstdout: {}",
        o.status.code(),
        stderr(&o),
        stdout(&o)
    );
    stdout(&o)
}

/// Assert a failure with exit code `code` and exactly one stderr line `vcsmooth: error: …`
/// that contains each of `mentions`.
pub fn fails(o: &Output, code: i32, mentions: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(code), "stderr: {err}");
    let lines: Vec<&str> = err.trim_end().lines().collect();
    assert_eq!(lines.len(), 1, "not one line: {err:?}");
    assert!(lines[0].starts_with("vcsmooth: error: "), "{err}");
    for m in mentions {
        assert!(lines[0].contains(m), "'{m}' not in: {err}");
    }
    assert!(
        !err.contains("panicked") && !err.contains("RUST_BACKTRACE"),
        "{err}"
    );
}

/// Checks a run that must fail with exactly `vcsmooth: error: <line>`; returns what is wrong.
pub fn failed_with(out: &Output, line: &str) -> Result<(), String> {
    let err = stderr(out);
    let expected = format!("vcsmooth: error: {line}\n");
    if out.status.success() || out.status.code().is_none() {
        return Err(format!("status {:?}, stderr {err:?}", out.status));
    }
    if err != expected {
        return Err(format!("stderr {err:?}\n      expected {expected:?}"));
    }
    if err.contains("panick") || err.contains("internal error") {
        return Err(format!("panic: {err:?}"));
    }
    Ok(())
}

/// `vcsmooth generate sphere PATH --subdivisions LEVEL [--noise NOISE] [--seed SEED]`, which must
/// succeed.
pub fn generate_sphere(path: &Path, level: u32, noise: Option<f64>, seed: Option<u64>) {
    let mut args = vec![
        "generate".to_string(),
        "sphere".into(),
        path.display().to_string(),
        "--subdivisions".into(),
        level.to_string(),
    ];
    if let Some(noise) = noise {
        args.extend(["--noise".into(), noise.to_string()]);
    }
    if let Some(seed) = seed {
        args.extend(["--seed".into(), seed.to_string()]);
    }
    ok(vcsmooth(&args));
    assert!(path.is_file(), "{} not written", path.display());
}

// ---------------------------------------------------------------------------------------------
// Files

/// Parse `text` as JSON.
pub fn json(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("not JSON ({e}): {text}"))
}

/// Read the JSON file at `path`.
pub fn read_json(path: &Path) -> Value {
    json(&std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
}

/// File names in `dir`, sorted.
pub fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The iterations a checkpointed run has recorded in `work/state.json`; 0 while there is none.
pub fn iterations_done(work: &Path) -> u64 {
    std::fs::read_to_string(work.join("state.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .and_then(|v| v["done"].as_u64())
        .unwrap_or(0)
}

// ---------------------------------------------------------------------------------------------
// The real scans (tests/data, see tests/data/PROVENANCE.md)

/// The repository's root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The path of the scan `name` in `tests/data`.
pub fn scan(name: &str) -> PathBuf {
    root().join("tests/data").join(name)
}

/// The scan `name` of `tests/data`, read.
pub fn read_scan(name: &str) -> Mesh {
    io::read_mesh(&scan(name)).unwrap()
}

/// The paths of the six scans of `tests/data`, sorted.
pub fn scans() -> Vec<PathBuf> {
    let dir = root().join("tests/data");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "ply"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 6, "expected the six scans of tests/data");
    files
}

// ---------------------------------------------------------------------------------------------
// Generated meshes

/// An icosphere of `level` with Gaussian noise `sigma` (× mean edge length) along the normals.
pub fn noisy_sphere(level: u32, sigma: f64, seed: u64) -> Mesh {
    let mut m = shapes::icosphere(level);
    shapes::add_normal_noise(&mut m, sigma, seed);
    m
}

/// `mesh` split along a seam as a textured file splits it: the vertices shared by triangles on
/// both sides of `z = 0` (by centroid) get a copy (appended after the originals), which the
/// triangles above use, so that the two halves meet only at equal positions. Returns the mesh
/// and, per vertex, the vertex it copies (itself for the originals).
pub fn seamed(mesh: &Mesh) -> (Mesh, Vec<u32>) {
    let above = |t: &[u32; 3]| t.iter().map(|&v| mesh.positions[v as usize].z).sum::<f64>() > 0.0;
    let mut sides = vec![[false; 2]; mesh.positions.len()];
    for t in mesh.triangles.iter() {
        for &v in t {
            sides[v as usize][above(t) as usize] = true;
        }
    }
    let mut positions = mesh.positions.to_vec();
    let mut copy_of: Vec<u32> = (0..positions.len() as u32).collect();
    let mut copies = std::collections::HashMap::new();
    let triangles = mesh
        .triangles
        .iter()
        .map(|t| {
            if !above(t) {
                return *t;
            }
            t.map(|v| {
                if sides[v as usize] != [true; 2] {
                    return v;
                }
                *copies.entry(v).or_insert_with(|| {
                    positions.push(mesh.positions[v as usize]);
                    copy_of.push(v);
                    (positions.len() - 1) as u32
                })
            })
        })
        .collect();
    (Mesh::new(positions, triangles), copy_of)
}

/// The octahedron of [`vcsmooth::shapes::octahedron`] as a file holds it: `f32` corners ...
pub fn octa_v() -> Vec<[f32; 3]> {
    let m = vcsmooth::shapes::octahedron();
    m.positions.iter().map(|p| p.as_vec3().to_array()).collect()
}

/// ... and its 8 outward triangles as `i32` indices.
pub fn octa_f() -> Vec<[i32; 3]> {
    let m = vcsmooth::shapes::octahedron();
    m.triangles.iter().map(|t| t.map(|v| v as i32)).collect()
}

// ---------------------------------------------------------------------------------------------
// The cluster engine on thread ranks (the code path MPI ranks take)

pub fn engine_settings(patch_size: usize, threads: usize) -> EngineSettings {
    EngineSettings {
        threads: Some(threads),
        patch_size,
        ..EngineSettings::default()
    }
}

pub fn cluster_settings(work_dir: &Path, keep: bool, checkpoint_every: usize) -> ClusterSettings {
    ClusterSettings {
        work_dir: work_dir.to_path_buf(),
        keep,
        checkpoint_every,
    }
}

/// Run the cluster engine on `ranks` thread-ranks exchanging through `cluster::Local`; returns
/// every rank's result, rank 0 first.
pub fn run_ranks(
    ranks: usize,
    input: &Path,
    output: &Path,
    opts: &Options,
    engine: &EngineSettings,
    settings: &ClusterSettings,
) -> Vec<vcsmooth::Result<Report>> {
    let comms = Local::group(ranks);
    std::thread::scope(|s| {
        let handles: Vec<_> = comms
            .iter()
            .map(|c| {
                s.spawn(move || {
                    cluster::run_file(c, input, output, opts, engine, settings, &mut Quiet)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    })
}

/// `mesh` planned in `storage` with patches of `patch_size` on `threads` threads, `prepare`d
/// (pins, creases, checks of the plan), smoothed with `opts` (statistics of the last iteration),
/// its positions in input order: the runs that tests compare across threads and storage.
pub fn planned_positions(
    mesh: &Mesh,
    storage: &vcsmooth::mesh::Storage,
    threads: usize,
    patch_size: usize,
    opts: &Options,
    prepare: impl Fn(&mut vcsmooth::engine::Plan) + Sync,
) -> Vec<glam::DVec3> {
    use vcsmooth::engine::{Layout, Plan, Statistics, thread_pool};
    thread_pool(Some(threads)).unwrap().install(|| {
        let layout = Layout::Patches(patch_size);
        let mut plan = Plan::new(storage, &mesh.positions, &mesh.triangles, layout).unwrap();
        prepare(&mut plan);
        plan.smooth(storage, opts, Statistics::Last, &mut Quiet)
            .unwrap();
        let mut out = vec![glam::DVec3::ZERO; mesh.positions.len()];
        plan.positions_in_input_order(&mut out);
        out
    })
}

/// The mean angle (degrees) between each face's normal in `a` and in `b` (same faces), as the
/// denoising literature measures a result against the clean mesh.
pub fn normal_error(a: &Mesh, b: &Mesh) -> f64 {
    let normal = |m: &Mesh, t: &[u32; 3]| {
        let p = |i: u32| m.positions[i as usize];
        (p(t[1]) - p(t[0]))
            .cross(p(t[2]) - p(t[0]))
            .normalize_or_zero()
    };
    let sum: f64 = (a.triangles.iter())
        .map(|t| normal(a, t).dot(normal(b, t)).clamp(-1.0, 1.0).acos())
        .sum();
    sum.to_degrees() / a.triangles.len() as f64
}
