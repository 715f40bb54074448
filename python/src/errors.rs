//! The library's errors as Python exceptions: `ValueError` for a bad argument, `OSError` (with
//! its errno, so `FileNotFoundError` and friends) for a file the system refused,
//! `vcsmooth.MeshError` (a `ValueError`) for a file that is not a mesh the library can read.

use pyo3::create_exception;
use pyo3::exceptions::{
    PyKeyboardInterrupt, PyMemoryError, PyOSError, PyRuntimeError, PyValueError,
};
use pyo3::prelude::*;
use vcsmooth::Error;

use crate::keywords::keyword;

create_exception!(
    vcsmooth,
    MeshError,
    PyValueError,
    "A mesh file that cannot be read (malformed, truncated, not a mesh, an unknown format), or \
     an output format that cannot be written. A ValueError; its message names the file and \
     what is wrong."
);

/// `e` as the Python exception a caller should catch.
pub fn to_py(e: Error) -> PyErr {
    match e {
        // The library names parameters as its options structs do; Python callers know them by
        // their keyword arguments (`lam`, `pinned`).
        Error::Parameter { name, problem } => {
            PyValueError::new_err(format!("{} {problem}", keyword(name)))
        }
        Error::InvalidInput { .. } => MeshError::new_err(e.to_string()),
        // Connectivity of a file (it names the file), or of arrays the caller gave.
        Error::Topology { path: Some(_), .. } => MeshError::new_err(e.to_string()),
        Error::Topology { path: None, .. } => PyValueError::new_err(e.to_string()),
        Error::Io { path, source } => match source.raw_os_error() {
            // OSError(errno, strerror, filename) becomes the matching subclass.
            Some(errno) => {
                let text = source.to_string();
                let strerror = text.split(" (os error").next().unwrap_or(&text).to_string();
                PyOSError::new_err((errno, strerror, path.display().to_string()))
            }
            None => PyOSError::new_err(format!("{}: {source}", path.display())),
        },
        Error::Resource { .. } => PyMemoryError::new_err(e.to_string()),
        Error::Interrupted => PyKeyboardInterrupt::new_err("interrupted"),
        other => PyRuntimeError::new_err(other.to_string()),
    }
}
