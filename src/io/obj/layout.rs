//! The text of an OBJ input, kept so that an OBJ output changes only what smoothing changed.
//!
//! The output is the input, byte for byte (byte-order mark, comments, line endings, blank lines,
//! `mtllib`, `o`, `g`, `s`, `usemtl`, `vt`, unknown statements, and every `f` line with its
//! `v/vt/vn` corners, polygon size and relative indices as written), except for:
//!
//! - the first three numbers of each `v` line: the smoothed position, in the mesh's precision
//!   (what comes before and after them, e.g. a colour `r g b` or a comment, is kept);
//! - the first three numbers of each `vn` line: the normal recomputed from the smoothed positions.
//!   **Rule**: normal `k` is the normalised sum, over every face corner that refers to it, of the
//!   area-weighted normal (`(b − a) × (c − a)`) of each fan triangle of that face that has the
//!   corner. A `vn` shared by the corners around a vertex (smooth shading) thus becomes the
//!   area-weighted vertex normal, one used by a single face (flat shading) that face's normal,
//!   and hard edges stay hard. A normal with no area around it is written `0 0 0`; one that no
//!   corner refers to is kept as it was (there is nothing to recompute it from). Normals are
//!   written in single precision (they are unit vectors).
//!
//! Memory: the text of the file without the numbers cut out of `v` and `vn` lines (for a typical
//! textured scan, about two thirds of the file), plus 8 bytes per `v` and per `vn` line (where
//! the numbers go back) and, when the file has normals, 4 bytes per face corner (the normal each
//! corner refers to). The read adds one pass over the text to copy it.

use std::fmt;
use std::io::{self, Write};

use glam::DVec3;

use super::NO_NORMAL;
use crate::io::{Faces, Spelling, tokens, without_bom, write_xyz};
use crate::mesh::{Carried, FileLayout, Mesh};

/// An OBJ input's text without the numbers of its `v` and `vn` lines, and where they go back (see
/// the module documentation).
pub(crate) struct ObjLayout {
    /// The file's bytes without the first three numbers of every `v` and `vn` line.
    text: Vec<u8>,
    /// Where the numbers of each `v` line were in `text`, in file order (one per vertex).
    vertex_cuts: Vec<u64>,
    /// The same for each `vn` line that a corner refers to.
    normal_cuts: Vec<u64>,
    /// The normal each face corner refers to, numbered as `normal_cuts` (`NO_NORMAL` for none),
    /// in face order; `None` when no corner refers to one.
    corner_normals: Option<Vec<u32>>,
    /// A hash of the triangles read, to refuse writing this text for other faces.
    triangles: u64,
    carried: Carried,
}

impl ObjLayout {
    /// The layout of `file` (whole, with its byte-order mark), which was read into `mesh`.
    pub(super) fn new(
        file: &[u8],
        mesh: &Mesh,
        carried: Carried,
        normals: usize,
        mut corner_normals: Option<Vec<u32>>,
    ) -> Self {
        // The new number of each normal some corner refers to, in file order; the others are
        // kept as text.
        let mut used = vec![false; normals];
        let mut renumbered = vec![NO_NORMAL; normals];
        if let Some(corners) = &mut corner_normals {
            for &r in corners.iter() {
                if let Some(u) = used.get_mut(r as usize) {
                    *u = true;
                }
            }
            let kept = renumbered.iter_mut().zip(&used).filter(|(_, u)| **u);
            for (k, (slot, _)) in kept.enumerate() {
                *slot = k as u32;
            }
            for r in corners.iter_mut() {
                *r = renumbered.get(*r as usize).copied().unwrap_or(NO_NORMAL);
            }
        }
        let mut referenced = used.into_iter();
        let body = without_bom(file);
        let mut text = Vec::with_capacity(file.len());
        text.extend_from_slice(&file[..file.len() - body.len()]);
        let (mut vertex_cuts, mut normal_cuts) = (Vec::new(), Vec::new());
        for (i, line) in body.split(|&b| b == b'\n').enumerate() {
            if i > 0 {
                text.push(b'\n');
            }
            let code = line.split(|&b| b == b'#').next().unwrap_or_default();
            let cuts = match tokens(code).next() {
                Some(b"v") => &mut vertex_cuts,
                Some(b"vn") if referenced.next().unwrap_or(false) => &mut normal_cuts,
                _ => {
                    text.extend_from_slice(line);
                    continue;
                }
            };
            // The reader checked that both have three numbers.
            let mut numbers = spans(code).skip(1);
            match (numbers.next(), numbers.nth(1)) {
                (Some((start, _)), Some((_, end))) => {
                    text.extend_from_slice(&line[..start]);
                    cuts.push(text.len() as u64);
                    text.extend_from_slice(&line[end..]);
                }
                _ => text.extend_from_slice(line),
            }
        }
        // The cut numbers were reserved too; give back what a large file does not need.
        text.shrink_to_fit();
        ObjLayout {
            text,
            vertex_cuts,
            normal_cuts,
            corner_normals,
            triangles: hash(&mesh.triangles),
            carried,
        }
    }

    /// Writes the text with `mesh`'s positions and recomputed normals, and `colours` after each
    /// position in place of the numbers that followed it (colours, or a weight); `check_writable`
    /// passed.
    pub(super) fn write(
        &self,
        out: &mut impl Write,
        mesh: &Mesh,
        colours: Option<&(dyn Fn(usize) -> [u8; 3] + Sync)>,
    ) -> io::Result<()> {
        let normals = self.normals(mesh);
        let mut normals = self.normal_cuts.iter().zip(&normals).peekable();
        let mut at = 0;
        for (i, (&cut, &p)) in self
            .vertex_cuts
            .iter()
            .zip(mesh.positions.iter())
            .enumerate()
        {
            while let Some((&n_cut, &n)) = normals.next_if(|&(&c, _)| c < cut) {
                at = self.put(out, at, n_cut, n, Spelling::NORMAL)?;
            }
            at = self.put(out, at, cut, p, Spelling::of(&mesh.source))?;
            if let Some(colour) = colours {
                super::write_colour(out, colour(i))?;
                at = after_numbers(&self.text, at);
            }
        }
        for (&n_cut, &n) in normals {
            at = self.put(out, at, n_cut, n, Spelling::NORMAL)?;
        }
        out.write_all(&self.text[at..])
    }

    /// Writes the text from `at` to `cut`, then `p`; returns `cut`.
    fn put(
        &self,
        out: &mut impl Write,
        at: usize,
        cut: u64,
        p: DVec3,
        spelling: Spelling,
    ) -> io::Result<usize> {
        let cut = cut as usize;
        out.write_all(&self.text[at..cut])?;
        write_xyz(out, p, spelling)?;
        Ok(cut)
    }

    /// Every `vn`'s normal by the rule of the module documentation.
    fn normals(&self, mesh: &Mesh) -> Vec<DVec3> {
        let mut sums = vec![DVec3::ZERO; self.normal_cuts.len()];
        if let Some(corner_normals) = &self.corner_normals {
            let mut next = 0;
            let _ = Faces::of(mesh).try_for_each(|corners| -> Result<(), ()> {
                let refs = corner_normals
                    .get(next..next + corners.len())
                    .unwrap_or_default();
                next += corners.len();
                for k in 1..corners.len().saturating_sub(1) {
                    let fan = [0, k, k + 1];
                    let [a, b, c] = fan.map(|j| mesh.positions[corners[j] as usize]);
                    let n = (b - a).cross(c - a);
                    for j in fan {
                        // A corner without a normal (`NO_NORMAL`) is no index of `sums`.
                        if let Some(sum) = refs.get(j).and_then(|&r| sums.get_mut(r as usize)) {
                            *sum += n;
                        }
                    }
                }
                Ok(())
            });
        }
        sums.iter_mut().for_each(|n| *n = n.normalize_or_zero());
        sums
    }
}

/// Where the numbers that follow `at` on its line end (`at` itself when none does): the rest of
/// the line from there (a comment, the line's end) is kept.
fn after_numbers(text: &[u8], mut at: usize) -> usize {
    loop {
        let mut i = at;
        while i < text.len() && (text[i] == b' ' || text[i] == b'\t') {
            i += 1;
        }
        let start = i;
        while i < text.len() && !text[i].is_ascii_whitespace() && text[i] != b'#' {
            i += 1;
        }
        let token = &text[start..i];
        if token.is_empty() || crate::io::number(token).is_err() {
            return at;
        }
        at = i;
    }
}

/// The byte ranges of a line's whitespace-separated tokens.
fn spans(line: &[u8]) -> impl Iterator<Item = (usize, usize)> + '_ {
    let mut i = 0;
    std::iter::from_fn(move || {
        i += line[i..]
            .iter()
            .take_while(|b| b.is_ascii_whitespace())
            .count();
        let start = i;
        i += line[i..]
            .iter()
            .take_while(|b| !b.is_ascii_whitespace())
            .count();
        (i > start).then_some((start, i))
    })
}

/// FNV-1a over the triangles' indices.
fn hash(triangles: &[[u32; 3]]) -> u64 {
    triangles
        .iter()
        .flatten()
        .fold(0xcbf2_9ce4_8422_2325, |h, &v| {
            (h ^ u64::from(v)).wrapping_mul(0x0100_0000_01b3)
        })
}

/// The OBJ layout `mesh` was read with, if any.
pub(super) fn of(mesh: &Mesh) -> Option<&ObjLayout> {
    let layout = mesh.source.layout.as_deref()?;
    layout.as_any().downcast_ref::<ObjLayout>()
}

/// Whether `mesh`'s OBJ layout, if any, still describes it (the rest of what an OBJ output needs
/// is checked by `io::write_mesh`).
pub(crate) fn check_writable(mesh: &Mesh) -> Result<(), String> {
    let Some(layout) = of(mesh) else {
        return Ok(());
    };
    if layout.vertex_cuts.len() != mesh.positions.len() {
        return Err(format!(
            "the mesh has {} vertices but its OBJ source has {}; clear mesh.source.layout after \
             adding or removing vertices",
            mesh.positions.len(),
            layout.vertex_cuts.len()
        ));
    }
    if hash(&mesh.triangles) != layout.triangles {
        return Err(
            "the triangles no longer match the OBJ source's faces; clear \
                    mesh.source.layout after changing connectivity"
                .into(),
        );
    }
    Ok(())
}

impl FileLayout for ObjLayout {
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    fn carries(&self) -> Carried {
        self.carried.clone()
    }
}

// By hand: the text is as large as the file.
impl fmt::Debug for ObjLayout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ObjLayout")
            .field("text_bytes", &self.text.len())
            .field("vertices", &self.vertex_cuts.len())
            .field("normals", &self.normal_cuts.len())
            .field("carried", &self.carried)
            .finish()
    }
}
