//! The deviation field and its statistics ([`crate::metrics::deviation`]) computed over chunks
//! on the current rayon pool, in heap or scratch storage: a run's output against its input, and
//! `compare`'s two meshes. Each normal sum goes in triangle order and every other value is a
//! function of its vertex, the sums over chunks fold in chunk order ([`reduce`]), the percentiles
//! are counted exactly: the same bits for any thread count, storage and memory budget.

use glam::DVec3;
use rayon::prelude::*;

use super::reduce;
use crate::error::Result;
use crate::mesh::{Buf, Storage};
use crate::metrics::deviation::{
    self as kernel, DeviationStats, Histogram, PERCENTILES, Percentile, Points, Sums,
    ToleranceCheck,
};
use crate::metrics::surface::Surface;

/// What the field asks of a run: write it into the output, its colours too, a tolerance.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct DeviationSettings {
    /// Measure the field and its statistics (implied by the others).
    pub stats: bool,
    /// Write the deviation into the output's vertices (PLY `quality`).
    pub field: bool,
    /// Also its colour map (PLY `red green blue`, see [`kernel::colour`]) over
    /// [`DeviationSettings::colour_scale`].
    pub colours: bool,
    /// The largest distance a vertex may end from its input position without counting as beyond
    /// it ([`ToleranceCheck`]); `None`: no tolerance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
}

impl DeviationSettings {
    /// Whether the run measures the field at all (to write it or to check a tolerance).
    pub fn is_on(&self) -> bool {
        self.stats || self.field || self.tolerance.is_some()
    }

    /// Check the settings: a tolerance is a finite length > 0.
    pub fn check(&self) -> Result<()> {
        match self.tolerance {
            Some(t) if !(t > 0.0 && t.is_finite()) => Err(crate::Error::parameter(
                "tolerance",
                format!("must be a finite length > 0, got {t}"),
            )),
            _ => Ok(()),
        }
    }

    /// Whether nothing is asked (the settings' JSON leaves them out then).
    pub fn is_off(&self) -> bool {
        !self.is_on() && !self.colours
    }

    /// The deviation the colour map saturates at: the tolerance, else the largest absolute
    /// deviation of the field.
    pub fn colour_scale(&self, stats: &DeviationStats) -> f64 {
        self.tolerance
            .unwrap_or_else(|| stats.min.abs().max(stats.max.abs()))
    }
}

/// A deviation field: per vertex, the signed deviation and the distance.
pub struct Field {
    /// `"vertex"` or `"surface"` (see [`DeviationStats::measure`]).
    pub measure: &'static str,
    pub signed: Buf<f64>,
    pub distance: Buf<f64>,
}

/// The field of vertices that moved from `input` to `output` (alike indexed) over the input's
/// `triangles`, in `storage`; the output as `stored` stores it when given (a file run's output,
/// so that the field is the one `compare` measures on the files).
pub fn field(
    storage: &Storage,
    input: &[DVec3],
    output: &[DVec3],
    triangles: &[[u32; 3]],
    stored: Option<&crate::io::Stored>,
) -> Result<Field> {
    let at = |i: usize| match stored {
        Some(s) => s.round(output[i]),
        None => output[i],
    };
    let n = input.len();
    let signed = signed_into(storage, input, triangles, at, |d| d)?;
    let mut distance: Buf<f64> = storage.zeroed(n)?;
    reduce::for_chunks_mut(&mut distance, |first, out| {
        for (k, d) in out.iter_mut().enumerate() {
            *d = input[first + k].distance(at(first + k));
        }
    });
    Ok(Field {
        measure: "vertex",
        signed,
        distance,
    })
}

/// Ranges the normal sums are split into at most: each reads every triangle, so more ranges
/// would read the triangles more times over than they save (out of core, from the disk).
const NORMAL_RANGES: usize = 4;

/// The area-weighted normal sum of every vertex, in `storage`: a range of the vertices for each
/// thread (up to [`NORMAL_RANGES`]), each summing its own in triangle order (the bits of one
/// thread's sums, for any count). Each range reads every triangle, and takes the cross product
/// of those it touches.
fn normal_sums<P: Points + ?Sized>(
    storage: &Storage,
    positions: &P,
    triangles: &[[u32; 3]],
) -> Result<Buf<DVec3>> {
    let n = positions.count();
    let mut normals: Buf<DVec3> = storage.working(n)?;
    let ranges = rayon::current_num_threads().clamp(1, NORMAL_RANGES);
    let part = n.div_ceil(ranges).max(1);
    normals
        .par_chunks_mut(part)
        .enumerate()
        .for_each(|(k, sums)| {
            kernel::vertex_normal_sums_from(positions, triangles, k * part, sums)
        });
    Ok(normals)
}

/// A copy of positions kept to measure from later (a run's input, for its picture): in single
/// precision when every coordinate is a single exactly (those of a float PLY or an STL), which
/// halves the copy and the fresh memory it takes, else as they are. The same values either way.
pub enum Kept {
    Single(Buf<[f32; 3]>),
    Double(Buf<DVec3>),
}

impl Kept {
    /// A copy of `positions` in `storage`.
    pub fn of(storage: &Storage, positions: &[DVec3]) -> Result<Kept> {
        let mut single = storage.working::<[f32; 3]>(positions.len())?;
        let exact = reduce::map_fold_mut(
            &mut single,
            |first, chunk| {
                let mut exact = true;
                for (k, s) in chunk.iter_mut().enumerate() {
                    let p = positions[first + k];
                    *s = p.as_vec3().to_array();
                    exact &= s.map(f64::from) == p.to_array();
                }
                exact
            },
            true,
            |a, b| a && b,
        );
        if exact {
            return Ok(Kept::Single(single));
        }
        drop(single);
        let mut double = storage.working::<DVec3>(positions.len())?;
        reduce::for_chunks_mut(&mut double, |first, chunk| {
            chunk.copy_from_slice(&positions[first..first + chunk.len()])
        });
        Ok(Kept::Double(double))
    }

    /// [`signed`] from these positions: each form read as its plain slice, so that the sums'
    /// loop does not choose between them at every read.
    pub fn signed<T: crate::mesh::storage::Pod>(
        &self,
        storage: &Storage,
        output: &[DVec3],
        triangles: &[[u32; 3]],
        to: impl Fn(f64) -> T + Sync,
    ) -> Result<Buf<T>> {
        match self {
            Kept::Single(p) => signed(storage, &p[..], output, triangles, to),
            Kept::Double(p) => signed(storage, &p[..], output, triangles, to),
        }
    }
}

/// The signed part of [`field`] alone, without the output's rounding, each value as `T`: what a
/// picture colours.
pub fn signed<T: crate::mesh::storage::Pod, P: Points + ?Sized>(
    storage: &Storage,
    input: &P,
    output: &[DVec3],
    triangles: &[[u32; 3]],
    to: impl Fn(f64) -> T + Sync,
) -> Result<Buf<T>> {
    signed_into(storage, input, triangles, |i| output[i], to)
}

/// Each vertex's signed deviation from `input` to `at(i)` along `input`'s vertex normal over
/// `triangles`, as `to` makes it, in `storage`.
fn signed_into<T: crate::mesh::storage::Pod, P: Points + ?Sized>(
    storage: &Storage,
    input: &P,
    triangles: &[[u32; 3]],
    at: impl Fn(usize) -> DVec3 + Sync,
    to: impl Fn(f64) -> T + Sync,
) -> Result<Buf<T>> {
    let n = input.count();
    let mut signed: Buf<T> = storage.zeroed(n)?;
    // The chunks' lists are heap memory, outside a scratch run's budget.
    if !storage.is_mapped()
        && let Some(reaching) = Reaching::of(triangles, n, SUM_CHUNK_SHIFT)
    {
        signed_by_chunks(&mut signed, input, triangles, &reaching, &at, &to);
        return Ok(signed);
    }
    let normals = normal_sums(storage, input, triangles)?;
    reduce::for_chunks_mut(&mut signed, |first, out| {
        for (k, d) in out.iter_mut().enumerate() {
            let i = first + k;
            *d = to(kernel::signed(input.at(i), at(i), normals[i]));
        }
    });
    Ok(signed)
}

/// Vertices per chunk of [`signed_by_chunks`], 2^16: their normal sums (1.5 MiB) stay in the
/// cache.
const SUM_CHUNK_SHIFT: u32 = 16;

/// For triangles in the plan's order (each one's first corner its smallest, first corners
/// ascending) and vertices cut into chunks: the triangles of each chunk that begin in an earlier
/// one, ascending. A chunk's triangles are these, then those whose first corner it holds (a run
/// of the list): each of its sums can be taken in triangle order from them alone.
struct Reaching {
    /// A chunk is `1 << shift` vertices.
    shift: u32,
    into: Vec<Vec<u64>>,
}

impl Reaching {
    /// `None` when `triangles` are not in that order.
    fn of(triangles: &[[u32; 3]], n: usize, shift: u32) -> Option<Reaching> {
        struct Part {
            sorted: bool,
            firsts: (u32, u32),
            reach: Vec<(usize, u64)>,
        }
        const PART: usize = 1 << 20;
        let parts: Vec<Part> = triangles
            .par_chunks(PART)
            .enumerate()
            .map(|(p, part)| {
                let mut reach = Vec::new();
                let mut sorted = true;
                let mut last = part[0][0];
                for (k, &[a, b, c]) in part.iter().enumerate() {
                    sorted &= last <= a && a <= b && a <= c && (b.max(c) as usize) < n;
                    last = a;
                    let t = (p * PART + k) as u64;
                    let [ca, cb, cc] = [a, b, c].map(|v| (v >> shift) as usize);
                    if cb != ca {
                        reach.push((cb, t));
                    }
                    if cc != ca && cc != cb {
                        reach.push((cc, t));
                    }
                }
                Part {
                    sorted,
                    firsts: (part[0][0], last),
                    reach,
                }
            })
            .collect();
        let in_order = parts.iter().all(|p| p.sorted)
            && parts.windows(2).all(|w| w[0].firsts.1 <= w[1].firsts.0);
        if !in_order {
            return None;
        }
        let mut into = vec![Vec::new(); n.div_ceil(1 << shift)];
        for (c, t) in parts.into_iter().flat_map(|p| p.reach) {
            into[c].push(t);
        }
        Some(Reaching { shift, into })
    }
}

/// [`signed_into`]'s values into `signed`, chunk by chunk of `reaching`'s vertices, each
/// chunk's normal sums in a buffer of its own (no array of every vertex's sums): the same bits.
fn signed_by_chunks<T: Send, P: Points + ?Sized>(
    signed: &mut [T],
    input: &P,
    triangles: &[[u32; 3]],
    reaching: &Reaching,
    at: &(impl Fn(usize) -> DVec3 + Sync),
    to: &(impl Fn(f64) -> T + Sync),
) {
    let begin = |v: usize| triangles.partition_point(|t| (t[0] as usize) < v);
    signed
        .par_chunks_mut(1 << reaching.shift)
        .enumerate()
        .for_each_init(Vec::new, |sums, (c, out)| {
            let first = c << reaching.shift;
            sums.clear();
            sums.resize(out.len(), DVec3::ZERO);
            let own = begin(first)..begin(first + out.len());
            let reach = reaching.into[c].iter().map(|&t| t as usize);
            for t in reach.chain(own) {
                kernel::add_normal(input, triangles[t], first, sums);
            }
            for (k, d) in out.iter_mut().enumerate() {
                let i = first + k;
                *d = to(kernel::signed(input.at(i), at(i), sums[k]));
            }
        });
}

/// The field of the vertices of `a` (over its `a_triangles`) against the surface of `b`: each
/// vertex's distance to the nearest point of `b`'s triangles, signed by the side of that point
/// along `a`'s normal (positive outward; a vertex without a normal counts as outward).
pub fn surface_field(
    a: &[DVec3],
    a_triangles: &[[u32; 3]],
    b: &[DVec3],
    b_triangles: &[[u32; 3]],
) -> Result<Field> {
    let storage = Storage::heap();
    let n = a.len();
    let normals = normal_sums(&storage, a, a_triangles)?;
    let surface = Surface::new(b, b_triangles);
    let mut signed: Buf<f64> = storage.zeroed(n)?;
    reduce::for_chunks_mut(&mut signed, |first, out| {
        for (k, d) in out.iter_mut().enumerate() {
            let i = first + k;
            *d = match surface.nearest(a[i]) {
                Some(near) if kernel::signed(a[i], near.point, normals[i]) < 0.0 => -near.distance,
                Some(near) => near.distance,
                None => f64::INFINITY,
            };
        }
    });
    let mut distance: Buf<f64> = storage.zeroed(n)?;
    reduce::for_chunks_mut(&mut distance, |first, out| {
        for (k, d) in out.iter_mut().enumerate() {
            *d = signed[first + k].abs();
        }
    });
    Ok(Field {
        measure: "surface",
        signed,
        distance,
    })
}

/// The statistics of `field`, with the count beyond `tolerance` when given.
pub fn statistics(field: &Field, tolerance: Option<f64>) -> DeviationStats {
    let (signed, distance) = (&field.signed[..], &field.distance[..]);
    let sums = reduce::map_fold(
        signed,
        |first, c| Sums::of(first, c, &distance[first..first + c.len()]),
        Sums::default(),
        Sums::then,
    );
    let values = reduce::ranked(distance, |n| {
        PERCENTILES
            .iter()
            .map(|&p| kernel::percentile_rank(p, n))
            .collect()
    });
    let percentiles = PERCENTILES
        .iter()
        .zip(values)
        .map(|(&percent, distance)| Percentile { percent, distance })
        .collect();
    let empty = Histogram::new(sums.extent());
    let histogram = reduce::map_fold(
        signed,
        |_, c| {
            let mut h = empty.clone();
            h.add(c);
            h
        },
        empty.clone(),
        |mut a, b| {
            a.counts.iter_mut().zip(b.counts).for_each(|(x, y)| *x += y);
            a
        },
    );
    let tolerance = tolerance.map(|limit| {
        let beyond = reduce::map_fold(
            distance,
            |_, c| c.iter().filter(|&&r| r > limit).count() as u64,
            0,
            |a, b| a + b,
        );
        ToleranceCheck {
            limit,
            beyond,
            within: beyond == 0,
        }
    });
    sums.stats(field.measure, percentiles, histogram, tolerance)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{add_normal_noise, icosphere};

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// A noisy sphere and a moved copy, its triangles in the plan's order (each one's smallest
    /// corner first, first corners ascending).
    fn in_plan_order() -> (Vec<DVec3>, Vec<DVec3>, Vec<[u32; 3]>) {
        let mut s = icosphere(3);
        add_normal_noise(&mut s, 0.05, 7);
        let mut triangles: Vec<[u32; 3]> = s
            .triangles
            .iter()
            .map(|t| {
                let k = (0..3).min_by_key(|&k| t[k]).unwrap();
                [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
            })
            .collect();
        triangles.sort_by_key(|t| t[0]);
        let moved = s.positions.iter().map(|p| *p * 1.1 + 0.01).collect();
        (s.positions.to_vec(), moved, triangles)
    }

    #[test]
    fn the_chunked_sums_give_the_bits_of_one_pass() {
        let (input, output, triangles) = in_plan_order();
        let expected = kernel::signed_deviations(&input, &output, &triangles);
        let whole = input.len().next_power_of_two().trailing_zeros();
        for shift in [0, 3, 7, whole, whole + 1] {
            let reaching = Reaching::of(&triangles, input.len(), shift).expect("in plan order");
            let mut got = vec![0.0; input.len()];
            signed_by_chunks(
                &mut got,
                &input[..],
                &triangles,
                &reaching,
                &|i| output[i],
                &|d| d,
            );
            assert_eq!(bits(&got), bits(&expected), "chunks of 2^{shift}");
        }
        // And through the public path, for any thread count.
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let got = pool
                .install(|| signed(&Storage::heap(), &input[..], &output, &triangles, |d| d))
                .unwrap();
            assert_eq!(bits(&got), bits(&expected), "{threads} threads");
        }
    }

    #[test]
    fn triangles_out_of_the_plans_order_are_summed_in_ranges() {
        let (input, output, mut triangles) = in_plan_order();
        let n = input.len();
        assert!(Reaching::of(&triangles, n, 6).is_some());
        let mut swapped = triangles.clone();
        let last = swapped.len() - 1;
        swapped.swap(0, last);
        assert!(
            Reaching::of(&swapped, n, 6).is_none(),
            "first corners descending"
        );
        triangles[5].rotate_left(1);
        assert!(
            Reaching::of(&triangles, n, 6).is_none(),
            "first corner not the smallest"
        );
        let expected = kernel::signed_deviations(&input, &output, &triangles);
        let got = signed(&Storage::heap(), &input[..], &output, &triangles, |d| d).unwrap();
        assert_eq!(bits(&got), bits(&expected));
    }

    #[test]
    fn kept_positions_are_the_same_values_in_half_the_memory_when_singles() {
        let (input, output, triangles) = in_plan_order();
        let singles: Vec<DVec3> = input.iter().map(|p| p.as_vec3().as_dvec3()).collect();
        let storage = Storage::heap();
        let kept = Kept::of(&storage, &singles).unwrap();
        assert!(matches!(kept, Kept::Single(_)));
        let kept_double = Kept::of(&storage, &input).unwrap();
        assert!(matches!(kept_double, Kept::Double(_)));
        // The values a kept copy holds, read through its form's `Points`.
        let values = |kept: &Kept| -> Vec<DVec3> {
            match kept {
                Kept::Single(p) => (0..p.len()).map(|i| p[..].at(i)).collect(),
                Kept::Double(p) => (0..p.len()).map(|i| p[..].at(i)).collect(),
            }
        };
        for (kept, from) in [(&kept, &singles), (&kept_double, &input)] {
            let held = values(kept);
            assert_eq!(held.len(), from.len());
            for (h, p) in held.iter().zip(from) {
                assert_eq!(
                    h.to_array().map(f64::to_bits),
                    p.to_array().map(f64::to_bits)
                );
            }
            let expected = kernel::signed_deviations(from, &output, &triangles);
            let got = kept.signed(&storage, &output, &triangles, |d| d).unwrap();
            assert_eq!(bits(&got), bits(&expected));
        }
        // A coordinate beyond a single's precision, a NaN: kept as they are.
        for odd in [1.0 + f64::EPSILON, f64::NAN, 1e-310] {
            let mut p = singles.clone();
            p[3].y = odd;
            let kept = Kept::of(&storage, &p).unwrap();
            assert!(matches!(kept, Kept::Double(_)), "{odd}");
            assert_eq!(values(&kept)[3].y.to_bits(), odd.to_bits());
        }
    }
}
