//! Modes built on the engine: many files as one share of a job array ([`batch`]), throughput on
//! generated meshes ([`mod@bench`]), and the paper's subdivide-and-smooth workflow ([`refine`]).

pub mod batch;
pub mod bench;
pub mod refine;
