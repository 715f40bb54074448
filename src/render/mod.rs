//! Pictures of a mesh, drawn on the CPU: a small software rasteriser over the positions and
//! triangles as they lie (the engine's plan-order arrays, in memory or in scratch files, are
//! read in place, never copied), with no display and no GPU.
//!
//! - [`camera`]: the standard [`View`]s (front, side, top, iso) and the orthographic [`Camera`]
//!   that frames a [`Bounds`] in one.
//! - [`raster`]: the kernels: a triangle drawn into a frame of visibility samples (a z-buffer
//!   keyed by depth and triangle index), a sample shaded by a headlight, grey or by a per-vertex
//!   value through a colour map ([`Paint`]).
//! - `lanes`: the first test of a triangle against four frames at once, each vertex placed among
//!   the sample centres once, in SSE2's lanes on x86-64.
//! - `parallel`: the threads: triangles in fixed chunks, pixel rows.
//! - [`palette`]: colour maps over a range ([`Scale`]) and their round tick values.
//! - [`font`]: a 5 × 7 bitmap font for labels; [`sheet`]: tiles, labels and scale bars in one
//!   picture; [`image`]: the RGB picture itself.
//!
//! A picture is the same, byte for byte, for any thread count: each sample keeps the nearest
//! triangle by an atomic minimum over a key that orders depth and then triangle index, which no
//! order of drawing changes. Each pixel is the mean of [`SAMPLES`]² samples.
//!
//! Writing a picture to a file is [`crate::io::write_png`]'s.

pub mod camera;
pub mod font;
pub mod image;
mod lanes;
pub mod palette;
mod parallel;
pub mod raster;
pub mod sheet;

use glam::DVec3;

pub use camera::{Bounds, Camera, View};
pub use image::{Image, Rgb};
pub use palette::{Palette, Scale};
pub use raster::Paint;
pub use sheet::{Row, compose};

use crate::error::{Error, Result};
use crate::meter::Meter;

/// Samples per pixel along each axis.
pub const SAMPLES: usize = 3;

/// The box of `points` in the axes of each of `views` ([`Bounds::in_view`]), on the current
/// rayon pool: what [`cameras`] frames.
pub fn view_bounds(points: &[DVec3], views: &[View]) -> Vec<Bounds> {
    parallel::view_bounds(points, views)
}

/// A camera for each of `views`, framing `seen[k]` (the points' box in view `k`'s axes, see
/// [`view_bounds`]) in a tile of `size × size` pixels: each view as large as the mesh allows.
pub fn cameras(views: &[View], seen: &[Bounds], size: usize) -> Vec<Camera> {
    views
        .iter()
        .zip(seen)
        .map(|(&v, &b)| Camera::framing(v, b, size, size))
        .collect()
}

/// Pictures of the mesh of `positions` and `triangles` through each of `cameras`, once under each
/// of `paints`: `result[paint][camera]`. The triangles are drawn once (on the current rayon pool,
/// `meter` counting them) for all the cameras and paints.
pub fn render(
    cameras: &[Camera],
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    paints: &[Paint],
    meter: &Meter,
) -> Result<Vec<Vec<Image>>> {
    if triangles.len() as u64 > raster::MAX_TRIANGLES {
        return Err(Error::resource(format!(
            "{} triangles are more than a picture can tell apart ({})",
            triangles.len(),
            raster::MAX_TRIANGLES
        )));
    }
    for paint in paints {
        if let Paint::Values { values, .. } = paint
            && values.len() != positions.len()
        {
            return Err(Error::parameter(
                "values",
                format!(
                    "{} values for {} vertices: a picture colours every vertex",
                    values.len(),
                    positions.len()
                ),
            ));
        }
    }
    let frames: Vec<raster::Frame> = cameras
        .iter()
        .map(|c| raster::Frame::new(c.scaled(SAMPLES)))
        .collect();
    parallel::draw(&frames, positions, triangles, meter);
    // Shaded frame by frame, all the paints at once; handed back paint by paint.
    let mut shaded: Vec<std::vec::IntoIter<Image>> = frames
        .iter()
        .map(|f| parallel::shade(f, positions, triangles, paints, SAMPLES).into_iter())
        .collect();
    Ok(paints
        .iter()
        .map(|_| shaded.iter_mut().filter_map(Iterator::next).collect())
        .collect())
}

/// A fixed pseudo-random sequence in [0, 1) (xorshift), for the renderer's tests.
#[cfg(test)]
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}
