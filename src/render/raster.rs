//! The rasteriser's kernels, pure and sequential (the threads are `render::parallel`'s): a
//! triangle drawn into a frame of visibility samples, and a sample shaded from the triangle it
//! shows.
//!
//! A sample keeps the nearest triangle over it as one 64-bit key, its depth in the high bits and
//! its index in the low ones, lowered with an atomic minimum. The minimum of a set does not depend
//! on the order its members come in, so a frame is the same for any thread count and chunking;
//! equal depths go to the lower index.

use std::sync::atomic::{AtomicU64, Ordering};

use glam::{DVec2, DVec3};

use super::camera::Camera;
use super::image::{Rgb, WHITE};
use super::lanes::{Cells, LANES, Lanes};
use super::palette::Scale;

/// Bits of a key's depth and of its triangle index.
const DEPTH_BITS: u32 = 24;
const INDEX_BITS: u32 = 64 - DEPTH_BITS;
const DEPTH_MAX: f64 = ((1u64 << DEPTH_BITS) - 1) as f64;

/// The most triangles a frame tells apart.
pub const MAX_TRIANGLES: u64 = (1 << INDEX_BITS) - 1;

/// A sample that no triangle covers.
const EMPTY: u64 = u64::MAX;

/// The visibility samples of one camera: the key of the nearest triangle over each sample.
#[derive(Debug)]
pub struct Frame {
    pub camera: Camera,
    samples: Vec<AtomicU64>,
}

impl Frame {
    pub fn new(camera: Camera) -> Frame {
        let n = camera.width * camera.height;
        Frame {
            camera,
            samples: (0..n).map(|_| AtomicU64::new(EMPTY)).collect(),
        }
    }

    /// The triangle seen at sample (`x`, `y`), if any.
    pub fn triangle(&self, x: usize, y: usize) -> Option<usize> {
        let key = self.samples[y * self.camera.width + x].load(Ordering::Relaxed);
        (key != EMPTY).then_some((key & MAX_TRIANGLES) as usize)
    }
}

/// Twice the signed area of `(a, b, p)`: positive when `p` is left of `a → b` (rows grow down).
#[inline]
fn edge(a: DVec2, b: DVec2, p: DVec2) -> f64 {
    (b - a).perp_dot(p - a)
}

/// The samples `k` of an axis of `n` whose centres `k + ½` lie in [`lo`, `hi`], as `k0..=k1`;
/// `None` when there are none (or a bound is NaN). Rounded by casts of values made non-negative
/// first: x86-64's baseline has no rounding instruction, and `ceil`/`floor` are calls to libm
/// that cost more than the rest of a small triangle. The casts go through `i64`, one instruction
/// where a cast to an unsigned type is several; the values lie in `0..n`.
#[inline]
fn centres(lo: f64, hi: f64, n: usize) -> Option<(usize, usize)> {
    let last = n.checked_sub(1)? as f64;
    let (from, to) = (lo - 0.5, hi - 0.5);
    if !(to >= 0.0 && from <= last) {
        return None;
    }
    let (from, to) = (from.max(0.0), to.min(last));
    let floor = from as i64 as usize;
    let k0 = floor + usize::from((floor as f64) < from);
    let k1 = to as i64 as usize;
    (k0 <= k1).then_some((k0, k1))
}

/// A triangle projected into a frame, ready to test sample centres against.
struct Projected {
    a: DVec3,
    b: DVec3,
    c: DVec3,
    /// The sign of its area, its slack and 1 / area: see [`Projected::new`].
    sign: f64,
    slack: f64,
    inv: f64,
}

impl Projected {
    /// `corners` in frame coordinates; `None` for a triangle seen edge-on (or not finite),
    /// which covers nothing.
    #[inline]
    fn new(a: DVec3, b: DVec3, c: DVec3) -> Option<Projected> {
        let area = edge(a.truncate(), b.truncate(), c.truncate());
        if area == 0.0 || !area.is_finite() {
            return None;
        }
        // Either winding: the signs are turned so that inside is positive. A sample on a shared
        // edge is taken by both triangles (the key decides), never dropped by rounding: hence
        // the slack.
        Some(Projected {
            a,
            b,
            c,
            sign: area.signum(),
            slack: -1e-9 * area.abs(),
            inv: 1.0 / area,
        })
    }

    /// The depth key of triangle `index` at the centre of sample (`x`, `y`), if the triangle
    /// covers it (its edges included).
    #[inline]
    fn key(&self, index: u64, x: usize, y: usize) -> Option<u64> {
        let (a, b, c) = (self.a.truncate(), self.b.truncate(), self.c.truncate());
        let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
        let (e0, e1, e2) = (edge(b, c, p), edge(c, a, p), edge(a, b, p));
        if e0 * self.sign < self.slack || e1 * self.sign < self.slack || e2 * self.sign < self.slack
        {
            return None;
        }
        let z = (e0 * self.a.z + e1 * self.b.z + e2 * self.c.z) * self.inv;
        // Rounded by a cast: the clamped depth is not negative (NaN casts to 0), and below 2⁶³.
        let depth = (z.clamp(0.0, 1.0) * DEPTH_MAX + 0.5) as i64 as u64;
        Some(depth << INDEX_BITS | index)
    }
}

/// Draw triangles `first..first + triangles.len()` into every frame. Frames go four at a time
/// through `Lanes`, which rules most (triangle, frame) pairs out at once; the others take the
/// exact test. A vertex is shared by about six triangles, so the chunk's vertices are placed
/// among the sample centres once each (a `Window` of ids), and a triangle's test compares its
/// corners' `Cells` in integers.
pub fn draw_triangles(frames: &[Frame], positions: &[DVec3], first: usize, triangles: &[[u32; 3]]) {
    let Some(&[v, ..]) = triangles.first() else {
        return;
    };
    // The triangles of a chunk lie close together: near their first corner, f32 is precise.
    let origin = positions[v as usize];
    let window = Window::of(triangles);
    let mut cells = Vec::new();
    for group in frames.chunks(LANES) {
        let cameras: Vec<Camera> = group.iter().map(|f| f.camera).collect();
        let lanes = Lanes::new(&cameras, origin);
        cells.clear();
        cells.extend(positions[window.ids()].iter().map(|&p| lanes.cells(p)));
        for (k, &[i, j, l]) in triangles.iter().enumerate() {
            let ids = [i, j, l];
            let mut maybe = match ids.map(|v| window.get(&cells, v)) {
                [Some(a), Some(b), Some(c)] => lanes.maybe([a, b, c]),
                met => {
                    let [a, b, c] = [0, 1, 2].map(|n| {
                        met[n]
                            .copied()
                            .unwrap_or_else(|| lanes.cells(positions[ids[n] as usize]))
                    });
                    lanes.maybe([&a, &b, &c])
                }
            };
            if maybe == 0 {
                continue;
            }
            let [a, b, c] = ids.map(|v| positions[v as usize]);
            while maybe != 0 {
                let frame = &group[maybe.trailing_zeros() as usize];
                maybe &= maybe - 1;
                let cam = &frame.camera;
                let index = (first + k) as u64;
                draw_triangle(frame, index, cam.project(a), cam.project(b), cam.project(c));
            }
        }
    }
}

/// The ids of a chunk's vertices that are placed once for all its triangles: those from its
/// smallest first corner to its largest. In the plan's order (triangles sorted by their first
/// corner, which is their smallest, and vertices in Morton order) about 98 % of the corners fall
/// inside, and the others are placed where they are met. A chunk whose first corners are spread
/// wider than `SPAN` ids a triangle (a mesh in another order) places every corner where it is met.
struct Window {
    first: u32,
    len: u32,
}

/// Ids a window may span for each triangle of its chunk (a closed mesh has half as many
/// vertices as triangles).
const SPAN: u64 = 2;

impl Window {
    fn of(triangles: &[[u32; 3]]) -> Window {
        let (lo, hi) =
            (triangles.iter()).fold((u32::MAX, 0), |(lo, hi), t| (lo.min(t[0]), hi.max(t[0])));
        let len = (hi as u64 + 1).saturating_sub(lo as u64);
        Window {
            first: lo,
            len: if len <= SPAN * triangles.len() as u64 {
                len as u32
            } else {
                0
            },
        }
    }

    fn ids(&self) -> std::ops::Range<usize> {
        self.first as usize..self.first as usize + self.len as usize
    }

    /// Vertex `v`'s cells, if the window holds it.
    #[inline]
    fn get<'m>(&self, cells: &'m [Cells], v: u32) -> Option<&'m Cells> {
        cells.get(v.wrapping_sub(self.first) as usize)
    }
}

/// Draw triangle `index` with corners `a`, `b`, `c` (in frame coordinates) into `frame`: every
/// sample whose centre it covers takes it if it is nearer than what the sample holds.
#[inline]
fn draw_triangle(frame: &Frame, index: u64, a: DVec3, b: DVec3, c: DVec3) {
    let cam = &frame.camera;
    let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
    let Some((x0, x1)) = centres(lo.x, hi.x, cam.width) else {
        return;
    };
    let Some((y0, y1)) = centres(lo.y, hi.y, cam.height) else {
        return;
    };
    let Some(tri) = Projected::new(a, b, c) else {
        return;
    };
    // Most triangles of a large mesh hold one sample centre in their box, or none.
    if x0 == x1 && y0 == y1 {
        if let Some(key) = tri.key(index, x0, y0) {
            frame.samples[y0 * cam.width + x0].fetch_min(key, Ordering::Relaxed);
        }
        return;
    }
    for y in y0..=y1 {
        let row = &frame.samples[y * cam.width + x0..=y * cam.width + x1];
        for (x, sample) in (x0..=x1).zip(row) {
            if let Some(key) = tri.key(index, x, y) {
                sample.fetch_min(key, Ordering::Relaxed);
            }
        }
    }
}

/// How a visible triangle is coloured.
#[derive(Debug, Clone, Copy)]
pub enum Paint<'a> {
    /// Grey, lit by a headlight: each triangle flat by its own normal, so that the picture shows
    /// the surface's roughness as it is.
    Grey,
    /// A per-vertex value (indexed as the positions), interpolated across each triangle and
    /// coloured by `scale`, lit by the same headlight more softly.
    Values { values: &'a [f32], scale: Scale },
}

/// Grey of a surface facing the viewer, and of one seen edge-on.
const GREY_LIT: f64 = 235.0;
const GREY_DARK: f64 = 45.0;
/// Share of a value's colour that the headlight takes away at grazing angles.
const VALUE_SHADOW: f64 = 0.45;

/// A visible triangle as the paints need it, found once for all the samples that show it.
struct Seen {
    ids: [u32; 3],
    /// Its corners in frame coordinates (only when a paint interpolates values).
    corners: Option<[DVec2; 3]>,
    /// How squarely it faces the headlight: |cos| of the angle, 0 for a degenerate triangle.
    lit: f64,
}

impl Seen {
    fn new(frame: &Frame, positions: &[DVec3], ids: [u32; 3], corners: bool) -> Seen {
        let [a, b, c] = [0, 1, 2].map(|k| positions[ids[k] as usize]);
        let normal = (b - a).cross(c - a);
        let lit = match normal.length() {
            l if l > 0.0 && l.is_finite() => (normal.dot(frame.camera.toward) / l).abs(),
            _ => 0.0,
        };
        let cam = &frame.camera;
        Seen {
            ids,
            corners: corners.then(|| [a, b, c].map(|p| cam.project(p).truncate())),
            lit,
        }
    }

    /// Its colour under `paint` at `p` (frame coordinates). Channels are rounded by casts of
    /// non-negative values: `round` is a call to libm on x86-64's baseline.
    fn colour(&self, paint: &Paint, p: DVec2) -> Rgb {
        match paint {
            Paint::Grey => {
                let g = (GREY_DARK + (GREY_LIT - GREY_DARK) * self.lit + 0.5) as u8;
                [g, g, g]
            }
            Paint::Values { values, scale } => {
                let w = self.corners.map_or([1.0 / 3.0; 3], |c| barycentric(c, p));
                let v = (0..3)
                    .map(|k| w[k] * values[self.ids[k] as usize] as f64)
                    .sum::<f64>();
                let colour = scale.colour(v as f32);
                let light = 1.0 - VALUE_SHADOW * (1.0 - self.lit);
                colour.map(|ch| (ch as f64 * light + 0.5) as u8)
            }
        }
    }
}

/// The weights of `corners` at `p`, clamped to the triangle (a sample on its edge may fall a
/// rounding outside) and summing to 1.
fn barycentric([a, b, c]: [DVec2; 3], p: DVec2) -> [f64; 3] {
    let area = edge(a, b, c);
    if area == 0.0 || !area.is_finite() {
        return [1.0 / 3.0; 3];
    }
    let w = [edge(b, c, p), edge(c, a, p), edge(a, b, p)].map(|e| (e / area).max(0.0));
    let sum = w[0] + w[1] + w[2];
    match sum > 0.0 {
        true => w.map(|x| x / sum),
        false => [1.0 / 3.0; 3],
    }
}

/// Pixels a [`Looked`] takes at once: their samples' triangles (at most `SEGMENT × factor²`)
/// stay in the first levels of the cache between the look-up and the shading.
const SEGMENT: usize = 64;

/// The visible triangles of a segment of a pixel row, looked up for all its samples at once. On a
/// large mesh nearly every sample shows a triangle of its own, far in memory from the last one:
/// one triangle at a time, each look-up waits for its triangle's corners and then their
/// positions. Each step here is a loop of reads that do not wait for one another, which the
/// processor overlaps.
#[derive(Default)]
struct Looked {
    /// The triangle each sample shows (`NONE` for none), row by row of the segment's samples.
    triangle: Vec<usize>,
    /// Each sample's place in `seen` (the triangles it shows, each once for a run of samples).
    slot: Vec<u32>,
    /// The triangles to look up, and their corners' ids.
    wanted: Vec<usize>,
    ids: Vec<[u32; 3]>,
    seen: Vec<Seen>,
}

const NONE: usize = usize::MAX;

impl Looked {
    /// Look up the samples of pixels `px` of row `py` (`factor × factor` samples a pixel).
    #[allow(clippy::too_many_arguments)]
    fn segment(
        &mut self,
        frame: &Frame,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        corners: bool,
        factor: usize,
        py: usize,
        px: std::ops::Range<usize>,
    ) {
        let (sx, sy) = (
            px.start * factor..px.end * factor,
            py * factor..(py + 1) * factor,
        );
        let across = sx.len();
        self.triangle.clear();
        self.slot.clear();
        self.wanted.clear();
        for y in sy {
            for x in sx.clone() {
                let t = frame.triangle(x, y).unwrap_or(NONE);
                let s = self.triangle.len();
                // The sample before it and the one above show the same triangle most often.
                let known = [s.checked_sub(1), s.checked_sub(across)]
                    .into_iter()
                    .flatten()
                    .find(|&k| self.triangle[k] == t);
                let slot = match known {
                    Some(k) => self.slot[k],
                    None if t == NONE => u32::MAX,
                    None => {
                        self.wanted.push(t);
                        (self.wanted.len() - 1) as u32
                    }
                };
                self.triangle.push(t);
                self.slot.push(slot);
            }
        }
        self.ids.clear();
        self.ids.extend(self.wanted.iter().map(|&t| triangles[t]));
        self.seen.clear();
        self.seen.extend(
            self.ids
                .iter()
                .map(|&ids| Seen::new(frame, positions, ids, corners)),
        );
    }

    /// The triangle shown by sample `k` of the segment, and how it is seen.
    #[inline]
    fn at(&self, k: usize) -> Option<&Seen> {
        self.seen.get(self.slot[k] as usize)
    }
}

/// Pixel row `py` of the pictures of `frame` under each of `paints`, at `factor × factor`
/// samples a pixel: each pixel the mean of its samples' colours (the edges smoothed), into `out`
/// (the row of each paint in turn). A pixel whose samples all show one triangle is shaded once,
/// at its centre: its values interpolate linearly, so the centre's is the samples' mean.
pub fn shade_row(
    frame: &Frame,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    paints: &[Paint],
    factor: usize,
    py: usize,
    out: &mut [Rgb],
) {
    let width = out.len() / paints.len().max(1);
    let corners = paints.iter().any(|p| matches!(p, Paint::Values { .. }));
    let mut looked = Looked::default();
    let n = (factor * factor) as u32;
    let mut sums = vec![[0u32; 3]; paints.len()];
    for from in (0..width).step_by(SEGMENT) {
        let to = (from + SEGMENT).min(width);
        looked.segment(frame, positions, triangles, corners, factor, py, from..to);
        let across = (to - from) * factor;
        for px in from..to {
            // The segment's samples of pixel `px`, row by row.
            let first = (px - from) * factor;
            let samples = (0..factor).flat_map(|dy| (0..factor).map(move |dx| (dx, dy)));
            let index = |(dx, dy): (usize, usize)| dy * across + first + dx;
            let t = looked.triangle[first];
            if samples.clone().all(|s| looked.triangle[index(s)] == t) {
                let f = factor as f64;
                let centre = DVec2::new((px as f64 + 0.5) * f, (py as f64 + 0.5) * f);
                for (k, paint) in paints.iter().enumerate() {
                    out[k * width + px] =
                        looked.at(first).map_or(WHITE, |s| s.colour(paint, centre));
                }
                continue;
            }
            sums.iter_mut().for_each(|s| *s = [0; 3]);
            for (dx, dy) in samples {
                let (sx, sy) = (px * factor + dx, py * factor + dy);
                let p = DVec2::new(sx as f64 + 0.5, sy as f64 + 0.5);
                let seen = looked.at(index((dx, dy)));
                for (sum, paint) in sums.iter_mut().zip(paints) {
                    let c = seen.map_or(WHITE, |s| s.colour(paint, p));
                    for i in 0..3 {
                        sum[i] += c[i] as u32;
                    }
                }
            }
            for (k, sum) in sums.iter().enumerate() {
                out[k * width + px] = sum.map(|s| ((s + n / 2) / n) as u8);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::camera::{Bounds, View};

    #[test]
    fn the_nearer_triangle_wins_whatever_the_order() {
        let far = [
            DVec3::new(-1.0, -1.0, -1.0),
            DVec3::new(1.0, -1.0, -1.0),
            DVec3::new(0.0, 1.0, -1.0),
        ];
        let near = far.map(|p| p + DVec3::new(0.0, 0.0, 2.0));
        let positions: Vec<DVec3> = far.iter().chain(&near).copied().collect();
        let bounds = Bounds::in_view(&positions, View::Front);
        for tris in [[[0, 1, 2], [3, 5, 4]], [[3, 4, 5], [0, 2, 1]]] {
            let frame = Frame::new(Camera::framing(View::Front, bounds, 20, 20));
            draw_triangles(std::slice::from_ref(&frame), &positions, 0, &tris);
            let seen = frame.triangle(10, 10).unwrap();
            assert!(tris[seen][0] == 3, "{tris:?}: {seen}");
            assert_eq!(frame.triangle(0, 0), None);
        }
    }

    /// Triangles from a fixed pseudo-random sequence: most far smaller than a sample (one centre
    /// in their box or none: the fast path), some spanning many, both windings, a few degenerate.
    fn scattered(count: usize) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let mut next = crate::render::uniform(0x2545_f491_4f6c_dd1du64);
        let mut positions = Vec::new();
        for k in 0..count {
            let centre = DVec3::new(next(), next(), next());
            let size = if k % 10 == 0 { 0.2 } else { 0.02 };
            for _ in 0..3 {
                let jitter = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
                positions.push(centre + jitter * size);
            }
        }
        // A degenerate triangle: all its corners at one point.
        positions[3] = positions[4];
        positions[5] = positions[4];
        let triangles = (0..count as u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        (positions, triangles)
    }

    #[test]
    fn a_frame_holds_the_nearest_cover_of_every_sample() {
        let (near, listed) = scattered(3000);
        // Also far from the origin, where f32 alone would lose the samples.
        let far: Vec<DVec3> = near
            .iter()
            .map(|&p| p + DVec3::new(3e5, -2e6, 1e4))
            .collect();
        // The chunks' first corners span three ids a triangle: too wide for a `Window`. A strip
        // of triangles over the same points has nearly every corner in its chunk's window; and
        // with each triangle's second and third corners far from its first in the ids, the
        // window holds those not.
        let strip: Vec<[u32; 3]> = (0..listed.len() as u32)
            .map(|t| [t, t + 1, t + 2])
            .collect();
        let n = listed.len();
        let mut apart = near.clone();
        for (t, corners) in listed.iter().enumerate() {
            for (k, &v) in corners.iter().enumerate() {
                apart[k * n + t] = near[v as usize];
            }
        }
        let spread: Vec<[u32; 3]> = (0..n as u32)
            .map(|t| [t, n as u32 + t, 2 * n as u32 + t])
            .collect();
        for (positions, triangles) in [
            (near.clone(), &listed),
            (far, &listed),
            (near, &strip),
            (apart, &spread),
        ] {
            let cameras: Vec<Camera> = View::STANDARD
                .iter()
                .map(|&v| Camera::framing(v, Bounds::in_view(&positions, v), 48, 40))
                .collect();
            // All views at once, in two chunks (two origins), as `parallel` draws them.
            let frames: Vec<Frame> = cameras.iter().map(|&c| Frame::new(c)).collect();
            let (one, two) = triangles.split_at(1000);
            draw_triangles(&frames, &positions, 0, one);
            draw_triangles(&frames, &positions, one.len(), two);
            for (frame, camera) in frames.iter().zip(&cameras) {
                // Every sample tested against every triangle, without boxes or shortcuts.
                let projected: Vec<_> = triangles
                    .iter()
                    .map(|t| {
                        let [a, b, c] = t.map(|v| camera.project(positions[v as usize]));
                        Projected::new(a, b, c)
                    })
                    .collect();
                let mut covered = 0;
                for y in 0..camera.height {
                    for x in 0..camera.width {
                        let nearest = (projected.iter().enumerate())
                            .filter_map(|(t, p)| p.as_ref()?.key(t as u64, x, y))
                            .min();
                        let key = frame.samples[y * camera.width + x].load(Ordering::Relaxed);
                        assert_eq!(key, nearest.unwrap_or(EMPTY), "{camera:?} ({x}, {y})");
                        covered += usize::from(nearest.is_some());
                    }
                }
                assert!(covered > camera.width * camera.height / 8, "{covered}");
            }
        }
    }

    #[test]
    fn a_pixel_is_its_triangles_colour_or_the_mean_of_its_samples() {
        let (positions, triangles) = scattered(3000);
        let values: Vec<f32> = (0..positions.len())
            .map(|i| (i % 17) as f32 - 8.0)
            .collect();
        let scale = Scale::for_range(-8.0, 8.0);
        let paints = [
            Paint::Grey,
            Paint::Values {
                values: &values,
                scale,
            },
        ];
        // Wider than two segments, so that segments end inside a row.
        let factor = 3;
        let (w, h) = (2 * SEGMENT + 37, 30);
        let bounds = Bounds::in_view(&positions, View::Iso);
        let camera = Camera::framing(View::Iso, bounds, w * factor, h * factor);
        let frame = Frame::new(camera);
        draw_triangles(std::slice::from_ref(&frame), &positions, 0, &triangles);
        let seen = |x, y| {
            let t: Option<usize> = frame.triangle(x, y);
            t.map(|t| Seen::new(&frame, &positions, triangles[t], true))
        };
        let (mut uniform, mut mixed) = (0, 0);
        for py in 0..h {
            let mut out = vec![[0u8; 3]; w * paints.len()];
            shade_row(
                &frame, &positions, &triangles, &paints, factor, py, &mut out,
            );
            for px in 0..w {
                // One sample at a time, as the definition reads.
                let samples: Vec<(usize, usize)> = (0..factor * factor)
                    .map(|k| (px * factor + k % factor, py * factor + k / factor))
                    .collect();
                let shown: Vec<Option<usize>> =
                    samples.iter().map(|&(x, y)| frame.triangle(x, y)).collect();
                let one = shown.iter().all(|&t| t == shown[0]);
                for (k, paint) in paints.iter().enumerate() {
                    let expected = if one {
                        let f = factor as f64;
                        let centre = DVec2::new((px as f64 + 0.5) * f, (py as f64 + 0.5) * f);
                        let (sx, sy) = samples[0];
                        seen(sx, sy).map_or(WHITE, |s| s.colour(paint, centre))
                    } else {
                        let mut sum = [0u32; 3];
                        for &(x, y) in &samples {
                            let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                            let c = seen(x, y).map_or(WHITE, |s| s.colour(paint, p));
                            (0..3).for_each(|i| sum[i] += c[i] as u32);
                        }
                        let n = samples.len() as u32;
                        sum.map(|s| ((s + n / 2) / n) as u8)
                    };
                    assert_eq!(out[k * w + px], expected, "paint {k} pixel ({px}, {py})");
                }
                match one {
                    true => uniform += 1,
                    false => mixed += 1,
                }
            }
        }
        assert!(
            uniform > w * h / 20 && mixed > w * h / 20,
            "{uniform} {mixed}"
        );
    }

    #[test]
    fn the_centres_in_a_span_are_those_of_ceil_and_floor() {
        let values = [
            -3.0, -0.5, -0.2, 0.0, 0.3, 0.5, 0.50001, 1.5, 2.7, 9.5, 9.6, 12.0,
        ];
        for &lo in &values {
            for &hi in &values {
                let k0 = (lo - 0.5f64).ceil().max(0.0);
                let k1 = (hi - 0.5f64).floor().min(9.0);
                let expected = (k0 <= k1).then_some((k0 as usize, k1 as usize));
                assert_eq!(centres(lo, hi, 10), expected, "{lo} {hi}");
            }
        }
        assert_eq!(centres(f64::NAN, 3.0, 10), None);
        assert_eq!(centres(0.0, f64::NAN, 10), None);
        assert_eq!(centres(f64::NEG_INFINITY, f64::INFINITY, 10), Some((0, 9)));
        assert_eq!(centres(0.0, 5.0, 0), None);
    }
}
