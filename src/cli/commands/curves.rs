//! `vcsmooth curves IN --plot FILE.svg ...`: several methods from the same input, their volume %
//! per iteration plotted (the paper's Fig. 4) and printed as a table or JSON.

use std::io::Write;
use std::path::PathBuf;

use clap::Args as ClapArgs;
use serde::Serialize;

use crate::cli::flags;
use crate::cli::output::{check_files, print_json, stdout_error, svg_output};
use crate::cli::plot::{Curve, file_name, volume_curve, write_volume_plot};
use crate::cli::progress::Progress;
use crate::cli::report::fixed;
use crate::cli::shared::{EngineArgs, Iterations, MethodParams, PinArgs, distinct, iterations};
use crate::engine::{self, IterationRecord};
use crate::engine::{EngineSettings, Layout};
use crate::error::Result;
use crate::report::Tool;
use crate::smooth::{Method, Options};

/// `vcsmooth curves IN --plot FILE.svg ...`
#[derive(Debug, Clone, ClapArgs)]
pub struct CurvesArgs {
    /// Input mesh (PLY, OBJ, OFF, STL, glTF or GLB; any of them gzip-compressed).
    #[arg(value_name = "IN")]
    pub input: PathBuf,
    /// Comma-separated methods to run, each from the same input.
    #[arg(long, value_enum, value_delimiter = ',', value_name = "M,M,...",
          default_values_t = Method::CURVES)]
    pub methods: Vec<Method>,
    /// Iterations per method (at least 1), or 'auto': each method stops when its noise is gone, as `smooth --iterations auto` does (its curve ends there).
    #[arg(long, value_name = "N|auto", default_value = "10", allow_negative_numbers = true,
          value_parser = curve_iterations)]
    pub iterations: Iterations,
    #[command(flatten)]
    pub params: MethodParams,
    #[command(flatten)]
    pub pins: PinArgs,
    #[command(flatten)]
    pub engine: EngineArgs,
    /// SVG file for the volume curves, one line per method with a legend.
    #[arg(long, value_name = "FILE.svg", required = true)]
    pub plot: PathBuf,
    /// Print JSON instead of a table [default: table].
    #[arg(long)]
    pub json: bool,
}

/// `vcsmooth curves`, resolved.
#[derive(Debug, Clone)]
pub struct CurvesConfig {
    pub input: PathBuf,
    /// Distinct methods, in the order given.
    pub methods: Vec<Method>,
    /// Options shared by every method (`method` is replaced per run).
    pub options: Options,
    pub engine: EngineSettings,
    /// The stencils' order: the input's (the paper's sequential reference), or the patches of
    /// `--patch-size` when it is given.
    pub layout: Layout,
    pub plot: PathBuf,
    pub json: bool,
}

impl CurvesConfig {
    pub fn from_args(a: CurvesArgs) -> Result<CurvesConfig> {
        let methods = distinct(a.methods);
        if methods.is_empty() {
            return Err(flags::parameter("methods", "names no method"));
        }
        // Every method runs with the same parameters: each must accept them.
        let options_of = |method| match a.iterations {
            Iterations::Count(n) => a.params.options(method, n),
            Iterations::Auto => Ok(Options {
                auto_stop: true,
                ..a.params.options(method, engine::auto::DEFAULT_CAP)?
            }),
        };
        for &method in &methods {
            options_of(method)?;
        }
        let options = options_of(methods[0])?;
        svg_output(&a.plot)?;
        let mut reads = vec![("IN", a.input.as_path())];
        reads.extend(a.pins.pin.as_deref().map(|p| ("--pin", p)));
        check_files(&reads, None, &[("--plot", &a.plot)])?;
        let mut engine = a.engine.resolve()?;
        engine.pins = a.pins.resolve()?;
        let layout = match a.engine.patch_size {
            Some(_) => engine.layout(),
            None => Layout::Whole,
        };
        Ok(CurvesConfig {
            options,
            engine,
            layout,
            input: a.input,
            methods,
            plot: a.plot,
            json: a.json,
        })
    }
}

/// `--iterations` of `curves` (clap value parser): as `smooth`'s, but a curve needs at least one
/// iteration.
fn curve_iterations(s: &str) -> std::result::Result<Iterations, String> {
    match iterations(s)? {
        Iterations::Count(0) => Err("a curve needs at least 1 iteration".to_string()),
        n => Ok(n),
    }
}

/// One method's run in `vcsmooth curves`.
#[derive(Debug, Clone, Serialize)]
pub struct CurveDoc {
    pub method: Method,
    /// Volume % at iterations 0 (100), 1, …, N.
    pub volume_pct: Vec<f64>,
    pub seconds: f64,
    pub iterations: Vec<IterationRecord>,
}

/// The JSON of `vcsmooth curves --json`.
#[derive(Debug, Clone, Serialize)]
pub struct CurvesDoc {
    pub tool: Tool,
    pub input: String,
    pub iterations: usize,
    /// `--iterations auto`: every curve ends where its method stopped.
    pub auto_stop: bool,
    pub lambda: f64,
    /// `--mu`, or null: each method's own.
    pub mu: Option<f64>,
    pub reject_energy_increase: bool,
    pub plot: String,
    pub curves: Vec<CurveDoc>,
}

/// `vcsmooth curves`: every method from the same input positions, each through the engine's
/// in-memory run (so every option and engine flag reaches it as it reaches `smooth`); the plot,
/// then the table.
pub fn run(cfg: &CurvesConfig, progress: &mut Progress, out: &mut dyn Write) -> Result<()> {
    // Each method keeps one record per iteration: refuse counts the budget cannot hold first.
    let budget = cfg.engine.budget()?;
    engine::memory::check_records(
        cfg.options.iterations,
        budget / cfg.methods.len().max(1) as u64,
    )?;
    progress.phase(format!("reading {}", cfg.input.display()));
    let mesh = crate::io::read_mesh(&cfg.input)?;
    let settings = EngineSettings {
        statistics: engine::Statistics::Every,
        with_stats: false,
        ..cfg.engine.clone()
    };
    let mut docs = Vec::with_capacity(cfg.methods.len());
    for &method in &cfg.methods {
        let options = Options {
            method,
            ..cfg.options
        };
        let mut smoothed = mesh.clone();
        progress.iterations(method.name(), options.iterations);
        let report =
            engine::run::run_mesh(&mut smoothed, &options, &settings, cfg.layout, progress)
                .map_err(|e| e.in_file(&cfg.input))?;
        docs.push(CurveDoc {
            method,
            volume_pct: volume_curve(&report.records),
            seconds: report.timings.smoothing,
            iterations: report.records,
        });
    }

    let curves: Vec<Curve> = docs
        .iter()
        .map(|d| Curve {
            method: d.method,
            volume_pct: d.volume_pct.clone(),
        })
        .collect();
    let title = format!("volume per iteration: {}", file_name(&cfg.input));
    write_volume_plot(&cfg.plot, &title, &curves)?;
    progress.finish();

    let doc = CurvesDoc {
        tool: Tool::this(),
        input: cfg.input.display().to_string(),
        // With the automatic stop, the longest curve's length (each stops where its noise is gone).
        iterations: match cfg.options.auto_stop {
            true => docs.iter().map(|d| d.iterations.len()).max().unwrap_or(0),
            false => cfg.options.iterations,
        },
        auto_stop: cfg.options.auto_stop,
        lambda: cfg.options.lambda,
        mu: cfg.options.mu,
        reject_energy_increase: cfg.options.reject_energy_increase,
        plot: cfg.plot.display().to_string(),
        curves: docs,
    };
    if cfg.json {
        print_json(out, &doc)
    } else {
        print_curves(out, &doc)
    }
}

/// Print the iteration × method table of volume percentages.
fn print_curves(out: &mut dyn Write, doc: &CurvesDoc) -> Result<()> {
    let mut text = format!("{:>5}", "iter");
    for c in &doc.curves {
        text += &format!(" {:>14}", format!("{} %", c.method.name()));
    }
    text.push('\n');
    for it in 0..=doc.iterations {
        text += &format!("{it:>5}");
        for c in &doc.curves {
            match c.volume_pct.get(it) {
                Some(v) => text += &format!(" {:>14}", fixed(*v, 6)),
                None => text += &format!(" {:>14}", "-"),
            }
        }
        text.push('\n');
    }
    text += &format!("{:>5}", "secs");
    for c in &doc.curves {
        text += &format!(" {:>14.3}", c.seconds);
    }
    text.push('\n');
    out.write_all(text.as_bytes()).map_err(stdout_error)
}
