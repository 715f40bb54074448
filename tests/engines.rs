//! Against the real engines: OpenMPI ranks and a Slurm cluster on this machine. Built
//! only with `--features mpi` (Cargo.toml), which CI enables after installing OpenMPI and Slurm
//! (`.ci/run`); these tests fail, never skip, when an engine is missing.

#[allow(dead_code)]
mod util;

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use util::{BIN, command, generate_sphere, iterations_done, ok, root, scan};

/// `mpirun -n ranks vcsmooth args...`, oversubscribed (3 ranks on 2 cores), allowed as root.
fn mpirun(ranks: usize, args: &[&str]) -> Command {
    let mut c = Command::new("mpirun");
    c.args(["-n", &ranks.to_string(), "--oversubscribe", BIN])
        .args(args)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1");
    c
}

/// A noisy sphere of `level` in `dir/in.ply`.
fn generate(dir: &Path, level: u32) -> PathBuf {
    let p = dir.join("in.ply");
    generate_sphere(&p, level, Some(0.4), None);
    p
}

/// The reference: `vcsmooth smooth input dir/plain.ply args...` in one process, without MPI.
fn single_process(dir: &Path, input: &Path, args: &[&str]) -> PathBuf {
    let plain = dir.join("plain.ply");
    ok(command()
        .args(["smooth", input.to_str().unwrap(), plain.to_str().unwrap()])
        .args(args)
        .output()
        .unwrap());
    plain
}

#[test]
fn mpi_ranks_1_2_3_are_bit_identical_to_one_process() {
    let tmp = tempfile::tempdir().unwrap();
    let armadillo = scan("armadillo-86k.ply");
    let bunny = tmp.path().join("bunny.ply");
    let source = scan("stanford-bunny.ply");
    ok(command()
        .args(["generate", "mesh", bunny.to_str().unwrap(), "--from"])
        .args([
            source.to_str().unwrap(),
            "--subdivide",
            "0",
            "--noise",
            "0.3",
        ])
        .output()
        .unwrap());
    let sphere = generate(tmp.path(), 6);
    let three = |method| {
        ["--method", method, "--iterations", "3"]
            .map(String::from)
            .to_vec()
    };
    // The automatic stop and smoothed boundaries (loops crossing ranks) with the default method.
    let auto: Vec<String> = ["--iterations", "auto", "--boundary", "smooth"]
        .map(String::from)
        .to_vec();
    // A seamed sphere: the welded copies follow their vertices on every rank count.
    let seamed = tmp.path().join("seamed.ply");
    let one = vcsmooth::io::read_mesh(&sphere).unwrap();
    vcsmooth::io::write_mesh(&seamed, &util::seamed(&one).0).unwrap();
    for (input, args) in [
        (&seamed, three("vcs-lowpass")),
        (&armadillo, three("vcs")),
        (&sphere, three("taubin")),
        (&sphere, three("vcs-triangle")),
        (&sphere, three("hc")),
        (&sphere, three("vcs-guided")),
        (&bunny, auto),
    ] {
        let method = args.join(" ");
        let mut common: Vec<&str> = args.iter().map(String::as_str).collect();
        common.extend(["--patch-size", "2048"]);
        let plain = single_process(tmp.path(), input, &common);
        for ranks in [1, 2, 3] {
            let out = tmp.path().join(format!("mpi{ranks}.ply"));
            let text = ok(mpirun(
                ranks,
                &["smooth", input.to_str().unwrap(), out.to_str().unwrap()],
            )
            .args(&common)
            .args(["--threads", "1"])
            .output()
            .unwrap());
            assert_eq!(
                std::fs::read(&out).unwrap(),
                std::fs::read(&plain).unwrap(),
                "{method} on {ranks} MPI ranks differs from one process"
            );
            // One table, from rank 0 only.
            assert_eq!(text.matches(" -> ").count(), 1, "{text}");
            if ranks > 1 {
                assert!(text.contains(&format!("{ranks} ranks")), "{text}");
            }
            let mut work = out.as_os_str().to_owned();
            work.push(".vcsmooth-work");
            assert!(!Path::new(&work).exists(), "work directory left behind");
        }
    }
}

#[test]
fn mpi_run_killed_and_resumed_equals_uninterrupted() {
    let tmp = tempfile::tempdir().unwrap();
    let input = generate(tmp.path(), 7);
    // The default method runs a level-7 iteration in tens of milliseconds: 60 iterations leave
    // the kill a window of over a second.
    let common = [
        "--iterations",
        "60",
        "--patch-size",
        "4096",
        "--threads",
        "1",
    ];
    let plain = single_process(tmp.path(), &input, &common);
    let ck = tmp.path().join("ck");
    let out = tmp.path().join("out.ply");
    let args = [
        "smooth",
        input.to_str().unwrap(),
        out.to_str().unwrap(),
        "--checkpoint",
        ck.to_str().unwrap(),
    ];
    // mpirun and its ranks in a process group of their own, killed together below, as a node
    // failure would take them: a SIGKILL to mpirun alone leaves the ranks running until the
    // launcher's daemon notices, long enough for them to finish.
    let mut child = mpirun(2, &args)
        .args(common)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .process_group(0)
        .spawn()
        .unwrap();
    let done = || iterations_done(&ck);
    let start = std::time::Instant::now();
    while done() < 2 && start.elapsed().as_secs() < 300 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let group = format!("-{}", child.id());
    ok(Command::new("kill")
        .args(["-KILL", "--", &group])
        .output()
        .unwrap());
    child.wait().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    let at = done();
    assert!((2..60).contains(&at), "killed after {at} iterations");
    assert!(!out.exists());
    let text = ok(mpirun(3, &args).args(common).output().unwrap());
    assert!(text.contains("60 iterations"), "{text}");
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&plain).unwrap());
}

/// Start the single-node cluster (idempotent; needs root) and run one of the Slurm scripts.
fn slurm_script(script: &str, args: &[&str]) {
    // One at a time: both start the same cluster and share its two CPUs.
    static SLURM: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = SLURM.lock().unwrap_or_else(|e| e.into_inner());
    let up = Command::new("scontrol")
        .arg("ping")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("is UP"));
    if !up {
        let start = root().join("tools/slurm/start_local_cluster.sh");
        ok(Command::new("bash").arg(start).output().unwrap());
    }
    let text = ok(Command::new("bash")
        .arg(root().join("tools/slurm").join(script))
        .args(args)
        .output()
        .unwrap());
    assert!(text.contains("PASS"), "{text}");
}

#[test]
fn slurm_array_batch_survives_a_killed_task() {
    slurm_script("test_array.sh", &[BIN]);
}

#[test]
fn slurm_sbatch_runs_the_mpi_mode() {
    slurm_script("test_mpi.sh", &[BIN]);
}
