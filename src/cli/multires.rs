//! The flags of `vcsmooth smooth --multires` (see [`crate::multires`]): a part of `smooth` kept in
//! its own file, with their resolution and the per-level table they add to `smooth`'s output.

use clap::builder::PossibleValue;
use clap::{Args as ClapArgs, ValueEnum};

use super::output::stdout_error;
use super::report::{fixed, percent_text};
use crate::error::Result;
use crate::multires::{DEFAULT_LEVELS, MAX_LEVELS, MultiresOptions, Transfer};
use crate::smooth::{Control, Method};

/// Multiresolution flags of `smooth`.
#[derive(Debug, Clone, ClapArgs)]
pub struct MultiresArgs {
    /// Multiresolution: vcs (--method vcs or vcs-triangle) on coarse levels built by vertex clustering with quadric placement, the displacement transferred down, then --iterations of --fine-method on the input, and a final global volume correction [default: off].
    #[arg(long)]
    pub multires: bool,
    /// Levels of the hierarchy, the input included (2..=8); each coarse level has about 18× fewer vertices (--cell-factor 4) [default: 2].
    #[arg(long, value_name = "K", requires = "multires", allow_negative_numbers = true,
          value_parser = clap::value_parser!(u32).range(2..=MAX_LEVELS as i64))]
    pub levels: Option<u32>,
    /// Iterations of --method on each coarse level [default: --iterations; 10 with --iterations auto].
    #[arg(long, value_name = "N", requires = "multires", allow_negative_numbers = true,
          value_parser = super::shared::whole)]
    pub coarse_iterations: Option<usize>,
    /// Method on the input level: laplacian or taubin [default: laplacian].
    #[arg(long, value_name = "M", requires = "multires", value_parser = fine_method)]
    pub fine_method: Option<Method>,
    /// How fine vertices follow their coarse representative [default: interpolate].
    #[arg(long, value_enum, value_name = "HOW", requires = "multires")]
    pub transfer: Option<Transfer>,
    /// Cell edge of each coarse level, in mean edge lengths of the level below (> 1) [default: 4].
    #[arg(long, value_name = "X", requires = "multires", allow_hyphen_values = true,
          value_parser = super::shared::finite_f64)]
    pub cell_factor: Option<f64>,
}

impl MultiresArgs {
    /// The options, or `None` without `--multires`; checked against the smoothing `options`.
    pub fn resolve(&self, options: &crate::Options) -> Result<Option<MultiresOptions>> {
        if !self.multires {
            return Ok(None);
        }
        let d = MultiresOptions::default();
        let m = MultiresOptions {
            levels: self.levels.map_or(DEFAULT_LEVELS, |k| k as usize),
            coarse_iterations: self.coarse_iterations,
            fine_method: self.fine_method.unwrap_or(d.fine_method),
            transfer: self.transfer.unwrap_or(d.transfer),
            cell_factor: self.cell_factor.unwrap_or(d.cell_factor),
        };
        crate::multires::validate(options, &m)?;
        Ok(Some(m))
    }
}

impl ValueEnum for Transfer {
    fn value_variants<'a>() -> &'a [Self] {
        &Transfer::ALL
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        let help = match self {
            Transfer::Constant => "each fine vertex moves as its cluster's representative",
            Transfer::Smooth => "the same, diffused over about one cluster's width",
            Transfer::Interpolate => {
                "Shepard interpolation over the representative and its coarse neighbours"
            }
        };
        Some(PossibleValue::new(self.name()).help(help))
    }
}

/// The per-level table of a `--multires` run: what each level was, what ran on it, how long it took.
pub fn print_multires(
    out: &mut dyn std::io::Write,
    m: &crate::multires::MultiresStats,
) -> Result<()> {
    let mut text = format!(
        "{:>5} {:>10} {:>10} {:>7} {:>13} {:>5} {:>11} {:>8} {:>9} {:>8}\n",
        "level",
        "vertices",
        "triangles",
        "fixed",
        "method",
        "iter",
        "volume %",
        "build s",
        "transfer s",
        "smooth s"
    );
    for l in &m.levels {
        text += &format!(
            "{:>5} {:>10} {:>10} {:>7} {:>13} {:>5} {:>11} {:>8.3} {:>9.3} {:>8.3}\n",
            l.level,
            l.vertices,
            l.triangles,
            l.fixed_vertices,
            l.method.name(),
            l.iterations,
            fixed(l.volume_pct, 6),
            l.build_seconds,
            l.transfer_seconds,
            l.smooth_seconds
        );
    }
    text += &format!(
        "multires: {} transfer, volume {} before the final correction, relative error {:.1e} after ({:.3} s); {:.3} s in all\n",
        m.options.transfer.name(),
        percent_text(m.volume_pct_before_correction, 6),
        m.volume_error,
        m.correction_seconds,
        m.seconds
    );
    if let Some(r) = &m.refused {
        text += &format!(
            "levels: {} of {} asked: level {} would have {} vertices keeping {} % of the volume, below {} % (too coarse to carry the shape)\n",
            m.levels.len(),
            m.options.levels,
            r.level,
            r.vertices,
            fixed(r.volume_pct, 1),
            fixed(100.0 * crate::multires::MIN_LEVEL_VOLUME, 0)
        );
    }
    out.write_all(text.as_bytes()).map_err(stdout_error)
}

/// Only the methods made for the fine level (cheap Jacobi ones: the point of the mode is to avoid
/// the stencil methods there).
fn fine_method(s: &str) -> std::result::Result<Method, String> {
    let fine: Vec<Method> = Method::accepting(Control::MultiresFine).collect();
    fine.iter().copied().find(|m| m.name() == s).ok_or_else(|| {
        let names: Vec<&str> = fine.iter().map(|m| m.name()).collect();
        format!("expected {}", names.join(" or "))
    })
}
