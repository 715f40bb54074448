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
    self as kernel, DeviationStats, Histogram, PERCENTILES, Percentile, Sums, ToleranceCheck,
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
fn normal_sums(
    storage: &Storage,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
) -> Result<Buf<DVec3>> {
    let mut normals: Buf<DVec3> = storage.working(positions.len())?;
    let ranges = rayon::current_num_threads().clamp(1, NORMAL_RANGES);
    let part = positions.len().div_ceil(ranges).max(1);
    normals
        .par_chunks_mut(part)
        .enumerate()
        .for_each(|(k, sums)| {
            kernel::vertex_normal_sums_from(positions, triangles, k * part, sums)
        });
    Ok(normals)
}

/// The signed part of [`field`] alone, without the output's rounding, each value as `T`: what a
/// picture colours.
pub fn signed<T: crate::mesh::storage::Pod>(
    storage: &Storage,
    input: &[DVec3],
    output: &[DVec3],
    triangles: &[[u32; 3]],
    to: impl Fn(f64) -> T + Sync,
) -> Result<Buf<T>> {
    signed_into(storage, input, triangles, |i| output[i], to)
}

/// Each vertex's signed deviation from `input` to `at(i)` along `input`'s vertex normal over
/// `triangles`, as `to` makes it, in `storage`.
fn signed_into<T: crate::mesh::storage::Pod>(
    storage: &Storage,
    input: &[DVec3],
    triangles: &[[u32; 3]],
    at: impl Fn(usize) -> DVec3 + Sync,
    to: impl Fn(f64) -> T + Sync,
) -> Result<Buf<T>> {
    let n = input.len();
    let normals = normal_sums(storage, input, triangles)?;
    let mut signed: Buf<T> = storage.zeroed(n)?;
    reduce::for_chunks_mut(&mut signed, |first, out| {
        for (k, d) in out.iter_mut().enumerate() {
            let i = first + k;
            *d = to(kernel::signed(input[i], at(i), normals[i]));
        }
    });
    Ok(signed)
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
