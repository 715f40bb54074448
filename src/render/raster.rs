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

/// Draw triangles `first..first + triangles.len()` into every frame.
pub fn draw_triangles(frames: &[Frame], positions: &[DVec3], first: usize, triangles: &[[u32; 3]]) {
    for (k, t) in triangles.iter().enumerate() {
        let corners = t.map(|v| positions[v as usize]);
        for frame in frames {
            draw_triangle(frame, (first + k) as u64, corners);
        }
    }
}

/// Draw triangle `index` with `corners` into `frame`: every sample whose centre it covers (its
/// edges included) takes it if it is nearer than what the sample holds. Triangles seen edge-on
/// cover nothing.
#[inline]
fn draw_triangle(frame: &Frame, index: u64, corners: [DVec3; 3]) {
    let cam = &frame.camera;
    let [a, b, c] = corners.map(|p| cam.project(p));
    let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
    // Sample centres at k + ½ inside the triangle's box, clipped to the frame.
    let x0 = (lo.x - 0.5).ceil().max(0.0);
    let y0 = (lo.y - 0.5).ceil().max(0.0);
    let x1 = (hi.x - 0.5).floor().min(cam.width as f64 - 1.0);
    let y1 = (hi.y - 0.5).floor().min(cam.height as f64 - 1.0);
    if !(x0 <= x1 && y0 <= y1) {
        return;
    }
    let (a2, b2, c2) = (a.truncate(), b.truncate(), c.truncate());
    let area = edge(a2, b2, c2);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    // Either winding: the signs are turned so that inside is positive. A sample on a shared edge
    // is taken by both triangles (the key decides), never dropped by rounding: hence the slack.
    let sign = area.signum();
    let slack = -1e-9 * area.abs();
    let inv = 1.0 / area;
    for y in y0 as usize..=y1 as usize {
        let row = &frame.samples[y * cam.width..(y + 1) * cam.width];
        for (x, sample) in row
            .iter()
            .enumerate()
            .take(x1 as usize + 1)
            .skip(x0 as usize)
        {
            let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            let (e0, e1, e2) = (edge(b2, c2, p), edge(c2, a2, p), edge(a2, b2, p));
            if e0 * sign < slack || e1 * sign < slack || e2 * sign < slack {
                continue;
            }
            let z = (e0 * a.z + e1 * b.z + e2 * c.z) * inv;
            let depth = (z.clamp(0.0, 1.0) * DEPTH_MAX).round() as u64;
            sample.fetch_min(depth << INDEX_BITS | index, Ordering::Relaxed);
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

/// The colour of sample (`x`, `y`) of `frame`: the background where no triangle is, else the
/// visible triangle's colour under `paint`.
pub fn shade_sample(
    frame: &Frame,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    paint: &Paint,
    x: usize,
    y: usize,
) -> Rgb {
    let Some(t) = frame.triangle(x, y) else {
        return WHITE;
    };
    let ids = triangles[t];
    let [a, b, c] = ids.map(|v| positions[v as usize]);
    let normal = (b - a).cross(c - a);
    let lit = match normal.length() {
        l if l > 0.0 && l.is_finite() => (normal.dot(frame.camera.toward) / l).abs(),
        _ => 0.0,
    };
    match paint {
        Paint::Grey => {
            let g = (GREY_DARK + (GREY_LIT - GREY_DARK) * lit).round() as u8;
            [g, g, g]
        }
        Paint::Values { values, scale } => {
            let w = barycentric(&frame.camera, [a, b, c], x, y);
            let v = w[0] * values[ids[0] as usize] as f64
                + w[1] * values[ids[1] as usize] as f64
                + w[2] * values[ids[2] as usize] as f64;
            let colour = scale.colour(v as f32);
            let light = 1.0 - VALUE_SHADOW * (1.0 - lit);
            colour.map(|ch| (ch as f64 * light).round() as u8)
        }
    }
}

/// The weights of `corners` at the centre of sample (`x`, `y`), clamped to the triangle (a
/// sample on its edge may fall a rounding outside) and summing to 1.
fn barycentric(cam: &Camera, corners: [DVec3; 3], x: usize, y: usize) -> [f64; 3] {
    let [a, b, c] = corners.map(|p| cam.project(p).truncate());
    let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
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

/// Pixel row `py` of a picture of `frame` at `factor × factor` samples a pixel: each pixel the
/// mean of its samples' colours (the edges smoothed), into `out`.
pub fn shade_row(
    frame: &Frame,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    paint: &Paint,
    factor: usize,
    py: usize,
    out: &mut [Rgb],
) {
    let n = (factor * factor) as u32;
    for (px, pixel) in out.iter_mut().enumerate() {
        let mut sum = [0u32; 3];
        for sy in py * factor..(py + 1) * factor {
            for sx in px * factor..(px + 1) * factor {
                let c = shade_sample(frame, positions, triangles, paint, sx, sy);
                for i in 0..3 {
                    sum[i] += c[i] as u32;
                }
            }
        }
        *pixel = sum.map(|s| ((s + n / 2) / n) as u8);
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
}
