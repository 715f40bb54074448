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
    if output_format(path).is_none() {
        let what = match path.extension() {
            Some(e) => format!("unknown output format '.{}'", e.to_string_lossy()),
            None => "output file has no extension".to_string(),
        };
        return Err(Error::invalid(
            path,
            format!("{what} (expected .ply, .obj, .off or .stl)"),
        ));
    }
    parent_exists(path)
}

/// [`mesh_output`] in the words of `subdivide` and `refine`.
pub fn refined_mesh_output(path: &Path) -> Result<()> {
    if output_format(path).is_none() {
        return Err(Error::invalid(
            path,
            "unknown or missing output format (expected .ply, .obj, .off or .stl)",
        ));
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

/// Check that the directory `path` would be created in exists.
pub fn parent_exists(path: &Path) -> Result<()> {
    if path.as_os_str().is_empty() {
        return Err(Error::Usage {
            what: "an output file name is empty".into(),
        });
    }
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() && !dir.is_dir() => Err(Error::invalid(
            path,
            format!("directory '{}' does not exist", dir.display()),
        )),
        _ => Ok(()),
    }
}

/// Write `bytes` to `path` through a temporary file beside it, renamed into place when complete:
/// a reader never sees a half-written file under `path`, and a failure leaves no file behind.
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
