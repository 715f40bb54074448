//! # vcsmooth
//!
//! Smooths triangle meshes — 3D scans of millions to billions of triangles — without shrinking
//! them: the volume-constrained stencil smoothing of Liu, Tang, Lu, Wang and Zheng, "A novel
//! volume constrained smoothing method for meshes", Graphical Models 64 (2002), with the
//! default `vcs-lowpass` (Taubin's displacement, the volume restored on 2-ring stencils), and
//! Laplacian, Taubin, HC and local energy minimisation for comparison ([`smooth::Method`]).
//!
//! The front door is [`smooth()`]: a [`Mesh`] and [`Options`] (method, iterations, step sizes) in,
//! the smoothed mesh and a [`Report`] out. [`engine::run_file`] does the same from file to file
//! for meshes larger than memory.
//!
//! ## The pipeline, module by module
//! Data flows one way; each module uses only those listed before it.
//! - [`error`]: the [`Error`] kinds (invalid input, topology, parameter, I/O, resource).
//! - `signals`: temporary files registered while they exist, removed on SIGINT, SIGTERM and
//!   SIGHUP.
//! - [`meter`]: how far a long phase is, counted from its loops ([`meter::Meter`]).
//! - [`mesh`]: [`Mesh`] (positions and triangles in flat arrays, on the heap or in memory-mapped
//!   scratch files) and what a file carried besides them.
//! - [`topology`]: CSR adjacency, boundary and non-manifold masks ([`Topology`]).
//! - [`io`]: PLY (memory-mapped fast path), OBJ, OFF, STL, glTF and GLB; atomic writes. Knows
//!   nothing of smoothing.
//! - [`metrics`]: volume, area, roughness, comparisons (sequential, pure).
//! - [`shapes`]: generated test meshes (icosphere, torus, subdivision, noise along normals).
//! - [`mod@smooth`]: the kernels, pure functions over slices that run no threads and touch no files.
//! - [`partition`]: Morton reorder and patches; [`schedule`]: patch colouring and read-ahead.
//! - [`engine`]: the plan, the one iteration loop, deterministic parallel sums, the run from file
//!   to file, the memory model.
//! - [`multires`]: coarse levels smoothed with `vcs`, the fine level with Laplacian or Taubin.
//! - [`cluster`]: the same loop over MPI ranks, with checkpoints.
//! - [`render`]: pictures of a mesh drawn on the CPU (views, shading, colour maps, labels).
//! - [`report`]: the report model, what `smooth --report` and `info --json` write and Python
//!   returns.
//! - `modes`: `batch` (job arrays), `bench` (throughput), `refine` (subdivide and smooth).
//! - `cli`: the `vcsmooth` command line: flags → config → run → output.
//!
//! `signals`, `modes` and `cli` serve the `vcsmooth` binary and the Python binding; they are not
//! the library's API (hidden from its documentation, and free to change).
//!
//! Results are part of the contract: for given inputs and options the output is bit-identical for
//! any thread count and memory budget (the golden test in `tests/golden.rs` holds it).

// The CLI's doc comments are its --help text (with <placeholders>), not rustdoc.
#[doc(hidden)]
#[allow(rustdoc::invalid_html_tags)]
pub mod cli;
pub mod cluster;
pub mod engine;
pub mod error;
pub mod io;
pub mod mesh;
pub mod meter;
pub mod metrics;
#[doc(hidden)]
pub mod modes;
pub mod multires;
pub mod partition;
pub mod render;
pub mod report;
pub mod schedule;
pub mod shapes;
#[doc(hidden)]
pub mod signals;

pub mod smooth;
pub mod topology;

pub use engine::{EngineSettings, Report, smooth, smooth_with};

/// The version of the results: bumped by every change to the bytes a run writes (a release may
/// change them when a change needs it, never by accident; `CHANGELOG.md` says what changed and
/// why). Within one results version an output is the same for any thread count, memory budget
/// and rank count. Reports (`results_version`) and batch markers carry it, and a rerun of a batch
/// redoes what an earlier results version made.
pub const RESULTS_VERSION: u32 = 11;
pub use error::{Error, Result};
pub use mesh::Mesh;

pub use smooth::{Boundary, Method, Options};
pub use topology::Topology;
