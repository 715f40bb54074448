//! Many meshes as one batch, spread over the tasks of a job array (Slurm's, or any scheduler's
//! that numbers its tasks): which inputs a task owns, where their outputs and success markers go,
//! and the summary gathered from the markers. The CLI's `batch` and `slurm-script` commands
//! (`crate::cli::commands::{batch, slurm_script}`) are thin layers over this module.
//!
//! * Inputs: the mesh files of a directory (known extensions `.ply .obj .off .stl`, any case; hidden
//!   files skipped), sorted by file name; or the lines of a list file (blank lines and lines
//!   starting with `#` skipped; relative paths are relative to the list file's directory).
//! * Share: input `k` (0-based, in that order) belongs to task `k mod N` — a round-robin split, so
//!   every task gets ⌊n/N⌋ or ⌈n/N⌉ inputs and large and small files (which often sort together)
//!   are spread over the tasks.
//! * Outputs: `OUTDIR/<stem>.<ext>`; the success marker `OUTDIR/.done/<stem>.json` is written
//!   (atomically) only after the output was written (atomically), so a marker means "finished".
//!   Inputs whose marker exists are skipped: rerunning a failed or killed task finishes the batch.

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
            if !hidden && Format::from_extension(&path).is_some() && path.is_file() {
                files.push(path);
            }
        }
        files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
        return Ok(files);
    }
    let text = std::fs::read_to_string(list_or_dir).map_err(|e| Error::io(list_or_dir, e))?;
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
    pub iterations: usize,
    pub vertices: usize,
    pub triangles: usize,
    /// Final volume and area as a percentage of the input's.
    pub volume_pct: f64,
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

/// A success marker, `OUTDIR/.done/<stem>.json`: the summary row flattened at the top, then the
/// options, the engine settings and the whole [`Report`] report.
#[derive(Debug, Clone, Serialize)]
pub struct Marker<'a> {
    pub format: &'static str,
    pub version: &'static str,
    #[serde(flatten)]
    pub row: MeshRow,
    pub options: &'a Options,
    pub engine: &'a EngineSettings,
    pub run: &'a Report,
}

/// What a marker is read as (the rest of it is ignored).
#[derive(Debug, Clone, Deserialize)]
struct MarkerHead {
    format: String,
    #[serde(flatten)]
    row: MeshRow,
}

/// Read a marker's summary row.
pub fn read_marker(path: &Path) -> Result<MeshRow> {
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
    Ok(head.row)
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
    /// One row per marker, by name.
    pub meshes: Vec<MeshRow>,
    pub totals: Totals,
    /// Number of inputs in the given input list (`None` when no list was given).
    pub inputs: Option<usize>,
    /// Inputs of the list without a readable marker.
    pub missing: Vec<String>,
    /// Markers that could not be read, with the reason.
    pub unreadable: Vec<String>,
}

/// Gather the markers of `outdir`; with `inputs`, list those without a marker.
pub fn summarize(outdir: &Path, inputs: Option<&[PathBuf]>) -> Result<BatchSummary> {
    let dir = outdir.join(MARKER_DIR);
    let mut meshes = Vec::new();
    let mut unreadable = Vec::new();
    if dir.is_dir() || inputs.is_none() {
        let entries = std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))?;
        let mut paths: Vec<PathBuf> = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| Error::io(&dir, e))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if !name.starts_with('.') && name.ends_with(".json") {
                paths.push(entry.path());
            }
        }
        paths.sort();
        for p in paths {
            match read_marker(&p) {
                Ok(row) => meshes.push(row),
                Err(e) => unreadable.push(e.to_string()),
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
    if let Some(list) = inputs {
        let done: std::collections::BTreeSet<&str> =
            meshes.iter().map(|m| m.name.as_str()).collect();
        for input in list {
            if !done.contains(stem(input)?.as_str()) {
                missing.push(input.display().to_string());
            }
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
    })
}

/// Memory of a Slurm task whose largest input is `largest` bytes: what the memory model says a job
/// smoothing it in core needs ([`memory::job_bytes_of_file`]), at least 1 GiB; in MiB, rounded up.
pub fn slurm_mem_mib(largest: u64) -> u64 {
    const MIB: u64 = 1 << 20;
    memory::job_bytes_of_file(largest).div_ceil(MIB).max(1024)
}

/// The number of array tasks for `inputs` inputs under `max_array_size` (indices must be below it).
pub fn array_tasks(inputs: usize, max_array_size: usize) -> usize {
    inputs.min(max_array_size).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn mem_rule() {
        assert_eq!(slurm_mem_mib(0), 1024);
        assert_eq!(slurm_mem_mib(1 << 30), 6 * 1024 + 256);
        assert_eq!(array_tasks(5000, 1001), 1001);
        assert_eq!(array_tasks(8, 1001), 8);
    }
}
