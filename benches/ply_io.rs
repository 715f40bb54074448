//! PLY read and write, binary little-endian and ASCII, on the armadillo scan and on a generated
//! 1.3M-triangle icosphere; throughput in bytes of the file. Files live in a tmpfs when there is
//! one (see `common::scratch`): these figures are the codec and the page cache, not the disk.
//!
//! `cargo bench --bench ply_io`

mod common;

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use vcsmooth::io;

fn ply_io(c: &mut Criterion) {
    let dir = common::scratch();
    let mut meshes = Vec::new();
    meshes.extend(common::armadillo());
    meshes.push(common::one_million());
    for named in &meshes {
        // Binary: the shared file as it is, or the generated mesh written once (binary LE float).
        let binary = match &named.path {
            Some(p) => p.clone(),
            None => {
                let p = dir.path().join(format!("{}.ply", named.name));
                io::write_mesh(&p, &named.mesh).expect("write binary PLY");
                p
            }
        };
        let ascii = dir.path().join(format!("{}-ascii.ply", named.name));
        common::write_ascii_ply(&ascii, &named.mesh);

        let mut group = c.benchmark_group(format!("ply_read/{}", named.name));
        common::configure(&mut group, named.large, 3.0);
        for (encoding, path) in [("binary", &binary), ("ascii", &ascii)] {
            group.throughput(Throughput::Bytes(common::file_len(path)));
            group.bench_function(encoding, |b| {
                b.iter(|| black_box(io::read_mesh(path).expect("read PLY")))
            });
        }
        group.finish();

        let mut group = c.benchmark_group(format!("ply_write/{}", named.name));
        common::configure(&mut group, named.large, 3.0);
        for (encoding, source) in [("binary", &binary), ("ascii", &ascii)] {
            // A mesh read from the file keeps its layout, so it is written in the same encoding.
            let mesh = io::read_mesh(source).expect("read PLY");
            let out = dir
                .path()
                .join(format!("{}-{encoding}-out.ply", named.name));
            io::write_mesh(&out, &mesh).expect("write PLY");
            group.throughput(Throughput::Bytes(common::file_len(&out)));
            group.bench_function(encoding, |b| {
                b.iter(|| io::write_mesh(&out, black_box(&mesh)).expect("write PLY"))
            });
        }
        group.finish();
    }
}

criterion_group!(benches, ply_io);
criterion_main!(benches);
