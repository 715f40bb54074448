//! Pinned vertices: vertices the caller wants kept where they are, named in the input's vertex
//! order (indices, a mask, a file of indices, or a PLY vertex property). The engine resolves them
//! against the mesh it read into a [`PinSet`] and marks them fixed in the plan's topology
//! ([`Plan::pin`]), in its own vertex order: no method moves a pinned vertex, and a stencil that
//! contains one is skipped like a stencil with a boundary vertex, so the volumes of the stencils
//! that are applied stay exact. Crease vertices ([`Plan::crease`], the options' `crease_angle`)
//! are fixed the same way, but for those on crease lines, which the methods that smooth creases
//! move along their lines ([`crate::Topology::line_neighbors`]).

use std::path::{Path, PathBuf};

use serde::ser::SerializeMap;

use super::iterate::{Alone, ShareExec};
use super::plan::Plan;
use crate::error::{Error, Result};
use crate::io::PlyLayout;
use crate::mesh::{Buf, Mesh, Storage};
use crate::smooth::guided;
use crate::smooth::method::Exec;
use glam::DVec3;

/// Which vertices never move, in the input's vertex order. Part of the result's definition (like
/// the patch size): [`Pins::key`] says which pins a stored plan or a batch marker was made with.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum Pins {
    /// Nothing pinned.
    #[default]
    None,
    /// 0-based vertex indices; duplicates are allowed, an index past the last vertex is an error.
    Indices(Vec<u32>),
    /// One flag per vertex, `true`: pinned; its length must be the vertex count.
    Mask(Vec<bool>),
    /// A text file of 0-based vertex indices, one per line; blank lines and `#` comments (whole
    /// lines or after an index) are allowed. Read when the run starts; errors name the file.
    File(PathBuf),
    /// A scalar vertex property of a PLY input (any numeric type): a non-zero value pins the vertex.
    Property(String),
}

/// Pins resolved against a mesh: one bit per vertex in the input's order.
#[derive(Debug, Clone, Default)]
pub struct PinSet {
    bits: Vec<u64>,
    count: usize,
}

impl PinSet {
    fn new(n: usize) -> PinSet {
        PinSet {
            bits: vec![0; n.div_ceil(64)],
            count: 0,
        }
    }

    fn insert(&mut self, v: usize) {
        let (w, b) = (v / 64, 1u64 << (v % 64));
        if self.bits[w] & b == 0 {
            self.bits[w] |= b;
            self.count += 1;
        }
    }

    /// Whether input vertex `v` is pinned.
    #[inline]
    pub fn contains(&self, v: usize) -> bool {
        self.bits
            .get(v / 64)
            .is_some_and(|w| w & (1 << (v % 64)) != 0)
    }

    /// Distinct pinned vertices.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether nothing is pinned.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

impl Pins {
    /// Whether these pins name no vertex source at all.
    pub fn is_none(&self) -> bool {
        matches!(self, Pins::None)
    }

    /// The pins of `mesh` (read from `input`, which errors name; `None` for an in-memory mesh).
    /// `Ok(None)` when nothing is asked for.
    pub fn resolve(&self, mesh: &Mesh, input: Option<&Path>) -> Result<Option<PinSet>> {
        let n = mesh.positions.len();
        let mut set = PinSet::new(n);
        let out_of_range = |i: u64| {
            format!(
                "vertex index {i} is out of range: {} has {n} vertices",
                input.map_or("the mesh".into(), |p| p.display().to_string())
            )
        };
        match self {
            Pins::None => return Ok(None),
            Pins::Indices(indices) => {
                for &i in indices {
                    if i as usize >= n {
                        return Err(Error::parameter("pins", out_of_range(i.into())));
                    }
                    set.insert(i as usize);
                }
            }
            Pins::Mask(mask) => {
                if mask.len() != n {
                    return Err(Error::parameter(
                        "pins",
                        format!(
                            "has {} flags for a mesh of {n} vertices (one per vertex)",
                            mask.len()
                        ),
                    ));
                }
                mask.iter()
                    .enumerate()
                    .filter(|(_, p)| **p)
                    .for_each(|(v, _)| set.insert(v));
            }
            // Streamed into the mesh's bit set: whatever the file's length, it costs no more than
            // one bit per vertex, and fails at its first index out of range.
            Pins::File(path) => for_each_pin(path, |line, i| {
                if i >= n as u64 {
                    return Err(Error::invalid(
                        path,
                        format!("line {line}: {}", out_of_range(i)),
                    ));
                }
                set.insert(i as usize);
                Ok(())
            })?,
            Pins::Property(name) => {
                let fail = |what: String| match input {
                    Some(p) => Error::invalid(p, what),
                    None => Error::parameter("pins", format!("(the mesh) {what}")),
                };
                let ply = mesh
                    .source
                    .layout
                    .as_ref()
                    .and_then(|l| l.as_any().downcast_ref::<PlyLayout>());
                let Some(ply) = ply else {
                    return Err(fail(format!(
                        "has no vertex property '{name}': pinning by a vertex property needs a PLY input"
                    )));
                };
                ply.vertex_values(name, |v, x| {
                    if x != 0.0 && v < n {
                        set.insert(v);
                    }
                })
                .map_err(fail)?;
            }
        }
        Ok(Some(set))
    }

    /// What a stored plan or a batch marker records of these pins, so that a run with other pins
    /// does not reuse it: empty for none; the property's name; for indices, a mask or a file, the
    /// count and a hash of the distinct pinned indices (a file is read for it; its errors are
    /// the run's). The plan's or marker's input identity covers what a property holds.
    pub fn key(&self) -> Result<String> {
        let mut indices: Vec<u64> = match self {
            Pins::None => return Ok(String::new()),
            Pins::Property(name) => return Ok(format!("property {name}")),
            Pins::Indices(i) => i.iter().map(|&i| i.into()).collect(),
            Pins::Mask(m) => (0..m.len() as u64).filter(|&v| m[v as usize]).collect(),
            Pins::File(path) => distinct_pins(path)?,
        };
        indices.sort_unstable();
        indices.dedup();
        // FNV-1a over the little-endian indices: stable across builds and platforms.
        let hash = indices
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
                (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
            });
        Ok(format!("{} vertices {hash:016x}", indices.len()))
    }
}

/// The longest line a pin file may have (an index and its comment).
const MAX_PIN_LINE: usize = 64 << 10;

/// Call `each(line, index)` for the indices of a pin file, with their line numbers (1-based), in
/// file order. Streamed: memory is one line, at most [`MAX_PIN_LINE`] bytes. Only a regular file
/// is read (a pin file is read more than once: for the plan's key, then against the mesh; a pipe
/// would be empty the second time, a device endless); a NUL byte, text that is not UTF-8 or a line
/// too long refuse it at once.
fn for_each_pin(path: &Path, mut each: impl FnMut(usize, u64) -> Result<()>) -> Result<()> {
    use std::io::BufRead;
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a directory"
        } else {
            "a pipe, device or socket: save the indices to a regular file"
        };
        return Err(Error::invalid(
            path,
            format!("is not a file of vertex indices ({kind})"),
        ));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut reader = std::io::BufReader::with_capacity(1 << 16, file);
    let mut line = Vec::new();
    for k in 1.. {
        line.clear();
        let n = std::io::Read::take(&mut reader, MAX_PIN_LINE as u64 + 1)
            .read_until(b'\n', &mut line)
            .map_err(|e| Error::io(path, e))?;
        if n == 0 {
            break;
        }
        let at = |what: &str| Error::invalid(path, format!("line {k}: {what}"));
        if line.contains(&0) {
            return Err(at(
                "a NUL byte: binary data, not a text file of vertex indices",
            ));
        }
        if line.len() > MAX_PIN_LINE {
            return Err(at(&format!(
                "longer than {} KiB: not a text file of vertex indices",
                MAX_PIN_LINE >> 10
            )));
        }
        let bytes = if k == 1 {
            crate::io::without_bom(&line)
        } else {
            &line
        };
        let text = std::str::from_utf8(bytes)
            .map_err(|_| Error::invalid(path, "is not a text file of vertex indices"))?;
        let entry = text.split('#').next().unwrap_or_default().trim();
        if entry.is_empty() {
            continue;
        }
        let i = entry.parse::<u64>().map_err(|_| {
            let shown: String = entry.chars().take(40).collect();
            let more = if shown.len() < entry.len() { "…" } else { "" };
            at(&format!(
                "'{shown}{more}' is not a vertex index (a whole number from 0)"
            ))
        })?;
        each(k, i)?;
    }
    Ok(())
}

/// The distinct indices of a pin file, ascending. A mesh has fewer than 2^32 vertices, so an
/// index from 2^32 is refused here; the set is held compactly (sorted and deduplicated as it
/// grows) and allocated fallibly.
fn distinct_pins(path: &Path) -> Result<Vec<u64>> {
    let mut out: Vec<u32> = Vec::new();
    for_each_pin(path, |line, i| {
        let Ok(i) = u32::try_from(i) else {
            return Err(Error::invalid(
                path,
                format!("line {line}: vertex index {i} is out of range for any mesh (from 2^32)"),
            ));
        };
        if out.len() == out.capacity() {
            out.sort_unstable();
            out.dedup();
            if out.len() * 2 > out.capacity() {
                out.try_reserve(out.capacity().max(1 << 12)).map_err(|_| {
                    Error::invalid(
                        path,
                        format!(
                            "line {line}: out of memory holding {} distinct pins",
                            out.len()
                        ),
                    )
                })?;
            }
        }
        out.push(i);
        Ok(())
    })?;
    out.sort_unstable();
    out.dedup();
    Ok(out.into_iter().map(u64::from).collect())
}

/// In reports: `null`, or what was pinned by (`{"indices": n}`, `{"mask": n}`, `{"file": path}`,
/// `{"property": name}`), never the indices themselves.
impl serde::Serialize for Pins {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        if self.is_none() {
            return s.serialize_none();
        }
        let mut m = s.serialize_map(Some(1))?;
        match self {
            Pins::None => unreachable!("serialized as null above"),
            Pins::Indices(i) => m.serialize_entry("indices", &i.len())?,
            Pins::Mask(mask) => m.serialize_entry("mask", &mask.iter().filter(|p| **p).count())?,
            Pins::File(path) => m.serialize_entry("file", path)?,
            Pins::Property(name) => m.serialize_entry("property", name)?,
        }
        m.end()
    }
}

impl Plan {
    /// Fix the vertices of `pins` (input order) in the plan's topology, in the plan's order.
    pub fn pin(&mut self, pins: &PinSet) {
        if pins.is_empty() {
            return;
        }
        let r = &self.reordered;
        // A vertex is pinned when it or any of its welded copies is (a copy itself never moves).
        let mut by_copy = std::collections::HashSet::new();
        for (new, &to) in r.welded_to.iter().enumerate() {
            if to as usize != new && pins.contains(r.order[new] as usize) {
                by_copy.insert(to);
            }
        }
        self.topology.pin(|new| {
            r.source_of(new as usize) == new as usize
                && (pins.contains(r.order[new as usize] as usize) || by_copy.contains(&new))
        });
    }

    /// Mark the vertices on creases sharper than `angle` degrees (see [`Topology::crease`]) of
    /// the plan's current positions (the input's, before smoothing); nothing when `None`. The
    /// creases are found where noise cannot make them:
    /// 1. the input's face normals, [`guided::CREASE_ITERATIONS`] iterations of the guided
    ///    normal filter ([`guided::filter_normals`]) that never averages two faces whose
    ///    guidance normals differ by more than `angle`, so that the edges of a clean mesh stay
    ///    as sharp as they are;
    /// 2. a copy of the positions, [`guided::CREASE_FIT_STEPS`] steps towards the planes of
    ///    those normals ([`guided::fit_into`]): on heavy noise the edges along a crease zigzag
    ///    across it, and the crease test needs them along it;
    /// 3. the normals of the fitted copy, [`guided::CREASE_REFILTER_ITERATIONS`] more
    ///    iterations: the crease test's normals and positions (with the input's, which keep the
    ///    filter's own facets from making creases).
    ///
    /// The fields are allocated in `storage` (scratch out of core) and dropped on return. Every
    /// pass is a Jacobi pass, so the creases do not depend on the thread count or the storage.
    /// Like pins, creases are part of the result's definition.
    ///
    /// [`Topology::crease`]: crate::Topology::crease
    pub fn crease(&mut self, storage: &Storage, angle: Option<f64>) -> Result<()> {
        let Some(angle) = angle else {
            return Ok(());
        };
        let r = &self.reordered;
        let (tris, pos) = (&r.triangles[..], &r.positions[..]);
        let faces = tris.len();
        let mut vectors: Buf<DVec3> = storage.zeroed(guided::FACE_VECTORS * faces)?;
        let mut fitted: Buf<DVec3> = storage.zeroed(pos.len())?;
        let cut = angle.to_radians().cos();
        let parts = self.topology.parts();
        let mut alone = Alone {
            vertices: pos.len(),
            triangles: faces,
        };
        let mut exec = ShareExec { share: &mut alone };
        // The filter's scalars are made for each filter and go with it: they are not alive
        // beside the fit's two arrays, nor beside the crease test's.
        let scalars = || storage.zeroed::<f64>(guided::FACE_SCALARS * faces);
        {
            let iterations = guided::CREASE_ITERATIONS;
            let filtered = guided::filter_normals(
                &mut exec,
                &parts,
                tris,
                pos,
                &mut vectors,
                &mut scalars()?,
                iterations,
                cut,
            );
            let mut spare: Buf<DVec3> = storage.zeroed(pos.len())?;
            fitted.copy_from_slice(pos);
            for _ in 0..guided::CREASE_FIT_STEPS {
                let from: &[DVec3] = &fitted;
                exec.vertex_pass(&mut spare, &|first, out| {
                    guided::fit_into(&parts, tris, filtered, from, out, first)
                });
                std::mem::swap(&mut fitted, &mut spare);
            }
        }
        let normals = guided::filter_normals(
            &mut exec,
            &parts,
            tris,
            &fitted,
            &mut vectors,
            &mut scalars()?,
            guided::CREASE_REFILTER_ITERATIONS,
            cut,
        );
        self.topology
            .crease(storage, tris, pos, &fitted, normals, angle)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_pin_file(path: &Path) -> Result<Vec<(usize, u64)>> {
        let mut out = Vec::new();
        for_each_pin(path, |line, i| {
            out.push((line, i));
            Ok(())
        })?;
        Ok(out)
    }

    #[test]
    fn pin_files_and_keys() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("pins.txt");
        std::fs::write(&path, "# comment\n\n 5 \n3 # three\n5\n").unwrap();
        assert_eq!(read_pin_file(&path).unwrap(), vec![(3, 5), (4, 3), (5, 5)]);
        // A byte-order mark (as some editors save text) is not part of the first line.
        std::fs::write(&path, "\u{feff}7\r\n8\r\n").unwrap();
        assert_eq!(read_pin_file(&path).unwrap(), vec![(1, 7), (2, 8)]);
        std::fs::write(&path, "# comment\n\n 5 \n3 # three\n5\n").unwrap();
        // The key names the distinct indices, whatever their order, repeats or source.
        let key = Pins::File(path.clone()).key().unwrap();
        assert_eq!(key, Pins::Indices(vec![3, 5]).key().unwrap());
        let mask = (0..6).map(|v| v == 3 || v == 5).collect();
        assert_eq!(key, Pins::Mask(mask).key().unwrap());
        assert_ne!(key, Pins::Indices(vec![3]).key().unwrap());
        assert_eq!(Pins::None.key().unwrap(), "");
        std::fs::write(&path, "1\n2.5\n").unwrap();
        let e = Pins::File(path).key().unwrap_err().to_string();
        assert!(e.contains("line 2: '2.5' is not a vertex index"), "{e}");
    }

    #[test]
    fn reports_name_the_source_not_the_indices() {
        let json = |p: &Pins| serde_json::to_string(p).unwrap();
        assert_eq!(json(&Pins::None), "null");
        assert_eq!(json(&Pins::Indices(vec![1, 2, 2])), r#"{"indices":3}"#);
        assert_eq!(json(&Pins::Mask(vec![true, false])), r#"{"mask":1}"#);
        assert_eq!(json(&Pins::Property("q".into())), r#"{"property":"q"}"#);
    }
}
