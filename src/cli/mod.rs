//! The `vcsmooth` command line. Each command has one file in [`commands`], in three steps (after
//! ripgrep):
//!
//! 1. its clap arguments (`…Args`): raw flags, per-flag checks only;
//! 2. its config (`…Config::from_args`): the command resolved and validated — output formats known,
//!    plot files SVG, target directories present — so that a run fails before it reads or smooths
//!    anything;
//! 3. its `run`: executes the config through the library, rendering the engine's
//!    [`crate::engine::Observer`] as an indicatif progress bar ([`progress`]) when stderr is a
//!    terminal, and prints its result.
//!
//! What several commands share has one file each: the flag groups ([`shared`]; [`batch_smooth`] for
//! `batch` and `slurm-script`), `smooth`'s `--multires` flags ([`multires`]), the pictures of `--png` ([`pictures`]), the reports' pieces
//! ([`report`]), output files and streams ([`output`]), plots ([`plot`]), progress ([`progress`])
//! and flag names ([`flags`]). Command files use shared files and never each other; shared files
//! use no command file; this file only parses, dispatches and prints errors.
//!
//! [`main_with`] ties them together for the binary and returns the exit code: 0 on success, 2 for
//! usage errors (clap's, and options that resolve to nothing valid), 1 for failures at run time,
//! 3 ([`shared::EXIT_TOLERANCE`]) for a run that wrote everything but found vertices beyond its
//! `--tolerance` (one line `vcsmooth: tolerance: …` on stderr).
//! Every failure is one line on stderr, `vcsmooth: error: <file>: <problem>`; no output file, report
//! or plot is written by a run that fails before it would write them.

pub mod batch_smooth;
pub mod commands;
pub mod flags;
pub mod multires;
pub mod output;
pub mod pictures;
pub mod plot;
pub mod progress;
pub mod report;
pub mod shared;
#[cfg(test)]
mod tests;

use std::ffi::OsString;
use std::io::Write;
use std::path::Path;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use commands::{
    batch, bench, compare, curves, demo, generate, info, refine, slurm_script, smooth, subdivide,
};
use output::{one_line, print_error};
pub use progress::Progress;

use crate::error::{Error, Result};

/// vcsmooth: smooth triangle meshes without shrinking them (volume-constrained smoothing, Liu et al. 2002).
#[derive(Debug, Clone, Parser)]
#[command(name = "vcsmooth", version, about, long_about = None, propagate_version = true)]
pub struct Args {
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands. Their names and flags are a contract: scripts depend on them.
#[derive(Debug, Clone, Subcommand)]
pub enum Command {
    /// Smooth a mesh file and write the result (format chosen by OUT's extension).
    Smooth(smooth::SmoothArgs),
    /// Print vertices, faces, edges, boundary, components, volume, area, bounding box of a mesh.
    Info(info::InfoArgs),
    /// Compare two meshes with the same connectivity (distances, normals, volume and area ratios), or any two with --surface; the deviation field and a tolerance on request.
    Compare(compare::CompareArgs),
    /// Write a closed test mesh (icosphere or torus), optionally with Gaussian noise along normals.
    Generate(generate::GenerateArgs),
    /// Run several methods from the same input and plot volume % per iteration (the paper's Fig. 4).
    #[command(
        mut_arg("patch_size", |a| a.help("Vertices per patch: the stencils in the order of smooth's patches of this size [default: the input's order, the paper's sequential reference]")),
        mut_arg("memory_budget", |a| a.help("Anonymous memory allowed for the iteration records, with K/M/G/T suffixes (binary units); curves holds the mesh in memory [default: 3/4 of available memory, or of a tighter cgroup limit or rlimit]")),
        mut_arg("scratch", |a| a.hide(true)),
    )]
    Curves(curves::CurvesArgs),
    /// Smooth a generated noisy sphere with every method and print volume and roughness per method.
    Demo(demo::DemoArgs),
    /// Measure throughput on generated meshes: smoothing, plan, PLY I/O, memory (to size jobs).
    #[command(long_about = bench::BENCH_ABOUT)]
    Bench(bench::BenchArgs),
    /// Smooth many meshes as one share of a job array (Slurm's), with per-input success markers; --summary gathers them.
    Batch(batch::BatchArgs),
    /// Print a ready Slurm script: an array job running `batch` over the inputs, and a dependent summary job.
    SlurmScript(slurm_script::SlurmScriptArgs),
    /// Split triangles until no edge is longer than --max-edge (the paper's adaptive subdivision, §4).
    Subdivide(subdivide::SubdivideArgs),
    /// Alternate subdivide and vcs smoothing --rounds times (the paper's Figs. 5–7).
    Refine(refine::RefineArgs),
}

/// One resolved command.
#[derive(Debug, Clone)]
pub enum Config {
    Smooth(smooth::SmoothConfig),
    Info(info::InfoConfig),
    Compare(compare::CompareConfig),
    Generate(generate::GenerateConfig),
    Curves(curves::CurvesConfig),
    Demo(demo::DemoConfig),
    Bench(bench::BenchConfig),
    Batch(batch::BatchConfig),
    SlurmScript(slurm_script::SlurmScriptConfig),
    Subdivide(subdivide::SubdivideConfig),
    Refine(refine::RefineConfig),
}

impl Config {
    /// Resolve and validate parsed flags. `argv` is the command line, kept for reports.
    pub fn from_args(args: Args, argv: Vec<String>) -> Result<Config> {
        Ok(match args.command {
            Command::Smooth(a) => Config::Smooth(smooth::SmoothConfig::from_args(a, argv)?),
            Command::Info(a) => Config::Info(info::InfoConfig::from_args(a)?),
            Command::Compare(a) => Config::Compare(compare::CompareConfig::from_args(a)?),
            Command::Generate(a) => Config::Generate(generate::GenerateConfig::from_args(a)?),
            Command::Curves(a) => Config::Curves(curves::CurvesConfig::from_args(a)?),
            Command::Demo(a) => Config::Demo(demo::DemoConfig::from_args(a)?),
            Command::Bench(a) => Config::Bench(bench::BenchConfig::from_args(a)?),
            Command::Batch(a) => Config::Batch(batch::BatchConfig::from_args(a)?),
            Command::SlurmScript(a) => {
                Config::SlurmScript(slurm_script::SlurmScriptConfig::from_args(a)?)
            }
            Command::Subdivide(a) => Config::Subdivide(subdivide::SubdivideConfig::from_args(a)?),
            Command::Refine(a) => Config::Refine(refine::RefineConfig::from_args(a)?),
        })
    }
}
impl Config {
    /// The file a run of this command works on, named if it is interrupted: the file it writes,
    /// or the one it reads when it writes none (`batch` names each input as it goes).
    fn subject(&self) -> Option<&Path> {
        match self {
            Config::Smooth(c) => Some(&c.output),
            Config::Info(c) => Some(&c.input),
            Config::Compare(c) => Some(&c.b),
            Config::Generate(c) => Some(&c.output),
            Config::Curves(c) => Some(&c.input),
            Config::Subdivide(c) => Some(&c.output),
            Config::Refine(c) => Some(&c.output),
            Config::Demo(_) | Config::Bench(_) | Config::Batch(_) | Config::SlurmScript(_) => None,
        }
    }
}

/// Exit code of a failure at run time (unreadable input, failed write, …).
pub const EXIT_FAILURE: u8 = 1;
/// Exit code of a usage error (bad flags or option values), as clap uses.
pub const EXIT_USAGE: u8 = 2;

/// Parse `argv` (including the program name), resolve and run it; print any error as one line.
pub fn main_with<I, T>(argv: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<OsString>,
{
    install_panic_hook();
    // Without it, SIGINT, SIGTERM and SIGHUP still end the process, leaving temporary files.
    let _ = crate::signals::remove_on_signals(|signal| {
        // Not `eprintln!`: stderr may be a closed pipe, and this must not panic.
        let mut stderr = std::io::stderr();
        let _ = match crate::signals::subject() {
            Some(file) => writeln!(
                stderr,
                "vcsmooth: error: {}: interrupted by {signal}",
                file.display()
            ),
            None => writeln!(stderr, "vcsmooth: error: interrupted by {signal}"),
        };
    });
    let argv: Vec<OsString> = argv.into_iter().map(Into::into).collect();
    let args = match Args::try_parse_from(&argv) {
        Ok(args) => args,
        Err(e) => return clap_exit(e),
    };
    let argv = argv
        .iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let config = match Config::from_args(args, argv) {
        Ok(c) => c,
        Err(e) => {
            print_error(&flags::message(&e));
            return ExitCode::from(EXIT_USAGE);
        }
    };
    crate::signals::set_subject(config.subject());
    match run(&config) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Error::Reported { .. }) => ExitCode::from(EXIT_FAILURE),
        Err(Error::Tolerance { what }) => {
            let _ = writeln!(
                std::io::stderr(),
                "vcsmooth: tolerance: {}",
                one_line(&what)
            );
            ExitCode::from(shared::EXIT_TOLERANCE)
        }
        Err(e) => {
            print_error(&flags::message(&e));
            ExitCode::from(EXIT_FAILURE)
        }
    }
}

/// Run a resolved command, printing its result on stdout and progress on stderr (if a terminal).
pub fn run(config: &Config) -> Result<()> {
    let mut progress = Progress::for_stderr();
    let stdout = std::io::stdout();
    let mut out = output::ClosablePipe::new(stdout.lock());
    run_with(config, &mut progress, &mut out)
}

/// [`run`] with an explicit progress display and output stream.
pub fn run_with(
    config: &Config,
    progress: &mut Progress,
    out: &mut dyn std::io::Write,
) -> Result<()> {
    match config {
        Config::Smooth(c) => smooth::run(c, progress, out),
        Config::Info(c) => info::run(c, progress, out),
        Config::Compare(c) => compare::run(c, progress, out),
        Config::Generate(c) => generate::run(c, progress, out),
        Config::Curves(c) => curves::run(c, progress, out),
        Config::Demo(c) => demo::run(c, progress, out),
        Config::Bench(c) => bench::run(c, progress, out),
        Config::Batch(c) => batch::run(c, progress, out),
        Config::SlurmScript(c) => slurm_script::run(c, out),
        Config::Subdivide(c) => subdivide::run(c, progress, out),
        Config::Refine(c) => refine::run(c, progress, out),
    }
}

/// Help and version go to stdout with exit 0; a usage error becomes one line with exit 2.
fn clap_exit(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    match e.kind() {
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
            let _ = e.print();
            ExitCode::SUCCESS
        }
        ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            let _ = e.print();
            ExitCode::from(EXIT_USAGE)
        }
        _ => {
            print_error(&clap_message(&e.to_string()));
            ExitCode::from(EXIT_USAGE)
        }
    }
}

/// The first paragraph of clap's error text, without its `error: ` prefix.
fn clap_message(rendered: &str) -> String {
    let first = rendered.split("\n\n").next().unwrap_or(rendered).trim();
    let first = first.strip_prefix("error:").unwrap_or(first).trim();
    format!("{} (see 'vcsmooth --help')", one_line(first))
}

/// A panic is a bug, never the way bad input is reported; still, keep it to one line on stderr
/// (set `RUST_BACKTRACE` to get Rust's default report with a backtrace).
fn install_panic_hook() {
    if std::env::var_os("RUST_BACKTRACE").is_some() {
        return;
    }
    std::panic::set_hook(Box::new(|info| {
        eprintln!(
            "vcsmooth: error: internal error (a bug, please report it): {}",
            one_line(&panic_message(info))
        );
    }));
}

/// A panic's message and where it was raised.
pub(crate) fn panic_message(info: &std::panic::PanicHookInfo) -> String {
    let what = info
        .payload()
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| info.payload().downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".to_string());
    let at = info
        .location()
        .map(|l| format!(" at {}:{}", l.file(), l.line()))
        .unwrap_or_default();
    format!("{what}{at}")
}
