//! Deterministic parallel work over arrays: fixed-size chunks of [`CHUNK`] items, mapped on the
//! current rayon pool, their results combined in chunk order. The chunking, not the thread count,
//! decides every rounding, so each result is bit-identical for any number of threads. Every
//! parallel sum of the engine (its statistics included), the multiresolution mode and the cluster
//! engine goes through here.

use glam::DVec3;
use rayon::prelude::*;

use crate::meter::Meter;
use crate::metrics;
use crate::smooth::laplacian::StepStats;
use crate::topology::Topology;

/// Items per work unit.
pub const CHUNK: usize = 1 << 14;

/// `f(first, chunk)` on each chunk of `items` (`first`: the index of the chunk's first item).
pub fn for_chunks_mut<T: Send>(items: &mut [T], f: impl Fn(usize, &mut [T]) + Sync) {
    items
        .par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, chunk)| f(c * CHUNK, chunk));
}

/// `map(first, chunk)` on each chunk of `items`, folded in chunk order from `init`.
pub fn map_fold<T: Sync, R: Send>(
    items: &[T],
    map: impl Fn(usize, &[T]) -> R + Sync,
    init: R,
    fold: impl Fn(R, R) -> R,
) -> R {
    let parts: Vec<R> = items
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| map(c * CHUNK, chunk))
        .collect();
    parts.into_iter().fold(init, fold)
}

/// `map(first, chunk)` on each chunk of `out`, writing it, and the results folded in chunk order.
pub fn map_fold_mut<T: Send, R: Send>(
    out: &mut [T],
    map: impl Fn(usize, &mut [T]) -> R + Sync,
    init: R,
    fold: impl Fn(R, R) -> R,
) -> R {
    let parts: Vec<R> = out
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, chunk)| map(c * CHUNK, chunk))
        .collect();
    parts.into_iter().fold(init, fold)
}

/// Signed volume about `origin` and area of `tris` ([`metrics::volume_about`], [`metrics::area`]).
pub fn volume_area(pos: &[DVec3], tris: &[[u32; 3]], origin: DVec3) -> (f64, f64) {
    let (v, a) = map_fold(
        tris,
        |_, chunk| metrics::determinant_and_area_sums(pos, chunk, origin),
        (-0.0, -0.0),
        |(v, a), (pv, pa)| (v + pv, a + pa),
    );
    (v / 6.0, a / 2.0)
}

/// [`metrics::geometry`] over chunks of vertices ([`metrics::vertex_sums`]): the centroid, then
/// every other figure in one pass, about it.
pub fn geometry(pos: &[DVec3], tris: &[[u32; 3]], topo: &Topology) -> metrics::Geometry {
    geometry_about(pos, tris, topo, centroid(pos), &Meter::default())
}

/// [`geometry`] with the volume about `origin` (an output's about its input's centroid), the
/// vertices counted into `meter` as they are measured.
pub fn geometry_about(
    pos: &[DVec3],
    tris: &[[u32; 3]],
    topo: &Topology,
    origin: DVec3,
    meter: &Meter,
) -> metrics::Geometry {
    geometry_about_as(pos, pos, tris, topo, origin, meter)
}

/// [`geometry_about`] of the positions `pos` as `read` reads them (`read` views `pos`).
pub fn geometry_about_as<P: metrics::Positions + ?Sized>(
    pos: &[DVec3],
    read: &P,
    tris: &[[u32; 3]],
    topo: &Topology,
    origin: DVec3,
    meter: &Meter,
) -> metrics::Geometry {
    map_fold(
        pos,
        |first, chunk| {
            let vertices = first as u32..(first + chunk.len()) as u32;
            let sums = metrics::vertex_sums(read, tris, topo, vertices, origin);
            meter.add(chunk.len() as u64);
            sums
        },
        metrics::VertexSums::default(),
        |a, b| a + b,
    )
    .geometry(origin)
}

/// Signed volume about `origin` ([`metrics::volume_about`]).
pub fn volume(pos: &[DVec3], tris: &[[u32; 3]], origin: DVec3) -> f64 {
    map_fold(
        tris,
        |_, chunk| metrics::determinant_sum(pos, chunk, origin),
        -0.0,
        |s, x| s + x,
    ) / 6.0
}

/// Mean position (zero for none), [`metrics::centroid`] summed over chunks.
pub fn centroid(pos: &[DVec3]) -> DVec3 {
    if pos.is_empty() {
        return DVec3::ZERO;
    }
    position_sum(pos) / pos.len() as f64
}

/// Sum of the positions (ranks add theirs before dividing by the count).
pub fn position_sum(pos: &[DVec3]) -> DVec3 {
    map_fold(
        pos,
        |_, chunk| metrics::position_sum(chunk),
        DVec3::ZERO,
        |s, p| s + p,
    )
}

/// Largest and summed distance between `a` and `b`, vertex by vertex.
pub fn displacement(a: &[DVec3], b: &[DVec3]) -> StepStats {
    moves(a, |k, p| p.distance(b[k]))
}

/// Largest and summed `distance(k, item)` over `items`, in fixed chunks folded in their order
/// (the same for any thread count): how far each of a set of vertices moved.
pub fn moves<T: Sync>(items: &[T], distance: impl Fn(usize, &T) -> f64 + Sync) -> StepStats {
    let (max, sum) = map_fold(
        items,
        |first, chunk| {
            let mut k = first;
            chunk.iter().fold((0.0f64, 0.0), |(m, s), item| {
                let d = distance(k, item);
                k += 1;
                (m.max(d), s + d)
            })
        },
        (0.0f64, 0.0),
        |(m, s), (pm, ps)| (m.max(pm), s + ps),
    );
    StepStats {
        moved: 0,
        max_displacement: max,
        sum_displacement: sum,
    }
}

/// The median of the values that are not NaN: the element of rank `count / 2` in ascending
/// order (the upper median of an even count), 0 when there are none.
///
/// Found by counting, not by sorting: eight passes, each counting the values that share the
/// digits found so far by their next byte (of the order-preserving bit pattern of the value)
/// over chunks, so the result is exact and the same for any thread count, and no copy of the
/// values is made (they may be a memory-mapped scratch array).
pub fn median(values: &[f64]) -> f64 {
    median_over(values, None, |counts| counts)
}

/// [`median`] of the values of several processes, each calling it with its own `values`:
/// `total` turns this process's counts into the sums over all of them (integer sums, so the
/// result is exact and the same for any split of the values). The counting runs on `pool` (the
/// current one when `None`), `total` on the calling thread (where a cluster rank keeps its
/// communicator).
pub fn median_over(
    values: &[f64],
    pool: Option<&rayon::ThreadPool>,
    total: impl FnMut(Vec<u64>) -> Vec<u64>,
) -> f64 {
    ranked_over(values, pool, total, |count| vec![count / 2])
        .first()
        .copied()
        .unwrap_or(0.0)
}

/// The values of the ranks `ranks(count)` (0-based, ascending order, each below `count`) among
/// the values that are not NaN, `count` of them; none when there are none. Counted as
/// [`median`] counts, every rank in the same eight passes.
pub fn ranked(values: &[f64], ranks: impl Fn(u64) -> Vec<u64>) -> Vec<f64> {
    ranked_over(values, None, |counts| counts, ranks)
}

/// [`ranked`] over processes and on a pool, as [`median_over`].
pub fn ranked_over(
    values: &[f64],
    pool: Option<&rayon::ThreadPool>,
    mut total: impl FnMut(Vec<u64>) -> Vec<u64>,
    ranks: impl Fn(u64) -> Vec<u64>,
) -> Vec<f64> {
    let on = |f: &(dyn Fn() -> Vec<u64> + Sync)| match pool {
        Some(p) => p.install(f),
        None => f(),
    };
    // Ascending values map to ascending keys (negative numbers have their bits inverted).
    let key = |x: f64| {
        let b = x.to_bits();
        if b >> 63 == 1 { !b } else { b | 1 << 63 }
    };
    let local = on(&|| {
        vec![map_fold(
            values,
            |_, c| c.iter().filter(|x| !x.is_nan()).count() as u64,
            0,
            |a, b| a + b,
        )]
    });
    let count = total(local)[0];
    if count == 0 {
        return Vec::new();
    }
    let mut rank = ranks(count);
    let mut prefix = vec![0u64; rank.len()];
    for shift in (0..64).step_by(8).rev() {
        // The keys that agree with a prefix above bit `shift + 8`, counted by their byte at
        // `shift`: 256 bins per rank.
        let high = |k: u64| k.checked_shr(shift + 8).unwrap_or(0);
        let highs: Vec<u64> = prefix.iter().map(|&p| high(p)).collect();
        let bins = on(&|| {
            map_fold(
                values,
                |_, c| {
                    let mut bins = vec![0u64; 256 * highs.len()];
                    for k in c.iter().filter(|x| !x.is_nan()).map(|&x| key(x)) {
                        let (h, byte) = (high(k), ((k >> shift) & 0xff) as usize);
                        for (r, &want) in highs.iter().enumerate() {
                            if h == want {
                                bins[256 * r + byte] += 1;
                            }
                        }
                    }
                    bins
                },
                vec![0u64; 256 * highs.len()],
                |mut a, b| {
                    a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                    a
                },
            )
        });
        let bins = total(bins);
        for (r, (rank, prefix)) in rank.iter_mut().zip(&mut prefix).enumerate() {
            let bins = &bins[256 * r..256 * (r + 1)];
            let mut byte = 0;
            while *rank >= bins[byte] {
                *rank -= bins[byte];
                byte += 1;
            }
            *prefix |= (byte as u64) << shift;
        }
    }
    prefix
        .into_iter()
        .map(|p| {
            let bits = if p >> 63 == 1 { p & !(1 << 63) } else { !p };
            f64::from_bits(bits)
        })
        .collect()
}

/// Fractional bits of [`Fixed`].
const FRACTION_BITS: i32 = 40;
/// The largest term a [`Fixed`] sum takes (larger ones count as this): 2⁴⁸, so that 2³⁴ terms
/// (far more vertices than a mesh indexed by u32 has) cannot overflow 128 bits.
const FIXED_TERM_MAX: f64 = (1u64 << 48) as f64;

/// A sum of non-negative terms in fixed point (40 fractional bits, each term truncated to that
/// grid and capped at 2⁴⁸). Integer additions are associative, so the sum has the same bits for
/// any split of its terms, over threads, chunks or processes alike; the automatic stop's sums use
/// it so that a run stops at the same iteration on any number of cluster ranks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Fixed(pub u128);

impl std::ops::Add for Fixed {
    type Output = Fixed;
    fn add(self, other: Fixed) -> Fixed {
        Fixed(self.0 + other.0)
    }
}

impl Fixed {
    /// The term `x` (NaN and negative values count as 0).
    pub fn of(x: f64) -> Fixed {
        let x = if x > 0.0 { x.min(FIXED_TERM_MAX) } else { 0.0 };
        // Exact: a power-of-two scale, then truncation toward zero.
        Fixed((x * 2f64.powi(FRACTION_BITS)) as u128)
    }

    /// The nearest f64.
    pub fn value(self) -> f64 {
        self.0 as f64 * 2f64.powi(-FRACTION_BITS)
    }

    /// As four 32-bit limbs, so that ranks can add them as u64s without overflow (up to 2³²
    /// ranks), then [`Fixed::from_limbs`].
    pub fn limbs(self) -> [u64; 4] {
        [0, 1, 2, 3].map(|k| ((self.0 >> (32 * k)) & 0xffff_ffff) as u64)
    }

    pub fn from_limbs(limbs: &[u64]) -> Fixed {
        Fixed(
            limbs
                .iter()
                .enumerate()
                .fold(0u128, |s, (k, &l)| s.wrapping_add((l as u128) << (32 * k))),
        )
    }
}

/// `Σ term(i, item)` over `items` (`i`: the item's index in `items`) as a [`Fixed`] sum.
pub fn fixed_sum<T: Sync>(items: &[T], term: impl Fn(usize, &T) -> f64 + Sync) -> Fixed {
    map_fold(
        items,
        |first, c| {
            c.iter().enumerate().fold(Fixed::default(), |s, (k, x)| {
                s + Fixed::of(term(first + k, x))
            })
        },
        Fixed::default(),
        |a, b| a + b,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_counts_as_a_sort_would_select() {
        let mut next = crate::shapes::uniform(7);
        // More than one chunk, negative and positive values, ties, NaNs skipped.
        let mut values: Vec<f64> = (0..3 * CHUNK + 5).map(|_| next() * 4.0 - 3.0).collect();
        values.extend([0.25; 9]);
        values.extend([-0.0, 0.0, f64::NAN, f64::NAN]);
        let mut sorted: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
        sorted.sort_by(f64::total_cmp);
        let want = sorted[sorted.len() / 2];
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            assert_eq!(pool.install(|| median(&values)).to_bits(), want.to_bits());
        }
        assert_eq!(median(&[3.0, -1.0, 2.0, 5.0]), 3.0);
        assert_eq!(median(&[-2.5]), -2.5);
        assert_eq!(median(&[f64::NAN]), 0.0);
        assert_eq!(median(&[]), 0.0);

        // Split over two "processes" that add their counts: the same element.
        let (a, b) = values.split_at(CHUNK + 77);
        let barrier = std::sync::Barrier::new(2);
        let slots = std::sync::Mutex::new([Vec::new(), Vec::new()]);
        let run = |me: usize, part: &[f64]| {
            median_over(part, None, |mine| {
                slots.lock().unwrap()[me] = mine;
                barrier.wait();
                let both = slots.lock().unwrap().clone();
                barrier.wait();
                both[0].iter().zip(&both[1]).map(|(x, y)| x + y).collect()
            })
        };
        let (x, y) = std::thread::scope(|s| {
            let h = s.spawn(|| run(1, b));
            (run(0, a), h.join().unwrap())
        });
        assert_eq!((x.to_bits(), y.to_bits()), (want.to_bits(), want.to_bits()));
    }

    #[test]
    fn fixed_sums_are_the_same_for_any_split() {
        let terms: Vec<f64> = (0..3 * CHUNK + 11)
            .map(|i| (i as f64 * 0.37).sin().powi(2) * 1e3 / (1.0 + i as f64))
            .collect();
        let whole = fixed_sum(&terms, |_, &x| x);
        let (a, b) = terms.split_at(CHUNK / 3 + 5);
        assert_eq!(whole, fixed_sum(a, |_, &x| x) + fixed_sum(b, |_, &x| x));
        let plain: f64 = terms.iter().sum();
        assert!((whole.value() - plain).abs() <= 1e-9 * plain);
        let twice: Vec<u64> = whole.limbs().iter().map(|l| 2 * l).collect();
        assert_eq!(Fixed::from_limbs(&twice), whole + whole);
        assert_eq!(Fixed::of(f64::NAN), Fixed::default());
        assert_eq!(Fixed::of(-1.0), Fixed::default());
        assert_eq!(Fixed::of(f64::INFINITY), Fixed::of(FIXED_TERM_MAX));
    }
}
