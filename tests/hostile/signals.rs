//! Termination signals and temporary files: SIGINT, SIGTERM and SIGHUP sent to a running `smooth`
//! (mid-write, mid-smoothing, with scratch files) end it with one line and 128 + the signal's
//! number, remove its temporary files and leave the previous output as it was; what a SIGKILL left
//! is removed by the next write of the same target, unless its process still runs.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use super::is_temp_of;
use crate::util::{BIN, generate_sphere, listing, ok, vcsmooth};

const PREVIOUS: &[u8] = b"the previous output, which must survive";

/// `vcsmooth smooth IN OUT EXTRA…`, stderr captured, with the default action for the signals
/// sent here (`env --default-signal`): a test runner started in the background, as a shell
/// starts one, ignores SIGINT, and so would vcsmooth (see the test of ignored signals below).
fn spawn_smooth(input: &Path, output: &Path, extra: &[&str]) -> Child {
    Command::new("env")
        .arg("--default-signal=INT,TERM,HUP")
        .arg(BIN)
        .arg("smooth")
        .arg(input)
        .arg(output)
        .args(extra)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn send(child: &Child, signal: &str) {
    let sent = Command::new("kill")
        .args(["-s", signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success(), "kill -s {signal}");
}

/// Waits until `ready` or the child ended; returns whether it still runs.
fn wait_for(child: &mut Child, ready: impl Fn() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(60) {
        if child.try_wait().unwrap().is_some() {
            return false;
        }
        if ready() {
            return true;
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    let _ = child.kill();
    panic!("neither ready nor finished after 60 s");
}

/// Bytes in the temporary file of `out.ply` in `dir`, if there is one.
fn temp_bytes(dir: &Path) -> Option<u64> {
    std::fs::read_dir(dir).ok()?.find_map(|e| {
        let e = e.ok()?;
        is_temp_of(&e.file_name().to_string_lossy(), "out.ply")
            .then(|| e.metadata().map_or(0, |m| m.len()))
    })
}

/// The child, interrupted by `signal` (number `number`), must have printed one line naming
/// `output` and exited with 128 + `number`.
fn check_interrupted(child: Child, output: &Path, signal: &str, number: i32) {
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(128 + number), "{signal}: {err}");
    assert_eq!(
        err,
        format!(
            "vcsmooth: error: {}: interrupted by {signal}\n",
            output.display()
        ),
        "{signal}"
    );
}

#[test]
fn a_signal_mid_write_removes_the_temporary_file_and_keeps_the_previous_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("big.ply");
    generate_sphere(&input, 8, None, None); // a 25 MB output: written over tens of milliseconds
    let output = d.join("out.ply");
    for (signal, number) in [("INT", 2), ("TERM", 15), ("HUP", 1)] {
        let mut interrupted = false;
        // A loaded machine may finish the write before the signal lands: then try again.
        for _ in 0..5 {
            std::fs::write(&output, PREVIOUS).unwrap();
            let mut child = spawn_smooth(&input, &output, &["--iterations", "0"]);
            if !wait_for(&mut child, || temp_bytes(d).is_some_and(|b| b > 0)) {
                ok(child.wait_with_output().unwrap());
                continue;
            }
            send(&child, signal);
            let out = child.wait_with_output().unwrap();
            if out.status.success() {
                continue; // the rename came first: a complete output, nothing to check here
            }
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(128 + number), "SIG{signal}: {err}");
            assert_eq!(
                err,
                format!(
                    "vcsmooth: error: {}: interrupted by SIG{signal}\n",
                    output.display()
                )
            );
            assert_eq!(std::fs::read(&output).unwrap(), PREVIOUS, "SIG{signal}");
            assert_eq!(listing(d), ["big.ply", "out.ply"], "SIG{signal}");
            interrupted = true;
            break;
        }
        assert!(
            interrupted,
            "SIG{signal} never landed while the output was written"
        );
    }
}

#[test]
fn a_signal_ends_the_run_also_when_stderr_is_gone() {
    // A job whose log reader went away: the message cannot be written, the run still ends.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("in.ply");
    generate_sphere(&input, 6, None, None);
    let output = d.join("out.ply");
    let mut child = spawn_smooth(&input, &output, &["--iterations", "100000"]);
    drop(child.stderr.take());
    std::thread::sleep(Duration::from_millis(300));
    send(&child, "TERM");
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if start.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            child.wait().unwrap();
            break None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    assert_eq!(status.and_then(|s| s.code()), Some(143), "{status:?}");
    assert_eq!(listing(d), ["in.ply"]);
}

#[test]
fn a_signal_ignored_from_the_start_stays_ignored() {
    // As under `nohup`: SIGHUP is ignored before vcsmooth starts; the run goes on and completes.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("in.ply");
    generate_sphere(&input, 6, None, None);
    let output = d.join("out.ply");
    let mut child = Command::new("sh")
        .args(["-c", "trap '' HUP; exec \"$0\" \"$@\"", BIN, "smooth"])
        .arg(&input)
        .arg(&output)
        .args(["--iterations", "200"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let finished = child.try_wait().unwrap();
    assert!(finished.is_none(), "ended before the signal: {finished:?}");
    send(&child, "HUP");
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(output.is_file());
}

#[test]
fn a_signal_while_smoothing_with_scratch_files_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("in.ply");
    generate_sphere(&input, 8, None, None); // 25 MB: does not fit a budget of 64 MiB in core
    let scratch = d.join("scratch");
    std::fs::create_dir(&scratch).unwrap();
    let output = d.join("out.ply");
    std::fs::write(&output, PREVIOUS).unwrap();
    // Records of 30,000 iterations fit the budget (they count against it); the run lasts minutes.
    let args = [
        "--iterations",
        "30000",
        "--memory-budget",
        "64M",
        "--scratch",
        scratch.to_str().unwrap(),
    ];
    let mut child = spawn_smooth(&input, &output, &args);
    // Smoothing has begun once the process has mapped its scratch files.
    let maps = format!("/proc/{}/maps", child.id());
    let mapped = || {
        std::fs::read_to_string(&maps).is_ok_and(|m| m.contains(".vcsmooth-scratch-"))
            || !Path::new("/proc/self").exists()
    };
    assert!(wait_for(&mut child, mapped), "the run ended by itself");
    std::thread::sleep(Duration::from_millis(100));
    send(&child, "TERM");
    check_interrupted(child, &output, "SIGTERM", 15);
    assert_eq!(std::fs::read(&output).unwrap(), PREVIOUS);
    assert_eq!(listing(d), ["in.ply", "out.ply", "scratch"]);
    assert!(listing(&scratch).is_empty(), "{:?}", listing(&scratch));
}

#[test]
fn leftovers_of_gone_processes_are_removed_and_those_of_running_ones_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("in.ply");
    generate_sphere(&input, 2, None, None);
    // A process that is gone, and one that runs (as a concurrent run of the same target would).
    let mut gone = Command::new("true").spawn().unwrap();
    let gone_pid = gone.id();
    gone.wait().unwrap();
    let mut running = Command::new("sleep").arg("60").spawn().unwrap();
    let stale = format!(".out.ply.tmp-{gone_pid}-0");
    let live = format!(".out.ply.tmp-{}-3", running.id());
    let other = format!(".other.ply.tmp-{gone_pid}-0"); // another target's: not this run's business
    for name in [&stale, &live, &other] {
        std::fs::write(d.join(name), b"partial").unwrap();
    }
    let output = d.join("out.ply");
    let result = vcsmooth([
        "smooth".as_ref(),
        input.as_os_str(),
        output.as_os_str(),
        "--iterations".as_ref(),
        "1".as_ref(),
    ]);
    running.kill().unwrap();
    running.wait().unwrap();
    ok(result);
    let mut expected = vec![live.clone(), other, "in.ply".into(), "out.ply".into()];
    if !Path::new("/proc/self").exists() {
        expected.push(stale); // nothing tells that a process is gone: kept
    }
    expected.sort();
    assert_eq!(listing(d), expected);
    assert_eq!(std::fs::read(d.join(&live)).unwrap(), b"partial");
}

#[test]
fn two_concurrent_runs_to_one_target_both_succeed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let input = d.join("in.ply");
    generate_sphere(&input, 7, None, None);
    let output = d.join("out.ply");
    let runs: Vec<Child> = (0..2)
        .map(|_| spawn_smooth(&input, &output, &["--iterations", "0"]))
        .collect();
    for child in runs {
        let out = child.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    assert_eq!(listing(d), ["in.ply", "out.ply"]);
    assert_eq!(
        vcsmooth::io::read_mesh(&output).unwrap().triangles,
        vcsmooth::io::read_mesh(&input).unwrap().triangles
    );
}
