//! STL, binary and ASCII. Written as binary.
//!
//! STL stores each triangle with its own three corners and no vertex ids. The reader merges corners
//! whose coordinates are equal `f32` values into one vertex (numbered in order of first
//! appearance, placed where it first appears), so that the mesh has connectivity: exactly what was
//! written as the same vertex comes back as one. `0.0` and `-0.0` are the same value and merge
//! (apart, they would open a crack along every edge through a zero coordinate); nearby but
//! different coordinates are not merged. Facet normals are ignored on read (recomputed on write).
//!
//! What else the file holds is kept ([`StlLayout`]) and written back when the output is STL too,
//! in the input's encoding: a binary input's 80-byte header and each facet's 2 attribute bytes
//! (some tools keep a colour there), in facet order; an ASCII input's solids, each with its name
//! and its facets. [`FileLayout::carries`] reports the attribute bytes (`other: ["attribute
//! bytes"]`) when any is non-zero, and colours when the header holds `COLOR=` (the VisCAM /
//! SolidView convention: a default colour in the header, a 15-bit colour in each facet's
//! attribute); an ASCII file carries nothing besides its names. A mesh without an STL layout is
//! written as binary with a header of our own and zero attributes.
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

use std::sync::Arc;

use super::{F32, FaceBuilder, Faces, Format, MAX_HEADER_LINE, Source, show, without_bom};
use crate::mesh::{Carried, FileLayout, Mesh};

const HEADER: usize = 84;
const FACET: usize = 50;

/// What an STL input holds besides its triangles, for an STL output to repeat.
#[derive(Clone)]
pub(crate) enum StlLayout {
    Binary {
        header: [u8; 80],
        /// Each facet's attribute bytes, in facet order.
        attributes: Vec<[u8; 2]>,
    },
    Ascii {
        solids: Vec<Solid>,
    },
}

/// One solid of an ASCII STL: the rest of its `solid` and `endsolid` lines (the name, with its
/// leading space) and how many facets it has.
#[derive(Debug, Clone)]
pub(crate) struct Solid {
    name: Vec<u8>,
    end_name: Vec<u8>,
    facets: usize,
}

// By hand: a binary file's attributes run to millions.
impl std::fmt::Debug for StlLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StlLayout::Binary { attributes, .. } => f
                .debug_struct("StlLayout::Binary")
                .field("facets", &attributes.len())
                .finish(),
            StlLayout::Ascii { solids } => f
                .debug_struct("StlLayout::Ascii")
                .field("solids", solids)
                .finish(),
        }
    }
}

impl FileLayout for StlLayout {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    fn carries(&self) -> Carried {
        let StlLayout::Binary { header, attributes } = self else {
            return Carried::default();
        };
        let any_attribute = attributes.iter().any(|a| *a != [0, 0]);
        Carried {
            colours: header.windows(6).any(|w| w == b"COLOR="),
            other: if any_attribute {
                vec!["attribute bytes".to_string()]
            } else {
                Vec::new()
            },
            ..Carried::default()
        }
    }
}

/// The STL layout `mesh` came with, if any.
fn layout_of(mesh: &Mesh) -> Option<&StlLayout> {
    let layout = mesh.source.layout.as_deref()?;
    layout.as_any().downcast_ref::<StlLayout>()
}

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

    fn into_mesh(self, faces: FaceBuilder, layout: StlLayout) -> Mesh {
        faces.into_mesh(
            self.positions,
            Source {
                format: Some(Format::Stl),
                layout: Some(Arc::new(layout)),
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
    let mut attributes = Vec::with_capacity(n);
    for (i, facet) in facets.chunks_exact(FACET).enumerate() {
        attributes.push([facet[48], facet[49]]);
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
    let mut header = [0; 80];
    header.copy_from_slice(&bytes[..80]);
    Ok(merger.into_mesh(faces, StlLayout::Binary { header, attributes }))
}

fn read_ascii(bytes: &[u8]) -> Result<Mesh, String> {
    let mut words = Words::new(bytes);
    let mut merger = Merger::default();
    let mut faces = FaceBuilder::with_capacity(0);
    let mut corners = Vec::new();
    let mut solids = Vec::new();
    while let Some(w) = words.next() {
        if !w.eq_ignore_ascii_case(b"solid") {
            return Err(format!(
                "line {}: expected 'solid', found {}",
                words.line,
                show(w)
            ));
        }
        let name = words.skip_name()?.to_vec();
        let first = faces.len();
        loop {
            let f = faces.len();
            match words.next() {
                Some(w) if w.eq_ignore_ascii_case(b"facet") => {}
                Some(w) if w.eq_ignore_ascii_case(b"endsolid") => {
                    let end_name = words.skip_name()?.to_vec();
                    solids.push(Solid {
                        name,
                        end_name,
                        facets: f - first,
                    });
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
    Ok(merger.into_mesh(faces, StlLayout::Ascii { solids }))
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
    /// bytes, returned without the line's end (`\r` of CRLF included).
    fn skip_name(&mut self) -> Result<&'a [u8], String> {
        let rest = &self.bytes[self.pos..];
        let len = match rest
            .iter()
            .take(MAX_HEADER_LINE + 1)
            .position(|&b| b == b'\n')
        {
            Some(end) => end,
            None if rest.len() <= MAX_HEADER_LINE => rest.len(),
            None => {
                return Err(format!(
                    "line {}: the solid's name runs on for more than {} KiB",
                    self.line,
                    MAX_HEADER_LINE >> 10
                ));
            }
        };
        self.pos += len;
        Ok(rest[..len].strip_suffix(b"\r").unwrap_or(&rest[..len]))
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

/// Binary STL holds `f32` coordinates and a 32-bit triangle count; an STL layout's facets must
/// still be the mesh's.
pub(crate) fn check_writable(mesh: &Mesh) -> Result<(), String> {
    if u32::try_from(mesh.triangles.len()).is_err() {
        return Err(format!(
            "{} triangles: more than binary STL can count",
            mesh.triangles.len()
        ));
    }
    let (facets, have) = match layout_of(mesh) {
        Some(StlLayout::Binary { attributes, .. }) => (attributes.len(), mesh.triangles.len()),
        Some(StlLayout::Ascii { solids }) => {
            let faces = Faces::of(mesh);
            faces.check()?;
            (solids.iter().map(|s| s.facets).sum(), faces.len())
        }
        None => (0, 0),
    };
    if facets != have {
        return Err(format!(
            "the mesh has {have} faces but its STL source has {facets} facets; clear \
             mesh.source.layout after changing connectivity"
        ));
    }
    super::fits_single(mesh)
}

pub(crate) fn write(out: &mut impl Write, mesh: &Mesh) -> io::Result<()> {
    match layout_of(mesh) {
        Some(StlLayout::Binary { header, attributes }) => {
            write_binary(out, mesh, header, |i| attributes[i])
        }
        Some(StlLayout::Ascii { solids }) => write_ascii(out, mesh, solids),
        None => {
            // Never starting with "solid": some readers take that for ASCII.
            let mut header = [b' '; 80];
            let text = b"binary STL written by vcsmooth";
            header[..text.len()].copy_from_slice(text);
            write_binary(out, mesh, &header, |_| [0, 0])
        }
    }
}

/// Each face as an ASCII facet with its corners (polygons as they came) under its solid.
fn write_ascii(out: &mut impl Write, mesh: &Mesh, solids: &[Solid]) -> io::Result<()> {
    let faces = Faces::of(mesh);
    let mut solid = solids.iter().map(|s| (s, s.facets));
    let mut current: Option<(&Solid, usize)> = None;
    let close = |out: &mut dyn Write, s: &Solid| -> io::Result<()> {
        out.write_all(b"endsolid")?;
        out.write_all(&s.end_name)?;
        out.write_all(b"\n")
    };
    let open = |out: &mut dyn Write, s: &Solid| -> io::Result<()> {
        out.write_all(b"solid")?;
        out.write_all(&s.name)?;
        out.write_all(b"\n")
    };
    let f32s = |p: DVec3| p.to_array().map(|x| F32(x as f32));
    faces.try_for_each(|corners| {
        // Close the solids that are complete and open the next one with facets left.
        while current.is_none_or(|(_, left)| left == 0) {
            if let Some((s, _)) = current {
                close(out, s)?;
            }
            let (s, n) = solid
                .next()
                .ok_or_else(|| io::Error::other("facets beyond the solids"))?;
            open(out, s)?;
            current = Some((s, n));
        }
        let p = |k: usize| mesh.positions[corners[k] as usize];
        // The polygon's normal: the sum of its fan's cross products.
        let normal = (2..corners.len())
            .map(|k| (p(k - 1) - p(0)).cross(p(k) - p(0)))
            .sum::<DVec3>()
            .normalize_or_zero();
        let [x, y, z] = f32s(normal);
        writeln!(out, "facet normal {x} {y} {z}\nouter loop")?;
        for k in 0..corners.len() {
            let [x, y, z] = f32s(p(k));
            writeln!(out, "vertex {x} {y} {z}")?;
        }
        out.write_all(b"endloop\nendfacet\n")?;
        if let Some((_, left)) = &mut current {
            *left -= 1;
        }
        Ok::<(), io::Error>(())
    })?;
    // The solids left: the current one, and any without facets.
    if let Some((s, _)) = current {
        close(out, s)?;
    }
    for (s, _) in solid {
        open(out, s)?;
        close(out, s)?;
    }
    Ok(())
}

fn write_binary(
    out: &mut impl Write,
    mesh: &Mesh,
    header: &[u8; 80],
    attribute: impl Fn(usize) -> [u8; 2],
) -> io::Result<()> {
    out.write_all(header)?;
    out.write_all(&(mesh.triangles.len() as u32).to_le_bytes())?;
    let mut buf = Vec::with_capacity(FACET * 4096);
    for (k, chunk) in mesh.triangles.chunks(4096).enumerate() {
        buf.clear();
        for (i, t) in chunk.iter().enumerate() {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            let normal = (b - a).cross(c - a).normalize_or_zero();
            for p in [normal, a, b, c] {
                for x in p.to_array() {
                    buf.extend_from_slice(&(x as f32).to_le_bytes());
                }
            }
            buf.extend_from_slice(&attribute(k * 4096 + i));
        }
        out.write_all(&buf)?;
    }
    Ok(())
}
