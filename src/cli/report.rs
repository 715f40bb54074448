//! The pieces of the human-readable tables the commands print (the report model they render is
//! [`crate::report`]).

use std::io::Write;

use super::output::stdout_error;
use crate::engine::Report;
use crate::error::Result;
use crate::metrics::DeviationStats;
use crate::smooth::Options;

/// What the tables print for a quantity that is not defined (a ratio whose denominator is 0, a
/// mean over nothing, a percentage of a zero volume): never NaN, inf, or a made-up 0 or 1. JSON
/// has `null` for them.
pub const UNDEFINED: &str = "undefined";

/// `x` as a percentage of `reference`: NaN (undefined) when the reference is 0.
pub fn percent_of(x: f64, reference: f64) -> f64 {
    crate::metrics::percent(x, reference)
}

/// `x` as `12.345678 %` with `decimals` decimals, or [`UNDEFINED`] (no `%`) when it is not finite:
/// a ratio against zero.
pub fn percent_text(x: f64, decimals: usize) -> String {
    if x.is_finite() {
        format!("{} %", fixed(x, decimals))
    } else {
        UNDEFINED.to_string()
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

/// The iterations a run of `opts` ran, for people: `10 iterations`, or with the automatic stop
/// `14 iterations (auto: why it stopped; noise estimate σ̂[, heavy-tailed], cap N)`.
pub fn iterations_run(opts: &Options, run: &Report) -> String {
    match &run.auto_stop {
        Some(a) if opts.auto_stop => format!(
            "{} (auto: {}; noise estimate {}{}, cap {})",
            count(run.iterations_run, "iteration"),
            a.stopped_by.describe(),
            num(a.noise_estimate),
            if a.noise_estimate > a.noise_estimate_median {
                ", heavy-tailed"
            } else {
                ""
            },
            a.cap
        ),
        _ => count(opts.iterations, "iteration"),
    }
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

/// Print the statistics of a deviation field: a line of the deviation, one of the distance and
/// its percentiles, the histogram as bars, and the tolerance's verdict.
pub fn print_deviation(out: &mut dyn Write, d: &DeviationStats) -> Result<()> {
    let along = match d.measure {
        "surface" => "signed distance to B's surface, along A's normals",
        _ => "displacement along the input's vertex normals",
    };
    let g = |x: f64| format!("{x:.4e}");
    let mut text = format!(
        "deviation ({along}) over {} vertices: rms {}, mean {}, min {}, max {}\n",
        d.vertices,
        g(d.rms),
        g(d.mean),
        g(d.min),
        g(d.max)
    );
    let percentiles: Vec<String> = d
        .percentiles
        .iter()
        .map(|p| format!("{}% {}", p.percent, g(p.distance)))
        .collect();
    text += &format!(
        "distance: rms {}, mean {}, max {} (vertex {}); percentiles {}\n",
        g(d.distance_rms),
        g(d.distance_mean),
        g(d.distance_max),
        d.distance_max_vertex,
        percentiles.join(", ")
    );
    let h = &d.histogram;
    let most = h.counts.iter().copied().max().unwrap_or(0).max(1);
    for (k, &c) in h.counts.iter().enumerate() {
        let bar = "#".repeat(((c as f64 / most as f64) * 40.0).ceil() as usize);
        let (lo, hi) = (g(h.edge(k)), g(h.edge(k + 1)));
        text += &format!("  {lo:>12} .. {hi:<12} {c:>10} {bar}\n");
    }
    if let Some(t) = &d.tolerance {
        text += &match t.within {
            true => format!("tolerance {}: every vertex within\n", t.limit),
            false => format!(
                "tolerance {}: {} vertices beyond (largest {}, vertex {})\n",
                t.limit,
                t.beyond,
                g(d.distance_max),
                d.distance_max_vertex
            ),
        };
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
    }
}
