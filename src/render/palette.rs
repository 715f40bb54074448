//! Colour maps from a per-vertex value to a colour: a sequential one for magnitudes (dark blue
//! through green to yellow, readable in grey and by most colour-blind readers) and a diverging
//! one for signed values (blue below zero, white at zero, red above), each over a range.

use super::image::Rgb;

/// A colour map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Palette {
    /// Low values dark blue, high values yellow (the control points of matplotlib's viridis).
    Sequential,
    /// Negative values blue, zero white, positive values red.
    Diverging,
}

/// Sequential's control points, evenly spaced from 0 to 1.
const SEQUENTIAL: [[f32; 3]; 5] = [
    [68.0, 1.0, 84.0],
    [59.0, 82.0, 139.0],
    [33.0, 145.0, 140.0],
    [94.0, 201.0, 98.0],
    [253.0, 231.0, 37.0],
];

/// Diverging's control points, evenly spaced from 0 to 1 (0.5 is zero).
const DIVERGING: [[f32; 3]; 5] = [
    [33.0, 80.0, 170.0],
    [140.0, 180.0, 225.0],
    [247.0, 247.0, 247.0],
    [235.0, 150.0, 120.0],
    [180.0, 25.0, 40.0],
];

impl Palette {
    /// The colour at `t` in [0, 1] (clamped; NaN as 0). Channels are rounded by a cast (they are
    /// not negative): `round` is a call to libm on x86-64's baseline.
    pub fn at(self, t: f32) -> Rgb {
        let points = match self {
            Palette::Sequential => &SEQUENTIAL,
            Palette::Diverging => &DIVERGING,
        };
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let x = t * (points.len() - 1) as f32;
        let k = (x as usize).min(points.len() - 2);
        let f = x - k as f32;
        let (a, b) = (points[k], points[k + 1]);
        std::array::from_fn(|i| (a[i] + (b[i] - a[i]) * f + 0.5) as u8)
    }
}

/// A colour map over a range of values: `lo` gets the map's first colour, `hi` its last, values
/// outside take the nearer end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scale {
    pub palette: Palette,
    pub lo: f32,
    pub hi: f32,
}

impl Scale {
    /// The scale for values from `lo` to `hi`: sequential from `lo` to `hi` when they have one
    /// sign (a magnitude, whose 0 is `lo` when `lo` is 0), diverging and symmetric about 0 when
    /// they straddle it, so that white is no change. An empty range (`lo == hi`) is widened so that
    /// every value takes one end.
    pub fn for_range(lo: f32, hi: f32) -> Scale {
        let (lo, hi) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        if lo < 0.0 && hi > 0.0 {
            let m = lo.abs().max(hi);
            return Scale {
                palette: Palette::Diverging,
                lo: -m,
                hi: m,
            };
        }
        Scale {
            palette: Palette::Sequential,
            lo,
            hi,
        }
    }

    /// Where `v` falls in the range, 0 at `lo` and 1 at `hi` (0 for an empty range).
    pub fn position(&self, v: f32) -> f32 {
        let span = self.hi - self.lo;
        if span > 0.0 && span.is_finite() {
            ((v - self.lo) / span).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// The colour of `v`.
    pub fn colour(&self, v: f32) -> Rgb {
        self.palette.at(self.position(v))
    }

    /// About `count` round values from `lo` to `hi` (both ends included) for a scale bar's
    /// labels: steps of 1, 2 or 5 times a power of ten, none within half a step of an end.
    pub fn ticks(&self, count: usize) -> Vec<f32> {
        let (lo, hi) = (self.lo as f64, self.hi as f64);
        let span = hi - lo;
        if !(span > 0.0 && span.is_finite()) || count < 2 {
            return vec![self.lo];
        }
        let rough = span / (count - 1) as f64;
        let power = 10f64.powf(rough.log10().floor());
        // The round step nearest the rough one (by ratio), so the count is about what was asked.
        let step = [1.0, 2.0, 5.0, 10.0]
            .into_iter()
            .map(|m| m * power)
            .min_by(|a, b| (a / rough).ln().abs().total_cmp(&(b / rough).ln().abs()))
            .unwrap_or(power);
        // The ends, which say the range exactly, and the round values between them that leave
        // room for the ends' labels.
        let first = (lo / step).ceil() as i64;
        let last = (hi / step).floor() as i64;
        let inside = (first..=last)
            .map(|k| k as f64 * step)
            .filter(|&t| t - lo > 0.5 * step && hi - t > 0.5 * step)
            .map(|t| t as f32);
        let mut ticks = vec![self.lo];
        ticks.extend(inside);
        ticks.push(self.hi);
        ticks
    }
}

/// `v` as a short label: three significant digits, in exponent form outside [0.01, 10000).
pub fn label(v: f32) -> String {
    let a = v.abs();
    if a == 0.0 {
        return "0".into();
    }
    if (0.01..10000.0).contains(&a) {
        let decimals = (2 - a.log10().floor() as i32).max(0) as usize;
        let text = format!("{v:.decimals$}");
        // 0.500 → 0.5, 12.0 → 12: the digits that carry nothing go.
        return match text.contains('.') {
            true => text.trim_end_matches('0').trim_end_matches('.').to_string(),
            false => text,
        };
    }
    let text = format!("{v:.2e}");
    let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
    let mantissa = match mantissa.contains('.') {
        true => mantissa.trim_end_matches('0').trim_end_matches('.'),
        false => mantissa,
    };
    format!("{mantissa}e{exponent}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ends_of_a_range_take_the_ends_of_the_map() {
        let s = Scale::for_range(0.0, 2.0);
        assert_eq!(s.palette, Palette::Sequential);
        assert_eq!(s.colour(0.0), [68, 1, 84]);
        assert_eq!(s.colour(2.0), [253, 231, 37]);
        assert_eq!(s.colour(9.0), [253, 231, 37]);
        assert_eq!(s.colour(f32::NAN), [68, 1, 84]);
        let d = Scale::for_range(-1.0, 3.0);
        assert_eq!((d.palette, d.lo, d.hi), (Palette::Diverging, -3.0, 3.0));
        assert_eq!(d.colour(0.0), [247, 247, 247]);
        let empty = Scale::for_range(1.0, 1.0);
        assert_eq!(empty.position(1.0), 0.0);
    }

    #[test]
    fn ticks_are_round_and_hold_the_ends() {
        let t = Scale::for_range(0.0, 0.0123).ticks(5);
        assert_eq!(t.first(), Some(&0.0));
        assert_eq!(t.last(), Some(&0.0123));
        assert!(t.len() >= 4 && t.len() <= 8, "{t:?}");
        let t = Scale::for_range(0.0, 1.0).ticks(5);
        assert_eq!(t, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        assert!(t.windows(2).all(|w| w[0] < w[1]), "{t:?}");
        assert_eq!(label(0.005), "5e-3");
        assert_eq!(label(0.0123), "0.0123");
        assert_eq!(label(0.5), "0.5");
        assert_eq!(label(12.0), "12");
        assert_eq!(label(-2.5e-5), "-2.5e-5");
        assert_eq!(label(123456.0), "1.23e5");
    }
}
