//! PNG pictures: 8-bit RGB encoded by the `png` crate, written atomically like every output.

use std::io::Write;
use std::path::Path;

use super::atomic;
use crate::error::{Error, Result};

/// Write a `width × height` picture, `rgb` holding `r g b` per pixel row by row from the top, as
/// a PNG at `path` (through a temporary file, see [`super::write_mesh`]'s atomicity).
pub fn write_png(path: &Path, width: usize, height: usize, rgb: &[u8]) -> Result<()> {
    let bytes = encode_png(width, height, rgb)
        .map_err(|what| Error::invalid(path, format!("cannot encode PNG: {what}")))?;
    atomic::write_atomically(path, |out| out.write_all(&bytes))
}

/// The PNG file of a picture (see [`write_png`]); an error for an empty picture, a size PNG cannot
/// hold, or pixels that do not fill it.
pub fn encode_png(width: usize, height: usize, rgb: &[u8]) -> std::result::Result<Vec<u8>, String> {
    if width == 0 || height == 0 {
        return Err(format!("a picture of {width} x {height} pixels is empty"));
    }
    let (w, h) = match (u32::try_from(width), u32::try_from(height)) {
        (Ok(w), Ok(h)) if w <= i32::MAX as u32 && h <= i32::MAX as u32 => (w, h),
        _ => return Err(format!("{width} x {height} pixels is too large for PNG")),
    };
    if Some(rgb.len()) != width.checked_mul(height).and_then(|n| n.checked_mul(3)) {
        return Err(format!(
            "{} bytes for {width} x {height} RGB pixels",
            rgb.len()
        ));
    }
    let mut bytes = Vec::new();
    let mut encoder = ::png::Encoder::new(&mut bytes, w, h);
    encoder.set_color(::png::ColorType::Rgb);
    encoder.set_depth(::png::BitDepth::Eight);
    // fdeflate's fast mode: a few times quicker than the default level on a picture of a
    // large mesh (noise-like grey), for a file a little larger.
    encoder.set_compression(::png::Compression::Fast);
    let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
    writer.write_image_data(rgb).map_err(|e| e.to_string())?;
    writer.finish().map_err(|e| e.to_string())?;
    Ok(bytes)
}
