//! Streamed binary PLY output, for meshes larger than memory: a producer hands over the vertices,
//! then the triangles, one at a time, and they are encoded as they come.
//!
//! The output is exactly what [`super::write_mesh`] writes for the same mesh in memory (plain
//! layout, single precision: `x y z float`, `list uchar int vertex_indices`, `uint` indices beyond
//! `i32::MAX` vertices), plus the given comment lines: one header writer and one record encoder
//! for both (`ply::write_header`, `ply::put_xyz`, `ply::put_face`). The write is atomic like every
//! other output (`atomic`): a temporary file renamed over the target only when complete, so a
//! failing producer, a refused record or a count that does not match the header leaves nothing
//! under the target's name.

use std::io::{self, Write};
use std::path::Path;

use glam::DVec3;

use super::ply::{self, PlainRecords, Scalar};
use super::{Format, Precision, atomic};
use crate::error::{Error, Result};

/// Bytes gathered before they go to the file.
const FLUSH: usize = 1 << 20;

/// Writes a binary little-endian PLY of `vertices` vertices and `triangles` triangles to `path`
/// (which must end in `.ply`), atomically. `comments` become `comment …` header lines, in order.
/// `produce` hands the records to the [`PlyStream`]: every vertex, in id order, then every
/// triangle.
///
/// # Errors
/// - [`Error::InvalidInput`] for a path that does not end in `.ply` or a comment that spans lines,
///   before any file is created.
/// - [`Error::InvalidInput`] (`cannot write: …`) for a record the layout cannot hold (a coordinate
///   that is not finite in single precision, a vertex index out of range), records out of order,
///   or fewer or more records than announced. Nothing is left under `path`.
/// - [`Error::Io`] for a write error, or an error returned by `produce`.
pub fn write_ply_streamed(
    path: &Path,
    vertices: u64,
    triangles: u64,
    comments: &[&str],
    produce: impl FnOnce(&mut PlyStream<'_>) -> io::Result<()>,
) -> Result<()> {
    write_ply_streamed_in(
        path,
        Precision::Float,
        vertices,
        triangles,
        comments,
        produce,
    )
}

/// [`write_ply_streamed`] with the coordinates in `precision` (`double` for a mesh derived from
/// one whose coordinates `float` cannot hold).
pub fn write_ply_streamed_in(
    path: &Path,
    precision: Precision,
    vertices: u64,
    triangles: u64,
    comments: &[&str],
    produce: impl FnOnce(&mut PlyStream<'_>) -> io::Result<()>,
) -> Result<()> {
    if Format::from_extension(path) != Some(Format::Ply) {
        return Err(Error::invalid(
            path,
            "a streamed mesh is written as binary PLY only; use a .ply output",
        ));
    }
    if let Some(c) = comments.iter().find(|c| c.contains(['\n', '\r'])) {
        return Err(Error::invalid(
            path,
            format!("a PLY comment is one line, got {c:?}"),
        ));
    }
    let too_many = |what| {
        Error::resource(format!(
            "{}: too many {what} for this platform",
            path.display()
        ))
    };
    let n_vertices = usize::try_from(vertices).map_err(|_| too_many("vertices"))?;
    let n_triangles = usize::try_from(triangles).map_err(|_| too_many("triangles"))?;
    let records = PlainRecords::new(n_vertices, 3, precision);
    let meta = comments.iter().map(|c| format!("comment {c}")).collect();
    let layout = records.layout(n_vertices, n_triangles, meta);

    let mut refused = None;
    let gz = super::gzip::has_gz_extension(path);
    let written = atomic::write_atomically(path, |file| {
        let mut compressed = None;
        let out: &mut dyn Write = match gz {
            true => compressed.insert(super::gzip::encoder(file)),
            false => file,
        };
        ply::write_header(&mut &mut *out, &layout, |_, el| el.count, None)?;
        let mut stream = PlyStream {
            out,
            records,
            buf: Vec::with_capacity(FLUSH + 64),
            vertices,
            triangles,
            vertices_written: 0,
            triangles_written: 0,
            refused: None,
        };
        let result = produce(&mut stream).and_then(|()| stream.finish());
        refused = stream.refused.take();
        result?;
        match compressed {
            Some(gz) => gz.finish().map(|_| ()),
            None => Ok(()),
        }
    });
    match (written, refused) {
        (Err(_), Some(what)) => Err(Error::invalid(path, format!("cannot write: {what}"))),
        (written, _) => written,
    }
}

/// The receiving end of [`write_ply_streamed`]: encodes each record as it comes, checking it
/// against the header (the order, the counts, what the types hold).
pub struct PlyStream<'w> {
    out: &'w mut dyn Write,
    records: PlainRecords,
    buf: Vec<u8>,
    /// The header's counts.
    vertices: u64,
    triangles: u64,
    vertices_written: u64,
    triangles_written: u64,
    /// Why a record was refused: the message of the error the write then fails with.
    refused: Option<String>,
}

impl PlyStream<'_> {
    /// Appends the next vertex (ids count from 0 in the order of the calls).
    pub fn vertex(&mut self, p: DVec3) -> io::Result<()> {
        let i = self.vertices_written;
        if i == self.vertices {
            return self.refuse(format!(
                "more than the {} vertices announced",
                self.vertices
            ));
        }
        let coordinate = self.records.coordinate;
        let fits = match coordinate {
            Scalar::F64 => p.is_finite(),
            _ => p.as_vec3().is_finite(),
        };
        if !fits {
            return self.refuse(format!(
                "vertex {i}: coordinate {p} does not fit PLY type {}",
                coordinate.name()
            ));
        }
        ply::put_xyz(self.records.coordinate, p, &mut self.buf);
        self.vertices_written += 1;
        self.flush_full()
    }

    /// Appends the next triangle; every vertex must have been written before the first one.
    pub fn triangle(&mut self, t: [u32; 3]) -> io::Result<()> {
        let i = self.triangles_written;
        if self.vertices_written < self.vertices {
            return self.refuse(format!(
                "triangle {i} before the last vertex ({} of {} written)",
                self.vertices_written, self.vertices
            ));
        }
        if i == self.triangles {
            return self.refuse(format!(
                "more than the {} triangles announced",
                self.triangles
            ));
        }
        if let Some(&v) = t.iter().find(|&&v| u64::from(v) >= self.vertices) {
            let what = super::bad_index(v.into(), self.vertices as usize);
            return self.refuse(format!("triangle {i}: {what}"));
        }
        ply::put_face(self.records.count, self.records.index, &t, &mut self.buf);
        self.triangles_written += 1;
        self.flush_full()
    }

    fn flush_full(&mut self) -> io::Result<()> {
        if self.buf.len() >= FLUSH {
            self.out.write_all(&self.buf)?;
            self.buf.clear();
        }
        Ok(())
    }

    /// Writes what is left, once every announced record came.
    fn finish(&mut self) -> io::Result<()> {
        if (self.vertices_written, self.triangles_written) != (self.vertices, self.triangles) {
            return self.refuse(format!(
                "{} vertices and {} triangles written, {} and {} announced",
                self.vertices_written, self.triangles_written, self.vertices, self.triangles
            ));
        }
        self.out.write_all(&self.buf)?;
        self.buf.clear();
        Ok(())
    }

    fn refuse(&mut self, what: String) -> io::Result<()> {
        let e = io::Error::new(io::ErrorKind::InvalidData, what.clone());
        self.refused = Some(what);
        Err(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;
    use crate::shapes::{self, Subdivision};

    fn stream_mesh(path: &Path, m: &Mesh, comments: &[&str]) -> Result<()> {
        let (v, t) = (m.positions.len() as u64, m.triangles.len() as u64);
        write_ply_streamed(path, v, t, comments, |w| {
            m.positions.iter().try_for_each(|&p| w.vertex(p))?;
            m.triangles.iter().try_for_each(|&t| w.triangle(t))
        })
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut n: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        n.sort();
        n
    }

    #[test]
    fn streamed_bytes_are_write_meshs_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let mut m = shapes::torus(1);
        shapes::add_normal_noise(&mut m, 0.3, 2);
        let (a, b) = (dir.path().join("a.ply"), dir.path().join("b.ply"));
        super::super::write_mesh(&a, &m).unwrap();
        stream_mesh(&b, &m, &[]).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    }

    #[test]
    fn streamed_subdivision_reads_back_as_the_mesh_in_memory() {
        let dir = tempfile::tempdir().unwrap();
        let base = shapes::icosphere(1);
        let sub = Subdivision::new(&base, 2, 0.3, 9).unwrap();
        let out = dir.path().join("sub.ply");
        write_ply_streamed(&out, sub.vertices(), sub.triangles(), &["made here"], |w| {
            sub.for_each_vertex(|p| w.vertex(p))?;
            sub.for_each_triangle(|t| w.triangle(t))
        })
        .unwrap();
        let bytes = std::fs::read(&out).unwrap();
        assert!(bytes.starts_with(b"ply\nformat binary_little_endian 1.0\ncomment made here\n"));
        let read = super::super::read_mesh(&out).unwrap();
        let mem = sub.to_mesh();
        assert_eq!(read.triangles, mem.triangles);
        let f32s = |m: &Mesh| -> Vec<[f32; 3]> {
            m.positions.iter().map(|p| p.as_vec3().to_array()).collect()
        };
        assert_eq!(f32s(&read), f32s(&mem));
    }

    #[test]
    fn bad_streams_leave_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("x.ply");
        let m = shapes::icosphere(0);
        let (v, t) = (m.positions.len() as u64, m.triangles.len() as u64);
        let fails = |what: &str, r: Result<()>| {
            let e = r.unwrap_err().to_string();
            assert!(e.contains(what), "{e} lacks {what}");
            assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
        };
        // Too few, too many, out of order, out of range, not finite in f32.
        fails(
            "11 vertices and 0 triangles written, 12 and 20 announced",
            write_ply_streamed(&out, v, t, &[], |w| {
                m.positions[..11].iter().try_for_each(|&p| w.vertex(p))
            }),
        );
        fails(
            "more than the 19 triangles announced",
            write_ply_streamed(&out, v, t - 1, &[], |w| {
                m.positions.iter().try_for_each(|&p| w.vertex(p))?;
                m.triangles.iter().try_for_each(|&t| w.triangle(t))
            }),
        );
        fails(
            "triangle 0 before the last vertex (1 of 12 written)",
            write_ply_streamed(&out, v, t, &[], |w| {
                w.vertex(DVec3::ZERO)?;
                w.triangle([0, 0, 0])
            }),
        );
        fails(
            "cannot write: triangle 0: vertex index 12 out of range (0..12)",
            write_ply_streamed(&out, v, 1, &[], |w| {
                m.positions.iter().try_for_each(|&p| w.vertex(p))?;
                w.triangle([0, 1, 12])
            }),
        );
        fails(
            "vertex 0: coordinate",
            write_ply_streamed(&out, 1, 0, &[], |w| w.vertex(DVec3::splat(1e39))),
        );
        // A producer's own error is reported as it is.
        fails(
            "producer gave up",
            write_ply_streamed(&out, 1, 0, &[], |_| {
                Err(io::Error::other("producer gave up"))
            }),
        );
        // Refused before a file exists.
        fails(
            "use a .ply output",
            stream_mesh(&dir.path().join("x.obj"), &m, &[]),
        );
        fails("one line", stream_mesh(&out, &m, &["two\nlines"]));
    }
}
