//! `vcsmooth slurm-script LIST_OR_DIR OUTDIR [smooth options] ...`: print a ready Slurm script, an
//! array job running `batch` over the inputs and a dependent summary job. The script is the
//! template `slurm_script.sh.in` with its `@name@` placeholders filled in.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::Args as ClapArgs;

use crate::cli::batch_smooth::{BatchSmooth, BatchSmoothArgs, batch_inputs};
use crate::cli::flags;
use crate::cli::output::stdout_error;
use crate::error::{Error, Result};
use crate::modes::batch as core;

/// The script, with `@name@` placeholders.
const TEMPLATE: &str = include_str!("slurm_script.sh.in");

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
    /// CPUs per array task, also passed as --threads, 1 to 4096 [default: --threads, else 1].
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..=crate::cli::shared::MAX_THREADS as i64))]
    pub cpus: Option<u32>,
    /// Largest array size allowed (indices stay below it); more inputs than that share tasks [default: MaxArraySize of `scontrol show config`, else 1001].
    #[arg(long, value_name = "M", allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(1..))]
    pub max_array_size: Option<u32>,
    /// Name of the array job (the summary job is NAME-summary).
    #[arg(long, value_name = "NAME", default_value = "vcsmooth")]
    pub job_name: String,
    /// The vcsmooth executable the jobs run [default: this one].
    #[arg(long, value_name = "PATH")]
    pub vcsmooth: Option<PathBuf>,
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
                    return Err(flags::parameter(
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

/// `vcsmooth slurm-script`: print the wrapper that writes and submits the array and summary jobs.
pub fn run(cfg: &SlurmScriptConfig, out: &mut dyn Write) -> Result<()> {
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
    let mem = core::slurm_mem_mib(largest.0, &cfg.smooth.options);
    let a = &cfg.smooth.args.smoothing;
    let cpus = cfg.cpus.or(a.engine.threads).unwrap_or(1);

    // The flags of `batch`, repeated.
    let mut flags: Vec<String> = vec![
        "--method".into(),
        cfg.smooth.options.method.name().into(),
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
    if let Some(a) = a.params.crease_angle {
        flags.extend(["--crease-angle".into(), a.to_string()]);
    }
    if let Some(d) = a.params.max_deviation {
        flags.extend(["--max-deviation".into(), d.to_string()]);
    }
    if !a.params.boundary.is_fixed() {
        flags.extend(["--boundary".into(), a.params.boundary.name().into()]);
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
    if let Some(name) = &cfg.smooth.args.pins.pin_property {
        flags.extend(["--pin-property".into(), name.clone()]);
    }
    flags.extend(["--format".into(), core::extension(cfg.smooth.format).into()]);
    let flags: Vec<String> = flags.iter().map(|f| quote(f)).collect();

    let jobs = format!("{outdir_text}/.slurm");
    let partition_line = cfg
        .partition
        .as_ref()
        .map_or(String::new(), |p| format!("#SBATCH --partition={p}\n"));
    let time_line = cfg
        .time
        .as_ref()
        .map_or(String::new(), |t| format!("#SBATCH --time={t}\n"));
    let summary_time_line = if cfg.time.is_some() {
        "#SBATCH --time=0:10:00\n"
    } else {
        ""
    };
    let script = fill(
        TEMPLATE,
        &[
            ("version", env!("CARGO_PKG_VERSION").to_string()),
            ("jobs", jobs.clone()),
            ("jobs_q", quote(&jobs)),
            ("tasks", tasks.to_string()),
            ("tasks2", (2 * tasks).to_string()),
            ("last", (tasks - 1).to_string()),
            ("max_array", max_array.to_string()),
            ("max_source", max_source),
            ("inputs", inputs.len().to_string()),
            ("list_name", list.display().to_string()),
            ("per_task", inputs.len().div_ceil(tasks).to_string()),
            ("outdir", outdir_text.clone()),
            ("ext", core::extension(cfg.smooth.format).to_string()),
            ("mem", mem.to_string()),
            (
                "largest_size",
                crate::engine::memory::format_size(largest.0),
            ),
            ("largest_name", largest.1.display().to_string()),
            ("name", cfg.job_name.clone()),
            ("cpus", cpus.to_string()),
            ("time_line", time_line),
            ("summary_time_line", summary_time_line.to_string()),
            ("partition_line", partition_line),
            ("exe_q", quote(&exe.display().to_string())),
            ("list_q", quote(&list.display().to_string())),
            ("outdir_q", quote(&outdir_text)),
            ("flags", flags.join(" ")),
            ("summary_q", quote(&format!("{outdir_text}/summary.json"))),
        ],
    );
    out.write_all(script.as_bytes()).map_err(stdout_error)
}

/// `template` with each `@name@` replaced by the value of `name` in `values`, in one pass (a
/// value is never scanned for placeholders); an `@` that starts no known placeholder stays.
fn fill(template: &str, values: &[(&str, String)]) -> String {
    let mut out = String::with_capacity(template.len() + 1024);
    let mut rest = template;
    while let Some(at) = rest.find('@') {
        out.push_str(&rest[..at]);
        let after = &rest[at + 1..];
        let name = after.find('@').map(|end| &after[..end]).filter(|n| {
            !n.is_empty()
                && n.bytes()
                    .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
        });
        match name {
            Some(name) => {
                let value = values.iter().find(|(n, _)| *n == name);
                debug_assert!(value.is_some(), "no value for the placeholder @{name}@");
                out.push_str(value.map_or("", |(_, v)| v.as_str()));
                rest = &after[name.len() + 1..];
            }
            None => {
                out.push('@');
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
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

    #[test]
    fn placeholders_filled_once() {
        let values = [("a", "@b@".to_string()), ("b", "x".to_string())];
        assert_eq!(fill("@a@-@b@ ${v[@]} a@b", &values), "@b@-x ${v[@]} a@b");
        assert_eq!(fill("@a@@b@", &values), "@b@x");
        let values = [("a2", "y".to_string())];
        assert_eq!(fill("I+@a2@, @@", &values), "I+y, @@");
    }
}
