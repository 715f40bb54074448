//! STL, binary and ASCII. Written as binary.
//!
//! STL stores each triangle with its own three corners and no vertex ids. The reader merges corners
//! whose coordinates are bitwise-equal `f32`s into one vertex (numbered in order of first
//! appearance), so that the mesh has connectivity: exactly what was written as the same vertex
//! comes back as one. Nearby but different coordinates are not merged, and `0.0` / `-0.0` stay
//! apart. Facet normals are ignored on read (recomputed on write) and the 2-byte attribute is
//! neither kept nor written (always 0).
//!
//! A file whose size is exactly `84 + 50·n`, with `n` the triangle count at byte 80, is binary —
//! even when its 80-byte header starts with `solid`, as many exporters write. Otherwise a file
//! starting with `solid` is ASCII: `solid name`, then `facet normal nx ny nz`, `outer loop`,
//! `vertex x y z` (3 or more; polygons are fan-triangulated), `endloop`, `endfacet`, …,
//! `endsolid name`; several solids in one file are concatenated.

use std::collections::HashMap;
use std::io::{self, Write};

use glam::DVec3;

use super::{FaceBuilder, Format, Source, show, tokens};
use crate::mesh::Mesh;

const HEADER: usize = 84;
const FACET: usize = 50;

/// Whether the file's size is exactly what its triangle count says a binary STL has.
pub(crate) fn is_binary(bytes: &[u8]) -> bool {
    triangle_count(bytes)
        .is_some_and(|n| HEADER as u64 + FACET as u64 * u64::from(n) == bytes.len() as u64)
}

/// Whether the file is ASCII STL: it starts with `solid` and is text. (A binary STL whose header
/// starts with `solid` has zero bytes in its count, attributes and coordinates: a damaged one
/// gets the binary size message rather than an ASCII parse error.)
pub(crate) fn is_ascii(bytes: &[u8]) -> bool {
    let first_line = bytes.trim_ascii_start().split(|&b| b == b'\n').next();
    tokens(first_line.unwrap_or_default()).next() == Some(b"solid")
        && !bytes[..bytes.len().min(1024)].contains(&0)
}

fn triangle_count(bytes: &[u8]) -> Option<u32> {
    bytes
        .get(80..HEADER)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

pub(crate) fn read(bytes: &[u8]) -> Result<Mesh, String> {
    if is_binary(bytes) {
        read_binary(bytes)
    } else if is_ascii(bytes) {
        read_ascii(bytes)
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

/// Merges corners with bitwise-equal coordinates. std's keyed hasher: STL files come from
/// anywhere, and a keyed hash keeps a hostile file from making the merge quadratic.
#[derive(Default)]
struct Merger {
    positions: Vec<DVec3>,
    ids: HashMap<[u32; 3], u32>,
}

impl Merger {
    fn vertex(&mut self, p: [f32; 3]) -> Result<u32, String> {
        let Merger { positions, ids } = self;
        let next = positions.len();
        let id = *ids.entry(p.map(f32::to_bits)).or_insert_with(|| {
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
    let mut words = Words {
        bytes,
        pos: 0,
        line: 1,
    };
    let mut merger = Merger::default();
    let mut faces = FaceBuilder::with_capacity(0);
    let mut corners = Vec::new();
    while let Some(w) = words.next() {
        if w != b"solid" {
            return Err(format!(
                "line {}: expected 'solid', found {}",
                words.line,
                show(w)
            ));
        }
        words.skip_line(); // the solid's name
        loop {
            let f = faces.len();
            match words.next() {
                Some(b"facet") => {}
                Some(b"endsolid") => {
                    words.skip_line();
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
            while words.peek() == Some(b"vertex") {
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

    fn skip_line(&mut self) {
        let rest = &self.bytes[self.pos..];
        self.pos += rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
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

    fn expect(&mut self, f: usize, want: &str) -> Result<(), String> {
        match self.next() {
            Some(w) if w == want.as_bytes() => Ok(()),
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
