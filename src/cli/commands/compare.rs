//! `vcsmooth compare A B [--json]`: distances, normals, volume and area ratios of two meshes with
//! the same connectivity, or with `--surface` of any two meshes; the deviation field, its
//! statistics and a tolerance on request.

use std::io::Write;
use std::path::PathBuf;

use clap::Args as ClapArgs;
use serde::Serialize;

use std::sync::Arc;

use crate::cli::output::{check_files, mesh_output, print_json};
use crate::cli::pictures::{Drawn, PictureArgs, PictureConfig, Sheet, print_drawn};
use crate::cli::plot::file_name;
use crate::cli::progress::Progress;
use crate::cli::report::{defined, fixed, num, print_deviation, print_rows};
use crate::cli::shared::{DeviationArgs, check_deviation_field, tolerance_verdict};
use crate::engine::{DeviationSettings, Meter, Observer, Phase, deviation};
use crate::error::{Error, Result};
use crate::mesh::{Mesh, Storage};
use crate::metrics::{self, Comparison, DeviationStats};
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
    /// Meshes that need not share vertices: each vertex of A is measured to the nearest point of B's triangles (through a bounding-volume hierarchy); the distances are those, the normal angle undefined; implies --deviation-stats [default: off: the same vertices and triangles].
    #[arg(long)]
    pub surface: bool,
    /// Write the deviation field into FILE.ply as the vertex property 'quality' (see smooth's --deviation-field): B with each vertex's deviation from A, or with --surface A with each vertex's signed distance to B's surface; implies --deviation-stats.
    #[arg(long, value_name = "FILE.ply")]
    pub deviation_field: Option<PathBuf>,
    #[command(flatten)]
    pub deviation: DeviationArgs,
    #[command(flatten)]
    pub pictures: PictureArgs,
}

/// `vcsmooth compare`, resolved.
#[derive(Debug, Clone)]
pub struct CompareConfig {
    pub a: PathBuf,
    pub b: PathBuf,
    pub json: bool,
    pub surface: bool,
    /// What to measure and write of the deviation field; `field` writes it to `field_file`.
    pub deviation: DeviationSettings,
    pub field_file: Option<PathBuf>,
    /// `--png` and its tile size.
    pub png: Option<PictureConfig>,
}

impl CompareConfig {
    pub fn from_args(a: CompareArgs) -> Result<CompareConfig> {
        if let Some(f) = &a.deviation_field {
            mesh_output(f)?;
            check_deviation_field(f, a.deviation.deviation_colours)?;
            check_files(
                &[("A", &a.a), ("B", &a.b)],
                None,
                &[("--deviation-field", f)],
            )?;
        }
        let png = a.pictures.resolve()?;
        if let Some(p) = &png {
            let mut side = vec![("--png", p.path.as_path())];
            if let Some(f) = &a.deviation_field {
                side.push(("--deviation-field", f.as_path()));
            }
            check_files(&[("A", &a.a), ("B", &a.b)], None, &side)?;
        }
        Ok(CompareConfig {
            deviation: DeviationSettings {
                stats: a.deviation.deviation_stats || a.surface,
                field: a.deviation_field.is_some(),
                colours: a.deviation.deviation_colours,
                tolerance: a.deviation.tolerance,
            },
            field_file: a.deviation_field,
            a: a.a,
            b: a.b,
            json: a.json,
            surface: a.surface,
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
    /// The deviation field's statistics, when asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub deviation: Option<DeviationStats>,
}

/// `vcsmooth compare`.
pub fn run(cfg: &CompareConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.a.display()));
    let a = crate::io::read_mesh(&cfg.a)?;
    progress.phase(format!("reading {}", cfg.b.display()));
    let b = crate::io::read_mesh(&cfg.b)?;
    progress.phase("comparing");
    let named = |e: Error| match e {
        Error::Topology { path: None, what } => Error::Topology {
            path: Some(cfg.b.clone()),
            what: format!("{what} (compared with {})", cfg.a.display()),
        },
        other => other,
    };
    let (comparison, field) = if cfg.surface {
        if b.triangles.is_empty() {
            return Err(Error::invalid(
                &cfg.b,
                "has no triangles to measure A's distances to (--surface)",
            ));
        }
        let field =
            deviation::surface_field(&a.positions, &a.triangles, &b.positions, &b.triangles)?;
        let stats = deviation::statistics(&field, cfg.deviation.tolerance);
        let c = metrics::compare_surfaces(&a, &b, stats.distance_rms, stats.distance_max);
        (c, Some((field, stats)))
    } else {
        let c = metrics::compare(&a, &b).map_err(named)?;
        let field = match cfg.deviation.is_on() {
            true => {
                let storage = crate::mesh::Storage::heap();
                let field =
                    deviation::field(&storage, &a.positions, &b.positions, &a.triangles, None)?;
                let stats = deviation::statistics(&field, cfg.deviation.tolerance);
                Some((field, stats))
            }
            false => None,
        };
        (c, field)
    };
    if let (Some(path), Some((field, stats))) = (&cfg.field_file, &field) {
        progress.phase(format!("writing {}", path.display()));
        // The field lives on the vertices it measures: B's, or with --surface A's.
        let on = if cfg.surface { &a } else { &b };
        let scale = cfg.deviation.colour_scale(stats);
        let colour = |i: usize| metrics::deviation::colour(field.signed[i], scale);
        let values = crate::io::VertexValues {
            quality: &field.signed,
            colours: match cfg.deviation.colours {
                true => Some(&colour as &(dyn Fn(usize) -> [u8; 3] + Sync)),
                false => None,
            },
        };
        crate::io::write_mesh_with(path, on, &values, &crate::meter::Meter::default())?;
    }
    let drawn = match &cfg.png {
        Some(png) => {
            let surface = field
                .as_ref()
                .filter(|_| cfg.surface)
                .map(|(f, _)| &f.distance[..]);
            Some(draw(cfg, png.clone(), &a, &b, surface, progress)?)
        }
        None => None,
    };
    progress.finish();
    let doc = CompareDoc {
        a: cfg.a.display().to_string(),
        b: cfg.b.display().to_string(),
        comparison,
        deviation: field.map(|(_, stats)| stats),
    };
    if cfg.json {
        print_json(out, &doc)?;
    } else {
        print_comparison(out, &doc)?;
        if let Some(d) = &doc.deviation {
            print_deviation(out, d)?;
        }
        if let Some(d) = drawn {
            print_drawn(out, &d)?;
        }
    }
    match &doc.deviation {
        Some(d) => tolerance_verdict(&cfg.b, d),
        None => Ok(()),
    }
}

/// The picture of `compare --png`: A and B in grey, and B coloured by its deviation from A along
/// A's vertex normals (with `--surface`, A coloured by `surface`, its vertices' distances to B's surface),
/// every view framing both.
fn draw(
    cfg: &CompareConfig,
    png: PictureConfig,
    a: &Mesh,
    b: &Mesh,
    surface: Option<&[f64]>,
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
        match surface {
            None => {
                let moved = crate::engine::deviation::signed(
                    &Storage::heap(),
                    &a.positions[..],
                    &b.positions,
                    &a.triangles,
                    |d| d as f32,
                )?;
                let what = Some((&moved[..], "deviation from A along its normal".to_string()));
                sheet.draw(
                    format!("B: {name_b}"),
                    &b.positions,
                    &b.triangles,
                    what,
                    &meter,
                )?;
            }
            Some(d) => {
                sheet.draw(
                    format!("B: {name_b}"),
                    &b.positions,
                    &b.triangles,
                    None,
                    &meter,
                )?;
                let d: Vec<f32> = d.iter().map(|&x| x as f32).collect();
                let what = Some((&d[..], "distance to B's surface".to_string()));
                sheet.draw(
                    format!("A: {name_a}"),
                    &a.positions,
                    &a.triangles,
                    what,
                    &meter,
                )?;
            }
        }
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
