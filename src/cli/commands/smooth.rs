//! `vcsmooth smooth IN OUT ...`: read → reorder → topology → partition → smooth → write the mesh →
//! write the report and the plot → print the table. Its `--multires` flags are
//! [`crate::cli::multires`].

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args as ClapArgs;

use crate::cli::flags;
use crate::cli::multires::{MultiresArgs, print_multires};
use crate::cli::output::{
    check_files, check_work_dir, mesh_output, stdout_error, svg_output, write_json,
};
use crate::cli::pictures::{PictureArgs, PictureConfig, RunPictures, Sheet, print_drawn};
use crate::cli::plot::{Curve, file_name, volume_curve, write_volume_plot};
use crate::cli::progress::Progress;
use crate::cli::report::{count, fixed, iterations_run, percent_text, print_deviation};
use crate::cli::shared::{
    DeviationArgs, InOut, PinArgs, SmoothingArgs, check_deviation_field, fixed_warning,
    tolerance_verdict,
};
use crate::engine::{self, EngineSettings, IterationRecord, Statistics};
use crate::error::{Error, Result};
use crate::report::{SmoothReport, Summary};
use crate::smooth::Options;

/// `vcsmooth smooth IN OUT ...`
#[derive(Debug, Clone, ClapArgs)]
pub struct SmoothArgs {
    #[command(flatten)]
    pub files: InOut,
    #[command(flatten)]
    pub smoothing: SmoothingArgs,
    #[command(flatten)]
    pub pins: PinArgs,
    #[command(flatten)]
    pub multires: MultiresArgs,
    /// Write a JSON report (options, input/output statistics, timings, per-iteration table).
    #[arg(long, value_name = "FILE.json")]
    pub report: Option<PathBuf>,
    /// Write an SVG plot of volume % per iteration.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Which iterations measure volume, area and displacement (each costs passes over the whole mesh, about one taubin iteration for volume and area); the others show '-' in the table and null in the report. With laplacian and taubin, 'last' also lets up to 8 steps share one pass over memory (with 'every' up to 7, each iteration measured inside the pass): their smoothing runs up to about twice as fast. The output is the same bit for bit.
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = Statistics::Every)]
    pub stats: Statistics,
    /// Write each vertex's deviation into OUT as the PLY vertex property 'quality' (an OBJ or glTF output carries its colours alone, with --deviation-colours) (MeshLab and CloudCompare read it as a scalar field): its displacement along the input's vertex normal, signed, positive outward; print its statistics (RMS, mean, percentiles of the distance, histogram), also in --report. The rest of OUT is as without it [default: off].
    #[arg(long)]
    pub deviation_field: bool,
    #[command(flatten)]
    pub deviation: DeviationArgs,
    #[command(flatten)]
    pub pictures: PictureArgs,
    #[command(flatten)]
    pub cluster: ClusterArgs,
}

/// Checkpoints and MPI ranks (see the README's "One mesh over MPI ranks").
#[derive(Debug, Clone, ClapArgs)]
pub struct ClusterArgs {
    /// Keep the prepared plan and the positions after every --checkpoint-every iterations in DIR
    /// (on a file system all ranks see); a run started again with the same input, options and patch
    /// size resumes after the last completed iteration. Under mpirun/srun without it, a work
    /// directory OUT.vcsmooth-work is used and removed after success.
    #[arg(long, value_name = "DIR")]
    pub checkpoint: Option<PathBuf>,
    /// Iterations between checkpoints (the last iteration is always written).
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = crate::cli::shared::whole_in(1, u64::MAX), allow_negative_numbers = true)]
    pub checkpoint_every: u64,
}

/// `vcsmooth smooth`, resolved.
#[derive(Debug, Clone)]
pub struct SmoothConfig {
    pub input: PathBuf,
    pub output: PathBuf,
    pub options: Options,
    pub engine: EngineSettings,
    pub report: Option<PathBuf>,
    pub plot: Option<PathBuf>,
    /// `--png` and its tile size.
    pub png: Option<PictureConfig>,
    /// `--multires` and its options.
    pub multires: Option<crate::multires::MultiresOptions>,
    /// `--checkpoint DIR` (kept) and `--checkpoint-every`.
    pub checkpoint: Option<PathBuf>,
    pub checkpoint_every: usize,
    /// The command line as given, recorded in the report.
    pub argv: Vec<String>,
    /// Whether `--method` was given: without it the summary says when to choose another.
    pub method_given: bool,
}

impl SmoothConfig {
    /// Resolve and check the flags; `argv` is the command line, kept for the report.
    pub fn from_args(a: SmoothArgs, argv: Vec<String>) -> Result<SmoothConfig> {
        // Multiresolution runs a volume-constrained method on its coarse levels.
        let default = match a.multires.multires {
            true => crate::Method::MULTIRES_COARSE,
            false => crate::Method::default(),
        };
        let options = a.smoothing.options(default)?;
        let method_given = a.smoothing.method.is_some();
        let multires = a.multires.resolve(&options)?;
        if multires.is_some() && a.cluster.checkpoint.is_some() {
            return Err(flags::parameter(
                "multires",
                "cannot be combined with --checkpoint (it runs in one process)",
            ));
        }
        mesh_output(&a.files.output)?;
        if let Some(p) = &a.plot {
            svg_output(p)?;
            if a.stats != Statistics::Every {
                return Err(flags::parameter(
                    "plot",
                    "draws the volume of every iteration: it needs --stats every",
                ));
            }
        }
        let png = a.pictures.resolve()?;
        let mut sides = Vec::new();
        sides.extend(a.report.as_deref().map(|r| ("--report", r)));
        sides.extend(a.plot.as_deref().map(|p| ("--plot", p)));
        sides.extend(png.as_ref().map(|p| ("--png", p.path.as_path())));
        let mut reads = vec![("IN", a.files.input.as_path())];
        reads.extend(a.pins.pin.as_deref().map(|p| ("--pin", p)));
        check_files(&reads, Some(("OUT", &a.files.output)), &sides)?;
        if let Some(dir) = &a.cluster.checkpoint {
            let mut files = reads.clone();
            files.push(("OUT", &a.files.output));
            files.extend(&sides);
            check_work_dir(("--checkpoint", dir), &files)?;
        }
        if a.deviation_field {
            check_deviation_field(&a.files.output, a.deviation.deviation_colours)?;
        }
        let mut engine = a.smoothing.engine.resolve()?;
        engine.pins = a.pins.resolve()?;
        engine.deviation = crate::engine::DeviationSettings {
            stats: a.deviation.deviation_stats,
            field: a.deviation_field,
            colours: a.deviation.deviation_colours,
            tolerance: a.deviation.tolerance,
        };
        if a.cluster.checkpoint.is_some() {
            in_one_process(false, &engine.deviation, png.is_some())?;
        }
        engine.with_stats = a.report.is_some();
        engine.statistics = a.stats;
        Ok(SmoothConfig {
            multires,
            options,
            engine,
            input: a.files.input,
            output: a.files.output,
            report: a.report,
            plot: a.plot,
            png,
            checkpoint: a.cluster.checkpoint,
            checkpoint_every: a.cluster.checkpoint_every as usize,
            argv,
            method_given,
        })
    }

    /// How a run over `ranks` ranks uses its work directory; `None` for the plain engine (one
    /// rank, no checkpoint).
    pub fn cluster(&self, ranks: usize) -> Option<crate::cluster::ClusterSettings> {
        let (work_dir, keep) = match &self.checkpoint {
            Some(dir) => (dir.clone(), true),
            None if ranks > 1 => {
                let mut name = self.output.as_os_str().to_owned();
                name.push(".vcsmooth-work");
                (PathBuf::from(name), false)
            }
            None => return None,
        };
        Some(crate::cluster::ClusterSettings {
            work_dir,
            keep,
            checkpoint_every: self.checkpoint_every,
        })
    }
}

/// `vcsmooth smooth`.
///
/// Under `mpirun`/`srun` (built with `--features mpi`) or with `--checkpoint`, the cluster engine
/// runs it; rank 0 alone reports.
pub fn run(cfg: &SmoothConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    crate::cluster::with_world(|comm| {
        let Some(cluster) = cfg.cluster(comm.size()) else {
            // On a thread of its own beside the run, which leaves a core idle in its sequential
            // parts (the read, the write): the run reads the file at the same time, so what it
            // reads is what was hashed as much as when the hash went first.
            let input = cfg.input.clone();
            let hashing = cfg.report.as_ref().map(|_| {
                std::thread::spawn(move || {
                    let clock = std::time::Instant::now();
                    crate::io::sha256_file(&input).map(|hash| (hash, clock.elapsed().as_secs_f64()))
                })
            });
            progress.phase(format!("smoothing {}", cfg.input.display()));
            progress.smoothing(&cfg.options);
            let labels = (
                format!("before: {}", file_name(&cfg.input)),
                format!("after: {}", file_name(&cfg.output)),
            );
            let smooth = |observer: &mut dyn engine::Observer| match &cfg.multires {
                None => Ok((
                    engine::run_file(&cfg.input, &cfg.output, &cfg.options, &cfg.engine, observer)?,
                    None,
                )),
                Some(m) => {
                    let (run, stats) = crate::multires::run_file(
                        &cfg.input,
                        &cfg.output,
                        &cfg.options,
                        m,
                        &cfg.engine,
                        observer,
                    )?;
                    Ok::<_, Error>((run, Some(stats)))
                }
            };
            let (run, multires, sheet) = match cfg.png.clone() {
                Some(png) => {
                    let mut pictures = RunPictures::new(&mut *progress, png, labels);
                    let (run, multires) = smooth(&mut pictures)?;
                    (run, multires, pictures.into_sheet())
                }
                None => {
                    let (run, multires) = smooth(&mut *progress)?;
                    (run, multires, None)
                }
            };
            let sha256 = match hashing.map(|h| h.join()) {
                Some(Ok(hashed)) => Some(hashed?),
                Some(Err(panic)) => std::panic::resume_unwind(panic),
                None => None,
            };
            return report(cfg, &run, multires, sha256, sheet, progress, out);
        };
        in_one_process(
            cfg.multires.is_some(),
            &cfg.engine.deviation,
            cfg.png.is_some(),
        )?;
        let lead = comm.rank() == 0;
        if lead {
            progress.phase(format!(
                "smoothing {} on {} (work directory {})",
                cfg.input.display(),
                count(comm.size(), "rank"),
                cluster.work_dir.display()
            ));
            progress.smoothing(&cfg.options);
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
        report(cfg, &run, None, None, None, progress, out)
    })
}

/// What only the engine of one process does (the multiresolution levels, the deviation field
/// and its statistics, the pictures): a usage error with the cluster engine (`--checkpoint`, MPI
/// ranks), named by its flag.
fn in_one_process(multires: bool, d: &crate::engine::DeviationSettings, png: bool) -> Result<()> {
    let name = match (multires, d.is_on(), png) {
        (true, _, _) => "multires",
        (false, true, _) if d.field => "deviation_field",
        (false, true, _) if d.tolerance.is_some() => "tolerance",
        (false, true, _) => "deviation_stats",
        (false, false, true) => "png",
        (false, false, false) => return Ok(()),
    };
    let does = match name {
        "png" => "draws a run in one process",
        _ => "runs in one process",
    };
    Err(flags::parameter(
        name,
        format!("{does}; it cannot be combined with --checkpoint or MPI ranks"),
    ))
}

/// The report, plot and table of a finished `smooth`.
fn report(
    cfg: &SmoothConfig,
    run: &engine::Report,
    multires: Option<crate::multires::MultiresStats>,
    sha256: Option<(String, f64)>,
    sheet: Option<Sheet>,
    progress: &mut Progress,
    out: &mut dyn Write,
) -> Result<()> {
    let records = &run.records;

    if let Some(path) = &cfg.report
        && run.input_stats.is_some()
        && run.output_stats.is_some()
    {
        let mut report = SmoothReport::new(
            cfg.argv.clone(),
            cfg.options,
            cfg.engine.clone(),
            (&cfg.input, &cfg.output),
            run,
            multires.clone(),
        );
        if let Some((hash, seconds)) = sha256 {
            report.input.sha256 = Some(hash);
            report.timings.hash = seconds;
        } else if let Some(hash) = &run.input_sha256 {
            report.input.sha256 = Some(hash.clone());
        }
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
    let drawn = match sheet {
        Some(sheet) => {
            let title = format!(
                "vcsmooth smooth {} -> {}: {}, {}",
                file_name(&cfg.input),
                file_name(&cfg.output),
                cfg.options.method,
                iterations_run(&cfg.options, run)
            );
            Some(sheet.write(&title)?)
        }
        None => None,
    };
    progress.finish();
    if cfg.options.iterations > 0
        && let Some(line) = fixed_warning(
            &run.plan.fixed,
            !cfg.options.boundary.is_fixed(),
            cfg.options.weld,
        )
    {
        // Not `eprintln!`: stderr may be a closed pipe, and this must not panic.
        let _ = writeln!(
            std::io::stderr(),
            "vcsmooth: warning: {}: {line}",
            cfg.input.display()
        );
    }

    if !run.dropped.is_empty() {
        let _ = writeln!(
            std::io::stderr(),
            "vcsmooth: note: {}: written without the input's {}: {}",
            cfg.output.display(),
            run.dropped.join(", "),
            keep_advice(run.input_format, &cfg.output, &run.dropped)
        );
    }

    let s = Summary::of_run(records, multires.as_ref());
    let text = format!(
        "{} -> {}: {}, {}, {} vertices, {} triangles; volume {}, area {}\n",
        cfg.input.display(),
        cfg.output.display(),
        cfg.options.method,
        iterations_run(&cfg.options, run),
        run.vertices,
        run.triangles,
        percent_text(s.volume_pct, 6),
        percent_text(s.area_pct, 4)
    );
    out.write_all(text.as_bytes()).map_err(stdout_error)?;
    if !records.is_empty() {
        print_iterations(out, records)?;
    }
    if let Some(m) = &multires {
        print_multires(out, m)?;
    }
    if let Some(d) = &run.deviation {
        print_deviation(out, d)?;
    }
    let (t, p, m) = (&run.timings, &run.plan, &run.memory);
    writeln!(
        out,
        "patches: {} of {} vertices, {} colours in {} {} on {} threads, {} crossing edge stencils; memory: {} ({}), peak anonymous {}",
        p.patches,
        p.patch_size,
        p.colours,
        p.steps,
        if p.steps == 1 { "step" } else { "steps" },
        p.threads,
        p.crossing_edge_stencils,
        m.storage,
        crate::engine::memory::format_size(m.budget),
        crate::engine::memory::format_size(m.peak_anon)
    )
    .map_err(stdout_error)?;
    if m.scratch_peak_bytes > 0 {
        // What the sweep moves to and from the disk, to hold against the scratch (issue #33);
        // not with --multires, whose smoothing phase runs the coarse levels too.
        let sweep = match (&run.disk, run.iterations_run) {
            (Some(d), n @ 1..) if multires.is_none() => format!(
                "; disk per iteration: {} read, {} written",
                crate::engine::memory::format_size(d.smoothing.disk_read_bytes / n as u64),
                crate::engine::memory::format_size(d.smoothing.disk_written_bytes / n as u64)
            ),
            _ => String::new(),
        };
        writeln!(
            out,
            "scratch: at most {} on disk at once ({} in all){sweep}",
            crate::engine::memory::format_size(m.scratch_peak_bytes),
            crate::engine::memory::format_size(m.scratch_bytes)
        )
        .map_err(stdout_error)?;
    }
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
    // A report's hash is taken outside the run; a checkpoint's is part of it.
    let hash = match &run.cluster {
        Some(_) => format!("hash {:.3}, ", t.hash),
        None => String::new(),
    };
    writeln!(
        out,
        "seconds: {hash}ingest {:.3}, reorder {:.3}, topology {:.3}, partition {:.3}, smoothing {:.3}, write {:.3}, total {:.3}",
        t.ingest, t.reorder, t.topology, t.partition, t.smoothing, t.write, t.total
    )
    .map_err(stdout_error)?;
    if let Some(d) = drawn {
        print_drawn(out, &d)?;
    }
    if let Some(hint) = method_hint(cfg, run.iterations_run) {
        writeln!(out, "{hint}").map_err(stdout_error)?;
    }
    match &run.deviation {
        Some(d) => tolerance_verdict(&cfg.output, d),
        None => Ok(()),
    }
}

/// When the method was left to its default, which other one to choose for which input: no
/// cheap measure tells a machined part from an organic scan (docs/quality-research.md §18), so
/// the user is told once per run, and naming any method hides the line.
fn method_hint(cfg: &SmoothConfig, iterations_run: usize) -> Option<String> {
    let o = &cfg.options;
    // Without `--method` or `--multires` the method is the default.
    let plain = !cfg.method_given && cfg.multires.is_none() && o.crease_angle.is_none();
    (plain && iterations_run > 0).then(|| {
        format!(
            "method: {} (the default) is for organic and smooth scans; a part with sharp edges \
             (machined, CAD) keeps them with --method {} (slower), or keeps its clearest ones \
             with --crease-angle 40; --method {} hides this line",
            o.method,
            crate::Method::SHARP_EDGES,
            o.method
        )
    })
}

/// Print the per-iteration table of a run.
fn print_iterations(out: &mut dyn Write, records: &[IterationRecord]) -> Result<()> {
    let mut text = format!(
        "{:>5} {:>12} {:>10} {:>11} {:>11} {:>10} {:>9} {:>10} {:>9} {:>9}\n",
        "iter",
        "volume %",
        "area %",
        "max disp",
        "mean disp",
        "applied",
        "fixed",
        "degenerate",
        "rejected",
        "seconds"
    );
    // Statistics not measured (`smooth --stats last`) are NaN: shown as '-'; a measured volume
    // whose ratio is undefined (against a volume of 0) as `undefined`.
    let measured = |x: f64, text: String| if x.is_nan() { "-".into() } else { text };
    for r in records {
        let s = &r.stencils;
        text += &format!(
            "{:>5} {:>12} {:>10} {:>11} {:>11} {:>10} {:>9} {:>10} {:>9} {:>9.3}\n",
            r.iteration,
            measured(r.volume, fixed(r.volume_pct, 6)),
            measured(r.volume, fixed(r.area_pct, 4)),
            measured(r.max_displacement, format!("{:.4e}", r.max_displacement)),
            measured(r.mean_displacement, format!("{:.4e}", r.mean_displacement)),
            s.applied,
            s.skipped_fixed,
            s.skipped_degenerate,
            s.rejected,
            r.seconds
        );
    }
    out.write_all(text.as_bytes()).map_err(stdout_error)
}

/// How to keep what a conversion from `input` (a file of that format) to `output` drops.
fn keep_advice(input: Option<crate::io::Format>, output: &Path, dropped: &[String]) -> String {
    let name = |f: Option<crate::io::Format>| {
        f.map_or("?".to_string(), |f| {
            crate::report::format_name(f).to_uppercase()
        })
    };
    let (from, to) = (name(input), name(crate::io::Format::from_extension(output)));
    match from == to {
        true if dropped.iter().any(|d| d == crate::io::DRACO_DROPPED) => {
            "vcsmooth decodes Draco and writes glTF uncompressed; compress the output again \
             (e.g. gltf-transform draco) where size matters"
                .to_string()
        }
        true => format!("{to} holds triangles only"),
        false => format!(
            "{to} written from {from} holds positions and faces only; write .{} to keep them",
            from.to_lowercase()
        ),
    }
}
