//! The renderer's threads: triangles drawn in fixed chunks on the current rayon pool, pixel rows
//! shaded in parallel. A frame is a minimum over its triangles and a pixel a function of its
//! samples, so the pictures are the same for any thread count.

use glam::DVec3;
use rayon::prelude::*;

use super::camera::{Bounds, View};
use super::image::Image;
use super::raster::{self, Frame, Paint};
use crate::meter::{Meter, STEP};

/// The box of `points` in the axes of each of `views`, over chunks (minima and maxima: exact
/// whatever the chunking).
pub fn view_bounds(points: &[DVec3], views: &[View]) -> Vec<Bounds> {
    points
        .par_chunks(STEP)
        .map(|c| {
            views
                .iter()
                .map(|&v| Bounds::in_view(c, v))
                .collect::<Vec<_>>()
        })
        .reduce(
            || vec![Bounds::EMPTY; views.len()],
            |a, b| a.into_iter().zip(b).map(|(x, y)| x.union(y)).collect(),
        )
}

/// Draw every triangle into every frame; `meter` counts the triangles drawn.
pub fn draw(frames: &[Frame], positions: &[DVec3], triangles: &[[u32; 3]], meter: &Meter) {
    triangles
        .par_chunks(STEP)
        .enumerate()
        .for_each(|(c, chunk)| {
            raster::draw_triangles(frames, positions, c * STEP, chunk);
            meter.add(chunk.len() as u64);
        });
}

/// The pictures of `frame` under each of `paints`, at `factor × factor` samples a pixel, shaded
/// together: each visible triangle is looked up once for all of them.
pub fn shade(
    frame: &Frame,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    paints: &[Paint],
    factor: usize,
) -> Vec<Image> {
    let (w, h) = (frame.camera.width / factor, frame.camera.height / factor);
    // Row by row, each paint's row beside the others'.
    let mut rows = vec![[0; 3]; w * h * paints.len()];
    if w > 0 && !paints.is_empty() {
        rows.par_chunks_mut(w * paints.len())
            .enumerate()
            .for_each(|(py, out)| {
                raster::shade_row(frame, positions, triangles, paints, factor, py, out)
            });
    }
    (0..paints.len())
        .map(|k| Image {
            width: w,
            height: h,
            pixels: rows
                .chunks((w * paints.len()).max(1))
                .flat_map(|row| &row[k * w..(k + 1) * w])
                .copied()
                .collect(),
        })
        .collect()
}
