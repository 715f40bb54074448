//! The CLI's own files and streams: checks that an output can be written (before anything is
//! read or smoothed), JSON reports and SVG plots written atomically, results printed to stdout and
//! errors to stderr as one line.

use std::io::Write;
use std::path::Path;

use crate::error::{Error, Result};
use crate::io::Format;

/// The mesh format written for `path`, from its extension (case-insensitive), as the writer sees it.
pub fn output_format(path: &Path) -> Option<Format> {
    Format::from_extension(path)
}

/// Check that a mesh can be written to `path`: known extension, existing directory.
pub fn mesh_output(path: &Path) -> Result<()> {
    match output_format(path) {
        None => {
            let what = match path.extension() {
                Some(e) => format!("unknown output format '.{}'", e.to_string_lossy()),
                None => "output file has no extension".to_string(),
            };
            return Err(Error::invalid(
                path,
                format!(
                    "{what} (expected .ply, .obj, .off, .stl, .gltf or .glb; .gz after the first \
                     four compresses)"
                ),
            ));
        }
        Some(format) => {
            if let Some(why) = crate::io::refused_output(format, path) {
                return Err(Error::invalid(path, why));
            }
        }
    }
    parent_exists(path)
}

/// Check that a plot can be written to `path`: `.svg`, existing directory.
pub fn svg_output(path: &Path) -> Result<()> {
    let ok = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    if !ok {
        return Err(Error::invalid(
            path,
            "plots are written as SVG: the file name must end in .svg",
        ));
    }
    parent_exists(path)
}

/// Check that a picture can be written to `path`: `.png`, existing directory.
pub fn png_output(path: &Path) -> Result<()> {
    let ok = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !ok {
        return Err(Error::invalid(
            path,
            "pictures are written as PNG: the file name must end in .png",
        ));
    }
    parent_exists(path)
}

/// Check that the directory `path` would be created in exists (and is a directory).
pub fn parent_exists(path: &Path) -> Result<()> {
    if path.as_os_str().is_empty() {
        return Err(Error::Usage {
            what: "an output file name is empty".into(),
        });
    }
    match path.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(dir) => match std::fs::metadata(dir) {
            Ok(m) if m.is_dir() => Ok(()),
            Ok(_) => Err(Error::invalid(
                path,
                format!("'{}' is not a directory", dir.display()),
            )),
            Err(_) => Err(Error::invalid(
                path,
                format!("directory '{}' does not exist", dir.display()),
            )),
        },
        None => Ok(()),
    }
}

/// A file a command reads or writes, with the flag or argument that names it (`IN`, `OUT`,
/// `--report`, …), for [`check_files`].
pub type Named<'a> = (&'a str, &'a Path);

/// Check, before anything is read or smoothed, every file a command will write: `output` (if any) and
/// its side files (`sides`: reports, plots). Each can be written (see [`writable`]); no side file
/// is one of the files the command reads (`reads`), the output or another side file. The output
/// itself may be an input: it replaces the file atomically, which is how a file is smoothed in
/// place. "The same" is decided by identity: device and inode when the file exists (which also
/// catches hard links, symbolic links and spellings such as `./a/../x.ply`), else the absolute
/// path with `.`, `..` and the symbolic links of its existing part resolved. The error names the
/// flag of the file that would be overwritten.
pub fn check_files(reads: &[Named], output: Option<Named>, sides: &[Named]) -> Result<()> {
    let mut taken: Vec<(String, Identity)> = reads
        .iter()
        .map(|&(n, p)| (n.to_string(), Identity::of(p)))
        .collect();
    // A glTF's external buffers and images are read too, and must survive the run.
    let named: Vec<(String, std::path::PathBuf)> = reads
        .iter()
        .flat_map(|&(n, p)| {
            crate::io::referenced_files(p)
                .into_iter()
                .map(move |f| (format!("a file {n} names"), f))
        })
        .collect();
    if let Some((name, path)) = output {
        let id = Identity::of(path);
        if let Some((other, _)) = named.iter().find(|(_, f)| Identity::of(f) == id) {
            return Err(Error::invalid(
                path,
                format!("{name} names the same file as {other}: it would be overwritten"),
            ));
        }
        taken.push((name.to_string(), id));
    }
    taken.extend(named.iter().map(|(n, f)| (n.clone(), Identity::of(f))));
    for &(name, path) in sides {
        let id = Identity::of(path);
        if let Some((other, _)) = taken.iter().find(|(_, t)| *t == id) {
            return Err(Error::invalid(
                path,
                format!("{name} names the same file as {other}: it would be overwritten"),
            ));
        }
        if let (Some((out, out_path)), Some(file)) = (output, path.file_name())
            && crate::io::buffer_name_of(out_path, file)
            && Identity::of(&out_path.with_file_name(file)) == id
        {
            return Err(Error::invalid(
                path,
                format!("{name} names a file the buffers of {out} may be written to"),
            ));
        }
        taken.push((name.to_string(), id));
    }
    if let Some((_, path)) = output {
        writable(path)?;
    }
    for (_, path) in sides {
        side_writable(path)?;
    }
    Ok(())
}

/// Check, before any work, the directory a run keeps its work in (`--checkpoint DIR`, named
/// `dir`) against every file the command reads or writes (`files`), by the identity of
/// [`check_files`]: neither the directory nor a missing folder above it that the run would create
/// is one of those files (a directory would take its place), and none of them is a file the run
/// keeps in it ([`crate::cluster::store::FILES`]); the directory exists as one or can be created.
pub fn check_work_dir(dir: Named, files: &[Named]) -> Result<()> {
    let (flag, dir) = dir;
    let absolute = std::path::absolute(dir).map_err(|e| Error::io(dir, e))?;
    // The directory, then each folder above it, up to the first that exists.
    for (k, folder) in absolute.ancestors().enumerate() {
        let id = Identity::of(folder);
        if let Some((name, _)) = files.iter().find(|(_, f)| Identity::of(f) == id) {
            let what = match k {
                0 => format!("{flag} names the same path as {name}"),
                _ => format!("{flag} is inside {name}"),
            };
            return Err(Error::invalid(
                dir,
                format!("{what}: the work directory would take its place"),
            ));
        }
        match std::fs::metadata(folder) {
            Ok(m) if m.is_dir() => break,
            Ok(_) if k == 0 => {
                return Err(Error::invalid(
                    dir,
                    format!("{flag} exists and is not a directory"),
                ));
            }
            Ok(_) => {
                return Err(Error::invalid(
                    dir,
                    format!(
                        "{flag} cannot be made: '{}' is not a directory",
                        folder.display()
                    ),
                ));
            }
            Err(_) => {}
        }
    }
    let id = Identity::of(&absolute);
    for &(name, path) in files {
        let inside = path
            .file_name()
            .and_then(|f| f.to_str())
            .is_some_and(|f| crate::cluster::store::FILES.contains(&f))
            && Identity::of(folder(path)) == id;
        if inside {
            return Err(Error::invalid(
                path,
                format!("{name} names a file of the {flag} directory: it would be overwritten"),
            ));
        }
    }
    Ok(())
}

/// The folder a file `path` is in (`.` for a bare name).
fn folder(path: &Path) -> &Path {
    path.parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// What makes two paths the same file (see [`check_files`]).
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Identity {
    /// Device and inode of an existing file.
    Inode(u64, u64),
    /// The resolved absolute path of a file that does not exist (yet).
    Path(std::path::PathBuf),
}

impl Identity {
    pub(crate) fn of(path: &Path) -> Identity {
        #[cfg(unix)]
        if let Ok(m) = std::fs::metadata(path) {
            use std::os::unix::fs::MetadataExt;
            return Identity::Inode(m.dev(), m.ino());
        }
        Identity::Path(resolved(path))
    }
}

/// `path` made absolute, component by component: `.` dropped, `..` removing the component before
/// it, and each prefix that exists replaced by its canonical form (its symbolic links resolved,
/// so that a later `..` leaves the real directory).
fn resolved(path: &Path) -> std::path::PathBuf {
    use std::path::Component;
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut out = std::path::PathBuf::new();
    for c in absolute.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => {
                out.push(other);
                if let Ok(real) = out.canonicalize() {
                    out = real;
                }
            }
        }
    }
    out
}

/// Check that the output `path` can be written, before any work (see `check_writable`): it is
/// replaced by renaming, so what it leads to must be a regular file or nothing yet.
pub fn writable(path: &Path) -> Result<()> {
    check_writable(path, false)
}

/// Check that the side file `path` (a report, a plot, a summary) can be written, before any work
/// (see `check_writable`): it may also lead to a character device, a pipe or a descriptor of
/// this process (`/dev/stdout`), written through as a stream.
pub fn side_writable(path: &Path) -> Result<()> {
    check_writable(path, true)
}

/// Check that a file can be written at `path`, before any work. `path` is written where it leads
/// ([`crate::io::destination`]: a symbolic link's target, a device or pipe as a stream, never
/// by replacing the link or the device node); a file there to replace must have its directory,
/// which lets us create files (tried with an empty file named as the atomic writer's temporary
/// files, `.<name>.tmp-<pid>-<n>`, removed at once), and not be a directory; a stream is refused
/// unless `stream` (an output mesh is replaced by renaming, never half-written).
fn check_writable(path: &Path, stream: bool) -> Result<()> {
    if path.as_os_str().as_encoded_bytes().ends_with(b"/") {
        return Err(Error::invalid(
            path,
            "ends with '/': it names a directory, not a file",
        ));
    }
    parent_exists(path)?;
    let real = match crate::io::destination(path).map_err(|e| Error::io(path, e))? {
        crate::io::Destination::Replace(real) => real,
        _ if stream => return Ok(()),
        _ => {
            return Err(Error::invalid(
                path,
                "exists and is not a regular file (vcsmooth replaces its output by renaming)",
            ));
        }
    };
    if real != path {
        parent_exists(&real)?;
    }
    let dir = folder(&real);
    let Some(name) = real.file_name() else {
        return Err(Error::invalid(path, "the output path names no file"));
    };
    if std::fs::metadata(&real).is_ok_and(|m| m.is_dir()) {
        return Err(Error::invalid(path, "is a directory, not a file"));
    }
    // Numbers counted down from the top, so that they never meet the atomic writer's (counted up
    // from 0) in the same process.
    for n in (0..100).map(|k| u64::MAX - k) {
        let mut probe = std::ffi::OsString::from(".");
        probe.push(name);
        probe.push(format!(".tmp-{}-{n}", std::process::id()));
        let probe = dir.join(probe);
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&probe)
        {
            Ok(_) => {
                let _ = std::fs::remove_file(&probe);
                return Ok(());
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => {
                return Err(Error::invalid(
                    path,
                    format!("cannot create files in '{}': {e}", dir.display()),
                ));
            }
        }
    }
    Ok(())
}

/// Write `bytes` to `path` through a temporary file beside it, renamed into place when complete:
/// a reader never sees a half-written file under `path`, and a failure leaves no file behind (a
/// path that leads to a stream is written through, see `io::destination`).
pub fn atomic_write(path: &Path, bytes: &[u8]) -> Result<()> {
    crate::io::write_atomically(path, |w| w.write_all(bytes))
}

/// Serialize `value` as pretty JSON (with a final newline) and write it atomically.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let mut bytes = serde_json::to_vec_pretty(value)
        .map_err(|e| Error::invalid(path, format!("cannot encode JSON: {e}")))?;
    bytes.push(b'\n');
    atomic_write(path, &bytes)
}

/// Print `value` as pretty JSON to `out`.
pub fn print_json<T: serde::Serialize>(out: &mut dyn Write, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::invalid("<stdout>", format!("cannot encode JSON: {e}")))?;
    writeln!(out, "{text}").map_err(stdout_error)
}

/// A failed write to standard output.
pub fn stdout_error(e: std::io::Error) -> Error {
    Error::io("<stdout>", e)
}

/// Standard output that a reader may close early (`vcsmooth info x.ply | head -1`): once a write
/// finds the pipe closed, that and every later write are dropped as written, so the command
/// finishes its work (its files, its exit code) quietly, as `head` expects of a producer.
pub struct ClosablePipe<W: Write> {
    inner: W,
    closed: bool,
}

impl<W: Write> ClosablePipe<W> {
    pub fn new(inner: W) -> ClosablePipe<W> {
        ClosablePipe {
            inner,
            closed: false,
        }
    }
}

impl<W: Write> Write for ClosablePipe<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.closed {
            return Ok(buf.len());
        }
        match self.inner.write(buf) {
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
                self.closed = true;
                Ok(buf.len())
            }
            r => r,
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self.closed {
            true => Ok(()),
            false => match self.inner.flush() {
                Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
                    self.closed = true;
                    Ok(())
                }
                r => r,
            },
        }
    }
}

/// Print `vcsmooth: error: <message>` on stderr, on one line.
pub fn print_error(message: &str) {
    eprintln!("vcsmooth: error: {}", one_line(message));
}

/// Collapse all whitespace runs (newlines included) into single spaces.
pub fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("r.json");
        atomic_write(&p, b"one").unwrap();
        atomic_write(&p, b"two").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"two");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
        let bad = dir.path().join("missing").join("r.json");
        let e = atomic_write(&bad, b"x").unwrap_err().to_string();
        assert!(e.contains("r.json"), "{e}");
    }
}
