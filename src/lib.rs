//! # vcsmooth
//!
//! Volume-constrained smoothing of very large triangle meshes, after Liu, Tang, Lu, Wang and Zheng,
//! "A novel volume constrained smoothing method for meshes", Graphical Models 64 (2002).
//!
//! Data flows one way: [`io`] reads a [`mesh::Mesh`] → [`topology::Topology`] builds CSR adjacency and
//! the fixed-vertex mask → [`smooth`] kernels move positions (pure functions over slices) →
//! [`io`] writes atomically → [`metrics`] report volume, area and per-iteration statistics.
//! [`driver`] is the one place that wires them together; [`cluster`] spreads the same patches over
//! MPI ranks, with checkpoints.

pub mod cli;
pub mod cluster;
pub mod engine;
pub mod error;
pub mod io;
pub mod mesh;
pub mod metrics;
pub mod modes;
pub mod multires;
pub mod partition;
pub mod schedule;
pub mod smooth;
pub mod topology;

pub use error::{Error, Result};
pub use mesh::Mesh;
pub use smooth::{Method, Options};
pub use topology::Topology;
