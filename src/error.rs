//! The library's error type: one variant per kind of failure (invalid input, I/O, configuration),
//! each carrying enough context for a one-line message that names the file and the problem.

use std::path::PathBuf;

/// Everything that can go wrong in vcsmooth's library code.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file's content is malformed or unsupported. `what` names the element and the offset or line.
    #[error("{}: {what}", path.display())]
    InvalidInput { path: PathBuf, what: String },
    /// The operating system refused a read, write, rename or map.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Options that cannot work together or are out of range (e.g. `--iterations 0` where that is refused).
    #[error("{0}")]
    Config(String),
}

impl Error {
    /// Shorthand for [`Error::InvalidInput`].
    pub fn invalid(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        Error::InvalidInput {
            path: path.into(),
            what: what.into(),
        }
    }
    /// Name `path` in an error that names no file (a [`Error::Config`] raised while working on it).
    pub fn in_file(self, path: &std::path::Path) -> Self {
        match self {
            Error::Config(what) => Error::invalid(path, what),
            other => other,
        }
    }

    /// Shorthand for [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

/// Result with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
