//! Volume curves as SVG (the paper's Fig. 4): volume as a percentage of the input's, per iteration,
//! one line per method, with axis labels and a legend. Rendered in memory by plotters' SVG backend
//! (its text needs no font feature: it emits `<text>` elements), then written atomically.

use std::path::Path;

use plotters::prelude::*;

use super::output::atomic_write;
use crate::engine::IterationRecord;
use crate::error::{Error, Result};
use crate::smooth::Method;

/// One line of the plot: a method and its volume % at iterations 0 (the input, 100 %), 1, 2, ….
pub struct Curve {
    pub method: Method,
    pub volume_pct: Vec<f64>,
}

/// Volume % at iterations 0 (the input: 100), 1, …, N; all undefined (NaN) when the input's
/// volume is 0 (a measured volume whose percentage is not finite).
pub fn volume_curve(records: &[IterationRecord]) -> Vec<f64> {
    let against_zero = records
        .iter()
        .any(|r| r.volume.is_finite() && !r.volume_pct.is_finite());
    std::iter::once(if against_zero { f64::NAN } else { 100.0 })
        .chain(records.iter().map(|r| r.volume_pct))
        .collect()
}

/// The file name of `path`, for a plot's title.
pub fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

/// Draw `curves` under `title` and write the SVG to `path` atomically.
pub fn write_volume_plot(path: &Path, title: &str, curves: &[Curve]) -> Result<()> {
    let svg = render(title, curves)
        .map_err(|e| Error::invalid(path, format!("cannot draw plot: {e}")))?;
    atomic_write(path, svg.as_bytes())
}

/// The line of each method by its place in the registry ([`Method::ALL`]), so every figure
/// draws a method the same way: a colour, and whether the line is dashed (the fifth method's
/// curve usually coincides with the fourth's: dashed, both stay visible).
const PALETTE: [(RGBColor, bool); 10] = [
    (RGBColor(214, 39, 40), false),
    (RGBColor(255, 127, 14), false),
    (RGBColor(44, 160, 44), false),
    (RGBColor(31, 119, 180), false),
    (RGBColor(148, 103, 189), true),
    (RGBColor(140, 86, 75), false),
    (RGBColor(227, 119, 194), false),
    (RGBColor(127, 127, 127), false),
    (RGBColor(188, 189, 34), false),
    (RGBColor(23, 190, 207), false),
];

/// The colour and dash of method `m`'s line.
fn line(m: Method) -> (RGBColor, bool) {
    let at = Method::ALL.iter().position(|&x| x == m).unwrap_or(0);
    PALETTE[at % PALETTE.len()]
}

/// The y range to show: every value and 100 %, padded; at least ±0.5 % around a flat line.
fn y_range(curves: &[Curve]) -> (f64, f64) {
    let values = curves
        .iter()
        .flat_map(|c| c.volume_pct.iter().copied())
        .filter(|v| v.is_finite());
    let (lo, hi) = values.fold((100.0f64, 100.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = ((hi - lo) * 0.08).max(0.5);
    (lo - pad, hi + pad)
}

/// Decimals for y labels so that neighbouring ticks differ.
fn decimals(lo: f64, hi: f64) -> usize {
    let step = (hi - lo) / 8.0;
    if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil().clamp(0.0, 9.0) as usize
    }
}

fn render(title: &str, curves: &[Curve]) -> std::result::Result<String, String> {
    let n = curves
        .iter()
        .map(|c| c.volume_pct.len().saturating_sub(1))
        .max()
        .unwrap_or(0)
        .max(1) as u32;
    let (lo, hi) = y_range(curves);
    let digits = decimals(lo, hi);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (800, 520)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(0u32..n, lo..hi)
            .map_err(|e| e.to_string())?;
        let y_fmt = move |v: &f64| format!("{v:.digits$}");
        chart
            .configure_mesh()
            .x_desc("iteration")
            .y_desc("volume (% of input)")
            .x_labels((n as usize + 1).min(11))
            .y_labels(9)
            .y_label_formatter(&y_fmt)
            .axis_desc_style(("sans-serif", 16))
            .draw()
            .map_err(|e| e.to_string())?;
        for c in curves {
            let (col, dashed) = line(c.method);
            let points: Vec<(u32, f64)> = c
                .volume_pct
                .iter()
                .enumerate()
                .filter(|(_, v)| v.is_finite())
                .map(|(i, &v)| (i as u32, v))
                .collect();
            let style = col.stroke_width(2);
            let series = if dashed {
                chart.draw_series(DashedLineSeries::new(points.iter().copied(), 9, 6, style))
            } else {
                chart.draw_series(LineSeries::new(points.iter().copied(), style))
            };
            series
                .map_err(|e| e.to_string())?
                .label(c.method.name())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], col.stroke_width(2))
                });
            if points.len() <= 41 {
                chart
                    .draw_series(points.iter().map(|&p| Circle::new(p, 3, col.filled())))
                    .map_err(|e| e.to_string())?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_has_labels_legend_and_lines() {
        let curves = vec![
            Curve {
                method: Method::Vcs,
                volume_pct: vec![100.0, 100.0, 100.0],
            },
            Curve {
                method: Method::Laplacian,
                volume_pct: vec![100.0, 80.0, 65.0],
            },
        ];
        let svg = render("test mesh", &curves).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("<polyline"));
        // plotters' SVG backend puts each <text>'s content on a line of its own.
        for text in [
            "iteration",
            "volume (% of input)",
            "vcs",
            "laplacian",
            "test mesh",
        ] {
            assert!(
                svg.lines().any(|l| l.trim() == text),
                "text '{text}' missing from SVG"
            );
        }
    }

    #[test]
    fn flat_and_empty_curves_draw() {
        let flat = vec![Curve {
            method: Method::Vcs,
            volume_pct: vec![100.0],
        }];
        assert!(render("flat", &flat).is_ok());
        assert!(render("none", &[]).is_ok());
        assert_eq!(decimals(99.5, 100.5), 1);
        assert_eq!(decimals(40.0, 105.0), 0);
    }

    #[test]
    fn curve_starts_at_100() {
        let r = IterationRecord {
            iteration: 1,
            volume_pct: 90.0,
            ..Default::default()
        };
        assert_eq!(volume_curve(&[r]), vec![100.0, 90.0]);
    }
}
