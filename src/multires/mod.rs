//! Multiresolution smoothing (`vcsmooth smooth --multires`), after the closing remark of Liu et
//! al. 2002 (§4): the volume constraint matters on coarse meshes and hardly on dense ones, so run
//! `vcs` where the mesh is coarse and a cheap Jacobi filter where it is dense.
//!
//! 1. **Hierarchy** ([`clustering`]): level 0 is the input on the patch engine ([`Plan`]); level
//!    k + 1 clusters level k's vertices into grid cubes of `cell_factor` × level k's mean edge
//!    length, with quadric placement, and is then given level 0's volume back
//!    ([`transfer::restore_volume`]). Every level is a [`Plan`] on the same [`Storage`]
//!    (heap or memory-mapped scratch), so the whole mode runs out of core like `smooth`.
//! 2. **Coarse levels**, coarsest first: the coarser level's total displacement is transferred
//!    ([`transfer::apply`]), then `coarse_iterations` of `vcs` (or `vcs-triangle`) run on the
//!    level, patch-parallel.
//! 3. **Level 0**: the displacement of level 1 is transferred, then `iterations` of `laplacian` or
//!    `taubin` (Jacobi, ~35× cheaper per iteration than `vcs` at 5M triangles) remove the fine noise.
//! 4. A global volume correction (every movable vertex translated along its volume gradient by a
//!    common factor, the global form of vcs's step 2) makes the output's volume the input's.
//!
//! Pins and crease corners fix vertices of level 0, which neither the transfer nor the
//! correction moves; crease line vertices move along their lines in level 0's steps only.
//! With the automatic stop level 0 stops when its noise is gone; with a deviation bound level 0
//! stays within it of the input through the transfer, the fine method and the correction
//! ([`transfer::restore_volume_within`]).
//!
//! Deterministic for any thread count and storage placement at a given patch size: clustering sorts
//! unique keys and sums each cluster in a fixed order, every parallel sum uses fixed-size chunks,
//! and the smoothing is the engine's.

pub mod clustering;
pub mod transfer;

use std::path::Path;
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::engine::reduce;
use crate::engine::{
    self, AutoStopStats, EngineSettings, IterationRecord, Layout, Observer, Plan, Report,
    Statistics,
};
use crate::error::{Error, Result};
use crate::mesh::{Buf, Storage};
use crate::metrics;
use crate::smooth::{Control, Method, Options};
pub use transfer::Transfer;

/// Default number of levels, the input included: the input and one coarse level with about
/// 18× fewer vertices. A second coarse level (~300× fewer) smooths away real features of a scan
/// when its vcs runs as many iterations: measured on the armadillo at 5.5M triangles, RMS distance
/// to the clean mesh 4.4e-4 with three levels against 2.4e-4 with two.
pub const DEFAULT_LEVELS: usize = 2;
/// Largest `--levels`: beyond that a level has a handful of vertices even for billions of triangles.
pub const MAX_LEVELS: usize = 8;
/// The least share of the input's volume a coarse level must keep as clustered (before its
/// volume is restored) to be built. A coarser level has lost the shape: restoring its volume
/// inflates what it collapsed, smoothing it moves vertices farther than a cell, and the transfer
/// hands that down (a level-4 sphere's 8-vertex level kept 56 % and wrecked the output; levels
/// that carry the shape keep 97 % and more).
pub const MIN_LEVEL_VOLUME: f64 = 0.95;
/// Default cell edge of a coarse level, in mean edge lengths of the level below it.
pub const DEFAULT_CELL_FACTOR: f64 = 4.0;

/// Options of the multiresolution mode. The coarse method and the fine iteration count come from
/// the ordinary [`Options`] (`method`, `iterations`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MultiresOptions {
    /// Levels including the input (≥ 2); fewer are built when a level stops shrinking.
    pub levels: usize,
    /// Iterations of the coarse method on each coarse level; `None`: the same as `iterations`.
    pub coarse_iterations: Option<usize>,
    /// Method on level 0: `laplacian` or `taubin`.
    pub fine_method: Method,
    pub transfer: Transfer,
    /// Cell edge of a coarse level in mean edge lengths of the level below.
    pub cell_factor: f64,
}

impl Default for MultiresOptions {
    fn default() -> Self {
        MultiresOptions {
            levels: DEFAULT_LEVELS,
            coarse_iterations: None,
            fine_method: Method::MULTIRES_FINE,
            transfer: Transfer::Interpolate,
            cell_factor: DEFAULT_CELL_FACTOR,
        }
    }
}

/// What happened on one level.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LevelStats {
    /// 0 is the input.
    pub level: usize,
    pub vertices: usize,
    pub triangles: usize,
    /// Vertices no method moves (boundary, non-manifold: clustering can create both).
    pub fixed_vertices: usize,
    pub method: Method,
    pub iterations: usize,
    /// Volume of the level after it was built (coarse levels: after the volume restoration), % of
    /// the input's.
    pub volume_pct: f64,
    /// Seconds clustering and preparing the level (0 for the input, prepared by the engine).
    pub build_seconds: f64,
    /// Seconds transferring the coarser displacement onto the level.
    pub transfer_seconds: f64,
    pub smooth_seconds: f64,
}

/// A coarse level not built: clustered, it kept too little of the input's volume
/// ([`MIN_LEVEL_VOLUME`]).
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct RefusedLevel {
    pub level: usize,
    pub vertices: usize,
    /// Its volume as clustered, % of the input's.
    pub volume_pct: f64,
}

/// The whole multiresolution run, for reports.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MultiresStats {
    pub options: MultiresOptions,
    /// Finest first.
    pub levels: Vec<LevelStats>,
    /// The coarser level that was not built because it lost the shape, when one was not.
    pub refused: Option<RefusedLevel>,
    /// Volume % after the fine smoothing, before the final correction.
    pub volume_pct_before_correction: f64,
    /// The output's volume and area as a percentage of the input's: also after 0 iterations of
    /// the input level, when the coarse levels still moved it.
    pub volume_pct: f64,
    pub area_pct: f64,
    /// |V_out − V_in| / |V_in| after the final correction (f64 positions).
    pub volume_error: f64,
    pub correction_seconds: f64,
    pub seconds: f64,
}

/// Check that `opts` and `m` make a multiresolution run.
pub fn validate(opts: &Options, m: &MultiresOptions) -> Result<()> {
    if !opts.boundary.is_fixed() {
        return Err(Error::parameter(
            "boundary",
            format!(
                "smooth cannot mean anything in multiresolution mode: the input level runs {}, which keep the boundary fixed, and the coarse levels' clusters do not follow the loops",
                Method::names_accepting(Control::MultiresFine, "or")
            ),
        ));
    }
    if !opts.method.unit().accepts(Control::MultiresCoarse) {
        return Err(Error::parameter(
            "multires",
            format!(
                "runs {} on the coarse levels, not {} (the fine level runs {})",
                Method::names_accepting(Control::MultiresCoarse, "or"),
                opts.method,
                Method::names_accepting(Control::MultiresFine, "or")
            ),
        ));
    }
    if !m.fine_method.unit().accepts(Control::MultiresFine) {
        return Err(Error::parameter(
            "fine_method",
            format!(
                "must be {}, not {}",
                Method::names_accepting(Control::MultiresFine, "or"),
                m.fine_method
            ),
        ));
    }
    if !(2..=MAX_LEVELS).contains(&m.levels) {
        return Err(Error::parameter(
            "levels",
            format!(
                "must be between 2 and {MAX_LEVELS} (the input counts as one), got {}",
                m.levels
            ),
        ));
    }
    if !(m.cell_factor.is_finite() && m.cell_factor > 1.0) {
        return Err(Error::parameter(
            "cell_factor",
            format!(
                "must be a number above 1 (a cell factor of 1 or less builds no coarser level), got {}",
                m.cell_factor
            ),
        ));
    }
    Ok(())
}

/// A coarse level: its plan, how the level below maps onto it, and its positions as built.
struct Level {
    plan: Plan,
    /// `map[v]`: the vertex of this level (reordered id) representing vertex `v` of the level below.
    map: Buf<u32>,
    rest: Buf<DVec3>,
    /// Cell edge of the clustering that built it.
    cell: f64,
    stats: LevelStats,
}

impl Level {
    /// This level as the transfer reads it, with displacement `disp`.
    fn coarse<'a>(&'a self, disp: &'a [DVec3]) -> transfer::Coarse<'a> {
        transfer::Coarse {
            topo: &self.plan.topology,
            rest: &self.rest,
            disp,
            cell: self.cell,
        }
    }
}

/// Smooth the plan `plan` (level 0) in multiresolution (see the module doc), creating the coarse
/// levels on `storage` with `patch_size`. Returns level 0's iteration records (the last includes
/// the final volume correction), what its automatic stop measured (with `opts.auto_stop`: the
/// input level stops when its noise is gone; the coarse levels run `coarse_iterations`, by
/// default 10 then) and the per-level statistics.
pub fn smooth_plan(
    plan: &mut Plan,
    storage: &Storage,
    opts: &Options,
    m: &MultiresOptions,
    patch_size: usize,
    when: Statistics,
    observer: &mut dyn Observer,
) -> Result<(Vec<IterationRecord>, Option<AutoStopStats>, MultiresStats)> {
    validate(opts, m)?;
    let start = Instant::now();
    let origin = reduce::centroid(&plan.reordered.positions);
    let (v0, a0) =
        reduce::volume_area(&plan.reordered.positions, &plan.reordered.triangles, origin);
    let pct = |v: f64| metrics::percent(v, v0);
    // The input level's records are measured against the input, not the coarse levels' result
    // it starts from.
    let input = crate::engine::Reference {
        origin: origin.to_array(),
        volume: v0,
        area: a0,
    };
    // The deviation bound holds against the input, whatever the coarse levels did to level 0.
    let bound_input = match opts.max_deviation {
        Some(_) => Some(storage.copy_of(&plan.reordered.positions)?),
        None => None,
    };
    let bound = bound_input.as_deref().zip(opts.max_deviation);
    let coarse_iterations = m.coarse_iterations.unwrap_or(match opts.auto_stop {
        // `iterations` is then the input level's cap, not a count for the coarse levels.
        true => Options::default().iterations,
        false => opts.iterations,
    });

    // 1. The hierarchy, finest to coarsest.
    let mut levels: Vec<Level> = Vec::new();
    let mut refused = None;
    for k in 1..m.levels {
        let t = Instant::now();
        let finer = levels.last().map_or(&*plan, |l| &l.plan);
        let (pos, tris, topo) = (
            &finer.reordered.positions,
            &finer.reordered.triangles,
            &finer.topology,
        );
        let edge = metrics::mean_edge_length(pos, topo);
        if edge.is_nan() || edge <= 0.0 {
            break;
        }
        let cell = m.cell_factor * edge;
        let c = clustering::cluster(storage, pos, tris, topo, cell)?;
        // A level that does not shrink (or has nothing left to smooth) ends the hierarchy.
        if c.triangles.is_empty() || 2 * c.positions.len() > pos.len() {
            break;
        }
        // So does one that lost the shape (for a mesh that encloses a volume).
        let kept = reduce::volume(&c.positions, &c.triangles, origin) / v0;
        if v0.is_finite()
            && v0 != 0.0
            && !((MIN_LEVEL_VOLUME..=1.0 / MIN_LEVEL_VOLUME).contains(&kept))
        {
            refused = Some(RefusedLevel {
                level: k,
                vertices: c.positions.len(),
                volume_pct: 100.0 * kept,
            });
            break;
        }
        let mut coarse = Plan::new(
            storage,
            &c.positions,
            &c.triangles,
            Layout::Patches(patch_size),
        )?;
        let mut rank: Buf<u32> = storage.zeroed(c.positions.len())?;
        for (new, &old) in coarse.reordered.order.iter().enumerate() {
            rank[old as usize] = new as u32;
        }
        let mut map = c.map;
        map.par_iter_mut().for_each(|x| *x = rank[*x as usize]);
        drop(rank);
        let cp = &mut coarse.reordered;
        transfer::restore_volume(
            storage,
            &coarse.topology,
            &cp.triangles,
            &mut cp.positions,
            v0,
            origin,
        )?;
        let rest = storage.copy_of(&cp.positions)?;
        let stats = LevelStats {
            level: k,
            vertices: cp.positions.len(),
            triangles: cp.triangles.len(),
            fixed_vertices: coarse.topology.stats.fixed_vertices,
            method: opts.method,
            iterations: coarse_iterations,
            volume_pct: pct(reduce::volume(&cp.positions, &cp.triangles, origin)),
            build_seconds: t.elapsed().as_secs_f64(),
            transfer_seconds: 0.0,
            smooth_seconds: 0.0,
        };
        levels.push(Level {
            plan: coarse,
            map,
            rest,
            cell,
            stats,
        });
    }

    // 2. Coarse levels, coarsest first; `disp` is the total displacement of the level just done.
    // The automatic stop judges the input level's noise; the coarse levels run their count, and
    // their vertices are no input vertices to bound.
    let coarse_opts = Options {
        iterations: coarse_iterations,
        auto_stop: false,
        max_deviation: None,
        ..*opts
    };
    // Diffusing over about one cluster's width: the spread of k Jacobi steps grows like √k rings.
    let passes = (m.cell_factor * m.cell_factor).ceil() as usize;
    let mut disp: Option<Buf<DVec3>> = None;
    for i in (0..levels.len()).rev() {
        let (finer, coarser) = levels.split_at_mut(i + 1);
        let level = &mut finer[i];
        let t = Instant::now();
        if let (Some(d), Some(c)) = (&disp, coarser.first()) {
            let p = &mut level.plan;
            transfer::apply(
                storage,
                &p.topology,
                &c.map,
                &c.coarse(d),
                &mut p.reordered.positions,
                m.transfer,
                passes,
            )?;
        }
        level.stats.transfer_seconds = t.elapsed().as_secs_f64();
        let t = Instant::now();
        level.plan.smooth_unrecorded(storage, &coarse_opts)?;
        level.stats.smooth_seconds = t.elapsed().as_secs_f64();
        let mut d: Buf<DVec3> = storage.zeroed(level.rest.len())?;
        let r = &level.plan.reordered;
        let topo = &level.plan.topology;
        transfer::normal_displacement(topo, &r.triangles, &r.positions, &level.rest, &mut d);
        disp = Some(d);
    }

    // 3. Level 0.
    let mut fine = LevelStats {
        level: 0,
        vertices: plan.reordered.positions.len(),
        triangles: plan.reordered.triangles.len(),
        fixed_vertices: plan.topology.stats.fixed_vertices,
        method: m.fine_method,
        iterations: opts.iterations,
        // The input itself: 100 %, undefined against a volume of 0.
        volume_pct: if pct(0.0).is_nan() { f64::NAN } else { 100.0 },
        build_seconds: 0.0,
        transfer_seconds: 0.0,
        smooth_seconds: 0.0,
    };
    let t = Instant::now();
    if let (Some(d), Some(c)) = (&disp, levels.first()) {
        transfer::apply(
            storage,
            &plan.topology,
            &c.map,
            &c.coarse(d),
            &mut plan.reordered.positions,
            m.transfer,
            passes,
        )?;
        if let Some((input, limit)) = bound {
            let pos = &mut plan.reordered.positions;
            pos.par_iter_mut().zip(input.par_iter()).for_each(|(p, o)| {
                *p = crate::smooth::laplacian::clamp_to_ball(*p, *o, limit);
            });
        }
    }
    drop(disp);
    fine.transfer_seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let fine_opts = Options {
        method: m.fine_method,
        ..*opts
    };
    let (mut records, auto) = plan.smooth_against(
        storage,
        &fine_opts,
        when,
        input,
        bound_input.as_deref(),
        observer,
    )?;
    fine.smooth_seconds = t.elapsed().as_secs_f64();
    fine.iterations = records.len();

    // 4. The final volume correction.
    let t = Instant::now();
    let r = &mut plan.reordered;
    let before = pct(reduce::volume(&r.positions, &r.triangles, origin));
    let err = transfer::restore_volume_within(
        storage,
        &plan.topology,
        &r.triangles,
        &mut r.positions,
        v0,
        origin,
        bound,
    )?;
    let (volume, area) = reduce::volume_area(&r.positions, &r.triangles, origin);
    if let Some(last) = records.last_mut() {
        last.volume = volume;
        last.volume_pct = pct(volume);
    }
    let correction_seconds = t.elapsed().as_secs_f64();

    let mut all = vec![fine];
    all.extend(levels.into_iter().map(|l| l.stats));
    Ok((
        records,
        auto,
        MultiresStats {
            options: *m,
            levels: all,
            refused,
            volume_pct_before_correction: before,
            volume_pct: pct(volume),
            area_pct: metrics::percent(area, a0),
            volume_error: err.abs(),
            correction_seconds,
            seconds: start.elapsed().as_secs_f64(),
        },
    ))
}

/// Read `input`, smooth it in multiresolution on the patch engine (heap or scratch as `engine`
/// says, exactly as [`engine::run_file`]), write `output`.
pub fn run_file(
    input: &Path,
    output: &Path,
    opts: &Options,
    m: &MultiresOptions,
    engine: &EngineSettings,
    observer: &mut dyn Observer,
) -> Result<(Report, MultiresStats)> {
    validate(opts, m)?;
    let mut stats = None;
    let run = engine::run_file_with(
        input,
        output,
        opts,
        engine,
        observer,
        |plan, storage, obs| {
            let (records, auto, s) = smooth_plan(
                plan,
                storage,
                opts,
                m,
                engine.patch_size,
                engine.statistics,
                obs,
            )
            .map_err(|e| e.in_file(input))?;
            stats = Some(s);
            Ok((records, auto))
        },
    )?;
    // `run_file_with` returns Ok only after the closure above succeeded.
    let stats = stats.expect("run_file_with smooths before it succeeds");
    Ok((run, stats))
}
