//! A sheet: pictures of the same views tiled in rows under a title and the views' names, each
//! row under its label, and beside a row of colour-mapped tiles the scale bar of its
//! colour map with round values.

use super::camera::View;
use super::font::{self, draw_text, line_height, text_width};
use super::image::{INK, Image, Rgb, WHITE};
use super::palette::{Scale, label};

/// One row of a sheet: a tile per view.
#[derive(Debug, Clone)]
pub struct Row {
    pub label: String,
    pub tiles: Vec<Image>,
    /// The colour map of the tiles and what it measures, for the bar beside them.
    pub scale: Option<(Scale, String)>,
}

/// Margin round the sheet and gap between tiles, in pixels.
const MARGIN: usize = 16;
const GAP: usize = 10;
/// Size of the title's and labels' glyph pixels.
const TEXT: usize = 2;
/// Width of the scale bar, length of its ticks.
const BAR: usize = 18;
const TICK: usize = 5;
/// Rounded values a bar labels, about.
const TICKS: usize = 6;
const FRAME: Rgb = [200, 200, 200];

/// Compose `rows` (every row a tile per view of `views`, all tiles of one size) under `title`.
pub fn compose(title: &str, views: &[View], rows: &[Row]) -> Image {
    let (tw, th) = rows
        .iter()
        .flat_map(|r| r.tiles.first())
        .map(|t| (t.width, t.height))
        .next()
        .unwrap_or((0, 0));
    let columns = views.len();
    let tiles_w = columns * tw + columns.saturating_sub(1) * GAP;
    let bar_w = rows
        .iter()
        .filter_map(|r| r.scale.as_ref())
        .map(|(scale, what)| {
            let labels = scale.ticks(TICKS).into_iter().map(|v| label(v).len());
            let widest = labels.max().unwrap_or(0);
            let numbers = BAR + TICK + 4 + text_width(&"0".repeat(widest), TEXT);
            numbers.max(text_width(what, TEXT)) + GAP
        })
        .max()
        .map_or(0, |w| GAP * 2 + w);
    let width = MARGIN * 2 + tiles_w + bar_w;
    let line = line_height(TEXT);
    let row_h = line + GAP / 2 + th + GAP * 2;
    // The title, then a line naming the views above their columns.
    let height = MARGIN * 2 + 2 * (line + GAP) + rows.len() * row_h;
    let mut sheet = Image::filled(width, height, WHITE);
    let chars = |w: usize| w / (font::ADVANCE * TEXT);
    let title = font::fit(title, chars(width - 2 * MARGIN));
    draw_text(&mut sheet, MARGIN as i64, MARGIN as i64, &title, TEXT, INK);

    let mut y = MARGIN + line + GAP;
    for (k, view) in views.iter().enumerate() {
        let x = MARGIN + k * (tw + GAP);
        let name = font::fit(view.name(), chars(tw));
        draw_text(&mut sheet, x as i64, y as i64, &name, TEXT, INK);
    }
    y += line + GAP;
    for row in rows {
        let label = font::fit(&row.label, chars(tiles_w));
        draw_text(&mut sheet, MARGIN as i64, y as i64, &label, TEXT, INK);
        let top = y + line + GAP / 2;
        for (k, tile) in row.tiles.iter().take(columns).enumerate() {
            let x = MARGIN + k * (tw + GAP);
            sheet.paste(tile, x as i64, top as i64);
            sheet.frame_rect(x as i64, top as i64, tw as i64, th as i64, FRAME);
        }
        if let Some((scale, what)) = &row.scale {
            let x = MARGIN + tiles_w + GAP * 2;
            draw_text(&mut sheet, x as i64, top as i64 + 6, what, TEXT, INK);
            let bar_top = top + 6 + line + GAP;
            let bar_h = th.saturating_sub(bar_top - top + GAP + line / 2);
            draw_bar(&mut sheet, scale, x, bar_top, bar_h);
        }
        y += row_h;
    }
    sheet
}

/// The scale bar of `scale`, `h` pixels high with its top left corner at (`x`, `top`): its
/// highest value at the top, labels to its right.
fn draw_bar(sheet: &mut Image, scale: &Scale, x: usize, top: usize, h: usize) {
    if h < 2 {
        return;
    }
    for r in 0..h {
        let t = 1.0 - r as f32 / (h - 1) as f32;
        let c = scale.palette.at(t);
        sheet.fill_rect(x as i64, (top + r) as i64, BAR as i64, 1, c);
    }
    sheet.frame_rect(
        x as i64 - 1,
        top as i64 - 1,
        BAR as i64 + 2,
        h as i64 + 2,
        INK,
    );
    let glyph_h = (font::GLYPH_H * TEXT) as i64;
    for v in scale.ticks(TICKS) {
        let r = (top as f32 + (1.0 - scale.position(v)) * (h - 1) as f32).round() as i64;
        let right = (x + BAR) as i64;
        sheet.fill_rect(right, r, TICK as i64, 1, INK);
        let text = label(v);
        draw_text(
            sheet,
            right + (TICK + 4) as i64,
            r - glyph_h / 2,
            &text,
            TEXT,
            INK,
        );
    }
}
