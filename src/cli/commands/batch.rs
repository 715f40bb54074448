//! `vcsmooth batch`: smooth many meshes as one share of a job array, with a success marker per
//! input; `--summary` gathers the markers. The logic lives in [`crate::modes::batch`]; this file
//! holds the flags, their resolution and the printing.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use clap::Args as ClapArgs;

use crate::cli::batch_smooth::{BatchSmooth, BatchSmoothArgs, batch_inputs};
use crate::cli::flags;
use crate::cli::output::{
    Identity, one_line, print_error, print_json, side_writable, stdout_error, write_json,
};
use crate::cli::progress::Progress;
use crate::cli::report::{fixed, percent_text};
use crate::engine;
use crate::error::{Error, Result};
use crate::io::Format;
use crate::modes::batch::{self as core, Marker, MarkerCheck, MeshRow};

/// `vcsmooth batch LIST_OR_DIR OUTDIR [smooth options] [--task-index I --task-count N]` or
/// `vcsmooth batch --summary OUTDIR [--inputs LIST_OR_DIR] [--json FILE|-]`
#[derive(Debug, Clone, ClapArgs)]
pub struct BatchArgs {
    /// A directory (its .ply/.obj/.off/.stl/.gltf/.glb files, sorted by name) or a file listing one mesh per line (relative to the list's directory; blank lines and #comments skipped).
    #[arg(value_name = "LIST_OR_DIR", required_unless_present = "summary")]
    pub inputs: Option<PathBuf>,
    /// Directory of the outputs (<stem>.<format>) and the success markers (.done/<stem>.json); created if missing.
    #[arg(value_name = "OUTDIR", required_unless_present = "summary")]
    pub outdir: Option<PathBuf>,
    #[command(flatten)]
    pub smooth: BatchSmoothArgs,
    /// This task's index: it smooths inputs I, I+N, I+2N, … of the sorted list [default: $SLURM_ARRAY_TASK_ID − $SLURM_ARRAY_TASK_MIN, else 0].
    #[arg(long, value_name = "I")]
    pub task_index: Option<u32>,
    /// Number of tasks sharing the inputs [default: $SLURM_ARRAY_TASK_COUNT, else MAX − MIN + 1 of the array, else 1].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub task_count: Option<u32>,
    /// Gather the markers of OUTDIR into one summary (table; JSON with --json) instead of smoothing.
    #[arg(long, value_name = "OUTDIR", conflicts_with_all = ["inputs", "outdir", "task_index", "task_count"])]
    pub summary: Option<PathBuf>,
    /// With --summary: the batch's inputs; those without a marker are listed and make the exit status 1.
    #[arg(long = "inputs", value_name = "LIST_OR_DIR", requires = "summary")]
    pub summary_inputs: Option<PathBuf>,
    /// With --summary: write the summary as JSON to FILE (atomically), or to stdout instead of the table with '-'.
    #[arg(long, value_name = "FILE", requires = "summary")]
    pub json: Option<PathBuf>,
}

/// `vcsmooth batch`, resolved.
#[derive(Debug, Clone)]
pub enum BatchConfig {
    Run {
        inputs: PathBuf,
        outdir: PathBuf,
        smooth: Box<BatchSmooth>,
        task_index: Option<usize>,
        task_count: Option<usize>,
    },
    Summary {
        outdir: PathBuf,
        inputs: Option<PathBuf>,
        json: Option<PathBuf>,
    },
}

impl BatchConfig {
    pub fn from_args(a: BatchArgs) -> Result<BatchConfig> {
        if let Some(outdir) = a.summary {
            if let Some(j) = a.json.as_deref().filter(|j| j.as_os_str() != "-") {
                side_writable(j)?;
            }
            return Ok(BatchConfig::Summary {
                outdir,
                inputs: a.summary_inputs,
                json: a.json,
            });
        }
        // clap's `requires` does not hold these to --summary here (the positional OUTDIR also
        // satisfies it): a flag that would be ignored is refused instead.
        if a.json.is_some() || a.summary_inputs.is_some() {
            return Err(Error::Usage {
                what: "--json and --inputs go with --summary".into(),
            });
        }
        let (Some(inputs), Some(outdir)) = (a.inputs, a.outdir) else {
            return Err(Error::Usage {
                what: "batch needs LIST_OR_DIR and OUTDIR".into(),
            });
        };
        Ok(BatchConfig::Run {
            inputs,
            outdir,
            smooth: Box::new(BatchSmooth::from_args(a.smooth)?),
            task_index: a.task_index.map(|i| i as usize),
            task_count: a.task_count.map(|n| n as usize),
        })
    }
}

/// `vcsmooth batch`: smooth this task's share, or print the summary.
pub fn run(cfg: &BatchConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    match cfg {
        BatchConfig::Run {
            inputs,
            outdir,
            smooth,
            task_index,
            task_count,
        } => run_share(
            inputs,
            outdir,
            smooth,
            *task_index,
            *task_count,
            progress,
            out,
        ),
        BatchConfig::Summary {
            outdir,
            inputs,
            json,
        } => summary(outdir, inputs.as_deref(), json.as_deref(), out),
    }
}

fn run_share(
    list_or_dir: &Path,
    outdir: &Path,
    smooth: &BatchSmooth,
    task_index: Option<usize>,
    task_count: Option<usize>,
    progress: &mut Progress,
    out: &mut dyn Write,
) -> Result<()> {
    let inputs = batch_inputs(list_or_dir, outdir, smooth.format)?;
    let (index, count) = core::resolve_task(task_index, task_count, &|n| std::env::var(n).ok())?;
    let markers = outdir.join(core::MARKER_DIR);
    std::fs::create_dir_all(&markers).map_err(|e| Error::io(&markers, e))?;
    let mine = core::share(inputs.len(), index, count);
    writeln!(
        out,
        "task {index} of {count}: {} of {} inputs -> {}",
        mine.len(),
        inputs.len(),
        outdir.display()
    )
    .map_err(stdout_error)?;
    let host = hostname();
    let slurm = core::SlurmIds::from_env();
    let settings = core::settings_key(&smooth.options, &smooth.engine, smooth.format);
    let (mut done, mut skipped, mut failed) = (0usize, 0usize, 0usize);
    for k in mine {
        let input = &inputs[k];
        let output = core::output_path(outdir, input, smooth.format)?;
        let marker = core::marker_path(outdir, input)?;
        match core::check_marker(&marker, Some(input), Some(&settings)) {
            MarkerCheck::Done(..) => {
                skipped += 1;
                writeln!(out, "skipped {}: already done", input.display()).map_err(stdout_error)?;
                continue;
            }
            MarkerCheck::Missing => {}
            MarkerCheck::Unreadable(why) | MarkerCheck::Stale(why) => {
                writeln!(out, "redoing {}: {}", input.display(), one_line(&why))
                    .map_err(stdout_error)?;
                // A marker that no longer holds must not be read as one while this input is redone.
                std::fs::remove_file(&marker).map_err(|e| Error::io(&marker, e))?;
            }
        }
        let clock = Instant::now();
        progress.phase(format!("smoothing {}", input.display()));
        progress.smoothing(&smooth.options);
        crate::signals::set_subject(Some(input));
        let result = catch_panic(|| {
            let input_id = core::FileId::of(input)?;
            let run = engine::run_file(input, &output, &smooth.options, &smooth.engine, progress)?;
            Ok((input_id, core::FileId::of(&output)?, run))
        });
        let result = match result {
            Ok(r) => r.and_then(|(input_id, output_id, run)| {
                let row = MeshRow {
                    name: core::stem(input)?,
                    input: input.display().to_string(),
                    output: output.display().to_string(),
                    method: smooth.options.method.name().to_string(),
                    iterations: run.iterations_run,
                    vertices: run.vertices,
                    triangles: run.triangles,
                    volume_pct: run.records.last().map_or(100.0, |r| r.volume_pct),
                    area_pct: run.records.last().map_or(100.0, |r| r.area_pct),
                    seconds: clock.elapsed().as_secs_f64(),
                    finished_unix: std::time::SystemTime::now()
                        .duration_since(std::time::UNIX_EPOCH)
                        .map_or(0, |d| d.as_secs()),
                    host: host.clone(),
                    task_index: index,
                    task_count: count,
                    slurm: slurm.clone(),
                };
                let doc = Marker {
                    format: core::MARKER_FORMAT,
                    version: env!("CARGO_PKG_VERSION"),
                    results_version: crate::RESULTS_VERSION,
                    row,
                    certifies: core::Certificate {
                        input: input_id,
                        settings: settings.clone(),
                        output: output_id,
                    },
                    options: &smooth.options,
                    engine: &smooth.engine,
                    run: &run,
                };
                write_json(&marker, &doc)?;
                Ok(doc.row)
            }),
            Err(panic) => Err(Error::invalid(
                input,
                format!("internal error while smoothing (a bug, please report it): {panic}"),
            )),
        };
        match result {
            Ok(row) => {
                done += 1;
                writeln!(
                    out,
                    "done {} -> {}: {} triangles, {} × {}{}, volume {}, {:.3} s",
                    row.input,
                    row.output,
                    row.triangles,
                    row.iterations,
                    row.method,
                    if smooth.options.auto_stop {
                        " (stopped automatically)"
                    } else {
                        ""
                    },
                    percent_text(row.volume_pct, 6),
                    row.seconds
                )
                .map_err(stdout_error)?;
            }
            Err(e) => {
                failed += 1;
                print_error(&failure(input, &e));
            }
        }
    }
    progress.finish();
    writeln!(
        out,
        "task {index} of {count}: {done} done, {skipped} already done, {failed} failed"
    )
    .map_err(stdout_error)?;
    if failed > 0 {
        return Err(Error::Reported { failed });
    }
    Ok(())
}

/// `vcsmooth batch --summary`.
fn summary(
    outdir: &Path,
    inputs: Option<&Path>,
    json: Option<&Path>,
    out: &mut dyn Write,
) -> Result<()> {
    let list = match inputs {
        Some(l) => Some(core::list_inputs(l)?),
        None => None,
    };
    let s = core::summarize(outdir, list.as_deref())?;
    if let Some(p) = json.filter(|p| p.as_os_str() != "-") {
        refuse_batch_file(p, outdir, inputs, list.as_deref().unwrap_or_default(), &s)?;
    }
    match json {
        Some(p) if p.as_os_str() == "-" => print_json(out, &s)?,
        Some(p) => {
            write_json(p, &s)?;
            print_summary(out, &s)?;
        }
        None => print_summary(out, &s)?,
    }
    for u in s.unreadable.iter().chain(&s.stale) {
        print_error(u);
    }
    let mixed = s.settings.len() > 1;
    if !s.missing.is_empty() || !s.unreadable.is_empty() || !s.stale.is_empty() || mixed {
        let mut what = Vec::new();
        if !s.missing.is_empty() {
            let shown: Vec<&str> = s.missing.iter().take(5).map(String::as_str).collect();
            let more = s.missing.len() - shown.len();
            what.push(format!(
                "{} of {} inputs have no marker: {}{}",
                s.missing.len(),
                s.inputs.unwrap_or(0),
                shown.join(", "),
                if more > 0 {
                    format!(" and {more} more")
                } else {
                    String::new()
                }
            ));
        }
        if !s.unreadable.is_empty() {
            what.push(format!("{} markers are unreadable", s.unreadable.len()));
        }
        if !s.stale.is_empty() {
            what.push(format!(
                "{} markers no longer hold (see above; a rerun redoes them)",
                s.stale.len()
            ));
        }
        if mixed {
            what.push(format!(
                "the outputs were made with {} different settings: {}",
                s.settings.len(),
                s.settings.join(" and ")
            ));
        }
        return Err(Error::Incomplete {
            what: format!("{}: {}", outdir.display(), what.join("; ")),
        });
    }
    Ok(())
}

/// Refuse to write the summary `target` over a file of the batch: its input list, an input, an
/// output (present or to come) or a marker.
fn refuse_batch_file(
    target: &Path,
    outdir: &Path,
    list: Option<&Path>,
    inputs: &[PathBuf],
    s: &core::BatchSummary,
) -> Result<()> {
    let mut files: Vec<(&str, PathBuf)> = Vec::new();
    if let Some(l) = list.filter(|l| l.is_file()) {
        files.push(("the input list", l.to_path_buf()));
    }
    for input in inputs {
        files.push(("an input", input.clone()));
        for format in [Format::Ply, Format::Obj, Format::Off, Format::Stl] {
            files.push(("an output", core::output_path(outdir, input, format)?));
        }
        files.push(("a marker", core::marker_path(outdir, input)?));
    }
    for m in &s.meshes {
        files.push(("an input", PathBuf::from(&m.input)));
        files.push(("an output", PathBuf::from(&m.output)));
    }
    if let Ok(entries) = std::fs::read_dir(outdir.join(core::MARKER_DIR)) {
        files.extend(entries.flatten().map(|e| ("a marker", e.path())));
    }
    let target_id = Identity::of(target);
    match files
        .into_iter()
        .find(|(_, f)| Identity::of(f) == target_id)
    {
        Some((what, f)) => Err(Error::invalid(
            target,
            format!(
                "is {what} of the batch ({}): the summary would overwrite it",
                f.display()
            ),
        )),
        None => Ok(()),
    }
}

fn print_summary(out: &mut dyn Write, s: &core::BatchSummary) -> Result<()> {
    let w = s
        .meshes
        .iter()
        .map(|m| m.name.chars().count())
        .max()
        .unwrap_or(4)
        .max(4);
    let mut text = format!(
        "{:<w$}  {:>12}  {:<12}  {:>10}  {:>12}  {:>10}\n",
        "mesh", "triangles", "method", "iterations", "volume %", "seconds"
    );
    for m in &s.meshes {
        text += &format!(
            "{:<w$}  {:>12}  {:<12}  {:>10}  {:>12}  {:>10.3}\n",
            m.name,
            m.triangles,
            m.method,
            m.iterations,
            fixed(m.volume_pct, 6),
            m.seconds
        );
    }
    let t = &s.totals;
    text += &format!(
        "{:<w$}  {:>12}  {:<12}  {:>10}  {:>12}  {:>10.3}\n",
        format!("total ({})", t.meshes),
        t.triangles,
        "",
        "",
        match (t.min_volume_pct, t.max_volume_pct) {
            (Some(a), Some(b)) if (a - b).abs() < 5e-7 => format!("{a:.6}"),
            (Some(a), Some(b)) => format!("{a:.3}–{b:.3}"),
            _ => String::new(),
        },
        t.seconds
    );
    if let Some(n) = s.inputs {
        text += &format!(
            "{} of {n} inputs done, {} missing\n",
            n - s.missing.len(),
            s.missing.len()
        );
        for m in &s.missing {
            text += &format!("missing: {m}\n");
        }
    }
    out.write_all(text.as_bytes()).map_err(stdout_error)
}

/// The one line of a failed input: the error, led by the input's name unless it names a file.
fn failure(input: &Path, e: &Error) -> String {
    let message = flags::message(e);
    match e {
        Error::InvalidInput { .. } | Error::Io { .. } | Error::Topology { path: Some(_), .. } => {
            message
        }
        _ => format!("{}: {message}", input.display()),
    }
}

/// Runs `f`; a panic in it (or in the threads it waits for) is returned as its message and
/// place instead of being printed by the panic hook, so that the input it broke is reported in one
/// line, with it.
fn catch_panic<T>(f: impl FnOnce() -> T) -> std::result::Result<T, String> {
    static LAST: Mutex<String> = Mutex::new(String::new());
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(|info| {
        *LAST.lock().unwrap_or_else(|e| e.into_inner()) = crate::cli::panic_message(info);
    }));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    std::panic::set_hook(previous);
    result.map_err(|_| LAST.lock().unwrap_or_else(|e| e.into_inner()).clone())
}

fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_default()
}
