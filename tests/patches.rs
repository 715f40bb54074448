//! The patch-parallel engine: determinism across threads and storage, no seams, volume
//! preservation on many small patches, equality with the whole-mesh engine on one patch.

use std::path::Path;

use glam::DVec3;
use vcsmooth::engine::{self, EngineSettings, Layout, Plan, Quiet, Statistics};
use vcsmooth::mesh::Storage;
use vcsmooth::{Mesh, Method, Options, metrics};

use crate::util::{noisy_sphere, read_scan};

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}

/// Prepare and smooth on `threads` threads; returns positions in the input order and the records.
fn run(
    mesh: &Mesh,
    storage: &Storage,
    patch_size: usize,
    opts: &Options,
    threads: usize,
) -> (Vec<DVec3>, Vec<engine::IterationRecord>, Plan) {
    pool(threads).install(|| {
        let mut plan = Plan::new_observed(
            storage,
            &mesh.positions,
            &mesh.triangles,
            Layout::Patches(patch_size),
            opts.welding(),
            &mut Quiet,
        )
        .unwrap();
        let records = plan
            .smooth(storage, opts, Statistics::Every, &mut Quiet)
            .unwrap();
        let mut out = vec![DVec3::ZERO; mesh.positions.len()];
        plan.positions_in_input_order(&mut out);
        (out, records, plan)
    })
}

#[test]
fn bit_identical_for_any_thread_count_and_any_storage() {
    let mesh = noisy_sphere(5, 0.4, 17);
    let scratch = tempfile::tempdir().unwrap();
    let mapped = Storage::scratch(scratch.path()).unwrap();
    for method in Method::ALL {
        let opts = Options {
            method,
            iterations: 2,
            ..Options::default()
        };
        let (reference, _, plan) = run(&mesh, &Storage::heap(), 500, &opts, 1);
        assert!(plan.schedule.colours.len() > 1 && plan.patches.len() > 10);
        for threads in [2, 8] {
            let (out, _, _) = run(&mesh, &Storage::heap(), 500, &opts, threads);
            assert!(
                out == reference,
                "{method}: {threads} threads differ from 1"
            );
        }
        let (out, _, _) = run(&mesh, &mapped, 500, &opts, 2);
        assert!(
            out == reference,
            "{method}: scratch-mapped storage differs from heap"
        );
        assert!(mapped.mapped_bytes() > 0);
    }
    assert_eq!(
        std::fs::read_dir(scratch.path()).unwrap().count(),
        0,
        "scratch files left behind"
    );
}

/// A mesh split along a seam (as texture seams split files) is welded: each copy ends where its
/// original does, the vertices along the seam move (without welding they are boundary and stay),
/// the volume is kept, and the result is bit-identical for any thread count and storage.
#[test]
fn seams_are_welded_for_any_thread_count_and_any_storage() {
    let sphere = noisy_sphere(4, 0.4, 3);
    let (mesh, copy_of) = crate::util::seamed(&sphere);
    let copies = mesh.positions.len() - sphere.positions.len();
    assert!(copies > 40, "{copies}");
    let scratch = tempfile::tempdir().unwrap();
    let mapped = Storage::scratch(scratch.path()).unwrap();
    for method in Method::ALL {
        let opts = Options {
            method,
            iterations: 2,
            ..Options::default()
        };
        let (reference, _, plan) = run(&mesh, &Storage::heap(), 300, &opts, 1);
        assert_eq!(plan.reordered.welded, copies);
        for (v, &of) in copy_of.iter().enumerate() {
            assert_eq!(reference[v], reference[of as usize], "{method}: copy {v}");
        }
        // The seam's originals (those with a copy) move.
        let seam = copy_of[sphere.positions.len()..].iter();
        let moved = seam
            .filter(|&&v| reference[v as usize] != mesh.positions[v as usize])
            .count();
        assert_eq!(moved, copies, "{method}: seam vertices that moved");
        if method.keeps_volume() {
            let (v0, v1) = (
                metrics::volume(&sphere.positions, &sphere.triangles),
                metrics::volume(&reference, &sphere.triangles),
            );
            assert!(((v1 - v0) / v0).abs() < 1e-12, "{method}: {v0} -> {v1}");
        }
        let (out, _, _) = run(&mesh, &Storage::heap(), 300, &opts, 3);
        assert!(out == reference, "{method}: 3 threads differ from 1");
        let (out, _, _) = run(&mesh, &mapped, 300, &opts, 2);
        assert!(out == reference, "{method}: mapped storage differs");
    }
}

#[test]
fn seams_rounded_apart_are_welded_within_a_tolerance() {
    let sphere = noisy_sphere(4, 0.4, 3);
    let (exact, copy_of) = crate::util::seamed(&sphere);
    let copies = exact.positions.len() - sphere.positions.len();
    // The copies as an exporter that rounds each attribute set on its own leaves them: a few
    // units in the last place apart (the sphere's edges are about 0.1 long).
    let mut rounded = exact.clone();
    for (v, &of) in copy_of.iter().enumerate() {
        if v != of as usize {
            rounded.positions[v] += DVec3::new(3e-7, -2e-7, 1e-7);
        }
    }
    let opts = Options {
        iterations: 2,
        ..Options::default()
    };
    let (reference, _, _) = run(&exact, &Storage::heap(), 300, &opts, 1);
    let (apart, _, plan) = run(&rounded, &Storage::heap(), 300, &opts, 1);
    assert_eq!(plan.reordered.welded, 0);
    assert!(apart != reference);
    // Within the tolerance: welded onto the originals, so the very run of the exact seam.
    let within = Options {
        weld_tolerance: 1e-6,
        ..opts
    };
    let scratch = tempfile::tempdir().unwrap();
    let mapped = Storage::scratch(scratch.path()).unwrap();
    for (storage, threads) in [(&Storage::heap(), 1), (&Storage::heap(), 3), (&mapped, 2)] {
        let (out, _, plan) = run(&rounded, storage, 300, &within, threads);
        assert_eq!(plan.reordered.welded, copies);
        assert!(
            out == reference,
            "{threads} threads, mapped {}",
            storage.is_mapped()
        );
    }
    // A tolerance below the rounding welds nothing.
    let below = Options {
        weld_tolerance: 1e-7,
        ..opts
    };
    assert_eq!(
        run(&rounded, &Storage::heap(), 300, &below, 1)
            .2
            .reordered
            .welded,
        0
    );
}

#[test]
fn every_stencil_is_applied_once_across_many_small_patches_and_volume_is_kept() {
    for name in ["armadillo-86k.ply", "stanford-bunny.ply"] {
        let mesh = read_scan(name);
        let origin = metrics::centroid(&mesh.positions);
        let v0 = metrics::volume_about(&mesh.positions, &mesh.triangles, origin);
        for (method, per_iteration) in [
            (Method::Vcs, None),
            (Method::VcsTriangle, Some(mesh.triangles.len())),
        ] {
            let opts = Options {
                method,
                iterations: 3,
                ..Options::default()
            };
            let (out, records, plan) = run(&mesh, &Storage::heap(), 64, &opts, 2);
            let edges = plan.topology.stats.edges;
            let crossing = plan
                .patches
                .iter()
                .map(|p| p.crossing_edges(&plan.topology))
                .sum::<u64>();
            assert!(
                crossing > 1000,
                "{name}: patches of 64 vertices must cut many edges ({crossing})"
            );
            let expected = per_iteration.unwrap_or(edges) as u64;
            for r in &records {
                assert_eq!(
                    r.stencils.considered(),
                    expected,
                    "{name} {method}: a stencil was missed or repeated"
                );
                assert!(r.stencils.applied > expected / 2);
            }
            let v1 = metrics::volume_about(&out, &mesh.triangles, origin);
            assert!(
                ((v1 - v0) / v0).abs() <= 1e-9,
                "{name} {method}: {:e}",
                ((v1 - v0) / v0).abs()
            );
            // The input's fixed (boundary) vertices are untouched.
            let topo = vcsmooth::Topology::build(mesh.positions.len(), &mesh.triangles).unwrap();
            for (v, (p, q)) in out.iter().zip(mesh.positions.iter()).enumerate() {
                if topo.is_fixed(v as u32) {
                    assert_eq!(p, q, "fixed vertex {v} moved");
                }
            }
        }
    }
}

#[test]
fn one_patch_equals_the_whole_mesh_engine_on_the_reordered_mesh() {
    let mesh = noisy_sphere(3, 0.4, 17);
    for method in Method::ALL {
        let opts = Options {
            method,
            iterations: 3,
            ..Options::default()
        };
        let (out, _, plan) = run(&mesh, &Storage::heap(), usize::MAX / 2, &opts, 2);
        assert_eq!(plan.patches.len(), 1);
        // The whole-mesh engine on the same reordered arrays.
        let re = vcsmooth::partition::reorder(&Storage::heap(), &mesh.positions, &mesh.triangles)
            .unwrap();
        let mut whole = Mesh::new(re.positions.to_vec(), re.triangles.to_vec());
        engine::smooth_in_order(&mut whole, &opts, &one_thread(), &mut Quiet).unwrap();
        for (new, &old) in re.order.iter().enumerate() {
            assert_eq!(
                out[old as usize], whole.positions[new],
                "{method}: vertex {old}"
            );
        }
    }
}

#[test]
fn patched_laplacian_matches_the_whole_mesh_engine() {
    // Jacobi methods do not depend on order: only the neighbour summation order may differ.
    let mesh = noisy_sphere(4, 0.4, 17);
    for method in [Method::Laplacian, Method::Taubin] {
        let opts = Options {
            method,
            iterations: 5,
            ..Options::default()
        };
        let (out, _, _) = run(&mesh, &Storage::heap(), 100, &opts, 2);
        let mut reference = mesh.clone();
        engine::smooth_in_order(&mut reference, &opts, &one_thread(), &mut Quiet).unwrap();
        for (a, b) in out.iter().zip(reference.positions.iter()) {
            assert!((*a - *b).length() < 1e-12, "{method}: {a} vs {b}");
        }
    }
}

/// A scratch directory without room gives a clean error up front (no SIGBUS later, no file left).
/// Needs root to mount a 1 MiB tmpfs; as another user the check is reported and skipped.
#[test]
fn full_scratch_disk_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let mounted = std::process::Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=1m", "tmpfs"])
        .arg(dir.path())
        .status()
        .is_ok_and(|s| s.success());
    if !mounted {
        let root = std::process::Command::new("id")
            .arg("-u")
            .output()
            .is_ok_and(|o| o.stdout.starts_with(b"0\n"));
        assert!(
            !root,
            "running as root, but could not mount a tmpfs for the full-disk test"
        );
        eprintln!(
            "full_scratch_disk_is_a_clear_error: not root, cannot mount a small tmpfs; skipped"
        );
        return;
    }
    struct Unmount<'a>(&'a Path);
    impl Drop for Unmount<'_> {
        fn drop(&mut self) {
            let _ = std::process::Command::new("umount").arg(self.0).status();
        }
    }
    let _guard = Unmount(dir.path());
    let storage = Storage::scratch(dir.path()).unwrap();
    let small = storage.zeroed::<DVec3>(1000);
    assert!(small.is_ok(), "24 kB must fit in 1 MiB");
    let err = storage.zeroed::<DVec3>(1 << 20).unwrap_err().to_string();
    assert!(
        err.contains("cannot reserve") && err.contains("scratch"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "a scratch file was left behind"
    );
}

fn one_thread() -> EngineSettings {
    EngineSettings {
        threads: Some(1),
        ..EngineSettings::default()
    }
}

#[test]
fn multi_iteration_rounds_equal_plain_steps() {
    // The bunny: two tiles of the in-memory engine, a boundary (fixed vertices). In memory the
    // Jacobi methods run tile by tile, several steps per round; in scratch storage one plain step
    // at a time. Both must give the same bits, with statistics every iteration (one iteration per
    // round) or only at the end (rounds of up to 8 steps, the last one short).
    let mesh = read_scan("stanford-bunny.ply");
    let scratch = tempfile::tempdir().unwrap();
    let mapped = Storage::scratch(scratch.path()).unwrap();
    for (method, iterations) in [(Method::Laplacian, 11), (Method::Taubin, 9)] {
        let opts = Options {
            method,
            iterations,
            ..Options::default()
        };
        let plain = pool(2).install(|| {
            let mut plan = Plan::new(
                &mapped,
                &mesh.positions,
                &mesh.triangles,
                Layout::Patches(16384),
            )
            .unwrap();
            plan.smooth(&mapped, &opts, Statistics::Every, &mut Quiet)
                .unwrap();
            plan.reordered.positions.to_vec()
        });
        for threads in [1, 3] {
            // Statistics every iteration, or only for the last (`--stats last`): the Jacobi methods
            // then run several iterations per pass over memory.
            let tiled = |when: Statistics| {
                pool(threads).install(|| {
                    let heap = Storage::heap();
                    let mut plan = Plan::new(
                        &heap,
                        &mesh.positions,
                        &mesh.triangles,
                        Layout::Patches(16384),
                    )
                    .unwrap();
                    let records = plan.smooth(&heap, &opts, when, &mut Quiet).unwrap();
                    (plan.reordered.positions.to_vec(), records)
                })
            };
            let (every, rec_every) = tiled(Statistics::Every);
            let (last, rec_last) = tiled(Statistics::Last);
            assert!(
                every == plain,
                "{method}, {threads} threads: every iteration"
            );
            assert!(last == plain, "{method}, {threads} threads: last only");
            // The last iteration's statistics agree (every iteration's volume is measured inside
            // the tiles, summed in another order); the others are measured only when asked.
            let (a, b) = (rec_every.last().unwrap(), rec_last.last().unwrap());
            assert!((a.volume - b.volume).abs() <= 1e-12 * a.volume.abs());
            assert_eq!(a.max_displacement, b.max_displacement);
            assert!(
                (a.mean_displacement - b.mean_displacement).abs() <= 1e-12 * a.mean_displacement
            );
            assert!(
                rec_every
                    .iter()
                    .all(|r| r.max_displacement > 0.0 && r.volume.is_finite() && r.area_pct > 0.0)
            );
            assert!(rec_last[..iterations - 1].iter().all(|r| r.volume.is_nan()));
        }
    }
}

/// The stencil methods' patches measure how far their vertices moved (each patch when it ends,
/// its vertices next to an earlier patch against their positions at the sweep's start), with no
/// copy of the positions: the records agree with those of the loop's copy, which smoothed
/// boundaries keep (a closed sphere has none, so the positions are the same), for small and
/// default patches, any thread count, and the patch's own sums (scratch) or the array (heap).
#[test]
fn patches_measure_their_moves_as_the_copy_does() {
    let mesh = noisy_sphere(5, 0.4, 23);
    let scratch = tempfile::tempdir().unwrap();
    let mapped = Storage::scratch(scratch.path()).unwrap();
    for method in [
        Method::Vcs,
        Method::Lem,
        Method::VcsTriangle,
        Method::VcsLowpass,
    ] {
        for patch_size in [200, 16384] {
            let opts = Options {
                method,
                iterations: 2,
                ..Options::default()
            };
            let copied = Options {
                boundary: vcsmooth::smooth::Boundary::Smooth,
                ..opts
            };
            let (reference, by_copy, _) = run(&mesh, &Storage::heap(), patch_size, &copied, 1);
            for (storage, threads) in [(&Storage::heap(), 1), (&Storage::heap(), 3), (&mapped, 2)] {
                let (out, records, _) = run(&mesh, storage, patch_size, &opts, threads);
                let case = format!("{method}, patches of {patch_size}, {threads} threads");
                assert!(out == reference, "{case}: positions");
                for (a, b) in records.iter().zip(&by_copy) {
                    assert!(a.max_displacement > 0.0, "{case}");
                    assert_eq!(a.max_displacement, b.max_displacement, "{case}");
                    let mean = (a.mean_displacement - b.mean_displacement).abs();
                    assert!(mean <= 1e-12 * b.mean_displacement, "{case}: {a:?} {b:?}");
                }
            }
        }
    }
}
