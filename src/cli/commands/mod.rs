//! One file per command, each in the same order: its clap arguments (`…Args`), its resolved config
//! (`…Config::from_args`, which fails before anything is read or smoothed), its `run` and its
//! output. A command file uses the shared files of [`crate::cli`], never another command's file.

pub mod batch;
pub mod bench;
pub mod compare;
pub mod curves;
pub mod demo;
pub mod generate;
pub mod info;
pub mod refine;
pub mod slurm_script;
pub mod smooth;
pub mod subdivide;
