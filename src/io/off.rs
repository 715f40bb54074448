//! OFF (Object File Format): a magic line, `nv nf ne`, `nv` vertex lines, `nf` face lines
//! `n i0 … i(n-1)`, indices from 0.
//!
//! The `C`, `N` and `ST` variants (`COFF`, `NOFF`, `STCNOFF`, …) add vertex columns, and faces may
//! carry a colour after their indices: those numbers are checked to be numbers and ignored.
//! Comments run from `#` to the end of the line. Binary OFF and 4-D / n-D OFF are refused. A
//! UTF-8 byte-order mark is skipped; the magic and counts lines are at most 64 KiB.

use std::io::{self, Write};

use super::{
    FaceBuilder, Faces, Format, MAX_HEADER_LINE, Precision, Source, bad_index, integer, number,
    show, text_position, tokens, without_bom, write_xyz,
};
use crate::mesh::Mesh;

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

    let mut precision = Precision::Float;
    // Reserved up to what the file can hold (a vertex line takes at least 6 bytes, "0 0 0\n", a
    // face line 8): a count the file cannot back fails at the file's real end.
    let mut positions = Vec::with_capacity(nv.min(bytes.len() / 6));
    for i in 0..nv {
        let (n, line) = lines.next().ok_or_else(|| {
            format!(
                "vertex {i} (line {last_line}): file ends early (the header declares {nv} vertices)"
            )
        })?;
        let p = text_position(tokens(line), &mut precision)
            .map_err(|what| format!("vertex {i} (line {n}): {what}"))?;
        positions.push(p);
    }

    let mut faces = FaceBuilder::with_capacity(nf.min(bytes.len() / 8));
    let mut corners = Vec::new();
    for f in 0..nf {
        let (n, line) = lines.next().ok_or_else(|| {
            format!("face {f} (line {last_line}): file ends early (the header declares {nf} faces)")
        })?;
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
        }
        faces.polygon(&corners);
    }
    if let Some((n, line)) = lines.next() {
        let first = tokens(line).next().unwrap_or_default();
        return Err(format!(
            "line {n}: unexpected data after the last face: {}",
            show(first)
        ));
    }
    let source = Source {
        format: Some(Format::Off),
        precision,
        ..Source::default()
    };
    Ok(faces.into_mesh(positions, source))
}

pub(crate) fn write(out: &mut impl Write, mesh: &Mesh) -> io::Result<()> {
    let faces = Faces::of(mesh);
    writeln!(out, "OFF\n{} {} 0", mesh.positions.len(), faces.len())?;
    for &p in &mesh.positions {
        write_xyz(out, p, mesh.source.precision)?;
        out.write_all(b"\n")?;
    }
    faces.try_for_each(|corners| {
        write!(out, "{}", corners.len())?;
        for &v in corners {
            write!(out, " {v}")?;
        }
        out.write_all(b"\n")
    })
}
