//! `vcsmooth slurm-script LIST_OR_DIR OUTDIR [smooth options] ...`: print a ready Slurm script, an
//! array job running `batch` over the inputs and a dependent summary job. The script is the
//! template `slurm_script.sh.in` with its `@name@` placeholders filled in.

use std::ffi::{OsStr, OsString};
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
                if !sbatch_value(v, &[]) {
                    return Err(flags::parameter(
                        name,
                        format!(
                            "{} must be one word without quotes, backslashes, '#' or control characters",
                            comment_text(v.as_ref())
                        ),
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
    // OUTDIR names the job logs in #SBATCH lines, which sbatch reads itself ('%' starts its
    // file name patterns).
    let Some(outdir_text) = outdir.to_str().filter(|o| sbatch_value(o, &['%'])) else {
        return Err(Error::invalid(
            comment_text(outdir.as_os_str()),
            "a Slurm job's OUTDIR must be UTF-8 without whitespace, quotes, backslashes, '#', '%' or control characters (it names the job logs)",
        ));
    };
    let outdir_text = outdir_text.to_string();
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
    let mut flags: Vec<OsString> = vec![
        "--method".into(),
        cfg.smooth.options.method.name().into(),
        "--iterations".into(),
        a.iterations.to_string().into(),
        "--lambda".into(),
        a.params.lambda.to_string().into(),
        "--mu".into(),
        cfg.smooth.options.mu().to_string().into(),
    ];
    if a.params.reject_energy_increase {
        flags.push("--reject-energy-increase".into());
    }
    if let Some(a) = a.params.crease_angle {
        flags.extend(["--crease-angle".into(), a.to_string().into()]);
    }
    if let Some(d) = a.params.max_deviation {
        flags.extend(["--max-deviation".into(), d.to_string().into()]);
    }
    if !a.params.boundary.is_fixed() {
        flags.extend(["--boundary".into(), a.params.boundary.name().into()]);
    }
    flags.extend(["--threads".into(), cpus.to_string().into()]);
    if let Some(p) = a.engine.patch_size {
        flags.extend(["--patch-size".into(), p.to_string().into()]);
    }
    let budget = a
        .engine
        .memory_budget
        .map_or_else(|| format!("{}M", mem / 4 * 3), |b| b.to_string());
    flags.extend(["--memory-budget".into(), budget.into()]);
    if let Some(s) = &a.engine.scratch {
        flags.extend(["--scratch".into(), absolute(s)?.into_os_string()]);
    }
    if let Some(name) = &cfg.smooth.args.pins.pin_property {
        flags.extend(["--pin-property".into(), name.into()]);
    }
    flags.extend(["--format".into(), core::extension(cfg.smooth.format).into()]);

    let jobs = format!("{outdir_text}/.slurm");
    let mut sbatch = Vec::new();
    sbatch.extend(cfg.time.iter().map(|t| ("time", t.clone())));
    sbatch.extend(cfg.partition.iter().map(|p| ("partition", p.clone())));
    let mut summary_sbatch = Vec::new();
    if cfg.time.is_some() {
        summary_sbatch.push(("time", "0:10:00".to_string()));
    }
    summary_sbatch.extend(cfg.partition.iter().map(|p| ("partition", p.clone())));
    let text = |t: &dyn std::fmt::Display| Value::Text(t.to_string().into());
    let word = |w: &OsStr| Value::Words(vec![w.to_os_string()]);
    let script = fill(
        TEMPLATE,
        &[
            ("version", text(&env!("CARGO_PKG_VERSION"))),
            ("jobs", text(&jobs)),
            ("jobs_q", word(jobs.as_ref())),
            ("tasks", text(&tasks)),
            ("tasks2", text(&(2 * tasks))),
            ("last", text(&(tasks - 1))),
            ("max_array", text(&max_array)),
            ("max_source", text(&max_source)),
            ("inputs", text(&inputs.len())),
            ("list_name", Value::Text(list.clone().into_os_string())),
            ("per_task", text(&inputs.len().div_ceil(tasks))),
            ("outdir", text(&outdir_text)),
            ("ext", text(&core::extension(cfg.smooth.format))),
            ("mem", text(&mem)),
            (
                "largest_size",
                text(&crate::engine::memory::format_size(largest.0)),
            ),
            ("largest_name", Value::Text(largest.1.into_os_string())),
            ("name", text(&cfg.job_name)),
            ("cpus", text(&cpus)),
            ("sbatch_lines", Value::Sbatch(sbatch)),
            ("summary_sbatch_lines", Value::Sbatch(summary_sbatch)),
            ("exe_q", word(exe.as_os_str())),
            ("list_q", word(list.as_os_str())),
            ("outdir_q", word(outdir_text.as_ref())),
            ("flags", Value::Words(flags)),
            (
                "summary_q",
                word(format!("{outdir_text}/summary.json").as_ref()),
            ),
        ],
    );
    out.write_all(script.as_bytes()).map_err(stdout_error)
}

/// A value for a placeholder of the template. Every piece of text that comes from a path or a
/// flag reaches the script as one of these, made safe for where it goes by [`Value::render`],
/// the one place that knows how.
enum Value {
    /// Text in a comment or in an `#SBATCH` line (whose values [`sbatch_value`] checks):
    /// escaped by [`comment_text`], so that nothing in it ends the line.
    Text(OsString),
    /// Shell words, each quoted by [`shell_word`], separated by spaces.
    Words(Vec<OsString>),
    /// Optional `#SBATCH --option=value` lines, each value as [`Value::Text`].
    Sbatch(Vec<(&'static str, String)>),
}

impl Value {
    fn render(&self) -> String {
        match self {
            Value::Text(t) => comment_text(t),
            Value::Words(words) => {
                let words: Vec<String> = words.iter().map(|w| shell_word(w)).collect();
                words.join(" ")
            }
            Value::Sbatch(lines) => lines
                .iter()
                .map(|(option, v)| format!("#SBATCH --{option}={}\n", comment_text(v.as_ref())))
                .collect(),
        }
    }
}

/// Whether sbatch reads `text` back as it is from an `#SBATCH --option=text` line: not empty, no
/// whitespace (it ends the value), quote or backslash (sbatch takes them away), `#` (it starts a
/// comment), control character (a line break ends the line), nor any of `also`.
fn sbatch_value(text: &str, also: &[char]) -> bool {
    !text.is_empty()
        && !text.chars().any(|c| {
            c.is_whitespace()
                || c.is_control()
                || matches!(c, '\'' | '"' | '\\' | '#')
                || also.contains(&c)
        })
}

/// `template` with each `@name@` replaced by the value of `name` in `values`, rendered
/// ([`Value::render`]), in one pass (a value is never scanned for placeholders); an `@` that
/// starts no known placeholder stays.
fn fill(template: &str, values: &[(&str, Value)]) -> String {
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
                out.push_str(&value.map_or(String::new(), |(_, v)| v.render()));
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

/// `word` as one bash word that reads back as exactly its bytes: as it is when every byte is
/// plain; in single quotes when it is printable UTF-8; else in ANSI-C quotes (`$'...'`) with
/// every control character, line separator, quote, backslash and byte that is not UTF-8 escaped.
/// The result never holds a line break, so it cannot end a here-document or a comment.
fn shell_word(word: &OsStr) -> String {
    let bytes = word.as_encoded_bytes();
    let plain = !bytes.is_empty()
        && bytes
            .iter()
            .all(|&b| b.is_ascii_alphanumeric() || b"-_./=:,+@%".contains(&b));
    if plain {
        return String::from_utf8_lossy(bytes).into_owned();
    }
    match word.to_str() {
        Some(text) if !text.chars().any(unprintable) => {
            format!("'{}'", text.replace('\'', r"'\''"))
        }
        _ => {
            let mut out = String::from("$'");
            escape(bytes, &mut out, |c| matches!(c, '\'' | '\\'));
            out.push('\'');
            out
        }
    }
}

/// `text` for a comment line (or an `#SBATCH` value): every control character, line separator,
/// bidirectional override and byte that is not UTF-8 written as an escape (`\n`, `\x1b`,
/// `\u{2028}`), and a backslash as `\\`, so that the text stays on its line and reads as it is.
fn comment_text(text: &OsStr) -> String {
    let mut out = String::new();
    escape(text.as_encoded_bytes(), &mut out, |c| c == '\\');
    out
}

/// Characters that change how a line reads or where it ends.
fn unprintable(c: char) -> bool {
    c.is_control()
        || matches!(c, '\u{2028}' | '\u{2029}' | '\u{200e}' | '\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}')
}

/// `bytes` appended to `out` with [`unprintable`] characters, bytes that are not UTF-8 and the
/// characters `special` says escaped, in the escapes of bash's `$'...'`.
fn escape(bytes: &[u8], out: &mut String, special: impl Fn(char) -> bool) {
    for chunk in bytes.utf8_chunks() {
        for c in chunk.valid().chars() {
            match c {
                '\n' => out.push_str("\\n"),
                '\r' => out.push_str("\\r"),
                '\t' => out.push_str("\\t"),
                c if special(c) => {
                    out.push('\\');
                    out.push(c);
                }
                c if unprintable(c) => {
                    let mut utf8 = [0; 4];
                    for b in c.encode_utf8(&mut utf8).bytes() {
                        out.push_str(&format!("\\x{b:02x}"));
                    }
                }
                c => out.push(c),
            }
        }
        for b in chunk.invalid() {
            out.push_str(&format!("\\x{b:02x}"));
        }
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
        let q = |s: &str| shell_word(s.as_ref());
        assert_eq!(q("/a/b.ply"), "/a/b.ply");
        assert_eq!(q("a b"), "'a b'");
        assert_eq!(q("it's"), r"'it'\''s'");
        assert_eq!(q(""), "''");
        assert_eq!(q("$(touch x)`y`#"), "'$(touch x)`y`#'");
        assert_eq!(q("a\nb"), r"$'a\nb'");
        assert_eq!(q("it's\r\u{1b}\\"), r"$'it\'s\r\x1b\\'");
        assert_eq!(q("é\u{2028}"), r"$'é\xe2\x80\xa8'");
        use std::os::unix::ffi::OsStrExt;
        let raw = OsStr::from_bytes(b"a\xff\xfe b");
        assert_eq!(shell_word(raw), r"$'a\xff\xfe b'");
        // bash reads every word back as its bytes.
        let words: Vec<&OsStr> = [
            "plain",
            "a b",
            "it's",
            "x\ny",
            "tab\tcr\r",
            "\\back",
            "$(id)",
            "`id`",
            "#c",
            "é",
        ]
        .iter()
        .map(OsStr::new)
        .chain([raw])
        .collect();
        let script: Vec<String> = words
            .iter()
            .map(|w| format!("printf '%s\\0' {}", shell_word(w)))
            .collect();
        let out = std::process::Command::new("bash")
            .arg("-c")
            .arg(script.join("\n"))
            .output();
        if let Ok(out) = out {
            let back: Vec<&[u8]> = out.stdout.split(|&b| b == 0).collect();
            for (i, w) in words.iter().enumerate() {
                assert_eq!(back[i], w.as_encoded_bytes(), "{w:?}");
            }
        }
    }

    #[test]
    fn comment_text_stays_on_its_line() {
        let c = |s: &str| comment_text(s.as_ref());
        assert_eq!(c("/data/scan.ply"), "/data/scan.ply");
        assert_eq!(c("in\ntouch PWNED #"), r"in\ntouch PWNED #");
        assert_eq!(c("a\rb\u{1b}[2Jc\\"), r"a\rb\x1b[2Jc\\");
        assert_eq!(c("\u{202e}x\u{2029}"), r"\xe2\x80\xaex\xe2\x80\xa9");
        use std::os::unix::ffi::OsStrExt;
        assert_eq!(comment_text(OsStr::from_bytes(b"\xffz")), r"\xffz");
    }

    #[test]
    fn sbatch_values_are_one_word_sbatch_reads_as_it_is() {
        for good in ["debug", "2:00:00", "vcsmooth-1", "a.b_c"] {
            assert!(sbatch_value(good, &['%']), "{good}");
        }
        for bad in [
            "", "a b", "a\nb", "a'b", "a\"b", "a\\b", "a#b", "a\u{1}b", "a\u{85}b",
        ] {
            assert!(!sbatch_value(bad, &[]), "{bad:?}");
        }
        assert!(sbatch_value("50%", &[]) && !sbatch_value("50%", &['%']));
    }

    #[test]
    fn placeholders_filled_once() {
        let text = |s: &str| Value::Text(s.into());
        let values = [("a", text("@b@")), ("b", text("x"))];
        assert_eq!(fill("@a@-@b@ ${v[@]} a@b", &values), "@b@-x ${v[@]} a@b");
        assert_eq!(fill("@a@@b@", &values), "@b@x");
        let values = [("a2", text("y"))];
        assert_eq!(fill("I+@a2@, @@", &values), "I+y, @@");
        let values = [
            ("w", Value::Words(vec!["a b".into(), "c".into()])),
            ("l", Value::Sbatch(vec![("time", "1:00".into())])),
            ("t", text("x\ny")),
        ];
        assert_eq!(
            fill("@w@|@l@|@t@", &values),
            "'a b' c|#SBATCH --time=1:00\n|x\\ny"
        );
    }
}
