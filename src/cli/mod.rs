//! The `vcsmooth` command line, in three layers (after ripgrep):
//!
//! 1. [`Args`] — raw flags parsed by clap ([`args`]); per-flag checks only.
//! 2. [`Config`] — the resolved, validated command ([`config`]): output formats known, plot files
//!    SVG, target directories present, so a run fails before it reads or smooths anything.
//! 3. [`run`] — executes a [`Config`] through the library, rendering the driver's
//!    [`crate::engine::Observer`] as an indicatif progress bar ([`progress`]) when stderr is a terminal.
//!
//! [`main_with`] ties them together for the binary and returns the exit code: 0 on success, 2 for
//! usage errors (clap's, and options that resolve to nothing valid), 1 for failures at run time.
//! Every failure is one line on stderr, `vcsmooth: error: <file>: <problem>`; no output file, report
//! or plot is written by a run that fails before it would write them.
//!
//! Commands: `smooth`, `info`, `compare`, `generate`, `curves`, `demo`, `bench`, `batch`,
//! `slurm-script` (see [`args::Command`]).

pub mod args;
pub mod batch;
pub mod commands;
pub mod config;
pub mod flags;
pub mod multires;
pub mod output;
pub mod plot;
pub mod progress;
pub mod refine;
pub mod report;

use std::ffi::OsString;
use std::process::ExitCode;

use clap::Parser;

pub use args::Args;
pub use config::Config;
pub use progress::Progress;

use crate::error::Result;

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
    match run(&config) {
        Ok(()) => ExitCode::SUCCESS,
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
    let mut out = stdout.lock();
    run_with(config, &mut progress, &mut out)
}

/// [`run`] with an explicit progress display and output stream.
pub fn run_with(
    config: &Config,
    progress: &mut Progress,
    out: &mut dyn std::io::Write,
) -> Result<()> {
    match config {
        Config::Smooth(c) => commands::smooth(c, progress, out),
        Config::Info(c) => commands::info(c, progress, out),
        Config::Compare(c) => commands::compare(c, progress, out),
        Config::Generate(c) => commands::generate(c, progress, out),
        Config::Curves(c) => commands::curves(c, progress, out),
        Config::Demo(c) => commands::demo(c, progress, out),
        Config::Bench(c) => commands::bench(c, progress, out),
        Config::Batch(c) => batch::batch(c, progress, out),
        Config::SlurmScript(c) => batch::slurm_script(c, out),
        Config::Subdivide(c) => refine::subdivide(c, progress, out),
        Config::Refine(c) => refine::refine(c, progress, out),
    }
}

/// Print `vcsmooth: error: <message>` on one line.
fn print_error(message: &str) {
    eprintln!("vcsmooth: error: {}", one_line(message));
}

/// Collapse all whitespace runs (newlines included) into single spaces.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
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
        eprintln!(
            "vcsmooth: error: internal error (a bug, please report it): {}{at}",
            one_line(&what)
        );
    }));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clap_errors_become_one_line() {
        let e = Args::try_parse_from([
            "vcsmooth",
            "smooth",
            "a.ply",
            "b.ply",
            "--iterations",
            "abc",
        ])
        .unwrap_err();
        let m = clap_message(&e.to_string());
        assert!(
            !m.contains('\n') && m.contains("--iterations") && m.contains("abc"),
            "{m}"
        );
        let e = Args::try_parse_from(["vcsmooth", "smooth", "a.ply"]).unwrap_err();
        let m = clap_message(&e.to_string());
        assert!(!m.contains('\n') && m.contains("OUT"), "{m}");
        let e =
            Args::try_parse_from(["vcsmooth", "smooth", "a", "b", "--method", "x"]).unwrap_err();
        let m = clap_message(&e.to_string());
        assert!(m.contains("vcs-triangle"), "{m}");
    }
}
