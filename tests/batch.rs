//! `vcsmooth batch` and `vcsmooth slurm-script` end to end: a batch of generated meshes split over
//! three array tasks, a rerun that redoes only what lost its marker, the summary, a corrupt input,
//! and the Slurm script's essentials. (The real Slurm cluster test is tools/slurm/test_array.sh.)

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

use crate::util::{command, generate_sphere, ok, read_json, vcsmooth};

const MESHES: usize = 8;

/// Generate `MESHES` noisy spheres (levels 2 and 3) in `dir/in`.
fn meshes(dir: &Path) -> PathBuf {
    let input = dir.join("in");
    std::fs::create_dir(&input).unwrap();
    for k in 0..MESHES {
        let path = input.join(format!("m{k}.ply"));
        generate_sphere(&path, 2 + (k % 2) as u32, Some(0.3), Some(k as u64));
    }
    input
}

fn run_task(input: &Path, out: &Path, index: usize, count: usize) -> Output {
    vcsmooth([
        "batch".as_ref(),
        input.as_os_str(),
        out.as_os_str(),
        "--iterations".as_ref(),
        "5".as_ref(),
        "--threads".as_ref(),
        "2".as_ref(),
        "--task-index".as_ref(),
        index.to_string().as_ref(),
        "--task-count".as_ref(),
        count.to_string().as_ref(),
    ])
}

fn marker(out: &Path, k: usize) -> PathBuf {
    out.join(".done").join(format!("m{k}.json"))
}

fn mtime(path: &Path) -> std::time::SystemTime {
    std::fs::metadata(path).unwrap().modified().unwrap()
}

#[test]
fn array_of_three_tasks_rerun_and_summary() {
    let dir = tempfile::tempdir().unwrap();
    let input = meshes(dir.path());
    let out = dir.path().join("out");
    for task in 0..3 {
        let text = ok(run_task(&input, &out, task, 3));
        // Round robin: task t owns m{t}, m{t+3}, m{t+6}.
        let expected: Vec<usize> = (task..MESHES).step_by(3).collect();
        assert_eq!(text.matches("\ndone ").count(), expected.len(), "{text}");
        for k in expected {
            assert!(text.contains(&format!("m{k}.ply ->")), "{text}");
        }
    }
    for k in 0..MESHES {
        assert!(out.join(format!("m{k}.ply")).is_file(), "m{k}.ply missing");
        let m = read_json(&marker(&out, k));
        assert_eq!(m["format"], "vcsmooth-batch-marker/1");
        assert_eq!(m["name"], format!("m{k}"));
        assert_eq!(m["method"], "vcs-lowpass");
        assert_eq!(m["iterations"], 5);
        assert_eq!(m["triangles"], 20 * 4u64.pow(2 + (k % 2) as u32));
        let v = m["volume_pct"].as_f64().unwrap();
        assert!((v - 100.0).abs() < 1e-6, "m{k}: volume {v} %");
        assert_eq!(m["run"]["records"].as_array().unwrap().len(), 5);
        assert!(m["run"]["input_stats"].is_object());
    }
    // No temporary files left in OUTDIR.
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), MESHES + 1, "{names:?}");

    // Lose m4 (task 1 owns m1, m4, m7) and rerun task 1: only m4 is redone.
    let before: Vec<_> = (0..MESHES).map(|k| mtime(&marker(&out, k))).collect();
    std::fs::remove_file(out.join("m4.ply")).unwrap();
    std::fs::remove_file(marker(&out, 4)).unwrap();
    // As if a killed task left its temporary output behind.
    let leftover = out.join(".m4.ply.tmp-999999-0");
    std::fs::write(&leftover, b"partial").unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    let text = ok(run_task(&input, &out, 1, 3));
    assert_eq!(text.matches("\ndone ").count(), 1, "{text}");
    assert!(text.contains("m4.ply ->"), "{text}");
    assert_eq!(text.matches("\nskipped ").count(), 2, "{text}");
    assert!(out.join("m4.ply").is_file() && marker(&out, 4).is_file());
    assert!(!leftover.exists());
    for k in (0..MESHES).filter(|&k| k != 4) {
        assert_eq!(mtime(&marker(&out, k)), before[k], "m{k} was redone");
    }

    // The summary lists all 8, as a table and as JSON.
    let table = ok(vcsmooth([
        "batch".as_ref(),
        "--summary".as_ref(),
        out.as_os_str(),
        "--inputs".as_ref(),
        input.as_os_str(),
    ]));
    for k in 0..MESHES {
        assert!(table.contains(&format!("m{k} ")), "{table}");
    }
    assert!(table.contains("8 of 8 inputs done, 0 missing"), "{table}");
    let json_path = dir.path().join("summary.json");
    ok(vcsmooth([
        "batch".as_ref(),
        "--summary".as_ref(),
        out.as_os_str(),
        "--json".as_ref(),
        json_path.as_os_str(),
    ]));
    let s = read_json(&json_path);
    assert_eq!(s["meshes"].as_array().unwrap().len(), MESHES);
    assert_eq!(s["totals"]["meshes"], MESHES);
    assert_eq!(s["totals"]["triangles"], 4 * 320 + 4 * 1280);

    // A missing marker makes the summary fail and names the input.
    std::fs::remove_file(marker(&out, 6)).unwrap();
    let o = vcsmooth([
        "batch".as_ref(),
        "--summary".as_ref(),
        out.as_os_str(),
        "--inputs".as_ref(),
        input.as_os_str(),
        "--json".as_ref(),
        "-".as_ref(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let s: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(s["missing"].as_array().unwrap().len(), 1);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("m6.ply") && err.contains("1 of 8"), "{err}");
}

#[test]
fn a_corrupt_input_fails_its_task_but_not_its_neighbours() {
    let dir = tempfile::tempdir().unwrap();
    let input = meshes(dir.path());
    // m3 (task 0 of 3 owns m0, m3, m6) is truncated.
    let bad = input.join("m3.ply");
    let bytes = std::fs::read(&bad).unwrap();
    std::fs::write(&bad, &bytes[..bytes.len() / 2]).unwrap();
    let out = dir.path().join("out");
    let o = run_task(&input, &out, 0, 3);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<&str> = err.trim_end().lines().collect();
    // One line for the one failure; the count is in the task's summary on stdout.
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].starts_with("vcsmooth: error: ") && lines[0].contains("m3.ply"),
        "{err}"
    );
    let summary = String::from_utf8_lossy(&o.stdout);
    assert!(
        summary.contains("task 0 of 3: 2 done, 0 already done, 1 failed"),
        "{summary}"
    );
    for k in [0, 6] {
        assert!(out.join(format!("m{k}.ply")).is_file() && marker(&out, k).is_file());
    }
    assert!(!out.join("m3.ply").exists() && !marker(&out, 3).exists());
    // The other tasks are unaffected.
    ok(run_task(&input, &out, 1, 3));
}

#[test]
fn list_files_collisions_and_environment() {
    let dir = tempfile::tempdir().unwrap();
    let input = meshes(dir.path());
    // A list with a comment, a blank line and paths relative to the list's directory.
    let list = dir.path().join("list.txt");
    std::fs::write(&list, "# two meshes\nin/m0.ply\n\nin/m1.ply\n").unwrap();
    let out = dir.path().join("out");
    let o = command()
        .args(["batch".as_ref(), list.as_os_str(), out.as_os_str()])
        .args(["--iterations", "1", "--format", "obj"])
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env("SLURM_ARRAY_TASK_COUNT", "2")
        .output()
        .unwrap();
    let text = ok(o);
    assert!(text.starts_with("task 1 of 2: 1 of 2 inputs"), "{text}");
    assert!(out.join("m1.obj").is_file() && !out.join("m0.obj").exists());

    // Two inputs with the same stem are refused before anything runs.
    std::fs::copy(input.join("m0.ply"), dir.path().join("m0.ply")).unwrap();
    std::fs::write(&list, "in/m0.ply\nm0.ply\n").unwrap();
    let o = vcsmooth([
        "batch".as_ref(),
        list.as_os_str(),
        dir.path().join("o2").as_os_str(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("same name 'm0'"), "{err}");
    assert!(!dir.path().join("o2").exists());
}

/// An input that is its own output under another name (a symbolic link into OUTDIR, or OUTDIR
/// itself) is refused before anything runs, and left as it was.
#[test]
fn an_input_reached_through_a_link_is_never_its_own_output() {
    let dir = tempfile::tempdir().unwrap();
    let (input, out) = (dir.path().join("in"), dir.path().join("out"));
    std::fs::create_dir_all(&input).unwrap();
    std::fs::create_dir_all(&out).unwrap();
    generate_sphere(&out.join("a.ply"), 2, Some(0.3), Some(1));
    let before = std::fs::read(out.join("a.ply")).unwrap();
    std::os::unix::fs::symlink("../out/a.ply", input.join("a.ply")).unwrap();
    let link = dir.path().join("link");
    std::os::unix::fs::symlink("out", &link).unwrap();
    for outdir in [&out, &link] {
        let o = vcsmooth(["batch".as_ref(), input.as_os_str(), outdir.as_os_str()]);
        assert_eq!(o.status.code(), Some(1), "{outdir:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("its output would overwrite it"), "{err}");
        assert_eq!(std::fs::read(out.join("a.ply")).unwrap(), before);
    }
}

#[test]
fn slurm_script_has_array_mem_and_dependent_summary() {
    let dir = tempfile::tempdir().unwrap();
    let input = meshes(dir.path());
    let out = dir.path().join("out");
    let script = ok(vcsmooth([
        "slurm-script".as_ref(),
        input.as_os_str(),
        out.as_os_str(),
        "--iterations".as_ref(),
        "7".as_ref(),
        "--cpus".as_ref(),
        "2".as_ref(),
        "--partition".as_ref(),
        "debug".as_ref(),
        "--time".as_ref(),
        "0:30:00".as_ref(),
        "--max-array-size".as_ref(),
        "3".as_ref(),
    ]));
    for needle in [
        "#SBATCH --array=0-2\n",
        "#SBATCH --mem=1024M\n",
        "#SBATCH --cpus-per-task=2\n",
        "#SBATCH --partition=debug\n",
        "#SBATCH --time=0:30:00\n",
        "--task-index \"$SLURM_ARRAY_TASK_ID\" --task-count 3\n",
        "--iterations 7",
        "--threads 2",
        "--dependency=afterany:",
        "--kill-on-invalid-dep=yes",
        "sbatch --parsable",
        "batch --summary",
    ] {
        assert!(script.contains(needle), "'{needle}' not in:\n{script}");
    }
    let script = ok(vcsmooth([
        "slurm-script".as_ref(),
        input.as_os_str(),
        out.as_os_str(),
        "--max-array-size".as_ref(),
        "1001".as_ref(),
    ]));
    assert!(script.contains("#SBATCH --array=0-7\n"), "{script}");
    assert!(script.contains("--task-count 8\n"), "{script}");
    assert!(script.contains("--mem="), "{script}");
    // bash accepts it.
    let path = dir.path().join("submit.sh");
    std::fs::write(&path, &script).unwrap();
    let o = Command::new("bash").arg("-n").arg(&path).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// A marker certifies the results version of its output: a rerun redoes an input whose marker was
/// made by another results version, or before they were recorded, and says why; the others stay.
#[test]
fn a_marker_of_another_results_version_is_redone() {
    let dir = tempfile::tempdir().unwrap();
    let input = meshes(dir.path());
    let out = dir.path().join("out");
    ok(run_task(&input, &out, 0, 1));
    let m = read_json(&marker(&out, 0));
    assert_eq!(m["results_version"], vcsmooth::RESULTS_VERSION);
    let mut old = m.clone();
    old["results_version"] = (vcsmooth::RESULTS_VERSION - 1).into();
    std::fs::write(marker(&out, 0), old.to_string()).unwrap();
    let mut before = m;
    before.as_object_mut().unwrap().remove("results_version");
    std::fs::write(marker(&out, 1), before.to_string()).unwrap();
    let text = ok(run_task(&input, &out, 0, 1));
    assert_eq!(text.matches("\ndone ").count(), 2, "{text}");
    assert_eq!(text.matches("\nskipped ").count(), MESHES - 2, "{text}");
    let now = vcsmooth::RESULTS_VERSION;
    for was in [now - 1, 1] {
        assert!(
            text.contains(&format!("results version {was}, this is {now}")),
            "{text}"
        );
    }
    assert_eq!(read_json(&marker(&out, 1))["results_version"], now);
}
