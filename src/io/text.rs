//! Text the readers and writers share: tokens, numbers and positions of text lines, how a token
//! is shown in an error, and the shortest text that reads back to a coordinate.

use std::fmt;
use std::io::Write;

use crate::mesh::{Mesh, Precision};

/// Why 0-based index `v` is not a vertex of a mesh with `vertices` vertices.
pub(crate) fn bad_index(v: i64, vertices: usize) -> String {
    if v < 0 {
        format!("vertex index {v} is negative")
    } else {
        format!("vertex index {v} out of range (0..{vertices})")
    }
}

/// The longest header line a reader accepts (a PLY header line, OFF's magic and counts lines,
/// ASCII STL's `solid` line): a file whose header runs on is refused once this much is read.
pub(crate) const MAX_HEADER_LINE: usize = 64 << 10;

/// Text without its UTF-8 byte-order mark, if it has one.
pub(crate) fn without_bom(text: &[u8]) -> &[u8] {
    text.strip_prefix(b"\xef\xbb\xbf").unwrap_or(text)
}

/// Text lines numbered from 1, without their `\n` (a trailing `\r` is left for the whitespace
/// tokeniser to drop, so CRLF files read like LF files).
pub(crate) fn lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .map(|(i, line)| (i + 1, line))
}

/// The whitespace-separated tokens of a line.
pub(crate) fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// A token for an error message: quoted, escaped and shortened, so that the message stays on one
/// line whatever the file contains.
pub(crate) fn show(token: &[u8]) -> String {
    const MAX: usize = 24;
    let cut = &token[..token.len().min(MAX)];
    let more = if token.len() > MAX { "…" } else { "" };
    let text = match std::str::from_utf8(cut) {
        Ok(text) => Some(text),
        // The cut split a character: the text before it.
        Err(e) if e.error_len().is_none() => std::str::from_utf8(&cut[..e.valid_up_to()]).ok(),
        Err(_) => None,
    };
    match text {
        Some(text) => format!("{text:?}{more}"),
        // Not text (a binary file read as text): its bytes, escaped.
        None => format!("\"{}\"{more}", cut.escape_ascii()),
    }
}

/// A decimal number token (`f64`), or a message saying it is not one.
pub(crate) fn number(token: &[u8]) -> std::result::Result<f64, String> {
    std::str::from_utf8(token)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("{} is not a number", show(token)))
}

/// An integer token, or a message saying it is not one.
pub(crate) fn integer(token: &[u8]) -> std::result::Result<i64, String> {
    std::str::from_utf8(token)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("{} is not an integer", show(token)))
}

/// The position on a text vertex line: its first three numbers. Later numbers (OBJ's `w` or
/// colour, OFF's colour or normal columns) must be numbers and are ignored. Sets `precision` to
/// `Double` when an `f32` would not reproduce a coordinate's text.
pub(crate) fn text_position<'a>(
    words: impl Iterator<Item = &'a [u8]>,
    precision: &mut Precision,
) -> std::result::Result<glam::DVec3, String> {
    let mut p = [0.0; 3];
    let mut count = 0;
    for w in words {
        let v = number(w)?;
        if let Some(c) = p.get_mut(count) {
            *c = v;
            if !single_precision_suffices(w, v) {
                *precision = Precision::Double;
            }
        }
        count += 1;
    }
    if count < 3 {
        return Err(format!("{count} coordinates, 3 are needed"));
    }
    let p = glam::DVec3::from_array(p);
    if !p.is_finite() {
        return Err(format!(
            "coordinate is not finite ({}, {}, {})",
            p.x, p.y, p.z
        ));
    }
    Ok(p)
}

/// Whether a float output (`f32`, shortest text) reproduces the coordinate that `token` spells,
/// i.e. whether a text input may be written back in single precision without losing digits.
fn single_precision_suffices(token: &[u8], value: f64) -> bool {
    // A decimal with at most 6 significant digits survives decimal → f32 → decimal (FLT_DIG) in
    // the normal range; only longer tokens need the exact check.
    let digits = token
        .iter()
        .take_while(|&&b| b != b'e' && b != b'E')
        .filter(|b| b.is_ascii_digit())
        .skip_while(|&&b| b == b'0')
        .count();
    if digits <= 6 && (value == 0.0 || (1e-30..1e30).contains(&value.abs())) {
        return true;
    }
    let single = value as f32;
    single.is_finite() && F32(single).to_string().parse::<f64>() == Ok(value)
}

/// The shortest text that reads back to the same `f32` (Rust's `{}` and `{:e}` are shortest
/// round-trip); the exponent form keeps very large and very small numbers short.
pub(crate) struct F32(pub f32);

/// [`F32`] for `f64`.
pub(crate) struct F64(pub f64);

fn shortest(
    f: &mut fmt::Formatter<'_>,
    v: impl fmt::Display + fmt::LowerExp,
    magnitude: f64,
) -> fmt::Result {
    if magnitude == 0.0 || (1e-5..1e16).contains(&magnitude) {
        write!(f, "{v}")
    } else {
        write!(f, "{v:e}")
    }
}

impl fmt::Display for F32 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        shortest(f, self.0, self.0.abs().into())
    }
}

impl fmt::Display for F64 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        shortest(f, self.0, self.0.abs())
    }
}

/// Writes `x y z` in the text precision `precision` asks for.
pub(crate) fn write_xyz(
    out: &mut impl Write,
    p: glam::DVec3,
    precision: Precision,
) -> std::io::Result<()> {
    match precision {
        Precision::Float => write!(
            out,
            "{} {} {}",
            F32(p.x as f32),
            F32(p.y as f32),
            F32(p.z as f32)
        ),
        Precision::Double => write!(out, "{} {} {}", F64(p.x), F64(p.y), F64(p.z)),
    }
}

/// Whether every coordinate survives rounding to `f32` (does not overflow to infinity).
pub(crate) fn fits_single(mesh: &Mesh) -> std::result::Result<(), String> {
    match mesh.positions.iter().position(|p| !p.as_vec3().is_finite()) {
        Some(i) => Err(format!(
            "vertex {i}: coordinate {} does not fit single precision (set mesh.source.precision to Double)",
            mesh.positions[i]
        )),
        None => Ok(()),
    }
}

/// Area-weighted vertex normals, normalised; `0` where the faces around a vertex have no area
/// (the one definition, [`crate::metrics::deviation::vertex_normals`]).
pub(crate) fn vertex_normals(
    positions: &[glam::DVec3],
    triangles: &[[u32; 3]],
) -> Vec<glam::DVec3> {
    crate::metrics::deviation::vertex_normals(positions, triangles)
}
