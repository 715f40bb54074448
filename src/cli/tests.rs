//! Tests of the whole command line: the clap definition, defaults, per-flag checks, resolution of
//! each command, and the flag names of [`super::flags`].

use std::path::Path;

use clap::{CommandFactory, Parser};

use super::*;
use crate::io::Format;
use crate::smooth::Method;

fn resolve(argv: &[&str]) -> Result<Config> {
    Config::from_args(Args::try_parse_from(argv).unwrap(), vec![])
}

#[test]
fn clap_definition_is_consistent() {
    Args::command().debug_assert();
}

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
    let e = Args::try_parse_from(["vcsmooth", "smooth", "a", "b", "--method", "x"]).unwrap_err();
    let m = clap_message(&e.to_string());
    assert!(m.contains("vcs-triangle"), "{m}");
}

#[test]
fn defaults_match_the_contract() {
    let a = Args::try_parse_from(["vcsmooth", "smooth", "in.ply", "out.ply"]).unwrap();
    let Command::Smooth(s) = a.command else {
        panic!("not smooth")
    };
    let s = s.smoothing;
    assert_eq!(s.method, None);
    assert_eq!(
        s.options(Method::default()).unwrap().method,
        Method::VcsLowpass
    );
    assert_eq!(s.iterations, crate::cli::shared::Iterations::Count(10));
    assert_eq!(s.options(Method::default()).unwrap().iterations, 10);
    assert!(!s.options(Method::default()).unwrap().auto_stop);
    assert_eq!(s.params.lambda, 0.5);
    assert_eq!(s.params.mu, None);
    assert_eq!(s.options(Method::default()).unwrap().mu, Some(-0.52));
    let taubin = s.params.options(Method::Taubin, 10).unwrap();
    assert_eq!((taubin.mu, taubin.mu()), (None, -0.53));
    assert!(!s.params.reject_energy_increase);
    assert_eq!(s.engine.threads, None);

    let a = Args::try_parse_from(["vcsmooth", "curves", "in.ply", "--plot", "c.svg"]).unwrap();
    let Command::Curves(c) = a.command else {
        panic!("not curves")
    };
    assert_eq!(c.methods, vec![Method::Vcs, Method::Lem, Method::Laplacian]);
}

#[test]
fn rejects_bad_values() {
    for argv in [
        &[
            "vcsmooth",
            "smooth",
            "a.ply",
            "b.ply",
            "--iterations",
            "abc",
        ][..],
        &["vcsmooth", "smooth", "a.ply", "b.ply", "--method", "median"],
        &["vcsmooth", "smooth", "a.ply", "b.ply", "--lambda", "nan"],
        &["vcsmooth", "smooth", "a.ply", "b.ply", "--mu", "inf"],
        &["vcsmooth", "smooth", "a.ply", "b.ply", "--threads", "0"],
        &[
            "vcsmooth",
            "curves",
            "a.ply",
            "--plot",
            "c.svg",
            "--iterations",
            "0",
        ],
        &["vcsmooth", "curves", "a.ply"],
        &[
            "vcsmooth",
            "generate",
            "cube",
            "a.ply",
            "--subdivisions",
            "1",
        ],
    ] {
        assert!(Args::try_parse_from(argv).is_err(), "{argv:?} accepted");
    }
    let a = Args::try_parse_from(["vcsmooth", "smooth", "a", "b", "--mu", "-0.6"]).unwrap();
    let Command::Smooth(s) = a.command else {
        panic!("not smooth")
    };
    assert_eq!(s.smoothing.params.mu, Some(-0.6));
}

#[test]
fn output_extensions() {
    use output::output_format;
    assert_eq!(output_format(Path::new("a/b.PLY")), Some(Format::Ply));
    assert_eq!(output_format(Path::new("b.stl")), Some(Format::Stl));
    assert_eq!(output_format(Path::new("b.xyz")), None);
    assert_eq!(output_format(Path::new("b")), None);
    let e = resolve(&["vcsmooth", "smooth", "a.ply", "b.xyz"])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("b.xyz") && e.contains("unknown output format"),
        "{e}"
    );
    assert!(
        resolve(&[
            "vcsmooth",
            "generate",
            "torus",
            "t.vtk",
            "--subdivisions",
            "1"
        ])
        .is_err()
    );
}

#[test]
fn plot_must_be_svg_and_directory_must_exist() {
    assert!(resolve(&["vcsmooth", "smooth", "a.ply", "b.ply", "--plot", "v.png"]).is_err());
    assert!(resolve(&["vcsmooth", "curves", "a.ply", "--plot", "v.pdf"]).is_err());
    let e = resolve(&["vcsmooth", "smooth", "a.ply", "/no/such/dir/b.ply"]).unwrap_err();
    assert!(e.to_string().contains("does not exist"), "{e}");
    assert!(resolve(&["vcsmooth", "smooth", "a.ply", "b.ply", "--plot", "v.svg"]).is_ok());
}

#[test]
fn curves_methods_deduplicated_and_options_carried() {
    let c = resolve(&[
        "vcsmooth",
        "curves",
        "a.ply",
        "--plot",
        "c.svg",
        "--methods",
        "vcs,lem,vcs",
        "--lambda",
        "0.3",
        "--iterations",
        "6",
        "--threads",
        "2",
    ])
    .unwrap();
    let Config::Curves(c) = c else {
        panic!("not curves")
    };
    assert_eq!(c.methods, vec![Method::Vcs, Method::Lem]);
    assert_eq!(c.options.lambda, 0.3);
    assert_eq!(c.options.iterations, 6);
    assert_eq!(c.engine.threads, Some(2));
}

#[test]
fn negative_noise_refused() {
    assert!(
        resolve(&[
            "vcsmooth",
            "generate",
            "sphere",
            "s.ply",
            "--subdivisions",
            "1",
            "--noise=-1"
        ])
        .is_err()
    );
}

/// Every flag of the table of [`flags`] exists on some subcommand (an entry that names a value,
/// `--iterations auto`, by its flag).
#[test]
fn every_flag_exists() {
    let cmd = Args::command();
    let mut longs = Vec::new();
    for sub in cmd.get_subcommands() {
        for a in sub.get_arguments() {
            if let Some(l) = a.get_long() {
                longs.push(format!("--{l}"));
            }
        }
    }
    for (name, flag) in flags::FLAGS {
        let flag = flag.split(' ').next().unwrap();
        assert!(longs.iter().any(|l| l == flag), "{name}: no flag {flag}");
    }
}
