//! The automatic stop ([`Options::auto_stop`], `--iterations auto`): the iteration loop ends when
//! what an iteration removes is no longer noise. Defined and measured in docs/quality-research.md
//! §5; the per-vertex operators are [`crate::smooth::noise`]. All from the input alone:
//!
//! - **Noise level** `σ̂` over the movable vertices, from `g`, the second difference of the
//!   normal component of the umbrella Laplacian of the input (its smooth curvature cancels, the
//!   noise does not), and `g^ε`, the same operators on a white-noise sample ε (seed [`SEED`]) on
//!   the same connectivity, which calibrates the operators' gain. Two measures of the spread of
//!   each: the median absolute deviation (MAD), which ignores features (a minority of vertices),
//!   and the root mean square of the deviations from the median that are within [`CLIP`] MADs,
//!   which leaves out the features too but keeps the spikes of impulsive noise, which hits part
//!   of the vertices hard and which the MAD does not see (on the impulsive pair of
//!   docs/quality-research.md §15 the MAD puts σ̂ at 0.72× the true noise). `σ̂_m = MAD(g) /
//!   MAD(g^ε)`, `σ̂_e = RMS(g) / RMS(g^ε)`; on Gaussian noise the two agree within 2 %, so
//!   `σ̂ = max(σ̂_m, σ̂_e / `[`HEAVY_TAILS`]`)`: the median's estimate unless the noise is
//!   heavy-tailed.
//! - **Removed**, after iteration k: `O_k = mean ((P^k − P⁰) · n⁰)² / σ̂²`, the energy the
//!   iterations took away along the input normals, in units of the noise.
//! - **Expected** (`laplacian`, `taubin`, `vcs-lowpass`): `E_k = Σ (e^k − ε)² / Σ ε²`, where `e^k`
//!   is ε after k iterations of the method's scalar analogue (one λ step; a λ|μ pair): what the
//!   filter would remove from pure noise.
//! - **Along the edges** (`laplacian`, which shrinks: [`StopRule::ShrinkingFilter`]): both
//!   energies are taken on the differences of the displacement across the edges instead,
//!   `O_k = Σ_v Σ_{u∈N(v)} (d_u − d_v)² / (σ̂² Σ_v Σ_{u∈N(v)} (ε_u − ε_v)²)` with
//!   `d = (P^k − P⁰) · n⁰`, and `E_k` the same of `e^k − ε`. Every iteration of `laplacian` also
//!   moves a curved surface inwards by about λ times its curvature, nearly the same over a
//!   vertex's neighbours: along the normals that shrink grows with the square of the
//!   iterations and stopped the run after 2–4 of them on the denoising pairs, while it hardly
//!   tilts a normal (docs/quality-research.md §17).
//! - **Rule** with `R_k = (O_k − O_{k−1}) / (E_k − E_{k−1})`: stop after iteration k when
//!   `k ≥ 2` and `R_k >` [`DETAIL_RATIO`] (more than 2/7 of what the iteration removed is not
//!   explained by noise: it is removing shape), or when `E_k − E_{k−1} <` [`NOISE_GONE`] (a
//!   further iteration would remove less than 1 % of the noise: what the filter can remove is
//!   gone). The other methods (the stencil methods `lem`, `vcs`, `vcs-triangle`; `hc`;
//!   `vcs-guided`) have no scalar analogue (a scalar stencil minimiser removes most white noise
//!   at once, then stalls); they stop when the iteration's mean displacement falls below a
//!   share of σ̂, or when `O_k` exceeds a multiple of the noise energy along the normals, so
//!   that the rest was shape: the method's [`Settle`] thresholds (for the stencil methods, on
//!   noisy scans they settle first, at `O_k` ≤ 1.34; on a clean one this ends the run after an
//!   iteration or two).
//! - Always at [`Options::iterations`] at the latest (the cap), and before the first iteration
//!   when σ̂ is 0 (nothing movable, or no measurable noise).
//!
//! Every process (a cluster rank, or the one process that owns everything) measures its owned
//! vertices and exchanges the fields' halos through its [`Share`]. The medians count (exact), the
//! sums are fixed-point integers ([`Fixed`]), so they have the same bits for any split over
//! threads, chunks and ranks; the white noise is a function of the vertex (recomputed, not
//! stored). So the stop iteration is the same for any thread count, storage and number of ranks.
//! Memory: four arrays of the plan's size in its storage (normals, their offsets,
//! the scalar field and its second buffer), [`super::memory::AUTO_BYTES_PER_TRIANGLE`].
//!
//! [`Settle`]: crate::smooth::method::Settle

use glam::DVec3;

pub use super::observer::{AutoStopStats, StopReason};
use super::reduce::{self, Fixed};
use super::share::{Share, on_pool};
use crate::error::Result;
use crate::mesh::{Buf, Storage};
use crate::smooth::method::StopRule;
use crate::smooth::{Options, noise};
use crate::topology::Topology;

/// Seed of the white-noise sample ε.
pub const SEED: u64 = 1;
/// Deviations from the median beyond this many MADs are features, left out of the RMS. 8 MADs is
/// 5.4 standard deviations of Gaussian noise: no noise sample is left out.
pub const CLIP: f64 = 8.0;
/// The RMS estimate is taken (divided by this) when it exceeds the median's by more than this
/// factor: on the 20 noisy meshes of docs/quality-research.md §15 with Gaussian noise the ratio is
/// 0.988–1.018, so their σ̂ is the median's; on the impulsive pair it is 1.31.
pub const HEAVY_TAILS: f64 = 1.05;
/// Largest ratio of removed to expected energy that still counts as removing noise. 7/5 is the
/// centre of the thresholds that stop every noisy scan of the research inside the iterations
/// where the result beats the quality target (demosthenes σ 0.2 needs [1.19, 1.49), armadillo
/// σ 0.2 [1.34, 1.45), the others anything above 1.25); 4/3, the round value first tried, sits on
/// armadillo's edge, where the noise sample decides (docs/quality-research.md §5, §10).
pub const DETAIL_RATIO: f64 = 7.0 / 5.0;
/// Smallest share of the noise energy an iteration of the filter must still remove.
pub const NOISE_GONE: f64 = 0.01;
/// The cap of `--iterations auto` (the command line's; the library's is
/// [`Options::iterations`]). The rule stops `taubin` and `vcs-lowpass` after at most 14
/// iterations on the scans measured (the noise-removed test depends only on λ, μ and the
/// connectivity), so the cap only bounds the unusual.
pub const DEFAULT_CAP: usize = 100;

/// The state of the automatic stop over one run (see the module doc).
#[derive(Debug)]
pub struct AutoStop {
    /// `n⁰`, unit, zero on fixed vertices.
    normals: Buf<DVec3>,
    /// `(P⁰ − origin) · n⁰`.
    base: Buf<f64>,
    /// The scalar field `e^k` (after the start), and the second buffer of its steps.
    field: Buf<f64>,
    spare: Buf<f64>,
    origin: DVec3,
    movable: f64,
    noise_energy: f64,
    /// The noise sample's energy along the edges ([`edge_energy`]), for a
    /// [`StopRule::ShrinkingFilter`] (0 for the others).
    edge_noise: f64,
    sigma: f64,
    /// `σ̂_m` and `σ̂_e` (module doc).
    estimates: (f64, f64),
    /// The method's rule: the step factors of its scalar analogue, or its settle thresholds.
    rule: StopRule,
    removed: Vec<f64>,
    expected: Vec<f64>,
    started: bool,
    stopped_by: Option<StopReason>,
    cap: usize,
}

impl AutoStop {
    /// The arrays of a mesh of `vertices` vertices in `storage`, for `opts` (method, cap).
    pub fn new(storage: &Storage, vertices: usize, opts: &Options) -> Result<AutoStop> {
        Ok(Self::with_arrays(
            [storage.zeroed(vertices)?],
            [
                storage.zeroed(vertices)?,
                storage.zeroed(vertices)?,
                storage.zeroed(vertices)?,
            ],
            opts,
        ))
    }

    /// The same with arrays of which only the touched pages cost memory (a cluster rank's, which
    /// touches its region only).
    pub fn sparse(vertices: usize, opts: &Options) -> Result<AutoStop> {
        Ok(Self::with_arrays(
            [Buf::sparse(vertices)?],
            [
                Buf::sparse(vertices)?,
                Buf::sparse(vertices)?,
                Buf::sparse(vertices)?,
            ],
            opts,
        ))
    }

    fn with_arrays(
        [normals]: [Buf<DVec3>; 1],
        [base, field, spare]: [Buf<f64>; 3],
        opts: &Options,
    ) -> AutoStop {
        let rule = opts.method.unit().stop_rule(opts);
        AutoStop {
            normals,
            base,
            field,
            spare,
            origin: DVec3::ZERO,
            movable: 0.0,
            noise_energy: 0.0,
            edge_noise: 0.0,
            sigma: 0.0,
            estimates: (0.0, 0.0),
            rule,
            removed: Vec::new(),
            expected: Vec::new(),
            started: false,
            stopped_by: None,
            cap: opts.iterations,
        }
    }

    /// Measure the input `pos` (σ̂, normals, the noise sample) over the vertices `share` owns,
    /// on its threads; `origin` is a point near the mesh (the offsets are taken from it), the
    /// same in every process. `Some` when no iteration is to run: σ̂ is 0, or the cap is.
    pub fn start(
        &mut self,
        topo: &Topology,
        tris: &[[u32; 3]],
        pos: &[DVec3],
        origin: DVec3,
        share: &mut dyn Share,
    ) -> Option<StopReason> {
        let owned = share.owned();
        let first = owned.start;
        let normals = &mut self.normals;
        on_pool(share, || {
            reduce::for_chunks_mut(&mut normals[owned.clone()], |at, out| {
                noise::unit_normals_into(topo, tris, pos, out, first + at)
            })
        });
        share.step_end(normals);
        let normals: &[DVec3] = normals;
        let spare = &mut self.spare;
        on_pool(share, || {
            reduce::for_chunks_mut(&mut spare[owned.clone()], |at, out| {
                noise::normal_laplacian_into(topo, pos, normals, out, first + at)
            })
        });
        share.step_end_scalar(spare);
        let input = spread_of_second_difference(topo, spare, &mut self.field, share);
        white_noise(topo, &mut self.field, share);
        let (eps, spare) = (&self.field, &mut self.spare);
        on_pool(share, || {
            reduce::for_chunks_mut(&mut spare[owned.clone()], |at, out| {
                noise::scalar_laplacian_into(topo, eps, out, first + at)
            })
        });
        share.step_end_scalar(spare);
        let calibration = spread_of_second_difference(topo, spare, &mut self.field, share);
        self.estimates = if calibration.0 > 0.0 && calibration.1 > 0.0 {
            (input.0 / calibration.0, input.1 / calibration.1)
        } else {
            (0.0, 0.0)
        };
        self.sigma = self.estimates.0.max(self.estimates.1 / HEAVY_TAILS);
        white_noise(topo, &mut self.field, share);
        let eps = &self.field[owned.clone()];
        let energy = on_pool(share, || reduce::fixed_sum(eps, |_, e| e * e));
        self.noise_energy = total(share, energy);
        if let StopRule::ShrinkingFilter(_) = self.rule {
            let eps: &[f64] = &self.field;
            self.edge_noise = edge_energy(topo, share, |v| eps[v]);
        }
        let base = &mut self.base;
        on_pool(share, || {
            reduce::for_chunks_mut(&mut base[owned.clone()], |at, out| {
                for (k, b) in out.iter_mut().enumerate() {
                    let v = first + at + k;
                    *b = (pos[v] - origin).dot(normals[v]);
                }
            })
        });
        self.origin = origin;
        let fixed = &topo.fixed_mask()[owned.clone()];
        let movable = on_pool(share, || {
            reduce::map_fold(
                fixed,
                |_, c| c.iter().filter(|&&f| f == 0).count() as u64,
                0,
                |a, b| a + b,
            )
        });
        self.movable = share.sum_counts(vec![movable])[0] as f64;
        self.started = true;
        self.stopped_by = if self.sigma == 0.0 || !self.sigma.is_finite() {
            Some(StopReason::NoNoise)
        } else if self.cap == 0 {
            Some(StopReason::Cap)
        } else {
            None
        };
        self.stopped_by
    }

    /// Whether [`AutoStop::start`] has measured the input.
    pub fn started(&self) -> bool {
        self.started
    }

    /// σ̂ (model units; 0 before [`AutoStop::start`]).
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// Whether the run has ended, and why.
    pub fn stopped_by(&self) -> Option<StopReason> {
        self.stopped_by
    }

    /// After [`AutoStop::start`] on the input: take up a run whose iterations so far removed
    /// `removed` and which ended by `stopped` (from a checkpoint), replaying the noise sample's
    /// steps. A run that stopped at its cap goes on when the cap is now higher.
    pub fn resume(
        &mut self,
        topo: &Topology,
        removed: &[f64],
        stopped: Option<StopReason>,
        share: &mut dyn Share,
    ) {
        for &o in removed {
            let expected = self.expected_after_step(topo, share);
            self.expected.push(expected);
            self.removed.push(o);
        }
        if self.stopped_by.is_none() {
            self.stopped_by =
                stopped.filter(|&r| r != StopReason::Cap || removed.len() >= self.cap);
        }
    }

    /// After the next iteration, whose result is `pos` and whose previous positions are `prev`
    /// (the stencil methods' rule reads the displacement; the filter methods pass `None`): `Some`
    /// when the run ends with it. Every process calls it and gets the same answer.
    pub fn after(
        &mut self,
        topo: &Topology,
        pos: &[DVec3],
        prev: Option<&[DVec3]>,
        share: &mut dyn Share,
    ) -> Option<StopReason> {
        let k = self.removed.len() + 1;
        let owned = share.owned();
        let before = (
            self.removed.last().copied().unwrap_or(0.0),
            self.expected.last().copied().unwrap_or(0.0),
        );
        let expected = self.expected_after_step(topo, share);
        let removed = self.removed_by(topo, pos, share);
        self.expected.push(expected);
        self.removed.push(removed);
        let stop = if let StopRule::Settle(settle) = self.rule {
            // The mean displacement in units of σ̂.
            let moved = prev.map_or(f64::NAN, |prev| {
                let (now, prev) = (&pos[owned.clone()], &prev[owned.clone()]);
                let sigma = self.sigma;
                let sum = on_pool(share, || {
                    reduce::fixed_sum(now, |i, p| p.distance(prev[i]) / sigma)
                });
                total(share, sum) / self.movable.max(1.0)
            });
            if removed > settle.removed {
                Some(StopReason::Detail)
            } else if moved < settle.moved {
                Some(StopReason::Settled)
            } else {
                None
            }
        } else {
            let gain = expected - before.1;
            let ratio = if gain > 0.0 {
                (removed - before.0) / gain
            } else {
                f64::INFINITY
            };
            if k >= 2 && ratio > DETAIL_RATIO {
                Some(StopReason::Detail)
            } else if gain < NOISE_GONE {
                Some(StopReason::NoiseRemoved)
            } else {
                None
            }
        };
        self.stopped_by = stop.or((k >= self.cap).then_some(StopReason::Cap));
        self.stopped_by
    }

    /// `O_k` of the positions `pos` after iteration k: the energy removed along the input
    /// normals, in units of the noise; for a [`StopRule::ShrinkingFilter`] that of its
    /// differences along the edges, relative to the noise sample's (this uses the spare field).
    fn removed_by(&mut self, topo: &Topology, pos: &[DVec3], share: &mut dyn Share) -> f64 {
        let owned = share.owned();
        let (normals, base, origin, sigma) = (&*self.normals, &*self.base, self.origin, self.sigma);
        let along = |v: usize| ((pos[v] - origin).dot(normals[v]) - base[v]) / sigma;
        if let StopRule::ShrinkingFilter(_) = self.rule {
            let d = &mut self.spare;
            on_pool(share, || {
                reduce::for_chunks_mut(&mut d[owned.clone()], |at, out| {
                    for (k, o) in out.iter_mut().enumerate() {
                        *o = along(owned.start + at + k);
                    }
                })
            });
            share.step_end_scalar(d);
            let d: &[f64] = d;
            return edge_energy(topo, share, |v| d[v]) / self.edge_noise;
        }
        let now = &pos[owned.clone()];
        let sum = on_pool(share, || {
            reduce::fixed_sum(now, |i, _| along(owned.start + i).powi(2))
        });
        total(share, sum) / self.movable.max(1.0)
    }

    /// One iteration of the scalar analogue on the field, and `E_k` (NaN for a method without
    /// one); for a [`StopRule::ShrinkingFilter`] measured along the edges, as its `O_k`.
    fn expected_after_step(&mut self, topo: &Topology, share: &mut dyn Share) -> f64 {
        let owned = share.owned();
        let (StopRule::Filter(factors) | StopRule::ShrinkingFilter(factors)) = &self.rule else {
            return f64::NAN;
        };
        for &factor in factors {
            let (src, out) = (&self.field, &mut self.spare);
            on_pool(share, || {
                reduce::for_chunks_mut(&mut out[owned.clone()], |at, out| {
                    noise::scalar_step_into(topo, src, out, owned.start + at, factor)
                })
            });
            share.step_end_scalar(out);
            std::mem::swap(&mut self.field, &mut self.spare);
        }
        if let StopRule::ShrinkingFilter(_) = self.rule {
            let field: &[f64] = &self.field;
            let eps = |v| noise::epsilon(topo, SEED, v);
            return edge_energy(topo, share, |v| field[v] - eps(v)) / self.edge_noise;
        }
        let field = &self.field[owned.clone()];
        let sum = on_pool(share, || {
            reduce::fixed_sum(field, |i, e| {
                let v = owned.start + i;
                if topo.is_fixed(v as u32) {
                    0.0
                } else {
                    (e - noise::gaussian(SEED, v as u64)).powi(2)
                }
            })
        });
        total(share, sum) / self.noise_energy
    }

    /// What the rule measured and why the run ended (the cap if it has not ended).
    pub fn stats(&self) -> AutoStopStats {
        AutoStopStats {
            cap: self.cap,
            stopped_by: self.stopped_by.unwrap_or(StopReason::Cap),
            noise_estimate: self.sigma,
            noise_estimate_median: self.estimates.0,
            noise_estimate_rms: self.estimates.1,
            removed: self.removed.clone(),
            expected: self.expected.clone(),
        }
    }
}

/// The white-noise sample ε into `field` (owned entries, then the others' copies).
fn white_noise(topo: &Topology, field: &mut [f64], share: &mut dyn Share) {
    let owned = share.owned();
    on_pool(share, || {
        reduce::for_chunks_mut(&mut field[owned.clone()], |at, out| {
            noise::white_noise_into(topo, SEED, out, owned.start + at)
        })
    });
    share.step_end_scalar(field);
}

/// `Σ_v Σ_{u ∈ N(v)} (x_u − x_v)²` over the vertices of all processes (each edge from both of
/// its ends), `x` known on each one's owned vertices and their neighbours.
fn edge_energy(topo: &Topology, share: &mut dyn Share, x: impl Fn(usize) -> f64 + Sync) -> f64 {
    let owned = share.owned();
    let fixed = &topo.fixed_mask()[owned.clone()];
    let sum = on_pool(share, || {
        reduce::fixed_sum(fixed, |i, _| {
            let v = owned.start + i;
            let xv = x(v);
            topo.neighbors(v as u32)
                .iter()
                .map(|&u| (x(u as usize) - xv).powi(2))
                .sum()
        })
    });
    total(share, sum)
}

/// A [`Fixed`] sum over all processes, as an f64.
fn total(share: &dyn Share, local: Fixed) -> f64 {
    Fixed::from_limbs(&share.sum_counts(local.limbs().to_vec())).value()
}

/// The spread of the second difference of `x` over the movable vertices of all processes (`x`
/// valid on this one's owned vertices and their neighbours): its median absolute deviation, and
/// the root mean square of its deviations from the median within [`CLIP`] of those (module doc);
/// `out` is scratch space.
fn spread_of_second_difference(
    topo: &Topology,
    x: &[f64],
    out: &mut [f64],
    share: &mut dyn Share,
) -> (f64, f64) {
    let owned = share.owned();
    let out = &mut out[owned.clone()];
    on_pool(share, || {
        reduce::for_chunks_mut(out, |at, o| {
            noise::second_difference_into(topo, x, o, owned.start + at)
        })
    });
    let share: &dyn Share = share;
    let median = reduce::median_over(out, share.pool(), |c| share.sum_counts(c));
    // NaN (a fixed vertex) stays NaN, and the median skips it.
    on_pool(share, || {
        reduce::for_chunks_mut(out, |_, o| {
            o.iter_mut().for_each(|y| *y = (*y - median).abs())
        })
    });
    let mad = reduce::median_over(out, share.pool(), |c| share.sum_counts(c));
    if mad <= 0.0 || !mad.is_finite() {
        return (mad, 0.0);
    }
    // In units of the MAD, so that the fixed-point sum's resolution does not depend on the
    // model's units.
    let within = |y: f64| y <= CLIP * mad;
    let out: &[f64] = out;
    let (sum, count) = on_pool(share, || {
        let sum = reduce::fixed_sum(out, |_, &y| if within(y) { (y / mad).powi(2) } else { 0.0 });
        let count = reduce::map_fold(
            out,
            |_, c| c.iter().filter(|&&y| within(y)).count() as u64,
            0,
            |a, b| a + b,
        );
        (sum, count)
    });
    let count = share.sum_counts(vec![count])[0].max(1);
    let rms = mad * (total(share, sum) / count as f64).sqrt();
    (mad, rms)
}
