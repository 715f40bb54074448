//! What several commands print and record: the tool that wrote a report, a mesh file's statistics,
//! a run's totals, and the pieces of the human-readable tables.

use std::io::Write;
use std::path::Path;

use serde::Serialize;

use super::output::stdout_error;
use crate::engine::IterationRecord;
use crate::error::Result;
use crate::io::Format;
use crate::metrics::MeshInfo;
use crate::smooth::SweepStats;

/// The program that wrote a report.
#[derive(Debug, Clone, Serialize)]
pub struct Tool {
    pub name: &'static str,
    pub version: &'static str,
}

impl Tool {
    pub fn this() -> Tool {
        Tool {
            name: env!("CARGO_PKG_NAME"),
            version: env!("CARGO_PKG_VERSION"),
        }
    }
}

/// A mesh file and what was measured on it.
#[derive(Debug, Clone, Serialize)]
pub struct FileStats {
    pub path: String,
    /// `ply`, `obj`, `off`, `stl`; absent when unknown.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub format: Option<String>,
    pub stats: MeshInfo,
}

impl FileStats {
    pub fn new(path: &Path, format: Option<Format>, stats: MeshInfo) -> Self {
        FileStats {
            path: path.display().to_string(),
            format: format.map(format_name),
            stats,
        }
    }
}

/// Totals over all iterations of a run.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Summary {
    /// Final volume and area as a percentage of the input's (100 after 0 iterations).
    pub volume_pct: f64,
    pub area_pct: f64,
    pub stencils: SweepStats,
    /// Sum of the per-iteration smoothing seconds.
    pub seconds: f64,
}

impl Summary {
    pub fn of(records: &[IterationRecord]) -> Summary {
        let mut stencils = SweepStats::default();
        for r in records {
            stencils.add(&r.stencils);
        }
        Summary {
            volume_pct: records.last().map_or(100.0, |r| r.volume_pct),
            area_pct: records.last().map_or(100.0, |r| r.area_pct),
            stencils,
            seconds: records.iter().map(|r| r.seconds).sum(),
        }
    }
}

/// Lower-case name of a format, as in file extensions.
pub fn format_name(f: Format) -> String {
    format!("{f:?}").to_ascii_lowercase()
}

/// `n word` or `n words`.
pub fn count(n: usize, word: &str) -> String {
    if n == 1 {
        format!("1 {word}")
    } else {
        format!("{n} {word}s")
    }
}

/// A number for people: 9 significant digits, fixed-point between 1e-3 and 1e7, else scientific.
pub fn num(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || !x.is_finite() {
        format!("{x}")
    } else if (1e-3..1e7).contains(&a) {
        let decimals = (8 - a.log10().floor() as i32).clamp(0, 11) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.8e}")
    }
}

/// Print `key  value` lines, the values aligned.
pub fn print_rows(out: &mut dyn Write, rows: &[(&str, String)]) -> Result<()> {
    let width = rows.iter().map(|(k, _)| k.len()).max().unwrap_or(0);
    let mut text = String::new();
    for (k, v) in rows {
        text += &format!("{k:<width$}  {v}\n");
    }
    out.write_all(text.as_bytes()).map_err(stdout_error)
}

#[cfg(test)]
mod tests {
    use super::num;

    #[test]
    fn numbers_for_people() {
        assert_eq!(num(4.186713092382924), "4.18671309");
        assert_eq!(num(-1.07786905), "-1.07786905");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(123456.789), "123456.789");
        assert_eq!(num(2.5e-7), "2.50000000e-7");
    }
}
