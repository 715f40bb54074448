//! Atomic file output: write a temporary file beside the target, flush and sync it, then rename it
//! over the target. A crash, a kill or an error at any moment leaves either no file or the previous
//! one under the target's name, never a partial one.

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};

/// Writes `target` through `write`, atomically. On failure the temporary file is removed and an
/// existing target is left as it was.
pub(crate) fn write_atomically(
    target: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<()> {
    let (temp, file) = create_temp(target).map_err(|e| Error::io(target, e))?;
    let guard = RemoveOnDrop(Some(temp));
    let mut out = BufWriter::with_capacity(1 << 20, file);
    write(&mut out).map_err(|e| Error::io(target, e))?;
    let file = out
        .into_inner()
        .map_err(|e| Error::io(target, e.into_error()))?;
    // The data must be on disk before the rename makes it visible, or a power cut could leave a
    // renamed but empty file.
    file.sync_all().map_err(|e| Error::io(target, e))?;
    drop(file);
    let temp = guard.path();
    fs::rename(temp, target).map_err(|e| Error::io(target, e))?;
    guard.disarm();
    sync_directory(target);
    Ok(())
}

/// Creates `.<name>.tmp-<pid>-<n>` in the target's directory (the same file system, so the rename
/// is atomic), never reusing an existing file.
fn create_temp(target: &Path) -> io::Result<(PathBuf, File)> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
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
    // Each try takes a fresh number; a name can only be taken by a leftover of a killed process
    // that had our pid, so a few tries always suffice.
    let mut tries = 0;
    loop {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(name);
        temp_name.push(format!(".tmp-{}-{n}", std::process::id()));
        let temp = dir.join(temp_name);
        match OpenOptions::new().write(true).create_new(true).open(&temp) {
            Ok(file) => return Ok((temp, file)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists && tries < 100 => tries += 1,
            Err(e) => return Err(e),
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

/// Removes the temporary file unless disarmed, also when a writer panics.
struct RemoveOnDrop(Option<PathBuf>);

impl RemoveOnDrop {
    fn path(&self) -> &Path {
        self.0.as_deref().unwrap_or(Path::new(""))
    }

    fn disarm(mut self) {
        self.0 = None;
    }
}

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        if let Some(path) = &self.0 {
            let _ = fs::remove_file(path);
        }
    }
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
    fn panicking_writer_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.ply");
        let r = std::panic::catch_unwind(|| write_atomically(&target, |_| panic!("writer bug")));
        assert!(r.is_err());
        assert!(names(dir.path()).is_empty());
    }
}
