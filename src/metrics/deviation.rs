//! The deviation field: how far, and to which side, each vertex of a mesh lies from a reference.
//!
//! For two meshes with the same vertices (a run's input and output), a vertex's **deviation** is
//! its displacement `q − p` along the reference's unit vertex normal `n̂(p)`: `(q − p) · n̂`,
//! positive outward (for outward-oriented faces, see [`crate::metrics`]); its **distance** is the
//! length `|q − p|`. The vertex normal is the sum of the cross products `(b − a) × (c − a)` of the
//! triangles around the vertex (area-weighted), summed in triangle order, then normalised; a vertex
//! without area around it (unreferenced, or only on degenerate triangles) has no normal and
//! deviation 0, while its distance is still measured. Every value is a function of the two
//! position arrays and the triangles alone, so it is the same for any thread count, storage or
//! memory budget.
//!
//! For meshes that do not share vertices, the distance of a vertex of the reference is the
//! distance to the nearest point of the other mesh's triangles ([`super::surface`]) and the
//! deviation is that distance signed by the side of the nearest point along the reference's normal.
//!
//! The statistics ([`DeviationStats`]) are what a reviewer reads: RMS, mean, extremes, exact
//! percentiles of the distance, a histogram of the deviation and, with a tolerance, how many
//! vertices lie farther than it.

use glam::DVec3;

/// The percentiles of the distance that [`DeviationStats`] reports.
pub const PERCENTILES: [f64; 4] = [50.0, 90.0, 99.0, 99.9];

/// Bins of [`Histogram`].
pub const HISTOGRAM_BINS: usize = 20;

/// The area-weighted normal sum of every vertex, into `sums` (indexed like `positions`, zeroed
/// first): `Σ (b − a) × (c − a)` over the triangles around it, in triangle order.
pub fn vertex_normal_sums(positions: &[DVec3], triangles: &[[u32; 3]], sums: &mut [DVec3]) {
    vertex_normal_sums_from(positions, triangles, 0, sums);
}

/// Positions read one at a time: a slice, or a copy kept in another form
/// ([`crate::engine::deviation::Kept`]).
pub trait Points: Sync {
    fn count(&self) -> usize;
    fn at(&self, i: usize) -> DVec3;
}

impl Points for [DVec3] {
    fn count(&self) -> usize {
        self.len()
    }

    #[inline]
    fn at(&self, i: usize) -> DVec3 {
        self[i]
    }
}

impl Points for [[f32; 3]] {
    fn count(&self) -> usize {
        self.len()
    }

    #[inline]
    fn at(&self, i: usize) -> DVec3 {
        DVec3::from_array(self[i].map(f64::from))
    }
}

/// [`vertex_normal_sums`] of the vertices `first..first + sums.len()` alone, into `sums`: the
/// same bits (each sum in triangle order), so that disjoint ranges can be summed apart.
pub fn vertex_normal_sums_from<P: Points + ?Sized>(
    positions: &P,
    triangles: &[[u32; 3]],
    first: usize,
    sums: &mut [DVec3],
) {
    sums.fill(DVec3::ZERO);
    for &t in triangles {
        add_normal(positions, t, first, sums);
    }
}

/// Adds triangle `t`'s normal to the sums of its corners among the vertices
/// `first..first + sums.len()`: one step of [`vertex_normal_sums_from`].
#[inline]
pub fn add_normal<P: Points + ?Sized>(
    positions: &P,
    t: [u32; 3],
    first: usize,
    sums: &mut [DVec3],
) {
    // Below `first`, an index wraps past the range.
    let local = t.map(|v| (v as usize).wrapping_sub(first));
    if local.iter().all(|&l| l >= sums.len()) {
        return;
    }
    let [a, b, c] = t.map(|v| positions.at(v as usize));
    // |(b − a) × (c − a)| is twice the triangle's area: the sum is area-weighted.
    let n = (b - a).cross(c - a);
    for l in local {
        if let Some(sum) = sums.get_mut(l) {
            *sum += n;
        }
    }
}

/// The unit vertex normals of `positions` (zero where there is no area around a vertex).
pub fn vertex_normals(positions: &[DVec3], triangles: &[[u32; 3]]) -> Vec<DVec3> {
    let mut normals = vec![DVec3::ZERO; positions.len()];
    vertex_normal_sums(positions, triangles, &mut normals);
    normals.iter_mut().for_each(|n| *n = n.normalize_or_zero());
    normals
}

/// The deviation of a vertex that moved from `from` to `to`, whose reference normal sum is
/// `normal` (any length): the displacement along the unit normal, 0 without a normal.
#[inline]
pub fn signed(from: DVec3, to: DVec3, normal: DVec3) -> f64 {
    (to - from).dot(normal.normalize_or_zero()) + 0.0
}

/// The deviation of every vertex from `input` to `output` (both indexed alike) over `triangles`
/// (the input's; see the module documentation). Sequential; the engine computes the same values in
/// parallel into storage of its choice ([`crate::engine::deviation`]).
pub fn signed_deviations(input: &[DVec3], output: &[DVec3], triangles: &[[u32; 3]]) -> Vec<f64> {
    let mut normals = vec![DVec3::ZERO; input.len()];
    vertex_normal_sums(input, triangles, &mut normals);
    input
        .iter()
        .zip(output)
        .zip(&normals)
        .map(|((&p, &q), &n)| signed(p, q, n))
        .collect()
}

/// The colour of deviation `d` on a diverging map over `[−scale, scale]`: blue inward, white at
/// 0, red outward, saturated beyond the scale (a scale of 0 shows only the sign).
pub fn colour(d: f64, scale: f64) -> [u8; 3] {
    let t = if scale > 0.0 {
        (d / scale).clamp(-1.0, 1.0)
    } else if d > 0.0 {
        1.0
    } else if d < 0.0 {
        -1.0
    } else {
        0.0
    };
    // White fading to red (t > 0) or blue (t < 0).
    let fade = (255.0 * (1.0 - t.abs())).round() as u8;
    if t >= 0.0 {
        [255, fade, fade]
    } else {
        [fade, fade, 255]
    }
}

/// What [`DeviationStats`] says of a tolerance.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ToleranceCheck {
    /// The tolerance (model units): a vertex is beyond it when its distance is larger.
    pub limit: f64,
    /// Vertices beyond it.
    pub beyond: u64,
    /// Whether none is.
    pub within: bool,
}

/// A histogram of the deviation over `[min, max]` in [`HISTOGRAM_BINS`] equal bins (bin `k`
/// holds `[min + k w, min + (k + 1) w)`, the last one also `max`); `min = −max` = the largest
/// absolute deviation, so that 0 is the edge between the two middle bins.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Histogram {
    pub min: f64,
    pub max: f64,
    pub counts: Vec<u64>,
}

impl Histogram {
    /// An empty histogram over `[−extent, extent]`.
    pub fn new(extent: f64) -> Histogram {
        Histogram {
            min: -extent + 0.0,
            max: extent + 0.0,
            counts: vec![0; HISTOGRAM_BINS],
        }
    }

    /// The lower edge of bin `k` (`k = HISTOGRAM_BINS`: the upper edge of the last); the middle
    /// edge is exactly 0.
    pub fn edge(&self, k: usize) -> f64 {
        self.min + (self.max - self.min) * (k as f64 / HISTOGRAM_BINS as f64) + 0.0
    }

    /// The bin of `d` (a value in range).
    #[inline]
    pub fn bin(&self, d: f64) -> usize {
        let width = self.max - self.min;
        if width <= 0.0 {
            // Every value is 0: the edge between the middle bins, the upper one.
            return HISTOGRAM_BINS / 2;
        }
        let k = ((d - self.min) / width * HISTOGRAM_BINS as f64).floor();
        (k.max(0.0) as usize).min(HISTOGRAM_BINS - 1)
    }

    /// Count `values` into the bins.
    pub fn add(&mut self, values: &[f64]) {
        for &d in values {
            let k = self.bin(d);
            self.counts[k] += 1;
        }
    }
}

/// One percentile of the distance.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Percentile {
    /// The percentage, e.g. 99.9.
    pub percent: f64,
    /// The smallest distance that at least `percent` % of the vertices do not exceed (the value
    /// of rank `⌈percent/100 · n⌉`, 1-based, in ascending order).
    pub distance: f64,
}

/// The rank (0-based, in ascending order) of percentile `percent` of `n` values (`n > 0`).
pub fn percentile_rank(percent: f64, n: u64) -> u64 {
    // The product first: `99.9 × 1000` is 99900 exactly, `0.999 × 1000` is not 999.
    let r = (percent * n as f64 / 100.0).ceil() as u64;
    r.clamp(1, n) - 1
}

/// The statistics of a deviation field (see the module documentation).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct DeviationStats {
    /// How the field was measured: `"vertex"` (the same vertices: displacement along the
    /// reference's normal) or `"surface"` (nearest point on the other mesh's triangles).
    pub measure: &'static str,
    /// Vertices measured.
    pub vertices: u64,
    /// Of the deviation: root mean square, mean, extremes.
    pub rms: f64,
    pub mean: f64,
    pub min: f64,
    pub max: f64,
    /// Of the distance: root mean square, mean, largest and the vertex that has it (the first
    /// such), percentiles ([`PERCENTILES`]).
    pub distance_rms: f64,
    pub distance_mean: f64,
    pub distance_max: f64,
    pub distance_max_vertex: u64,
    pub percentiles: Vec<Percentile>,
    pub histogram: Histogram,
    /// With a tolerance: how many vertices lie beyond it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<ToleranceCheck>,
}

/// Sums over a run of vertices that combine into [`DeviationStats`]: the engine computes them
/// per chunk and adds them in chunk order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sums {
    pub vertices: u64,
    pub sum: f64,
    pub sum_sq: f64,
    pub min: f64,
    pub max: f64,
    pub distance_sum: f64,
    pub distance_sum_sq: f64,
    pub distance_max: f64,
    /// The first vertex at `distance_max` (global index).
    pub distance_max_vertex: u64,
}

impl Default for Sums {
    fn default() -> Self {
        Sums {
            vertices: 0,
            sum: -0.0,
            sum_sq: -0.0,
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            distance_sum: -0.0,
            distance_sum_sq: -0.0,
            distance_max: 0.0,
            distance_max_vertex: 0,
        }
    }
}

impl Sums {
    /// The sums of `signed` and `distance` (alike indexed), the first at global index `first`.
    pub fn of(first: usize, signed: &[f64], distance: &[f64]) -> Sums {
        let mut s = Sums::default();
        for (k, (&d, &r)) in signed.iter().zip(distance).enumerate() {
            s.vertices += 1;
            s.sum += d;
            s.sum_sq += d * d;
            s.min = s.min.min(d);
            s.max = s.max.max(d);
            s.distance_sum += r;
            s.distance_sum_sq += r * r;
            if r > s.distance_max {
                s.distance_max = r;
                s.distance_max_vertex = (first + k) as u64;
            }
        }
        s
    }

    /// `self` then `later` (the vertices after `self`'s).
    pub fn then(self, later: Sums) -> Sums {
        let (distance_max, distance_max_vertex) = if later.distance_max > self.distance_max {
            (later.distance_max, later.distance_max_vertex)
        } else {
            (self.distance_max, self.distance_max_vertex)
        };
        Sums {
            vertices: self.vertices + later.vertices,
            sum: self.sum + later.sum,
            sum_sq: self.sum_sq + later.sum_sq,
            min: self.min.min(later.min),
            max: self.max.max(later.max),
            distance_sum: self.distance_sum + later.distance_sum,
            distance_sum_sq: self.distance_sum_sq + later.distance_sum_sq,
            distance_max,
            distance_max_vertex,
        }
    }

    /// The statistics of these sums with the `percentiles` (of [`PERCENTILES`]) and `histogram`
    /// counted apart, and the tolerance's count, when one was given.
    pub fn stats(
        &self,
        measure: &'static str,
        percentiles: Vec<Percentile>,
        histogram: Histogram,
        tolerance: Option<ToleranceCheck>,
    ) -> DeviationStats {
        let n = self.vertices as f64;
        let mean = |s: f64| if self.vertices == 0 { 0.0 } else { s / n + 0.0 };
        let extreme = |x: f64| if self.vertices == 0 { 0.0 } else { x + 0.0 };
        DeviationStats {
            measure,
            vertices: self.vertices,
            rms: mean(self.sum_sq).sqrt(),
            mean: mean(self.sum),
            min: extreme(self.min),
            max: extreme(self.max),
            distance_rms: mean(self.distance_sum_sq).sqrt(),
            distance_mean: mean(self.distance_sum),
            distance_max: self.distance_max,
            distance_max_vertex: self.distance_max_vertex,
            percentiles,
            histogram,
            tolerance,
        }
    }

    /// The largest absolute deviation (the histogram's extent).
    pub fn extent(&self) -> f64 {
        if self.vertices == 0 {
            0.0
        } else {
            self.min.abs().max(self.max.abs())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::icosphere;

    #[test]
    fn normal_sums_by_ranges_have_the_bits_of_one_pass() {
        let mut s = icosphere(3);
        // Uneven, so that the sums' order shows in their last bits.
        for (k, p) in s.positions.iter_mut().enumerate() {
            *p *= 1.0 + 0.1 * ((k * 7919) % 13) as f64 / 13.0;
        }
        let mut whole = vec![DVec3::ZERO; s.positions.len()];
        vertex_normal_sums(&s.positions, &s.triangles, &mut whole);
        for part in [1, 7, 100, s.positions.len()] {
            let mut parts = vec![DVec3::ONE; s.positions.len()];
            for (k, sums) in parts.chunks_mut(part).enumerate() {
                vertex_normal_sums_from(&s.positions[..], &s.triangles, k * part, sums);
            }
            let bits = |v: &[DVec3]| {
                v.iter()
                    .map(|p| p.to_array().map(f64::to_bits))
                    .collect::<Vec<_>>()
            };
            assert_eq!(bits(&parts), bits(&whole), "{part}");
        }
    }

    #[test]
    fn a_sphere_grown_by_a_known_amount() {
        let a = icosphere(3);
        let b: Vec<DVec3> = a.positions.iter().map(|p| *p * 1.25).collect();
        let d = signed_deviations(&a.positions, &b, &a.triangles);
        // Each vertex moves 0.25 along its radius, nearly its vertex normal.
        for x in &d {
            assert!((x - 0.25).abs() < 1e-3, "{x}");
        }
        let inward: Vec<DVec3> = a.positions.iter().map(|p| *p * 0.9).collect();
        assert!(
            signed_deviations(&a.positions, &inward, &a.triangles)
                .iter()
                .all(|x| *x < 0.0)
        );
    }

    #[test]
    fn tangential_motion_and_no_normal() {
        let p = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(5.0, 5.0, 5.0)];
        let q = vec![
            DVec3::new(0.1, 0.0, 0.5), // normal (z) part 0.5
            DVec3::X,
            DVec3::Y,
            DVec3::new(6.0, 5.0, 5.0), // unreferenced: no normal
        ];
        let d = signed_deviations(&p, &q, &[[0, 1, 2]]);
        assert_eq!(d, vec![0.5, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn sums_and_percentiles() {
        let signed = [1.0, -3.0, 2.0, 0.0];
        let distance = [1.0, 3.0, 2.0, 0.5];
        let s = Sums::of(0, &signed[..2], &distance[..2]).then(Sums::of(
            2,
            &signed[2..],
            &distance[2..],
        ));
        let st = s.stats("vertex", Vec::new(), Histogram::new(s.extent()), None);
        assert_eq!(st.vertices, 4);
        assert_eq!(st.mean, 0.0);
        assert!((st.rms - (14.0f64 / 4.0).sqrt()).abs() < 1e-15);
        assert_eq!((st.min, st.max), (-3.0, 2.0));
        assert_eq!((st.distance_max, st.distance_max_vertex), (3.0, 1));
        assert_eq!(st.histogram.min, -3.0);
        assert_eq!(percentile_rank(50.0, 4), 1);
        assert_eq!(percentile_rank(99.9, 4), 3);
        assert_eq!(percentile_rank(99.9, 1000), 998);
        assert_eq!(percentile_rank(0.0, 10), 0);
        let empty = Sums::default().stats("vertex", Vec::new(), Histogram::new(0.0), None);
        assert_eq!((empty.min, empty.max, empty.rms), (0.0, 0.0, 0.0));
    }

    #[test]
    fn histogram_bins() {
        let mut h = Histogram::new(1.0);
        h.add(&[-1.0, -0.95, 0.0, 0.99, 1.0]);
        assert_eq!(h.counts[0], 2);
        assert_eq!(h.counts[10], 1);
        assert_eq!(h.counts[19], 2);
        let mut flat = Histogram::new(0.0);
        flat.add(&[0.0, 0.0]);
        assert_eq!(flat.counts[10], 2);
    }

    #[test]
    fn colours() {
        assert_eq!(colour(0.0, 1.0), [255, 255, 255]);
        assert_eq!(colour(1.0, 1.0), [255, 0, 0]);
        assert_eq!(colour(-2.0, 1.0), [0, 0, 255]);
        assert_eq!(colour(0.5, 1.0), [255, 128, 128]);
        assert_eq!(colour(1e-9, 0.0), [255, 0, 0]);
    }
}
