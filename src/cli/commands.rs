//! The commands: each takes its resolved config, does its work through the library, writes its
//! files only after everything before them succeeded, and prints its result to `out`.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use super::args::Shape;
use super::config::{
    CompareConfig, CurvesConfig, DemoConfig, GenerateConfig, InfoConfig, SmoothConfig,
};
use super::output::{print_json, stdout_error, write_json};
use super::plot::{Curve, write_volume_plot};
use super::progress::Progress;
use super::report::{
    CompareDoc, CurveDoc, CurvesDoc, FileStats, InfoDoc, SmoothReport, Summary, Timings, Tool,
    count, format_name, print_comparison, print_curves, print_info, print_iterations,
};
use crate::engine::{self, IterationRecord};
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::mesh::shapes;
use crate::topology::Topology;
use crate::{io, metrics};

/// `vcsmooth smooth`: read → reorder → topology → partition → smooth → write mesh → write report
/// and plot → print table.
///
/// Under `mpirun`/`srun` (built with `--features mpi`) or with `--checkpoint`, the cluster engine
/// runs it; rank 0 alone reports.
pub fn smooth(cfg: &SmoothConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    crate::cluster::with_world(|comm| {
        let Some(cluster) = cfg.cluster(comm.size()) else {
            progress.phase(format!("smoothing {}", cfg.input.display()));
            progress.iterations(cfg.options.method.name(), cfg.options.iterations);
            let (run, multires) = match &cfg.multires {
                None => (
                    engine::run_file(&cfg.input, &cfg.output, &cfg.options, &cfg.engine, progress)?,
                    None,
                ),
                Some(m) => {
                    let (run, stats) = crate::multires::run_file(
                        &cfg.input,
                        &cfg.output,
                        &cfg.options,
                        m,
                        &cfg.engine,
                        progress,
                    )?;
                    (run, Some(stats))
                }
            };
            return smooth_report(cfg, &run, multires, progress, out);
        };
        if cfg.multires.is_some() {
            return Err(super::flags::parameter(
                "multires",
                "runs in one process; it cannot be combined with --checkpoint or MPI ranks",
            ));
        }
        let lead = comm.rank() == 0;
        if lead {
            progress.phase(format!(
                "smoothing {} on {} (work directory {})",
                cfg.input.display(),
                count(comm.size(), "rank"),
                cluster.work_dir.display()
            ));
            progress.iterations(cfg.options.method.name(), cfg.options.iterations);
        }
        let observer: &mut dyn engine::Observer = if lead { progress } else { &mut engine::Quiet };
        let run = crate::cluster::run_file(
            comm,
            &cfg.input,
            &cfg.output,
            &cfg.options,
            &cfg.engine,
            &cluster,
            observer,
        )
        .map_err(|e| {
            if comm.size() > 1 {
                Error::Rank {
                    rank: comm.rank(),
                    source: Box::new(e),
                }
            } else {
                e
            }
        })?;
        if !lead {
            return Ok(());
        }
        smooth_report(cfg, &run, None, progress, out)
    })
}

/// The report, plot and table of a finished `smooth`.
fn smooth_report(
    cfg: &SmoothConfig,
    run: &engine::Report,
    multires: Option<crate::multires::MultiresStats>,
    progress: &mut Progress,
    out: &mut dyn Write,
) -> Result<()> {
    let records = &run.records;

    if let (Some(path), Some(input_stats), Some(output_stats)) =
        (&cfg.report, &run.input_stats, &run.output_stats)
    {
        let report = SmoothReport {
            tool: Tool::this(),
            command: "smooth",
            argv: cfg.argv.clone(),
            options: cfg.options,
            engine: cfg.engine.clone(),
            input: FileStats::new(&cfg.input, run.input_format, input_stats.clone()),
            output: FileStats::new(
                &cfg.output,
                super::config::output_format(&cfg.output),
                output_stats.clone(),
            ),
            plan: run.plan.clone(),
            memory: run.memory.clone(),
            timings: run.timings,
            cluster: run.cluster.clone(),
            summary: Summary::of(records),
            iterations: records.clone(),
            multires: multires.clone(),
        };
        write_json(path, &report)?;
    }
    if let Some(path) = &cfg.plot {
        let curve = Curve {
            method: cfg.options.method,
            volume_pct: volume_curve(records),
        };
        let title = format!("{} on {}", cfg.options.method, file_name(&cfg.input));
        write_volume_plot(path, &title, &[curve])?;
    }
    progress.finish();

    let s = Summary::of(records);
    let text = format!(
        "{} -> {}: {}, {}, {} vertices, {} triangles; volume {:.6} %, area {:.4} %\n",
        cfg.input.display(),
        cfg.output.display(),
        cfg.options.method,
        count(cfg.options.iterations, "iteration"),
        run.vertices,
        run.triangles,
        s.volume_pct,
        s.area_pct
    );
    out.write_all(text.as_bytes()).map_err(stdout_error)?;
    if !records.is_empty() {
        print_iterations(out, records)?;
    }
    if let Some(m) = &multires {
        super::multires::print_multires(out, m)?;
    }
    let (t, p, m) = (&run.timings, &run.plan, &run.memory);
    writeln!(
        out,
        "patches: {} of {} vertices in {} colours on {} threads, {} crossing edge stencils; memory: {} ({}), peak anonymous {}",
        p.patches,
        p.patch_size,
        p.colours,
        p.threads,
        p.crossing_edge_stencils,
        m.storage,
        crate::engine::memory::format_size(m.budget),
        crate::engine::memory::format_size(m.peak_anon)
    )
    .map_err(stdout_error)?;
    if let Some(c) = &run.cluster {
        writeln!(
            out,
            "cluster: {}, {}-{} owned vertices and up to {} held per rank, {} halo values per iteration (largest rank {}/iteration), largest rank peak {} ({} while smoothing); resumed after {}, checkpoint every {}",
            count(c.ranks, "rank"),
            c.owned_vertices_min,
            c.owned_vertices_max,
            c.region_vertices_max,
            c.halo_values_per_iteration,
            crate::engine::memory::format_size(c.halo_bytes_per_iteration_max),
            crate::engine::memory::format_size(c.peak_anon_max),
            crate::engine::memory::format_size(c.smoothing_peak_anon_max),
            count(c.resumed_after, "iteration"),
            count(c.checkpoint_every, "iteration"),
        )
        .map_err(stdout_error)?;
    }
    writeln!(
        out,
        "seconds: ingest {:.3}, reorder {:.3}, topology {:.3}, partition {:.3}, smoothing {:.3}, write {:.3}, total {:.3}",
        t.ingest, t.reorder, t.topology, t.partition, t.smoothing, t.write, t.total
    )
    .map_err(stdout_error)
}

/// `vcsmooth info`.
pub fn info(cfg: &InfoConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.input.display()));
    let (mesh, topo) = read_with_topology(&cfg.input, progress, &mut Timings::default())?;
    progress.phase("measuring");
    let doc = InfoDoc {
        path: cfg.input.display().to_string(),
        format: mesh.source.format.map(format_name),
        info: metrics::info(&mesh, &topo),
    };
    progress.finish();
    if cfg.json {
        print_json(out, &doc)
    } else {
        print_info(out, &doc)
    }
}

/// `vcsmooth compare`.
pub fn compare(cfg: &CompareConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.a.display()));
    let a = io::read_mesh(&cfg.a)?;
    progress.phase(format!("reading {}", cfg.b.display()));
    let b = io::read_mesh(&cfg.b)?;
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

/// Peak memory of generating one triangle and writing it (positions, triangles, the previous
/// subdivision level, write buffers): measured 32 B at level 8, with a margin.
const GENERATE_BYTES_PER_TRIANGLE: u64 = 48;
/// Extra peak memory per triangle for the noise (the adjacency it builds, the normals): measured
/// 38 B at level 8, with a margin.
const NOISE_BYTES_PER_TRIANGLE: u64 = 48;

/// `vcsmooth generate`.
pub fn generate(cfg: &GenerateConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    if cfg.shape == Shape::Mesh || cfg.subdivide.is_some() {
        return generate_streamed(cfg, progress, out);
    }
    let k = cfg.subdivisions;
    let max = max_subdivisions(cfg.shape);
    if k > max {
        return Err(Error::invalid(
            &cfg.output,
            format!(
                "--subdivisions {k} is too large: the largest {} level is {max} ({} triangles; ×4 per level)",
                shape_name(cfg.shape),
                triangles_at(cfg.shape, max)
            ),
        ));
    }
    let triangles = triangles_at(cfg.shape, k);
    let per_triangle = GENERATE_BYTES_PER_TRIANGLE
        + if cfg.noise > 0.0 {
            NOISE_BYTES_PER_TRIANGLE
        } else {
            0
        };
    let need = triangles.saturating_mul(per_triangle);
    let available = available_memory().unwrap_or(u64::MAX);
    if need > available {
        return Err(Error::invalid(
            &cfg.output,
            format!(
                "--subdivisions {k} makes {triangles} triangles and needs about {} of memory, \
                 but only {} is available",
                gib(need),
                gib(available)
            ),
        ));
    }

    progress.phase(format!("generating {} level {k}", shape_name(cfg.shape)));
    let mut mesh = match cfg.shape {
        Shape::Sphere => shapes::icosphere(k),
        // `mesh` always takes the streamed path above.
        Shape::Torus | Shape::Mesh => shapes::torus(k),
    };
    if cfg.noise > 0.0 {
        progress.phase("adding noise");
        shapes::add_normal_noise(&mut mesh, cfg.noise, cfg.seed);
    }
    progress.phase(format!("writing {}", cfg.output.display()));
    io::write_mesh(&cfg.output, &mesh)?;
    progress.finish();
    writeln!(
        out,
        "{}: {} level {k}, {} vertices, {} triangles, noise {} × mean edge length (seed {})",
        cfg.output.display(),
        shape_name(cfg.shape),
        mesh.positions.len(),
        mesh.triangles.len(),
        cfg.noise,
        cfg.seed
    )
    .map_err(stdout_error)
}

/// `vcsmooth curves`: every method from the same input positions; the plot, then the table.
pub fn curves(cfg: &CurvesConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!("reading {}", cfg.input.display()));
    let mesh = io::read_mesh(&cfg.input)?;
    progress.phase("building topology");
    let pool = engine::thread_pool(cfg.engine.threads)?;
    let storage = crate::mesh::Storage::heap();
    // Every method from the input in its own order (the sequential reference order).
    let mut plan = pool
        .install(|| {
            engine::Plan::new(
                &storage,
                &mesh.positions,
                &mesh.triangles,
                engine::Layout::Whole,
            )
        })
        .map_err(|e| e.in_file(&cfg.input))?;

    let mut docs = Vec::with_capacity(cfg.methods.len());
    for &method in &cfg.methods {
        let options = crate::smooth::Options {
            method,
            ..cfg.options
        };
        plan.set_positions_from_input(&mesh.positions);
        progress.iterations(method.name(), options.iterations);
        let clock = Instant::now();
        let records = pool
            .install(|| plan.smooth(&storage, &options, engine::Statistics::Every, progress))
            .map_err(|e| e.in_file(&cfg.input))?;
        docs.push(CurveDoc {
            method,
            volume_pct: volume_curve(&records),
            seconds: clock.elapsed().as_secs_f64(),
            iterations: records,
        });
    }

    let curves: Vec<Curve> = docs
        .iter()
        .map(|d| Curve {
            method: d.method,
            volume_pct: d.volume_pct.clone(),
        })
        .collect();
    let title = format!("volume per iteration: {}", file_name(&cfg.input));
    write_volume_plot(&cfg.plot, &title, &curves)?;
    progress.finish();

    let doc = CurvesDoc {
        tool: Tool::this(),
        input: cfg.input.display().to_string(),
        iterations: cfg.options.iterations,
        lambda: cfg.options.lambda,
        mu: cfg.options.mu,
        reject_energy_increase: cfg.options.reject_energy_increase,
        plot: cfg.plot.display().to_string(),
        curves: docs,
    };
    if cfg.json {
        print_json(out, &doc)
    } else {
        print_curves(out, &doc)
    }
}

/// Read a mesh and build its topology, timing both.
fn read_with_topology(
    path: &Path,
    progress: &Progress,
    t: &mut Timings,
) -> Result<(Mesh, Topology)> {
    let clock = Instant::now();
    let mesh = io::read_mesh(path)?;
    t.read = clock.elapsed().as_secs_f64();
    progress.phase("building topology");
    let clock = Instant::now();
    let topo =
        Topology::build(mesh.positions.len(), &mesh.triangles).map_err(|e| e.in_file(path))?;
    t.topology = clock.elapsed().as_secs_f64();
    Ok((mesh, topo))
}

/// Volume % at iterations 0 (the input: 100), 1, …, N.
fn volume_curve(records: &[IterationRecord]) -> Vec<f64> {
    std::iter::once(100.0)
        .chain(records.iter().map(|r| r.volume_pct))
        .collect()
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

fn shape_name(s: Shape) -> &'static str {
    match s {
        Shape::Sphere => "sphere",
        Shape::Torus => "torus",
        Shape::Mesh => "mesh",
    }
}

/// The largest subdivision level the generator accepts for `shape`.
fn max_subdivisions(shape: Shape) -> u32 {
    match shape {
        Shape::Sphere => shapes::ICOSPHERE_MAX_SUBDIVISIONS,
        Shape::Torus => shapes::TORUS_MAX_SUBDIVISIONS,
        Shape::Mesh => 0,
    }
}

/// Triangles of `shape` at level `k` (≤ its maximum): sphere `20·4^k`, torus `256·4^k`.
fn triangles_at(shape: Shape, k: u32) -> u64 {
    let base = match shape {
        Shape::Sphere => 20,
        Shape::Torus => 256,
        Shape::Mesh => 0,
    };
    base << (2 * k.min(max_subdivisions(shape)))
}

/// `MemAvailable` from /proc/meminfo, in bytes (`None` where that is not available).
fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

fn gib(bytes: u64) -> String {
    format!("{:.1} GiB", bytes as f64 / (1u64 << 30) as f64)
}

/// `vcsmooth bench`: throughput on generated meshes (see [`crate::modes::bench`]), as a table or JSON.
pub fn bench(
    cfg: &super::config::BenchConfig,
    progress: &mut Progress,
    out: &mut dyn Write,
) -> Result<()> {
    let report = crate::modes::bench::run(&cfg.settings, &mut |m| progress.phase(m))?;
    progress.finish();
    if cfg.json {
        let doc = super::report::BenchDoc {
            tool: Tool::this(),
            report,
        };
        print_json(out, &doc)
    } else {
        super::report::print_bench(out, &report)
    }
}

/// `vcsmooth demo`: the embedded default job. A noisy icosphere is smoothed by every method on the
/// patch engine; the table shows what the paper shows: only the volume-constrained methods keep
/// the volume, and all of them remove the noise.
pub fn demo(cfg: &DemoConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    use crate::mesh::Storage;
    progress.phase(format!(
        "generating a noisy sphere (level {})",
        cfg.subdivisions
    ));
    let clean = shapes::icosphere(cfg.subdivisions);
    let mut noisy = clean.clone();
    shapes::add_normal_noise(&mut noisy, cfg.noise, 1);
    let pool = engine::thread_pool(cfg.engine.threads)?;
    let storage = Storage::heap();
    let clean_topo = Topology::build(clean.positions.len(), &clean.triangles)?;
    let rough_clean = metrics::roughness(&clean.positions, &clean.triangles, &clean_topo);
    let rough_noisy = metrics::roughness(&noisy.positions, &noisy.triangles, &clean_topo);
    writeln!(
        out,
        "noisy unit sphere: {} vertices, {} triangles, noise {} × mean edge; {} iterations per method, {} threads\n\
         roughness (mean dihedral angle): clean {:.3}°, noisy {:.3}°\n",
        noisy.positions.len(),
        noisy.triangles.len(),
        cfg.noise,
        cfg.iterations,
        pool.current_num_threads(),
        rough_clean,
        rough_noisy
    )
    .map_err(stdout_error)?;
    writeln!(
        out,
        "{:<13} {:>12} {:>10} {:>14} {:>16} {:>10}",
        "method", "volume %", "area %", "roughness °", "RMS to clean", "seconds"
    )
    .map_err(stdout_error)?;
    for method in crate::smooth::Method::ALL {
        let opts = crate::smooth::Options {
            method,
            iterations: cfg.iterations,
            ..Default::default()
        };
        progress.iterations(method.name(), cfg.iterations);
        let (records, positions) = pool.install(|| -> Result<_> {
            let mut prep = engine::Plan::new(
                &storage,
                &noisy.positions,
                &noisy.triangles,
                engine::Layout::Patches(cfg.engine.patch_size),
            )?;
            let records = prep.smooth(&storage, &opts, engine::Statistics::Every, progress)?;
            let mut positions = noisy.positions.clone();
            prep.positions_in_input_order(&mut positions);
            Ok((records, positions))
        })?;
        let last = records.last().copied().unwrap_or_default();
        let rough = metrics::roughness(&positions, &noisy.triangles, &clean_topo);
        let rms = (positions
            .iter()
            .zip(&clean.positions)
            .map(|(a, b)| a.distance_squared(*b))
            .sum::<f64>()
            / positions.len().max(1) as f64)
            .sqrt();
        let seconds: f64 = records.iter().map(|r| r.seconds).sum();
        writeln!(
            out,
            "{:<13} {:>12.6} {:>10.4} {:>14.3} {:>16.3e} {:>10.3}",
            method.name(),
            last.volume_pct,
            last.area_pct,
            rough,
            rms,
            seconds
        )
        .map_err(stdout_error)?;
    }
    progress.finish();
    Ok(())
}

/// `vcsmooth generate … --subdivide L` (and the `mesh` shape): refine a base mesh and stream it.
fn generate_streamed(
    cfg: &GenerateConfig,
    progress: &mut Progress,
    out: &mut dyn Write,
) -> Result<()> {
    let base = match (&cfg.from, cfg.shape) {
        (Some(path), _) => {
            progress.phase(format!("reading {}", path.display()));
            io::read_mesh(path)?
        }
        (None, Shape::Sphere) => {
            shapes::icosphere(cfg.subdivisions.min(shapes::ICOSPHERE_MAX_SUBDIVISIONS))
        }
        (None, _) => shapes::torus(cfg.subdivisions.min(shapes::TORUS_MAX_SUBDIVISIONS)),
    };
    let levels = cfg.subdivide.unwrap_or(0);
    progress.phase(format!(
        "writing {} (streamed, ×{} triangles)",
        cfg.output.display(),
        1u64 << (2 * levels)
    ));
    let n = shapes::Subdivision::new(&base, levels, cfg.noise, cfg.seed)
        .map_err(|e| e.in_file(&cfg.output))?;
    let comment = format!(
        "vcsmooth generate: {} triangles x {}^2",
        n.base_triangles(),
        n.pieces()
    );
    io::write_ply_streamed(&cfg.output, n.vertices(), n.triangles(), &[&comment], |w| {
        n.for_each_vertex(|p| w.vertex(p))?;
        n.for_each_triangle(|t| w.triangle(t))
    })?;
    progress.finish();
    writeln!(
        out,
        "{}: {} triangles of {} split into 4^{levels}: {} vertices, {} triangles, noise {} × mean edge length (seed {})",
        cfg.output.display(),
        base.triangles.len(),
        cfg.from.as_ref().map_or_else(|| shape_name(cfg.shape).to_string(), |p| p.display().to_string()),
        n.vertices(),
        n.triangles(),
        cfg.noise,
        cfg.seed
    )
    .map_err(stdout_error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_counts_match_the_generators() {
        assert_eq!(triangles_at(Shape::Sphere, 3), 1280);
        for shape in [Shape::Sphere, Shape::Torus] {
            let mesh = match shape {
                Shape::Sphere => shapes::icosphere(1),
                _ => shapes::torus(1),
            };
            assert_eq!(triangles_at(shape, 1), mesh.triangles.len() as u64);
            assert!(triangles_at(shape, max_subdivisions(shape)) < 1 << 31);
        }
    }

    #[test]
    fn curve_starts_at_100() {
        let r = IterationRecord {
            iteration: 1,
            volume_pct: 90.0,
            ..Default::default()
        };
        assert_eq!(volume_curve(&[r]), vec![100.0, 90.0]);
    }
}
