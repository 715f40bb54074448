//! Measurement for issue #18 (not part of the tool): what the report's statistics cost on one
//! thread, against the least that any pass giving the same values must do.
//!
//! usage: statistics_floor MESH [REPEATS]   (medians of REPEATS, default 5; one thread)
//!
//! Prints, for the mesh in the plan's order:
//! - `components`: the connected-component count ([`vcsmooth::metrics::connectivity`]);
//! - `geometry`: every figure that depends on the positions ([`Plan::geometry`]);
//! - `vertex pass`: its pass over the vertices alone ([`vcsmooth::metrics::vertex_sums`]);
//! - `edge arithmetic`: the same edge sums (the angles with the library's arctangent) with every
//!   edge's two faces found beforehand (untimed): each face normal once, each length, each
//!   dihedral angle;
//! - `arctangents and roots`: only the `atan2` and the two square roots of every edge, their
//!   arguments computed beforehand: the floor of the pass while the values stay the same.
use std::time::Instant;

use glam::DVec3;
use vcsmooth::engine::plan::{Layout, Plan};
use vcsmooth::engine::reduce;
use vcsmooth::mesh::Storage;
use vcsmooth::meter::Meter;
use vcsmooth::metrics::{self, EdgeSums, VertexSums};

fn median(repeats: usize, mut f: impl FnMut() -> f64) -> f64 {
    let mut seconds: Vec<f64> = (0..repeats)
        .map(|_| {
            let clock = Instant::now();
            std::hint::black_box(f());
            clock.elapsed().as_secs_f64()
        })
        .collect();
    seconds.sort_by(f64::total_cmp);
    seconds[seconds.len() / 2]
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: statistics_floor MESH [REPEATS]");
    let repeats: usize = args.next().map_or(5, |r| r.parse().expect("REPEATS"));
    let mesh = vcsmooth::io::read_mesh(std::path::Path::new(&path)).expect("a mesh");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    pool.install(|| {
        let plan = Plan::new(
            &Storage::heap(),
            &mesh.positions,
            &mesh.triangles,
            Layout::Patches(4096),
        )
        .expect("a plan");
        let (pos, tris, topo) = (
            &plan.reordered.positions[..],
            &plan.reordered.triangles[..],
            &plan.topology,
        );
        let pass = || {
            reduce::map_fold(
                pos,
                |first, chunk| {
                    let vertices = first as u32..(first + chunk.len()) as u32;
                    metrics::vertex_sums(pos, tris, topo, vertices, DVec3::ZERO)
                },
                VertexSums::default(),
                |a, b| a + b,
            )
        };
        // Every edge (i < j), ascending, with its two faces when it has exactly two.
        let mut edges: Vec<(u32, u32, Option<[u32; 2]>)> = Vec::new();
        for i in 0..topo.len() as u32 {
            for &j in topo.neighbors(i).iter().filter(|&&j| j > i) {
                let mut faces = topo
                    .faces_of(i, tris)
                    .filter(|&t| tris[t as usize].contains(&j));
                let pair = match (faces.next(), faces.next(), faces.next()) {
                    (Some(a), Some(b), None) => Some([a, b]),
                    _ => None,
                };
                edges.push((i, j, pair));
            }
        }
        let normal = |t: u32| {
            let [a, b, c] = tris[t as usize].map(|v| pos[v as usize]);
            (b - a).cross(c - a)
        };
        let usable = |n: DVec3| n.length_squared() > 0.0 && n.is_finite();
        let arithmetic = || {
            let normals: Vec<DVec3> = (0..tris.len() as u32).map(normal).collect();
            let mut sums = EdgeSums::default();
            for &(i, j, pair) in &edges {
                sums.length.0 += pos[i as usize].distance(pos[j as usize]);
                sums.length.1 += 1;
                if let Some([a, b]) = pair {
                    let (n, m) = (normals[a as usize], normals[b as usize]);
                    if usable(n) && usable(m) {
                        sums.angle.0 += n.cross(m).length().atan2(n.dot(m)).to_degrees();
                        sums.angle.1 += 1;
                    }
                }
            }
            sums
        };
        // One chunk of the pass sums as the whole does only below 16,384 vertices; the check
        // compares the sequential sums, which the arithmetic reproduces.
        let whole = metrics::vertex_sums(pos, tris, topo, 0..topo.len() as u32, DVec3::ZERO).edges;
        let same = arithmetic();
        let angle = (whole.angle.0 - same.angle.0).abs() <= 1e-12 * same.angle.0;
        assert!(
            whole.length == same.length && whole.angle.1 == same.angle.1 && angle,
            "the arithmetic gives the pass's sums"
        );
        let roots: Vec<(f64, f64, f64)> = edges
            .iter()
            .map(|&(i, j, pair)| {
                let d2 = pos[i as usize].distance_squared(pos[j as usize]);
                let (y2, x) = pair.map_or((0.0, 1.0), |[a, b]| {
                    let (n, m) = (normal(a), normal(b));
                    (n.cross(m).length_squared(), n.dot(m))
                });
                (y2, x, d2)
            })
            .collect();
        let floor = || {
            roots
                .iter()
                .map(|&(y2, x, d2)| y2.sqrt().atan2(x).to_degrees() + d2.sqrt())
                .sum::<f64>()
        };
        let heap = Storage::heap();
        let components = || {
            metrics::components(plan.len(), tris, &heap, &Meter::default()).expect("counts") as f64
        };
        println!(
            "{} vertices, {} edges, one thread, medians of {repeats}",
            pos.len(),
            edges.len()
        );
        for (what, f) in [
            ("components", &components as &dyn Fn() -> f64),
            ("geometry", &|| {
                let origin = reduce::centroid(&plan.reordered.positions);
                plan.geometry_about(origin, &Meter::default()).area
            }),
            ("vertex pass", &|| pass().edges.angle.0),
            ("edge arithmetic", &|| arithmetic().angle.0),
            ("arctangents and roots", &floor),
        ] {
            println!("{what:>22} {:.4} s", median(repeats, f));
        }
    });
}
