//! Atomic file output: write a temporary file beside the target, flush and sync it, then rename it
//! over the target. A crash, a kill or an error at any moment leaves either no file or the previous
//! one under the target's name, never a partial one.
//!
//! The temporary file is `.<name>.tmp-<pid>-<n>`, registered with [`crate::signals`] while it
//! exists, so that SIGINT, SIGTERM and SIGHUP remove it. What a SIGKILL or a power cut leaves is
//! removed by the next write of the same target, once the process named in it is gone.
//!
//! A path is written where it leads ([`destination`]): a symbolic link stays a link, its target
//! (at the end of the chain) is replaced atomically; a path that leads to a character device or a
//! pipe (`/dev/null`, a FIFO) is written through as a stream, and one that leads to a descriptor
//! of this process (`/dev/stdout`, `/dev/fd/N`, `/proc/self/fd/N`) is written to that descriptor,
//! after what the process wrote there. Renaming over such a path would replace the link or the
//! device node itself (as root, `/dev/stdout`). A stream cannot be staged: what fails mid-write
//! has gone out.

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

/// Where the bytes written for a path go (see the module doc).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Destination {
    /// A regular file, or nothing yet: replaced atomically at this path, the end of the path's
    /// chain of symbolic links.
    Replace(PathBuf),
    /// A character device or a pipe (or a link to one): opened and written through.
    Stream(PathBuf),
    /// An open descriptor of this process: written at its offset, which the process's own writes
    /// to it share (a reopened file would start again at 0 and overwrite them).
    Descriptor(i32),
}

/// Symbolic links followed before giving up, as the kernel's limit.
const MAX_LINKS: usize = 40;

/// Where writing `path` goes: its symbolic links followed one by one (a relative target against
/// the link's folder), up to a regular file or nothing ([`Destination::Replace`]), a character
/// device or a pipe ([`Destination::Stream`]) or a descriptor of this process
/// ([`Destination::Descriptor`]). A directory is a `Replace` that the rename refuses; a block
/// device or a socket is an error: nothing a command writes belongs there.
pub(crate) fn destination(path: &Path) -> io::Result<Destination> {
    let mut at = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        let meta = match fs::symlink_metadata(&at) {
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Destination::Replace(at)),
            m => m?,
        };
        let kind = meta.file_type();
        if kind.is_symlink() {
            if let Some(d) = magic_link(&at)? {
                return Ok(d);
            }
            let to = fs::read_link(&at)?;
            at = match at.parent() {
                Some(dir) => dir.join(to),
                None => to,
            };
            continue;
        }
        if kind.is_file() || kind.is_dir() {
            return Ok(Destination::Replace(at));
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::FileTypeExt;
            if kind.is_char_device() || kind.is_fifo() {
                return Ok(Destination::Stream(at));
            }
        }
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "leads to '{}', a block device or a socket: not a file to write",
                at.display()
            ),
        ));
    }
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        "too many levels of symbolic links",
    ))
}

/// A symbolic link of procfs is the kernel's link to an open file, not a path: its text
/// (`pipe:[123]`, or the name of a file that may since be gone) must not be followed. This
/// process's descriptors (`/proc/self/fd/N`, which `/dev/stdout` and `/dev/fd/N` lead to) are
/// written to as descriptors; another process's are opened through the kernel, as streams.
#[cfg(target_os = "linux")]
fn magic_link(link: &Path) -> io::Result<Option<Destination>> {
    let Some(folder) = link.parent().filter(|d| !d.as_os_str().is_empty()) else {
        return Ok(None);
    };
    let folder = fs::canonicalize(folder)?;
    if !folder.starts_with("/proc") {
        return Ok(None);
    }
    let own = Path::new("/proc").join(std::process::id().to_string());
    let own_fd_folder = folder == own.join("fd")
        || (folder.file_name().is_some_and(|f| f == "fd")
            && folder.parent().and_then(Path::parent) == Some(&own.join("task")));
    let fd = link
        .file_name()
        .and_then(|n| n.to_str())
        .filter(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
        .and_then(|n| n.parse::<i32>().ok());
    Ok(Some(match fd {
        Some(fd) if own_fd_folder => Destination::Descriptor(fd),
        _ => Destination::Stream(link.to_path_buf()),
    }))
}

#[cfg(not(target_os = "linux"))]
fn magic_link(_: &Path) -> io::Result<Option<Destination>> {
    Ok(None)
}

/// This process's descriptor `fd`, duplicated (the duplicate shares its offset).
#[cfg(unix)]
fn duplicate(fd: i32) -> io::Result<File> {
    use std::os::fd::BorrowedFd;
    // SAFETY: the borrow lives only for the duplication, and `fd` was just seen open under
    // /proc/self/fd; were it closed since, duplicating it fails with EBADF.
    let owned = unsafe { BorrowedFd::borrow_raw(fd) }.try_clone_to_owned()?;
    Ok(File::from(owned))
}

#[cfg(not(unix))]
fn duplicate(_: i32) -> io::Result<File> {
    Err(io::Error::from(io::ErrorKind::Unsupported))
}

/// A complete temporary file, on disk, waiting to be renamed over its target: several files that
/// belong together (a `.gltf` and its buffers) are all staged before any is committed, so that a
/// failure while writing any of them changes none. Dropped uncommitted, the file is removed. A
/// stream (not a [`Destination::Replace`]) has no temporary file: it is written when staged.
pub(crate) struct Staged {
    /// The temporary file and the file it replaces; `None` for a stream, already written.
    pending: Option<(Temporary, PathBuf)>,
    /// The path as the caller named it, for messages.
    named: PathBuf,
}

/// Writes `write`'s bytes to a temporary file beside where `target` leads ([`destination`]),
/// synced, for [`Staged::commit`]; or through the stream it leads to.
pub(crate) fn stage(
    target: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<Staged> {
    let named = target.to_path_buf();
    let fail = |e: io::Error| Error::io(target, e);
    let file = match destination(target).map_err(fail)? {
        Destination::Replace(real) => {
            remove_stale_temps(&real);
            let (temp, file) = create_temp(&real).map_err(fail)?;
            let file = write_all(file, write).map_err(fail)?;
            // The data must be on disk before the rename makes it visible, or a power cut could
            // leave a renamed but empty file.
            file.sync_all().map_err(fail)?;
            return Ok(Staged {
                pending: Some((temp, real)),
                named,
            });
        }
        Destination::Stream(path) => OpenOptions::new()
            .write(true)
            .truncate(true)
            .open(path)
            .map_err(fail)?,
        Destination::Descriptor(fd) => duplicate(fd).map_err(fail)?,
    };
    write_all(file, write).map_err(fail)?;
    Ok(Staged {
        pending: None,
        named,
    })
}

/// `write`'s bytes into `file`, through a buffer, flushed.
fn write_all(
    file: File,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> io::Result<File> {
    let mut out = BufWriter::with_capacity(1 << 20, file);
    write(&mut out)?;
    out.into_inner().map_err(|e| e.into_error())
}

impl Staged {
    /// Renames the file over its target (a stream has nothing left to do).
    pub(crate) fn commit(self) -> Result<()> {
        let Staged { pending, named } = self;
        if let Some((temp, real)) = pending {
            temp.rename_to(&real).map_err(|e| Error::io(&named, e))?;
            sync_directory(&real);
        }
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
    use std::os::unix::fs::FileTypeExt;

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
    fn a_link_stays_a_link_and_its_target_gets_the_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        fs::create_dir(d.join("sub")).unwrap();
        fs::write(d.join("real.json"), b"old").unwrap();
        // A chain: absolute link -> relative link in another folder -> the file.
        std::os::unix::fs::symlink("../real.json", d.join("sub/rel")).unwrap();
        std::os::unix::fs::symlink(d.join("sub/rel"), d.join("abs")).unwrap();
        assert_eq!(
            destination(&d.join("abs")).unwrap(),
            Destination::Replace(d.join("sub").join("../real.json"))
        );
        write_atomically(&d.join("abs"), |w| w.write_all(b"new")).unwrap();
        assert_eq!(fs::read(d.join("real.json")).unwrap(), b"new");
        for link in ["abs", "sub/rel"] {
            assert!(fs::symlink_metadata(d.join(link)).unwrap().is_symlink());
        }
        // A dangling link: the file is made where it points.
        std::os::unix::fs::symlink("made.json", d.join("dangling")).unwrap();
        write_atomically(&d.join("dangling"), |w| w.write_all(b"made")).unwrap();
        assert_eq!(fs::read(d.join("made.json")).unwrap(), b"made");
        assert!(
            fs::symlink_metadata(d.join("dangling"))
                .unwrap()
                .is_symlink()
        );
        // A loop is an error, not a hang.
        std::os::unix::fs::symlink("b", d.join("a")).unwrap();
        std::os::unix::fs::symlink("a", d.join("b")).unwrap();
        let e = write_atomically(&d.join("a"), |w| w.write_all(b"x")).unwrap_err();
        assert!(e.to_string().contains("symbolic links"), "{e}");
    }

    #[test]
    fn devices_pipes_and_descriptors_are_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let null = d.join("null");
        std::os::unix::fs::symlink("/dev/null", &null).unwrap();
        assert_eq!(
            destination(&null).unwrap(),
            Destination::Stream("/dev/null".into())
        );
        write_atomically(&null, |w| w.write_all(b"gone")).unwrap();
        assert!(fs::symlink_metadata(&null).unwrap().is_symlink());
        assert_eq!(names(d), ["null"]);
        // A pipe, read by another thread.
        let fifo = d.join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let reader = {
                let fifo = fifo.clone();
                std::thread::spawn(move || fs::read(fifo).unwrap())
            };
            write_atomically(&fifo, |w| w.write_all(b"through")).unwrap();
            assert_eq!(reader.join().unwrap(), b"through");
            assert!(fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        }
        #[cfg(target_os = "linux")]
        {
            let out = d.join("out");
            std::os::unix::fs::symlink("/proc/self/fd/2", &out).unwrap();
            assert_eq!(destination(&out).unwrap(), Destination::Descriptor(2));
            // Written at the descriptor's offset, between what the process writes before and
            // after (a reopened file would start again at 0).
            use std::os::fd::AsRawFd;
            let mut file = File::create(d.join("log")).unwrap();
            file.write_all(b"before ").unwrap();
            let fd = file.as_raw_fd();
            let by_fd = PathBuf::from(format!("/dev/fd/{fd}"));
            assert_eq!(destination(&by_fd).unwrap(), Destination::Descriptor(fd));
            write_atomically(&by_fd, |w| w.write_all(b"report ")).unwrap();
            file.write_all(b"after").unwrap();
            assert_eq!(fs::read(d.join("log")).unwrap(), b"before report after");
            // Another process's descriptor is opened through the kernel, never followed by name.
            let other = Path::new("/proc/1/fd/1");
            if fs::symlink_metadata(other).is_ok() {
                assert_eq!(
                    destination(other).unwrap(),
                    Destination::Stream(other.into())
                );
            }
        }
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
