//! One iteration of each method (laplacian, taubin, lem, vcs, vcs-triangle) on the patch engine,
//! on the armadillo scan, a 1.3M-triangle icosphere and a 4.2M-triangle torus, on all cores.
//!
//! The time is the driver's own per-iteration figure (`IterationRecord::seconds`: the sweep,
//! without the per-iteration volume and area statistics), collected with `iter_custom` over runs
//! of as many iterations as criterion asks for, each run starting from the same noisy positions.
//! Throughput is in triangles per second for every method, so the methods compare directly; the
//! edge-stencil methods (lem, vcs) process about 1.5 stencils per triangle of a closed mesh
//! (`vcsmooth bench` reports stencils per second).
//!
//! `cargo bench --bench smooth`

mod common;

use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use vcsmooth::engine::{DEFAULT_PATCH_SIZE, Layout, Plan, Quiet, Statistics};
use vcsmooth::mesh::Storage;
use vcsmooth::{Method, Options};

fn smooth(c: &mut Criterion) {
    let storage = Storage::heap();
    for named in common::all_meshes() {
        let mesh = &named.mesh;
        let mut plan = Plan::new(
            &storage,
            &mesh.positions,
            &mesh.triangles,
            Layout::Patches(DEFAULT_PATCH_SIZE),
        )
        .expect("prepare");
        let initial = plan.reordered.positions.to_vec();
        let mut group = c.benchmark_group(format!("smooth/{}", named.name));
        let seconds = if mesh.triangles.len() > 2_000_000 {
            6.0
        } else {
            3.0
        };
        common::configure(&mut group, named.large, seconds);
        group.throughput(Throughput::Elements(mesh.triangles.len() as u64));
        for method in Method::ALL {
            group.bench_function(method.name(), |b| {
                b.iter_custom(|iterations| {
                    plan.reordered.positions.copy_from_slice(&initial);
                    let opts = Options {
                        method,
                        iterations: iterations as usize,
                        ..Default::default()
                    };
                    let records = plan
                        .smooth(&storage, &opts, Statistics::Every, &mut Quiet)
                        .expect("smooth");
                    Duration::from_secs_f64(records.iter().map(|r| r.seconds).sum())
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, smooth);
criterion_main!(benches);
