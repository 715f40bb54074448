//! Wavefront OBJ: `v` and `f` statements.
//!
//! - `v x y z …`: the first three numbers are the position; further numbers (a `w`, or the common
//!   `r g b` extension) are checked to be numbers and ignored.
//! - `f a b c …`: each corner is `i`, `i/t`, `i//n` or `i/t/n`; `i` counts from 1, and a negative
//!   `i` counts back from the last vertex defined so far. Texture and normal references must be
//!   integers and are otherwise ignored. Positive indices may refer to vertices defined later.
//! - Every other statement (`vt`, `vn`, `g`, `o`, `s`, `mtllib`, `usemtl`, `l`, `p`, …) and
//!   everything after a `#` is ignored, and so is a statement with a keyword OBJ does not define,
//!   as long as the keyword is a name (ASCII letters, digits and `_`, starting with a letter or
//!   `_`): exporters add their own statements, and a reader that knows fewer keywords than the
//!   writer must still read the mesh.
//! - A line that starts with anything else (a number, punctuation, a zero byte, bytes that are
//!   not ASCII) is not OBJ, and is refused: a binary file or prose given an `.obj` name stops at
//!   its first such line. A file with no `v` and no `f` statement at all is refused too (`no OBJ
//!   vertex or face found`): there is nothing OBJ in it, and it would otherwise read as an empty
//!   mesh. A UTF-8 byte-order mark at the start is skipped.

use std::io::{self, Write};

use glam::DVec3;

use super::{
    FaceBuilder, Faces, Format, Precision, Source, integer, lines, show, text_position, tokens,
    without_bom, write_xyz,
};
use crate::mesh::Mesh;

/// Whether `word` can be an OBJ keyword: a name of ASCII letters, digits and `_`, not starting
/// with a digit.
fn is_keyword(word: &[u8]) -> bool {
    word.first()
        .is_some_and(|b| b.is_ascii_alphabetic() || *b == b'_')
        && word.iter().all(|b| b.is_ascii_alphanumeric() || *b == b'_')
}

pub(crate) fn read(bytes: &[u8]) -> Result<Mesh, String> {
    let bytes = without_bom(bytes);
    let mut positions: Vec<DVec3> = Vec::new();
    let mut faces = FaceBuilder::with_capacity(0);
    let mut precision = Precision::Float;
    let mut corners = Vec::new();
    // The largest positive index with its face and line: forward references are legal, so
    // positive indices can only be checked once every vertex is known.
    let mut furthest = (0, 0, 0);
    for (n, line) in lines(bytes) {
        let line = line.split(|&b| b == b'#').next().unwrap_or_default();
        let mut words = tokens(line);
        match words.next() {
            Some(b"v") => {
                let i = positions.len();
                let p = text_position(words, &mut precision)
                    .map_err(|what| format!("vertex {i} (line {n}): {what}"))?;
                positions.push(p);
            }
            Some(b"f") => {
                let f = faces.len();
                let at = |what: String| format!("face {f} (line {n}): {what}");
                corners.clear();
                for w in words {
                    let mut refs = w.split(|&b| b == b'/');
                    let v = integer(refs.next().unwrap_or_default()).map_err(at)?;
                    for (k, r) in refs.enumerate() {
                        if k > 1 {
                            return Err(at(format!(
                                "corner {} has more than 3 parts",
                                super::show(w)
                            )));
                        }
                        if !r.is_empty() {
                            integer(r).map_err(at)?;
                        }
                    }
                    let defined = positions.len() as i64;
                    let index = match v {
                        0 => return Err(at("vertex index 0 (OBJ indices start at 1)".into())),
                        v if v < 0 && v + defined < 0 => {
                            return Err(at(format!(
                                "vertex index {v} points before the first vertex ({defined} defined so far)"
                            )));
                        }
                        v if v < 0 => v + defined,
                        v => {
                            if v > furthest.0 {
                                furthest = (v, f, n);
                            }
                            v - 1
                        }
                    };
                    corners.push(
                        u32::try_from(index)
                            .map_err(|_| at(format!("vertex index {v} out of range")))?,
                    );
                }
                if corners.len() < 3 {
                    return Err(at(format!(
                        "face has {} vertices, at least 3 are needed",
                        corners.len()
                    )));
                }
                faces.polygon(&corners);
            }
            Some(keyword) if is_keyword(keyword) => {}
            Some(other) => {
                return Err(format!("line {n}: {} is not an OBJ statement", show(other)));
            }
            None => {}
        }
    }
    if positions.is_empty() && faces.len() == 0 {
        return Err("no OBJ vertex or face found".into());
    }
    let count = positions.len();
    if u32::try_from(count).is_err() {
        return Err(format!(
            "{count} vertices: more than 32-bit indices can address"
        ));
    }
    let (v, f, n) = furthest;
    if v > count as i64 {
        return Err(format!(
            "face {f} (line {n}): vertex index {v} out of range (1..={count})"
        ));
    }
    let source = Source {
        format: Some(Format::Obj),
        precision,
        ..Source::default()
    };
    Ok(faces.into_mesh(positions, source))
}

pub(crate) fn write(out: &mut impl Write, mesh: &Mesh) -> io::Result<()> {
    let faces = Faces::of(mesh);
    writeln!(
        out,
        "# vcsmooth: {} vertices, {} faces",
        mesh.positions.len(),
        faces.len()
    )?;
    for &p in &mesh.positions {
        out.write_all(b"v ")?;
        write_xyz(out, p, mesh.source.precision)?;
        out.write_all(b"\n")?;
    }
    faces.try_for_each(|corners| {
        out.write_all(b"f")?;
        for &v in corners {
            write!(out, " {}", u64::from(v) + 1)?;
        }
        out.write_all(b"\n")
    })
}
