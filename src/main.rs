//! The `vcsmooth` binary: all of the command line lives in [`vcsmooth::cli`].

use std::process::ExitCode;

fn main() -> ExitCode {
    vcsmooth::cli::main_with(std::env::args_os())
}
