//! The integration tests, one binary: `cargo test --test tests` runs them all, `cargo test --test
//! tests multires::` one module. Each module tests one part of vcsmooth; `util` holds what they
//! share (running the binary, the scans of `tests/data`, generated meshes, fixtures). The tests
//! against real OpenMPI and Slurm are `tests/engines.rs`, built only with `--features mpi`.

mod util;

mod auto;
mod batch;
mod bench_cli;
mod boundary;
mod cli;
mod cluster;
mod controls;
mod denoise;
mod deviation;
mod engine;
mod fidelity;
mod golden;
mod hostile;
mod hostile_gltf;
mod hostile_scripts;
mod layout;
mod multires;
mod oracles;
mod patches;
mod pictures;
mod pins;
mod progress;
mod refine;
