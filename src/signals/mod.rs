//! Temporary files that must not outlive the process, and the termination signals that would
//! otherwise leave them behind.
//!
//! Every temporary file vcsmooth creates (an atomic write's `.<name>.tmp-<pid>-<n>`, a scratch
//! file in the moment before it is unlinked) is a [`Temporary`]: its path is in a process-wide
//! registry from its creation until it is renamed into place or removed. [`remove_on_signals`]
//! (the command line calls it once, at start) starts a thread that waits for SIGINT (Ctrl-C),
//! SIGTERM (Slurm's time limit, `scancel`, `kill`) or SIGHUP (a closed terminal); on the first
//! one it removes every registered file, reports the signal and exits with 128 + its number, the
//! status a shell gives a process killed by it. A signal the process inherited as ignored (SIGHUP
//! under `nohup`) stays ignored.
//!
//! Creating, renaming and removing a registered file happen under the registry's lock, and the
//! signal thread takes that lock for good before it removes anything: every temporary file that
//! exists is registered, and none is created or renamed once the cleanup has begun, so an
//! interrupted write leaves the previous target and no temporary file.
//!
//! SIGKILL cannot be caught: what it leaves is found by the next write of the same target, which
//! removes the temporary files of processes that are gone ([`remove_if_stale`]). Files meant to
//! survive an interruption (a cluster run's checkpoints) are never registered.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// The registered temporary files of this process.
static REGISTRY: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The registry, also after a panic elsewhere (its list stays valid: every change is one push or
/// one removal).
fn registry() -> MutexGuard<'static, Vec<PathBuf>> {
    REGISTRY.lock().unwrap_or_else(|e| e.into_inner())
}

/// The file the process is working on (a run's output, a batch's current input), named by the
/// line that reports an interruption.
static SUBJECT: Mutex<Option<PathBuf>> = Mutex::new(None);

/// Name `path` as the file the process is working on from now on (`None`: no file).
pub fn set_subject(path: Option<&Path>) {
    *SUBJECT.lock().unwrap_or_else(|e| e.into_inner()) = path.map(Path::to_path_buf);
}

/// The file named by [`set_subject`] last.
pub fn subject() -> Option<PathBuf> {
    SUBJECT.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// A registered temporary file: removed when dropped, unless it was renamed into place.
#[derive(Debug)]
pub struct Temporary(Option<PathBuf>);

impl Temporary {
    /// Creates the file `path` through `create` (which must create it, e.g. with `create_new`)
    /// and registers it, in one step under the registry's lock.
    pub fn create<T>(
        path: PathBuf,
        create: impl FnOnce(&Path) -> io::Result<T>,
    ) -> io::Result<(Temporary, T)> {
        let mut registry = registry();
        let made = create(&path)?;
        registry.push(path.clone());
        Ok((Temporary(Some(path)), made))
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        self.0.as_deref().unwrap_or(Path::new(""))
    }

    /// Renames the file to `target` and forgets it. On failure the file is removed.
    pub fn rename_to(mut self, target: &Path) -> io::Result<()> {
        let Some(path) = self.0.take() else {
            return Ok(());
        };
        let mut registry = registry();
        match fs::rename(&path, target) {
            Ok(()) => {
                registry.retain(|p| *p != path);
                Ok(())
            }
            Err(e) => {
                drop(registry);
                self.0 = Some(path); // removed by `drop`
                Err(e)
            }
        }
    }

    /// Removes the file now (an open handle or a mapping keeps its data alive).
    pub fn remove(mut self) -> io::Result<()> {
        match self.0.take() {
            Some(path) => remove_registered(&path),
            None => Ok(()),
        }
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        if let Some(path) = self.0.take() {
            let _ = remove_registered(&path);
        }
    }
}

fn remove_registered(path: &Path) -> io::Result<()> {
    let mut registry = registry();
    registry.retain(|p| p != path);
    fs::remove_file(path)
}

/// Removes `path`, a temporary file created by process `pid`, if that process is gone (for this
/// process's own id: if the file is not one of its registered files, so a leftover of an earlier
/// process that had the same id). Returns whether it was removed. A file of a process that may be
/// running is never removed: two runs writing the same target do not disturb each other.
pub fn remove_if_stale(path: &Path, pid: u32) -> bool {
    // Under the lock, so that a file of this process is not registered or renamed meanwhile.
    let registry = registry();
    let stale = if pid == std::process::id() {
        !registry.iter().any(|p| p == path)
    } else {
        !may_be_running(pid)
    };
    stale && fs::remove_file(path).is_ok()
}

/// Whether process `pid` may be running on this machine; `false` only when it certainly is not.
/// Read from `/proc`; where there is none, every process may be running.
fn may_be_running(pid: u32) -> bool {
    let proc = Path::new("/proc");
    if pid == 0 || !proc.join("self").exists() {
        return true;
    }
    proc.join(pid.to_string()).exists()
}

/// The signals this process inherited as ignored, as a mask (bit `n - 1` for signal `n`): the
/// `SigIgn` line of `/proc/self/status`; none where there is no `/proc`.
#[cfg(unix)]
fn inherited_ignored() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigIgn:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .unwrap_or(0)
}

/// The name of a signal this module handles.
#[cfg(unix)]
fn signal_name(signal: i32) -> &'static str {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    match signal {
        SIGINT => "SIGINT",
        SIGTERM => "SIGTERM",
        SIGHUP => "SIGHUP",
        _ => "a signal",
    }
}

/// From now on, SIGINT, SIGTERM and SIGHUP remove the registered temporary files, call `report`
/// with the signal's name (`"SIGTERM"`), and end the process with status 128 + the signal's
/// number. `report` should not panic (it runs on its own thread, under the panic hook; the
/// process ends either way). Further calls do nothing. Does nothing where there are no such
/// signals.
///
/// # Errors
/// The signals or the thread waiting for them could not be set up; they keep their default
/// action (the process ends without removing anything).
pub fn remove_on_signals(report: fn(&str)) -> io::Result<()> {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        use signal_hook::iterator::Signals;
        static STARTED: Mutex<bool> = Mutex::new(false);
        let mut started = STARTED.lock().unwrap_or_else(|e| e.into_inner());
        if *started {
            return Ok(());
        }
        // A signal ignored from the start stays ignored: `nohup` ignores SIGHUP, and a shell
        // ignores SIGINT in its background jobs.
        let ignored = inherited_ignored();
        let wanted: Vec<i32> = [SIGINT, SIGTERM, SIGHUP]
            .into_iter()
            .filter(|&s| ignored & (1 << (s - 1)) == 0)
            .collect();
        let mut signals = Signals::new(wanted)?;
        std::thread::Builder::new()
            .name("vcsmooth-signals".into())
            .spawn(move || {
                if let Some(signal) = signals.forever().next() {
                    // Held until the process ends: no temporary file is created or renamed from
                    // here on.
                    let registry = registry();
                    for path in registry.iter() {
                        let _ = fs::remove_file(path);
                    }
                    // Whatever `report` does (a write to a closed stderr panics in `eprintln!`),
                    // the process ends.
                    let _ = std::panic::catch_unwind(|| report(signal_name(signal)));
                    std::process::exit(128 + signal);
                }
            })?;
        *started = true;
    }
    #[cfg(not(unix))]
    let _ = report;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn registered(path: &Path) -> bool {
        registry().iter().any(|p| p == path)
    }

    fn create(path: &Path) -> Temporary {
        let (t, ()) = Temporary::create(path.to_path_buf(), |p| fs::write(p, b"x")).unwrap();
        t
    }

    #[test]
    fn registered_from_creation_until_renamed_or_removed() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b, target) = (
            dir.path().join("a"),
            dir.path().join("b"),
            dir.path().join("target"),
        );
        let t = create(&a);
        assert!(registered(&a) && a.exists());
        t.rename_to(&target).unwrap();
        assert!(!registered(&a) && !a.exists() && target.exists());

        let t = create(&b);
        assert!(registered(&b));
        t.remove().unwrap();
        assert!(!registered(&b) && !b.exists());

        // Dropped: removed; a failed creation registers nothing.
        drop(create(&a));
        assert!(!registered(&a) && !a.exists());
        let e = Temporary::create(dir.path().join("no/such/dir"), |p| fs::write(p, b"x"));
        assert!(e.is_err() && !registry().iter().any(|p| p.starts_with(dir.path())));
    }

    #[test]
    fn a_failed_rename_removes_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a");
        let t = create(&a);
        t.rename_to(&dir.path().join("missing/target")).unwrap_err();
        assert!(!registered(&a) && !a.exists());
    }

    #[test]
    fn only_files_of_gone_processes_are_stale() {
        let dir = tempfile::tempdir().unwrap();
        let own = std::process::id();
        // Ours and registered: kept; ours but unregistered (an earlier process with our id): removed.
        let live = create(&dir.path().join("live"));
        assert!(!remove_if_stale(live.path(), own));
        assert!(live.path().exists());
        let leftover = dir.path().join("leftover");
        fs::write(&leftover, b"x").unwrap();
        assert!(remove_if_stale(&leftover, own));
        assert!(!leftover.exists());
        // Another running process's (our parent's): kept.
        let parent = dir.path().join("parent");
        fs::write(&parent, b"x").unwrap();
        assert!(!remove_if_stale(
            &parent,
            std::os::unix::process::parent_id()
        ));
        assert!(parent.exists());
        // A process that is gone: removed, where /proc tells.
        if Path::new("/proc/self").exists() {
            let mut child = std::process::Command::new("true").spawn().unwrap();
            let pid = child.id();
            child.wait().unwrap();
            let gone = dir.path().join("gone");
            fs::write(&gone, b"x").unwrap();
            assert!(remove_if_stale(&gone, pid));
        }
    }
}
