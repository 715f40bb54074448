//! The automatic stop ([`Options::auto_stop`], `--iterations auto`): the iteration loop ends when
//! what an iteration removes is no longer noise. Defined and measured in docs/quality-research.md
//! §5; the per-vertex operators are [`crate::smooth::noise`]. All from the input alone:
//!
//! - **Noise level** `σ̂ = MAD(g) / MAD(g^ε)` over the movable vertices: `g` is the second
//!   difference of the normal component of the umbrella Laplacian of the input (its smooth
//!   curvature cancels, the noise does not), `g^ε` the same operators on a white-noise sample ε
//!   (seed [`SEED`]) on the same connectivity, which calibrates the operators' gain. The median
//!   absolute deviation ignores features (a minority of vertices).
//! - **Removed**, after iteration k: `O_k = mean ((P^k − P⁰) · n⁰)² / σ̂²`, the energy the
//!   iterations took away along the input normals, in units of the noise.
//! - **Expected** (`laplacian`, `taubin`, `vcs-lowpass`): `E_k = Σ (e^k − ε)² / Σ ε²`, where `e^k`
//!   is ε after k iterations of the method's scalar analogue (one λ step; a λ|μ pair): what the
//!   filter would remove from pure noise.
//! - **Rule** with `R_k = (O_k − O_{k−1}) / (E_k − E_{k−1})`: stop after iteration k when
//!   `k ≥ 2` and `R_k >` [`DETAIL_RATIO`] (more than 2/7 of what the iteration removed is not
//!   explained by noise: it is removing shape), or when `E_k − E_{k−1} <` [`NOISE_GONE`] (a
//!   further iteration would remove less than 1 % of the noise: what the filter can remove is
//!   gone). The stencil methods (`lem`, `vcs`, `vcs-triangle`) have no scalar analogue (a scalar
//!   stencil minimiser removes most white noise at once, then stalls); they stop when the
//!   iteration's mean displacement falls below [`SETTLED`] × σ̂, or when `O_k >`
//!   [`REMOVED_ENOUGH`]: the iterations together removed more than 4/3 of the noise energy along
//!   the normals, so the rest was shape (on noisy scans they settle first, at `O_k` ≤ 1.34; on
//!   a clean one this ends the run after an iteration or two).
//! - Always at [`Options::iterations`] at the latest (the cap), and before the first iteration
//!   when σ̂ is 0 (nothing movable, or no measurable noise).
//!
//! Every sum and median runs over [`reduce`]'s fixed chunks, and the white noise is a function of
//! the vertex (recomputed, not stored), so the stop iteration is the same for any thread count
//! and storage. Memory: four arrays of the plan's size in its storage (normals, their offsets,
//! the scalar field and its second buffer), [`super::memory::AUTO_BYTES_PER_TRIANGLE`].

use glam::DVec3;

use super::reduce;
use crate::error::Result;
use crate::mesh::{Buf, Storage};
use crate::smooth::{Method, Options, noise};
use crate::topology::Topology;

/// Seed of the white-noise sample ε.
pub const SEED: u64 = 1;
/// Largest ratio of removed to expected energy that still counts as removing noise. 7/5 is the
/// centre of the thresholds that stop every noisy scan of the research inside the iterations
/// where the result beats the quality target (demosthenes σ 0.2 needs [1.19, 1.49), armadillo
/// σ 0.2 [1.34, 1.45), the others anything above 1.25); 4/3, the round value first tried, sits on
/// armadillo's edge, where the noise sample decides (docs/quality-research.md §5, §10).
pub const DETAIL_RATIO: f64 = 7.0 / 5.0;
/// The stencil methods stop when the iterations together removed more than this many times the
/// noise energy along the normals: the rest was shape.
pub const REMOVED_ENOUGH: f64 = 4.0 / 3.0;
/// Smallest share of the noise energy an iteration of the filter must still remove.
pub const NOISE_GONE: f64 = 0.01;
/// The stencil methods stop when an iteration moves the vertices by less than this share of σ̂
/// on average.
pub const SETTLED: f64 = 0.05;
/// The cap of `--iterations auto` (the command line's; the library's is
/// [`Options::iterations`]). The rule stops `taubin` and `vcs-lowpass` after at most 14
/// iterations on the scans measured (the noise-removed test depends only on λ, μ and the
/// connectivity), so the cap only bounds the unusual.
pub const DEFAULT_CAP: usize = 100;

/// Why an automatically stopped run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopReason {
    /// σ̂ is 0: no iteration ran.
    NoNoise,
    /// `R_k >` [`DETAIL_RATIO`] (the stencil methods: `O_k >` [`REMOVED_ENOUGH`]): the last
    /// iteration removed shape as well as noise.
    Detail,
    /// `E_k − E_{k−1} <` [`NOISE_GONE`]: the filter has removed what it can of the noise.
    NoiseRemoved,
    /// The mean displacement fell below [`SETTLED`] × σ̂ (the stencil methods).
    Settled,
    /// The cap ([`Options::iterations`]).
    Cap,
}

impl StopReason {
    /// How the command line says it.
    pub fn describe(self) -> &'static str {
        match self {
            StopReason::NoNoise => "no noise measured",
            StopReason::Detail => "the last iteration removed detail, not only noise",
            StopReason::NoiseRemoved => "the noise the filter can remove is gone",
            StopReason::Settled => "the vertices stopped moving",
            StopReason::Cap => "the cap was reached",
        }
    }
}

/// What the automatic stop measured, for the report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AutoStopStats {
    /// The cap ([`Options::iterations`]).
    pub cap: usize,
    pub stopped_by: StopReason,
    /// σ̂, in model units (along the normals).
    pub noise_estimate: f64,
    /// `O_k` of each iteration run.
    pub removed: Vec<f64>,
    /// `E_k` of each iteration run (`null` for the stencil methods, which have none).
    pub expected: Vec<f64>,
}

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
    sigma: f64,
    /// The step factors of the method's scalar analogue; empty for the stencil methods.
    factors: Vec<f64>,
    removed: Vec<f64>,
    expected: Vec<f64>,
    stopped_by: Option<StopReason>,
    cap: usize,
}

impl AutoStop {
    /// The arrays of a mesh of `vertices` vertices in `storage`, for `opts` (method, cap).
    pub fn new(storage: &Storage, vertices: usize, opts: &Options) -> Result<AutoStop> {
        let factors = match opts.method {
            Method::Laplacian => vec![opts.lambda],
            Method::Taubin | Method::VcsLowpass => vec![opts.lambda, opts.mu],
            Method::Lem | Method::Vcs | Method::VcsTriangle => Vec::new(),
        };
        Ok(AutoStop {
            normals: storage.zeroed(vertices)?,
            base: storage.zeroed(vertices)?,
            field: storage.zeroed(vertices)?,
            spare: storage.zeroed(vertices)?,
            origin: DVec3::ZERO,
            movable: 0.0,
            noise_energy: 0.0,
            sigma: 0.0,
            factors,
            removed: Vec::new(),
            expected: Vec::new(),
            stopped_by: None,
            cap: opts.iterations,
        })
    }

    /// Measure the input `pos` (σ̂, normals, the noise sample), on the current pool; `origin`
    /// is a point near the mesh (the offsets are taken from it). `Some` when no iteration is to
    /// run: σ̂ is 0, or the cap is.
    pub fn start(
        &mut self,
        topo: &Topology,
        tris: &[[u32; 3]],
        pos: &[DVec3],
        origin: DVec3,
    ) -> Option<StopReason> {
        let AutoStop {
            normals,
            field,
            spare,
            ..
        } = self;
        reduce::for_chunks_mut(normals, |at, out| {
            noise::unit_normals_into(topo, tris, pos, out, at)
        });
        let normals: &[DVec3] = normals;
        reduce::for_chunks_mut(spare, |at, out| {
            noise::normal_laplacian_into(topo, pos, normals, out, at)
        });
        let input = mad_of_second_difference(topo, spare, field);
        reduce::for_chunks_mut(field, |at, out| {
            noise::white_noise_into(topo, SEED, out, at)
        });
        let eps: &[f64] = field;
        reduce::for_chunks_mut(spare, |at, out| {
            noise::scalar_laplacian_into(topo, eps, out, at)
        });
        let calibration = mad_of_second_difference(topo, spare, field);
        self.sigma = if calibration > 0.0 {
            input / calibration
        } else {
            0.0
        };
        reduce::for_chunks_mut(&mut self.field, |at, out| {
            noise::white_noise_into(topo, SEED, out, at)
        });
        self.noise_energy = reduce::map_fold(
            &self.field,
            |_, c| c.iter().map(|x| x * x).sum::<f64>(),
            0.0,
            |a, b| a + b,
        );
        reduce::for_chunks_mut(&mut self.base, |at, out| {
            for (k, b) in out.iter_mut().enumerate() {
                *b = (pos[at + k] - origin).dot(normals[at + k]);
            }
        });
        self.origin = origin;
        self.movable = reduce::map_fold(
            topo.fixed_mask(),
            |_, c| c.iter().filter(|&&f| f == 0).count() as u64,
            0,
            |a, b| a + b,
        ) as f64;
        self.stopped_by = if self.sigma == 0.0 || !self.sigma.is_finite() {
            Some(StopReason::NoNoise)
        } else if self.cap == 0 {
            Some(StopReason::Cap)
        } else {
            None
        };
        self.stopped_by
    }

    /// σ̂ (model units; 0 before [`AutoStop::start`]).
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// After the next iteration, whose result is `pos` and whose mean displacement over the
    /// movable vertices is `mean_displacement` (read by the stencil methods' rule): `Some` when
    /// the run ends with it. On the current pool.
    pub fn after(
        &mut self,
        topo: &Topology,
        pos: &[DVec3],
        mean_displacement: f64,
    ) -> Option<StopReason> {
        let k = self.removed.len() + 1;
        let (normals, base, origin) = (&*self.normals, &*self.base, self.origin);
        let sum = reduce::map_fold(
            pos,
            |first, c| {
                c.iter()
                    .enumerate()
                    .map(|(i, p)| {
                        let v = first + i;
                        ((*p - origin).dot(normals[v]) - base[v]).powi(2)
                    })
                    .sum::<f64>()
            },
            0.0,
            |a, b| a + b,
        );
        let removed = sum / self.movable.max(1.0) / (self.sigma * self.sigma);
        let before = (
            self.removed.last().copied().unwrap_or(0.0),
            self.expected.last().copied().unwrap_or(0.0),
        );
        self.removed.push(removed);
        let stop = if self.factors.is_empty() {
            self.expected.push(f64::NAN);
            if removed > REMOVED_ENOUGH {
                Some(StopReason::Detail)
            } else if mean_displacement < SETTLED * self.sigma {
                Some(StopReason::Settled)
            } else {
                None
            }
        } else {
            let expected = self.expected_after_step(topo);
            self.expected.push(expected);
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

    /// One iteration of the scalar analogue on the field, and `E_k`.
    fn expected_after_step(&mut self, topo: &Topology) -> f64 {
        for &factor in &self.factors {
            let src: &[f64] = &self.field;
            reduce::for_chunks_mut(&mut self.spare, |at, out| {
                noise::scalar_step_into(topo, src, out, at, factor)
            });
            std::mem::swap(&mut self.field, &mut self.spare);
        }
        let sum = reduce::map_fold(
            &self.field,
            |first, c| {
                c.iter()
                    .enumerate()
                    .filter(|&(i, _)| !topo.is_fixed((first + i) as u32))
                    .map(|(i, e)| (e - noise::gaussian(SEED, (first + i) as u64)).powi(2))
                    .sum::<f64>()
            },
            0.0,
            |a, b| a + b,
        );
        sum / self.noise_energy
    }

    /// What the rule measured and why the run ended (the cap if it has not ended).
    pub fn stats(&self) -> AutoStopStats {
        AutoStopStats {
            cap: self.cap,
            stopped_by: self.stopped_by.unwrap_or(StopReason::Cap),
            noise_estimate: self.sigma,
            removed: self.removed.clone(),
            expected: self.expected.clone(),
        }
    }
}

/// The median absolute deviation of the second difference of `x` over the movable vertices;
/// `out` is scratch space.
fn mad_of_second_difference(topo: &Topology, x: &[f64], out: &mut [f64]) -> f64 {
    reduce::for_chunks_mut(out, |at, o| noise::second_difference_into(topo, x, o, at));
    let median = reduce::median(out);
    // NaN (a fixed vertex) stays NaN, and the median skips it.
    reduce::for_chunks_mut(out, |_, o| {
        o.iter_mut().for_each(|y| *y = (*y - median).abs())
    });
    reduce::median(out)
}
