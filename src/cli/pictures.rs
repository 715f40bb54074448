//! `--png FILE` of `smooth` and `compare`: one picture of the meshes from the standard views
//! (front, side, top, iso) in rows, before and after (A and B), and a row coloured by each
//! vertex's signed deviation along the normal of the first with its scale bar. Drawn by [`crate::render`] on the run's threads
//! over the engine's own arrays, written by [`crate::io::write_png`].

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use clap::Args as ClapArgs;
use glam::DVec3;

use crate::cli::output::png_output;
use crate::engine::deviation::Kept;
use crate::engine::{Meter, Moment, Observer, Phase, reduce};
use crate::error::Result;
use crate::mesh::Storage;
use crate::render::{self, Camera, Paint, Row, Scale, View};

/// `--png FILE` and its tile size.
#[derive(Debug, Clone, ClapArgs)]
pub struct PictureArgs {
    /// Write a PNG picture of the mesh from the front, the side, the top and an isometric view (+Y up): with smooth, before and after smoothing and coloured by each vertex's signed deviation along its input normal (blue inwards, red outwards), with its scale; with compare, A, B and B coloured by its deviation from A. Drawn on the CPU, written atomically.
    #[arg(long, value_name = "FILE.png")]
    pub png: Option<PathBuf>,
    /// Pixels of each view's square tile in the --png picture.
    #[arg(long, value_name = "PIXELS", default_value_t = 400, value_parser = crate::cli::shared::whole_in(64, 2048), allow_negative_numbers = true)]
    pub png_size: u64,
}

/// `--png`, resolved.
#[derive(Debug, Clone)]
pub struct PictureConfig {
    pub path: PathBuf,
    /// Pixels of a tile's side.
    pub size: usize,
}

impl PictureArgs {
    /// The picture asked for, its file name checked (`.png` in an existing directory).
    pub fn resolve(&self) -> Result<Option<PictureConfig>> {
        let Some(path) = &self.png else {
            return Ok(None);
        };
        png_output(path)?;
        Ok(Some(PictureConfig {
            path: path.clone(),
            size: self.png_size as usize,
        }))
    }
}

/// What a written picture is, for the command's last lines.
#[derive(Debug, Clone)]
pub struct Drawn {
    pub path: PathBuf,
    pub width: usize,
    pub height: usize,
    /// Seconds spent drawing (both passes over the mesh), composing and encoding.
    pub seconds: f64,
}

/// The rows of a picture as they are drawn, all through the same cameras.
pub struct Sheet {
    cfg: PictureConfig,
    cameras: Vec<Camera>,
    rows: Vec<Row>,
    seconds: f64,
}

impl Sheet {
    /// A picture whose views frame `seen` (a box in each view's axes, see
    /// [`render::view_bounds`]).
    pub fn new(cfg: PictureConfig, seen: &[render::Bounds]) -> Sheet {
        let cameras = render::cameras(&View::STANDARD, seen, cfg.size);
        Sheet {
            cfg,
            cameras,
            rows: Vec::new(),
            seconds: 0.0,
        }
    }

    /// A row of the mesh in grey, labelled `label`; with `distances` (one a vertex), a second row
    /// of it coloured by them, labelled `distance_label`.
    pub fn draw(
        &mut self,
        label: String,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        distances: Option<(&[f32], String)>,
        meter: &Meter,
    ) -> Result<()> {
        let clock = Instant::now();
        let mut paints = vec![Paint::Grey];
        let mut scale = None;
        if let Some((values, what)) = &distances {
            // Magnitudes on a sequential scale from 0; signed values on a diverging one, white
            // at 0.
            let (lo, hi) = range(values);
            let s = Scale::for_range(lo.min(0.0), hi);
            paints.push(Paint::Values { values, scale: s });
            scale = Some((s, what.clone()));
        }
        let mut drawn = render::render(&self.cameras, positions, triangles, &paints, meter)?;
        let coloured = (drawn.len() > 1).then(|| drawn.pop()).flatten();
        let grey = drawn.pop().unwrap_or_default();
        self.rows.push(Row {
            label,
            tiles: grey,
            scale: None,
        });
        if let (Some(tiles), Some(scale)) = (coloured, scale) {
            let (lo, hi) = distances.as_ref().map_or((0.0, 0.0), |(v, _)| range(v));
            let label = match lo < 0.0 {
                true => format!(
                    "{}: from {} to {}",
                    scale.1,
                    render::palette::label(lo),
                    render::palette::label(hi)
                ),
                false => format!("{}: largest {}", scale.1, render::palette::label(hi)),
            };
            self.rows.push(Row {
                label,
                tiles,
                scale: Some(scale),
            });
        }
        self.seconds += clock.elapsed().as_secs_f64();
        Ok(())
    }

    /// Compose the rows under `title` and write the PNG.
    pub fn write(self, title: &str) -> Result<Drawn> {
        let clock = Instant::now();
        let image = render::compose(title, &View::STANDARD, &self.rows);
        crate::io::write_png(
            &self.cfg.path,
            image.width,
            image.height,
            &image.rgb_bytes(),
        )?;
        Ok(Drawn {
            path: self.cfg.path,
            width: image.width,
            height: image.height,
            seconds: self.seconds + clock.elapsed().as_secs_f64(),
        })
    }
}

/// The line a command prints for a picture it wrote.
pub fn print_drawn(out: &mut dyn std::io::Write, d: &Drawn) -> Result<()> {
    writeln!(
        out,
        "picture: {}, {} x {} pixels, {:.3} s",
        d.path.display(),
        d.width,
        d.height,
        d.seconds
    )
    .map_err(crate::cli::output::stdout_error)
}

/// The largest of `values` (0 for none), over chunks.
/// The smallest and largest of `values`, with 0 (NaN ignored).
fn range(values: &[f32]) -> (f32, f32) {
    reduce::map_fold(
        values,
        |_, c| {
            c.iter()
                .fold((0.0f32, 0.0f32), |(lo, hi), &v| (lo.min(v), hi.max(v)))
        },
        (0.0, 0.0),
        |(a, b), (c, d)| (a.min(c), b.max(d)),
    )
}

/// What the deviation row of a run's picture says it shows.
pub const DEVIATION: &str = "deviation along the input normal";

/// The observer of a `smooth --png` run: everything passes on to `inner`; before the iterations
/// the mesh is drawn and its positions kept (in the run's storage: scratch when the run is out of
/// core), after them it is drawn again with each vertex's signed deviation along its input
/// normal.
pub struct RunPictures<'a> {
    pub inner: &'a mut dyn Observer,
    /// The picture's settings and the labels of its rows, before and after.
    pub cfg: Option<PictureConfig>,
    pub labels: (String, String),
    sheet: Option<Sheet>,
    before: Option<Kept>,
}

impl<'a> RunPictures<'a> {
    pub fn new(
        inner: &'a mut dyn Observer,
        cfg: PictureConfig,
        labels: (String, String),
    ) -> RunPictures<'a> {
        RunPictures {
            inner,
            cfg: Some(cfg),
            labels,
            sheet: None,
            before: None,
        }
    }

    /// The sheet drawn, once the run is done (`None` if it never smoothed).
    pub fn into_sheet(self) -> Option<Sheet> {
        self.sheet
    }

    /// `draw` as the `Render` phase of `total` triangles.
    fn phase<T>(&mut self, total: usize, draw: impl FnOnce(&Meter) -> Result<T>) -> Result<T> {
        let meter = Arc::new(Meter::new(total as u64));
        self.inner.phase_start(Phase::Render, &meter);
        let out = draw(&meter);
        self.inner.phase_end(Phase::Render);
        out
    }
}

impl Observer for RunPictures<'_> {
    fn iteration(&mut self, record: &crate::engine::IterationRecord, total: usize) {
        self.inner.iteration(record, total);
    }

    fn iteration_part(&mut self, done: usize, of: usize) {
        self.inner.iteration_part(done, of);
    }

    fn phase_start(&mut self, phase: Phase, meter: &Arc<Meter>) {
        self.inner.phase_start(phase, meter);
    }

    fn phase_end(&mut self, phase: Phase) {
        self.inner.phase_end(phase);
    }

    fn interrupted(&mut self) -> bool {
        self.inner.interrupted()
    }

    fn mesh_at(
        &mut self,
        moment: Moment,
        positions: &[DVec3],
        triangles: &[[u32; 3]],
        storage: &Storage,
    ) -> Result<()> {
        match moment {
            Moment::BeforeSmoothing => {
                let Some(cfg) = self.cfg.take() else {
                    return Ok(());
                };
                let label = self.labels.0.clone();
                let (sheet, before) = self.phase(triangles.len(), |meter| {
                    let seen = render::view_bounds(positions, &View::STANDARD);
                    let mut sheet = Sheet::new(cfg, &seen);
                    sheet.draw(label, positions, triangles, None, meter)?;
                    let clock = Instant::now();
                    let before = Kept::of(storage, positions)?;
                    sheet.seconds += clock.elapsed().as_secs_f64();
                    Ok((sheet, before))
                })?;
                self.sheet = Some(sheet);
                self.before = Some(before);
            }
            Moment::AfterSmoothing => {
                let (Some(mut sheet), Some(before)) = (self.sheet.take(), self.before.take())
                else {
                    return Ok(());
                };
                let label = self.labels.1.clone();
                let sheet = self.phase(triangles.len(), |meter| {
                    let clock = Instant::now();
                    let moved = before.signed(storage, positions, triangles, |d| d as f32)?;
                    drop(before);
                    sheet.seconds += clock.elapsed().as_secs_f64();
                    let distances = Some((&moved[..], DEVIATION.to_string()));
                    sheet.draw(label, positions, triangles, distances, meter)?;
                    Ok(sheet)
                })?;
                self.sheet = Some(sheet);
            }
        }
        Ok(())
    }
}
