//! `vcsmooth compare A B [--json]`: distances, normals, volume and area ratios of two meshes with
//! the same connectivity.

use std::io::Write;
use std::path::PathBuf;

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cli::output::print_json;
use crate::cli::progress::Progress;
use crate::cli::report::{defined, fixed, num, print_rows};
use crate::error::{Error, Result};
use crate::metrics::{self, Comparison};

/// `vcsmooth compare A B [--json]`
#[derive(Debug, Clone, ClapArgs)]
pub struct CompareArgs {
    /// Reference mesh.
    #[arg(value_name = "A")]
    pub a: PathBuf,
    /// Mesh compared against A (same vertex count and triangles).
    #[arg(value_name = "B")]
    pub b: PathBuf,
    /// Print JSON instead of a table [default: table].
    #[arg(long)]
    pub json: bool,
}

/// `vcsmooth compare`, resolved.
#[derive(Debug, Clone)]
pub struct CompareConfig {
    pub a: PathBuf,
    pub b: PathBuf,
    pub json: bool,
}

impl CompareConfig {
    pub fn from_args(a: CompareArgs) -> Result<CompareConfig> {
        Ok(CompareConfig {
            a: a.a,
            b: a.b,
            json: a.json,
        })
    }
}

/// The JSON of `vcsmooth compare --json`.
#[derive(Debug, Clone, Serialize)]
pub struct CompareDoc {
    pub a: String,
    pub b: String,
    #[serde(flatten)]
    pub comparison: Comparison,
}

/// `vcsmooth compare`.
pub fn run(cfg: &CompareConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.a.display()));
    let a = crate::io::read_mesh(&cfg.a)?;
    progress.phase(format!("reading {}", cfg.b.display()));
    let b = crate::io::read_mesh(&cfg.b)?;
    progress.phase("comparing");
    let comparison = metrics::compare(&a, &b).map_err(|e| match e {
        Error::Topology { path: None, what } => Error::Topology {
            path: Some(cfg.b.clone()),
            what: format!("{what} (compared with {})", cfg.a.display()),
        },
        other => other,
    })?;
    progress.finish();
    let doc = CompareDoc {
        a: cfg.a.display().to_string(),
        b: cfg.b.display().to_string(),
        comparison,
    };
    if cfg.json {
        print_json(out, &doc)
    } else {
        print_comparison(out, &doc)
    }
}

/// Print a comparison as aligned `key  value` lines.
fn print_comparison(out: &mut dyn Write, doc: &CompareDoc) -> Result<()> {
    let c = &doc.comparison;
    let distance = |d: f64, relative: Option<f64>| match relative {
        Some(r) => format!("{} ({} of the bbox diagonal of a)", num(d), num(r)),
        None => format!("{} (the bbox diagonal of a is 0)", num(d)),
    };
    let rows: Vec<(&str, String)> = vec![
        ("a", doc.a.clone()),
        ("b", doc.b.clone()),
        ("rms distance", distance(c.rms_distance, c.rms_relative)),
        ("max distance", distance(c.max_distance, c.max_relative)),
        (
            "mean normal angle",
            defined(c.mean_normal_angle_deg, |x| format!("{} deg", fixed(x, 6))),
        ),
        ("volume ratio b/a", defined(c.volume_ratio, |x| fixed(x, 9))),
        ("area ratio b/a", defined(c.area_ratio, |x| fixed(x, 9))),
    ];
    print_rows(out, &rows)
}
