//! The plan's phases, each on the output of the one before, as `engine::Plan::new` runs them:
//! Morton reorder, topology (CSR adjacency, fixed mask), partition (patches) + schedule (conflict
//! graph colouring), and the statistics a report measures of a plan (the counts, components
//! included, and the geometry walk: volume, area, extent, edge lengths, roughness). On the
//! armadillo scan, a 1.3M-triangle icosphere and a 4.2M-triangle torus;
//! throughput in triangles, on all cores.
//!
//! `cargo bench --bench prepare`

mod common;

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use vcsmooth::engine::{DEFAULT_PATCH_SIZE, reduce};
use vcsmooth::mesh::Storage;
use vcsmooth::meter::Meter;
use vcsmooth::{Topology, metrics, partition, schedule};

fn prepare(c: &mut Criterion) {
    let storage = Storage::heap();
    for named in common::all_meshes() {
        let mesh = &named.mesh;
        let n = mesh.positions.len();
        let mut group = c.benchmark_group(format!("prepare/{}", named.name));
        common::configure(&mut group, named.large, 4.0);
        group.throughput(Throughput::Elements(mesh.triangles.len() as u64));

        group.bench_function("reorder", |b| {
            b.iter(|| {
                black_box(partition::reorder(&storage, &mesh.positions, &mesh.triangles).unwrap())
            })
        });
        let reordered = partition::reorder(&storage, &mesh.positions, &mesh.triangles).unwrap();
        group.bench_function("topology", |b| {
            b.iter(|| black_box(Topology::build_in(&storage, n, &reordered.triangles).unwrap()))
        });
        let topo = Topology::build_in(&storage, n, &reordered.triangles).unwrap();
        group.bench_function("partition+schedule", |b| {
            b.iter(|| {
                let patches = partition::patches(n, &reordered.triangles, DEFAULT_PATCH_SIZE);
                black_box(schedule::schedule(&topo, &patches))
            })
        });
        let source = &mesh.source;
        group.bench_function("statistics/counts", |b| {
            b.iter(|| {
                let tris = &reordered.triangles;
                let components = metrics::components(n, tris, &storage, &Meter::default()).unwrap();
                black_box(metrics::connectivity(
                    n,
                    tris.len(),
                    source,
                    &topo,
                    components,
                ))
            })
        });
        group.bench_function("statistics/geometry", |b| {
            b.iter(|| {
                black_box(reduce::geometry(
                    &reordered.positions,
                    &reordered.triangles,
                    &topo,
                ))
            })
        });
        group.finish();
    }
}

criterion_group!(benches, prepare);
criterion_main!(benches);
