//! The rasteriser's first test, four frames at once: which frames a triangle may hold a sample
//! centre of in its box. Each vertex is placed among every frame's sample centres once
//! ([`Lanes::cells`], in f32 with a margin of rounding), and a triangle's test compares its
//! corners' [`Cells`] in 16-bit integers ([`Lanes::maybe`]). On x86-64 both run in SSE2's
//! vector instructions (part of its baseline); the plain versions beside them are the reference
//! and run elsewhere.

use glam::{DVec3, Vec3};

use super::camera::Camera;

/// Frames a [`Lanes`] tests at once.
pub const LANES: usize = 4;

/// Lanes of a [`Cells`]: a column and a row for each frame.
const AXES: usize = 2 * LANES;

/// Where a point lies among the sample centres of up to four frames, on each axis (lane `f` the
/// column in frame `f`, lane `LANES + f` its row), with the margin of rounding: `up` is the last
/// centre at or before the point moved forward by the margin, `down` the last one before the
/// point moved back by it. Both are clamped to −1 ..= last + 1, which decides no test
/// differently; a point that is not finite in f32 (with its margin) holds `NEVER_UP` and
/// `NEVER_DOWN`, which rule nothing out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C, align(16))]
pub struct Cells {
    up: [i16; AXES],
    down: [i16; AXES],
}

/// `Cells` of a point that is not finite. Far enough from `i16`'s ends that no difference the test
/// takes overflows: `NEVER_UP − NEVER_DOWN` is `i16::MAX`.
const NEVER_UP: i16 = (1 << 14) - 1;
const NEVER_DOWN: i16 = -(1 << 14);

/// The largest last sample a frame's side may have for its `Cells`; a wider frame (a picture has
/// a few thousand samples a side) is left to the exact test.
const MAX_LAST: i64 = (1 << 13) - 2;

/// The column and row maps of up to four frames' cameras in f32 lanes. Points are taken
/// relative to `origin` (f64, then f32) so that f32 keeps its precision near it, and the test is
/// made conservative by a margin of about 160 times f32's rounding of every term (and f64's of
/// the exact projection): a frame it rules out, the exact test in f64 would have too. Unused
/// lanes rule everything out.
#[derive(Debug)]
pub struct Lanes {
    origin: DVec3,
    /// Lane `f` of `s[k]` is component `k` of frame `f`'s column map, lane `LANES + f` of its
    /// row map; `o` their offsets at `origin`, less ½ (sample centres lie at `k + ½`).
    s: [[f32; AXES]; 3],
    o: [f32; AXES],
    /// The last column and row (−1 in unused lanes), laid out as `Cells`; `top` one beyond
    /// each, as f32: where `Cells` clamp.
    last: [i16; AXES],
    top: [f32; AXES],
    /// The margin: `fixed + per_unit × (the point's largest coordinate from origin)`.
    fixed: [f32; AXES],
    per_unit: [f32; AXES],
    used: u32,
    /// Frames too wide for `Cells`, which the test leaves to the exact one.
    wide: u32,
}

impl Lanes {
    /// The lanes of the frames of `cameras` (the first [`LANES`]), for points near `origin`.
    pub fn new(cameras: &[Camera], origin: DVec3) -> Lanes {
        let frames = &cameras[..cameras.len().min(LANES)];
        // Lane `f` of `f(frame, axis)` for each axis, as `Cells` lay them out.
        let lane = |f: &dyn Fn(&Camera, usize) -> f64| {
            let mut v = [0.0f32; AXES];
            for (k, frame) in frames.iter().enumerate() {
                v[k] = f(frame, 0) as f32;
                v[LANES + k] = f(frame, 1) as f32;
            }
            v
        };
        let map = |camera: &Camera, axis: usize| camera.screen()[axis];
        let at = |frame: &Camera, axis: usize| {
            let (s, o) = map(frame, axis);
            origin.dot(s) + o
        };
        let l1 = |frame: &Camera, axis: usize| map(frame, axis).0.abs().element_sum();
        let scale = |frame: &Camera| l1(frame, 0).max(l1(frame, 1));
        const F32: f64 = 1e-5;
        const F64: f64 = 1e-14;
        let fixed = |frame: &Camera| {
            let (o, ox, oy) = (origin.abs().max_element(), map(frame, 0).1, map(frame, 1).1);
            F32 * at(frame, 0).abs().max(at(frame, 1).abs())
                + F64 * (o * scale(frame) + ox.abs().max(oy.abs()))
                + 1e-6
        };
        let mut last = [-1i16; AXES];
        let mut wide = 0;
        for (f, frame) in frames.iter().enumerate() {
            let side = |n: usize| (n as i64 - 1).clamp(-1, MAX_LAST);
            let (w, h) = (frame.width, frame.height);
            wide |= u32::from(w.max(h) as i64 - 1 > MAX_LAST) << f;
            last[f] = side(w) as i16;
            last[LANES + f] = side(h) as i16;
        }
        Lanes {
            origin,
            s: [0, 1, 2].map(|k| lane(&|f, axis| map(f, axis).0[k])),
            o: lane(&|f, axis| at(f, axis) - 0.5),
            last,
            top: last.map(|l| l as f32 + 1.0),
            fixed: lane(&|f, _| fixed(f)),
            per_unit: lane(&|f, _| F32 * scale(f)),
            used: (1 << frames.len()) - 1,
            wide,
        }
    }

    /// Where `p` lies among each frame's sample centres.
    #[inline]
    pub fn cells(&self, p: DVec3) -> Cells {
        let q = (p - self.origin).as_vec3();
        // SAFETY: SSE2 is part of x86-64's baseline.
        #[cfg(target_arch = "x86_64")]
        return unsafe { sse2::cells(self, q) };
        #[cfg(not(target_arch = "x86_64"))]
        return self.cells_plain(q);
    }

    /// The frames (bit `f` for lane `f`) in which the triangle of corners `a`, `b`, `c` may hold
    /// a sample centre in its box: all but those where it surely holds none.
    #[inline]
    pub fn maybe(&self, corners: [&Cells; 3]) -> u32 {
        // SAFETY: SSE2 is part of x86-64's baseline.
        #[cfg(target_arch = "x86_64")]
        let ruled_out = unsafe { sse2::ruled_out(self, corners) };
        #[cfg(not(target_arch = "x86_64"))]
        let ruled_out = self.ruled_out_plain(corners);
        (!ruled_out | self.wide) & self.used
    }

    /// [`Lanes::cells`] of `q` (the point less `origin`), lane by lane.
    #[cfg_attr(target_arch = "x86_64", allow(dead_code))]
    fn cells_plain(&self, q: Vec3) -> Cells {
        let far = q.abs().max_element();
        let (mut up, mut down) = ([0i16; AXES], [0i16; AXES]);
        for k in 0..AXES {
            let v = q.x * self.s[0][k] + q.y * self.s[1][k] + q.z * self.s[2][k] + self.o[k];
            let margin = self.fixed[k] + self.per_unit[k] * far;
            let (hi, lo) = (v + margin, v - margin);
            if !(hi - lo).is_finite() {
                (up[k], down[k]) = (NEVER_UP, NEVER_DOWN);
                continue;
            }
            // Clamped first, so that a cast truncates values in −1 ..= last + 1: ⌊hi⌋ is then
            // the truncation less one where it rounded up, ⌈lo⌉ − 1 the truncation less one
            // where it did not round down.
            let (hi, lo) = (hi.clamp(-1.0, self.top[k]), lo.clamp(-1.0, self.top[k]));
            let (th, tl) = (hi as i32, lo as i32);
            up[k] = (th - i32::from(th as f32 > hi)) as i16;
            down[k] = (tl - i32::from(tl as f32 >= lo)) as i16;
        }
        Cells { up, down }
    }

    /// The frames (bit `f`) in which the corners surely hold no sample centre, lane by lane.
    #[cfg_attr(target_arch = "x86_64", allow(dead_code))]
    fn ruled_out_plain(&self, [a, b, c]: [&Cells; 3]) -> u32 {
        // On an axis, the centres k in the box (with the margin) are those with
        // min(down) < k ≤ max(up), inside 0 ..= last: none when `up ≤ down`, `up < 0` or
        // `down ≥ last`, each a negative number.
        let mut none = [0i16; AXES];
        for (k, none) in none.iter_mut().enumerate() {
            let up = a.up[k].max(b.up[k]).max(c.up[k]);
            let down = a.down[k].min(b.down[k]).min(c.down[k]);
            *none = (up - down - 1) | up | (self.last[k] - 1 - down);
        }
        (0..LANES).fold(0, |bits, f| {
            bits | u32::from((none[f] | none[LANES + f]) < 0) << f
        })
    }
}

/// The same in SSE2's lanes: four f32 or eight i16 a register, the columns in one register and
/// the rows in another.
#[cfg(target_arch = "x86_64")]
mod sse2 {
    use std::arch::x86_64::*;

    use glam::Vec3;

    use super::{AXES, Cells, LANES, Lanes, NEVER_DOWN, NEVER_UP};

    /// Lanes `4 h .. 4 h + 4` of `a`.
    #[inline]
    #[target_feature(enable = "sse2")]
    fn half(a: &[f32; AXES], h: usize) -> __m128 {
        // SAFETY: four f32 from `4 h`, inside the array for h ≤ 1 (the slice checks it).
        unsafe { _mm_loadu_ps(a[4 * h..4 * h + 4].as_ptr()) }
    }

    #[inline]
    #[target_feature(enable = "sse2")]
    pub fn cells(l: &Lanes, q: Vec3) -> Cells {
        let far = _mm_set1_ps(q.abs().max_element());
        let (x, y, z) = (_mm_set1_ps(q.x), _mm_set1_ps(q.y), _mm_set1_ps(q.z));
        let minus_one = _mm_set1_ps(-1.0);
        let axis = |h: usize| {
            let v = _mm_add_ps(
                _mm_add_ps(
                    _mm_add_ps(
                        _mm_mul_ps(x, half(&l.s[0], h)),
                        _mm_mul_ps(y, half(&l.s[1], h)),
                    ),
                    _mm_mul_ps(z, half(&l.s[2], h)),
                ),
                half(&l.o, h),
            );
            let margin = _mm_add_ps(half(&l.fixed, h), _mm_mul_ps(half(&l.per_unit, h), far));
            let (hi, lo) = (_mm_add_ps(v, margin), _mm_sub_ps(v, margin));
            // Finite both: their difference less itself is 0 (NaN otherwise).
            let d = _mm_sub_ps(hi, lo);
            let finite = _mm_castps_si128(_mm_cmpeq_ps(_mm_sub_ps(d, d), _mm_setzero_ps()));
            let top = half(&l.top, h);
            let clamp = |w| _mm_min_ps(_mm_max_ps(w, minus_one), top);
            let (hi, lo) = (clamp(hi), clamp(lo));
            let (th, tl) = (_mm_cvttps_epi32(hi), _mm_cvttps_epi32(lo));
            // A true comparison is all ones, −1: added, it takes one away.
            let up = _mm_add_epi32(th, _mm_castps_si128(_mm_cmpgt_ps(_mm_cvtepi32_ps(th), hi)));
            let down = _mm_add_epi32(tl, _mm_castps_si128(_mm_cmpge_ps(_mm_cvtepi32_ps(tl), lo)));
            let pick = |v, never: i16| {
                _mm_or_si128(
                    _mm_and_si128(finite, v),
                    _mm_andnot_si128(finite, _mm_set1_epi32(never as i32)),
                )
            };
            (pick(up, NEVER_UP), pick(down, NEVER_DOWN))
        };
        let ((ux, dx), (uy, dy)) = (axis(0), axis(1));
        let mut out = Cells {
            up: [0; AXES],
            down: [0; AXES],
        };
        // SAFETY: `Cells` is 16-byte aligned, and each array 16 bytes.
        unsafe {
            _mm_store_si128(out.up.as_mut_ptr().cast(), _mm_packs_epi32(ux, uy));
            _mm_store_si128(out.down.as_mut_ptr().cast(), _mm_packs_epi32(dx, dy));
        }
        out
    }

    #[inline]
    #[target_feature(enable = "sse2")]
    pub fn ruled_out(l: &Lanes, [a, b, c]: [&Cells; 3]) -> u32 {
        // SAFETY: `Cells` and `Lanes::last` hold 16 bytes each; `Cells` is 16-byte aligned.
        let (up, down, last) = unsafe {
            let ld = |v: &[i16; AXES]| _mm_loadu_si128(v.as_ptr().cast());
            (
                _mm_max_epi16(_mm_max_epi16(ld(&a.up), ld(&b.up)), ld(&c.up)),
                _mm_min_epi16(_mm_min_epi16(ld(&a.down), ld(&b.down)), ld(&c.down)),
                ld(&l.last),
            )
        };
        let one = _mm_set1_epi16(1);
        let none = _mm_or_si128(
            _mm_or_si128(_mm_sub_epi16(_mm_sub_epi16(up, down), one), up),
            _mm_sub_epi16(_mm_sub_epi16(last, one), down),
        );
        // Each frame's column with its row, then the signs of the first four lanes.
        let frames = _mm_or_si128(none, _mm_srli_si128::<8>(none));
        let bytes = _mm_packs_epi16(frames, frames);
        (_mm_movemask_epi8(bytes) as u32) & ((1 << LANES) - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::camera::{Bounds, View};

    /// Points near and far, some on sample centres and edges, some not finite in f32.
    fn points() -> Vec<DVec3> {
        let mut next = crate::render::uniform(0x9e37_79b9_7f4a_7c15u64);
        let mut out: Vec<DVec3> = (0..20_000)
            .map(|k| {
                let reach = [1.0, 0.01, 3.0, 1e3][k % 4];
                DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * reach
            })
            .collect();
        out.extend([
            DVec3::NAN,
            DVec3::new(0.0, f64::INFINITY, 0.0),
            DVec3::new(1e39, 0.0, 0.0),
            DVec3::ZERO,
        ]);
        out
    }

    #[test]
    fn the_vector_lanes_give_the_plain_ones() {
        let pts = points();
        let bounds = Bounds::in_view(&pts[..4], View::Front);
        for (size, frames) in [(48, 4), (300, 3), (9000, 2)] {
            let cameras: Vec<Camera> = View::STANDARD[..frames]
                .iter()
                .map(|&v| Camera::framing(v, bounds, size, size))
                .collect();
            let lanes = Lanes::new(&cameras, pts[7]);
            let cells: Vec<Cells> = pts.iter().map(|&p| lanes.cells(p)).collect();
            for (c, &p) in cells.iter().zip(&pts) {
                assert_eq!(*c, lanes.cells_plain((p - lanes.origin).as_vec3()), "{p}");
            }
            let mut seen = [0usize; 2];
            for t in cells.windows(3) {
                let corners = [&t[0], &t[1], &t[2]];
                let ruled = lanes.ruled_out_plain(corners);
                // SAFETY: SSE2 is part of x86-64's baseline.
                #[cfg(target_arch = "x86_64")]
                assert_eq!(unsafe { sse2::ruled_out(&lanes, corners) }, ruled);
                seen[usize::from(ruled != 0)] += 1;
            }
            // Both answers occur.
            assert!(seen[0] > 0 && seen[1] > 0, "{seen:?}");
        }
    }
}
