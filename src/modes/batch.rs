//! Many meshes as one batch, spread over the tasks of a job array (Slurm's, or any scheduler's
//! that numbers its tasks): which inputs a task owns, where their outputs and success markers go,
//! and the summary gathered from the markers. The CLI's `batch` and `slurm-script` commands
//! (`crate::cli::commands::{batch, slurm_script}`) are thin layers over this module.
//!
//! * Inputs: the entries of a directory with a mesh extension (`.ply .obj .off .stl`, any case;
//!   hidden ones skipped), sorted by file name; or the lines of a list file (blank lines and lines
//!   starting with `#` skipped; relative paths are relative to the list file's directory). An
//!   entry that cannot be read (a dangling symbolic link, a directory, no permission) is an input
//!   all the same: it fails with one line of its own, counts as failed, and the summary lists it as
//!   missing, so nothing in the directory is passed over in silence. The command line refuses
//!   OUTDIR = the input directory: the next run would take the outputs for inputs.
//! * Share: input `k` (0-based, in that order) belongs to task `k mod N` — a round-robin split, so
//!   every task gets ⌊n/N⌋ or ⌈n/N⌉ inputs and large and small files (which often sort together)
//!   are spread over the tasks.
//! * Outputs: `OUTDIR/<stem>.<ext>`; the success marker `OUTDIR/.done/<stem>.json` is written
//!   (atomically) only after the output was written (atomically), so a marker means "finished".
//! * Markers certify what they claim ([`Certificate`]): the input (canonical path, size,
//!   modification time in ns, inode), the settings that define the output (options, patch size,
//!   format) and the output (size, modification time, inode). A rerun skips an input only when its
//!   marker reads and all of these still match ([`check_marker`]); anything else (no marker, a
//!   garbage one, a deleted or changed output, a changed input, other settings) is redone, so
//!   rerunning a failed or killed task finishes the batch, and the summary counts as done exactly
//!   what a rerun would skip. The content is not hashed: that would read every input in full on
//!   every rerun (hours for a batch of large scans); an edit that keeps the size, the modification
//!   time and the inode goes unnoticed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::engine::{EngineSettings, Report, memory};
use crate::error::{Error, Result};
use crate::io::Format;
use crate::smooth::Options;

/// The subdirectory of OUTDIR holding the success markers.
pub const MARKER_DIR: &str = ".done";
/// The value of a marker's `format` field.
pub const MARKER_FORMAT: &str = "vcsmooth-batch-marker/1";

/// The inputs named by `list_or_dir`: a directory's mesh files sorted by name, or a list file's
/// lines in order.
pub fn list_inputs(list_or_dir: &Path) -> Result<Vec<PathBuf>> {
    let meta = std::fs::metadata(list_or_dir).map_err(|e| Error::io(list_or_dir, e))?;
    if meta.is_dir() {
        let mut files = Vec::new();
        for entry in std::fs::read_dir(list_or_dir).map_err(|e| Error::io(list_or_dir, e))? {
            let entry = entry.map_err(|e| Error::io(list_or_dir, e))?;
            let path = entry.path();
            let hidden = entry.file_name().to_string_lossy().starts_with('.');
            // Readable or not: an entry that cannot be read fails as an input, visibly.
            if !hidden && Format::from_extension(&path).is_some() {
                files.push(path);
            }
        }
        files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
        return Ok(files);
    }
    let text = std::fs::read_to_string(list_or_dir).map_err(|e| Error::io(list_or_dir, e))?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let base = list_or_dir.parent().unwrap_or(Path::new(""));
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| {
            let p = Path::new(l);
            if p.is_absolute() {
                p.to_path_buf()
            } else {
                base.join(p)
            }
        })
        .collect())
}

/// The name an input's output and marker are filed under: its file stem.
pub fn stem(input: &Path) -> Result<String> {
    input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty() && !s.starts_with('.'))
        .ok_or_else(|| Error::invalid(input, "an input of a batch needs a file name"))
}

/// Check that no two inputs share a stem (their outputs and markers would collide).
pub fn check_stems(inputs: &[PathBuf]) -> Result<()> {
    let mut seen: BTreeMap<String, &PathBuf> = BTreeMap::new();
    for input in inputs {
        let s = stem(input)?;
        if let Some(first) = seen.insert(s.clone(), input) {
            return Err(Error::invalid(
                input,
                format!(
                    "same name '{s}' as {}: both would be written to {s}.*; rename one",
                    first.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Indices (into the input list) owned by task `index` of `count`: `k` with `k mod count == index`.
pub fn share(inputs: usize, index: usize, count: usize) -> Vec<usize> {
    if count == 0 {
        return Vec::new();
    }
    (index..inputs).step_by(count).collect()
}

/// The array task this process is, from `index` and `count` if given, else from Slurm's environment
/// (`SLURM_ARRAY_TASK_ID` minus `SLURM_ARRAY_TASK_MIN`, of `SLURM_ARRAY_TASK_COUNT` or else
/// `MAX − MIN + 1`), else task 0 of 1.
pub fn resolve_task(
    index: Option<usize>,
    count: Option<usize>,
    env: &dyn Fn(&str) -> Option<String>,
) -> Result<(usize, usize)> {
    let num =
        |name: &'static str| -> Result<Option<usize>> {
            match env(name) {
                None => Ok(None),
                Some(v) if v.trim().is_empty() => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| {
                    Error::parameter(name, format!("must be a task number, got '{v}'"))
                }),
            }
        };
    let min = num("SLURM_ARRAY_TASK_MIN")?;
    let index = match index {
        Some(i) => i,
        None => match num("SLURM_ARRAY_TASK_ID")? {
            Some(id) => id.checked_sub(min.unwrap_or(0)).ok_or_else(|| {
                Error::parameter("SLURM_ARRAY_TASK_ID", "is below SLURM_ARRAY_TASK_MIN")
            })?,
            None => 0,
        },
    };
    let count = match count {
        Some(c) => c,
        None => match (
            num("SLURM_ARRAY_TASK_COUNT")?,
            min,
            num("SLURM_ARRAY_TASK_MAX")?,
        ) {
            (Some(c), _, _) => c,
            (None, Some(lo), Some(hi)) if hi >= lo => hi - lo + 1,
            _ => 1,
        },
    };
    if count == 0 {
        return Err(Error::parameter("task_count", "must be at least 1"));
    }
    if index >= count {
        return Err(Error::parameter(
            "task_index",
            format!(
                "{index} is not below the task count {count} (an array with a step or holes \
                 needs the task index and count given explicitly)"
            ),
        ));
    }
    Ok((index, count))
}

/// `OUTDIR/<stem>.<ext>` of an input.
pub fn output_path(outdir: &Path, input: &Path, format: Format) -> Result<PathBuf> {
    Ok(outdir.join(format!("{}.{}", stem(input)?, extension(format))))
}

/// `OUTDIR/.done/<stem>.json` of an input.
pub fn marker_path(outdir: &Path, input: &Path) -> Result<PathBuf> {
    Ok(outdir
        .join(MARKER_DIR)
        .join(format!("{}.json", stem(input)?)))
}

/// The file extension written for `format`.
pub fn extension(format: Format) -> &'static str {
    match format {
        Format::Ply => "ply",
        Format::Obj => "obj",
        Format::Off => "off",
        Format::Stl => "stl",
        Format::Gltf => "gltf",
        Format::Glb => "glb",
    }
}

/// The Slurm job this process runs in, if any (recorded in markers).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Eq)]
pub struct SlurmIds {
    pub job_id: Option<String>,
    pub array_job_id: Option<String>,
    pub array_task_id: Option<String>,
}

impl SlurmIds {
    pub fn from_env() -> Option<SlurmIds> {
        let get = |n: &str| std::env::var(n).ok();
        let ids = SlurmIds {
            job_id: get("SLURM_JOB_ID"),
            array_job_id: get("SLURM_ARRAY_JOB_ID"),
            array_task_id: get("SLURM_ARRAY_TASK_ID"),
        };
        ids.job_id.is_some().then_some(ids)
    }
}

/// The figures of one finished mesh: the head of its marker, and a row of the summary.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct MeshRow {
    /// The stem the output and marker are filed under.
    pub name: String,
    pub input: String,
    pub output: String,
    pub method: String,
    /// Iterations that ran (with `--iterations auto`, where the automatic stop ended the run).
    pub iterations: usize,
    pub vertices: usize,
    pub triangles: usize,
    /// Final volume and area as a percentage of the input's (NaN, `null`, against zero).
    #[serde(deserialize_with = "crate::engine::observer::nan_if_null")]
    pub volume_pct: f64,
    #[serde(deserialize_with = "crate::engine::observer::nan_if_null")]
    pub area_pct: f64,
    /// Wall-clock seconds of the whole file (read, prepare, smooth, write).
    pub seconds: f64,
    /// When the marker was written, seconds since the Unix epoch.
    pub finished_unix: u64,
    pub host: String,
    pub task_index: usize,
    pub task_count: usize,
    pub slurm: Option<SlurmIds>,
}

/// A success marker, `OUTDIR/.done/<stem>.json`: the summary row flattened at the top, what the
/// marker certifies, then the options, the engine settings and the whole [`Report`] report.
#[derive(Debug, Clone, Serialize)]
pub struct Marker<'a> {
    pub format: &'static str,
    pub version: &'static str,
    /// [`crate::RESULTS_VERSION`] of the output it certifies.
    pub results_version: u32,
    #[serde(flatten)]
    pub row: MeshRow,
    pub certifies: Certificate,
    pub options: &'a Options,
    pub engine: &'a EngineSettings,
    pub run: &'a Report,
}

/// Which file, as far as can be told without reading it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Eq)]
pub struct FileId {
    /// Canonical (absolute, links resolved).
    pub path: String,
    pub size: u64,
    /// Modification time, nanoseconds since the Unix epoch.
    pub mtime_ns: i64,
    /// Inode number (`None` where the platform has none): a file replaced by another one (a
    /// rename over it) is noticed even with the same size and time.
    pub inode: Option<u64>,
}

impl FileId {
    /// The identity of the file at `path`. A dangling symbolic link and a directory are errors that
    /// say so.
    pub fn of(path: &Path) -> Result<FileId> {
        let meta = match std::fs::metadata(path) {
            Ok(m) => m,
            Err(e) => {
                return Err(match std::fs::read_link(path) {
                    Ok(to) if e.kind() == std::io::ErrorKind::NotFound => Error::invalid(
                        path,
                        format!(
                            "a symbolic link to '{}', which does not exist",
                            to.display()
                        ),
                    ),
                    _ => Error::io(path, e),
                });
            }
        };
        if !meta.is_file() {
            return Err(Error::invalid(path, "not a regular file"));
        }
        let canonical = path.canonicalize().map_err(|e| Error::io(path, e))?;
        let mtime_ns = match meta.modified().map_err(|e| Error::io(path, e))? {
            t if t >= std::time::UNIX_EPOCH => {
                let d = t.duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
                i64::try_from(d.as_nanos()).unwrap_or(i64::MAX)
            }
            t => {
                let d = std::time::UNIX_EPOCH.duration_since(t).unwrap_or_default();
                i64::try_from(d.as_nanos()).map_or(i64::MIN, |n| -n)
            }
        };
        #[cfg(unix)]
        let inode = Some(std::os::unix::fs::MetadataExt::ino(&meta));
        #[cfg(not(unix))]
        let inode = None;
        Ok(FileId {
            path: canonical.display().to_string(),
            size: meta.len(),
            mtime_ns,
            inode,
        })
    }

    /// What differs from `then` (the same file as before when `None`); the path only if `path`.
    fn change(&self, then: &FileId, path: bool) -> Option<String> {
        if path && self.path != then.path {
            Some(format!("now '{}', was '{}'", self.path, then.path))
        } else if self.size != then.size {
            Some(format!("size {} bytes, was {}", self.size, then.size))
        } else if self.mtime_ns != then.mtime_ns {
            Some("modification time changed".to_string())
        } else if self.inode != then.inode {
            Some("replaced by another file (inode changed)".to_string())
        } else {
            None
        }
    }
}

/// What a marker certifies: this output was made from this input with these settings.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Eq)]
pub struct Certificate {
    pub input: FileId,
    /// The settings that define the output ([`settings_key`]).
    pub settings: String,
    /// The output as written (its path is where it was written; a moved OUTDIR is checked where
    /// it is now).
    pub output: FileId,
}

/// The settings that define a batch's outputs, as canonical JSON: the smoothing options, the
/// patch size (outputs are identical for any thread count and memory budget, not for any patch
/// size) and the output format.
/// Pins, when there are any, are part of it (`pins`, [`crate::engine::Pins::key`]; a pin
/// file that cannot be read counts as its own key, and the run then fails on it).
pub fn settings_key(options: &Options, engine: &EngineSettings, format: Format) -> String {
    let mut key = serde_json::json!({
        "options": options,
        "patch_size": engine.patch_size,
        "format": extension(format),
    });
    if !engine.pins.is_none() {
        key["pins"] = match engine.pins.key() {
            Ok(k) => k.into(),
            Err(e) => e.to_string().into(),
        };
    }
    key.to_string()
}

/// The settings that differ between two [`settings_key`]s, as `name then -> now`.
fn settings_change(then: &str, now: &str) -> String {
    fn flat(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, String>) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, v) in m {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    flat(&key, v, out);
                }
            }
            other => {
                out.insert(prefix.to_string(), other.to_string());
            }
        }
    }
    let parse = |s: &str| {
        let mut out = BTreeMap::new();
        flat("", &serde_json::from_str(s).unwrap_or_default(), &mut out);
        out
    };
    let (a, b) = (parse(then), parse(now));
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let none = String::from("none");
    keys.into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| {
            let name = k.strip_prefix("options.").unwrap_or(k);
            format!(
                "{name} {} -> {}",
                a.get(k).unwrap_or(&none),
                b.get(k).unwrap_or(&none)
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// What a marker is read as (the rest of it is ignored). Markers of versions that certified
/// nothing have no `certifies`.
#[derive(Debug, Clone, Deserialize)]
struct MarkerHead {
    format: String,
    /// Absent before results versions were recorded: results version 1.
    #[serde(default = "first_results_version")]
    results_version: u32,
    #[serde(flatten)]
    row: MeshRow,
    certifies: Option<Certificate>,
}

fn first_results_version() -> u32 {
    1
}

/// Read a marker's summary row.
pub fn read_marker(path: &Path) -> Result<MeshRow> {
    read_head(path).map(|h| h.row)
}

fn read_head(path: &Path) -> Result<MarkerHead> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let head: MarkerHead = serde_json::from_slice(&bytes)
        .map_err(|e| Error::invalid(path, format!("not a batch marker: {e}")))?;
    if head.format != MARKER_FORMAT {
        return Err(Error::invalid(
            path,
            format!(
                "marker format '{}', expected '{MARKER_FORMAT}'",
                head.format
            ),
        ));
    }
    Ok(head)
}

/// What a marker says about its input.
#[derive(Debug, Clone, PartialEq)]
pub enum MarkerCheck {
    /// It reads, and its input, settings and output are as it certifies: the input is done. With
    /// the settings it records.
    Done(Box<MeshRow>, String),
    /// There is no marker.
    Missing,
    /// The marker cannot be read (the error's message): the input is to be redone.
    Unreadable(String),
    /// The marker reads but no longer holds (why): the input is to be redone.
    Stale(String),
}

/// Check the marker `marker` (`OUTDIR/.done/<stem>.json`) against the input `input` (`None`: the
/// input it names, when that still exists) and the batch's `settings` ([`settings_key`]; `None`:
/// not known, not checked). The output is looked for in OUTDIR, under the name it was written
/// with. `batch` skips an input only on [`MarkerCheck::Done`], and the summary counts only those
/// as done.
pub fn check_marker(marker: &Path, input: Option<&Path>, settings: Option<&str>) -> MarkerCheck {
    let head = match read_head(marker) {
        Ok(h) => h,
        Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
            return MarkerCheck::Missing;
        }
        Err(e) => return MarkerCheck::Unreadable(e.to_string()),
    };
    let Some(cert) = &head.certifies else {
        return MarkerCheck::Stale("the marker certifies no input and output".into());
    };
    if head.results_version != crate::RESULTS_VERSION {
        return MarkerCheck::Stale(format!(
            "made by results version {}, this is {} (see CHANGELOG.md)",
            head.results_version,
            crate::RESULTS_VERSION
        ));
    }
    let input_now = match input {
        Some(p) => Some(FileId::of(p).map_err(|e| e.to_string())),
        None => {
            let p = Path::new(&cert.input.path);
            p.exists().then(|| FileId::of(p).map_err(|e| e.to_string()))
        }
    };
    match input_now {
        Some(Err(e)) => return MarkerCheck::Stale(format!("input: {e}")),
        Some(Ok(now)) => {
            if let Some(what) = now.change(&cert.input, true) {
                return MarkerCheck::Stale(format!("input {} changed: {what}", cert.input.path));
            }
        }
        None => {}
    }
    if let Some(now) = settings.filter(|s| *s != cert.settings) {
        return MarkerCheck::Stale(format!(
            "made with other settings: {}",
            settings_change(&cert.settings, now)
        ));
    }
    let outdir = marker
        .parent()
        .and_then(Path::parent)
        .unwrap_or(Path::new("."));
    let Some(name) = Path::new(&cert.output.path).file_name() else {
        return MarkerCheck::Stale("the marker names no output file".into());
    };
    let output = outdir.join(name);
    match FileId::of(&output) {
        Err(e) => MarkerCheck::Stale(format!("output: {e}")),
        Ok(now) => match now.change(&cert.output, false) {
            Some(what) => {
                MarkerCheck::Stale(format!("output {} changed: {what}", output.display()))
            }
            None => MarkerCheck::Done(Box::new(head.row), cert.settings.clone()),
        },
    }
}

/// Totals over the finished meshes.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Totals {
    pub meshes: usize,
    pub vertices: u64,
    pub triangles: u64,
    pub seconds: f64,
    pub min_volume_pct: Option<f64>,
    pub max_volume_pct: Option<f64>,
}

/// The gathered markers of a batch.
#[derive(Debug, Clone, Serialize)]
pub struct BatchSummary {
    pub format: &'static str,
    pub outdir: String,
    /// One row per marker that holds ([`MarkerCheck::Done`]), by name.
    pub meshes: Vec<MeshRow>,
    pub totals: Totals,
    /// Number of inputs in the given input list (`None` when no list was given).
    pub inputs: Option<usize>,
    /// Inputs of the list without a marker that holds.
    pub missing: Vec<String>,
    /// Markers that could not be read, with the reason.
    pub unreadable: Vec<String>,
    /// Markers that read but no longer hold (an output deleted or changed, an input changed), with
    /// the reason: a rerun redoes their inputs.
    pub stale: Vec<String>,
    /// The distinct settings ([`settings_key`]) of the markers that hold: more than one means
    /// that the outputs were made with different options.
    pub settings: Vec<String>,
}

/// Gather the markers of `outdir`, each checked as a rerun would check it ([`check_marker`],
/// against its input in `inputs` if listed there, else against the input it names); with
/// `inputs`, list those without a marker that holds.
pub fn summarize(outdir: &Path, inputs: Option<&[PathBuf]>) -> Result<BatchSummary> {
    let dir = outdir.join(MARKER_DIR);
    let mut by_stem: BTreeMap<String, &Path> = BTreeMap::new();
    for input in inputs.unwrap_or_default() {
        by_stem.insert(stem(input)?, input);
    }
    let mut meshes = Vec::new();
    let mut unreadable = Vec::new();
    let mut stale = Vec::new();
    let mut settings = std::collections::BTreeSet::new();
    let mut done = std::collections::BTreeSet::new();
    if dir.is_dir() || inputs.is_none() {
        let entries = std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))?;
        let mut paths: Vec<(String, PathBuf)> = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| Error::io(&dir, e))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some(s) = name
                .strip_suffix(".json")
                .filter(|_| !name.starts_with('.'))
            {
                paths.push((s.to_string(), entry.path()));
            }
        }
        paths.sort();
        for (name, p) in paths {
            match check_marker(&p, by_stem.get(&name).copied(), None) {
                MarkerCheck::Done(row, s) => {
                    done.insert(name);
                    settings.insert(s);
                    meshes.push(*row);
                }
                MarkerCheck::Missing => {} // removed since it was listed
                MarkerCheck::Unreadable(e) => unreadable.push(e),
                MarkerCheck::Stale(why) => stale.push(format!("{}: {why}", p.display())),
            }
        }
    }
    meshes.sort_by(|a, b| a.name.cmp(&b.name));
    let mut totals = Totals::default();
    for m in &meshes {
        totals.meshes += 1;
        totals.vertices += m.vertices as u64;
        totals.triangles += m.triangles as u64;
        totals.seconds += m.seconds;
        // An undefined volume ratio (an input of zero volume) is no extreme.
        if !m.volume_pct.is_finite() {
            continue;
        }
        totals.min_volume_pct = Some(
            totals
                .min_volume_pct
                .map_or(m.volume_pct, |v| v.min(m.volume_pct)),
        );
        totals.max_volume_pct = Some(
            totals
                .max_volume_pct
                .map_or(m.volume_pct, |v| v.max(m.volume_pct)),
        );
    }
    let mut missing = Vec::new();
    for input in inputs.unwrap_or_default() {
        if !done.contains(&stem(input)?) {
            missing.push(input.display().to_string());
        }
    }
    Ok(BatchSummary {
        format: "vcsmooth-batch-summary/1",
        outdir: outdir.display().to_string(),
        meshes,
        totals,
        inputs: inputs.map(<[PathBuf]>::len),
        missing,
        unreadable,
        stale,
        settings: settings.into_iter().collect(),
    })
}

/// Memory of a Slurm task whose largest input is `largest` bytes, smoothed with `opts`: what the
/// memory model says a job smoothing it in core needs ([`memory::job_bytes_of_file`]), at least
/// 1 GiB; in MiB, rounded up.
pub fn slurm_mem_mib(largest: u64, opts: &Options) -> u64 {
    const MIB: u64 = 1 << 20;
    memory::job_bytes_of_file(largest, opts)
        .div_ceil(MIB)
        .max(1024)
}

/// The number of array tasks for `inputs` inputs under `max_array_size` (indices must be below it).
pub fn array_tasks(inputs: usize, max_array_size: usize) -> usize {
    inputs.min(max_array_size).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_list_file_may_start_with_a_byte_order_mark() {
        let dir = tempfile::tempdir().unwrap();
        let list = dir.path().join("list.txt");
        std::fs::write(&list, "\u{feff}in/a.ply\r\n# b\r\nin/c.ply\r\n").unwrap();
        let inputs = list_inputs(&list).unwrap();
        assert_eq!(
            inputs,
            [dir.path().join("in/a.ply"), dir.path().join("in/c.ply")]
        );
    }

    #[test]
    fn round_robin_share_covers_every_input_once() {
        for n in 0..20 {
            for count in 1..7 {
                let mut all: Vec<usize> = (0..count).flat_map(|i| share(n, i, count)).collect();
                all.sort();
                assert_eq!(all, (0..n).collect::<Vec<_>>());
                for i in 0..count {
                    let len = share(n, i, count).len();
                    assert!(len == n / count || len == n.div_ceil(count));
                }
            }
        }
        assert_eq!(share(8, 1, 3), vec![1, 4, 7]);
    }

    #[test]
    fn task_from_flags_environment_or_default() {
        let none = |_: &str| None;
        assert_eq!(resolve_task(None, None, &none).unwrap(), (0, 1));
        assert_eq!(resolve_task(Some(2), Some(3), &none).unwrap(), (2, 3));
        assert!(resolve_task(Some(3), Some(3), &none).is_err());
        let slurm = |n: &str| match n {
            "SLURM_ARRAY_TASK_ID" => Some("5".to_string()),
            "SLURM_ARRAY_TASK_COUNT" => Some("8".to_string()),
            _ => None,
        };
        assert_eq!(resolve_task(None, None, &slurm).unwrap(), (5, 8));
        assert_eq!(resolve_task(None, Some(6), &slurm).unwrap(), (5, 6));
        let min_max = |n: &str| match n {
            "SLURM_ARRAY_TASK_ID" => Some("3".to_string()),
            "SLURM_ARRAY_TASK_MIN" => Some("1".to_string()),
            "SLURM_ARRAY_TASK_MAX" => Some("4".to_string()),
            _ => None,
        };
        assert_eq!(resolve_task(None, None, &min_max).unwrap(), (2, 4));
    }

    #[test]
    fn stems_collide() {
        let a = vec![PathBuf::from("x/a.ply"), PathBuf::from("y/b.ply")];
        check_stems(&a).unwrap();
        let b = vec![PathBuf::from("x/a.ply"), PathBuf::from("y/a.obj")];
        let e = check_stems(&b).unwrap_err().to_string();
        assert!(e.contains("a.obj") && e.contains("x/a.ply"), "{e}");
    }

    #[test]
    fn settings_changes_are_named() {
        let opts = Options::default();
        let engine = EngineSettings::default();
        let a = settings_key(&opts, &engine, Format::Ply);
        assert_eq!(a, settings_key(&opts, &engine, Format::Ply));
        let more = Options {
            iterations: 3,
            ..opts
        };
        let b = settings_key(&more, &engine, Format::Obj);
        assert_eq!(
            settings_change(&a, &b),
            "format \"ply\" -> \"obj\", iterations 10 -> 3"
        );
        // Threads and memory do not change the output.
        let threads = EngineSettings {
            threads: Some(3),
            memory_budget: Some(1 << 30),
            ..EngineSettings::default()
        };
        assert_eq!(a, settings_key(&opts, &threads, Format::Ply));
    }

    #[test]
    fn mem_rule() {
        let opts = Options::default();
        assert_eq!(slurm_mem_mib(0, &opts), 1024);
        assert_eq!(slurm_mem_mib(1 << 30, &opts), 6 * 1024 + 256);
        // The automatic stop's arrays: 24 B more per triangle (19 B of file).
        let auto = Options {
            auto_stop: true,
            ..opts
        };
        assert_eq!(slurm_mem_mib(19 << 26, &auto), 138 * 64 + 256);
        assert_eq!(array_tasks(5000, 1001), 1001);
        assert_eq!(array_tasks(8, 1001), 8);
    }
}
