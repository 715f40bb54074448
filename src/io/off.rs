//! OFF (Object File Format): a magic line, `nv nf ne`, `nv` vertex lines, `nf` face lines
//! `n i0 … i(n-1)`, indices from 0.
//!
//! The `C`, `N` and `ST` variants (`COFF`, `NOFF`, `STCNOFF`, …) add vertex columns (`x y z`, then
//! `nx ny nz` for `N`, then the colour for `C`, then `s t` for `ST`), and faces may carry a colour
//! after their indices (`3 i j k r g b`); extra vertex columns in a file without `C` or `ST` are a
//! colour too. Those numbers are checked to be numbers; a file that has any of them keeps its text
//! in an [`OffLayout`], and an OFF output of it is that text again, byte for byte, except the
//! `x y z` of each vertex (and its `nx ny nz`, recomputed from the new positions). Comments run from
//! `#` to the end of the line. Binary OFF and 4-D / n-D OFF are refused. A UTF-8 byte-order mark is
//! skipped; the magic and counts lines are at most 64 KiB.

use std::io::{self, Write};
use std::sync::Arc;

use super::{
    Digits, FaceBuilder, Faces, Format, MAX_HEADER_LINE, Source, Spelling, bad_index, integer,
    number, show, text_position, tokens, vertex_normals, without_bom, write_encoded,
    write_face_lines, write_xyz,
};
use crate::mesh::{Carried, FileLayout, Mesh};

/// The text of an OFF input that carries more than positions and faces (colours, normals, texture
/// coordinates), kept whole so that an OFF output repeats it with only the coordinates changed.
#[derive(Clone)]
pub(crate) struct OffLayout {
    /// The file as read, byte-order mark included.
    text: Vec<u8>,
    /// Line (from 1) of the first vertex, and of the first face.
    vertex_line: usize,
    face_line: usize,
    vertices: usize,
    faces: usize,
    /// Whether columns 4 to 6 of a vertex line are its normal (`N` in the magic word).
    normals: bool,
    carried: Carried,
}

// By hand: the text can run to gigabytes.
impl std::fmt::Debug for OffLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OffLayout")
            .field("bytes", &self.text.len())
            .field("vertices", &self.vertices)
            .field("faces", &self.faces)
            .field("carried", &self.carried)
            .finish()
    }
}

impl FileLayout for OffLayout {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    fn carries(&self) -> Carried {
        self.carried.clone()
    }
}

/// What a file carries, from its magic word and what its lines hold beyond `x y z` and indices.
fn carried(magic: &[u8], extra_vertex_columns: bool, face_colours: bool) -> Carried {
    let uvs = magic.starts_with(b"ST");
    let colour_column = magic.contains(&b'C');
    Carried {
        uvs,
        // Extra columns in a file whose magic announces neither colour nor texture are a colour
        // (`x y z r g b [a]`, as MeshLab and others write).
        colours: colour_column || face_colours || (extra_vertex_columns && !uvs),
        normals: magic.contains(&b'N'),
        ..Carried::default()
    }
}

/// Lines with their comments removed, skipping those left empty.
fn significant(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    super::lines(bytes)
        .map(|(n, line)| (n, line.split(|&b| b == b'#').next().unwrap_or_default()))
        .filter(|(_, line)| tokens(line).next().is_some())
}

/// The magic word of the OFF family: `OFF` with an optional `ST`, `C`, `N`, `4`, `n` prefix.
fn is_magic(word: &[u8]) -> bool {
    word.len() <= 9
        && word.ends_with(b"OFF")
        && word[..word.len() - 3].iter().all(|b| b"STCN4n".contains(b))
}

/// Whether the text (after any byte-order mark) starts, after comments, with an OFF magic word.
pub(crate) fn has_magic(text: &[u8]) -> bool {
    significant(text)
        .next()
        .and_then(|(_, line)| tokens(line).next())
        .is_some_and(is_magic)
}

/// A header line, refused when it is longer than [`MAX_HEADER_LINE`].
fn header_line((n, line): (usize, &[u8])) -> Result<(usize, &[u8]), String> {
    if line.len() > MAX_HEADER_LINE {
        return Err(format!(
            "line {n} is longer than {} KiB",
            MAX_HEADER_LINE >> 10
        ));
    }
    Ok((n, line))
}

pub(crate) fn read(bytes: &[u8]) -> Result<Mesh, String> {
    let bytes_with_bom = bytes;
    let bytes = without_bom(bytes);
    let mut lines = significant(bytes);
    let last_line = super::lines(bytes).count();
    let (n, line) = header_line(lines.next().ok_or("not an OFF file (no OFF line)")?)?;
    let mut words = tokens(line);
    let magic = words.next().unwrap_or_default();
    if !is_magic(magic) {
        return Err(format!(
            "line {n}: not an OFF file ({} instead of OFF)",
            show(magic)
        ));
    }
    if magic.contains(&b'4') || magic.contains(&b'n') {
        return Err(format!(
            "line {n}: {} (4-D or n-D OFF) is not supported",
            show(magic)
        ));
    }
    // The counts follow the magic word on its line, or on the next line.
    // At most 4 words: 3 counts, and one more to see that there are too many.
    let mut counts: Vec<&[u8]> = words.take(4).collect();
    let mut counts_line = n;
    if counts.first() == Some(&&b"BINARY"[..]) {
        return Err(format!("line {n}: binary OFF is not supported"));
    }
    if counts.is_empty() {
        let (n, line) = header_line(
            lines
                .next()
                .ok_or(format!("line {}: file ends before the counts", last_line))?,
        )?;
        counts = tokens(line).take(4).collect();
        counts_line = n;
    }
    let at = |what: String| format!("counts (line {counts_line}): {what}");
    let counts: Vec<i64> = counts
        .into_iter()
        .map(integer)
        .collect::<Result<_, _>>()
        .map_err(at)?;
    let (nv, nf) = match counts[..] {
        [nv, nf] | [nv, nf, _] => (usize::try_from(nv), usize::try_from(nf)),
        _ => return Err(at("expected 'vertices faces edges'".into())),
    };
    let (Ok(nv), Ok(nf)) = (nv, nf) else {
        return Err(at("negative count".into()));
    };
    if u32::try_from(nv).is_err() {
        return Err(at(format!(
            "{nv} vertices: more than 32-bit indices can address"
        )));
    }

    let mut digits = Digits::default();
    // Reserved up to what the file can hold (a vertex line takes at least 6 bytes, "0 0 0\n", a
    // face line 8): a count the file cannot back fails at the file's real end.
    let mut positions = Vec::with_capacity(nv.min(bytes.len() / 6));
    // Columns besides `x y z` (and the normal, for `N`): a colour or texture coordinates.
    let columns = if magic.contains(&b'N') { 6 } else { 3 };
    let mut extra_vertex_columns = false;
    let mut vertex_line = counts_line + 1;
    for i in 0..nv {
        let (n, line) = lines.next().ok_or_else(|| {
            format!(
                "vertex {i} (line {last_line}): file ends early (the header declares {nv} vertices)"
            )
        })?;
        if i == 0 {
            vertex_line = n;
        }
        let p = text_position(tokens(line), &mut digits)
            .map_err(|what| format!("vertex {i} (line {n}): {what}"))?;
        extra_vertex_columns |= tokens(line).nth(columns).is_some();
        positions.push(p);
    }

    let mut faces = FaceBuilder::with_capacity(nf.min(bytes.len() / 8));
    let mut face_line = None;
    let face_colours = read_faces(&mut lines, nv, nf, last_line, &mut faces, &mut face_line)?;
    if let Some((n, line)) = lines.next() {
        let first = tokens(line).next().unwrap_or_default();
        return Err(format!(
            "line {n}: unexpected data after the last face: {}",
            show(first)
        ));
    }
    let carried = carried(magic, extra_vertex_columns, face_colours);
    let layout = (carried != Carried::default()).then(|| {
        Arc::new(OffLayout {
            text: bytes_with_bom.to_vec(),
            vertex_line,
            face_line: face_line.unwrap_or(usize::MAX),
            vertices: nv,
            faces: nf,
            normals: carried.normals,
            carried,
        }) as Arc<dyn FileLayout>
    });
    let source = Source {
        format: Some(Format::Off),
        precision: digits.precision(),
        decimals: digits.decimals(),
        layout,
        ..Source::default()
    };
    Ok(faces.into_mesh(positions, source))
}

/// Reads `nf` face lines from `lines` into `faces`, noting the line of the first; returns whether
/// any face has a colour after its indices.
fn read_faces<'a>(
    lines: &mut impl Iterator<Item = (usize, &'a [u8])>,
    nv: usize,
    nf: usize,
    last_line: usize,
    faces: &mut FaceBuilder,
    first_line: &mut Option<usize>,
) -> Result<bool, String> {
    let mut corners = Vec::new();
    let mut face_colours = false;
    for f in 0..nf {
        let (n, line) = lines.next().ok_or_else(|| {
            format!("face {f} (line {last_line}): file ends early (the header declares {nf} faces)")
        })?;
        first_line.get_or_insert(n);
        let at = |what: String| format!("face {f} (line {n}): {what}");
        let mut words = tokens(line);
        let k = integer(words.next().unwrap_or_default()).map_err(at)?;
        if k < 3 {
            return Err(at(format!("face has {k} vertices, at least 3 are needed")));
        }
        corners.clear();
        for _ in 0..k {
            let w = words.next().ok_or_else(|| {
                at(format!(
                    "face lists {k} vertices but has only {}",
                    corners.len()
                ))
            })?;
            let v = integer(w).map_err(at)?;
            if !(0..nv as i64).contains(&v) {
                return Err(at(bad_index(v, nv)));
            }
            corners.push(v as u32);
        }
        for colour in words {
            number(colour).map_err(at)?;
            face_colours = true;
        }
        faces.polygon(&corners);
    }
    Ok(face_colours)
}

/// The OFF layout `mesh` came with, if any.
fn layout_of(mesh: &Mesh) -> Option<&OffLayout> {
    let layout = mesh.source.layout.as_deref()?;
    layout.as_any().downcast_ref::<OffLayout>()
}

/// Whether `mesh` (already checked by `io::check_mesh`) can be written as OFF: with its OFF
/// layout, only if its vertices and faces are still those of the file.
pub(crate) fn check_writable(mesh: &Mesh) -> Result<(), String> {
    let Some(layout) = layout_of(mesh) else {
        return Faces::of(mesh).check();
    };
    if layout.vertices != mesh.positions.len() {
        return Err(format!(
            "the mesh has {} vertices but its OFF source has {}; clear mesh.source.layout after \
             adding or removing vertices",
            mesh.positions.len(),
            layout.vertices
        ));
    }
    let text = without_bom(&layout.text);
    let mut lines = significant(text).skip_while(|&(n, _)| n < layout.face_line);
    let mut faces = FaceBuilder::with_capacity(layout.faces);
    let same = read_faces(
        &mut lines,
        layout.vertices,
        layout.faces,
        0,
        &mut faces,
        &mut None,
    )
    .is_ok_and(|_| faces.triangles() == &mesh.triangles[..]);
    if !same {
        return Err(
            "the triangles no longer match the OFF source's faces; clear \
                    mesh.source.layout after changing connectivity"
                .into(),
        );
    }
    Ok(())
}

pub(crate) fn write(out: &mut impl Write, mesh: &Mesh) -> io::Result<()> {
    match layout_of(mesh) {
        Some(layout) => write_layout(out, mesh, layout),
        None => write_plain(out, mesh),
    }
}

/// The layout's text with each vertex line's `x y z` (and normal) replaced by the mesh's.
fn write_layout(out: &mut impl Write, mesh: &Mesh, layout: &OffLayout) -> io::Result<()> {
    let normals = if layout.normals {
        vertex_normals(&mesh.positions, &mesh.triangles)
    } else {
        Vec::new()
    };
    let spelling = Spelling::of(&mesh.source);
    let normal = Spelling {
        decimals: None,
        ..spelling
    };
    let mut v = 0;
    // Line numbers as the reader counted them (a byte-order mark adds no line).
    for (i, line) in layout.text.split_inclusive(|&b| b == b'\n').enumerate() {
        let spans = if i + 1 >= layout.vertex_line && v < layout.vertices {
            token_spans(line)
        } else {
            Vec::new()
        };
        if spans.len() < 3 {
            out.write_all(line)?;
            continue;
        }
        out.write_all(&line[..spans[0].0])?;
        write_xyz(out, mesh.positions[v], spelling)?;
        let mut rest = spans[2].1;
        if layout.normals && spans.len() >= 6 {
            out.write_all(&line[rest..spans[3].0])?;
            write_xyz(out, normals[v], normal)?;
            rest = spans[5].1;
        }
        out.write_all(&line[rest..])?;
        v += 1;
    }
    Ok(())
}

/// The `(start, end)` byte ranges of the tokens of a line before its comment.
fn token_spans(line: &[u8]) -> Vec<(usize, usize)> {
    let code = line.split(|&b| b == b'#').next().unwrap_or_default();
    let mut spans = Vec::new();
    let mut start = None;
    for (i, &b) in code.iter().enumerate() {
        match (b.is_ascii_whitespace(), start) {
            (false, None) => start = Some(i),
            (true, Some(s)) => {
                spans.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        spans.push((s, code.len()));
    }
    spans
}

fn write_plain(out: &mut impl Write, mesh: &Mesh) -> io::Result<()> {
    let faces = Faces::of(mesh);
    writeln!(out, "OFF\n{} {} 0", mesh.positions.len(), faces.len())?;
    let spelling = Spelling::of(&mesh.source);
    // Lines of about 36 and 24 bytes: what sizes the pieces encoded in parallel.
    write_encoded(out, mesh.positions.len(), 36, |range, buf| {
        for &p in &mesh.positions[range] {
            write_xyz(buf, p, spelling)?;
            buf.push(b'\n');
        }
        Ok(())
    })?;
    let face = |out: &mut Vec<u8>, corners: &[u32]| {
        write!(out, "{}", corners.len())?;
        for &v in corners {
            write!(out, " {v}")?;
        }
        out.push(b'\n');
        Ok(())
    };
    write_face_lines(out, &faces, face)
}
