//! Meshes and scratch space shared by the benchmarks.
//!
//! - [`armadillo`]: `../shared/meshes/armadillo-86k.ply` (relative to the crate), a real scan of
//!   86 482 triangles; the benchmarks that need it are skipped with a note when it is missing.
//! - [`one_million`]: icosphere level 8, 1 310 720 triangles; [`four_million`]: torus level 7,
//!   4 194 304 triangles. Both with Gaussian noise along the normals (0.3 × the mean edge length,
//!   seed 1), as `vcsmooth bench` uses.
//! - [`scratch`]: a temporary directory on `/dev/shm` when there is one, so that file benchmarks
//!   measure the encoder, the decoder and the page cache rather than the disk (the atomic writer's
//!   `fsync` is free on a tmpfs).

#![allow(dead_code)] // each bench binary uses its own subset

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{BenchmarkGroup, SamplingMode, measurement::WallTime};
use vcsmooth::shapes;
use vcsmooth::{Mesh, io};

/// Noise of the generated meshes, × the mean edge length.
pub const NOISE: f64 = 0.3;

/// A named benchmark mesh.
pub struct Named {
    pub name: &'static str,
    pub mesh: Mesh,
    /// Where it was read from (shared meshes only).
    pub path: Option<PathBuf>,
    /// Large meshes get few, flat samples.
    pub large: bool,
}

/// The armadillo scan, if `../shared/meshes` has it.
pub fn armadillo() -> Option<Named> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes/armadillo-86k.ply");
    match io::read_mesh(&path) {
        Ok(mesh) => Some(Named {
            name: "armadillo-86k",
            mesh,
            path: Some(path),
            large: false,
        }),
        Err(e) => {
            eprintln!("skipping the armadillo benchmarks: {e}");
            None
        }
    }
}

/// Noisy icosphere level 8: 1 310 720 triangles.
pub fn one_million() -> Named {
    let mut mesh = shapes::icosphere(8);
    shapes::add_normal_noise(&mut mesh, NOISE, 1);
    Named {
        name: "icosphere8-1.3M",
        mesh,
        path: None,
        large: true,
    }
}

/// Noisy torus level 7: 4 194 304 triangles.
pub fn four_million() -> Named {
    let mut mesh = shapes::torus(7);
    shapes::add_normal_noise(&mut mesh, NOISE, 1);
    Named {
        name: "torus7-4.2M",
        mesh,
        path: None,
        large: true,
    }
}

/// The armadillo (when present), then the generated 1M and 4M meshes.
pub fn all_meshes() -> Vec<Named> {
    armadillo()
        .into_iter()
        .chain([one_million(), four_million()])
        .collect()
}

/// A temporary directory, on `/dev/shm` when possible.
pub fn scratch() -> tempfile::TempDir {
    let shm = Path::new("/dev/shm");
    if shm.is_dir() {
        if let Ok(dir) = tempfile::Builder::new()
            .prefix("vcsmooth-bench")
            .tempdir_in(shm)
        {
            return dir;
        }
    }
    tempfile::Builder::new()
        .prefix("vcsmooth-bench")
        .tempdir()
        .expect("temporary directory")
}

/// Write `mesh` as an ASCII PLY (`x y z float`, `list uchar int vertex_indices`), so that reading
/// it back gives a mesh that `io::write_mesh` writes as ASCII again.
pub fn write_ascii_ply(path: &Path, mesh: &Mesh) {
    let file = std::fs::File::create(path).expect("create ASCII PLY");
    let mut out = std::io::BufWriter::with_capacity(1 << 20, file);
    write!(
        out,
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    )
    .unwrap();
    for p in &mesh.positions {
        writeln!(out, "{} {} {}", p.x as f32, p.y as f32, p.z as f32).unwrap();
    }
    for t in &mesh.triangles {
        writeln!(out, "3 {} {} {}", t[0], t[1], t[2]).unwrap();
    }
    out.flush().unwrap();
}

/// Size of a file in bytes.
pub fn file_len(path: &Path) -> u64 {
    std::fs::metadata(path).expect("file size").len()
}

/// Sampling for a mesh: small meshes get 20 samples over 2 s; large ones 10 flat samples (one
/// run each when a run is long) over `large_seconds`.
pub fn configure(group: &mut BenchmarkGroup<'_, WallTime>, large: bool, large_seconds: f64) {
    if large {
        group
            .sample_size(10)
            .sampling_mode(SamplingMode::Flat)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(Duration::from_secs_f64(large_seconds));
    } else {
        group
            .sample_size(20)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(Duration::from_secs(2));
    }
}
