//! `vcsmooth demo [--subdivisions K] [--iterations N] [--noise SIGMA]`: the embedded default job.
//! A noisy icosphere is smoothed by every method on the patch engine; the table shows what the
//! paper shows: only the volume-constrained methods keep the volume, and all of them remove the
//! noise.

use std::io::Write;

use clap::Args as ClapArgs;

use crate::cli::flags;
use crate::cli::output::stdout_error;
use crate::cli::progress::Progress;
use crate::cli::report::fixed;
use crate::cli::shared::{EngineArgs, finite_f64};
use crate::engine;
use crate::engine::EngineSettings;
use crate::error::Result;
use crate::metrics;
use crate::shapes;
use crate::smooth::{Method, Options};
use crate::topology::Topology;

/// `vcsmooth demo [--subdivisions K] [--iterations N] [--noise SIGMA]`
#[derive(Debug, Clone, ClapArgs)]
pub struct DemoArgs {
    /// Icosphere level of the embedded test mesh (20·4^K triangles).
    #[arg(long, value_name = "K", default_value_t = 4, allow_negative_numbers = true, value_parser = clap::value_parser!(u32).range(0..=10))]
    pub subdivisions: u32,
    /// Iterations per method.
    #[arg(long, value_name = "N", default_value_t = 10, allow_negative_numbers = true, value_parser = clap::value_parser!(u64).range(1..10_000))]
    pub iterations: u64,
    /// Noise along normals, × the mean edge length.
    #[arg(long, value_name = "SIGMA", default_value_t = 0.3, value_parser = finite_f64, allow_hyphen_values = true)]
    pub noise: f64,
    #[command(flatten)]
    pub engine: EngineArgs,
}

/// `vcsmooth demo`, resolved.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    pub subdivisions: u32,
    pub iterations: usize,
    pub noise: f64,
    pub engine: EngineSettings,
}

impl DemoConfig {
    pub fn from_args(a: DemoArgs) -> Result<DemoConfig> {
        if !(a.noise.is_finite() && a.noise >= 0.0) {
            return Err(flags::parameter(
                "noise",
                format!("must be a finite number ≥ 0, got {}", a.noise),
            ));
        }
        Ok(DemoConfig {
            subdivisions: a.subdivisions,
            iterations: a.iterations as usize,
            noise: a.noise,
            engine: a.engine.resolve()?,
        })
    }
}

/// `vcsmooth demo`.
pub fn run(cfg: &DemoConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    progress.phase(format!(
        "generating a noisy sphere (level {})",
        cfg.subdivisions
    ));
    let clean = shapes::icosphere(cfg.subdivisions);
    let mut noisy = clean.clone();
    shapes::add_normal_noise(&mut noisy, cfg.noise, 1);
    let clean_topo = Topology::build(clean.positions.len(), &clean.triangles)?;
    let rough_clean = metrics::roughness(&clean.positions, &clean.triangles, &clean_topo);
    let rough_noisy = metrics::roughness(&noisy.positions, &noisy.triangles, &clean_topo);
    writeln!(
        out,
        "noisy unit sphere: {} vertices, {} triangles, noise {} × mean edge; {} iterations per method, {} threads\n\
         roughness (mean dihedral angle): clean {:.3}°, noisy {:.3}°\n",
        noisy.positions.len(),
        noisy.triangles.len(),
        cfg.noise,
        cfg.iterations,
        cfg.engine.threads.unwrap_or_else(rayon::current_num_threads),
        rough_clean,
        rough_noisy
    )
    .map_err(stdout_error)?;
    writeln!(
        out,
        "{:<13} {:>12} {:>10} {:>14} {:>16} {:>10}",
        "method", "volume %", "area %", "roughness °", "RMS to clean", "seconds"
    )
    .map_err(stdout_error)?;
    // Every method from the noisy positions, through the library's front door.
    let settings = EngineSettings {
        statistics: engine::Statistics::Every,
        with_stats: false,
        ..cfg.engine.clone()
    };
    for method in Method::ALL {
        let opts = Options {
            method,
            iterations: cfg.iterations,
            ..Default::default()
        };
        progress.iterations(method.name(), cfg.iterations);
        let mut smoothed = noisy.clone();
        let records = crate::smooth_with(&mut smoothed, &opts, &settings, progress)?.records;
        let positions = &smoothed.positions;
        let last = records.last().copied().unwrap_or_default();
        let rough = metrics::roughness(positions, &noisy.triangles, &clean_topo);
        let rms = (positions
            .iter()
            .zip(&clean.positions)
            .map(|(a, b)| a.distance_squared(*b))
            .sum::<f64>()
            / positions.len().max(1) as f64)
            .sqrt();
        let seconds: f64 = records.iter().map(|r| r.seconds).sum();
        writeln!(
            out,
            "{:<13} {:>12} {:>10} {:>14.3} {:>16.3e} {:>10.3}",
            method.name(),
            fixed(last.volume_pct, 6),
            fixed(last.area_pct, 4),
            rough,
            rms,
            seconds
        )
        .map_err(stdout_error)?;
    }
    progress.finish();
    Ok(())
}
