//! Wavefront OBJ: `v` and `f` statements, and everything else kept for the output.
//!
//! - `v x y z …`: the first three numbers are the position; further numbers (a `w`, or the common
//!   `r g b` colour extension) are checked to be numbers and kept as text.
//! - `f a b c …`: each corner is `i`, `i/t`, `i//n` or `i/t/n`; an index counts from 1, and a
//!   negative one counts back from the last vertex (texture coordinate, normal) defined so far.
//!   Positive indices may refer to elements defined later. Texture (`vt`) and normal (`vn`)
//!   references must be in range too, since the output writes them back.
//! - `vn x y z`: its first three tokens must be numbers (the output replaces them).
//! - Every other statement (`vt`, `g`, `o`, `s`, `mtllib`, `usemtl`, `l`, `p`, …) and everything
//!   after a `#` is kept as it is, and so is a statement with a keyword OBJ does not define, as
//!   long as the keyword is a name (ASCII letters, digits and `_`, starting with a letter or `_`):
//!   exporters add their own statements, and a reader that knows fewer keywords than the writer
//!   must still read the mesh.
//! - A line that starts with anything else (a number, punctuation, a zero byte, bytes that are
//!   not ASCII) is not OBJ, and is refused: a binary file or prose given an `.obj` name stops at
//!   its first such line. A file with no `v` and no `f` statement at all is refused too (`no OBJ
//!   vertex or face found`): there is nothing OBJ in it, and it would otherwise read as an empty
//!   mesh. A UTF-8 byte-order mark at the start is skipped.
//!
//! # Round trip
//!
//! A file with anything beyond bare `v x y z` and `f` lines (a comment, any other statement, a
//! `v` with more than three numbers) keeps its text in an [`ObjLayout`]; an OBJ output of that
//! mesh is the input with only the `v` coordinates and the `vn` normals rewritten (see `layout`).
//! A bare file is not kept (it would only double the memory of a large scan) and is written as
//! any other mesh: a `# vcsmooth` comment, `v x y z` and `f` lines with absolute indices.

mod layout;

use std::io::{self, Write};

use glam::DVec3;

pub(crate) use layout::check_writable;

use super::{
    Digits, FaceBuilder, Faces, Format, Source, Spelling, integer, lines, show, text_position,
    tokens, without_bom, write_encoded, write_face_lines, write_xyz,
};
use crate::mesh::{Carried, Mesh};

/// Whether `word` can be an OBJ keyword: a name of ASCII letters, digits and `_`, not starting
/// with a digit.
fn is_keyword(word: &[u8]) -> bool {
    word.first()
        .is_some_and(|b| b.is_ascii_alphabetic() || *b == b'_')
        && word.iter().all(|b| b.is_ascii_alphanumeric() || *b == b'_')
}

/// `other` keywords kept for `carries()` at most: a hostile file with a new keyword on every line
/// must not grow a list per line.
const MAX_OTHER: usize = 64;

/// One kind of indexed element a face corner refers to (`v`, `vt` or `vn`): how many are defined
/// so far, and the largest positive reference with its face and line (forward references are
/// legal, so those can only be checked at the end).
struct Indexed {
    name: &'static str,
    first: &'static str,
    defined: i64,
    furthest: (i64, usize, usize),
}

impl Indexed {
    fn new(name: &'static str, first: &'static str) -> Self {
        Indexed {
            name,
            first,
            defined: 0,
            furthest: (0, 0, 0),
        }
    }

    /// The 0-based index that reference `r` of face `f` on line `n` stands for.
    fn resolve(&mut self, r: i64, f: usize, n: usize) -> Result<u32, String> {
        let index = match r {
            0 => return Err(format!("{} index 0 (OBJ indices start at 1)", self.name)),
            r if r < 0 && r + self.defined < 0 => {
                return Err(format!(
                    "{} index {r} points before the first {} ({} defined so far)",
                    self.name, self.first, self.defined
                ));
            }
            r if r < 0 => r + self.defined,
            r => {
                if r > self.furthest.0 {
                    self.furthest = (r, f, n);
                }
                r - 1
            }
        };
        u32::try_from(index).map_err(|_| format!("{} index {r} out of range", self.name))
    }

    /// Every positive reference in range, once all are defined.
    fn check(&self) -> Result<(), String> {
        let (r, f, n) = self.furthest;
        if r > self.defined {
            return Err(format!(
                "face {f} (line {n}): {} index {r} out of range (1..={})",
                self.name, self.defined
            ));
        }
        if u32::try_from(self.defined).is_err() {
            return Err(format!(
                "{} {}s: more than 32-bit indices can address",
                self.defined, self.first
            ));
        }
        Ok(())
    }
}

pub(crate) fn read(bytes: &[u8]) -> Result<Mesh, String> {
    let file = bytes;
    let bytes = without_bom(bytes);
    let mut positions: Vec<DVec3> = Vec::new();
    let mut faces = FaceBuilder::with_capacity(0);
    let mut digits = Digits::default();
    let mut corners = Vec::new();
    let mut vertex = Indexed::new("vertex", "vertex");
    let mut texture = Indexed::new("texture", "texture coordinate");
    let mut normal = Indexed::new("normal", "normal");
    // The normal of every face corner (`NO_NORMAL` for none), in face order; started at the
    // first corner that has one.
    let mut corner_normals: Option<Vec<u32>> = None;
    let mut corner_count = 0;
    let mut carried = Carried::default();
    // Only `v x y z` and `f` lines so far: nothing a plain output would lose.
    let mut bare = true;
    for (n, line) in lines(bytes) {
        let mut parts = line.splitn(2, |&b| b == b'#');
        let code = parts.next().unwrap_or_default();
        bare &= parts.next().is_none();
        let mut words = tokens(code);
        match words.next() {
            Some(b"v") => {
                let i = positions.len();
                let mut numbers = 0;
                let p = text_position(words.inspect(|_| numbers += 1), &mut digits)
                    .map_err(|what| format!("vertex {i} (line {n}): {what}"))?;
                positions.push(p);
                bare &= numbers == 3;
                carried.colours |= numbers >= 6;
            }
            Some(b"f") => {
                let f = faces.len();
                let at = |what: String| format!("face {f} (line {n}): {what}");
                corners.clear();
                vertex.defined = positions.len() as i64;
                for w in words {
                    let mut refs = w.split(|&b| b == b'/');
                    let v = integer(refs.next().unwrap_or_default()).map_err(at)?;
                    corners.push(vertex.resolve(v, f, n).map_err(at)?);
                    let mut corner_normal = NO_NORMAL;
                    for (k, r) in refs.enumerate() {
                        if k > 1 {
                            return Err(at(format!(
                                "corner {} has more than 3 parts",
                                super::show(w)
                            )));
                        }
                        if r.is_empty() {
                            continue;
                        }
                        let r = integer(r).map_err(at)?;
                        if k == 0 {
                            texture.resolve(r, f, n).map_err(at)?;
                        } else {
                            corner_normal = normal.resolve(r, f, n).map_err(at)?;
                        }
                    }
                    if corner_normal != NO_NORMAL || corner_normals.is_some() {
                        corner_normals
                            .get_or_insert_with(|| vec![NO_NORMAL; corner_count])
                            .push(corner_normal);
                    }
                    corner_count += 1;
                }
                if corners.len() < 3 {
                    return Err(at(format!(
                        "face has {} vertices, at least 3 are needed",
                        corners.len()
                    )));
                }
                faces.polygon(&corners);
            }
            Some(b"vt") => {
                texture.defined += 1;
                carried.uvs = true;
                bare = false;
            }
            Some(b"vn") => {
                text_position(words, &mut Digits::default())
                    .map_err(|what| format!("normal {} (line {n}): {what}", normal.defined))?;
                normal.defined += 1;
                carried.normals = true;
                bare = false;
            }
            Some(keyword) if is_keyword(keyword) => {
                bare = false;
                if matches!(keyword, b"mtllib" | b"usemtl") {
                    carried.materials = true;
                } else if carried.other.len() < MAX_OTHER
                    && !carried.other.iter().any(|k| k.as_bytes() == keyword)
                {
                    // A keyword is ASCII.
                    carried
                        .other
                        .push(String::from_utf8_lossy(keyword).into_owned());
                }
            }
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
    vertex.defined = count as i64;
    vertex.check()?;
    texture.check()?;
    normal.check()?;
    let source = Source {
        format: Some(Format::Obj),
        precision: digits.precision(),
        decimals: digits.decimals(),
        ..Source::default()
    };
    let mut mesh = faces.into_mesh(positions, source);
    if !bare {
        let normals = normal.defined as usize;
        let layout = layout::ObjLayout::new(file, &mesh, carried, normals, corner_normals);
        mesh.source.layout = Some(std::sync::Arc::new(layout));
    }
    Ok(mesh)
}

/// A face corner without a normal reference.
const NO_NORMAL: u32 = u32::MAX;

pub(crate) fn write(
    out: &mut impl Write,
    mesh: &Mesh,
    colours: Option<&(dyn Fn(usize) -> [u8; 3] + Sync)>,
) -> io::Result<()> {
    if let Some(layout) = layout::of(mesh) {
        return layout.write(out, mesh, colours);
    }
    let faces = Faces::of(mesh);
    writeln!(
        out,
        "# vcsmooth: {} vertices, {} faces",
        mesh.positions.len(),
        faces.len()
    )?;
    let spelling = Spelling::of(&mesh.source);
    // Lines of about 40 and 24 bytes: what sizes the pieces encoded in parallel.
    write_encoded(out, mesh.positions.len(), 40, |range, buf| {
        for i in range {
            buf.extend_from_slice(b"v ");
            write_xyz(buf, mesh.positions[i], spelling)?;
            if let Some(colour) = colours {
                write_colour(buf, colour(i))?;
            }
            buf.push(b'\n');
        }
        Ok(())
    })?;
    let face = |out: &mut Vec<u8>, corners: &[u32]| {
        out.push(b'f');
        for &v in corners {
            write!(out, " {}", u64::from(v) + 1)?;
        }
        out.push(b'\n');
        Ok(())
    };
    write_face_lines(out, &faces, face)
}

/// ` r g b` after a vertex's position: the colour's bytes over 255, in four decimals, which read
/// back to the same bytes.
pub(crate) fn write_colour(out: &mut impl Write, rgb: [u8; 3]) -> io::Result<()> {
    let [r, g, b] = rgb.map(|c| c as f64 / 255.0);
    write!(out, " {r:.4} {g:.4} {b:.4}")
}
