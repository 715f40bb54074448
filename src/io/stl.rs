//! STL, binary and ASCII. Written as binary.
//!
//! STL stores each triangle with its own three corners and no vertex ids. The reader merges corners
//! whose coordinates are equal `f32` values into one vertex (numbered in order of first
//! appearance, placed where it first appears), so that the mesh has connectivity: exactly what was
//! written as the same vertex comes back as one. `0.0` and `-0.0` are the same value and merge
//! (apart, they would open a crack along every edge through a zero coordinate); nearby but
//! different coordinates are not merged. Facet normals are ignored on read (recomputed on write)
//! and the 2-byte attribute is neither kept nor written (always 0).
//!
//! A file whose size is exactly `84 + 50·n`, with `n` the triangle count at byte 80, is binary —
//! even when its 80-byte header starts with `solid`, as many exporters write. Otherwise a text
//! file starting with `solid` whose next line starts with `facet` or `endsolid` is ASCII:
//! `solid name`, then `facet normal nx ny nz`, `outer loop`, `vertex x y z` (3 or more; polygons
//! are fan-triangulated), `endloop`, `endfacet`, …, `endsolid name`; several solids in one file
//! are concatenated. Keywords are matched in any case (`SOLID`, `Facet Normal`, …), a UTF-8
//! byte-order mark is skipped, and the `solid` line (the name) is at most 64 KiB.

use std::collections::HashMap;
use std::io::{self, Write};

use glam::DVec3;

use super::{FaceBuilder, Format, MAX_HEADER_LINE, Source, show, without_bom};
use crate::mesh::Mesh;

const HEADER: usize = 84;
const FACET: usize = 50;

/// Whether a file of `len` bytes that starts with `head` has exactly the size its triangle count
/// says a binary STL has.
pub(crate) fn is_binary(head: &[u8], len: u64) -> bool {
    triangle_count(head).is_some_and(|n| HEADER as u64 + FACET as u64 * u64::from(n) == len)
}

/// Whether the text (after any byte-order mark) is ASCII STL: its first word is `solid`, its first
/// KiB has no zero byte, and the first word of its second line is `facet` or `endsolid` (any case)
/// or there is no second line within [`MAX_HEADER_LINE`] bytes (the reader says what is wrong). A
/// binary STL whose header starts with `solid` fails these tests (zero bytes in its count,
/// attributes and coordinates; no keyword after the header), so a damaged one gets the binary
/// size message rather than an ASCII parse error.
pub(crate) fn is_ascii(text: &[u8]) -> bool {
    let mut words = Words::new(text);
    if !(is_text(text) && starts_with_solid(text)) {
        return false;
    }
    words.next();
    let rest = &text[words.pos..];
    match rest
        .iter()
        .take(MAX_HEADER_LINE + 1)
        .position(|&b| b == b'\n')
    {
        None => true,
        Some(end) => Words::new(&rest[end..]).next().is_none_or(|w| {
            w.eq_ignore_ascii_case(b"facet") || w.eq_ignore_ascii_case(b"endsolid")
        }),
    }
}

/// Whether the first KiB has no zero byte: text, not a binary STL (whose count, attributes and
/// small coordinates hold zero bytes).
fn is_text(bytes: &[u8]) -> bool {
    !bytes[..bytes.len().min(1024)].contains(&0)
}

fn starts_with_solid(text: &[u8]) -> bool {
    Words::new(text)
        .next()
        .is_some_and(|w| w.eq_ignore_ascii_case(b"solid"))
}

fn triangle_count(bytes: &[u8]) -> Option<u32> {
    bytes
        .get(80..HEADER)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

pub(crate) fn read(bytes: &[u8]) -> Result<Mesh, String> {
    let text = without_bom(bytes);
    if is_binary(bytes, bytes.len() as u64) {
        read_binary(bytes)
    } else if is_text(text) && starts_with_solid(text) {
        // Its own messages say where the ASCII goes wrong.
        read_ascii(text)
    } else if is_text(text) {
        Err("not an STL file: text that does not start with 'solid'".into())
    } else if let Some(n) = triangle_count(bytes) {
        Err(format!(
            "binary STL: the header declares {n} triangles ({} bytes) but the file has {} bytes",
            HEADER as u64 + FACET as u64 * u64::from(n),
            bytes.len()
        ))
    } else {
        Err(format!(
            "binary STL: {} bytes, shorter than the 84-byte header",
            bytes.len()
        ))
    }
}

/// Merges corners with equal coordinates. std's keyed hasher: STL files come from anywhere, and a
/// keyed hash keeps a hostile file from making the merge quadratic.
#[derive(Default)]
struct Merger {
    positions: Vec<DVec3>,
    ids: HashMap<[u32; 3], u32>,
}

impl Merger {
    fn vertex(&mut self, p: [f32; 3]) -> Result<u32, String> {
        let Merger { positions, ids } = self;
        let next = positions.len();
        // Keyed by bits with -0.0 made +0.0 (`x + 0.0`): equal values, equal keys (NaN never
        // comes here). The position stored is the corner as first seen, sign of zero included.
        let key = p.map(|x| (x + 0.0).to_bits());
        let id = *ids.entry(key).or_insert_with(|| {
            positions.push(DVec3::from_array(p.map(f64::from)));
            next as u32
        });
        if positions.len() > u32::MAX as usize {
            return Err("more distinct vertices than 32-bit indices can address".into());
        }
        Ok(id)
    }

    fn into_mesh(self, faces: FaceBuilder) -> Mesh {
        faces.into_mesh(
            self.positions,
            Source {
                format: Some(Format::Stl),
                ..Source::default()
            },
        )
    }
}

fn not_finite(p: [f32; 3]) -> String {
    format!("coordinate is not finite ({}, {}, {})", p[0], p[1], p[2])
}

fn read_binary(bytes: &[u8]) -> Result<Mesh, String> {
    let facets = &bytes[HEADER..];
    let n = facets.len() / FACET; // the size was checked: exactly n facets
    let mut merger = Merger::default();
    let mut faces = FaceBuilder::with_capacity(n);
    for (i, facet) in facets.chunks_exact(FACET).enumerate() {
        let mut t = [0; 3];
        for (c, id) in t.iter_mut().enumerate() {
            let at = 12 + 12 * c; // after the normal
            let p: [f32; 3] = std::array::from_fn(|k| {
                let b = &facet[at + 4 * k..at + 4 * k + 4];
                f32::from_le_bytes([b[0], b[1], b[2], b[3]])
            });
            if !p.iter().all(|x| x.is_finite()) {
                return Err(format!(
                    "facet {i} (byte {}): {}",
                    HEADER + i * FACET + at,
                    not_finite(p)
                ));
            }
            *id = merger.vertex(p).map_err(|e| format!("facet {i}: {e}"))?;
        }
        faces.triangle(t);
    }
    Ok(merger.into_mesh(faces))
}

fn read_ascii(bytes: &[u8]) -> Result<Mesh, String> {
    let mut words = Words::new(bytes);
    let mut merger = Merger::default();
    let mut faces = FaceBuilder::with_capacity(0);
    let mut corners = Vec::new();
    while let Some(w) = words.next() {
        if !w.eq_ignore_ascii_case(b"solid") {
            return Err(format!(
                "line {}: expected 'solid', found {}",
                words.line,
                show(w)
            ));
        }
        words.skip_name()?;
        loop {
            let f = faces.len();
            match words.next() {
                Some(w) if w.eq_ignore_ascii_case(b"facet") => {}
                Some(w) if w.eq_ignore_ascii_case(b"endsolid") => {
                    words.skip_name()?;
                    break;
                }
                w => return Err(words.unexpected(f, "'facet' or 'endsolid'", w)),
            }
            words.expect(f, "normal")?;
            for _ in 0..3 {
                words.number(f)?;
            }
            words.expect(f, "outer")?;
            words.expect(f, "loop")?;
            corners.clear();
            while words
                .peek()
                .is_some_and(|w| w.eq_ignore_ascii_case(b"vertex"))
            {
                words.next();
                let p = [words.number(f)?, words.number(f)?, words.number(f)?];
                if !p.iter().all(|x| x.is_finite()) {
                    return Err(format!(
                        "facet {f} (line {}): {}",
                        words.line,
                        not_finite(p)
                    ));
                }
                corners.push(
                    merger
                        .vertex(p)
                        .map_err(|e| format!("facet {f} (line {}): {e}", words.line))?,
                );
            }
            words.expect(f, "endloop")?;
            if corners.len() < 3 {
                return Err(format!(
                    "facet {f} (line {}): {} vertices, at least 3 are needed",
                    words.line,
                    corners.len()
                ));
            }
            words.expect(f, "endfacet")?;
            faces.polygon(&corners);
        }
    }
    Ok(merger.into_mesh(faces))
}

/// The whitespace-separated words of an ASCII STL, with the line of the last one read.
#[derive(Clone, Copy)]
struct Words<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Words<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Words {
            bytes,
            pos: 0,
            line: 1,
        }
    }

    fn next(&mut self) -> Option<&'a [u8]> {
        while let Some(&b) = self.bytes.get(self.pos).filter(|b| b.is_ascii_whitespace()) {
            self.line += usize::from(b == b'\n');
            self.pos += 1;
        }
        let rest = &self.bytes[self.pos..];
        let len = rest
            .iter()
            .position(|b| b.is_ascii_whitespace())
            .unwrap_or(rest.len());
        self.pos += len;
        (len > 0).then(|| &rest[..len])
    }

    fn peek(&self) -> Option<&'a [u8]> {
        let mut ahead = *self;
        ahead.next()
    }

    /// Skips the rest of a `solid` or `endsolid` line: the name, at most [`MAX_HEADER_LINE`]
    /// bytes.
    fn skip_name(&mut self) -> Result<(), String> {
        let rest = &self.bytes[self.pos..];
        match rest
            .iter()
            .take(MAX_HEADER_LINE + 1)
            .position(|&b| b == b'\n')
        {
            Some(end) => self.pos += end,
            None if rest.len() <= MAX_HEADER_LINE => self.pos += rest.len(),
            None => {
                return Err(format!(
                    "line {}: the solid's name runs on for more than {} KiB",
                    self.line,
                    MAX_HEADER_LINE >> 10
                ));
            }
        }
        Ok(())
    }

    fn unexpected(&self, f: usize, want: &str, found: Option<&[u8]>) -> String {
        match found {
            Some(w) => format!(
                "facet {f} (line {}): expected {want}, found {}",
                self.line,
                show(w)
            ),
            None => format!(
                "facet {f} (line {}): file ends early, expected {want}",
                self.line
            ),
        }
    }

    /// The keyword `want`, in any case.
    fn expect(&mut self, f: usize, want: &str) -> Result<(), String> {
        match self.next() {
            Some(w) if w.eq_ignore_ascii_case(want.as_bytes()) => Ok(()),
            w => Err(self.unexpected(f, &format!("'{want}'"), w)),
        }
    }

    fn number(&mut self, f: usize) -> Result<f32, String> {
        let w = self.next();
        w.and_then(|w| std::str::from_utf8(w).ok()?.parse().ok())
            .ok_or_else(|| self.unexpected(f, "a number", w))
    }
}

/// Binary STL holds `f32` coordinates and a 32-bit triangle count.
pub(crate) fn check_writable(mesh: &Mesh) -> Result<(), String> {
    if u32::try_from(mesh.triangles.len()).is_err() {
        return Err(format!(
            "{} triangles: more than binary STL can count",
            mesh.triangles.len()
        ));
    }
    super::fits_single(mesh)
}

pub(crate) fn write(out: &mut impl Write, mesh: &Mesh) -> io::Result<()> {
    // Never starting with "solid": some readers take that for ASCII.
    let mut header = [b' '; 80];
    let text = b"binary STL written by vcsmooth";
    header[..text.len()].copy_from_slice(text);
    out.write_all(&header)?;
    out.write_all(&(mesh.triangles.len() as u32).to_le_bytes())?;
    let mut buf = Vec::with_capacity(FACET * 4096);
    for chunk in mesh.triangles.chunks(4096) {
        buf.clear();
        for t in chunk {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            let normal = (b - a).cross(c - a).normalize_or_zero();
            for p in [normal, a, b, c] {
                for x in p.to_array() {
                    buf.extend_from_slice(&(x as f32).to_le_bytes());
                }
            }
            buf.extend_from_slice(&[0, 0]);
        }
        out.write_all(&buf)?;
    }
    Ok(())
}
