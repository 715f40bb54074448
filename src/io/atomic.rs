//! Atomic file output: write a temporary file beside the target, flush and sync it, then rename it
//! over the target. A crash, a kill or an error at any moment leaves either no file or the previous
//! one under the target's name, never a partial one.
//!
//! The temporary file is `.<name>.tmp-<pid>-<n>`, registered with [`crate::signals`] while it
//! exists, so that SIGINT, SIGTERM and SIGHUP remove it. What a SIGKILL or a power cut leaves is
//! removed by the next write of the same target, once the process named in it is gone.

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};
use crate::signals::{self, Temporary};

/// Writes `target` through `write`, atomically. On failure the temporary file is removed and an
/// existing target is left as it was.
pub(crate) fn write_atomically(
    target: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<()> {
    stage(target, write)?.commit()
}

/// A complete temporary file, on disk, waiting to be renamed over its target: several files that
/// belong together (a `.gltf` and its buffers) are all staged before any is committed, so that a
/// failure while writing any of them changes none. Dropped uncommitted, the file is removed.
pub(crate) struct Staged {
    temp: Temporary,
    target: PathBuf,
}

/// Writes `write`'s bytes to a temporary file beside `target`, synced, for [`Staged::commit`].
pub(crate) fn stage(
    target: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<Staged> {
    remove_stale_temps(target);
    let (temp, file) = create_temp(target).map_err(|e| Error::io(target, e))?;
    let mut out = BufWriter::with_capacity(1 << 20, file);
    write(&mut out).map_err(|e| Error::io(target, e))?;
    let file = out
        .into_inner()
        .map_err(|e| Error::io(target, e.into_error()))?;
    // The data must be on disk before the rename makes it visible, or a power cut could leave a
    // renamed but empty file.
    file.sync_all().map_err(|e| Error::io(target, e))?;
    Ok(Staged {
        temp,
        target: target.to_path_buf(),
    })
}

impl Staged {
    /// Renames the file over its target.
    pub(crate) fn commit(self) -> Result<()> {
        let Staged { temp, target } = self;
        temp.rename_to(&target).map_err(|e| Error::io(&target, e))?;
        sync_directory(&target);
        Ok(())
    }
}

/// The directory and file name of `target`.
fn split(target: &Path) -> io::Result<(&Path, &std::ffi::OsStr)> {
    let name = target.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            "the output path has no file name",
        )
    })?;
    let dir = target
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    Ok((dir, name))
}

/// Creates `.<name>.tmp-<pid>-<n>` in the target's directory (the same file system, so the rename
/// is atomic), never reusing an existing file.
fn create_temp(target: &Path) -> io::Result<(Temporary, File)> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let (dir, name) = split(target)?;
    // Each try takes a fresh number; a name can only be taken by a leftover of a killed process
    // that had our pid, so a few tries always suffice.
    let mut tries = 0;
    loop {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(name);
        temp_name.push(format!(".tmp-{}-{n}", std::process::id()));
        let created = Temporary::create(dir.join(temp_name), |p| {
            OpenOptions::new().write(true).create_new(true).open(p)
        });
        match created {
            Ok(made) => return Ok(made),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists && tries < 100 => tries += 1,
            Err(e) => return Err(e),
        }
    }
}

/// The process id in `file_name` if it is a temporary file of the target named `name`
/// (`.<name>.tmp-<pid>-<n>`).
fn temp_owner(file_name: &str, name: &str) -> Option<u32> {
    let rest = file_name
        .strip_prefix('.')?
        .strip_prefix(name)?
        .strip_prefix(".tmp-")?;
    let (pid, n) = rest.split_once('-')?;
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    (digits(pid) && digits(n)).then(|| pid.parse().ok())?
}

/// Removes the temporary files of `target` left by processes that are gone (killed, or the
/// machine lost power). Best effort: a directory that cannot be listed is left alone.
fn remove_stale_temps(target: &Path) {
    let Ok((dir, name)) = split(target) else {
        return;
    };
    let (Some(name), Ok(entries)) = (name.to_str(), fs::read_dir(dir)) else {
        return;
    };
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        if let Some(pid) = file_name.to_str().and_then(|f| temp_owner(f, name)) {
            signals::remove_if_stale(&entry.path(), pid);
        }
    }
}

/// Makes the rename itself durable. Best effort: the output is complete and in place either way.
fn sync_directory(target: &Path) {
    #[cfg(unix)]
    if let Some(dir) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
        let _ = File::open(dir).and_then(|d| d.sync_all());
    }
    #[cfg(not(unix))]
    let _ = target;
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn writes_and_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.ply");
        write_atomically(&target, |w| w.write_all(b"first")).unwrap();
        write_atomically(&target, |w| w.write_all(b"second")).unwrap();
        assert_eq!(fs::read(&target).unwrap(), b"second");
        assert_eq!(names(dir.path()), ["out.ply"]);
    }

    #[test]
    fn failure_mid_write_leaves_nothing_and_keeps_the_old_target() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.ply");
        let fail = |w: &mut BufWriter<File>| {
            w.write_all(&[7; 3 << 20])?; // past the buffer: bytes reach the temporary file
            Err(io::Error::other("disk full (injected)"))
        };
        let e = write_atomically(&target, fail).unwrap_err();
        assert!(e.to_string().contains("disk full (injected)"), "{e}");
        assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));

        fs::write(&target, b"previous").unwrap();
        write_atomically(&target, fail).unwrap_err();
        assert_eq!(fs::read(&target).unwrap(), b"previous");
        assert_eq!(names(dir.path()), ["out.ply"]);
    }

    #[test]
    fn failed_rename_removes_the_temporary_file() {
        // A directory in the target's place makes the final rename fail after a complete write.
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.ply");
        fs::create_dir(&target).unwrap();
        write_atomically(&target, |w| w.write_all(b"data")).unwrap_err();
        assert_eq!(names(dir.path()), ["out.ply"]);
        assert!(target.is_dir());
    }

    #[test]
    fn temp_names_are_recognised() {
        assert_eq!(temp_owner(".out.ply.tmp-123-4", "out.ply"), Some(123));
        assert_eq!(temp_owner(".out.ply.tmp-123-", "out.ply"), None);
        assert_eq!(temp_owner(".out.ply.tmp-x-4", "out.ply"), None);
        assert_eq!(temp_owner(".out.ply.tmp-1-4", "out.obj"), None);
        assert_eq!(temp_owner("out.ply.tmp-1-4", "out.ply"), None);
    }

    #[test]
    fn leftovers_of_gone_processes_are_removed_and_others_kept() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.ply");
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let gone = child.id();
        child.wait().unwrap();
        let parent = std::os::unix::process::parent_id();
        let temps = [
            format!(".out.ply.tmp-{gone}-0"),
            format!(".out.ply.tmp-{parent}-0"),
            format!(".other.ply.tmp-{gone}-0"),
        ];
        for t in &temps {
            fs::write(dir.path().join(t), b"partial").unwrap();
        }
        write_atomically(&target, |w| w.write_all(b"new")).unwrap();
        let mut left = vec![temps[1].clone(), temps[2].clone(), "out.ply".to_string()];
        if !Path::new("/proc/self").exists() {
            left.push(temps[0].clone()); // nothing tells that a process is gone
        }
        left.sort();
        assert_eq!(names(dir.path()), left);
    }

    #[test]
    fn panicking_writer_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.ply");
        let r = std::panic::catch_unwind(|| write_atomically(&target, |_| panic!("writer bug")));
        assert!(r.is_err());
        assert!(names(dir.path()).is_empty());
    }
}
