//! What several commands print and record: the tool that wrote a report, a mesh file's statistics,
//! a run's totals, and the pieces of the human-readable tables.

use std::io::Write;
use std::path::Path;

use serde::Serialize;

use super::output::stdout_error;
use crate::engine::{IterationRecord, Report};
use crate::error::Result;
use crate::io::Format;
use crate::metrics::MeshInfo;
use crate::smooth::{Options, SweepStats};

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
            stats: undefined_as_nan(&stats),
        }
    }
}

/// `info` with the figures that are not defined for its mesh set to NaN, which JSON writes as
/// `null` and the tables as [`UNDEFINED`], and −0 as 0. The library reports them as 0: the
/// bounding box of no vertices, the mean length of no edges, the roughness (a mean over interior
/// manifold edges) of a mesh that has none.
pub fn undefined_as_nan(info: &MeshInfo) -> MeshInfo {
    let nan_if = |undefined: bool, x: f64| if undefined { f64::NAN } else { x + 0.0 };
    let no_vertex = info.vertices == 0;
    let interior = info
        .edges
        .saturating_sub(info.boundary_edges + info.non_manifold_edges);
    MeshInfo {
        volume: info.volume + 0.0,
        area: info.area + 0.0,
        bbox_min: info.bbox_min.map(|x| nan_if(no_vertex, x)),
        bbox_max: info.bbox_max.map(|x| nan_if(no_vertex, x)),
        bbox_diagonal: nan_if(no_vertex, info.bbox_diagonal),
        mean_edge_length: nan_if(info.edges == 0, info.mean_edge_length),
        roughness_deg: nan_if(interior == 0, info.roughness_deg),
        ..info.clone()
    }
}

/// What the tables print for a quantity that is not defined (a ratio whose denominator is 0, a
/// mean over nothing, a percentage of a zero volume): never NaN, inf, or a made-up 0 or 1. JSON
/// has `null` for them.
pub const UNDEFINED: &str = "undefined";

/// `x` as a percentage of `reference`: NaN (undefined) when the reference is 0.
pub fn percent_of(x: f64, reference: f64) -> f64 {
    if reference == 0.0 {
        f64::NAN
    } else {
        100.0 * x / reference
    }
}

/// `x` with `decimals` decimals, [`UNDEFINED`] when it is not finite, and never `-0.000`: a
/// negative number that rounds to zero prints as zero.
pub fn fixed(x: f64, decimals: usize) -> String {
    if !x.is_finite() {
        return UNDEFINED.to_string();
    }
    let s = format!("{x:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => s,
    }
}

/// `x` in the form `format` gives, or [`UNDEFINED`] for `None` or a number that is not finite.
pub fn defined(x: Option<f64>, format: impl Fn(f64) -> String) -> String {
    match x.filter(|x| x.is_finite()) {
        Some(x) => format(x),
        None => UNDEFINED.to_string(),
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
            // `+ 0.0`: an empty sum is −0.
            seconds: records.iter().map(|r| r.seconds).sum::<f64>() + 0.0,
        }
    }

    /// [`Summary::of`] a run's records; with `--multires`, the output's volume and area as the
    /// run measured them after its final correction (the coarse levels move the mesh even when
    /// the input level runs no iteration).
    pub fn of_run(
        records: &[IterationRecord],
        multires: Option<&crate::multires::MultiresStats>,
    ) -> Summary {
        let mut s = Summary::of(records);
        if let Some(m) = multires {
            (s.volume_pct, s.area_pct) = (m.volume_pct, m.area_pct);
        }
        s
    }
}

/// The iterations a run of `opts` ran, for people: `10 iterations`, or with the automatic stop
/// `14 iterations (auto: why it stopped; noise estimate σ̂, cap N)`.
pub fn iterations_run(opts: &Options, run: &Report) -> String {
    match &run.auto_stop {
        Some(a) if opts.auto_stop => format!(
            "{} (auto: {}; noise estimate {}, cap {})",
            count(run.iterations_run, "iteration"),
            a.stopped_by.describe(),
            num(a.noise_estimate),
            a.cap
        ),
        _ => count(opts.iterations, "iteration"),
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

/// A number for people: 9 significant digits, fixed-point between 1e-3 and 1e7, else scientific;
/// [`UNDEFINED`] when not finite, and 0 never signed.
pub fn num(x: f64) -> String {
    let a = x.abs();
    if !x.is_finite() {
        UNDEFINED.to_string()
    } else if x == 0.0 {
        "0".to_string()
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
    use super::*;

    #[test]
    fn numbers_for_people() {
        assert_eq!(num(4.186713092382924), "4.18671309");
        assert_eq!(num(-1.07786905), "-1.07786905");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(123456.789), "123456.789");
        assert_eq!(num(2.5e-7), "2.50000000e-7");
        assert_eq!(num(-0.0), "0");
        assert_eq!(num(f64::NAN), UNDEFINED);
        assert_eq!(num(f64::NEG_INFINITY), UNDEFINED);
    }

    #[test]
    fn undefined_and_never_minus_zero() {
        assert_eq!(fixed(-0.0, 3), "0.000");
        assert_eq!(fixed(-0.0004, 3), "0.000");
        assert_eq!(fixed(-0.0006, 3), "-0.001");
        assert_eq!(fixed(-12.5, 1), "-12.5");
        assert_eq!(fixed(f64::INFINITY, 2), UNDEFINED);
        assert_eq!(defined(None, |x| fixed(x, 2)), UNDEFINED);
        assert_eq!(defined(Some(1.5), |x| fixed(x, 2)), "1.50");
        assert!(percent_of(1.0, 0.0).is_nan());
        assert_eq!(percent_of(1.0, 4.0), 25.0);
        let flat = MeshInfo {
            vertices: 3,
            edges: 3,
            boundary_edges: 3,
            volume: -0.0,
            ..Default::default()
        };
        let f = undefined_as_nan(&flat);
        assert!(f.roughness_deg.is_nan() && !f.mean_edge_length.is_nan());
        assert!(f.volume.is_sign_positive() && !f.bbox_diagonal.is_nan());
        let json = serde_json::to_string(&undefined_as_nan(&MeshInfo::default())).unwrap();
        assert!(json.contains("\"bbox_min\":[null,null,null]"), "{json}");
        assert!(
            json.contains("\"roughness_deg\":null") && !json.contains("-0"),
            "{json}"
        );
    }
}
