//! `vcsmooth compare A B [--json]`: distances, normals, volume and area ratios of two meshes with
//! the same connectivity.

use std::io::Write;
use std::path::PathBuf;

use clap::Args as ClapArgs;
use serde::Serialize;

use std::sync::Arc;

use crate::cli::output::{check_files, print_json};
use crate::cli::pictures::{Drawn, PictureArgs, PictureConfig, Sheet, distances, print_drawn};
use crate::cli::plot::file_name;
use crate::cli::progress::Progress;
use crate::cli::report::{defined, fixed, num, print_rows};
use crate::engine::{Meter, Observer, Phase};
use crate::error::{Error, Result};
use crate::mesh::{Mesh, Storage};
use crate::metrics::{self, Comparison};
use crate::render::{self, View};

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
    #[command(flatten)]
    pub pictures: PictureArgs,
}

/// `vcsmooth compare`, resolved.
#[derive(Debug, Clone)]
pub struct CompareConfig {
    pub a: PathBuf,
    pub b: PathBuf,
    pub json: bool,
    /// `--png` and its tile size.
    pub png: Option<PictureConfig>,
}

impl CompareConfig {
    pub fn from_args(a: CompareArgs) -> Result<CompareConfig> {
        let png = a.pictures.resolve()?;
        if let Some(p) = &png {
            check_files(&[("A", &a.a), ("B", &a.b)], None, &[("--png", &p.path)])?;
        }
        Ok(CompareConfig {
            a: a.a,
            b: a.b,
            json: a.json,
            png,
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
    let drawn = match &cfg.png {
        Some(png) => Some(draw(cfg, png.clone(), &a, &b, progress)?),
        None => None,
    };
    progress.finish();
    let doc = CompareDoc {
        a: cfg.a.display().to_string(),
        b: cfg.b.display().to_string(),
        comparison,
    };
    if cfg.json {
        return print_json(out, &doc);
    }
    print_comparison(out, &doc)?;
    match drawn {
        Some(d) => print_drawn(out, &d),
        None => Ok(()),
    }
}

/// The picture of `compare --png`: A and B in grey, and B coloured by the distance between their
/// vertices, every view framing both.
fn draw(
    cfg: &CompareConfig,
    png: PictureConfig,
    a: &Mesh,
    b: &Mesh,
    progress: &mut Progress,
) -> Result<Drawn> {
    let meter = Arc::new(Meter::new((a.triangles.len() + b.triangles.len()) as u64));
    progress.phase_start(Phase::Render, &meter);
    let drawn = (|| {
        let views = &View::STANDARD;
        let seen: Vec<_> = render::view_bounds(&a.positions, views)
            .into_iter()
            .zip(render::view_bounds(&b.positions, views))
            .map(|(x, y)| x.union(y))
            .collect();
        let mut sheet = Sheet::new(png, &seen);
        let (name_a, name_b) = (file_name(&cfg.a), file_name(&cfg.b));
        sheet.draw(
            format!("A: {name_a}"),
            &a.positions,
            &a.triangles,
            None,
            &meter,
        )?;
        let moved = distances(&a.positions, &b.positions, &Storage::heap())?;
        let what = Some((&moved[..], "distance to A".to_string()));
        sheet.draw(
            format!("B: {name_b}"),
            &b.positions,
            &b.triangles,
            what,
            &meter,
        )?;
        sheet.write(&format!("vcsmooth compare {name_a} {name_b}"))
    })();
    progress.phase_end(Phase::Render);
    drawn
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
