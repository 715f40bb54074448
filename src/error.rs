//! The library's error type: one variant per kind of failure (invalid input, topology, parameter,
//! I/O, resource, …), each carrying enough context for a one-line message that names the file and
//! the problem.
//!
//! Messages use the library's own vocabulary: a parameter is named as in the options structs
//! (`patch_size`, `memory_budget`, …), never as a command-line flag. The command line renders
//! [`Error::Parameter`] with its flags (`crate::cli::flags`).

use std::path::PathBuf;

/// Everything that can go wrong in vcsmooth's library code.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file is malformed or unsupported: its content (`what` names the element and the offset or
    /// line), or for an output its name (an unknown extension).
    #[error("{}: {what}", path.display())]
    InvalidInput { path: PathBuf, what: String },
    /// Connectivity the engine cannot handle: more vertices or triangles than 32-bit ids address,
    /// a triangle that indexes a vertex that does not exist, arrays of mismatched sizes, two meshes
    /// that should share their triangles but do not. `path` names the mesh once it is known (see
    /// [`Error::in_file`]).
    #[error("{}{what}", file_prefix(path.as_deref()))]
    Topology { path: Option<PathBuf>, what: String },
    /// A parameter out of its range, or one that does not fit the others. `name` is the library's
    /// name of the parameter (the field of the options struct: `patch_size`, `iterations`, …);
    /// `problem` follows it and says what is allowed, e.g. `must be at least 1`.
    #[error("{name} {problem}")]
    Parameter { name: &'static str, problem: String },
    /// The operating system refused a read, write, rename or map.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Not enough of a resource: memory, disk space, address space, threads.
    #[error("{what}")]
    Resource { what: String },
    /// Work that was not all done: inputs of a batch that failed or have no result. Each failure
    /// was reported on its own; this is the summary.
    #[error("{what}")]
    Incomplete { what: String },
    /// Work of which `failed` parts failed, each reported on its own line already (and counted in
    /// the command's own summary on stdout): nothing more to print, only the exit status.
    #[error("{failed} failed")]
    Reported { failed: usize },
    /// Another rank of a cluster run failed (and reports its own error); `what` says at which step.
    #[error("{what}")]
    Peer { what: String },
    /// The error of one rank of a cluster run.
    #[error("rank {rank}: {source}")]
    Rank {
        rank: usize,
        #[source]
        source: Box<Error>,
    },
    /// The run was stopped by its observer ([`crate::engine::Observer::interrupted`]) before it
    /// wrote anything.
    #[error("interrupted")]
    Interrupted,
    /// Not a failure: work that was all done and written, whose vertices lie beyond the tolerance
    /// it was asked to check (`what` says how many and the largest). The command line exits with
    /// its own code for it.
    #[error("{what}")]
    Tolerance { what: String },
    /// A command line that asks for something impossible, in words the command line chose (its
    /// flags and arguments). Raised only by [`crate::cli`].
    #[error("{what}")]
    Usage { what: String },
}

/// `"<path>: "`, or nothing without a path.
fn file_prefix(path: Option<&std::path::Path>) -> String {
    path.map(|p| format!("{}: ", p.display()))
        .unwrap_or_default()
}

impl Error {
    /// Shorthand for [`Error::InvalidInput`].
    pub fn invalid(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        Error::InvalidInput {
            path: path.into(),
            what: what.into(),
        }
    }
    /// Shorthand for [`Error::Topology`] (with no file yet: see [`Error::in_file`]).
    pub fn topology(what: impl Into<String>) -> Self {
        Error::Topology {
            path: None,
            what: what.into(),
        }
    }

    /// Shorthand for [`Error::Parameter`]: `name` as in the options struct, `problem` following it.
    pub fn parameter(name: &'static str, problem: impl Into<String>) -> Self {
        Error::Parameter {
            name,
            problem: problem.into(),
        }
    }

    /// Shorthand for [`Error::Resource`].
    pub fn resource(what: impl Into<String>) -> Self {
        Error::Resource { what: what.into() }
    }

    /// Name `path` in an error about a mesh that names no file yet (an [`Error::Topology`] raised
    /// while working on it). Other errors are returned unchanged.
    pub fn in_file(self, path: &std::path::Path) -> Self {
        match self {
            Error::Topology { path: None, what } => Error::Topology {
                path: Some(path.to_path_buf()),
                what,
            },
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
