//! Writing the CLI's own files (JSON reports, SVG plots) atomically, and printing to stdout.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Write `bytes` to `path` through a temporary file beside it, renamed into place when complete:
/// a reader never sees a half-written file under `path`, and a failure leaves no file behind.
pub fn atomic_write(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = fs::remove_file(&tmp);
        Error::io(path, e)
    })
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

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

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
