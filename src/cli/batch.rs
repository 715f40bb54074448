//! `vcsmooth batch` (many meshes, one share per job-array task; `--summary` gathers the markers)
//! and `vcsmooth slurm-script` (a ready Slurm array job for a batch). The logic lives in
//! [`crate::modes::batch`]; this module holds the flags, their resolution and the printing.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::{Args as ClapArgs, ValueEnum};

use super::config::EngineConfig;
use super::output::{print_json, stdout_error, write_json};
use super::progress::Progress;
use crate::engine;
use crate::error::{Error, Result};
use crate::io::Format;
use crate::modes::batch::{self as core, Marker, MeshRow};
use crate::smooth::Options;

/// Output formats of `batch --format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OutputFormat {
    Ply,
    Obj,
    Off,
    Stl,
}

impl From<OutputFormat> for Format {
    fn from(f: OutputFormat) -> Format {
        match f {
            OutputFormat::Ply => Format::Ply,
            OutputFormat::Obj => Format::Obj,
            OutputFormat::Off => Format::Off,
            OutputFormat::Stl => Format::Stl,
        }
    }
}

/// The smoothing flags of `smooth`, for every mesh of a batch, plus the output format.
#[derive(Debug, Clone, ClapArgs)]
pub struct BatchSmoothArgs {
    #[command(flatten)]
    pub smoothing: super::args::SmoothingArgs,
    /// Format of the outputs, OUTDIR/<input's stem>.<format>.
    #[arg(long, value_enum, default_value_t = OutputFormat::Ply)]
    pub format: OutputFormat,
}

/// `vcsmooth batch LIST_OR_DIR OUTDIR [smooth options] [--task-index I --task-count N]` or
/// `vcsmooth batch --summary OUTDIR [--inputs LIST_OR_DIR] [--json FILE|-]`
#[derive(Debug, Clone, ClapArgs)]
pub struct BatchArgs {
    /// A directory (its .ply/.obj/.off/.stl files, sorted by name) or a file listing one mesh per line (relative to the list's directory; blank lines and #comments skipped).
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

/// `vcsmooth slurm-script LIST_OR_DIR OUTDIR [smooth options] [--partition P] [--time T] [--cpus N] [--max-array-size M]`
#[derive(Debug, Clone, ClapArgs)]
pub struct SlurmScriptArgs {
    /// A directory of meshes or a list file, as for `batch`.
    #[arg(value_name = "LIST_OR_DIR")]
    pub inputs: PathBuf,
    /// Directory of the outputs and markers (created by the script).
    #[arg(value_name = "OUTDIR")]
    pub outdir: PathBuf,
    #[command(flatten)]
    pub smooth: BatchSmoothArgs,
    /// Slurm partition [default: the cluster's default].
    #[arg(long, value_name = "P")]
    pub partition: Option<String>,
    /// Time limit of each array task, in sbatch's syntax (e.g. 2:00:00) [default: the partition's].
    #[arg(long, value_name = "T")]
    pub time: Option<String>,
    /// CPUs per array task, also passed as --threads [default: --threads, else 1].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub cpus: Option<u32>,
    /// Largest array size allowed (indices stay below it); more inputs than that share tasks [default: MaxArraySize of `scontrol show config`, else 1001].
    #[arg(long, value_name = "M", value_parser = clap::value_parser!(u32).range(1..))]
    pub max_array_size: Option<u32>,
    /// Name of the array job (the summary job is NAME-summary).
    #[arg(long, value_name = "NAME", default_value = "vcsmooth")]
    pub job_name: String,
    /// The vcsmooth executable the jobs run [default: this one].
    #[arg(long, value_name = "PATH")]
    pub vcsmooth: Option<PathBuf>,
}

/// The smoothing a batch applies to each of its meshes.
#[derive(Debug, Clone)]
pub struct BatchSmooth {
    pub options: Options,
    pub engine: EngineConfig,
    pub format: Format,
    /// The flags as given, to repeat them in a job script.
    pub args: BatchSmoothArgs,
}

impl BatchSmooth {
    fn from_args(a: BatchSmoothArgs) -> Result<BatchSmooth> {
        let s = &a.smoothing;
        let mut engine = super::config::engine(&s.engine)?;
        engine.with_stats = true;
        Ok(BatchSmooth {
            options: super::config::options(s.method, s.iterations, &s.params),
            engine,
            format: a.format.into(),
            args: a,
        })
    }
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
            if let Some(j) = &a.json {
                if j.as_os_str() != "-" {
                    if let Some(dir) = j.parent().filter(|d| !d.as_os_str().is_empty()) {
                        if !dir.is_dir() {
                            return Err(Error::invalid(
                                j,
                                format!("directory '{}' does not exist", dir.display()),
                            ));
                        }
                    }
                }
            }
            return Ok(BatchConfig::Summary {
                outdir,
                inputs: a.summary_inputs,
                json: a.json,
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

/// `vcsmooth slurm-script`, resolved.
#[derive(Debug, Clone)]
pub struct SlurmScriptConfig {
    pub inputs: PathBuf,
    pub outdir: PathBuf,
    pub smooth: BatchSmooth,
    pub partition: Option<String>,
    pub time: Option<String>,
    pub cpus: Option<u32>,
    pub max_array_size: Option<u32>,
    pub job_name: String,
    pub vcsmooth: Option<PathBuf>,
}

impl SlurmScriptConfig {
    pub fn from_args(a: SlurmScriptArgs) -> Result<SlurmScriptConfig> {
        for (name, v) in [
            ("partition", &a.partition),
            ("time", &a.time),
            ("job_name", &Some(a.job_name.clone())),
        ] {
            if let Some(v) = v {
                if v.is_empty()
                    || v.chars()
                        .any(|c| c.is_whitespace() || c == '\'' || c == '"')
                {
                    return Err(super::flags::parameter(
                        name,
                        format!("'{v}' must be one word without quotes"),
                    ));
                }
            }
        }
        Ok(SlurmScriptConfig {
            inputs: a.inputs,
            outdir: a.outdir,
            smooth: BatchSmooth::from_args(a.smooth)?,
            partition: a.partition,
            time: a.time,
            cpus: a.cpus,
            max_array_size: a.max_array_size,
            job_name: a.job_name,
            vcsmooth: a.vcsmooth,
        })
    }
}

/// `vcsmooth batch`: smooth this task's share, or print the summary.
pub fn batch(cfg: &BatchConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
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

/// The inputs of a batch, checked: at least one, no two with the same stem, none that its output
/// would overwrite.
fn batch_inputs(list_or_dir: &Path, outdir: &Path, format: Format) -> Result<Vec<PathBuf>> {
    let inputs = core::list_inputs(list_or_dir)?;
    if inputs.is_empty() {
        return Err(Error::invalid(
            list_or_dir,
            "names no mesh files (.ply, .obj, .off or .stl)",
        ));
    }
    core::check_stems(&inputs)?;
    if let Ok(out) = outdir.canonicalize() {
        for input in &inputs {
            let same_dir = input
                .parent()
                .map(|p| {
                    if p.as_os_str().is_empty() {
                        Path::new(".")
                    } else {
                        p
                    }
                })
                .and_then(|p| p.canonicalize().ok())
                .is_some_and(|p| p == out);
            if same_dir && Format::from_extension(input) == Some(format) {
                let name = core::output_path(outdir, input, format)?;
                if name.file_name() == input.file_name() {
                    return Err(Error::invalid(
                        input,
                        "its output would overwrite it: choose another OUTDIR or --format",
                    ));
                }
            }
        }
    }
    Ok(inputs)
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
    let (mut done, mut skipped, mut failed) = (0usize, 0usize, 0usize);
    for k in mine {
        let input = &inputs[k];
        let output = core::output_path(outdir, input, smooth.format)?;
        let marker = core::marker_path(outdir, input)?;
        if marker.exists() {
            skipped += 1;
            writeln!(out, "skipped {}: already done", input.display()).map_err(stdout_error)?;
            continue;
        }
        // A task killed while writing leaves its temporary files; this task owns the input now.
        remove_leftovers(&output);
        remove_leftovers(&marker);
        let clock = Instant::now();
        progress.phase(format!("smoothing {}", input.display()));
        progress.iterations(smooth.options.method.name(), smooth.options.iterations);
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            engine::run_file(input, &output, &smooth.options, &smooth.engine, progress)
        }));
        let result = match result {
            Ok(r) => r.and_then(|run| {
                let row = MeshRow {
                    name: core::stem(input)?,
                    input: input.display().to_string(),
                    output: output.display().to_string(),
                    method: smooth.options.method.name().to_string(),
                    iterations: smooth.options.iterations,
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
                    row,
                    options: &smooth.options,
                    engine: &smooth.engine,
                    run: &run,
                };
                write_json(&marker, &doc)?;
                Ok(doc.row)
            }),
            Err(_) => Err(Error::invalid(
                input,
                "internal error while smoothing (a bug, please report it)",
            )),
        };
        match result {
            Ok(row) => {
                done += 1;
                writeln!(
                    out,
                    "done {} -> {}: {} triangles, {} × {}, volume {:.6} %, {:.3} s",
                    row.input,
                    row.output,
                    row.triangles,
                    row.iterations,
                    row.method,
                    row.volume_pct,
                    row.seconds
                )
                .map_err(stdout_error)?;
            }
            Err(e) => {
                failed += 1;
                eprintln!("vcsmooth: error: {}", one_line(&super::flags::message(&e)));
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
        return Err(Error::Incomplete {
            what: format!(
                "{failed} of the inputs of task {index} of {count} failed (see above); rerun the task to retry them"
            ),
        });
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
    match json {
        Some(p) if p.as_os_str() == "-" => print_json(out, &s)?,
        Some(p) => {
            write_json(p, &s)?;
            print_summary(out, &s)?;
        }
        None => print_summary(out, &s)?,
    }
    for u in &s.unreadable {
        eprintln!("vcsmooth: error: {}", one_line(u));
    }
    if !s.missing.is_empty() || !s.unreadable.is_empty() {
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
        return Err(Error::Incomplete {
            what: format!("{}: {}", outdir.display(), what.join("; ")),
        });
    }
    Ok(())
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
            "{:<w$}  {:>12}  {:<12}  {:>10}  {:>12.6}  {:>10.3}\n",
            m.name, m.triangles, m.method, m.iterations, m.volume_pct, m.seconds
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

/// `vcsmooth slurm-script`: print the wrapper that writes and submits the array and summary jobs.
pub fn slurm_script(cfg: &SlurmScriptConfig, out: &mut dyn Write) -> Result<()> {
    let inputs = batch_inputs(&cfg.inputs, &cfg.outdir, cfg.smooth.format)?;
    let mut largest = (0u64, PathBuf::new());
    for input in &inputs {
        let len = std::fs::metadata(input)
            .map_err(|e| Error::io(input, e))?
            .len();
        if len >= largest.0 {
            largest = (len, input.clone());
        }
    }
    let list = absolute(&cfg.inputs)?;
    let outdir = absolute(&cfg.outdir)?;
    let outdir_text = outdir.display().to_string();
    if outdir_text
        .chars()
        .any(|c| c.is_whitespace() || c == '%' || c == '\'' || c == '"')
    {
        return Err(Error::invalid(
            &outdir,
            "a Slurm job's OUTDIR must not contain whitespace, quotes or '%' (it names the job logs)",
        ));
    }
    let exe = match &cfg.vcsmooth {
        Some(p) => absolute(p)?,
        None => std::env::current_exe().map_err(|e| Error::io("vcsmooth", e))?,
    };
    let (max_array, max_source) = match cfg.max_array_size {
        Some(m) => (m as usize, "--max-array-size".to_string()),
        None => match scontrol_max_array_size() {
            Some(m) => (m, "MaxArraySize of scontrol show config".to_string()),
            None => (1001, "Slurm's default MaxArraySize".to_string()),
        },
    };
    let tasks = core::array_tasks(inputs.len(), max_array);
    let per_task = inputs.len().div_ceil(tasks);
    let mem = core::slurm_mem_mib(largest.0);
    let a = &cfg.smooth.args.smoothing;
    let cpus = cfg.cpus.or(a.engine.threads).unwrap_or(1);

    // The flags of `batch`, repeated.
    let mut flags: Vec<String> = vec![
        "--method".into(),
        a.method.name().into(),
        "--iterations".into(),
        a.iterations.to_string(),
        "--lambda".into(),
        a.params.lambda.to_string(),
        "--mu".into(),
        a.params.mu.to_string(),
    ];
    if a.params.reject_energy_increase {
        flags.push("--reject-energy-increase".into());
    }
    flags.extend(["--threads".into(), cpus.to_string()]);
    if let Some(p) = a.engine.patch_size {
        flags.extend(["--patch-size".into(), p.to_string()]);
    }
    let budget = a
        .engine
        .memory_budget
        .map_or_else(|| format!("{}M", mem / 4 * 3), |b| b.to_string());
    flags.extend(["--memory-budget".into(), budget]);
    if let Some(s) = &a.engine.scratch {
        flags.extend(["--scratch".into(), absolute(s)?.display().to_string()]);
    }
    flags.extend(["--format".into(), core::extension(cfg.smooth.format).into()]);
    let flags: Vec<String> = flags.iter().map(|f| quote(f)).collect();

    let jobs = format!("{outdir_text}/.slurm");
    let mut common = String::new();
    if let Some(p) = &cfg.partition {
        common += &format!("#SBATCH --partition={p}\n");
    }
    let exe_q = quote(&exe.display().to_string());
    let list_q = quote(&list.display().to_string());
    let out_q = quote(&outdir_text);
    let name = &cfg.job_name;
    let version = env!("CARGO_PKG_VERSION");
    let n = inputs.len();
    let last = tasks - 1;
    let largest_size = crate::engine::memory::format_size(largest.0);
    let largest_name = largest.1.display();
    let time = cfg
        .time
        .as_ref()
        .map_or(String::new(), |t| format!("#SBATCH --time={t}\n"));
    let summary_time = if cfg.time.is_some() {
        "#SBATCH --time=0:10:00\n"
    } else {
        ""
    };
    let flags = flags.join(" ");
    let script = format!(
        r#"#!/bin/bash
# Generated by vcsmooth {version} (`vcsmooth slurm-script`). Run it with bash: it writes the job
# scripts to {jobs}/ and submits them with sbatch --parsable:
#   1. an array job of {tasks} tasks (indices 0-{last}, below the MaxArraySize {max_array} from {max_source})
#      over the {n} inputs of {list_name}: task I smooths inputs I, I+{tasks}, I+{tasks2}, ... of the
#      sorted list (at most {per_task} each), writing {outdir_text}/<stem>.{ext} and the success marker
#      {outdir_text}/.done/<stem>.json; inputs with a marker are skipped;
#   2. a summary job, run after every task ended (afterany; cancelled if the array job is invalid),
#      writing {outdir_text}/summary.json and exiting 1 if an input has no marker.
# --mem={mem}M: 8 x the largest input ({largest_size}, {largest_name}) + 256 MiB, at least 1 GiB;
# the engine's --memory-budget is 3/4 of it.
# To rerun failed or cancelled tasks (then a new summary):  bash THIS_FILE 3,5
set -euo pipefail
jobs={jobs_q}
mkdir -p "$jobs"
cat > "$jobs/array.sbatch" <<'VCSMOOTH_EOF'
#!/bin/bash
#SBATCH --job-name={name}
#SBATCH --array=0-{last}
#SBATCH --ntasks=1
#SBATCH --cpus-per-task={cpus}
#SBATCH --mem={mem}M
{time}{common}#SBATCH --output={jobs}/%A_%a.out
exec {exe_q} batch {list_q} {out_q} {flags} --task-index "$SLURM_ARRAY_TASK_ID" --task-count {tasks}
VCSMOOTH_EOF
cat > "$jobs/summary.sbatch" <<'VCSMOOTH_EOF'
#!/bin/bash
#SBATCH --job-name={name}-summary
#SBATCH --ntasks=1
#SBATCH --cpus-per-task=1
#SBATCH --mem=1G
{summary_time}{common}#SBATCH --output={jobs}/summary-%j.out
exec {exe_q} batch --summary {out_q} --inputs {list_q} --json {summary_q}
VCSMOOTH_EOF
array=()
if [ $# -gt 0 ]; then array=(--array="$1"); fi
array_job=$(sbatch --parsable "${{array[@]}}" "$jobs/array.sbatch")
array_job=${{array_job%%;*}}
summary_job=$(sbatch --parsable --dependency=afterany:"$array_job" --kill-on-invalid-dep=yes "$jobs/summary.sbatch")
summary_job=${{summary_job%%;*}}
echo "array job $array_job, summary job $summary_job"
"#,
        jobs = jobs,
        jobs_q = quote(&jobs),
        tasks2 = 2 * tasks,
        list_name = list.display(),
        ext = core::extension(cfg.smooth.format),
        summary_q = quote(&format!("{outdir_text}/summary.json")),
    );
    out.write_all(script.as_bytes()).map_err(stdout_error)
}

/// `path` made absolute against the current directory (without resolving links).
fn absolute(path: &Path) -> Result<PathBuf> {
    std::path::absolute(path).map_err(|e| Error::io(path, e))
}

/// Quote `s` for a POSIX shell when it needs it.
fn quote(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// MaxArraySize from `scontrol show config`, if scontrol answers within 10 seconds.
fn scontrol_max_array_size() -> Option<usize> {
    let mut child = std::process::Command::new("scontrol")
        .args(["show", "config"])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .ok()?;
    let start = Instant::now();
    loop {
        match child.try_wait() {
            Ok(Some(_)) => break,
            Ok(None) if start.elapsed() < Duration::from_secs(10) => {
                std::thread::sleep(Duration::from_millis(50));
            }
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
        }
    }
    let output = child.wait_with_output().ok()?;
    if !output.status.success() {
        return None;
    }
    parse_max_array_size(&String::from_utf8_lossy(&output.stdout))
}

/// The value of `MaxArraySize = N` in `scontrol show config` output.
fn parse_max_array_size(text: &str) -> Option<usize> {
    text.lines().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        (k.trim() == "MaxArraySize")
            .then(|| v.trim().parse().ok())
            .flatten()
            .filter(|&m| m > 0)
    })
}

/// Remove the temporary files `.<name>.tmp-*` that an atomic write of `path` interrupted by a
/// kill left beside it.
fn remove_leftovers(path: &Path) {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
        return;
    };
    let prefix = format!(".{}.tmp-", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        if entry.file_name().to_string_lossy().starts_with(&prefix) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_default()
}

/// Collapse whitespace runs (newlines included) into single spaces.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scontrol_output_parsed() {
        let text = "MailProg                = /bin/mail\nMaxArraySize            = 4001\nMaxJobCount = 10000\n";
        assert_eq!(parse_max_array_size(text), Some(4001));
        assert_eq!(parse_max_array_size("MaxJobCount = 3\n"), None);
    }

    #[test]
    fn shell_quoting() {
        assert_eq!(quote("/a/b.ply"), "/a/b.ply");
        assert_eq!(quote("a b"), "'a b'");
        assert_eq!(quote("it's"), r"'it'\''s'");
    }
}
