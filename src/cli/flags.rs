//! The library names its parameters as its options structs do (`patch_size`, `memory_budget`, …);
//! the command line names them by their flags (`--patch-size`). This is the one place that maps
//! one to the other, and [`message`] renders an error as users see it.

use crate::error::Error;

/// Library parameter name → command-line flag. A name that is not here is shown as it is (e.g. an
/// environment variable such as `SLURM_ARRAY_TASK_ID`, or a parameter no flag sets).
pub(super) const FLAGS: &[(&str, &str)] = &[
    // Smoothing (`Options`).
    ("method", "--method"),
    ("iterations", "--iterations"),
    ("auto_stop", "--iterations auto"),
    ("lambda", "--lambda"),
    ("mu", "--mu"),
    ("crease_angle", "--crease-angle"),
    ("max_deviation", "--max-deviation"),
    ("boundary", "--boundary"),
    // Engine (`EngineSettings`) and cluster runs.
    ("threads", "--threads"),
    ("patch_size", "--patch-size"),
    ("memory_budget", "--memory-budget"),
    ("scratch", "--scratch"),
    ("checkpoint", "--checkpoint"),
    ("checkpoint_every", "--checkpoint-every"),
    // Multiresolution (`MultiresOptions`).
    ("multires", "--multires"),
    ("levels", "--levels"),
    ("coarse_iterations", "--coarse-iterations"),
    ("fine_method", "--fine-method"),
    ("transfer", "--transfer"),
    ("cell_factor", "--cell-factor"),
    // Refinement (`RefineOptions`).
    ("max_edge", "--max-edge"),
    ("rounds", "--rounds"),
    // Generated meshes.
    ("subdivisions", "--subdivisions"),
    ("subdivision_levels", "--subdivide"),
    ("noise", "--noise"),
    ("from", "--from"),
    // Reports.
    ("plot", "--plot"),
    ("stats", "--stats"),
    ("methods", "--methods"),
    ("deviation_field", "--deviation-field"),
    ("deviation_stats", "--deviation-stats"),
    ("tolerance", "--tolerance"),
    ("png", "--png"),
    // Benchmark (`BenchSettings`).
    ("sizes", "--sizes"),
    ("repeats", "--repeats"),
    ("dir", "--dir"),
    // Batch and Slurm.
    ("task_index", "--task-index"),
    ("task_count", "--task-count"),
    ("partition", "--partition"),
    ("time", "--time"),
    ("job_name", "--job-name"),
];

/// The flag that sets the library parameter `name`, if one does.
pub fn flag(name: &str) -> Option<&'static str> {
    FLAGS.iter().find(|(n, _)| *n == name).map(|(_, f)| *f)
}

/// `name`'s flag, or `name` itself when no flag sets it.
pub fn display_name(name: &str) -> &str {
    flag(name).unwrap_or(name)
}

/// The one-line message of `e` in the command line's words: a parameter is named by its flag
/// (`--patch-size must be at least 1`); every other kind reads as the library words it.
pub fn message(e: &Error) -> String {
    match e {
        Error::Parameter { name, problem } => format!("{} {problem}", display_name(name)),
        Error::Rank { rank, source } => format!("rank {rank}: {}", message(source)),
        other => other.to_string(),
    }
}

/// A parameter error raised by the command line itself, by the library name of its flag.
pub(super) fn parameter(name: &'static str, problem: impl Into<String>) -> Error {
    debug_assert!(flag(name).is_some(), "no flag for {name}");
    Error::parameter(name, problem)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameters_read_as_flags() {
        let e = Error::parameter("patch_size", "must be at least 1");
        assert_eq!(e.to_string(), "patch_size must be at least 1");
        assert_eq!(message(&e), "--patch-size must be at least 1");
        let e = Error::parameter("SLURM_ARRAY_TASK_ID", "is below SLURM_ARRAY_TASK_MIN");
        assert_eq!(message(&e), e.to_string());
        let e = Error::Rank {
            rank: 2,
            source: Box::new(Error::parameter("memory_budget", "is below the minimum")),
        };
        assert_eq!(message(&e), "rank 2: --memory-budget is below the minimum");
        let e = Error::topology("triangle 3 indexes a vertex out of range (0..3)");
        assert_eq!(message(&e), e.to_string());
    }
}
