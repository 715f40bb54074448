//! What `batch` and `slurm-script` share: the smoothing applied to every mesh of a batch (its
//! flags, their resolution) and the check of a batch's inputs.

use std::path::{Path, PathBuf};

use clap::{Args as ClapArgs, ValueEnum};

use super::shared::{PinPropertyArg, SmoothingArgs};
use crate::cli::output::Identity;
use crate::engine::EngineSettings;
use crate::error::{Error, Result};
use crate::io::Format;
use crate::modes::batch as core;
use crate::smooth::Options;

/// Output formats of `batch --format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OutputFormat {
    Ply,
    Obj,
    Off,
    Stl,
}

impl From<OutputFormat> for Format {
    fn from(f: OutputFormat) -> Format {
        match f {
            OutputFormat::Ply => Format::Ply,
            OutputFormat::Obj => Format::Obj,
            OutputFormat::Off => Format::Off,
            OutputFormat::Stl => Format::Stl,
        }
    }
}

/// The smoothing flags of `smooth`, for every mesh of a batch, plus the output format.
#[derive(Debug, Clone, ClapArgs)]
pub struct BatchSmoothArgs {
    #[command(flatten)]
    pub smoothing: SmoothingArgs,
    #[command(flatten)]
    pub pins: PinPropertyArg,
    /// Refused with a reason: one list of vertex indices cannot name the vertices of several meshes.
    #[arg(long, value_name = "FILE", hide = true)]
    pub pin: Option<PathBuf>,
    /// Format of the outputs, OUTDIR/<input's stem>.<format>.
    #[arg(long, value_enum, default_value_t = OutputFormat::Ply)]
    pub format: OutputFormat,
}

/// The smoothing a batch applies to each of its meshes.
#[derive(Debug, Clone)]
pub struct BatchSmooth {
    pub options: Options,
    pub engine: EngineSettings,
    pub format: Format,
    /// The flags as given, to repeat them in a job script.
    pub args: BatchSmoothArgs,
}

impl BatchSmooth {
    pub fn from_args(a: BatchSmoothArgs) -> Result<BatchSmooth> {
        if a.pin.is_some() {
            return Err(Error::Usage {
                what: "--pin FILE names the vertices of one mesh, not of every mesh of a batch; \
                       pin by a PLY vertex property of each mesh with --pin-property NAME"
                    .into(),
            });
        }
        let options = a.smoothing.options(crate::Method::default())?;
        let mut engine = a.smoothing.engine.resolve()?;
        engine.with_stats = true;
        engine.pins = a.pins.resolve();
        Ok(BatchSmooth {
            options,
            engine,
            format: a.format.into(),
            args: a,
        })
    }
}

/// The inputs of a batch, checked: at least one, no two with the same stem, none that its output
/// would overwrite, and OUTDIR not the input directory (the next run would take the outputs for
/// inputs, whatever their format).
pub fn batch_inputs(list_or_dir: &Path, outdir: &Path, format: Format) -> Result<Vec<PathBuf>> {
    if list_or_dir.is_dir()
        && let (Ok(a), Ok(b)) = (list_or_dir.canonicalize(), outdir.canonicalize())
        && a == b
    {
        return Err(Error::invalid(
            outdir,
            "OUTDIR is the input directory: a later run would take the outputs for inputs; \
             choose another OUTDIR",
        ));
    }
    let inputs = core::list_inputs(list_or_dir)?;
    if inputs.is_empty() {
        return Err(Error::invalid(
            list_or_dir,
            "names no mesh files (.ply, .obj, .off, .stl, .gltf or .glb)",
        ));
    }
    core::check_stems(&inputs)?;
    // The same file, however reached (a symbolic or hard link, `..`): not by its name only.
    for input in &inputs {
        let output = core::output_path(outdir, input, format)?;
        if Identity::of(&output) == Identity::of(input) {
            return Err(Error::invalid(
                input,
                "its output would overwrite it: choose another OUTDIR or --format",
            ));
        }
    }
    Ok(inputs)
}
