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

/// The fewest decimals a text input's coordinates must all have for [`Digits::decimals`] to take
/// them as the file's precision: fewer are as likely a coarse grid as a fixed-point export, and
/// rounding a smoothed mesh to them would undo the smoothing.
const MIN_FIXED_DECIMALS: u8 = 4;

/// What the coordinates of a text input say about how precisely it was written: whether an `f32`
/// reproduces every one ([`Digits::precision`]), and whether all were written with one number of
/// decimals, as a fixed-point export (`%.6f`) writes them ([`Digits::decimals`]).
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct Digits {
    double: bool,
    decimals: Decimals,
}

#[derive(Debug, Default, Clone, Copy, PartialEq)]
enum Decimals {
    #[default]
    Unseen,
    Same(u8),
    Mixed,
}

impl Digits {
    fn see(&mut self, token: &[u8], value: f64) {
        if !self.double && !single_precision_suffices(token, value) {
            self.double = true;
        }
        let here = fixed_decimals(token);
        self.decimals = match (self.decimals, here) {
            (Decimals::Unseen, Some(d)) => Decimals::Same(d),
            (Decimals::Same(d), Some(e)) if d == e => Decimals::Same(d),
            _ => Decimals::Mixed,
        };
    }

    /// `Double` when an `f32` would not reproduce some coordinate's text, else `Float`.
    pub(crate) fn precision(&self) -> Precision {
        match self.double {
            true => Precision::Double,
            false => Precision::Float,
        }
    }

    /// The decimals every coordinate was written with, when they were one number of at least
    /// [`MIN_FIXED_DECIMALS`] and at most 17.
    pub(crate) fn decimals(&self) -> Option<u8> {
        match self.decimals {
            Decimals::Same(d) if (MIN_FIXED_DECIMALS..=17).contains(&d) => Some(d),
            _ => None,
        }
    }
}

/// The digits after the point of a plain decimal token (`-12.3400` has 4); `None` for any other
/// spelling (an exponent, no point, no digits after it).
fn fixed_decimals(token: &[u8]) -> Option<u8> {
    let body = token
        .strip_prefix(b"-")
        .or_else(|| token.strip_prefix(b"+"))
        .unwrap_or(token);
    let point = body.iter().position(|&b| b == b'.')?;
    let (whole, fraction) = (&body[..point], &body[point + 1..]);
    let digits = |s: &[u8]| s.iter().all(u8::is_ascii_digit);
    match !fraction.is_empty() && digits(whole) && digits(fraction) {
        true => u8::try_from(fraction.len()).ok(),
        false => None,
    }
}

/// The position on a text vertex line: its first three numbers. Later numbers (OBJ's `w` or
/// colour, OFF's colour or normal columns) must be numbers and are ignored. Tells `digits` how
/// each coordinate was written.
pub(crate) fn text_position<'a>(
    words: impl Iterator<Item = &'a [u8]>,
    digits: &mut Digits,
) -> std::result::Result<glam::DVec3, String> {
    let mut p = [0.0; 3];
    let mut count = 0;
    for w in words {
        let v = number(w)?;
        if let Some(c) = p.get_mut(count) {
            *c = v;
            digits.see(w, v);
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

/// How a text output spells coordinates: rounded to a fixed number of decimals (a text input's own,
/// see [`crate::mesh::Source::decimals`]), else the shortest text of its precision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Spelling {
    pub(crate) precision: Precision,
    pub(crate) decimals: Option<u8>,
}

impl Spelling {
    /// A mesh's coordinates, as its source says.
    pub(crate) fn of(source: &crate::mesh::Source) -> Spelling {
        Spelling {
            precision: source.precision,
            decimals: source.decimals,
        }
    }

    /// Unit normals: single precision is plenty.
    pub(crate) const NORMAL: Spelling = Spelling {
        precision: Precision::Float,
        decimals: None,
    };
}

/// Writes `x y z` as `spelling` says.
pub(crate) fn write_xyz(
    out: &mut impl Write,
    p: glam::DVec3,
    spelling: Spelling,
) -> std::io::Result<()> {
    match (spelling.decimals, spelling.precision) {
        (Some(d), _) => write!(out, "{} {} {}", Fixed(p.x, d), Fixed(p.y, d), Fixed(p.z, d)),
        (None, Precision::Float) => write!(
            out,
            "{} {} {}",
            F32(p.x as f32),
            F32(p.y as f32),
            F32(p.z as f32)
        ),
        (None, Precision::Double) => write!(out, "{} {} {}", F64(p.x), F64(p.y), F64(p.z)),
    }
}

/// `x` rounded to `d` decimals (correctly, from its exact binary value), in the shortest text of
/// that value: no trailing zeros, no point without decimals, `0` for a value that rounds to zero;
/// from 2^53 on, where an `f64` has no fraction, the shortest text of `x`.
pub(crate) struct Fixed(pub f64, pub u8);

impl fmt::Display for Fixed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // From 2^53 on an `f64` has no fraction: its shortest text is the value itself.
        if self.0.abs() >= 9007199254740992.0 {
            return F64(self.0).fmt(f);
        }
        let mut text = [0u8; 48];
        let capacity = text.len();
        let mut rest = &mut text[..];
        write!(rest, "{:.*}", usize::from(self.1), self.0).map_err(|_| fmt::Error)?;
        let len = capacity - rest.len();
        let mut t = &text[..len];
        if t.contains(&b'.') {
            while let [head @ .., b'0'] = t {
                t = head;
            }
            if let [head @ .., b'.'] = t {
                t = head;
            }
        }
        if t == b"-0" {
            t = b"0";
        }
        f.write_str(std::str::from_utf8(t).map_err(|_| fmt::Error)?)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fixed_point_export_is_told_by_its_decimals() {
        for (token, decimals) in [
            (&b"12.345600"[..], Some(6)),
            (b"-0.1234", Some(4)),
            (b"+3.0", Some(1)),
            (b"3.", None),
            (b".5", Some(1)),
            (b"1e-3", None),
            (b"1.5e3", None),
            (b"42", None),
            (b"-", None),
        ] {
            assert_eq!(fixed_decimals(token), decimals, "{}", show(token));
        }
        let seen = |tokens: &[&[u8]]| {
            let mut d = Digits::default();
            tokens.iter().for_each(|t| d.see(t, number(t).unwrap()));
            d
        };
        assert_eq!(seen(&[b"1.000000", b"-2.500000"]).decimals(), Some(6));
        // Fewer than four decimals may be a coarse grid: never taken as the file's precision.
        assert_eq!(seen(&[b"1.000", b"2.500"]).decimals(), None);
        assert_eq!(seen(&[b"1.0000", b"2.50000"]).decimals(), None);
        assert_eq!(seen(&[b"1.0000", b"2e-4"]).decimals(), None);
        assert_eq!(seen(&[]).decimals(), None);
        assert_eq!(seen(&[b"0.123456789"]).precision(), Precision::Double);
        assert_eq!(seen(&[b"0.1234"]).precision(), Precision::Float);
    }

    #[test]
    fn fixed_text_is_the_shortest_of_the_rounded_value() {
        for (x, d, text) in [
            (1.5, 6, "1.5"),
            (13.514784109449824, 6, "13.514784"),
            (2.0000004, 6, "2"),
            (-0.0000004, 6, "0"),
            (-0.0, 4, "0"),
            (0.00005, 4, "0.0001"),
            (-123456789.123456, 4, "-123456789.1235"),
            (1e300, 4, "1e300"),
            (-9007199254740993.0, 6, "-9007199254740992"),
        ] {
            assert_eq!(Fixed(x, d).to_string(), text, "{x} at {d}");
        }
        // Read back, it is the value rounded to d decimals.
        for x in [0.1, 1.0 / 3.0, -7.123456789, 1234.5678901] {
            let back: f64 = Fixed(x, 6).to_string().parse().unwrap();
            assert!((back - x).abs() <= 5e-7 + 1e-15, "{x} -> {back}");
        }
    }
}
